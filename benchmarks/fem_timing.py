"""TLED throughput: element updates per second and real-time factor vs mesh size, law and precision.

Each case runs undamped explicit steps of a cube (bottom fixed, initial shear-velocity field) and reports

* ``Mupd/s``: element updates per wall second (n_elements x steps / s), the hardware-independent figure;
* ``steps/s`` and ``RT factor``: simulated seconds per wall second with the critical step of a brain-like
  material (mu = 1 kPa, nu = 0.49, rho = 1040 kg/m^3) on that mesh (>1 = faster than real time);
* ``Mupd/cpu-s``: element updates per CPU second of the process (all threads): on a shared machine this
  is what the kernel does while it actually runs; ``wall/cpu`` shows how much the run was descheduled.

``--brain-mesh mesh.vtu`` adds the MNI brain mesh (real-time factor with its own critical step);
``--felupe`` times the same quasi-static square-punch indentation with FElupe (Newton, sparse direct) and
with TLED dynamic relaxation. The CPU model, core count and load average are printed with the table.

The machine this runs on may be shared: compare rows measured in the same run (ratios), not absolute
figures between runs. On an oversubscribed machine use ``--threads 1``: every parallel region (3-5 per
step) waits for its slowest, possibly descheduled, thread. Usage::

    python benchmarks/fem_timing.py                       # CI-sized: 1e3 ... 1e5 tets, CPU
    python benchmarks/fem_timing.py --max-elements 1e6 --threads 2
    python benchmarks/fem_timing.py --gpu                 # numba-cuda kernel (tissuemech.fem.cuda)
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

from tissuemech.fem.materials import make_material  # noqa: E402
from tissuemech.fem.mesh import block_mesh  # noqa: E402
from tissuemech.fem.tled import build_model, critical_time_step, fixed_group, numba_threads, run_explicit  # noqa: E402

LAWS = {
    "SVK": ("saint_venant_kirchhoff", {"mu": 1000.0}, (), ()),
    "NH": ("neo_hookean", {"mu": 1000.0}, (), ()),
    "LP2": ("lopez_pamies2", {"mu1": 900.0, "alpha1": 1.2, "mu2": 100.0, "alpha2": 3.0}, (), ()),
    "QLV4-NH": ("neo_hookean", {"mu": 1000.0}, (0.3, 0.2, 0.1, 0.05), (0.01, 0.1, 1.0, 10.0)),
    # the nonseparable extension: Pipkin-Rogers with QLV4-NH's small-strain weights (beta_i = g_i / g_inf) and the
    # bundled brain's fitted weight law (kappa, gamma_s of pr_rp3_prony4)
    "PR4-NH": ("neo_hookean", {"mu": 1000.0}, (), (0.01, 0.1, 1.0, 10.0),
               {"beta": [0.3 / 0.35, 0.2 / 0.35, 0.1 / 0.35, 0.05 / 0.35], "kappa": [0.537] * 4, "gamma_s": 0.1223}),
    # stretch-based (spectral decomposition per element; generic kernel), Budday-like cortex parameters
    "OG1": ("ogden1", {"mu1": 1000.0, "alpha1": -25.0}, (), ()),
}


def cube_with_n_elements(n_elements: float):
    """Unit-ish cube (10 mm) with about ``n_elements`` tets (6 per hex cell)."""
    cells = max(1, int(round((n_elements / 6.0) ** (1.0 / 3.0))))
    return block_mesh((1e-2, 1e-2, 1e-2), (cells, cells, cells))


def setup(mesh, law: str, precision: str, anp: bool):
    key, params, g, tau, *pr = LAWS[law]
    mat = make_material(key, params, poisson_ratio=0.49, density_kg_m3=1040.0, prony_g=g, prony_tau_s=tau,
                        pipkin_rogers=pr[0] if pr else None)
    x = mesh.nodes
    height = (x[:, 2] - x[:, 2].min()) / np.ptp(x[:, 2])
    # cube: the bottom face; brain: the lowest 5 % (the support of the indentation experiment)
    model = build_model(mesh, mat, [fixed_group("bottom", np.flatnonzero(height < 0.05))], anp=anp, precision=precision)
    v0 = np.zeros_like(x)
    v0[:, 0] = 1e-3 * height
    return model, v0


def time_cpu(model, v0, n_steps: int, threads: int | None, kernel: str = "auto") -> tuple[float, float, str]:
    """Wall and process-CPU seconds of ``n_steps`` explicit steps (after a warm-up run that also compiles)
    and the internal-force kernel that ran (``"fused"``, ``"vectorised"`` or ``"generic"``)."""
    dt = critical_time_step(model, 0.7)
    with numba_threads(threads):
        run_explicit(model, 3 * dt, dt_s=dt, v0_m_s=v0, n_outputs=1, track_energy=False, kernel=kernel)
        c0, t0 = time.process_time(), time.perf_counter()
        res = run_explicit(model, n_steps * dt, dt_s=dt, v0_m_s=v0, n_outputs=1, track_energy=False, kernel=kernel)
        return time.perf_counter() - t0, time.process_time() - c0, res.kernel


def machine() -> dict:
    """CPU model (lscpu), logical CPUs, load averages and date: the context of the figures."""
    import datetime
    import subprocess

    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True, timeout=10).stdout
        model = next((ln.split(":", 1)[1].strip() for ln in out.splitlines() if ln.startswith("Model name")), "?")
    except (OSError, subprocess.SubprocessError):
        model = "?"
    return {"cpu": model, "logical_cpus": os.cpu_count(), "load_avg_1_5_15": os.getloadavg(),
            "date_utc": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M")}


def felupe_comparison(threads: int | None, size: float = 1e3) -> list[dict]:
    """Wall time of the quasi-static square-punch indentation (10 % depth, neo-Hookean, nu = 0.45, plain
    linear tets, 4 load steps) with FElupe and with TLED dynamic relaxation on the same mesh (the ~1e3-tet case of
    ``benchmarks/fem_felupe.py``, which compares 1e3-1e5 tets and several tolerances)."""
    from fem_felupe import indentation_case, run_felupe, run_tled

    mesh, punch, bottom = indentation_case(size)
    mat = make_material("neo_hookean", {"mu": 1000.0}, poisson_ratio=0.45)
    wall_fe, _, f_fe = run_felupe(mesh, punch, bottom, mat.bulk_modulus_pa)
    wall_tled, _, f_tled, iterations = run_tled(mesh, punch, bottom, mat, 1e-6, threads)
    return [{"solver": "FElupe 4 Newton load steps", "n_elements": mesh.n_elements, "wall_s": wall_fe, "force_n": f_fe},
            {"solver": "TLED dynamic relaxation, 4 increments", "n_elements": mesh.n_elements, "wall_s": wall_tled,
             "force_n": f_tled, "dr_iterations": iterations}]


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--min-elements", type=float, default=1e3)
    ap.add_argument("--max-elements", type=float, default=1e5)
    ap.add_argument("--laws", default="SVK,NH,LP2,QLV4-NH")
    ap.add_argument("--precisions", default="float64,float32")
    ap.add_argument("--threads", type=int, default=None, help="numba threads (default: numba's setting)")
    ap.add_argument("--kernels", default="auto",
                    help="internal-force kernels to time side by side: auto (vectorised where the law allows, "
                         "else generic), generic, vectorised, fused (one parallel region per step); comma separated")
    ap.add_argument("--no-anp", action="store_true", help="plain linear tets (no average nodal pressure)")
    ap.add_argument("--updates", type=float, default=2e7, help="element updates per measurement")
    ap.add_argument("--gpu", action="store_true", help="also time tissuemech.fem.cuda on the GPU")
    ap.add_argument("--gpu-batch", type=int, default=200, help="steps per persistent-kernel launch")
    ap.add_argument("--out", default=None, help="also write the table as CSV to this path")
    ap.add_argument("--brain-mesh", default=None, help="also time this (MNI brain) mesh (VTU)")
    ap.add_argument("--felupe", action="store_true", help="also compare a quasi-static indentation with FElupe")
    args = ap.parse_args(argv)
    info = machine()
    print(f"# {info['date_utc']} UTC, CPU {info['cpu']}, {info['logical_cpus']} logical CPUs, "
          f"load average {info['load_avg_1_5_15']}")

    sizes = [s for s in (1e3, 1e4, 1e5, 1e6, 1e7) if args.min_elements <= s <= args.max_elements]
    anp = not args.no_anp
    print(f"# TLED explicit step throughput ({'ANP' if anp else 'plain'} linear tets); threads = "
          f"{args.threads or 'numba default'}")
    print(f"{'mesh':>6} {'tets':>7} {'law':>8} {'prec':>8} {'device':>6} {'kernel':>10} {'steps':>7} {'wall s':>8} {'Mupd/s':>8} "
          f"{'Mupd/cpu-s':>10} {'steps/s':>9} {'dt_cr s':>9} {'RT factor':>9}")
    table = []
    meshes = [("cube", cube_with_n_elements(size)) for size in sizes]
    if args.brain_mesh:
        from tissuemech.fem.mesh import read_mesh

        meshes.append(("brain", read_mesh(args.brain_mesh)[0]))
    for mesh_name, mesh in meshes:
        ne = mesh.n_elements
        for law in args.laws.split(","):
            for precision in args.precisions.split(","):
                model, v0 = setup(mesh, law, precision, anp)
                dt_cr = critical_time_step(model, 0.7)
                n_steps = max(20, int(args.updates / ne))
                rows = []
                for kernel in dict.fromkeys(args.kernels.split(",")):
                    if kernel != "auto" and any(r[1] == kernel for r in rows):
                        continue  # "auto" already ran this kernel
                    wall, cpu, ran = time_cpu(model, v0, n_steps, args.threads, kernel)
                    if ran == kernel or kernel == "auto":
                        rows.append(("cpu", ran, wall, cpu))
                if args.gpu:
                    from tissuemech.fem import cuda as fem_cuda

                    rows.append(("gpu", "cuda", fem_cuda.time_steps(model, v0, n_steps, dt_cr, batch=args.gpu_batch),
                                 float("nan")))
                for device, kernel, wall, cpu in rows:
                    sps = n_steps / wall
                    table.append({"mesh": mesh_name, "n_elements": ne, "law": law, "precision": precision,
                                  "device": device, "kernel": kernel, "anp": anp, "steps": n_steps, "wall_s": wall, "cpu_s": cpu,
                                  "element_updates_per_s": ne * sps, "element_updates_per_cpu_s": ne * n_steps / cpu,
                                  "steps_per_s": sps, "critical_dt_s": dt_cr, "real_time_factor": sps * dt_cr,
                                  "threads": args.threads or 0, **{k: str(v) for k, v in info.items()}})
                    print(f"{mesh_name:>6} {ne:>7d} {law:>8} {precision:>8} {device:>6} {kernel:>10} {n_steps:>7d} {wall:>8.3f} "
                          f"{ne * sps / 1e6:>8.2f} {ne * n_steps / cpu / 1e6:>10.2f} {sps:>9.0f} {dt_cr:>9.2e} "
                          f"{sps * dt_cr:>9.3f}", flush=True)
    if args.felupe:
        print("# quasi-static square-punch indentation, same mesh and law")
        for row in felupe_comparison(args.threads):
            print("  " + ", ".join(f"{k} = {v:.4g}" if isinstance(v, float) else f"{k} = {v}" for k, v in row.items()))
    print(f"# load average after: {os.getloadavg()}")


    if args.out:
        import pandas as pd

        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        pd.DataFrame(table).to_csv(args.out, index=False)


if __name__ == "__main__":
    main()
