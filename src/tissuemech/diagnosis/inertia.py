"""Inertia-dominated oscillation points as a named cause (``inertia_dominated_points``).

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
"""
from __future__ import annotations

import numpy as np
from scipy import stats as sps

from .catalogue import DiagnosisContext, fix_record, make_finding, untested_finding
from .evidence import run_id

EFFECT = "inertia_dominated_points"
#: raw phase above which the inertial torque exceeds the sample's in-phase torque (rad; module docstring)
RAW_PHASE_LIMIT_RAD = np.pi / 2
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


def detect_inertia_dominated_points(ctx: DiagnosisContext) -> dict:
    """Oscillation points with raw phase beyond 90 deg; fix = exclude them, scored on held-out points."""
    runs = [r for r in ctx.runs if r.attrs.get("test") in OSCILLATION]
    if not runs:
        return untested_finding(EFFECT, "not testable here: no oscillation test")
    with_phase = [r for r in runs if "raw_phase" in r and np.isfinite(np.asarray(r["raw_phase"].values, float)).any()]
    if not with_phase:
        return untested_finding(EFFECT, "not testable here: no raw phase channel in the oscillation exports")
    named, n_total = [], 0
    eb, ea = [], []
    for r in with_phase:
        phase = np.asarray(r["raw_phase"].values, float)
        ok = np.isfinite(phase)
        n_total += int(ok.sum())
        flag = flagged_points(phase) & ok
        if "angular_frequency" in r:
            w = np.asarray(r["angular_frequency"].values, float)
        elif "frequency" in r:
            w = 2 * np.pi * np.asarray(r["frequency"].values, float)
        else:
            w = np.full(phase.size, np.nan)
        for i in np.flatnonzero(flag):
            named.append({"run": run_id(r), "point": int(i), "angular_frequency_rad_s": float(w[i]),
                          "raw_phase_deg": float(np.degrees(phase[i]))})
        if not flag.any() or "storage_modulus" not in r or "loss_modulus" not in r:
            continue
        g1 = np.asarray(r["storage_modulus"].values, float)
        g2 = np.asarray(r["loss_modulus"].values, float)
        x = np.log10(w) if r.attrs.get("test") == "frequency_sweep" else np.log10(
            np.abs(np.asarray(r["shear_strain"].values, float))) if "shear_strain" in r else np.full(phase.size, np.nan)
        good = ok & np.isfinite(x) & (g1 > 0) & (g2 > 0)
        if (good & ~flag).sum() < MIN_CLEAN_POINTS:
            continue
        b, a = _loo_errors(x[good], np.log10(np.column_stack([g1[good], g2[good]])), flag[good])
        eb.append(b)
        ea.append(a)
    share = len(named) / max(n_total, 1)
    if not named:
        return untested_finding(EFFECT, f"tested, none found: the raw phase of all {n_total} oscillation points "
                                        f"is <= 90 deg") | {"tested": True, "p_value": 1.0, "log10_p": 0.0,
                                                           "statistic": 0.0, "effect_size": 0.0, "points": []}
    if not eb:
        out = untested_finding(EFFECT, f"{len(named)} oscillation points have raw phase > 90 deg (inertia-dominated), "
                                       f"but no run keeps >= {MIN_CLEAN_POINTS} clean points to score their exclusion")
        out["points"] = named
        return out
    eb, ea = np.concatenate(eb), np.concatenate(ea)
    d = eb ** 2 - ea ** 2
    if np.allclose(d, 0):
        test = {"statistic": 0.0, "p_value": 1.0, "log10_p": 0.0}
    else:
        w = sps.wilcoxon(eb ** 2, ea ** 2, alternative="greater")
        p = float(max(w.pvalue, 1e-300))
        test = {"statistic": float(w.statistic), "p_value": p, "log10_p": float(np.log10(p))}
    before, after = float(np.sqrt(np.mean(eb ** 2))), float(np.sqrt(np.mean(ea ** 2)))
    runs_named = sorted({p["run"] for p in named})
    wmin = min(p["angular_frequency_rad_s"] for p in named)
    evidence = (f"{len(named)} of {n_total} oscillation points ({', '.join(runs_named)}) have a raw phase above 90 deg "
                f"(max {max(p['raw_phase_deg'] for p in named):.1f} deg; from {wmin:.3g} rad/s up): there the inertial "
                f"torque exceeds the sample's in-phase torque. Predicting each clean point from the others, the smooth "
                f"description errs by {before:.3g} decades with these points and {after:.3g} without them "
                f"(one-sided Wilcoxon signed-rank p = {test['p_value']:.2g}).")
    fix = fix_record("exclude inertia-dominated points (raw phase > 90 deg)", "rms_log10_modulus_held_out_clean_points",
                     before, after, "leave-one-clean-point-out", n_excluded=len(named))
    return make_finding(EFFECT, test, "W", share, "share of oscillation points", len(named) >= 1, evidence, fix,
                        points=named)
