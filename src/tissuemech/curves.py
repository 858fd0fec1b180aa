"""Sample averages of canonical runs per test and condition, on common grids.

A *condition* is a test kind plus its nominal settings taken from the run attributes
(:data:`CONDITION_ATTRS`: ``shear_rate_1_per_s``, ``strain_pct``, ``stress_pa``, ``frequency_hz``; plus
``temperature_c`` for a test whose runs carry several temperatures, :data:`VARYING_CONDITION_ATTRS`). All runs of
one condition are resampled onto one grid of the test's independent variable (:data:`GRID_SPECS`): log-spaced
time for stress relaxation and creep, log-spaced strain amplitude for amplitude sweeps, log-spaced frequency for
frequency sweeps, log-spaced shear rate for flow curves, linear strain / stretch / displacement for ramps.

Resampling rules
----------------
* Each run is interpolated, never extrapolated: grid points outside a run's own range are NaN for that run, so
  the count ``n`` varies along the grid.
* On log grids the interpolation is linear in log x, and also in log y when every value of that variable is
  positive in every run of the condition (moduli, viscosities); signed variables (a noisy relaxation stress
  may cross zero) are interpolated linearly in y.
* Non-time runs keep their *loading branch*: points from the first one up to the point farthest from it
  (a flow curve's down-sweep or a ramp's unloading is not mixed in). Points are then sorted by x and points
  sharing an x are averaged. Log grids drop x <= 0 (e.g. t = 0).
* The grid spans the *common range*: the x interval covered by every sample (``min_fraction = 1``; a smaller
  fraction allows a majority range) among the samples whose range passes the count check below. The mean is
  therefore made of the same samples along the whole grid (no jump where a replicate ends a few percent
  early), while one aborted or mis-set run (flagged) does not truncate the others: it contributes within its
  own range only. When no point is covered by enough samples the union is used and the curve is flagged. The
  grid has as many points as the median run (after the branch rule), clipped to ``[2, max_grid_points]``.
* Runs of the same specimen and sample in one condition are averaged first; ``n`` counts *samples*.
* Mean and SD (``ddof=1``; NaN where n < 2) are taken in linear space.

Point/interval count check
--------------------------
Replicates of a condition should have been measured with the same protocol. A member is flagged when its
point count differs from the condition median by more than ``point_count_tolerance`` (default 50 %), or when its
x range ends differ from the condition medians by more than ``range_tolerance_decades`` (default 0.5 decade,
log grids) or ``range_tolerance_span`` (default 25 % of the median span, linear grids). Across the conditions
of one test, samples measured in other conditions but missing from a curve are listed (``missing_samples``), so
a condition with fewer replicates is visible. Flags are recorded, not acted on.

``averages.nc`` layout (flat, padded; no object dtypes)
-------------------------------------------------------
Dimensions ``curve`` (one per test + condition), ``grid`` (padded to the longest curve, NaN beyond
``grid_length``) and ``member`` (one per run used).

* per curve: ``test`` (str), ``condition`` (str label, see :func:`condition_label`), ``grid_variable`` (str,
  canonical name of x), ``grid_scale`` (``"log"``/``"linear"``), ``grid_length`` (int), ``n_runs``,
  ``n_samples``, ``n_specimens`` (int), ``count_check`` (``"ok"`` or the reasons), ``missing_samples`` (str,
  ``specimen/sample`` entries joined by ``,``; empty when none), the nominal condition
  variables ``shear_rate_1_per_s``, ``strain_pct``, ``stress_pa``, ``frequency_hz`` and the members' median
  geometry/setting attributes :data:`SETTING_ATTRS` (``radius_m``, ``gap_m``, ``temperature_c``,
  ``rise_time_s``) (float, NaN when unset).
* on ``(curve, grid)``: ``grid_value`` (x, in the units of ``grid_variable``) and, for every canonical
  variable ``v`` present in the runs, ``v_mean``, ``v_sd`` (units of ``v``) and ``v_n`` (int count of samples);
  a variable a test does not have is all-NaN for that curve. The moduli of sweeps also get ``v_noise``: the
  measurement noise SD of the mean, :func:`tissuemech.noise.noise_sd` of the dataset's sweeps of that test over
  sqrt(``v_n``) (a modulus is a torque over the strain amplitude, so it is largest at the smallest amplitudes).
  ``v_sd`` is the scatter between samples (specimen levels included), ``v_noise`` that of the measurement.
* per member: ``member_curve`` (int index into ``curve``), ``member_run``, ``member_specimen``,
  ``member_sample`` (str), ``member_n_points`` (points used), ``member_x_min``, ``member_x_max`` (float),
  ``member_flag`` (str, ``""`` when the member passed the count check).

Use :func:`load_average` (file) or :func:`select_average` (in memory) to get one curve back as a tidy
dataset whose dimension is the grid variable.

Flagged points (the fit-data selection)
---------------------------------------
Run files carry the point-level bitmask ``quality_flags`` set at ingest (:mod:`tissuemech.io.quality`:
inertia-dominated raw phase, torque below the declared resolution, frequency-sweep points above the LVE limit).
With ``exclude_flagged=True`` (the default; pipeline config ``fit.exclude_flagged``) :func:`average_runs` drops
those points before averaging, so the curves the fits read hold none of them; a run left with no point is not
averaged. The averages attributes ``exclude_flagged`` (0/1) and ``n_flagged_points_excluded`` record it.
"""
from __future__ import annotations

import logging
import math
from collections import defaultdict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import xarray as xr

from .canonical import CANONICAL_VARIABLES, read_netcdf, write_netcdf
from .noise import MODULI, OSCILLATORY_TESTS, estimate_noise, noise_sd, torque_modulus

_log = logging.getLogger(__name__)

#: nominal condition attributes (run attrs) that, with the test, define a condition
CONDITION_ATTRS: tuple[str, ...] = ("shear_rate_1_per_s", "strain_pct", "stress_pa", "frequency_hz")

#: settings that become part of a test's condition where its runs carry two or more distinct values (after
#: rounding to :data:`SETTING_RESOLUTION`): a temperature series (e.g. frequency sweeps for time-temperature
#: superposition) gives one curve per temperature instead of an average across temperatures. A single
#: temperature leaves the condition unchanged.
VARYING_CONDITION_ATTRS: tuple[str, ...] = ("temperature_c",)
#: values of a varying setting closer than this are one value (rounded to its multiples); 0.5 degC separates
#: temperature set points, not the +-0.1 degC stability of a Peltier or oven (the diagnosis' temperature rule)
SETTING_RESOLUTION: dict[str, float] = {"temperature_c": 0.5}

#: numeric run attributes summarised per curve (median over members; geometry is needed by plate fits)
SETTING_ATTRS: tuple[str, ...] = ("radius_m", "gap_m", "temperature_c", "rise_time_s")

#: test kind -> (grid variable, grid scale)
GRID_SPECS: dict[str, tuple[str, str]] = {
    "stress_relaxation": ("time", "log"),
    "creep_recovery": ("time", "log"),
    "amplitude_sweep": ("shear_strain", "log"),
    "frequency_sweep": ("frequency", "log"),
    "flow_curve": ("shear_rate", "log"),
    "constant_shear_rate": ("shear_strain", "linear"),
    "simple_shear": ("shear_strain", "linear"),
    "uniaxial": ("stretch", "linear"),
    "indentation": ("displacement", "linear"),
}

#: variables never averaged: session clock time has no meaning across samples
_NOT_AVERAGED = frozenset({"total_time"})

_NO_CONDITION = "default"

#: name of the point-level quality bitmask in run files (written by :mod:`tissuemech.io.quality`)
QUALITY_FLAG_VARIABLE = "quality_flags"


def unflagged_points(run: xr.Dataset) -> np.ndarray:
    """Boolean mask over ``point``: True where the run has no quality flag (all True without ``quality_flags``)."""
    if QUALITY_FLAG_VARIABLE not in run:
        return np.ones(run.sizes.get("point", 0), dtype=bool)
    return np.asarray(run[QUALITY_FLAG_VARIABLE].values) == 0


def drop_flagged(run: xr.Dataset) -> xr.Dataset:
    """The run without its quality-flagged points (the same object when none is flagged)."""
    keep = unflagged_points(run)
    return run if keep.all() else run.isel(point=np.flatnonzero(keep))


def condition_of(run: xr.Dataset) -> dict[str, float]:
    """Nominal condition of a run: the :data:`CONDITION_ATTRS` it sets (finite values only), as floats."""
    out = {}
    for key in CONDITION_ATTRS:
        value = run.attrs.get(key)
        if value is None:
            continue
        try:
            value = float(value)
        except (TypeError, ValueError):
            continue
        if math.isfinite(value):
            out[key] = value
    return out


def condition_label(condition: Mapping[str, float] | None) -> str:
    """Stable text label of a condition, e.g. ``"strain_pct=10"``; ``"default"`` when no nominal setting.

    Values are written with 6 significant digits so that 0.1 and 0.1000000001 name the same condition.
    """
    if not condition:
        return _NO_CONDITION
    parts = [f"{key}={float(condition[key]):.6g}" for key in CONDITION_ATTRS + VARYING_CONDITION_ATTRS
             if key in condition]
    return ";".join(parts) if parts else _NO_CONDITION


def rounded_setting(value, key: str = "temperature_c") -> float | None:
    """``value`` rounded to the multiples of ``SETTING_RESOLUTION[key]``; None when not a finite number."""
    try:
        value = float(value)
    except (TypeError, ValueError):
        return None
    step = SETTING_RESOLUTION.get(key, 0.1)
    return float(round(value / step) * step) if math.isfinite(value) else None


def distinct_temperatures(temperatures_c) -> list[float]:
    """Sorted distinct finite temperatures [degC], rounded as the averaging rounds them
    (:func:`rounded_setting`: multiples of 0.5 degC), so that the DAG's "sweeps at >= 2
    temperatures" and the per-temperature averages agree."""
    return sorted({t for t in (rounded_setting(v) for v in temperatures_c) if t is not None})


def _setting(run: xr.Dataset, key: str) -> float | None:
    return rounded_setting(run.attrs.get(key), key)


def varying_settings(runs: Sequence[xr.Dataset]) -> set[tuple[str, str]]:
    """(test, setting) pairs of :data:`VARYING_CONDITION_ATTRS` whose runs carry >= 2 distinct values."""
    seen: dict[tuple[str, str], set] = defaultdict(set)
    for run in runs:
        for key in VARYING_CONDITION_ATTRS:
            value = _setting(run, key)
            if value is not None:
                seen[(str(run.attrs.get("test", "")), key)].add(value)
    return {pair for pair, values in seen.items() if len(values) >= 2}


def _grid_x(run: xr.Dataset, test: str) -> np.ndarray:
    """Values of the test's grid variable in a run (frequency derived from angular frequency if needed)."""
    name, _ = GRID_SPECS[test]
    if name in run:
        return np.asarray(run[name].values, dtype=float)
    if name == "frequency" and "angular_frequency" in run:
        return np.asarray(run["angular_frequency"].values, dtype=float) / (2.0 * np.pi)
    raise ValueError(
        f"run {run.attrs.get('run', '?')!r} ({test}) has no {name!r} variable to average on; "
        f"variables: {sorted(run.data_vars)}"
    )


def _branch_indices(x: np.ndarray, test: str) -> np.ndarray:
    """Indices of the points used: finite x, loading branch for non-time grids, x > 0 for log grids."""
    name, scale = GRID_SPECS[test]
    idx = np.flatnonzero(np.isfinite(x))
    if name != "time" and idx.size:
        # loading branch: from the first point up to the one farthest from it (sweeps may run up or down)
        far = int(np.argmax(np.abs(x[idx] - x[idx[0]])))
        idx = idx[: far + 1]
    if scale == "log":
        idx = idx[x[idx] > 0]
    return idx


@dataclass(frozen=True)
class _PreparedRun:
    run: xr.Dataset
    x: np.ndarray                 # sorted unique grid-variable values
    columns: dict[str, np.ndarray]  # variable -> values at x (duplicates averaged)


def _prepare(run: xr.Dataset, test: str) -> _PreparedRun:
    x_all = _grid_x(run, test)
    idx = _branch_indices(x_all, test)
    x = x_all[idx]
    order = np.argsort(x, kind="stable")
    x = x[order]
    unique_x, inverse = np.unique(x, return_inverse=True)
    columns = {}
    grid_name = GRID_SPECS[test][0]
    for name in run.data_vars:
        if name == grid_name or name in _NOT_AVERAGED or name not in CANONICAL_VARIABLES:
            continue
        values = np.asarray(run[name].values, dtype=float)[idx][order]
        # duplicates at one x are averaged (NaN-aware: a NaN does not erase its neighbours)
        finite = np.isfinite(values)
        sums = np.bincount(inverse, weights=np.where(finite, values, 0.0))
        n_finite = np.bincount(inverse, weights=finite.astype(float))
        with np.errstate(invalid="ignore", divide="ignore"):
            columns[name] = np.where(n_finite > 0, sums / np.maximum(n_finite, 1), np.nan)
    return _PreparedRun(run=run, x=unique_x, columns=columns)


def _interp(grid: np.ndarray, x: np.ndarray, y: np.ndarray, log_x: bool, log_y: bool) -> np.ndarray:
    """Interpolate y(x) at grid without extrapolation: NaN outside the range of the finite points (isolated NaN
    points inside it are bridged by their neighbours)."""
    ok = np.isfinite(y) & np.isfinite(x)
    if log_y:
        ok &= y > 0
    if ok.sum() < 2:
        return np.full(grid.shape, np.nan)
    xs, ys = x[ok], y[ok]
    gx = np.log(grid) if log_x else grid
    xs = np.log(xs) if log_x else xs
    ys = np.log(ys) if log_y else ys
    out = np.interp(gx, xs, ys, left=np.nan, right=np.nan)
    return np.exp(out) if log_y else out


def _majority_range(ranges: Sequence[tuple[float, float]], min_fraction: float) -> tuple[float, float]:
    """Smallest and largest x covered by at least ``ceil(min_fraction * len(ranges))`` of the closed ranges.

    Returns (lo, hi) with hi <= lo when no point has that coverage.
    """
    need = max(1, math.ceil(min_fraction * len(ranges)))
    starts = np.array([lo for lo, _ in ranges])
    ends = np.array([hi for _, hi in ranges])
    points = np.unique(np.concatenate([starts, ends]))
    coverage = ((starts[None, :] <= points[:, None]) & (points[:, None] <= ends[None, :])).sum(axis=1)
    covered = points[coverage >= need]
    if covered.size == 0:
        return math.inf, -math.inf
    return float(covered[0]), float(covered[-1])


def _member_key(run: xr.Dataset) -> tuple[str, str]:
    return str(run.attrs.get("specimen", "")), str(run.attrs.get("sample", run.attrs.get("run", "")))


def _count_check(
    prepared: Sequence[_PreparedRun],
    scale: str,
    point_count_tolerance: float,
    range_tolerance_decades: float,
    range_tolerance_span: float,
) -> tuple[list[str], np.ndarray]:
    """Per-member flag text ('' when fine) for the point-count and range check, and whether the range passed."""
    counts = np.array([p.x.size for p in prepared], dtype=float)
    lo = np.array([p.x[0] for p in prepared])
    hi = np.array([p.x[-1] for p in prepared])
    med_count = float(np.median(counts))
    if scale == "log":
        lo_dev = np.abs(np.log10(lo) - np.median(np.log10(lo)))
        hi_dev = np.abs(np.log10(hi) - np.median(np.log10(hi)))
        unit = "decades"
        range_tolerance = range_tolerance_decades
    else:
        span = float(np.median(hi - lo)) or 1.0
        lo_dev = np.abs(lo - np.median(lo)) / abs(span)
        hi_dev = np.abs(hi - np.median(hi)) / abs(span)
        unit = "of the median span"
        range_tolerance = range_tolerance_span
    flags = []
    range_ok = (lo_dev <= range_tolerance) & (hi_dev <= range_tolerance)
    for i in range(len(prepared)):
        reasons = []
        if med_count > 0 and abs(counts[i] - med_count) > point_count_tolerance * med_count:
            reasons.append(f"{int(counts[i])} points vs median {med_count:g}")
        if lo_dev[i] > range_tolerance:
            reasons.append(f"starts {lo_dev[i]:.2g} {unit} from the median start")
        if hi_dev[i] > range_tolerance:
            reasons.append(f"ends {hi_dev[i]:.2g} {unit} from the median end")
        flags.append("; ".join(reasons))
    return flags, range_ok


def _average_condition(
    test: str,
    condition: dict[str, float],
    runs: Sequence[xr.Dataset],
    *,
    min_fraction: float,
    max_grid_points: int,
    point_count_tolerance: float,
    range_tolerance_decades: float,
    range_tolerance_span: float,
) -> tuple[dict, list[dict]]:
    grid_name, scale = GRID_SPECS[test]
    prepared = [_prepare(r, test) for r in runs]
    prepared = [p for p in prepared if p.x.size >= 2]
    if not prepared:
        raise ValueError(f"{test} {condition_label(condition)}: no run has two usable {grid_name} points")
    flags, range_ok = _count_check(prepared, scale, point_count_tolerance, range_tolerance_decades,
                                   range_tolerance_span)

    # group by sample so n counts samples, not repeated runs of one sample
    by_sample: dict[tuple[str, str], list[int]] = defaultdict(list)
    for i, p in enumerate(prepared):
        by_sample[_member_key(p.run)].append(i)
    sample_ranges = [
        (min(prepared[i].x[0] for i in members), max(prepared[i].x[-1] for i in members))
        for members in by_sample.values()
    ]
    consistent = [r for r, members in zip(sample_ranges, by_sample.values()) if all(range_ok[i] for i in members)]
    lo, hi = _majority_range(consistent or sample_ranges, min_fraction)
    n_grid = int(np.clip(np.median([p.x.size for p in prepared]), 2, max_grid_points))
    if hi <= lo:
        # replicates do not overlap enough: keep the union so the curve exists, and say so
        lo = min(r[0] for r in sample_ranges)
        hi = max(r[1] for r in sample_ranges)
        flags = [f + ("; " if f else "") + "replicate ranges do not overlap" for f in flags]
    grid = np.geomspace(lo, hi, n_grid) if scale == "log" else np.linspace(lo, hi, n_grid)

    variables = sorted({name for p in prepared for name in p.columns})
    means, sds, ns = {}, {}, {}
    log_x = scale == "log"
    for name in variables:
        positive = all(
            np.all(p.columns[name][np.isfinite(p.columns[name])] > 0) for p in prepared if name in p.columns
        )
        per_sample = []
        for members in by_sample.values():
            curves = [
                _interp(grid, prepared[i].x, prepared[i].columns[name], log_x, log_x and positive)
                for i in members
                if name in prepared[i].columns
            ]
            if curves:
                with np.errstate(all="ignore"):
                    stack = np.vstack(curves)
                    counts = np.isfinite(stack).sum(axis=0)
                    per_sample.append(np.where(counts > 0, np.nansum(stack, axis=0) / np.maximum(counts, 1), np.nan))
        stack = np.vstack(per_sample)
        n = np.isfinite(stack).sum(axis=0)
        with np.errstate(all="ignore"):
            mean = np.where(n > 0, np.nansum(stack, axis=0) / np.maximum(n, 1), np.nan)
            sq = np.nansum((stack - mean) ** 2, axis=0)
            sd = np.where(n > 1, np.sqrt(sq / np.maximum(n - 1, 1)), np.nan)
        means[name], sds[name], ns[name] = mean, sd, n

    settings = {}
    for key in SETTING_ATTRS:
        values = [_float_attr(p.run, key) for p in prepared]
        values = [v for v in values if math.isfinite(v)]
        settings[key] = float(np.median(values)) if values else math.nan
    curve = {
        "settings": settings,
        "test": test,
        "condition": condition_label(condition),
        "nominal": dict(condition),
        "grid_variable": grid_name,
        "grid_scale": scale,
        "grid": grid,
        "mean": means,
        "sd": sds,
        "n": ns,
        "n_runs": len(prepared),
        "n_samples": len(by_sample),
        "n_specimens": len({k[0] for k in by_sample}),
        "sample_keys": sorted(by_sample),
        "count_check": "ok" if not any(flags) else " | ".join(
            f"{p.run.attrs.get('run', i)}: {f}" for i, (p, f) in enumerate(zip(prepared, flags)) if f
        ),
    }
    members = [
        {
            "run": str(p.run.attrs.get("run", "")),
            "specimen": _member_key(p.run)[0],
            "sample": _member_key(p.run)[1],
            "n_points": int(p.x.size),
            "x_min": float(p.x[0]),
            "x_max": float(p.x[-1]),
            "flag": f,
        }
        for p, f in zip(prepared, flags)
    ]
    return curve, members


def _float_attr(run: xr.Dataset, key: str) -> float:
    try:
        return float(run.attrs.get(key, math.nan))
    except (TypeError, ValueError):
        return math.nan


def _str_array(values: Sequence[str]) -> np.ndarray:
    """Fixed-width unicode array (never object dtype); width at least 1."""
    values = [str(v) for v in values]
    width = max([1] + [len(v) for v in values])
    return np.array(values, dtype=f"<U{width}")


def average_runs(
    runs: Sequence[xr.Dataset],
    *,
    min_fraction: float = 1.0,
    max_grid_points: int = 256,
    point_count_tolerance: float = 0.5,
    range_tolerance_decades: float = 0.5,
    range_tolerance_span: float = 0.25,
    exclude_flagged: bool = True,
) -> xr.Dataset:
    """Average canonical runs per test and condition (layout in the module docstring).

    Parameters
    ----------
    runs : canonical run datasets (attrs ``test`` required; ``specimen``, ``sample``, ``run`` and the nominal
        condition attributes used when present). Runs of tests without a grid rule are ignored.
    min_fraction : fraction of the range-consistent samples that must cover a grid point's x for it to be in
        the grid (1: common range).
    max_grid_points : largest number of grid points of a curve.
    point_count_tolerance : relative deviation of a member's point count from the condition median that
        flags it.
    range_tolerance_decades : deviation of a member's x range ends from the condition medians that flags it
        on log grids, in decades.
    range_tolerance_span : the same on linear grids, as a fraction of the median span.
    exclude_flagged : drop points with a non-zero ``quality_flags`` before averaging (module docstring).

    Returns
    -------
    xarray.Dataset with dims ``curve``, ``grid``, ``member``.

    Raises
    ------
    ValueError
        when no run can be averaged.
    """
    groups: dict[tuple[str, str], list[xr.Dataset]] = defaultdict(list)
    conditions: dict[tuple[str, str], dict[str, float]] = {}
    n_excluded = 0
    varying = varying_settings(runs)
    for run in runs:
        test = str(run.attrs.get("test", ""))
        if test not in GRID_SPECS:
            continue
        if exclude_flagged:
            kept = drop_flagged(run)
            n_excluded += run.sizes.get("point", 0) - kept.sizes.get("point", 0)
            if kept.sizes.get("point", 0) == 0:
                _log.warning("run %s: every point is quality-flagged; not averaged", run.attrs.get("run", "?"))
                continue
            run = kept
        condition = condition_of(run)
        for setting in VARYING_CONDITION_ATTRS:
            if (test, setting) in varying and _setting(run, setting) is not None:
                condition[setting] = _setting(run, setting)
        key = (test, condition_label(condition))
        groups[key].append(run)
        conditions[key] = condition
    if not runs:
        raise ValueError("no run to average: the dataset has no ingested run (every export was rejected at ingest: "
                         "see the dataset's ingest report)")
    if not groups:
        raise ValueError("no run to average: none has a test with a grid rule " f"({sorted(GRID_SPECS)})")

    # one noise model per sweep test (all its conditions: one instrument), for the noise of the averaged moduli
    noise_models = {test: estimate_noise([r for (t, _), group in groups.items() if t == test for r in group])
                    for test in {t for t, _ in groups} if test in OSCILLATORY_TESTS}
    curves, members = [], []
    for key in sorted(groups):
        curve, curve_members = _average_condition(
            key[0],
            conditions[key],
            groups[key],
            min_fraction=min_fraction,
            max_grid_points=max_grid_points,
            point_count_tolerance=point_count_tolerance,
            range_tolerance_decades=range_tolerance_decades,
            range_tolerance_span=range_tolerance_span,
        )
        for m in curve_members:
            m["curve"] = len(curves)
        curve["noise"] = _noise_of_mean(curve, noise_models.get(key[0]), key[0])
        curves.append(curve)
        members.extend(curve_members)
    _mark_missing_samples(curves)
    averages = _to_dataset(curves, members)
    averages.attrs["exclude_flagged"] = int(exclude_flagged)
    averages.attrs["n_flagged_points_excluded"] = n_excluded
    return averages


def _noise_of_mean(curve: dict, noise: Mapping | None, test: str) -> dict:
    """Noise SD of the averaged moduli of a sweep curve (module docstring, ``v_noise``): ``noise``, the
    :func:`tissuemech.noise.estimate_noise` model of every run of the test, at the curve's mean and strain
    amplitude, over sqrt(n); empty for other tests."""
    if noise is None:
        return {}
    strain = curve["grid"] if curve["grid_variable"] == "shear_strain" else curve["mean"].get("shear_strain")
    out = {}
    both = [curve["mean"].get(name) for name in MODULI]
    for name in MODULI:
        mean, n = curve["mean"].get(name), curve["n"].get(name)
        if mean is None or strain is None:
            continue
        magnitude = torque_modulus(*both, name) if all(v is not None for v in both) else None
        with np.errstate(invalid="ignore", divide="ignore"):
            out[name] = noise_sd(noise, test, name, mean, np.asarray(strain, float),
                                 magnitude=magnitude) / np.sqrt(np.maximum(n, 1))
    return out


def _mark_missing_samples(curves: list[dict]) -> None:
    """Record, per curve, the samples of the same test measured in other conditions but not in this one."""
    by_test: dict[str, set] = defaultdict(set)
    for c in curves:
        by_test[c["test"]].update(c["sample_keys"])
    for c in curves:
        missing = sorted(by_test[c["test"]] - set(c["sample_keys"]))
        c["missing_samples"] = ",".join(f"{spec}/{samp}" for spec, samp in missing)
        if missing:
            note = f"{len(missing)} sample(s) of other {c['test']} conditions missing"
            c["count_check"] = note if c["count_check"] == "ok" else f"{c['count_check']} | {note}"


def _to_dataset(curves: list[dict], members: list[dict]) -> xr.Dataset:
    n_curve = len(curves)
    n_grid = max(c["grid"].size for c in curves)
    variables = sorted({name for c in curves for name in c["mean"]})

    def padded(getter, dtype=float, fill=np.nan):
        out = np.full((n_curve, n_grid), fill, dtype=dtype)
        for i, c in enumerate(curves):
            values = getter(c)
            if values is not None:
                out[i, : values.size] = values
        return out

    data_vars: dict[str, tuple] = {
        "test": ("curve", _str_array([c["test"] for c in curves])),
        "condition": ("curve", _str_array([c["condition"] for c in curves])),
        "grid_variable": ("curve", _str_array([c["grid_variable"] for c in curves])),
        "grid_scale": ("curve", _str_array([c["grid_scale"] for c in curves])),
        "grid_length": ("curve", np.array([c["grid"].size for c in curves], dtype=np.int64)),
        "n_runs": ("curve", np.array([c["n_runs"] for c in curves], dtype=np.int64)),
        "n_samples": ("curve", np.array([c["n_samples"] for c in curves], dtype=np.int64)),
        "n_specimens": ("curve", np.array([c["n_specimens"] for c in curves], dtype=np.int64)),
        "count_check": ("curve", _str_array([c["count_check"] for c in curves])),
        "missing_samples": ("curve", _str_array([c["missing_samples"] for c in curves])),
        "grid_value": (("curve", "grid"), padded(lambda c: c["grid"]),
                       {"long_name": "grid values, in the units of grid_variable"}),
    }
    for key in CONDITION_ATTRS:
        data_vars[key] = ("curve", np.array([c["nominal"].get(key, np.nan) for c in curves], dtype=float))
    for key in SETTING_ATTRS:
        data_vars[key] = ("curve", np.array([c["settings"][key] for c in curves], dtype=float))
    for name in variables:
        units, long_name = CANONICAL_VARIABLES[name]
        data_vars[f"{name}_mean"] = (("curve", "grid"), padded(lambda c: c["mean"].get(name)),
                                     {"units": units, "long_name": f"sample mean of {long_name}"})
        data_vars[f"{name}_sd"] = (("curve", "grid"), padded(lambda c: c["sd"].get(name)),
                                   {"units": units, "long_name": f"sample SD (ddof=1) of {long_name}"})
        data_vars[f"{name}_n"] = (("curve", "grid"), padded(lambda c: c["n"].get(name), np.int64, 0),
                                  {"long_name": f"number of samples contributing to {name}"})
        if any(name in c["noise"] for c in curves):
            data_vars[f"{name}_noise"] = (("curve", "grid"), padded(lambda c: c["noise"].get(name)),
                                          {"units": units, "long_name": f"measurement noise SD of the mean of "
                                                                        f"{long_name}"})
    data_vars.update({
        "member_curve": ("member", np.array([m["curve"] for m in members], dtype=np.int64)),
        "member_run": ("member", _str_array([m["run"] for m in members])),
        "member_specimen": ("member", _str_array([m["specimen"] for m in members])),
        "member_sample": ("member", _str_array([m["sample"] for m in members])),
        "member_n_points": ("member", np.array([m["n_points"] for m in members], dtype=np.int64)),
        "member_x_min": ("member", np.array([m["x_min"] for m in members], dtype=float)),
        "member_x_max": ("member", np.array([m["x_max"] for m in members], dtype=float)),
        "member_flag": ("member", _str_array([m["flag"] for m in members])),
    })
    ds = xr.Dataset(data_vars)
    ds.attrs["layout"] = "tissuemech averages v1 (see tissuemech.curves module docstring)"
    return ds


def write_averages(averages: xr.Dataset, path: str | Path) -> Path:
    """Atomically write the output of :func:`average_runs` as netCDF (:func:`tissuemech.canonical.write_netcdf`)."""
    return write_netcdf(averages, path)


def as_str(values) -> np.ndarray:
    """Text variables come back from netCDF as object arrays; turn them into fixed-width unicode."""
    return _str_array([v.decode() if isinstance(v, bytes) else v for v in np.asarray(values).ravel()])




def curve_index(averages: xr.Dataset, test: str, condition: Mapping[str, float] | str | None = None) -> int:
    """Index along ``curve`` of a test and condition (label, mapping, or None when the test has one curve)."""
    tests = as_str(averages["test"].values)
    labels = as_str(averages["condition"].values)
    candidates = np.flatnonzero(tests == test)
    if condition is not None:
        label = condition if isinstance(condition, str) else condition_label(condition)
        candidates = candidates[labels[candidates] == label]
    if candidates.size == 1:
        return int(candidates[0])
    available = [f"{t} [{c}]" for t, c in zip(tests, labels)]
    if candidates.size == 0:
        raise KeyError(f"no average for test {test!r} condition {condition!r}; available: {available}")
    raise KeyError(f"test {test!r} has several conditions, name one: {available}")


def select_average(averages: xr.Dataset, test: str, condition: Mapping[str, float] | str | None = None) -> xr.Dataset:
    """One curve of an averages dataset as a tidy dataset.

    Returns
    -------
    xarray.Dataset whose dimension and coordinate is the grid variable (e.g. ``time``), with
    ``<v>_mean``, ``<v>_sd``, ``<v>_n`` for every variable present in that curve (and ``<v>_noise`` where the
    averages have it), attrs ``test``,
    ``condition``, ``grid_scale``, ``n_samples``, ``n_specimens``, ``count_check``, the nominal condition
    and settings (finite ones only), and member lists ``runs``, ``specimens``, ``samples`` (comma-separated).
    """
    i = curve_index(averages, test, condition)
    length = int(averages["grid_length"].values[i])
    grid_name = str(as_str(averages["grid_variable"].values)[i])
    x = averages["grid_value"].values[i, :length]
    data_vars = {}
    for name in averages.data_vars:
        if not name.endswith("_mean") or averages[name].dims != ("curve", "grid"):
            continue
        if not np.isfinite(averages[name].values[i, :length]).any():
            continue  # variable absent from this curve's test
        base = name[: -len("_mean")]
        for suffix in ("_mean", "_sd", "_n", "_noise"):
            if suffix == "_noise" and (base + suffix not in averages
                                       or not np.isfinite(averages[base + suffix].values[i, :length]).any()):
                continue
            var = averages[base + suffix]
            data_vars[base + suffix] = (grid_name, var.values[i, :length], dict(var.attrs))
    units = CANONICAL_VARIABLES.get(grid_name, ("", ""))[0]
    ds = xr.Dataset(data_vars, coords={grid_name: (grid_name, x, {"units": units})})
    member = np.flatnonzero(averages["member_curve"].values == i)
    attrs = {
        "test": test,
        "condition": str(as_str(averages["condition"].values)[i]),
        "grid_scale": str(as_str(averages["grid_scale"].values)[i]),
        "n_runs": int(averages["n_runs"].values[i]),
        "n_samples": int(averages["n_samples"].values[i]),
        "n_specimens": int(averages["n_specimens"].values[i]),
        "count_check": str(as_str(averages["count_check"].values)[i]),
        "missing_samples": str(as_str(averages["missing_samples"].values)[i]),
        "runs": ",".join(as_str(averages["member_run"].values[member])),
        "specimens": ",".join(as_str(averages["member_specimen"].values[member])),
        "samples": ",".join(as_str(averages["member_sample"].values[member])),
    }
    for key in CONDITION_ATTRS + SETTING_ATTRS:
        if key not in averages:
            continue
        value = float(averages[key].values[i])
        if math.isfinite(value):
            attrs[key] = value
    ds.attrs.update(attrs)
    return ds


def load_average(path: str | Path, test: str, condition: Mapping[str, float] | str | None = None) -> xr.Dataset:
    """Load one averaged curve from an ``averages.nc`` file (see :func:`select_average`)."""
    return select_average(read_netcdf(path), test, condition)
