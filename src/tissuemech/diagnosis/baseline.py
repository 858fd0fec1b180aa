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
"""
from __future__ import annotations

import json
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np
import xarray as xr

from .. import fitting
from ..canonical import read_netcdf
from ..models.base import ConstitutiveModel, ResponseNotSupported
from ..models.plate import oscillation_moduli
from ..models.registry import get_model


def read_fit_record(path: str | Path) -> dict:
    """Parameters and metadata of a fit netCDF written by :func:`tissuemech.fitting.write_fit_netcdf`.

    Returns ``{"model_key", "target", "params", "aicc", "family", "correlations", "scope", "tests",
    "relaxation"}``;
    ``correlations`` maps ``"a|b"`` to the fitted correlation of every varying pair.
    """
    ds = read_netcdf(path)
    names = [str(n) for n in ds["param"].values]
    params = {n: float(v) for n, v in zip(names, ds["value"].values)}
    corr = {}
    c = ds["correlation"].values
    for i, a in enumerate(names):
        for j, b in enumerate(names):
            if j > i and np.isfinite(c[i, j]):
                corr[f"{a}|{b}"] = float(c[i, j])
    selection = json.loads(ds.attrs.get("selection", "[]"))
    return {"model_key": str(ds.attrs.get("model_key", Path(path).stem)), "target": str(ds.attrs.get("target", "")),
            "family": str(ds.attrs.get("family", "")), "scope": str(ds.attrs.get("scope", "")),
            "aicc": float(ds.attrs.get("aicc", np.nan)), "params": params, "correlations": corr,
            # relaxation strain-history treatment of the fit (fitting.relaxation_history); "measured" when
            # the record does not say
            "relaxation": str(ds.attrs.get("relaxation", "measured")),
            "tests": sorted({s.get("test", "") for s in selection})}


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
            f_hz = float(run.attrs.get("frequency_hz", np.nanmedian(run["frequency"].values) if "frequency" in run else 1.0))
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
        curve, rows = fitting._curve_and_rows(run, relaxation)
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


def _curves(runs: Sequence[xr.Dataset], relaxation: str, n_points: int) -> list[fitting.Curve]:
    out = []
    for r in runs:
        if r.attrs.get("test") in fitting.TEST_RESPONSE:
            try:
                out.append(fitting.thin(fitting.curve_from_run(r, relaxation), n_points))
            except (ValueError, KeyError):
                continue
    return out


def fit_runs(model_key: str, runs: Sequence[xr.Dataset], target: str, relaxation: str = "measured",
             n_points: int = 25, n_random: int = 1, seed: int = 0, start: Mapping[str, float] | None = None):
    """Fit a registered model jointly to the runs (thinned per curve); returns the ``FitResult``."""
    model = get_model(model_key)
    curves = _curves(runs, relaxation, n_points)
    problem = fitting.FitProblem(model=model, curves=curves, target=target, model_key=model_key, scope="diagnosis")
    return fitting.fit(problem, starts=[start] if start else (), n_random=n_random, seed=seed)


def extension_gain(runs: Sequence[xr.Dataset], baseline_key: str, extension_key: str, target: str,
                   folds: Sequence[tuple[str, Callable[[xr.Dataset], bool]]], relaxation: str = "measured",
                   n_points: int = 25, seed: int = 0) -> dict:
    """Held-out gain of ``extension_key`` over ``baseline_key``.

    Parameters
    ----------
    runs : the runs both models are fitted to (only the test kinds both describe)
    folds : ``(label, is_held_out(run))`` pairs; each fold fits on the other runs and scores the held-out
        ones (fitting.evaluate NRMSE)
    Returns
    -------
    ``{model, metric, before, after, gain, cv, parameters: {delta_aicc, folds}}`` in the shape of a
    catalogue ``fix`` (before/after = mean held-out NRMSE of baseline/extension).
    """
    base_model, ext_model = get_model(baseline_key), get_model(extension_key)
    before, after, labels = [], [], []
    for label, held in folds:
        train = [r for r in runs if not held(r)]
        test = [r for r in runs if held(r)]
        test_curves = _curves(test, relaxation, n_points)
        if not train or not test_curves:
            continue
        fb = fit_runs(baseline_key, train, target, relaxation, n_points, seed=seed)
        fe = fit_runs(extension_key, train, target, relaxation, n_points, seed=seed)
        before.append(fitting.evaluate(base_model, fb.params, test_curves, target)["nrmse"])
        after.append(fitting.evaluate(ext_model, fe.params, test_curves, target)["nrmse"])
        labels.append(label)
    fb = fit_runs(baseline_key, runs, target, relaxation, n_points, seed=seed)
    fe = fit_runs(extension_key, runs, target, relaxation, n_points, seed=seed)
    b, a = float(np.mean(before)) if before else np.nan, float(np.mean(after)) if after else np.nan
    return {"model": extension_key, "metric": "held_out_nrmse", "before": b, "after": a,
            "gain": (b - a) / b if b > 0 else np.nan, "cv": "leave-one-condition-out (" + ", ".join(labels) + ")",
            "parameters": {"delta_aicc": float(fe.aicc - fb.aicc), "baseline_aicc": float(fb.aicc),
                           "extension_aicc": float(fe.aicc)},
            "extension_params": {k: float(v) for k, v in fe.params.items()}}
