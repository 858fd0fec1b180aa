"""Posterior diagnostics of the bundled brain's material model (the material scope's baseline) at given settings.

Run after the fits exist (``snakemake results/porcine_brain_thesis/ranking.csv``):
    PYTHONPATH=src .venv/bin/python benchmarks/posterior_brain.py [--walkers 8 --steps 1400 --burn 400]
Prints per model: sampling seconds, seconds per residual evaluation, max split R-hat, min ESS, acceptance and
the 90 % credible width / lmfit interval per parameter (tissuemech.uq).
"""
from __future__ import annotations

import argparse
from pathlib import Path

import yaml

from tissuemech import fitting as F
from tissuemech import uq
from tissuemech.canonical import read_netcdf
from tissuemech.ranking import scope_model
from tissuemech.scopes import dataset_scopes

ROOT = Path("results/porcine_brain_thesis")
SCOPE = "material"


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--walkers", type=int, default=8)
    ap.add_argument("--steps", type=int, default=1400)
    ap.add_argument("--burn", type=int, default=400)
    ap.add_argument("--seed", type=int, default=20261124)
    ap.add_argument("--models", default="baseline", help="model keys of the scope, or 'baseline'")
    a = ap.parse_args()
    averages = read_netcdf(ROOT / "averages.nc")
    config = yaml.safe_load(Path("config/config.yaml").read_text())
    tests = sorted({str(t) for t in averages["test"].values})
    spec = dataset_scopes(tests, config["fit"])[SCOPE]
    for key in a.models.split(","):
        key = scope_model(ROOT / "ranking" / f"{SCOPE}.csv", key)
        record = F.FitRecord.from_netcdf(ROOT / "fits" / SCOPE / f"{key}.nc")
        problem = uq.problem_for_record(averages, record, spec)
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
