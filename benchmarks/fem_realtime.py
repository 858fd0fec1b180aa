"""Real-time factor of the TLED explicit step on the MNI brain (issue 17 targets), with float32 vs float64 agreement.

For each brain mesh given (e.g. the pipeline's ``results/fem/brain_mesh.vtu`` and an older or finer one) and each law
(neo-Hookean, QLV with 4 Prony terms on neo-Hookean, with ``--laws NH,QLV4-NH,PR4-NH`` also the nonseparable
extension Pipkin-Rogers with the same small-strain weights; mu = 1 kPa, nu = 0.49, rho = 1040 kg/m^3, ANP, the lowest
5 % of the brain fixed, an initial shear-velocity field), the explicit step runs at the critical step
``0.7 min altitude / c_d`` on 1 and 2 threads (alternating, ``--repeats`` times, median kept) in float64 and float32
storage. Printed: element updates per wall second (median of the repeats), the real-time factor (simulated / wall
seconds), the 1-minute load before and after the case, with ``--kernels`` the speed ratio of each kernel to the first
(all kernels and thread counts interleaved within each repeat), and the float32 - float64 difference of the displacement field and of the support reaction
after the timed steps (relative to their float64 maxima). ``--cube`` adds a ~10k-tet cube (the 8e7 updates/s
target). Usage::

    python benchmarks/fem_realtime.py --brain-mesh results/fem/brain_mesh.vtu [--brain-mesh improved.vtu] --cube
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

from tissuemech.fem.mesh import mesh_quality, read_mesh  # noqa: E402
from tissuemech.fem.tled import build_model, critical_time_step, numba_threads, run_explicit  # noqa: E402


def timed(model, v0, dt, n_steps, threads, kernel="auto"):
    t0 = time.perf_counter()
    res = run_explicit(model, n_steps * dt, dt_s=dt, v0_m_s=v0, n_outputs=1, track_energy=False, n_threads=threads,
                       kernel=kernel)
    return time.perf_counter() - t0, res


def mass_scaling_indentation(mesh, factor: float, law: str = "QLV4-NH", precision: str = "float32",
                             depth_m: float = 2e-3, ramp_s: float = 0.2, hold_s: float = 0.1, radius_m: float = 7.5e-3,
                             damping_1_s: float = 20.0):
    """Explicit flat-punch indentation of the brain (the top nodes within ``radius_m`` of the highest node pushed
    ``depth_m`` down over ``ramp_s``, held ``hold_s``; lowest 5 % fixed), without and with selective mass scaling
    to ``factor`` times the unscaled critical step. Returns a dict with the step, the added mass, the wall times, and
    the largest differences of the punch force history (relative to its peak) and of the final displacement
    (relative to its largest value)."""
    from tissuemech.fem.materials import make_material
    from tissuemech.fem.tled import fixed_group, translation_group

    from fem_timing import LAWS

    key, params, g, tau, *pr = LAWS[law]
    mat = make_material(key, params, poisson_ratio=0.49, density_kg_m3=1040.0, prony_g=g, prony_tau_s=tau,
                        pipkin_rogers=pr[0] if pr else None)
    x = mesh.nodes
    height = (x[:, 2] - x[:, 2].min()) / np.ptp(x[:, 2])
    top = x[np.argmax(x[:, 2])]
    from tissuemech.fem.mesh import boundary_nodes

    surf = boundary_nodes(mesh.elements)
    under = surf[(np.linalg.norm(x[surf, :2] - top[:2], axis=1) < radius_m) & (x[surf, 2] > top[2] - 10e-3)]
    t_end = ramp_s + hold_s
    groups = [translation_group("punch", under, (0, 0, -1), [0, ramp_s, t_end], [0, depth_m, depth_m],
                                dofs=(False, False, True)),
              fixed_group("bottom", np.flatnonzero(height < 0.05))]
    out = {"punch_nodes": int(under.size)}
    runs = {}
    for name, safety, scaled in (("plain", 0.7, False), ("scaled", 0.7, True), ("plain_half_step", 0.35, False)):
        model = build_model(mesh, mat, groups, precision=precision)
        if scaled:
            model = build_model(mesh, mat, groups, precision=precision,
                                mass_scaling_step_s=factor * critical_time_step(model, 1.0))
        dt = critical_time_step(model, safety)
        run_explicit(model, 3 * dt, dt_s=dt, n_outputs=1, track_energy=False)
        t0 = time.perf_counter()
        res = run_explicit(model, t_end, dt_s=dt, damping_1_s=damping_1_s, n_outputs=200, track_energy=False)
        wall = time.perf_counter() - t0
        runs[name] = res
        out[f"{name}_dt_s"] = dt
        out[f"{name}_wall_s"] = wall
        out[f"{name}_rt"] = t_end / wall
        out[f"{name}_added_mass"] = model.added_mass_fraction
    fp = runs["plain"].reaction_force_n["punch"][:, 2]
    out["peak_force_n"] = float(np.abs(fp).max())
    up = runs["plain"].displacement_m
    # "scaled": the error of mass scaling; "plain_half_step": the unscaled run at half the step, i.e. how much the
    # force history of this dynamic indentation depends on the time discretisation alone
    for other in ("scaled", "plain_half_step"):
        fs = np.interp(runs["plain"].time_s, runs[other].time_s, runs[other].reaction_force_n["punch"][:, 2])
        out[f"{other}_force_diff_of_peak"] = float(np.abs(fs - fp).max() / np.abs(fp).max())
        out[f"{other}_final_force_diff"] = float(abs(fs[-1] / fp[-1] - 1))
        out[f"{other}_displacement_diff_of_max"] = float(np.abs(runs[other].displacement_m - up).max() / np.abs(up).max())
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--brain-mesh", action="append", default=[])
    ap.add_argument("--cube", action="store_true", help="also a ~10k-tet cube")
    ap.add_argument("--laws", default="NH,QLV4-NH")
    ap.add_argument("--seconds", type=float, default=0.1, help="simulated seconds per measurement")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--kernels", default="auto",
                    help="internal-force kernels timed side by side, interleaved (e.g. vectorised,fused); the "
                         "float32 - float64 difference is per kernel, 'vs 1st' the speed ratio to the first kernel")
    ap.add_argument("--precisions", default="float64,float32")
    ap.add_argument("--rt-mass-scaling", type=float, default=None,
                    help="build the timed models with selective mass scaling to this multiple of the unscaled "
                         "critical step (the table's RT then includes it)")
    ap.add_argument("--mass-scaling", type=float, default=None,
                    help="also an explicit brain indentation with selective mass scaling to this multiple of the "
                         "unscaled critical step, against the unscaled run (first brain mesh)")
    args = ap.parse_args(argv)
    info = machine()
    print(f"# {info['date_utc']} UTC, CPU {info['cpu']}, {info['logical_cpus']} logical CPUs; mass scaling "
          f"{args.rt_mass_scaling or 'none'}")
    meshes = [(Path(p).stem, read_mesh(p)[0]) for p in args.brain_mesh]
    if args.cube:
        meshes.append(("cube", cube_with_n_elements(1e4)))
    kernels = args.kernels.split(",")
    print(f"{'mesh':>16} {'tets':>6} {'alt mm':>6} {'law':>8} {'prec':>7} {'kernel':>10} {'steps':>6} {'load1':>5} "
          f"{'Mupd/s 1t':>9} {'Mupd/s 2t':>9} {'RT 1t':>6} {'RT 2t':>6} {'vs 1st 1t':>9} {'vs 1st 2t':>9} "
          f"{'du32/u64':>9} {'dF32/F64':>9} {'load1 end':>9}")
    with numba_threads(2):
        for name, mesh in meshes:
            alt = mesh_quality(mesh)["min_altitude_m"]
            for law in args.laws.split(","):
                ref = {}
                for precision in args.precisions.split(","):
                    load = os.getloadavg()[0]
                    model, v0 = setup(mesh, law, precision, True)
                    if args.rt_mass_scaling:
                        model = build_model(mesh, model.material, model.groups, precision=precision,
                                            mass_scaling_step_s=args.rt_mass_scaling * critical_time_step(model, 1.0))
                    dt = critical_time_step(model, 0.7)
                    n_steps = max(20, int(round(args.seconds / dt)))
                    for kernel in kernels:
                        for threads in (1, 2):
                            timed(model, v0, dt, 3, threads, kernel)
                    # every repeat times each kernel on 1 and 2 threads back to back (A/B under the same load)
                    walls = {(k, t): [] for k in kernels for t in (1, 2)}
                    last = {}
                    for _ in range(args.repeats):
                        for threads in (1, 2):
                            for kernel in kernels:
                                wall, res = timed(model, v0, dt, n_steps, threads, kernel)
                                walls[kernel, threads].append(wall)
                                last[kernel] = res
                    load_end = os.getloadavg()[0]
                    ne = mesh.n_elements
                    for kernel in kernels:
                        res = last[kernel]
                        u, f = res.displacement_m, res.reaction_force_n["bottom"][-1]
                        if kernel not in ref:
                            ref[kernel] = (u, f)
                            du = df = float("nan")
                        else:
                            du = np.abs(u - ref[kernel][0]).max() / np.abs(ref[kernel][0]).max()
                            df = np.abs(f - ref[kernel][1]).max() / np.abs(ref[kernel][1]).max()
                        b1, b2 = np.median(walls[kernel, 1]), np.median(walls[kernel, 2])
                        r1 = np.median(walls[kernels[0], 1]) / b1
                        r2 = np.median(walls[kernels[0], 2]) / b2
                        print(f"{name:>16} {ne:>6d} {alt * 1e3:>6.3f} {law:>8} {precision[-2:]:>7} {res.kernel:>10} "
                              f"{n_steps:>6d} {load:>5.2f} {ne * n_steps / b1 / 1e6:>9.1f} {ne * n_steps / b2 / 1e6:>9.1f} "
                              f"{n_steps * dt / b1:>6.2f} {n_steps * dt / b2:>6.2f} {r1:>9.2f} {r2:>9.2f} {du:>9.1e} "
                              f"{df:>9.1e} {load_end:>9.2f}", flush=True)
    if args.mass_scaling and args.brain_mesh:
        print(f"# explicit flat-punch indentation (QLV4-NH, float32, 2 mm in 0.2 s, held 0.1 s, 1 thread), mass scaling to "
              f"{args.mass_scaling} x the critical step, {meshes[0][0]}; load {os.getloadavg()[0]:.2f}")
        with numba_threads(1):
            for k, v in mass_scaling_indentation(meshes[0][1], args.mass_scaling).items():
                print(f"  {k} = {v:.4g}" if isinstance(v, float) else f"  {k} = {v}")
    print(f"# load average after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
