"""Diagnosis of homogeneous-specimen data: simple shear plus uniaxial compression and tension (Budday et al.).

A hyperelastic law calibrated on simple shear alone predicts compression and tension badly when the tissue
is stiffer in compression than an ``W(I1)`` law allows. This module names the cause, fits all modes
jointly and scores the cross-mode predictions.

Why shear alone cannot tell
---------------------------
In simple shear ``I1 = I2 = 3 + gamma^2`` and ``sigma12 = 2 gamma (W1 + W2)``: only the sum of the I1 and I2
derivatives enters, so for ``W = ... + C10 (I1 - 3) + C01 (I2 - 3)`` the Jacobian columns of C10 and C01 are
identical (correlation +1, the fitted correlation -> -1) and the profile of chi-square over C01 is flat. In
uniaxial loading ``P = 2 (lambda - lambda^-2)(W1 + W2 / lambda)``: the I2 term weighs more in compression
(lambda < 1) than in tension, which is the tension-compression asymmetry of brain tissue. (A one-term Ogden
law has the same blind spot: its shear response is identical for alpha and -alpha.)

Findings (the :mod:`.report` JSON contract)
-------------------------------------------
``tension_compression_asymmetry`` (id :data:`ASYMMETRY_ID`)
    The baseline -- the I1-only law of :data:`PAIRS` with the lowest shear-only AICc -- is calibrated on
    simple shear and predicts both uniaxial modes. Statistic: the difference of the mean log ratios
    ln(observed/predicted) in compression and in tension, ``Delta = <r>_c - <r>_t`` (> 0: the data are
    stiffer in compression relative to tension than the model), z-tested against the measurement noise
    (:class:`tissuemech.fitting.NoiseModel`, 1 % + floor, independent under H0). Practical when
    ``|Delta| >=`` :data:`MIN_ASYMMETRY`. Fix: the I2-extended law calibrated on shear plus the *other*
    uniaxial mode; metric: NRMSE on the held-out uniaxial mode (fit shear+tension -> predict compression
    and fit shear+compression -> predict tension), before = the shear-only baseline on that mode.
``unidentified_i2_dependence``
    From shear alone: the C10/C01 Jacobian-column correlation and the flat C01 profile (reported in
    ``not_identifiable``). From all modes jointly: nested F-test of the baseline against its I2 extension
    (weighted chi-square, effective n from the lag-1 residual autocorrelation), C01 with its profile
    confidence interval; practical when ``|C01| >=`` :data:`MIN_I2_SHARE` ``|C10 + C01|``. Fix: the
    extension; metric: held-out NRMSE averaged over the three leave-one-mode-out rotations (fit
    shear+tension -> compression, shear+compression -> tension, tension+compression -> shear), before =
    the baseline law trained on the same modes; ``delta_aicc`` of the joint fits.

The parallel-plate causes of the catalogue are reported as untested (no plates, no time or rate data).
``unexplained``: runs tests on the residual signs of the joint fix fit, per mode (structure no named cause
accounts for, e.g. a higher-order law would be needed). A cause is named by the one decision rule of
:mod:`.decision` (:data:`~tissuemech.diagnosis.decision.DECISION_RULE`, as for parallel-plate data): Holm at
``alpha/2`` within the named causes and within the structure tests, practical relevance, and a fix whose
leave-one-mode-out improvement beats the noise margin (eps: the relative noise of the runs, from their own
scatter, :func:`tissuemech.noise.relative_noise_level`); a significant, relevant cause without a scored
fix goes to ``significant_fix_not_evaluated``. The JSON carries ``decision_rule`` and ``noise_model`` as the
parallel-plate diagnosis does.

``cross_mode`` (extra JSON block): every candidate law's shear-only predictions of compression and tension,
its joint fit (AICc, parameters, stability flags) and every rotation's held-out NRMSE, with the gains.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
import xarray as xr

from .. import fitting as F
from ..models.hyperelastic import stability_flags
from ..models.registry import get_model
from .. import stats as st
from .causes import CATALOGUE_IDS
from .decision import DECISION_RULE, apply_rule, ordered
from .findings import fix_record, untested_finding
from .noise import estimate_noise, relative_noise_level

ASYMMETRY_ID = "tension_compression_asymmetry"
I2_ID = "unidentified_i2_dependence"
#: ids reported by the homogeneous diagnosis: the catalogue plus the cross-mode asymmetry
HOMOGENEOUS_IDS: tuple[str, ...] = (ASYMMETRY_ID,) + CATALOGUE_IDS
HOMOGENEOUS_TESTS = frozenset({"simple_shear", "uniaxial"})
MODES = ("shear", "compression", "tension")
#: leave-one-mode-out rotations: (training modes, held-out mode)
ROTATIONS: tuple[tuple[tuple[str, ...], str], ...] = (
    (("shear", "tension"), "compression"), (("shear", "compression"), "tension"),
    (("compression", "tension"), "shear"))
#: practical size of the asymmetry: 5 % in the compression/tension log ratio
MIN_ASYMMETRY = 0.05
#: practical size of the I2 term: 10 % of C10 + C01 (the initial shear modulus is 2 (C10 + C01))
MIN_I2_SHARE = 0.1
#: points whose magnitude is below this many noise SDs carry no log-ratio information (near lambda = 1)
MIN_SNR = 5.0
#: a profile is flat when chi-square varies by less than this fraction of its minimum over the grid
FLAT_PROFILE = 1e-6
#: Delta chi2 / s^2 of a 95 % profile interval (F(1, inf) quantile)
PROFILE_95 = 3.841

_SIGNED = (-1e7, 1e7)
#: effort of the pipeline entry (:func:`tissuemech.diagnosis.report.run_homogeneous_diagnosis`): random starts per fit, C01 profile points
SETTINGS = {"n_random": 4, "n_grid": 41}


@dataclass(frozen=True)
class Law:
    """A hyperelastic candidate: registry model, parameters held fixed, bounds overridden.

    I2 laws fit C10 and C01 with signed bounds: the data, not the prior, say whether C10 > 0 (stability is
    checked on the fitted parameters and reported)."""

    key: str
    model: str
    i2: bool | None
    formula: str
    fixed: Mapping[str, float] = field(default_factory=dict)
    bounds: Mapping[str, tuple[float, float]] = field(default_factory=dict)


LAWS: dict[str, Law] = {law.key: law for law in (
    Law("neo_hookean", "neo_hookean", False, "W = mu/2 (I1 - 3)"),
    Law("mooney_rivlin", "mooney_rivlin", True, "W = C10 (I1 - 3) + C01 (I2 - 3)",
        bounds={"C10": _SIGNED, "C01": _SIGNED}),
    Law("reduced_polynomial2", "reduced_polynomial2", False, "W = C10 (I1 - 3) + C20 (I1 - 3)^2"),
    Law("reduced_polynomial2_i2", "polynomial2", True, "W = C10 (I1 - 3) + C20 (I1 - 3)^2 + C01 (I2 - 3)",
        fixed={"C11": 0.0, "C02": 0.0}, bounds={"C10": _SIGNED, "C01": _SIGNED}),
    Law("ogden1", "ogden1", None, "W = 2 mu1/alpha1^2 (l1^alpha1 + l2^alpha1 + l3^alpha1 - 3)"),
)}
#: (I1-only baseline, its I2 extension)
PAIRS: tuple[tuple[str, str], ...] = (("reduced_polynomial2", "reduced_polynomial2_i2"),
                                      ("neo_hookean", "mooney_rivlin"))


# ------------------------------------------------------------------------------------------------
# data
# ------------------------------------------------------------------------------------------------
def is_homogeneous(runs: Sequence[xr.Dataset]) -> bool:
    """True when every run is a homogeneous simple-shear or uniaxial test (no parallel plates)."""
    return bool(runs) and all(str(r.attrs.get("test")) in HOMOGENEOUS_TESTS for r in runs)


def mode_of(run: xr.Dataset) -> str:
    """``shear``, ``compression`` or ``tension``: the ``covariate_mode`` attribute, else the stretch side."""
    test = str(run.attrs.get("test"))
    if test == "simple_shear":
        return "shear"
    if test != "uniaxial":
        raise ValueError(f"run {run.attrs.get('run', '?')}: test {test!r} is not a homogeneous mode")
    mode = str(run.attrs.get("covariate_mode", run.attrs.get("mode", ""))).lower()
    if mode in ("compression", "tension"):
        return mode
    lam = np.asarray(run["stretch"].values, float)
    lam = lam[np.isfinite(lam) & (lam != 1.0)]
    if lam.size == 0:
        raise ValueError(f"run {run.attrs.get('run', '?')}: uniaxial run without stretch != 1")
    return "compression" if np.median(lam) < 1.0 else "tension"


def mode_curves(runs: Sequence[xr.Dataset]) -> dict[str, list[tuple[str, F.Curve]]]:
    """Mode -> [(run id, curve)] of the runs; every mode of :data:`MODES` must be present."""
    out: dict[str, list[tuple[str, F.Curve]]] = {m: [] for m in MODES}
    for r in runs:
        out[mode_of(r)].append((str(r.attrs.get("run", "?")), F.curve_from_run(r)))
    missing = [m for m in MODES if not out[m]]
    if missing:
        have = sorted({f"{r.attrs.get('run', '?')} ({mode_of(r)})" for r in runs})
        raise ValueError(f"the multi-mode diagnosis needs simple shear, compression and tension runs; "
                         f"missing {missing} among {have}")
    return out


def _curves(by_mode: Mapping[str, list[tuple[str, F.Curve]]], modes: Sequence[str]) -> list[F.Curve]:
    return [c for m in modes for _, c in by_mode[m]]


# ------------------------------------------------------------------------------------------------
# fits and predictions
# ------------------------------------------------------------------------------------------------
def problem(law: Law, curves: Sequence[F.Curve], fixed: Mapping[str, float] | None = None,
            scope: str = "") -> F.FitProblem:
    return F.FitProblem(model=get_model(law.model), curves=list(curves), target="none", model_key=law.key,
                        fixed={**law.fixed, **(fixed or {})}, bounds=dict(law.bounds), scope=scope)


def fit_law(law: Law, curves: Sequence[F.Curve], seed: int = 0, n_random: int = 4,
            fixed: Mapping[str, float] | None = None, start: Mapping[str, float] | None = None,
            scope: str = "") -> F.FitResult:
    """Weighted least-squares fit of ``law`` to the curves jointly (:func:`tissuemech.fitting.fit`)."""
    return F.fit(problem(law, curves, fixed, scope), starts=[start] if start else (), n_random=n_random, seed=seed)


def predict_stress(law: Law, params: Mapping[str, float], curve: F.Curve) -> np.ndarray:
    """Stress the law predicts at the curve's points (P12 for shear, P11 for uniaxial; Pa)."""
    pred = F.predict(get_model(law.model), params, curve, "none")
    return np.asarray(next(iter(pred.values())), float)


def _observed(curve: F.Curve) -> np.ndarray:
    return np.asarray(next(iter(curve.observed.values())), float)


def _sigma(curve: F.Curve, y: np.ndarray) -> np.ndarray:
    name = next(iter(curve.observed))
    return F.NoiseModel().sigma(name, y, None)


def log_ratios(law: Law, params: Mapping[str, float], curves: Sequence[F.Curve]) -> tuple[np.ndarray, np.ndarray]:
    """ln(observed/predicted) and its noise SD at the points where both are well above the noise and of
    the same sign (near zero strain the ratio carries no information)."""
    r, s = [], []
    for c in curves:
        y, f = _observed(c), predict_stress(law, params, c)
        sig = _sigma(c, f)
        ok = (np.abs(f) > MIN_SNR * sig) & (np.abs(y) > MIN_SNR * sig) & (np.sign(y) == np.sign(f))
        r.append(np.log(y[ok] / f[ok]))
        s.append(sig[ok] / np.abs(f[ok]))
    return np.concatenate(r), np.concatenate(s)


def held_out_error(law: Law, params: Mapping[str, float], curves: Sequence[F.Curve]) -> dict:
    """NRMSE (RMSE / mean |observed|), RMSE [Pa], mean log ratio and the relative error at the largest
    strain of held-out curves."""
    ev = F.evaluate(get_model(law.model), params, list(curves), "none")
    lr, _ = log_ratios(law, params, curves)
    c = max(curves, key=lambda c: np.nanmax(np.abs(_observed(c))))
    y, f = _observed(c), predict_stress(law, params, c)
    i = int(np.nanargmax(np.abs(y)))
    return {"nrmse": ev["nrmse"], "rmse_pa": ev["rmse"], "mean_log_ratio": float(np.mean(lr)) if lr.size else np.nan,
            "rel_error_at_max": float((f[i] - y[i]) / y[i])}


def jacobian_correlation(law: Law, params: Mapping[str, float], curves: Sequence[F.Curve], a: str, b: str) -> float:
    """Correlation (cosine) of the weighted-residual Jacobian columns of parameters ``a`` and ``b``
    (central differences). +-1: the data see only a combination of the two (the fitted correlation of the
    estimates tends to -+1 and the covariance is singular)."""
    prob = problem(law, curves)
    base = dict(params)

    def resid(p):
        return np.concatenate([w for t in prob.curve_terms(p) for (_, _, w) in t.values()])

    cols = []
    for name in (a, b):
        h = 1e-6 * max(abs(base[name]), 1.0)
        up, dn = dict(base), dict(base)
        up[name] += h
        dn[name] -= h
        cols.append((resid(up) - resid(dn)) / (2 * h))
    u, v = cols
    return float(np.dot(u, v) / np.sqrt(np.dot(u, u) * np.dot(v, v)))


def profile_c01(law: Law, curves: Sequence[F.Curve], grid: np.ndarray, start: Mapping[str, float],
                seed: int = 0) -> np.ndarray:
    """Chi-square with C01 held at each grid value and every other parameter refitted (profile)."""
    out = np.empty(grid.size)
    for i, c01 in enumerate(grid):
        res = fit_law(law, curves, seed=seed, n_random=1, fixed={"C01": float(c01)}, start=start)
        out[i] = res.chisqr
    return out


def profile_interval(grid: np.ndarray, delta: np.ndarray, best: float, level: float = PROFILE_95) -> tuple[float, float]:
    """Interval where the scaled profile ``delta`` stays below ``level`` (linear interpolation); NaN at an
    end where the profile never rises above it (unbounded on that side within the grid)."""
    inside = delta <= level
    i0 = int(np.argmin(np.abs(grid - best)))
    lo = hi = np.nan
    j = i0
    while j > 0 and inside[j - 1]:
        j -= 1
    if j > 0:
        lo = float(np.interp(level, [delta[j], delta[j - 1]], [grid[j], grid[j - 1]]))
    j = i0
    while j < grid.size - 1 and inside[j + 1]:
        j += 1
    if j < grid.size - 1:
        hi = float(np.interp(level, [delta[j], delta[j + 1]], [grid[j], grid[j + 1]]))
    return lo, hi


# ------------------------------------------------------------------------------------------------
# the diagnosis
# ------------------------------------------------------------------------------------------------
def _params_txt(p: Mapping[str, float], law: Law) -> str:
    return ", ".join(f"{k} = {v:.4g}" for k, v in p.items() if k not in law.fixed)


def diagnose_homogeneous(runs: Sequence[xr.Dataset], alpha: float = st.ALPHA, seed: int = 0, n_random: int = 4,
                         laws: Sequence[str] = tuple(LAWS), n_grid: int = 41) -> tuple[dict, pd.DataFrame]:
    """Named findings, cross-mode predictions and residual table of a multi-mode homogeneous dataset.

    Parameters
    ----------
    runs : canonical runs of simple shear (P12 vs gamma) and uniaxial compression and tension (P11 vs lambda)
    alpha : family-wise false-alarm level (Holm, module docstring)
    seed, n_random : seeded random starts of every fit
    laws : keys of :data:`LAWS` to fit (must include at least one complete pair of :data:`PAIRS`)
    n_grid : points of the C01 profiles

    Returns
    -------
    result : dict in the ``diagnosis.json`` layout (module docstring), with ``cross_mode`` and ``profiles``
    table : residual table, one row per (law, calibration, point): ``model``, ``calibration``, ``mode``,
        ``test``, ``curve``, ``point``, ``strain`` (gamma, or lambda - 1), ``observed``, ``predicted``,
        ``residual``, ``sigma``, ``rel_residual``, ``log_ratio`` (NaN near zero), ``held_out`` (Pa)
    """
    by_mode = mode_curves(runs)
    pairs = [(b, e) for b, e in PAIRS if b in laws and e in laws]
    if not pairs:
        raise ValueError(f"laws {list(laws)} contain no I1/I2 pair of {PAIRS}")
    use = [LAWS[k] for k in laws]
    shear_c, all_c = _curves(by_mode, ["shear"]), _curves(by_mode, MODES)
    fits: dict[tuple[str, str], F.FitResult] = {}
    for law in use:
        fits[law.key, "simple_shear"] = fit_law(law, shear_c, seed, n_random, scope="simple_shear")
        fits[law.key, "all_modes"] = fit_law(law, all_c, seed, n_random, scope="all_modes")
        for train, _ in ROTATIONS:
            fits[law.key, "+".join(train)] = fit_law(law, _curves(by_mode, train), seed, n_random,
                                                      scope="+".join(train))
    base_key, ext_key = min(pairs, key=lambda p: fits[p[0], "simple_shear"].aicc)
    base, ext = LAWS[base_key], LAWS[ext_key]

    # --- cross-mode table -------------------------------------------------------------------------
    shear_only, joint, rotations = {}, {}, []
    g_max = max(float(np.nanmax(np.abs(c.obs_inputs("shear_strain")))) for c in shear_c)
    lams = np.concatenate([c.obs_inputs("stretch") for m in ("compression", "tension") for _, c in by_mode[m]])
    for law in use:
        fs, fa = fits[law.key, "simple_shear"], fits[law.key, "all_modes"]
        shear_only[law.key] = {m: held_out_error(law, fs.params, _curves(by_mode, [m])) for m in ("compression", "tension")}
        shear_only[law.key]["params"] = fs.params
        shear_only[law.key]["aicc"] = fs.aicc
        joint[law.key] = {"formula": law.formula, "aicc": fa.aicc, "nrmse": fa.nrmse, "params": fa.params,
                          "stderr": fa.stderr, "flags": fa.flags,
                          "stability": stability_flags(get_model(law.model), fa.params, strain_max=g_max,
                                                       stretch_range=(float(lams.min()), float(lams.max())))}
    for train, held in ROTATIONS:
        row = {"train": list(train), "held_out": held, "label": f"fit {'+'.join(train)} -> predict {held}"}
        for law in use:
            row[law.key] = held_out_error(law, fits[law.key, "+".join(train)].params, _curves(by_mode, [held]))["nrmse"]
        row["baseline"], row["extension"] = base.key, ext.key
        row["gain_extension_vs_baseline"] = (row[base.key] - row[ext.key]) / row[base.key]
        if held != "shear":
            row["shear_only_baseline"] = shear_only[base.key][held]["nrmse"]
            row["gain_vs_shear_only_baseline"] = (row["shear_only_baseline"] - row[ext.key]) / row["shear_only_baseline"]
        rotations.append(row)

    # which candidate predicts the held-out modes best (the I2 extension names the cause; another law may
    # still extrapolate better, e.g. a one-term Ogden law with a negative exponent)
    best_law = {r["label"]: min((k.key for k in use), key=lambda k: r[k]) for r in rotations}
    uni = [r for r in rotations if r["held_out"] != "shear"]
    best_uniaxial = min((k.key for k in use), key=lambda k: np.mean([r[k] for r in uni]))
    findings = [_asymmetry_finding(by_mode, fits, base, ext, rotations)]
    findings[0]["evidence"] += (
        f" Best held-out uniaxial predictor among the candidates: {best_uniaxial} (mean NRMSE "
        f"{np.mean([r[best_uniaxial] for r in uni]):.3f} vs {np.mean([r[ext.key] for r in uni]):.3f} for {ext.key}"
        + (f"; alpha1 = {fits['ogden1', 'all_modes'].params['alpha1']:+.3g} in the joint fit"
           if best_uniaxial == "ogden1" else "") + ").")
    i2, profiles, not_identifiable = _i2_finding(by_mode, fits, base, ext, rotations, seed, n_grid)
    findings.append(i2)
    if "ogden1" in laws:
        _ogden_note(by_mode, fits, i2)
    for eff in CATALOGUE_IDS:
        if eff != I2_ID:
            findings.append(untested_finding(eff, "not applicable: homogeneous simple-shear/uniaxial specimens (no "
                                           "parallel plates, no time, rate or instrument channels)"))
    generic = _structure_tests(by_mode, ext, fits[ext.key, "all_modes"].params)

    # --- the decision rule of the parallel-plate diagnosis (decision.DECISION_RULE) ---------------------
    noise = estimate_noise(runs)
    eps = relative_noise_level(noise)
    if not np.isfinite(eps):
        eps = F.NoiseModel().relative
    not_evaluated = apply_rule(findings, generic, alpha, eps, n_default=float(len(all_c)))
    unexplained = []
    for g in generic:
        if g["significant"] and g["practical"]:
            entry = {"effect": "unexplained_structure", **g, "candidates": [], "evidence": (
                f"{ext.key} fitted to all modes still misfits {g['test']} ({g['mode']}) systematically: residual "
                f"signs cluster along {g['covariate']} (runs z = {g['statistic']:.2f}, Holm p = {g['p_holm']:.2g}), "
                f"rms log residual {100 * g['effect_size']:.1f} %; no named cause accounts for it (a law with more "
                f"terms, or specimen differences between the modes' averaged curves).")}
            entry["what_to_do"] = ("Try a law with more terms, or check whether the modes' averaged curves come from "
                                   "different specimens.")
            unexplained.append(entry)
    result = {
        "model": base.key, "kind": "homogeneous_multimode",
        "fit_info": {"calibration": "simple_shear", "baseline": base.key, "baseline_formula": base.formula,
                     "extension": ext.key, "extension_formula": ext.formula, "target": "none",
                     "modes": {m: [rid for rid, _ in by_mode[m]] for m in MODES},
                     "noise_model": "1 % relative + 0.03 Pa floor (tissuemech.fitting.NoiseModel)"},
        "alpha": alpha, "decision_rule": DECISION_RULE,
        "noise_model": {**noise, "relative_level": eps},
        "n_tests": sum(1 for f in findings if f["tested"]) + len(generic), "findings": ordered(findings),
        "unexplained": unexplained, "significant_fix_not_evaluated": not_evaluated,
        "not_identifiable": not_identifiable, "structure_tests": generic,
        "cross_mode": {"shear_only": shear_only, "joint": joint, "rotations": rotations,
                       "best_law_by_rotation": best_law, "best_uniaxial_predictor": best_uniaxial,
                       "mean_gain_extension_vs_baseline": float(np.mean([r["gain_extension_vs_baseline"]
                                                                         for r in rotations]))},
        "profiles": profiles,
    }
    return result, mode_residual_table(by_mode, fits, use)


def _asymmetry_finding(by_mode, fits, base: Law, ext: Law, rotations) -> dict:
    p = fits[base.key, "simple_shear"].params
    rc, sc = log_ratios(base, p, _curves(by_mode, ["compression"]))
    rt, s_t = log_ratios(base, p, _curves(by_mode, ["tension"]))
    if rc.size < 3 or rt.size < 3:
        return untested_finding(ASYMMETRY_ID, "fewer than 3 compression or tension points above the noise")
    delta = float(rc.mean() - rt.mean())
    se = float(np.sqrt(np.sum(sc ** 2) / rc.size ** 2 + np.sum(s_t ** 2) / rt.size ** 2))
    z = delta / se
    test = {"statistic": z, "p_value": 10 ** st.log10_p_from_z(z), "log10_p": st.log10_p_from_z(z)}
    # model-free view: |P| in compression over P in tension at the same |lambda - 1|
    eps = min(max(abs(c.obs_inputs("stretch") - 1).max() for _, c in by_mode[m]) for m in ("compression", "tension"))
    data_ratio, model_ratio = _matched_ratio(by_mode, eps), None
    if np.isfinite(data_ratio):
        pm = get_model(base.model)
        model_ratio = float(-pm.uniaxial_nominal_stress(p, np.array([1 - eps]))[0]
                            / pm.uniaxial_nominal_stress(p, np.array([1 + eps]))[0])
    uni = [r for r in rotations if r["held_out"] != "shear"]
    before = float(np.mean([r["shear_only_baseline"] for r in uni]))
    after = float(np.mean([r[ext.key] for r in uni]))
    fix = fix_record(f"{ext.key} ({ext.formula}) calibrated on shear + the other uniaxial mode", "held_out_nrmse",
               before, after, "; ".join(r["label"] for r in uni) + f" (before: {base.key} calibrated on shear alone)",
               n_held_out_points=float(sum(_observed(c).size for m in ("compression", "tension")
                                           for c in _curves(by_mode, [m]))),
               **{r["label"]: r[ext.key] for r in uni})
    e_c = 100 * np.expm1(rc.mean())
    e_t = 100 * np.expm1(rt.mean())
    ratio_txt = (f" At |lambda - 1| = {eps:.3g} the data give |P_compression|/P_tension = {data_ratio:.2f}, "
                 f"{base.key} {model_ratio:.2f}." if model_ratio is not None else "")
    evidence = (f"Calibrated on simple shear alone, {base.key} ({base.formula}) is off by {e_c:+.0f} % in "
                f"compression and {e_t:+.0f} % in tension (data over model, from the mean ln(observed/predicted); NRMSE "
                f"{rotations[0]['shear_only_baseline']:.2f} and {rotations[1]['shear_only_baseline']:.2f}): the "
                f"tissue is {np.exp(delta):.2f}x stiffer in compression relative to tension than the shear-calibrated "
                f"I1-only law predicts (Delta = {delta:+.3f}, z = {z:.1f} against the 1 % measurement noise, "
                f"{rc.size} + {rt.size} points).{ratio_txt} Cause: an I2 (or negative-exponent) dependence that "
                f"simple shear cannot see (see {I2_ID}).")
    return {"effect": ASYMMETRY_ID, "tested": True, **test, "statistic_name": "z (difference of mean log ratios)",
            "effect_size": delta, "effect_size_unit": "log ratio compression - tension (shear-calibrated baseline)",
            "practical": bool(abs(delta) >= MIN_ASYMMETRY), "evidence": evidence, "fix": fix,
            "compression_mean_log_ratio": float(rc.mean()), "tension_mean_log_ratio": float(rt.mean()),
            "data_compression_tension_ratio": data_ratio, "model_compression_tension_ratio": model_ratio}


def _matched_ratio(by_mode, eps: float) -> float:
    vals = []
    for m, lam in (("compression", 1 - eps), ("tension", 1 + eps)):
        _, c = by_mode[m][0]
        x, y = c.obs_inputs("stretch"), _observed(c)
        order = np.argsort(x)
        vals.append(float(np.interp(lam, x[order], y[order])))
    return float(-vals[0] / vals[1]) if vals[1] != 0 else np.nan


def _i2_finding(by_mode, fits, base: Law, ext: Law, rotations, seed: int, n_grid: int):
    shear_c, all_c = _curves(by_mode, ["shear"]), _curves(by_mode, MODES)
    fs, fa, fb = fits[ext.key, "simple_shear"], fits[ext.key, "all_modes"], fits[base.key, "all_modes"]
    rho_shear = jacobian_correlation(ext, fs.params, shear_c, "C10", "C01")
    rho_all = jacobian_correlation(ext, fa.params, all_c, "C10", "C01")
    c01, c10 = fa.params["C01"], fa.params["C10"]
    c_sum_shear = fs.params["C10"] + fs.params["C01"]
    half = max(abs(c01), abs(c_sum_shear), 1e-3)
    grid = np.linspace(min(0.0, c01) - half, max(0.0, c01) + half, n_grid)
    grid = np.unique(np.r_[grid, c01])
    prof_s = profile_c01(ext, shear_c, grid, fs.params, seed)
    prof_a = profile_c01(ext, all_c, grid, fa.params, seed)
    # scaled by the residual variance of the joint fit: a real-data misfit must not shrink the interval
    s2_a = fa.chisqr / max(fa.n - fa.k, 1)
    s2_s = fs.chisqr / max(fs.n - fs.k, 1)
    d_a = (prof_a - prof_a.min()) / s2_a
    d_s = (prof_s - prof_s.min()) / s2_s
    flat = float((prof_s.max() - prof_s.min()) / max(prof_s.min(), np.finfo(float).tiny))
    lo, hi = profile_interval(grid, d_a, c01)
    identifiable = bool(np.isfinite(lo) and np.isfinite(hi))
    # nested test on all modes: the I2 term is one extra parameter over the I1-only baseline
    n_eff = min(fa.n_eff, fa.n)
    ftest = st.nested_f_test(fb.chisqr, fa.chisqr, n_eff, fa.k, max(fa.k - fb.k, 1))
    share = c01 / (c10 + c01) if (c10 + c01) != 0 else np.inf
    before = float(np.mean([r[base.key] for r in rotations]))
    after = float(np.mean([r[ext.key] for r in rotations]))
    fix = fix_record(f"{ext.key} ({ext.formula}) fitted to all modes jointly", "held_out_nrmse (mean over rotations)",
               before, after, "; ".join(r["label"] for r in rotations) + f" (before: {base.key} on the same modes)",
               delta_aicc=fa.aicc - fb.aicc, C01_pa=c01, C10_pa=c10, C01_ci95_low_pa=lo, C01_ci95_high_pa=hi,
               n_held_out_points=float(sum(_observed(c).size for c in all_c)),
               **{r["label"]: r[ext.key] for r in rotations})
    shear_txt = (f"Not identifiable from simple shear alone: I1 = I2 = 3 + gamma^2, so the C10 and C01 Jacobian "
                 f"columns have correlation {rho_shear:+.4f} (|rho| -> 1) and the chi-square profile over C01 in "
                 f"[{grid[0]:.3g}, {grid[-1]:.3g}] Pa is flat (relative range {flat:.1e}); the shear-only fit splits "
                 f"C10 + C01 = {c_sum_shear:.4g} Pa arbitrarily (C10 = {fs.params['C10']:.4g}, C01 = "
                 f"{fs.params['C01']:.4g} Pa).")
    ci_txt = (f"95 % profile interval [{lo:.4g}, {hi:.4g}] Pa" if identifiable else
              f"profile interval not closed within [{grid[0]:.3g}, {grid[-1]:.3g}] Pa ([{lo:.4g}, {hi:.4g}])")
    all_txt = (f" With compression and tension (all modes jointly, Jacobian correlation {rho_all:+.3f}) C01 = "
               f"{c01:.4g} Pa ({ci_txt}), C10 = {c10:.4g} Pa, C01/(C10 + C01) = {share:.2f}; adding C01 (I2 - 3) "
               f"to {base.key} changes AICc by {fa.aicc - fb.aicc:+.1f} (F = {ftest['statistic']:.1f} on "
               f"n_eff = {n_eff:.1f}) and the held-out NRMSE over the three leave-one-mode-out rotations from "
               f"{before:.3f} to {after:.3f}.")
    if identifiable:
        all_txt += " Identifiable from these data (all modes); not from shear alone."
    else:
        all_txt += " Not identifiable from these data even with all modes."
    stab = fits[ext.key, "all_modes"]
    stab_flags = stability_flags(get_model(ext.model), stab.params)
    if stab_flags:
        all_txt += f" Stability of the joint fit over gamma <= 0.5, lambda in [0.5, 1.5]: {', '.join(stab_flags)}."
    finding = {"effect": I2_ID, "tested": True, "statistic": ftest["statistic"], "p_value": ftest["p_value"],
               "log10_p": ftest["log10_p"], "statistic_name": "F (I1-only vs + C01 (I2 - 3), all modes)",
               "effect_size": float(c01), "effect_size_unit": "Pa (C01, all modes)",
               "practical": bool(abs(c01) >= MIN_I2_SHARE * abs(c10 + c01)), "identifiable": identifiable,
               "identifiable_from_shear": False if flat < FLAT_PROFILE or abs(rho_shear) > 0.9999 else True,
               "jacobian_correlation_shear": rho_shear, "jacobian_correlation_all_modes": rho_all,
               "profile_flatness_shear": flat, "c01_share": float(share),
               "evidence": shear_txt + all_txt, "fix": fix}
    not_identifiable = []
    if not finding["identifiable_from_shear"]:
        not_identifiable.append({"effect": I2_ID, "data": "simple_shear", "evidence": shear_txt})
    if not identifiable:
        not_identifiable.append({"effect": I2_ID, "data": "all_modes", "evidence": all_txt.strip()})
    profiles = {"law": ext.key, "c01_pa": grid, "delta_shear": d_s, "delta_all_modes": d_a,
                "chisqr_shear": prof_s, "chisqr_all_modes": prof_a, "level_95": PROFILE_95}
    return finding, profiles, not_identifiable


def _ogden_note(by_mode, fits, finding: dict) -> None:
    """The stretch-law face of the same blind spot: one-term Ogden shear is even in alpha."""
    law = LAWS["ogden1"]
    ps, pa = fits[law.key, "simple_shear"].params, fits[law.key, "all_modes"].params
    flipped = dict(ps, alpha1=-ps["alpha1"])
    c = _curves(by_mode, ["shear"])
    diff = max(float(np.max(np.abs(predict_stress(law, flipped, x) - predict_stress(law, ps, x)))) for x in c)
    finding["evidence"] += (f" The one-term Ogden law shows the same blind spot: its shear response is identical for "
                            f"alpha and -alpha (max difference {diff:.2g} Pa); shear alone gives alpha1 = "
                            f"{ps['alpha1']:+.3g}, all modes {pa['alpha1']:+.3g}.")
    finding["ogden_alpha_shear"], finding["ogden_alpha_all_modes"] = ps["alpha1"], pa["alpha1"]


def _structure_tests(by_mode, law: Law, params: Mapping[str, float]) -> list[dict]:
    """Runs test on residual signs along the strain of each mode's curves (joint fit of the fix)."""
    out = []
    for m in MODES:
        for rid, c in by_mode[m]:
            x = c.obs_inputs("shear_strain" if m == "shear" else "stretch")
            y, f = _observed(c), predict_stress(law, params, c)
            sig = _sigma(c, f)
            ok = np.abs(f) > MIN_SNR * sig
            order = np.argsort(x[ok])
            e = (y - f)[ok][order]
            if e.size < 8:
                continue
            t = st.runs_test(e)
            lr = np.log(np.abs(y[ok] / f[ok]))
            out.append({"test": "simple_shear" if m == "shear" else "uniaxial", "mode": m, "curve": rid,
                        "quantity": next(iter(c.observed)), "covariate": "shear_strain" if m == "shear" else "stretch",
                        "level": "within curves", "statistic": t["statistic"], "p_value": t["p_value"],
                        "log10_p": t["log10_p"], "effect_size": float(np.sqrt(np.mean(lr ** 2))),
                        "practical": bool(np.sqrt(np.mean(lr ** 2)) >= MIN_ASYMMETRY), "n_points": int(e.size)})
    return out


def mode_residual_table(by_mode, fits, laws: Sequence[Law]) -> pd.DataFrame:
    """Residuals of every law under every calibration (module docstring of :func:`diagnose_homogeneous`)."""
    rows = []
    for law in laws:
        for (key, calib), res in fits.items():
            if key != law.key:
                continue
            trained = MODES if calib == "all_modes" else calib.split("+") if "+" in calib else ["shear"]
            for m in MODES:
                for rid, c in by_mode[m]:
                    y, f = _observed(c), predict_stress(law, res.params, c)
                    sig = _sigma(c, f)
                    x = c.obs_inputs("shear_strain") if m == "shear" else c.obs_inputs("stretch") - 1.0
                    with np.errstate(divide="ignore", invalid="ignore"):
                        ok = (np.abs(f) > MIN_SNR * sig) & (np.sign(y) == np.sign(f)) & (y != 0)
                        lr = np.where(ok, np.log(np.abs(y / f)), np.nan)
                        rel = np.where(f != 0, (y - f) / np.abs(f), np.nan)
                    rows.append(pd.DataFrame({
                        "model": law.key, "calibration": calib, "mode": m, "test": "simple_shear" if m == "shear" else "uniaxial",
                        "curve": rid, "point": np.arange(y.size), "strain": x, "observed": y, "predicted": f,
                        "residual": y - f, "sigma": sig, "rel_residual": rel, "log_ratio": lr,
                        "held_out": m not in trained}))
    return pd.concat(rows, ignore_index=True)


# ------------------------------------------------------------------------------------------------
# figures
# ------------------------------------------------------------------------------------------------
