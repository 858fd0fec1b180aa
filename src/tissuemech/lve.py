"""Linear-viscoelastic (LVE) limit of amplitude sweeps, yield stress, flow point, loss-factor class.

LVE limit (ISO 6721-10 5 % rule)
--------------------------------
The LVE range ends where a modulus leaves the band ``plateau * (1 ± tolerance)`` (``tolerance = 0.05``). It is
evaluated separately on G', G'' and |G*| (|G*| computed from G' and G'' when the run lacks it); the G' limit is
*the* LVE limit (``lve_strain``), as in ISO 6721-10 / Mezger's practice, and the one used for the yield stress
and the frequency-sweep check.

Noise. The lowest-amplitude points are often the noisiest: the instrument's torque noise is a constant, so the
noise of a modulus grows as the strain amplitude falls. Where the per-point noise SD of the modulus is known
(``modulus_sd``; :func:`lve_summary` and the ingest's flags take it, :func:`amplitude_sweep_noise`, from
:func:`tissuemech.noise.estimate_noise` of the dataset's amplitude sweeps, the within-curve scatter, with a declared
torque resolution as a floor), points
whose modulus does not stand :data:`~tissuemech.noise.ABOVE_NOISE_SIGMAS` SDs above zero are torque noise and
left out (``points_below_noise``), and a point departs from the plateau only when it leaves the band *and* lies
more than :data:`DEPARTURE_SIGMAS` noise SDs from the plateau: a 5 % band means nothing where one point's noise
is 30 %. Without ``modulus_sd`` the band alone decides (ISO 6721-10 as written).

Plateau reference. Neither the first point nor the maximum is a safe reference. The plateau is an
*expanding-window median*: starting from the first ``min_plateau_points`` (3) points, the window grows one point at a time while the next
point lies inside ``median(window) * (1 ± tolerance)``. The first point outside the band ends the plateau if the
departure persists, i.e. the following ``persist - 1`` points (default 1) are outside on the same side (a single
noisy point does not end it; at the end of the sweep the points that exist must all be outside). The plateau value is the median of the window at that moment, and the LVE limit is
the crossing of ``plateau * (1 ∓ tolerance)`` between the last plateau point and the first departed one,
interpolated linearly in (log strain, log modulus). Departures downwards (softening, direction -1) and upwards
(strain stiffening, +1) both count. If no persistent departure occurs, the limit is beyond the largest strain
measured: ``lve_strain`` is NaN and ``lve_reached`` is 0.

Derived quantities
------------------
* yield stress [Pa]: shear-stress amplitude at the G' LVE limit (interpolated in log-log from the measured
  stress; from |G*|·γ where the run has no stress).
* flow point: first crossover G' = G'' after a G' > G'' start, interpolated linearly in log γ of log(G'/G'');
  strain and stress there. NaN when the sweep never crosses (or starts with G'' > G').
* loss-factor class: median tan δ = G''/G' over the G' plateau points; ``"gel"`` when < 1 (solid-like),
  ``"liquid"`` otherwise (``"unknown"`` without G'' data).

Frequency sweeps are flagged ``outside_lve`` when their largest strain amplitude (measured, or the nominal
``strain_pct``) exceeds the G' LVE limit of the reference amplitude sweep: the same specimen and sample's sweep
when there is one, otherwise the smallest limit among the dataset's averaged amplitude sweeps, otherwise the
smallest limit of all its amplitude-sweep runs. The limit is amplitude- and frequency-dependent; the check is
against sweeps measured at their own frequency, recorded alongside.

Output ``lve.nc``: dimension ``sweep`` (one per amplitude-sweep run and per averaged amplitude sweep) with the
variables of :data:`SWEEP_FIELDS`, and dimension ``frequency_sweep`` with :data:`FREQUENCY_SWEEP_FIELDS`. ``lve.csv``
has one row per entry of either, with a ``kind`` column (``amplitude_sweep`` / ``frequency_sweep``).
"""
from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import xarray as xr

from .canonical import atomic_write, write_netcdf
from .curves import as_str, select_average
from .noise import ABOVE_NOISE_SIGMAS, estimate_noise, noise_sd, torque_modulus

_log = logging.getLogger(__name__)

#: per amplitude-sweep output variables -> (units, description)
SWEEP_FIELDS: dict[str, tuple[str, str]] = {
    "source": ("", "'run' (one sample) or 'average' (averaged curve)"),
    "name": ("", "run name or averaged condition label"),
    "specimen": ("", "specimen of the run (empty for averages)"),
    "sample": ("", "sample of the run (empty for averages)"),
    "frequency_hz": ("Hz", "oscillation frequency of the sweep"),
    "n_samples": ("1", "samples behind the curve"),
    "lve_strain": ("1", "LVE limit strain from G' (5 % rule)"),
    "lve_reached": ("1", "1 when G' left the band inside the sweep"),
    "lve_strain_storage": ("1", "LVE limit strain from G'"),
    "lve_strain_loss": ("1", "LVE limit strain from G''"),
    "lve_strain_complex": ("1", "LVE limit strain from |G*|"),
    "direction_storage": ("1", "-1 softening, +1 stiffening, 0 not reached (G')"),
    "direction_loss": ("1", "-1 / +1 / 0 for G''"),
    "direction_complex": ("1", "-1 / +1 / 0 for |G*|"),
    "plateau_storage_pa": ("Pa", "G' plateau reference"),
    "plateau_loss_pa": ("Pa", "G'' plateau reference"),
    "plateau_complex_pa": ("Pa", "|G*| plateau reference"),
    "plateau_points": ("1", "points in the G' plateau window"),
    "yield_stress_pa": ("Pa", "shear stress amplitude at the G' LVE limit"),
    "flow_point_strain": ("1", "strain at G' = G''"),
    "flow_point_stress_pa": ("Pa", "shear stress amplitude at G' = G''"),
    "tan_delta_plateau": ("1", "median loss factor over the G' plateau"),
    "loss_factor_class": ("", "'gel' (tan delta < 1 at plateau), 'liquid', or 'unknown' (no G'' data)"),
    "max_strain": ("1", "largest strain amplitude of the sweep"),
    "points_below_noise": ("1", "points whose G' does not stand 5 noise SDs above zero (left out)"),
    "tolerance": ("1", "relative band of the LVE rule"),
    "note": ("", "why a sweep could not be analysed (empty when it was)"),
}

#: per frequency-sweep output variables -> (units, description)
FREQUENCY_SWEEP_FIELDS: dict[str, tuple[str, str]] = {
    "run": ("", "frequency-sweep run"),
    "specimen": ("", "specimen"),
    "sample": ("", "sample"),
    "strain_amplitude": ("1", "largest strain amplitude of the sweep (nominal when not measured)"),
    "reference_lve_strain": ("1", "G' LVE limit it is compared with"),
    "reference": ("", "which amplitude sweep gave the reference"),
    "outside_lve": ("1", "1 when the sweep's amplitude exceeds the LVE limit"),
}

#: a departure from the plateau must also exceed this many noise SDs of the point (with ``persist`` = 2
#: consecutive points on one side, noise alone does it with probability ~ (1.35e-3)^2 per pair of points)
DEPARTURE_SIGMAS = 3.0

_STRING_FIELDS = {"source", "name", "specimen", "sample", "loss_factor_class", "run", "reference", "note"}
_INT_FIELDS = {"lve_reached", "direction_storage", "direction_loss", "direction_complex", "plateau_points",
               "n_samples", "outside_lve", "points_below_noise"}


@dataclass(frozen=True)
class LveLimit:
    """Result of the tolerance-band rule on one modulus curve.

    Attributes
    ----------
    strain : LVE limit strain [1]; NaN when the curve never leaves the band.
    plateau : plateau reference modulus [Pa].
    plateau_points : number of points in the plateau window.
    direction : -1 (fell below the band), +1 (rose above), 0 (not reached).
    points_below_noise : points left out because their modulus is noise (0 without a noise SD).
    """

    strain: float
    plateau: float
    plateau_points: int
    direction: int
    points_below_noise: int = 0


def _clean_curve(strain: np.ndarray, *arrays: np.ndarray) -> tuple[np.ndarray, ...]:
    strain = np.asarray(strain, dtype=float)
    arrays = tuple(np.asarray(a, dtype=float) for a in arrays)
    ok = np.isfinite(strain) & (strain > 0)
    for a in arrays:
        ok &= np.isfinite(a)
    order = np.argsort(strain[ok], kind="stable")
    return (strain[ok][order],) + tuple(a[ok][order] for a in arrays)


def lve_limit(
    strain: np.ndarray,
    modulus: np.ndarray,
    *,
    tolerance: float = 0.05,
    min_plateau_points: int = 3,
    persist: int = 2,
    modulus_sd: np.ndarray | None = None,
) -> LveLimit:
    """LVE limit of one modulus curve by the tolerance-band rule (see the module docstring).

    Parameters
    ----------
    strain : strain amplitudes [1] (any order; non-positive and non-finite points are ignored).
    modulus : G', G'' or |G*| [Pa] at those amplitudes (positive).
    tolerance : relative band half-width (ISO 6721-10: 0.05).
    min_plateau_points : smallest plateau window.
    persist : number of consecutive points that must lie outside the band on the same side.
    modulus_sd : per-point noise SD of ``modulus`` [Pa], or None (the band alone decides). Points whose modulus
        is below :data:`~tissuemech.noise.ABOVE_NOISE_SIGMAS` SDs are left out; a departure must also exceed
        :data:`DEPARTURE_SIGMAS` SDs.

    Raises
    ------
    ValueError
        with fewer than ``min_plateau_points + 1`` usable points or a non-positive modulus.
    """
    sd_given = modulus_sd is not None
    sd_in = np.asarray(modulus_sd, float) if sd_given else np.zeros(np.shape(modulus))
    strain, modulus, sd = _clean_curve(strain, modulus, np.where(np.isfinite(sd_in), sd_in, 0.0))
    below = 0
    if sd_given:
        resolved = modulus > ABOVE_NOISE_SIGMAS * sd
        below = int((~resolved).sum())
        strain, modulus, sd = strain[resolved], modulus[resolved], sd[resolved]
    if strain.size < min_plateau_points + 1:
        raise ValueError(
            f"LVE limit needs at least {min_plateau_points + 1} finite points with strain > 0"
            + (f" whose modulus stands {ABOVE_NOISE_SIGMAS:g} noise SDs above zero" if sd_given else "")
            + f"; got {strain.size}"
        )
    if np.any(modulus <= 0):
        raise ValueError("LVE limit needs a positive modulus curve (log interpolation)")
    n = modulus.size

    def departs(index, plateau: float, side: int) -> np.ndarray:
        gap = side * (modulus[index] - plateau)
        return (gap > tolerance * plateau) & (gap > DEPARTURE_SIGMAS * sd[index])

    for end in range(min_plateau_points, n):
        plateau = float(np.median(modulus[:end]))
        side = int(np.sign(modulus[end] - plateau))
        following = np.arange(end, min(end + persist, n))
        if side == 0 or not np.all(departs(following, plateau, side)):
            continue
        level = plateau * (1.0 + side * tolerance)
        # crossing between the last plateau point and the first departed one, linear in log-log
        y0, y1 = math.log(modulus[end - 1]), math.log(modulus[end])
        x0, x1 = math.log(strain[end - 1]), math.log(strain[end])
        fraction = float(np.clip((math.log(level) - y0) / (y1 - y0), 0.0, 1.0)) if y1 != y0 else 0.0
        return LveLimit(math.exp(x0 + fraction * (x1 - x0)), plateau, end, side, below)
    return LveLimit(math.nan, float(np.median(modulus)), n, 0, below)


def amplitude_sweep_noise(noise: dict | None, strain: np.ndarray, storage: np.ndarray, loss: np.ndarray,
                          radius_m: float = math.nan, torque_resolution_nm: float = math.nan
                          ) -> dict[str, np.ndarray | None]:
    """Per-point noise SDs [Pa] of G' and G'' of one amplitude sweep under a dataset's noise model.

    ``noise``: :func:`tissuemech.noise.estimate_noise` of the dataset's amplitude sweeps (None: no SDs). A modulus
    is a torque over the strain amplitude, so its noise floor grows as the amplitude falls
    (:func:`tissuemech.noise.noise_sd`). Where low-torque points are present, the model's relative part takes up
    some of the floor (a linear gel through a pure torque noise: relative parts of 2-14 % against a true 0, the
    floor 0.6-1.0 times the truth); an inflated relative part makes a departure harder to call, so a limit may be
    found late, never early. Returns ``{"storage_sd": ..., "loss_sd": ...}``; an entry is None where
    the model has no estimate for that modulus.
    """
    out: dict[str, np.ndarray | None] = {"storage_sd": None, "loss_sd": None}
    if noise is None:
        return out
    for key, quantity, values in (("storage_sd", "storage_modulus", storage), ("loss_sd", "loss_modulus", loss)):
        if values is None:
            continue
        magnitude = torque_modulus(storage, loss, quantity) if storage is not None and loss is not None else None
        sd = noise_sd(noise, "amplitude_sweep", quantity, values, strain, radius_m, torque_resolution_nm, magnitude)
        out[key] = sd if np.isfinite(sd).any() else None
    return out


def _interp_loglog(x_at: float, x: np.ndarray, y: np.ndarray) -> float:
    ok = (x > 0) & (y > 0) & np.isfinite(y)
    if not math.isfinite(x_at) or ok.sum() < 2:
        return math.nan
    return float(np.exp(np.interp(math.log(x_at), np.log(x[ok]), np.log(y[ok]), left=np.nan, right=np.nan)))


def flow_point(strain: np.ndarray, storage: np.ndarray, loss: np.ndarray) -> float:
    """Strain [1] of the first G' = G'' crossover after a solid-like (G' > G'') start; NaN if none."""
    strain, storage, loss = _clean_curve(strain, storage, loss)
    ok = (storage > 0) & (loss > 0)
    strain, storage, loss = strain[ok], storage[ok], loss[ok]
    if strain.size < 2 or storage[0] <= loss[0]:
        return math.nan
    log_ratio = np.log(storage / loss)
    below = np.flatnonzero(log_ratio <= 0)
    if below.size == 0:
        return math.nan
    i = int(below[0])
    x0, x1 = math.log(strain[i - 1]), math.log(strain[i])
    r0, r1 = log_ratio[i - 1], log_ratio[i]
    return math.exp(x0 + r0 / (r0 - r1) * (x1 - x0))


def analyse_amplitude_sweep(
    strain: np.ndarray,
    storage: np.ndarray,
    loss: np.ndarray,
    stress: np.ndarray | None = None,
    complex_modulus: np.ndarray | None = None,
    *,
    tolerance: float = 0.05,
    min_plateau_points: int = 3,
    persist: int = 2,
    storage_sd: np.ndarray | None = None,
    loss_sd: np.ndarray | None = None,
) -> dict[str, float | int | str]:
    """LVE limits on G', G'', |G*|, yield stress, flow point and loss-factor class of one sweep.

    Parameters
    ----------
    strain : strain amplitudes [1].
    storage, loss : G', G'' [Pa].
    stress : shear-stress amplitudes [Pa]; |G*|·γ is used when None.
    complex_modulus : |G*| [Pa]; sqrt(G'^2 + G''^2) when None.
    storage_sd, loss_sd : per-point noise SDs of G' and G'' [Pa] (:func:`lve_limit`), or None; the SD of |G*|
        follows from both (first-order propagation).

    Returns
    -------
    dict with the numeric keys of :data:`SWEEP_FIELDS` from ``lve_strain`` to ``max_strain``.
    """
    strain = np.asarray(strain, dtype=float)
    storage = np.asarray(storage, dtype=float)
    loss = np.asarray(loss, dtype=float)
    if complex_modulus is None:
        complex_modulus = np.hypot(storage, loss)
    complex_modulus = np.asarray(complex_modulus, dtype=float)
    if stress is None:
        stress = complex_modulus * strain
    stress = np.asarray(stress, dtype=float)
    kw = {"tolerance": tolerance, "min_plateau_points": min_plateau_points, "persist": persist}
    sds = {"storage": storage_sd, "loss": loss_sd, "complex": None}
    if storage_sd is not None and loss_sd is not None:
        with np.errstate(invalid="ignore", divide="ignore"):
            sds["complex"] = np.hypot(storage * np.asarray(storage_sd, float),
                                      loss * np.asarray(loss_sd, float)) / complex_modulus
    limits = {}
    for key, modulus in (("storage", storage), ("loss", loss), ("complex", complex_modulus)):
        try:
            limits[key] = lve_limit(strain, modulus, modulus_sd=sds[key], **kw)
        except ValueError:
            # G'' of a nearly elastic gel may dip to zero or below resolution: no limit from it
            limits[key] = LveLimit(math.nan, math.nan, 0, 0)
    main = limits["storage"]
    s_sorted, stress_sorted = _clean_curve(strain, stress)
    yield_stress = _interp_loglog(main.strain, s_sorted, stress_sorted)
    flow_strain = flow_point(strain, storage, loss)
    flow_stress = _interp_loglog(flow_strain, s_sorted, stress_sorted)
    # tan δ over the strain range of the G' plateau window (among the points above the noise, when known)
    s_storage, g_storage, g_sd = _clean_curve(strain, storage, np.zeros(storage.shape) if storage_sd is None
                                              else np.where(np.isfinite(storage_sd), storage_sd, 0.0))
    s_resolved = s_storage[g_storage > ABOVE_NOISE_SIGMAS * g_sd] if storage_sd is not None else s_storage
    plateau_end = s_resolved[max(main.plateau_points, 1) - 1] if s_resolved.size else math.nan
    s_both, g1, g2 = _clean_curve(strain, storage, loss)
    in_plateau = s_both <= plateau_end
    tan_delta = float(np.median(g2[in_plateau] / g1[in_plateau])) if in_plateau.any() else math.nan
    return {
        "lve_strain": main.strain,
        "lve_reached": int(main.direction != 0),
        **{f"lve_strain_{k}": v.strain for k, v in limits.items()},
        **{f"direction_{k}": v.direction for k, v in limits.items()},
        **{f"plateau_{k}_pa": v.plateau for k, v in limits.items()},
        "plateau_points": main.plateau_points,
        "yield_stress_pa": yield_stress,
        "flow_point_strain": flow_strain,
        "flow_point_stress_pa": flow_stress,
        "tan_delta_plateau": tan_delta,
        "loss_factor_class": "gel" if tan_delta < 1.0 else ("liquid" if tan_delta >= 1.0 else "unknown"),
        "max_strain": float(s_storage[-1]) if s_storage.size else math.nan,
        "points_below_noise": main.points_below_noise,
    }


#: result of a sweep that could not be analysed (the analysis fields of SWEEP_FIELDS, empty values)
_EMPTY_RESULT: dict[str, float | int | str] = {
    name: (0 if name in _INT_FIELDS else "unknown" if name == "loss_factor_class" else math.nan)
    for name in list(SWEEP_FIELDS)[list(SWEEP_FIELDS).index("lve_strain"):
                                 list(SWEEP_FIELDS).index("points_below_noise") + 1]
}


def _sweep_arrays(ds: xr.Dataset, suffix: str = "") -> dict[str, np.ndarray | None]:
    """Strain and moduli of a run (suffix '') or of an averaged curve (suffix '_mean')."""
    def get(name):
        key = name + suffix
        return np.asarray(ds[key].values, dtype=float) if key in ds else None

    # a run holds shear_strain as a variable; an averaged amplitude sweep has it as its grid coordinate
    strain = np.asarray(ds["shear_strain"].values, dtype=float) if "shear_strain" in ds.variables else None
    if strain is None or get("storage_modulus") is None or get("loss_modulus") is None:
        raise ValueError(
            f"amplitude sweep {ds.attrs.get('run', ds.attrs.get('condition', '?'))!r} needs shear_strain, "
            f"storage_modulus and loss_modulus; has {sorted(ds.variables)}"
        )
    return {"strain": strain, "storage": get("storage_modulus"), "loss": get("loss_modulus"),
            "stress": get("shear_stress"), "complex_modulus": get("complex_modulus")}


def _frequency_of(ds: xr.Dataset, suffix: str = "") -> float:
    nominal = ds.attrs.get("frequency_hz")
    if nominal is not None and math.isfinite(float(nominal)):
        return float(nominal)
    for name, factor in (("frequency", 1.0), ("angular_frequency", 1.0 / (2 * np.pi))):
        if name + suffix in ds:
            return float(np.nanmedian(ds[name + suffix].values)) * factor
    return math.nan


def _frequency_sweep_amplitude(run: xr.Dataset) -> float:
    if "shear_strain" in run and np.isfinite(run["shear_strain"].values).any():
        return float(np.nanmax(np.abs(run["shear_strain"].values)))
    nominal = run.attrs.get("strain_pct")
    return float(nominal) / 100.0 if nominal is not None else math.nan


def lve_summary(
    runs: Sequence[xr.Dataset],
    averages: xr.Dataset | None = None,
    *,
    tolerance: float = 0.05,
    min_plateau_points: int = 3,
    persist: int = 2,
) -> xr.Dataset:
    """LVE analysis of every amplitude sweep of a dataset and the frequency-sweep check.

    Parameters
    ----------
    runs : canonical runs of one dataset (amplitude and frequency sweeps are used, others ignored).
    averages : output of :func:`tissuemech.curves.average_runs` for the same runs (its amplitude-sweep curves
        are analysed too), or None.

    The noise SDs of G' and G'' come from :func:`amplitude_sweep_noise` of the runs' amplitude sweeps; an averaged
    curve's are its ``<modulus>_noise`` (:func:`tissuemech.curves.average_runs`: the same model over the square root
    of its samples), which the fit stage's LVE selection reads too.

    Returns
    -------
    xarray.Dataset with dims ``sweep`` and ``frequency_sweep`` (layout in the module docstring).
    """
    kw = {"tolerance": tolerance, "min_plateau_points": min_plateau_points, "persist": persist}
    sweeps = [r for r in runs if r.attrs.get("test") == "amplitude_sweep"]
    noise = estimate_noise(sweeps) if sweeps else None

    def analysed(ds: xr.Dataset, suffix: str, name: str) -> dict:
        # one unusable sweep (missing moduli, too few points) must not stop the dataset's analysis
        try:
            arrays = _sweep_arrays(ds, suffix)
            if suffix:
                sds = {f"{k}_sd": (np.asarray(ds[f"{k}_modulus_noise"].values, float)
                                   if f"{k}_modulus_noise" in ds else None) for k in ("storage", "loss")}
            else:
                sds = amplitude_sweep_noise(noise, arrays["strain"], arrays["storage"], arrays["loss"],
                                            float(ds.attrs.get("radius_m", np.nan) or np.nan),
                                            float(ds.attrs.get("torque_resolution_nm", np.nan)))
            return {**analyse_amplitude_sweep(**arrays, **sds, **kw), "note": ""}
        except ValueError as err:
            _log.warning("amplitude sweep %s not analysed: %s", name, err)
            return {**_EMPTY_RESULT, "note": str(err)}

    rows: list[dict] = []
    for run in runs:
        if run.attrs.get("test") != "amplitude_sweep":
            continue
        name = str(run.attrs.get("run", ""))
        rows.append({"source": "run", "name": name, "specimen": str(run.attrs.get("specimen", "")),
                     "sample": str(run.attrs.get("sample", "")), "frequency_hz": _frequency_of(run), "n_samples": 1,
                     **analysed(run, "", name), "tolerance": tolerance})
    if averages is not None and averages.sizes.get("curve", 0):
        for test, label in zip(as_str(averages["test"].values), as_str(averages["condition"].values)):
            if test != "amplitude_sweep":
                continue
            curve = select_average(averages, str(test), str(label))
            rows.append({"source": "average", "name": str(label), "specimen": "", "sample": "",
                         "frequency_hz": _frequency_of(curve, "_mean"), "n_samples": int(curve.attrs["n_samples"]),
                         **analysed(curve, "_mean", f"average {label}"), "tolerance": tolerance})

    fs_rows = []
    for run in runs:
        if run.attrs.get("test") != "frequency_sweep":
            continue
        key = (str(run.attrs.get("specimen", "")), str(run.attrs.get("sample", "")))
        same = [r for r in rows if r["source"] == "run" and (r["specimen"], r["sample"]) == key
                and math.isfinite(r["lve_strain"])]
        averaged = [r for r in rows if r["source"] == "average" and math.isfinite(r["lve_strain"])]
        any_run = [r for r in rows if r["source"] == "run" and math.isfinite(r["lve_strain"])]
        reference = None
        for pool, what in ((same, "same sample"), (averaged, "dataset average"), (any_run, "smallest run limit")):
            if pool:
                best = min(pool, key=lambda r: r["lve_strain"])
                reference = (best["lve_strain"], f"{what}: {best['name']}")
                break
        amplitude = _frequency_sweep_amplitude(run)
        limit, text = reference if reference else (math.nan, "no amplitude sweep with an LVE limit")
        fs_rows.append({"run": str(run.attrs.get("run", "")), "specimen": key[0], "sample": key[1],
                        "strain_amplitude": amplitude, "reference_lve_strain": limit, "reference": text,
                        "outside_lve": int(math.isfinite(limit) and amplitude > limit)})
    return _to_dataset(rows, fs_rows)


def _column(values: list, name: str) -> np.ndarray:
    if name in _STRING_FIELDS:
        values = [str(v) for v in values]
        return np.array(values, dtype=f"<U{max([1] + [len(v) for v in values])}")
    if name in _INT_FIELDS:
        return np.array(values, dtype=np.int64)
    return np.array(values, dtype=float)


def _to_dataset(rows: list[dict], fs_rows: list[dict]) -> xr.Dataset:
    data_vars = {}
    for dim, fields, table in (("sweep", SWEEP_FIELDS, rows), ("frequency_sweep", FREQUENCY_SWEEP_FIELDS, fs_rows)):
        for name, (units, description) in fields.items():
            var_name = name if dim == "sweep" else f"fs_{name}"
            attrs = {"long_name": description}
            if units:
                attrs["units"] = units
            data_vars[var_name] = (dim, _column([r[name] for r in table], name), attrs)
    ds = xr.Dataset(data_vars)
    ds.attrs["method"] = "ISO 6721-10 tolerance band on an expanding-window median plateau (tissuemech.lve)"
    return ds


def lve_table(summary: xr.Dataset) -> pd.DataFrame:
    """One row per amplitude sweep and per frequency sweep, with a ``kind`` column (the ``lve.csv`` content)."""
    sweeps = pd.DataFrame({name: summary[name].values for name in SWEEP_FIELDS})
    sweeps.insert(0, "kind", "amplitude_sweep")
    fs = pd.DataFrame({name: summary[f"fs_{name}"].values for name in FREQUENCY_SWEEP_FIELDS})
    fs.insert(0, "kind", "frequency_sweep")
    fs = fs.rename(columns={"run": "name"})
    return pd.concat([sweeps, fs], ignore_index=True, sort=False)


def write_lve(summary: xr.Dataset, nc_path: str | Path, csv_path: str | Path) -> tuple[Path, Path]:
    """Atomically write ``lve.nc`` and the ``lve.csv`` summary."""
    nc = write_netcdf(summary, nc_path)
    table = lve_table(summary)
    csv = atomic_write(csv_path, lambda tmp: table.to_csv(tmp, index=False, float_format="%.6g"))
    return nc, csv

