"""The one place that holds the Numba compilation flags (all kernels use ``numba.njit``,
so nopython mode is implied: a kernel that cannot compile fully is a bug, not a slow path)."""

JIT = dict(
    # Keep compiled machine code on disk so a second process (a Dask worker,
    # the next run) skips the ~seconds of LLVM compilation: in the per-user
    # cache directory the package's __init__ points Numba at, never in the
    # installed package.
    cache=True,
    # No fastmath: results must be bitwise identical whatever the thread count,
    # chunking or worker (reassociation would make them depend on inlining).
    fastmath=False,
    # NumPy semantics for float errors (inf/nan instead of exceptions); the
    # kernels check finiteness themselves and report it as a status.
    error_model="numpy",
    boundscheck=False,
)

#: Same flags, inlined into the caller at Numba-IR level: for the helpers called every step of an
#: integrator's loop (a call passes each array as seven scalars, plus a reference-count increment and
#: decrement for an owning array, see ``memory.borrowed``), and for helpers whose arguments are
#: constants where they are called (Numba prunes the branches those decide in the inlined copy). Each
#: inlined copy costs the first run Numba's front end again (IR-inlining the root search's helpers
#: cost more compilation than it saved); LLVM also inlines small compiled functions, whose code Numba
#: links into their callers'.
JIT_INLINE = dict(JIT, inline="always")

#: Same flags, for the helpers that only compiled code calls: without the CPython and C wrappers Numba
#: generates for every compiled function so that Python (or a function pointer) can call it. For a
#: helper taking records of arrays the CPython wrapper's unboxing is more code than the helper, and
#: Numba lowers it and LLVM optimises and compiles it on the first run like any other code.
JIT_INTERNAL = dict(JIT, no_cpython_wrapper=True, no_cfunc_wrapper=True)

#: Same flags plus threading, for the ensemble loop (``numba.prange``): that loop alone. With
#: ``parallel=True`` Numba also turns array expressions and allocations (the ``np.zeros`` of each
#: realisation's arrays, inside the loop) into parallel loops of their own, which it then runs serially
#: there: ~0.6 s more compilation of the ensemble kernel and nothing at run time.
#: ``nogil``: the calling thread releases the GIL while the loop runs, so that the ensemble's helper thread
#: draws the next chunk and writes the last one meanwhile (``ensembles.run._run_local``).
JIT_PARALLEL = dict(JIT, nogil=True, parallel=dict(prange=True, comprehension=False, setitem=False, reduction=False,
                                                   numpy=False, stencil=False, fusion=False, inplace_binop=False))


def named(tag: str):
    """Decorator for a function that a factory compiles once per value of its closure's variables:
    gives each such function a name of its own (``__qualname__`` + "_" + ``tag``) before Numba sees it.

    Numba names a compiled function's machine-code symbols after its qualified name and a counter of
    the process that compiled it, and keeps its cache files under the qualified name. Two closures of
    one factory share the qualified name, and when both are loaded from the cache, compiled by two
    processes, their counters can be equal too: the same symbol twice. The address of an entry point
    is looked up by that name (``dispatch.kernel_function``: the ensemble kernel ran the RKN4 entry
    point's code for a DP5 ensemble, or the other way round, after both had been loaded from the
    cache), and a kernel that links two such helpers (the root searches) keeps one of them. With a name
    per closure the symbols differ and each closure also gets cache files of its own."""

    def rename(func):
        func.__qualname__ = f"{func.__qualname__}_{tag}"
        func.__name__ = f"{func.__name__}_{tag}"
        return func

    return rename
