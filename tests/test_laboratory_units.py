"""A laboratory chain in physical units: stainless-steel beads of the embedded-sensor experiments.

C. Daraio, V. F. Nesterenko, E. B. Herbold and S. Jin, Phys. Rev. E 73, 026610 (2006) measured the
speed of solitary waves against their force amplitude in chains of stainless-steel beads
(``granchain.units.STAINLESS_STEEL``: E = 193 GPa, nu = 0.3, rho = 8000 kg/m^3; here beads of
D = 4.76 mm, 3/16 in, a standard bearing-ball size), without and with a static load, and found it in agreement with Nesterenko's
long-wavelength theory (as did C. Coste, E. Falcon and S. Fauve, Phys. Rev. E 56, 6104 (1997), with
steel beads). The measured points themselves are not available to this test-suite (only the papers'
abstracts could be consulted), so what is checked here is the chain of conversions that a comparison
with them needs: a chain built and struck in SI units (``granchain.units``: the force, mass, time
and length units of the rescaled equation), integrated, and its wave speed in m/s and force
amplitude in N compared with that theory in SI units, within the discreteness difference of the
discrete chain from the long-wavelength limit (measured: +1.25 % at equal force amplitude without
load, the same at every amplitude: a pure number of the discrete chain, V. F. Nesterenko, *Dynamics
of Heterogeneous Materials*, Springer 2001, Sec. 1.3).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import granchain as gc
from granchain.units import STAINLESS_STEEL as STEEL

D = 4.76e-3  # bead diameter, m
E_RED = 2.0 * STEEL.E / (D * (1.0 - STEEL.nu**2))  # 2E / (D (1 - nu^2)), Pa / m


def uncompressed_speed(force_amplitude: float) -> float:
    """Nesterenko's solitary wave in an unloaded chain: V_s = 0.6802 (2E / (D (1 - nu^2)))^(1/3)
    F_m^(1/6) rho^(-1/2) (m/s, F_m in N)."""
    return 0.6802 * E_RED ** (1.0 / 3.0) * force_amplitude ** (1.0 / 6.0) / math.sqrt(STEEL.rho)


def sound_speed(static_force: float) -> float:
    """c0 = D sqrt(k0 / m) with k0 = (3/2) A^(2/3) F0^(1/3), A = E D^(1/2) / (3 (1 - nu^2)) and
    m = pi rho D^3 / 6: 0.931456 (2E / (D (1 - nu^2)))^(1/3) F0^(1/6) rho^(-1/2) (m/s)."""
    a = STEEL.E * math.sqrt(D) / (3.0 * (1.0 - STEEL.nu**2))
    k0 = 1.5 * a ** (2.0 / 3.0) * static_force ** (1.0 / 3.0)
    return D * math.sqrt(k0 / (math.pi * STEEL.rho * D**3 / 6.0))


def precompressed_speed(force_amplitude: float, static_force: float) -> float:
    """Nesterenko's long-wavelength solitary wave on a static load F0 (f_r = F_m / F0):
    V_s = c0 (f_r^(2/3) - 1)^(-1) [4/15 (3 + 2 f_r^(5/3) - 5 f_r^(2/3))]^(1/2)."""
    fr = force_amplitude / static_force
    return sound_speed(static_force) / (fr ** (2 / 3) - 1.0) * math.sqrt(4.0 / 15.0 * (3.0 + 2.0 * fr ** (5 / 3) - 5.0 * fr ** (2 / 3)))


def measured(chain: gc.Chain, scale, first: int = 21, last: int = 40):
    """(wave speed in m/s, force amplitude in N) over granules first..last of a monodisperse chain: the
    speed from the peak times (``PulseResult.wave_speed``, centres 2R apart), the amplitude the mean
    peak force of the contacts there (total force, static load included, as a gauge measures it)."""
    res = gc.simulate(chain, gc.DP5(1e-10, 1e-12))
    assert res.ok
    speed = scale.wave_speed_si(res.wave_speed(first, last))
    return speed, float(np.mean(res.peak_force[first - 1:last - 1])) * scale.force


def test_the_constants_of_the_long_wave_theory():
    """The two prefactors are one theory: the precompressed speed tends to the unloaded one as f_r grows
    (0.931456 sqrt(8/15) = 0.68024), and tends to the sound speed as f_r -> 1."""
    assert sound_speed(1.0) / (E_RED ** (1 / 3) / math.sqrt(STEEL.rho)) == pytest.approx(0.931456, rel=1e-6)
    assert precompressed_speed(1e9, 1.0) / uncompressed_speed(1e9) == pytest.approx(1.0, rel=2e-3)
    assert precompressed_speed(1.0 + 1e-3, 1.0) / sound_speed(1.0) == pytest.approx(1.0, abs=1e-3)  # ~(f_r - 1) / 18 above c0


@pytest.mark.parametrize("impact_speed", [0.1, 0.5, 2.0])
def test_unloaded_stainless_steel_chain_in_si_units(impact_speed):
    """Struck at 0.1, 0.5 and 2 m/s (force amplitudes ~3, ~21 and ~110 N, the experiments' range) the wave
    speed in m/s is Nesterenko's V_s(F_m) in SI units +1.25 % (the discrete chain's own difference,
    the same at every amplitude because the unloaded chain has no scale: V_s ~ F_m^(1/6) exactly).
    A wrong force or time unit would move the ratio by far more than the 0.1 % allowed around it,
    and differently at each amplitude."""
    s = gc.units.scale(STEEL, D / 2, impact_speed)
    speed, fm = measured(gc.monodisperse(60), s)
    assert speed / uncompressed_speed(fm) == pytest.approx(1.0125, abs=1e-3)


@pytest.mark.parametrize("static_n, impact_speed", [(2.0, 0.3), (2.0, 1.0)])
def test_precompressed_stainless_steel_chain_in_si_units(static_n, impact_speed):
    """Under a static load of 2 N (given in newtons, converted with ``Scale.to_rescaled``) a pulse of
    f_r = F_m / F0 ~ 5.6 and ~17 travels at Nesterenko's long-wave speed within 1.5 % (the discreteness
    difference shrinks from the unloaded +1.25 % as the pulse widens, measured +0.1 % and +0.6 %), and
    faster than the unloaded chain's wave of the same amplitude (the load stiffens the contacts). Negative
    control: the unloaded theory misses the loaded chain by several per cent at f_r ~ 5.6."""
    s = gc.units.scale(STEEL, D / 2, impact_speed)
    chain = gc.monodisperse(60).with_precompression(s.to_rescaled(f"{static_n} N", "force"))
    speed, fm = measured(chain, s)
    assert speed / precompressed_speed(fm, static_n) == pytest.approx(1.0, abs=0.015)
    assert speed > uncompressed_speed(fm)
    if fm / static_n < 8:
        assert abs(speed / uncompressed_speed(fm) - 1.0125) > 0.03
