"""Residual-structure statistics on constructed residuals with known structure (alpha = 0.01)."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy import stats as sps

from tissuemech import stats as st

ALPHA = st.ALPHA


def ar1(n, rho, rng):
    e = np.empty(n)
    e[0] = rng.normal()
    for i in range(1, n):
        e[i] = rho * e[i - 1] + np.sqrt(1 - rho ** 2) * rng.normal()
    return e


def test_runs_test_detects_sign_blocks_and_is_silent_on_white_noise():
    rng = np.random.default_rng(1)
    white = rng.normal(size=200)
    assert st.runs_test(white)["p_value"] > ALPHA
    # a systematic misfit: residual positive on the first half, negative on the second, plus noise
    block = np.r_[np.full(100, 1.0), np.full(100, -1.0)] + 0.3 * rng.normal(size=200)
    res = st.runs_test(block)
    assert res["p_value"] < 1e-10 and res["statistic"] < 0
    # closed form (Wald-Wolfowitz) for a tiny case: + + - - + +  -> R = 3, n+ = 4, n- = 2
    x = np.array([1, 1, -1, -1, 1, 1.0])
    mu = 2 * 4 * 2 / 6 + 1
    var = 2 * 4 * 2 * (2 * 4 * 2 - 6) / (36 * 5)
    assert st.runs_test(x)["n_runs"] == 3
    assert st.runs_test(x)["statistic"] == pytest.approx((3 - mu + 0.5) / np.sqrt(var), rel=1e-9)


def test_durbin_watson_and_effective_sample_size():
    rng = np.random.default_rng(2)
    white = rng.normal(size=4000)
    assert st.durbin_watson(white) == pytest.approx(2.0, abs=0.1)
    correlated = ar1(4000, 0.8, rng)
    assert st.durbin_watson(correlated) == pytest.approx(2 * (1 - 0.8), abs=0.1)
    # n_eff = n (1 - rho)/(1 + rho) = 4000 / 9
    assert st.effective_sample_size(correlated) == pytest.approx(4000 / 9, rel=0.25)
    assert st.effective_sample_size(white) == pytest.approx(4000, rel=0.1)


def _clustered(slope, rng, n_curves=12, n_points=40):
    x = np.tile(np.linspace(0, 1, n_points), n_curves)
    curve = np.repeat(np.arange(n_curves), n_points)
    # curve-level offsets and autocorrelated within-curve noise: what rheometer residuals look like
    noise = np.concatenate([ar1(n_points, 0.7, rng) for _ in range(n_curves)]) * 0.05
    y = slope * x + rng.normal(0, 0.2, n_curves)[curve] + noise
    return y, pd.DataFrame({"x": x}), curve


def test_cluster_regression_recovers_slope_and_is_silent_without_one():
    rng = np.random.default_rng(3)
    y, X, g = _clustered(0.1, rng)
    res = st.coefficient_test(st.cluster_regression(y, X, groups=g), "x")
    assert res["estimate"] == pytest.approx(0.1, abs=0.03)
    assert res["p_value"] < ALPHA
    assert res["df"] == 11  # clusters - 1
    false_alarms = 0
    for seed in range(40):
        y0, X0, g0 = _clustered(0.0, np.random.default_rng(100 + seed))
        false_alarms += st.coefficient_test(st.cluster_regression(y0, X0, groups=g0), "x")["p_value"] < 0.05
    assert false_alarms <= 6  # nominal 2 of 40 at 5 %; iid OLS standard errors would give far more


def test_nested_f_lrt_and_aicc_closed_forms():
    f = st.nested_f_test(rss_restricted=12.0, rss_full=10.0, n=50, k_full=4, dk=2)
    assert f["statistic"] == pytest.approx((2.0 / 2) / (10.0 / 46))
    assert f["p_value"] == pytest.approx(sps.f.sf(f["statistic"], 2, 46))
    lrt = st.likelihood_ratio_test(-100.0, -95.0, 2)
    assert lrt["statistic"] == pytest.approx(10.0)
    assert lrt["p_value"] == pytest.approx(sps.chi2.sf(10.0, 2))
    assert st.aicc(10.0, 50, 4) == pytest.approx(50 * np.log(0.2) + 8 + 40 / 45)
    assert st.gaussian_loglik(10.0, 50) == pytest.approx(np.sum(sps.norm.logpdf(np.full(50, np.sqrt(0.2)), 0,
                                                                                  np.sqrt(0.2))) , rel=1e-12)


def test_holm_step_down():
    reject, adj = st.holm([0.001, 0.004, 0.03, np.nan], alpha=0.01)
    assert reject.tolist() == [True, True, False, False]
    assert adj[:3] == pytest.approx([0.003, 0.008, 0.03])
    assert np.isnan(adj[3])


def test_log10_p_survives_underflow():
    assert st.log10_p_from_z(30.0) == pytest.approx(np.log10(2 * sps.norm.sf(30.0)), rel=1e-9)
    assert st.log10_p_from_z(60.0) < -780  # p itself underflows to 0 in double precision


def test_outlier_scores():
    x = np.array([1.0, 1.1, 0.9, 1.05, 0.95, 3.0])
    z = st.modified_z_scores(x)
    med = np.median(x)
    mad = np.median(np.abs(x - med))
    assert z[-1] == pytest.approx(0.6745 * (3.0 - med) / mad)
    res = st.deletion_outlier_test(x)
    assert res["index"] == 5 and res["p_value"] < ALPHA
    rng = np.random.default_rng(4)
    assert st.deletion_outlier_test(rng.normal(size=8))["p_value"] > ALPHA


def test_mixed_model_recovers_between_and_within_spread():
    rng = np.random.default_rng(5)
    n_b, n_s = 40, 4
    u = rng.normal(0, 0.3, n_b)
    rows = [{"g": f"b{b}", "v": np.exp(np.log(200.0) + u[b] + rng.normal(0, 0.1))} for b in range(n_b) for _ in range(n_s)]
    table = pd.DataFrame(rows).assign(log_v=lambda d: np.log(d["v"]))
    res = st.mixed_effects(table, "log_v", specimen="g", sample=None, method=None)  # one row per sample
    assert res["mean"] == pytest.approx(np.log(200.0), abs=0.15)
    assert res["sd_specimen"] == pytest.approx(0.3, rel=0.3)
    assert res["sd_sample"] == pytest.approx(0.1, rel=0.2)


def test_strongest_component_is_bonferroni_over_the_components():
    parts = [{"statistic": 2.0, "log10_p": -3.0}, {"statistic": 6.5, "log10_p": -8.0}, {"statistic": 1.0, "log10_p": np.nan}]
    t = st.strongest_component(parts)
    assert t["statistic"] == 6.5
    assert t["log10_p"] == pytest.approx(-8.0 + np.log10(2))  # two finite components: p = 2 * 1e-8
    assert t["p_value"] == pytest.approx(2e-8)
