"""The compiled entry points for a single chain, one per method and model class, and the choice
among them.

``simulate`` and the ensemble kernel (``batch``) both call the entry point :func:`chain_kernel`
picks, so a realisation of an ensemble is integrated by exactly the code (and to the bit) that
``simulate`` uses. Each entry point is its own compiled function and Numba compiles a function on
its first call: a run compiles the one kernel it uses (a first ``granchain pulse`` compiles DP5 for
the paper's chain, not RKN4, Verlet or the real-contact loops). The Runge-Kutta entry points are
made by ``rkloop.rk_kernel``, with the method's scheme (``schemes``) and the model class constants of
their code, one per scheme of ``schemes.SCHEMES`` and model class, made when first asked for. The
ensemble kernel calls an entry point through its address (:func:`kernel_function`), so that one
ensemble kernel serves every entry point and the entry point's machine code is the very code
``simulate`` runs, compiled once. A new Runge-Kutta method is a new scheme (``schemes``): nothing here
changes.

The common contract of every single-chain kernel ``kernel(method, model, run, state, out)``:
integrate ``model`` from ``state`` at t = 0 with ``method`` (``records.Method``), record the observed
granules' peaks, their velocities on the grid, every contact's peak force, the wall force on the grid
when the chain ends in a wall, fill ``info`` (``records.INFO_*``) and return a status code
(``granchain._status``).
"""

from __future__ import annotations

from numba import njit, typeof
from numba.core.types import WrapperAddressProtocol

from .jit import JIT
from .records import KIND_VERLET
from .rkloop import rk_kernel
from .schemes import DP5, RKN4, SCHEMES
from .verlet import verlet_integrate

#: The Runge-Kutta entry points made so far, by (kind, general): see :func:`rk_chain`.
_RK_CHAINS = {}


def rk_chain(kind: int, general: bool):
    """The Runge-Kutta entry point of the scheme ``kind`` (``schemes.SCHEMES``) for the model class
    ``general`` (real contacts), made on first use and kept (Numba compiles it on its first call)."""
    key = (kind, bool(general))
    if key not in _RK_CHAINS:
        _RK_CHAINS[key] = rk_kernel(SCHEMES[kind], key[1])
    return _RK_CHAINS[key]


#: DP5 on the paper's chain (elastic, unloaded: ``forces.accelerations`` with ``general`` False).
dp5_chain = rk_chain(DP5.kind, False)
#: DP5 with real contacts (a static load, damping, yielding contacts).
dp5_chain_general = rk_chain(DP5.kind, True)
#: RKN4(3) on the paper's chain.
rkn4_chain = rk_chain(RKN4.kind, False)
#: RKN4(3) with a static load (RKN4 refuses damping: its forces may not read velocities).
rkn4_chain_general = rk_chain(RKN4.kind, True)


@njit(**JIT)
def verlet_chain(method, model, run, state, out):
    """Velocity Verlet on the paper's chain, params = [dt]."""
    return verlet_integrate(False, method.params[0], model, run, state, out)


@njit(**JIT)
def verlet_chain_general(method, model, run, state, out):
    """Velocity Verlet with a static load (Verlet refuses damping: its forces may not read velocities)."""
    return verlet_integrate(True, method.params[0], model, run, state, out)


def is_general(params) -> bool:
    """Whether a model (``records.Params``) needs the real-contact kernels: damping, a static load or yielding
    contacts."""
    return params.gamma > 0.0 or params.static_force > 0.0 or params.yield_overlap > 0.0


def chain_kernel(kind: int, params):
    """The entry point for a method ``kind`` (``records.KIND_*``) and a model's ``params``."""
    general = is_general(params)
    if kind == KIND_VERLET:
        return verlet_chain_general if general else verlet_chain
    if kind in SCHEMES:
        return rk_chain(kind, general)
    raise ValueError(f"no compiled kernel of kind {kind!r}")


def integrate_chain(method, model, run, state, out):
    """Integrate one chain with the kernel of ``method`` and ``model`` (see the module's contract), called
    directly through its CPython wrapper: calling it through its address from Python (a compiled caller
    taking a first-class function) cost ~0.27 ms per call in Numba's dispatch, 5-10 % of a decorated
    N = 26 ``simulate``, for ~2 s less compilation of a first ensemble."""
    return chain_kernel(method.kind, model.params)(method, model, run, state, out)


class _KernelFunction(WrapperAddressProtocol):
    """An entry point compiled for one signature, as a first-class function (Numba's wrapper address
    protocol): a compiled function that takes it calls the entry point's machine code through its
    address, without linking the entry point's code into its own."""

    def __init__(self, kernel, signature):
        self.kernel = kernel
        self.sig = signature

    def __wrapper_address__(self) -> int:
        from numba.experimental.function_type import _get_wrapper_address

        return _get_wrapper_address(self.kernel, self.sig)

    def signature(self):
        return self.sig


def kernel_function(kernel, *records):
    """The entry point ``kernel`` (:func:`chain_kernel`) as a first-class function for calls with
    arguments of the types of ``records`` (method, model, run, state, out), compiled now (or loaded
    from Numba's cache) for them. Under ``NUMBA_DISABLE_JIT`` the plain Python function."""
    if not hasattr(kernel, "py_func"):
        return kernel
    args = tuple(typeof(r) for r in records)
    kernel.compile(args)
    (sig,) = [s for s in kernel.nopython_signatures if s.args == args]
    return _KernelFunction(kernel, sig)
