"""What every detector of the catalogue shares: the cause ids and their signatures (which covariate
structure each cause explains), the diagnosis context, the finding and fix records and the diagnosis.json writer, curve levels
and the leave-one-group-out scoring of a correction. The catalogue itself is :mod:`.catalogue`."""
from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
import xarray as xr

from ..canonical import to_jsonable, write_text
from ..records import Finding

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


def rms(x) -> float:
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


def fixed_effect_design(frame: pd.DataFrame, columns: Sequence[str], fixed_effects: Sequence[str]) -> pd.DataFrame:
    X = frame[list(columns)].astype(float).copy()
    for fe in fixed_effects:
        if frame[fe].nunique() > 1:
            X = X.join(pd.get_dummies(frame[fe], prefix=fe, drop_first=True, dtype=float))
    return X


def demean_by(frame: pd.DataFrame, value: str, by: str) -> np.ndarray:
    return (frame[value] - frame.groupby(by)[value].transform("mean")).to_numpy(float)


def group_cv(frame: pd.DataFrame, group: str, fit: Callable[[pd.DataFrame], object],
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
    return rms(np.concatenate(before)), rms(np.concatenate(after))


def cv_group_column(frame: pd.DataFrame) -> str:
    for col in ("specimen", "sample", "condition", "curve"):
        if col in frame and frame[col].nunique() >= 3:
            return col
    return "curve"


def write_diagnosis_json(result: dict, path: str | Path, dataset: str = "") -> Path:
    """Atomically write a diagnosis result as ``diagnosis.json`` (structure tests are summarised, not dumped;
    NaN/inf -> null through :func:`tissuemech.canonical.to_jsonable`). Every finding is validated as the
    :class:`tissuemech.records.Finding` the report reads (:class:`~tissuemech.records.FindingError` names it)."""
    out = {k: v for k, v in result.items() if k != "structure_tests"}
    out["dataset"] = dataset
    out["n_structure_tests"] = (len(result["structure_tests"]) if "structure_tests" in result
                                else int(result.get("n_structure_tests", 0)))  # a diagnosis.json written again
    out = to_jsonable(out)
    for finding in out.get("findings", []):
        Finding.from_dict(finding)  # the record the report reads: a malformed finding stops here, named
    return write_text(json.dumps(out, indent=2) + "\n", path)
