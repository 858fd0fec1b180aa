"""Causes read from curve levels (one level per curve from the baseline's residuals): elapsed-time drift,
preconditioning (first load) and an outlier specimen, the within-sample mixed-model test they share
(:func:`within_test`: specimen and sample as random effects, the covariate read within samples, else within
specimens) and the confounded-covariate bookkeeping. Detectors of the registry :mod:`.causes`."""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd
import xarray as xr

from .. import stats as st
from ..curves import distinct_temperatures
from ..tts import run_temperature_c
from .evidence import condition_label, run_id
from .findings import (DiagnosisContext, curve_levels, demean_by, fix_record, make_finding, primary_rows, rms,
                       separating_design, untested_finding)

# ------------------------------------------------------------------------------------------------
# curve-level scale: elapsed-time drift, preconditioning, outlier specimen
# ------------------------------------------------------------------------------------------------
#: within-sample |correlation| above which two curve-level covariates are reported as confounded
CONFOUND_CORRELATION = 0.9

def _within_corr(levels: pd.DataFrame, a: str, b: str, between_samples: bool = False) -> float:
    """Correlation of two curve-level covariates after removing sample means, or with ``between_samples`` of their
    sample means after removing specimen means (the variation :func:`within_test` reads there); NaN when
    undefined."""
    lv = levels[levels[a].notna() & levels[b].notna()]
    if between_samples:
        lv = lv.groupby("sample").agg(**{a: (a, "mean"), b: (b, "mean"), "specimen": ("specimen", "first")})
    if len(lv) < 3:
        return np.nan
    group = "specimen" if between_samples else "sample"
    x, y = demean_by(lv, a, group), demean_by(lv, b, group)
    if x.std() == 0 or y.std() == 0:
        return np.nan
    return float(np.corrcoef(x, y)[0, 1])


def _condition_share(levels: pd.DataFrame, column: str) -> float:
    """Share of the within-sample variance of ``column`` explained by the test condition (1 for a fixed
    test order with equal pauses; a squared multiple correlation)."""
    lv = levels[levels[column].notna()]
    x = demean_by(lv, column, "sample")
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


def _varies_within(x: pd.Series, groups: pd.Series) -> bool:
    return bool((x - x.groupby(groups).transform("mean")).abs().max() > 1e-12 * max(float(x.abs().max()), 1e-300))


def within_test(levels: pd.DataFrame, column: str, controls: Sequence[str] = (),
                confounded_within: bool = True, between_samples: bool = False) -> tuple[dict, str] | None:
    """Mixed-model test of ``column`` read within samples, else within specimens: the condition as fixed effects,
    specimen and sample as random effects (:func:`tissuemech.stats.mixed_coefficient_test`, between-within
    degrees of freedom). Within samples, the column and its ``controls`` are centred on their sample's mean; where
    that leaves nothing testable (one curve per sample, or, with ``confounded_within`` False, a fixed test order that
    makes the column follow the condition: :func:`_condition_share` at least :data:`CONFOUND_CORRELATION` squared),
    each sample's mean, centred on its specimen's mean, is tested across the samples of a specimen. So a
    trend of the session clock is read inside a specimen, never from the specimens' differences (a block design
    measures the specimens one after the other). ``between_samples``: the read between the samples of a specimen
    only. Returns ``(test, design sentence)`` or None."""
    factors = ("condition",) if levels["condition"].nunique() > 1 else ()
    cols = [column, *controls]
    x = {c: levels[c].astype(float) for c in cols}
    # a column the condition explains within samples (a fixed test order with equal pauses) leaves the within-sample
    # regression only its clock jitter to read: a misfit that differs by condition would pass for its effect
    readable = confounded_within or _condition_share(levels, column) < CONFOUND_CORRELATION ** 2
    if _varies_within(x[column], levels["sample"]) and readable and not between_samples:
        frame = levels.assign(**{c: x[c] - x[c].groupby(levels["sample"]).transform("mean") for c in cols})
        t = st.mixed_coefficient_test(frame, "log_scale", column, factors, controls=tuple(controls))
        if t is not None:
            return t, (f"within samples (condition fixed effects, specimen and sample random effects"
                       + (f", controlled for {', '.join(controls)}" if controls else "") + f"; {t['method']})")
    means = {c: x[c].groupby(levels["sample"]).transform("mean") for c in cols}
    if not _varies_within(means[column], levels["specimen"]):
        return None
    frame = levels.assign(**{c: means[c] - means[c].groupby(levels["specimen"]).transform("mean") for c in cols})
    t = st.mixed_coefficient_test(frame, "log_scale", column, factors, controls=tuple(controls))
    if t is None:
        return None
    return t, (f"between the samples of each specimen (sample means centred on the specimen's; condition fixed "
               f"effects, specimen and sample random effects" + (f", controlled for {', '.join(controls)}"
                                                                 if controls else "") + f"; {t['method']})")


def clock_test(levels: pd.DataFrame, column: str, controls: Sequence[str] = ()) -> tuple[dict, str] | None:
    """The one read of a session clock (elapsed time, or the position in the sequence where no time was recorded)
    on the curve levels, for the drift detector and the covariates table alike: within samples where the condition
    does not explain the clock there (``confounded_within`` False of :func:`within_test`), and between the samples of
    each specimen; the read with the smaller standard error is kept (a choice that does not depend on the slope).
    With a fixed test order and regular pauses the within-sample read has only the jitter of the pauses to go on,
    and a misfit that differs by condition would pass for a trend; between the samples of a specimen the clock
    moves by a whole sample's sequence. Where neither read exists (one sample per specimen in a fixed order), the
    within-sample read is returned with ``confounded_with_condition`` True: its slope cannot be told from a misfit
    that differs by condition, and the reader says so. Returns ``(test, design sentence)`` or None."""
    first = within_test(levels, column, controls, confounded_within=False)
    if first is None:
        # within_test already fell back to the between-samples read: none exists, only the confounded one may
        confounded = within_test(levels, column, controls)
        return None if confounded is None else (dict(confounded[0], confounded_with_condition=True), confounded[1])
    if not first[1].startswith("within samples"):
        return first
    reads = [r for r in (first, within_test(levels, column, controls, between_samples=True)) if r is not None]
    finite = [r for r in reads if np.isfinite(r[0].get("std_error", np.nan))] or reads
    return min(finite, key=lambda r: r[0].get("std_error", np.inf))


def _level_tests(levels: pd.DataFrame, column: str):
    """Curve-level test of ``column`` (elapsed time or first load) within samples, else within specimens
    (:func:`within_test`), controlled for the other and for the logged temperature where the design allows (the
    largest estimable set of controls). Returns ``(test, design)`` or ``(None, None)``; ``test`` carries
    ``controls`` (the covariates held fixed) and ``confounded_with`` (covariates whose within-sample correlation
    with ``column`` reaches :data:`CONFOUND_CORRELATION`, or ``condition`` when the condition explains that share
    squared of its within-sample variance, with the design that would separate them in ``separating_design``).
    Elapsed time is read with the first-load control when the first loads are known and not absorbed by the
    condition effects (a within-sample trend needs two curves after the first load; otherwise the slope is the
    first-load contrast). Elapsed time falls back to the position in the sequence when no time was recorded.
    The first load, collinear with the condition within samples in a fixed test order, is reported as confounded
    with the condition when it is read within samples. Elapsed time is read by :func:`clock_test` (the read the
    covariates table makes too): within samples only where the condition does not explain the clock there, and
    between the samples of each specimen, the read with the smaller standard error kept; with a fixed order and
    regular pauses the within-sample read had only the jitter of the pauses to go on (a slope of hundreds per hour
    with a standard error to match).
    Measured on generated null level tables the between-samples read keeps its level (1.1 % at p < 0.01), where
    reading the specimens' differences through their random effect does not (3.5 %; docs/calibration.md)."""
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
    # a logged temperature that stays within one set point (curves.distinct_temperatures) is sensor noise: a control
    # of it would only spend a degree of freedom of the between-samples read
    controls = [c for c in (other, "temperature_c") if c in levels and _usable(levels, c)
                and (c != "temperature_c" or len(distinct_temperatures(levels[c])) > 1)]
    if "first_load" in controls and levels.groupby("condition")["first_load"].nunique().max() == 1:
        controls.remove("first_load")  # each condition always or never first: the condition effects absorb it
    combos = [[column] + controls] + ([[column, controls[0]]] if len(controls) > 1 else []) + [[column]]
    if column == "elapsed_h" and "first_load" in controls:
        # a trend within a sample needs two curves after its first load: without them the within-sample
        # slope is the first-load contrast itself (preconditioning), so it is only read with that control
        combos = [c for c in combos if "first_load" in c]
    found = None
    for cols in combos:
        got = clock_test(levels, column, cols[1:]) if column == "elapsed_h" else within_test(levels, column, cols[1:])
        if got is not None:
            found = (dict(got[0], controls=cols[1:]), got[1])
            break
    if found is None:
        return None, None
    t, design = found
    confounded = []
    # the first load is position 1: only time and temperature can be confounded with it
    candidates = ("elapsed_h", "temperature_c") if column == "first_load" else (
        ("position", "first_load", "temperature_c") if time_recorded else ("first_load", "temperature_c"))
    within = design.startswith("within samples")
    for c in candidates:  # a control nearly collinear with the covariate still cannot be separated from it
        if c in levels and abs(_within_corr(levels, column, c, between_samples=not within)) >= CONFOUND_CORRELATION:
            confounded.append(c)
    if within and _condition_share(levels, column) >= CONFOUND_CORRELATION ** 2:
        confounded.append("condition")
    return dict(t, confounded_with=confounded, separating_design=[separating_design(c) for c in confounded]), design


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
    out = st.statistic_result(tval, st.log10_p_from_t(tval, x.size - 1), estimate=float(x.mean()), n=x.size)
    out["kinds"] = sorted(kinds)
    return out


def scale_correction_cv(ctx: DiagnosisContext, levels: pd.DataFrame, column: str,
                        units: tuple[str, str] | None = None) -> tuple[float, float, str, int]:
    """Held-out gain of a curve-level covariate (elapsed time, first load, temperature).

    ``units`` (unit, held): with ("sample", "curve") -- the default with >= 3 curves per sample -- leave one curve
    out and predict its level from the other curves of the same sample (baseline: their mean; fix: their mean
    adjusted by b * column, b fitted within samples without the held-out curve); with ("specimen", "sample") --
    the default otherwise, and the unit of a covariate that changes only between samples -- leave one sample out
    and use the specimen's other samples. Error: log(observed/predicted) at every point of the held-out curve.
    Returns (RMS error before, after, the held-out unit, the number of held-out points)."""
    if column == "elapsed_h" and levels["elapsed_h"].isna().any():
        levels = levels.assign(elapsed_h=levels["position"].astype(float))
    levels = levels[levels[column].notna()]
    if levels.empty:
        return np.nan, np.nan, "curve", 0
    rows = primary_rows(ctx.table)
    point_errors = {c: g.to_numpy(float) for c, g in rows.groupby("curve")["log_ratio"]}
    by_sample = levels.groupby("sample").size().min() >= 3
    unit, held = units or (("sample", "curve") if by_sample else ("specimen", "sample"))
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
        return np.nan, np.nan, held, 0
    b = np.concatenate(before)
    return rms(b), rms(np.concatenate(after)), held, int(np.isfinite(b).sum())


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
            "separating_design": [separating_design("temperature_c")]}
    t, design = _level_tests(levels, "elapsed_h")
    if t is None:
        return untested_finding(eff, "elapsed time (total_time/started_at) and the test order do not vary across "
                              "curves in a way that is not confounded with the test conditions; a design that "
                              f"would: {separating_design('condition')}"
                              + ("" if _usable(levels, "elapsed_h") else f"; {separating_design('elapsed_h')}"))
    kappa = float(np.expm1(t["estimate"]))
    use_time = _usable(levels, "elapsed_h")
    unit = "1/h" if use_time else "1/test"
    span = float(levels["elapsed_h"].max() - levels["elapsed_h"].min()) if use_time else float(
        levels["position"].max() - levels["position"].min())
    before, after, group, n_held = scale_correction_cv(
        ctx, levels, "elapsed_h", None if design.startswith("within samples") else ("specimen", "sample"))
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
               before, after, f"leave-one-{group}-out", kappa_per_unit=kappa, n_held_out_points=n_held)
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
    per_sample: dict[tuple, int] = {}
    for r in ctx.runs:
        key = (str(r.attrs.get("specimen")), str(r.attrs.get("sample")))
        per_sample[key] = per_sample.get(key, 0) + 1
    if per_sample and max(per_sample.values()) == 1:
        return untested_finding(eff, f"every one of the {len(per_sample)} samples has a single test: no first load "
                                     f"can be compared with a later test of the same sample; a design that would: "
                                     f"{separating_design('first_load')}")
    if levels.empty:
        return untested_finding(eff, "no curve of these data has a level from the baseline (it predicts none of "
                                     "the tests)")
    if levels["first_load"].isna().all():
        return untested_finding(eff, "the measuring order of the tests on each sample is unknown (no distinct order, "
                                     "started_at or total_time within a sample): the first load cannot be identified")
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
                              f"would: {separating_design('first_load')}")
    t, design = min(found, key=lambda f: f[0]["log10_p"])
    lp = min(0.0, t["log10_p"] + np.log10(len(found)))
    t = dict(t, log10_p=lp, p_value=10 ** lp)
    delta = float(np.expm1(t["estimate"]))
    before, after, group, n_held = scale_correction_cv(ctx, levels, "first_load")
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
               "rms_log_residual", before, after, f"leave-one-{group}-out", first_load_factor=1 + delta,
               n_held_out_points=n_held)
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
        n_runs = len({str(r.attrs.get("specimen")) for r in ctx.runs})
        have = (f"{n_spec} specimen{'s' if n_spec != 1 else ''} with a curve level" if n_spec else
                f"no curve with a level from the baseline ({n_runs} specimen{'s' if n_runs != 1 else ''} in the runs)")
        return untested_finding(eff, f"not testable here: {have}; an outlier specimen needs at least 3 specimens "
                                     "(one tested against the spread of at least two others)")
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
        if per_sample["specimen"].value_counts().max() > 1:  # one row per sample: the residual is within-specimen
            mixed = st.mixed_effects(per_sample, "resid", sample=None, method=None)
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
    before, after = rms(np.concatenate(errs_before)), rms(np.concatenate(errs_after))
    mixed_txt = ""
    if mixed is not None and "sd_specimen" in mixed:
        mixed_txt = (f"; MixedLM on log-scales: omega_between = {mixed['sd_specimen']:.2f}, omega_within = "
                     f"{mixed['sd_sample']:.2f}, standardized BLUP of {name} = "
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
