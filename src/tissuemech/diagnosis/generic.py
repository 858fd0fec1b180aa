"""Generic detection of residual structure that no catalogued cause names.

Every numeric covariate of the residual table (strain, log rate and their products, time within a test,
elapsed time, test order, first load, frequency^2, 1/gap, the predicted level, every logged channel and
every ``covariate_*`` column of ``samples.csv``) is tested, per block of comparable rows (test kind x
quantity), with a regression of the log-residual ln(observed/predicted) on the covariate:

* a covariate that varies *within* curves is tested within curves (both sides demeaned per curve, so the
  level differences between samples do not enter) with standard errors clustered by curve;
* a covariate that is constant within each curve (elapsed time, order, first load, sample-sheet columns,
  channel means) is tested across curve levels with sample (else specimen) and condition fixed effects
  (population variability and a misfit that differs by condition are not structure in the covariate;
  :func:`tissuemech.diagnosis.catalogue.level_regression`), clustered by sample; a covariate collinear
  with them (e.g. a fixed test order) is not testable and skipped.

Specimen-to-specimen variability is expected and not scanned (an unusual specimen is the catalogue's
``outlier_specimen``).

``effect_size`` is the change of the log-residual over the covariate's 5-95 % range (about a relative
change; 0.05 = 5 %). A structure is *practically* relevant when |effect_size| >= :data:`MIN_EFFECT`.
The false-alarm rate is controlled by the caller (Holm across every catalogue and generic test,
:mod:`.report`).
"""
from __future__ import annotations

import numpy as np
import pandas as pd
import statsmodels.api as sm

from . import stats as st
from .catalogue import between_sample_test, level_regression

#: smallest structured misfit (log-residual change over the covariate range) worth reporting
MIN_EFFECT = 0.03

#: residual-table columns scanned as covariates (plus every ``channel_*`` and ``covariate_*`` column)
COVARIATES = ("strain", "log_rate", "strain_x_log_rate", "strain_sq_x_log_rate", "log_time", "elapsed_time",
              "test_order", "first_load", "frequency_sq", "inverse_gap", "predicted_abs")

#: smallest number of curves in a block for a test
MIN_CURVES = 3


#: logged channels that are functions of the measured response itself (a stiffer sample has a smaller
#: raw phase and deflection); their correlation with the residual is tautological, so they are not scanned
RESPONSE_CHANNELS = ("channel_raw_phase", "channel_deflection_angle")


def covariate_columns(table: pd.DataFrame) -> list[str]:
    """Covariates present in ``table`` (fixed list, then logged channels and sample-sheet covariates)."""
    cols = [c for c in COVARIATES if c in table]
    cols += sorted(c for c in table.columns if (c.startswith("channel_") and c not in RESPONSE_CHANNELS)
                   or c.startswith("covariate_"))
    return cols


def _demean(values: np.ndarray, codes: np.ndarray) -> np.ndarray:
    n = np.bincount(codes)
    return values - (np.bincount(codes, values) / np.maximum(n, 1))[codes]


def _range(x: np.ndarray) -> float:
    lo, hi = np.nanquantile(x, [0.05, 0.95])
    return float(hi - lo)


def test_covariate(block: pd.DataFrame, cov: str) -> dict | None:
    """Regression test of the block's log-residual on one covariate (module docstring); None if untestable."""
    b = block[np.isfinite(block[cov].to_numpy(float)) & np.isfinite(block["log_ratio"].to_numpy(float))]
    if b["curve"].nunique() < MIN_CURVES or b[cov].nunique() < 3:
        return None
    codes = pd.factorize(b["curve"])[0]
    x = b[cov].to_numpy(float)
    spread = np.zeros(codes.max() + 1)
    np.maximum.at(spread, codes, x)
    low = np.full(codes.max() + 1, np.inf)
    np.minimum.at(low, codes, x)
    total = x.max() - x.min()
    if total > 0 and np.median(spread - low) > 0.05 * total:
        y = _demean(b["log_ratio"].to_numpy(float), codes)
        xd = _demean(x, codes)
        res = st.cluster_regression(y, pd.DataFrame({cov: xd}), groups=codes)
        span = _range(x)
        level = "within curves"
    else:
        lv = b.groupby("curve").agg(y=("log_ratio", "median"), x=(cov, "mean"), specimen=("specimen", "first"),
                                    sample=("sample", "first"), condition=("condition", "first"),
                                    test=("test", "first")).rename(columns={"x": cov})
        if lv[cov].nunique() < 3 or len(lv) < 5:
            return None
        # within samples (sample + condition fixed effects) and between samples (two-stage on sample
        # means): population variability and condition-specific misfit are not structure in the covariate
        found = []
        res = level_regression(lv, "y", [cov], sets=[("sample", "condition")])
        if res is not None:
            found.append(st.coefficient_test(res, cov))
        between = between_sample_test(lv, "y", cov)
        if between is not None:
            found.append(between)
        if not found:
            return None
        t = min(found, key=lambda f: f["log10_p"])
        lp = min(0.0, t["log10_p"] + np.log10(len(found)))
        t = dict(t, log10_p=lp, p_value=10 ** lp)
        span = _range(lv[cov].to_numpy(float))
        return {"covariate": cov, "level": "across curves", "statistic": t["statistic"], "p_value": t["p_value"],
                "log10_p": t["log10_p"], "effect_size": float(t["estimate"] * span), "slope": t["estimate"],
                "n_curves": int(b["curve"].nunique()), "n_points": int(len(b))}
    t = st.coefficient_test(res, cov)
    return {"covariate": cov, "level": level, "statistic": t["statistic"], "p_value": t["p_value"],
            "log10_p": t["log10_p"], "effect_size": float(t["estimate"] * span), "slope": t["estimate"],
            "n_curves": int(b["curve"].nunique()), "n_points": int(len(b))}


def structure_tests(table: pd.DataFrame) -> list[dict]:
    """Every covariate test on every (test kind, quantity) block of the residual table.

    Returns a list of dicts with ``test``, ``quantity``, ``covariate``, ``level``, ``statistic``,
    ``p_value``, ``log10_p``, ``effect_size``, ``practical``, ``n_curves``, ``n_points``.
    """
    out = []
    rows = table[np.isfinite(table["log_ratio"])]
    rows = rows[rows["predicted_abs"] > 5.0 * rows["sigma"]]
    covs = covariate_columns(rows)
    for (test, quantity), block in rows.groupby(["test", "quantity"]):
        # specimen-to-specimen variability is expected (log-normal population); an unusual specimen is the
        # catalogue's outlier_specimen, so the specimen factor is not scanned here
        results = [test_covariate(block, c) for c in covs]
        for r in results:
            if r is None:
                continue
            r.update(test=str(test), quantity=str(quantity), practical=bool(abs(r["effect_size"]) >= MIN_EFFECT))
            out.append(r)
    return out


def serial_structure(table: pd.DataFrame) -> dict:
    """Descriptive serial structure of the residuals per test kind: median Durbin-Watson d, share of
    curves with d < 1.5 and median runs-test z (residuals in the order measured)."""
    out = {}
    for test, block in table.groupby("test"):
        dws, zs = [], []
        for _, g in block.groupby(["curve", "quantity"]):
            e = g.sort_values("point")["residual"].to_numpy()
            if e.size >= 8 and np.any(e != 0):
                dws.append(st.durbin_watson(e))
                zs.append(st.runs_test(e)["statistic"])
        if dws:
            zs = np.asarray(zs, float)
            out[str(test)] = {"n_curves": len(dws), "median_durbin_watson": float(np.median(dws)),
                              "share_dw_below_1_5": float(np.mean(np.asarray(dws) < 1.5)),
                              "median_runs_z": float(np.median(zs[np.isfinite(zs)])) if np.isfinite(zs).any() else np.nan}
    return out
