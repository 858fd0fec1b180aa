"""stats.mixed_coefficient_test: specimen and sample as random effects, degrees of freedom where the covariate varies.

Oracles: closed forms written out here independently of the code under test (a line through the specimen means,
the Student-t level of a null design over many seeds), and a block design whose specimens happen to follow the
clock, where only a within-sample reading can keep the null."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import statsmodels.api as sm

from tissuemech import stats as st
from tissuemech.diagnosis.levels import within_test


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


def test_a_specimen_covariate_is_judged_on_the_specimens():
    lv = _levels(n_specimens=6, samples=2, slope=0.0)
    out = st.mixed_coefficient_test(lv, "y", "x", ("condition",))
    # constant within each specimen: 6 specimens, intercept and slope at the specimen level -> df = 6 - 2
    assert out["level"] == "specimen" and out["df"] == 4 and "MixedLM" in out["method"]
    # oracle: a straight line through the 6 specimen means of the condition-centred levels (balanced design: the
    # GLS slope of the mixed model is that line's slope)
    centred = lv.assign(r=lv["y"] - lv.groupby("condition")["y"].transform("mean"))
    means = centred.groupby("specimen").agg(r=("r", "mean"), x=("x", "mean"))
    slope = np.polyfit(means["x"], means["r"], 1)[0]
    assert out["estimate"] == pytest.approx(slope, rel=1e-3)


def test_specimen_random_effects_keep_the_null_calm_where_curves_as_replicates_would_not():
    """Curves as replicates count each specimen's level four times: over 100 null designs the mixed-model test
    rejects at about its nominal 5 %, the naive OLS of the curve levels far more often."""
    rejections, naive = 0, 0
    for seed in range(100):
        lv = _levels(6, 2, slope=0.0, seed=seed)
        rejections += st.mixed_coefficient_test(lv, "y", "x", ("condition",))["p_value"] < 0.05
        X = sm.add_constant(pd.get_dummies(lv[["x", "condition"]], drop_first=True, dtype=float))
        naive += sm.OLS(lv["y"].to_numpy(), X.to_numpy(float)).fit().pvalues[1] < 0.05
    assert rejections <= 12, rejections   # nominal 5 of 100; the binomial 99.9 % bound is about 12
    assert naive >= 30, naive


def test_a_real_slope_is_found_on_the_specimens():
    out = st.mixed_coefficient_test(_levels(6, 2, slope=0.5), "y", "x", ("condition",))
    assert out["estimate"] == pytest.approx(0.5, abs=0.15)
    assert out["p_value"] < 0.01   # 6 specimens with log-SD 0.3 around the line: 4 df


def _block_design(drift_per_h: float, seed: int = 0) -> pd.DataFrame:
    """Six specimens measured one after the other over two days (a block each), two samples of three curves each in
    a shuffled order; the specimens' random levels happen to rise with the order they were measured in (a draw the
    clock follows)."""
    rng = np.random.default_rng(seed)
    spec_levels = np.sort(rng.normal(0.0, 0.3, 6))              # the unlucky draw: levels follow the clock
    rows = []
    for s in range(6):
        t0 = 24.0 * (s // 3) + 3.0 * (s % 3)                     # hours since the first specimen
        for k in range(2):
            for j, cond in enumerate(rng.permutation(["a", "b", "c"])):   # a shuffled test order per sample
                t = t0 + 1.2 * k + 0.3 * j + rng.uniform(0, 0.1)
                rows.append({"specimen": f"S{s}", "sample": f"S{s}/{k}", "condition": cond, "elapsed_h": t,
                             "log_scale": spec_levels[s] + rng.normal(0, 0.02) + drift_per_h * (t - t0)
                             + rng.normal(0, 0.01)})
    return pd.DataFrame(rows)


def test_a_block_design_does_not_turn_the_specimens_into_a_time_trend():
    lv = _block_design(0.0)
    # the specimens' levels follow the clock: read across curves, they are a strong "trend"
    across = st.mixed_coefficient_test(lv.assign(specimen=lv["sample"]), "log_scale", "elapsed_h", ("condition",))
    assert across["p_value"] < 1e-3
    t, design = within_test(lv, "elapsed_h")
    assert design.startswith("within samples") and t["p_value"] > 0.01, (t, design)


def test_a_drift_within_samples_is_found_in_a_block_design():
    t, design = within_test(_block_design(0.10), "elapsed_h")
    assert t["estimate"] == pytest.approx(0.10, abs=0.03) and t["p_value"] < 1e-4


def test_a_preload_that_acts_as_a_power_is_read_on_a_log_scale():
    """Six specimens, three samples each, every sample pressed with its own preload F (log-uniform 0.02-0.5 N) and
    stiffened by (F / 0.1 N)^0.15: a power law in the preload. A linear regressor on F puts its leverage on the few
    largest preloads; the covariates table also reads a positive covariate that spans a decade on a log scale, and
    there recovers the exponent (oracle: 0.15 ln F), Bonferroni x 2 with the linear read."""
    from tissuemech.diagnosis.covariates import covariate_tests

    rng = np.random.default_rng(11)
    rows = []
    for s in range(6):
        spec = rng.normal(0.0, 0.2)
        for k in range(3):
            force = float(np.exp(rng.uniform(np.log(0.02), np.log(0.5))))
            level = spec + 0.15 * np.log(force / 0.1) + rng.normal(0.0, 0.03)
            for cond, offset in (("c1", 0.0), ("c2", 0.3)):
                rows.append({"curve": f"S{s}/{k}/{cond}", "specimen": f"S{s}", "sample": f"S{s}/{k}",
                             "condition": cond, "channel_normal_force": force,
                             "log_scale": offset + level + rng.normal(0.0, 0.01)})
    entry = next(e for e in covariate_tests(pd.DataFrame(rows)) if e["covariate"] == "channel_normal_force")
    assert entry["tested"] and "log scale" in entry["variation"], entry
    assert entry["slope"] == pytest.approx(0.15, abs=0.03) and entry["p_value"] < 1e-4
    linear = st.mixed_coefficient_test(pd.DataFrame(rows), "log_scale", "channel_normal_force", ("condition",))
    assert linear["log10_p"] > entry["log10_p"]
