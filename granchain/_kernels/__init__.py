"""Numba-compiled kernels: pure functions over arrays and scalars.

The Python layer (``granchain._simulate``, ``granchain._ensemble``) validates,
allocates and calls these. Every kernel runs unchanged under
``NUMBA_DISABLE_JIT=1`` (slowly), which the test-suite checks.
"""
