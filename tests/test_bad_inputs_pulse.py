"""Bad inputs of ``granchain pulse``: every option with nonsense (empty, NaN, inf, negative, huge,
wrong units, malformed lists). Each must exit 2 with a ``granchain pulse: error: ...`` line that says
what to change, before any integration (``tests/_bad_inputs.py`` judges them)."""

from __future__ import annotations

import pytest
from _bad_inputs import Cli, check

R = ["pulse", "--radii", "1,1,1"]
UNITS = ["--material", "steel", "--radius", "5mm", "--impact-speed", "1m/s"]

CASES = [
    # -- the chain ---------------------------------------------------------------------------------------
    Cli("no-chain", ["pulse"], r"one of the arguments --small-radii --radii is required"),
    Cli("radii-empty", ["pulse", "--radii", ""], r"--radii has an empty field"),
    Cli("radii-empty-field", ["pulse", "--radii", "1,,1"], r"--radii has an empty field"),
    Cli("radii-text", ["pulse", "--radii", "1,a,1"], r"--radii expects comma-separated numbers"),
    Cli("radii-nan", ["pulse", "--radii", "1,nan,1"], r"radii must be finite"),
    Cli("radii-inf", ["pulse", "--radii", "1,inf"], r"radii must be finite"),
    Cli("radii-negative", ["pulse", "--radii", "1,-1,1"], r"radii must be > 0"),
    Cli("radii-zero", ["pulse", "--radii", "1,0"], r"radii must be > 0"),
    Cli("radii-tiny", ["pulse", "--radii", "1,1e-300,1"], r"radii\[1\] = 1e-300 is too small"),
    Cli("radii-huge", ["pulse", "--radii", "1,1e300"], r"radii\[1\].*too large"),
    Cli("radii-one", ["pulse", "--radii", "1"], r"at least 2 granules"),
    Cli("radii-semicolons", ["pulse", "--radii", "1;1;1"], r"--radii expects comma-separated numbers"),
    Cli("radii-and-small", ["pulse", "--radii", "1,1", "--small-radii", "0.1"], r"not allowed with"),
    Cli("small-radii-empty", ["pulse", "--small-radii", ""], r"--small-radii has an empty field"),
    Cli("small-radii-too-big", ["pulse", "--small-radii", "1.5"], r"larger than its neighbouring"),
    Cli("small-radii-nan", ["pulse", "--small-radii", "0.1,nan"], r"small_radii must be finite"),
    Cli("effective-without-small", R + ["--effective"], r"--effective needs --small-radii"),
    Cli("momentum-without-effective", R + ["--momentum-conserving"], r"applies only to the effective chain"),
    Cli("n-nan", R + ["--n", "nan"], r"n must be finite"),
    Cli("n-one", R + ["--n", "1"], r"need n > 1"),
    Cli("n-text", R + ["--n", "hertz"], r"invalid float value"),
    Cli("n-inf", R + ["--n", "inf"], r"n must be finite"),
    # -- the integrator -----------------------------------------------------------------------------------
    Cli("integrator-unknown", R + ["--integrator", "euler"], r"unknown integrator"),
    Cli("integrator-empty", R + ["--integrator", ""], r"unknown integrator"),
    Cli("rtol-nan", R + ["--rtol", "nan"], r"rtol"),
    Cli("rtol-negative", R + ["--rtol", "-1e-8"], r"rtol"),
    Cli("rtol-huge", R + ["--rtol", "5"], r"rtol"),
    Cli("rtol-text", R + ["--rtol", "tight"], r"invalid float value"),
    Cli("atol-negative", R + ["--atol", "-1"], r"atol"),
    Cli("atol-inf", R + ["--atol", "inf"], r"atol"),
    Cli("dt-for-dp5", R + ["--dt", "0.01"], r"does not take"),
    Cli("dt-nan", R + ["--integrator", "verlet", "--dt", "nan"], r"dt"),
    Cli("dt-negative", R + ["--integrator", "verlet", "--dt", "-0.01"], r"dt"),
    # -- precompression ----------------------------------------------------------------------------------
    Cli("precompression-empty", R + ["--precompression", ""], r"--precompression is empty: give a static force"),
    Cli("precompression-nan", R + ["--precompression", "nan"], r"--precompression must be finite"),
    Cli("precompression-inf", R + ["--precompression", "inf"], r"--precompression must be finite"),
    Cli("precompression-negative", R + ["--precompression", "-2"], r"--precompression must be finite and >= 0.*'-2'"),
    Cli("precompression-negative-unit", R + UNITS + ["--precompression", "-2N"], r"--precompression must be finite and >= 0.*'-2N'"),
    Cli("precompression-huge", R + ["--precompression", "1e300"], r"--precompression '1e300'.*exceeds 1e\+12"),
    Cli("precompression-unresolvable", R + ["--precompression", "1e10"], r"--precompression '1e10'.*too large for this chain"),
    Cli("precompression-unit-without-scale", R + ["--precompression", "2N"], r"has a unit: give the physical-unit options"),
    Cli("precompression-wrong-unit", R + UNITS + ["--precompression", "2kg"], r"needs a force"),
    Cli("precompression-garbage", R + ["--precompression", "@@"], r"neither a number nor a quantity"),
    Cli("precompression-nan-unit", R + UNITS + ["--precompression", "nan N"], r"must be finite|neither a number"),
    Cli("precompression-n-one", ["pulse", "--radii", "1,1,1", "--n", "1", "--precompression", "0.1"], r"need n > 1|n > 1"),
    # -- dissipation --------------------------------------------------------------------------------------
    Cli("dissipation-empty", R + ["--dissipation", ""], r"--dissipation is empty: give a damping time"),
    Cli("dissipation-nan", R + ["--dissipation", "nan"], r"--dissipation must be finite"),
    Cli("dissipation-negative", R + ["--dissipation", "-0.1"], r"--dissipation must be finite and >= 0.*'-0.1'"),
    Cli("dissipation-wrong-unit", R + UNITS + ["--dissipation", "2m"], r"needs a time"),
    Cli("dissipation-and-restitution", R + ["--dissipation", "0.1", "--restitution", "0.9@1"], r"not allowed with"),
    Cli("restitution-empty", R + ["--restitution", ""], r"--restitution takes E@V"),
    Cli("restitution-double-at", R + ["--restitution", "0.9@@1"], r"--restitution takes E@V"),
    Cli("restitution-no-at", R + ["--restitution", "0.9"], r"--restitution takes E@V"),
    Cli("restitution-e-text", R + ["--restitution", "high@1"], r"E = 'high' is not a finite number"),
    Cli("restitution-e-nan", R + ["--restitution", "nan@1"], r"not a finite number"),
    Cli("restitution-e-above-one", R + ["--restitution", "1.5@1"], r"must lie in \(0, 1\]"),
    Cli("restitution-e-zero", R + ["--restitution", "0@1"], r"must lie in \(0, 1\]"),
    Cli("restitution-e-tiny", R + ["--restitution", "0.001@1"], r"below 0.05"),
    Cli("restitution-speed-zero", R + ["--restitution", "0.9@0"], r"impact speed V must be > 0"),
    Cli("restitution-speed-nan", R + ["--restitution", "0.9@nan"], r"must be finite"),
    Cli("restitution-speed-huge", R + ["--restitution", "0.9@1e300"], r"outside"),
    Cli("restitution-speed-wrong-unit", R + UNITS + ["--restitution", "0.9@1kg"], r"needs a speed"),
    Cli("restitution-speed-unit-no-scale", R + ["--restitution", "0.9@1m/s"], r"has a unit"),
    # -- striker ------------------------------------------------------------------------------------------
    Cli("striker-mass-empty", R + ["--striker-mass", ""], r"--striker-mass is empty: give a mass"),
    Cli("striker-mass-nan", R + ["--striker-mass", "nan"], r"--striker-mass must be finite"),
    Cli("striker-mass-zero", R + ["--striker-mass", "0"], r"--striker-mass must be > 0"),
    Cli("striker-mass-negative", R + ["--striker-mass", "-3"], r"--striker-mass must be > 0.*'-3'"),
    Cli("striker-mass-huge", R + ["--striker-mass", "1e300"], r"--striker-mass '1e300'.*outside"),
    Cli("striker-mass-wrong-unit", R + UNITS + ["--striker-mass", "5m"], r"needs a mass"),
    Cli("striker-radius-negative", R + ["--striker-radius", "-1"], r"--striker-radius must be > 0"),
    Cli("striker-radius-tiny", R + ["--striker-radius", "1e-300"], r"--striker-radius.*too small"),
    Cli("striker-radius-inf", R + ["--striker-radius", "inf"], r"--striker-radius must be finite"),
    Cli("striker-both", R + ["--striker-mass", "1", "--striker-radius", "1"], r"not allowed with"),
    # -- wall, sensors ---------------------------------------------------------------------------------------
    Cli("wall-material-without-wall", R + ["--wall-material", "rigid"], r"--wall-material needs --wall"),
    Cli("wall-material-without-units", R + ["--wall", "--wall-material", "steel"], r"give the physical-unit options"),
    Cli("wall-material-unknown", R + UNITS + ["--wall", "--wall-material", "jelly"], r"unknown material"),
    Cli("sensor-empty", R + ["--sensor", ""], r"--sensor has an empty field"),
    Cli("sensor-float", R + ["--sensor", "1.5"], r"--sensor expects comma-separated whole numbers"),
    Cli("sensor-nan", R + ["--sensor", "nan"], r"--sensor expects comma-separated whole numbers"),
    Cli("sensor-inf", R + ["--sensor", "inf"], r"--sensor expects comma-separated whole numbers"),
    Cli("sensor-end", R + ["--sensor", "3"], r"no contact on one side"),
    Cli("sensor-zero", R + ["--sensor", "0"], r"no contact on one side"),
    # -- physical units -----------------------------------------------------------------------------------
    Cli("material-unknown", R + ["--material", "jelly", "--radius", "5mm", "--impact-speed", "1m/s"], r"unknown material"),
    Cli("material-missing-radius", R + ["--material", "steel", "--impact-speed", "1m/s"], r"need --radius"),
    Cli("radius-negative", R + ["--material", "steel", "--radius", "-5mm", "--impact-speed", "1m/s"], r"must be > 0"),
    Cli("radius-nan", R + ["--material", "steel", "--radius", "nan", "--impact-speed", "1m/s"], r"must be finite"),
    Cli("radius-wrong-unit", R + ["--material", "steel", "--radius", "5s", "--impact-speed", "1m/s"], r"needs a length"),
    Cli("impact-speed-zero", R + ["--material", "steel", "--radius", "5mm", "--impact-speed", "0"], r"must be > 0"),
    Cli("impact-speed-inf", R + ["--material", "steel", "--radius", "5mm", "--impact-speed", "inf"], r"must be finite"),
    Cli("E-in-GPa-number", R + ["--E", "200", "--nu", "0.3", "--rho", "7850", "--radius", "5mm", "--impact-speed", "1m/s"],
        r"outside 1e5..2e12 Pa"),
    Cli("nu-half", R + ["--E", "200GPa", "--nu", "0.5", "--rho", "7850", "--radius", "5mm", "--impact-speed", "1m/s"],
        r"\(-1, 0.5\)"),
    Cli("E-and-material", R + UNITS + ["--E", "200GPa"], r"not both"),
]


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_bad_input_is_refused_clearly(case, tmp_path):
    check(case, tmp_path)
