"""Timing of the fit stage (not a test): a QLV fit over all CSR rates + relaxation, then the whole
fit + rank + cards stage.

Data: ``results/<dataset>/averages.nc`` of the bundled brain dataset when it exists (``--averages``),
otherwise thesis-shaped curves generated here from a registry QLV model through the parallel-plate forward
model (CSR 0.001/0.005/0.01/0.05/0.1 1/s to 50 %, relaxation at 1/10/20/40 % with a 0.1 s rise, R = 12.5 mm,
reported apparent rim stress with 1 % noise). Numba is warmed up first; the target is < 60 s for the whole
stage on 2 cores.

    NUMBA_CACHE_DIR=.numba_cache .venv/bin/python benchmarks/fit_benchmark.py [--averages PATH] [--radius-m R]
"""
from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from tissuemech import fitting as F
from tissuemech import ranking as R
from tissuemech.canonical import read_netcdf
from tissuemech.models import plate
from tissuemech.models.registry import available_models, get_model

RATES = (0.001, 0.005, 0.01, 0.05, 0.1)
STRAINS = (0.01, 0.10, 0.20, 0.40)
G_PRONY = (0.10, 0.23, 0.21, 0.14)


def synthetic_curves(radius_m: float, seed: int = 0) -> list[F.Curve]:
    from tissuemech.models.qlv import qlv_params

    key = "qlv_rp3_prony4" if "qlv_rp3_prony4" in available_models() else "qlv_linear_prony4"
    model = get_model(key)
    inst = {"G0": 200.0} if key.endswith("linear_prony4") else {"C10": 100.0, "C20": 150.0, "C30": 300.0}
    truth = qlv_params(model, inst, G_PRONY)
    rng = np.random.default_rng(seed)
    curves = []
    for rate in RATES:
        t = np.linspace(0.0, 0.5 / rate, 201)
        y = plate.forward_plate(model, truth, t, rate * t, radius_m)[1:]
        y = y * (1 + 0.01 * rng.standard_normal(y.size))
        curves.append(F.Curve(test="constant_shear_rate", condition=f"rate={rate:g}/s", response="shear_history",
                              inputs={"time": t, "shear_strain": rate * t}, observed={"shear_stress": y},
                              sd={"shear_stress": 0.05 * np.abs(y)}, obs_index=np.arange(1, t.size), radius_m=radius_m,
                              gap_m=0.003, n_samples=6, nominal={"shear_rate_1_per_s": rate}))
    for s in STRAINS:
        t = np.r_[0.0, np.linspace(0.01, 0.1, 10), np.geomspace(0.12, 300.0, 150)]
        g = np.minimum(t / 0.1, 1.0) * s
        y = plate.forward_plate(model, truth, t, g, radius_m)[1:]
        y = y * (1 + 0.01 * rng.standard_normal(y.size))
        curves.append(F.Curve(test="stress_relaxation", condition=f"strain={100 * s:g}%", response="shear_history",
                              inputs={"time": t, "shear_strain": g}, observed={"shear_stress": y},
                              sd={"shear_stress": 0.05 * np.abs(y)}, obs_index=np.arange(1, t.size), radius_m=radius_m,
                              gap_m=0.003, n_samples=8, nominal={"strain_pct": 100 * s}))
    return curves


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--averages", type=Path, default=Path("results/porcine_brain_thesis/averages.nc"))
    ap.add_argument("--radius-m", type=float, default=0.0125)
    ap.add_argument("--qlv", default="qlv_linear_prony4", help="QLV model key for the single-fit timing")
    ap.add_argument("--workers", type=int, default=2, help="processes for the candidate fits")
    args = ap.parse_args()

    if args.averages.exists():
        curves = F.curves_from_averages(read_netcdf(args.averages), radius_m=args.radius_m, gap_m=0.003)
        source = str(args.averages)
    else:
        curves = synthetic_curves(args.radius_m)
        source = "synthetic thesis-shaped curves (bundled averages not found)"
    print(f"data: {source}; {len(curves)} curves")

    t0 = time.perf_counter()
    warm = [F.thin(c, 5) for c in curves[:2]]
    F.fit(F.FitProblem(get_model(args.qlv), warm, target="apparent_stress"), n_random=0, max_nfev=5)
    print(f"numba warm-up: {time.perf_counter() - t0:.1f} s")

    scope = [F.thin(c, 30) for c in curves if c.test in ("constant_shear_rate", "stress_relaxation")]
    t0 = time.perf_counter()
    res = F.fit(F.FitProblem(get_model(args.qlv), scope, target="apparent_stress", model_key=args.qlv), n_random=2)
    dt = time.perf_counter() - t0
    print(f"QLV fit {args.qlv} on {len(scope)} curves ({res.n} points, {res.nfev} evaluations, {res.n_starts} starts): "
          f"{dt:.2f} s; flags: {res.flags or 'none'}")

    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        summary = R.run_fit_stage(curves, tmp, dataset="benchmark", workers=args.workers)
        dt = time.perf_counter() - t0
    print(f"full fit + rank + cards stage: {dt:.1f} s ({summary['n_fits']} fits, scopes {summary['scopes']}); "
          f"target < 60 s")
    for name, rec in summary["recommendations"].items():
        print(f"  {name}: {rec['statement']}")
    if summary["failures"]:
        print(f"  failures: {summary['failures']}")


if __name__ == "__main__":
    main()
