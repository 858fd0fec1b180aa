"""Point-level data-quality flags of canonical runs, set at ingest and honoured by the fits.

Every run file gets one integer variable ``quality_flags`` (dimension ``point``), a bitmask in the CF
``flag_masks``/``flag_meanings`` convention: 0 = no flag, otherwise the sum of the bits below.

=====  =========================  ==================================================================================
bit    meaning                    rule
=====  =========================  ==================================================================================
1      ``inertia_dominated``      |raw phase| (``raw_phase``, rad) above :data:`RAW_PHASE_LIMIT_RAD` (90 deg)
2      ``torque_below_resolution`` ``|torque|`` below the instrument's declared torque resolution [N m]
4      ``outside_lve``            frequency-sweep point whose strain amplitude exceeds the G' LVE limit of the
                                  amplitude sweep(s) of the same specimen and sample (:func:`tissuemech.lve.lve_limit`,
                                  with the noise of the dataset's amplitude sweeps)
=====  =========================  ==================================================================================

Inertia. On a combined motor-transducer rheometer the measured (raw) phase is the phase of the total torque,
sample plus the inertial torque ``-I omega^2 theta`` of motor and geometry, and runs from 0 deg (elastic sample) to
180 deg (pure inertia); the sample's phase is what remains after subtracting the inertial part (science.md
section 2.5; nobadscience.com/rheo3.htm, "Locking the phase angle"). Above 90 deg the inertial torque already
exceeds the sample's elastic torque; close to 180 deg the sample's contribution is a small difference of two
large numbers and G', G'' depend entirely on the inertia calibration (J Rheol 53:765, 2009, PMC2947155: errors
grow quadratically with the inertia uncertainty above the coupled resonance). The threshold is that physical
boundary, 90 deg: above it the in-phase torque the instrument measured is negative, i.e. the subtracted
inertia correction is larger than the whole elastic signal and G' is made of the correction (the
instrument-inertia limit line where inertial torque equals sample torque; Ewoldt, Johnston & Caretta 2015,
"Experimental challenges of shear rheology", in *Complex Fluids in Biological Systems*, pp. 207-241).
Instrument makers' rules of thumb (a raw phase above about 150-175 deg, as issue 13 cites TA Instruments)
are more lenient; they trust the correction further than the physics lets us check. This is the one
definition of the threshold: the diagnosis's ``inertia_dominated_points`` uses it too. It is a keyword
of :func:`inertia_flags`. Runs without a raw-phase channel (most
RheoCompass and LIMS exports) are *not testable*; they are never flagged on other evidence.

Torque resolution. Only when it is declared: ``dataset.yaml`` ``instrument: {torque_resolution_nm: 1e-8}``
(value in N m; ``nm`` stands for newton metre, not nanometre). There is no default: without a declared
resolution the check is not testable.

LVE limit. Only for frequency sweeps whose specimen and sample also have an amplitude sweep in the dataset
(the smallest G' limit of those sweeps is used; a sweep that never leaves the band gives no limit, so nothing is
flagged). The strain amplitude of a point is its measured ``shear_strain``, or the nominal ``strain_pct`` of the
sample sheet for every point when the export has no strain column.

Fits exclude flagged points by default: :func:`tissuemech.curves.average_runs` (``exclude_flagged``, pipeline
config ``fit.exclude_flagged``) drops them before the averages the fits read.

Checks that could not be made are recorded, with the reason, in the run attribute ``quality_not_testable``
(``"<check>: <reason>"`` entries joined by ``"; "``); ``quality_checks`` lists those that were made. The counts
per bit are ``quality_n_<meaning>``.
"""
from __future__ import annotations

import logging
import math
from collections import defaultdict
from collections.abc import Iterable, Mapping
from pathlib import Path

import numpy as np
import xarray as xr

from ..canonical import read_netcdf, write_netcdf
from ..curves import QUALITY_FLAG_VARIABLE
from ..lve import amplitude_sweep_noise, lve_limit
from ..noise import estimate_noise

log = logging.getLogger(__name__)

#: bit -> (meaning, description); the CF ``flag_meanings`` use the meanings in bit order
QUALITY_BITS: dict[int, tuple[str, str]] = {
    1: ("inertia_dominated", "raw phase above the inertia threshold (instrument inertia dominates the torque)"),
    2: ("torque_below_resolution", "|torque| below the declared torque resolution of the instrument"),
    4: ("outside_lve", "strain amplitude above the LVE limit of the same sample's amplitude sweep"),
}
INERTIA_DOMINATED, TORQUE_BELOW_RESOLUTION, OUTSIDE_LVE = 1, 2, 4

#: raw-phase threshold [rad] above which a point is inertia-dominated: the inertial torque exceeds the sample's
#: in-phase torque (90 deg, see the module docstring); the one definition, used by the diagnosis too
RAW_PHASE_LIMIT_RAD: float = math.pi / 2

#: name of the flag variable in a run file (defined with the fit-data selection in :mod:`tissuemech.curves`)
FLAG_VARIABLE = QUALITY_FLAG_VARIABLE

#: oscillation test kinds (raw phase only has a meaning there)
OSCILLATION_TESTS = ("amplitude_sweep", "frequency_sweep")


def inertia_flags(run: xr.Dataset, limit_rad: float = RAW_PHASE_LIMIT_RAD) -> tuple[np.ndarray | None, str]:
    """Points whose raw phase exceeds ``limit_rad``.

    Parameters
    ----------
    run : canonical run (``raw_phase`` in rad when present).
    limit_rad : threshold [rad]; default :data:`RAW_PHASE_LIMIT_RAD` (90 deg).

    Returns
    -------
    (mask, reason): boolean mask over ``point`` (NaN raw phase -> False), or ``None`` and the reason the check is
    not testable.
    """
    if "raw_phase" not in run or not np.isfinite(run["raw_phase"].values).any():
        return None, "no raw-phase channel in the export"
    phase = np.asarray(run["raw_phase"].values, dtype=float)
    with np.errstate(invalid="ignore"):
        return np.abs(phase) > limit_rad, ""


def torque_resolution_flags(run: xr.Dataset, resolution_n_m: float | None) -> tuple[np.ndarray | None, str]:
    """Points whose torque magnitude is below the declared resolution.

    Parameters
    ----------
    run : canonical run (``torque`` in N m, amplitude for oscillation).
    resolution_n_m : declared torque resolution [N m], or None when the data do not declare one.

    Returns
    -------
    (mask, reason) as :func:`inertia_flags`.
    """
    if "torque" not in run or not np.isfinite(run["torque"].values).any():
        return None, "no torque channel in the export"
    if resolution_n_m is None:
        return None, "no torque resolution declared (dataset.yaml instrument: torque_resolution_nm)"
    torque = np.asarray(run["torque"].values, dtype=float)
    with np.errstate(invalid="ignore"):
        return np.abs(torque) < resolution_n_m, ""


def strain_amplitude(run: xr.Dataset) -> np.ndarray | None:
    """Strain amplitude [1] per point: measured ``shear_strain``, else the nominal ``strain_pct`` / 100, else None."""
    if "shear_strain" in run and np.isfinite(run["shear_strain"].values).any():
        return np.abs(np.asarray(run["shear_strain"].values, dtype=float))
    nominal = run.attrs.get("strain_pct")
    if nominal is not None and np.isfinite(float(nominal)):
        return np.full(run.sizes.get("point", 0), float(nominal) / 100.0)
    return None


def amplitude_sweep_lve_strain(run: xr.Dataset, noise: Mapping | None = None,
                               torque_resolution_n_m: float | None = None) -> tuple[float, str]:
    """G' LVE limit [1] of one amplitude-sweep run by :func:`tissuemech.lve.lve_limit` (ISO 6721-10 5 % rule).

    ``noise``: :func:`tissuemech.noise.estimate_noise` of the dataset's amplitude sweeps; with it, points whose G'
    is torque noise are left out and a departure must stand out of the noise (:mod:`tissuemech.lve`); a declared
    ``torque_resolution_n_m`` [N m] (else the run's ``torque_resolution_nm`` attribute) is the floor where larger.

    Returns
    -------
    (limit, reason): NaN and the reason when the sweep cannot be analysed; NaN and ``""`` when G' never leaves
    the band (the limit lies beyond the largest strain measured).
    """
    if "shear_strain" not in run or "storage_modulus" not in run:
        return math.nan, f"amplitude sweep {run.attrs.get('run', '?')} has no strain or G' column"
    strain, storage = run["shear_strain"].values, run["storage_modulus"].values
    loss = run["loss_modulus"].values if "loss_modulus" in run else None
    resolution = run.attrs.get("torque_resolution_nm", np.nan) if torque_resolution_n_m is None \
        else torque_resolution_n_m
    sd = amplitude_sweep_noise(noise, strain, storage, loss, float(run.attrs.get("radius_m", np.nan) or np.nan),
                               float(resolution))["storage_sd"]
    try:
        return lve_limit(strain, storage, modulus_sd=sd).strain, ""
    except ValueError as exc:
        return math.nan, f"amplitude sweep {run.attrs.get('run', '?')}: {exc}"


def outside_lve_flags(run: xr.Dataset, lve_strain: float) -> tuple[np.ndarray | None, str]:
    """Points whose strain amplitude exceeds ``lve_strain`` [1] (none when the limit is NaN: not reached)."""
    amplitude = strain_amplitude(run)
    if amplitude is None:
        return None, "no strain amplitude (no shear_strain column and no strain_pct in samples.csv)"
    if not math.isfinite(lve_strain):
        return np.zeros(amplitude.shape, dtype=bool), ""
    with np.errstate(invalid="ignore"):
        return amplitude > lve_strain, ""


def declared_torque_resolution(meta: Mapping | None) -> tuple[float | None, str]:
    """Torque resolution [N m] declared in ``dataset.yaml`` (``instrument: {torque_resolution_nm: ...}``).

    Returns
    -------
    (value, problem): value None when not declared; ``problem`` is non-empty when a value is given but is not a
    positive finite number (then the value is None too).
    """
    instrument = (meta or {}).get("instrument")
    if not isinstance(instrument, Mapping) or instrument.get("torque_resolution_nm") is None:
        return None, ""
    raw = instrument["torque_resolution_nm"]
    try:
        value = float(raw)
    except (TypeError, ValueError):
        value = math.nan
    if isinstance(raw, bool) or not math.isfinite(value) or value <= 0:
        return None, f"instrument.torque_resolution_nm = {raw!r} is not a positive number (N m)"
    return value, ""


def with_quality_flags(
    run: xr.Dataset,
    *,
    torque_resolution_n_m: float | None = None,
    torque_resolution_problem: str = "",
    lve_strain: float | None = None,
    lve_reason: str = "no amplitude sweep of the same specimen and sample",
    raw_phase_limit_rad: float = RAW_PHASE_LIMIT_RAD,
) -> xr.Dataset:
    """A copy of ``run`` with the ``quality_flags`` bitmask and its attributes (see the module docstring).

    Parameters
    ----------
    run : canonical run dataset.
    torque_resolution_n_m : declared torque resolution [N m], or None.
    torque_resolution_problem : why a declared value was unusable (reported as not testable).
    lve_strain : G' LVE limit [1] of the same sample's amplitude sweep (NaN: never reached), or None when there is
        none; used for frequency sweeps only.
    lve_reason : why ``lve_strain`` is None.
    raw_phase_limit_rad : inertia threshold [rad].
    """
    n = run.sizes.get("point", 0)
    flags = np.zeros(n, dtype=np.int32)
    checked, not_testable = [], []
    test = str(run.attrs.get("test", ""))

    def record(bit: int, result: tuple[np.ndarray | None, str]) -> None:
        mask, reason = result
        name = QUALITY_BITS[bit][0]
        if mask is None:
            not_testable.append(f"{name}: {reason}")
        else:
            checked.append(name)
            flags[np.asarray(mask, dtype=bool)] |= bit

    if test in OSCILLATION_TESTS:
        record(INERTIA_DOMINATED, inertia_flags(run, raw_phase_limit_rad))
    record(TORQUE_BELOW_RESOLUTION, torque_resolution_flags(run, torque_resolution_n_m) if not
           torque_resolution_problem else (None, torque_resolution_problem))
    if test == "frequency_sweep":
        record(OUTSIDE_LVE, (None, lve_reason) if lve_strain is None else outside_lve_flags(run, lve_strain))

    out = run.copy()
    bits = sorted(QUALITY_BITS)
    out[FLAG_VARIABLE] = ("point", flags, {
        "long_name": "point-level data-quality flags (bitmask, 0 = none)",
        "units": "1",
        "flag_masks": np.asarray(bits, dtype=np.int32),
        "flag_meanings": " ".join(QUALITY_BITS[b][0] for b in bits),
        **{f"bit_{b}": QUALITY_BITS[b][1] for b in bits},
        "raw_phase_limit_deg": math.degrees(raw_phase_limit_rad),
    })
    if torque_resolution_n_m is not None and not torque_resolution_problem:
        # the declared resolution travels with the run: the diagnosis's noise model reads it from here
        out.attrs["torque_resolution_nm"] = float(torque_resolution_n_m)
    out.attrs["quality_checks"] = ", ".join(checked)
    out.attrs["quality_not_testable"] = "; ".join(not_testable)
    for b in bits:
        out.attrs[f"quality_n_{QUALITY_BITS[b][0]}"] = int(np.count_nonzero(flags & b))
    if test == "frequency_sweep" and lve_strain is not None and math.isfinite(lve_strain):
        out.attrs["quality_lve_strain"] = float(lve_strain)
    return out


def flag_runs(runs: Iterable[xr.Dataset], meta: Mapping | None = None) -> list[xr.Dataset]:
    """Quality flags for the runs of one dataset (the LVE check pairs frequency and amplitude sweeps by sample).

    Parameters
    ----------
    runs : canonical runs of one dataset.
    meta : the dataset's ``dataset.yaml`` content (for the declared torque resolution), or None.
    """
    runs = list(runs)
    resolution, problem = declared_torque_resolution(meta)
    limits: dict[tuple[str, str], list[float]] = defaultdict(list)
    reasons: dict[tuple[str, str], list[str]] = defaultdict(list)
    sweeps = [run for run in runs if run.attrs.get("test") == "amplitude_sweep"]
    noise = estimate_noise(sweeps) if sweeps else None
    for run in sweeps:
        key = (str(run.attrs.get("specimen")), str(run.attrs.get("sample")))
        limit, reason = amplitude_sweep_lve_strain(run, noise, resolution)
        (reasons[key] if reason else limits[key]).append(reason or limit)
    out = []
    for run in runs:
        key = (str(run.attrs.get("specimen")), str(run.attrs.get("sample")))
        lve_strain, lve_reason = None, "no amplitude sweep of the same specimen and sample"
        if limits.get(key):
            finite = [v for v in limits[key] if math.isfinite(v)]
            lve_strain = min(finite) if finite else math.nan
        elif reasons.get(key):
            lve_reason = "; ".join(reasons[key])
        out.append(with_quality_flags(run, torque_resolution_n_m=resolution, torque_resolution_problem=problem,
                                      lve_strain=lve_strain, lve_reason=lve_reason))
    return out


def flag_run_files(paths: Iterable[str | Path], meta: Mapping | None = None) -> list[Path]:
    """Add quality flags to written run files of one dataset, in place (each rewritten atomically)."""
    paths = [Path(p) for p in paths]
    runs = [read_netcdf(p) for p in paths]
    for path, flagged in zip(paths, flag_runs(runs, meta)):
        write_netcdf(flagged, path)
        if flagged[FLAG_VARIABLE].values.any():
            log.info("%s: %d flagged points", path.name, int(np.count_nonzero(flagged[FLAG_VARIABLE].values)))
    return paths


def describe_flags(run: xr.Dataset) -> str:
    """One line: flagged point counts per meaning and the checks that were not testable."""
    parts = []
    if FLAG_VARIABLE in run:
        flags = np.asarray(run[FLAG_VARIABLE].values)
        counts = [f"{int(np.count_nonzero(flags & b))} {QUALITY_BITS[b][0]}" for b in sorted(QUALITY_BITS)
                  if np.count_nonzero(flags & b)]
        parts.append("flagged: " + (", ".join(counts) if counts else "none") + f" of {flags.size} points")
    if run.attrs.get("quality_not_testable"):
        parts.append("not testable: " + str(run.attrs["quality_not_testable"]))
    return "; ".join(parts)
