"""``--backend`` and ``--switch-backend``: what computes the ensembles of ``ensemble``, ``reproduce``,
``design`` and ``validity`` (``run_ensemble(backend=..., switch_backend=...)``), and the one chain of
``pulse`` (``simulate(backend=...)``; no store, so no ``--switch-backend``)."""

from __future__ import annotations

#: The choices on the command line: the CPU default and the GPU.
CHOICES = ("cpu", "cuda")


def add_backend_arguments(p, switch: bool = True) -> None:
    """Add ``--backend`` (and ``--switch-backend``) to the sub-command's parser ``p``."""
    g = p.add_argument_group("backend")
    g.add_argument("--backend", choices=CHOICES, default="cpu",
                   help="what integrates the chains: cpu (default; Numba threads on this machine's cores) or cuda "
                        "(an NVIDIA GPU, pip install granchain[cuda]; thousands of chains per launch). The two agree "
                        "per realisation within the accuracy contract, not bitwise, so a store (or a design run) "
                        "records its backend and is continued on it")
    if switch:
        g.add_argument("--switch-backend", action="store_true",
                       help="continue or extend a store computed on another backend than --backend (its record then lists "
                            "every backend used); without it such a run is refused")


def backend_of(args):
    """The ``backend=`` value of the parsed arguments: None for the CPU default, else the name."""
    return None if args.backend == "cpu" else args.backend


def check_usable(args) -> None:
    """Get the backend the arguments name, before anything is computed or written: where it cannot run
    (``BackendUnavailable``) the command ends with its one-line reason (``granchain.cli.main``)."""
    from ..ensembles import backend

    backend.resolve(backend.checked(backend_of(args)))


def is_unavailable(exc: BaseException) -> bool:
    """True when ``exc`` says a backend cannot run here (``granchain.backends.BackendUnavailable``: no
    numba-cuda, no GPU): a one-line error and exit status 2 for the command line, not a traceback."""
    try:
        from ..backends import BackendUnavailable
    except ImportError:  # a version of the backends without it: recognised by its name
        return any(cls.__name__ == "BackendUnavailable" for cls in type(exc).__mro__)
    return isinstance(exc, BackendUnavailable)
