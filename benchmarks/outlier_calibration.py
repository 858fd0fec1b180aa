"""Calibration of the outlier-specimen threshold: the level of the largest deletion t, and what a design can name.

The diagnosis tests the most extreme of n specimen levels with the externally studentised deletion t
(``tissuemech.stats.deletion_outlier_test``: t_{n-2}, Bonferroni over the n specimens) and names it only after Holm
over the catalogue's tested causes (first step: alpha/2 over them, ``tissuemech.diagnosis.decision``). This script
measures, by seeded Monte Carlo,

1. the rejection rate of that test on n normal specimen levels without an outlier, against its nominal level (the
   calibration: is the Bonferroni threshold the exact level of the largest of n deletion t's?), for n = 3..8;
2. the share of designs of n specimens (log-SD ``sd`` between specimens) in which one specimen k times the others
   is named at the family-wise alpha = 0.01 with ``n_tested`` catalogue tests (the power the issue asks about: "a
   2.4x outlier among 4-6 specimens").

Prints two markdown tables (docs/diagnosis.md, "Outlier specimens"). Run:

    PYTHONPATH=src python benchmarks/outlier_calibration.py --draws 40000 --seed 20261201
"""
from __future__ import annotations

import argparse

import numpy as np
import scipy.stats


def deletion_t(x: np.ndarray) -> np.ndarray:
    """Deletion t of every value of every row of ``x`` (rows: designs, columns: specimen levels), as
    ``tissuemech.stats.deletion_outlier_test`` computes it for one design: (x_b - mean_-b) / (sd_-b sqrt(1 + 1/(n-1)))."""
    n = x.shape[1]
    s1 = x.sum(axis=1, keepdims=True)
    s2 = (x ** 2).sum(axis=1, keepdims=True)
    mean = (s1 - x) / (n - 1)
    var = ((s2 - x ** 2) - (n - 1) * mean ** 2) / (n - 2)
    return (x - mean) / np.sqrt(var * (1.0 + 1.0 / (n - 1)))


def bonferroni_p(x: np.ndarray) -> np.ndarray:
    """The test's p-value of every design: min(1, n x two-sided t_{n-2} p of the largest |deletion t|)."""
    n = x.shape[1]
    t = np.abs(deletion_t(x)).max(axis=1)
    return np.minimum(1.0, n * 2.0 * scipy.stats.t.sf(t, n - 2))


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--draws", type=int, default=40000)
    ap.add_argument("--seed", type=int, default=20261201)
    ap.add_argument("--n-tested", type=int, default=10, help="catalogue causes tested on the design (Holm)")
    args = ap.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    print(f"Level of the largest deletion t (Bonferroni over n), {args.draws} null designs per n, seed {args.seed}:\n")
    print("| n specimens | nominal 0.05 | nominal 0.01 | nominal 0.001 |")
    print("|---|---|---|---|")
    for n in (3, 4, 5, 6, 8):
        p = bonferroni_p(rng.normal(size=(args.draws, n)))
        print(f"| {n} | " + " | ".join(f"{np.mean(p < a):.4f}" for a in (0.05, 0.01, 0.001)) + " |")
    alpha_step = 0.01 / 2 / args.n_tested
    print(f"\nShare of designs in which one specimen k x the others is named (alpha = 0.01 family-wise, first Holm step "
          f"alpha/2/{args.n_tested} = {alpha_step:.1e}), {args.draws // 4} designs per cell:\n")
    print("| n specimens | specimen log-SD | k = 1.5 | k = 2.4 | k = 4 |")
    print("|---|---|---|---|---|")
    for n in (4, 5, 6, 8, 12):
        for sd in (0.1, 0.2, 0.3):
            cells = []
            for k in (1.5, 2.4, 4.0):
                x = rng.normal(0.0, sd, size=(args.draws // 4, n))
                x[:, 0] += np.log(k)
                cells.append(f"{np.mean(bonferroni_p(x) < alpha_step):.2f}")
            print(f"| {n} | {sd} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
