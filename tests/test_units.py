"""Physical units (granchain.units, paper Sec. II) and the CLI quantity options.

Levels: numbers derived by hand for one steel chain; the scaling laws in R and V_1 that
Sec. II implies; the force unit computed two ways; a two-body Hertz collision against
Landau & Lifshitz's closed form (tests ``a`` independently of the r' matching); the
solitary-wave speed of a long monodisperse steel chain against Nesterenko's
long-wavelength formula; conversions of results and Datasets (including the contact and
wall force variables a later granchain adds); the quantity parser and the CLI.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest
import xarray as xr
from scipy.integrate import quad

import granchain as gc
from granchain import units
from granchain.cli import main
from granchain.cli._units import add_unit_arguments, parse_quantity, scale_from_args

STEEL_TEST = units.Material(200e9, 0.3, 7850.0, "steel (test)")


# --- the numbers, by hand ------------------------------------------------------------------

def test_steel_5mm_1ms_by_hand():
    s = units.scale(STEEL_TEST, radius=5e-3, impact_speed=1.0)
    # a = sqrt(2) E / (3 (1 - nu^2)) = 1.414213562 * 200e9 / (3 * 0.91) = 282.8427125e9 / 2.73
    assert s.a == pytest.approx(1.036053892e11, rel=1e-9)
    # M_1 = (4/3) pi rho R^3 = 4.188790205 * 7850 * 1.25e-7 = 4.188790205 * 9.8125e-4
    assert s.mass == pytest.approx(4.110250388e-3, rel=1e-9)
    # alpha = M_1 V_1^2 / (a R^3) = 4.110250388e-3 / (1.036053892e11 * 1.25e-7 = 1.295067365e4)
    assert s.alpha == pytest.approx(3.173773427e-7, rel=1e-8)
    # alpha^(2/5): ln alpha = ln 3.173773427 - 7 ln 10 = 1.154920 - 16.118096 = -14.963176;
    # times 0.4 = -5.985270; exp = e^-6 * e^0.014730 = 2.478752e-3 * 1.014839 = 2.515534e-3
    # T = (R / V_1) alpha^(2/5) = 0.005 * 2.515534e-3 = 1.257767e-5 s;  L = R alpha^(2/5) = 1.257767e-5 m
    assert s.time == pytest.approx(1.257767e-5, rel=2e-6)
    assert s.length == pytest.approx(1.257767e-5, rel=2e-6)
    assert s.velocity == 1.0
    # force unit M_1 V_1^2 / L = 4.110250e-3 / 1.257767e-5 = 326.789 N; energy M_1 V_1^2
    assert s.force == pytest.approx(326.789, rel=2e-6)
    assert s.energy == pytest.approx(4.110250388e-3, rel=1e-9)
    # the preset is the same material
    assert units.scale("steel", 5e-3, 1.0).time == s.time


def test_hertz_prefactor_is_four_thirds_estar_over_sqrt2():
    for m in units.MATERIALS.values():
        estar = 1.0 / (2 * (1 - m.nu**2) / m.E)
        assert units.hertz_prefactor(m) == pytest.approx(4 / 3 * estar / math.sqrt(2), rel=1e-14)
        # equal spheres: a r' = a sqrt(R) is Nesterenko's E (2R)^(1/2) / (3 (1 - nu^2))
        R = 3e-3
        assert units.hertz_prefactor(m) * math.sqrt(R) == pytest.approx(m.E * math.sqrt(2 * R) / (3 * (1 - m.nu**2)), rel=1e-14)


@pytest.mark.parametrize("R", [1e-3, 5e-3, 2e-2])
@pytest.mark.parametrize("V", [0.01, 0.3, 1.0, 7.0])
def test_scaling_laws_hertz(R, V):
    """n = 5/2: alpha ~ V^2 (no R), L ~ R V^(4/5), T ~ R V^(-1/5), F ~ R^2 V^(6/5), E ~ R^3 V^2."""
    ref = units.scale(STEEL_TEST, 5e-3, 1.0)
    s = units.scale(STEEL_TEST, R, V)
    r, v = R / 5e-3, V / 1.0
    assert s.alpha / ref.alpha == pytest.approx(v**2, rel=1e-12)
    assert s.length / ref.length == pytest.approx(r * v**0.8, rel=1e-12)
    assert s.time / ref.time == pytest.approx(r * v**-0.2, rel=1e-12)
    assert s.velocity == V
    assert s.force / ref.force == pytest.approx(r**2 * v**1.2, rel=1e-12)
    assert s.energy / ref.energy == pytest.approx(r**3 * v**2, rel=1e-12)


@pytest.mark.parametrize("n, a", [(2.5, None), (2.5, 3e10), (3.0, 1e13), (2.2, 5e9)])
def test_force_unit_two_ways(n, a):
    """M_1 L / T^2 = a R^(n - 1/2) alpha^((n-1)/n) = M_1 V_1^2 / L (module docstring)."""
    s = units.scale(units.BRASS, 4e-3, 0.7, n=n, a=a)
    assert s.force == pytest.approx(s.a * s.radius ** (n - 0.5) * s.alpha ** ((n - 1) / n), rel=1e-12)
    assert s.force == pytest.approx(s.mass * s.impact_speed**2 / s.length, rel=1e-12)
    assert s.length / s.time == pytest.approx(s.impact_speed, rel=1e-14)


def test_two_body_collision_is_landau_hertz():
    """Two equal steel spheres: the contact lasts 2 delta_m / V int_0^1 dx / sqrt(1 - x^(5/2))
    (Landau & Lifshitz, Theory of Elasticity, Sec. 9, problem: 2.94 delta_m / V), with the
    maximum compression from (1/2) mu V^2 = (2/5) (4/3) E* sqrt(R_eff) delta_m^(5/2). This
    uses E* and R_eff directly, not the r' matching inside ``scale``."""
    R, V = 5e-3, 1.0
    s = units.scale(units.STEEL, R, V)
    res = gc.simulate(gc.from_radii([1.0, 1.0]))
    t_contact = res.peak_time[1] * s.time  # granule 2 is fastest when the contact opens
    m = units.STEEL.effective_modulus
    mu = s.mass / 2
    delta_m = (0.5 * mu * V**2 / (0.4 * 4 / 3 * m * math.sqrt(R / 2))) ** 0.4
    integral = quad(lambda x: 1 / math.sqrt(1 - x**2.5), 0, 1)[0]
    assert 2 * integral == pytest.approx(2.9432, abs=1e-4)
    assert t_contact == pytest.approx(2 * delta_m / V * integral, rel=1e-6)


def test_solitary_wave_speed_is_nesterenko():
    """A monodisperse steel chain (R = 5 mm, V_1 = 1 m/s), in SI units.

    Nesterenko's long-wavelength solitary wave (Dynamics of Heterogeneous Materials,
    Springer 2001, Ch. 1): V_s = (2/sqrt(5)) c xi_m^(1/4), with c^2 = A D^(5/2) / M
    (F = A delta^(3/2), D = 2R; c^2 = 2E / (pi rho (1 - nu^2))) and xi_m the maximum strain.
    In a travelling wave the particle velocity is v = V_s xi, so for the velocity amplitude
    v_m: V_s = (16/25)^(1/5) c^(4/5) v_m^(1/5). (In force amplitude this is
    V_s = 0.6802 (2E / (D (1 - nu^2)))^(1/3) F_m^(1/6) / rho^(1/2), Daraio et al., PRE 73,
    026610 (2006).) The long-wavelength approximation is not exact for the discrete chain
    (its wave is only ~5 grains wide): the exact discrete wave differs by a few per cent
    (Chatterjee, PRE 59, 5912 (1999); Ahnert & Pikovsky, PRE 79, 026209 (2009)). Measured
    here: the discrete wave is 0.8 % slower; we assert within 2 %.
    """
    s = units.scale(units.STEEL, 5e-3, 1.0)
    res = gc.simulate(gc.monodisperse(50))
    k = np.arange(15, 36)  # far from the struck end (the wave forms within ~10 grains) and the free end
    phys = units.pulse_to_physical(res, s)
    t = phys.peak_time[k - 1]
    v_m = phys.peak_velocity[k - 1]
    assert np.ptp(v_m) / v_m.mean() < 1e-4  # a steady solitary wave
    D = 2 * s.radius
    speed = D / np.polyfit(k, t, 1)[0]  # m/s, from peak times
    A = s.a * math.sqrt(s.radius)  # F = A delta^(3/2) for equal spheres
    c = math.sqrt(A * D**2.5 / s.mass)
    assert c == pytest.approx(math.sqrt(2 * units.STEEL.E / (math.pi * units.STEEL.rho * (1 - units.STEEL.nu**2))), rel=1e-12)
    nesterenko = (16 / 25) ** 0.2 * c**0.8 * v_m.mean() ** 0.2
    assert 600 < speed < 750  # m/s: a ~670 m/s wave, far below c = 4222 m/s (sonic vacuum)
    assert speed / nesterenko == pytest.approx(1.0, abs=0.02)


def test_solitary_wave_force_amplitude():
    """The same in force amplitude, once results record peak contact forces (issue 12 item 2)."""
    res = gc.simulate(gc.monodisperse(50))
    if not hasattr(res, "peak_force"):
        pytest.skip("PulseResult has no peak_force yet (contact forces: issue 12 item 2)")
    s = units.scale(units.STEEL, 5e-3, 1.0)
    phys = units.pulse_to_physical(res, s)
    k = np.arange(15, 36)
    speed = 2 * s.radius / np.polyfit(k, phys.peak_time[k - 1], 1)[0]
    F_m = phys.peak_force[k - 1].mean()
    m = units.STEEL
    nesterenko = 0.6802 * (2 * m.E / (2 * s.radius * (1 - m.nu**2))) ** (1 / 3) * F_m ** (1 / 6) / math.sqrt(m.rho)
    assert speed / nesterenko == pytest.approx(1.0, abs=0.03)


# --- conversions ---------------------------------------------------------------------------

def test_pulse_to_physical_keeps_result():
    s = units.scale(units.GLASS, 2e-3, 0.5)
    res = gc.simulate(gc.from_radii([1, 0.3, 1, 0.1, 1]), t_grid=np.linspace(0, 5, 11))
    before = res.peak_time.copy()
    phys = gc.to_physical(res, s)
    np.testing.assert_array_equal(res.peak_time, before)
    np.testing.assert_allclose(phys.peak_time, before * s.time, rtol=1e-15)
    np.testing.assert_allclose(phys.peak_velocity, res.peak_velocity * 0.5, rtol=1e-15)
    np.testing.assert_allclose(phys.t_grid, np.linspace(0, 5, 11) * s.time, rtol=1e-15)
    np.testing.assert_allclose(phys.velocity, res.velocity * 0.5, rtol=1e-15)
    # results record peak contact forces (per contact): converted with the force unit
    np.testing.assert_allclose(phys.peak_force, res.peak_force * s.force, rtol=1e-15)
    np.testing.assert_allclose(phys.peak_force_time, res.peak_force_time * s.time, rtol=1e-15)
    d = phys.as_dict()
    assert set(d) >= {"peak_time_s", "peak_velocity_m_s", "t_end_s", "velocity_m_s", "peak_force_N", "peak_force_time_s"}


def test_pulse_with_forces_converts_forces():
    """Forward compatibility: results that carry peak_force / peak_force_time (per contact)."""
    s = units.scale(units.STEEL, 5e-3, 1.0)
    fake = SimpleNamespace(granule=np.arange(1, 4), peak_velocity=np.ones(3), peak_time=np.arange(3.0),
                           t_end=9.0, exit_time=8.0, t_grid=None, velocity=None,
                           peak_force=np.array([1.0, 2.0]), peak_force_time=np.array([0.5, 1.5]))
    phys = units.to_physical(fake, s)
    np.testing.assert_allclose(phys.peak_force, [s.force, 2 * s.force])
    np.testing.assert_allclose(phys.peak_force_time, [0.5 * s.time, 1.5 * s.time])
    assert phys.as_dict()["peak_force_N"] == pytest.approx([s.force, 2 * s.force])


def _synthetic_dataset():
    rng = np.random.default_rng(0)
    C, R, N, T = 2, 3, 4, 5
    return xr.Dataset(
        {
            "small_radius": (("realization", "gap"), rng.uniform(0.01, 0.4, (R, N - 1)), {"units": "R_1"}),
            "peak_velocity": (("chain", "realization", "granule"), rng.uniform(0.5, 1, (C, R, N)), {"units": "V_1", "long_name": "maximum velocity"}),
            "peak_time": (("chain", "realization", "granule"), rng.uniform(0, 10, (C, R, N)), {"units": "rescaled time"}),
            "t_end": (("chain", "realization"), rng.uniform(10, 20, (C, R))),
            "status": (("chain", "realization"), np.zeros((C, R), np.int8)),
            "energy_error": (("chain", "realization"), rng.normal(0, 1e-9, (C, R))),
            "mean_velocity": (("chain", "granule", "time"), rng.uniform(0, 1, (C, N, T))),
            "peak_force": (("chain", "realization", "contact"), rng.uniform(0, 2, (C, R, N - 1))),
            "peak_force_time": (("chain", "realization", "contact"), rng.uniform(0, 10, (C, R, N - 1))),
            "wall_force": (("chain", "time"), rng.uniform(0, 2, (C, T))),
            "peak_wall_force": (("chain", "realization"), rng.uniform(0, 2, (C, R))),
        },
        coords={"time": ("time", np.linspace(0, 4, T), {"units": "rescaled time"}), "chain": ["decorated", "effective"]},
        attrs={"seed": 1},
    )


def test_dataset_to_physical_adds_si_variables():
    s = units.scale(units.STAINLESS_STEEL, 3e-3, 2.0)
    ds = _synthetic_dataset()
    orig = ds.copy(deep=True)
    out = units.dataset_to_physical(ds, s)
    xr.testing.assert_identical(ds, orig)  # the input is untouched
    kinds = {"small_radius": ("radius", "m"), "peak_velocity": ("velocity", "m/s"), "peak_time": ("time", "s"),
             "t_end": ("time", "s"), "mean_velocity": ("velocity", "m/s"), "peak_force": ("force", "N"),
             "peak_force_time": ("time", "s"), "wall_force": ("force", "N"), "peak_wall_force": ("force", "N")}
    for name, (kind, unit) in kinds.items():
        si = out[name + "_si"]
        assert si.attrs["units"] == unit and si.dims == ds[name].dims
        np.testing.assert_allclose(si.values, ds[name].values * getattr(s, kind), rtol=1e-15)
        xr.testing.assert_identical(out[name].drop_vars("time_si", errors="ignore"), ds[name])  # kept as it was
    assert "status_si" not in out and "energy_error_si" not in out
    np.testing.assert_allclose(out["time_si"].values, ds["time"].values * s.time)
    assert out.attrs["physical_material"] == "stainless steel" and out.attrs["seed"] == 1
    assert out.attrs["physical_time_unit_s"] == s.time


def test_dataset_to_physical_on_a_stored_ensemble():
    from pathlib import Path

    store = Path(__file__).parent / "data" / "v0.1.0-decorated-N6.zarr"
    ds = xr.open_dataset(store, engine="zarr")
    s = units.scale("ptfe", 1e-2, 0.1)
    out = gc.to_physical(ds, s)
    np.testing.assert_allclose(out["peak_time_si"].values, ds["peak_time"].values * s.time)
    assert out["mean_velocity_si"].attrs["units"] == "m/s"


# --- bad input -----------------------------------------------------------------------------

@pytest.mark.parametrize("kwargs, words", [
    (dict(E=-1, nu=0.3, rho=7850), "E (Young's modulus"),
    (dict(E=200, nu=0.3, rho=7850), "in Pa"),
    (dict(E=2e11, nu=0.5, rho=7850), "nu"),
    (dict(E=2e11, nu=0.3, rho=7.85), "kg/m^3"),
    (dict(E=2e11, nu="x", rho=7850), "nu"),
    (dict(E=float("nan"), nu=0.3, rho=7850), "finite"),
])
def test_material_validates(kwargs, words):
    with pytest.raises(ValueError, match=words.replace("(", r"\(").replace("^", r"\^")):
        units.Material(**kwargs)


def test_material_is_frozen():
    with pytest.raises(AttributeError):
        units.STEEL.E = 1.0


@pytest.mark.parametrize("args, kwargs, words", [
    (("steel", 5.0e-3, 1.0), dict(n=3.0), "only n = 5/2 is Hertz"),
    (("steel", -1.0, 1.0), {}, "radius"),
    (("steel", 5.0, 1.0), {}, r"radius = 5 m|> 10"),
    (("steel", 50.0, 1.0), {}, "metres"),
    (("steel", 5e-3, 0.0), {}, "impact_speed"),
    (("unobtainium", 5e-3, 1.0), {}, "unknown material"),
    ((42, 5e-3, 1.0), {}, "Material"),
    (("steel", 5e-3, 1.0), dict(n=1.0), "n must be > 1"),
])
def test_scale_bad_input(args, kwargs, words):
    if args[1] == 5.0:
        units.scale(*args, **kwargs)  # 5 m is big, but a legal radius
        return
    with pytest.raises(ValueError, match=words):
        units.scale(*args, **kwargs)


def test_get_material_aliases():
    assert units.get_material("Stainless Steel") is units.STAINLESS_STEEL
    assert units.get_material("aluminum") is units.ALUMINIUM
    assert units.get_material("Teflon") is units.PTFE
    assert all(m.source for m in units.MATERIALS.values())


# --- the quantity parser -------------------------------------------------------------------

@pytest.mark.parametrize("text, kind, value", [
    ("5mm", "length", 5e-3), ("5 mm", "length", 5e-3), ("0.005 m", "length", 5e-3), ("0.005", "length", 5e-3),
    ("5e-3m", "length", 5e-3), ("500 um", "length", 5e-4), ("500µm", "length", 5e-4), ("0.5cm", "length", 5e-3),
    ("3/16 in", "length", 0.0047625), ("3/16in", "length", 0.0047625), ("0.25 inch", "length", 0.00635),
    ("1m/s", "speed", 1.0), ("100 cm/s", "speed", 1.0), ("3.6 km/h", "speed", 1.0), ("250mm/s", "speed", 0.25),
    ("50 cm/s", "speed", 0.5), ("1 ft/s", "speed", 0.3048),
    ("200GPa", "pressure", 2e11), ("193 GPa", "pressure", 1.93e11), ("1.46e9", "pressure", 1.46e9),
    ("200 GPa", "pressure", 2e11), ("2e11 N/m^2", "pressure", 2e11), ("29e6 psi", "pressure", 29e6 * 6894.757293168361),
    ("7850 kg/m^3", "density", 7850.0), ("7.85 g/cm^3", "density", 7850.0), ("2200kg/m**3", "density", 2200.0),
    ("7.85 g/cc", "density", 7850.0),
])
def test_parse_quantity(text, kind, value):
    """pint reads the quantity; a bare number is SI."""
    assert parse_quantity(text, kind, "--x") == pytest.approx(value, rel=1e-13)


@pytest.mark.parametrize("text, kind, words", [
    ("5 mmm", "length", r"--opt: unknown unit in '5 mmm' \('mmm' is not defined"),
    ("1 m/s", "length", r"--opt needs a length, got 1 m/s \(a speed\)"),
    ("5mm", "speed", r"--opt needs a speed, got 5mm \(a length\)"),
    ("5 s", "length", r"--opt needs a length, got 5 s \(a time\)"),
    ("200 GPa", "density", r"--opt needs a density, got 200 GPa \(a pressure\)"),
    ("fast", "speed", r"--opt: unknown unit in 'fast'"),
    ("5 m m/", "length", r"--opt: cannot read '5 m m/' as a quantity"),
    ("-5 mm", "length", r"--opt must be > 0, got '-5 mm': a radius is a size"),
    ("0 m/s", "speed", r"--opt must be > 0, got '0 m/s': the impact speed"),
    ("5 furlongs", "speed", r"needs a speed, got 5 furlongs \(a length\)"),
])
def test_parse_quantity_errors_name_the_option(text, kind, words):
    with pytest.raises(ValueError, match=words):
        parse_quantity(text, kind, "--opt")


def test_api_takes_pint_quantities_and_strings():
    """scale() and Material take pint.Quantity objects (of pint's application registry or another
    one) and strings; the result equals the SI-float call, and Scale.to_quantity returns pint."""
    pint = pytest.importorskip("pint")
    ureg = pint.get_application_registry()
    ref = units.scale(units.STEEL, 0.0047625, 0.5)
    for radius, speed in ((ureg.Quantity(3 / 16, "in"), ureg.Quantity(50, "cm/s")), ("3/16 in", "50 cm/s"),
                          (pint.UnitRegistry().Quantity(4.7625, "mm"), "0.5 m/s")):
        s = units.scale("steel", radius, speed)
        assert s.time == pytest.approx(ref.time, rel=1e-13) and s.force == pytest.approx(ref.force, rel=1e-13)
    m = units.Material("200 GPa", 0.3, ureg.Quantity(7.85, "g/cm^3"))
    assert (m.E, m.rho) == (pytest.approx(2e11), pytest.approx(7850.0))
    q = ref.to_quantity(np.array([1.0, 2.0]), "time")
    assert isinstance(q, ureg.Quantity) and q.to("s").magnitude[1] == pytest.approx(2 * ref.time)
    with pytest.raises(ValueError, match=r"radius \(m\) needs a length, got 5 second \(a time\)"):
        units.scale("steel", ureg.Quantity(5, "s"), 1.0)
    with pytest.raises(ValueError, match=r"E \(Young's modulus, Pa\) needs a pressure"):
        units.Material("7850 kg/m^3", 0.3, 7850.0)


def _parse(*argv):
    p = argparse.ArgumentParser()
    p.add_argument("--n", type=float, default=2.5)
    add_unit_arguments(p)
    return p.parse_args(list(argv))


def test_scale_from_args_is_reusable():
    assert scale_from_args(_parse()) is None
    s = scale_from_args(_parse("--material", "steel", "--radius", "5 mm", "--impact-speed", "100cm/s"))
    assert s.time == units.scale(units.STEEL, 5e-3, 1.0).time
    s = scale_from_args(_parse("--E", "200GPa", "--nu", "0.3", "--rho", "7.85g/cm^3", "--radius", "5mm", "--impact-speed", "1m/s"))
    assert s.time == pytest.approx(units.scale(STEEL_TEST, 5e-3, 1.0).time, rel=1e-14)
    # a namespace without --n (another sub-command) uses Hertz
    ns = SimpleNamespace(material="brass", E=None, nu=None, rho=None, radius=1e-3, impact_speed=2.0)
    assert scale_from_args(ns).n == 2.5


@pytest.mark.parametrize("argv, words", [
    (("--radius", "5mm", "--impact-speed", "1m/s"), "need a material"),
    (("--material", "steel", "--radius", "5mm"), "need --impact-speed"),
    (("--material", "steel"), "need --radius and --impact-speed"),
    (("--material", "steel", "--E", "1GPa", "--radius", "5mm", "--impact-speed", "1m/s"), "not both"),
    (("--E", "1GPa", "--nu", "0.3", "--radius", "5mm", "--impact-speed", "1m/s"), "missing --rho"),
    (("--material", "steel", "--radius", "5mm", "--impact-speed", "1m/s", "--n", "3"), "--contact-prefactor"),
])
def test_scale_from_args_errors(argv, words):
    with pytest.raises(ValueError, match=words):
        scale_from_args(_parse(*argv))


# --- the CLI -------------------------------------------------------------------------------

def test_cli_pulse_physical_json_equals_api():
    argv = ["pulse", "--radii", "1,1,1,1,1", "--material", "steel", "--radius", "5mm", "--impact-speed", "1m/s", "--json"]
    out = subprocess.run([sys.executable, "-m", "granchain", *argv], capture_output=True, text=True, check=True).stdout
    data = json.loads(out)
    s = units.scale(units.STEEL, 5e-3, 1.0)
    api = units.pulse_to_physical(gc.simulate(gc.from_radii([1.0] * 5)), s)
    phys = data["physical"]
    np.testing.assert_allclose(phys["peak_time_s"], api.peak_time, rtol=1e-14)
    np.testing.assert_allclose(phys["peak_velocity_m_s"], api.peak_velocity, rtol=1e-14)
    assert phys["scale"]["time_unit_s"] == pytest.approx(s.time, rel=1e-15)
    assert phys["scale"]["force_unit_N"] == pytest.approx(s.force, rel=1e-15)
    # the rescaled keys are unchanged
    np.testing.assert_allclose(np.array(phys["peak_time_s"]), np.array(data["peak_time"]) * s.time, rtol=1e-14)


def test_cli_pulse_physical_table(capsys):
    code = main(["pulse", "--small-radii", "0.2,0.1", "--E", "193GPa", "--nu", "0.3", "--rho", "8000kg/m^3",
                 "--radius", "4 mm", "--impact-speed", "50 cm/s"])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert "peak_time [s]" in out and "peak_velocity [m/s]" in out and "# physical units: custom" in out


def test_cli_without_units_prints_no_physical(capsys):
    assert main(["pulse", "--radii", "1,1", "--json"]) == 0
    assert "physical" not in json.loads(capsys.readouterr().out)


@pytest.mark.parametrize("argv, words", [
    (["--radius", "5 mmm", "--material", "steel", "--impact-speed", "1m/s"], "argument --radius: unknown unit in '5 mmm'"),
    (["--radius", "5mm", "--material", "steel", "--impact-speed", "1 mm"], "argument --impact-speed: needs a speed, got 1 mm (a length)"),
    (["--radius", "5 s", "--material", "steel", "--impact-speed", "1m/s"], "argument --radius: needs a length, got 5 s (a time)"),
    (["--radius", "5mm", "--material", "wood", "--impact-speed", "1m/s"], "unknown material 'wood'"),
    (["--radius", "5mm", "--impact-speed", "1m/s"], "need a material"),
    (["--material", "steel", "--radius", "5mm", "--impact-speed", "1m/s", "--n", "3"], "only n = 5/2"),
    # negative values reach the option's own check (argparse alone would say "expected one argument")
    (["--material", "steel", "--radius", "5mm", "--impact-speed", "-1m/s"], "argument --impact-speed: must be > 0, got '-1m/s'"),
    (["--E", "-1GPa", "--nu", "0.3", "--rho", "7850", "--radius", "5mm", "--impact-speed", "1m/s"],
     "argument --E: must be > 0, got '-1GPa': Young's modulus"),
    (["--material", "steel", "--radius", "-.5e-3", "--impact-speed", "1m/s"], "argument --radius: must be > 0"),
])
def test_cli_bad_units_exit_2(capsys, argv, words):
    try:
        code = main(["pulse", "--radii", "1,1", *argv])
    except SystemExit as exc:  # argparse type errors
        code = exc.code
    out, err = capsys.readouterr()
    assert code == 2 and out == ""
    assert words in err
