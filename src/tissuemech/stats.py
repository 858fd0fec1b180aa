"""Generic statistics, below fitting and diagnosis (this module imports nothing of the package).

* information criteria of a least-squares fit -- :func:`information_criteria` (AIC, AICc, BIC), the package's
  one AICc (:func:`aicc` is its AICc); effective sample size of autocorrelated residuals
  (:func:`effective_sample_size`, ``science.md`` section 4.2);
* residual-structure tests used to name what a fitted model gets wrong (``science.md`` section 4): runs test,
  Durbin-Watson, cluster-robust regression and coefficient tests, nested F-test, likelihood ratio, Holm and
  Bonferroni, outlier tests, a random-intercept model.

Thin, pure wrappers around statsmodels/scipy that return plain dicts (JSON-ready floats) so the catalogue
and the generic detector share one vocabulary: ``statistic``, ``p_value``, ``log10_p`` (kept separately
because strong effects drive p-values below double precision and findings are ranked on it), and an
``effect_size`` in the units the caller states.

Conventions: residual ``e = observed - predicted``; *standardized* residuals are divided by the noise model
of the measurement; all tests are two-sided unless stated.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd
from scipy import stats as sps

if TYPE_CHECKING:  # annotations only
    import statsmodels.api as sm

# statsmodels (with patsy and formulaic, ~1 CPU s) is imported by the functions that use it: the fit, figure and
# FEM jobs of the workflow import this module for the information criteria only

#: family-wise false-alarm level of the diagnosis (Holm across every test run on one dataset); the default of
#: :func:`holm`
ALPHA = 0.01


def log10_p_from_z(z: float) -> float:
    """log10 of the two-sided normal p-value of ``z``, accurate far below 1e-308."""
    return float((np.log(2.0) + sps.norm.logsf(abs(z))) / np.log(10.0))


def log10_p_from_t(t: float, df: float) -> float:
    """log10 of the two-sided Student-t p-value of ``t`` with ``df`` degrees of freedom."""
    if not np.isfinite(df) or df > 1e6:
        return log10_p_from_z(t)
    return float((np.log(2.0) + sps.t.logsf(abs(t), df)) / np.log(10.0))


def log10_p_from_f(f: float, df1: float, df2: float) -> float:
    """log10 of the upper-tail F p-value."""
    return float(sps.f.logsf(max(f, 0.0), df1, df2) / np.log(10.0))


def log10_p_from_chi2(x: float, df: float) -> float:
    """log10 of the upper-tail chi-square p-value."""
    return float(sps.chi2.logsf(max(x, 0.0), df) / np.log(10.0))


def statistic_result(statistic: float, log10_p: float, **extra) -> dict:
    """A test's result as the tests of this module return it: ``statistic``, ``p_value``, ``log10_p``
    (capped at 0) and the extra fields as floats."""
    log10_p = float(min(log10_p, 0.0))
    out = {"statistic": float(statistic), "p_value": float(10.0 ** log10_p), "log10_p": log10_p}
    out.update({k: (float(v) if isinstance(v, (int, float, np.floating, np.integer)) else v)
                for k, v in extra.items()})
    return out




# ------------------------------------------------------------------------------------------------
# serial structure
# ------------------------------------------------------------------------------------------------
def runs_test(residuals: np.ndarray) -> dict:
    """Wald-Wolfowitz runs test on residual signs (cutoff 0), in the order given.

    Too few runs (z < 0) means residuals of one sign cluster together: a systematic misfit along the
    ordering variable (strain, time ...). Returns ``statistic`` = z, two-sided ``p_value``, ``n_runs``.
    """
    e = np.asarray(residuals, float)
    e = e[np.isfinite(e) & (e != 0.0)]
    n_pos, n_neg = int((e > 0).sum()), int((e < 0).sum())
    if n_pos == 0 or n_neg == 0:
        # every residual of one sign: maximal structure; the exact probability under H0 is 2 * 0.5**n
        n = e.size
        return statistic_result(-np.inf if n else 0.0, (1 - n) * np.log10(2.0) if n else 0.0, n_runs=1 if n else 0)
    from statsmodels.sandbox.stats.runs import runstest_1samp

    z, _ = runstest_1samp(e, cutoff=0.0, correction=e.size < 50)
    n_runs = int(1 + np.count_nonzero(np.diff(np.sign(e))))
    return statistic_result(z, log10_p_from_z(z), n_runs=n_runs)


def durbin_watson(residuals: np.ndarray) -> float:
    """Durbin-Watson d = sum (e_t - e_{t-1})^2 / sum e_t^2 (about 2 for white noise, < 1.5 structured)."""
    from statsmodels.stats.stattools import durbin_watson as sm_durbin_watson

    e = np.asarray(residuals, float)
    return float(sm_durbin_watson(e[np.isfinite(e)]))


def lag1_autocorrelation(residuals: np.ndarray) -> float:
    """Lag-1 sample autocorrelation of a residual sequence (0 for fewer than 3 points)."""
    e = np.asarray(residuals, float)
    e = e[np.isfinite(e)] - np.nanmean(e)
    if e.size < 3 or not np.any(e):
        return 0.0
    return float(np.dot(e[1:], e[:-1]) / np.dot(e, e))


def effective_sample_size(residuals: np.ndarray) -> float:
    """n_eff = n (1 - rho1) / (1 + rho1) from the lag-1 autocorrelation (clipped to [1, n])."""
    e = np.asarray(residuals, float)
    n = int(np.isfinite(e).sum())
    rho = min(max(lag1_autocorrelation(e), -0.99), 0.99)
    return float(np.clip(n * (1.0 - rho) / (1.0 + rho), 1.0, max(n, 1)))


# ------------------------------------------------------------------------------------------------
# regressions
# ------------------------------------------------------------------------------------------------
def cluster_regression(y: np.ndarray, X: pd.DataFrame, groups: np.ndarray | None = None,
                       weights: np.ndarray | None = None) -> sm.regression.linear_model.RegressionResultsWrapper:
    """OLS/WLS of ``y`` on the columns of ``X`` (an intercept is added) with cluster-robust covariance.

    Residuals within one curve are autocorrelated, so standard errors are clustered by ``groups``
    (usually the curve); :func:`coefficient_test` then refers t to Student-t with G - 1 degrees of freedom
    (G clusters), which keeps the test valid, if wide, down to G = 2. The points of a curve are never
    treated as independent: with 2 or 3 clusters the cluster covariance is still used (an HC3 covariance,
    used here before, treated hundreds of autocorrelated points of a few curves as independent and gave most
    of the false alarms on null data, docs/calibration.md). Without groups, or with one group, the HC3
    covariance is used (the caller has no curve structure to respect).
    """
    import statsmodels.api as sm

    y = np.asarray(y, float)
    Xc = sm.add_constant(X.astype(float), has_constant="add")
    model = sm.WLS(y, Xc, weights=weights) if weights is not None else sm.OLS(y, Xc)
    if groups is not None and len(pd.unique(np.asarray(groups))) >= 2:
        codes = pd.factorize(np.asarray(groups))[0]
        return model.fit(cov_type="cluster", cov_kwds={"groups": codes}, use_t=True)
    return model.fit(cov_type="HC3", use_t=True)


def coefficient_test(result, name: str) -> dict:
    """t-test of one coefficient of a :func:`cluster_regression` result.

    Returns ``statistic`` (t), ``p_value``, ``log10_p``, ``estimate``, ``std_error``, ``df``.
    """
    est = float(result.params[name])
    se = float(result.bse[name])
    df = float(result.df_resid)
    if getattr(result, "cov_type", "") == "cluster":
        df = float(_n_clusters(result) - 1)
    t = est / se if se > 0 else (np.inf if est else 0.0)
    return statistic_result(t, log10_p_from_t(t, df), estimate=est, std_error=se, df=df)


def _n_clusters(result) -> int:
    groups = result.cov_kwds.get("groups") if hasattr(result, "cov_kwds") else None
    if groups is None:
        return int(result.nobs)
    return int(len(np.unique(groups)))


def nested_f_test(rss_restricted: float, rss_full: float, n: float, k_full: int, dk: int) -> dict:
    """F-test of nested least-squares models: F = [(RSS0 - RSS1)/dk] / [RSS1/(n - k1)].

    ``n`` may be an effective sample size (autocorrelated residuals overstate n).
    """
    df2 = max(n - k_full, 1.0)
    f = ((rss_restricted - rss_full) / dk) / (rss_full / df2) if rss_full > 0 else np.inf
    return statistic_result(f, log10_p_from_f(f, dk, df2), df1=dk, df2=df2)


def likelihood_ratio_test(loglik_restricted: float, loglik_full: float, dk: int) -> dict:
    """LRT: 2 (lnL1 - lnL0) ~ chi2(dk)."""
    lr = 2.0 * (loglik_full - loglik_restricted)
    return statistic_result(lr, log10_p_from_chi2(lr, dk), df=dk)


def gaussian_loglik(rss: float, n: float) -> float:
    """Profile log-likelihood of Gaussian residuals with the variance estimated as RSS/n."""
    return float(-0.5 * n * (np.log(2.0 * np.pi * rss / n) + 1.0))


def information_criteria(chisqr: float, n: float, k: int) -> dict[str, float]:
    """AIC, AICc and BIC of a (weighted) least-squares fit (Burnham & Anderson; ``science.md`` §4.2).

    AIC = n ln(chi2/n) + 2k; AICc = AIC + 2k(k+1)/(n-k-1) (infinite when n <= k+1); BIC = n ln(chi2/n) + k ln n.
    ``chisqr`` may be a weighted chi-square or a residual sum of squares; ``n`` may be an effective sample size.
    A zero chi-square is taken as the smallest positive float (finite criteria).
    """
    chisqr = max(float(chisqr), np.finfo(float).tiny)
    base = n * math.log(chisqr / n)
    aic = base + 2.0 * k
    corrected = aic + (2.0 * k * (k + 1) / (n - k - 1) if n - k - 1 > 0 else np.inf)
    bic = base + k * math.log(n)
    return {"aic": float(aic), "aicc": float(corrected), "bic": float(bic)}


def aicc(rss: float, n: float, k: int) -> float:
    """AICc of :func:`information_criteria` (RSS may be a weighted chi2)."""
    return information_criteria(rss, n, k)["aicc"]


# ------------------------------------------------------------------------------------------------
# multiplicity and outliers
# ------------------------------------------------------------------------------------------------
def holm(p_values: Sequence[float], alpha: float = ALPHA) -> tuple[np.ndarray, np.ndarray]:
    """Holm step-down correction. Returns ``(reject, adjusted_p)`` arrays (NaN p-values never reject)."""
    p = np.asarray(p_values, float)
    reject = np.zeros(p.size, bool)
    adjusted = np.full(p.size, np.nan)
    ok = np.isfinite(p)
    if ok.any():
        from statsmodels.stats.multitest import multipletests

        r, a, _, _ = multipletests(p[ok], alpha=alpha, method="holm")
        reject[ok], adjusted[ok] = r, a
    return reject, adjusted


def bonferroni_min(log10_ps: Sequence[float]) -> float:
    """log10 of the Bonferroni-combined p-value ``min(1, k * min p)`` of k component tests."""
    lp = [x for x in log10_ps if np.isfinite(x)]
    if not lp:
        return 0.0
    return float(min(0.0, min(lp) + np.log10(len(lp))))


def strongest_component(parts: Sequence[dict]) -> dict:
    """The combined result of k component tests (dicts with ``statistic`` and ``log10_p``): the statistic of
    the strongest component and the Bonferroni-combined p-value (:func:`bonferroni_min`)."""
    lp = bonferroni_min([p["log10_p"] for p in parts])
    best = min(parts, key=lambda p: p["log10_p"])
    return {"statistic": best["statistic"], "p_value": 10 ** lp, "log10_p": lp}


def modified_z_scores(values: np.ndarray) -> np.ndarray:
    """Iglewicz-Hoaglin modified z = 0.6745 (x - median) / MAD (|z| > 3.5 flags an outlier)."""
    x = np.asarray(values, float)
    med = np.median(x)
    mad = np.median(np.abs(x - med))
    if mad == 0:
        mad = 1.4826 * np.mean(np.abs(x - med)) / 0.6745 if np.any(x != med) else 1.0
    return 0.6745 * (x - med) / mad


def deletion_outlier_test(values: np.ndarray) -> dict:
    """Studentized leave-one-out test for the most extreme of ``values`` (e.g. per-specimen log-scales).

    For each value, t = (x_b - mean_-b) / (sd_-b sqrt(1 + 1/(n-1))) ~ t_{n-2} under a common normal
    population (the prediction-interval test; defined from n = 3, where it has 1 df); the most extreme is
    reported with a Bonferroni factor n.
    Returns ``statistic`` (t), ``p_value``, ``index`` of the extreme value, ``modified_z`` of it.
    """
    x = np.asarray(values, float)
    n = x.size
    if n < 3:
        return statistic_result(0.0, 0.0, index=-1, modified_z=0.0)
    ts = np.empty(n)
    for b in range(n):
        rest = np.delete(x, b)
        sd = rest.std(ddof=1)
        ts[b] = (x[b] - rest.mean()) / (sd * np.sqrt(1.0 + 1.0 / rest.size)) if sd > 0 else np.inf
    b = int(np.argmax(np.abs(ts)))
    lp = min(0.0, log10_p_from_t(ts[b], n - 2) + np.log10(n))
    return statistic_result(ts[b], lp, index=b, modified_z=float(modified_z_scores(x)[b]))


def mixed_log_params(table: pd.DataFrame, value: str, group: str) -> dict:
    """Random-intercept model ln(theta_bs) = ln(theta) + u_b + e_bs (statsmodels MixedLM).

    Parameters
    ----------
    table : one row per sample with columns ``value`` (positive parameter) and ``group`` (specimen)

    Returns
    -------
    dict with ``mean_log``, ``omega_between`` (SD of u_b), ``omega_within`` (SD of e_bs), ``icc`` and the
    standardized BLUPs ``blup_z`` per group (|z| > 3 flags an outlier specimen).
    """
    import statsmodels.formula.api as smf

    df = pd.DataFrame({"y": np.log(table[value].to_numpy(float)), "g": table[group].astype(str).to_numpy()})
    fit = smf.mixedlm("y ~ 1", df, groups=df["g"]).fit(reml=True)
    var_b = float(fit.cov_re.iloc[0, 0])
    var_w = float(fit.scale)
    blups = {g: float(v.iloc[0]) for g, v in fit.random_effects.items()}
    sd_b = np.sqrt(var_b) if var_b > 0 else np.nan
    return {"mean_log": float(fit.fe_params.iloc[0]), "omega_between": float(np.sqrt(max(var_b, 0.0))),
            "omega_within": float(np.sqrt(var_w)), "icc": float(var_b / (var_b + var_w)) if var_b + var_w > 0 else 0.0,
            "blup_z": {g: (u / sd_b if np.isfinite(sd_b) else 0.0) for g, u in blups.items()}}
