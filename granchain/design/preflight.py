"""Checks a design run makes before it integrates anything: a request that no design can satisfy, a chain
too long to integrate in a run's time, an output directory that cannot be written.

Each check costs at most a few thousand chain builds (NumPy, no integration), so a request that can never
succeed is refused in well under a second, naming the option to change and the value that would work.
"""

from __future__ import annotations

import os

import numpy as np

__all__ = ["MAX_GRANULES", "check_feasible", "check_size", "output_directory"]

#: The longest chain (granules, the wall excluded) a design run integrates. Each evaluation integrates the
#: whole chain until the pulse has reached its end: the pulse needs a time proportional to the number of
#: granules M, and each step updates all of them, so one design costs ~M^2. Measured (one core, DP5): 20
#: granules ~25 ms a design, so 2000 granules ~4 min a design and ~4 h for the default budget of 60.
MAX_GRANULES = 2000

#: Designs drawn to look for a feasible one (with the corners and the centre of the bounds).
PROBES = 2048


def check_size(space) -> None:
    """Refuse a space whose chains are longer than :data:`MAX_GRANULES`, with the reason."""
    size = space.granules
    if size > MAX_GRANULES:
        raise ValueError(
            f"the chains of this space have {size} granules, more than a design run integrates ({MAX_GRANULES}): every "
            f"evaluation integrates the whole chain and costs ~size^2 (about 25 ms a design at 20 granules, so ~"
            f"{_hours(size)} for a budget of 60 at {size}); lower the size (CLI: --size) to at most {MAX_GRANULES}, or "
            "simulate one chain with `granchain pulse`")


def _hours(size: int) -> str:
    seconds = 60 * 0.025 * (size / 20.0) ** 2
    if seconds < 3600:
        return f"{seconds / 60:.0f} minutes"
    if seconds < 86400 * 365:
        return f"{seconds / 3600:.3g} hours"
    return f"{seconds / (86400 * 365):.3g} years"


def _probes(space) -> np.ndarray:
    """Designs spread over the bounds: the centre, corners (all of them up to 2^10), and seeded random
    draws (0/1 for a binary space)."""
    lo, hi = space.lower, space.upper
    D = space.dim
    rows = [0.5 * (lo + hi)]
    if D <= 10:
        corners = (np.arange(2**D)[:, None] >> np.arange(D)[None]) & 1
        rows.extend(lo + (hi - lo) * corners)
    else:
        rows.extend([lo, hi])
    n = PROBES if getattr(space, "kind", "") != "function" and not hasattr(space, "build_fn") else 64
    X = np.concatenate((np.array(rows), space.random_designs(n, seed=12345)))
    return np.round(X) if space.integer else X


def check_feasible(space) -> None:
    """Refuse a space none of whose designs meets its constraints (before any integration).

    The constraints are evaluated on designs spread over the bounds; if none is feasible, a bounded
    minimisation of the violation (cheap: chains are built, not integrated) looks for one. The error names
    each limit that no design meets alone, with the value the best design reaches."""
    cons = space.constraints
    if not cons.active and not hasattr(space, "min_width"):
        return
    X = _probes(space)
    v = space.violation(X)
    if np.any(v <= 0.0):
        return
    if not space.integer:
        from scipy.optimize import minimize

        x0 = X[int(np.argmin(v))]
        res = minimize(lambda x: float(space.violation(np.clip(x, space.lower, space.upper)[None])[0]), x0,
                       method="Powell", bounds=space.bounds, options={"maxfev": 400, "xtol": 1e-9, "ftol": 1e-12})
        if res.fun <= 0.0:
            return
        X = np.concatenate((X, np.clip(res.x, space.lower, space.upper)[None]))
    radii = space.radii(X)
    if radii.shape[0] != X.shape[0]:  # a random space: the realisations of each design, row by row
        radii = radii.reshape(X.shape[0], -1, radii.shape[1]).reshape(-1, radii.shape[1])
    masses = _masses(space, X, radii)
    reach = {"max_mass": ("the lightest design weighs", masses.sum(axis=1).min(), "--max-mass", "at least"),
             "max_length": ("the shortest design is", 2.0 * radii.sum(axis=1).min(), "--max-length", "at least"),
             "min_radius": ("the design with the largest smallest radius has", radii.min(axis=1).max(), "--min-radius",
                            "at most"),
             "max_radius": ("the design with the smallest largest radius has", radii.max(axis=1).min(), "--max-radius",
                            "at least")}
    parts = []
    for name, (what, best, flag, side) in reach.items():
        limit = getattr(cons, name)
        if limit is None:
            continue
        ok = best <= limit if name != "min_radius" else best >= limit
        if not ok:
            hint = " (granule 1, the struck one, has radius 1 in every design)" if name == "max_radius" and best >= 1.0 and not hasattr(space, "build_fn") else ""
            parts.append(f"{name} = {limit:g}: {what} {best:.6g}{hint}; give {name} (CLI: {flag}) {side} {best:.6g}")
    if hasattr(space, "min_width") and not parts:
        parts.append(f"alpha + min_width <= beta (min_width = {space.min_width:g}) together with the limits")
    if not parts:
        parts.append("each limit alone can be met, but no design meets all of them together; relax one of "
                     f"{sorted(cons.describe())}")
    raise ValueError("no design of this space meets the constraints, so nothing would be evaluated: "
                     + "; ".join(parts) + ". Or widen the space's bounds")


def _masses(space, X, radii) -> np.ndarray:
    if hasattr(space, "build_fn"):
        chains = space._chains(X)
        return np.stack([c.masses[:-1] if c.wall else c.masses for c in chains])
    if radii.shape[0] != X.shape[0]:
        from ..model.chain import sphere_mass

        return sphere_mass(radii)
    return space.masses_and_stiffness(X, radii)[0]


def output_directory(out, option: str = "out") -> str:
    """``out`` as a string if it can be a directory of results (``granchain._validate.output_directory``:
    not empty, not an existing file, inside a folder that exists or can be made and is writable), else an
    error naming ``option``; nothing is created."""
    from .._validate import output_directory as checked

    return os.fspath(checked(out, option, create=False))


