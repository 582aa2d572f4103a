"""Numba-compiled kernels: pure functions over arrays, scalars and the grouped records of ``records``.

The Numba backend (``granchain.backends.numba_backend``) binds an integrator and a chain to these:
it validates, allocates, fills the records and calls the kernel :func:`~granchain.backends.kernels.dispatch.chain_kernel` picks (one chain) or
:func:`batch.integrate_batch` (many). Every kernel runs unchanged under ``NUMBA_DISABLE_JIT=1``
(slowly), which the test-suite checks. The modules, by concern:

- ``records``: the grouped arguments (model, method, run controls, state, outputs) and the ``info`` slots;
- ``forces``: contact forces, accelerations, energies (Eq. motion_rescaled, Eq. hertz-1);
- ``window``: the active window ahead of the pulse and the trailing window behind it;
- ``stop``: when the pulse has left (free end) or come back (wall);
- ``peaks``: peak records, the state at t = 0, the ``info`` record;
- ``dense``: dense output of the Runge-Kutta steps and the roots found on it;
- ``rkloop``: the adaptive Runge-Kutta step loop; ``observe``: what its accepted steps record (peaks, grid
  samples, a yielding contact's turn); ``dp5`` and ``rkn4``: the tableaux it runs;
- ``verlet``: velocity Verlet;
- ``dispatch``: the single-chain entry points; ``batch``: the parallel ensemble driver, which calls them
  through their addresses;
  ``aligned``: the aligned pulse's sums;
- ``memory``: borrowed views; ``jit``: the compilation flags.

Where the compiled machine code is kept (``cache=True``, see ``jit``): in a per-user cache
directory, never next to these sources. An installed package may be read-only, and files written into
it are files pip does not track: ``pip install .``, a first run, then ``pip install -e .`` left a
``site-packages/granchain/`` holding only them, which shadowed the editable install. The directory is
``granchain-kernels-<key>`` under ``$NUMBA_CACHE_DIR`` when the user set it (their choice wins), else
under ``numba`` in granchain's cache directory (``granchain._cache``: ``$GRANCHAIN_CACHE``, else
``$XDG_CACHE_HOME`` or ``~/.cache``, then ``granchain``). This package points ``numba.config.CACHE_DIR``
there when it is imported, before any kernel module creates its compiled functions (Numba fixes a
function's cache location when ``njit(cache=True)`` wraps it); compiled functions of other code that
this process creates afterwards are cached there too (Numba has one such setting per process).

Numba's cache checks only the source file of the function it compiles, but the kernels inline each
other across files (the step loop inlines the stages, which inline the force routines). So the
directory is keyed on all kernel sources together (and Numba's version): when any of them changes, a
new directory is used, and two installed versions, or a source checkout and an install, never share
machine code. The least recently used directories of other keys are removed, all but a few (two
installations in use side by side keep theirs).
"""

from __future__ import annotations

import atexit
import hashlib
import os
import shutil
import tempfile
from pathlib import Path

#: Directories of other keys kept besides this one's (the most recently used ones).
KEEP_OTHERS = 3
#: The file in a cache directory holding its full key; its modification time is the last use.
STAMP = "granchain-kernels.sha256"


def _key() -> str:
    """SHA-256 of Numba's version and every kernel source, plus the pure-Python module whose
    constants the kernels freeze in."""
    import numba

    here = Path(__file__).parent
    digest = hashlib.sha256(numba.__version__.encode())
    for src in sorted(here.glob("*.py")) + [here.parent.parent / "_status.py"]:
        digest.update(src.name.encode() + src.read_bytes())
    return digest.hexdigest()


def _writable(path: Path) -> bool:
    try:
        path.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=path).close()
        return True
    except OSError:
        return False


def _prune(root: Path, keep: Path) -> None:
    """Remove the directories of other keys under ``root``, all but the :data:`KEEP_OTHERS` most
    recently used (only directories that hold a stamp: nothing else under a user's directory)."""
    others = []
    for d in root.glob("granchain-kernels-*"):
        if d != keep and (d / STAMP).is_file():
            try:
                others.append(((d / STAMP).stat().st_mtime, d))
            except OSError:
                pass
    for _, d in sorted(others, reverse=True)[KEEP_OTHERS:]:
        shutil.rmtree(d, ignore_errors=True)


def _use_cache_dir() -> tuple[Path, Path]:
    """Choose the root and this key's directory, make sure the directory holds only this key's machine
    code, and point Numba's cache there. Returns (root, directory)."""
    from numba.core import config

    key = _key()
    root = Path(os.environ["NUMBA_CACHE_DIR"]).absolute() if os.environ.get("NUMBA_CACHE_DIR") else None
    if root is None:
        from ..._cache import user_cache_dir

        root = user_cache_dir() / "numba"
    directory = root / f"granchain-kernels-{key[:16]}"
    if config.DISABLE_JIT:  # nothing is compiled, nothing is cached: create nothing
        return root, directory
    if not _writable(directory):
        # No writable cache directory (a read-only home, say): a private temporary one, removed at exit.
        # Numba would otherwise fall back to the package's __pycache__ where that is writable.
        try:
            root = Path(tempfile.mkdtemp(prefix="granchain-kernels-"))
        except OSError:  # no temporary folder either: Numba's own fallbacks decide (nothing granchain can do)
            config.CACHE_DIR = str(directory)
            return root, directory
        atexit.register(shutil.rmtree, root, True)
        directory = root / f"granchain-kernels-{key[:16]}"
        directory.mkdir()
    stamp = directory / STAMP
    try:
        fresh = not stamp.is_file()
        if not fresh and stamp.read_text() != key:  # a shortened key shared by two keys: start afresh
            for f in list(directory.rglob("*.nbi")) + list(directory.rglob("*.nbc")):
                f.unlink(missing_ok=True)
            fresh = True
        if fresh:
            stamp.write_text(key)
            _prune(root, directory)
        else:
            os.utime(stamp)  # last used now
    except OSError:
        pass  # the cache still works; only its bookkeeping failed
    config.CACHE_DIR = str(directory)
    return root, directory


#: The directory Numba's cache of the kernels lives in (``CACHE_ROOT / granchain-kernels-<key>``), and
#: its root: a helper process that is to share the cache gets ``NUMBA_CACHE_DIR=CACHE_ROOT``.
CACHE_ROOT, CACHE_DIR = _use_cache_dir()
