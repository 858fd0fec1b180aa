"""The machine's limits for the TLED step: memory bandwidth (copy / triad) and an estimate of peak flops.

* bandwidth: numpy ``copy`` (1 thread) and a numba ``prange`` triad ``a = b + s c`` on 1 and 2 threads, on arrays
  that fit in L3 (3 x 2.7 MB, like a 10k-tet model's element arrays) and on arrays that do not (3 x 134 MB); bytes
  counted as read + written (no write-allocate);
* peak double-precision flops: cores x clock (``lscpu`` / ``/proc/cpuinfo`` MHz) x 16 flop per cycle (Zen 4:
  two 256-bit FMA pipes, AVX-512 instructions double-pumped: 2 x 4 doubles x 2 flops);
* the TLED step's bytes per element update, counted from the arrays each pass of the vectorised kernel reads and
  writes (neo-Hookean, ANP; gathers of node data counted once per element, i.e. perfect cache reuse), and its flops
  per element update (counted from the formulas: ~300 flop, fem.md section 0), against a measured rate.

Usage: ``python benchmarks/fem_roofline.py --rate 4.1e7 --threads 2`` prints the fractions of the two limits a
measured element-update rate reaches (the rate itself comes from ``fem_timing.py`` / ``fem_realtime.py``).
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))
from tissuemech.numba_cache import use_source_keyed_cache  # noqa: E402 (before anything imports numba)

use_source_keyed_cache(Path(__file__).resolve().parents[1] / ".numba_cache")
sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402
from numba import njit, prange  # noqa: E402

from fem_timing import machine  # noqa: E402


@njit(parallel=True, cache=True)
def triad(a, b, c, s):
    for i in prange(a.size):
        a[i] = b[i] + s * c[i]


def bandwidth(n: int, threads: int, repeats: int = 20) -> tuple[float, float]:
    """Best GB/s of numpy copy (1 thread) and of the numba triad on ``threads`` threads, arrays of ``n`` doubles."""
    import numba

    a, b, c = np.zeros(n), np.ones(n), np.ones(n)
    numba.set_num_threads(threads)
    triad(a, b, c, 0.5)
    best_copy, best_triad = np.inf, np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        np.copyto(a, b)
        best_copy = min(best_copy, time.perf_counter() - t0)
        t0 = time.perf_counter()
        triad(a, b, c, 0.5)
        best_triad = min(best_triad, time.perf_counter() - t0)
    return 16 * n / best_copy / 1e9, 24 * n / best_triad / 1e9


def clock_ghz() -> float:
    mhz = [float(ln.split(":")[1]) for ln in open("/proc/cpuinfo") if ln.startswith("cpu MHz")]
    return max(mhz) / 1e3 if mhz else float("nan")


#: bytes per element update of the vectorised neo-Hookean ANP step, float64 storage (float32: element arrays
#: halve): kinematics (conn 16, dN/dX 72, V0 8, gathered u 96 / 4 nodes shared ~ 24 with reuse -> counted 24;
#: writes F-I 72, J^-2/3 8, pe 8), nodal pressure (per element: incidence 16, pe 32 / 4 ... ~ 12, p_node 2),
#: stress + forces (F-I 72, J^-2/3 8, conn 16, dN/dX 72, V0 8, p_node ~8, W1/W2 16; writes 96), node pass (incidence
#: 16, element forces 96, per node ~1/4 of: u, u_old, u_new, f_int 4 x 24 and 3 coefficients 24 -> ~30)
BYTES_PER_UPDATE_F64 = (16 + 72 + 8 + 24 + 88) + (16 + 12 + 2) + (72 + 8 + 16 + 72 + 8 + 8 + 16 + 96) + (16 + 96 + 30)
#: the element arrays in float32 (dN/dX, V0, F - I, J^-2/3, pe, W1/W2 stay float64, forces, states) roughly halve
BYTES_PER_UPDATE_F32 = 0.6 * BYTES_PER_UPDATE_F64
#: floating-point operations per element update (F 36, cofactor + J 30, b 27, J^-2/3 Newton 20, stress 30, forces
#: 9 x 5 x 3 + 27, nodal pressure and averaging 10, node pass 12 x 1 + 9; fem.md: ~250-300)
FLOPS_PER_UPDATE = 300


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rate", type=float, action="append", default=[],
                    help="measured element updates per second to compare (repeatable)")
    ap.add_argument("--precision", default="float64")
    args = ap.parse_args(argv)
    info = machine()
    cores = os.cpu_count()
    ghz = clock_ghz()
    peak = cores * ghz * 16.0
    print(f"# {info['date_utc']} UTC, CPU {info['cpu']}, {cores} logical CPUs, clock {ghz:.2f} GHz, "
          f"load {info['load_avg_1_5_15']}")
    print(f"peak double-precision flops (estimate): {peak:.0f} GFLOP/s ({cores} x {ghz:.2f} GHz x 16 flop/cycle)")
    rows = {}
    for label, n in (("L3-resident, 3 x 2.7 MB", 2**18 + 2**16 + 2**15), ("DRAM, 3 x 134 MB", 2**24)):
        for threads in (1, 2):
            cp, tr = bandwidth(n, threads)
            rows[(label, threads)] = tr
            print(f"bandwidth {label}, {threads} thread(s): copy (numpy, 1 thread) {cp:.1f} GB/s, triad {tr:.1f} GB/s")
    bpu = BYTES_PER_UPDATE_F64 if args.precision == "float64" else BYTES_PER_UPDATE_F32
    print(f"TLED step (vectorised, neo-Hookean, ANP, {args.precision}): ~{bpu:.0f} B and ~{FLOPS_PER_UPDATE} flop per "
          f"element update")
    for rate in args.rate:
        gbs = rate * bpu / 1e9
        print(f"rate {rate:.3g} upd/s: {gbs:.1f} GB/s = {gbs / rows[('L3-resident, 3 x 2.7 MB', 2)]:.0%} of the 2-thread "
              f"L3 triad, {gbs / rows[('DRAM, 3 x 134 MB', 2)]:.0%} of the DRAM triad; "
              f"{rate * FLOPS_PER_UPDATE / 1e9:.1f} GFLOP/s = {rate * FLOPS_PER_UPDATE / 1e9 / peak:.1%} of peak")
    print(f"# load average after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
