"""Posterior sampling (emcee): on a linear model with a known Gaussian posterior the credible intervals match
the lmfit standard errors, and the diagnostics flag a chain that is too short."""
from __future__ import annotations

import emcee  # noqa: F401  (test extra: a missing emcee is an error, not a skip)
import lmfit
import numpy as np
import pytest

from tissuemech import posterior as P

X = np.linspace(0.0, 10.0, 40)


def _line_fit():
    rng = np.random.default_rng(7)
    y = 2.0 + 0.5 * X + rng.normal(0.0, 0.3, X.size)
    params = lmfit.Parameters()
    params.add("a", 0.0)
    params.add("b", 0.0)
    res = lmfit.minimize(lambda p: p["a"].value + p["b"].value * X - y, params)
    return y, res


def test_linear_model_credible_intervals_match_lmfit_standard_errors():
    y, res = _line_fit()
    opt = {n: res.params[n].value for n in ("a", "b")}
    post = P.sample_posterior(lambda th: th[0] + th[1] * X - y, opt, {"a": (-100, 100), "b": (-100, 100)},
                              noise_variance=res.redchi, n_walkers=32, n_steps=4000, burn=1000, seed=1)
    summary = post.summary()
    for n in ("a", "b"):
        se = res.params[n].stderr
        # flat prior + linear model: the posterior is Gaussian, mean = least squares, sd = lmfit stderr
        assert summary[n]["mean"] == pytest.approx(opt[n], abs=0.1 * se)
        assert summary[n]["sd"] == pytest.approx(se, rel=0.1)
        lo, hi = post.credible_interval(n, 0.9)
        assert (hi - lo) == pytest.approx(2 * 1.6448536 * se, rel=0.1)
        assert post.rhat[n] < P.RHAT_MAX and post.ess[n] > P.ESS_MIN
    assert post.acceptance >= P.ACCEPTANCE_MIN and post.warnings == []
    assert post.priors["a"] == "uniform on [-100, 100]"


def test_short_chain_is_flagged():
    y, res = _line_fit()
    opt = {n: res.params[n].value for n in ("a", "b")}
    post = P.sample_posterior(lambda th: th[0] + th[1] * X - y, opt, {"a": (-100, 100), "b": (-100, 100)},
                              noise_variance=res.redchi, n_walkers=8, n_steps=60, burn=0, seed=2)
    assert any("ESS" in w for w in post.warnings)


def test_split_rhat_detects_chains_in_different_places():
    rng = np.random.default_rng(0)
    same = rng.normal(size=(4, 1000))
    apart = same + np.arange(4)[:, None]
    assert P.split_rhat(same) < 1.01 and P.split_rhat(apart) > 1.5
