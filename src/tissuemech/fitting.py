"""Least-squares fitting of constitutive models to rheometer curves (lmfit).

Three layers:

1. **Data selection** -- :class:`Curve` is one curve to fit (one test at one condition, an average over
   samples or a single run) with the inputs the model needs (a strain history, angular frequencies, shear
   rates, an imposed stress history, strains or stretches), the observed values, their sample SD and the
   bookkeeping (test, condition, specimen, geometry). Builders turn canonical runs
   (:func:`curve_from_run`) or averaged curves (:func:`curves_from_averages`) into curves; selectors
   restrict the strain range or thin dense curves to log-spaced points (dense rheometer curves have
   autocorrelated residuals; thinning keeps the information criteria honest, ``science.md`` section 4.2).
2. **Problem** -- :class:`FitProblem` joins any number of curves for one model (joint fits across tests and
   conditions, e.g. QLV on every CSR rate plus relaxation), the parallel-plate *target* (how a model
   prediction is compared with rim data, recorded with every fit) and the noise model. Residuals are
   weighted by ``max(sample SD, noise floor)``; oscillation and flow curves use log residuals because they
   span decades.
3. **Fit** -- :func:`fit` runs lmfit (``least_squares``/TRF with bounds) on log10-transformed moduli and times,
   from the model's start, an optional supplied start (e.g. :func:`prony_nnls`) and seeded random starts,
   keeps the best, and returns a :class:`FitResult` with parameters, propagated standard errors,
   correlation matrix, identifiability and convergence flags, chi-square, RMSE, AIC/AICc/BIC (with n and
   with the effective n from lag-1 residual autocorrelation), residuals and the data selection.

Plate targets (``science.md`` section 2.1) for curves measured between parallel plates (the choice is
recorded with every fit):

``thesis``
    the thesis method: the reported apparent rim stress 2M/(pi R^3) is taken as the true rim stress and
    compared with the homogeneous model at the rim strain. Exact for linear materials only; biases
    stiffening terms (C20 -> 2/3, C30 -> 1/2 of the truth).
``apparent_stress``
    the reported apparent rim stress is compared with the model's apparent rim stress 2M/(pi R^3), M from
    the radial integral (``models.plate.forward_plate``, every radius with its own history). Unbiased.
``corrected_stress``
    the homogeneous model at the rim strain is compared with the Rabinowitsch-corrected data
    sigma_R = M/(2 pi R^3) (3 + d ln M / d ln gamma_R) (``models.plate.rabinowitsch_rim_stress``; needs a
    monotone strain or rate sweep).
``torque``
    the model's torque through the radial integral is compared with the measured torque (or the reported
    stress x pi R^3 / 2 when the export has no torque).
``none``
    homogeneous tests (simple shear/uniaxial specimens, e.g. Budday): no plate.

Oscillation (linear: the apparent stress is exact), creep and homogeneous tests do not depend on the
target.
"""
from __future__ import annotations

import math
import re
import warnings
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace

import lmfit
import numpy as np
import xarray as xr
from scipy.optimize import nnls

from .canonical import to_jsonable
from .curves import as_str, select_average
from .lve import lve_limit
from .models.base import ConstitutiveModel, ParamSpec, ResponseNotSupported
from .models.plate import forward_plate, rabinowitsch_rim_stress
from .models.recursion import prony_branch_histories
from .records import FitRecord
from .spectra import log_spaced_taus, prony_oscillation_basis  # log_spaced_taus re-exported (fitting.__all__)
from .stats import effective_sample_size, information_criteria

PLATE_TARGETS: tuple[str, ...] = ("thesis", "apparent_stress", "corrected_stress", "torque", "none")

#: response kind of the model that describes each canonical test kind
TEST_RESPONSE: dict[str, str] = {
    "stress_relaxation": "shear_history",
    "constant_shear_rate": "shear_history",
    "frequency_sweep": "oscillation",
    "creep_recovery": "creep",
    "flow_curve": "flow",
    "simple_shear": "elastic_shear",
    "uniaxial": "uniaxial",
}

#: relative chi-square difference under which two starts count as the same optimum (see :func:`fit`)
EQUIVALENT_CHISQR_RTOL = 1e-7

#: responses fitted with log residuals (the data span decades)
LOG_RESPONSES: frozenset[str] = frozenset({"oscillation", "flow"})

#: |correlation| above which a parameter pair is flagged as not separately identifiable
CORRELATION_FLAG = 0.95


# ------------------------------------------------------------------------------------------------
# data selection
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Curve:
    """One curve to fit.

    Attributes
    ----------
    test : canonical test kind (``canonical.TEST_KINDS``)
    condition : label of the nominal condition, e.g. ``"rate=0.01/s"``, ``"strain=10%"``
    response : model response kind (``models.base``): ``shear_history``, ``oscillation``, ``flow``,
        ``creep``, ``elastic_shear``, ``uniaxial``
    inputs : model inputs (SI): ``time`` [s] + ``shear_strain`` [1] (a full history from a virgin state) for
        ``shear_history``; ``angular_frequency`` [rad/s]; ``shear_rate`` [1/s]; ``time`` + ``shear_stress``
        [Pa] (imposed) for ``creep``; ``shear_strain`` for ``elastic_shear``; ``stretch`` for ``uniaxial``
    observed : observable name -> values at the observation points: ``shear_stress`` [Pa] (reported rim
        stress for plate tests), optional ``torque`` [N m], ``storage_modulus``/``loss_modulus`` [Pa],
        ``shear_strain`` (creep), ``nominal_stress`` [Pa] (uniaxial)
    sd : observable name -> sample SD (same shape); missing -> the noise model alone
    obs_index : indices of the observation points into the input arrays (``None``: every point)
    specimen : specimen label (``"mean"`` for averages over specimens)
    n_samples : number of samples behind the curve
    radius_m, gap_m : plate geometry (NaN for homogeneous tests)
    nominal : nominal condition values (``shear_rate_1_per_s``, ``strain_pct``, ``stress_pa``, ...)
    """

    test: str
    condition: str
    response: str
    inputs: Mapping[str, np.ndarray]
    observed: Mapping[str, np.ndarray]
    sd: Mapping[str, np.ndarray] = field(default_factory=dict)
    obs_index: np.ndarray | None = None
    specimen: str = "mean"
    n_samples: int = 1
    radius_m: float = float("nan")
    gap_m: float = float("nan")
    nominal: Mapping[str, float] = field(default_factory=dict)

    @property
    def label(self) -> str:
        spec = "" if self.specimen == "mean" else f"|{self.specimen}"
        return f"{self.test}|{self.condition}{spec}"

    @property
    def n_points(self) -> int:
        return int(next(iter(self.observed.values())).size)

    def obs_inputs(self, name: str) -> np.ndarray:
        """Input ``name`` at the observation points."""
        x = np.asarray(self.inputs[name], float)
        return x if self.obs_index is None else x[self.obs_index]

    @property
    def is_plate(self) -> bool:
        return bool(np.isfinite(self.radius_m) and self.radius_m > 0)


def _condition_label(test: str, attrs: Mapping) -> str:
    for key, fmt in (("shear_rate_1_per_s", "rate={:g}/s"), ("strain_pct", "strain={:g}%"),
                     ("stress_pa", "stress={:g}Pa"), ("frequency_hz", "f={:g}Hz")):
        if key in attrs and attrs[key] is not None and np.isfinite(float(attrs[key])):
            return fmt.format(float(attrs[key]))
    return test


def _nominal(attrs: Mapping) -> dict[str, float]:
    out = {}
    for key in ("shear_rate_1_per_s", "strain_pct", "stress_pa", "frequency_hz", "rise_time_s"):
        if key in attrs and attrs[key] is not None:
            try:
                out[key] = float(attrs[key])
            except (TypeError, ValueError):
                pass
    return out


def relaxation_history(time_s: np.ndarray, strain: np.ndarray, mode: str = "measured",
                       rise_time_s: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Strain history of a relaxation test and the observation indices into it.

    Parameters
    ----------
    time_s, strain : measured time [s] from the start of the test and rim strain [1]
    mode : ``"measured"`` -- the measured strain as the history (the finite ramp is honoured);
        ``"ramp"`` -- an ideal linear ramp to the hold strain over ``rise_time_s`` (estimated from the data
        as the time the strain first reaches 98 % of the hold strain when not given);
        ``"step"`` -- the thesis treatment: an instantaneous step at ``t = 0`` (biases fast modes, §2.12)

    Returns
    -------
    history time [s], history strain [1], observation indices into the history, and the rows of the
    measured arrays those observations are
    """
    t = np.asarray(time_s, float)
    g = np.asarray(strain, float)
    hold = float(np.median(g[g.size // 2:]))
    if mode == "measured":
        rows = np.arange(t.size)
        if t[0] > 0:  # virgin state at t = 0
            return np.r_[0.0, t], np.r_[0.0, g], rows + 1, rows
        return t, g, rows, rows
    if mode == "ramp":
        if rise_time_s is None:
            reached = np.nonzero(np.abs(g) >= 0.98 * abs(hold))[0]
            rise_time_s = float(t[reached[0]]) if reached.size else 0.0
        rise_time_s = max(float(rise_time_s), 0.0)
        obs = np.nonzero(t > rise_time_s)[0] if rise_time_s > 0 else np.nonzero(t > 0)[0]
        th = np.r_[0.0, rise_time_s, t[obs]] if rise_time_s > 0 else np.r_[0.0, t[obs]]
        gh = np.r_[0.0, hold, np.full(obs.size, hold)] if rise_time_s > 0 else np.r_[hold, np.full(obs.size, hold)]
        start = 2 if rise_time_s > 0 else 1
        return th, gh, np.arange(start, start + obs.size), obs
    if mode == "step":
        obs = np.nonzero(t > 0)[0]
        th = np.r_[0.0, t[obs]]
        gh = np.r_[hold, np.full(obs.size, hold)]
        return th, gh, np.arange(1, obs.size + 1), obs
    raise ValueError(f"unknown relaxation history mode {mode!r}; use 'measured', 'ramp' or 'step'")


def _var(ds: xr.Dataset, name: str) -> np.ndarray | None:
    return np.asarray(ds[name].values, float) if name in ds else None


def curve_from_run(ds: xr.Dataset, relaxation: str = "measured") -> Curve:
    """Turn one canonical run (``canonical.make_run_dataset``) into a :class:`Curve`.

    Parameters
    ----------
    ds : canonical run dataset (attrs ``test``, geometry ``radius_m``/``gap_m``, nominal condition)
    relaxation : strain-history treatment of relaxation tests, see :func:`relaxation_history`
    """
    return curve_and_rows(ds, relaxation)[0]


def curve_and_rows(ds: xr.Dataset, relaxation: str) -> tuple[Curve, np.ndarray]:
    """The curve of a run and the rows of the run that are its observation points."""
    attrs = dict(ds.attrs)
    test = str(attrs.get("test", ""))
    if test not in TEST_RESPONSE:
        raise ValueError(f"test kind {test!r} cannot be fitted; fittable kinds: {sorted(TEST_RESPONSE)}")
    response = TEST_RESPONSE[test]
    nominal = _nominal(attrs)
    common = dict(test=test, condition=str(attrs.get("condition", _condition_label(test, attrs))),
                  response=response, specimen=str(attrs.get("specimen", "mean")), n_samples=int(attrs.get("n_samples", 1)),
                  radius_m=float(attrs.get("radius_m", np.nan)), gap_m=float(attrs.get("gap_m", np.nan)),
                  nominal=nominal)
    n_rows = ds.sizes.get("point", next(iter(ds.sizes.values())))
    rows = np.arange(n_rows)
    if test == "uniaxial":
        common.update(radius_m=np.nan, gap_m=np.nan)
        return Curve(inputs={"stretch": _var(ds, "stretch")}, observed={"nominal_stress": _var(ds, "nominal_stress")},
                     **common), rows
    if test == "simple_shear":
        stress = _var(ds, "shear_stress") if "shear_stress" in ds else _var(ds, "nominal_stress")
        common.update(radius_m=np.nan, gap_m=np.nan)
        return Curve(inputs={"shear_strain": _var(ds, "shear_strain")}, observed={"shear_stress": stress},
                     **common), rows
    if test == "frequency_sweep":
        omega = _var(ds, "angular_frequency")
        if omega is None:
            omega = 2.0 * np.pi * _var(ds, "frequency")
        return Curve(inputs={"angular_frequency": omega},
                     observed={"storage_modulus": _var(ds, "storage_modulus"), "loss_modulus": _var(ds, "loss_modulus")},
                     **common), rows
    if test == "flow_curve":
        return Curve(inputs={"shear_rate": _var(ds, "shear_rate")}, observed={"shear_stress": _var(ds, "shear_stress")},
                     **common), rows
    t = _var(ds, "time")
    if test == "creep_recovery":
        stress = _var(ds, "shear_stress")
        if t[0] > 0:  # virgin state at t = 0
            th, sh, idx = np.r_[0.0, t], np.r_[0.0, stress], rows + 1
        else:
            th, sh, idx = t, stress, None
        return Curve(inputs={"time": th, "shear_stress": sh}, observed={"shear_strain": _var(ds, "shear_strain")},
                     obs_index=idx, **common), rows
    # shear histories: relaxation and constant shear rate
    strain = _var(ds, "shear_strain")
    observed = {"shear_stress": _var(ds, "shear_stress")}
    if "torque" in ds:
        observed["torque"] = _var(ds, "torque")
    if test == "constant_shear_rate":
        rate = nominal.get("shear_rate_1_per_s")
        if rate is not None and np.isfinite(rate) and rate > 0:
            if t is None:
                t = strain / rate
            strain = rate * t  # nominal history: exact for the recursion (piecewise linear)
        if t[0] > 0:
            th, gh, idx = np.r_[0.0, t], np.r_[0.0, strain], rows + 1
        else:
            th, gh, idx = t, strain, None
    else:
        th, gh, idx, rows = relaxation_history(t, strain, relaxation, nominal.get("rise_time_s"))
        observed = {k: v[rows] for k, v in observed.items()}
    return Curve(inputs={"time": th, "shear_strain": gh}, observed=observed, obs_index=idx, **common), rows


def geometry_from_runs(runs: Iterable[xr.Dataset]) -> dict[str, tuple[float, float]]:
    """Median plate radius and gap (m) per test kind of canonical runs (averages do not carry geometry)."""
    acc: dict[str, list[tuple[float, float]]] = {}
    for r in runs:
        test = str(r.attrs.get("test", ""))
        rad = float(r.attrs.get("radius_m", np.nan))
        gap = float(r.attrs.get("gap_m", np.nan))
        if np.isfinite(rad):
            acc.setdefault(test, []).append((rad, gap))
    return {t: (float(np.median([a for a, _ in v])), float(np.nanmedian([b for _, b in v])) if any(
        np.isfinite(b) for _, b in v) else float("nan")) for t, v in acc.items()}


def curves_from_averages(avg: xr.Dataset, radius_m: float | Mapping[str, float] = float("nan"),
                         gap_m: float | Mapping[str, float] = float("nan"),
                         relaxation: str = "measured", tests: Sequence[str] | None = None) -> list[Curve]:
    """Curves (sample means, SDs and counts) from an averages dataset (``curves.average_runs`` layout).

    Parameters
    ----------
    avg : averages dataset (``results/<dataset>/averages.nc``)
    radius_m, gap_m : plate geometry of the parallel-plate tests (averages do not carry it): one value, or a
        mapping test kind -> value (e.g. from :func:`geometry_from_runs`); NaN for homogeneous data
    relaxation : relaxation strain-history treatment (:func:`relaxation_history`)
    tests : restrict to these test kinds (default: every fittable one)

    Grid points where the mean is missing (fewer samples than needed) are dropped; the time of a CSR curve
    (grid: strain) is strain / nominal rate when the averaged time is absent.
    """

    out = []
    tests_all = as_str(avg["test"].values)
    labels = as_str(avg["condition"].values)
    for test, label in zip(tests_all, labels):
        test, label = str(test), str(label)
        if tests is not None and test not in tests:
            continue
        if test == "amplitude_sweep":
            curve = amplitude_sweep_lve_curve(select_average(avg, test, label))
            if curve is not None:
                out.append(curve)
            continue
        if test not in TEST_RESPONSE:
            continue
        one = select_average(avg, test, label)
        grid = one[next(iter(one.coords))]
        columns = {str(grid.name): np.asarray(grid.values, float)}
        sds = {}
        for name in one.data_vars:
            if name.endswith("_mean"):
                columns[name[:-5]] = np.asarray(one[name].values, float)
            elif name.endswith("_sd"):
                sds[name[:-3]] = np.asarray(one[name].values, float)
        needed = {"stress_relaxation": ("time", "shear_stress"), "constant_shear_rate": ("shear_strain", "shear_stress"),
                  "frequency_sweep": ("frequency", "storage_modulus", "loss_modulus"),
                  "creep_recovery": ("time", "shear_strain", "shear_stress"), "flow_curve": ("shear_rate", "shear_stress"),
                  "simple_shear": ("shear_strain",), "uniaxial": ("stretch", "nominal_stress")}[test]
        ok = np.ones(grid.size, bool)
        for name in needed:
            if name in columns:
                ok &= np.isfinite(columns[name])
        if test == "constant_shear_rate" and "time" in columns and not np.isfinite(columns["time"][ok]).all():
            columns.pop("time")
        run = xr.Dataset({k: ("point", v[ok]) for k, v in columns.items() if np.isfinite(v[ok]).any()})
        run.attrs.update({k: v for k, v in one.attrs.items() if isinstance(v, (int, float, str))})
        rad = radius_m.get(test, np.nan) if isinstance(radius_m, Mapping) else radius_m
        gap = gap_m.get(test, np.nan) if isinstance(gap_m, Mapping) else gap_m
        run.attrs.update({"condition": label, "specimen": "mean", "radius_m": float(rad), "gap_m": float(gap)})
        curve, rows = curve_and_rows(run, relaxation)
        sd = {k: sds[k][ok][rows] for k in curve.observed if k in sds}
        out.append(replace(curve, sd=sd))
    return out


def amplitude_sweep_lve_curve(sweep: xr.Dataset, tolerance: float = 0.05) -> Curve | None:
    """The linear part of an averaged amplitude sweep as an elastic shear curve (linear shear modulus G).

    Inside the LVE range a linear material's in-phase stress amplitude is ``G' * gamma_0``, so the points with
    amplitude up to the ISO 6721-10 limit of the mean G' (:func:`tissuemech.lve.lve_limit`, 5 % band) become an
    ``elastic_shear`` curve: input ``shear_strain`` = amplitude [1], observed ``shear_stress`` = G' * amplitude [Pa].
    A fitted linear elastic law then returns the thesis's "linear G from the amplitude sweep" (Table 4.4).
    The instrument's G' is already a modulus (plate geometry cancels for a linear material), so the curve is
    homogeneous (no plate radius). A sweep that never leaves the band is used whole.

    Parameters
    ----------
    sweep : one averaged amplitude sweep (``curves.select_average``), grid ``shear_strain`` [1], with
        ``storage_modulus_mean`` [Pa] (and ``_sd``)
    tolerance : relative band of the LVE limit rule

    Returns
    -------
    Curve or None when the sweep has fewer than two usable points inside the LVE range.
    """

    if "storage_modulus_mean" not in sweep:
        return None
    strain = np.abs(np.asarray(sweep[next(iter(sweep.coords))].values, float))
    storage = np.asarray(sweep["storage_modulus_mean"].values, float)
    sd = np.asarray(sweep["storage_modulus_sd"].values, float) if "storage_modulus_sd" in sweep else None
    ok = np.isfinite(strain) & np.isfinite(storage) & (strain > 0) & (storage > 0)
    try:
        limit = lve_limit(strain[ok], storage[ok], tolerance=tolerance).strain
    except ValueError:
        return None
    if np.isfinite(limit):
        ok &= strain <= limit
    if ok.sum() < 2:
        return None
    order = np.argsort(strain[ok])
    gamma = strain[ok][order]
    attrs = {k: v for k, v in sweep.attrs.items() if isinstance(v, (int, float, str))}
    nominal = {"frequency_hz": float(attrs["frequency_hz"])} if "frequency_hz" in attrs else {}
    nominal["lve_limit_strain"] = float(limit)
    curve = Curve(test="amplitude_sweep", condition=str(attrs.get("condition", "amplitude_sweep")),
                  response="elastic_shear", inputs={"shear_strain": gamma},
                  observed={"shear_stress": storage[ok][order] * gamma}, specimen="mean",
                  n_samples=int(attrs.get("n_samples", 1)), nominal=nominal)
    if sd is not None and np.isfinite(sd[ok]).all():
        curve = replace(curve, sd={"shear_stress": sd[ok][order] * gamma})
    return curve


def with_relaxation_history(curve: Curve, mode: str) -> Curve:
    """A relaxation curve with its strain history rebuilt as ``mode`` (:func:`relaxation_history`) from its
    observation points; other curves and ``mode="measured"`` are returned unchanged."""
    if curve.test != "stress_relaxation" or mode == "measured":
        return curve
    th, gh, idx, rows = relaxation_history(curve.obs_inputs("time"), curve.obs_inputs("shear_strain"), mode,
                                           curve.nominal.get("rise_time_s"))
    return replace(curve, inputs={"time": th, "shear_strain": gh}, obs_index=idx,
                   observed={k: np.asarray(v)[rows] for k, v in curve.observed.items()},
                   sd={k: np.asarray(v)[rows] for k, v in curve.sd.items()})


def _obs_x(curve: Curve) -> np.ndarray:
    """The natural ordering variable of a curve at its observation points."""
    key = {"shear_history": "time", "oscillation": "angular_frequency", "flow": "shear_rate", "creep": "time",
           "elastic_shear": "shear_strain", "uniaxial": "stretch"}[curve.response]
    return curve.obs_inputs(key)


def _subset(curve: Curve, keep: np.ndarray) -> Curve:
    keep = np.asarray(keep, int)
    idx = np.arange(curve.n_points) if curve.obs_index is None else np.asarray(curve.obs_index)
    observed = {k: np.asarray(v)[keep] for k, v in curve.observed.items()}
    sd = {k: np.asarray(v)[keep] for k, v in curve.sd.items()}
    if curve.response in ("shear_history", "creep"):
        # histories stay complete (the model needs the whole past); only the observations are thinned
        return replace(curve, observed=observed, sd=sd, obs_index=idx[keep])
    inputs = {k: np.asarray(v)[idx[keep]] for k, v in curve.inputs.items()}
    return replace(curve, inputs=inputs, observed=observed, sd=sd, obs_index=None)


def thin(curve: Curve, n_points: int = 40) -> Curve:
    """Keep about ``n_points`` observation points, log-spaced in the curve's ordering variable
    (time, frequency, rate, strain; linear spacing where it is not positive)."""
    x = _obs_x(curve)
    if x.size <= n_points:
        return curve
    pos = x > 0
    if pos.sum() > 0.9 * x.size:
        cand = np.nonzero(pos)[0]
        lx = np.log(x[cand])
        grid = np.linspace(lx.min(), lx.max(), n_points)
        keep = cand[np.unique(np.abs(lx[:, None] - grid[None, :]).argmin(axis=0))]
    else:
        grid = np.linspace(x.min(), x.max(), n_points)
        keep = np.unique(np.abs(x[:, None] - grid[None, :]).argmin(axis=0))
    return _subset(curve, np.sort(keep))


def select_strain(curve: Curve, max_strain: float | None = None, min_strain: float | None = None) -> Curve:
    """Restrict the observations to rim strains (or |stretch - 1|) within ``[min_strain, max_strain]``."""
    if curve.response in ("shear_history", "elastic_shear"):
        s = np.abs(curve.obs_inputs("shear_strain"))
    elif curve.response == "uniaxial":
        s = np.abs(curve.obs_inputs("stretch") - 1.0)
    else:
        return curve
    ok = np.ones(s.size, bool)
    if max_strain is not None:
        ok &= s <= max_strain * (1 + 1e-9)
    if min_strain is not None:
        ok &= s >= min_strain
    if not ok.any():
        raise ValueError(f"no point of {curve.label} within strain [{min_strain}, {max_strain}]")
    return _subset(curve, np.nonzero(ok)[0])


def curve_ranges(curves: Sequence[Curve]) -> dict[str, float]:
    """Strain, rate, frequency and time ranges covered by the observations of ``curves`` (validity range)."""
    strains, rates, omegas, times = [], [], [], []
    for c in curves:
        if c.response in ("shear_history", "elastic_shear"):
            strains.append(np.abs(c.obs_inputs("shear_strain")))
        if c.response == "uniaxial":
            strains.append(np.abs(c.obs_inputs("stretch") - 1.0))
        if c.response == "creep":
            strains.append(np.abs(c.observed["shear_strain"]))
        if c.response == "flow":
            rates.append(c.obs_inputs("shear_rate"))
        if "shear_rate_1_per_s" in c.nominal:
            rates.append(np.array([c.nominal["shear_rate_1_per_s"]]))
        if c.response == "oscillation":
            omegas.append(c.obs_inputs("angular_frequency"))
        if c.response in ("shear_history", "creep"):
            times.append(c.obs_inputs("time"))

    def rng(parts, fn):
        return float(fn(np.concatenate(parts))) if parts else float("nan")

    return {"strain_min": rng(strains, np.min), "strain_max": rng(strains, np.max),
            "rate_min_1_per_s": rng(rates, np.min), "rate_max_1_per_s": rng(rates, np.max),
            "omega_min_rad_per_s": rng(omegas, np.min), "omega_max_rad_per_s": rng(omegas, np.max),
            "time_min_s": rng(times, np.min), "time_max_s": rng(times, np.max)}


# ------------------------------------------------------------------------------------------------
# plate targets and predictions
# ------------------------------------------------------------------------------------------------
def plate_factor(radius_m: float) -> float:
    """Torque per unit apparent rim stress, pi R^3 / 2 [N m / Pa]."""
    return math.pi * radius_m ** 3 / 2.0


def target_observations(curve: Curve, target: str) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Observed values and SDs a fit compares predictions with, for a plate ``target``.

    Only shear histories (relaxation, CSR) and flow curves measured between plates depend on the target;
    oscillation (linear, where apparent stress is exact), creep, and homogeneous tests are unchanged.
    """
    obs = {k: np.asarray(v, float) for k, v in curve.observed.items()}
    sd = {k: np.asarray(v, float) for k, v in curve.sd.items()}
    if target not in PLATE_TARGETS:
        raise ValueError(f"unknown plate target {target!r}; use one of {PLATE_TARGETS}")
    plate_dependent = curve.response in ("shear_history", "flow") and curve.is_plate
    torque = obs.pop("torque", None)
    torque_sd = sd.pop("torque", None)
    if not plate_dependent:
        return obs, sd
    if target == "none":
        raise ValueError(f"{curve.label} was measured between plates: choose a plate target "
                         f"('thesis', 'apparent_stress', 'corrected_stress' or 'torque')")
    if target in ("thesis", "apparent_stress"):
        return obs, sd
    k = plate_factor(curve.radius_m)
    stress_sd = sd.pop("shear_stress", None)
    stress = obs.pop("shear_stress")
    if torque is None:
        torque = stress * k
    if torque_sd is None and stress_sd is not None:
        torque_sd = stress_sd * k
    if target == "torque":
        obs["torque"] = torque
        if torque_sd is not None:
            sd["torque"] = torque_sd
        return obs, sd
    # corrected_stress: needs a monotone sweep of the rim strain (CSR) or rate (flow)

    x = curve.obs_inputs("shear_strain") if curve.response == "shear_history" else curve.obs_inputs("shear_rate")
    if curve.test == "stress_relaxation" or np.any(np.diff(x) <= 0) or np.any(x <= 0):
        raise ValueError(f"corrected rim stress needs a monotone positive strain/rate sweep; {curve.label} has "
                         f"none (fit it with target='torque' or 'apparent_stress')")
    corrected = rabinowitsch_rim_stress(torque, x, curve.radius_m)
    obs["shear_stress"] = corrected
    if torque_sd is not None:
        sd["shear_stress"] = torque_sd / k * np.abs(corrected / np.where(stress != 0, stress, np.nan))
    return obs, sd


def _shear_history_stress(model: ConstitutiveModel, p, time_s, strain) -> np.ndarray:
    if model.supports("shear_history"):
        return model.shear_stress_history(p, time_s, strain)
    if model.supports("elastic_shear"):
        # a purely elastic (rate-independent) law: the stress follows the current strain
        return model.elastic_shear_stress(p, strain)
    raise ResponseNotSupported(f"model {model.name!r} ({model.family}) does not describe 'shear_history'")


def predict(model: ConstitutiveModel, p: Mapping[str, float], curve: Curve, target: str) -> dict[str, np.ndarray]:
    """Model prediction of every observable of ``curve`` (at its observation points) for a plate target."""
    r = curve.response
    idx = curve.obs_index
    if r == "shear_history":
        t = np.asarray(curve.inputs["time"], float)
        g = np.asarray(curve.inputs["shear_strain"], float)
        if curve.is_plate and target in ("torque", "apparent_stress"):

            full = forward_plate(model, p, t, g, curve.radius_m, curve.gap_m, target=target)
            key = "torque" if target == "torque" else "shear_stress"
            return {key: full if idx is None else full[idx]}
        full = _shear_history_stress(model, p, t, g)
        return {"shear_stress": full if idx is None else full[idx]}
    if r == "oscillation":
        gstar = model.complex_modulus(p, curve.obs_inputs("angular_frequency"))
        return {"storage_modulus": gstar.real, "loss_modulus": gstar.imag}
    if r == "flow":
        rate = curve.obs_inputs("shear_rate")
        if curve.is_plate and target in ("torque", "apparent_stress"):
            # steady flow: each radius sees the rate x r/R; torque by Gauss-Legendre on [0, R]
            xg, wg = np.polynomial.legendre.leggauss(12)
            u = 0.5 * (xg + 1.0)
            stress = model.steady_shear_stress(p, (rate[:, None] * u[None, :]).ravel()).reshape(rate.size, u.size)
            torque = 2.0 * math.pi * curve.radius_m ** 3 * (stress * u[None, :] ** 2) @ (0.5 * wg)
            if target == "torque":
                return {"torque": torque}
            return {"shear_stress": torque / plate_factor(curve.radius_m)}
        return {"shear_stress": model.steady_shear_stress(p, rate)}
    if r == "creep":
        full = model.creep_strain(p, np.asarray(curve.inputs["time"], float), np.asarray(curve.inputs["shear_stress"], float))
        return {"shear_strain": full if idx is None else full[idx]}
    if r == "elastic_shear":
        return {"shear_stress": model.elastic_shear_stress(p, curve.obs_inputs("shear_strain"))}
    if r == "uniaxial":
        return {"nominal_stress": model.uniaxial_nominal_stress(p, curve.obs_inputs("stretch"))}
    raise ValueError(f"unknown response kind {r!r}")


# ------------------------------------------------------------------------------------------------
# noise model and problem
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class NoiseModel:
    """Floor of the per-point standard deviation: ``floor = sqrt(absolute^2 + (relative |y|)^2)``;
    the weight of a point is ``1 / max(sample SD, floor)``.

    ``absolute`` maps observable -> absolute floor in its unit; default: 0.03 Pa for stresses (the
    ~0.05 uN m torque resolution of a 10 mm plate), 0.05 uN m for torque, 1e-5 for strain.
    ``relative`` is the relative floor (1 % = instrument accuracy).
    """

    relative: float = 0.01
    absolute: Mapping[str, float] = field(default_factory=lambda: {
        "shear_stress": 0.03, "torque": 5e-8, "storage_modulus": 0.03, "loss_modulus": 0.03,
        "shear_strain": 1e-5, "nominal_stress": 0.03})

    def sigma(self, name: str, y: np.ndarray, sd: np.ndarray | None) -> np.ndarray:
        y = np.asarray(y, float)
        floor = np.sqrt(self.absolute.get(name, 0.0) ** 2 + (self.relative * np.abs(y)) ** 2)
        floor = np.where(floor > 0, floor, np.finfo(float).tiny)
        if sd is None:
            return floor
        sd = np.where(np.isfinite(sd), np.asarray(sd, float), 0.0)
        return np.maximum(sd, floor)


@dataclass
class FitProblem:
    """A model and the curves it is fitted to jointly.

    Attributes
    ----------
    model : the constitutive model (structure fixed)
    curves : curves fitted jointly; each must be describable by the model
    target : plate target (see module docstring); homogeneous curves ignore it
    model_key : registry key recorded with the fit
    noise : :class:`NoiseModel`
    fixed : parameter name -> value held fixed
    bounds : parameter name -> (lower, upper) overriding the model's bounds
    scope : label of the data scope (e.g. ``"csr+relaxation"``), recorded with the fit
    relaxation : strain-history treatment of the relaxation curves (:func:`relaxation_history`), recorded
    """

    model: ConstitutiveModel
    curves: list[Curve]
    target: str = "apparent_stress"
    model_key: str = ""
    noise: NoiseModel = field(default_factory=NoiseModel)
    fixed: Mapping[str, float] = field(default_factory=dict)
    bounds: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    scope: str = ""
    relaxation: str = "measured"

    def __post_init__(self):
        if self.target not in PLATE_TARGETS:
            raise ValueError(f"unknown plate target {self.target!r}; use one of {PLATE_TARGETS}")
        if not self.curves:
            raise ValueError("a fit needs at least one curve")
        if not self.model_key:
            self.model_key = self.model.name
        self.observations = []
        for c in self.curves:
            need = c.response
            if need == "shear_history" and not (self.model.supports("shear_history") or self.model.supports("elastic_shear")):
                raise ValueError(f"model {self.model_key!r} cannot describe {c.label} (needs shear_history)")
            if need != "shear_history" and not self.model.supports(need):
                raise ValueError(f"model {self.model_key!r} ({self.model.family}) cannot describe {c.label} (needs {need})")
            obs, sd = target_observations(c, self.target)
            sig = {k: self.noise.sigma(k, v, sd.get(k)) for k, v in obs.items()}
            self.observations.append((obs, sig))

    # --- parameters -------------------------------------------------------------------------------
    def spec(self, name: str) -> ParamSpec:
        return next(s for s in self.model.param_specs if s.name == name)

    def param_bounds(self, s: ParamSpec) -> tuple[float, float]:
        return tuple(self.bounds.get(s.name, (s.lower, s.upper)))

    def is_log(self, s: ParamSpec) -> bool:
        lo, _ = self.param_bounds(s)
        return bool(s.log and lo >= 0 and s.init > 0)

    def internal_name(self, s: ParamSpec) -> str:
        return f"log10_{s.name}" if self.is_log(s) else s.name

    def make_params(self, start: Mapping[str, float] | None = None) -> lmfit.Parameters:
        """lmfit parameters in the internal (log10 for moduli/times) space."""
        start = dict(start or {})
        pars = lmfit.Parameters()
        for s in self.model.param_specs:
            lo, hi = self.param_bounds(s)
            value = float(self.fixed.get(s.name, start.get(s.name, s.init)))
            vary = s.name not in self.fixed
            if self.is_log(s):
                tiny = 1e-300
                ilo = math.log10(lo) if lo > 0 else -np.inf
                ihi = math.log10(hi) if np.isfinite(hi) else np.inf
                iv = math.log10(max(value, tiny))
                iv = min(max(iv, ilo), ihi)
                pars.add(self.internal_name(s), value=iv, min=ilo, max=ihi, vary=vary)
            else:
                value = min(max(value, lo), hi)
                pars.add(s.name, value=value, min=lo, max=hi, vary=vary)
        return pars

    def natural(self, pars: lmfit.Parameters | Mapping[str, float]) -> dict[str, float]:
        """Natural-unit parameter values from internal ones."""
        out = {}
        for s in self.model.param_specs:
            v = pars[self.internal_name(s)]
            v = float(v.value if isinstance(v, lmfit.Parameter) else v)
            out[s.name] = 10.0 ** v if self.is_log(s) else v
        return out

    # --- residuals --------------------------------------------------------------------------------
    def curve_terms(self, p: Mapping[str, float]) -> list[dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]]:
        """Per curve and observable: (observed, predicted, weighted residual)."""
        out = []
        for c, (obs, sig) in zip(self.curves, self.observations):
            pred = predict(self.model, p, c, self.target)
            terms = {}
            for k, y in obs.items():
                f = np.asarray(pred[k], float)
                if c.response in LOG_RESPONSES:
                    # log residual with the relative SD as its scale
                    tiny = 1e-12 * max(np.max(np.abs(y)), 1e-300)
                    w = (np.log(np.maximum(f, tiny)) - np.log(np.maximum(y, tiny))) / (sig[k] / np.maximum(np.abs(y), tiny))
                else:
                    w = (f - y) / sig[k]
                terms[k] = (y, f, w)
            out.append(terms)
        return out

    def residual(self, pars: lmfit.Parameters) -> np.ndarray:
        p = self.natural(pars)
        res = np.concatenate([w for terms in self.curve_terms(p) for (_, _, w) in terms.values()])
        # a non-finite prediction is a region the optimizer must leave, not a crash
        return np.where(np.isfinite(res), res, 1e10)

    @property
    def n_obs(self) -> int:
        return int(sum(v.size for obs, _ in self.observations for v in obs.values()))


# ------------------------------------------------------------------------------------------------
# fit result
# ------------------------------------------------------------------------------------------------
@dataclass
class FitResult:
    """Everything recorded about one fit (JSON/netCDF-ready through :func:`fit_to_dataset`)."""

    model_key: str
    family: str
    scope: str
    target: str
    params: dict[str, float]
    stderr: dict[str, float]
    units: dict[str, str]
    varying: list[str]
    correlation: np.ndarray
    flags: list[str]
    success: bool
    message: str
    chisqr: float
    redchi: float
    rmse: float
    nrmse: float
    n: int
    n_eff: float
    k: int
    aic: float
    aicc: float
    bic: float
    aicc_eff: float
    bic_eff: float
    nfev: int
    n_starts: int
    curve_labels: list[str]
    curve_rmse: dict[str, float]
    curve_nrmse: dict[str, float]
    residuals: list[dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]]
    ranges: dict[str, float]
    selection: list[dict]
    structure: dict
    start_chisqr: list[float] = field(default_factory=list)
    #: condition number of the correlation matrix and its sloppiest direction (science.md §4.5)
    condition_number: float = float("nan")
    sloppy_direction: dict[str, float] = field(default_factory=dict)
    #: strain-history treatment of relaxation curves ("measured", "ramp", "step")
    relaxation: str = "measured"

    @property
    def ok(self) -> bool:
        """Converged and no flag raised."""
        return self.success and not self.flags


def _flags(problem: FitProblem, best, names: list[str]) -> tuple[list[str], np.ndarray]:
    flags = []
    if not best.success:
        flags.append(f"not_converged: {best.message}")
    k = len(names)
    corr = np.full((k, k), np.nan)
    if best.covar is not None and np.all(np.isfinite(best.covar)):
        cov = np.asarray(best.covar)
        sd = np.sqrt(np.clip(np.diag(cov), 0, None))
        with np.errstate(invalid="ignore", divide="ignore"):
            corr = cov / np.outer(sd, sd)
        np.fill_diagonal(corr, 1.0)
        if not np.all(sd > 0):
            # a finite covariance with a zero variance: lmfit's inverse of a singular Jacobian
            flags.append("no_covariance: the Jacobian is singular (parameters not identifiable from these data)")
        for i in range(k):
            for j in range(i + 1, k):
                if np.isfinite(corr[i, j]) and abs(corr[i, j]) > CORRELATION_FLAG:
                    flags.append(f"correlated: {names[i]}~{names[j]} (rho={corr[i, j]:+.3f})")
    elif k:
        flags.append("no_covariance: the Jacobian is singular (parameters not identifiable from these data)")
    for iname in names:
        par = best.params[iname]
        lo, hi = par.min, par.max
        # "at a bound" relative to the parameter's own scale (not to a possibly huge box)
        init = par.init_value if par.init_value is not None else par.value
        scale = max(abs(init), abs(par.value), 1e-12)
        tol = 1e-4 * scale
        for bound, side in ((lo, "lower"), (hi, "upper")):
            if np.isfinite(bound) and abs(par.value - bound) <= tol:
                flags.append(f"at_bound: {iname.removeprefix('log10_')} at its {side} bound {bound:g}"
                             + (" (log10)" if iname.startswith("log10_") else ""))
    return flags, corr


#: the ``at_bound`` flag of :func:`fit` (parameter, side, bound)
_AT_BOUND = re.compile(r"at_bound: (\S+) at its (lower|upper) bound (\S+)")


def at_bound_parameters(flags: Iterable[str]) -> list[str]:
    """Varying parameters a fit left at a bound, from its flags (``at_bound: <name> at its <side> bound <b>``).

    A Prony weight ``beta_i`` at its lower bound 0 is not listed: that relaxation mode is simply absent (the
    NNLS answer "not needed"), not a collapse of the fit.
    """
    out = []
    for f in flags:
        m = _AT_BOUND.match(str(f))
        if m and not (re.fullmatch(r"beta_\d+", m.group(1)) and m.group(2) == "lower" and float(m.group(3)) == 0.0):
            out.append(m.group(1))
    return sorted(set(out))


def has_covariance(flags: Iterable[str], stderr: Mapping[str, float], varying: Sequence[str]) -> bool:
    """Whether a fit has a covariance: no ``no_covariance`` flag and a finite standard error of some varying
    parameter (true for a fit with nothing varying)."""
    if any(str(f).startswith("no_covariance") for f in flags):
        return False
    return not varying or any(np.isfinite(stderr.get(n, np.nan)) for n in varying)


def _random_start(problem: FitProblem, rng: np.random.Generator) -> dict[str, float]:
    """One random start around the model's defaults: log parameters within +-1 decade of the default, positive
    linear ones within a factor 10, others within +-max(|default|, 1); narrow finite bounds (less than ten
    times the default's scale wide) are sampled uniformly. Always clipped to the bounds."""
    out = {}
    for spec in problem.model.param_specs:
        if spec.name in problem.fixed:
            continue
        lo, hi = problem.param_bounds(spec)
        init = float(spec.init)
        if problem.is_log(spec):
            v = init * 10.0 ** rng.uniform(-1.0, 1.0)
        elif np.isfinite(lo) and np.isfinite(hi) and (hi - lo) <= 10.0 * max(abs(init), 1e-300):
            v = rng.uniform(lo, hi)
        elif lo >= 0 and init > 0:
            v = init * 10.0 ** rng.uniform(-1.0, 1.0)
        else:
            v = init + rng.uniform(-1.0, 1.0) * max(abs(init), 1.0)
        out[spec.name] = float(min(max(v, lo), hi))
    return out


def fit(problem: FitProblem, starts: Iterable[Mapping[str, float]] = (), n_random: int = 4, seed: int = 0,
        max_nfev: int | None = None, method: str = "least_squares") -> FitResult:
    """Fit ``problem`` from several starts and return the best fit with its full record.

    Parameters
    ----------
    problem : :class:`FitProblem`
    starts : explicit natural-unit starts (e.g. from :func:`prony_nnls`), tried before the model default
    n_random : number of seeded random starts around the defaults (:func:`_random_start`)
    seed : random seed (the result is reproducible)
    max_nfev : function-evaluation limit per start
    method : lmfit method (``least_squares`` = scipy TRF with bounds)
    """
    rng = np.random.default_rng(seed)
    start_list = [dict(s) for s in starts] + [problem.model.default_params()]
    start_list += [_random_start(problem, rng) for _ in range(n_random)]

    results, chis, nfev = [], [], 0
    for s in start_list:
        pars = problem.make_params(s)
        kws = {"max_nfev": max_nfev} if max_nfev else {}
        try:
            with warnings.catch_warnings():
                # lmfit divides by zero standard errors of singular fits; the flags below report them
                warnings.filterwarnings("ignore", "invalid value encountered", RuntimeWarning)
                res = lmfit.minimize(problem.residual, pars, method=method, **kws)
        except (ValueError, FloatingPointError, ZeroDivisionError) as exc:  # a start in a bad region
            chis.append(float("inf"))
            last_error = exc
            continue
        nfev += int(res.nfev)
        chis.append(float(res.chisqr))
        results.append(res)
    if not results:
        raise RuntimeError(f"every start of {problem.model_key!r} failed: {last_error}")
    # Starts that reach the same optimum within solver tolerance can differ by a relabelling (e.g. two Prony
    # modes swapped); taking the first such start, not the strictly smallest chi-square, keeps the reported
    # labels the same on every machine.
    lowest = min(float(r.chisqr) for r in results)
    best = next(r for r in results if float(r.chisqr) <= lowest * (1.0 + EQUIVALENT_CHISQR_RTOL) + 1e-300)
    return _record(problem, best, nfev, chis)


def _record(problem: FitProblem, best, nfev: int, chis: list[float]) -> FitResult:
    model = problem.model
    p = problem.natural(best.params)
    names = [n for n in best.var_names]
    flags, corr = _flags(problem, best, names)
    stderr = {}
    for s in model.param_specs:
        par = best.params[problem.internal_name(s)]
        if not par.vary:
            stderr[s.name] = 0.0
        elif par.stderr is None or not np.isfinite(par.stderr):
            stderr[s.name] = float("nan")
        elif problem.is_log(s):
            # delta method: d(10^u)/du = ln(10) 10^u
            stderr[s.name] = float(math.log(10.0) * p[s.name] * par.stderr)
        else:
            stderr[s.name] = float(par.stderr)
    terms = problem.curve_terms(p)
    weighted = [np.concatenate([w for (_, _, w) in t.values()]) for t in terms]
    n = int(sum(w.size for w in weighted))
    k = len(names)
    chisqr = float(sum(np.sum(w ** 2) for w in weighted))
    n_eff = float(sum(effective_sample_size(w) for w in weighted))
    raw = np.concatenate([f - y for t in terms for (y, f, _) in t.values()])
    curve_rmse, curve_nrmse = {}, {}
    for c, t in zip(problem.curves, terms):
        e = np.concatenate([f - y for (y, f, _) in t.values()])
        scale = np.mean(np.abs(np.concatenate([y for (y, _, _) in t.values()])))
        curve_rmse[c.label] = float(np.sqrt(np.mean(e ** 2)))
        curve_nrmse[c.label] = float(curve_rmse[c.label] / scale) if scale > 0 else float("nan")
    ic = information_criteria(chisqr, n, k)
    ic_eff = information_criteria(chisqr * n_eff / n, n_eff, k)  # chi2 rescaled to n_eff independent points
    for name in names:
        spec_name = name.removeprefix("log10_")
        se, v = stderr.get(spec_name, np.nan), p.get(spec_name, np.nan)
        if np.isfinite(se) and v != 0 and se > abs(v):
            flags.append(f"poorly_determined: {spec_name} standard error {se:.3g} exceeds |value| {abs(v):.3g}")
    cond, sloppy = float("nan"), {}
    if corr.size and np.all(np.isfinite(corr)):
        # sloppy direction = least-constrained combination = largest-variance eigenvector of the
        # (standardised) covariance, i.e. the smallest eigenvalue of the Fisher matrix J^T W J
        evals, evecs = np.linalg.eigh(corr)
        cond = float(evals[-1] / max(evals[0], np.finfo(float).tiny))
        sloppy = {n.removeprefix("log10_"): float(v) for n, v in zip(names, evecs[:, -1])}
    selection = [{"label": c.label, "test": c.test, "condition": c.condition, "specimen": c.specimen,
                  "n_points": c.n_points, "n_samples": c.n_samples, "response": c.response,
                  "observables": sorted(o.keys()), "radius_m": c.radius_m, "gap_m": c.gap_m,
                  **{f"nominal_{k2}": v2 for k2, v2 in c.nominal.items()}}
                 for c, (o, _) in zip(problem.curves, problem.observations)]
    return FitResult(
        model_key=problem.model_key, family=model.family, scope=problem.scope, target=problem.target,
        params=p, stderr=stderr, units={s.name: s.unit for s in model.param_specs},
        varying=[n.removeprefix("log10_") for n in names], correlation=corr, flags=flags,
        success=bool(best.success), message=str(best.message), chisqr=chisqr, redchi=chisqr / max(n - k, 1),
        rmse=float(np.sqrt(np.mean(raw ** 2))), nrmse=float(np.sqrt(np.mean(np.square(list(curve_nrmse.values()))))),
        n=n, n_eff=n_eff, k=k, aic=ic["aic"], aicc=ic["aicc"], bic=ic["bic"], aicc_eff=ic_eff["aicc"],
        bic_eff=ic_eff["bic"], nfev=nfev, n_starts=len(chis), curve_labels=[c.label for c in problem.curves],
        curve_rmse=curve_rmse, curve_nrmse=curve_nrmse, residuals=terms, ranges=curve_ranges(problem.curves),
        selection=selection, structure=to_jsonable(model.structure, nonfinite_as_null=False), start_chisqr=chis,
        condition_number=cond, sloppy_direction=sloppy, relaxation=problem.relaxation)


def evaluate(model: ConstitutiveModel, params: Mapping[str, float], curves: Sequence[Curve], target: str,
             noise: NoiseModel | None = None) -> dict[str, float]:
    """Prediction error of fixed parameters on (held-out) curves.

    Returns ``rmse`` (observed units, pooled), ``nrmse`` (RMS over curves of RMSE / mean |observed|),
    ``chisqr`` (weighted) and ``n``.
    """
    prob = FitProblem(model=model, curves=list(curves), target=target, noise=noise or NoiseModel())
    terms = prob.curve_terms(dict(params))
    raw, nr, chi, n = [], [], 0.0, 0
    for t in terms:
        e = np.concatenate([f - y for (y, f, _) in t.values()])
        y = np.concatenate([y for (y, _, _) in t.values()])
        w = np.concatenate([w for (_, _, w) in t.values()])
        raw.append(e)
        nr.append(np.sqrt(np.mean(e ** 2)) / np.mean(np.abs(y)))
        chi += float(np.sum(w ** 2))
        n += w.size
    raw = np.concatenate(raw)
    return {"rmse": float(np.sqrt(np.mean(raw ** 2))), "nrmse": float(np.sqrt(np.mean(np.square(nr)))),
            "chisqr": chi, "n": n}


# ------------------------------------------------------------------------------------------------
# Prony weights by non-negative least squares (robust start, science.md §4.1)
# ------------------------------------------------------------------------------------------------
def prony_nnls(curves: Sequence[Curve], taus: np.ndarray, elastic: Callable[[np.ndarray], np.ndarray] | None = None,
               noise: NoiseModel | None = None) -> dict[str, np.ndarray | float]:
    """Non-negative Prony weights on fixed relaxation times from shear-history and oscillation curves.

    The (quasi-)linear stress is linear in the weights for fixed taus:
    sigma(t) = a_inf s_e(t) + sum_i a_i h_i[s_e](t), with h_i the exact recursion of ``models.recursion``
    driven by the elastic history s_e = ``elastic(gamma(t))`` (default: s_e = gamma, i.e. moduli in Pa), and
    G*(omega) = a_inf + sum_i a_i i omega tau_i / (1 + i omega tau_i) for frequency sweeps (linear only).
    Rows are weighted by the noise model; NNLS keeps every weight >= 0.

    Returns
    -------
    dict with ``taus`` [s], ``a_inf`` and ``a`` (moduli in Pa for the linear drive, or stress factors
    for a QLV drive), the *relative* weights ``g = a / (a_inf + sum a)`` and ``g_inf`` (reduced relaxation
    function of QLV: G_r = g_inf + sum g_i exp(-t/tau_i)), the instantaneous scale ``a0 = a_inf + sum a``,
    and the weighted ``residual_norm``.
    """

    noise = noise or NoiseModel()
    taus = np.asarray(taus, float)
    rows, rhs = [], []
    for c in curves:
        if c.response == "shear_history":
            t = np.asarray(c.inputs["time"], float)
            g = np.asarray(c.inputs["shear_strain"], float)
            se = g if elastic is None else np.asarray(elastic(g), float)
            h = prony_branch_histories(t, np.repeat(se[None, :], taus.size, axis=0), taus)
            A = np.column_stack([se, h.T])
            if c.obs_index is not None:
                A = A[c.obs_index]
            y = np.asarray(c.observed["shear_stress"], float)
            sig = noise.sigma("shear_stress", y, c.sd.get("shear_stress"))
            rows.append(A / sig[:, None])
            rhs.append(y / sig)
        elif c.response == "oscillation":
            if elastic is not None:
                continue  # oscillation is linear: only informs the linear-moduli variant
            re, im = prony_oscillation_basis(c.obs_inputs("angular_frequency"), taus)
            for part, name in ((re, "storage_modulus"), (im, "loss_modulus")):
                y = np.asarray(c.observed[name], float)
                sig = noise.sigma(name, y, c.sd.get(name))
                rows.append(part / sig[:, None])
                rhs.append(y / sig)
    if not rows:
        raise ValueError("prony_nnls needs shear-history (relaxation/CSR) or frequency-sweep curves")
    A = np.vstack(rows)
    b = np.concatenate(rhs)
    scale = np.linalg.norm(A, axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    coef, rnorm = nnls(A / scale, b, maxiter=50 * A.shape[1])
    coef = coef / scale
    a0 = float(coef.sum())
    return {"taus": taus, "a_inf": float(coef[0]), "a": coef[1:], "a0": a0,
            "g": coef[1:] / a0 if a0 > 0 else np.zeros(taus.size),
            "g_inf": float(coef[0] / a0) if a0 > 0 else 1.0, "residual_norm": float(rnorm)}


def prony_start(model: ConstitutiveModel, curves: Sequence[Curve], noise: NoiseModel | None = None) -> dict | None:
    """A robust start for a QLV model with fixed relaxation times, from :func:`prony_nnls`.

    The elastic history is the instantaneous law at its default parameters; NNLS gives the overall scale
    ``a0`` (applied to the law's moduli, parameters in Pa) and the branch ratios ``beta_i = a_i / a_inf``.
    Returns ``None`` when the model is not such a QLV model or the curves carry no shear history.
    """
    if model.family != "qlv" or not hasattr(model, "prony_weights") or getattr(model, "free_taus", True):
        return None
    hist = [c for c in curves if c.response == "shear_history"]
    if not hist:
        return None
    p0 = model.default_params()
    inst = model.instantaneous
    ip = {k: p0[k] for k in inst.param_names}
    nn = prony_nnls(hist, model.taus(p0), elastic=lambda g: inst.elastic_shear_stress(ip, g), noise=noise)
    if not (nn["a0"] > 0 and nn["a_inf"] > 0):
        return None
    start = dict(p0)
    for spec in inst.param_specs:
        if spec.unit == "Pa":
            start[spec.name] = ip[spec.name] * nn["a0"]
    for i, a in enumerate(nn["a"]):
        start[f"beta_{i + 1}"] = float(a / nn["a_inf"])
    return start


# ------------------------------------------------------------------------------------------------
# outputs
# ------------------------------------------------------------------------------------------------
def fit_to_dataset(result: FitResult) -> xr.Dataset:
    """The fit record as an xarray Dataset (dims ``param``, ``param_b``, ``point``, ``curve``), written by
    :meth:`tissuemech.records.FitRecord.to_dataset` (the one layout; read back with ``FitRecord.from_dataset``)."""
    return FitRecord.from_result(result).to_dataset()


def write_fit_netcdf(result: FitResult, path) -> None:
    """Atomically write the fit record (``results/<dataset>/fits/<scope>/<model>.nc``); read it back with
    :meth:`tissuemech.records.FitRecord.from_netcdf`."""
    FitRecord.from_result(result).to_netcdf(path)


#: scalar attributes of a fit record copied to ``fits.csv`` (in this order, after ``dataset``/``file``/``model``)
FITS_CSV_ATTRS = ("family", "scope", "target", "relaxation", "success", "n", "n_eff", "k", "chisqr", "redchi", "rmse",
                  "nrmse", "aic", "aicc", "bic", "aicc_eff", "bic_eff", "condition_number", "nfev", "n_starts",
                  "message")


def fits_csv_row(record: FitRecord | xr.Dataset, dataset: str = "", file: str = "") -> dict:
    """One tidy ``fits.csv`` row of a fit record (a :class:`~tissuemech.records.FitRecord`, or its Dataset
    :func:`fit_to_dataset` / a ``fits/<scope>/<model>.nc`` read back): criteria, flags, ranges and
    ``param_<name>``/``se_<name>`` columns. The one ``fits.csv`` schema:
    ``dataset, file, model, <FITS_CSV_ATTRS>, n_flags, flags ("; "), curves ("; "), <ranges>, param_*, se_*``.
    """
    rec = record if isinstance(record, FitRecord) else FitRecord.from_dataset(record)
    row = {"dataset": dataset, "file": str(file), "model": rec.model_key}
    for name in FITS_CSV_ATTRS:
        row[name] = bool(rec.success) if name == "success" else getattr(rec, name)
    row["n_flags"] = len(rec.flags)
    row["flags"] = "; ".join(rec.flags)
    row["curves"] = "; ".join(rec.curve_labels)
    row.update(rec.ranges)
    for name, value in rec.params.items():
        row[f"param_{name}"] = float(value)
        row[f"se_{name}"] = float(rec.stderr[name])
    return row


_curve_and_rows = curve_and_rows  # old private name, still used by diagnosis.baseline (to be switched there)

__all__ = [
    "PLATE_TARGETS", "TEST_RESPONSE", "Curve", "amplitude_sweep_lve_curve", "curve_from_run", "curve_and_rows", "curves_from_averages", "geometry_from_runs", "relaxation_history",
    "thin", "select_strain", "with_relaxation_history", "curve_ranges", "plate_factor", "target_observations", "predict",
    "NoiseModel", "FitProblem", "FitResult", "fit", "evaluate", "log_spaced_taus",
    "prony_nnls", "prony_start", "FitRecord", "fit_to_dataset", "write_fit_netcdf", "fits_csv_row", "FITS_CSV_ATTRS",
    "at_bound_parameters", "has_covariance",
]
