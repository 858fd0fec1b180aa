"""1 versus 2 numba threads for the TLED explicit step, by mesh size: where does the second thread start to pay?

For each cube size (and the brain mesh with ``--brain-mesh``) the same model runs ``--updates`` element updates on
1 and on 2 threads (and with each of ``--kernels``), alternating, ``--repeats`` times; the table gives the median
wall time of each, the ratio
``wall(1 thread) / wall(2 threads)`` (> 1: two threads are faster) and the 1-minute load average before each case.
``tled.AUTO_THREADS_MIN_ELEMENTS`` (``n_threads="auto"``) is set from this crossover. Usage::

    python benchmarks/fem_threads.py --brain-mesh results/fem/brain_mesh.vtu
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
from fem_timing import cube_with_n_elements, machine, setup  # noqa: E402

from tissuemech.fem.tled import critical_time_step, numba_threads, run_explicit  # noqa: E402


def region_cost_us(n_regions: int = 20000, repeats: int = 5) -> dict:
    """Median microseconds of one empty ``prange(2)`` region (fork, a store per thread, join) called back to back from
    compiled code, on 1 and 2 threads: what one parallel region per explicit step costs in itself."""
    import numba
    from numba import njit, prange

    @njit(parallel=True)
    def region(a):
        for c in prange(2):
            a[16 * c] += 1.0

    @njit
    def regions(a, n):
        for _ in range(n):
            region(a)

    a = np.zeros(64)
    out = {}
    for threads in (1, 2):
        with numba_threads(threads):
            regions(a, 100)
            walls = []
            for _ in range(repeats):
                t0 = time.perf_counter()
                regions(a, n_regions)
                walls.append((time.perf_counter() - t0) / n_regions * 1e6)
        out[threads] = (float(np.median(walls)), float(min(walls)), float(max(walls)))
    del numba
    return out


def median_walls(model, v0, n_steps: int, repeats: int, kernels=("auto",)) -> dict:
    """Median wall seconds of ``n_steps`` explicit steps per ``(kernel, threads)`` for 1 and 2 threads, all measured
    alternately within each repeat (A/B under the same load)."""
    dt = critical_time_step(model, 0.7)
    walls = {(k, t): [] for k in kernels for t in (1, 2)}
    for kernel in kernels:
        for threads in (1, 2):  # warm-up (and compile)
            run_explicit(model, 3 * dt, dt_s=dt, v0_m_s=v0, n_outputs=1, track_energy=False, n_threads=threads,
                         kernel=kernel)
    for _ in range(repeats):
        for threads in (1, 2):
            for kernel in kernels:
                t0 = time.perf_counter()
                run_explicit(model, n_steps * dt, dt_s=dt, v0_m_s=v0, n_outputs=1, track_energy=False,
                             n_threads=threads, kernel=kernel)
                walls[kernel, threads].append(time.perf_counter() - t0)
    return {k: float(np.median(v)) for k, v in walls.items()}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", default="300,1e3,3e3,1e4,3e4,1e5")
    ap.add_argument("--laws", default="NH,QLV4-NH")
    ap.add_argument("--precisions", default="float64,float32")
    ap.add_argument("--updates", type=float, default=1e7, help="element updates per measurement")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--brain-mesh", default=None)
    ap.add_argument("--kernels", default="auto", help="kernels timed side by side (e.g. vectorised,fused)")
    ap.add_argument("--region-cost", action="store_true", help="also time an empty parallel region on 1 and 2 threads")
    args = ap.parse_args(argv)
    info = machine()
    print(f"# {info['date_utc']} UTC, CPU {info['cpu']}, {info['logical_cpus']} logical CPUs")
    if args.region_cost:
        for threads, (med, lo, hi) in region_cost_us().items():
            print(f"# empty prange(2) region, {threads} thread(s): {med:.2f} us (median of 5; {lo:.2f}-{hi:.2f}), "
                  f"load {os.getloadavg()[0]:.2f}", flush=True)
    with numba_threads(2):
        meshes = [("cube", cube_with_n_elements(float(s))) for s in args.sizes.split(",")]
        if args.brain_mesh:
            from tissuemech.fem.mesh import read_mesh

            meshes.append(("brain", read_mesh(args.brain_mesh)[0]))
        kernels = args.kernels.split(",")
        print(f"{'mesh':>6} {'tets':>7} {'law':>8} {'prec':>8} {'kernel':>10} {'steps':>6} {'1 thr s':>8} {'2 thr s':>8} "
              f"{'Mupd/s 1':>8} {'Mupd/s 2':>8} {'ratio':>6} {'load1':>5} {'load1 end':>9}")
        for name, mesh in meshes:
            for law in args.laws.split(","):
                for precision in args.precisions.split(","):
                    load = os.getloadavg()[0]
                    model, v0 = setup(mesh, law, precision, True)  # 2 element chunks (built under 2 threads)
                    n_steps = max(20, int(args.updates / mesh.n_elements))
                    walls = median_walls(model, v0, n_steps, args.repeats, kernels)
                    ne = mesh.n_elements
                    for kernel in kernels:
                        w1, w2 = walls[kernel, 1], walls[kernel, 2]
                        print(f"{name:>6} {ne:>7d} {law:>8} {precision:>8} {kernel:>10} {n_steps:>6d} {w1:>8.3f} "
                              f"{w2:>8.3f} {ne * n_steps / w1 / 1e6:>8.1f} {ne * n_steps / w2 / 1e6:>8.1f} "
                              f"{w1 / w2:>6.2f} {load:>5.2f} {os.getloadavg()[0]:>9.2f}", flush=True)
    print(f"# load average after: {os.getloadavg()}")


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
