"""``granchain info STORE``: what an ensemble store holds, whether it is intact, and how to go on."""

from __future__ import annotations

import json
import os
import warnings


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "info",
        help="describe an ensemble store: parameters, family, integrator, backend, progress, failures, size, how to resume",
        description="Read an ensemble store written by `granchain ensemble` (or run_ensemble(out=...)) without changing it: "
                    "its parameters, progress, integration failures, size on disk, the writer holding it (if any), "
                    "a check of every finished chunk against its checksums, and the command that continues it. "
                    "Exit status 1 when the store is damaged (the lines marked 'damaged' say where).",
    )
    p.add_argument("store", help="the Zarr store, e.g. runs/N26.zarr")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(func=run)


def _size(path: str) -> int:
    total = 0
    for root, _, files in os.walk(path):
        for name in files:
            try:
                total += os.path.getsize(os.path.join(root, name))
            except OSError:
                pass
    return total


def _human(n: int) -> str:
    for unit in ("B", "kB", "MB", "GB", "TB"):
        if n < 1000 or unit == "TB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1000.0
    return str(n)


def summary(path: str) -> dict:
    """The facts ``granchain info`` prints (a dict, also its ``--json`` output)."""
    import numpy as np

    from ..ensembles.lock import StoreLock
    from ..ensembles.read import open_store
    from ..ensembles.store import current_record, stored_parameters
    from ..ensembles.verify import StoreVerificationWarning, verify_store

    if not os.path.isdir(path):
        raise ValueError(f"{path} is not a directory: give the path of a Zarr store written by granchain ensemble")
    try:
        with warnings.catch_warnings():  # verified below, by the readers' own check, with every finding listed
            warnings.simplefilter("ignore", StoreVerificationWarning)
            ds, unreadable = open_store(path, verify=False), None  # the records in today's form (earlier versions too)
    except ValueError as exc:
        if stored_parameters(path) is None:
            raise  # not a store: open_store says what to give instead
        ds, unreadable = None, str(exc)  # damaged: what can be read is still reported, checksums included
    stored = stored_parameters(path)
    params = json.loads(ds.attrs["granchain_parameters"]) if ds is not None else current_record(json.loads(stored))
    R, cs = int(params["realizations"]), int(params["chunk_size"])
    n_chunks = -(-R // cs)
    found = verify_store(path, "all")  # what open_store checks, every finding listed
    done = found.done if found.done is not None else np.zeros(n_chunks, dtype=np.int8)  # unreadable records: none done
    damaged = {int(j): why for j, why in found.damaged.items()}
    checksums = found.scheme > 0
    try:
        status = np.asarray(ds["status"].values)
        chains = [str(c) for c in ds["chain"].values]
        codes, counts = np.unique(status, return_counts=True)
        failures = {chain: int(((status[i] != 0) & (status[i] != -1)).sum()) for i, chain in enumerate(chains)}
        status_counts = {int(c): int(n) for c, n in zip(codes, counts)}
    except Exception:  # noqa: BLE001 -- unreadable status chunks (reported as damaged chunks) or metadata
        failures, status_counts = None, None
    holder = StoreLock(path).holder()
    writing = None
    if isinstance(holder, dict) and not holder.get("released"):
        writing = holder
    done_r = sum(min((j + 1) * cs, R) - j * cs for j in np.flatnonzero(done == 1))
    written_by = (ds.attrs.get("granchain_version") if ds is not None else None) or json.loads(stored).get("granchain_version")
    return {"store": path, "family": params["family"], "integrator": params["integrator"],
            "chain_integrators": params.get("chain_integrators"), "realizations": R,
            "seed": params["seed"], "chains": params["chains"], "chunk_size": cs, "chunks_done": int((done == 1).sum()),
            "chunks": n_chunks, "realizations_done": int(done_r), "complete": bool((done == 1).all()),
            "damaged_chunks": damaged, "damaged": found.problems, "checksums": checksums,
            "checksum_scheme": found.scheme, "unreadable": unreadable, "failed_integrations": failures,
            "status_counts": status_counts, "size_bytes": _size(path), "lock": writing,
            # the writer's version is provenance (root attributes); records name it only before results_version
            "granchain_version": written_by, "results_version": params.get("results_version"),
            "pulse_window": params.get("pulse_window"),
            # what computed it: "cpu" for every record that names no backend (all stores before the choice existed)
            "backend": params.get("backend", "cpu"), "backends_used": params.get("backends_used")}


def _integrator_lines(integ: dict, per_chain: dict | None) -> list:
    """One line for the integrator, or one per chain kind when the kinds have their own."""
    def line(label, record):
        record = dict(record)
        return f"{label:<12} {record.pop('name', '?')}: " + ", ".join(f"{k}={v}" for k, v in sorted(record.items()))

    if not per_chain:
        return [line("integrator", integ)]
    return [line("integrator" if i == 0 else "", r) + f"  ({kind} chains)" for i, (kind, r) in enumerate(per_chain.items())]


def _pulse_window_line(window: dict | None) -> str:
    """Where the averaged pulse <v_k(t)> is recorded: in each granule's window (the windowed ensembles),
    or on the whole time grid."""
    if not window:
        return f"{'averaged':<12} <v_k(t)> on the whole time grid"
    if not window.get("ends"):
        return f"{'averaged':<12} <v_k(t)> in each granule's window, not set yet (the first run sets them)"
    parts = []
    for kind, ends in window["ends"].items():
        finite = [e for e in ends if e is not None]
        whole = len(ends) - len(finite)
        parts.append(f"{kind} chains until t = {min(finite):.4g} .. {max(finite):.4g} (granules 1..{len(finite)}), the "
                     f"whole grid for the last {whole}" if finite else f"{kind} chains: the whole grid")
    return (f"{'averaged':<12} <v_k(t)> in each granule's window, NaN after it (set from realisations "
            f"0..{window.get('pilot_realizations', 64) - 1}; --pulse-window full keeps the whole grid): " + "; ".join(parts))


def _backend_line(backend: str, used: list | None) -> str:
    """What computed the store: one backend, or (continued with --switch-backend) every one in order."""
    if used and len(used) > 1:
        return (f"{'backend':<12} {', then '.join(used)} (continued with --switch-backend: chunks of different backends "
                f"agree per realisation within the accuracy contract, not bitwise)")
    return f"{'backend':<12} {backend}" + ("" if backend == "cpu" else f" (continue it with --backend {backend})")


def _contacts_line(family: dict) -> str:
    """The family's contacts in words: the paper's, or the real contacts its record holds."""
    parts = []
    law = family.get("contact") or (family.get("contact_model")
                                    if family.get("contact_model", {}).get("law") not in (None, "power-law") else None)
    if law:
        from ..model.contacts import law_from_record

        parts.append(law_from_record(law).label(6, " = "))  # the law says what it is
    else:
        parts.append(f"elastic power law, n = {family.get('n', 2.5):g}")
    f0 = family.get("static_force") or family.get("contact_model", {}).get("static_force")
    parts.append(f"precompressed by F0 = {f0:.6g}" if f0 else "unloaded")
    m = family.get("striker_mass") or family.get("contact_model", {}).get("striker_mass")
    parts.append(f"struck by a striker of mass {m:.6g}" if m else "granule 1 struck")
    return f"{'contacts':<12} " + ", ".join(parts) + " (rescaled units)"


def run(args) -> int:
    from .._status import Status

    info = summary(args.store)
    # a script that checks a store before using it learns of damage from the exit status, as from export's
    damaged = bool(info["damaged_chunks"] or info["damaged"] or info["unreadable"])
    if args.json:
        print(json.dumps(info, indent=1, sort_keys=True))
        return int(damaged)
    fam = dict(info["family"])
    lines = [
        f"store        {info['store']} ({_human(info['size_bytes'])} on disk, granchain {info['granchain_version']})",
        f"family       {fam.pop('family', '?')}: " + ", ".join(f"{k}={json.dumps(v)}" for k, v in sorted(fam.items())),
        _contacts_line(info["family"]),
        *_integrator_lines(info["integrator"], info.get("chain_integrators")),
        f"run          {info['realizations']} realisations, seed {info['seed']}, chains {', '.join(info['chains'])}, "
        f"chunks of {info['chunk_size']}",
        _pulse_window_line(info.get("pulse_window")),
        _backend_line(info["backend"], info.get("backends_used")),
        f"progress     {info['chunks_done']}/{info['chunks']} chunks done ({info['realizations_done']} realisations)"
        + (": complete" if info["complete"] else ""),
    ]
    if info["status_counts"] is not None:
        names = {-1: "NOT_COMPUTED", **{int(s): s.name for s in Status}}
        lines.append("status       " + ", ".join(f"{names.get(c, c)}: {n}" for c, n in sorted(info["status_counts"].items())))
        lines.append("failures     " + ", ".join(f"{c}: {n}" for c, n in info["failed_integrations"].items()))
    if info["lock"]:
        h = info["lock"]
        lines.append(f"writer       PID {h.get('pid')} on {h.get('host')} since {h.get('since')} (if it has ended, "
                     "the next run takes the lock over)")
    if info["unreadable"]:
        lines.append(f"damaged      {info['unreadable']}")
    for reason in info["damaged"]:
        lines.append(f"damaged      {reason}")
    for j, reason in info["damaged_chunks"].items():
        lines.append(f"damaged      chunk {j} {reason}")
    if info["damaged_chunks"] or info["damaged"] or info["unreadable"] or not info["complete"]:
        lines.append("to continue  run the same `granchain ensemble ... --out STORE` command again (or run_ensemble with the "
                     "same arguments and out=STORE): damaged and missing chunks are recomputed; a larger --realizations "
                     "extends the store")
    elif not info["checksums"]:
        lines.append(f"unverified   written by granchain {info['granchain_version']}, before chunks were checksummed; "
                     "export with: granchain export STORE FILE.nc")
    elif info["checksum_scheme"] < 2:
        lines.append(f"intact       every chunk matches its checksums, which cover the values alone (written by granchain "
                     f"{info['granchain_version']}: a chunk copied from another store, the averaged pulse and the records "
                     "are not covered; resuming the store with the same arguments adds those checksums); export with: "
                     "granchain export STORE FILE.nc")
    else:
        lines.append("intact       every chunk, the averaged pulse and the parameter record match their checksums; "
                     "export with: granchain export STORE FILE.nc")
    print("\n".join(lines))
    return int(damaged)
