"""``granchain pulse``: peak velocity and peak time of every observed granule of one chain."""

from __future__ import annotations

import json
import sys

import numpy as np

from ..solve.integrators import INTEGRATORS
from ._backend import add_backend_arguments, backend_of, check_usable
from ._contacts import add_contact_arguments, apply_to_chain, model_from_args, wall_material_from_args
from ._units import add_unit_arguments, scale_from_args
from .plot import add_pulse_plot_arguments, passage_time, pulse_plot_request, write_pulse_plot


def _floats(text: str, flag: str = "--radii") -> list[float]:
    fields = text.split(",")
    if any(not f.strip() for f in fields):
        raise ValueError(f"{flag} has an empty field in {text!r}: give comma-separated numbers such as 0.1,0.2")
    try:
        return [float(s) for s in fields]
    except ValueError:
        raise ValueError(f"{flag} expects comma-separated numbers, got {text!r}") from None


def _labels(text: str, flag: str) -> list[int]:
    """Comma-separated whole numbers (1-based granule labels)."""
    out = []
    for f in _floats(text, flag):
        if not (f == f and abs(f) != float("inf") and float(f).is_integer()):
            raise ValueError(f"{flag} expects comma-separated whole numbers (1-based granule labels such as 2,5), got {text!r}")
        out.append(int(f))
    return out


#: What a user should know when choosing (every registered integrator is listed, noted or not).
INTEGRATOR_NOTES = {"dp5": "default, adaptive Dormand-Prince 5(4)", "rkn4": "adaptive Runge-Kutta-Nystrom 4(3)",
                    "verlet": "fixed step", "dop853": "SciPy's DOP853, the independent reference; slow"}


def taking(setting: str) -> list[str]:
    """The registered integrators that have ``setting`` (a field of their dataclass)."""
    import dataclasses

    return [name for name, cls in sorted(INTEGRATORS.items()) if setting in {f.name for f in dataclasses.fields(cls)}]


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "pulse",
        help="exact pulse dynamics of one chain: peak velocity and peak time per granule",
        description=(
            "Integrate one chain struck at granule 1 (velocity 1, rescaled units of the paper's Sec. II) "
            "until the pulse has left the last granule; print each observed granule's peak velocity and its time."
        ),
    )
    chain = p.add_mutually_exclusive_group(required=True)
    chain.add_argument("--small-radii", metavar="R1,R2,...", help="decorated chain: one large granule (R = 1) more than small radii; observes the large granules")
    chain.add_argument("--radii", metavar="R1,R2,...", help="any chain of spheres from its radii; all granules observed")
    p.add_argument("--effective", action="store_true", help="with --small-radii: integrate the effective (undecorated) chain instead")
    p.add_argument("--momentum-conserving", action="store_true", help="with --effective: start granule 1 with m_1/mu_1 instead of velocity 1")
    p.add_argument("--wall", action="store_true", help=(
        "end the chain in a fixed wall (a granule of infinite radius and mass, contact stiffness sqrt(2 R_M)); "
        "the run stops once the pulse has come back from the wall, and the wall's peak force and impulse are printed"))
    p.add_argument("--forces", action="store_true", help=(
        'also print the peak force of every contact j (between granules j and j+1) and its time '
        '(--json: "peak_force", "peak_force_time"); printed anyway, in N and s too, with physical units'))
    p.add_argument("--n", type=float, default=2.5, help="exponent of the contact potential (default: Hertz, 2.5)")
    # the lists of integrators and of the ones each setting applies to come from the registry
    p.add_argument("--integrator", default=None, metavar="{" + ",".join(sorted(INTEGRATORS)) + "}",
                   help=f"one of {', '.join(f'{name} ({INTEGRATOR_NOTES[name]})' if name in INTEGRATOR_NOTES else name for name in sorted(INTEGRATORS))} "
                        "(default dp5; rkn4 with --backend cuda, the GPU's default, for elastic contacts)")
    p.add_argument("--rtol", type=float, help=f"relative tolerance ({', '.join(taking('rtol'))})")
    p.add_argument("--atol", type=float, help=f"absolute tolerance ({', '.join(taking('atol'))})")
    p.add_argument("--dt", type=float, help=f"time step ({', '.join(taking('dt'))})")
    p.add_argument("--json", action="store_true", help=(
        'print {"granule": [...], "peak_velocity": [...], "peak_time": [...], "ok": true|false, "status": {"name", "code", '
        '"message"}} only (rescaled; a run that did not succeed still prints its JSON, and the command exits 1); with '
        '--wall also "wall": '
        '{"peak_force", "peak_force_time", "impulse"}; with physical units also "physical": {"peak_velocity_m_s", '
        '"peak_time_s", "peak_force_N", ..., "scale": {...}}'))
    add_contact_arguments(p, sensor=True)
    add_unit_arguments(p)
    add_pulse_plot_arguments(p)
    add_backend_arguments(p, switch=False)
    p.set_defaults(func=run)


def _integrator(args, conservative: bool = True):
    """The integrator asked for, else DP5 (``simulate``'s default), or on the GPU RKN4 (its default, measured there)
    where the contacts are ``conservative`` (RKN4 integrates forces of positions only; damped contacts keep DP5)."""
    from .. import INTEGRATORS

    gpu_default = backend_of(args) == "cuda" and conservative
    name = args.integrator if args.integrator is not None else ("rkn4" if gpu_default else "dp5")
    cls = INTEGRATORS.get(name.lower())
    if cls is None:
        raise ValueError(f"unknown integrator {name!r}; choose one of {sorted(INTEGRATORS)}")
    kwargs = {k: getattr(args, k) for k in ("rtol", "atol", "dt") if getattr(args, k) is not None}
    try:
        return cls(**kwargs)
    except TypeError:
        raise ValueError(f"integrator {cls.name} does not take {sorted(kwargs)}") from None


def _physical_table(phys, labels) -> str:
    lines = [f"{'granule':>8} {'peak_velocity [m/s]':>20} {'peak_time [s]':>14}"]
    for k, vp, tp in zip(labels, phys.peak_velocity, phys.peak_time):
        lines.append(f"{k:8d} {vp:20.9g} {tp:14.6e}")
    lines.append(f"# physical units: {phys.scale}")
    return "\n".join(lines)


def _force_table(result, scale=None) -> str:
    """Peak force and its time per contact j (between granules j and j+1, 1-based), rescaled and, with
    a scale, in N and s (granchain.units: force unit M_1 L / T^2)."""
    head = f"{'contact':>8} {'peak_force':>15} {'peak_force_time':>16}"
    if scale is not None:
        head += f" {'peak_force [N]':>15} {'time [s]':>13}"
    lines = [head]
    last = result.peak_force.size
    for j, (f, t) in enumerate(zip(result.peak_force, result.peak_force_time), start=1):
        row = f"{j:8d} {f:15.9g} {t:16.6f}"
        if scale is not None:
            row += f" {f * scale.force:15.9g} {t * scale.time:13.6e}"
        lines.append(row + ("  (wall)" if result.chain.wall and j == last else ""))
    return "\n".join(lines)


def _wall_summary(result, scale=None) -> str:
    text = (f"# wall: peak force {result.peak_wall_force:.9g} at t = {result.peak_wall_force_time:.6f}, "
            f"impulse {result.wall_impulse:.9g} (rescaled)")
    if scale is not None:
        text += (f"; {result.peak_wall_force * scale.force:.6g} N at {result.peak_wall_force_time * scale.time:.6e} s, "
                 f"impulse {result.wall_impulse * scale.mass * scale.velocity:.6g} N s")
    return text


def _sensor_summary(result, scale=None) -> str:
    peak, when = result.sensor_peak()
    lines = []
    for k, f, t in zip(result.sensor_granule, peak, when):
        text = f"# sensor granule {k}: peak force {f:.9g} at t = {t:.6f}"
        if result.chain.precompression.applied:
            text += f" (dynamic {f - result.static_force:.9g})"
        if scale is not None:
            text += f"; {f * scale.force:.6g} N at {t * scale.time:.6e} s"
        lines.append(text)
    return "\n".join(lines)


def run(args) -> int:
    import granchain as gc

    if args.momentum_conserving and not args.effective:
        raise ValueError("--momentum-conserving applies only to the effective chain: add --effective (with --small-radii)")
    check_usable(args)  # a GPU asked where none can run: its one-line reason, before any work
    units = scale_from_args(args)  # None without unit options; checked before integrating
    model = model_from_args(args, units, args.n)
    if args.small_radii is not None:
        chain = gc.decorated(_floats(args.small_radii, "--small-radii"), n=args.n)
        if args.effective:
            chain = gc.effective(chain, momentum_conserving=args.momentum_conserving)
    else:
        if args.effective:
            raise ValueError("--effective needs --small-radii (a decorated chain)")
        chain = gc.from_radii(_floats(args.radii, "--radii"), n=args.n)
    if args.wall:
        material = wall_material_from_args(args)
        if material is not None and units is None:
            raise ValueError("--wall-material is stiff relative to the beads' material: give the physical-unit options "
                             "too (--material or --E/--nu/--rho, --radius, --impact-speed)")
        chain = (chain.with_wall(material=material, granules=units.material) if material is not None
                 else chain.with_wall())
    chain = apply_to_chain(chain, model, args)
    sensors = None if args.sensor is None else _labels(args.sensor, "--sensor")
    grid = None
    if sensors is not None:  # the sensors' force on a grid over the pulse's passage (and, loaded, its reflection)
        t_end = passage_time(chain)
        grid = np.arange(0.0, t_end, 0.01)
    plot = pulse_plot_request(args, chain, grid, sensors)  # --plot: checked before the run; the grid (and gauges) it needs
    result = gc.simulate(chain, _integrator(args, chain.contact.conservative), t_grid=grid if plot is None else plot.grid,
                         sensors=sensors if plot is None else plot.sensors, backend=backend_of(args))
    # Decorated (and effective) chains are reported by large-granule index k = 1..N
    # (decorated chain index 2k - 1); a chain from --radii by its own index.
    labels = np.arange(1, result.granule.size + 1) if args.small_radii is not None else result.granule
    phys = None if units is None else gc.units.pulse_to_physical(result, units)
    if args.json:
        out = {
            "granule": [int(k) for k in labels],
            "peak_velocity": [float(v) for v in result.peak_velocity],
            "peak_time": [float(t) for t in result.peak_time],
            # the run's outcome: a script must not read peaks of a run that did not succeed as results
            "ok": bool(result.ok),
            "status": {"name": result.status.name, "code": int(result.status), "message": result.message},
        }
        if args.forces:
            out["peak_force"] = [float(f) for f in result.peak_force]
            out["peak_force_time"] = [float(t) for t in result.peak_force_time]
        if chain.wall:
            out["wall"] = {"peak_force": result.peak_wall_force, "peak_force_time": result.peak_wall_force_time,
                           "impulse": result.wall_impulse}
        if not chain.elastic or chain.striker:
            out["contact_model"] = chain.describe_model()
            out["dissipated_energy"] = result.dissipated_energy
        if sensors is not None:
            peak, when = result.sensor_peak()
            out["sensor"] = {"granule": sensors, "peak_force": peak.tolist(), "peak_force_time": when.tolist()}
        if phys is not None:
            physical = phys.as_dict()  # with peak_force_N, peak_force_time_s per contact
            if chain.wall:
                physical["peak_wall_force_N"] = result.peak_wall_force * units.force
                physical["peak_wall_force_time_s"] = result.peak_wall_force_time * units.time
                physical["wall_impulse_N_s"] = result.wall_impulse * units.mass * units.velocity
            out["physical"] = {**physical, "scale": units.as_dict()}
        print(json.dumps(out))
    else:
        print(result.table(labels))
        if args.small_radii is not None:
            print("# granule = large-granule index k (decorated chain index 2k - 1)")
        if phys is not None:
            print(_physical_table(phys, labels))
        if args.forces or units is not None:  # physical units: the peak forces in N too
            print(_force_table(result, units))
        if chain.wall and units is not None:
            print(_wall_summary(result, units))
        if sensors is not None:
            print(_sensor_summary(result, units))
        if chain.contact.dissipates:
            e = (f"# dissipated energy{' (plastic work)' if chain.contact.history else ''} {result.dissipated_energy:.6g} "
                 f"of {chain.energy:.6g} (rescaled)")
            if units is not None:
                e += f"; {result.dissipated_energy * units.energy:.6g} J"
            print(e)
    if plot is not None:
        path = write_pulse_plot(plot, result, units)
        if not args.json:
            print(f"# figure written to {path}")
    if not result.ok:
        # exit 1 (not 0): a script that checks the exit status, or reads "ok" in --json, must not take these
        # peaks for results; not 2, which is for refused input
        print(f"granchain pulse: warning: the run did not succeed ({result.status.name}): {result.message}",
              file=sys.stderr)
        return 1
    return 0
