"""Input checks that fail with a message saying what to change.

Every public constructor funnels its arguments through these helpers so that a
bad value is reported once, by name, with the allowed range.
"""

from __future__ import annotations

import math
import os
import warnings
from pathlib import Path

import numpy as np

#: Largest small-to-large radius ratio for which the effective description of a
#: decorated chain is known to hold (paper Sec. III A and Sec. V: "no larger
#: than ~40 % of the larger granules").
EFFECTIVE_VALIDITY_LIMIT = 0.4


class EffectiveValidityWarning(UserWarning):
    """The effective (undecorated) description is used outside its validity."""


def real_number(value, what: str) -> float:
    """``value`` as a float, or a ValueError naming ``what`` (not a bool or a string: a flag or text
    where a number belongs is a mistake)."""
    if isinstance(value, (bool, str, bytes)):
        raise ValueError(f"{what} must be a number, got {value!r}")
    try:
        return float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be a number, got {value!r}") from None


def finite_scalar(name: str, value, *, positive: bool = False) -> float:
    """Return ``value`` as a float, refusing NaN/inf (and <= 0 if ``positive``)."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a real number, got {value!r}") from None
    if not math.isfinite(x):
        raise ValueError(f"{name} must be finite, got {value!r}")
    if positive and x <= 0.0:
        raise ValueError(f"{name} must be > 0, got {x!r}")
    return x


def exponent(n, *, minimum: float = 1.0, why: str = "the contact force must be continuous") -> float:
    """Check the contact exponent ``n`` of the potential (c/n) delta^n.

    ``minimum`` is exclusive: the dynamics need n > 1 (continuous force), the
    binary collision theory needs n > 2 (solitary pulse, Sec. III B).
    """
    x = finite_scalar("n", n)
    if x <= minimum:
        raise ValueError(
            f"n = {x!r} is not allowed here: need n > {minimum:g} ({why}); "
            "the Hertz exponent for spheres is n = 2.5"
        )
    return x


def positive_array(name: str, values, *, min_size: int = 1) -> np.ndarray:
    """A 1-d float array of finite, strictly positive entries."""
    try:
        a = np.array(values, dtype=float).reshape(-1) if np.ndim(values) <= 1 else None
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a sequence of real numbers, got {values!r}") from None
    if a is None:
        raise ValueError(f"{name} must be one-dimensional, got shape {np.shape(values)}")
    if a.size < min_size:
        raise ValueError(f"{name} needs at least {min_size} entries, got {a.size}")
    bad = ~np.isfinite(a)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(f"{name} must be finite: entry {i} is {float(a[i])!r}")
    bad = a <= 0.0
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(f"{name} must be > 0: entry {i} is {float(a[i])!r}")
    return a


def count(name: str, value, *, minimum: int) -> int:
    """An integer >= ``minimum``."""
    try:
        whole = not isinstance(value, (bool, str, bytes)) and float(value).is_integer()
    except (TypeError, ValueError, OverflowError):
        whole = False
    if not whole:
        raise ValueError(f"{name} must be a whole number, got {value!r}")
    k = int(value)
    if k < minimum:
        raise ValueError(f"{name} must be >= {minimum}, got {k}")
    return k


def warn_effective_validity(max_ratio: float, *, what: str, stacklevel: int = 3) -> None:
    """Warn when small radii exceed the effective description's validity (~0.4)."""
    if max_ratio > EFFECTIVE_VALIDITY_LIMIT:
        warnings.warn(
            f"{what} reaches a small-to-large radius ratio of {max_ratio:.3g} > "
            f"{EFFECTIVE_VALIDITY_LIMIT}: the effective (undecorated) description and the "
            "binary collision approximation built on it are outside their validity "
            "(paper Sec. III A); use the decorated chain's exact dynamics instead",
            EffectiveValidityWarning,
            stacklevel=stacklevel,
        )


def output_directory(out, name: str = "out", *, create: bool = True) -> Path:
    """``out`` as a writable directory (created if missing), checked before anything runs: a run that
    could not save its first result would otherwise fail after minutes of work. ``name`` is what the
    message calls it (``--out`` on the command line); ``create=False`` checks that it can be created
    and leaves nothing behind (for a check before the other arguments are)."""
    try:
        text = os.fspath(out)
    except TypeError:
        raise ValueError(f"{name} must be a directory path (str or pathlib.Path), got {out!r}") from None
    if isinstance(text, bytes):
        text = os.fsdecode(text)
    if not text.strip():
        raise ValueError(f"{name} must be a directory path such as results, got an empty string")
    path = Path(text)
    if path.exists() and not path.is_dir():
        raise ValueError(f"{name} = {path} is an existing file, not a directory: choose another path")
    missing, existing = [], path.absolute()
    while not existing.exists():  # the folders to create, innermost first
        missing.append(existing)
        existing = existing.parent
    if not existing.is_dir():
        raise ValueError(f"{name} = {path}: cannot create its folder ({existing} is a file); choose another path")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise ValueError(f"{name} = {path} cannot be written ({existing} is not a writable directory); "
                         "choose a writable directory")
    if missing:
        try:
            path.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise ValueError(f"{name} = {path}: cannot create it ({exc.strerror}); choose a writable directory") from None
        if not create:
            for folder in missing:
                folder.rmdir()
    return path
