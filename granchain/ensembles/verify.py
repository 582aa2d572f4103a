"""Verifying a store against what its writer recorded: the one check that every reader
(:func:`granchain.open_store`, and through it ``granchain export``, the analysis and the figures),
``granchain info`` and a resuming writer share.

What the writer records, and what is checked:

* every finished chunk (``progress/done``): a BLAKE2b-64 checksum per variable of its stored values
  (``progress/checksum``), keyed by the store's identity (its parameter record without
  ``realizations``, so that extending a store keeps it) and labelled with the variable and the chunk
  index (``checksum_scheme`` 2). A flipped bit, a missing or truncated data file, and a chunk copied from
  another store (another seed, another family) or from another chunk of the same store all fail;
* the averaged variables (``mean_velocity``, its standard error, ``n_valid``, the aligned pulse and the
  windows), once every chunk is done: their checksums, keyed the same way and bound to the number of
  realisations, in ``progress/.zattrs`` (``granchain_averaged_digests``);
* the root attributes (the parameter record and everything derived from it: seed, family, integrator,
  ...): a digest of them in ``progress/.zattrs`` (``granchain_attributes_digest``; where and when the
  store was written, ``created`` and ``history``, and attributes added later, such as the physical scale
  ``physical_*``, are not covered), and the progress group's copy of the record equal to the root's.

Stores written before ``checksum_scheme`` 2 hold checksums of the values alone (granchain 0.2 to 0.5.0.dev):
they are verified as far as those go (a flipped bit or a lost file is found, a copied chunk is not), and
a resume re-keys them. A store of granchain 0.1.0 holds no checksums: nothing can be verified.

Values are hashed as they are read: :meth:`StoreCheck.read_variable` reads a variable once and checks
every chunk of it, :meth:`StoreCheck.read_chunk` one chunk (the lazy reader calls it for each chunk Dask
asks for), so verifying costs the hashing, not a second read.
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass, field

import numpy as np

from .schema import digest

__all__ = ["SCHEME", "StoreCheck", "StoreDamagedError", "StoreVerificationWarning", "Verification", "store_identity",
           "attributes_digest", "verify_store", "what_to_do"]

#: The checksum scheme this version writes (``checksum_scheme`` of ``progress/checksum``).
SCHEME = 2
#: Root attributes not covered by the attributes digest: where and when the store was written (a resume
#: keeps ``created`` and extends ``history``).
VOLATILE = ("created", "history")
ATTRIBUTES_DIGEST = "granchain_attributes_digest"
AVERAGED_DIGESTS = "granchain_averaged_digests"


class StoreDamagedError(ValueError):
    """A store's values or records do not match what its writer recorded (the message names the file)."""


class StoreVerificationWarning(UserWarning):
    """A store was read without verifying it (``verify=False``), or verified only partly."""


def what_to_do(path) -> str:
    return (f"run the ensemble command again with the same arguments (`granchain ensemble ... --out {path}`, or "
            f"granchain.run_ensemble(..., out={str(path)!r})): it recomputes damaged chunks and restores the records; "
            "or read it anyway with open_store(..., verify=False) (CLI: granchain export --no-verify)")


def _canonical(record) -> bytes:
    return json.dumps(record, sort_keys=True, separators=(",", ":")).encode()


def store_identity(record_text: str) -> bytes:
    """The key of a store's checksums: BLAKE2b-256 of its parameter record (JSON text as stored) without
    ``realizations`` and ``backends_used``, so that a store keeps its identity when it is extended or
    continued on another backend (``run_ensemble(switch_backend=True)``)."""
    record = json.loads(record_text)
    if isinstance(record, dict):
        record = {k: v for k, v in record.items() if k not in ("realizations", "backends_used")}
    return hashlib.blake2b(_canonical(record), digest_size=32).digest()


def attributes_digest(attrs: dict) -> dict:
    """The digest of a store's root attributes (as read back from its ``.zattrs``), less ``VOLATILE``:
    ``{"keys": [...], "blake2b": hex}``; the keys say which attributes it covers."""
    keys = sorted(k for k in attrs if k not in VOLATILE)
    return {"keys": keys, "blake2b": hashlib.blake2b(_canonical({k: attrs[k] for k in keys}), digest_size=16).hexdigest()}


def chunk_label(name: str, j: int) -> str:
    return f"{name}\0chunk {j}"


def averaged_label(name: str, realizations: int) -> str:
    return f"{name}\0averaged over {realizations}"


def _read_json(file):
    try:
        with open(file, "rb") as f:
            doc = json.loads(f.read())
        return doc if isinstance(doc, dict) else None
    except (OSError, ValueError):
        return None


def _undecodable(exc) -> str:
    """Why a data file cannot be read, in words (a codec's own message names neither the file nor the fix)."""
    if isinstance(exc, OSError) and exc.strerror:
        return exc.strerror
    return "truncated or garbled: it cannot be decompressed"


def _short(exc) -> str:
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0] if text else ''}"[:160]


@dataclass
class Verification:
    """What :func:`verify_store` found: ``damaged`` {chunk: why}, ``problems`` (records, averaged pulse,
    files outside the chunks), ``scheme`` (2; 1: checksums of the values alone; 0: none), ``complete``."""

    path: str
    scheme: int
    complete: bool
    damaged: dict = field(default_factory=dict)
    problems: list = field(default_factory=list)
    #: the done flags as the check read them (an unreadable flag: 0)
    done: np.ndarray | None = None

    @property
    def ok(self) -> bool:
        return not self.damaged and not self.problems

    def lines(self) -> list[str]:
        return list(self.problems) + [f"chunk {j} {why}" for j, why in sorted(self.damaged.items())]

    def error(self) -> StoreDamagedError:
        found = self.lines()
        more = f" (and {len(found) - 3} more)" if len(found) > 3 else ""
        return StoreDamagedError(f"{self.path} does not match what its writer recorded: {'; '.join(found[:3])}{more}; "
                                 f"its values cannot be trusted. To repair it, {what_to_do(self.path)}")


class StoreCheck:
    """The records of one store, read once (metadata, done flags, checksums: small), and the checks of its
    values against them. ``accept_unbound``: also accept checksums of the values alone (a writer upgrading
    a store of an earlier version); :attr:`unbound` then lists the chunks that matched only those."""

    def __init__(self, path, accept_unbound: bool = False):
        import zarr

        self.path = os.fspath(path)
        self.group = zarr.open_group(self.path, mode="r", zarr_format=2, use_consolidated=False)
        self.problems: list[str] = []
        self.unbound: set = set()
        root = _read_json(os.path.join(self.path, ".zattrs")) or {}
        progress = _read_json(os.path.join(self.path, "progress", ".zattrs")) or {}
        self.root_attrs, self.progress_attrs = root, progress
        # the progress group's copy first: the record the chunks were written with (an edited root record is
        # then reported as such, not as every chunk failing its checksums)
        text = progress.get("granchain_parameters") or root.get("granchain_parameters")
        record = json.loads(text) if isinstance(text, str) else {}
        self.realizations, self.chunk_size = int(record["realizations"]), int(record["chunk_size"])
        self.n_chunks = -(-self.realizations // self.chunk_size)
        checksum_attrs = _read_json(os.path.join(self.path, "progress", "checksum", ".zattrs")) or {}
        try:
            self.names = [str(x) for x in self.group["progress/checked"][...]]
        except KeyError:  # granchain 0.1.0 stored no checksums
            self.names = []
        self.scheme = 0 if not self.names else int(checksum_attrs.get("checksum_scheme", 1))
        self.identity = store_identity(text) if self.scheme >= SCHEME else None
        self.accept_unbound = accept_unbound or self.scheme == 1
        self.done = self._done()
        self.sums = None
        if self.scheme:
            try:
                self.sums = np.asarray(self.group["progress/checksum"][...])
            except Exception as exc:  # noqa: BLE001 -- every done chunk is then unverifiable
                self.problems.append(f"has an unreadable checksum record progress/checksum ({_short(exc)})")
        self._files: dict = {}
        self._layouts: dict = {}
        if self.scheme >= SCHEME:
            self._check_records(record)

    # -- records ------------------------------------------------------------------------------------
    def _done(self) -> np.ndarray:
        done = np.zeros(self.n_chunks, dtype=np.int8)
        try:
            flags = np.asarray(self.group["progress/done"][...])
            done[:min(flags.size, self.n_chunks)] = flags[:self.n_chunks]
        except Exception:  # noqa: BLE001 -- flag by flag: an unreadable one counts as not done (the writer redoes it)
            for j in range(self.n_chunks):
                try:
                    done[j] = self.group["progress/done"][j]
                except Exception:  # noqa: BLE001
                    pass
        return done

    @property
    def complete(self) -> bool:
        return bool((self.done == 1).all())

    def _check_records(self, record: dict) -> None:
        sealed = self.progress_attrs.get(ATTRIBUTES_DIGEST)
        root_text, copy = self.root_attrs.get("granchain_parameters"), self.progress_attrs.get("granchain_parameters")
        if not isinstance(root_text, str):
            self.problems.append("has lost its root attributes (.zattrs), which hold its parameter record")
            return
        if not isinstance(sealed, dict) or not isinstance(copy, str):
            self.problems.append("has lost the digest of its attributes (progress/.zattrs), so its parameter record "
                                 "cannot be verified")
            return
        if root_text != copy:
            from .params import _flatten

            try:
                a, b = _flatten(json.loads(root_text)), _flatten(json.loads(copy))
                diff = ", ".join(f"{k}: {a.get(k)!r} in .zattrs, {b.get(k)!r} in progress/.zattrs"
                                 for k in sorted(set(a) | set(b)) if a.get(k) != b.get(k))
            except (TypeError, ValueError):
                diff = "unreadable"
            self.problems.append(f"has a parameter record (.zattrs: granchain_parameters) that differs from the one its "
                                 f"chunks were written with ({diff})")
            return
        have = {k: self.root_attrs[k] for k in sealed.get("keys", []) if k in self.root_attrs}
        missing = [k for k in sealed.get("keys", []) if k not in self.root_attrs]
        if missing or attributes_digest(have)["blake2b"] != sealed.get("blake2b"):
            edited = missing or self._edited_attributes(record)
            self.problems.append("has root attributes (.zattrs) that do not match the digest recorded when it was written "
                                 f"(progress/.zattrs: {ATTRIBUTES_DIGEST}): "
                                 + (f"{', '.join(edited)} missing or edited" if edited else "an attribute was edited"))

    def _edited_attributes(self, record: dict) -> list[str]:
        """The root attributes that differ from those the parameter record gives (for the message)."""
        flat = {"seed": record.get("seed"), "realizations": record.get("realizations"),
                "chunk_size": record.get("chunk_size")}
        return [k for k, v in flat.items() if k in self.root_attrs and self.root_attrs[k] != v]

    # -- values -------------------------------------------------------------------------------------
    def _layout(self, name: str):
        """(Zarr array, dims, the axis chunks run along, realisations or chunks per chunk), opened once."""
        if name not in self._layouts:
            self._layouts[name] = self._open_layout(name)
        return self._layouts[name]

    def _open_layout(self, name: str):
        arr = self.group[name]
        dims = list(arr.metadata.attributes["_ARRAY_DIMENSIONS"])
        if name.startswith("progress/"):
            return arr, dims, dims.index("chunk"), 1
        return arr, dims, dims.index("realization"), self.chunk_size

    def _file(self, name: str, dims, axis: int, j: int) -> str:
        return f"{name}/" + ".".join(str(j) if i == axis else "0" for i in range(len(dims)))

    def _missing(self, name: str, key: str) -> bool:
        if name not in self._files:
            try:
                self._files[name] = set(os.listdir(os.path.join(self.path, *name.split("/"))))
            except OSError:
                self._files[name] = set()
        return key.rsplit("/", 1)[1] not in self._files[name]

    def expected(self, name: str, j: int) -> int | None:
        if self.sums is None or name not in self.names or j >= self.sums.shape[0]:
            return None
        return int(self.sums[j, self.names.index(name)])

    def chunk_problem(self, name: str, j: int, values, dtype, key: str) -> str | None:
        """Why chunk j of ``name`` (its stored ``values``) is not what the writer recorded, or None. The one
        comparison every reader, ``granchain info`` and a resuming writer make."""
        if not self.scheme or self.done[j] != 1 or name not in self.names:
            return None
        if self._missing(name, key):  # every chunk of a done chunk is written explicitly
            return f"has a missing data file {key}"
        want = self.expected(name, j)
        if want is None:
            return "has an unreadable checksum record progress/checksum"
        if self.identity is not None and digest(values, dtype, self.identity, chunk_label(name, j)) == want:
            return None
        if self.accept_unbound and digest(values, dtype) == want:
            if self.identity is not None:
                self.unbound.add(j)
            return None
        return (f"does not match its checksum: the data file {key} (or the checksum record progress/checksum/{j}.0) has "
                "changed, or it was copied from another store or another chunk")

    def _region(self, arr, dims, axis, step, j):
        return tuple(slice(j * step, min((j + 1) * step, arr.shape[axis])) if i == axis else slice(None)
                     for i in range(len(dims)))

    def _refuse(self, j: int, why: str) -> StoreDamagedError:
        return StoreDamagedError(f"{self.path}: chunk {j} {why}; its values cannot be trusted. To repair it, "
                                 f"{what_to_do(self.path)}")

    def read_chunk(self, name: str, j: int) -> np.ndarray:
        """Chunk j of ``name`` as stored, verified; :class:`StoreDamagedError` naming the file otherwise."""
        arr, dims, axis, step = self._layout(name)
        key = self._file(name, dims, axis, j)
        try:
            values = arr[self._region(arr, dims, axis, step, j)]
        except Exception as exc:  # noqa: BLE001 -- a truncated or garbled file
            raise self._refuse(j, f"has an unreadable data file {key} ({_undecodable(exc)})") from None
        why = self.chunk_problem(name, j, values, arr.dtype, key)
        if why:
            raise self._refuse(j, why)
        return values

    def read_variables(self, names, damaged: dict | None = None) -> dict:
        """{name: every value} of ``names``, read together (Zarr's reads of all of them overlap) and each
        verified chunk by chunk as :meth:`read_variable` does."""
        import asyncio

        from zarr.core.sync import sync

        arrays = [self._layout(name)[0] for name in names]

        async def together():
            return await asyncio.gather(*(a.async_array.getitem(...) for a in arrays), return_exceptions=True)

        read = sync(together())
        return {name: self.read_variable(name, damaged, None if isinstance(values, BaseException) else np.asarray(values))
                for name, values in zip(names, read)}

    def read_variable(self, name: str, damaged: dict | None = None, values=None) -> np.ndarray | None:
        """Every value of ``name``, read once (unless given as ``values``) and verified chunk by chunk. With
        ``damaged`` (a dict), what is wrong is recorded there ({chunk: why}) instead of raised, and None
        returned if it cannot be read."""
        arr, dims, axis, step = self._layout(name)
        if values is None:
            try:
                values = arr[...]
            except Exception:  # noqa: BLE001 -- a file cannot be decoded: read chunk by chunk to name it
                values = None
        parts = []
        for j in range(-(-arr.shape[axis] // step)):
            key = self._file(name, dims, axis, j)
            if values is None:
                try:
                    part = arr[self._region(arr, dims, axis, step, j)]
                except Exception as exc:  # noqa: BLE001
                    why = f"has an unreadable data file {key} ({_undecodable(exc)})"
                    if damaged is None:
                        raise self._refuse(j, why) from None
                    damaged.setdefault(j, why)
                    parts = None
                    continue
                if parts is not None:
                    parts.append(part)
            else:
                part = values[self._region(arr, dims, axis, step, j)]
            why = self.chunk_problem(name, j, part, arr.dtype, key) if j < self.n_chunks else None
            if why:
                if damaged is None:
                    raise self._refuse(j, why)
                damaged.setdefault(j, why)
        if values is None and parts:
            values = np.concatenate(parts, axis=axis)
        return values

    def missing_files(self, names) -> dict:
        """{chunk: why} for done chunks whose data file of one of ``names`` is missing (a listing, no read)."""
        found = {}
        if not self.scheme:
            return found
        for name in names:
            if name not in self.names:
                continue
            try:
                _, dims, axis, _ = self._layout(name)
            except Exception:  # noqa: BLE001 -- unreadable metadata: reported by the reader that opens it
                continue
            for j in np.flatnonzero(self.done == 1):
                key = self._file(name, dims, axis, int(j))
                if self._missing(name, key):
                    found.setdefault(int(j), f"has a missing data file {key}")
        return found

    # -- the averaged variables ---------------------------------------------------------------------
    def averaged_problem(self, name: str, values, dtype) -> str | None:
        """Why the averaged variable ``name`` (its stored values) is not what the writer recorded, or None
        (also where nothing can be checked: an incomplete store, or one written before scheme 2)."""
        if self.scheme < SCHEME or not self.complete:
            return None
        sealed = self.progress_attrs.get(AVERAGED_DIGESTS)
        if not isinstance(sealed, dict) or name not in sealed:
            return (f"has no checksum of {name} (the run stopped while writing the averaged pulse, or "
                    "progress/.zattrs was edited)")
        if digest(values, dtype, self.identity, averaged_label(name, self.realizations)) != int(sealed[name]):
            files = sorted(os.listdir(os.path.join(self.path, name))) if os.path.isdir(os.path.join(self.path, name)) else []
            data = [f for f in files if not f.startswith(".")]
            return (f"has an averaged variable {name} that does not match its checksum (a data file in {name}/ "
                    f"changed or is missing; the data files there: {', '.join(data) or 'none'})")
        return None

    def averaged_names(self) -> list[str]:
        sealed = self.progress_attrs.get(AVERAGED_DIGESTS)
        return sorted(sealed) if isinstance(sealed, dict) else []

    def verification(self) -> Verification:
        return Verification(self.path, self.scheme, self.complete, {}, list(self.problems), self.done.copy())


def averaged_digests(identity: bytes, realizations: int, ds, names) -> dict:
    """{name: checksum} of the averaged variables ``names`` of ``ds`` as the writer stores them."""
    return {name: digest(ds[name].values, ds[name].dtype, identity, averaged_label(name, realizations)) for name in names}


def verify_store(path, group: str | None = "all") -> Verification:
    """Everything a store's writer recorded, checked against the store (read once, nothing written):
    ``group`` None: the results (per-realisation chunks, averaged variables, records); "progress": the
    per-chunk sums; "all": both (``granchain info``, a resuming writer)."""
    try:
        check = StoreCheck(path)
    except Exception as exc:  # noqa: BLE001 -- the records themselves are unreadable
        return Verification(os.fspath(path), 0, False, {}, [f"has unreadable checksum records ({_short(exc)})"])
    found = check.verification()
    if not check.scheme:
        return found
    names = [n for n in check.names if (group in (None, "all") and not n.startswith("progress/"))
             or (group in ("progress", "all") and n.startswith("progress/"))]
    for name in names:
        try:
            check.read_variable(name, found.damaged)
        except Exception as exc:  # noqa: BLE001 -- unreadable metadata of one variable: every done chunk of it
            for j in np.flatnonzero(check.done == 1):
                found.damaged.setdefault(int(j), f"has unreadable metadata for {name} ({_short(exc)})")
    if group in (None, "all"):
        for name in check.averaged_names() or _averaged_of(check):
            try:
                arr = check.group[name]
                why = check.averaged_problem(name, arr[...], arr.dtype)
            except Exception as exc:  # noqa: BLE001
                why = f"has an unreadable averaged variable {name} ({_undecodable(exc)})"
            if why:
                found.problems.append(why)
    return found


def _averaged_of(check: StoreCheck) -> list[str]:
    """The averaged variables a complete store of scheme 2 must have sealed (when its record of them is lost)."""
    if check.scheme < SCHEME or not check.complete:
        return []
    return [n for n in ("mean_velocity", "mean_velocity_stderr", "n_valid") if n in check.group]
