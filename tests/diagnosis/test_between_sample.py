"""levels.between_sample_test: the unit of replication of a covariate that varies between samples."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import statsmodels.api as sm

from tissuemech.diagnosis.levels import between_sample_test


def _levels(n_specimens: int, samples: int, slope: float, seed: int = 3) -> pd.DataFrame:
    """Curve levels of ``n_specimens`` x ``samples`` samples x 2 conditions; the covariate is a property of the
    specimen (e.g. the day it was tested), each specimen has its own random level (log-SD 0.3) and each sample a
    small one (0.02)."""
    rng = np.random.default_rng(seed)
    rows = []
    for s in range(n_specimens):
        x = float(s)
        spec_level = rng.normal(0.0, 0.3)
        for k in range(samples):
            samp_level = rng.normal(0.0, 0.02)
            for cond, offset in (("c1", 0.0), ("c2", 0.5)):
                rows.append({"specimen": f"S{s}", "sample": f"S{s}/{k}", "condition": cond, "x": x,
                             "y": offset + slope * x + spec_level + samp_level + rng.normal(0.0, 0.01)})
    return pd.DataFrame(rows)


def test_a_specimen_covariate_is_tested_on_specimen_means():
    lv = _levels(n_specimens=6, samples=2, slope=0.0)
    out = between_sample_test(lv, "y", "x")
    # the covariate is constant within each specimen, so specimen fixed effects absorb it; the samples of one
    # specimen share its random level, so the specimens -- 6 of them -- are the replicates: df = 6 - 2
    assert out["design"] == "specimen means" and out["df"] == 4
    # oracle: a straight line through the 6 specimen means of the condition-centred levels
    centred = lv.assign(r=lv["y"] - lv.groupby("condition")["y"].transform("mean"))
    means = centred.groupby("specimen").agg(r=("r", "mean"), x=("x", "mean"))
    slope = np.polyfit(means["x"], means["r"], 1)[0]
    assert out["estimate"] == pytest.approx(slope, rel=1e-9)


def test_specimen_means_keep_the_null_calm_where_sample_means_would_not():
    """With sample means as replicates the shared specimen levels count twice (12 'replicates' of 6 levels):
    over 200 null designs the specimen-means test rejects at about its nominal 5 %."""
    rejections, naive = 0, 0
    for seed in range(200):
        lv = _levels(6, 2, slope=0.0, seed=seed)
        rejections += between_sample_test(lv, "y", "x")["p_value"] < 0.05
        # the naive design, written out independently: OLS of the 12 sample means on the covariate
        means = (lv.assign(r=lv["y"] - lv.groupby("condition")["y"].transform("mean"))
                 .groupby("sample").agg(r=("r", "mean"), x=("x", "mean")))
        naive += sm.OLS(means["r"].to_numpy(), sm.add_constant(means["x"].to_numpy())).fit().pvalues[1] < 0.05
    assert rejections <= 20, rejections   # nominal 10 of 200; the binomial 99.9 % bound is about 21
    assert naive >= 30, naive             # measured 50 of 200: the shared specimen levels counted as replicates


def test_a_real_slope_is_found_on_specimen_means():
    out = between_sample_test(_levels(6, 2, slope=0.5), "y", "x")
    assert out["design"] == "specimen means" and out["estimate"] == pytest.approx(0.5, abs=0.15)
    assert out["p_value"] < 0.01   # 6 specimens with log-SD 0.3 around the line: 4 df
