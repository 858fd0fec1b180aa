"""Causes read from the raw phase and the instants after a step: inertia-dominated oscillation points
(``inertia_dominated_points``), large-strain yield or slip (``yield_or_slip``) and inertial ringing after a strain
or torque step (``inertial_ringing``).

Criterion (physical, from the raw phase; no fitted threshold)
-------------------------------------------------------------
A combined motor-transducer rheometer measures the raw torque ``M_raw = M_sample + M_inertia``; the
inertial torque ``-I omega^2 theta`` is at 180 deg to the displacement, the sample torque at the sample phase
delta in [0, 90] deg. The raw phase (angle of M_raw to the displacement, the instrument's ``Raw phase``
channel) exceeds :data:`RAW_PHASE_LIMIT_RAD` = 90 deg exactly when the inertial torque exceeds the sample's
in-phase (elastic) torque ``|G*| b theta cos(delta)``: G' is then the difference of two torques of which the
subtracted inertia correction is the larger, i.e. the point lies beyond the instrument-inertia limit
(inertial torque = sample torque; Ewoldt, Johnston & Caretta 2015, "Experimental challenges of shear
rheology: how to avoid bad data", in *Complex Fluids in Biological Systems*, Springer, pp. 207-241;
``science.md`` 2.5: "raw phase -> 180 deg"). Such points are named with their run, angular frequency and
raw phase. The raw phase channel is required: without it the cause is not testable (never inferred from a
default inertia or geometry).

Statistical test and fix (held-out)
-----------------------------------
Fix = excluding the flagged points. It is scored on the points that are *not* flagged: every unflagged point
of a run is left out in turn and predicted by a smooth description of the run (quadratic in log10 omega of
log10 G' and log10 G'', refitted in every fold) fitted to the other points either with the flagged ones
(``before``) or without them (``after``); metric: RMS log10 error (decades) of the held-out G' and G''.
The p-value is the one-sided Wilcoxon signed-rank test (:func:`scipy.stats.wilcoxon`) that the squared
held-out errors are larger with the flagged points than without; ``effect_size`` is the share of
oscillation points that are flagged, practical when >= 1 point is flagged.

Inertial ringing after a strain or torque step (``inertial_ringing``)
--------------------------------------------------------------------
After a fast strain step the motor, geometry and sample form a damped oscillator; the stress of the first
instants rings around the relaxation (the stress may even turn negative, which no relaxing material does).
In the early window of every relaxation curve (0 < t <= sqrt(t_min t_max), the first half in log time) the
baseline's stress residual is regressed on a smooth trend (1, ln t, ln^2 t per curve) with and without a
damped sine ``exp(-(t - t0)/tau) (a sin(2 pi t/P) + b cos(2 pi t/P))`` (a, b per curve; P and tau common;
t from the step, so the phase of a ring triggered by the step is the same in every curve).
P is scanned on a log grid between 4 sampling intervals and half the window (>= 2 cycles), tau in 0.25, 0.5,
1, 2, 4 periods. Test: a ring triggered by the step is *coherent* -- the same phase and relative amplitude in
replicate curves -- whereas noise at the step is not, so the per-curve coefficients (a, b) / stress level
are tested for a zero mean across curves (one-sample Hotelling T^2, F(2, n - 2); >= 3 curves); the p-value of
the best (P, tau) is multiplied by the number of pairs (Bonferroni: the ringing frequency is undefined under
the null). ``effect_size`` = first ring amplitude / stress level of the
window (median over curves), practical when >= 0.05 *and* the measured stress rises again during the hold
in at least half of the curves (:func:`hold_rise_sds`: at constant strain a relaxing material's stress is
monotone, so only a ring makes it rise beyond noise; a coherent residual bump over a monotone stress is the
baseline's misfit near the step, which fired on 5 of 40 null datasets of the independent generator). Fix: the damped-sine term with (P, tau) chosen on the
other curves (same criterion, then refined by least squares); held out: its amplitudes fitted on the even points of a curve and scored on the odd points,
against the trend alone, on the odd points within 3 decay times of the window start.

The same test runs on creep curves (a torque step: the motor's inertia and the sample's compliance ring, so the
strain overshoots and oscillates, Ewoldt et al. 2015), on the measured strain of each creep phase's early window
(the points at which the torque step is held, :func:`creep_hold_mask`: the loading and unloading ramps are not
creep; the smooth trend in log t is projected out by the test, so no baseline is needed); practical when the strain
falls back during the creep (:func:`creep_fall_sds`; a creeping strain never decreases) in at least half of the
curves. The finding reports the stronger of the relaxation and creep tests with a Bonferroni factor 2.

Large-strain yield or slip (``yield_or_slip``)
----------------------------------------------
A raw phase beyond 90 deg means the inertial torque exceeds the sample's in-phase torque -- by inertia at high
frequency, or because the sample's modulus collapsed at large strain (:func:`classify_raw_phase` tells them apart
at each point); the second is named ``yield_or_slip`` (:func:`detect_yield_or_slip`), never inertia.
"""
from __future__ import annotations

import numpy as np
import pandas as pd
import scipy
import xarray as xr
from scipy.linalg import block_diag

from ..io.quality import RAW_PHASE_LIMIT_RAD
from .. import stats as st
from .findings import DiagnosisContext, fix_record, make_finding, untested_finding
from .evidence import run_id
from .noise import robust_noise_sd

EFFECT = "inertia_dominated_points"
#: fewest unflagged points of a run for the held-out score (a quadratic needs 3 + 1 to leave out)
MIN_CLEAN_POINTS = 5
OSCILLATION = ("frequency_sweep", "amplitude_sweep")


def flagged_points(raw_phase_rad: np.ndarray) -> np.ndarray:
    """Boolean mask of inertia-dominated points: raw phase > :data:`RAW_PHASE_LIMIT_RAD` (|raw phase|, so
    exports that report the raw phase as a negative angle are read alike)."""
    return np.abs(np.asarray(raw_phase_rad, float)) > RAW_PHASE_LIMIT_RAD


def _loo_errors(log_w: np.ndarray, log_g: np.ndarray, flagged: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Held-out squared errors of every unflagged point, fitted with (before) and without (after) the
    flagged points (module docstring); arrays of shape (n_clean * 2,)."""
    eb, ea = [], []
    clean = np.flatnonzero(~flagged)
    for i in clean:
        train_all = np.ones(log_w.size, bool)
        train_all[i] = False
        train_clean = train_all & ~flagged
        for k in range(2):
            cb = np.polyfit(log_w[train_all], log_g[train_all, k], 2)
            ca = np.polyfit(log_w[train_clean], log_g[train_clean, k], 2)
            eb.append(np.polyval(cb, log_w[i]) - log_g[i, k])
            ea.append(np.polyval(ca, log_w[i]) - log_g[i, k])
    return np.asarray(eb), np.asarray(ea)


def _angular_frequency(run: xr.Dataset, n: int) -> np.ndarray:
    if "angular_frequency" in run:
        return np.asarray(run["angular_frequency"].values, float)
    if "frequency" in run:
        return 2 * np.pi * np.asarray(run["frequency"].values, float)
    if "frequency_hz" in run.attrs:
        return np.full(n, 2 * np.pi * float(run.attrs["frequency_hz"]))
    return np.full(n, np.nan)


#: share of an amplitude sweep's points, from its smallest amplitude, that give its linear-regime moduli
LINEAR_SHARE = 0.25


def classify_raw_phase(run: xr.Dataset) -> dict:
    """Why each point of an oscillation run has a raw phase beyond 90 deg: the instrument's inertia, or a sample
    that has yielded or slips.

    The raw torque is the sample's plus the inertial torque -I omega^2 theta, so G' - G''/tan(raw phase) = I_cal
    omega^2/b =: X is the inertial modulus at that frequency (science.md 2.5; the same at any amplitude). A point's
    raw phase passes 90 deg when the sample's in-phase modulus falls below X. In a frequency sweep that happens
    because X grows as omega^2 (inertia). In an amplitude sweep (one frequency) X is fixed, so it happens either
    because the whole sweep's frequency is inertia-dominated -- its linear-regime points (the smallest
    :data:`LINEAR_SHARE` of amplitudes) are beyond 90 deg too -- or because the sample's modulus has collapsed
    below X at large strain although the linear modulus stands above it (G'_lin > X): the sample has yielded or
    slips at the wall. Without a raw phase, an amplitude sweep whose linear regime is solid-like (G' > G'') and
    whose G'' overtakes G' at large amplitude (the flow point) is read as yielded beyond the crossover.

    Returns ``{"inertia": mask, "yield": mask, "omega": rad/s, "strain": amplitude or None, "raw_phase": rad or
    None, "linear_storage": Pa, "inertial_modulus": Pa per point}``.
    """
    n = run.sizes.get("point", 0)
    phase = np.asarray(run["raw_phase"].values, float) if "raw_phase" in run else None
    w = _angular_frequency(run, n)
    g1 = np.asarray(run["storage_modulus"].values, float) if "storage_modulus" in run else np.full(n, np.nan)
    g2 = np.asarray(run["loss_modulus"].values, float) if "loss_modulus" in run else np.full(n, np.nan)
    flagged = flagged_points(phase) & np.isfinite(phase) if phase is not None else np.zeros(n, bool)
    out = {"inertia": flagged.copy(), "yield": np.zeros(n, bool), "omega": w, "strain": None, "raw_phase": phase,
           "linear_storage": np.nan, "inertial_modulus": np.full(n, np.nan)}
    if run.attrs.get("test") != "amplitude_sweep" or "shear_strain" not in run:
        return out
    amp = np.abs(np.asarray(run["shear_strain"].values, float))
    out["strain"] = amp
    ok = np.isfinite(amp) & np.isfinite(g1) & (amp > 0)
    if ok.sum() < 4:
        return out
    order = np.argsort(np.where(ok, amp, np.inf))
    linear = order[:max(2, int(np.ceil(LINEAR_SHARE * ok.sum())))]
    g1_lin, g2_lin = float(np.median(g1[linear])), float(np.nanmedian(g2[linear]))
    out["linear_storage"] = g1_lin
    if phase is not None:
        with np.errstate(divide="ignore", invalid="ignore"):
            x = g1 - g2 / np.tan(np.abs(phase))
        out["inertial_modulus"] = x
        linear_inertial = bool(np.any(flagged[linear]))
        collapsed = flagged & (not linear_inertial) & np.isfinite(x) & (g1_lin > x)
        out["yield"] = collapsed
        out["inertia"] = flagged & ~collapsed
    elif np.isfinite(g2_lin) and g1_lin > g2_lin:
        big = ok & (amp > np.max(amp[linear]))
        cross = big & (g2 > g1)
        if cross.any():
            out["yield"] = ok & (amp >= np.min(amp[cross]))
    return out


def detect_inertia_dominated_points(ctx: DiagnosisContext) -> dict:
    """Oscillation points with raw phase beyond 90 deg because of the instrument's inertia (not those of an
    amplitude sweep whose sample has yielded: :func:`classify_raw_phase`); fix = exclude them, scored on held-out
    points."""
    runs = [r for r in ctx.runs if r.attrs.get("test") in OSCILLATION]
    if not runs:
        return untested_finding(EFFECT, "not testable here: no oscillation test")
    with_phase = [r for r in runs if "raw_phase" in r and np.isfinite(np.asarray(r["raw_phase"].values, float)).any()]
    if not with_phase:
        return untested_finding(EFFECT, "not testable here: no raw phase channel in the oscillation exports")
    named, n_total, n_yield = [], 0, 0
    eb, ea = [], []
    for r in with_phase:
        phase = np.asarray(r["raw_phase"].values, float)
        ok = np.isfinite(phase)
        n_total += int(ok.sum())
        cls = classify_raw_phase(r)
        flag = cls["inertia"] & ok
        n_yield += int(cls["yield"].sum())
        w = cls["omega"]
        for i in np.flatnonzero(flag):
            named.append({"run": run_id(r), "point": int(i), "angular_frequency_rad_s": float(w[i]),
                          "raw_phase_deg": float(np.degrees(phase[i]))})
        if not flag.any() or "storage_modulus" not in r or "loss_modulus" not in r:
            continue
        g1 = np.asarray(r["storage_modulus"].values, float)
        g2 = np.asarray(r["loss_modulus"].values, float)
        x = np.log10(w) if r.attrs.get("test") == "frequency_sweep" else np.log10(
            np.abs(np.asarray(r["shear_strain"].values, float))) if "shear_strain" in r else np.full(phase.size, np.nan)
        good = ok & np.isfinite(x) & (g1 > 0) & (g2 > 0) & ~cls["yield"]
        if (good & ~flag).sum() < MIN_CLEAN_POINTS:
            continue
        b, a = _loo_errors(x[good], np.log10(np.column_stack([g1[good], g2[good]])), flag[good])
        eb.append(b)
        ea.append(a)
    share = len(named) / max(n_total, 1)
    yield_txt = (f" {n_yield} amplitude-sweep point(s) beyond 90 deg are not counted: their sample has yielded or "
                 f"slips (yield_or_slip)." if n_yield else "")
    if not named:
        return untested_finding(EFFECT, f"tested, none found: no oscillation point of {n_total} has a raw phase beyond "
                                        f"90 deg because of the instrument's inertia.{yield_txt}") | {
            "tested": True, "p_value": 1.0, "log10_p": 0.0, "statistic": 0.0, "effect_size": 0.0, "points": [],
            "baseline_free": True}
    if not eb:
        out = untested_finding(EFFECT, f"{len(named)} oscillation points have raw phase > 90 deg (inertia-dominated), "
                                       f"but no run keeps >= {MIN_CLEAN_POINTS} clean points to score their exclusion")
        out["points"] = named
        return out
    eb, ea = np.concatenate(eb), np.concatenate(ea)
    test = _wilcoxon_greater(eb, ea)
    before, after = float(np.sqrt(np.mean(eb ** 2))), float(np.sqrt(np.mean(ea ** 2)))
    runs_named = sorted({p["run"] for p in named})
    wmin = min(p["angular_frequency_rad_s"] for p in named)
    evidence = (f"{len(named)} of {n_total} oscillation points ({', '.join(runs_named)}) have a raw phase above 90 deg "
                f"(max {max(p['raw_phase_deg'] for p in named):.1f} deg; from {wmin:.3g} rad/s up): there the inertial "
                f"torque exceeds the sample's in-phase torque. Predicting each clean point from the others, the smooth "
                f"description errs by {before:.3g} decades with these points and {after:.3g} without them "
                f"(one-sided Wilcoxon signed-rank p = {test['p_value']:.2g}).{yield_txt}")
    fix = fix_record("exclude inertia-dominated points (raw phase > 90 deg)", "rms_log10_modulus_held_out_clean_points",
                     before, after, "leave-one-clean-point-out", n_excluded=len(named), n_held_out_points=eb.size)
    # test and fix use the raw phase and a smooth description of each run, never the baseline's predictions
    return make_finding(EFFECT, test, "W", share, "share of oscillation points", len(named) >= 1, evidence, fix,
                        points=named, baseline_free=True)


def _wilcoxon_greater(eb: np.ndarray, ea: np.ndarray) -> dict:
    """One-sided Wilcoxon signed-rank test that the squared held-out errors ``eb`` exceed ``ea``."""
    d = eb ** 2 - ea ** 2
    if np.allclose(d, 0):
        return {"statistic": 0.0, "p_value": 1.0, "log10_p": 0.0}
    w = scipy.stats.wilcoxon(eb ** 2, ea ** 2, alternative="greater")
    p = float(max(w.pvalue, 1e-300))
    return {"statistic": float(w.statistic), "p_value": p, "log10_p": float(np.log10(p))}


YIELD = "yield_or_slip"


def detect_yield_or_slip(ctx: DiagnosisContext) -> dict:
    """Amplitude-sweep points at which the sample has yielded or slips (:func:`classify_raw_phase`: raw phase beyond
    90 deg at a frequency where the linear-regime sample is not inertia-dominated, or beyond the G'/G'' crossover).

    Fix: the sweep restricted to the amplitudes below the yield, scored like the inertia-dominated points on the
    clean points (each predicted by a quadratic in log amplitude of log G', log G'' fitted to the others with and
    without the yielded points; one-sided Wilcoxon signed-rank test of the squared held-out errors). Baseline-free:
    the raw phase and the sweep itself, never the baseline's predictions. ``effect_size``: the smallest yielded
    amplitude; practical when a point has yielded."""
    runs = [r for r in ctx.runs if r.attrs.get("test") == "amplitude_sweep"]
    if not runs:
        return untested_finding(YIELD, "not testable here: no amplitude sweep")
    usable = [r for r in runs if "shear_strain" in r and "storage_modulus" in r]
    if not usable:
        return untested_finding(YIELD, "not testable here: the amplitude sweeps record no strain amplitude or G'")
    points, eb, ea, texts = [], [], [], []
    for r in usable:
        cls = classify_raw_phase(r)
        y = cls["yield"]
        amp = cls["strain"]
        if amp is None or not y.any():
            continue
        g1 = np.asarray(r["storage_modulus"].values, float)
        g2 = np.asarray(r["loss_modulus"].values, float) if "loss_modulus" in r else np.full(g1.size, np.nan)
        phase = cls["raw_phase"]
        for i in np.flatnonzero(y):
            points.append({"run": run_id(r), "point": int(i), "strain": float(amp[i]), "storage_modulus_pa": float(g1[i]),
                           "raw_phase_deg": float(np.degrees(abs(phase[i]))) if phase is not None else np.nan})
        good = np.isfinite(amp) & (amp > 0) & (g1 > 0) & (g2 > 0) & ~cls["inertia"]
        if (good & ~y).sum() >= MIN_CLEAN_POINTS:
            b, a = _loo_errors(np.log10(amp[good]), np.log10(np.column_stack([g1[good], g2[good]])), y[good])
            eb.append(b)
            ea.append(a)
        f_hz = float(np.nanmedian(cls["omega"]) / (2 * np.pi))
        first = int(np.flatnonzero(y)[np.argmin(amp[y])])
        how = (f"raw phase {np.degrees(abs(phase[first])):.0f} deg where the inertial modulus at this frequency is "
               f"{cls['inertial_modulus'][first]:.3g} Pa and the linear G' {cls['linear_storage']:.3g} Pa stands above it"
               if phase is not None else "G'' above G' beyond the crossover of a solid-like sweep")
        texts.append(f"{run_id(r)} at {f_hz:.3g} Hz: from {100 * amp[first]:.3g} % strain G' falls to "
                     f"{g1[first]:.3g} Pa ({100 * g1[first] / cls['linear_storage']:.2g} % of its linear "
                     f"{cls['linear_storage']:.3g} Pa; {how})")
    if not points:
        return untested_finding(YIELD, f"tested, none found: no point of the {len(usable)} amplitude sweep(s) shows a "
                                       f"yield or slip (raw phase beyond 90 deg at a frequency the linear sample is not "
                                       f"inertia-dominated at, or a G'/G'' crossover)") | {
            "tested": True, "p_value": 1.0, "log10_p": 0.0, "statistic": 0.0, "effect_size": np.nan,
            "points": [], "baseline_free": True}
    gamma_y = float(min(p["strain"] for p in points))
    if not eb:
        out = untested_finding(YIELD, f"{len(points)} amplitude-sweep points have yielded or slip ("
                                      + "; ".join(texts) + f"), but no sweep keeps >= {MIN_CLEAN_POINTS} clean points "
                                      "to score their exclusion")
        return out | {"points": points, "yield_strain": gamma_y}
    eb, ea = np.concatenate(eb), np.concatenate(ea)
    test = _wilcoxon_greater(eb, ea)
    before, after = float(np.sqrt(np.mean(eb ** 2))), float(np.sqrt(np.mean(ea ** 2)))
    evidence = ("The sample yields or slips at large strain, not inertia: " + "; ".join(texts)
                + f". Inertia cannot dominate there: at one frequency the inertial torque grows with the amplitude as "
                  f"the sample's does, so only a collapse of the sample's own modulus brings the raw phase beyond 90 "
                  f"deg (yield of the material, or slip at the plates; a second gap or roughened plates tell them "
                  f"apart). Predicting each clean point from the others, the smooth description errs by {before:.3g} "
                  f"decades with the yielded points and {after:.3g} without them (one-sided Wilcoxon p = "
                  f"{test['p_value']:.2g}).")
    fix = fix_record(f"restrict the amplitude sweeps to amplitudes below the yield ({100 * gamma_y:.3g} %)",
                     "rms_log10_modulus_held_out_clean_points", before, after, "leave-one-clean-point-out",
                     yield_strain=gamma_y, n_excluded=len(points), n_held_out_points=eb.size)
    return make_finding(YIELD, test, "W", gamma_y, "strain amplitude (1) of the first yielded point", True, evidence,
                        fix, points=points, yield_strain=gamma_y, baseline_free=True)


# ------------------------------------------------------------------------------------------------
# inertial ringing after a strain step
# ------------------------------------------------------------------------------------------------
RINGING = "inertial_ringing"
#: periods scanned (log grid between 4 sampling intervals and half the early window, so that >= 2 cycles fit)
N_PERIODS = 16
#: damping times scanned, in periods (0.25 period: the amplitude falls e^-2 per half cycle, the strongest
#: damping that still shows a sign change)
DAMPING_IN_PERIODS = (0.25, 0.5, 1.0, 2.0, 4.0)
#: fewest early points of a relaxation curve to scan it
MIN_EARLY_POINTS = 12


def _early_window(g: pd.DataFrame) -> pd.DataFrame:
    """Points of one relaxation curve in its early window: 0 < t <= sqrt(t_min t_max) (the first half of the
    record in log time, where a ringing of the motor-sample system decays)."""
    t = g["time_in_test"].to_numpy(float)
    pos = t[t > 0]
    if pos.size < 3:
        return g.iloc[:0]
    t_w = np.sqrt(pos.min() * pos.max())
    return g[(g["time_in_test"] > 0) & (g["time_in_test"] <= t_w)].sort_values("time_in_test")


def _trend(t: np.ndarray) -> np.ndarray:
    lt = np.log(t)
    lt = (lt - lt.mean()) / max(lt.std(), 1e-12)
    return np.column_stack([np.ones_like(t), lt, lt ** 2])


def _ring(t: np.ndarray, period: float, tau: float) -> np.ndarray:
    w = 2 * np.pi / period
    env = np.exp(-(t - t.min()) / tau)
    return np.column_stack([env * np.sin(w * t), env * np.cos(w * t)])


def _rss(y, X):
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    r = y - X @ coef
    return float(r @ r), coef


def _ring_fits(t: np.ndarray, y: np.ndarray, pairs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ring coefficients (a, b) and residual sum of squares of ``y ~ trend(t) + a e^{-t/tau} sin(w t) +
    b e^{-t/tau} cos(w t)`` for every (period, tau) row of ``pairs``, all at once: the trend is projected out
    (Frisch-Waugh-Lovell), leaving a 2 x 2 normal system per pair. Returns ``(coef (G, 2), rss (G,))``;
    NaN for a pair whose ring columns are degenerate on these points."""
    q, _ = np.linalg.qr(_trend(t))
    yr = y - q @ (q.T @ y)
    pairs = np.atleast_2d(np.asarray(pairs, float))
    env = np.exp(-(t - t.min())[:, None] / pairs[None, :, 1])
    phase = (2 * np.pi / pairs[None, :, 0]) * t[:, None]
    sin_, cos_ = env * np.sin(phase), env * np.cos(phase)
    sin_ -= q @ (q.T @ sin_)
    cos_ -= q @ (q.T @ cos_)
    a11, a12, a22 = (sin_ ** 2).sum(0), (sin_ * cos_).sum(0), (cos_ ** 2).sum(0)
    b1, b2 = sin_.T @ yr, cos_.T @ yr
    det = a11 * a22 - a12 ** 2
    ok = det > 1e-12 * np.maximum(a11 * a22, 1e-300)
    det = np.where(ok, det, np.nan)
    coef = np.column_stack([(a22 * b1 - a12 * b2) / det, (a11 * b2 - a12 * b1) / det])
    rss = float(yr @ yr) - (coef[:, 0] * b1 + coef[:, 1] * b2)
    return coef, rss


#: fewest relaxation curves: the ring is tested as a common (coherent) response to the step across curves
MIN_RINGING_CURVES = 3


def _hotelling(coefs: np.ndarray) -> dict | None:
    """One-sample Hotelling T^2 test that the mean of the per-curve (a, b) ring coefficients is zero:
    F = (n - 2) / (2 (n - 1)) T^2 ~ F(2, n - 2). The curves are the replicates, so within-curve noise that
    decays or is autocorrelated does not enter the error term."""
    n = coefs.shape[0]
    if n < MIN_RINGING_CURVES or not np.isfinite(coefs).all():
        return None
    m = coefs.mean(axis=0)
    S = np.cov(coefs, rowvar=False)
    try:
        t2 = float(n * m @ np.linalg.solve(S, m))
    except np.linalg.LinAlgError:
        return None
    f = (n - 2) / (2.0 * (n - 1)) * t2
    return {"statistic": f, "log10_p": st.log10_p_from_f(f, 2.0, float(n - 2))}


def _grid_coefficients(curves, grid) -> np.ndarray:
    """Per-curve ring coefficients over the grid relative to the curve's stress level: (curves, pairs, 2)."""
    pairs = np.asarray(grid, float)
    return np.stack([_ring_fits(c[1], c[2], pairs)[0] / max(c[3], 1e-300) for c in curves])


def _best_pair(coefs: np.ndarray, grid, full: bool = False):
    """(period, decay) of the grid with the strongest coherent ring (smallest Hotelling p) over the curves
    whose grid coefficients (:func:`_grid_coefficients`) are ``coefs``; with ``full`` also its test, as
    (period, decay, test); None when no pair is testable."""
    best = None
    for k, (p, tau) in enumerate(grid):
        h = _hotelling(coefs[:, k, :])
        if h is not None and (best is None or h["log10_p"] < best[2]["log10_p"]):
            best = (p, tau, h)
    if best is None:
        return None
    return best if full else best[:2]


def _refine(curves, start: tuple[float, float], period_range_s: tuple[float, float]) -> tuple[float, float]:
    """(period, decay) minimising the pooled residual sum of squares of trend + damped sine over ``curves``
    (variable projection, bounded Nelder-Mead in log P and log(tau / P) from the grid's pick). Used for the fix
    only: the p-value stays the grid's (Bonferroni).

    The refinement stays inside the scanned box: P in ``period_range_s`` and tau / P within
    :data:`DAMPING_IN_PERIODS`. Outside it the "ring" is no ring: a period far beyond the window turns the damped
    sine into a smooth exponential transient, which any misfit near the step can take."""
    t = np.concatenate([c[1] for c in curves])
    y = np.concatenate([c[2] / max(c[3], 1e-300) for c in curves])
    # trend and ring amplitudes are per curve: the trends are projected out with one block-diagonal basis,
    # then each curve's 2 x 2 normal system is summed over its segment (np.add.reduceat)
    q = block_diag(*[np.linalg.qr(_trend(c[1]))[0] for c in curves])
    t0 = np.concatenate([np.full(c[1].size, c[1].min()) for c in curves])
    starts = np.cumsum([0] + [c[1].size for c in curves[:-1]])
    yr = y - q @ (q.T @ y)
    total = float(yr @ yr)

    def cost(x):
        period = np.exp(x[0])
        decay = period * np.exp(x[1])
        env = np.exp(-(t - t0) / decay)
        ring = np.column_stack([env * np.sin(2 * np.pi / period * t), env * np.cos(2 * np.pi / period * t)])
        ring -= q @ (q.T @ ring)
        a11, a12, a22 = (np.add.reduceat(v, starts) for v in (ring[:, 0] ** 2, ring[:, 0] * ring[:, 1],
                                                               ring[:, 1] ** 2))
        b1, b2 = np.add.reduceat(ring[:, 0] * yr, starts), np.add.reduceat(ring[:, 1] * yr, starts)
        det = a11 * a22 - a12 ** 2
        ok = det > 1e-12 * np.maximum(a11 * a22, 1e-300)
        explained = np.where(ok, (a22 * b1 ** 2 - 2 * a12 * b1 * b2 + a11 * b2 ** 2) / np.where(ok, det, 1.0), 0.0)
        return total - float(explained.sum())

    x0 = np.log([start[0], start[1] / start[0]])
    bounds = [tuple(np.log(period_range_s)), (np.log(min(DAMPING_IN_PERIODS)), np.log(max(DAMPING_IN_PERIODS)))]
    res = scipy.optimize.minimize(cost, x0, method="Nelder-Mead", bounds=bounds,
                                  options={"xatol": 1e-3, "fatol": 1e-12})
    if not (res.success and cost(res.x) <= cost(x0)):
        return start
    return float(np.exp(res.x[0])), float(np.exp(res.x[0] + res.x[1]))


def hold_rise_sds(e: pd.DataFrame) -> tuple[float, int]:
    """Largest rise of the measured |stress| during the hold of one relaxation curve, in noise SDs.

    At constant strain the stress of any linear or quasi-linear viscoelastic material relaxes monotonically
    (a completely monotone relaxation function), so ``max_j (|s_j| - min_{i<j} |s_i|)`` is noise only; a
    ring makes it large. ``e``: the curve's rows in time order (``residual``, ``predicted`` or ``observed``;
    ``strain``: only points at >= 98 % of the curve's largest |strain|, i.e. the hold, are used when given;
    ``sigma``: per-point noise SD, else :func:`tissuemech.diagnosis.evidence.robust_noise_sd` of the
    stress). Returns (rise / (sqrt(2) median sigma) [1], number of hold points).
    """
    obs = (e["observed"] if "observed" in e else e["predicted"] + e["residual"]).to_numpy(float)
    keep = np.isfinite(obs)
    if "strain" in e and np.isfinite(e["strain"]).any():
        g = np.abs(e["strain"].to_numpy(float))
        keep &= g >= 0.98 * np.nanmax(g)
    s = np.abs(obs[keep])
    if s.size < 3:
        return 0.0, int(s.size)
    sd = float(np.nanmedian(e["sigma"].to_numpy(float)[keep])) if "sigma" in e else robust_noise_sd(s)
    rise = float(np.max(s - np.minimum.accumulate(s)))
    if not (np.isfinite(sd) and sd > 0):
        return (np.inf if rise > 0 else 0.0), int(s.size)
    return rise / (np.sqrt(2.0) * sd), int(s.size)


def creep_fall_sds(t: np.ndarray, strain: np.ndarray) -> tuple[float, int]:
    """Largest fall of the measured |strain| during the creep phase of one creep curve, in noise SDs (the noise:
    :func:`tissuemech.noise.robust_noise_sd` of the strain). Under a constant stress the strain of a
    viscoelastic material never decreases (its creep compliance is monotone), so only a ring makes it fall."""
    s = np.abs(np.asarray(strain, float)[np.argsort(t)])
    s = s[np.isfinite(s)]
    if s.size < 3:
        return 0.0, int(s.size)
    fall = float(np.max(np.maximum.accumulate(s) - s))
    sd = robust_noise_sd(s)
    if not (np.isfinite(sd) and sd > 0):
        return (np.inf if fall > 0 else 0.0), int(s.size)
    return fall / (np.sqrt(2.0) * sd), int(s.size)


def _relaxation_curves(ctx: DiagnosisContext):
    """(curves, rises) of the relaxations: the baseline's stress residual in each early window."""
    t = ctx.table
    if t.empty or "time_in_test" not in t:
        return [], []
    rows = t[(t["test"] == "stress_relaxation") & (t["quantity"] == "shear_stress") & np.isfinite(t["residual"])
             & np.isfinite(t["time_in_test"])]
    curves, rises = [], []
    for cid, g in rows.groupby("curve", sort=False):
        e = _early_window(g)
        if len(e) >= MIN_EARLY_POINTS:
            curves.append((cid, e["time_in_test"].to_numpy(float), e["residual"].to_numpy(float),
                           float(np.median(np.abs(e["predicted"])))))
            rises.append(hold_rise_sds(e))
    return curves, rises


#: relative tolerance of the held torque step of a creep phase (:func:`creep_hold_mask`): a stress controller
#: holds its set point far closer than this; the unloading ramp leaves it at once
HOLD_TOLERANCE = 1e-3


def creep_hold_mask(stress_pa: np.ndarray) -> np.ndarray:
    """Points of a creep test at which the torque step is held: from the first point that reaches the held
    stress to the last one before the stress leaves it.

    The held level is the median |stress| of the points above 90 % of the largest; a point is held when its
    |stress| is within ``max(3 robust SD, HOLD_TOLERANCE x level)`` of it. The loading and unloading ramps are not
    part of the hold (during the unloading the strain falls back with the stress, which is no ring).
    """
    s = np.abs(np.asarray(stress_pa, float))
    mask = np.zeros(s.size, bool)
    if not np.isfinite(s).any() or np.nanmax(s) <= 0:
        return mask
    upper = np.isfinite(s) & (s >= 0.9 * np.nanmax(s))
    level = float(np.median(s[upper]))
    sd = robust_noise_sd(s[upper]) if upper.sum() >= 3 else 0.0
    held = np.isfinite(s) & (np.abs(s - level) <= max(3.0 * (sd if np.isfinite(sd) else 0.0),
                                                      HOLD_TOLERANCE * level))
    if not held.any():
        return mask
    first = int(np.argmax(held))
    # the hold ends where the stress first drops out of it for good: the first point after `first` that is
    # neither held nor followed by held points is the start of the unloading
    left = np.flatnonzero(~held[first:] & (s[first:] < level))
    last = first + int(left[0]) - 1 if left.size else s.size - 1
    mask[first:last + 1] = held[first:last + 1]
    return mask


def _creep_curves(ctx: DiagnosisContext):
    """(curves, falls) of the creep tests: the measured strain of each creep phase's early window (the smooth
    trend in log time is projected out by the test itself, so no baseline is needed)."""
    curves, falls = [], []
    for r in ctx.runs_of("creep_recovery"):
        if "shear_strain" not in r or "time" not in r:
            continue
        t = np.asarray(r["time"].values, float)
        g = np.asarray(r["shear_strain"].values, float)
        keep = np.isfinite(t) & np.isfinite(g)
        if "shear_stress" in r:
            keep &= creep_hold_mask(r["shear_stress"].values)
        if keep.sum() < MIN_EARLY_POINTS:
            continue
        t, g = t[keep], g[keep]
        t = t - t.min() + (t.min() if t.min() > 0 else 0.0)
        frame = pd.DataFrame({"time_in_test": t, "y": g})
        e = _early_window(frame)
        if len(e) >= MIN_EARLY_POINTS:
            y = e["y"].to_numpy(float)
            curves.append((run_id(r), e["time_in_test"].to_numpy(float), y, float(np.median(np.abs(y)))))
            falls.append(creep_fall_sds(t, g))
    return curves, falls


def _ringing_test(curves, rises, kind: str):
    """The coherent-ring test of one kind of curve (module docstring): ``(test, size, period, decay, share, text,
    grid, coefs)`` or a reason (str) why it is not testable."""
    if not curves:
        return f"no {kind} curve with >= {MIN_EARLY_POINTS} points in its early window"
    dt = float(np.median(np.concatenate([np.diff(c[1]) for c in curves])))
    span = float(np.median([c[1].max() - c[1].min() for c in curves]))
    if span < 8 * dt:
        return f"the early {kind} window holds fewer than two oscillation periods at the sampling interval"
    if len(curves) < MIN_RINGING_CURVES:
        return f"{len(curves)} {kind} curve(s); the coherence test of a ringing needs >= {MIN_RINGING_CURVES}"
    periods = np.geomspace(4 * dt, span / 2, N_PERIODS)
    grid = [(p, m * p) for p in periods for m in DAMPING_IN_PERIODS]
    coefs = _grid_coefficients(curves, grid)
    best = _best_pair(coefs, grid, full=True)
    if best is None:
        return f"the ring coefficients of the {kind} curves are degenerate"
    _, _, h = best
    # the best of len(grid) (period, damping) pairs: Bonferroni over the grid (the frequency of a ringing is
    # not defined under the null, so the p-value of the best pair alone would be anti-conservative)
    lp = min(0.0, h["log10_p"] + np.log10(len(grid)))
    test = {"statistic": float(h["statistic"]), "p_value": 10 ** lp, "log10_p": float(lp)}
    # the ring's period and decay: the pair that explains most of the curves' early signal (pooled least squares
    # over the grid, then refined), not the pair of the smallest p (a shared smooth misfit can be the most coherent)
    pairs = np.asarray(grid, float)
    rss = np.sum([_ring_fits(c[1], c[2], pairs)[1] / max(c[3], 1e-300) ** 2 for c in curves], axis=0)
    start = tuple(pairs[int(np.nanargmin(rss))])
    p, tau = _refine(curves, start, (periods[0], periods[-1]))
    amps = []
    for cid, tt, y, level in curves:
        _, coef = _rss(y, np.column_stack([_trend(tt), _ring(tt, p, tau)]))
        amps.append(np.hypot(coef[3], coef[4]) / max(level, 1e-300))
    size = float(np.median(amps))
    # per curve, the rise (relaxation stress) or fall (creep strain) against the Bonferroni normal quantile over
    # its points at ALPHA: a relaxing stress and a creeping strain are monotone, only a ring reverses them
    reversed_ = [r >= scipy.stats.norm.isf(st.ALPHA / (2.0 * max(n, 1))) for r, n in rises]
    share = float(np.mean(reversed_)) if reversed_ else 0.0
    what = "stress rises again during the hold" if kind == "relaxation" else "strain falls back during the creep"
    source = "residuals of the baseline" if kind == "relaxation" else "measured strain (no baseline needed)"
    text = (f"the early {kind} {source} ({len(curves)} curves, t <= sqrt(t_min t_max)) hold a damped "
            f"oscillation: period {p:.3g} s, decay time {tau:.3g} s, first amplitude {100 * size:.3g} % of the level "
            f"(median over curves), coherent across curves (Hotelling F = {h['statistic']:.2f} (2, {len(curves) - 2}) "
            f"on the per-curve ring coefficients over a smooth trend in log t, Bonferroni over {len(grid)} (period, "
            f"decay) pairs); the measured {what} (beyond noise) in {sum(reversed_)} of {len(reversed_)} curves")
    return test, size, p, tau, share, text, grid, coefs


def detect_inertial_ringing(ctx: DiagnosisContext) -> dict:
    """Damped oscillation after a step (module docstring, "Inertial ringing"): in the early relaxation residuals
    (a strain step) and in the early measured creep strain (a torque step), the stronger of the two with a
    Bonferroni factor."""
    results, reasons = {}, []
    for kind, (curves, rises) in (("relaxation", _relaxation_curves(ctx)), ("creep", _creep_curves(ctx))):
        got = _ringing_test(curves, rises, kind)
        if isinstance(got, str):
            reasons.append(got)
        else:
            results[kind] = (got, curves)
    if not results:
        return untested_finding(RINGING, "not testable here: " + "; ".join(reasons))
    kind = min(results, key=lambda k: results[k][0][0]["log10_p"])
    (test, size, p, tau, share, text, grid, coefs), curves = results[kind]
    lp = min(0.0, test["log10_p"] + np.log10(len(results)))
    test = dict(test, log10_p=lp, p_value=10 ** lp)
    evidence = ("; ".join(f"{k}: {v[0][5]}" for k, v in results.items())
                + f". The strongest is the {kind} ring" + (f" (Bonferroni over {len(results)} kinds)" if len(results) > 1
                                                          else "")
                + (". A relaxing or creeping material cannot oscillate: this is the motor-sample system ringing "
                   "after the step." if share >= 0.5 else
                   ". Without a reversal in most curves the pattern is a smooth misfit near the step, not a ring "
                   "(not practical)."))
    practical = bool(size >= 0.05 and share >= 0.5)
    # the held-out fix (a leave-one-curve-out refit of period and decay per curve) is scored only for a ring that
    # could be named: one that is not practical is neither named nor listed as significant without a fix
    fix = _ringing_fix(curves, coefs, grid, p, tau, (grid[0][0], grid[-1][0])) if practical else None
    if not practical:
        evidence += " Held-out fix not scored (not practical)."
    return make_finding(RINGING, test, "F", size, "first ring amplitude / level", practical, evidence,
                        fix, period_s=p, decay_s=tau, hold_rise_share=share, ringing_in=kind)


def _ringing_fix(curves, coefs: np.ndarray, grid, p: float, tau: float, period_range_s: tuple[float, float]) -> dict:
    """Held-out score of the ring: period and decay from the other curves (their grid pick, refined), the
    amplitudes fitted on the even points of the held-out curve and scored on its odd points within 3 decay
    times; before = the trend only."""
    eb, ea = [], []
    for i, (cid, tt, y, level) in enumerate(curves):
        others = [c for j, c in enumerate(curves) if j != i]
        start = _best_pair(np.delete(coefs, i, axis=0), grid) if len(others) >= MIN_RINGING_CURVES else None
        pick = _refine(others, start or (p, tau), period_range_s)
        ev = np.arange(tt.size) % 2 == 0
        od = ~ev & (tt - tt.min() <= 3 * pick[1])      # scored where the ringing is: 3 decay times
        Xb, Xa = _trend(tt), np.column_stack([_trend(tt), _ring(tt, *pick)])
        _, cb = _rss(y[ev], Xb[ev])
        _, ca = _rss(y[ev], Xa[ev])
        if od.any():
            eb.append((y[od] - Xb[od] @ cb) / max(level, 1e-300))
            ea.append((y[od] - Xa[od] @ ca) / max(level, 1e-300))
    if not eb:
        eb, ea = [np.array([np.nan])], [np.array([np.nan])]
    before = float(np.sqrt(np.mean(np.concatenate(eb) ** 2)))
    after = float(np.sqrt(np.mean(np.concatenate(ea) ** 2)))
    return fix_record("damped-sine term (period, decay from the other curves) in the early window, or excluding "
                      f"t < {3 * tau:.3g} s", "rms_rel_residual_odd_points", before, after,
                      "leave-one-curve-out period/decay; amplitudes on even points, scored on odd points",
                      period_s=p, decay_s=tau)
