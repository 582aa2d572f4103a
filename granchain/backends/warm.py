"""Compile an entry point in a second process while this one compiles another.

Numba compiles one function at a time per process (a global lock), and a first ensemble of both of
the paper's chains (``granchain reproduce``, ``granchain ensemble``) needs two single-chain entry
points that take ~12 s each to compile on a laptop core: RKN4 for the decorated chains and DP5 for
the effective ones, one after the other. On a machine with a second core, a helper process compiles
DP5's entry point into Numba's on-disk cache while this process compiles RKN4's
(``granchain.ensembles.run`` starts it); when this process gets to the effective chains it waits for
the helper if it is still at work (:func:`wait_for`) and loads DP5 from the cache. The machine code
is the same either way (Numba keys its cache on the function's source, its closure's values, the
argument types and the CPU), so the results are bitwise those of a run that compiled both itself.

Nothing is started when the entry point is already cached, when Numba's JIT is disabled, or on a
single core; a helper still running when the run ends is stopped (Numba writes a cache file under a
temporary name and renames it, so a stopped helper leaves no partial entry)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

#: For each job, the entry point it compiles (its name in ``kernels.dispatch``) and what the helper runs:
#: the smallest run that compiles it for the argument types every run passes it (``simulate`` and the
#: ensemble kernel share one signature).
JOBS = {
    "dp5": ("dp5_chain", "import granchain as gc; gc.simulate(gc.effective(gc.decorated([0.05, 0.3, 0.012])))"),
}


#: The helpers still running, by job: :func:`wait_for` lets this process wait for one instead of
#: compiling the same entry point a second time.
_RUNNING: dict = {}
#: The longest :func:`wait_for` waits (s), far longer than a compilation takes: past it, this process
#: compiles the entry point itself (a helper that slow has something wrong with it).
WAIT_LIMIT = 120.0


def _entry_point(job: str):
    from .kernels import dispatch

    return getattr(dispatch, JOBS[job][0])


def is_cached(kernel) -> bool:
    """Whether Numba's on-disk cache holds machine code of ``kernel`` (a dispatcher with ``cache=True``)
    for its current source, for some signature. Reads Numba's cache index through a private attribute:
    if that is not there (another Numba), the answer is True, so that nothing is started."""
    try:
        return bool(kernel._cache._cache_file._load_index())
    except Exception:  # noqa: BLE001 -- any failure means "do not start a helper"
        return True


def compile_elsewhere(job: str = "dp5") -> subprocess.Popen | None:
    """Start a helper process compiling ``job``'s entry point into Numba's on-disk cache (see the
    module's docstring); None where none is started. Stop it with :func:`stop`."""
    from numba.core import config

    from .kernels import CACHE_ROOT

    if config.DISABLE_JIT or (os.cpu_count() or 1) < 2 or is_cached(_entry_point(job)):
        return None
    # The helper imports this very granchain: the directory this one is imported from goes first on its
    # path unless it is there, and the working directory (which may hold another checkout) stays off it
    # (-P, Python >= 3.11; before, the helper runs in that directory instead).
    root = str(Path(__file__).resolve().parents[2])
    code = f"import sys\nif {root!r} not in sys.path:\n    sys.path.insert(0, {root!r})\n{JOBS[job][1]}\n"
    safe_path = sys.version_info >= (3, 11)
    # The helper's kernels go where this process's are (it derives the same directory from that root).
    env = dict(os.environ, NUMBA_NUM_THREADS="1", NUMBA_CACHE_DIR=str(CACHE_ROOT))
    try:
        proc = subprocess.Popen([sys.executable, *(["-P"] if safe_path else []), "-c", code],
                                cwd=None if safe_path else root, env=env,
                                stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    except OSError:  # no process can be started here: this process compiles it when it needs it
        return None
    _RUNNING[job] = proc
    return proc


def wait_for(kernel) -> None:
    """Before this process compiles the entry point ``kernel``: if a helper is compiling it, wait for
    the helper (at most :data:`WAIT_LIMIT`) so that Numba then loads it from the cache. The helper's
    head start makes the wait shorter than a compilation here; on a busy machine this process could
    otherwise reach the entry point first and compile it a second time."""
    for job, proc in list(_RUNNING.items()):
        if _entry_point(job) is kernel and not kernel.signatures:
            try:
                proc.wait(timeout=WAIT_LIMIT)
            except subprocess.TimeoutExpired:
                pass  # compiled here, then


def stop(proc: subprocess.Popen | None) -> None:
    """Stop a helper of :func:`compile_elsewhere` that is still running (its work is only a cache)."""
    for job, running in list(_RUNNING.items()):
        if running is proc:
            del _RUNNING[job]
    if proc is None or proc.poll() is not None:
        return
    proc.terminate()
    try:
        proc.wait(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
