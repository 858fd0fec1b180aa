r"""Whether a fit can be recommended: determined parameters, a misfit consistent with the measured noise, and skill
over the curves' means. One rule for every fit scope (:func:`verdict`).

* **Determined** (:func:`determined`): converged, with a covariance, no parameter at a bound, and every varying
  parameter's standard error within its value (prune modes rather than report G_inf = 0.0002 +- 264 Pa).
* **Noise** (:func:`point_noise`): per point of an averaged curve, the scatter between its replicate samples and the
  curve's own point-to-point noise (:func:`tissuemech.stats.relative_noise_sd`), in quadrature.
* **Misfit in noise units** (:func:`misfit_in_noise_units`): the RMS residual over every point divided by that noise,
  in the quantity the fit compares (torque, stress, strain; log moduli for sweeps).
* **Adequate** (:func:`is_adequate`): misfit at most :data:`ADEQUACY_FACTOR` = 2 noise SDs.
* **Skill**: ``1 - SSE / SSE of each curve's own mean`` in noise units; a model with skill <= 0 predicts no better
  than a flat line through each curve.

A scope's verdict is ``supported`` (a recommendable, determined, adequate fit with skill > 0 exists; the scope's
preferred one is recommended) or ``no_model_supported`` with the reason; no card is exported for the latter.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace

import numpy as np
import pandas as pd

from . import fitting as F
from .models.base import ConstitutiveModel
from .stats import relative_noise_sd

#: a fit is adequate when its RMS misfit is at most this many noise SDs (:func:`point_noise`): the typical point
#: off by no more than twice the scatter a replicate shows about the mean (a replicate itself is off by about one)
ADEQUACY_FACTOR = 2.0
#: the columns :func:`assess` adds to a ranking table
ASSESSMENT_COLUMNS = ("determined", "undetermined", "misfit_noise_units", "adequate", "skill", "signal_to_scatter",
                      "noise_relative")


def point_noise(curve: F.Curve, observable: str, values: np.ndarray) -> np.ndarray:
    """Noise SD of each point of an averaged curve [unit of ``values``]: the scatter between its replicate samples
    (``curve.sd``) and the curve's own point-to-point noise (:func:`tissuemech.stats.relative_noise_sd` times the
    value), in quadrature. NaN where neither is measured.

    The replicate scatter, not the standard error of the mean: a model stands for the material a new specimen is
    made of, and one that predicts the mean curve as closely as a typical replicate does is as good as the data can
    tell; a single-specimen curve has only its point-to-point noise.
    """
    y = np.asarray(values, float)
    sd = curve.sd.get(observable)
    between = np.zeros_like(y) if sd is None else np.where(np.isfinite(sd), np.asarray(sd, float), 0.0)
    rel = relative_noise_sd(y)
    within = np.abs(y) * rel if np.isfinite(rel) else np.zeros_like(y)
    out = np.sqrt(between ** 2 + within ** 2)
    return np.where(out > 0, out, np.nan)


def misfit_in_noise_units(model: ConstitutiveModel, params: Mapping[str, float], curves: Sequence[F.Curve],
                          target: str) -> dict:
    """Misfit of fixed parameters in units of the measured noise (:func:`point_noise`), and its skill.

    Residuals are taken in the quantity the fit compares (:func:`tissuemech.fitting.target_observations`: torque
    for plate histories with ``target="torque"``); for log-fitted responses (sweeps) relative to the value.

    Returns
    -------
    ``{"misfit": RMS residual / noise over every point, "per_curve": {label: misfit}, "skill": 1 - SSE/SSE of each
    curve's mean (noise units; <= 0: no better than the mean), "n_curves", "n_points", "noise_relative": median
    noise / |value|, "signal_to_scatter": median |value| / replicate SD}``
    """
    problem = F.FitProblem(model=model, curves=list(curves), target=target)
    terms = problem.curve_terms(dict(params))
    z_all, zmean_all, per_curve, rel, s2s = [], [], {}, [], []
    for c, t in zip(problem.curves, terms):
        _, sds = F.target_observations(c, target)  # the SDs in the compared quantity (torque or stress)
        measured = replace(c, sd=sds)
        zc, zm = [], []
        for k, (y, f, _) in t.items():
            sig = point_noise(measured, k, y)
            ok = np.isfinite(sig) & np.isfinite(y) & np.isfinite(f)
            if c.response in F.LOG_RESPONSES:
                ok &= (y != 0)
            if not ok.any():
                continue
            if c.response in F.LOG_RESPONSES:
                yy, ff, ss = np.log(np.abs(y[ok])), np.log(np.maximum(np.abs(f[ok]), 1e-300)), sig[ok] / np.abs(y[ok])
            else:
                yy, ff, ss = y[ok], f[ok], sig[ok]
            zc.append((ff - yy) / ss)
            zm.append((yy - yy.mean()) / ss)
            rel.append(np.median(sig[ok] / np.maximum(np.abs(y[ok]), 1e-300)))
            sd = sds.get(k)
            if sd is not None and np.isfinite(sd).any() and np.nanmax(sd) > 0:
                s2s.append(np.nanmedian(np.abs(y) / np.where(np.asarray(sd) > 0, sd, np.nan)))
        if zc:
            z = np.concatenate(zc)
            per_curve[c.label] = float(np.sqrt(np.mean(z ** 2)))
            z_all.append(z)
            zmean_all.append(np.concatenate(zm))
    if not z_all:
        return {"misfit": np.nan, "per_curve": {}, "skill": np.nan, "n_curves": 0, "n_points": 0,
                "noise_relative": np.nan, "signal_to_scatter": np.nan}
    z, zm = np.concatenate(z_all), np.concatenate(zmean_all)
    sse_mean = float(np.sum(zm ** 2))
    return {"misfit": float(np.sqrt(np.mean(z ** 2))), "per_curve": per_curve,
            "skill": float(1.0 - np.sum(z ** 2) / sse_mean) if sse_mean > 0 else np.nan,
            "n_curves": len(z_all), "n_points": int(z.size),
            "noise_relative": float(np.median(rel)) if rel else np.nan,
            "signal_to_scatter": float(np.nanmedian(s2s)) if s2s else np.nan}


def is_adequate(misfit: float) -> bool:
    """Misfit (noise units, :func:`misfit_in_noise_units`) within :data:`ADEQUACY_FACTOR` of the noise."""
    return bool(np.isfinite(misfit) and misfit <= ADEQUACY_FACTOR)


def undetermined(result: F.FitResult) -> list[str]:
    """Varying parameters of a fit whose standard error exceeds their value, or that have none (no covariance)."""
    out = []
    for name in result.varying:
        se, v = result.stderr.get(name, np.nan), result.params.get(name, np.nan)
        if not np.isfinite(se) or (v != 0 and se > abs(v)):
            out.append(name)
    return out


def determined(result: F.FitResult) -> bool:
    """Converged, with a covariance, no parameter at a bound and every standard error within its value."""
    return bool(result.success and not F.at_bound_parameters(result.flags)
                and F.has_covariance(result.flags, result.stderr, result.varying) and not undetermined(result))


def assess(model: ConstitutiveModel, result: F.FitResult, curves: Sequence[F.Curve], target: str) -> dict:
    """The :data:`ASSESSMENT_COLUMNS` of one fit: ``determined``, ``undetermined`` (names), ``misfit_noise_units``,
    ``adequate``, ``skill``, ``signal_to_scatter``, ``noise_relative``."""
    m = misfit_in_noise_units(model, result.params, curves, target)
    return {"determined": determined(result), "undetermined": "; ".join(undetermined(result)),
            "misfit_noise_units": m["misfit"], "adequate": is_adequate(m["misfit"]), "skill": m["skill"],
            "signal_to_scatter": m["signal_to_scatter"], "noise_relative": m["noise_relative"]}


def add_assessment(table: pd.DataFrame, assessed: Mapping[str, Mapping]) -> pd.DataFrame:
    """``table`` (a ranking table, one row per ``model``) with the :data:`ASSESSMENT_COLUMNS` of ``assessed``
    (model -> :func:`assess`); rows without an assessment get NaN/False."""
    blank = {"determined": False, "undetermined": "", "misfit_noise_units": np.nan, "adequate": False,
             "skill": np.nan, "signal_to_scatter": np.nan, "noise_relative": np.nan}
    for col in ASSESSMENT_COLUMNS:
        table[col] = [assessed.get(m, blank)[col] for m in table["model"]]
    return table


def supported_mask(table: pd.DataFrame) -> np.ndarray:
    """Fits a scope may recommend: ``recommendable`` (converged, with a covariance, no parameter at a bound) and, in
    an assessed table (:func:`add_assessment`), determined, adequate and better than the curves' means."""
    ok = table["recommendable"].fillna(False).astype(bool).to_numpy(copy=True) if "recommendable" in table \
        else np.ones(len(table), bool)
    if "determined" in table:
        ok &= (table["determined"].astype(bool) & table["adequate"].astype(bool)
               & (table["skill"].astype(float) > 0)).to_numpy()
    return ok


def verdict(table: pd.DataFrame, preferred: Sequence[str] = ()) -> dict:
    """The recommended model and the scope's verdict from an assessed ranking table (:func:`add_assessment`).

    A model is supported when its fit is recommendable (converged, with a covariance, no parameter at a bound),
    determined, predicts better than the curves' means (``skill`` > 0) and is adequate. The recommended model is the
    first supported one in ``preferred`` order (a scope's own choice, e.g. the thesis rule), else the supported one
    first in the table's order. Without a supported model the verdict is ``no_model_supported`` and the reason
    names what failed for the table's first candidate (its misfit against the noise, its undetermined parameters,
    its skill), the best determined fit, and the signal against the replicate scatter.

    Returns ``{"recommended", "verdict" ("supported" or "no_model_supported"), "reason", "misfit_noise_units"}``.
    """
    if table.empty or "model" not in table or "determined" not in table:
        return {"recommended": None, "verdict": "no_model_supported", "reason": "no candidate could be fitted",
                "misfit_noise_units": np.nan}
    supported = table[supported_mask(table)]
    if not supported.empty:
        names = list(supported["model"])
        chosen = next((m for m in preferred if m in names), names[0])
        row = supported[supported["model"] == chosen].iloc[0]
        return {"recommended": str(chosen), "verdict": "supported",
                "reason": (f"misfit {row['misfit_noise_units']:.3g} noise SDs (adequate: <= {ADEQUACY_FACTOR:g}), "
                           f"parameters determined, skill {row['skill']:.3g} over the curves' means"),
                "misfit_noise_units": float(row["misfit_noise_units"])}
    best = table.iloc[0]
    parts = []
    if not bool(best.get("recommendable", False)):
        parts.append(f"{best['model']} is not converged with a covariance and free of its bounds")
    if not bool(best["determined"]):
        parts.append(f"{best['model']} has undetermined parameters ({best['undetermined'] or 'no covariance'})")
    if not best["skill"] > 0:
        parts.append(f"{best['model']} predicts no better than the curves' means (skill {best['skill']:.3g})")
    if not bool(best["adequate"]):
        parts.append(f"{best['model']} misfits by {best['misfit_noise_units']:.3g} noise SDs "
                     f"(adequate: <= {ADEQUACY_FACTOR:g})")
    alternatives = table[table["recommendable"].astype(bool) & table["determined"].astype(bool)]
    if not alternatives.empty and alternatives.iloc[0]["model"] != best["model"]:
        a = alternatives.iloc[0]
        parts.append(f"the best determined fit, {a['model']}, misfits by {a['misfit_noise_units']:.3g} noise SDs "
                     f"with skill {a['skill']:.3g}")
    s2s = float(np.nanmedian(table["signal_to_scatter"])) if "signal_to_scatter" in table else np.nan
    parts.append(f"signal {s2s:.3g} times the replicate scatter (median |mean|/SD)" if np.isfinite(s2s)
                 else "no replicate scatter measured (one sample per curve): the noise is the curves' own")
    return {"recommended": None, "verdict": "no_model_supported", "reason": "; ".join(parts),
            "misfit_noise_units": float(best["misfit_noise_units"])}
