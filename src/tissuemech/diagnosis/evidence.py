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
  ``rel_residual`` = residual / |predicted|, ``log_ratio`` = ln(observed / predicted) where both are positive;
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

from ..models.recursion import prony_branch_histories
from ..stats import relative_differences

#: a row enters the level and structure tests only where its OBSERVED magnitude exceeds this many noise SDs
#: (a detection convention, not an instrument property)
ABOVE_NOISE_SIGMAS = 5.0
#: fewest second differences a noise block needs for the binned variance fit; fewer -> relative scale only
_MIN_BIN_POINTS = 10

#: logged channels carried into the residual table as covariates when a run has them
LOGGED_CHANNELS = ("temperature", "gap", "normal_force", "raw_phase", "deflection_angle")

#: quantities a residual table may compare, in preference order
COMPARED_QUANTITIES = ("shear_stress", "storage_modulus", "loss_modulus", "torque", "normal_force",
                       "shear_strain", "relaxation_modulus", "nominal_stress")

OSCILLATORY_TESTS = ("amplitude_sweep", "frequency_sweep")
TIME_DOMAIN_TESTS = ("constant_shear_rate", "stress_relaxation", "creep_recovery", "simple_shear")


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


#: oscillation quantities that are a torque divided by the strain amplitude (their absolute noise is not constant)
MODULI = ("storage_modulus", "loss_modulus")


def _stress_per_modulus(run: xr.Dataset, test: str, quantity: str) -> np.ndarray | None:
    """The strain amplitude of every point of a sweep's modulus (stress amplitude = modulus x amplitude);
    None for other quantities and where the sweep records no strain amplitude."""
    if quantity not in MODULI or test not in OSCILLATORY_TESTS:
        return None
    n = run[quantity].size
    if "shear_strain" in run and run["shear_strain"].size == n and np.isfinite(run["shear_strain"].values).any():
        return np.asarray(run["shear_strain"].values, float)
    if "strain_pct" in run.attrs:
        return np.full(n, float(run.attrs["strain_pct"]) / 100.0)
    return None


def estimate_noise(runs: Sequence[xr.Dataset]) -> dict:
    """Noise model of the measured quantities, from the data themselves (no instrument constant).

    Within every curve the relative differences of order 2-4 (acquisition order; of ln|y| or of y/|y|,
    whichever is smallest for that curve, see :func:`tissuemech.stats.relative_differences`) measure the point-to-point
    scatter; smooth trends (power laws in frequency, exponential decays, polynomial ramps) contribute little.
    Per (test, quantity) block the points are pooled over curves, binned by |y| (quantiles), and the
    robust variance per bin, s_b^2 = (1.4826 MAD)^2 (relative units), is fitted by NNLS as
    ``relative^2 + absolute^2 / |y|^2`` -- i.e. SD(y) = sqrt(absolute^2 + (relative |y|)^2). With too few
    points for bins only ``relative`` is estimated. The storage and loss moduli of sweeps are a torque over
    the strain amplitude, so their absolute part is not constant: where every sweep of the block records its
    strain amplitude, |y| is the stress amplitude |modulus| x amplitude, ``absolute`` is in stress units
    (``absolute_units``) and a point's floor is ``absolute`` / amplitude (:func:`noise_sd`); points of an
    amplitude sweep at amplitudes where the torque is noise are then recognised as such (``above_noise``).
    A torque resolution declared for the instrument
    (run attribute ``torque_resolution_nm``, from ``dataset.yaml``) replaces the absolute part of stress
    quantities when the run also records its plate radius (rim stress 2 M / (pi R^3)).

    Returns
    -------
    dict ``{"method", "blocks": {"<test>|<quantity>": {"relative" [1], "absolute" [quantity units],
    "median_abs" [quantity units], "n_points", "n_curves", "source"}}}``; a block with fewer than 5 points
    per curve is absent (its rows get NaN sigma and are excluded from noise-scaled tests).
    """
    pooled: dict[str, list] = {}
    for run in runs:
        test = str(run.attrs.get("test", "unknown"))
        for q in COMPARED_QUANTITIES:
            if q not in run or run[q].ndim != 1:
                continue
            pooled.setdefault(f"{test}|{q}", []).append((run[q].values, _stress_per_modulus(run, test, q)))
    blocks = {}
    for key, curves in pooled.items():
        # a modulus block is pooled in stress amplitude only when every sweep records its strain amplitude
        per_strain = all(a is not None for _, a in curves)
        parts = [relative_differences(y, a if per_strain else None) for y, a in curves]
        parts = [(m, d) for m, d in parts if m.size]
        if not parts:
            continue
        mag = np.concatenate([m for m, _ in parts])
        d2 = np.concatenate([d for _, d in parts])
        rel_all = 1.4826 * np.median(np.abs(d2))
        entry = {"relative": float(rel_all), "absolute": 0.0, "n_points": int(mag.size), "n_curves": len(parts),
                 "median_abs": float(np.median(mag)),
                 "source": "within-curve scatter (relative differences of order 2-4), relative only"}
        n_bins = min(8, mag.size // _MIN_BIN_POINTS)
        if n_bins >= 3:
            edges = np.quantile(mag, np.linspace(0, 1, n_bins + 1))
            idx = np.clip(np.searchsorted(edges, mag, side="right") - 1, 0, n_bins - 1)
            rows, rhs = [], []
            for b in range(n_bins):
                sel = idx == b
                if sel.sum() >= _MIN_BIN_POINTS:
                    s_b = 1.4826 * np.median(np.abs(d2[sel]))
                    rows.append([1.0, 1.0 / np.median(mag[sel]) ** 2])
                    rhs.append(s_b ** 2)
            if len(rows) >= 3:
                coef, _ = scipy.optimize.nnls(np.asarray(rows), np.asarray(rhs))
                entry.update(relative=float(np.sqrt(coef[0])), absolute=float(np.sqrt(coef[1])),
                             source="within-curve scatter (relative differences of order 2-4), binned by |y|: "
                                    "SD = sqrt(absolute^2 + (relative |y|)^2)")
        if per_strain and key.split("|")[1] in MODULI and key.split("|")[0] in OSCILLATORY_TESTS:
            # the instrument's absolute noise is a torque: a modulus carries it divided by the strain amplitude
            entry["absolute_units"] = "Pa of stress amplitude (the modulus floor is absolute / strain amplitude)"
            if entry["absolute"] > 0:
                entry["source"] += "; |y| and absolute as stress amplitude |modulus| x strain amplitude"
        blocks[key] = entry
    declared = {float(r.attrs["torque_resolution_nm"]) for r in runs if "torque_resolution_nm" in r.attrs}
    method = "within-curve residual scale (differences of order 2-4, per curve the smallest), per test and quantity"
    if declared:
        method += f"; declared torque resolution {sorted(declared)} N m used as the stress floor where R is known"
    return {"method": method, "blocks": blocks}


def noise_sd(noise: Mapping, test: str, quantity: str, observed: np.ndarray, strain: np.ndarray | None = None,
             radius_m: float = np.nan, torque_resolution_nm: float = np.nan) -> np.ndarray:
    """Per-point noise SD (quantity units) of observed values under :func:`estimate_noise`'s model.

    A declared torque resolution (N m) with a known radius R (m) gives the absolute floor of a stress as
    2 M / (pi R^3) and of a modulus as that over the strain amplitude; it is used when larger than the
    estimated floor. NaN where the block has no estimate.
    """
    obs = np.abs(np.asarray(observed, float))
    b = noise.get("blocks", {}).get(f"{test}|{quantity}")
    if b is None:
        return np.full(obs.shape, np.nan)
    floor = np.full(obs.shape, float(b["absolute"]))
    if "absolute_units" in b:
        # estimated in stress amplitude (estimate_noise): a modulus's floor is that over the strain amplitude
        amp = np.abs(np.asarray(strain, float)) if strain is not None else np.full(obs.shape, np.nan)
        with np.errstate(divide="ignore", invalid="ignore"):
            floor = np.where(np.isfinite(amp) & (amp > 0), floor / amp, np.nan) * np.ones(obs.shape)
    if np.isfinite(torque_resolution_nm) and np.isfinite(radius_m) and radius_m > 0:
        declared = 2.0 * torque_resolution_nm / (np.pi * radius_m ** 3)
        if quantity in ("storage_modulus", "loss_modulus", "relaxation_modulus") and strain is not None:
            with np.errstate(divide="ignore", invalid="ignore"):
                declared = declared / np.abs(np.asarray(strain, float))
        if quantity == "torque":
            declared = torque_resolution_nm
        if quantity in ("shear_stress", "torque", "storage_modulus", "loss_modulus", "relaxation_modulus"):
            floor = np.fmax(floor, declared)
    sd = np.sqrt(floor ** 2 + (float(b["relative"]) * obs) ** 2)
    return np.where(sd > 0, sd, np.nan)


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
                             float(a.get("torque_resolution_nm", np.nan)))
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
