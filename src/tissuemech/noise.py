"""The noise model of the measured quantities, read from the data themselves (never an instrument constant;
a torque resolution only where the dataset declares one). The LVE limit (:mod:`tissuemech.lve`), the ingest's
quality flags and the diagnosis (its second stage, :mod:`tissuemech.diagnosis.noise`) all use this one model.

* :func:`estimate_noise` -- per (test, quantity) block, ``SD(y) = sqrt(absolute^2 + (relative |y|)^2)`` from
  the within-curve scatter (relative differences of order 2-4);
* :func:`noise_sd` -- the per-point SD under that model (with a declared torque resolution as a floor);
* :func:`relative_noise_level` -- the typical relative noise SD eps of the responses (the scale of the
  decision rule's margin, :mod:`.decision`);
* :func:`robust_noise_sd` -- the white-noise SD of one smooth sequence (second differences, MAD);
* :func:`points_above_floor` -- which points of a run stand above its noise floor (data scatter or declared
  resolution).
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import scipy
import xarray as xr

from .stats import relative_differences, robust_noise_sd  # noqa: F401 (robust_noise_sd: the detectors' one)


#: a row enters the level and structure tests only where its OBSERVED magnitude exceeds this many noise SDs
#: (a detection convention, not an instrument property)
ABOVE_NOISE_SIGMAS = 5.0
#: fewest second differences a noise block needs for the binned variance fit; fewer -> relative scale only
_MIN_BIN_POINTS = 10

#: quantities a residual table may compare, in preference order
COMPARED_QUANTITIES = ("shear_stress", "storage_modulus", "loss_modulus", "torque", "normal_force",
                       "shear_strain", "relaxation_modulus", "nominal_stress")
#: tests whose moduli are a torque over the strain amplitude
OSCILLATORY_TESTS = ("amplitude_sweep", "frequency_sweep")
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


def measured_torque_modulus(run: xr.Dataset, quantity: str) -> np.ndarray | None:
    """:func:`torque_modulus` at every point of the sweep ``run``; None for other quantities and runs without both
    moduli."""
    if quantity not in MODULI or run.attrs.get("test") not in OSCILLATORY_TESTS or not all(q in run for q in MODULI):
        return None
    storage, loss = (np.asarray(run[q].values, float) for q in MODULI)
    if not storage.shape == loss.shape == run[quantity].shape:
        return None
    return torque_modulus(storage, loss, quantity)


def torque_modulus(storage: np.ndarray, loss: np.ndarray, quantity: str) -> np.ndarray:
    """The magnitude [Pa] a sweep modulus's relative noise is relative to, at every point of a sweep of storage and
    loss moduli [Pa]: the torque the instrument reported, in modulus units (torque over strain amplitude and plate
    factor).

    Both moduli are the in- and out-of-phase parts of one measured torque, whose noise (and the phase resolution)
    does not shrink with the out-of-phase part: a gel's loss modulus a twentieth of |G*| carries |G*|'s noise, not
    a twentieth of it. So the smaller modulus of the sweep (by median) is referred to |G*|; the dominant one to
    itself, which is |G*| up to its smaller partner where the signal stands above the noise, and does not take the
    partner's noise where it does not."""
    storage, loss = np.asarray(storage, float), np.asarray(loss, float)
    own = np.abs(storage if quantity == "storage_modulus" else loss)
    other = np.abs(loss if quantity == "storage_modulus" else storage)
    return np.hypot(storage, loss) if np.nanmedian(own) < np.nanmedian(other) else own


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
    strain amplitude, |y| is the measured torque's stress amplitude (:func:`measured_torque_modulus`: the relative noise of
    both moduli is relative to the torque), ``absolute`` is in stress units
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
            pooled.setdefault(f"{test}|{q}", []).append((run[q].values, _stress_per_modulus(run, test, q),
                                                         measured_torque_modulus(run, q)))
    blocks = {}
    for key, curves in pooled.items():
        # a modulus block is pooled in stress amplitude only when every sweep records its strain amplitude
        per_strain = all(a is not None for _, a, _ in curves)
        parts = [relative_differences(y, a if per_strain else None, m) for y, a, m in curves]
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
             radius_m: float = np.nan, torque_resolution_nm: float = np.nan,
             magnitude: np.ndarray | None = None) -> np.ndarray:
    """Per-point noise SD (quantity units) of observed values under :func:`estimate_noise`'s model.

    A declared torque resolution (N m) with a known radius R (m) gives the absolute floor of a stress as
    2 M / (pi R^3) and of a modulus as that over the strain amplitude; it is used when larger than the
    estimated floor. ``magnitude``: what the relative part is relative to where it is not |observed|
    (:func:`measured_torque_modulus` for a sweep's moduli). NaN where the block has no estimate.
    """
    obs = np.abs(np.asarray(observed, float)) if magnitude is None else np.abs(np.asarray(magnitude, float))
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



#: imposed inputs, not responses: their scatter does not set the noise of a fix's metric
INPUT_QUANTITIES = ("shear_strain",)
#: what a test kind imposes where it is not :data:`INPUT_QUANTITIES`: a creep test imposes the stress (the torque)
#: and responds in strain
IMPOSED_BY_TEST = {"creep_recovery": ("shear_stress", "torque")}


def is_response(block: str) -> bool:
    """Whether an :func:`estimate_noise` block ``"<test>|<quantity>"`` is a measured response of its test, not
    the input the test imposes (:data:`IMPOSED_BY_TEST`, else :data:`INPUT_QUANTITIES`)."""
    test, _, quantity = block.partition("|")
    return quantity not in IMPOSED_BY_TEST.get(test, INPUT_QUANTITIES)


def relative_noise_level(noise: Mapping) -> float:
    """Typical relative noise SD eps [1] of the measured responses.

    Per (test, quantity) block of an :func:`estimate_noise` model, the relative SD at the block's median
    magnitude, sqrt(relative^2 + (absolute / median|y|)^2); eps is the median over the response blocks
    (imposed inputs of :data:`INPUT_QUANTITIES` excluded). NaN without such a block.
    """
    rel = []
    for key, b in noise.get("blocks", {}).items():
        if key.split("|")[-1] in INPUT_QUANTITIES:
            continue
        med = b.get("median_abs", np.nan)
        a = b.get("absolute", 0.0) / med if np.isfinite(med) and med > 0 else 0.0
        r = float(np.hypot(b.get("relative", np.nan), a))
        if np.isfinite(r):
            rel.append(r)
    return float(np.median(rel)) if rel else np.nan


def points_above_floor(run: xr.Dataset, quantity: str, noise: Mapping | None = None,
                       sigmas: float = ABOVE_NOISE_SIGMAS) -> np.ndarray:
    """Boolean mask of the points of ``run`` whose ``quantity`` stands more than ``sigmas`` noise SDs above zero.

    The noise is the run's block of ``noise`` (:func:`estimate_noise` of the dataset; of this run alone when
    None): the within-curve scatter of the data, with a declared torque resolution (``torque_resolution_nm``
    and a plate radius) as the floor where it is larger (:func:`noise_sd`). Never a fixed torque: a run whose
    block has no estimate gives all False (nothing can be said to stand above an unknown floor).
    """
    if quantity not in run:
        return np.zeros(run.sizes.get("point", 0), bool)
    y = np.asarray(run[quantity].values, float)
    noise = estimate_noise([run]) if noise is None else noise
    strain = np.asarray(run["shear_strain"].values, float) if "shear_strain" in run else None
    sd = noise_sd(noise, str(run.attrs.get("test", "")), quantity, y, strain,
                  float(run.attrs.get("radius_m", np.nan) or np.nan),
                  float(run.attrs.get("torque_resolution_nm", np.nan)), measured_torque_modulus(run, quantity))
    with np.errstate(invalid="ignore"):
        return np.isfinite(y) & np.isfinite(sd) & (np.abs(y) > sigmas * sd)
