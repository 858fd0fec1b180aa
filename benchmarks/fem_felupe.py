"""Quasi-static speed: TLED dynamic relaxation against FElupe (Newton, sparse direct) on the same indentation.

A 10 x 10 x 5 mm block, bottom fixed, a square 2.5 x 2.5 mm punch on a corner of the top face pushed 0.5 mm
(10 %) down (frictionless: only z prescribed), neo-Hookean mu = 1 kPa, ``--nu`` (0.45), plain linear tets (FElupe's
displacement-only tetra element, no ANP in TLED), 4 load steps, at about 1e3, 1e4 and 1e5 tets. Both solvers get
the same mesh and boundary conditions; FElupe runs its default ``Job`` (Newton, ``scipy.sparse.linalg.spsolve``),
TLED ``solve_quasistatic`` with each error-bound tolerance of ``--tol-fractions`` (of the smallest altitude). The table
gives wall and process-CPU seconds (TLED after a compile run on the same model), the punch force of each and their
relative difference, and the ratio FElupe / TLED of the CPU seconds (the speed-up of TLED). The 1-minute load is
printed before each size: on a shared machine compare ratios, not absolute times. Usage::

    python benchmarks/fem_felupe.py --sizes 1e3,1e4,1e5 --threads 1 --tol-fractions 1e-6,1e-3
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
from fem_timing import machine  # noqa: E402

from tissuemech.fem.materials import make_material  # noqa: E402
from tissuemech.fem.mesh import block_mesh  # noqa: E402
from tissuemech.fem.tled import build_model, fixed_group, numba_threads, solve_quasistatic, translation_group  # noqa: E402

#: cells (x, y, z) of the 10 x 10 x 5 mm block per nominal size (6 tets per cell; x, y multiples of 4 so that a
#: node line lies at the punch edge, 2.5 mm)
CELLS = {1e3: (8, 8, 3), 1e4: (16, 16, 7), 1e5: (32, 32, 16)}
LX, LZ, MU, DEPTH, PUNCH = 10e-3, 5e-3, 1000.0, 0.5e-3, 2.5e-3


def indentation_case(size: float):
    mesh = block_mesh((LX, LX, LZ), CELLS[size])
    x = mesh.nodes
    punch = np.isclose(x[:, 2], LZ) & (x[:, 0] <= PUNCH + 1e-12) & (x[:, 1] <= PUNCH + 1e-12)
    bottom = np.isclose(x[:, 2], 0.0)
    return mesh, punch, bottom


def run_felupe(mesh, punch, bottom, bulk_pa: float, n_steps: int = 4) -> tuple[float, float, float]:
    """Wall s, CPU s and punch force (N, z) of FElupe's Newton solution (mesh set-up included)."""
    import felupe as fem

    c0, t0 = time.process_time(), time.perf_counter()
    region = fem.RegionTetra(fem.Mesh(mesh.nodes.copy(), mesh.elements.astype(np.int64), "tetra"))
    field = fem.FieldContainer([fem.Field(region, dim=3)])
    bcs = {"bottom": fem.Boundary(field[0], mask=bottom), "punch": fem.Boundary(field[0], mask=punch, skip=(1, 1, 0))}
    solid = fem.SolidBody(fem.NeoHooke(mu=MU, bulk=bulk_pa), field)
    step = fem.Step(items=[solid], ramp={bcs["punch"]: fem.math.linsteps([0, 1], num=n_steps) * (-DEPTH)},
                    boundaries=bcs)
    fem.Job(steps=[step]).evaluate(verbose=0)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    force = solid.assemble.vector().toarray().reshape(-1, 3)[punch, 2].sum()
    return wall, cpu, float(force)


def run_tled(mesh, punch, bottom, material, tol_fraction: float, threads: int | None, n_steps: int = 4):
    """Wall s, CPU s, punch force (N, z) and DR iterations of TLED dynamic relaxation (after a compile run)."""
    groups = [translation_group("punch", np.flatnonzero(punch), (0, 0, -1), [0, 1], [0, DEPTH],
                                dofs=(False, False, True)),
              fixed_group("bottom", np.flatnonzero(bottom))]
    model = build_model(mesh, material, groups, anp=False)
    tol = tol_fraction * model.min_altitude_m
    times = np.linspace(0, 1, n_steps + 1)[1:]
    with numba_threads(threads):
        solve_quasistatic(model, [1e-3], tol_m=tol, n_threads=threads)  # compile / warm-up
        c0, t0 = time.process_time(), time.perf_counter()
        res = solve_quasistatic(model, times, tol_m=tol, n_threads=threads)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return wall, cpu, float(res.reaction_force_n["punch"][-1, 2]), int(res.iterations.sum())


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", default="1e3,1e4,1e5")
    ap.add_argument("--nu", type=float, default=0.45)
    ap.add_argument("--threads", type=int, default=1, help="numba threads of TLED")
    ap.add_argument("--tol-fractions", default="1e-6,1e-3",
                    help="DR error-bound tolerances as fractions of the smallest altitude (1e-6: solve_quasistatic's "
                         "default), comma separated: TLED runs once per tolerance, FElupe once per size")
    args = ap.parse_args(argv)
    info = machine()
    print(f"# {info['date_utc']} UTC, CPU {info['cpu']}, {info['logical_cpus']} logical CPUs; TLED threads "
          f"{args.threads}; nu = {args.nu}")
    material = make_material("neo_hookean", {"mu": MU}, poisson_ratio=args.nu)
    print(f"{'tets':>7} {'DR tol':>6} {'load1':>5} {'FElupe wall':>11} {'cpu':>7} {'TLED wall':>9} {'cpu':>7} {'DR iter':>7} "
          f"{'F FElupe mN':>11} {'F TLED mN':>10} {'rel diff':>9} {'cpu ratio':>9} {'wall ratio':>10}")
    for size in (float(s) for s in args.sizes.split(",")):
        mesh, punch, bottom = indentation_case(size)
        load = os.getloadavg()[0]
        tled = [(tol, run_tled(mesh, punch, bottom, material, tol, args.threads))
                for tol in (float(t) for t in args.tol_fractions.split(","))]
        fw, fc, ff = run_felupe(mesh, punch, bottom, material.bulk_modulus_pa)
        for tol, (tw, tc, tf, it) in tled:
            print(f"{mesh.n_elements:>7d} {tol:>6.0e} {load:>5.2f} {fw:>11.2f} {fc:>7.2f} {tw:>9.2f} {tc:>7.2f} {it:>7d} "
                  f"{ff * 1e3:>11.4f} {tf * 1e3:>10.4f} {abs(tf / ff - 1):>9.1e} {fc / tc:>9.2f} {fw / tw:>10.2f}",
                  flush=True)
    print(f"# load average after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
