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
- ``rkloop``: the adaptive Runge-Kutta step loop; ``dp5`` and ``rkn4``: the tableaux it runs;
- ``verlet``: velocity Verlet;
- ``dispatch``: the single-chain entry points; ``batch``: the parallel ensemble driver, which calls them
  through their addresses;
  ``aligned``: the aligned pulse's sums;
- ``memory``: borrowed views; ``jit``: the compilation flags.

Numba's on-disk cache (``cache=True``) checks only the source file of the
function it compiles, but the kernels inline each other across files (the
step loop inlines the stages, which inline the force routines). So
the cache is keyed here on all kernel sources together: when any of them (or
Numba's version) changes, the cached machine code of every kernel is dropped.
"""

from __future__ import annotations

import hashlib
from pathlib import Path


def _drop_stale_cache() -> None:
    import numba

    here = Path(__file__).parent
    digest = hashlib.sha256(numba.__version__.encode())
    # Every kernel source, and the pure-Python module whose constants the kernels freeze in.
    for src in sorted(here.glob("*.py")) + [here.parent.parent / "_status.py"]:
        digest.update(src.name.encode() + src.read_bytes())
    key = digest.hexdigest()
    cache = here / "__pycache__"
    stamp = cache / "granchain-kernels.sha256"
    try:
        if stamp.exists() and stamp.read_text() == key:
            return
        for f in list(cache.glob("*.nbi")) + list(cache.glob("*.nbc")):
            f.unlink(missing_ok=True)
        cache.mkdir(exist_ok=True)
        stamp.write_text(key)
    except OSError:  # a read-only installation: Numba then caches elsewhere (or not at all)
        pass


_drop_stale_cache()
