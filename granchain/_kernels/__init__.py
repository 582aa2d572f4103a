"""Numba-compiled kernels: pure functions over arrays and scalars.

The Python layer (``granchain._simulate``, ``granchain._ensemble``) validates,
allocates and calls these. Every kernel runs unchanged under
``NUMBA_DISABLE_JIT=1`` (slowly), which the test-suite checks.

Numba's on-disk cache (``cache=True``) checks only the source file of the
function it compiles, but the kernels inline each other across files (the
ensemble kernel inlines the DP5 kernel, which inlines the force routines). So
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
    for src in sorted(here.glob("*.py")) + [here.parent / "_status.py"]:
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
