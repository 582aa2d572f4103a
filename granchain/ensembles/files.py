"""The store's file-system steps: the check of a run's ``out`` path before anything is computed, JSON
documents read without trusting them, atomic writes (a file is absent or complete, never half written),
and short error texts for warnings.

Shared by the writer (:mod:`~granchain.ensembles.sinks`), the parameter record
(:mod:`~granchain.ensembles.params`) and the reader (:mod:`~granchain.ensembles.read`).
"""

from __future__ import annotations

import json
import os


def _read_json(path):
    """The JSON document in ``path``, or None if it is missing or unreadable."""
    try:
        with open(path, "rb") as f:
            return json.loads(f.read())
    except (OSError, ValueError):
        return None


def _short(exc) -> str:
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0] if text else ''}"[:160]


def _atomic_write(file: str, data: bytes) -> None:
    tmp = f"{file}.tmp-{os.getpid()}"
    with open(tmp, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, file)


def _check_out(path, create: bool = True) -> str:
    """The store path as a string, refusing what can never be a store (with what to change). ``create``:
    make its folder; without, only check that it can be made (a run's arguments, before anything is
    computed or written)."""
    try:
        text = os.fspath(path)
    except TypeError:
        raise ValueError(f"out must be a path (str or pathlib.Path), got {path!r}") from None
    if isinstance(text, bytes):
        text = os.fsdecode(text)
    if not text.strip():
        raise ValueError("out must be a non-empty path such as runs/N26.zarr (CLI: --out), got an empty string")
    parent = os.path.dirname(os.path.abspath(text)) or "."
    if os.path.lexists(text) and not os.path.isdir(text):
        raise ValueError(f"out = {text} is an existing file, not a Zarr store (a directory): choose another path")
    if not create:
        existing = parent
        while not os.path.exists(existing) and os.path.dirname(existing) != existing:
            existing = os.path.dirname(existing)
        if not os.path.isdir(existing):
            raise ValueError(f"out = {text}: cannot create its folder {parent} ({existing} is a file); choose a writable path")
        if not os.access(existing, os.W_OK | os.X_OK):
            raise ValueError(f"out = {text}: its folder {existing} is not writable; choose a writable path")
        return text
    try:
        os.makedirs(parent, exist_ok=True)
    except OSError as exc:
        raise ValueError(f"out = {text}: cannot create its folder {parent} ({exc.strerror}); choose a writable path") from None
    if not os.access(parent, os.W_OK | os.X_OK):
        raise ValueError(f"out = {text}: its folder {parent} is not writable; choose a writable path")
    return text
