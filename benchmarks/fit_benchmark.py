"""Timing of the fit stage (not a test): a QLV fit over all CSR rates + relaxation, then the whole
fit + rank + cards stage as the Snakemake workflow runs it (``stages.dataset_scopes`` from ``config/config.yaml``,
``stages.run_fit_scope`` per scope, ``stages.collect_scopes``).

Data: ``results/<dataset>/averages.nc`` of the bundled brain dataset when it exists (``--averages``; plate
geometry from the averages), otherwise thesis-shaped runs generated here from a registry QLV model through the
parallel-plate forward model (CSR 0.001/0.005/0.01/0.05/0.1 1/s to 50 %, relaxation at 1/10/20/40 % with a
0.1 s rise, R = 12.5 mm, reported apparent rim stress with 1 % noise, two samples per condition) and averaged
as the workflow averages them. Numba is warmed up first; the target is < 60 s for the whole stage on 2 cores.

    NUMBA_CACHE_DIR=.numba_cache .venv/bin/python benchmarks/fit_benchmark.py [--averages PATH] [--radius-m R]
"""
from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from concurrent.futures import ProcessPoolExecutor

import yaml

from tissuemech import fitting as F
from tissuemech import stages
from tissuemech.canonical import make_run_dataset, read_netcdf
from tissuemech.curves import average_runs, write_averages
from tissuemech.models import plate
from tissuemech.models.registry import available_models, get_model

RATES = (0.001, 0.005, 0.01, 0.05, 0.1)
STRAINS = (0.01, 0.10, 0.20, 0.40)
G_PRONY = (0.10, 0.23, 0.21, 0.14)
CONFIG = Path(__file__).resolve().parents[1] / "config" / "config.yaml"


def synthetic_averages(path: Path, radius_m: float, seed: int = 0, samples: int = 2) -> Path:
    """Thesis-shaped canonical runs of a registry QLV model, averaged into ``path`` (``averages.nc``)."""
    from tissuemech.models.qlv import qlv_params

    key = "qlv_rp3_prony4" if "qlv_rp3_prony4" in available_models() else "qlv_linear_prony4"
    model = get_model(key)
    inst = {"G0": 200.0} if key.endswith("linear_prony4") else {"C10": 100.0, "C20": 150.0, "C30": 300.0}
    truth = qlv_params(model, inst, G_PRONY)
    rng = np.random.default_rng(seed)
    histories = [({"test": "constant_shear_rate", "shear_rate_1_per_s": rate}, t, rate * t)
                 for rate in RATES for t in [np.linspace(0.0, 0.5 / rate, 201)]]
    for s in STRAINS:
        t = np.r_[0.0, np.linspace(0.01, 0.1, 10), np.geomspace(0.12, 300.0, 150)]
        histories.append(({"test": "stress_relaxation", "strain_pct": 100 * s, "rise_time_s": 0.1}, t,
                          np.minimum(t / 0.1, 1.0) * s))
    runs = []
    for i, (condition, t, g) in enumerate(histories):
        y = plate.forward_plate(model, truth, t, g, radius_m)[1:]
        for s in range(samples):
            runs.append(make_run_dataset(
                {"time": t[1:], "shear_strain": g[1:], "shear_stress": y * (1 + 0.01 * rng.standard_normal(y.size))},
                condition | {"radius_m": radius_m, "gap_m": 0.003, "specimen": "b1", "sample": f"s{s}",
                             "run": f"r{i}_{s}"}))
    return write_averages(average_runs(runs), path)


def _fit_scope(args):
    averages, scope, spec, fit_config, poisson_ratio, out = args
    stages.run_fit_scope(averages, scope, spec, target=fit_config["plate_target"], seed=fit_config["seed"],
                         multistart=fit_config["multistart"], fits_dir=out / "fits" / scope,
                         cards_dir=out / "cards" / scope, ranking_path=out / "ranking" / f"{scope}.csv",
                         poisson_ratio=poisson_ratio, dataset="benchmark")
    return scope


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--averages", type=Path, default=Path("results/porcine_brain_thesis/averages.nc"))
    ap.add_argument("--radius-m", type=float, default=0.0125)
    ap.add_argument("--qlv", default="qlv_linear_prony4", help="QLV model key for the single-fit timing")
    ap.add_argument("--workers", type=int, default=2, help="processes for the scopes (Snakemake jobs)")
    args = ap.parse_args()

    config = yaml.safe_load(CONFIG.read_text())
    fit_config, poisson_ratio = config["fit"], config["fem"]["poisson_ratio"]
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        if args.averages.exists():
            averages, source = args.averages, str(args.averages)
        else:
            averages = synthetic_averages(out / "averages.nc", args.radius_m)
            source = "synthetic thesis-shaped runs (bundled averages not found)"
        avg = read_netcdf(averages)
        tests = sorted({str(t) for t in avg["test"].values})
        curves = stages.scope_curves(avg, tests)
        print(f"data: {source}; {len(curves)} curves")

        t0 = time.perf_counter()
        warm = [F.thin(c, 5) for c in curves[:2]]
        F.fit(F.FitProblem(get_model(args.qlv), warm, target="apparent_stress"), n_random=0, max_nfev=5)
        print(f"numba warm-up: {time.perf_counter() - t0:.1f} s")

        scope = [F.thin(c, 30) for c in curves if c.test in ("constant_shear_rate", "stress_relaxation")]
        t0 = time.perf_counter()
        res = F.fit(F.FitProblem(get_model(args.qlv), scope, target="apparent_stress", model_key=args.qlv),
                    n_random=2)
        dt = time.perf_counter() - t0
        print(f"QLV fit {args.qlv} on {len(scope)} curves ({res.n} points, {res.nfev} evaluations, "
              f"{res.n_starts} starts): {dt:.2f} s; flags: {res.flags or 'none'}")

        scopes = stages.dataset_scopes(tests, fit_config)
        jobs = [(averages, name, spec, fit_config, poisson_ratio, out) for name, spec in scopes.items()]
        t0 = time.perf_counter()
        if args.workers > 1:  # Snakemake runs the scopes as parallel jobs; a process pool stands in for it
            with ProcessPoolExecutor(max_workers=args.workers) as pool:
                list(pool.map(_fit_scope, jobs))
        else:
            for job in jobs:
                _fit_scope(job)
        ranking = stages.collect_scopes([out / "ranking" / f"{name}.csv" for name in scopes], out / "ranking.csv")
        stages.write_fits_table([out / "fits" / name for name in scopes], "benchmark", out / "fits.csv")
        dt = time.perf_counter() - t0
        n_fits = len(list(out.glob("fits/*/*.nc")))
    print(f"full fit + rank + cards stage: {dt:.1f} s ({n_fits} fits, scopes {list(scopes)}); target < 60 s")
    for name, text in ranking.groupby("scope", sort=False)["recommendation"].first().items():
        print(f"  {name}: {text}")
    failures = ranking.dropna(subset=["failures"]) if "failures" in ranking else ranking.iloc[:0]
    for name, text in failures.groupby("scope", sort=False)["failures"].first().items():
        print(f"  failures in {name}: {text}")


if __name__ == "__main__":
    main()
