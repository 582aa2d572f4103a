"""Which backend computes an ensemble's chunks, and how a store records it.

``backend=None`` or ``"cpu"`` (the default) runs each chain kind on its integrator's own backend
(``Integrator.integrate_batch``: the Numba kernels, SciPy for DOP853), as every store written before this
choice existed. A backend's name (``"cuda"``, ``"numba"``) or a :class:`granchain.backends.Backend`
instance runs every chunk through that backend's ``integrate_batch`` instead, with the same arguments.

Two backends agree per realisation within the accuracy contract, not bitwise (a GPU sums and rounds in
another order), so a store records the backend that computed it: its parameter record holds
``"backend": name`` only when that is not the CPU default (every earlier record stays as it was and
resumes), and a store is continued on the backend it was computed with. ``switch_backend=True`` accepts
another one; the record then keeps ``"backend"`` (the first backend, part of the store's identity) and
adds ``"backends_used"``, every backend that computed chunks, in the order they were first used (the
run's history: not compared on resume and not part of the checksums' key).
"""

from __future__ import annotations

__all__ = ["CPU", "choices", "checked", "name_of", "resolve", "runs_on_cpu", "default_chunk_size", "stored_backends",
           "check_same_backend", "other_backend"]

#: The default: each integrator on its own backend.
CPU = "cpu"
#: Realisations per chunk on the CPU (the unit of saving and resuming; a chunk a few seconds long on a laptop).
CPU_CHUNK_SIZE = 500
#: The backends that run on this machine's cores with Numba's threads (``threads=`` applies to them,
#: and a chunk may be split into batches to show progress).
CPU_BACKENDS = ("numba", "scipy")


def choices() -> tuple:
    """The backend names ``run_ensemble(backend=...)`` accepts: "cpu" and every registered backend
    (``granchain.backends.BACKENDS``), "cuda" included."""
    from ..backends import BACKENDS

    return tuple(dict.fromkeys((CPU, *BACKENDS, "cuda")))


def checked(backend):
    """None for the CPU default (None or "cpu"), a known backend name, or a ``Backend`` instance; anything
    else is refused naming the choices."""
    from ..backends import Backend

    if backend is None or (isinstance(backend, str) and backend == CPU):
        return None
    if isinstance(backend, Backend):
        return backend
    if isinstance(backend, str) and backend in choices():
        return backend
    raise ValueError(f"backend must be one of {list(choices())} or a granchain.backends.Backend instance, got {backend!r}: "
                     f"'cpu' (the default) runs each integrator on its own backend (Numba kernels, SciPy for DOP853); "
                     f"'cuda' runs the chunks on an NVIDIA GPU (pip install granchain[cuda]); CLI: --backend cpu|cuda")


def name_of(backend) -> str:
    """The name a record gives ``backend`` (a value of :func:`checked`)."""
    if backend is None:
        return CPU
    if isinstance(backend, str):
        return backend
    return backend.name or type(backend).__name__


def resolve(backend):
    """The ``Backend`` object that runs the chunks (None: each integrator's own). Getting "cuda" raises
    ``granchain.backends.BackendUnavailable`` where numba-cuda or a GPU is missing."""
    if backend is None or not isinstance(backend, str):
        return backend
    from ..backends import get_backend

    return get_backend(backend)


def runs_on_cpu(backend) -> bool:
    """True for the CPU default and the CPU backends: their chunks run on Numba's threads."""
    return backend is None or name_of(backend) in CPU_BACKENDS


def default_methods(backend) -> tuple | None:
    """The methods (``Integrator.name``) a caller's default integrator may be on ``backend`` (a resolved
    ``Backend`` or None): its ``default_methods`` where it declares them (the GPU: the one measured on it),
    else the ``methods`` it has kernels for; None: any (the CPU backends)."""
    if backend is None:
        return None
    return getattr(backend, "default_methods", None) or getattr(backend, "methods", None)


def default_chunk_size(backend) -> int:
    """Realisations per chunk the backend asks for (``Backend.default_chunk_size``: the GPU's is 30,000, the
    paper's ensemble in one launch, because a launch needs thousands of chains to fill the GPU and lasts until its
    slowest chain ends), :data:`CPU_CHUNK_SIZE` for the CPU."""
    if backend is None:
        return CPU_CHUNK_SIZE
    return int(getattr(resolve(backend), "default_chunk_size", CPU_CHUNK_SIZE))


def stored_backends(record: dict) -> list:
    """The backends a parameter record says computed the store, in the order they were first used
    (``["cpu"]`` for a record that names none: every store written before the choice existed)."""
    used = record.get("backends_used")
    if isinstance(used, list) and used and all(isinstance(u, str) for u in used):
        return list(used)
    backend = record.get("backend", CPU)
    return [backend if isinstance(backend, str) else CPU]


def check_same_backend(path, record: dict, backend: str, switch: bool) -> tuple | None:
    """The ``backends_used`` of a run continuing the store ``path`` (parameter record ``record``) on
    ``backend``: None while one backend computed it all, else every backend in the order first used.
    A backend the store was not computed with is refused unless ``switch``."""
    used = stored_backends(record)
    if backend not in used:
        if not switch:
            raise other_backend(path, used, backend)
        used = [*used, backend]
    return tuple(used) if len(used) > 1 else None


def other_backend(path, used: list, asked: str) -> ValueError:
    """The refusal of a run on the backend ``asked`` continuing a store that the backends ``used`` computed."""
    return ValueError(
        f"{path} was computed with the {' and '.join(repr(u) for u in used)} backend{'s' if len(used) > 1 else ''} and "
        f"this run asks for {asked!r}: two backends agree per realisation within the accuracy contract, not bitwise, so "
        f"a store is continued on the backend that computed it. Continue it with backend={used[-1]!r} (CLI: --backend "
        f"{used[-1]}), or accept the mix with switch_backend=True (CLI: --switch-backend), which records every backend used")
