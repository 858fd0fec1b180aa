"""Catalogue of named causes of model-data discrepancy (``science.md`` sections 2, 3 and 4.4).

Every cause has one detector ``detect_<id>(ctx) -> dict`` that returns a *finding*:

``effect``            the catalogue id (:data:`CATALOGUE_IDS`)
``tested``            False when the data cannot test it (e.g. no frequency sweep); then p_value is NaN
``statistic``         the test statistic (t, F, ... named in ``statistic_name``)
``p_value``/``log10_p`` the uncorrected p-value (Holm across all tests is applied in :mod:`.report`)
``effect_size``       physical size of the effect in ``effect_size_unit``
``practical``         True when the effect size exceeds the practical threshold of the cause (a finding
                      needs statistical *and* practical significance; dense curves make tiny misfits
                      significant)
``evidence``          a sentence naming tests, conditions and covariates
``fix``               ``{model, metric, before, after, gain, cv, parameters}`` -- the correction or
                      extension that removes the cause, scored on held-out data; ``gain`` is the relative
                      reduction ``(before - after) / before``

The signature matrix of ``science.md`` 4.4 is built into the detectors: the within-ramp residual
regressions of non-separability (strain^2 x log-rate) and wall slip (stress threshold / gap) share one design
with the rim-error (strain^2, strain^3) and offset (1/stress) signatures as controls and each other's
covariate as a control; drift is read from curve levels within samples (sample + condition fixed effects)
and between samples (two-stage on sample means, :func:`between_sample_test`), never from a fixed test order
alone; preconditioning by the model-free paired comparison of whatever test came first on each sample with
later repeats of a comparable measurement (:func:`paired_first_load_test`) and by the first-load indicator
within samples. Curve-level detectors assume no test order, specimen or sample count: the order of the tests
on a sample comes from ``order``, else ``started_at``, else ``total_time`` (:func:`curve_levels`); drift and
first load are each controlled for the other, and where the design cannot separate a covariate from the
test sequence, the first load, the logged temperature or the condition (a fixed order) the finding lists
them in ``confounded_with`` with the design that would separate them in ``separating_design``. A cause is
named (in :mod:`.report`) only when it passes Holm, is practically relevant and its fix does not lose on
held-out data.

Homogeneous multi-mode data (simple shear + uniaxial compression/tension) are diagnosed by
:mod:`.homogeneous`, which adds the cross-mode id ``tension_compression_asymmetry`` and tests
``unidentified_i2_dependence`` from the mode combination instead of the normal force.

Inputs (:class:`DiagnosisContext`): the canonical runs, the residual table of the baseline model
(:func:`tissuemech.diagnosis.evidence.residual_table`) and ``fit_info`` -- how the baseline was fitted:
``target`` (the plate targets of :mod:`tissuemech.fitting`: ``"thesis"``: reported 2M/(pi R^3) taken as rim
stress; ``"apparent_stress"``/``"torque"``: plate forward model; ``"corrected_stress"``: Rabinowitsch), ``relaxation`` (``"step"`` or ``"ramp"``) and
optionally ``correlations`` ({"p1|p2": rho}) of the fitted parameters.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
import statsmodels.api as sm
import xarray as xr
from scipy.optimize import least_squares

from .. import stats as st
from ..spectra import decade_aligned_taus, prony_complex_modulus
from ..tts import run_temperature_c
from .evidence import (booij_thoone, condition_label, estimate_noise, fit_prony_relaxation, noise_sd,
                       nominal_strain, run_id)

CATALOGUE_IDS: tuple[str, ...] = (
    "nonseparable_relaxation", "rim_stress_nonlinearity", "wall_slip", "elapsed_time_drift",
    "preconditioning", "instrument_inertia", "torque_offset", "outlier_specimen", "amplitude_softening",
    "finite_rise_time", "unidentified_i2_dependence",
)

#: test kinds whose residuals each cause distorts: a generic structure in these tests is explained once the
#: cause is named (within a curve, strain, time and predicted level are collinear, so a cause that bends a
#: curve shows up on all of them). "*": the cause scales whole curves and bends none.
DISTORTS: dict[str, tuple[str, ...]] = {
    "nonseparable_relaxation": ("constant_shear_rate", "stress_relaxation", "creep_recovery", "frequency_sweep",
                                "amplitude_sweep"),
    "rim_stress_nonlinearity": ("constant_shear_rate", "stress_relaxation", "creep_recovery"),
    "wall_slip": ("constant_shear_rate", "creep_recovery"),
    "elapsed_time_drift": ("*",),
    "preconditioning": ("*",),
    "instrument_inertia": ("frequency_sweep",),
    "torque_offset": ("constant_shear_rate", "stress_relaxation", "creep_recovery"),
    "outlier_specimen": ("*",),
    "amplitude_softening": ("amplitude_sweep",),
    "finite_rise_time": ("stress_relaxation", "frequency_sweep"),
    "unidentified_i2_dependence": (),
    # a temperature shift moves a curve along log time/frequency: it bends every rate-dependent curve
    "temperature_dependence": ("constant_shear_rate", "stress_relaxation", "creep_recovery", "frequency_sweep",
                               "amplitude_sweep"),
    "inertia_dominated_points": ("frequency_sweep", "amplitude_sweep"),
    "inertial_ringing": ("stress_relaxation",),
}

#: covariates whose structure each cause explains in any test (curve-level signatures)
EXPLAINS: dict[str, tuple[str, ...]] = {
    "nonseparable_relaxation": ("strain_x_log_rate", "strain_sq_x_log_rate", "log_rate"),
    "rim_stress_nonlinearity": ("strain",),
    "wall_slip": ("inverse_gap", "channel_gap"),
    "elapsed_time_drift": ("elapsed_time", "test_order"),
    "preconditioning": ("first_load", "test_order", "elapsed_time"),
    "instrument_inertia": ("frequency_sq", "channel_raw_phase"),
    "torque_offset": ("predicted_abs",),
    "outlier_specimen": (),
    "amplitude_softening": (),
    "finite_rise_time": ("log_time",),
    "unidentified_i2_dependence": ("channel_normal_force",),
    "temperature_dependence": ("channel_temperature", "covariate_temperature_c", "temperature_c"),
    "inertia_dominated_points": ("frequency_sq", "channel_raw_phase"),
    "inertial_ringing": (),
}


def explains(effect: str, test: str, covariate: str, level: str,
             confounded: Sequence[Sequence[str]] = ()) -> bool:
    """Whether a named ``effect`` accounts for generic structure in ``covariate`` of ``test`` residuals.

    Curve-level (``across curves``) structure is explained only through the covariates of the cause's own
    signature (:data:`EXPLAINS`) -- a detected drift, preconditioning or outlier does *not* explain every
    across-curve covariate (a significant temperature channel stays unexplained unless a temperature cause
    is named) -- or through a covariate that is confounded with one of them in this design
    (``confounded``: sets of covariate names that the design cannot separate,
    :func:`tissuemech.diagnosis.generic.confounded_covariates`). Within-curve structure is explained by the
    causes that distort the shape of that test's curves.
    """
    own = EXPLAINS.get(effect, ())
    if covariate in own:
        return True
    if level == "within curves":
        return test in DISTORTS.get(effect, ())  # whole-curve causes ("*": drift, first load, outlier) bend no curve
    return any(covariate in group and any(c in own for c in group) for group in confounded)


TIME_DOMAIN = ("stress_relaxation", "constant_shear_rate", "simple_shear", "creep_recovery")


@dataclass
class DiagnosisContext:
    """Everything a detector may look at.

    Attributes
    ----------
    runs : canonical runs (one per test on one sample)
    table : residual table of the baseline model on ``runs``
    model : baseline model key
    fit_info : how the baseline was fitted (see module docstring)
    """

    runs: Sequence[xr.Dataset]
    table: pd.DataFrame
    model: str = "model"
    fit_info: dict = field(default_factory=dict)

    def runs_of(self, test: str) -> list[xr.Dataset]:
        return [r for r in self.runs if r.attrs.get("test") == test]


# ------------------------------------------------------------------------------------------------
# helpers
# ------------------------------------------------------------------------------------------------
def untested_finding(effect: str, why: str) -> dict:
    return {"effect": effect, "tested": False, "statistic": np.nan, "statistic_name": "", "p_value": np.nan,
            "log10_p": np.nan, "effect_size": np.nan, "effect_size_unit": "", "practical": False,
            "evidence": why, "fix": None}


def make_finding(effect: str, test: dict, statistic_name: str, effect_size: float, unit: str, practical: bool,
             evidence: str, fix: dict | None, **extra) -> dict:
    out = {"effect": effect, "tested": True, "statistic": test["statistic"], "statistic_name": statistic_name,
           "p_value": test["p_value"], "log10_p": test["log10_p"], "effect_size": float(effect_size),
           "effect_size_unit": unit, "practical": bool(practical), "evidence": evidence, "fix": fix}
    out.update(extra)
    return out


def fix_record(model: str, metric: str, before: float, after: float, cv: str, **parameters) -> dict:
    gain = (before - after) / before if before > 0 and np.isfinite(after) else np.nan
    return {"model": model, "metric": metric, "before": float(before), "after": float(after),
            "gain": float(gain), "cv": cv,
            "parameters": {k: (float(v) if isinstance(v, (int, float, np.floating)) else v)
                           for k, v in parameters.items()}}


def _rms(x) -> float:
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x ** 2))) if x.size else np.nan


def primary_rows(table: pd.DataFrame) -> pd.DataFrame:
    """Rows of the quantity that carries each curve's level: stress for time-domain tests, G' for sweeps."""
    q = np.where(table["test"].isin(("amplitude_sweep", "frequency_sweep")), "storage_modulus", "shear_stress")
    rows = table[(table["quantity"] == q) & np.isfinite(table["log_ratio"])]
    # the first points of a ramp carry no level information and amplify noise in the log ratio
    return rows[rows["above_noise"]] if "above_noise" in rows else rows


def curve_levels(table: pd.DataFrame) -> pd.DataFrame:
    """One row per curve: precision-weighted mean log(observed/predicted) (``log_scale``) and its
    curve-level covariates (elapsed time at the start in hours, order, first load, specimen ...).

    The position of a curve in the sequence run on its sample (``position``, 1 = first load) is read from
    the recorded ``order`` when every curve of the sample has a distinct one, else from the elapsed time
    (``started_at``/``total_time``) when every curve of the sample has a distinct one, else it is unknown
    (NaN; ``order_source`` = ``"unknown"``). ``first_load`` is 1/0 where the position is known and NaN
    otherwise (the residual table's flag, which treats a missing order as 0, is not used).
    ``temperature_c`` is the curve's median logged temperature channel (NaN without one)."""
    rows = primary_rows(table)
    # the level of a curve is read where the model is least exposed to the nonlinear and instrumental
    # effects of the catalogue: the lower half of frequencies (inertia grows as omega^2), of amplitudes
    # (softening above the LVE limit) and of ramp strains (rim error, slip, non-separability at large strain)
    x = np.where(rows["test"] == "frequency_sweep", rows["frequency_sq"],
                 np.where(rows["test"] == "stress_relaxation", 0.0, rows["strain"]))
    rows = rows.assign(_x=x)
    rows = rows[rows["_x"] <= rows.groupby("curve")["_x"].transform("median")]
    g = rows.groupby("curve", sort=False)
    out = pd.DataFrame({
        "log_scale": g["log_ratio"].median(),
        "n_points": g.size(),
        "specimen": g["specimen"].first(), "sample": g["sample"].first(), "test": g["test"].first(),
        "condition": g["condition"].first(), "first_load": g["first_load"].first(),
        "test_order": g["test_order"].first(),
        "elapsed_h": g["elapsed_time"].min() / 3600.0,
        "temperature_c": (g["channel_temperature"].median() if "channel_temperature" in rows
                          else pd.Series(np.nan, index=g.size().index)),
    }).reset_index()
    position = pd.Series(np.nan, index=out.index)
    source = pd.Series("unknown", index=out.index, dtype=object)
    for _, idx in out.groupby("sample").groups.items():
        for col, name in (("test_order", "order"), ("elapsed_h", "elapsed time")):
            v = out.loc[idx, col]
            if v.notna().all() and v.nunique() == len(v):
                position[idx] = v.rank(method="first").to_numpy()
                source[idx] = name
                break
    out["position"] = position
    out["order_source"] = source
    out["first_load"] = np.where(position.notna(), (position == 1).astype(float), np.nan)
    return out


def _design(frame: pd.DataFrame, columns: Sequence[str], fixed_effects: Sequence[str]) -> pd.DataFrame:
    X = frame[list(columns)].astype(float).copy()
    for fe in fixed_effects:
        if frame[fe].nunique() > 1:
            X = X.join(pd.get_dummies(frame[fe], prefix=fe, drop_first=True, dtype=float))
    return X


def _demean_by(frame: pd.DataFrame, value: str, by: str) -> np.ndarray:
    return (frame[value] - frame.groupby(by)[value].transform("mean")).to_numpy(float)


def _group_cv(frame: pd.DataFrame, group: str, fit: Callable[[pd.DataFrame], object],
              error: Callable[[pd.DataFrame, object | None], np.ndarray]) -> tuple[float, float]:
    """Leave-one-group-out: returns (RMS error without correction, RMS error with the correction fitted
    on the other groups), pooled over the held-out points."""
    before, after = [], []
    for g in pd.unique(frame[group]):
        test = frame[frame[group] == g]
        train = frame[frame[group] != g]
        if train.empty:
            continue
        try:
            par = fit(train)
        except (np.linalg.LinAlgError, ValueError):
            continue
        before.append(error(test, None))
        after.append(error(test, par))
    if not before:
        return np.nan, np.nan
    return _rms(np.concatenate(before)), _rms(np.concatenate(after))


def _cv_group_column(frame: pd.DataFrame) -> str:
    for col in ("specimen", "sample", "condition", "curve"):
        if col in frame and frame[col].nunique() >= 3:
            return col
    return "curve"


# ------------------------------------------------------------------------------------------------
# curve-level scale: elapsed-time drift, preconditioning, outlier specimen
# ------------------------------------------------------------------------------------------------
#: fixed-effect sets tried in order for curve-level regressions: the sample absorbs sample-to-sample
#: stiffness variability (so drift and first load are read within samples), the condition a misfit that
#: differs by condition; a set is used when the design stays full rank with >= 3 residual dof
FIXED_EFFECT_SETS = (("sample", "condition"), ("sample", "test"), ("sample",), ("specimen", "condition"),
                     ("specimen", "test"), ("specimen",), ("condition",), ())


def level_regression(levels: pd.DataFrame, y: str, columns: Sequence[str], require_condition: bool = False,
                     sets: Sequence[tuple[str, ...]] | None = None):
    """Curve-level OLS ``y ~ columns + fixed effects`` (first usable set of :data:`FIXED_EFFECT_SETS`),
    standard errors clustered by sample (t with G - 1 df, :func:`tissuemech.stats.cluster_regression`). Returns the result (with
    ``fixed_effects`` set) or None when no set leaves the columns estimable.

    ``require_condition``: only sets with condition fixed effects are tried when the condition varies
    (a covariate collinear with the condition is then reported as untestable rather than confounded)."""
    sets = FIXED_EFFECT_SETS if sets is None else sets
    if require_condition and levels["condition"].nunique() > 1:
        sets = [fes for fes in sets if "condition" in fes]
    for fes in sets:
        # a covariate that is (nearly) constant within the fixed-effect groups is identified by noise only
        # (e.g. a logged gap channel with its sensor noise inside one sample): not estimable there
        if any(fe in levels and levels[c].std() > 0 and
               (levels[c] - levels.groupby(fe)[c].transform("mean")).std() < 0.05 * levels[c].std()
               for fe in fes if fe in ("sample", "specimen") for c in columns):
            continue
        X = _design(levels, columns, [fe for fe in fes if fe in levels])
        X = X.loc[:, (X.std() > 0) | X.columns.isin(columns)]
        if any(X[c].std() == 0 for c in columns) or len(levels) - X.shape[1] - 1 < 3:
            continue
        Xc = sm.add_constant(X, has_constant="add").to_numpy(float)
        if np.linalg.matrix_rank(Xc) == Xc.shape[1]:
            groups = levels["sample"].to_numpy() if "sample" in levels else None
            res = st.cluster_regression(levels[y].to_numpy(float), X, groups=groups)
            res.fixed_effects = list(fes)
            return res
    return None


def between_sample_test(levels: pd.DataFrame, y: str, column: str) -> dict | None:
    """Two-stage test of a covariate that varies between samples: condition effects are removed from the
    curve levels (condition fixed effects), the residual levels and the covariate are averaged per sample,
    and the sample means are regressed on the covariate with specimen fixed effects (plain OLS, df = samples
    - parameters). Curves of one sample share its stiffness, so the sample -- not the curve -- is the unit
    of replication for such covariates (curve-level cluster-robust errors are anti-conservative here)."""
    lv = levels[np.isfinite(levels[y]) & np.isfinite(levels[column])]
    if lv["sample"].nunique() < 5:
        return None
    r = lv[y] - lv.groupby("condition")[y].transform("mean")
    xr_ = lv[column] - lv.groupby("condition")[column].transform("mean")
    agg = pd.DataFrame({"r": r, "x": xr_, "sample": lv["sample"], "specimen": lv["specimen"]}).groupby("sample").agg(
        r=("r", "mean"), x=("x", "mean"), specimen=("specimen", "first"))
    if agg["x"].std() == 0:
        return None
    for fes in (["specimen"], []):
        X = _design(agg.rename(columns={"x": column}), [column], fes)
        Xc = sm.add_constant(X, has_constant="add").to_numpy(float)
        if len(agg) - Xc.shape[1] >= 3 and np.linalg.matrix_rank(Xc) == Xc.shape[1] and X[column].std() > 0:
            res = sm.OLS(agg["r"].to_numpy(float), Xc).fit()
            k = list(X.columns).index(column) + 1
            est, se = float(res.params[k]), float(res.bse[k])
            tval = est / se if se > 0 else 0.0
            out = st._pack(tval, st.log10_p_from_t(tval, res.df_resid), estimate=est, std_error=se,
                           df=float(res.df_resid))
            out["design"] = "sample means, " + ("specimen fixed effects" if fes else "no fixed effects")
            return out
    return None


#: within-sample |correlation| above which two curve-level covariates are reported as confounded
CONFOUND_CORRELATION = 0.9

#: the design that would separate a curve-level covariate from each confounder (``condition``: the test
#: condition when the covariate is collinear with it within samples, i.e. a fixed test order)
SEPARATING_DESIGN = {
    "position": "vary the pauses between tests, or start the samples of one session at different times, so "
                "that elapsed time varies at a fixed position in the sequence (a drift of the instrument or "
                "specimen follows the clock, an effect of the loading history follows the position)",
    "first_load": "repeat the first test of each sample later in its sequence, or vary which test comes first",
    "temperature_c": "hold the temperature constant over the session, or change it in steps that are not "
                     "monotone in time (e.g. a randomised or up-and-down temperature sequence)",
    "elapsed_h": "record started_at or total_time and run at least three tests per sample, so that a time "
                 "trend can be read from the tests after the first load",
    "condition": "randomise the test order across samples, or repeat a reference test (same kind and "
                 "condition as an early one) at the end of each sample's sequence",
}


def _within_corr(levels: pd.DataFrame, a: str, b: str) -> float:
    """Correlation of two curve-level covariates after removing sample means (NaN when undefined)."""
    lv = levels[levels[a].notna() & levels[b].notna()]
    if len(lv) < 3:
        return np.nan
    x, y = _demean_by(lv, a, "sample"), _demean_by(lv, b, "sample")
    if x.std() == 0 or y.std() == 0:
        return np.nan
    return float(np.corrcoef(x, y)[0, 1])


def _condition_share(levels: pd.DataFrame, column: str) -> float:
    """Share of the within-sample variance of ``column`` explained by the test condition (1 for a fixed
    test order with equal pauses; a squared multiple correlation)."""
    lv = levels[levels[column].notna()]
    x = _demean_by(lv, column, "sample")
    if len(lv) < 3 or x.std() == 0 or lv["condition"].nunique() < 2:
        return 0.0
    X = pd.get_dummies(lv[["sample", "condition"]].astype(str), drop_first=True, dtype=float).to_numpy(float)
    X = np.column_stack([np.ones(len(lv)), X])
    y = lv[column].to_numpy(float)
    resid = y - X @ np.linalg.lstsq(X, y, rcond=None)[0]
    return float(1.0 - np.sum(resid ** 2) / np.sum(x ** 2))


def _usable(levels: pd.DataFrame, column: str) -> bool:
    v = levels[column] if column in levels else pd.Series(dtype=float)
    if column == "first_load":
        return bool(v.notna().all() and 0 < v.sum() < len(v))
    return bool(len(v) and v.notna().all() and v.nunique() > 2)


def _level_tests(levels: pd.DataFrame, column: str):
    """Curve-level tests of ``column`` (elapsed time or first load), each controlled for the other and for
    the logged temperature where the design allows (the largest estimable set of controls): within samples with sample and condition fixed effects (clustered by sample) and,
    for covariates that vary between samples, the two-stage :func:`between_sample_test`; the stronger with
    a Bonferroni factor. Returns ``(test, design)`` or ``(None, None)``; ``test`` carries ``controls`` (the
    covariates held fixed) and ``confounded_with`` (covariates whose within-sample correlation with
    ``column`` reaches :data:`CONFOUND_CORRELATION`, or ``condition`` when the condition explains that
    share squared of its within-sample variance, with the design that would separate them in
    ``separating_design``). Elapsed time is read within samples only with the first-load control when the
    first loads are known and not absorbed by the condition effects (a within-sample trend needs two curves
    after the first load; otherwise the slope is the first-load contrast). Elapsed time falls back to the position in the sequence when no time was
    recorded. Designs in which the covariate is collinear with the condition within samples (a fixed
    test order) are not used within samples: a misfit that differs by condition would pass for the effect."""
    time_recorded = _usable(levels, "elapsed_h")
    if column == "elapsed_h" and not time_recorded:
        if not _usable(levels, "position"):
            return None, None
        levels = levels.assign(elapsed_h=levels["position"].astype(float))
    if column == "first_load":
        levels = levels[levels["first_load"].notna()]
        if not _usable(levels, "first_load"):
            return None, None
    other = "first_load" if column == "elapsed_h" else "elapsed_h"
    controls = [c for c in (other, "temperature_c") if c in levels and _usable(levels, c)]
    if "first_load" in controls and levels.groupby("condition")["first_load"].nunique().max() == 1:
        controls.remove("first_load")  # each condition always or never first: the condition effects absorb it
    found = []
    combos = [[column] + controls] + ([[column, controls[0]]] if len(controls) > 1 else []) + [[column]]
    if column == "elapsed_h" and "first_load" in controls:
        # a trend within a sample needs two curves after its first load: without them the within-sample
        # slope is the first-load contrast itself (preconditioning), so it is only read with that control
        combos = [c for c in combos if "first_load" in c]
    for cols in combos:
        res = level_regression(levels, "log_scale", cols, sets=[("sample", "condition")])
        if res is not None:
            t = st.coefficient_test(res, column)
            found.append((dict(t, controls=cols[1:]),
                          "within samples (sample + condition fixed effects"
                          + (f", controlled for {', '.join(cols[1:])})" if cols[1:] else ")")))
            break
    if column != "first_load":
        b = between_sample_test(levels, "log_scale", column)
        if b is not None:
            found.append((dict(b, controls=[]), f"between samples ({b['design']})"))
    if not found:
        return None, None
    t, design = min(found, key=lambda f: f[0]["log10_p"])
    lp = min(0.0, t["log10_p"] + np.log10(len(found)))
    confounded = []
    # the first load is position 1: only time and temperature can be confounded with it
    candidates = ("elapsed_h", "temperature_c") if column == "first_load" else (
        ("position", "first_load", "temperature_c") if time_recorded else ("first_load", "temperature_c"))
    for c in candidates:  # a control nearly collinear with the covariate still cannot be separated from it
        if c in levels and abs(_within_corr(levels, column, c)) >= CONFOUND_CORRELATION:
            confounded.append(c)
    if _condition_share(levels, column) >= CONFOUND_CORRELATION ** 2:
        confounded.append("condition")
    return dict(t, log10_p=lp, p_value=10 ** lp, confounded_with=confounded,
                separating_design=[SEPARATING_DESIGN[c] for c in confounded]), design


def _run_sequences(runs: Sequence[xr.Dataset]) -> list[list[xr.Dataset]]:
    """Runs of each sample in the order they were measured, from the ``order`` attribute when every run of
    the sample has a distinct one, else ``started_at``, else the first ``total_time``; samples whose order
    none of these gives are left out (their first load is unknown)."""
    by_sample: dict[tuple, list[xr.Dataset]] = {}
    for r in runs:
        by_sample.setdefault((str(r.attrs.get("specimen")), str(r.attrs.get("sample"))), []).append(r)

    def order_key(r):
        return float(r.attrs["order"]) if "order" in r.attrs else np.nan

    def start_key(r):
        try:
            return pd.Timestamp(str(r.attrs["started_at"])).value / 1e9
        except (KeyError, ValueError):
            return np.nan

    def total_key(r):
        return float(np.nanmin(r["total_time"].values)) if "total_time" in r and np.isfinite(
            r["total_time"].values).any() else np.nan

    out = []
    for rs in by_sample.values():
        for key in (order_key, start_key, total_key):
            k = [key(r) for r in rs]
            if np.all(np.isfinite(k)) and len(set(k)) == len(k):
                out.append([rs[i] for i in np.argsort(k)])
                break
    return out


def _primary_curve(run: xr.Dataset) -> tuple[np.ndarray, np.ndarray, float] | None:
    """(x, level, sign) of the quantity that carries a run's stiffness: G' over amplitude or frequency,
    stress over time (relaxation) or strain (ramps), creep strain over time (sign -1: compliance)."""
    test = run.attrs.get("test")
    pairs = {"amplitude_sweep": ("shear_strain", "storage_modulus", 1.0),
             "frequency_sweep": ("frequency", "storage_modulus", 1.0),
             "stress_relaxation": ("time", "shear_stress", 1.0),
             "constant_shear_rate": ("shear_strain", "shear_stress", 1.0),
             "simple_shear": ("shear_strain", "shear_stress", 1.0),
             "creep_recovery": ("time", "shear_strain", -1.0)}
    if test not in pairs:
        return None
    xn, yn, sign = pairs[test]
    if xn == "frequency" and xn not in run and "angular_frequency" in run:
        x = run["angular_frequency"].values / (2 * np.pi)
    elif xn in run:
        x = run[xn].values
    else:
        return None
    if yn not in run:
        return None
    x, y = np.abs(np.asarray(x, float)), np.asarray(run[yn].values, float)
    ok = np.isfinite(x) & np.isfinite(y) & (x > 0) & (y > 0)
    if test == "stress_relaxation" and "shear_strain" in run:
        g = np.abs(run["shear_strain"].values)
        ok &= g >= 0.99 * np.nanmax(g)  # the hold: the ramp depends on the rise time, not the stiffness
    return (x[ok], y[ok], sign) if ok.sum() >= 2 else None


def _log_contrast(first: xr.Dataset, later: xr.Dataset) -> float:
    """Model-free ln(first/later) of the stiffness-carrying quantity of two runs of the same kind and
    condition, as the median over the overlapping range of x (later run interpolated in log x)."""
    a, b = _primary_curve(first), _primary_curve(later)
    if a is None or b is None:
        return np.nan
    xa, ya, sign = a
    xb, yb, _ = b
    o = np.argsort(xb)
    xb, yb = xb[o], yb[o]
    inside = (xa >= xb[0]) & (xa <= xb[-1])
    if inside.sum() < 2:
        return np.nan
    yi = np.exp(np.interp(np.log(xa[inside]), np.log(xb), np.log(yb)))
    return float(sign * np.median(np.log(ya[inside] / yi)))


def _linear_storage(sweep: xr.Dataset, f_hz: float) -> float:
    """G' of a run at frequency ``f_hz`` (Pa): a frequency sweep interpolated in log f (NaN outside its
    range), or the lower half of an amplitude sweep's amplitudes at its own frequency."""
    if "storage_modulus" not in sweep:
        return np.nan
    gp = np.asarray(sweep["storage_modulus"].values, float)
    if sweep.attrs.get("test") == "amplitude_sweep":
        g0 = np.abs(sweep["shear_strain"].values) if "shear_strain" in sweep else None
        if g0 is None:
            return np.nan
        small = g0 <= np.nanmedian(g0)
        v = gp[small & (gp > 0)]
        return float(np.median(v)) if v.size else np.nan
    f = sweep["frequency"].values if "frequency" in sweep else (
        sweep["angular_frequency"].values / (2 * np.pi) if "angular_frequency" in sweep else None)
    if f is None:
        return np.nan
    ok = np.isfinite(f) & (f > 0) & (gp > 0)
    f, gp = f[ok], gp[ok]
    if f.size < 2 or not f.min() <= f_hz <= f.max():
        return np.nan
    o = np.argsort(f)
    return float(np.exp(np.interp(np.log(f_hz), np.log(f[o]), np.log(gp[o]))))


def _sweep_frequency(run: xr.Dataset) -> float:
    if "frequency_hz" in run.attrs:
        return float(run.attrs["frequency_hz"])
    if "frequency" in run:
        return float(np.nanmedian(run["frequency"].values))
    if "angular_frequency" in run:
        return float(np.nanmedian(run["angular_frequency"].values) / (2 * np.pi))
    return np.nan


def paired_first_load_test(ctx: DiagnosisContext) -> dict | None:
    """Model-free paired test of the first load, whatever test came first.

    For every sample whose measuring order is known (``order``, else ``started_at``, else ``total_time``;
    :func:`_run_sequences`), the first run is compared with the later runs of the same sample that repeat
    a comparable measurement: the same test kind and condition (ln ratio of the stiffness-carrying
    quantity over the common range, :func:`_log_contrast`), or -- between an amplitude sweep and a
    frequency sweep in either order -- the linear G' at the amplitude sweep's frequency (lower half of its
    amplitudes vs the frequency sweep interpolated in log f). One contrast per sample (mean over its
    comparable repeats); one-sample t-test over samples (>= 3). Returns None when fewer than 3 samples
    have a comparable repeat. ``n`` samples, ``kinds`` the first-test kinds compared."""
    logs, kinds = [], set()
    for seq in _run_sequences(ctx.runs):
        first, later = seq[0], seq[1:]
        ft = first.attrs.get("test")
        c = []
        for r in later:
            rt = r.attrs.get("test")
            if rt == ft and condition_label(r) == condition_label(first):
                c.append(_log_contrast(first, r))
            elif {ft, rt} == {"amplitude_sweep", "frequency_sweep"}:
                amp = first if ft == "amplitude_sweep" else r
                f_as = _sweep_frequency(amp)
                g_first, g_later = _linear_storage(first, f_as), _linear_storage(r, f_as)
                if g_first > 0 and g_later > 0:
                    c.append(float(np.log(g_first / g_later)))
        c = [v for v in c if np.isfinite(v)]
        if c:
            logs.append(float(np.mean(c)))
            kinds.add(str(ft))
    if len(logs) < 3:
        return None
    x = np.asarray(logs)
    sd = x.std(ddof=1)
    tval = x.mean() / (sd / np.sqrt(x.size)) if sd > 0 else (np.inf if x.mean() else 0.0)
    out = st._pack(tval, st.log10_p_from_t(tval, x.size - 1), estimate=float(x.mean()), n=x.size)
    out["kinds"] = sorted(kinds)
    return out


def _scale_correction_cv(ctx: DiagnosisContext, levels: pd.DataFrame, column: str) -> tuple[float, float, str]:
    """Held-out gain of a curve-level covariate (elapsed time, first load).

    With >= 3 curves per sample: leave one curve out and predict its level from the other curves of the
    same sample (baseline: their mean; fix: their mean adjusted by b * column, b fitted within samples
    without the held-out curve). Otherwise leave one sample out and use the specimen's other samples.
    Error: log(observed/predicted) at every point of the held-out curve."""
    if column == "elapsed_h" and levels["elapsed_h"].isna().any():
        levels = levels.assign(elapsed_h=levels["position"].astype(float))
    levels = levels[levels[column].notna()]
    if levels.empty:
        return np.nan, np.nan, "curve"
    rows = primary_rows(ctx.table)
    point_errors = {c: g.to_numpy(float) for c, g in rows.groupby("curve")["log_ratio"]}
    by_sample = levels.groupby("sample").size().min() >= 3
    unit, held = ("sample", "curve") if by_sample else ("specimen", "sample")
    unit_codes = pd.factorize(levels[unit])[0]
    held_codes = pd.factorize(levels[held])[0]
    x_all = levels[column].to_numpy(float)
    y_all = levels["log_scale"].to_numpy(float)
    curves = levels["curve"].to_numpy()
    before, after = [], []
    for g in np.unique(held_codes):
        train = held_codes != g
        # within-unit slope without the held-out group
        xm = np.bincount(unit_codes[train], x_all[train], minlength=unit_codes.max() + 1)
        ym = np.bincount(unit_codes[train], y_all[train], minlength=unit_codes.max() + 1)
        nm = np.bincount(unit_codes[train], minlength=unit_codes.max() + 1)
        with np.errstate(invalid="ignore", divide="ignore"):
            xm, ym = xm / nm, ym / nm
        dx = x_all[train] - xm[unit_codes[train]]
        dy = y_all[train] - ym[unit_codes[train]]
        slope = float(np.dot(dx, dy) / np.dot(dx, dx)) if np.dot(dx, dx) > 0 else 0.0
        test_idx = np.nonzero(~train)[0]
        u = unit_codes[test_idx[0]]
        if nm[u] == 0:
            continue
        base = ym[u]
        adj = ym[u] - slope * xm[u]
        for i in test_idx:
            e = point_errors.get(curves[i])
            if e is None:
                continue
            before.append(e - base)
            after.append(e - adj - slope * x_all[i])
    if not before:
        return np.nan, np.nan, held
    return _rms(np.concatenate(before)), _rms(np.concatenate(after)), held


#: elapsed time and run temperature explaining this share of each other's variance across curves cannot be
#: separated (R^2 >= 0.9: VIF >= 10; :data:`tissuemech.diagnosis.generic.CONFOUNDED_R2`)
TIME_TEMPERATURE_R2 = 0.9


def _temperature_confound(ctx: DiagnosisContext, levels: pd.DataFrame) -> str:
    """Why a drift cannot be tested when the run temperature follows the clock ('' when it can)."""
    temps = {}
    for r in ctx.runs:
        t = run_temperature_c(r)
        if np.isfinite(t):
            temps[run_id(r)] = t
    lv = levels.assign(temperature_c=levels["curve"].map(temps))
    x = lv["elapsed_h"] if lv["elapsed_h"].notna().all() and lv["elapsed_h"].nunique() > 2 else lv["test_order"]
    ok = lv["temperature_c"].notna() & x.notna()
    if ok.sum() < 3 or lv.loc[ok, "temperature_c"].std() == 0 or x[ok].std() == 0:
        return ""
    r2 = float(np.corrcoef(lv.loc[ok, "temperature_c"], x[ok])[0, 1] ** 2)
    if r2 < TIME_TEMPERATURE_R2:
        return ""
    return (f"not testable here: the run temperature follows the elapsed time (R^2 = {r2:.3f} across "
            f"{int(ok.sum())} curves, {lv.loc[ok, 'temperature_c'].min():.3g}..{lv.loc[ok, 'temperature_c'].max():.3g} "
            f"degC), so a drift at constant conditions cannot be separated from the temperature change; the "
            f"temperature, which has a physical model (time-temperature superposition scored on a held-out "
            f"temperature), is tested as temperature_dependence; a design that would separate them: repeat a "
            f"reference temperature at the start and the end of the session.")


def _confound_text(t: dict) -> str:
    names = {"position": "the position in the test sequence", "first_load": "the first load of each sample",
             "temperature_c": "the logged temperature", "elapsed_h": "elapsed time",
             "condition": "the test condition (the test order is nearly fixed)"}
    if not t.get("confounded_with"):
        return ""
    return (" The design cannot separate it from " + " or ".join(names[c] for c in t["confounded_with"])
            + " (within-sample |r| >= " + f"{CONFOUND_CORRELATION:g}); a design that would: "
            + "; ".join(t["separating_design"]) + ".")


def detect_elapsed_time_drift(ctx: DiagnosisContext) -> dict:
    """Per-curve stiffness scale regressed on elapsed time (``started_at``/``total_time``; the position in
    the sequence only when no time was recorded), controlled for the first load where the order is known;
    reports the covariates it is confounded with (order, temperature) and the design that would separate
    them."""
    eff = "elapsed_time_drift"
    levels = curve_levels(ctx.table)
    if len(levels) < 6:
        return untested_finding(eff, "fewer than 6 curves: the per-curve scale cannot be regressed on elapsed time")
    confound = _temperature_confound(ctx, levels)
    if confound:
        return untested_finding(eff, confound) | {
            "confounded_with": ["temperature_c"],
            "separating_design": ["repeat a reference temperature at the start and the end of the session"]}
    t, design = _level_tests(levels, "elapsed_h")
    if t is None:
        return untested_finding(eff, "elapsed time (total_time/started_at) and the test order do not vary across "
                              "curves in a way that is not confounded with the test conditions; a design that "
                              f"would: {SEPARATING_DESIGN['condition']}"
                              + ("" if _usable(levels, "elapsed_h") else f"; {SEPARATING_DESIGN['elapsed_h']}"))
    kappa = float(np.expm1(t["estimate"]))
    use_time = _usable(levels, "elapsed_h")
    unit = "1/h" if use_time else "1/test"
    span = float(levels["elapsed_h"].max() - levels["elapsed_h"].min()) if use_time else float(
        levels["position"].max() - levels["position"].min())
    before, after, group = _scale_correction_cv(ctx, levels, "elapsed_h")
    order = levels.sort_values("elapsed_h" if use_time else "position")["log_scale"].to_numpy()
    runs = st.runs_test(order - np.median(order))
    source = ("hour of elapsed session time" if use_time else
              "test in the sequence (no started_at or total_time recorded: drift cannot be told from a test-order "
              "effect)")
    evidence = (f"The per-test stiffness scale of {ctx.model} changes by {100 * kappa:+.1f} % per "
                f"{source} across {len(levels)} "
                f"curves ({', '.join(sorted(levels['test'].unique()))}; {design}; t = {t['statistic']:.2f}); "
                f"over the {span:.2g} "
                f"{'h' if use_time else 'tests'} of the session the model is off by "
                f"{100 * np.expm1(abs(t['estimate']) * span):.0f} %; curve scales ordered by time have "
                f"{int(runs['n_runs'])} runs (runs test p = {runs['p_value']:.2g})." + _confound_text(t))
    fix = fix_record("elapsed-time covariate: prediction x exp(b0 + kappa t_elapsed)", "rms_log_residual",
               before, after, f"leave-one-{group}-out", kappa_per_unit=kappa)
    practical = abs(np.expm1(abs(t["estimate"]) * span)) >= 0.05
    return make_finding(eff, t, "t", kappa, unit, practical, evidence, fix, time_source=(
        "elapsed time" if use_time else "test order"), confounded_with=t["confounded_with"],
        separating_design=t["separating_design"], design=design)


def detect_preconditioning(ctx: DiagnosisContext) -> dict:
    """First load of each sample stiffer than its later tests, whatever test came first: the model-free
    paired comparison with later repeats of a comparable measurement (:func:`paired_first_load_test`) and
    the first-load indicator in the curve-level regression with sample + condition fixed effects
    (controlled for elapsed time where recorded), the stronger with a Bonferroni factor."""
    eff = "preconditioning"
    levels = curve_levels(ctx.table)
    if levels["first_load"].isna().all():
        return untested_finding(eff, "the measuring order of the tests on each sample is unknown (no order, started_at "
                              "or total_time): the first load cannot be identified")
    found = []
    paired = paired_first_load_test(ctx)
    if paired is not None:
        found.append((dict(paired, confounded_with=[], separating_design=[]),
                      f"model-free, paired over {paired['n']:.0f} samples: the first test "
                      f"({', '.join(paired['kinds'])}) vs later repeats of a comparable measurement of the same "
                      f"sample"))
    if len(levels) >= 6:
        lt, ldesign = _level_tests(levels, "first_load")
        if lt is not None:
            found.append((lt, ldesign))
    if not found:
        return untested_finding(eff, "no sample has a first load comparable with a later repeat of the same kind of "
                              "measurement and the first-load indicator is confounded with the test conditions "
                              "(one test per sample, or the first test is always the same kind); a design that "
                              f"would: {SEPARATING_DESIGN['first_load']}")
    t, design = min(found, key=lambda f: f[0]["log10_p"])
    lp = min(0.0, t["log10_p"] + np.log10(len(found)))
    t = dict(t, log10_p=lp, p_value=10 ** lp)
    delta = float(np.expm1(t["estimate"]))
    before, after, group = _scale_correction_cv(ctx, levels, "first_load")
    known = levels[levels["first_load"].notna()]
    n_first = int(known["first_load"].sum())
    first_tests = known.loc[known["first_load"] == 1, "test"].value_counts().index.tolist()
    evidence = (f"The first test of each sample ({n_first} first loads, mostly {', '.join(first_tests[:2])}; "
                f"order from {', '.join(sorted(known['order_source'].unique()))}) "
                f"is {100 * delta:+.1f} % {'stiffer' if delta > 0 else 'softer'} than "
                f"the repeated tests of the same samples ({design}; t = {t['statistic']:.2f}"
                + (f"; Bonferroni over {len(found)} tests" if len(found) > 1 else "") + ")."
                + _confound_text(t))
    fix = fix_record("first-load indicator (pseudo-elastic factor on virgin loading) / discard first cycle",
               "rms_log_residual", before, after, f"leave-one-{group}-out", first_load_factor=1 + delta)
    # preconditioning softens: only a stiffer first load is this cause (a softer one is another misfit)
    return make_finding(eff, t, "t", delta, "1 (relative stiffness of first load)", delta >= 0.05, evidence, fix,
                    confounded_with=t.get("confounded_with", []),
                    separating_design=t.get("separating_design", []), design=design)


def specimen_levels(levels: pd.DataFrame) -> pd.Series:
    """Specimen stiffness levels (log scale) with the condition effects removed: least squares of the curve
    levels on specimen + condition fixed effects (the condition misfit is shared by all specimens), each
    specimen's level centred on the mean of all. Raises ValueError when specimen and condition are
    confounded (the levels are then not identified)."""
    lv = levels[np.isfinite(levels["log_scale"])]
    spec = pd.get_dummies(lv["specimen"], dtype=float)
    cond = pd.get_dummies(lv["condition"], drop_first=True, dtype=float)
    X = pd.concat([spec, cond], axis=1).to_numpy(float)
    if np.linalg.matrix_rank(X) < X.shape[1]:
        raise ValueError("specimen and condition are confounded (specimens measured on disjoint sets of tests)")
    coef, *_ = np.linalg.lstsq(X, lv["log_scale"].to_numpy(float), rcond=None)
    out = pd.Series(coef[:spec.shape[1]], index=spec.columns)
    return out - out.mean()


def detect_outlier_specimen(ctx: DiagnosisContext) -> dict:
    """Most extreme specimen level (curve scales with condition effects removed, :func:`specimen_levels`):
    externally studentised deletion residual against the other specimens, t_{n-2}, Bonferroni over the n
    specimens (:func:`tissuemech.stats.deletion_outlier_test`); valid from 3 specimens."""
    eff = "outlier_specimen"
    levels = curve_levels(ctx.table)
    n_spec = levels["specimen"].nunique()
    if n_spec < 3:
        return untested_finding(eff, f"only {n_spec} specimen(s): an outlier specimen needs at least 3 specimens "
                              "(one to test against the spread of at least two others)")
    try:
        spec = specimen_levels(levels)
    except ValueError as exc:
        return untested_finding(eff, f"{n_spec} specimens, but {exc}: a design that would: run at least one common "
                              "test condition on every specimen")
    t = st.deletion_outlier_test(spec.to_numpy())
    if int(t["index"]) < 0:
        return untested_finding(eff, f"{n_spec} specimens: the deletion test could not be formed")
    name = str(spec.index[int(t["index"])])
    ratio = float(np.exp(spec.iloc[int(t["index"])] - np.median(np.delete(spec.to_numpy(), int(t["index"])))))
    resid = levels["log_scale"] - levels.groupby("condition")["log_scale"].transform("median")
    levels = levels.assign(resid=resid)
    mixed = None
    try:
        per_sample = levels.groupby("sample").agg(resid=("resid", "mean"), specimen=("specimen", "first"))
        per_sample["value"] = np.exp(per_sample["resid"])
        if per_sample["specimen"].value_counts().max() > 1:
            mixed = st.mixed_log_params(per_sample, "value", "specimen")
    except Exception:  # MixedLM may fail to converge on tiny designs; the deletion test stands alone
        mixed = None
    # held-out: predict each typical specimen's level from the others by mean (baseline) vs median (robust)
    errs_before, errs_after = [], []
    rows = primary_rows(ctx.table)
    for s in spec.index:
        if s == name:
            continue
        others = spec.drop(s)
        r = rows.loc[rows["specimen"] == s, "log_ratio"].to_numpy()
        r = r - float(np.median(r)) + spec[s]  # condition misfit removed as in the specimen levels
        errs_before.append(r - others.mean())
        errs_after.append(r - others.median())
    before, after = _rms(np.concatenate(errs_before)), _rms(np.concatenate(errs_after))
    mixed_txt = ""
    if mixed is not None:
        mixed_txt = (f"; MixedLM on log-scales: omega_between = {mixed['omega_between']:.2f}, omega_within = "
                     f"{mixed['omega_within']:.2f}, standardized BLUP of {name} = "
                     f"{mixed['blup_z'].get(name, np.nan):.1f}")
    evidence = (f"Specimen {name} is {ratio:.2f}x the median of the other {spec.size - 1} specimens "
                f"(externally studentised deletion t = {t['statistic']:.2f} on {spec.size - 2} df, "
                f"Bonferroni over {spec.size} specimens; modified z = {t['modified_z']:.1f}){mixed_txt}.")
    fix = fix_record("robust/hierarchical population fit (median specimen level; outlier specimen reported apart)",
               "rms_log_residual_typical_specimens", before, after, "leave-one-specimen-out",
               outlier_ratio=ratio)
    practical = abs(np.log(ratio)) >= np.log(1.5)
    return make_finding(eff, t, "t", ratio, "x median specimen", practical, evidence, fix, specimen=name,
                    n_specimens=int(spec.size))


# ------------------------------------------------------------------------------------------------
# frequency sweep: inertia
# ------------------------------------------------------------------------------------------------
def detect_instrument_inertia(ctx: DiagnosisContext) -> dict:
    """G' residual of the frequency sweep regressed on the inertial torque term omega^2 2h/(pi R^4).

    Where the sweeps log a raw phase, an over-correction (dI < 0) must also be consistent with it (science.md
    2.5): the raw phase with the reported moduli gives the inertia the instrument corrected for, I_cal
    (:func:`raw_phase_inertia`), and an over-correction cannot exceed it (|dI| <= I_cal); otherwise the
    omega^2 trend is a misfit of the spectrum and the finding is not practical. An under-correction (dI > 0)
    has no such bound: the true inertia is I_cal + dI."""
    eff = "instrument_inertia"
    fs = ctx.table[(ctx.table["test"] == "frequency_sweep") & (ctx.table["quantity"] == "storage_modulus")]
    if fs.empty or fs["frequency_sq"].nunique() < 4:
        return untested_finding(eff, "no frequency sweep")
    # the inertial term needs the true gap and plate radius of every sweep: never a default
    fs = fs[np.isfinite(fs["inverse_gap"]) & np.isfinite(fs["radius_m"])]
    if fs.empty or fs["frequency_sq"].nunique() < 4:
        return untested_finding(eff, "not testable here: the frequency sweeps record no gap or no plate radius "
                              "(the inertial term omega^2 2h/(pi R^4) needs both)")
    gap = 1.0 / fs["inverse_gap"]
    b_inv = 2.0 * gap / (np.pi * fs["radius_m"] ** 4)          # 1/b = 2h/(pi R^4), 1/m^3
    x_inertia = fs["frequency_sq"] * b_inv                      # Pa per (kg m^2)
    logw = 0.5 * np.log(fs["frequency_sq"])
    frame = fs.assign(x_inertia=x_inertia.to_numpy(), logw=logw.to_numpy())
    # the sample's stiffness scales G' (multiplicative) while the inertial error is additive: rescale each
    # sweep's prediction to its own low-frequency half (where omega^2 terms are negligible) first
    low = frame["frequency_sq"] <= frame.groupby("curve")["frequency_sq"].transform("median")
    scale = (frame["observed"] / frame["predicted"]).where(low).groupby(frame["curve"]).transform("median")
    frame = frame.assign(residual=frame["observed"] - scale * frame["predicted"],
                         predicted=scale * frame["predicted"], predicted_abs=np.abs(scale * frame["predicted"]))
    y = frame["residual"].to_numpy()
    fitted_tests = set(ctx.fit_info.get("fitted_tests") or ())
    cross_test = bool(fitted_tests) and "frequency_sweep" not in fitted_tests
    if cross_test:
        # the sweeps are predicted from tests the baseline was fitted to: a misfit of the spectrum is a
        # relative shape along log omega shared by every sweep (generic.shared_shape), so the control is that
        # shape (predicted x Legendre polynomials in log omega); the additive omega^2/b term must be seen over it
        shape_cols = _relative_shape_columns(frame)
        frame = frame.assign(**shape_cols)
        controls = list(shape_cols)
    else:
        # log(omega) control: a smooth misfit of the spectrum is not an omega^2 artefact
        controls = ["logw"]
    X = frame[["x_inertia", *controls]]
    res = st.cluster_regression(y / frame["sigma"], X.div(frame["sigma"], axis=0).assign(
        inv_sigma=1.0 / frame["sigma"].to_numpy()), groups=frame["curve"].to_numpy())
    t = st.coefficient_test(res, "x_inertia")
    delta_i = -t["estimate"]                                    # G'_app = G' - dI omega^2 / b
    f_max = float(np.sqrt(frame["frequency_sq"].max()) / (2 * np.pi))
    artefact_at_fmax = float(delta_i * frame["x_inertia"].max())
    gmax = float(frame.loc[frame["frequency_sq"].idxmax(), "predicted_abs"])
    # Booij-Thoone local KK check on the measured sweep, averaged over curves
    kk_txt = ""
    fs_runs = ctx.runs_of("frequency_sweep")
    ratios = []
    for r in fs_runs:
        if "storage_modulus" in r and "loss_modulus" in r and "angular_frequency" in r:
            w = r["angular_frequency"].values
            kk = booij_thoone(w, r["storage_modulus"].values)
            hi = w >= np.quantile(w, 0.75)
            with np.errstate(divide="ignore", invalid="ignore"):
                ratios.append(np.nanmedian(r["loss_modulus"].values[hi] / kk[hi]))
    if ratios:
        kk_txt = (f" Booij-Thoone check in the top quarter of frequencies: measured G'' / ((pi/2) dG'/dln w) "
                  f"= {np.nanmedian(ratios):.2g}.")
    raw_txt = ""
    consistent = True
    i_raw = raw_phase_inertia(ctx.table, frame)
    if np.isfinite(i_raw["i_raw_kg_m2"]):
        # science.md 2.5: the raw torque carries the whole inertia I, the reported G' is corrected by I_cal,
        # so G'_rep - G''/tan(raw phase) = I_cal omega^2/b: the raw phase shows the corrected part. An
        # over-correction dI = I - I_cal < 0 is at most I_cal in size; an under-correction is unbounded by it
        consistent = bool(delta_i >= 0 or abs(delta_i) <= i_raw["i_raw_kg_m2"])
        raw_txt = (f" Raw phase reaches {i_raw['max_raw_phase_deg']:.0f} deg; the inertia the instrument "
                   f"corrected for (I_cal omega^2/b = G' - G''/tan(raw phase), top quarter of omega^2/b) is "
                   f"I_cal ~ {i_raw['i_raw_kg_m2']:.3g} kg m^2; the fitted dI is "
                   + ("an under-correction (true inertia I_cal + dI)" if delta_i >= 0 else
                      "an over-correction " + ("within" if consistent else "larger than") + " I_cal") + ".")

    # held-out: leave-one-sample-out fit of dI, applied to the held-out sample's sweep
    frame = frame.assign(rel=frame["residual"] / frame["predicted_abs"])

    shape = [c for c in controls if c != "logw"]

    def fit(train):
        return np.linalg.lstsq(train[["x_inertia", *shape]].to_numpy(), train["residual"].to_numpy(), rcond=None)[0]

    def error(test, par):
        corr = 0.0 if par is None else test[["x_inertia", *shape]].to_numpy() @ par
        return (test["residual"].to_numpy() - corr) / test["predicted_abs"].to_numpy()

    group = _cv_group_column(frame)
    if shape:
        # "before" is the baseline with the shared spectrum shape fitted on the training groups (a statement
        # about the baseline, reported by the generic scan), "after" adds the inertia term
        def shape_only(train):
            coef = np.linalg.lstsq(train[shape].to_numpy(), train["residual"].to_numpy(), rcond=None)[0]
            return np.r_[0.0, coef]

        before = _group_cv(frame, group, shape_only, error)[1]
        after = _group_cv(frame, group, fit, error)[1]
    else:
        before, after = _group_cv(frame, group, fit, error)
    control_txt = ("the shared relative spectrum shape of the predicted sweeps as control" if shape
                   else "log-omega control")
    evidence = (f"Frequency-sweep G' residuals of {ctx.model} follow -dI omega^2/b (b = pi R^4/(2h)) with "
                f"dI = {delta_i:.3g} kg m^2 (t = {t['statistic']:.2f}, {frame['curve'].nunique()} sweeps, "
                f"clustered by sweep, {control_txt}): an inertial error of {artefact_at_fmax:+.3g} Pa at "
                f"{f_max:.3g} Hz where |G'| ~ {gmax:.3g} Pa.{kk_txt}{raw_txt}")
    fix = fix_record("fitted inertia term G'_app = G' - dI omega^2 2h/(pi R^4)", "rms_rel_residual_storage_modulus",
               before, after, f"leave-one-{group}-out", delta_inertia_kg_m2=delta_i, n_held_out_points=len(frame))
    practical = abs(artefact_at_fmax) >= 0.05 * gmax and consistent
    return make_finding(eff, t, "t", delta_i, "kg m^2", practical, evidence, fix)


#: polynomial degree (in log omega) of the misfit shape of the relaxation spectrum shared by every predicted
#: frequency sweep that the inertia test uses as its control (the generic scan's shared shape,
#: :func:`tissuemech.diagnosis.generic.shared_shape`, chooses its own degree by BIC)
SPECTRUM_SHAPE_DEGREE = 3


def spectrum_shape_basis(frequency_sq, max_degree: int | None = SPECTRUM_SHAPE_DEGREE) -> np.ndarray:
    """Legendre polynomials P_1..P_d of log omega scaled to [-1, 1] over the given points (rows; 0 where omega^2
    is not finite and positive), d = min(``max_degree``, distinct omegas - 2) (no cap when ``max_degree`` is
    None): the basis of a misfit shape of the relaxation spectrum along a frequency sweep. Shape (n, d); d may
    be 0."""
    w2 = np.asarray(frequency_sq, float)
    ok = np.isfinite(w2) & (w2 > 0)
    logw = np.where(ok, 0.5 * np.log(np.where(ok, w2, 1.0)), np.nan)
    distinct = np.unique(logw[ok]).size - 2
    degree = int(max(0, distinct if max_degree is None else min(max_degree, distinct)))
    lo, hi = (np.min(logw[ok]), np.max(logw[ok])) if ok.any() else (0.0, 1.0)
    z = np.where(ok, 2.0 * (logw - lo) / max(hi - lo, 1e-12) - 1.0, 0.0)
    return np.polynomial.legendre.legvander(z, degree)[:, 1:]


def _relative_shape_columns(frame: pd.DataFrame) -> dict[str, np.ndarray]:
    """predicted x P_k(log omega) (:func:`spectrum_shape_basis`): a relative misfit shape along log omega shared
    by every sweep."""
    basis = spectrum_shape_basis(frame["frequency_sq"])
    pred = frame["predicted"].to_numpy(float)
    return {f"shape_P{k + 1}": pred * basis[:, k] for k in range(basis.shape[1])}


def raw_phase_inertia(table: pd.DataFrame, frame: pd.DataFrame) -> dict:
    """Inertia the instrument corrected for, from the raw phase of the frequency sweeps (science.md 2.5).

    The raw torque is (G* - I omega^2/b) b theta with the whole inertia I, so tan(raw phase) =
    G'' / (G' - I omega^2/b) with the true G'. The reported G' is corrected with the calibrated I_cal,
    G'_rep = G' - (I - I_cal) omega^2/b, so G'_rep - G''/tan(raw phase) = I_cal omega^2/b [Pa]: with the
    reported moduli the raw phase gives I_cal (= I when the correction is exact).
    ``frame``: the storage-modulus rows of the sweeps with ``x_inertia`` = omega^2/b [1/(m^3 s^2)] and
    ``channel_raw_phase`` [rad]; ``table``: the residual table (for the loss-modulus rows).

    Returns ``i_raw_kg_m2`` (median of (I omega^2/b)/(omega^2/b) over the top quarter of omega^2/b, where the
    inertial torque is largest; NaN without a raw phase channel or G'') and ``max_raw_phase_deg``.
    """
    out = {"i_raw_kg_m2": np.nan, "max_raw_phase_deg": np.nan}
    if "channel_raw_phase" not in frame:
        return out
    loss = table[(table["test"] == "frequency_sweep") & (table["quantity"] == "loss_modulus")]
    both = frame[["curve", "frequency_sq", "observed", "x_inertia", "channel_raw_phase"]].merge(
        loss[["curve", "frequency_sq", "observed"]].rename(columns={"observed": "loss"}), on=["curve", "frequency_sq"])
    both = both[np.isfinite(both["channel_raw_phase"]) & np.isfinite(both["loss"]) & (both["x_inertia"] > 0)]
    if both.empty:
        return out
    phi = np.abs(both["channel_raw_phase"].to_numpy(float))
    with np.errstate(divide="ignore", invalid="ignore"):
        inertial_pa = both["observed"].to_numpy(float) - both["loss"].to_numpy(float) / np.tan(phi)
    top = both["x_inertia"].to_numpy(float) >= np.quantile(both["x_inertia"], 0.75)
    i_pts = inertial_pa[top] / both["x_inertia"].to_numpy(float)[top]
    i_pts = i_pts[np.isfinite(i_pts)]
    if i_pts.size:
        out["i_raw_kg_m2"] = float(np.median(i_pts))
    out["max_raw_phase_deg"] = float(np.degrees(phi.max()))
    return out


# ------------------------------------------------------------------------------------------------
# torque offset
# ------------------------------------------------------------------------------------------------
def _offset_design(g: pd.DataFrame) -> np.ndarray:
    """Per-curve design of the offset regression: [1, predicted] plus, for relaxation holds, time in the
    test (a drifting offset M0 + dM/dt t; in a ramp time and strain are collinear, so it is left out)."""
    cols = [np.ones(len(g)), g["predicted"].to_numpy(float)]
    if g["test"].iloc[0] == "stress_relaxation" and np.isfinite(g["time_in_test"]).all():
        t = g["time_in_test"].to_numpy(float)
        cols.append(t / max(t.max(), 1e-12))
    return np.column_stack(cols)


def detect_torque_offset(ctx: DiagnosisContext) -> dict:
    """Per-curve intercept of the stress residual on the predicted stress (small-strain time-domain data).

    An additive torque offset gives residual = c + (s - 1) * predicted with c the same on every curve,
    while specimen variability only changes the slope s; the per-curve intercepts are t-tested across curves.
    """
    eff = "torque_offset"
    td = ctx.table[ctx.table["test"].isin(TIME_DOMAIN) & (ctx.table["quantity"] == "shear_stress")]
    # every relaxation hold (its own intercept, precision-weighted below) and the small-strain part of the ramps
    td = td[(td["test"] == "stress_relaxation") | (td["strain"] <= 0.2)]
    intercepts, ses, levels_pa, curves = [], [], [], []
    for c, g in td.groupby("curve"):
        if len(g) < 8 or g["predicted"].max() < 1.5 * g["predicted"].min():
            continue
        A = _offset_design(g)
        w = 1.0 / g["sigma"].to_numpy()
        Aw, yw = A * w[:, None], g["residual"].to_numpy() * w
        coef, *_ = np.linalg.lstsq(Aw, yw, rcond=None)
        dof = max(len(g) - A.shape[1], 1)
        s2 = float(np.sum((yw - Aw @ coef) ** 2) / dof)
        cov = s2 * np.linalg.pinv(Aw.T @ Aw)
        intercepts.append(coef[0])
        ses.append(float(np.sqrt(max(cov[0, 0], 1e-30))))
        levels_pa.append(float(g["predicted_abs"].median()))
        curves.append(c)
    if len(intercepts) < 4:
        return untested_finding(eff, "fewer than 4 small-strain relaxation/ramp curves with a usable stress range")
    # second stage: an offset is the same on every curve, whereas a shape misfit of the model leaves
    # intercepts proportional to the curve's stress level -> intercept_k = c + d * level_k, test c;
    # weighted by the precision of each curve's intercept (robust SEs keep the between-curve scatter)
    stage2 = st.cluster_regression(np.asarray(intercepts), pd.DataFrame({"level": levels_pa}),
                                   weights=1.0 / np.asarray(ses) ** 2)
    t = st.coefficient_test(stage2, "const")
    tval = t["statistic"]
    radius = float(td["radius_m"].median())
    offset_pa = float(t["estimate"])
    offset_unm = offset_pa * np.pi * radius ** 3 / 2.0 * 1e6
    small = td[td["curve"].isin(curves)]
    sr = small[small["test"] == "stress_relaxation"]
    # scale the offset against the lowest curve level, read from the OBSERVED stresses (median |observed| per
    # curve, relaxation holds when there are any): a model that collapses to a near-zero prediction must not
    # turn a small offset into an absurd percentage
    lowest = sr if not sr.empty else small
    late_level = float(lowest.groupby("curve")["observed"].apply(lambda v: np.median(np.abs(v))).min())

    def fit(train):
        vals, lv = [], []
        for _, g in train.groupby("curve"):
            if len(g) < 8 or g["predicted"].max() < 1.5 * g["predicted"].min():
                continue
            A = _offset_design(g)
            w = 1.0 / g["sigma"].to_numpy()
            vals.append(np.linalg.lstsq(A * w[:, None], g["residual"].to_numpy() * w, rcond=None)[0][0])
            lv.append(float(g["predicted_abs"].median()))
        if len(vals) < 3:
            raise ValueError("too few training curves")
        return float(np.polyfit(lv, vals, 1)[1])

    def error(test, par):
        return (test["residual"].to_numpy() - (0.0 if par is None else par)) / test["predicted_abs"].to_numpy()

    group = "condition" if small["condition"].nunique() >= 3 else _cv_group_column(small)
    before, after = _group_cv(small, group, fit, error)
    where = (f"torque offset M0 = {offset_unm:+.3g} uN m at R = {1e3 * radius:.1f} mm" if np.isfinite(radius)
             else "no plate radius in the data: not convertible to a torque")
    size = (f"{100 * abs(offset_pa) / late_level:.3g} % of the lowest curve level (median observed stress of "
            f"that curve, {late_level:.3g} Pa)"
            if late_level > 0 else "the observed stresses of these curves have no positive median level")
    evidence = (f"Stress residuals of {ctx.model} on {len(curves)} relaxation holds and ramp starts (<= 20 %) "
                f"have a common additive intercept of {offset_pa:+.3g} Pa ({where}; t = {tval:.2f} across curves), "
                f"i.e. {size}: G(t, gamma0) = sigma/gamma0 diverges as 1/gamma0.")
    fix = fix_record("torque offset M0 as a nuisance parameter (stress + 2 M0/(pi R^3))", "rms_rel_residual_small_strain",
               before, after, f"leave-one-{group}-out", offset_pa=offset_pa, offset_uNm=offset_unm,
               n_held_out_points=len(small))
    practical = bool(late_level > 0 and abs(offset_pa) >= 0.02 * late_level)
    return make_finding(eff, t, "t", offset_unm, "uN m", practical, evidence, fix)


# ------------------------------------------------------------------------------------------------
# amplitude sweep: Kraus softening
# ------------------------------------------------------------------------------------------------
def _kraus(log_g0, p):
    """log of the Kraus factor r_inf + (1 - r_inf)/(1 + (g0/gc)^(2m)) (p = [r_inf, log10 gc, m])."""
    r_inf, lgc, m = p
    return np.log(r_inf + (1.0 - r_inf) / (1.0 + 10.0 ** (2 * m * (log_g0 - lgc))))


def detect_amplitude_softening(ctx: DiagnosisContext) -> dict:
    """Slope of the amplitude-sweep G' log-residual against log strain amplitude (cluster by sweep)."""
    eff = "amplitude_softening"
    a = ctx.table[(ctx.table["test"] == "amplitude_sweep") & (ctx.table["quantity"] == "storage_modulus")]
    a = a[np.isfinite(a["log_ratio"]) & (a["strain"] > 0) & a.get("above_noise", True)]
    if a.empty or a["strain"].nunique() < 4:
        return untested_finding(eff, "no amplitude sweep above the torque noise floor")
    a = a.assign(log_g0=np.log10(a["strain"]), y=_demean_by(a, "log_ratio", "curve"))
    # softening sets in above gamma_c: test the within-sweep trend on log amplitude and on amplitude
    # (the latter weights the large amplitudes where Kraus softening acts), Bonferroni x 2
    tests = []
    for cov in ("log_g0", "strain"):
        xd = a[cov] - a.groupby("curve")[cov].transform("mean")
        r = st.cluster_regression(a["y"].to_numpy(), pd.DataFrame({cov: xd.to_numpy()}), groups=a["curve"].to_numpy())
        tt = st.coefficient_test(r, cov)
        tests.append((tt, cov, float(tt["estimate"] * (a[cov].max() - a[cov].min()))))
    t, cov_used, total = min(tests, key=lambda x: x[0]["log10_p"])
    lp = min(0.0, t["log10_p"] + np.log10(2))
    t = dict(t, log10_p=lp, p_value=10 ** lp)
    decades = float(a["log_g0"].max() - a["log_g0"].min())
    change = float(np.expm1(total))

    def kraus_centred(frame, p):
        k = _kraus(frame["log_g0"].to_numpy(), p)
        return k - pd.Series(k, index=frame.index).groupby(frame["curve"]).transform("mean").to_numpy()

    def fit(train):
        def resid(p):
            return train["y"].to_numpy() - kraus_centred(train, p)
        lg = train["log_g0"].to_numpy()
        sol = least_squares(resid, [0.7, float(np.quantile(lg, 0.7)), 0.8],
                            bounds=([0.05, lg.min() - 1, 0.2], [1.0, lg.max() + 1, 3.0]))
        return sol.x

    def error(test, par):
        # the sweep's level is the sample's stiffness (not the softening's business): compare shapes
        y = test["y"].to_numpy()
        return y if par is None else y - kraus_centred(test, par)

    group = _cv_group_column(a)
    before, after = _group_cv(a, group, fit, error)
    full = fit(a)
    evidence = (f"Amplitude-sweep G' falls relative to {ctx.model} with strain amplitude: within-sweep trend on "
                f"{'log amplitude' if cov_used == 'log_g0' else 'amplitude'} t = {t['statistic']:.2f} "
                f"({a['curve'].nunique()} sweeps, clustered), a {100 * change:+.0f} % change over {decades:.1f} "
                f"decades of amplitude "
                f"({100 * a['strain'].min():.2g}-{100 * a['strain'].max():.2g} %); Kraus fit G'inf/G'0 = "
                f"{full[0]:.2f}, gamma_c = {100 * 10 ** full[1]:.2g} %, m = {full[2]:.2f}.")
    fix = fix_record("Kraus amplitude softening G'(g0) = G'inf + (G'0 - G'inf)/(1 + (g0/gc)^(2m))",
               "rms_log_residual_amplitude_sweep_shape", before, after, f"leave-one-{group}-out",
               ratio_inf=full[0], gamma_c=10 ** full[1], m=full[2], n_held_out_points=len(a))
    return make_finding(eff, t, "t", change, "relative change of G' over the sweep", change <= -0.05, evidence, fix)


# ------------------------------------------------------------------------------------------------
# time-domain signature regression: non-separability, rim-stress error, wall slip
# ------------------------------------------------------------------------------------------------
def _csr_frame(ctx: DiagnosisContext) -> pd.DataFrame:
    c = ctx.table[(ctx.table["test"] == "constant_shear_rate") & (ctx.table["quantity"] == "shear_stress")]
    c = c[np.isfinite(c["log_ratio"]) & np.isfinite(c["log_rate"]) & (c["strain"] >= 0.02)]
    if c.empty:
        return c
    return c.assign(y=_demean_by(c, "log_ratio", "curve"))


def _slip_covariate(c: pd.DataFrame, sigma_c: float) -> np.ndarray:
    # no gap recorded -> NaN covariate (the detector is then not testable), never a default gap
    gap = (1.0 / c["inverse_gap"]).to_numpy()
    return np.maximum(0.0, c["observed"].to_numpy() - sigma_c) / (gap * 1e3) / c["strain"].to_numpy()


def _signature_regression(c: pd.DataFrame, sigma_c: float | None, slip_control: float | None = None):
    """Within-curve regression of the ramp log-residual on the signatures of science.md 4.4.

    Always: strain^2 and strain^3 (rate-independent: rim error), strain^2 x log-rate (non-separability),
    1/stress (offset). With ``sigma_c`` the slip covariate is added together with strain x log-rate, so
    that a smooth rate-dependent misfit cannot pass for a stress threshold."""
    cols = {"strain_sq": c["strain_sq"].to_numpy(), "strain_cu": c["strain"].to_numpy() ** 3,
            "strain_sq_x_log_rate": c["strain_sq_x_log_rate"].to_numpy(),
            "inv_stress": 1.0 / c["predicted_abs"].to_numpy()}
    if sigma_c is not None:
        cols["strain_x_log_rate"] = c["strain_x_log_rate"].to_numpy()
        cols["slip"] = _slip_covariate(c, sigma_c)
    if slip_control is not None:
        cols["slip_control"] = _slip_covariate(c, slip_control)
    X = pd.DataFrame(cols, index=c.index)
    X = X - X.groupby(c["curve"]).transform("mean")          # within-curve, as y
    return st.cluster_regression(c["y"].to_numpy(), X, groups=c["curve"].to_numpy())


def _best_slip(c: pd.DataFrame):
    best = None
    grid = np.quantile(c["observed"], [0.3, 0.5, 0.7, 0.85])
    for sc in grid:
        if np.count_nonzero(c["observed"] > sc) < 10:
            continue
        res = _signature_regression(c, sc)
        t = st.coefficient_test(res, "slip")
        if t["statistic"] < 0 and (best is None or t["statistic"] < best[1]["statistic"]):
            best = (sc, t, res)
    return best, len(grid)


def detect_nonseparable_relaxation(ctx: DiagnosisContext) -> dict:
    """Rate-dependent residual sign at large strain (strain^2 x log-rate interaction in the CSR residuals)
    and strain-specific relaxation shapes in the relaxation residuals (level x log-time interaction)."""
    eff = "nonseparable_relaxation"
    parts, texts, ev_size = [], [], np.nan
    c = _csr_frame(ctx)
    if not c.empty and c["log_rate"].nunique() >= 2 and c["curve"].nunique() >= 4:
        # the best stress-threshold (slip) covariate is a control: a rate-dependent misfit that a stress
        # threshold explains is not evidence of non-separability
        best_slip, _ = _best_slip(c)
        res = _signature_regression(c, None, slip_control=best_slip[0] if best_slip else None)
        t3 = st.coefficient_test(res, "strain_sq_x_log_rate")
        parts.append(t3)
        rates = np.sort(c["log_rate"].unique())
        gmax = float(c["strain"].max())
        ev_size = float(t3["estimate"] * gmax ** 2 * (rates[-1] - rates[0]))
        fast = c[c["log_rate"] == rates[-1]]
        slow = c[c["log_rate"] == rates[0]]
        big_f = fast.loc[fast["strain"] >= 0.5 * gmax, "log_ratio"].mean()
        big_s = slow.loc[slow["strain"] >= 0.5 * gmax, "log_ratio"].mean()
        texts.append(f"constant-shear-rate residuals of {ctx.model} change sign with rate at large strain "
                     f"(strain^2 x log10-rate coefficient {t3['estimate']:.3g}, t = {t3['statistic']:.2f}, "
                     f"{c['curve'].nunique()} ramps, clustered): above {50 * gmax:.0f} % strain the model is "
                     f"{100 * np.expm1(-big_f):+.0f} % off at {10 ** rates[-1]:g} 1/s and "
                     f"{100 * np.expm1(-big_s):+.0f} % at {10 ** rates[0]:g} 1/s (model minus data)")
    sr = ctx.table[(ctx.table["test"] == "stress_relaxation") & (ctx.table["quantity"] == "shear_stress")]
    sr = sr[np.isfinite(sr["log_ratio"]) & (sr["time_in_test"] > 0)]
    shape_change = np.nan
    if not sr.empty:
        levels = sr.groupby("curve")["strain"].max().round(4)
        sr = sr.assign(level=sr["curve"].map(levels))
        # hold segment only: from 2x the ramp end onwards
        ramp_end = sr[sr["strain"] >= 0.98 * sr["level"]].groupby("curve")["time_in_test"].min()
        sr = sr[sr["time_in_test"] >= 2.0 * sr["curve"].map(ramp_end).clip(lower=1e-3)]
        if sr["level"].nunique() >= 2 and sr["curve"].nunique() > sr["level"].nunique():
            lt = np.log10(sr["time_in_test"])
            edges = np.linspace(lt.min(), lt.max() + 1e-9, 9)
            sr = sr.assign(bin=np.digitize(lt, edges))
            sr = sr.assign(inv_stress=1.0 / sr["predicted_abs"])
            cell = sr.groupby(["curve", "bin"]).agg(y=("log_ratio", "mean"), level=("level", "first"),
                                                    inv_stress=("inv_stress", "mean")).reset_index()
            # 1/stress: a torque offset also makes small-strain holds decay differently; it is not this cause
            r0 = sm.OLS.from_formula("y ~ C(curve) + C(bin) + inv_stress", cell).fit()
            r1 = sm.OLS.from_formula("y ~ C(curve) + C(bin) + C(level):C(bin) + inv_stress", cell).fit()
            dk = int(r1.df_model - r0.df_model)
            if dk > 0 and r1.df_resid > 0:
                f = st.nested_f_test(r0.ssr, r1.ssr, r1.nobs, int(r1.df_model) + 1, dk)
                parts.append(f)
                lv = np.sort(cell["level"].unique())
                last = cell["bin"].max()
                first = cell["bin"].min()
                decay = cell.pivot_table(index="curve", columns="bin", values="y")
                lvl = cell.groupby("curve")["level"].first()
                shape = (decay[last] - decay[first]).groupby(lvl).mean()
                shape_change = float(shape.get(lv[-1], np.nan) - shape.get(lv[0], np.nan))
                texts.append(f"relaxation residuals have strain-specific shapes (level x log-time interaction "
                             f"F = {f['statistic']:.2f}, df = {dk}, {sr['curve'].nunique()} holds at "
                             f"{', '.join(f'{100 * x:g} %' for x in lv)}): from early to late hold the "
                             f"{100 * lv[-1]:g} % curve decays {100 * shape_change:+.1f} % relative to the "
                             f"{100 * lv[0]:g} % curve beyond what the shared QLV shape allows")
    if not parts:
        return untested_finding(eff, "needs constant-shear-rate ramps at >= 2 rates or relaxation at >= 2 strain levels")
    lp = st.bonferroni_min([p["log10_p"] for p in parts])
    best = min(parts, key=lambda p: p["log10_p"])
    t = {"statistic": best["statistic"], "p_value": 10 ** lp, "log10_p": lp}
    effect = ev_size if np.isfinite(ev_size) else shape_change
    fix = ctx.fit_info.get("fixes", {}).get(eff)
    evidence = "Non-separable (strain-dependent) relaxation: " + "; ".join(texts) + "."
    return make_finding(eff, t, "t" if best is parts[0] and np.isfinite(ev_size) else "F", effect,
                    "log residual change across rates at max strain" if np.isfinite(ev_size) else
                    "relative shape change", abs(effect) >= 0.03, evidence, fix)


#: plate targets that compare the homogeneous law at the rim strain with the reported 2M/(pi R^3) (the thesis
#: method, :mod:`tissuemech.fitting`): the only ones a nonlinear material biases
RIM_BIASED_TARGETS = ("thesis",)


def _isochrone_exponents(ctx: DiagnosisContext, rim_strain: float) -> np.ndarray:
    """n = d ln M / d ln gamma_R at ``rim_strain`` from the relaxation isochrones of every sample.

    A relaxation hold is a scaled step at every radius, so the Rabinowitsch exponent is the slope of the
    reported stress against the step strain *at a fixed time* (science.md 2.1): per sample with >= 3 strain
    levels, ln sigma is read at times 2-10x the longest ramp, sigma = a g + b g^3 fitted over the levels
    (relative least squares) and n = (a + 3 b g^2) / (a + b g^2) evaluated at ``rim_strain``. Early in the
    hold the reduced relaxation is still close to 1, so strain-dependent relaxation weights barely move it;
    a ramp's log slope would mix the relaxation of the material (n < 1 for any linear viscoelastic ramp)
    into the exponent."""
    by_sample: dict[tuple, list] = {}
    for r in ctx.runs_of("stress_relaxation"):
        if "shear_stress" in r and "shear_strain" in r and "time" in r:
            by_sample.setdefault((str(r.attrs.get("specimen")), str(r.attrs.get("sample"))), []).append(r)
    out = []
    for runs in by_sample.values():
        if len(runs) < 3:
            continue
        levels, ramp_end = [], 0.0
        for r in runs:
            g = np.abs(r["shear_strain"].values)
            t = r["time"].values - r["time"].values[0]
            g0 = float(np.nanmax(g))
            levels.append((g0, t, np.abs(r["shear_stress"].values)))
            ramp_end = max(ramp_end, float(t[np.argmax(g >= 0.98 * g0)]))
        t_read = np.geomspace(max(2.0 * ramp_end, 0.05), max(10.0 * ramp_end, 1.0), 5)
        g0s, sig = [], []
        for g0, t, s in levels:
            ok = (t > 0) & (s > 0)
            if ok.sum() < 4 or t[ok].max() < t_read[-1]:
                continue
            g0s.append(g0)
            sig.append(float(np.exp(np.mean(np.interp(np.log(t_read), np.log(t[ok]), np.log(s[ok]))))))
        if len(g0s) < 3:
            continue
        g0s, sig = np.asarray(g0s), np.asarray(sig)
        X = np.column_stack([g0s, g0s ** 3]) / sig[:, None]
        a, b = np.linalg.lstsq(X, np.ones_like(sig), rcond=None)[0]
        if a <= 0:
            continue
        out.append((a + 3 * b * rim_strain ** 2) / (a + b * rim_strain ** 2))
    return np.asarray(out, float)


def _ramp_exponents(ctx: DiagnosisContext) -> np.ndarray:
    """n = d ln M / d ln gamma_R over the top 70 % of each constant-shear-rate ramp (exact for rate-independent
    ramps; in a relaxing material the log slope also carries the relaxation, see :func:`_isochrone_exponents`)."""
    ns = []
    for r in ctx.runs_of("constant_shear_rate"):
        if "shear_stress" not in r or "shear_strain" not in r:
            continue
        g = np.abs(r["shear_strain"].values)
        s = np.abs(r["shear_stress"].values)
        m = (g >= 0.3 * np.nanmax(g)) & (s > 0)
        if m.sum() >= 4:
            ns.append(np.polyfit(np.log(g[m]), np.log(s[m]), 1)[0])
    return np.asarray(ns, float)


def detect_rim_stress_nonlinearity(ctx: DiagnosisContext) -> dict:
    """Rabinowitsch exponent n = dlnM/dln(gamma_R) at the largest ramp strain; a baseline fitted the thesis way
    (homogeneous law vs the reported 2M/(pi R^3)) is biased there by 4/(n+3) - 1."""
    eff = "rim_stress_nonlinearity"
    target = ctx.fit_info.get("target", "thesis")
    csr = [r for r in ctx.runs_of("constant_shear_rate") if "shear_strain" in r]
    strains = [float(np.nanmax(np.abs(r["shear_strain"].values))) for r in csr + ctx.runs_of("stress_relaxation")
               if "shear_strain" in r]
    gmax = max(strains) if strains else np.nan
    ns = _isochrone_exponents(ctx, gmax) if np.isfinite(gmax) else np.asarray([])
    source = f"relaxation isochrones of {ns.size} samples (stress at 2-10x the ramp time vs step strain)"
    if ns.size < 3:
        ns = _ramp_exponents(ctx)
        source = f"log slope over the top 70 % of strain of {ns.size} constant-shear-rate ramps"
    if ns.size < 3:
        return untested_finding(eff, "fewer than 3 samples with relaxation at >= 3 strains and fewer than 3 "
                              "constant-shear-rate ramps to estimate n = dlnM/dln(gamma_R)")
    n_mean = float(ns.mean())
    se = float(ns.std(ddof=1) / np.sqrt(ns.size))
    bias = 4.0 / (n_mean + 3.0) - 1.0
    # practical null: |n - 1| <= 0.2, i.e. a rim-stress bias within 5 %
    tval = (abs(n_mean - 1.0) - 0.2) / se if se > 0 else np.inf
    lp = float(np.log10(max(st.sps.t.sf(tval, ns.size - 1), 1e-300)))
    t = st._pack(tval, lp)
    if target not in RIM_BIASED_TARGETS:
        evidence = (f"n = dlnM/dln(gamma_R) = {n_mean:.2f} +- {se:.2f} at {100 * gmax:.0f} % ({source}), but the "
                    f"baseline was fitted through {target}, which already accounts for the radial strain field.")
        return make_finding(eff, st._pack(tval, 0.0), "t", 0.0, "relative stress bias", False, evidence, None)
    evidence = (f"The material {'stiffens' if n_mean > 1 else 'softens'} (n = dlnM/dln(gamma_R) = {n_mean:.2f} +- "
                f"{se:.2f} at {100 * gmax:.0f} %, {source}) while {ctx.model} was fitted to the reported "
                f"2M/(pi R^3) as if it were the rim stress: the reported stress is {100 * bias:+.0f} % off the rim "
                f"stress at {100 * gmax:.0f} %, rate-independent and growing with strain; the stiffening "
                f"parameters are biased (C20 -> 2/3, C30 -> 1/2 of the truth for a reduced polynomial).")
    # the correction is exact for the power-law segment; its residual bias is the n uncertainty
    after = abs(4.0 / (n_mean + 3.0) - 4.0 / (n_mean + se + 3.0))
    fix = fix_record("torque forward model (radial Gauss-Legendre integral) or Rabinowitsch-corrected rim stress "
               "sigma_R = M/(2 pi R^3) (3 + n)", "rim_stress_bias_at_max_strain (not held-out)", abs(bias), after,
               "none (bias correction)", n=n_mean)
    return make_finding(eff, t, "t", bias, "relative stress bias at max strain", abs(bias) >= 0.05, evidence, fix)


def detect_wall_slip(ctx: DiagnosisContext) -> dict:
    """Stress-threshold (and gap-scaled) loss of stress in the ramps, with the non-separability and
    rim-stress signatures as controls; sigma_c profiled over a grid (Bonferroni)."""
    eff = "wall_slip"
    c = _csr_frame(ctx)
    if c.empty or c["curve"].nunique() < 4:
        return untested_finding(eff, "needs >= 4 constant-shear-rate ramps")
    best, k = _best_slip(c)
    if best is None:
        return make_finding(eff, st._pack(0.0, 0.0), "t", 0.0, "Pa", False,
                        "No stress-threshold loss of stress in the ramps.", None)
    sigma_c, t, res = best
    lp = min(0.0, t["log10_p"] + np.log10(k))
    t = dict(t, p_value=10 ** lp, log10_p=lp)
    # size: the fitted stress loss at the most slipped point (largest stress over gap x strain)
    x_slip = _slip_covariate(c, sigma_c)
    loss = float(np.expm1(t["estimate"] * (x_slip.max() - np.median(x_slip))))
    gaps = np.unique(np.round(1e3 / c["inverse_gap"].dropna(), 1))
    gap_txt = (f"; gaps {gaps.min():.1f}-{gaps.max():.1f} mm ({gaps.size} values) enter through 1/h"
               if gaps.size > 1 else "; single gap (no Mooney gap regression possible)")

    def centred_slip(frame):
        x = _slip_covariate(frame, sigma_c)
        return x - pd.Series(x, index=frame.index).groupby(frame["curve"]).transform("mean").to_numpy()

    def fit(train):
        y = train["y"].to_numpy()
        x = centred_slip(train)
        return float(np.dot(x, y) / np.dot(x, x)) if np.dot(x, x) > 0 else 0.0

    def error(test, par):
        # the curve level (sample variability) is not the slip's business: compare within-curve shapes
        y = test["y"].to_numpy()
        return y if par is None else y - par * centred_slip(test)

    group = "condition" if c["condition"].nunique() >= 3 else _cv_group_column(c)
    before, after = _group_cv(c, group, fit, error)
    evidence = (f"Above a critical stress sigma_c ~ {sigma_c:.3g} Pa the ramps lose stress relative to "
                f"{ctx.model} at every rate (up to {100 * loss:+.0f} % at the largest stress; slip covariate "
                f"max(0, sigma - sigma_c)/(h gamma), t = {t['statistic']:.2f}, controls strain^2 and "
                f"strain^2 x log-rate, Bonferroni over {k} thresholds){gap_txt}.")
    fix = fix_record("slip-corrected strain gamma = gamma_app - 2 beta_s max(0, sigma - sigma_c)/h",
               "rms_log_residual", before, after, f"leave-one-{group}-out", sigma_c_pa=sigma_c,
               n_held_out_points=len(c))
    return make_finding(eff, t, "t", sigma_c, "Pa (critical stress)", loss <= -0.03, evidence, fix)


# ------------------------------------------------------------------------------------------------
# relaxation rise time and cross-test consistency
# ------------------------------------------------------------------------------------------------
def _measured_sweep(ctx: DiagnosisContext):
    ws, g1, g2 = [], [], []
    for r in ctx.runs_of("frequency_sweep"):
        if all(k in r for k in ("storage_modulus", "loss_modulus")):
            w = r["angular_frequency"].values if "angular_frequency" in r else 2 * np.pi * r["frequency"].values
            ws.append(w), g1.append(r["storage_modulus"].values), g2.append(r["loss_modulus"].values)
    if not ws:
        return None
    frame = pd.DataFrame({"w": np.concatenate(ws), "g1": np.concatenate(g1), "g2": np.concatenate(g2)})
    frame["w"] = frame["w"].round(6)
    return frame.groupby("w").median().reset_index()


def detect_finite_rise_time(ctx: DiagnosisContext) -> dict:
    """A relaxation ramp analysed as a step: (a) cross-test -- the frequency sweep predicted from the
    step-analysed Prony spectrum of each small-strain relaxation vs from the ramp-aware one (paired over
    tests; model-free, so it also says whether a ramp-aware baseline was needed); (b) when the baseline was
    fitted as a step (``fit_info["relaxation"] == "step"``), its early-hold residuals (t <= 10 t_r) against
    the later hold. Bonferroni over the components. Tested only when the baseline was fitted as a step: a
    baseline fitted through the measured strain history (``"measured"``) does not commit the error, so the
    cause cannot explain its misfit (the finding is then untested, with that reason)."""
    eff = "finite_rise_time"
    sr = [r for r in ctx.runs_of("stress_relaxation") if all(k in r for k in ("time", "shear_stress", "shear_strain"))]
    if len(sr) < 3:
        return untested_finding(eff, "fewer than 3 relaxation tests")
    lv = min(nominal_strain(r) for r in sr)
    small = [r for r in sr if nominal_strain(r) <= 1.5 * lv]
    ramps = []
    for r in small:
        g = np.abs(r["shear_strain"].values)
        t_ = r["time"].values
        ramps.append(t_[np.argmax(g >= 0.98 * g.max())] - t_[0])
    t_r = float(np.median(ramps))
    if t_r <= 0:
        return untested_finding(eff, "the relaxation data contain no ramp (ideal step in the export): the rise time "
                              "cannot be checked from these files")
    step_baseline = ctx.fit_info.get("relaxation", "measured") == "step"
    if not step_baseline:
        # the cause is an analysis error (a ramp treated as a step), not a property of the data: a baseline
        # fitted through the measured strain history does not commit it, so it cannot explain that
        # baseline's misfit. The model-free cross-test below would still show that *a* step analysis of
        # these data is biased whenever the fast modes are comparable to the rise time (true of any
        # sample), which is no finding about this diagnosis.
        return untested_finding(eff, f"not applicable: the baseline was fitted through the measured strain "
                                     f"history (relaxation ramps of {t_r:.3g} s are modelled, not treated as "
                                     f"steps)")
    parts, texts, fix = [], [], None
    sweep = _measured_sweep(ctx)
    tmax = max(float(r["time"].values.max()) for r in small)
    taus = decade_aligned_taus(t_r / 10.0, tmax)
    # weights from the noise of these relaxations themselves (evidence.estimate_noise), not an instrument constant
    relax_noise = estimate_noise(small)
    fits = []
    for r in small:
        g = np.abs(r["shear_strain"].values)
        s_ = np.abs(r["shear_stress"].values)
        t_ = r["time"].values - r["time"].values[0]
        sd = noise_sd(relax_noise, "stress_relaxation", "shear_stress", s_)
        w = np.where(np.isfinite(sd) & (sd > 0), 1.0 / sd, 0.0) if np.isfinite(sd).any() else np.ones_like(s_)
        fits.append((fit_prony_relaxation(t_, s_, g, taus, ramp_aware=False, weights=w),
                     fit_prony_relaxation(t_, s_, g, taus, ramp_aware=True, weights=w)))
    g_fast = [np.mean([p[k]["g_pa"][p[k]["taus_s"] <= 10 * t_r].sum() for p in fits]) for k in (0, 1)]
    if sweep is not None:
        w_ = sweep["w"].to_numpy()

        def sweep_err(f):
            gs = prony_complex_modulus(f["g_inf_pa"], f["g_pa"], f["taus_s"], w_)
            return _rms(np.r_[np.log(np.maximum(np.abs(gs.real), 1e-9) / sweep["g1"]),
                              np.log(np.maximum(np.abs(gs.imag), 1e-9) / sweep["g2"])])
        e_step = np.array([sweep_err(p[0]) for p in fits])
        e_ramp = np.array([sweep_err(p[1]) for p in fits])
        d = e_step - e_ramp
        tval = d.mean() / (d.std(ddof=1) / np.sqrt(d.size)) if d.size > 1 and d.std(ddof=1) > 0 else 0.0
        parts.append(st._pack(tval, st.log10_p_from_t(tval, max(d.size - 1, 1))))
        before, after = float(np.mean(e_step)), float(np.mean(e_ramp))
        fix = fix_record("ramp-aware relaxation fit (exact recursion over the measured strain history)",
                   "rms_log_error_frequency_sweep_predicted_from_relaxation", before, after,
                   "cross-test (relaxation -> frequency sweep)", rise_time_s=t_r)
        texts.append(f"the frequency sweep predicted from each {100 * lv:g} % relaxation is off by "
                     f"{100 * before:.0f} % (rms log error of G', G'') with the step analysis and "
                     f"{100 * after:.0f} % with a ramp-aware analysis of the same data (paired over {d.size} "
                     f"tests, t = {tval:.2f})")
    early = ctx.table[(ctx.table["test"] == "stress_relaxation") & (ctx.table["quantity"] == "shear_stress")]
    early = early[np.isfinite(early["log_ratio"]) & (early["time_in_test"] > 0)]
    if step_baseline and not early.empty and early["curve"].nunique() >= 3:
        ind = (early["time_in_test"] <= 10 * t_r).astype(float)
        if 0 < ind.sum() < len(ind):
            y = _demean_by(early.assign(ind=ind), "log_ratio", "curve")
            x = (ind - ind.groupby(early["curve"]).transform("mean")).to_numpy()
            res = st.cluster_regression(y, pd.DataFrame({"early": x}), groups=early["curve"].to_numpy())
            te = st.coefficient_test(res, "early")
            parts.append(te)
            texts.append(f"the baseline's residuals in the first {10 * t_r:.3g} s of the holds differ by "
                         f"{100 * te['estimate']:+.1f} % from the later hold (t = {te['statistic']:.2f})")
    if not parts:
        return untested_finding(eff, "no frequency sweep to cross-check and no early-hold residuals")
    lp = st.bonferroni_min([p["log10_p"] for p in parts])
    best = min(parts, key=lambda p: p["log10_p"])
    t = {"statistic": best["statistic"], "p_value": 10 ** lp, "log10_p": lp}
    how = ("that the baseline analysis treated as a step" if step_baseline else
           "(the baseline was fitted through the measured strain history, which is the fix; a step analysis "
           "of these data would be biased)")
    evidence = (f"Relaxation tests have a {t_r:.3g} s ramp {how}: "
                + "; ".join(texts) + f". The step analysis puts {g_fast[0]:.3g} Pa in modes with tau <= 10 t_r "
                f"(ramp-aware: {g_fast[1]:.3g} Pa).")
    if fix is not None:
        practical = bool(np.isfinite(fix["gain"]) and fix["gain"] >= 0.1)
    else:
        practical = abs(parts[-1].get("estimate", 0.0)) >= 0.03
    return make_finding(eff, t, "t", t_r, "s (rise time)", bool(practical), evidence, fix)


# ------------------------------------------------------------------------------------------------
# I2 dependence
# ------------------------------------------------------------------------------------------------
def detect_unidentified_i2_dependence(ctx: DiagnosisContext) -> dict:
    """Thrust excess F - psi M / 2 = 2 pi psi^2 int W2 r^3 dr (zero for any W(I1) material) regressed on
    (pi/2) psi^2 R^4: the slope is C01. Without normal force (or non-shear modes) C01 is not identifiable."""
    eff = "unidentified_i2_dependence"
    rows = []
    for r in ctx.runs:
        if r.attrs.get("test") not in TIME_DOMAIN:
            continue
        if not all(k in r for k in ("normal_force", "torque", "deflection_angle")):
            continue
        h = r["gap"].values if "gap" in r else np.full(r.sizes["point"], float(r.attrs.get("gap_m", np.nan)))
        R = float(r.attrs.get("radius_m", np.nan))
        psi = np.abs(r["deflection_angle"].values) / h
        rows.append(pd.DataFrame({"curve": run_id(r), "F": r["normal_force"].values,
                                  "half_psi_M": 0.5 * psi * np.abs(r["torque"].values),
                                  "x": 0.5 * np.pi * psi ** 2 * R ** 4, "strain": psi * R}))
    corr = {k: v for k, v in ctx.fit_info.get("correlations", {}).items()
            if ("C01" in k or "c01" in k.lower()) and ("C10" in k or "c10" in k.lower())}
    corr_txt = (f" The fitted C10-C01 correlation is {list(corr.values())[0]:+.3f}." if corr else "")
    modes = {str(r.attrs.get("test")) for r in ctx.runs}
    if not rows:
        finding = untested_finding(eff, "")
        finding.update(identifiable=False, evidence=(
            "Not identifiable from these data: in simple shear/torsion I1 = I2 = 3 + gamma^2, so the torque "
            "depends on W1 + W2 only; the C10 and C01 Jacobian columns are identical (correlation -> -1, flat "
            f"profile likelihood).{corr_txt} Only the normal force in torsion (W1 + 2 W2) or compression/"
            f"tension tests identify an I2 dependence; the runs ({', '.join(sorted(modes))}) record neither."))
        return finding
    d = pd.concat(rows, ignore_index=True)
    d = d[np.isfinite(d["F"]) & np.isfinite(d["x"]) & (d["strain"] >= 0.1)]
    if len(d) < 10 or d["curve"].nunique() < 2:
        finding = untested_finding(eff, "normal force recorded only below 10 % strain, where the thrust is at the "
                                 "resolution of the transducer: C01 is not identifiable")
        finding["identifiable"] = False
        return finding
    y = (d["F"] - d["half_psi_M"]).to_numpy()
    res = st.cluster_regression(y, d[["x"]], groups=d["curve"].to_numpy())
    t = st.coefficient_test(res, "x")
    c01 = t["estimate"]
    # C10 + C01 = mu/2 from the torque of a Mooney-Rivlin disc, M = (pi/2) mu psi R^4 = 2 x * (mu/2) / psi
    c_sum = float(np.median(d["half_psi_M"] / d["x"]))
    evidence = (f"The normal force exceeds the W(I1) thrust psi M/2 by (pi/2) psi^2 R^4 C01 with C01 = {c01:.3g} Pa "
                f"(t = {t['statistic']:.2f}, {d['curve'].nunique()} ramps/holds above 10 % strain, clustered): "
                f"an I2 (C01) dependence invisible in the torque (which carries only W1 + W2); C01/(C10 + C01) = "
                f"{c01 / c_sum:.2f}.{corr_txt}")
    fix = ctx.fit_info.get("fixes", {}).get(eff)
    # the thrust relation is exact for elastic laws; viscoelastic normal-stress histories depart from it by
    # a few % of C10 + C01, so only a larger C01 is a finding
    return make_finding(eff, t, "t", c01, "Pa (C01)", abs(c01) >= 0.1 * abs(c_sum), evidence, fix, identifiable=True,
                    c10_plus_c01_pa=c_sum)


DETECTORS: dict[str, Callable[[DiagnosisContext], dict]] = {
    "nonseparable_relaxation": detect_nonseparable_relaxation,
    "rim_stress_nonlinearity": detect_rim_stress_nonlinearity,
    "wall_slip": detect_wall_slip,
    "elapsed_time_drift": detect_elapsed_time_drift,
    "preconditioning": detect_preconditioning,
    "instrument_inertia": detect_instrument_inertia,
    "torque_offset": detect_torque_offset,
    "outlier_specimen": detect_outlier_specimen,
    "amplitude_softening": detect_amplitude_softening,
    "finite_rise_time": detect_finite_rise_time,
    "unidentified_i2_dependence": detect_unidentified_i2_dependence,
}
assert tuple(DETECTORS) == CATALOGUE_IDS
