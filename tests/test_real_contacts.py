"""Real contacts: a static load, viscoelastic dissipation, a striker, several materials and a wall,
validated against physics that does not come from the kernels, and against the independent SciPy
reference.

1. Neutral elements. A static force F0 = 0 and a damping time gamma = 0 leave every result of the
   paper's chain bitwise unchanged (DP5, RKN4, the trailing window, free and walled chains).
2. Precompression. (a) the static state is an exact equilibrium in floating point; (b) a small pulse
   travels at the sound speed c0 = sqrt((n-1) c delta0^(n-2) / m), its peak lagging the front as the
   Airy front of a linear lattice does; (c) the solitary wave's speed against Nesterenko's
   long-wavelength formula at f_r = F_max / F0 = 2, 5, 20 (the discreteness difference grows with f_r
   towards the uncompressed chain's); (d) F0 -> 0 gives the uncompressed chain's speed, the
   difference falling like F0^(2/3).
3. Dissipation (Kuwabara-Kono / Brilliantov et al. law). (a) a two-sphere collision in the kernels
   has the coefficient of restitution of the two-body solve of ``granchain.model.collision`` and, for
   n = 2, of the closed-form damped oscillator; (b) the small-damping series: C1 = 1.15345 in closed
   form, e - e_leading = O(gamma^2) with the coefficient (3/5) C1^2; (c) 1 - e ~ v^(1/5); (d) energy
   balance E_kin + E_pot + E_diss = E_0 on a decorated chain; (e) the pulse decays along a
   monodisperse chain as v^(-1/5) linear in the granule (Hertz scaling), faster for larger gamma;
   (f) calibration from a coefficient of restitution.
4. The compiled kernels against DOP853 at rtol 1e-11 on random decorated chains with each law and
   all of them together: peaks, forces, dissipated energy.
5. Bad input: every refusal says what to change.
6. The trailing window on a dissipative chain, and its switching off on a precompressed one.
7. Sensors and the wall force against momentum balance (F = -dP/dt from the recorded velocities).

Three tests here found faults that are fixed: the dissipated energy of DP5 over a force-free,
still-overlapping phase (its error now steers the step), the wall force of the compiled kernels on a
precompressed chain before the integration window reaches the wall (the static load, not 0), and
gamma = 0 refused by RKN4 (the viscoelastic law without damping is conservative).
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest
from conftest import chain_energy, in_order
from scipy.special import beta as beta_function
from scipy.special import gamma as gamma_function

import granchain as gc
from granchain.model import collision
from granchain.model.contacts import Precompression, Viscoelastic


def nesterenko_speed_ratio(f_r):
    """V_s / c0 of Nesterenko's long-wavelength solitary wave in a chain precompressed by F0, with
    f_r = F_m / F0 the ratio of the wave's maximum (total) contact force to the static one
    (V. F. Nesterenko, *Dynamics of Heterogeneous Materials*, Springer 2001, Sec. 1.3; the form used by
    C. Daraio et al., Phys. Rev. E 73, 026610 (2006))."""
    f = np.asarray(f_r, dtype=float)
    return (f ** (2 / 3) - 1) ** -1 * np.sqrt(4 / 15 * (3 + 2 * f ** (5 / 3) - 5 * f ** (2 / 3)))


def two_sphere_restitution(gamma, speed, integrator, n=2.5):
    """e = -(v2 - v1)_end / v0 of two unit spheres (masses 1, contact prefactor 1, Eq. r-prime) with
    the viscoelastic law, integrated by ``simulate`` (the kernels under test)."""
    chain = gc.from_radii([1.0, 1.0], n=n, initial_velocity=speed).with_dissipation(gamma)
    res = gc.simulate(chain, integrator)
    assert res.ok, res.message
    return (res.velocities[1] - res.velocities[0]) / speed, res


TIGHT = gc.DP5(rtol=1e-12, atol=1e-14)


# -- 1. neutral elements -----------------------------------------------------------------------------
NEUTRAL_CHAINS = {
    "random decorated": lambda: gc.random_decorated(6, gc.Uniform(0.01, 0.4), seed=3),
    "decorated + wall": lambda: gc.decorated([0.3, 0.1, 0.2]).with_wall(),
    "monodisperse + wall": lambda: gc.monodisperse(8, wall=True),
}
NEUTRAL_LAWS = {
    "F0 = 0": lambda c: c.with_precompression(0.0),
    "gamma = 0": lambda c: c.with_dissipation(0.0),
    "F0 = 0, gamma = 0": lambda c: c.with_precompression(0.0).with_dissipation(0.0),
}
def neutral_cases():
    for integ_name, integ in [("dp5", gc.DP5()), ("rkn4", gc.RKN4()), ("dp5.windowed", gc.DP5.windowed())]:
        for law in NEUTRAL_LAWS:
            yield pytest.param(integ, law, id=f"{integ_name}-{law}")


@pytest.mark.parametrize("chain_name", list(NEUTRAL_CHAINS))
@pytest.mark.parametrize("integrator, law", list(neutral_cases()))
def test_zero_load_and_zero_damping_are_the_paper_chain_bitwise(chain_name, integrator, law):
    """F0 = 0 and gamma = 0 are the paper's chain: every number ``simulate`` returns (peaks, times,
    forces and their times, grid velocities, wall force, final state, energy and momentum errors, step
    counts, stop time, the integrator as it ran) is bitwise the plain chain's, and nothing is
    dissipated.

    How it could fail: any extra arithmetic on the elastic path (a static force 0 subtracted in another
    branch, a damping term 0 * gamma * w added, a force routine chosen by the law's class rather than
    its value, a goal-control or stop rule that reads the load) changes bits somewhere in a run of
    thousands of steps, or changes the step sequence itself."""
    chain = NEUTRAL_CHAINS[chain_name]()
    variant = NEUTRAL_LAWS[law](chain)
    assert variant.elastic and variant.static_force == 0.0 and variant.contact.gamma == 0.0
    grid = np.linspace(0.0, 20.0, 101)
    plain = gc.simulate(chain, integrator, t_grid=grid)
    res = gc.simulate(variant, integrator, t_grid=grid)
    assert plain.ok and res.ok
    for name in ("peak_velocity", "peak_time", "peak_force", "peak_force_time", "velocity", "positions", "velocities"):
        np.testing.assert_array_equal(getattr(res, name), getattr(plain, name), err_msg=name)
    if chain.wall:
        np.testing.assert_array_equal(res.wall_force, plain.wall_force)
        assert (res.peak_wall_force, res.wall_impulse) == (plain.peak_wall_force, plain.wall_impulse)
    assert res.energy_error == plain.energy_error
    np.testing.assert_array_equal(res.momentum_error, plain.momentum_error)  # NaN (a wall) equals NaN here
    for name in ("n_steps", "n_rejected", "t_end", "exit_time"):
        assert getattr(res, name) == getattr(plain, name), name
    assert res.integrator_record == plain.integrator_record
    assert res.dissipated_energy == 0.0


# -- 2. precompression -----------------------------------------------------------------------------
@pytest.mark.parametrize("wall", [False, True], ids=["loaded end", "wall"])
@pytest.mark.parametrize("integrator", [gc.DP5(), gc.DOP853()], ids=["dp5", "dop853"])
def test_static_state_is_an_exact_equilibrium(wall, integrator):
    """A precompressed chain struck at granule 1: the granules the pulse has not reached are exactly
    at rest, in velocity and displacement, on the grid and at the end (t = 3: the pulse around granule
    5 of 59), and the sensors ahead read a constant force, the static load.

    Why this proves the static state is an equilibrium in floating point: a random decorated chain has
    a different contact prefactor c_k at almost every contact, and for most of them
    c_k ((F0/c_k)^(2/3))^(3/2) differs from F0 by an ulp (checked below: the control). Had the kernels
    balanced the contacts against F0 itself, or against a static force computed by other arithmetic
    than the dynamic one, every granule would feel a net force of ~1e-17 from t = 0 and move by
    ~1e-17 t: not exactly 0. DOP853 integrates every granule from t = 0, so it sees such a residual
    everywhere; DP5 integrates the granules its window has reached. A genuine precursor of the
    pulse cannot reach them either: displacements below ulp(delta0) ~ 1e-17 do not change
    delta0 + D, so nothing propagates ahead of ~20 granules in this time (measured: granule 15 at
    5e-13, granule 20 and beyond exactly 0). The sensors there read a constant total force, F0 to
    rounding (each contact's static force is c_k delta0_k^(3/2), not F0 bitwise)."""
    chain = gc.random_decorated(30, gc.Uniform(0.01, 0.4), seed=5).with_precompression(0.05).replace(initial_velocity=0.05)
    if wall:
        chain = chain.with_wall()
    c, F0, n = chain.stiffness, chain.static_force, chain.n
    naive = c * ((F0 / c) ** (1 / (n - 1))) ** (n - 1) - F0
    assert np.count_nonzero(naive) > 20, "control: the chain must have contacts whose static force is not F0 bitwise"

    grid = np.linspace(0.0, 3.0, 31)
    far = np.flatnonzero(chain.observed >= 20)  # observed granules from array index 20 on
    sensors = chain.labels[far][:-1]  # every one of them has two contacts
    res = gc.simulate(chain, integrator, t_grid=grid, t_max=3.0, stop="t_max", sensors=sensors)
    assert res.ok
    moving = chain.size - int(wall)
    assert np.all(res.velocities[20:moving] == 0.0) and np.all(res.positions[20:moving] == 0.0)
    assert np.all(res.velocity[far] == 0.0)
    # the static forces by the law's own arithmetic: F0 to rounding, and not changing at all
    np.testing.assert_array_equal(res.sensor_force, np.repeat(res.sensor_force[:, :1], grid.size, axis=1))
    np.testing.assert_allclose(res.sensor_force, F0, rtol=1e-15)
    assert np.any(res.velocities[:10] != 0.0)  # the pulse did start
    np.testing.assert_array_equal(chain.overlaps, (F0 / c) ** (1 / (n - 1)))


SOUND_N = 200
#: Ai(0) / max Ai: the point of an Airy front that moves at the front's speed.
AIRY_FRONT_FRACTION = 0.355028053887817 / 0.535656656015700


@functools.cache
def small_pulse(static_force: float):
    """A monodisperse chain of 200 under F0, struck with v0 = 1e-3 F0^(5/6) (the same small amplitude
    relative to the static strain for every F0: delta -> delta0 u, t -> delta0^(-1/4) s, v -> F0^(5/6) w
    leave the Hertz chain invariant), observed every 10th granule from 40 to 160, integrated until a
    linear wave is 10 granules from the end. DP5's absolute tolerance is scaled with v0 (its default
    1e-10 is in units where the impact speed is 1: with v0 = 2e-5 the energy error is then 4e-4, and
    the two loads' runs agree only to 5e-7)."""
    v0 = 1e-3 * static_force ** (5 / 6)
    chain = gc.monodisperse(SOUND_N).with_precompression(static_force).replace(initial_velocity=v0)
    chain = chain.with_observed(np.arange(40, 161, 10))
    c0 = chain.precompression.sound_speed()
    t_end = (SOUND_N - 10) / c0
    grid = np.arange(0.0, t_end, 0.01 / c0)
    res = gc.simulate(chain, gc.DP5(rtol=1e-8, atol=1e-10 * v0), t_grid=grid, t_max=t_end, stop="t_max")
    assert res.ok and abs(res.energy_error) < 1e-7
    return chain, c0, res


def front_arrival(res, fraction):
    """Per observed granule, the first time its velocity reaches ``fraction`` of its peak (linear
    interpolation between grid samples: error ~1e-4 time units on this grid)."""
    t = res.t_grid
    out = []
    for v, vp in zip(res.velocity, res.peak_velocity):
        i = int(np.argmax(v >= fraction * vp))
        assert i > 0
        out.append(t[i - 1] + (fraction * vp - v[i - 1]) / (v[i] - v[i - 1]) * (t[i] - t[i - 1]))
    return np.array(out)


@pytest.mark.parametrize("static_force", [1.0, 1e-2])
def test_small_pulse_travels_at_the_sound_speed(static_force):
    """A small pulse (v0 / (c0 delta0) ~ 1e-3) on a precompressed monodisperse chain is a linear wave:
    its front travels at c0 = sqrt((n-1) c delta0^(n-2) / m) = sqrt(3/2) F0^(1/6) (Hertz, c = m = 1).

    What is measured, and why it is robust: a linear lattice struck at one granule disperses; granule
    k's velocity is a Bessel function J_2k(2 c0 t) (and its image at the free end), whose leading
    edge is an Airy front J_nu(nu + z nu^(1/3)) ~ (2/nu)^(1/3) Ai(-2^(1/3) z). The front's z = 0 point,
    where the velocity first reaches Ai(0)/max Ai = 0.663 of its peak, moves at exactly c0; the peak
    itself lags by 0.8086 (2k)^(1/3) / (2 c0), so that a speed fitted to peak times is slow by
    ~0.17 k^(-2/3) (0.8 % here). Measured over granules 40..160: front speed / c0 - 1 = -3.4e-4
    (tolerance 2e-3; a 1 % error of c0 fails); the peak lag's k^(1/3) coefficient times c0 = 0.523
    against Airy's 0.509 (+2.6 %, higher orders of the expansion at k ~ 100; tolerance 6 %);
    and the two loads give the same scaled peaks to 1.2e-12 (tolerance 1e-9): a check that the load
    enters the kernels only through delta0, as Hertz's homogeneity demands."""
    chain, c0, res = small_pulse(static_force)
    assert c0 == pytest.approx(math.sqrt(1.5) * static_force ** (1 / 6), rel=1e-14)
    assert c0 == pytest.approx(math.sqrt(1.5 * chain.overlaps[0] ** 0.5), rel=1e-15)
    k = res.granule.astype(float)
    speed = 1.0 / np.polyfit(k, front_arrival(res, AIRY_FRONT_FRACTION), 1)[0]
    assert speed / c0 - 1 == pytest.approx(0.0, abs=2e-3)
    # The peak lags the front like an Airy front: t_peak - k / c0 = a + b k^(1/3), b c0 = 0.8086 2^(1/3) / 2.
    _, b = np.linalg.lstsq(np.c_[np.ones_like(k), k ** (1 / 3)], res.peak_time - k / c0, rcond=None)[0]
    assert b * c0 == pytest.approx(0.8086 * 2 ** (1 / 3) / 2, rel=0.06)
    assert res.wave_speed() < c0  # so a speed from peak times alone would be off by ~1 %
    # Hertz homogeneity: F0 = 1e-2 is F0 = 1 rescaled (times by F0^(-1/6), velocities by F0^(5/6)).
    _, c1, ref = small_pulse(1.0)
    np.testing.assert_allclose(res.peak_time * c0, ref.peak_time * c1, rtol=1e-9)
    np.testing.assert_allclose(res.peak_velocity / static_force ** (5 / 6), ref.peak_velocity, rtol=1e-9)


#: Impact speeds on a monodisperse chain under F0 = 1 that give f_r ~ 2, 5, 20 (found by trial), and
#: the chain lengths over which the wave forms (f_r = 2 is a broad, slowly forming wave).
SOLITARY = {2: (2.0, 400), 5: (5.6, 150), 20: (18.5, 150)}


@functools.cache
def precompressed_solitary_wave(f_target: int):
    """(f_r, V_s / c0, V_s / c0 over the first and the second half of the window) of the wave struck
    into a monodisperse chain under F0 = 1, measured over its middle third to last 15 granules."""
    v0, size = SOLITARY[f_target]
    chain = gc.monodisperse(size).with_precompression(1.0).replace(initial_velocity=v0)
    c0 = chain.precompression.sound_speed()
    res = gc.simulate(chain, t_max=(size - 5) / c0, stop="t_max")
    assert res.ok
    lo, hi = size // 3, size - 15
    mid = (lo + hi) // 2
    f_r = float(np.mean(res.peak_force[lo - 1:hi])) / chain.static_force  # contacts lo..hi, total force
    return (f_r, res.wave_speed(lo, hi) / c0, res.wave_speed(lo, mid) / c0, res.wave_speed(mid, hi) / c0)


@functools.cache
def uncompressed_solitary_wave():
    """(V_s, F_m, the F0 = 0 run) of the paper's chain: 80 granules, v0 = 1, measured over 30..65."""
    res = gc.simulate(gc.monodisperse(80))
    assert res.ok
    return res.wave_speed(30, 65), float(np.mean(res.peak_force[29:65])), res


def test_precompressed_solitary_wave_speed_against_nesterenko():
    """The solitary wave's speed V_s / c0 against Nesterenko's long-wavelength formula at the measured
    f_r = F_m / F0 (F_m the wave's maximum total contact force: f_r -> 1 is the linear limit
    V_s -> c0), for f_r ~ 2, 5, 20.

    Measured (speed from peak times over the window where the wave has formed; the two halves of the
    window agree within 1.7e-5, 9e-6 and 4e-9 at f_r = 2, 5, 20): f_r = 1.957, 5.091, 20.33 give
    V_s / V_Nesterenko - 1 = +0.031 %, +0.214 %, +0.577 %. The discrete wave is a little faster than the
    long-wave one at the same force, more so as it narrows (larger f_r), and the difference tends to
    the uncompressed chain's, measured here too: V_s / ((2/sqrt 5) F_m^(1/6)) - 1 = +1.240 % (0.90552
    against 0.89443; literature notes: the same +1.24 % from an independent script). So the test asks:
    each within 1 % of the formula (a wrong c0, overlap or force unit is off by more: c0 enters at the
    power 1, the overlap at 1/4), the difference growing with f_r, and below the uncompressed limit.
    How it could fail: a static force not included in the reported peak (f_r off by 1), a c0 or an
    overlap from the wrong exponent, a wave that does not form (halves disagree)."""
    measured = {f: precompressed_solitary_wave(f) for f in SOLITARY}
    diffs = []
    for f_target, (f_r, speed, first, second) in measured.items():
        assert f_r == pytest.approx(f_target, rel=0.05), "the impact no longer gives the f_r the table was made for"
        assert first == pytest.approx(second, rel=1e-4), f"the wave at f_r = {f_r:.3g} has not formed"
        diff = speed / float(nesterenko_speed_ratio(f_r)) - 1
        assert abs(diff) < 0.01, f"f_r = {f_r:.4g}: V_s/c0 = {speed:.6f}, {diff:+.4%} off Nesterenko's"
        diffs.append(diff)
    speed0, force0, _ = uncompressed_solitary_wave()
    limit = speed0 / (2 / math.sqrt(5) * force0 ** (1 / 6)) - 1
    assert limit == pytest.approx(0.0124, abs=0.001)
    assert diffs[0] < diffs[1] < diffs[2] < limit, (diffs, limit)
    assert diffs[0] > -0.002


def test_vanishing_precompression_gives_the_uncompressed_wave():
    """The same impact (v0 = 1) on chains under F0 = 1e-2 .. 1e-8 against the F0 = 0 chain: the wave's
    speed converges to the uncompressed one, the relative difference falling like F0^(2/3).

    Why F0^(2/3): Nesterenko's formula for f_r >> 1 is V_s / c0 = (8/15)^(1/2) f_r^(1/6) (1 + f_r^(-2/3) + ...),
    and the leading term is the uncompressed V_s = (2/sqrt 5) F_m^(1/6); so the load's correction is
    (F0/F_m)^(2/3) at leading order. Measured: +3.7e-2, 8.8e-3, 2.0e-3, 4.3e-4, 9.5e-5, 4.4e-6 at F0 =
    1e-2 .. 1e-6 and 1e-8 (difference / (F0/F_m)^(2/3) = 0.60 .. 0.71, the discrete wave's coefficient),
    the fitted exponent over 1e-4 .. 1e-8 0.663 (tolerance 0.05). How it could fail: a precompressed
    chain that does not reduce to the paper's as F0 -> 0 (a floor of the static overlap, a sound-speed
    or overlap formula used where it does not apply), or a correction of another order."""
    speed0, force0, plain = uncompressed_solitary_wave()
    loads = np.array([1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-8])
    diffs = []
    for F0 in loads:
        res = gc.simulate(plain.chain.with_precompression(F0), t_max=plain.peak_time[-1] + 5, stop="t_max")
        assert res.ok
        diffs.append(res.wave_speed(30, 65) / speed0 - 1)
    diffs = np.array(diffs)
    assert np.all(diffs > 0) and np.all(np.diff(diffs) < 0), diffs
    assert diffs[-1] < 1e-5
    small = loads <= 1e-4
    slope = np.polyfit(np.log(loads[small]), np.log(diffs[small]), 1)[0]
    assert slope == pytest.approx(2 / 3, abs=0.05)
    assert np.all((diffs / (loads / force0) ** (2 / 3) > 0.5) & (diffs / (loads / force0) ** (2 / 3) < 1.0))


# -- 3. dissipation ------------------------------------------------------------------------------------
@pytest.mark.parametrize("speed", [0.01, 1.0, 10.0])
@pytest.mark.parametrize("gamma", [0.01, 0.1, 0.5, 2.0])
def test_two_sphere_restitution_is_the_two_body_solution(gamma, speed):
    """Two unit spheres with the viscoelastic law, integrated by the kernels (DP5 at rtol 1e-12) to the
    end of the collision, bounce with e = -(v2 - v1) / v0 equal to ``collision.restitution`` (SciPy's
    DOP853 on the two-body equation mu delta'' = -F, ending where the force vanishes): they share no
    code but the law. Over gamma 0.01..2 and v0 0.01..10 (e from 0.99 to 0.09) the two agree within
    8e-11 (tolerance 1e-9); momentum is conserved to round-off. How it could fail: a damping term with
    the wrong power of delta, sign or rate (the relative velocity of the pair), a force not clamped at
    0 (the spheres would stick or pull), a clamp in the wrong place."""
    e, res = two_sphere_restitution(gamma, speed, TIGHT)
    assert 0.0 < e < 1.0
    assert e == pytest.approx(collision.restitution(gamma, speed), abs=1e-9)
    assert abs(res.momentum_error) < 1e-14
    assert res.dissipated_energy > 0.0


@pytest.mark.parametrize("gamma", [0.05, 0.3])
def test_linear_dashpot_restitution_closed_form(gamma):
    """n = 2: F = c (delta + gamma delta'), a damped oscillator mu delta'' = -c delta - c gamma delta',
    delta(t) = (v/w) exp(-z w0 t) sin(w t), w0^2 = c/mu, z = gamma w0 / 2, w = w0 sqrt(1 - z^2). The
    collision ends where the force vanishes, delta + gamma delta' = 0 (root found here on the closed
    form), not where delta does; e = -delta'(end) / v, the same at every speed (the equation is linear).
    Both ``collision.restitution`` (the kernels' reference) and the kernels (two spheres, n = 2) must
    give it: within 1e-10 and 1e-9 (measured 1e-11 and 4e-11; e = 0.89705 and 0.55480). How it could
    fail: the end of the contact taken at delta = 0 (e = 0.89481 and 0.50563: lower by 0.25 % and
    9 %), a rate term with the wrong factor, the reference wrong in the same way as the kernels (it is
    checked against algebra here)."""
    from scipy.optimize import brentq

    mu, c = 0.5, 1.0
    w0 = math.sqrt(c / mu)
    z = gamma * w0 / 2
    w = w0 * math.sqrt(1 - z * z)

    def delta(t, v):
        return v / w * math.exp(-z * w0 * t) * math.sin(w * t)

    def rate(t, v):
        return v * math.exp(-z * w0 * t) * (math.cos(w * t) - z * w0 / w * math.sin(w * t))

    for v in (0.3, 1.0, 4.0):
        t_end = brentq(lambda t, v=v: delta(t, v) + gamma * rate(t, v), 0.5 * math.pi / w, math.pi / w, xtol=1e-15)
        exact = -rate(t_end, v) / v
        assert collision.restitution(gamma, v, n=2.0) == pytest.approx(exact, abs=1e-10)
        e, _ = two_sphere_restitution(gamma, v, TIGHT, n=2.0)
        assert e == pytest.approx(exact, abs=1e-9)
    assert exact > math.exp(-z * math.pi / math.sqrt(1 - z * z))  # ends before delta = 0: less is lost


def test_kuwabara_kono_constant():
    """C1 of 1 - e = C1 gamma (c/mu)^(2/5) v^(1/5) + ... (n = 5/2): the module's constant equals the
    closed form sqrt(pi) Gamma(3/5) / (2^(1/5) 5^(2/5) Gamma(21/10)) (evaluated here with SciPy's Gamma)
    and the same number reached another way, the damping's work along the elastic collision,
    (4/5) (5/4)^(3/5) B(3/5, 3/2) (to 1e-14); and the printed 1.15345 (T. Schwager and T. Poschel, Phys.
    Rev. E 57, 650 (1998); R. Ramirez et al., Phys. Rev. E 60, 4465 (1999)) to its last digit.
    ``restitution_leading_order`` is that law for any masses and stiffness (1e-14). The ODE gives it too:
    (1 - e) / beta + C2 beta with C2 = (3/5) C1^2 at beta = 1.3e-4 is C1 within 3.9e-7 (tolerance 2e-6;
    the next term is O(beta^(3/2)))."""
    closed = math.sqrt(math.pi) * gamma_function(0.6) / (2 ** 0.2 * 5 ** 0.4 * gamma_function(2.1))
    work = 0.8 * 1.25 ** 0.6 * beta_function(0.6, 1.5)
    assert collision.KUWABARA_KONO_C1 == pytest.approx(closed, rel=1e-15)
    assert collision.KUWABARA_KONO_C1 == pytest.approx(work, rel=1e-14)
    assert round(collision.KUWABARA_KONO_C1, 5) == 1.15345
    C1 = collision.KUWABARA_KONO_C1
    for mass, stiffness, v in [(1.0, 1.0, 1.0), ((1.0, 0.3), 0.7, 0.2), ((2.0, 5.0), 1.9, 7.0)]:
        m = np.broadcast_to(np.asarray(mass, dtype=float), (2,))
        mu = m[0] * m[1] / (m[0] + m[1])
        g = 0.03
        lo = collision.restitution_leading_order(g, v, mass=mass, stiffness=stiffness)
        assert lo == pytest.approx(1 - C1 * g * (stiffness / mu) ** 0.4 * v ** 0.2, rel=1e-14)
    g = 1e-4
    b = g * 2 ** 0.4  # mu = 1/2, c = 1, v = 1
    e = collision.restitution(g, 1.0)
    assert (1 - e) / b + 0.6 * C1 ** 2 * b == pytest.approx(C1, abs=2e-6)


def test_small_damping_restitution_is_second_order_off_the_leading_order():
    """e - e_leading = C2 beta^2 + ..., beta = gamma (c/mu)^(2/5) v^(1/5): the leading-order law is exact
    to first order in gamma. Measured (e - e_leading) / beta^2 at gamma = 1e-2, 1e-3, 1e-4 (v = 1):
    0.8214, 0.8072, 0.8012, at v = 0.1: 0.8179, 0.8055, 0.8007: the difference falls 100-fold per
    decade of gamma, its coefficient tending from above to (3/5) C1^2 = 0.79827 (Ramirez et al. 1999;
    literature notes, derived), which the extrapolation beta -> 0 gives within 1.4e-4 (C2(beta) =
    C2 + a beta^(1/2), the measured approach, through gamma = 9e-4 and 1e-4: 0.79841). Tolerances:
    coefficient within
    [0.798, 0.825]; extrapolation within 2e-3. How it could fail: a leading-order law with the wrong
    constant or exponent (the ratio would diverge like 1/beta), a first-order error of the two-body
    solve."""
    C2 = 0.6 * collision.KUWABARA_KONO_C1 ** 2
    for v in (1.0, 0.1):
        ratios = []
        gammas = [1e-2, 1e-3, 1e-4]
        for g in gammas:
            b = g * 2 ** 0.4 * v ** 0.2
            ratios.append((collision.restitution(g, v) - collision.restitution_leading_order(g, v)) / b**2)
        ratios = np.array(ratios)
        assert np.all((ratios > 0.798) & (ratios < 0.825)), ratios
        assert np.all(np.diff(ratios) < 0), ratios
    g1, g2 = 9e-4, 1e-4
    r1, r2 = [(collision.restitution(g, 1.0) - collision.restitution_leading_order(g, 1.0)) / (g * 2 ** 0.4) ** 2
              for g in (g1, g2)]
    s1, s2 = math.sqrt(g1 * 2 ** 0.4), math.sqrt(g2 * 2 ** 0.4)
    extrapolated = r2 - (r1 - r2) / (s1 - s2) * s2
    assert extrapolated == pytest.approx(C2, abs=2e-3)


def test_one_minus_restitution_grows_as_the_fifth_root_of_the_speed():
    """The Kuwabara-Kono law: 1 - e ~ C1 gamma (c/mu)^(2/5) v^(1/5). From the kernels (two spheres, DP5 at
    rtol 1e-12, gamma = 1e-3) at five speeds over two decades, 0.01..1: the fitted exponent is 0.19988
    (the second-order term lowers it by (C2/C1) beta / 5 ~ 1.1e-4, beta ~ 8e-4 over these speeds);
    tolerance 1e-3, 8x the measured deviation (a Hertz exponent other than 5/2, or damping not
    ~ delta^(1/2), moves it by more than 0.01). A linear dashpot (n = 2) gives
    exponent 0 (test above: e independent of v): the negative control of what the fit sees."""
    speeds = np.logspace(-2, 0, 5)
    loss = [1 - two_sphere_restitution(1e-3, v, TIGHT)[0] for v in speeds]
    slope = np.polyfit(np.log(speeds), np.log(loss), 1)[0]
    assert slope == pytest.approx(0.2, abs=1e-3)
    loss2 = [1 - two_sphere_restitution(0.05, v, TIGHT, n=2.0)[0] for v in (0.1, 1.0, 10.0)]
    assert np.ptp(loss2) < 1e-9


def test_energy_balance_on_a_dissipative_decorated_chain(energy_of):
    """E_kin + E_pot + E_diss = E_0 on a random decorated chain (light granules rattling and colliding
    again and again) with gamma = 0.05, DP5 at rtol 1e-12: |energy_error| = 3.5e-11 (tolerance 1e-8),
    and ``energy_error`` is that balance recomputed here from the final state in plain NumPy
    (``conftest.chain_energy``) and ``dissipated_energy`` (to round-off). The dissipated energy is
    also DOP853's (rtol 1e-13, the dissipated energy one more component of its state) at a common end
    time t = 15: measured 7.9e-10 apart (relative; tolerance 1e-8). How it could fail: dissipated power
    not (F - F_elastic) d(delta)/dt, a clamped phase not counted, a quadrature of the wrong order or
    on the wrong stages (DP5's is its 5th-order weights on the stages' powers)."""
    chain = gc.random_decorated(8, gc.Uniform(0.01, 0.4), seed=4).with_dissipation(0.05)
    res = gc.simulate(chain, TIGHT)
    assert res.ok
    assert abs(res.energy_error) < 1e-8
    balance = (energy_of(chain, res.positions, res.velocities) + res.dissipated_energy - chain.energy) / chain.energy
    assert res.energy_error == pytest.approx(balance, abs=1e-14)
    assert 0.1 * chain.energy < res.dissipated_energy < chain.energy
    a = gc.simulate(chain, TIGHT, t_max=15.0, stop="t_max")
    b = gc.simulate(chain, gc.DOP853(rtol=1e-13, atol=1e-15), t_max=15.0, stop="t_max")
    assert a.dissipated_energy == pytest.approx(b.dissipated_energy, rel=1e-8)


@pytest.mark.parametrize("radii", [[1.0, 1.0], [1.0, 1.0, 1.0]], ids=["two spheres", "three spheres"])
def test_dissipated_energy_converges_when_contacts_separate_freely(radii):
    """On two and three spheres (the granules fly apart after the collisions: nothing keeps the steps
    small) the energy balance at DP5 rtol 1e-12 must be as good as on a decorated chain (1e-8), and the
    dissipated energy must be what the final velocities say was lost (1e-8 relative). Measured (gamma =
    0.1 on the pair, 0.3 on the three) before the dissipated energy's own error steered DP5's steps:
    energy errors 4.2e-5 and -3.5e-4 at any rtol (the quadrature of the power over the force-free phase
    on steps of ~0.5); since then -2.3e-12 and 1.1e-11, as DOP853 at rtol 1e-12 (3e-12 and 7e-11)."""
    gamma = 0.1 if len(radii) == 2 else 0.3
    chain = gc.from_radii(radii).with_dissipation(gamma)
    res = gc.simulate(chain, TIGHT)
    assert res.ok
    lost = chain.energy - chain_energy(chain, res.positions, res.velocities)
    assert res.dissipated_energy == pytest.approx(lost, rel=1e-8)
    assert abs(res.energy_error) < 1e-8


@functools.cache
def damped_monodisperse(gamma: float):
    res = gc.simulate(gc.monodisperse(90).with_dissipation(gamma))
    assert res.ok
    return res


def test_pulse_decays_along_a_dissipative_chain():
    """The pulse of a monodisperse chain (90 granules, v0 = 1) loses amplitude to the viscoelastic
    contacts, granule after granule, faster for larger gamma; without damping it does not.

    The law of the decay, from Hertz scaling: the equations are invariant under delta -> A delta,
    t -> A^(-1/4) t if gamma -> gamma A^(1/4); a wave of velocity amplitude v (A ~ v^(4/5)) therefore sees
    the damping gamma v^(1/5) (as a collision does: 1 - e ~ gamma v^(1/5)), and loses per granule the
    fraction kappa gamma v^(1/5) at first order: dv/dk = -kappa gamma v^(6/5), i.e. v^(-1/5) grows
    linearly in k with slope kappa gamma / 5. Measured over granules 30..80: gamma = 0 keeps the peak
    velocity constant to 1.4e-8 (tolerance 1e-6; energy errors up to 2.5e-7, tolerance 1e-6);
    gamma = 0.005, 0.01, 0.02, 0.04 lose 8 %, 15 %, 27 %,
    42 %, with v^(-1/5) linear in k to 2e-5, 8e-5, 3e-4, 1.1e-3 of its change (tolerance 2e-3), where
    an exponential decay (log v linear) misses by 1.4e-3 .. 8e-3 (checked: 5x worse at least); slopes /
    gamma = 0.0747, 0.0736, 0.0716, 0.0679 (first order: constant; tolerance: slope(2 gamma) / slope(gamma)
    within 4 % of 2 for the two smallest pairs). How it could fail: no or wrong dissipation in a long
    chain (damping on absolute rather than relative velocities, on the wrong contact), an energy leak in
    the elastic chain."""
    lo, hi = 30, 80
    plain = damped_monodisperse(0.0)
    v = plain.peak_velocity[lo - 1:hi]
    assert np.ptp(v) / v.mean() < 1e-6
    slopes, losses = [], []
    for gamma in (0.005, 0.01, 0.02, 0.04):
        res = damped_monodisperse(gamma)
        k = res.granule[lo - 1:hi].astype(float)
        v = res.peak_velocity[lo - 1:hi]
        assert np.all(np.diff(v) < 0), f"gamma = {gamma}: the pulse must lose amplitude at every granule"
        losses.append(1 - v[-1] / v[0])
        y = v ** -0.2
        p = np.polyfit(k, y, 1)
        misfit = np.abs(np.polyval(p, k) - y).max() / np.ptp(y)
        q = np.polyfit(k, np.log(v), 1)
        misfit_exp = np.abs(np.polyval(q, k) - np.log(v)).max() / np.ptp(np.log(v))
        assert misfit < 2e-3 and misfit_exp > 5 * misfit, (gamma, misfit, misfit_exp)
        slopes.append(p[0])
        assert res.dissipated_energy > 0 and abs(res.energy_error) < 1e-6
    assert np.all(np.diff(losses) > 0), losses
    assert slopes[1] / slopes[0] == pytest.approx(2.0, rel=0.04)
    assert slopes[2] / slopes[1] == pytest.approx(2.0, rel=0.04)


def test_dissipation_calibrated_from_a_coefficient_of_restitution():
    """``with_dissipation(restitution=0.9, speed=1.0)`` finds the gamma whose two-body collision at
    v = 1 has e = 0.9 (``collision.restitution``: 4e-14 off, tolerance 1e-10), and two granules of the
    chain, struck at v = 1, bounce with e = 0.9 in the kernels (DP5 rtol 1e-12: 5e-12 off, tolerance
    1e-9; DP5 at its defaults: 7e-8, tolerance 1e-6). At v = 0.5 the same gamma gives the two-body
    solve's e(0.5) = 0.912 > 0.9 (1 - e ~ v^(1/5)): the calibration fixes gamma, not e. How it could
    fail: a calibration on another pair (masses, stiffness), a root of the wrong function, gamma
    and e swapped."""
    chain = gc.from_radii([1.0, 1.0]).with_dissipation(restitution=0.9, speed=1.0)
    g = chain.contact.gamma
    assert g == collision.gamma_for_restitution(0.9, 1.0)
    assert collision.restitution(g, 1.0) == pytest.approx(0.9, abs=1e-10)
    for integrator, tol in [(TIGHT, 1e-9), (gc.DP5(), 1e-6)]:
        res = gc.simulate(chain, integrator)
        assert res.velocities[1] - res.velocities[0] == pytest.approx(0.9, abs=tol)
    e_half, _ = two_sphere_restitution(g, 0.5, TIGHT)
    assert e_half == pytest.approx(collision.restitution(g, 0.5), abs=1e-9) and e_half > 0.91
    assert Viscoelastic.from_restitution(1.0).gamma == 0.0


# -- 4. the kernels against DOP853 ---------------------------------------------------------------------
REFERENCE = gc.DOP853(rtol=1e-11, atol=1e-13)  # tests/test_backends.py's conformance reference


def _materials_chain(seed):
    base = gc.random_decorated(8, gc.Uniform(0.01, 0.4), seed=seed)
    mats = ["steel" if i % 2 == 0 else ("ptfe" if (i // 2) % 2 == 0 else "brass") for i in range(base.size)]
    return gc.from_radii(base.radii, materials=mats, observed=base.observed, kind="decorated")


#: name -> (builder of seed, integrator under test, run keywords). The dissipative runs end at a fixed
#: time (their dissipated energy is compared at the same time; a run that stops at the exit ends
#: within ~0.1 of the reference's, where the rattling granules still dissipate). The precompressed
#: chain runs to t = 30: the pulse's first passage and its reflection at the loaded far end (peaks at
#: t < 20); later maxima are superpositions of waves reflected back and forth, where DP5's errors
#: accumulate (measured up to 8.9e-7 at t = 42, seeds 1-6).
VARIANTS = {
    "dissipation": (lambda s: gc.random_decorated(8, gc.Uniform(0.01, 0.4), seed=s).with_dissipation(0.05), gc.DP5(),
                    {"t_max": 30.0, "stop": "t_max"}),
    "precompression": (lambda s: gc.random_decorated(8, gc.Uniform(0.01, 0.4), seed=s).with_precompression(0.1), gc.DP5(),
                       {"t_max": 30.0}),
    "striker": (lambda s: gc.random_decorated(8, gc.Uniform(0.01, 0.4), seed=s).with_striker(radius=0.7, velocity=1.0),
                gc.DP5(), {}),
    "wall": (lambda s: gc.random_decorated(8, gc.Uniform(0.01, 0.4), seed=s).with_wall(), gc.DP5(), {}),
    "materials": (_materials_chain, gc.DP5(), {}),
    # Every law at once, at DP5's defaults. (Before the dissipated energy's error steered DP5's steps,
    # these chains were at the contract's edge: peak velocities 1.1e-6 off on seed 3, an error made early
    # in a force-free phase and carried; since then 1.1e-7 .. 1.5e-7 over seeds 1-4.)
    "all combined": (lambda s: _materials_chain(s).with_wall(material="steel").with_striker(radius=0.8)
                     .with_precompression(0.05).with_dissipation(0.05), gc.DP5(), {"t_max": 60.0}),
}
SEEDS = [1, 3]
SLOW_SEEDS = [2, 4]


@functools.cache
def conformance_pair(name: str, seed: int):
    build, integrator, kw = VARIANTS[name]
    chain = build(seed)
    return chain, gc.simulate(chain, integrator, **kw), gc.simulate(chain, REFERENCE, **kw)


def check_conformance(name, seed):
    chain, res, ref = conformance_pair(name, seed)
    what = f"{name}, seed {seed}"
    assert res.ok and ref.ok, what
    np.testing.assert_array_equal(res.granule, ref.granule)
    ok = in_order(ref)
    # (granule 2 of the materials chains of seeds 1, 2 and 4 has a late hump above its pulse peak)
    assert ok[0] and ok.sum() >= 0.5 * ok.size, f"{what}: too many out-of-order peaks"
    np.testing.assert_allclose(res.peak_velocity[ok], ref.peak_velocity[ok], rtol=1e-6, atol=0, err_msg=what)
    np.testing.assert_allclose(res.peak_time[ok], ref.peak_time[ok], rtol=0, atol=1e-5, err_msg=what)
    np.testing.assert_allclose(res.peak_force, ref.peak_force, rtol=1e-6, atol=0, err_msg=what)
    if chain.contact.gamma > 0:
        assert res.t_end == ref.t_end, what
        assert ref.dissipated_energy > 0
        assert res.dissipated_energy == pytest.approx(ref.dissipated_energy, rel=DISSIPATED_RTOL[name]), what


#: Dissipated energy at a common end time, relative to DOP853's, at DP5's defaults (rtol 1e-8): all laws
#: together 2.6e-6 .. 5.0e-6 over seeds 1-4 (1.7e-7 .. 9.7e-7 at rtol 1e-9): the energy is one more
#: integrated component, to DP5's tolerance.
DISSIPATED_RTOL = {"dissipation": 1e-5, "all combined": 1e-5}


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("name", list(VARIANTS))
def test_kernels_agree_with_dop853_on_real_contacts(name, seed):
    """Random decorated chains (8 large granules, small radii U(0.01, 0.4)) with each real contact and
    all at once, DP5 against DOP853 at rtol 1e-11 (SciPy, its own NumPy force law, sharing no code
    with the kernels): peak velocities within 1e-6 (relative) and times within 1e-5 at the granules
    whose peaks come in order (``conftest.in_order``), every contact's peak force within 1e-6
    (relative; total force, the static load included; for the viscoelastic law the maximum of the
    force itself, before the compression's), and the dissipated energy (see ``DISSIPATED_RTOL``).
    Measured worst cases over seeds 1-4 (peak velocities, times, forces): dissipation 3.8e-8, 6.6e-8,
    4.7e-8; precompression 8.6e-10, 2.4e-9, 1.9e-9 (to t = 30; up to 8.9e-7 in the forces of later
    maxima, seeds 1-6); striker 7.7e-8, 2.9e-7, 1.0e-7; wall 3.8e-9, 1.3e-8, 1.9e-7; materials 4.9e-10,
    2.3e-7, 2.3e-8; all combined: 1.5e-7, 3.3e-6, 1.6e-7.
    How it could fail: any law coded differently in the kernels and in SciPy (static overlap,
    damping term, clamp, materials' moduli and densities, striker contact, wall contact), force peaks
    located on the compression instead of the force, a static load left out of the reported force."""
    check_conformance(name, seed)


@pytest.mark.slow
@pytest.mark.parametrize("seed", SLOW_SEEDS)
@pytest.mark.parametrize("name", list(VARIANTS))
def test_kernels_agree_with_dop853_on_real_contacts_more_seeds(name, seed):
    """The test above on two more seeds (DOP853 takes up to ~6 s per run on these)."""
    check_conformance(name, seed)


def test_striker_of_a_granule_is_the_chain_one_granule_longer():
    """A striker of granule 1's mass and radius at granule 1's speed is exactly granule 1 of a chain one
    granule longer: ``with_striker(mass=1)`` on 8 spheres runs bitwise as 9 spheres (peaks, forces,
    energy error), its granules keep their labels 1..8 (the 9-sphere chain's 2..9), and the striker
    built from its radius is the same chain. How it could fail: a striker contact from another formula,
    labels shifted, a striker observed by default."""
    struck = gc.monodisperse(8).with_striker(mass=1.0)
    longer = gc.monodisperse(9)
    assert struck.striker and np.array_equal(struck.labels, np.arange(1, 9))
    np.testing.assert_array_equal(gc.monodisperse(8).with_striker(radius=1.0).stiffness, struck.stiffness)
    a, b = gc.simulate(struck), gc.simulate(longer)
    np.testing.assert_array_equal(a.granule, np.arange(1, 9))
    np.testing.assert_array_equal(a.peak_velocity, b.peak_velocity[1:])
    np.testing.assert_array_equal(a.peak_time, b.peak_time[1:])
    np.testing.assert_array_equal(a.peak_force, b.peak_force)
    assert a.energy_error == b.energy_error
    one = gc.from_radii(np.ones(6), materials=["steel"] * 6)  # one material: Eq. r-prime bit for bit
    np.testing.assert_array_equal(one.stiffness, gc.monodisperse(6).stiffness)
    np.testing.assert_array_equal(one.masses, gc.monodisperse(6).masses)


# -- 5. bad input ------------------------------------------------------------------------------------
def _chain():
    return gc.monodisperse(5)


BAD = {
    "negative F0": (lambda: _chain().with_precompression(-1.0), "static force F0 must be finite and >= 0"),
    "NaN F0": (lambda: _chain().with_precompression(float("nan")), "static force F0 must be finite"),
    "infinite F0": (lambda: _chain().with_precompression(math.inf), "static force F0 must be finite"),
    "F0 with units": (lambda: _chain().with_precompression("2 N"), "static force F0 must be a number"),
    "negative F0, Chain": (
        lambda: gc.Chain([1.0, 1.0], [1.0], static_force=-1.0),
        "static force F0 must be finite and >= 0"),
    "negative gamma": (
        lambda: _chain().with_dissipation(-0.1),
        r"gamma .* must be finite and >= 0.*gamma = 0 is the elastic"),
    "NaN gamma": (lambda: _chain().with_dissipation(float("nan")), r"gamma .* must be finite and >= 0"),
    "gamma and restitution": (
        lambda: _chain().with_dissipation(0.1, restitution=0.9),
        "give either gamma .* or restitution"),
    "neither": (lambda: _chain().with_dissipation(), "give either gamma .* or restitution"),
    "restitution 0": (lambda: _chain().with_dissipation(restitution=0.0), r"restitution must lie in \(0, 1\]"),
    "restitution > 1": (lambda: _chain().with_dissipation(restitution=1.1), r"restitution must lie in \(0, 1\]"),
    "restitution < 0": (lambda: _chain().with_dissipation(restitution=-0.5), r"restitution must lie in \(0, 1\]"),
    "restitution NaN": (
        lambda: _chain().with_dissipation(restitution=float("nan")),
        r"restitution must lie in \(0, 1\]"),
    "calibration speed 0": (
        lambda: _chain().with_dissipation(restitution=0.9, speed=0.0),
        "impact speed must be finite and > 0"),
    "striker mass 0": (lambda: _chain().with_striker(mass=0.0), "striker mass must be > 0"),
    "striker mass < 0": (lambda: _chain().with_striker(mass=-1.0), "striker mass must be > 0"),
    "striker mass NaN": (lambda: _chain().with_striker(mass=float("nan")), "striker mass must be finite"),
    "striker radius 0": (lambda: _chain().with_striker(radius=0.0), "striker radius must be > 0"),
    "striker speed 0": (lambda: _chain().with_striker(mass=1.0, velocity=0.0), "striker velocity must be > 0"),
    "striker mass and radius": (
        lambda: _chain().with_striker(mass=1.0, radius=1.0),
        "give the striker's mass or its radius"),
    "two strikers": (lambda: _chain().with_striker(mass=1.0).with_striker(mass=1.0), "already has a striker"),
    "precompression at n = 1": (lambda: gc.monodisperse(5, n=1.0).with_precompression(1.0), "need n > 1"),
    "viscoelastic at n < 2": (
        lambda: gc.monodisperse(5, n=1.5).with_dissipation(0.1),
        "needs an exponent n >= 2.*diverge"),
    "RKN4 with dissipation": (
        lambda: gc.simulate(_chain().with_dissipation(0.1), gc.RKN4()),
        "rkn4 .*depends on velocities: use DP5"),
    "Verlet with dissipation": (
        lambda: gc.simulate(_chain().with_dissipation(0.1), gc.Verlet(1e-3)),
        "verlet .*depends on velocities: use DP5"),
    "RKN4, calibrated": (lambda: gc.simulate(_chain().with_dissipation(restitution=0.9), "rkn4"), "use DP5 or DOP853"),
    "sensor without grid": (lambda: gc.simulate(_chain(), sensors=[2]), "pass t_grid=... with sensors"),
    "sensor at the struck granule": (
        lambda: gc.simulate(_chain(), sensors=[1], t_grid=[0.0, 1.0]),
        r"choose labels in 2\.\.4"),
    "collision at speed 0": (lambda: collision.restitution(0.1, 0.0), "impact speed must be finite and > 0"),
    "collision of a massless sphere": (
        lambda: collision.restitution(0.1, 1.0, mass=0.0),
        "masses must be finite and > 0"),
}


@pytest.mark.parametrize("name", list(BAD))
def test_bad_input_says_what_to_change(name):
    """Each refusal is a ValueError whose message names the quantity and the admissible values (or the
    integrator to use instead). How it could fail: a silent acceptance (a negative load would pull the
    chain apart, a negative gamma feed energy in, RKN4 integrate a velocity-dependent force as if it
    were not), or a message that does not say what to change."""
    call, words = BAD[name]
    with pytest.raises(ValueError, match=words):
        call()


def test_the_law_objects_validate_themselves():
    """The same checks on the model's values themselves (``Precompression``, ``Viscoelastic``), so that
    no path around the Chain methods builds an invalid law; and RKN4 and Verlet accept a
    precompressed elastic chain (its forces depend on positions only)."""
    with pytest.raises(ValueError, match="finite and >= 0"):
        Precompression(-0.5)
    with pytest.raises(ValueError, match="must be a number"):
        Viscoelastic("soft")
    with pytest.raises(ValueError, match="n >= 2"):
        Viscoelastic(0.1, n=1.9)
    chain = gc.monodisperse(5).with_precompression(1.0)
    for integrator in (gc.RKN4(), gc.Verlet(1e-3)):
        assert gc.simulate(chain, integrator, t_max=10.0).ok


# -- 6. the trailing window --------------------------------------------------------------------------
def test_trailing_window_on_a_dissipative_chain():
    """``DP5.windowed()`` on a long dissipative decorated chain (40 large granules, gamma = 0.05): its
    peaks agree with the exact DP5 run's within the accuracy contract, 1e-6 (relative) and 1e-5
    (measured 5.5e-7 and 1.4e-6; the exact run is within 5e-9 of DOP853 at rtol 1e-10, measured), it
    keeps its energy balance (measured 5.4e-8; tolerance 1e-5, for the relaxed zone's looser steps),
    and it reports less dissipated energy than the exact run (0.206 against 0.225): the granules behind
    the window stop rattling, so their contacts stop dissipating (the rattling of the full dynamics
    is not reproduced behind the window, as for the averaged pulse's tail). How it could fail: the window cut across a closed
    viscoelastic contact, the dissipated power of frozen granules counted, peaks behind the window
    changed."""
    chain = gc.random_decorated(40, gc.Uniform(0.01, 0.4), seed=1).with_dissipation(0.05)
    exact = gc.simulate(chain)
    windowed = gc.simulate(chain, gc.DP5.windowed())
    assert exact.ok and windowed.ok
    assert windowed.integrator_record.get("window_lag") is not None and "goal_control" not in windowed.integrator_record
    ok = in_order(exact)
    np.testing.assert_allclose(windowed.peak_velocity[ok], exact.peak_velocity[ok], rtol=1e-6, atol=0)
    np.testing.assert_allclose(windowed.peak_time[ok], exact.peak_time[ok], rtol=0, atol=1e-5)
    assert abs(windowed.energy_error) < 1e-5
    assert 0.5 * exact.dissipated_energy < windowed.dissipated_energy < exact.dissipated_energy
    assert windowed.n_steps < exact.n_steps


def test_precompression_switches_goal_control_off():
    """A precompressed chain reflects the pulse at its loaded far end and keeps every contact closed,
    so the relaxed zone and the trailing window are switched off: the windowed run is bitwise the exact
    DP5 at the same tolerances, and the result says so (integrator record, table). Negative control:
    the same chain without load keeps its goal-oriented record."""
    chain = gc.random_decorated(8, gc.Uniform(0.01, 0.4), seed=2).with_dissipation(0.05)
    loaded = chain.with_precompression(0.05)
    integ = gc.DP5.windowed()
    res = gc.simulate(loaded, integ)
    exact = gc.simulate(loaded, gc.DP5(integ.rtol, integ.atol))
    np.testing.assert_array_equal(res.peak_velocity, exact.peak_velocity)
    np.testing.assert_array_equal(res.peak_force, exact.peak_force)
    assert res.dissipated_energy == exact.dissipated_energy
    record = res.integrator_record
    assert "precompressed" in record["goal_control"] and record.get("window_lag") is None
    assert "goal-oriented error control off: the chain is precompressed" in res.table()
    assert "goal_control" not in gc.simulate(chain, integ).integrator_record


# -- 7. sensors and the wall force ---------------------------------------------------------------------
def momentum_forces(res, masses, dt):
    """F_j(t) = -dP_j/dt, P_j = sum_{i <= j} m_i v_i: the force of contact j from the momentum of the
    granules behind it (nothing else acts on them), by the 5-point central difference (error O(dt^4))."""
    P = np.cumsum(masses[:, None] * res.velocity, axis=0)
    dP = np.full_like(P, np.nan)
    dP[:, 2:-2] = (-P[:, 4:] + 8 * P[:, 3:-1] - 8 * P[:, 1:-3] + P[:, :-4]) / (12 * dt)
    return -dP


def parabola_peak(f):
    """The maximum of a sampled smooth peak: the vertex of the parabola through the largest sample and
    its two neighbours (error O(dt^3))."""
    i = int(np.nanargmax(f))
    u = 0.5 * (f[i - 1] - f[i + 1]) / (f[i - 1] - 2 * f[i] + f[i + 1])
    return f[i] - 0.25 * (f[i - 1] - f[i + 1]) * u


def smooth_and_closed(F, fraction=0.02):
    """Grid samples whose 5-point stencil lies inside one closed phase of a contact (force above
    ``fraction`` of its peak on all five samples): where the difference formula's error is O(dt^4).
    Across a contact's opening the force behaves like delta^(3/2) (elastic) or has a kink (the
    viscoelastic clamp), and the difference formula is off by up to 2e-5 there (measured)."""
    from numpy.lib.stride_tricks import sliding_window_view

    ok = np.zeros(F.shape, dtype=bool)
    ok[2:-2] = sliding_window_view(np.nan_to_num(F, nan=-1.0), 5).min(axis=1) > fraction * np.nanmax(F)
    return ok


def test_sensor_force_is_the_mean_of_its_contact_forces():
    """A sensor granule's force (``sensor_force``) in a monodisperse chain against momentum balance:
    the contact forces on either side are -dP/dt of the granules behind each (from the recorded grid
    velocities, 5-point differences, dt = 0.005), and the sensor reads their mean: within 1e-7 where
    both contacts are closed over the stencil (measured 3.6e-9 at DP5's defaults, 4e-11 at rtol
    1e-12: the integration error, not the formula's). Its peak (``sensor_peak``) comes between the two
    contacts' peaks, at their midpoint within 0.05, and is lower than either: the mean of two equal
    pulses 1/V_s apart is 0.707 of the solitary wave's contact force (measured at granules 10 and 15;
    the long-wave wave, F ~ cos^6, would give cos^6(sqrt(10)/10) = 0.74), not the contact force
    itself. How it could fail: the wrong contacts (or labels) for a sensor, a sum instead of a mean,
    forces sampled off the grid times."""
    chain = gc.monodisperse(20)
    dt = 0.005
    grid = np.arange(0.0, 30.0, dt)
    sensors = [5, 10, 15]
    res = gc.simulate(chain, t_grid=grid, sensors=sensors)
    assert res.ok and np.array_equal(res.sensor_granule, sensors)
    F = momentum_forces(res, chain.masses, dt)
    peaks, times = res.sensor_peak()
    for s, k in enumerate(sensors):
        mean = 0.5 * (F[k - 2] + F[k - 1])  # contacts k-1 (granules k-1, k) and k (k, k+1)
        closed = smooth_and_closed(F[k - 2]) & smooth_and_closed(F[k - 1])
        assert closed.sum() > 400  # ~2.5 time units of the pulse's passage
        np.testing.assert_allclose(res.sensor_force[s, closed], mean[closed], rtol=0, atol=1e-7)
        left, right = res.peak_force[k - 2], res.peak_force[k - 1]
        t_left, t_right = res.peak_force_time[k - 2], res.peak_force_time[k - 1]
        assert t_left < times[s] < t_right and times[s] == pytest.approx(0.5 * (t_left + t_right), abs=0.05)
        assert peaks[s] < min(left, right)
        if k >= 10:  # where the solitary wave has formed (at granule 5: 0.692 and 0.699 of its two contacts')
            assert peaks[s] / left == pytest.approx(0.707, abs=0.005)
        assert peaks[s] == pytest.approx(parabola_peak(mean), rel=1e-7)


def test_wall_force_is_the_momentum_the_wall_takes():
    """With a wall, the wall force on the grid is -dP/dt of all the granules (nothing else acts on the
    chain): within 1e-7 while the wall contact is closed over the stencil (measured 1.9e-8, and 1.9e-10
    at rtol 1e-12), and its maximum, refined by the parabola through the largest sample and its
    neighbours, is ``peak_wall_force`` (measured 5e-10 apart; tolerance 1e-7, the parabola's O(dt^3)).
    With a viscoelastic law too: the wall contact damps like any other. How it could fail: the wall
    force of the wrong contact or without its damping term, a peak located on the compression instead
    of the force."""
    dt = 0.005
    grid = np.arange(0.0, 25.0, dt)
    for chain in (gc.monodisperse(10, wall=True), gc.monodisperse(10, wall=True).with_dissipation(0.1)):
        res = gc.simulate(chain, t_grid=grid)
        F = momentum_forces(res, chain.masses[:-1], dt)[-1]
        closed = smooth_and_closed(F)
        assert closed.sum() > 400
        np.testing.assert_allclose(res.wall_force[closed], F[closed], rtol=0, atol=1e-7)
        assert parabola_peak(res.wall_force) == pytest.approx(res.peak_wall_force, rel=1e-7)
        assert res.peak_wall_force == res.peak_force[-1]


def test_sensor_and_wall_forces_of_a_loaded_dissipative_chain_agree_with_dop853():
    """On a precompressed, dissipative decorated chain against a wall, the sensors' forces (static load
    included) on the grid agree with DOP853's within 1e-6 (measured 1.06e-7): the dense force of the
    viscoelastic law, damping term included. The first sample (t = 0) is left out: there the struck
    granule's contact is compressed by the static overlap and closing at v0, so the viscoelastic
    force jumps from F0 to F0 + c gamma delta0^(1/2) v0 at t = 0+; DOP853 reports the latter, the
    compiled kernels the former (0.05 against 0.064 at granule 2)."""
    chain = gc.decorated([0.3, 0.1, 0.2, 0.25]).with_dissipation(0.1).with_precompression(0.05).with_wall()
    grid = np.linspace(0.0, 25.0, 2501)
    sensors = [2, 5, 9]
    res = gc.simulate(chain, t_grid=grid, sensors=sensors, t_max=25.0)
    ref = gc.simulate(chain, REFERENCE, t_grid=grid, sensors=sensors, t_max=25.0)
    assert res.ok and ref.ok
    np.testing.assert_allclose(res.sensor_force[:, 1:], ref.sensor_force[:, 1:], rtol=0, atol=1e-6)
    np.testing.assert_allclose(res.sensor_force[1:, 0], chain.static_force, rtol=1e-15)  # not touching the struck granule


@pytest.mark.parametrize("integrator", [gc.DP5(), gc.RKN4(), gc.Verlet(1e-3)], ids=["dp5", "rkn4", "verlet"])
def test_wall_of_a_precompressed_chain_carries_the_static_load(integrator):
    """The wall of a chain under F0 pushes back with F0 until the pulse arrives, then more: ``wall_force``
    (total force, static load included, as the sensors and ``peak_force``) is F0 at every grid time
    before the pulse reaches the wall and never below F0 - 1e-12 while the contact stays closed;
    DOP853 reports exactly that."""
    chain = gc.monodisperse(40, wall=True).with_precompression(0.2)
    grid = np.linspace(0.0, 20.0, 11)
    ref = gc.simulate(chain, gc.DOP853(), t_grid=grid, t_max=20.0)
    np.testing.assert_allclose(ref.wall_force, 0.2, rtol=0, atol=1e-12)
    res = gc.simulate(chain, integrator, t_grid=grid, t_max=20.0)
    np.testing.assert_allclose(res.wall_force, ref.wall_force, rtol=0, atol=1e-9)


# -- 8. the clamp of the viscoelastic force, and the published (unclamped) law ----------------------------
# The published restitution of the Kuwabara-Kono / Brilliantov law (T. Schwager and T. Poschel, Phys. Rev.
# E 57, 650 (1998); R. Ramirez, T. Poschel, N. V. Brilliantov and T. Schwager, Phys. Rev. E 60, 4465 (1999))
# is for the equation  xi'' + rho (xi^(3/2) + (3/2) A xi^(1/2) xi') = 0  with rho = (the contact's
# prefactor) / (the reduced mass), integrated until xi returns to 0 (the force pulls before that):
#     1 - e = 1.7302 A rho^(2/5) g^(1/5) + O(A^2),  g the impact speed.
# Here mu delta'' = -c [delta^(3/2) + gamma delta^(1/2) delta'], so rho = c / mu and A = 2 gamma / 3;
# 1.7302 = (3/2) C1 with C1 = KUWABARA_KONO_C1 (checked below, so the identification is tested too).
PUBLISHED_C = 1.7302


def unclamped_two_sphere_restitution(gamma, integrator=TIGHT, clamp=False):
    """e of two unit spheres (masses 1: mu = 1/2; prefactor 1: rho = c / mu = 2) meeting at speed 1, with
    the viscoelastic law clamped or not, from ``simulate`` (the kernels under test)."""
    chain = gc.from_radii([1.0, 1.0]).replace(contact=Viscoelastic(gamma, clamp=clamp))
    res = gc.simulate(chain, integrator)
    assert res.ok, res.message
    return res.velocities[1] - res.velocities[0]


def test_published_constant_is_three_halves_of_c1():
    """1.7302 (Schwager & Poschel 1998) = (3/2) C1 to its printed digits: the published A is 2 gamma / 3."""
    assert 1.5 * collision.KUWABARA_KONO_C1 == pytest.approx(PUBLISHED_C, abs=5e-5)


@pytest.mark.parametrize("A", [1e-4, 1e-3, 1e-2])
def test_unclamped_restitution_follows_the_published_small_damping_law(A):
    """The unclamped law in the kernels (DP5 at rtol 1e-12) against 1 - e = 1.7302 A rho^(2/5) g^(1/5)
    (rho = 2, g = 1): the expansion's next term is O(A^2), measured (1 - e - lead) / lead^2 = -0.67, -0.61,
    -0.59 at A = 1e-4, 1e-3, 1e-2 (Ramirez et al.'s C2 / C1^2 ~ 0.6); tolerance |1 - e - lead| <= lead^2.
    How it could fail: rho taken as c (not c / mu: a factor 2^(2/5) = 1.32), A as gamma (a factor 3/2),
    the clamp left on at larger A, or damping not ~ delta^(1/2) (another power of g)."""
    lead = PUBLISHED_C * A * 2.0**0.4 * 1.0**0.2
    e = unclamped_two_sphere_restitution(1.5 * A)
    assert abs((1.0 - e) - lead) <= lead**2, ((1.0 - e) - lead) / lead**2


@pytest.mark.parametrize("gamma", [0.075, 0.15, 0.3])
def test_unclamped_kernels_agree_with_an_independent_two_body_solve(gamma):
    """The kernels' unclamped e (DP5 at rtol 1e-12, a 2-granule chain) against SciPy's DOP853 on the
    two-body ODE (``collision.restitution(clamp=False)``, rtol 1e-12, ended at delta = 0 by an event):
    within 1e-9 (measured < 1e-11). And the clamped law gives a higher e (the pull at the end of the
    collision takes energy the clamp leaves in the motion): measured 0.08 %, 0.4 %, 2.2 % higher at
    A = 0.05, 0.1, 0.2 (gamma = 0.075, 0.15, 0.3), in the kernels and in the two-body solve alike. A
    clamp that did nothing (or a switch that did not reach the kernels) fails the second part."""
    e_kernel = unclamped_two_sphere_restitution(gamma)
    e_scipy = collision.restitution(gamma, 1.0, mass=1.0, stiffness=1.0, clamp=False)
    assert e_kernel == pytest.approx(e_scipy, abs=1e-9)
    e_clamped = unclamped_two_sphere_restitution(gamma, clamp=True)
    assert e_clamped == pytest.approx(collision.restitution(gamma, 1.0), abs=1e-9)
    assert e_clamped > e_kernel + 1e-4 * gamma
    # the SciPy reference backend integrates the same unclamped law
    e_dop853 = unclamped_two_sphere_restitution(gamma, gc.DOP853(rtol=1e-12, atol=1e-14))
    assert e_dop853 == pytest.approx(e_scipy, abs=1e-9)


def test_unclamped_calibration_needs_less_damping():
    """from_restitution(clamp=False) solves the published law: its gamma gives e back in the two-body solve,
    and is smaller than the clamped law's for the same e (the pull dissipates more)."""
    unclamped = Viscoelastic.from_restitution(0.8, clamp=False)
    clamped = Viscoelastic.from_restitution(0.8)
    assert not unclamped.clamp and clamped.clamp
    assert collision.restitution(unclamped.gamma, clamp=False) == pytest.approx(0.8, abs=1e-10)
    assert unclamped.gamma < clamped.gamma


def test_the_clamp_is_recorded_and_old_records_read_clamped():
    """A family's record holds "clamp": False only for the unclamped law, so records written before the
    option (no "clamp") read back as clamped and a clamped and an unclamped family's records differ (the
    store's resume check compares them and refuses a difference)."""
    from granchain.families import family_from_record

    clamped = gc.RandomDecorated(5, contact=Viscoelastic(0.05))
    unclamped = gc.RandomDecorated(5, contact=Viscoelastic(0.05, clamp=False))
    assert "clamp" not in clamped.describe()["contact"]
    assert unclamped.describe()["contact"]["clamp"] is False
    assert clamped.describe() != unclamped.describe()
    assert family_from_record(unclamped.describe()).contact.clamp is False
    old = clamped.describe()
    assert family_from_record(old).contact == Viscoelastic(0.05)
    with pytest.raises(ValueError, match="clamp must be True"):
        Viscoelastic(0.05, clamp="no")


# -- 9. a peak at the last instant of a run is no peak ----------------------------------------------------
def test_a_peak_at_the_end_of_the_run_is_not_success(capsys):
    """A heavy striker (mass 1e6) on 10 granules keeps pushing: when the pulse has left the last granule
    (the exit rule) granule 8 is still speeding up, so its located "peak" is the run's last instant:
    status PEAK_AT_END, not SUCCESS, in ``simulate`` and in ``granchain pulse`` (exit 1, a warning, and
    "ok": false with the status in --json). Negative control: the same chain struck by a striker of mass
    1 succeeds (its peaks are maxima before the end). With stop="t_max" the peaks are the maxima up to
    the chosen time by request, and the run succeeds."""
    import json
    import warnings

    from granchain.cli import main

    chain = gc.from_radii(np.ones(10))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        heavy = gc.simulate(chain.with_striker(1e6))
    assert heavy.status == gc.Status.PEAK_AT_END, heavy.status
    assert np.max(heavy.peak_time) == heavy.t_end
    light = gc.simulate(chain.with_striker(1.0))
    assert light.ok and np.max(light.peak_time) < light.t_end - 1.0
    cut = gc.simulate(chain, t_max=5.0, stop="t_max")
    assert cut.ok and np.max(cut.peak_time) == pytest.approx(5.0)

    assert main(["pulse", "--radii", ",".join(["1"] * 10), "--striker-mass", "1e6", "--json"]) == 1
    captured = capsys.readouterr()
    out = json.loads(captured.out)
    assert out["ok"] is False and out["status"]["name"] == "PEAK_AT_END", out["status"]
    assert "warning: the run did not succeed (PEAK_AT_END)" in captured.err
    assert main(["pulse", "--radii", ",".join(["1"] * 10), "--striker-mass", "1", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["ok"] is True and out["status"]["name"] == "SUCCESS"
