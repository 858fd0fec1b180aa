"""Memory order of the mesh and the TLED step rate: as given, shuffled, and renumbered (reverse Cuthill-McKee).

For the cube meshes (and the brain mesh with ``--brain-mesh``) the explicit step (neo-Hookean, ANP, float64,
1 thread, best of ``--repeats``) runs on the mesh as generated, on a randomly shuffled copy (nodes and elements),
on the shuffled copy renumbered by ``mesh.reorder_for_locality`` and on the given mesh renumbered; every variant
is built with ``reorder=False`` so that the order measured is the one given. Printed: element updates per wall and
per CPU second, the mean element node span (``mesh.mean_element_span``) and the load. ``build_model(reorder="auto")``
renumbers when that at least halves the span. Usage::

    python benchmarks/fem_locality.py --sizes 1e4,1e5 --brain-mesh results/fem/brain_mesh.vtu
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
from fem_timing import cube_with_n_elements, machine  # noqa: E402

from tissuemech.fem.materials import make_material  # noqa: E402
from tissuemech.fem.mesh import TetMesh, mean_element_span, read_mesh, reorder_for_locality  # noqa: E402
from tissuemech.fem.tled import build_model, critical_time_step, fixed_group, numba_threads, run_explicit  # noqa: E402


def shuffled(mesh: TetMesh, seed: int = 0) -> TetMesh:
    """The mesh with its nodes and elements in random order."""
    rng = np.random.default_rng(seed)
    perm = rng.permutation(mesh.n_nodes)
    new_index = np.empty_like(perm)
    new_index[perm] = np.arange(perm.size)
    return TetMesh(mesh.nodes[perm], new_index[mesh.elements][rng.permutation(mesh.n_elements)].astype(np.int32))


def rate(mesh: TetMesh, repeats: int, updates: float) -> tuple[float, float]:
    """Best element updates per wall and per CPU second (1e6/s) of explicit steps on ``mesh`` in its own order."""
    mat = make_material("neo_hookean", {"mu": 1000.0}, poisson_ratio=0.49, density_kg_m3=1040.0)
    x = mesh.nodes
    height = (x[:, 2] - x[:, 2].min()) / np.ptp(x[:, 2])
    model = build_model(mesh, mat, [fixed_group("bottom", np.flatnonzero(height < 0.05))], reorder=False)
    v0 = np.zeros_like(x)
    v0[:, 0] = 1e-3 * height
    dt = critical_time_step(model)
    n = max(50, int(updates / mesh.n_elements))
    with numba_threads(1):
        run_explicit(model, 3 * dt, dt_s=dt, v0_m_s=v0, n_outputs=1, track_energy=False)
        walls, cpus = [], []
        for _ in range(repeats):
            c0, t0 = time.process_time(), time.perf_counter()
            run_explicit(model, n * dt, dt_s=dt, v0_m_s=v0, n_outputs=1, track_energy=False)
            walls.append(time.perf_counter() - t0)
            cpus.append(time.process_time() - c0)
    return mesh.n_elements * n / min(walls) / 1e6, mesh.n_elements * n / min(cpus) / 1e6


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", default="1e4,1e5")
    ap.add_argument("--brain-mesh", default=None)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--updates", type=float, default=4e6)
    args = ap.parse_args(argv)
    info = machine()
    print(f"# {info['date_utc']} UTC, CPU {info['cpu']}, {info['logical_cpus']} logical CPUs; neo-Hookean, ANP, "
          f"float64, 1 thread")
    meshes = [(f"cube {float(s):.0e}", cube_with_n_elements(float(s))) for s in args.sizes.split(",")]
    if args.brain_mesh:
        meshes.append(("brain", read_mesh(args.brain_mesh)[0]))
    print(f"{'mesh':>10} {'tets':>7} {'variant':>14} {'span':>7} {'Mupd/s':>7} {'Mupd/cpu-s':>10} {'load1':>5}")
    for name, mesh in meshes:
        mixed = shuffled(mesh)
        for variant, m in (("given", mesh), ("shuffled", mixed), ("RCM(shuffled)", reorder_for_locality(mixed)),
                           ("RCM(given)", reorder_for_locality(mesh))):
            load = os.getloadavg()[0]
            wall, cpu = rate(m, args.repeats, args.updates)
            print(f"{name:>10} {m.n_elements:>7d} {variant:>14} {mean_element_span(m.elements):>7.0f} {wall:>7.1f} "
                  f"{cpu:>10.1f} {load:>5.2f}", flush=True)
    print(f"# load average after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
