"""``granchain export STORE FILE.nc``: an ensemble store as one CF-1.8 netCDF file.

Written by xarray's ``netcdf4`` engine, i.e. Unidata's netCDF-C library through the ``netCDF4``
package: the reference implementation that every netCDF reader (and the IOOS compliance checker,
which itself depends on netCDF4) understands. It is an optional dependency:
``pip install "granchain[netcdf]"``.
"""

from __future__ import annotations

import datetime as _dt
import os


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "export",
        help="write an ensemble store as a CF-1.8 netCDF file",
        description="Write the results of an ensemble store (parameters, per-realisation results, averaged pulse) "
                    "to one netCDF-4 file with CF-1.8 metadata (units UDUNITS understands, flag_values/flag_meanings "
                    "of status, history). Needs the netCDF4 package: pip install 'granchain[netcdf]'.",
    )
    p.add_argument("store", help="the Zarr store, e.g. runs/N26.zarr")
    p.add_argument("file", help="the netCDF file to write, e.g. N26.nc")
    p.add_argument("--force", action="store_true", help="overwrite FILE if it exists")
    p.add_argument("--no-verify", dest="verify", action="store_false",
                   help="export without checking the store against its checksums (a damaged store is refused "
                        "otherwise; `granchain info STORE` lists what is damaged), with a warning")
    p.set_defaults(func=run)


def cf_dataset(ds):
    """The store's Dataset (:func:`granchain.open_store`: its metadata already today's) with CF-1.8 metadata:
    every rescaled quantity is dimensionless (units "1", any other scale in ``comment``), text variables
    (``chain``) carry no units, flag variables (``status``) carry the schema's ``flag_values``/``flag_meanings``
    (-1 = not computed) instead of units, and no integer is wider than 32 bits (CF-1.8, Sec. 2.2)."""
    import numba
    import numpy as np
    import scipy

    from .. import __version__
    from ..ensembles.schema import AVERAGED, FORCES, RESULTS, WALL

    flags = {v.name: v.attrs for v in RESULTS + FORCES + WALL + AVERAGED if "flag_values" in v.attrs}
    out = ds.copy()
    for name, var in out.variables.items():
        attrs = dict(var.attrs)
        units = attrs.get("units")
        if units is not None and units != "1":
            attrs["comment"] = f"rescaled units: {units}"
            attrs["units"] = "1"
        if var.dtype.kind not in "fiu" or name in flags:
            attrs.pop("units", None)
        elif "units" not in attrs:
            attrs["units"] = "1"
        var.attrs = attrs
        var.encoding = {"_FillValue": None} if name in ds.coords or var.dtype.kind in "iu" else {}
    for name in list(out.variables):  # CF 1.8 (Sec. 2.2) has no 64-bit integers
        var = out[name]
        if var.dtype == np.int64:
            if var.size and (int(var.min()) < np.iinfo(np.int32).min or int(var.max()) > np.iinfo(np.int32).max):
                raise ValueError(f"{name} holds values beyond 32-bit integers, which CF-1.8 netCDF cannot hold")
            out[name] = var.astype(np.int32)
            out[name].attrs = var.attrs
            out[name].encoding = {"_FillValue": None}
    for name, attrs in flags.items():
        if name in out:
            out[name].attrs.update(flag_values=np.array(attrs["flag_values"], dtype=out[name].dtype),
                                   flag_meanings=attrs["flag_meanings"])
    now = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    attrs = dict(out.attrs)
    attrs["Conventions"] = "CF-1.8"
    attrs["history"] = (attrs.get("history", "") + f"\n{now} exported to netCDF by granchain {__version__} export").strip()
    attrs.setdefault("numpy_version", np.__version__)
    attrs.setdefault("scipy_version", scipy.__version__)
    attrs.setdefault("numba_version", numba.__version__)
    attrs.setdefault("granchain_version", __version__)
    out.attrs = {k: (int(v) if isinstance(v, bool) else v) for k, v in attrs.items()}
    return out


def export(store, file, force: bool = False, verify: bool = True) -> str:
    """Write ``store`` as a CF-1.8 netCDF file (returns the path). The store is verified as every reader
    verifies it (:func:`granchain.open_store`); ``verify=False`` exports it unchecked, with a warning."""
    import warnings

    from ..ensembles.read import open_store

    try:
        import netCDF4  # noqa: F401
    except ImportError:
        raise ValueError("granchain export needs the netCDF4 package: pip install 'granchain[netcdf]' "
                         "(or pip install netCDF4)") from None
    if not os.path.isdir(store):
        raise ValueError(f"{store} is not a granchain ensemble store (a Zarr directory): give the path of a store written by "
                         "granchain ensemble")
    file = os.fspath(file)
    if not file.strip():
        raise ValueError("FILE must be a path such as N26.nc, got an empty string")
    if os.path.exists(file) and not force:
        raise ValueError(f"{file} already exists: pass --force to overwrite it, or choose another name")
    parent = os.path.dirname(os.path.abspath(file))
    if not os.path.isdir(parent) or not os.access(parent, os.W_OK):
        raise ValueError(f"cannot write {file}: its folder {parent} is missing or not writable")
    ds = open_store(store, load=True, verify=verify)  # says what to do for a path that is no store or a damaged one
    done = None
    try:
        from ..ensembles.verify import StoreVerificationWarning

        with warnings.catch_warnings():  # warned about once, above; only the done flags are read (lazily)
            warnings.simplefilter("ignore", StoreVerificationWarning)
            done = open_store(store, group="progress", verify=verify)["done"].values
    except (ValueError, KeyError):
        pass
    if done is not None and not done.all():
        warnings.warn(f"{store} is incomplete ({int(done.sum())}/{done.size} chunks done): the file holds status = -1 "
                      "for realisations not computed and an averaged pulse of the finished part only", UserWarning)
    cf_dataset(ds).to_netcdf(file, engine="netcdf4", format="NETCDF4")
    return file


def run(args) -> int:
    path = export(args.store, args.file, force=args.force, verify=args.verify)
    print(f"wrote {path}")
    return 0
