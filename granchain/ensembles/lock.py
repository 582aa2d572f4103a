"""One writer per store: an advisory lock file ``STORE.lock`` next to the store, there only while a
writer holds it.

The lock is an ``fcntl.flock`` on that file (released by the kernel when its holder exits, even
after ``kill -9``), and the file records the holder's PID, host and start time for messages. A lock
file whose holder is gone (killed) is therefore simply taken over (a warning names the old holder).
:meth:`StoreLock.release` deletes the file while still holding the lock; a process that opened the file
just before and is granted the lock just after finds that the path no longer names the file it locked,
and starts over on the file now at the path (so two writers never hold locks on two different files).
Every user of the lock (ensemble stores, the design history ``OUT/history.zarr.lock``) calls
``release()`` (or uses ``with StoreLock(path):``) when it ends, also on errors and interruptions.

On file systems without ``flock`` (some network mounts) it falls back to creating the file with
``O_CREAT | O_EXCL``; a lock left by a process that no longer runs on this host is then taken over.
"""

from __future__ import annotations

import datetime as _dt
import errno
import json
import os
import socket
import warnings

__all__ = ["StoreLock", "StoreLockedError"]


class StoreLockedError(ValueError):
    """Another process is writing the store."""


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


class StoreLock:
    """``with StoreLock(path):`` or ``acquire()`` / ``release()``; ``holder()`` reads the record."""

    def __init__(self, store: str):
        self.store = os.fspath(store)
        self.file = self.store.rstrip("/" + os.sep) + ".lock"
        self._fd = None
        self._exclusive = False

    def holder(self) -> dict | None:
        try:
            with open(self.file, encoding="utf-8") as f:
                return json.loads(f.read() or "null")
        except (OSError, ValueError):
            return None

    def _current_holder(self, patience: float = 1.0):
        """The record of the process that holds the lock. It writes its record just after taking the lock,
        so a process refused in between would read an empty file (or the record a previous writer left,
        marked released) and could not name the holder: wait up to ``patience`` seconds for it."""
        import time

        deadline = time.monotonic() + patience
        while True:
            holder = self.holder()
            if (isinstance(holder, dict) and not holder.get("released")) or time.monotonic() > deadline:
                return holder
            time.sleep(0.01)

    def _record(self) -> bytes:
        return json.dumps({"pid": os.getpid(), "host": socket.gethostname(),
                           "since": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")}).encode()

    def _refuse(self, holder):
        who = (f"PID {holder.get('pid')} on host {holder.get('host')} (since {holder.get('since')})"
               if isinstance(holder, dict) else "another process")
        raise StoreLockedError(
            f"{self.store} is being written by {who}: wait for it to finish, or stop it; the lock is {self.file} "
            "(delete it only if that process is certainly gone)")

    def acquire(self) -> None:
        import fcntl

        for _ in range(100):  # each retry follows a release that deleted the file between our open and lock
            try:
                fd = os.open(self.file, os.O_RDWR | os.O_CREAT, 0o644)
            except OSError as exc:
                raise ValueError(f"out = {self.store}: cannot write there ({exc.strerror} for {self.file}); "
                                 "choose a writable path") from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                os.close(fd)
                self._refuse(self._current_holder())
            except OSError as exc:
                os.close(fd)
                if exc.errno in (errno.ENOLCK, errno.EOPNOTSUPP, errno.EINVAL):
                    return self._acquire_exclusive()
                raise
            if self._names(fd):
                break
            os.close(fd)  # locked a file its holder deleted on release: start over on the one at the path now
        else:
            self._refuse(self.holder())
        previous = self.holder()
        if isinstance(previous, dict) and previous.get("pid") is not None and not previous.get("released"):
            warnings.warn(f"took over the stale lock {self.file} of PID {previous.get('pid')} on host "
                          f"{previous.get('host')} (that process has ended)", UserWarning, stacklevel=3)
        os.ftruncate(fd, 0)
        os.pwrite(fd, self._record(), 0)
        os.fsync(fd)
        self._fd = fd

    def _names(self, fd) -> bool:
        """Whether the lock file's path still names the open file ``fd``."""
        try:
            st, mine = os.stat(self.file), os.fstat(fd)
        except OSError:
            return False
        return (st.st_ino, st.st_dev) == (mine.st_ino, mine.st_dev)

    def _acquire_exclusive(self) -> None:
        """Fallback without flock: O_EXCL creation; a dead holder on this host is taken over."""
        for _ in range(2):
            try:
                fd = os.open(self.file, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
            except FileExistsError:
                holder = self.holder()
                if (isinstance(holder, dict) and (holder.get("released") or (holder.get("host") == socket.gethostname()
                                                                              and not _pid_alive(int(holder.get("pid", -1)))))):
                    os.replace(self.file, f"{self.file}.stale-{os.getpid()}")
                    os.unlink(f"{self.file}.stale-{os.getpid()}")
                    continue
                self._refuse(holder)
            os.write(fd, self._record())
            os.close(fd)
            self._exclusive = True
            return
        self._refuse(self.holder())

    def release(self) -> None:
        """Give the lock up and delete the lock file (idempotent)."""
        if self._exclusive:
            self._exclusive = False
            try:
                os.unlink(self.file)
            except OSError:
                pass
        if self._fd is None:
            return
        import fcntl

        fd, self._fd = self._fd, None
        try:
            if self._names(fd):  # deleted while held: whoever locks the old file next sees it is gone
                os.unlink(self.file)
        except OSError:
            pass
        finally:
            try:
                fcntl.flock(fd, fcntl.LOCK_UN)
            finally:
                os.close(fd)

    def __enter__(self):
        self.acquire()
        return self

    def __exit__(self, *exc):
        self.release()
