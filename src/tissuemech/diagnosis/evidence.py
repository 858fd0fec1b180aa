"""Discrepancy evidence: tidy residual tables with every covariate, and cross-test consistency checks.

Residual table
--------------
:func:`residual_table` turns canonical runs (``tissuemech.canonical``) and a fitted model's predictions on
them into one row per (run, point, quantity) with

* identity: ``curve`` (run id), ``test``, ``specimen``, ``sample`` (``specimen/sample``, unique across
  specimens), ``condition`` (test + nominal
  condition), ``quantity`` (canonical variable compared: ``shear_stress``, ``storage_modulus`` ...);
* ``observed``, ``predicted``, ``residual`` = observed - predicted (quantity units), ``sigma`` (noise SD of the
  observed value from :func:`estimate_noise`: the within-curve scatter of the data, never an instrument
  constant; a torque resolution is used only where declared), ``std_residual`` = residual / sigma,
  ``rel_residual`` = residual / |predicted|, ``log_ratio`` = ln(observed / predicted) where both are positive
  (the noise model is :mod:`.noise`);
* covariates: ``strain`` [1], ``strain_sq``, ``log_rate`` (log10 of the nominal rate in 1/s),
  ``strain_x_log_rate``, ``strain_sq_x_log_rate``, ``time_in_test`` [s], ``log_time`` (log10 s),
  ``elapsed_time`` [s since the session start: the ``total_time`` channel, else the run's ``started_at``
  relative to the first run of its specimen plus ``time``], ``test_order``, ``first_load`` (1 on the first run of a
  sample), ``frequency_sq`` [(rad/s)^2], ``inverse_gap`` [1/m], ``radius_m`` [m; NaN when neither the export
  nor the sample sheet gives it],
  ``predicted_abs`` / ``observed_abs`` [quantity units], ``above_noise`` (|observed| > :data:`ABOVE_NOISE_SIGMAS`
  sigma: the row filter of level and structure tests), every
  logged channel of :data:`LOGGED_CHANNELS` present in the run, and every numeric ``covariate_*`` attribute.

Predictions are a mapping ``{canonical variable: array aligned with the run's points}`` per run; the
builder compares every predicted variable that the run also measured.

Cross-test consistency
----------------------
:func:`fit_prony_relaxation` identifies a Prony spectrum (fixed log-spaced times, NNLS, ``science.md``
4.1) from relaxation data, either treating the ramp as a step or through the actual strain history (the
exact recursion of :mod:`tissuemech.models.recursion`); :func:`tissuemech.spectra.prony_complex_modulus` interconverts it to
G', G''; :func:`booij_thoone` is the local Kramers-Kronig estimate G'' ~ (pi/2) dG'/dln(omega).
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd
import xarray as xr
import scipy

from ..curves import QUALITY_FLAG_VARIABLE
from ..models.recursion import prony_branch_histories
from .noise import ABOVE_NOISE_SIGMAS, COMPARED_QUANTITIES, estimate_noise, measured_torque_modulus, noise_sd


#: logged channels carried into the residual table as covariates when a run has them
LOGGED_CHANNELS = ("temperature", "gap", "normal_force", "raw_phase", "deflection_angle")



def run_id(run: xr.Dataset) -> str:
    """Stable curve identifier of a run (the ``run`` attribute, else specimen/sample/test/order)."""
    if "run" in run.attrs:
        return str(run.attrs["run"])
    a = run.attrs
    return f"{a.get('specimen', '?')}/{a.get('sample', '?')}/{a.get('test', '?')}/{a.get('order', '?')}"


def nominal_rate(run: xr.Dataset) -> float:
    """Nominal shear rate (1/s) of a run: the ``shear_rate_1_per_s`` attribute, else the median of the
    positive ``shear_rate`` channel; NaN when the run has no rate."""
    if "shear_rate_1_per_s" in run.attrs:
        return float(run.attrs["shear_rate_1_per_s"])
    if "shear_rate" in run:
        r = np.abs(run["shear_rate"].values)
        r = r[np.isfinite(r) & (r > 0)]
        if r.size:
            return float(np.median(r))
    return np.nan


def nominal_strain(run: xr.Dataset) -> float:
    """Nominal strain of a relaxation/oscillation run (1): ``strain_pct``/100, else the maximum strain."""
    if "strain_pct" in run.attrs:
        return float(run.attrs["strain_pct"]) / 100.0
    if "shear_strain" in run:
        s = np.abs(run["shear_strain"].values)
        s = s[np.isfinite(s)]
        return float(s.max()) if s.size else np.nan
    return np.nan


def condition_label(run: xr.Dataset) -> str:
    """Test kind plus its nominal condition, e.g. ``constant_shear_rate@0.1/s``."""
    a = run.attrs
    test = str(a.get("test", "unknown"))
    if test == "constant_shear_rate" and "shear_rate_1_per_s" in a:
        return f"{test}@{float(a['shear_rate_1_per_s']):g}/s"
    if test == "stress_relaxation":
        return f"{test}@{nominal_strain(run):g}"
    if test == "creep_recovery" and "stress_pa" in a:
        return f"{test}@{float(a['stress_pa']):g}Pa"
    if test == "amplitude_sweep" and "frequency_hz" in a:
        return f"{test}@{float(a['frequency_hz']):g}Hz"
    if test == "frequency_sweep" and "strain_pct" in a:
        return f"{test}@{float(a['strain_pct']):g}%"
    return test



def first_load_flags(runs: Sequence[xr.Dataset]) -> list[float]:
    """1 for the run with the smallest ``order`` of each (specimen, sample), else 0; NaN for a run whose test
    order the export and sample sheet do not give (never a default order)."""
    first: dict[tuple, float] = {}
    keys, orders = [], []
    for r in runs:
        key = (str(r.attrs.get("specimen")), str(r.attrs.get("sample")))
        o = float(r.attrs.get("order", np.nan))
        keys.append(key)
        orders.append(o)
        if np.isfinite(o):
            first[key] = min(first.get(key, np.inf), o)
    return [float(o == first[k]) if np.isfinite(o) else np.nan for k, o in zip(keys, orders)]


def session_offsets_s(runs: Sequence[xr.Dataset]) -> list[float]:
    """Start of each run in seconds since the first run of its specimen, from the ``started_at`` attribute
    (ISO 8601); NaN where it is missing. Used as elapsed time when a run has no ``total_time`` channel."""
    starts = []
    for r in runs:
        try:
            starts.append(pd.Timestamp(str(r.attrs["started_at"])))
        except (KeyError, ValueError):
            starts.append(None)
    first: dict[str, pd.Timestamp] = {}
    for r, t in zip(runs, starts):
        if t is not None:
            key = str(r.attrs.get("specimen"))
            first[key] = min(first.get(key, t), t)
    return [((t - first[str(r.attrs.get("specimen"))]).total_seconds() if t is not None else np.nan)
            for r, t in zip(runs, starts)]


def _point_array(run: xr.Dataset, name: str, n: int) -> np.ndarray:
    if name in run:
        v = np.asarray(run[name].values, float)
        if v.size == n:
            return v
    return np.full(n, np.nan)


def residual_table(runs: Sequence[xr.Dataset], predictions: Sequence[Mapping[str, np.ndarray]],
                   model: str = "model", noise: Mapping | None = None) -> pd.DataFrame:
    """Tidy residual table of a model's predictions against measured runs (columns: module docstring).

    Parameters
    ----------
    runs : canonical run datasets (dimension ``point``)
    predictions : per run, ``{canonical variable: predicted array}`` aligned with the run's points;
        variables the run did not measure are ignored
    model : model key recorded in the ``model`` column
    noise : noise model of :func:`estimate_noise` (estimated from ``runs`` when None)

    Returns
    -------
    pandas.DataFrame, one row per (run, point, compared quantity); rows with non-finite observed or
    predicted values are dropped.
    """
    if len(runs) != len(predictions):
        raise ValueError(f"{len(runs)} runs but {len(predictions)} prediction sets")
    noise = estimate_noise(runs) if noise is None else noise
    firsts = first_load_flags(runs)
    offsets = session_offsets_s(runs)
    blocks = []
    for run, pred, first, offset in zip(runs, predictions, firsts, offsets):
        a = run.attrs
        n = run.sizes.get("point", 0)
        if n == 0:
            continue
        # no plate radius in the export/sample sheet -> NaN (never a default): radius-based quantities
        # (torque offset in N m, rim-stress floor) are then not computable
        radius = float(a.get("radius_m", np.nan))
        strain = np.abs(_point_array(run, "shear_strain", n))
        if not np.isfinite(strain).any() and "strain_pct" in a:
            strain = np.full(n, float(a["strain_pct"]) / 100.0)
        rate = nominal_rate(run)
        log_rate = np.log10(rate) if np.isfinite(rate) and rate > 0 else np.nan
        time = _point_array(run, "time", n)
        total = _point_array(run, "total_time", n)
        if not np.isfinite(total).any() and np.isfinite(offset):
            total = offset + np.where(np.isfinite(time), time, 0.0)
        omega = _point_array(run, "angular_frequency", n)
        if not np.isfinite(omega).any():
            omega = 2.0 * np.pi * _point_array(run, "frequency", n)
        gap = _point_array(run, "gap", n)
        if not np.isfinite(gap).any() and "gap_m" in a:
            gap = np.full(n, float(a["gap_m"]))
        base = {
            "model": model, "curve": run_id(run), "test": str(a.get("test", "unknown")),
            # sample labels are often reused across specimens (s01, s02 ...): the key is specimen/sample
            "specimen": str(a.get("specimen", "")), "sample": f"{a.get('specimen', '')}/{a.get('sample', '')}",
            "condition": condition_label(run), "point": np.arange(n),
            "strain": strain, "strain_sq": strain ** 2, "log_rate": np.full(n, log_rate),
            "strain_x_log_rate": strain * log_rate, "strain_sq_x_log_rate": strain ** 2 * log_rate,
            "time_in_test": time, "log_time": np.log10(np.where(time > 0, time, np.nan)),
            "elapsed_time": total, "test_order": np.full(n, float(a.get("order", np.nan))),
            "first_load": np.full(n, float(first)), "frequency_sq": omega ** 2,
            "inverse_gap": 1.0 / gap, "radius_m": np.full(n, radius),
            "quality_flag": (np.asarray(run[QUALITY_FLAG_VARIABLE].values, int) if QUALITY_FLAG_VARIABLE in run
                             else np.zeros(n, int)),
        }
        for ch in LOGGED_CHANNELS:
            if ch in run:
                base[f"channel_{ch}"] = _point_array(run, ch, n)
        for k, v in a.items():
            if k.startswith("covariate_") and isinstance(v, (int, float, np.integer, np.floating)):
                base[k] = np.full(n, float(v))
        for q in COMPARED_QUANTITIES:
            if q not in pred or q not in run:
                continue
            obs = np.asarray(run[q].values, float)
            prd = np.asarray(pred[q], float)
            if prd.shape != obs.shape:
                raise ValueError(f"prediction of {q!r} for run {run_id(run)!r} has shape {prd.shape}, "
                                 f"data {obs.shape}")
            block = pd.DataFrame(base)
            block["quantity"] = q
            block["observed"] = obs
            block["predicted"] = prd
            block["residual"] = obs - prd
            sigma = noise_sd(noise, base["test"], q, obs, strain, radius,
                             float(a.get("torque_resolution_nm", np.nan)), measured_torque_modulus(run, q))
            block["sigma"] = sigma
            block["std_residual"] = (obs - prd) / sigma
            block["rel_residual"] = (obs - prd) / np.where(np.abs(prd) > 0, np.abs(prd), np.nan)
            with np.errstate(divide="ignore", invalid="ignore"):
                block["log_ratio"] = np.where((obs > 0) & (prd > 0), np.log(obs / prd), np.nan)
            block["predicted_abs"] = np.abs(prd)
            block["observed_abs"] = np.abs(obs)
            # the row filter of the level/structure tests reads the OBSERVED magnitude against the noise
            block["above_noise"] = np.abs(obs) > ABOVE_NOISE_SIGMAS * sigma
            blocks.append(block[np.isfinite(obs) & np.isfinite(prd)])
    if not blocks:
        return pd.DataFrame(columns=["model", "curve", "test", "quantity", "observed", "predicted", "residual"])
    return pd.concat(blocks, ignore_index=True)


def residual_table_to_xarray(table: pd.DataFrame) -> xr.Dataset:
    """Residual table as an xarray Dataset (dimension ``row``) for netCDF output."""
    t = table.reset_index(drop=True)
    ds = xr.Dataset({c: ("row", t[c].to_numpy() if t[c].dtype != object else t[c].astype(str).to_numpy())
                     for c in t.columns})
    return ds


# ------------------------------------------------------------------------------------------------
# cross-test consistency (linear viscoelastic interconversion)
# ------------------------------------------------------------------------------------------------
def fit_prony_relaxation(time_s: np.ndarray, stress_pa: np.ndarray, strain: np.ndarray, taus_s: np.ndarray,
                         ramp_aware: bool = True, weights: np.ndarray | None = None) -> dict:
    """Linear Prony spectrum G(t) = G_inf + sum_i G_i exp(-t/tau_i) from one relaxation test, by NNLS.

    Parameters
    ----------
    time_s, stress_pa, strain : the run's channels (time from the start of the ramp)
    taus_s : fixed relaxation times (s)
    ramp_aware : True -> the stress is the convolution of G with the actual strain history (exact
        recursion, any rise time); False -> the thesis analysis: the hold is treated as an ideal step of
        the final strain applied at ``time_s[0]`` (ramp points are dropped)
    weights : optional per-point weights (1/sigma)

    Returns
    -------
    dict with ``g_inf_pa``, ``g_pa`` (array), ``taus_s``, ``rss`` (weighted), ``n``, ``k`` (number of
    positive terms), ``predicted`` (stress at the points used) and ``mask`` of the points used.
    """
    t = np.asarray(time_s, float)
    s = np.asarray(stress_pa, float)
    g = np.asarray(strain, float)
    taus = np.asarray(taus_s, float)
    gamma0 = float(np.nanmax(np.abs(g)))
    if ramp_aware:
        mask = np.isfinite(s) & np.isfinite(g)
        branch = prony_branch_histories(t[mask], np.repeat(g[mask][None, :], taus.size, axis=0), taus)
        A = np.column_stack([g[mask]] + [branch[i] for i in range(taus.size)])
    else:
        mask = np.isfinite(s) & (np.abs(g) >= 0.98 * gamma0)
        tt = t[mask] - t[0]
        A = np.column_stack([np.full(tt.size, gamma0)] + [gamma0 * np.exp(-tt / tau) for tau in taus])
    y = s[mask]
    w = np.ones_like(y) if weights is None else np.asarray(weights, float)[mask]
    coef, _ = scipy.optimize.nnls(A * w[:, None], y * w)
    pred = A @ coef
    return {"g_inf_pa": float(coef[0]), "g_pa": coef[1:], "taus_s": taus,
            "rss": float(np.sum(((y - pred) * w) ** 2)), "n": int(y.size), "k": int(np.count_nonzero(coef)),
            "predicted": pred, "mask": mask}


def booij_thoone(omega_rad_s: np.ndarray, storage_pa: np.ndarray) -> np.ndarray:
    """Local Kramers-Kronig estimate G''_KK = (pi/2) dG'/dln(omega) (Booij & Thoone 1982), in Pa.

    The derivative is taken on ln(omega) with second-order central differences (sorted by omega).
    """
    w = np.asarray(omega_rad_s, float)
    order = np.argsort(w)
    d = np.empty_like(w)
    d[order] = np.gradient(np.asarray(storage_pa, float)[order], np.log(w[order]))
    return 0.5 * np.pi * d
