"""The fixes that change the baseline itself, scored on held-out data by refitting it in every fold.

A cause whose fix is a change of the model (not a correction of the residuals) is scored here, and only when the
decision rule needs the score (the cause is significant and relevant): :data:`MODEL_FIXES` maps the cause to its
scorer, :func:`score_model_fixes` runs them and stores each score in ``fit_info["fixes"]``, where the detector
finds it when the diagnosis is run again (:func:`tissuemech.diagnosis.report.with_model_fixes`).

* ``nonseparable_relaxation`` -- :func:`nonseparable_fix`: the QLV baseline against its Pipkin-Rogers extension,
  both refitted leaving out the extreme CSR rates and the relaxations at the extreme strains;
* ``torque_offset`` -- :func:`offset_fix`: the baseline refitted with a torque offset, read from the training
  residuals (:func:`tissuemech.diagnosis.time_domain.offset_intercept`), removed.
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import xarray as xr

from .. import fitting
from ..models.registry import FIXED_TIME_KEY, available_models, get_model, model_on_times
from .baseline import curves_of_runs, extension_gain, fit_runs, predict_runs, resolved_window_s, window_taus
from .evidence import nominal_strain, residual_table
from .time_domain import offset_intercept

#: the tests whose torque a transducer offset shifts and the model-level fixes refit: ramps and relaxations
RAMP_AND_RELAXATION = ("constant_shear_rate", "stress_relaxation")


def nonseparable_fix(runs, baseline_key: str, target: str, taus_s: Sequence[float] | None = None,
                     fits_out: list | None = None) -> dict | None:
    """Pipkin-Rogers counterpart of a QLV baseline, scored on held-out extremes of the design: the lowest and
    the highest CSR rate when there are >= 3 rates, and the relaxations at the lowest and at the highest
    nominal strain when there are >= 2 (non-separability is a strain dependence of the relaxation, so a model
    trained on the other strains must predict the extreme one); a design with both has four folds, so that the
    simulator scores the extension on held-out ramps and held-out relaxations. Both models are refitted in every fold on the
    baseline's relaxation times ``taus_s`` [s] (the runs-only path's NNLS times), or, when None, on a
    one-per-decade grid spanning the window the tests resolve. None when the design has neither."""
    if not baseline_key.startswith("qlv_"):
        return None
    ext = "pr_" + baseline_key[len("qlv_"):]
    if ext not in available_models() and not (FIXED_TIME_KEY.fullmatch(ext) and "_fluid" not in ext):
        # a fixed-time Pipkin-Rogers model on the baseline's times (models.registry.model_on_times); a fluid QLV
        # has no Pipkin-Rogers counterpart
        return None
    use = [r for r in runs if r.attrs.get("test") in ("constant_shear_rate", "stress_relaxation")]
    rates = sorted({float(r.attrs["shear_rate_1_per_s"]) for r in use
                    if r.attrs.get("test") == "constant_shear_rate" and "shear_rate_1_per_s" in r.attrs})
    strains = sorted({round(nominal_strain(r), 6) for r in use if r.attrs.get("test") == "stress_relaxation"}
                     - {np.nan})
    strains = [g for g in strains if np.isfinite(g)]
    folds = []
    if len(rates) >= 3:
        folds += [(f"CSR {rate:g} 1/s", (lambda r, rate=rate: r.attrs.get("test") == "constant_shear_rate"
                                         and float(r.attrs.get("shear_rate_1_per_s", -1)) == rate))
                  for rate in (rates[0], rates[-1])]
    if len(strains) >= 2:
        folds += [(f"relaxation at {100 * g:g} %", (lambda r, g=g: r.attrs.get("test") == "stress_relaxation"
                                                    and round(nominal_strain(r), 6) == g))
                  for g in (strains[0], strains[-1])]
    if not folds:
        return None
    # both models on the relaxation times these tests resolve (never the registry's fixed 0.1-100 s)
    window = resolved_window_s(use)
    taus = np.asarray(taus_s, float) if taus_s is not None and len(taus_s) else window_taus(window)
    fix = extension_gain(use, baseline_key, ext, target, folds, taus_s=taus if taus.size else None,
                         fits_out=fits_out)
    fix["parameters"]["window_t_min_s"] = window["t_min_s"]
    fix["parameters"]["window_t_max_s"] = window["t_max_s"]
    return fix


def offset_removed(runs: Sequence[xr.Dataset], offset_nm: float) -> list[xr.Dataset]:
    """Ramps and relaxations with an additive torque offset ``offset_nm`` [N m] removed from the torque, the
    apparent shear stress (2 M0/(pi R^3)) and the relaxation modulus derived from it; other runs unchanged."""
    out = []
    for r in runs:
        radius = float(r.attrs.get("radius_m", np.nan) or np.nan)
        if r.attrs.get("test") not in RAMP_AND_RELAXATION or not np.isfinite(radius):
            out.append(r)
            continue
        d = r.copy()
        stress_pa = 2.0 * offset_nm / (np.pi * radius ** 3)
        strain = nominal_strain(r)
        for var, shift in (("torque", offset_nm), ("shear_stress", stress_pa),
                           ("relaxation_modulus", stress_pa / strain if strain else np.nan)):
            if var in d and np.isfinite(shift):
                d[var] = d[var].copy(data=d[var].values - shift)
        out.append(d)
    return out


def condition_of(run: xr.Dataset) -> str:
    """A ramp's rate or a relaxation's nominal strain: the condition a held-out fold leaves out."""
    if run.attrs.get("test") == "constant_shear_rate":
        return f"CSR {float(run.attrs.get('shear_rate_1_per_s', np.nan)):g} 1/s"
    return f"relaxation at {100 * nominal_strain(run):g} %"


def held_out_nrmse(model, params, curves, target: str, reference_curves, free_level: bool = False) -> float:
    """RMS over curves of RMSE / mean |observed| (:func:`tissuemech.fitting.evaluate`), the observed mean taken
    from ``reference_curves`` (the raw measurement) so that a model fitted to offset-removed data is scored on
    the same scale as one fitted to the raw data. ``free_level``: each curve's prediction gets its own
    least-squares factor first (a held-out sample's stiffness level is specimen variability, not the fix's
    business; its shape is)."""
    terms = fitting.FitProblem(model=model, curves=list(curves), target=target).curve_terms(dict(params))
    ref = fitting.FitProblem(model=model, curves=list(reference_curves), target=target).observations
    per = []
    for t, (obs, _) in zip(terms, ref):
        y = np.concatenate([y for (y, _, _) in t.values()])
        f = np.concatenate([f for (_, f, _) in t.values()])
        if free_level and np.dot(f, f) > 0:
            f = f * (np.dot(f, y) / np.dot(f, f))
        per.append(np.sqrt(np.mean((f - y) ** 2)) / np.mean(np.abs(np.concatenate(list(obs.values())))))
    return float(np.sqrt(np.mean(np.square(per)))) if per else np.nan


def offset_fix(runs: Sequence[xr.Dataset], baseline_key: str, fit_info: dict, noise: dict | None,
                n_points: int = 16) -> dict | None:
    """The baseline refitted with a torque offset removed, scored on held-out conditions.

    Folds: with three or more ramp/relaxation conditions (rate or nominal strain), the condition with the
    smallest median |torque| (where an offset is the largest share of the signal) and the one with the largest;
    with two, the training runs must keep both (an offset is told from a level only across conditions), so up
    to three samples are held out in turn and each held-out curve keeps its own level (``free_level`` of
    :func:`held_out_nrmse`). In each fold the baseline is fitted
    to the training runs as measured; the offset M0 is read from its training residuals
    (:func:`tissuemech.diagnosis.time_domain.offset_intercept`, converted at the median plate radius); the
    baseline is refitted to the training runs with M0 removed; both predict the held-out runs (the refit on the
    held-out runs with the training M0 removed). ``before``/``after``: mean held-out NRMSE over folds, both
    normalised by the raw held-out observations. None without two conditions, a plate radius, or a torque /
    apparent-stress target.
    """
    target = fit_info.get("target", "apparent_stress")
    relaxation = fit_info.get("relaxation", "measured")
    taus = fit_info.get("taus_s") or None
    use = [r for r in runs if r.attrs.get("test") in RAMP_AND_RELAXATION]
    radii = np.array([float(r.attrs.get("radius_m", np.nan) or np.nan) for r in use])
    if target not in ("torque", "apparent_stress") or not use or not np.isfinite(radii).all():
        return None
    groups: dict[str, list[xr.Dataset]] = {}
    for r in use:
        groups.setdefault(condition_of(r), []).append(r)
    if len(groups) < 2:
        return None

    def level(rs):
        vals = [np.abs(r["torque"].values) if "torque" in r else np.abs(r["shear_stress"].values) * radius ** 3
                for r, radius in ((r, float(r.attrs["radius_m"])) for r in rs)]
        return float(np.nanmedian(np.concatenate(vals)))

    def piece(r):
        return f"specimen {r.attrs.get('specimen')} sample {r.attrs.get('sample')}"

    if len(groups) >= 3:
        order = sorted(groups, key=lambda k: level(groups[k]))
        folds = [(label, condition_of, groups[label]) for label in (order[0], order[-1])]
    else:
        pieces = list(dict.fromkeys(piece(r) for r in use))[:3]
        folds = [(p, piece, [r for r in use if piece(r) == p]) for p in pieces if len(pieces) >= 2]
    free_level = len(groups) < 3
    model = model_on_times(baseline_key, taus) if taus else get_model(baseline_key)
    before, after, labels, n_held, offsets = [], [], [], [], []
    for label, key_of, held in folds:
        train = [r for r in use if key_of(r) != label]
        test_curves = curves_of_runs(held, relaxation, n_points)
        if not train or not test_curves or len({condition_of(r) for r in train}) < 2:
            continue
        raw = fit_runs(baseline_key, train, target, relaxation, n_points, taus_s=taus)
        preds = predict_runs(model, raw.params, train, target, relaxation)
        kept = [(r, p) for r, p in zip(train, preds) if p]
        est = offset_intercept(residual_table([r for r, _ in kept], [p for _, p in kept], baseline_key, noise=noise)) \
            if kept else None
        if est is None:
            continue
        offset_nm = float(est["estimate"]) * np.pi * float(np.median(radii)) ** 3 / 2.0
        refit = fit_runs(baseline_key, offset_removed(train, offset_nm), target, relaxation, n_points,
                         start=raw.params, taus_s=taus)
        corrected = curves_of_runs(offset_removed(held, offset_nm), relaxation, n_points)
        before.append(held_out_nrmse(model, raw.params, test_curves, target, test_curves, free_level))
        after.append(held_out_nrmse(model, refit.params, corrected, target, test_curves, free_level))
        labels.append(label)
        offsets.append(offset_nm)
        n_held.append(int(sum(min(np.size(v) for v in c.observed.values()) for c in test_curves if c.observed)))
    if not before:
        return None
    b, a = float(np.mean(before)), float(np.mean(after))
    return {"model": f"{baseline_key} refitted with the torque offset M0 removed (M0 read from the training "
                     "residuals)", "metric": "held_out_nrmse", "before": b, "after": a,
            "gain": (b - a) / b if b > 0 else np.nan,
            "cv": ("leave-one-sample-out, levels free (" if free_level else "leave-one-condition-out (")
            + ", ".join(labels) + ")",
            "parameters": {"offset_uNm_per_fold": [1e6 * m for m in offsets],
                           # the folds' metrics are averaged, so the margin pools all held-out points
                           "n_held_out_points": float(sum(n_held)) if min(n_held) > 0 else np.nan},
            "folds": [{"label": lab, "before": b_, "after": a_} for lab, b_, a_ in zip(labels, before, after)]}


#: model-level fixes (refits) scored by :func:`score_model_fixes`: cause -> scorer(runs, baseline, fit_info, noise)
MODEL_FIXES = {
    "nonseparable_relaxation": lambda runs, key, info, noise: nonseparable_fix(
        runs, key, info.get("target", "apparent_stress"), info.get("taus_s"),
        fits_out=info["simulation_fits"].setdefault("nonseparable_relaxation", [])
        if isinstance(info.get("simulation_fits"), dict) else None),
    "torque_offset": offset_fix,
}


def score_model_fixes(result: dict, runs: Sequence[xr.Dataset], fit_info: dict, noise: dict | None = None) -> bool:
    """Score the model-level fix of every cause of ``result`` (a :func:`tissuemech.diagnosis.report.diagnose`
    result) that passes Holm and practical relevance; the scores go into ``fit_info["fixes"]``. Returns whether
    any fix was scored (the diagnosis must then be run again for the rule to read them)."""
    if not result["baseline"]["adequate"]:
        return False
    scored = False
    for effect, scorer in MODEL_FIXES.items():
        f = next((f for f in result["findings"] if f["effect"] == effect), None)
        if f is None or not (f["significant"] and f["practical"]):
            continue
        fix = scorer(runs, result["model"], fit_info, noise)
        if fix is not None:
            fit_info.setdefault("fixes", {})[effect] = fix
            scored = True
    return scored
