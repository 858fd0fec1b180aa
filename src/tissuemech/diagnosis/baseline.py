"""Fitted models evaluated on the measured runs, and the extension fits that remove a named cause.

* :func:`predict_runs` -- a fitted model's prediction of every run in the quantity the run reports
  (reported rim stress for ramps and holds, G'/G'' for sweeps; amplitude sweeps through the
  instrument-style first-harmonic analysis of :func:`tissuemech.models.plate.oscillation_moduli`), aligned
  with the run's points (NaN where the fit's data selection has no observation, e.g. ramp points of a
  step-analysed relaxation).
* :func:`extension_gain` -- the held-out gain of an extended model over the baseline: both are fitted by
  :func:`tissuemech.fitting.fit` on the training runs of each fold and scored with
  :func:`tissuemech.fitting.evaluate` on the held-out runs (NRMSE), plus the full-data ΔAICc.
* :func:`read_fit_record` -- a ``results/<dataset>/fits/<model>.nc`` record back into parameters.
* :func:`baseline_adequacy` -- whether a fitted baseline describes the data well enough to blame anything on
  an effect: no varying parameter at a bound, a covariance (finite standard errors), no gross misfit.
* :func:`ranked_candidates` -- the fit records in the order of the dataset's ``ranking.csv``.
* :func:`resolved_window_s` / :func:`window_taus` / :func:`nnls_relaxation_times` / :func:`tissuemech.models.registry.model_on_times` -- the relaxation-time
  window the tests resolve (sweep frequencies, relaxation rise and hold times, ramp durations), a log grid
  spanning it, the times NNLS selects on a dense grid over that window,
  and a registered QLV/Pipkin-Rogers model rebuilt on that grid (instead of the registry's fixed 0.1-100 s
  times); :func:`fit_runs` and :func:`extension_gain` use it when given ``taus_s``.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd
import xarray as xr

from .. import fitting
from ..models.base import ConstitutiveModel, ResponseNotSupported
from ..models.plate import oscillation_moduli
from ..models.registry import get_model, model_on_times
from .. import material
from ..material import NNLS_TIMES_PER_DECADE, window_taus
from ..curves import condition_label, condition_of, drop_flagged
from ..ranking import recommended_mask
from .noise import MODULI, OSCILLATORY_TESTS, estimate_noise, fit_noise, measured_torque_modulus, noise_sd


def read_fit_record(path: str | Path) -> dict:
    """Parameters and metadata of a fit netCDF written by :func:`tissuemech.fitting.write_fit_netcdf`.

    Returns ``{"model_key", "target", "params", "aicc", "family", "correlations", "scope", "tests",
    "relaxation", "stderr", "varying", "flags", "converged", "taus_s"}``;
    ``correlations`` maps ``"a|b"`` to the fitted correlation of every varying pair; ``taus_s`` the relaxation
    times [s] of a fixed-time model's structure (empty for other models).
    """
    rec = fitting.FitRecord.from_netcdf(path)  # the one fit-record reader
    # relaxation: the strain-history treatment of the fit (fitting.relaxation_history), "measured" when the
    # record does not say
    return {"model_key": rec.model_key, "target": rec.target, "family": rec.family, "scope": rec.scope,
            "aicc": rec.aicc, "params": rec.params, "correlations": rec.correlations, "relaxation": rec.relaxation,
            "tests": rec.tests, "stderr": rec.stderr, "varying": rec.varying, "flags": rec.flags,
            "converged": rec.converged,
            "taus_s": [float(t) for t in (rec.structure or {}).get("taus_s") or []]}


#: a baseline whose typical point (median over rows) is off by more than this factor misfits grossly: the
#: error is the model's level, not an effect of the catalogue (a definition, stated in README "Reading a
#: diagnosis")
GROSS_MISFIT_FACTOR = 2.0


def baseline_adequacy(record: Mapping, table: pd.DataFrame) -> dict:
    """Is a fitted baseline adequate to diagnose with?

    Parameters
    ----------
    record : :func:`read_fit_record` output (``flags``, ``stderr``, ``varying``, ``converged``)
    table : the residual table of that model (:func:`tissuemech.diagnosis.evidence.residual_table`)

    Returns
    -------
    dict ``{"model", "adequate", "at_bound" (parameter names), "no_covariance" (bool),
    "not_converged" (bool), "median_abs_log_ratio" [1], "misfit_factor" (exp of it),
    "misfit_noise_units" (RMS of residual/sigma over rows with a noise estimate), "reasons" (sentences)}``; rows
    the ingest flagged (``quality_flag``) are left out, as the fits leave them out.
    Inadequate when a varying parameter sits at a bound (a Prony weight ``beta_i`` at its lower bound 0 is
    exempt: that relaxation mode is simply absent), no parameter has a finite standard error (no
    covariance), the fit did not converge, or the typical point is off by more than
    :data:`GROSS_MISFIT_FACTOR`.
    """
    flags = [str(f) for f in record.get("flags", [])]
    # the ranking's rule (a Prony weight at its lower bound 0 is an absent mode, not a collapse)
    at_bound = fitting.at_bound_parameters(flags)
    varying = list(record.get("varying", []))
    se = record.get("stderr", {})
    no_cov = bool(varying) and bool(se) and not any(np.isfinite(se.get(n, np.nan)) for n in varying)
    if "quality_flag" in table:
        table = table[table["quality_flag"] == 0]
    lr = table["log_ratio"].to_numpy(float) if "log_ratio" in table else np.array([])
    lr = lr[np.isfinite(lr)]
    med = float(np.median(np.abs(lr))) if lr.size else np.nan
    if "std_residual" in table:
        z = table["std_residual"].to_numpy(float)
        z = z[np.isfinite(z)]
    else:
        z = np.array([])
    noise_units = float(np.sqrt(np.mean(z ** 2))) if z.size else np.nan
    reasons = []
    if at_bound:
        reasons.append(f"parameters at a bound: {', '.join(at_bound)}")
    if no_cov:
        reasons.append("no covariance (no finite standard error of any varying parameter)")
    if not record.get("converged", True):
        reasons.append("the fit did not converge")
    gross = np.isfinite(med) and med > np.log(GROSS_MISFIT_FACTOR)
    if gross:
        reasons.append(f"gross misfit: the typical point is off by a factor {np.exp(med):.3g} "
                       f"(median |ln(observed/predicted)| = {med:.3g}; RMS misfit {noise_units:.3g} noise SDs)")
    if not lr.size:
        reasons.append("no residual of this model on the data")
    return {"model": str(record.get("model_key", "")), "adequate": not reasons, "at_bound": at_bound,
            "no_covariance": no_cov, "not_converged": not record.get("converged", True),
            "median_abs_log_ratio": med, "misfit_factor": float(np.exp(med)) if np.isfinite(med) else np.nan,
            "misfit_noise_units": noise_units, "reasons": reasons}


def ranked_candidates(records: Sequence[Mapping], ranking: pd.DataFrame | None) -> tuple[list[Mapping], str]:
    """Fit records in baseline-preference order and the source of that order.

    The diagnosis explains departures from a separable (QLV-family) reference, so QLV-family records come
    first. Within each group the model the ranking stage recommends for the records' scope (``ranking.csv``
    column ``recommended``, the one choice cards and FEM use too) comes first, then the dataset's ranking
    (column ``rank``), which chooses the instantaneous law. Without a usable ranking the order is AICc.
    When the recommended model is not QLV-family, the source says that the QLV-first rule overrode it.
    """
    order: dict[str, float] = {}
    recommended: set[str] = set()
    source = "aicc (no ranking.csv rows for these fits)"
    if ranking is not None and not ranking.empty and {"model", "rank"} <= set(ranking.columns):
        scopes = {str(r.get("scope", "")) for r in records}
        rows = ranking[ranking["scope"].astype(str).isin(scopes)] if "scope" in ranking else ranking
        keys = {str(r["model_key"]) for r in records}
        rows = rows[rows["model"].astype(str).isin(keys)]
        if not rows.empty:
            order = {str(m): float(k) for m, k in zip(rows["model"], rows["rank"])}
            source = "ranking.csv (rank within scope " + ", ".join(sorted(scopes)) + ")"
            if "recommended" in rows:
                recommended = set(rows["model"].astype(str).to_numpy()[recommended_mask(rows)])
                families = {str(r["model_key"]): r.get("family") for r in records}
                if recommended:
                    rec = ", ".join(sorted(recommended))
                    qlv = all(families.get(m) == "qlv" for m in recommended)
                    source += (f"; recommended model {rec} first" if qlv else
                               f"; recommended model {rec} is not QLV-family: the separable reference comes first")
                else:
                    source += "; no model recommended for this scope"

    def key(r):
        aicc = r.get("aicc", np.nan)
        return (r.get("family") != "qlv", str(r["model_key"]) not in recommended,
                order.get(str(r["model_key"]), np.inf), aicc if np.isfinite(aicc) else np.inf)
    return sorted(records, key=key), source


def _stress_from_prediction(pred: Mapping[str, np.ndarray], radius_m: float) -> dict[str, np.ndarray]:
    out = dict(pred)
    if "torque" in out and "shear_stress" not in out:
        out["shear_stress"] = np.asarray(out.pop("torque"), float) / fitting.plate_factor(radius_m)
    return out


def predict_run(model: ConstitutiveModel, params: Mapping[str, float], run: xr.Dataset,
                target: str = "apparent_stress", relaxation: str = "measured") -> dict[str, np.ndarray]:
    """Prediction of one run, aligned with its points (see module docstring); empty when the model does
    not describe the run's test."""
    n = run.sizes.get("point", 0)
    test = str(run.attrs.get("test", ""))
    radius = float(run.attrs.get("radius_m", np.nan))
    try:
        if test == "amplitude_sweep":
            strain = np.abs(run["shear_strain"].values)
            f_hz = float(run.attrs.get("frequency_hz", np.nanmedian(run["frequency"].values) if "frequency" in run
                                       else np.nan))
            if not np.isfinite(f_hz):
                return {}  # no frequency in the export or sample sheet: not predictable (never a default 1 Hz)
            if model.supports("shear_history") and np.isfinite(radius):
                mode = "apparent_stress" if target == "torque" else "corrected_stress"
                g1, g2 = oscillation_moduli(model, params, f_hz, strain, radius, target=mode)
                return {"storage_modulus": g1, "loss_modulus": g2}
            if model.supports("oscillation"):
                gs = model.complex_modulus(params, np.array([2 * np.pi * f_hz]))[0]
                return {"storage_modulus": np.full(n, gs.real), "loss_modulus": np.full(n, gs.imag)}
            return {}
        if test not in fitting.TEST_RESPONSE:
            return {}
        curve, rows = fitting.curve_and_rows(run, relaxation)
        tgt = target if curve.is_plate else "none"
        if curve.response != "shear_history" or not curve.is_plate:
            tgt = target if target in fitting.PLATE_TARGETS else "apparent_stress"
        if tgt == "corrected_stress":
            tgt = "apparent_stress"  # the homogeneous law at the rim strain; compared with reported stress below
        pred = _stress_from_prediction(fitting.predict(model, params, curve, tgt), radius)
    except (ResponseNotSupported, ValueError, KeyError):
        return {}
    out = {}
    for k, v in pred.items():
        full = np.full(n, np.nan)
        v = np.asarray(v, float)
        if v.size == rows.size:
            full[rows] = v
            out[k] = full
    return out


def predict_runs(model: ConstitutiveModel, params: Mapping[str, float], runs: Sequence[xr.Dataset],
                 target: str = "apparent_stress", relaxation: str = "measured") -> list[dict[str, np.ndarray]]:
    """:func:`predict_run` for every run."""
    return [predict_run(model, params, r, target, relaxation) for r in runs]


def resolved_window_s(runs: Sequence[xr.Dataset]) -> dict:
    """Relaxation-time window [s] the runs resolve: :func:`tissuemech.material.resolved_window_s` of their curves
    (sweeps: 1/omega; relaxations: rise time to hold duration; creep and ramps: first sample to duration)."""
    return material.resolved_window_s(curves_of_runs(runs, "measured", 10 ** 9))


def loading_unit(run: xr.Dataset) -> str:
    """The loaded piece a run was measured on: ``specimen/sample`` from the run's attributes ("" when the
    export and the sample sheet name neither)."""
    return f"{run.attrs.get('specimen', '')}/{run.attrs.get('sample', '')}"


#: curve responses the baseline's NNLS times and piece levels come from (:func:`nnls_relaxation_times`): the
#: strain and stress histories. Sweeps are left out: with them the bundled brain's ramps kept a residual shape
#: that a wall-slip correction removed on held-out ramps (a cause that is not in those data) and the diagnosis
#: cost 2.5x the CPU; a sweep piece takes its level from the piece's other tests
NNLS_RESPONSES = ("shear_history", "creep")


def nnls_relaxation_times(runs: Sequence[xr.Dataset], target: str, relaxation: str = "measured",
                          window: Mapping | None = None, model_key: str = "qlv_linear_prony4",
                          per_decade: float = NNLS_TIMES_PER_DECADE, n_points: int = 40,
                          law_params: Mapping[str, float] | None = None) -> dict:
    """Relaxation times the runs ask for, and the modulus level of every loaded piece: the material model's NNLS
    (:func:`tissuemech.material.nnls_relaxation_times`, one level per :func:`loading_unit`) on the runs' curves.

    The histories take part (:data:`NNLS_RESPONSES`): ramps and relaxations (measured strain history) and creep
    read as strain-controlled (:func:`tissuemech.material.as_strain_controlled`), so that a creep piece gets its
    level and the times see the creep's time scales.

    Parameters
    ----------
    runs : the runs the baseline is fitted to
    target : plate target of :mod:`tissuemech.fitting`
    window : :func:`resolved_window_s` of ``runs`` (computed when None)
    model_key : fixed-time QLV key whose instantaneous law drives the basis
    law_params : parameters of that law (others are ignored); its overall modulus is absorbed by the weights
    per_decade : grid density (times per decade) of :func:`window_taus`
    n_points : observation points kept per curve (:func:`tissuemech.fitting.thin`)

    Returns
    -------
    The material function's record (``taus_s``: every active time, a pair of neighbouring ones merged;
    ``levels``: {unit: c_u}).
    """
    window = resolved_window_s(runs) if window is None else window
    curves, units = [], []
    for r in runs:
        for c in curves_of_runs([r], relaxation, n_points):
            if c.response in NNLS_RESPONSES:
                curves.append(c)
                units.append(loading_unit(r))
    return material.nnls_relaxation_times(curves, window, law_tag=material.law_tag(model_key),
                                          law_params=law_params, per_decade=per_decade, target=target,
                                          units=units, merge_per_decade=None)


#: run variables that scale with a loaded piece's modulus level (divided by it) and inversely (multiplied)
LEVEL_SCALED = ("shear_stress", "torque", "relaxation_modulus", "storage_modulus", "loss_modulus")
LEVEL_INVERSE = ("creep_compliance",)


def level_normalised(runs: Sequence[xr.Dataset], levels: Mapping[str, float]) -> list[xr.Dataset]:
    """Copies of ``runs`` as the piece of level 1 would give them (:func:`nnls_relaxation_times`), for fitting the
    shape common to all pieces: stresses, torques and moduli divided by their loaded piece's level and
    compliances multiplied (a piece ``c`` times stiffer answers a stress as the level-1 piece answers ``1/c`` of
    it, so a creep's imposed stress is divided too); runs of a piece without a level are returned unchanged."""
    out = []
    for r in runs:
        c = levels.get(loading_unit(r))
        if c is None or not np.isfinite(c) or c <= 0 or c == 1.0:
            out.append(r)
            continue
        r = r.copy()
        for name in LEVEL_SCALED:
            if name in r:
                r[name] = r[name] / c
        for name in LEVEL_INVERSE:
            if name in r:
                r[name] = r[name] * c
        out.append(r)
    return out


def curves_of_runs(runs: Sequence[xr.Dataset], relaxation: str, n_points: int,
                   noise: Mapping | None = None) -> list[fitting.Curve]:
    """The runs as fitting curves (``fitting.curve_from_run``, thinned to ``n_points``, a creep-recovery by phase
    so that its recovery keeps its share); runs of tests the fit stage does not describe, or that cannot be read as
    a curve, are left out. The quality-flagged points of a sweep (:func:`tissuemech.curves.drop_flagged`:
    inertia-dominated, below the declared torque resolution, beyond the sample's LVE limit) are left out, as the
    fit stage's averages leave them out (a sweep flagged at every point is left out); a history keeps every sample
    (it is the model's input).

    ``noise`` (an :func:`estimate_noise` model of the runs): the sweeps' moduli then carry their per-point noise SD
    (:func:`oscillation_noise_sd`) as the curve's ``sd``, so that a fit weighs them as the residual tests judge
    them."""
    out = []
    for r in runs:
        if r.attrs.get("test") in fitting.TEST_RESPONSE:
            try:
                if r.attrs.get("test") in OSCILLATORY_TESTS:
                    r = drop_flagged(r)
                    if not r.sizes.get("point", 0):
                        continue
                curve, rows = fitting.curve_and_rows(r, relaxation)
                if noise is not None:
                    curve = oscillation_noise_sd(curve, r, rows, noise)
                out.append(fitting.thin(curve, n_points))
            except (ValueError, KeyError):
                continue
    return out


def oscillation_noise_sd(curve: fitting.Curve, run: xr.Dataset, rows: np.ndarray, noise: Mapping) -> fitting.Curve:
    """``curve`` with the noise SD [Pa] of each storage- and loss-modulus point of its sweep ``run`` (``rows``: the
    run's rows that are the curve's points) under ``noise``: :func:`tissuemech.noise.noise_sd`, whose absolute
    floor is a torque and so, in a modulus, the floor over the strain amplitude, and whose relative part is
    relative to the measured torque (:func:`tissuemech.noise.measured_torque_modulus`). A fit's own per-observable floor
    (:class:`tissuemech.fitting.NoiseModel`) has no strain amplitude: without this, a sweep's small loss modulus
    near the torque floor weighed as if it were known to 1 %. Other curves are returned unchanged."""
    test = str(run.attrs.get("test", ""))
    if test not in OSCILLATORY_TESTS:
        return curve
    strain = np.asarray(run["shear_strain"].values, float)[rows] if "shear_strain" in run else None
    if strain is None and "strain_pct" in run.attrs:
        strain = np.full(rows.size, float(run.attrs["strain_pct"]) / 100.0)
    sd = dict(curve.sd)
    for q in MODULI:
        if q in curve.observed and curve.observed[q] is not None:
            magnitude = measured_torque_modulus(run, q)
            s = noise_sd(noise, test, q, curve.observed[q], strain, float(run.attrs.get("radius_m", np.nan)),
                         float(run.attrs.get("torque_resolution_nm", np.nan)),
                         None if magnitude is None else magnitude[rows])
            if np.isfinite(s).any():
                sd[q] = s
    return dataclasses.replace(curve, sd=sd)


def fit_runs(model_key: str, runs: Sequence[xr.Dataset], target: str, relaxation: str = "measured",
             n_points: int = 25, n_random: int = 1, seed: int = 0, start: Mapping[str, float] | None = None,
             taus_s: Sequence[float] | None = None):
    """Fit a registered model jointly to the runs (thinned per curve); returns the ``FitResult``.

    The points are weighted by the noise measured in these runs (:func:`tissuemech.diagnosis.noise.fit_noise` of
    :func:`~tissuemech.diagnosis.noise.estimate_noise`), the noise model the residual tests then judge the fit
    under: with the fit's default floors a creep recovery's tail, a hundred times below the creep strain, weighed
    as little as a tenth of its measured precision, and its misfit became structure along time and strain.

    ``taus_s``: relaxation times [s] to rebuild a fixed-time QLV/Pipkin-Rogers model on
    (:func:`tissuemech.models.registry.model_on_times`); None keeps the registered model."""
    model = get_model(model_key) if taus_s is None else model_on_times(model_key, taus_s)
    noise = estimate_noise(runs)
    curves = curves_of_runs(runs, relaxation, n_points, noise)
    problem = fitting.FitProblem(model=model, curves=curves, target=target, model_key=model_key, scope="diagnosis",
                                 noise=fit_noise(noise))
    return fitting.fit(problem, starts=[start] if start else (), n_random=n_random, seed=seed)


#: observation points per curve of the free-time fit (the times need the shape of each phase, not every point;
#: the fixed-time refit on the refined times uses the caller's points)
POLISH_POINTS = 12
#: runs per test and condition in the free-time fit (the runs are level-normalised: replicates repeat the shape)
POLISH_RUNS_PER_CONDITION = 2


def polished_times(model_key: str, runs: Sequence[xr.Dataset], target: str, relaxation: str, n_points: int,
                   taus_s: Sequence[float], fit: fitting.FitResult) -> tuple[np.ndarray, fitting.FitResult]:
    """The relaxation times of a fixed-time QLV solid fitted with the rest of the model, from its NNLS times
    (:func:`tissuemech.material.refined_times` on :data:`POLISH_POINTS` points per curve of
    :data:`POLISH_RUNS_PER_CONDITION` runs per test and condition, weighted by the runs' measured noise); when the
    fixed-time model refitted on the refined times has a lower chi-square than ``fit``, it is returned with them
    (every later fit, fold and extension then uses them as it used the NNLS times). Other models (fluid,
    Pipkin-Rogers, free-time or fractional keys), a failed fit or no gain return ``(taus_s, fit)`` unchanged.
    """
    taus = np.asarray(taus_s, float)
    per_condition: dict[tuple, int] = {}
    sample = []
    for run in runs:
        key = (run.attrs.get("test"), condition_label(condition_of(run)))
        per_condition[key] = per_condition.get(key, 0) + 1
        if per_condition[key] <= POLISH_RUNS_PER_CONDITION:
            sample.append(run)
    noise = estimate_noise(runs)
    new = material.refined_times(model_key, curves_of_runs(sample, relaxation, min(n_points, POLISH_POINTS), noise),
                                 target, taus, fit, noise=fit_noise(noise))
    if new is None:
        return taus, fit
    refit = fit_runs(model_key, runs, target, relaxation, n_points=n_points, taus_s=new, start=dict(fit.params))
    return (new, refit) if refit.success and refit.chisqr <= fit.chisqr else (taus, fit)


def extension_gain(runs: Sequence[xr.Dataset], baseline_key: str, extension_key: str, target: str,
                   folds: Sequence[tuple[str, Callable[[xr.Dataset], bool]]], relaxation: str = "measured",
                   n_points: int = 25, seed: int = 0, taus_s: Sequence[float] | None = None,
                   fits_out: list | None = None) -> dict:
    """Held-out gain of ``extension_key`` over ``baseline_key``.

    Parameters
    ----------
    runs : the runs both models are fitted to (only the test kinds both describe)
    folds : ``(label, is_held_out(run))`` pairs; each fold fits on the other runs and scores the held-out
        ones (fitting.evaluate NRMSE)
    fits_out : when a list, receives one ``{"label", "train", "held_out", "baseline", "extension"}`` per fold and
        one with label ``"all"`` (the training runs, the held-out runs and both :class:`~tissuemech.fitting.FitResult`),
        for the cards the simulator replays (:mod:`tissuemech.diagnosis.simulation_cards`)
    taus_s : relaxation times [s] both models are rebuilt on (:func:`tissuemech.models.registry.model_on_times`), e.g.
        ``window_taus(resolved_window_s(runs))``; None keeps the registered models
    Returns
    -------
    ``{model, metric, before, after, gain, cv, parameters: {delta_aicc, baseline_aicc, extension_aicc,
    n_held_out_points}, folds: [{label, before, after}]}`` in the shape of a catalogue ``fix``
    (before/after = mean held-out NRMSE of baseline/extension). The baseline is refitted on the training
    runs of every fold (never reused from the full-data fit), exactly like the extension.
    """
    if taus_s is None:
        base_model, ext_model = get_model(baseline_key), get_model(extension_key)
    else:
        base_model, ext_model = model_on_times(baseline_key, taus_s), model_on_times(extension_key, taus_s)
    before, after, labels, n_held = [], [], [], []
    for label, held in folds:
        train = [r for r in runs if not held(r)]
        test = [r for r in runs if held(r)]
        test_curves = curves_of_runs(test, relaxation, n_points)
        if not train or not test_curves:
            continue
        fb = fit_runs(baseline_key, train, target, relaxation, n_points, seed=seed, taus_s=taus_s)
        fe = fit_runs(extension_key, train, target, relaxation, n_points, seed=seed, taus_s=taus_s)
        before.append(fitting.evaluate(base_model, fb.params, test_curves, target)["nrmse"])
        after.append(fitting.evaluate(ext_model, fe.params, test_curves, target)["nrmse"])
        labels.append(label)
        if fits_out is not None:
            fits_out.append({"label": label, "train": train, "held_out": test, "baseline": fb, "extension": fe})
        n_held.append(int(sum(min(np.size(v) for v in c.observed.values()) for c in test_curves if c.observed)))
    fb = fit_runs(baseline_key, runs, target, relaxation, n_points, seed=seed, taus_s=taus_s)
    fe = fit_runs(extension_key, runs, target, relaxation, n_points, seed=seed, taus_s=taus_s)
    if fits_out is not None:
        fits_out.append({"label": "all", "train": list(runs), "held_out": [], "baseline": fb, "extension": fe})
    b, a = float(np.mean(before)) if before else np.nan, float(np.mean(after)) if after else np.nan
    return {"model": extension_key, "metric": "held_out_nrmse", "before": b, "after": a,
            "gain": (b - a) / b if b > 0 else np.nan, "cv": "leave-one-condition-out (" + ", ".join(labels) + ")",
            "parameters": {"delta_aicc": float(fe.aicc - fb.aicc), "baseline_aicc": float(fb.aicc),
                           "extension_aicc": float(fe.aicc),
                           # per fold, for the noise-calibrated margin of report.diagnose
                           "n_held_out_points": float(min(n_held)) if n_held and min(n_held) > 0 else np.nan},
            "relaxation_times_s": None if taus_s is None else [float(x) for x in taus_s],
            "folds": [{"label": lab, "before": b_, "after": a_} for lab, b_, a_ in zip(labels, before, after)],
            "extension_params": {k: float(v) for k, v in fe.params.items()}}
