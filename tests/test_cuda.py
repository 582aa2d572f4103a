"""The CUDA backend, run under Numba's CUDA simulator (no GPU needed: CI has none).

Each check runs in a subprocess (``tests/_cuda_sim.py``): the simulator must be switched on before
Numba's CUDA target is imported. The simulator runs the kernels' arithmetic in Python, without the
GPU's fused multiply-adds, so there the GPU kernels must reproduce the CPU kernels' numbers to
rounding: a test that checks them against each other within 1e-12 catches any difference in method,
step control, window, peak search or stop rule. On a GPU they agree within the accuracy contract
(``benchmarks/bench_gpu.py`` measures it on 1,000 chains of each kind). The simulator is slow (a minute
to several per check), so the kernel checks are marked ``slow``; the refusals run with the fast tests, and so do
three quick kernel checks (seconds each: the aligned pulse's sums, a precompressed chain's granules at rest, warp
votes), so that the README's test command runs the CUDA kernels too.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("numba.cuda")

HERE = Path(__file__).resolve().parent


def sim(check: str, *args, simulator: bool = True, timeout: float = 900) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_ENABLE_CUDASIM"}
    if simulator:
        env["NUMBA_ENABLE_CUDASIM"] = "1"
    proc = subprocess.run([sys.executable, str(HERE / "_cuda_sim.py"), check, *map(json.dumps, args)], env=env,
                          capture_output=True, text=True, timeout=timeout)
    assert proc.returncode == 0, proc.stderr[-3000:]
    line = next(x for x in proc.stdout.splitlines() if x.startswith("RESULT "))
    return json.loads(line[len("RESULT "):])


def assert_same_run(gpu: dict, cpu: dict) -> None:
    """Every per-realisation result within rounding and the fixed-point sums equal (the CPU kernels' numbers)."""
    for key in ("status", "n_steps", "n_valid"):
        assert gpu[key] == cpu[key], key
    for key in ("peak_velocity", "peak_time", "peak_force", "peak_force_time", "t_end"):
        np.testing.assert_allclose(gpu[key], cpu[key], rtol=1e-12, atol=1e-14, err_msg=key)
    np.testing.assert_allclose(gpu["energy_error"], cpu["energy_error"], rtol=0, atol=1e-12)
    for key in ("sum_v", "sum_v2"):
        assert np.max(np.abs(np.subtract(gpu[key], cpu[key]))) <= 2, key  # a rounding of one term at most


@pytest.mark.slow
def test_thread_per_chain_reproduces_the_cpu_kernels_with_averaged_pulse_windows():
    """One thread per chain (no exchange between threads), N = 8 with the trailing window cutting behind
    the front and averaged-pulse windows closing: the CPU kernels' results; a second run is bitwise the first."""
    res = sim("compare", 1, "shared", 8, 3, 30.0, True, True)
    assert_same_run(res["cuda"], res["cpu"])
    assert res["again"] == res["cuda"]
    assert res["cpu"]["n_valid"] == [3]


@pytest.mark.slow
def test_granules_spread_over_threads_exchange_through_shared_memory():
    """Four threads per chain, two granules each: the contact forces, error norm, peak candidates, the
    window's cut and the stop rule cross thread boundaries through shared memory."""
    res = sim("compare", 4, "shared", 4, 1, 16.0, False)
    assert_same_run(res["cuda"], res["cpu"])


@pytest.mark.slow
def test_one_warp_per_chain_exchanges_by_shuffles():
    """The GPU's layout (32 threads, warp shuffles and votes; emulated in the simulator): the CPU kernels'
    results, and bitwise the same with the votes' reductions done by shuffle trees instead."""
    res = sim("compare", 32, "shuffle", 2, 1, 6.0, False, True)
    assert_same_run(res["cuda"], res["cpu"])
    assert res["again"] == res["cuda"]


def assert_same_steps(gpu: dict, cpu: dict, rtol: float) -> None:
    """The same steps (status, step counts, energy errors: the step control reads no dense output) and peaks
    within ``rtol``; the fixed-point sums of the grid velocities within ``rtol`` of their scale per term."""
    for key in ("status", "n_steps", "n_valid"):
        assert gpu[key] == cpu[key], key
    for key in ("peak_velocity", "peak_force"):
        np.testing.assert_allclose(gpu[key], cpu[key], rtol=rtol, atol=0, err_msg=key)
    for key in ("peak_time", "peak_force_time"):
        np.testing.assert_allclose(gpu[key], cpu[key], rtol=0, atol=rtol, err_msg=key)
    np.testing.assert_allclose(gpu["energy_error"], cpu["energy_error"], rtol=0, atol=1e-12)
    terms = cpu["n_valid"][0]
    for key in ("sum_v", "sum_v2"):
        assert np.max(np.abs(np.subtract(gpu[key], cpu[key]))) <= terms * (rtol * 2.0**30 + 1), key


@pytest.mark.slow
def test_dp5_takes_the_cpu_steps_across_threads():
    """DP5 (the effective chains' method on the CPU), four threads per chain with two granules each, the
    trailing window and averaged-pulse windows: the CPU's steps, bit for bit (a wrong tableau entry or PI
    exponent changes the step counts), and its peaks within 1e-8, 1 % of the accuracy contract (the GPU reads
    them on the quintic Hermite interpolant, the CPU on Shampine's extension: measured 3e-10); a second run
    is bitwise the first."""
    res = sim("compare", 4, "shared", 8, 1, 16.0, True, True, True, "effective", "effective")
    assert_same_steps(res["cuda"], res["cpu"], rtol=1e-8)
    assert res["again"] == res["cuda"]
    assert res["cpu"]["n_valid"] == [1]


@pytest.mark.slow
@pytest.mark.parametrize("integrator", ["verlet:0.01", "rkn4:0.01"], ids=["verlet", "rkn4 fixed step"])
def test_fixed_steps_are_the_cpu_kernels(integrator):
    """Velocity Verlet, and RKN4 with a fixed step, on effective chains: the CPU kernels' results to rounding
    (Verlet's peaks and grid on its cubic Hermite interpolant, as the CPU reads them), twice the same bits."""
    res = sim("compare", 1, "shared", 8, 2, 16.0, True, True, True, "effective", integrator)
    assert_same_run(res["cuda"], res["cpu"])
    assert res["again"] == res["cuda"]
    assert res["cpu"]["n_valid"] == [2]


@pytest.mark.slow
@pytest.mark.parametrize("contact", ["kuwabara-kono:0.05", "viscous:0.1"])
def test_damped_dp5_is_the_cpu_kernel(contact):
    """DP5 on contacts that dissipate (Kuwabara-Kono's clamped law; the viscous law of Rosas et al., unclamped),
    one thread per chain, with the trailing window cutting (12 large granules, averaged-pulse windows
    closing from t = 6): the CPU's steps, its dissipated energy and energy balance to rounding (the forces
    read the stage velocities, the dissipated energy's error steers the step, and after a cut the first stage
    is evaluated again without the contact at the window's edge: leaving that out changed 4 of 581 steps and
    the dissipated energy by 3e-7, measured), peaks within 1e-8 (read on another interpolant: measured 5e-10),
    the force peaks at the root of the force's rate."""
    res = sim("compare", 1, "shared", 12, 2, 30.0, True, False, True, "effective", "effective", contact)
    gpu, cpu = res["cuda"], res["cpu"]
    assert_same_steps(gpu, cpu, rtol=1e-8)
    assert min(cpu["dissipated_energy"]) > 0.05
    np.testing.assert_allclose(gpu["dissipated_energy"], cpu["dissipated_energy"], rtol=1e-13)


def assert_damped_within_contract(gpu: dict, cpu: dict) -> None:
    """A damped run across threads against the CPU's: each thread applies the dissipation's quadrature to its own
    contacts and the group adds the shares, rounded in another order than the CPU's sum over the contacts,
    which may move a step by its last bits (the step control reads the dissipated energy's error); so steps
    within 1 %, peaks within 1e-7 (a tenth of the contract), the dissipated energy within 1e-9."""
    assert gpu["status"] == cpu["status"] == [0]
    np.testing.assert_allclose(gpu["n_steps"], cpu["n_steps"], rtol=0.01)
    for key in ("peak_velocity", "peak_force"):
        np.testing.assert_allclose(gpu[key], cpu[key], rtol=1e-7, err_msg=key)
    assert cpu["dissipated_energy"][0] > 0.05
    np.testing.assert_allclose(gpu["dissipated_energy"], cpu["dissipated_energy"], rtol=1e-9)
    np.testing.assert_allclose(gpu["energy_error"], cpu["energy_error"], atol=1e-10)


@pytest.mark.slow
def test_damped_exchange_across_threads():
    """The damped forces' exchange of stage velocities through shared memory (four threads a chain, two
    granules each), Kuwabara-Kono's unclamped law: the CPU's run within the contract
    (:func:`assert_damped_within_contract`), and a second run bitwise the first (the group's sums are in a fixed
    order)."""
    res = sim("compare", 4, "shared", 8, 1, 16.0, False, True, True, "effective", "damped", "kuwabara-kono-unclamped:0.05")
    assert_damped_within_contract(res["cuda"], res["cpu"])
    assert res["again"] == res["cuda"]


@pytest.mark.slow
def test_damped_forces_by_warp_shuffles():
    """One warp per chain (the default layout): the stage velocities of the neighbours by warp shuffles and the
    dissipated energy's shares by a shuffle butterfly, the viscous law of Rosas et al.: the CPU's run within the
    contract (:func:`assert_damped_within_contract`). A tiny chain: the simulator runs the warp's 32 threads in
    Python (two minutes)."""
    res = sim("compare", 32, "shuffle", 3, 1, 10.0, False, False, True, "effective", "damped", "viscous:0.1")
    assert_damped_within_contract(res["cuda"], res["cpu"])


@pytest.mark.slow
def test_damped_ensemble_on_the_gpu_is_the_cpus(tmp_path):
    """``run_ensemble`` of a damped family on the GPU backend (one thread per chain), both chain kinds, written to
    a store and read back: each kind integrated with the CPU's own default for it (the effective chains' tighter
    DP5, not the decorated chains'), and the dissipated energies and energy errors the CPU's to rounding, the
    peaks within 1e-8 (another interpolant)."""
    res = sim("model_ensemble", 1, str(tmp_path / "damped.zarr"), "damped")
    gpu, cpu = res["cuda"], res["cpu"]
    assert gpu["status"] == cpu["status"] and np.all(np.array(cpu["status"]) == 0)
    assert np.min(cpu["dissipated_energy"]) > 0.02
    np.testing.assert_allclose(gpu["dissipated_energy"], cpu["dissipated_energy"], rtol=1e-12)
    np.testing.assert_allclose(gpu["energy_error"], cpu["energy_error"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(gpu["peak_velocity"], cpu["peak_velocity"], rtol=1e-8)


@pytest.mark.slow
def test_precompressed_ensemble_on_the_gpu_is_the_cpus(tmp_path):
    """``run_ensemble`` of a precompressed family against a wall on the GPU backend, both chain kinds, through a
    store: every chain runs to its own time limit (no exit under a static load), the decorated chains (RKN4 on
    both backends) give the CPU's peaks and wall forces to rounding, the effective chains (RKN4 on the GPU, the
    CPU's default DP5 there) within the accuracy contract; energy balanced within 1e-7 on both."""
    res = sim("model_ensemble", 1, str(tmp_path / "loaded.zarr"), "precompressed")
    gpu, cpu = res["cuda"], res["cpu"]
    assert gpu["status"] == cpu["status"] and np.all(np.array(cpu["status"]) == 0)
    np.testing.assert_array_equal(gpu["t_end"], cpu["t_end"])
    assert np.min(cpu["peak_wall_force"]) > 0.5  # the pulse on the wall, far above the static load (1e-3)
    for key in ("peak_velocity", "peak_wall_force"):
        np.testing.assert_allclose(gpu[key][0], cpu[key][0], rtol=1e-12, err_msg=f"decorated {key}")
        np.testing.assert_allclose(gpu[key][1], cpu[key][1], rtol=1e-6, err_msg=f"effective {key}")
    assert np.max(np.abs(gpu["energy_error"])) < 1e-7 and np.max(np.abs(cpu["energy_error"])) < 1e-7


def test_the_aligned_pulse_is_summed_on_the_gpu():
    """The aligned pulse <v_k(t_k^peak + tau)> (``kernels.aligned``) summed on the GPU from the grid velocities and
    peak times it holds, one thread per lag and granule: the CPU's fixed-point sums to a rounding of one term per
    realisation (the simulator gives the CPU's velocities to rounding), and a second run bitwise the first.
    Negative control: the sums at the lags shifted by one grid step differ (the comparison sees the lags)."""
    lags = np.arange(-2.0, 2.01, 0.25)
    res = sim("compare", 1, "shared", 4, 2, 16.0, False, True, True, "decorated", "decorated", None, 0.0, lags.tolist())
    gpu, cpu = res["cuda"], res["cpu"]
    assert_same_run(gpu, cpu)
    assert res["again"] == gpu
    for key in ("sum_a", "sum_a2"):
        assert np.max(np.abs(np.subtract(gpu[key], cpu[key]))) <= 2, key
    assert np.min(np.max(cpu["sum_a"], axis=0)) > 0.1 * 2.0**30  # every granule's pulse seen about its peak
    shifted = np.asarray(cpu["sum_a"])[1:]
    assert np.max(np.abs(np.asarray(gpu["sum_a"])[:-1] - shifted)) > 1e-3 * 2.0**30


@pytest.mark.parametrize("threads, wall, load, repeats, t_end", [
    pytest.param(1, True, 0.0, 1, 14.0, id="wall", marks=pytest.mark.slow),
    pytest.param(4, True, 1e-3, 1, 14.0, id="shared memory, loaded", marks=pytest.mark.slow),
    pytest.param(1, False, 0.0, 3, 30.0, id="trailing window", marks=pytest.mark.slow),
])
def test_force_sensors_on_the_gpu_are_the_cpus(threads, wall, load, repeats, t_end):
    """Force sensors (each sensor granule's two contacts, sampled on the grid by the threads that hold them; with a
    wall the granule next to it), the ensembles' RKN4 (its trailing window on where the chain licenses it): the
    CPU's forces to rounding, one thread or a group through shared memory, a static load in them (the grid's first
    sample is F0); behind the trailing window NaN, as on the CPU, at the same grid times (and there are such
    times, with samples before them)."""
    res = sim("sensors", threads, "decorated", None, wall, load, repeats, t_end)
    gpu, cpu = res["cuda"], res["cpu"]
    assert gpu["status"] == cpu["status"] == 0 and gpu["n_steps"] == cpu["n_steps"]
    g, c = np.array(gpu["sensor_force"], dtype=float), np.array(cpu["sensor_force"], dtype=float)
    np.testing.assert_array_equal(np.isnan(g), np.isnan(c))
    np.testing.assert_allclose(g, c, rtol=1e-12, atol=1e-14)
    assert np.nanmax(c) > 0.3  # the pulse went through every sensor
    if load:
        np.testing.assert_allclose(c[:, 0], load, rtol=1e-12)
    if not (wall or load):
        behind = np.isnan(c[0])
        assert behind.any() and not behind[: len(behind) // 2].any()


@pytest.mark.slow
@pytest.mark.parametrize("integrator, contact, rtol", [("verlet:0.005", None, 1e-12), ("damped", "kuwabara-kono:0.05", 1e-8),
                                                       ("damped", "plastic:0.2", 1e-7)],
                         ids=["verlet", "dp5 kuwabara-kono", "dp5 yielding"])
def test_force_sensors_of_every_method_and_law(integrator, contact, rtol):
    """Force sensors against a wall read on each method's interpolant by each law, one thread per chain: Verlet's
    cubic Hermite (the CPU's to rounding), DP5's damped force from the dense output's compression and its rate,
    Thornton's force from each contact's history (within the contract: DP5's quintic Hermite on the GPU against
    the CPU's continuous extension, and, yielding, steps retaken at turns located on them; measured 4e-10 and
    7e-10 apart), each within ``rtol`` of the largest force."""
    res = sim("sensors", 1, integrator, contact, True)
    gpu, cpu = res["cuda"], res["cpu"]
    assert gpu["status"] == cpu["status"] == 0
    scale = np.max(cpu["sensor_force"])  # (within rtol of the largest force: the small ones too)
    assert scale > 0.2
    np.testing.assert_allclose(gpu["sensor_force"], cpu["sensor_force"], rtol=0, atol=rtol * scale)
    np.testing.assert_allclose(gpu["wall_force"], cpu["wall_force"], rtol=0, atol=rtol * scale)


@pytest.mark.slow
def test_an_exponent_compiled_into_the_kernel_changes_no_bit():
    """``CudaBackend(compiled_exponent=True)`` compiles each chain's n into its kernel (for Hertz's 5/2 the general
    power's code leaves it): Hertz's chain with RKN4, the same damped with DP5 (the damped force's own powers of n)
    and an n = 3 chain, all on one backend, give the steps, peaks and final state of the kernel that reads n at run
    time, bit for bit. The n = 3 chain runs after the Hertz kernel is compiled: it gets a kernel of its own (three,
    where the run-time exponent needs two), else it would run with 5/2, and its peaks are not Hertz's (the control
    that n reaches the forces). An exponent that is no contact law's is refused."""
    res = sim("compiled_exponent", 1)
    for case in ("hertz", "damped", "n=3"):
        assert res["compiled"][case] == res["read"][case], case
    assert (res["read"]["kernels"], res["compiled"]["kernels"]) == (2, 3)
    hertz, cubic = res["read"]["hertz"]["peak_velocity"], res["read"]["n=3"]["peak_velocity"]
    assert abs(cubic[-1] - hertz[-1]) > 1e-3
    assert "finite n > 1" in res["exponent 1"]


def test_precompressed_granules_ahead_stay_exactly_at_rest():
    """A precompressed chain on the GPU is integrated in displacements from its static state, each contact pushing
    with its force less its static force computed by the same arithmetic: ahead of the pulse that is exactly 0, so
    the last granules are exactly at rest at t = 2 (the GPU integrates every granule; no window hides them).
    Negative control: the static forces differ from F0 by rounding, so an integration that subtracted F0 instead
    would push them."""
    res = sim("rest_ahead", 1)
    assert res["t_end"] == 2.0
    assert res["positions"][-2:] == [0.0, 0.0] and res["velocities"][-2:] == [0.0, 0.0]
    assert res["positions"][0] > 0.5
    assert any(r != 0.0 for r in res["residual"])


@pytest.mark.slow
def test_a_striker_on_a_loaded_chain_against_a_wall_is_the_cpus():
    """Real contacts together on the GPU (one thread per chain): a striker of twice the first granule's mass, a
    static load and a wall: the CPU's steps, peaks, wall force and energy balance to rounding."""
    res = sim("striker", 1)
    gpu, cpu = res["cuda"], res["cpu"]
    assert gpu["status"] == cpu["status"] == 0 and gpu["n_steps"] == cpu["n_steps"]
    for key in ("peak_velocity", "peak_force", "wall_force"):
        np.testing.assert_allclose(gpu[key], cpu[key], rtol=1e-12, atol=1e-14, err_msg=key)
    assert abs(gpu["energy_error"] - cpu["energy_error"]) < 1e-12


@pytest.mark.slow
@pytest.mark.parametrize("threads, exchange, args", [
    (1, "shared", (4, 2, 16.0, False, True, True, "decorated", "decorated", None)),
    (1, "shared", (4, 2, 16.0, False, True, True, "effective", "verlet:0.01", None)),
    (32, "shuffle", (2, 1, 5.0, False, False, True, "decorated", "decorated", None)),
], ids=["rkn4", "verlet", "rkn4 warp shuffles"])
def test_precompressed_chains_are_the_cpu_kernels(threads, exchange, args):
    """Precompressed chains (F0 = 1e-3), one thread per chain and one warp per chain: the CPU kernels' results to
    rounding (the static overlap in every compression, the dynamic force in the equations of motion, the total
    force in the records: each contact's peak starts from its static load), to the time limit; one thread per
    chain, a second run bitwise the first (the warp's run is not repeated: the simulator takes minutes for it)."""
    res = sim("compare", threads, exchange, *args, 1e-3)
    assert_same_run(res["cuda"], res["cpu"])
    assert res["again"] in (None, res["cuda"]) and (res["again"] is not None) == (threads == 1)
    assert np.min(res["cpu"]["peak_force"]) > 1e-3
    assert res["cpu"]["t_end"] == [args[2]] * len(res["cpu"]["t_end"])


@pytest.mark.slow
@pytest.mark.parametrize("threads, contact", [(1, "kuwabara-kono:0.05"), (4, "viscous:0.1")],
                         ids=["kuwabara-kono, one thread", "viscous, shared memory"])
def test_precompressed_damped_chains_are_the_cpu_kernels(threads, contact):
    """Damped contacts under a static load (DP5; the dissipated power of each contact from its total compression):
    the CPU's steps and dissipated energy, peaks within 1e-7 (read on another interpolant: measured 1.4e-8 at the
    damped default's rtol 1e-6)."""
    res = sim("compare", threads, "shared", 6 if threads == 1 else 4, 2 if threads == 1 else 1, 16.0, False, False,
              True, "effective", "damped", contact, 1e-3)
    gpu, cpu = res["cuda"], res["cpu"]
    assert gpu["status"] == cpu["status"] and gpu["n_steps"] == cpu["n_steps"]
    assert min(cpu["dissipated_energy"]) > 0.02
    np.testing.assert_allclose(gpu["dissipated_energy"], cpu["dissipated_energy"], rtol=1e-12)
    np.testing.assert_allclose(gpu["energy_error"], cpu["energy_error"], rtol=0, atol=1e-12)
    for key in ("peak_velocity", "peak_force"):
        np.testing.assert_allclose(gpu[key], cpu[key], rtol=1e-7, err_msg=key)


def assert_yielding_within_contract(gpu: dict, cpu: dict) -> None:
    """Yielding contacts against the CPU's run: a step is retaken to end where a contact turns from loading to
    unloading, located on the dense output, which the GPU reads on another interpolant (``kernel.make_kernel``):
    the turns move within the step's error, and with them the steps that follow, so the runs agree within the
    contract, not to rounding (measured: peaks 4e-8, dissipated energy 9e-8 apart). Steps within 2 %, peaks and
    the plastic work (the dissipated energy, from the final histories) within half the contract, and the energy
    balance E_end + W_plastic = E_0 within 1e-6 on both."""
    assert gpu["status"] == cpu["status"] and set(cpu["status"]) == {0}
    np.testing.assert_allclose(gpu["n_steps"], cpu["n_steps"], rtol=0.02)
    for key in ("peak_velocity", "peak_force"):
        np.testing.assert_allclose(gpu[key], cpu[key], rtol=5e-7, err_msg=key)
    assert min(cpu["dissipated_energy"]) > 0.1  # the contacts yielded
    np.testing.assert_allclose(gpu["dissipated_energy"], cpu["dissipated_energy"], rtol=5e-7)
    assert np.max(np.abs(gpu["energy_error"])) < 1e-6 and np.max(np.abs(cpu["energy_error"])) < 1e-6


@pytest.mark.slow
@pytest.mark.parametrize("threads, exchange, n_large, realizations", [(1, "shared", 4, 2), (4, "shared", 4, 1),
                                                                      (32, "shuffle", 2, 1)],
                         ids=["one thread", "shared memory", "warp shuffles"])
def test_yielding_contacts_are_the_cpus(threads, exchange, n_large, realizations):
    """Thornton's elastic-plastic contacts (yield speed 0.3, DP5 as the ensembles run them) on decorated chains:
    each contact's history kept by the thread that holds it, read by its neighbour across threads (shared memory,
    or one warp), moved after every accepted step: the CPU's run within the contract
    (:func:`assert_yielding_within_contract`); a second run bitwise the first (one thread per chain)."""
    res = sim("compare", threads, exchange, n_large, realizations, 16.0, False, threads == 1, True, "decorated", "damped",
              "plastic:0.3")
    assert_yielding_within_contract(res["cuda"], res["cpu"])
    if threads == 1:
        assert res["again"] == res["cuda"]


@pytest.mark.slow
def test_yielding_ensemble_on_the_gpu_is_the_cpus(tmp_path):
    """``run_ensemble`` of a family of yielding contacts on the GPU backend (one thread per chain), both chain
    kinds, through a store: DP5 for both (RKN4 cannot integrate a force with memory), the plastic work and the
    peaks within the contract of the CPU's, energy balanced within 1e-6."""
    res = sim("model_ensemble", 1, str(tmp_path / "plastic.zarr"), "plastic")
    gpu, cpu = res["cuda"], res["cpu"]
    assert gpu["integrator"] == cpu["integrator"] and "dp5" in cpu["integrator"]
    assert gpu["status"] == cpu["status"] and np.all(np.array(cpu["status"]) == 0)
    assert np.min(cpu["dissipated_energy"]) > 0.05
    np.testing.assert_allclose(gpu["dissipated_energy"], cpu["dissipated_energy"], rtol=5e-7)
    np.testing.assert_allclose(gpu["peak_velocity"], cpu["peak_velocity"], rtol=5e-7)
    assert np.max(np.abs(gpu["energy_error"])) < 1e-6


def test_warp_votes_give_the_last_lanes_value():
    """The shuffle exchange's integer reductions (``device.warp_last``, ``warp_any``) against NumPy's maximum
    over the warp, on values that are -1 or grow with the lane: none set, all set, only lane 31 (the ballot's
    sign bit), random. Negative control: where the values do not grow with the lane, the last lane's value
    is not the maximum (why the kernel only reduces granule and observed indices this way)."""
    rng = np.random.default_rng(3)
    patterns = [[-1] * 32, list(range(32)), [-1] * 31 + [40], [7] + [-1] * 31]
    for _ in range(6):
        grows = np.sort(rng.choice(200, size=32, replace=False))
        patterns.append(np.where(rng.random(32) < 0.3, grows, -1).tolist())
    control = [-1] * 32
    control[4], control[20] = 90, 12
    got = sim("votes", patterns + [control])
    for pattern, last, any_ in zip(patterns, got["last"][:-1], got["any"][:-1]):
        assert last == [max(pattern)] * 32, pattern
        assert any_ == [int(max(pattern) >= 0)] * 32, pattern
    assert got["last"][-1] == [12] * 32 != [max(control)] * 32


@pytest.mark.slow
@pytest.mark.parametrize("method, contact, load", [("rkn4", None, 0.0), ("dp5", None, 0.0), ("verlet", None, 0.0),
                                                   ("dp5", "kuwabara-kono:0.05", 0.0), ("dp5", "viscous:0.1", 0.0),
                                                   ("rkn4", None, 1e-2), ("dp5", "kuwabara-kono:0.05", 1e-3),
                                                   ("dp5", "plastic:0.2", 0.0), ("dp5", "plastic:0.2", 1e-4)],
                         ids=["rkn4", "dp5", "verlet", "dp5 kuwabara-kono", "dp5 viscous", "rkn4 precompressed",
                              "dp5 kuwabara-kono precompressed", "dp5 yielding", "dp5 yielding precompressed"])
@pytest.mark.parametrize("wall", [False, True], ids=["free end", "wall"])
def test_single_chain_against_dop853(wall, method, contact, load):
    """``simulate(backend=...)`` on the GPU backend, with each method it has a kernel for (Verlet at dt =
    2.5e-4, the step at which it meets the contract on decorated chains: ``benchmarks/bench_verlet.py``), and
    DP5 for contacts that dissipate (damped or yielding: to the same end, t = 15), elastic, damped and yielding
    chains under a static load (to t = 15: they do not stop at an exit), against SciPy's DOP853 (an independent
    integrator, which carries the yielding contacts' histories in its own way): peaks, grid velocities and force
    peaks (the wall's among them) within the accuracy contract, the energy balance E_end + E_dissipated = E_0
    within 1e-8 (yielding: E_end from each contact's final history, the plastic work dissipated); damped, yielding
    or loaded, also the force peaks' times and the wall force on the grid; damped or yielding, the dissipated
    energy; loaded, every force peak at or above the contact's static load and the wall's force at t = 0 that
    load (F0)."""
    res = sim("versus_dop853", 1, wall, method, contact, load)
    gpu, ref = res["cuda"], res["dop853"]
    assert gpu["status"] == ref["status"] == 0
    np.testing.assert_allclose(gpu["peak_velocity"], ref["peak_velocity"], rtol=1e-6)
    np.testing.assert_allclose(gpu["peak_time"][1:-1], ref["peak_time"][1:-1], atol=1e-5)
    np.testing.assert_allclose(gpu["grid"], ref["grid"], atol=1e-6)
    np.testing.assert_allclose(gpu["peak_force"], ref["peak_force"], rtol=1e-6)
    assert abs(gpu["energy_error"]) < 1e-8
    if contact is not None or load:
        np.testing.assert_allclose(gpu["peak_force_time"], ref["peak_force_time"], atol=1e-5)
        assert gpu["t_end"] == ref["t_end"] == 15.0
        if wall:
            np.testing.assert_allclose(gpu["wall_force"], ref["wall_force"], atol=1e-8)
    if contact is not None:
        assert ref["dissipated_energy"] > 0.04
        np.testing.assert_allclose(gpu["dissipated_energy"], ref["dissipated_energy"], rtol=1e-6)
    if load:
        static = np.array(res["static_force"])
        np.testing.assert_allclose(static, load, rtol=1e-12)
        assert np.all(np.array(gpu["peak_force"]) >= static * (1 - 1e-12))
        if wall:
            assert gpu["wall_force"][0] == pytest.approx(load, rel=1e-12)


def test_what_it_cannot_run_is_refused_naming_the_cpu_backend():
    got = sim("refusals")
    # The CPU refuses these too: the message names the methods that run them.
    assert "depends on velocities: use DP5" in got.pop("damping with RKN4")
    assert "depends on that history): use DP5" in got.pop("yielding contacts with RKN4")
    for case, message in got.items():
        assert message != "accepted", case
        assert "backend='cpu'" in message, (case, message)


def test_without_a_gpu_the_error_says_what_to_do():
    try:
        from numba import cuda

        if cuda.is_available():
            pytest.skip("a GPU is present")
    except Exception:  # noqa: BLE001
        pass
    got = sim("unavailable", simulator=False)
    assert got["error"] is not None
    assert "backend='cpu'" in got["error"] and "granchain[cuda]" in got["error"]
