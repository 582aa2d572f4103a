"""The GPU kernels' registers, spills and shared memory, and the chains each multiprocessor can hold: what
NVIDIA's assembler (ptxas) allots every compiled kernel of ``granchain.backends.cuda.kernel``, for an
architecture, with no GPU at hand.

Why: one chain is one block (a warp at ``L`` = 32), and a multiprocessor holds as many blocks as its
registers allow (65,536 per multiprocessor on sm_80 and sm_90, allotted per warp in units of 256, so a
thread's count is rounded up to a multiple of 8), up to 32 blocks and 64 warps. A step is a chain of
dependent operations (stages, shuffles, the error norm's maximum), so fewer resident chains means more idle
issue slots; a register cap trades them for spills to local memory. ptxas decides all of this at compile
time, so it can be read here; how fast a layout runs is measured on a GPU by ``benchmarks/bench_gpu.py``.

Each line: the kernel (method, threads per chain L, exchange, granules per thread G, register cap), the
registers, the bytes of spill stores and loads and of shared memory, the chains per multiprocessor that
registers and shared memory allow, and that number as a ratio to the default kernel's (RKN4, L = 32, warp
shuffles and votes, G = 1: the paper's N = 26 chains), measured in the same run. Also a digest of each
kernel's PTX (symbols and comments removed): equal digests are the same machine code, which is how a change
to one method's code can be shown to leave another's kernel untouched. Compare a kernel's digests between runs
of the same ``--methods`` and ``--caps``: a kernel's PTX also depends on what the process compiled before it
(measured: the G = 2 kernel's digest differs when the capped kernels are not compiled first), and the default
kernel, always compiled first, has one digest whatever the lists.

Needs Numba's CUDA target and NVIDIA's compiler wheels (NVVM, ptxas), which ``pip install
"numba-cuda[cu12]"`` brings (a few hundred MB; not in granchain's own extras, which run on a GPU machine's
own CUDA)::

    python benchmarks/gpu_registers.py                  # sm_90 (H100, H200)
    python benchmarks/gpu_registers.py --cc 8.0 --caps 128,96
"""

from __future__ import annotations

import argparse
import hashlib
import os
import re
import shutil
import subprocess
import sys
import tempfile

#: Per multiprocessor, for compute capability 8.0 and 9.0: registers, warps, blocks, shared memory (bytes).
SM_REGISTERS = 65536
SM_WARPS = 64
SM_BLOCKS = 32
SM_SHARED = {(8, 0): 164 * 1024, (9, 0): 228 * 1024}
#: Registers are allotted per warp in units of 256: per thread, a multiple of 8.
REGISTER_UNIT = 8
#: The default kernel: the one ``CudaBackend()`` compiles for the paper's N = 26 chains.
BASELINE = ("rkn4", 32, "shuffle", 1, None)


def resident_chains(registers: int, shared_bytes: int, threads_per_chain: int, cc=(9, 0), block_threads: int = 64) -> int:
    """Chains one multiprocessor holds at once: its resident blocks, the least of what its registers, its
    warps, its block slots and its shared memory allow, times the chains per block. A chain of
    ``threads_per_chain`` > 1 threads is one block; one thread per chain packs ``block_threads`` chains in a
    block (``granchain.backends.cuda.BLOCK_THREADS``)."""
    threads, chains = (threads_per_chain, 1) if threads_per_chain > 1 else (block_threads, block_threads)
    warps = -(-threads // 32)
    per_thread = -(-registers // REGISTER_UNIT) * REGISTER_UNIT
    by_registers = SM_REGISTERS // (per_thread * 32 * warps)
    by_shared = SM_SHARED.get(tuple(cc), SM_SHARED[(9, 0)]) // shared_bytes if shared_bytes else SM_BLOCKS
    return int(min(by_registers, SM_WARPS // warps, SM_BLOCKS, by_shared)) * chains


def parse_ptxas(text: str) -> dict:
    """Registers, spill stores and loads, shared memory (bytes) from ``ptxas -v``'s report of one kernel."""
    def num(pattern):
        m = re.search(pattern, text)
        return int(m.group(1)) if m else 0

    return {"registers": num(r"Used (\d+) registers"), "spill_stores": num(r"(\d+) bytes spill stores"),
            "spill_loads": num(r"(\d+) bytes spill loads"), "shared": num(r"(\d+) bytes smem"),
            "stack": num(r"(\d+) bytes stack frame")}


def ptx_digest(ptx: str) -> str:
    """A digest of the PTX's code alone: comments (the compiler's build), the declarations of Numba's
    environment words (one per device function, which no instruction reads, so that moving code into a
    device function of its own changes nothing) and mangled symbols (which carry closure addresses and
    module names) removed."""
    lines = [line for line in ptx.splitlines()
             if line.strip() and not line.startswith("//") and not (line.startswith(".common") and "NumbaEnv" in line)]
    body = "\n".join(lines)
    body = re.sub(r"_ZN[0-9A-Za-z_]+", "SYM", body)
    return hashlib.sha256(body.encode()).hexdigest()[:12]


def find_ptxas() -> str | None:
    """ptxas from NVIDIA's nvcc wheel, else from PATH or CUDA_HOME."""
    try:
        import nvidia.cuda_nvcc as nvcc  # the wheel numba-cuda[cu12] installs

        for base in list(getattr(nvcc, "__path__", [])):
            exe = os.path.join(base, "bin", "ptxas")
            if os.path.exists(exe):
                return exe
    except ImportError:
        pass
    exe = shutil.which("ptxas")
    if exe:
        return exe
    home = os.environ.get("CUDA_HOME") or os.environ.get("CUDA_PATH")
    if home and os.path.exists(os.path.join(home, "bin", "ptxas")):
        return os.path.join(home, "bin", "ptxas")
    return None


def _compile_for(cc):
    """Device functions are compiled for the current device's architecture; without a GPU there is none,
    so Numba is told the one asked for (only this process, only for compiling PTX)."""
    import numba.cuda.dispatcher as dispatcher
    from numba import cuda

    try:
        if cuda.is_available():
            return
    except Exception:  # noqa: BLE001 - no driver
        pass

    class _Device:
        compute_capability = tuple(cc)

    dispatcher.get_current_device = lambda: _Device()


def signature(plastic: bool = False, sensed: bool = False):
    """The kernel's argument types as ``CudaBackend._run`` passes them (C-contiguous device arrays; the yielding
    contacts' histories and the sensed contacts and their forces, or empty tuples for the kernels without them)."""
    from numba import float64, int64, typeof

    f1, f2, f3, i1 = float64[::1], float64[:, ::1], float64[:, :, ::1], int64[::1]
    return (f2, f2, f1, f1, i1, i1, f1, f1, f1,  # masses, stiffness, v_init, t_limit, obs_of, obs, t_grid, ends, prm
            f2, f2, f2, f2, f2, f3, f2,  # peak_v, peak_t, peak_f, peak_ft, peak_d, grid_v, grid_f
            i1, i1, i1, f1, f1, i1, f1, f1, f2, f2,  # status, steps, rejected, t_end, exit, lo, frozen, dissipated, x, v
            f2 if plastic else typeof(()),  # history
            i1 if sensed else typeof(()), f3 if sensed else typeof(()))  # sensors, grid_c


def report(method: str, L: int, exchange: str, G: int, cap: int | None, cc, ptxas: str, fixed: bool = False,
           damped: bool = False, precompressed: bool = False, plastic: bool = False, sensed: bool = False,
           exponent: float | None = None) -> dict:
    """Compile one kernel to PTX (NVVM) and assemble it (ptxas -v): its resources and digest. ``exponent``: the
    contact law's n compiled in (``make_kernel``'s ``exponent``; None: read at run time, the default kernels)."""
    from numba import cuda

    from granchain.backends.cuda import BLOCK_THREADS
    from granchain.backends.cuda.kernel import make_kernel

    kernel = make_kernel(L, G, cap, exchange == "shuffle", exchange == "shuffle", method, fixed, damped, precompressed,
                         plastic, sensed, exponent)
    ptx, _ = cuda.compile_ptx(kernel.py_func, signature(plastic, sensed), cc=tuple(cc))
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "kernel.ptx")
        with open(path, "w") as f:
            f.write(ptx)
        args = [ptxas, f"-arch=sm_{cc[0]}{cc[1]}", "-v", *([f"-maxrregcount={cap}"] if cap else []), path,
                "-o", os.path.join(tmp, "kernel.cubin")]
        done = subprocess.run(args, capture_output=True, text=True, check=True)
    res = parse_ptxas(done.stderr)
    res["digest"] = ptx_digest(ptx)
    res["chains_per_sm"] = resident_chains(res["registers"], res["shared"], L, cc, BLOCK_THREADS)
    return res


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cc", default="9.0", help="compute capability, e.g. 9.0 (H100, H200) or 8.0 (A100); default 9.0")
    ap.add_argument("--methods", default="rkn4,dp5,verlet,dp5-damped,rkn4-precompressed,dp5-plastic,rkn4-hertz",
                    help="methods, comma-separated; a suffix -damped: for contacts that dissipate (DP5 only), "
                         "-plastic: for contacts that yield (DP5 only, instead of -damped), -precompressed: for "
                         "precompressed chains, -sensed: with force sensors on the grid, -hertz: Hertz's n = 5/2 "
                         "compiled into the kernel (CudaBackend(compiled_exponent=True); also at G = 2, the decorated "
                         "chains'), after the others (default "
                         "rkn4,dp5,verlet,dp5-damped,rkn4-precompressed,dp5-plastic,rkn4-hertz)")
    ap.add_argument("--caps", default="168,128,96", help="register caps tried on the default layout (default 168,128,96)")
    args = ap.parse_args(argv)
    try:
        cc = tuple(int(x) for x in args.cc.split("."))
        caps = [int(x) for x in args.caps.split(",") if x]
    except ValueError:
        ap.error(f"--cc must be like 9.0 and --caps like 128,96; got {args.cc!r}, {args.caps!r}")
    methods = [m for m in args.methods.split(",") if m]
    try:
        from numba import cuda  # noqa: F401
    except ImportError as exc:
        print(f"Numba's CUDA target is missing ({exc}): pip install \"numba-cuda[cu12]\"", file=sys.stderr)
        return 2
    ptxas = find_ptxas()
    if ptxas is None:
        print("ptxas not found (NVIDIA's nvcc wheel, PATH or CUDA_HOME): pip install \"numba-cuda[cu12]\"", file=sys.stderr)
        return 2
    _compile_for(cc)
    # (method, L, exchange, G, cap): the default first (the baseline), its caps, the other layouts, the other methods.
    cases = [BASELINE] + [("rkn4", 32, "shuffle", 1, c) for c in caps]
    cases += [("rkn4", 32, "shuffle", 2, None), ("rkn4", 32, "shared", 1, None), ("rkn4", 64, "shared", 1, None),
              ("rkn4", 1, "shared", 32, None)]
    cases += [(m, 32, "shuffle", 1, None) for m in methods if m != "rkn4"]
    cases += [(m, 32, "shuffle", 2, None) for m in methods if m.endswith("-hertz")]  # the decorated chains' G
    base = None
    for method, L, exchange, G, cap in cases:
        if method not in methods:
            continue
        name, damped, precompressed = method.partition("-")[0], "-damped" in method, "-precompressed" in method
        r = report(name, L, exchange, G, cap, cc, ptxas, damped=damped, precompressed=precompressed,
                   plastic="-plastic" in method, sensed="-sensed" in method, exponent=2.5 if "-hertz" in method else None)
        base = r if base is None else base
        print(f"[registers sm_{cc[0]}{cc[1]}] {method} L={L} {exchange} G={G} cap {cap or 'none'}: "
              f"{r['registers']} registers, spills {r['spill_stores']} B stored / {r['spill_loads']} B loaded, "
              f"stack {r['stack']} B, shared {r['shared']:,} B; {r['chains_per_sm']} chains per multiprocessor = "
              f"{r['chains_per_sm'] / base['chains_per_sm']:.2f}x the default kernel's ({base['chains_per_sm']}); "
              f"ptx {r['digest']}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
