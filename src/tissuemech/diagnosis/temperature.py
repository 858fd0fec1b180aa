"""Temperature dependence as a named cause (``temperature_dependence``).

Detection
---------
The temperature of every run is read from the data: the median of its logged ``temperature`` channel, else
its ``temperature_c`` attribute (sample sheet / export); never a default
(:func:`tissuemech.tts.run_temperature_c`). When fewer than :data:`MIN_TEMPERATURES` distinct temperatures
(:func:`tissuemech.curves.distinct_temperatures`: rounded to 0.5 degC, as the averaging rounds them) are present the cause is not testable.

The per-curve level of the baseline's residual (:func:`tissuemech.diagnosis.findings.curve_levels`: median
ln(observed/predicted) on the lower half of each curve) is regressed on the run temperature with the condition
as fixed effects and specimen and sample as random effects (:func:`tissuemech.stats.mixed_coefficient_test`,
between-within degrees of freedom: a temperature that changes only between specimens is judged on the
specimens); elapsed time is a control when it varies and is not collinear with temperature; with >= 5 distinct
temperatures the p-value is the stronger of the slope's t and the joint F-test of T and T^2 (shift factors are
curved in T), Bonferroni x 2. ``effect_size`` is the change of the curve level (ln) over the 5-95 % range of
temperatures, practical when >= :data:`tissuemech.diagnosis.generic.MIN_EFFECT`.

Shift test
----------
A thermorheologically simple material answers a temperature by a shift of its time scale (relaxation times
a_T tau_i), which moves a curve along its time, frequency or rate axis; its level need not move (a relaxation whose
late half sits on the equilibrium modulus). So the baseline is also predicted with every relaxation time x
exp(:data:`SHIFT_STEP`), which gives the sensitivity s = d ln(prediction) / d ln a_T at every point
(:func:`shift_sensitivity`), and the log residual, demeaned within each curve and quantity, is regressed on
s (T - mean T) (the slope is d ln a_T / dT), with s x condition as controls (a baseline whose time scale is off by
condition), standard errors clustered by specimen (by sample with fewer than 3 specimens; t with G - 1 df).
Demeaning within curves leaves every level out: specimen and sample stiffness cannot pass for a shift.
Calibration on constructed null designs (3-8 specimens, time-scale scatter between specimens and samples, a
baseline that misses a relaxation mode): the shift test 5.0 % at p < 0.05 and 0.5 % at p < 0.01 (600 designs), the
finding's combined p 3.7 % and 0.3 % (300). The finding reports the stronger of
the curve-level and shift tests, with the p-value of the two combined by Fisher's method (the shift test reads
within curves and the level test between them, so the two are independent under the null); read as a shift, ``effect_size`` is the change of log10 a_T over
the 5-95 % temperature range, practical when the 90th percentile of |s| times the change of ln a_T reaches
:data:`tissuemech.diagnosis.generic.MIN_EFFECT`, and the fix is the shift a_T = exp(b (T - mean T)) with b from the
other specimens (samples), scored on the held-out curves' shapes (RMS of the within-curve log residual).

Fix and held-out gain (leave-one-temperature-out)
-------------------------------------------------
Where frequency sweeps of one loading exist at >= :data:`MIN_TEMPERATURES` temperatures (the temperature changes
within samples: a temperature series): for every temperature, the
sweeps at the *other* temperatures are shifted automatically (:func:`tissuemech.tts.shift_factors`), a WLF
function is fitted to their log aT(T) (Arrhenius if WLF fails, linear interpolation of log aT if both fail;
the one used is reported), log aT of the held-out temperature is predicted from it and the held-out sweep is
predicted from the training mastercurve (:func:`tissuemech.tts.predict_from_mastercurve`). "Before" is the
temperature-blind prediction from the same training sweeps (their unshifted pooled curve at the held-out
frequencies: what a model without temperature predicts). Metric: RMS of log10 G' and log10 G'' errors
(decades) over the held-out points both predictions cover; ``gain = (before - after) / before``. Without
such a series (the temperature changes only between samples or specimens, whose sweeps also differ by their
stiffness) the fix is a level trend exp(a + b T) of the curve levels, read where the
temperature changes (between the samples of a specimen, else between the curves of a sample) and scored leaving
each sample (curve) out (:func:`tissuemech.diagnosis.levels.scale_correction_cv`; metric: RMS ln error of the
held-out curves' points).

The finding carries ``shift_factors`` (:meth:`tissuemech.tts.TTSResult.to_dict` of all sweeps), ``wlf`` and
``arrhenius`` (parameters with standard errors) and ``temperatures_c``.
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd
import scipy.stats
import xarray as xr

from .. import tts
from ..curves import distinct_temperatures, rounded_setting
from ..models.registry import FIXED_TIME_KEY, model_on_times
from .. import stats as st
from .baseline import predict_runs
from .findings import (DiagnosisContext, curve_levels, cv_group_column, describe_fix, fix_record, group_cv,
                       make_finding, untested_finding)
from .levels import scale_correction_cv
from .evidence import run_id
from .generic import CONFOUNDED_R2, MIN_EFFECT

EFFECT = "temperature_dependence"
#: fewest distinct run temperatures for a test (a slope and a held-out temperature need three)
MIN_TEMPERATURES = 3
#: step of ln a_T for the numerical shift sensitivity (5 %: small against the decades a spectrum spans, large
#: against the round-off of a creep inversion)
SHIFT_STEP = 0.05


def curve_temperatures(runs: Sequence[xr.Dataset]) -> dict[str, float]:
    """Temperature [degC] of every run with one, keyed by the residual table's curve id."""
    out = {}
    for r in runs:
        t = tts.run_temperature_c(r)
        if np.isfinite(t):
            out[run_id(r)] = t
    return out


def _shift_function(res: tts.TTSResult):
    """Callable log aT(T) fitted to ``res`` and its name: WLF, else Arrhenius, else linear interpolation."""
    ok = np.isfinite(res.log_aT)
    wlf = tts.fit_wlf(res.temperatures_c[ok], res.log_aT[ok], res.log_aT_stderr[ok], res.t_ref_c)
    if wlf.get("success") and np.isfinite(wlf.get("c1", np.nan)):
        return (lambda t: tts.wlf_log_aT(t, wlf["c1"], wlf["c2_k"], res.t_ref_c)), "WLF"
    arr = tts.fit_arrhenius(res.temperatures_c[ok], res.log_aT[ok], res.log_aT_stderr[ok], res.t_ref_c)
    if arr.get("success") and np.isfinite(arr.get("ea_j_per_mol", np.nan)):
        return (lambda t: tts.arrhenius_log_aT(t, arr["ea_j_per_mol"], res.t_ref_c)), "Arrhenius"
    return (lambda t: np.interp(t, res.temperatures_c[ok], res.log_aT[ok])), "interpolated"


def leave_one_temperature_out(sweeps: Sequence[tts.Sweep]) -> dict:
    """Held-out comparison of the TTS prediction with the temperature-blind one (module docstring).

    Returns ``before``, ``after`` (RMS decades), ``n_folds``, ``n_points``, ``shift_functions`` (name
    used per fold) and ``per_temperature`` {T: [before, after]}."""
    groups = np.array([rounded_setting(s.temperature_c) for s in sweeps], float)
    cache: dict = {}
    before, after, used, per_t = [], [], [], {}
    for g in np.unique(groups):
        held = [s for s, k in zip(sweeps, groups) if k == g]
        train = sorted((s for s, k in zip(sweeps, groups) if k != g), key=lambda s: s.temperature_c)
        if len(distinct_temperatures(s.temperature_c for s in train)) < 2:
            continue
        try:
            res = tts.shift_factors(train, cache=cache)
        except ValueError:
            continue
        func, name = _shift_function(res)
        mx, my = tts.mastercurve(train, res.log_aT)
        bx, by = tts.mastercurve(train, np.zeros(len(train)))
        eb, ea = [], []
        for s in held:
            la = float(func(s.temperature_c))
            p_after = tts.predict_from_mastercurve(mx, my, s.log_w, la) if np.isfinite(la) else np.full((s.omega.size, 2), np.nan)
            p_before = tts.predict_from_mastercurve(bx, by, s.log_w, 0.0)
            ok = np.isfinite(p_after) & np.isfinite(p_before)
            eb.append((p_before - s.log_g)[ok])
            ea.append((p_after - s.log_g)[ok])
        eb, ea = np.concatenate(eb), np.concatenate(ea)
        if eb.size:
            before.append(eb)
            after.append(ea)
            used.append(name)
            per_t[float(np.mean([s.temperature_c for s in held]))] = [float(np.sqrt(np.mean(eb ** 2))),
                                                                     float(np.sqrt(np.mean(ea ** 2)))]
    if not before:
        return {"before": np.nan, "after": np.nan, "n_folds": 0, "n_points": 0, "shift_functions": [],
                "per_temperature": {}}
    b, a = np.concatenate(before), np.concatenate(after)
    return {"before": float(np.sqrt(np.mean(b ** 2))), "after": float(np.sqrt(np.mean(a ** 2))),
            "n_folds": len(before), "n_points": int(b.size), "shift_functions": used, "per_temperature": per_t}


def _time_control(levels: pd.DataFrame) -> list[str]:
    """``["elapsed_h"]`` when elapsed time varies across curves and is not collinear with temperature (R^2 <
    :data:`tissuemech.diagnosis.generic.CONFOUNDED_R2`): temperature is then tested given elapsed time (the two
    compete for the same curve-level structure); [] otherwise (collinear sets are reported as confounded)."""
    e = levels["elapsed_h"]
    if not (e.notna().all() and e.nunique() > 2 and levels["temperature_c"].std() > 0 and e.std() > 0):
        return []
    r2 = float(np.corrcoef(levels["temperature_c"], e)[0, 1] ** 2)
    return ["elapsed_h"] if r2 < CONFOUNDED_R2 else []


def _factors(levels: pd.DataFrame) -> tuple[str, ...]:
    return ("condition",) if levels["condition"].nunique() > 1 else ()


def _curved_test(levels: pd.DataFrame, controls: Sequence[str] = ()) -> dict | None:
    """Joint Wald F-test of temperature and (centred) temperature^2 in the curve-level mixed model (condition
    fixed effects, specimen and sample random effects, :func:`tissuemech.stats.mixed_coefficient_test`); None with
    < 5 distinct temperatures."""
    if levels["temperature_c"].nunique() < 5:
        return None
    t = levels["temperature_c"]
    lv = levels.assign(temperature_sq=((t - t.mean()) / max(float(t.std()), 1e-12)) ** 2)
    return st.mixed_coefficient_test(lv, "log_scale", ["temperature_c", "temperature_sq"], _factors(levels),
                                     controls=tuple(controls))


def shift_sensitivity(ctx: DiagnosisContext) -> pd.DataFrame | None:
    """The rows of ``ctx.table`` with ``shift_sensitivity`` = d ln|prediction| / d ln a_T: the baseline predicted
    again with every relaxation time multiplied by exp(:data:`SHIFT_STEP`) (a_T scales the times of a
    thermorheologically simple material, so this is its response to a shift of the time axis; a sweep's modulus
    moves along frequency, a relaxation's or creep's along time, a ramp's along rate). None when the baseline has
    no fixed relaxation times (``fit_info`` without ``taus_s``/``params``, or a model key other than the
    fixed-time QLV/Pipkin-Rogers family)."""
    info = ctx.fit_info
    taus, params = info.get("taus_s"), info.get("params")
    if not taus or not params or FIXED_TIME_KEY.fullmatch(str(ctx.model)) is None or ctx.table.empty:
        return None
    curves = set(ctx.table["curve"])
    runs = [r for r in ctx.runs if run_id(r) in curves]
    model = model_on_times(ctx.model, np.asarray(taus, float) * np.exp(SHIFT_STEP))
    preds = predict_runs(model, params, runs, info.get("target", "apparent_stress"),
                         info.get("relaxation", "measured"))
    parts = []
    for run, pred in zip(runs, preds):
        for quantity, values in (pred or {}).items():
            values = np.asarray(values, float)
            parts.append(pd.DataFrame({"curve": run_id(run), "quantity": quantity, "point": np.arange(values.size),
                                       "predicted_shifted": values}))
    if not parts:
        return None
    rows = ctx.table.merge(pd.concat(parts, ignore_index=True), on=["curve", "quantity", "point"], how="inner")
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (np.log(np.abs(rows["predicted_shifted"])) - np.log(np.abs(rows["predicted"]))) / SHIFT_STEP
    return rows.assign(shift_sensitivity=s)


def _demeaned(frame: pd.DataFrame, columns: Sequence[str], group: pd.Series) -> pd.DataFrame:
    return frame[list(columns)] - frame[list(columns)].groupby(group).transform("mean")


def shift_test(ctx: DiagnosisContext, temps: dict[str, float]) -> dict | None:
    """Test of a time-temperature shift read from the shape of every curve (module docstring, "Shift test"):
    the baseline's log residual regressed, within each curve and quantity, on ``shift_sensitivity`` x (T - mean T),
    with ``shift_sensitivity`` x condition as controls, standard errors clustered by specimen (by sample with
    fewer than 3 specimens). Returns the coefficient test with ``per_k`` (d ln a_T / dT [1/K]), ``rows`` (the
    frame, for the fix) and ``sensitivity_q90`` (90th percentile of |d ln prediction / d ln a_T| over the points:
    the points where the time scale matters); None when no curve's sensitivity varies along it."""
    rows = shift_sensitivity(ctx)
    if rows is None:
        return None
    flagged = rows["quality_flag"] != 0 if "quality_flag" in rows else False
    rows = rows.assign(temperature_c=rows["curve"].map(temps))
    rows = rows[rows["above_noise"].astype(bool) & ~flagged & np.isfinite(rows["shift_sensitivity"])
                & np.isfinite(rows["log_ratio"]) & rows["temperature_c"].notna()]
    if rows.empty or len(distinct_temperatures(rows["temperature_c"])) < MIN_TEMPERATURES:
        return None
    group = rows["curve"].astype(str) + "|" + rows["quantity"].astype(str)
    d_t = rows["temperature_c"] - rows.groupby("curve")["temperature_c"].first().mean()
    x = rows.assign(shift_x_temperature=rows["shift_sensitivity"] * d_t)
    controls = []
    if x["condition"].nunique() > 1:
        for k, c in enumerate(sorted(x["condition"].astype(str).unique())):
            x[f"shift_x_condition_{k}"] = x["shift_sensitivity"] * (x["condition"].astype(str) == c)
            controls.append(f"shift_x_condition_{k}")
    cols = ["shift_x_temperature", *controls]
    X = _demeaned(x, cols, group)
    y = x["log_ratio"] - x["log_ratio"].groupby(group).transform("mean")
    spread = float(np.sqrt(np.mean(X["shift_x_temperature"] ** 2)))
    if not spread > 1e-9 * max(float(np.abs(x["shift_x_temperature"]).max()), 1e-300):
        return None
    clusters = x["specimen"] if x["specimen"].nunique() >= 3 else x["sample"]
    # controls collinear with each other (a condition measured at one temperature only) are dropped by rank
    keep = [c for c in cols if float(np.abs(X[c]).max()) > 0]
    Xk = X[keep]
    if np.linalg.matrix_rank(Xk.to_numpy(float)) < len(keep):
        r = np.linalg.qr(Xk.to_numpy(float), mode="r")
        independent = np.abs(np.diag(r)) > 1e-10 * np.abs(np.diag(r)).max()
        keep = [c for c, ok in zip(keep, independent) if ok or c == "shift_x_temperature"]
    if "shift_x_temperature" not in keep:
        return None
    result = st.cluster_regression(y.to_numpy(float), X[keep], groups=clusters.to_numpy())
    t = st.coefficient_test(result, "shift_x_temperature")
    if not np.isfinite(t.get("p_value", np.nan)):
        return None
    return dict(t, per_k=float(t["estimate"]), rows=x.assign(y=y.to_numpy(), x_shift=X["shift_x_temperature"]
                                                            .to_numpy()),
                sensitivity_q90=float(np.quantile(np.abs(x["shift_sensitivity"]), 0.9)),
                n_clusters=int(clusters.nunique()), cluster_unit="specimen" if x["specimen"].nunique() >= 3
                else "sample")


def _shift_fix(test: dict) -> tuple[float, float, str, int]:
    """Held-out score of the shift a_T(T) = exp(b (T - mean T)): b from the other specimens (samples) by the
    regression of :func:`shift_test` without its controls, applied to the held-out curves' shapes (each curve's
    mean log residual removed: a level is not the shift's business). Returns (before, after, unit, n points)."""
    frame = test["rows"]
    unit = cv_group_column(frame)

    def fit(train):
        xs, ys = train["x_shift"].to_numpy(), train["y"].to_numpy()
        return float(np.dot(xs, ys) / np.dot(xs, xs)) if np.dot(xs, xs) > 0 else 0.0

    def error(held, b):
        ys = held["y"].to_numpy()
        return ys if b is None else ys - b * held["x_shift"].to_numpy()

    before, after = group_cv(frame, unit, fit, error)
    return before, after, unit, int(len(frame))


def detect_temperature_dependence(ctx: DiagnosisContext) -> dict:
    """Curve levels of the baseline regressed on run temperature; fix = TTS scored on a held-out
    temperature (module docstring)."""
    temps = curve_temperatures(ctx.runs)
    distinct = distinct_temperatures(temps.values())
    if len(distinct) < MIN_TEMPERATURES:
        why = ("no run temperature in the data (no temperature channel, no temperature_c)" if not temps else
               f"runs are at {len(distinct)} distinct temperature(s) ({', '.join(f'{t:g}' for t in distinct)} "
               f"degC); a temperature dependence needs >= {MIN_TEMPERATURES}")
        return untested_finding(EFFECT, "not testable here: " + why)
    levels = curve_levels(ctx.table)
    levels = levels.assign(temperature_c=levels["curve"].map(temps)).dropna(subset=["temperature_c"])
    if len(levels) < 4 or levels["temperature_c"].nunique() < MIN_TEMPERATURES:
        return untested_finding(EFFECT, "not testable here: fewer than 4 residual curves with a temperature")
    try:
        shift = shift_test(ctx, temps)
    except (ValueError, np.linalg.LinAlgError):
        shift = None
    controls = _time_control(levels)
    t = st.mixed_coefficient_test(levels, "log_scale", "temperature_c", _factors(levels), controls=tuple(controls))
    if t is None and shift is None:
        return untested_finding(EFFECT, "not testable here: temperature is collinear with the test conditions of this "
                                        "design")
    if t is None:
        return _shift_finding(ctx, shift, levels, distinct)
    design = (f"curve levels, condition fixed effects, specimen and sample random effects"
              + (", elapsed-time control" if controls else "") + f"; {t['method']}")
    joint = _curved_test(levels, controls)
    if joint is not None:
        # the slope gives the size; the p-value is the stronger of the slope's test and the joint test of (T, T^2),
        # Bonferroni x 2: shift factors are curved in T (WLF), so over a wide range a straight line understates a
        # temperature dependence, while over a few degrees the slope alone is the more powerful test
        lp = min(0.0, min(t["log10_p"], joint["log10_p"]) + np.log10(2.0))
        if joint["log10_p"] < t["log10_p"]:
            t = dict(t, statistic=joint["statistic"])
            design += f", joint F of T and T^2 (df {joint['df1']:.0f}, {joint['df2']:.0f}), Bonferroni x 2 with the slope"
        else:
            design += ", t of the slope, Bonferroni x 2 with the joint F of T and T^2"
        t = dict(t, p_value=10 ** lp, log10_p=lp)
    if shift is not None:
        # the shift test reads within curves and the level test between them: independent under the null
        p = float(scipy.stats.combine_pvalues([t["p_value"], shift["p_value"]], method="fisher").pvalue)
        combined = {"p_value": p, "log10_p": float(np.log10(max(p, np.finfo(float).tiny)))}
        if shift["log10_p"] < t["log10_p"]:
            return _shift_finding(ctx, dict(shift, **combined), levels, distinct, level_test=t)
        t = dict(t, **combined)
        design += (f"; combined with the shift read from the curves' shapes (t = {shift['statistic']:.2f}) by "
                   "Fisher's method")
    lo, hi = np.nanquantile(levels["temperature_c"], [0.05, 0.95])
    size = float(t["estimate"] * (hi - lo))
    sweeps = tts.sweeps_from_runs(ctx.runs)
    extra: dict = {"temperatures_c": [float(x) for x in distinct]}
    # without sweeps for a mastercurve: a level trend in temperature, read where the temperature changes (between the
    # samples of a specimen, else between the curves of a sample), each held out in turn
    level = st.variation_level(levels, "temperature_c")
    units = ("sample", "curve") if level == "within" else ("specimen", "sample") if level == "piece" else None
    fix, fix_txt = None, " No frequency sweeps at several temperatures: the TTS fix is not evaluated."
    if units is not None:
        b_, a_, held, n_pts = scale_correction_cv(ctx, levels, "temperature_c", units)
        if n_pts:
            fix = fix_record("temperature level trend: prediction x exp(a + b T), b from the other samples",
                             "rms_log_residual", b_, a_, f"leave-one-{held}-out",
                             per_degc=float(np.expm1(t["estimate"])) if "estimate" in t else np.nan,
                             n_held_out_points=n_pts)
            fix_txt = (f" No temperature series of one loading for a mastercurve; a level trend in temperature, "
                       f"fitted within {units[0]}s leaving each {held} out, predicts the held-out curves with "
                       f"{describe_fix(b_, a_)}.")
    # a mastercurve shifts the sweeps of one loading measured at several temperatures; where the temperature changes
    # only between samples or specimens, their sweeps differ by the samples' stiffness too, and the level trend above
    # is the fix that separates the two
    series = level == "within"
    if series and len(distinct_temperatures(s.temperature_c for s in sweeps)) >= MIN_TEMPERATURES:
        full = tts.shift_factors(sweeps)
        ok = np.isfinite(full.log_aT)
        wlf = tts.fit_wlf(full.temperatures_c[ok], full.log_aT[ok], full.log_aT_stderr[ok], full.t_ref_c)
        arr = tts.fit_arrhenius(full.temperatures_c[ok], full.log_aT[ok], full.log_aT_stderr[ok], full.t_ref_c)
        extra.update(shift_factors=full.to_dict(), wlf=wlf, arrhenius=arr)
        cv = leave_one_temperature_out(sweeps)
        names = sorted(set(cv["shift_functions"]))
        fix = fix_record("time-temperature superposition: mastercurve of the training temperatures, log aT(T) by "
                         + "/".join(names or ["WLF"]), "rms_log10_modulus_decades", cv["before"], cv["after"],
                         "leave-one-temperature-out", **({"c1": wlf["c1"], "c2_k": wlf["c2_k"],
                                                          "t_ref_c": full.t_ref_c} if wlf.get("success") else {}))
        extra["held_out"] = cv
        # the fix is scored without the baseline (mastercurve vs temperature-blind prediction of held-out sweeps),
        # so it stands even when no fitted model is adequate (report.diagnose: baseline-free causes)
        extra["baseline_free"] = True
        span = (np.nanmax(full.log_aT) - np.nanmin(full.log_aT)) if ok.any() else np.nan
        fix_txt = (f" Shifting the {len(sweeps)} frequency sweeps gives log aT from {np.nanmax(full.log_aT):+.2f} to "
                   f"{np.nanmin(full.log_aT):+.2f} ({span:.1f} decades, Tref = {full.t_ref_c:.1f} degC, "
                   f"{int((~ok).sum())} NaN)"
                   + (f"; WLF C1 = {wlf['c1']:.3g} +- {wlf['c1_stderr']:.2g}, C2 = {wlf['c2_k']:.3g} +- "
                      f"{wlf['c2_k_stderr']:.2g} K" if wlf.get("success") else "")
                   + f". Leaving each temperature out, the TTS prediction of its sweep errs by {cv['after']:.3g} "
                     f"decades against {cv['before']:.3g} for the temperature-blind prediction ({cv['n_folds']} "
                     f"folds, {cv['n_points']} values).")
    evidence = (f"Curve levels ln(observed/predicted) of {ctx.model} change by {size:+.3g} over "
                f"{lo:.3g}..{hi:.3g} degC across {len(levels)} curves at {len(distinct)} temperatures "
                f"({', '.join(sorted(levels['test'].unique()))}; {design}; "
                f"{'F' if 'joint F of T and T^2 (df' in design else 't'} = {t['statistic']:.2f}, p = {t['p_value']:.2g}).{fix_txt}")
    return make_finding(EFFECT, t, "F" if "joint F of T and T^2 (df" in design else "t", size, "ln(observed/predicted) over the temperature range",
                   abs(size) >= MIN_EFFECT, evidence, fix, **extra)


def _shift_finding(ctx: DiagnosisContext, shift: dict, levels: pd.DataFrame, distinct,
                   level_test: dict | None = None) -> dict:
    """The finding when the shift test (:func:`shift_test`) is the stronger of the two (its p-value then already
    combined with ``level_test``'s) or the only one."""
    t = shift
    tested_alone = level_test is None
    lo, hi = np.nanquantile(levels["temperature_c"], [0.05, 0.95])
    decades = float(t["per_k"] * (hi - lo) / np.log(10.0))
    moved = float(shift["sensitivity_q90"] * abs(t["per_k"]) * (hi - lo))
    before, after, unit, n_pts = _shift_fix(shift)
    fix = fix_record("time-temperature shift of the baseline's relaxation times: a_T = exp(b (T - mean T)), b from "
                     "the other " + unit + "s", "rms_log_residual_within_curve", before, after,
                     f"leave-one-{unit}-out", log10_aT_per_degc=float(t["per_k"] / np.log(10.0)),
                     n_held_out_points=n_pts)
    evidence = (f"The shapes of {ctx.model}'s residuals follow a shift of its time scale with temperature: "
                f"log10 a_T changes by {decades:+.2f} decades over {lo:.3g}..{hi:.3g} degC "
                f"({t['per_k'] / np.log(10.0):+.3g} per degC; read within each curve from d ln(prediction)/d ln a_T "
                f"x (T - mean T), condition x sensitivity controls, {shift['n_clusters']} {shift['cluster_unit']} "
                f"clusters; t = {t['statistic']:.2f}"
                + ("" if tested_alone else f"; combined with the curve-level test (t = "
                   f"{level_test['statistic']:.2f}) by Fisher's method") + f"); over that range it changes the prediction by a factor "
                f"{np.exp(moved):.3g} where the time scale matters (90th percentile of the points). A time shift, not a level: a higher temperature "
                f"makes the material relax sooner. Held out, the shift predicts the {unit}s' curve shapes with "
                f"{describe_fix(before, after)}.")
    return make_finding(EFFECT, t, "t", decades, "decades of log10 a_T over the temperature range",
                        moved >= MIN_EFFECT, evidence, fix, temperatures_c=[float(x) for x in distinct],
                        read_as="time shift")
