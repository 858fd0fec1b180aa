"""Posterior diagnostics of the bundled brain's joint viscoelastic fits (QLV and beyond-QLV) at given settings.

Run after the fits exist (``snakemake results/porcine_brain_thesis/ranking.csv``):
    PYTHONPATH=src .venv/bin/python benchmarks/posterior_brain.py [--walkers 8 --steps 1400 --burn 400]
Prints per model: sampling seconds, seconds per residual evaluation, max split R-hat, min ESS, acceptance and
the 90 % credible width / lmfit interval per parameter (tissuemech.uq).
"""
from __future__ import annotations

import argparse
from pathlib import Path

from tissuemech import fitting as F
from tissuemech import uq
from tissuemech.canonical import read_netcdf

ROOT = Path("results/porcine_brain_thesis")
SCOPE, TESTS = "viscoelastic_joint", ["constant_shear_rate", "stress_relaxation"]


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--walkers", type=int, default=8)
    ap.add_argument("--steps", type=int, default=1400)
    ap.add_argument("--burn", type=int, default=400)
    ap.add_argument("--seed", type=int, default=20261124)
    ap.add_argument("--models", default="qlv_rp3_prony4,pr_rp3_prony4")
    a = ap.parse_args()
    averages = read_netcdf(ROOT / "averages.nc")
    for key in a.models.split(","):
        record = F.FitRecord.from_netcdf(ROOT / "fits" / SCOPE / f"{key}.nc")
        problem = uq.problem_for_record(averages, record, TESTS)
        post, info = uq.sample_record_posterior(problem, record, walkers=a.walkers, steps=a.steps, burn=a.burn,
                                                seed=a.seed)
        table = uq.posterior_table(record, post)
        print(f"{key}: {info['seconds']:.1f} s sampling, {1e3 * info['seconds_per_evaluation']:.2f} ms/evaluation, "
              f"max R-hat {table['rhat'].max():.4f}, min ESS {table['ess'].min():.0f}, "
              f"acceptance {post.acceptance:.2f}")
        print("  CI90/lmfit: " + ", ".join(f"{p} {r:.2f}" for p, r in zip(table["parameter"],
                                                                       table["ci90_over_lmfit"])))
        for w in post.warnings:
            print("  warning:", w)


if __name__ == "__main__":
    main()
