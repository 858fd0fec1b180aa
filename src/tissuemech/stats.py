"""Generic statistics, below fitting and diagnosis (this module imports nothing of the package).

* information criteria of a least-squares fit -- :func:`information_criteria` (AIC, AICc, BIC), the package's
  one AICc (:func:`aicc` is its AICc); the package's one normalised RMS error of a curve (:func:`nrmse`: fit
  records, held-out scores, FEM torsion and the FEM replay of the measured tests); effective sample size of autocorrelated residuals
  (:func:`effective_sample_size`, ``science.md`` section 4.2);
* residual-structure tests used to name what a fitted model gets wrong (``science.md`` section 4): runs test,
  Durbin-Watson, cluster-robust regression and coefficient tests, nested F-test, likelihood ratio, Holm and
  Bonferroni, outlier tests;
* the package's one linear mixed-effects model (:func:`mixed_effects`: specimen random intercept, nested sample
  component, SEs, standardised BLUPs), used by ``uq.run_population`` and the diagnosis's outlier-specimen detector.

Thin, pure wrappers around statsmodels/scipy that return plain dicts (JSON-ready floats) so the catalogue
and the generic detector share one vocabulary: ``statistic``, ``p_value``, ``log10_p`` (kept separately
because strong effects drive p-values below double precision and findings are ranked on it), and an
``effect_size`` in the units the caller states.

Conventions: residual ``e = observed - predicted``; *standardized* residuals are divided by the noise model
of the measurement; all tests are two-sided unless stated.
"""
from __future__ import annotations

import math
import warnings
from math import comb
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd
import scipy

if TYPE_CHECKING:  # annotations only
    import statsmodels.api as sm

# statsmodels (with patsy and formulaic, ~1 CPU s) is imported by the functions that use it: the fit, figure and
# FEM jobs of the workflow import this module for the information criteria only

#: family-wise false-alarm level of the diagnosis (Holm across every test run on one dataset); the default of
#: :func:`holm`
ALPHA = 0.01


# ------------------------------------------------------------------------------------------------
# the noise of a smooth measured sequence
# ------------------------------------------------------------------------------------------------
def robust_noise_sd(values: np.ndarray) -> float:
    """White-noise SD of a smooth sequence from its second differences: 1.4826 MAD(d2) / sqrt(6).

    For y_i = f_i + e_i with slowly varying f and independent e_i of SD s, var(e_{i+1} - 2 e_i + e_{i-1})
    = 6 s^2; the median absolute value makes the estimate robust to steps and outliers. Units of ``values``;
    NaN for fewer than 3 finite values.
    """
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    if v.size < 3:
        return np.nan
    d2 = v[2:] - 2.0 * v[1:-1] + v[:-2]
    return float(1.4826 * np.median(np.abs(d2)) / np.sqrt(6.0))


def relative_differences(y: np.ndarray, scale: np.ndarray | None = None,
                         magnitude: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(|y| x ``scale`` at the centre points, relative k-th differences scaled to the noise SD) of one curve.

    Six detrendings are computed: k-th differences (k = 2, 3, 4) of ln|y| (exact for exponential and
    power-law trends) and of y over |y| (exact for polynomial trends, e.g. a ramp from zero), each divided
    by sqrt(C(2k, k)) so that white noise of relative SD s gives differences of SD s. A smooth trend can only
    add to them, so the detrending with the smallest median magnitude is kept for the curve. ``scale``
    (per point, e.g. the strain amplitude of a modulus) converts the magnitudes to the units the absolute
    noise is constant in; such a curve (a modulus along amplitude or frequency) is detrended in ln|y| only, its
    trends being power laws. ``magnitude`` (per point, e.g. |G*| for a storage or loss modulus): the noise is
    relative to it, not to |y|; the differences are then expressed relative to it (those of ln|y| times
    |y| / magnitude) and the magnitudes returned are it times ``scale``.
    """
    y = np.asarray(y, float)
    s = np.ones_like(y) if scale is None else np.abs(np.asarray(scale, float))
    m = np.abs(y) if magnitude is None else np.abs(np.asarray(magnitude, float))
    keep = np.isfinite(y) & (y != 0) & np.isfinite(s) & (s > 0) & np.isfinite(m) & (m > 0)
    y, s, m = y[keep], s[keep], m[keep]
    if y.size < 5:
        return np.empty(0), np.empty(0)
    z = np.log(np.abs(y))
    best, best_scale, centre = None, np.inf, None
    for k in (2, 3, 4):
        norm = np.sqrt(float(comb(2 * k, k)))
        lo = k // 2
        mid = slice(lo, y.size - (k - lo))
        ln_d = np.diff(z, k) / norm * np.abs(y[mid]) / m[mid]
        for d in (ln_d,) if scale is not None else (ln_d, np.diff(y, k) / norm / m[mid]):
            spread = float(np.median(np.abs(d)))
            if spread < best_scale:
                best, best_scale, centre = d, spread, m[mid] * s[mid]
    return centre, best


def relative_noise_sd(y: np.ndarray) -> float:
    """Relative white-noise SD of a smooth curve (1.4826 times the median absolute relative difference of
    :func:`relative_differences`); NaN for fewer than 5 usable points."""
    _, d = relative_differences(y)
    return float(1.4826 * np.median(np.abs(d))) if d.size else float("nan")


def log10_p_from_z(z: float) -> float:
    """log10 of the two-sided normal p-value of ``z``, accurate far below 1e-308."""
    return float((np.log(2.0) + scipy.stats.norm.logsf(abs(z))) / np.log(10.0))


def log10_p_from_t(t: float, df: float) -> float:
    """log10 of the two-sided Student-t p-value of ``t`` with ``df`` degrees of freedom."""
    if not np.isfinite(df) or df > 1e6:
        return log10_p_from_z(t)
    return float((np.log(2.0) + scipy.stats.t.logsf(abs(t), df)) / np.log(10.0))


def log10_p_from_f(f: float, df1: float, df2: float) -> float:
    """log10 of the upper-tail F p-value."""
    return float(scipy.stats.f.logsf(max(f, 0.0), df1, df2) / np.log(10.0))


def log10_p_from_chi2(x: float, df: float) -> float:
    """log10 of the upper-tail chi-square p-value."""
    return float(scipy.stats.chi2.logsf(max(x, 0.0), df) / np.log(10.0))


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
    """Lag-1 sample autocorrelation of a residual sequence (0 for fewer than 3 points).

    The formula of ``statsmodels.tsa.stattools.acf(e, nlags=1)[1]``, written out: every fit calls it (through
    :func:`effective_sample_size`) and the fit jobs do not import statsmodels (module note)."""
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


def nrmse(observed, predicted) -> float:
    """Normalised RMS error of one curve: ``sqrt(mean((predicted - observed)^2)) / mean(|observed|)`` (1).

    The arrays are flattened together, so a curve with several observables (G' and G'' of a sweep) is passed as
    their concatenation. NaN when the observations are empty or their mean magnitude is 0.
    """
    y = np.ravel(np.asarray(observed, float))
    f = np.ravel(np.asarray(predicted, float))
    if y.shape != f.shape:
        raise ValueError(f"nrmse: {y.size} observations but {f.size} predictions")
    scale = float(np.mean(np.abs(y))) if y.size else 0.0
    if scale <= 0.0:
        return float("nan")
    return float(np.sqrt(np.mean((f - y) ** 2)) / scale)


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
    mad = float(scipy.stats.median_abs_deviation(x))  # unscaled: median |x - median|
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


#: the optimizers :func:`mixed_effects` hands to ``MixedLM.fit`` by default (L-BFGS, Powell where it fails)
MIXED_OPTIMIZERS = ("lbfgs", "powell")


def mixed_effects(table: pd.DataFrame, value: str, specimen: str = "specimen", sample: str | None = "sample",
                  method: Sequence[str] | None = MIXED_OPTIMIZERS, covariates: Sequence[str] = (),
                  factors: Sequence[str] = ()) -> dict:
    """The package's one linear mixed-effects model: ``value = mu + b_specimen [+ c_sample] + e`` (statsmodels
    ``MixedLM``, REML).

    * a specimen random intercept ``b ~ N(0, sd_specimen^2)``;
    * when a piece (a ``specimen``/``sample`` pair) has several rows, a sample variance component nested in the
      specimen (``c ~ N(0, sd_sample^2)``) and a within-piece residual ``sd_residual``; with one row per piece
      (or ``sample`` None: every row is its own piece) the residual *is* the sample-to-sample SD (it includes any
      within-row misfit) and ``sd_residual`` is NaN;
    * standard errors: the mean's from ``MixedLM``; a variance component's from ``MixedLM``'s covariance of its
      variance parameters (relative to the residual scale) times the scale, ``sqrt(2/df)`` for the residual
      variance; the delta method for the SDs;
    * ``blup_z``: the specimens' BLUPs (predicted intercepts) divided by ``sd_specimen`` (0 where that is 0;
      |z| > 3 flags an outlier specimen); ``icc``: the specimen share of the total variance.

    Parameters
    ----------
    table : one row per observation with columns ``value`` (already on the scale modelled, e.g. a log), ``specimen``
        and, unless None, ``sample``; rows with a non-finite ``value`` are dropped
    method : optimizers tried in turn by ``MixedLM.fit`` (None: statsmodels' default list)
    covariates, factors : numeric columns and categorical columns (``C(...)``) of the fixed part, ``value ~ 1 +
        covariates + factors`` (default: the mean only); their estimates are returned in ``coefficients``
        (``{column: {"estimate", "std_error"}}``) and ``factor_wald`` (``{column: {"chi2", "df"}}``, the joint Wald
        statistic of the factor's levels), the fixed-effect covariance in ``fe_cov``; rows missing any of them are
        dropped

    Returns
    -------
    A JSON-ready dict: ``value``, ``n_runs`` (rows), ``n_specimens``, ``n_pieces``, ``mean``, ``mean_se``,
    ``sd_specimen``, ``sd_specimen_se``, ``sd_sample``, ``sd_sample_se``, ``sd_residual``, ``sd_residual_se``,
    ``icc``, ``blup_z`` (per specimen, keys as strings), ``converged`` and the ``method`` statement; with fewer than
    2 specimens or 3 rows only the counts, ``mean`` and ``status``.
    """
    import statsmodels.formula.api as smf  # a slow import (module note), only here

    keep = np.isfinite(table[value].to_numpy(float))
    for c in covariates:
        keep &= np.isfinite(table[c].to_numpy(float))
    for c in factors:
        keep &= table[c].notna().to_numpy()
    d = table[keep]
    spec = d[specimen].astype(str).to_numpy()
    piece = spec + "/" + (d[sample].astype(str).to_numpy() if sample is not None else np.arange(len(d)).astype(str))
    # safe names for the formula (sample-sheet columns may hold any characters)
    xs = {f"x{i}": c for i, c in enumerate(covariates)}
    fs = {f"f{i}": c for i, c in enumerate(factors)}
    fixed = {k: d[c].to_numpy(float) for k, c in xs.items()} | {k: d[c].astype(str).to_numpy() for k, c in fs.items()}
    d = pd.DataFrame({"y": d[value].to_numpy(float), "specimen": spec, "piece": piece, **fixed})
    formula = "y ~ 1" + "".join(f" + {k}" for k in xs) + "".join(f" + C({k})" for k in fs)
    n, n_spec, n_piece = len(d), d["specimen"].nunique(), d["piece"].nunique()
    repeated = n_piece < n
    out = {"value": value, "n_runs": n, "n_specimens": int(n_spec), "n_pieces": int(n_piece)}
    if n_spec < 2 or n < 3:
        out.update({"mean": float(d["y"].mean()) if n else float("nan"), "status": "fewer than 2 specimens"})
        return out
    fit_method = list(method) if method is not None else None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # boundary / convergence warnings: reported through `converged` and the SDs
        vc = {"sample": "0 + C(piece)"} if repeated else None
        model = smf.mixedlm(formula, d, groups=d["specimen"], re_formula="1", vc_formula=vc)
        fit = model.fit(reml=True, method=fit_method)
    # statsmodels parameterises the variances relative to the residual scale; cov_params holds the covariance of
    # those relative parameters, so SE(variance) = scale x SE(relative) (the scale's own uncertainty left out)
    var_spec = float(fit.cov_re.iloc[0, 0])
    boundary = not var_spec > 0
    if boundary:
        # REML puts the specimen variance on its boundary (0): the model is the one without specimens. Its fit
        # is refitted as such, because MixedLM's own fixed effect at the boundary can be meaningless (a mean of
        # 2.2 with SE 1.7e6 on data of mean 5.7 seen with statsmodels 0.14 on an AVX-512 machine)
        var_spec, var_spec_se = 0.0, float("nan")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            if repeated:
                fit = smf.mixedlm(formula, d, groups=d["piece"]).fit(reml=True, method=fit_method)
            else:
                fit = smf.ols(formula, d).fit()
    scale = float(fit.scale)
    if boundary and not repeated:
        mean, mean_se = float(fit.params.iloc[0]), float(fit.bse.iloc[0])
    else:
        mean, mean_se = float(fit.fe_params.iloc[0]), float(fit.bse_fe.iloc[0])
        k_fe = len(fit.fe_params)
        cp = np.diag(np.asarray(fit.cov_params(), float))
        rel_se = np.sqrt(np.where(cp[k_fe:] >= 0, cp[k_fe:], np.nan))
    if not boundary:
        var_spec_se = float(scale * rel_se[0])
    if repeated:
        var_samp = float(fit.cov_re.iloc[0, 0]) if boundary else float(fit.vcomp[0])
        var_samp_se = float(scale * rel_se[0 if boundary else 1])
        var_resid, var_resid_se = scale, scale * math.sqrt(2.0 / max(n - n_piece, 1))
    else:  # one row per piece: the residual is the sample-to-sample variance
        var_samp, var_samp_se = scale, scale * math.sqrt(2.0 / max(n - (1 if boundary else n_spec), 1))
        var_resid, var_resid_se = float("nan"), float("nan")

    def sd(v, se):
        v = max(v, 0.0)
        return math.sqrt(v), (se / (2.0 * math.sqrt(v)) if v > 0 else float("nan"))

    out["mean"], out["mean_se"] = mean, mean_se
    out["sd_specimen"], out["sd_specimen_se"] = sd(var_spec, var_spec_se)
    out["sd_sample"], out["sd_sample_se"] = sd(var_samp, var_samp_se)
    out["sd_residual"], out["sd_residual_se"] = sd(var_resid, var_resid_se) if repeated else (float("nan"),) * 2
    total = var_spec + max(var_samp, 0.0) + (var_resid if repeated else 0.0)
    out["icc"] = float(var_spec / total) if total > 0 else 0.0
    sd_b = out["sd_specimen"]
    if boundary:  # every predicted specimen intercept is 0
        out["blup_z"] = {str(g): 0.0 for g in model.group_labels}
    else:
        out["blup_z"] = {str(g): float(v.iloc[0]) / sd_b for g, v in fit.random_effects.items()}
    if covariates or factors:
        fe = fit.params if boundary and not repeated else fit.fe_params
        cov = np.asarray(fit.cov_params(), float)[:len(fe), :len(fe)]
        names = list(fe.index)
        out["coefficients"] = {c: {"estimate": float(fe[k]), "std_error": float(np.sqrt(max(cov[names.index(k)][names.index(k)], 0.0)))}
                               for k, c in xs.items()}
        out["factor_wald"] = {}
        for k, c in fs.items():
            idx = [i for i, n in enumerate(names) if n.startswith(f"C({k})[")]
            b = np.asarray(fe.iloc[idx], float)
            v = cov[np.ix_(idx, idx)]
            try:
                chi2 = float(b @ np.linalg.solve(v, b)) if idx else float("nan")
            except np.linalg.LinAlgError:
                chi2 = float("nan")
            out["factor_wald"][c] = {"chi2": chi2, "df": len(idx)}
        out["fe_cov"] = cov.tolist()
        out["fe_names"] = [xs.get(n, n) for n in names]
    out["converged"] = bool(getattr(fit, "converged", True))
    out["method"] = ("statsmodels MixedLM (REML): value ~ " + ("1" if not (covariates or factors) else
                                                               "fixed covariates") + " + specimen random intercept"
                     + (" (estimated at 0, its boundary: refitted without it)" if boundary else "")
                     + (" + sample variance component nested in specimen" if repeated else
                        "; one run per piece, so the residual SD is the sample-to-sample SD (it includes the "
                        "within-run misfit)")
                     + "; SEs: MixedLM covariance of the variance parameters x scale, sqrt(2/df) for the residual "
                       "variance, delta method for SDs")
    return out


def variation_level(table: pd.DataFrame, column: str, specimen: str = "specimen", sample: str | None = "sample") -> str:
    """Where a column varies in a nested specimen/sample design: ``"within"`` (between rows of one piece, a
    ``specimen``/``sample`` pair), ``"piece"`` (between the pieces of one specimen, constant within each) or
    ``"specimen"`` (constant within every specimen). A numeric column counts as varying within a group when its
    standard deviation there exceeds a tenth of its overall one."""
    keys = [specimen] + ([sample] if sample is not None else [])
    if not pd.api.types.is_numeric_dtype(table[column]) or pd.api.types.is_bool_dtype(table[column]):
        col = table[column].astype(str)
        if sample is not None and (col.groupby([table[k] for k in keys]).nunique() > 1).any():
            return "within"
        if (col.groupby(table[specimen]).nunique() > 1).any():
            return "piece" if sample is not None else "within"
        return "specimen"
    # a numeric column varies within a group when its spread there is more than a tenth of its spread overall (a
    # logged channel's sensor noise inside a sample does not make a between-sample covariate a within-sample one)
    x = table[column].astype(float)
    total = float(x.std())
    if not total > 0:
        return "specimen"
    if sample is not None and float((x - x.groupby([table[k] for k in keys]).transform("mean")).std()) > 0.1 * total:
        return "within"
    if float((x - x.groupby(table[specimen]).transform("mean")).std()) > 0.1 * total:
        return "piece" if sample is not None else "within"
    return "specimen"


#: fewest residual degrees of freedom of a coefficient test in :func:`mixed_coefficient_test`
MIN_TEST_DF = 2


def mixed_coefficient_test(table: pd.DataFrame, value: str, covariate: str | Sequence[str],
                           factors: Sequence[str] = (), specimen: str = "specimen", sample: str | None = "sample",
                           categorical: bool = False, controls: Sequence[str] = ()) -> dict | None:
    """Test of fixed covariates of ``value`` with specimen and sample as random effects (:func:`mixed_effects`:
    ``value ~ 1 + covariate(s) + controls + C(factors) + (1 | specimen) + (1 | sample in specimen)``).

    Degrees of freedom by the between-within rule: a covariate that varies within pieces (a ``specimen``/``sample``
    pair) is referred to n - n_pieces - p_within, one that varies only between the pieces of a specimen to
    n_pieces - n_specimens - p_piece, one constant within specimens to n_specimens - p_specimen (p: the fixed
    parameters estimated at that level, the intercept at the specimen level), so that a covariate that follows the
    specimens is judged on the specimens, not on the curves. One numeric ``covariate`` gives a t-test of its slope;
    several (a sequence) a joint Wald F; ``categorical`` a joint Wald F over its levels. ``controls``: numeric
    columns held fixed (not tested). Where the mixed model cannot be fitted (fewer than 2 specimens, a failed or
    degenerate fit) the fixed part is fitted by OLS with standard errors clustered by specimen (else by sample; t
    with G - 1 df, :func:`cluster_regression`; HC3 with one sample), and ``method`` says so. Returns ``statistic``,
    ``p_value``, ``log10_p``, ``estimate``/``std_error`` (one numeric covariate), ``df`` (``df1``/``df2`` for an F),
    ``level`` (:func:`variation_level`), ``n``, ``method``; None when the covariate does not vary, is collinear with
    the factors and controls, or leaves fewer than :data:`MIN_TEST_DF` degrees of freedom where it varies (the
    fallback never takes more degrees of freedom than that either).
    """
    import statsmodels.api as sm  # noqa: F401  (a slow import, only here; cluster_regression needs it too)

    tested = [covariate] if isinstance(covariate, str) else list(covariate)
    cols = [value] + tested + list(controls) + [specimen] + ([sample] if sample is not None else []) + list(factors)
    d = table[list(dict.fromkeys(cols))].copy()
    ok = np.isfinite(d[value].to_numpy(float))
    for c in tested:
        ok &= d[c].notna().to_numpy()
        if not categorical:
            ok &= np.isfinite(pd.to_numeric(d[c], errors="coerce").to_numpy(float))
    for c in controls:
        ok &= np.isfinite(pd.to_numeric(d[c], errors="coerce").to_numpy(float))
    d = d[ok]
    for c in tested:
        d[c] = d[c].astype(str) if categorical else d[c].astype(float)
    for c in controls:
        d[c] = d[c].astype(float)
    if any(d[c].nunique() < 2 for c in tested) or len(d) < 4:
        return None
    # the fixed-effect design: a covariate collinear with the factors (e.g. a gap set per condition) is not testable
    dummies = [pd.get_dummies(d[f].astype(str), drop_first=True, dtype=float) for f in factors]
    xcov = (pd.get_dummies(d[tested[0]], drop_first=True, dtype=float).add_prefix("cov_") if categorical
            else d[tested])
    const = pd.Series(1.0, index=d.index, name="const")
    X = pd.concat([const, xcov, d[list(controls)]] + dummies, axis=1).to_numpy(float)
    base = pd.concat([const, d[list(controls)]] + dummies, axis=1).to_numpy(float)
    rank = np.linalg.matrix_rank(X)
    if rank - np.linalg.matrix_rank(base) < xcov.shape[1] or len(d) - rank < MIN_TEST_DF:
        return None
    level = max((variation_level(d, c, specimen, sample) for c in tested),
                key=("specimen", "piece", "within").index)
    n = len(d)
    n_spec = d[specimen].nunique()
    piece = d[specimen].astype(str) + "/" + (d[sample].astype(str) if sample is not None else pd.Series(
        np.arange(n).astype(str), index=d.index))
    n_piece = piece.nunique()
    repeated = n_piece < n
    q = xcov.shape[1]
    p_at = {"specimen": 1, "piece": 0, "within": 0}
    for f in factors:
        p_at[variation_level(d, f, specimen, sample)] += int(d[f].nunique()) - 1
    for c in controls:
        p_at[variation_level(d, c, specimen, sample)] += 1
    p_at[level] += q
    units = {"specimen": n_spec, "piece": n_piece - n_spec, "within": n - n_piece}
    if not repeated:  # one row per piece: the piece is the residual level
        units["piece"] = n - n_spec
        p_at["piece"] += p_at.pop("within")
        level = "piece" if level == "within" else level
    df = float(units[level] - p_at[level])
    if df < MIN_TEST_DF:
        return None   # too few units where the covariate varies: a property of the design, not of the fit
    joint = categorical or q > 1
    method = None
    if n_spec >= 2:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                me = mixed_effects(d, value, specimen=specimen, sample=sample,
                                   covariates=tuple(controls) + (() if categorical else tuple(tested)),
                                   factors=tuple(factors) + ((tested[0],) if categorical else ()))
            extra = dict(level=level, n=float(n), n_specimens=float(n_spec), n_pieces=float(n_piece))
            if joint:
                if categorical:
                    w = me["factor_wald"][tested[0]]
                    chi2, k = w["chi2"], w["df"]
                else:
                    names = me["fe_names"]
                    idx = [names.index(c) for c in tested]
                    fe = np.asarray([me["coefficients"][c]["estimate"] for c in tested])
                    cov = np.asarray(me["fe_cov"])[np.ix_(idx, idx)]
                    chi2, k = float(fe @ np.linalg.solve(cov, fe)), len(tested)
                f_stat = chi2 / max(k, 1)
                if np.isfinite(f_stat):
                    return statistic_result(f_stat, log10_p_from_f(f_stat, float(k), df), df1=float(k), df2=df,
                                            method=me["method"] + "; Wald F, between-within df", **extra)
            else:
                c = me["coefficients"][tested[0]]
                if np.isfinite(c["std_error"]) and c["std_error"] > 0:
                    t = c["estimate"] / c["std_error"]
                    return statistic_result(t, log10_p_from_t(t, df), estimate=c["estimate"], std_error=c["std_error"],
                                            df=df, method=me["method"] + "; t, between-within df", **extra)
            method = "MixedLM gave no finite standard error"
        except (ValueError, np.linalg.LinAlgError, KeyError, IndexError) as exc:
            method = f"MixedLM failed ({type(exc).__name__})"
    else:
        method = "fewer than 2 specimens: no specimen random effect"
    groups = d[specimen].to_numpy() if n_spec >= 2 else (piece.to_numpy() if n_piece >= 2 else None)
    Xf = pd.concat([xcov, d[list(controls)]] + dummies, axis=1).astype(float)
    res = cluster_regression(d[value].to_numpy(float), Xf, groups=groups)
    how = ("OLS with standard errors clustered by " + ("specimen" if n_spec >= 2 else "sample")
           if groups is not None else "OLS with HC3 standard errors (one sample)")
    extra = dict(level=level, n=float(n), n_specimens=float(n_spec), n_pieces=float(n_piece),
                 method=f"{how} ({method})")
    df_fb = float(_n_clusters(res) - 1) if getattr(res, "cov_type", "") == "cluster" else float(res.df_resid)
    # never more degrees of freedom than the units the covariate varies over (clusters that do not see it add none)
    df_fb = min(df_fb, df)
    if df_fb < MIN_TEST_DF:
        return None
    if joint:
        names = list(xcov.columns)
        R = np.eye(len(res.params))[[list(res.params.index).index(c) for c in names]]
        b = R @ np.asarray(res.params, float)
        V = R @ np.asarray(res.cov_params(), float) @ R.T
        try:
            f_stat = float(b @ np.linalg.solve(V, b)) / len(names)
        except np.linalg.LinAlgError:
            return None
        return statistic_result(f_stat, log10_p_from_f(f_stat, float(len(names)), df_fb), df1=float(len(names)),
                                df2=df_fb, **extra)
    out = coefficient_test(res, tested[0])
    out = statistic_result(out["statistic"], log10_p_from_t(out["statistic"], df_fb), estimate=out["estimate"],
                           std_error=out["std_error"], df=df_fb)
    out.update(extra)
    return out
