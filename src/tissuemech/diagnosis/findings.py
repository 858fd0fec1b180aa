"""What every detector shares: the diagnosis context, the finding and fix records and the diagnosis.json
writer, curve levels, the leave-one-group-out scoring of a correction and the one table of designs that separate
confounded covariates (:data:`SEPARATING_DESIGN`). The finding contract is :mod:`.catalogue`'s, the registry of
causes :mod:`.causes`."""
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

#: what would separate a covariate from the others it is confounded with in a design: the one table the
#: detectors (``separating_design`` of a finding) and the confounded-set report (``confounded``) quote;
#: keys are the kinds of :func:`separating_design`
SEPARATING_DESIGN = {
    "test_order": "vary the pauses between tests and shuffle the test order between samples, so that elapsed time "
                  "and the position in the sequence vary independently (a drift of the instrument or specimen "
                  "follows the clock, an effect of the loading history follows the position)",
    "first_load": "repeat the first test of each sample later in its sequence, or vary which test comes first",
    "temperature": "hold the temperature constant over the session, or change it in steps that do not follow the "
                   "clock (repeat one temperature at the start and at the end of the series, or randomise the "
                   "temperature order)",
    "elapsed_time": "record started_at or total_time, and repeat a reference test at the start and at the end of "
                    "the session at constant conditions (at least three tests per sample)",
    "condition": "randomise the test order across samples, or repeat a reference test (same kind and condition as "
                 "an early one) at the end of each sample's sequence",
    "specimen": "interleave the specimens (alternate samples of different specimens over the session, or spread "
                "each specimen over several days), so that specimen and session time vary independently",
    "gap": "measure at two gaps at the same conditions",
    "strain": "repeat the test at two strain amplitudes at the same conditions",
    "factor": "cross the factor levels with the other covariates (each level at several of their values)",
}


def separating_design(covariate: str) -> str:
    """The :data:`SEPARATING_DESIGN` sentence of a covariate name (residual-table column, curve-level column or
    ``factor:<column>``)."""
    name = covariate.lower()
    for key, kinds in (("first_load", ("first_load",)), ("test_order", ("position", "test_order", "order")),
                       ("temperature", ("temperature",)), ("elapsed_time", ("elapsed",)),
                       ("condition", ("condition",)), ("specimen", ("specimen",)), ("gap", ("gap",)),
                       ("strain", ("strain",))):
        if any(k in name for k in kinds):
            return SEPARATING_DESIGN[key]
    return SEPARATING_DESIGN["factor"]


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


def describe_fix(before: float, after: float) -> str:
    """A held-out score in bounded plain words: "held-out error 0.12 -> 0.08 (33 % lower)", "... (2.5x higher)",
    "... (more than 100x higher)"."""
    try:
        b, a = float(before), float(after)
    except (TypeError, ValueError):
        return "not scored"
    if not (np.isfinite(b) and np.isfinite(a)) or b < 0 or a < 0:
        return "not scored"
    head = f"held-out error {b:.3g} -> {a:.3g}"
    if a <= b:
        return head + (f" ({100 * (b - a) / b:.0f} % lower)" if b > 0 else " (unchanged)")
    if b == 0 or a / b > 100:
        return head + " (more than 100x higher: the fix makes the held-out predictions worse)"
    return head + (f" ({100 * (a - b) / b:.0f} % higher)" if a < 2 * b else f" ({a / b:.2g}x higher)")


def fix_record(model: str, metric: str, before: float, after: float, cv: str, **parameters) -> dict:
    gain = (before - after) / before if before > 0 and np.isfinite(after) else np.nan
    return {"model": model, "metric": metric, "before": float(before), "after": float(after),
            "gain": float(gain), "cv": cv, "summary": describe_fix(before, after),
            "parameters": {k: (float(v) if isinstance(v, (int, float, np.floating)) else v)
                           for k, v in parameters.items()}}


def describe_log_change(log_change: float) -> str:
    """A change of ln(observed/predicted) in bounded plain words: "change by +12.3 %" up to a factor 3, else
    "rise/fall by a factor 40" (beyond a factor 1000: "by more than a factor 1000")."""
    try:
        x = float(log_change)
    except (TypeError, ValueError):
        x = np.nan
    if not np.isfinite(x):
        return "change by an undetermined amount"
    if abs(x) <= np.log(3.0):
        return f"change by {100 * np.expm1(x):+.1f} %"
    way = "rise" if x > 0 else "fall"
    return f"{way} by a factor {np.exp(abs(x)):.2g}" if abs(x) < np.log(1e3) else f"{way} by more than a factor 1000"


def rms(x) -> float:
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x ** 2))) if x.size else np.nan


#: the quantity that carries a curve's level, by test (else the stress): G' of a sweep, the strain of a creep
LEVEL_QUANTITY = {"amplitude_sweep": "storage_modulus", "frequency_sweep": "storage_modulus",
                  "creep_recovery": "shear_strain"}
#: tests whose level quantity is a compliance: a stiffer curve answers with less of it
COMPLIANCE_LEVEL_TESTS = ("creep_recovery",)


def primary_rows(table: pd.DataFrame) -> pd.DataFrame:
    """Rows of the quantity that carries each curve's level (:data:`LEVEL_QUANTITY`: stress for strain-controlled
    time-domain tests, G' for sweeps, the strain for creep), with ``log_ratio`` as a stiffness scale: a creep's
    log(observed/predicted) strain is negated (:data:`COMPLIANCE_LEVEL_TESTS`), so that every level-based detector
    (drift, first load, outlier specimen, temperature, covariates) reads creep curves as it reads the others
    instead of finding no level in them."""
    q = table["test"].map(LEVEL_QUANTITY).fillna("shear_stress")
    rows = table[(table["quantity"] == q) & np.isfinite(table["log_ratio"])]
    compliance = rows["test"].isin(COMPLIANCE_LEVEL_TESTS)
    if compliance.any():
        rows = rows.assign(log_ratio=np.where(compliance, -rows["log_ratio"], rows["log_ratio"]))
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
