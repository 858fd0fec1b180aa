"""Data selection of a fit: :class:`Curve` (one curve to fit) and its builders and selectors (part of
:mod:`tissuemech.fitting`, which re-exports every public name)."""
from __future__ import annotations

import logging
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
import xarray as xr

from ..curves import as_str, select_average
from ..lve import lve_limit

logger = logging.getLogger(__name__)

#: response kind of the model that describes each canonical test kind
TEST_RESPONSE: dict[str, str] = {
    "stress_relaxation": "shear_history",
    "constant_shear_rate": "shear_history",
    "frequency_sweep": "oscillation",
    "amplitude_sweep": "amplitude_sweep",
    "creep_recovery": "creep",
    "flow_curve": "flow",
    "simple_shear": "elastic_shear",
    "uniaxial": "uniaxial",
}


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
        ``creep``, ``elastic_shear``, ``uniaxial``; or ``amplitude_sweep``, the first harmonic of a model's
        ``shear_history`` response to sinusoidal rim strains (:func:`tissuemech.models.plate.oscillation_moduli`)
    inputs : model inputs (SI): ``time`` [s] + ``shear_strain`` [1] (a full history from a virgin state) for
        ``shear_history``; ``angular_frequency`` [rad/s]; ``shear_rate`` [1/s]; ``time`` + ``shear_stress``
        [Pa] (imposed) for ``creep``; ``shear_strain`` for ``elastic_shear``; ``stretch`` for ``uniaxial``;
        ``shear_strain`` = rim strain amplitude [1] for ``amplitude_sweep`` (its frequency: ``nominal["frequency_hz"]``)
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
    if test == "amplitude_sweep":
        return amplitude_sweep_curve(ds, common), rows
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
                         relaxation: str = "measured", tests: Sequence[str] | None = None,
                         amplitude: str = "lve") -> list[Curve]:
    """Curves (sample means, SDs and counts) from an averages dataset (``curves.average_runs`` layout).

    Parameters
    ----------
    avg : averages dataset (``results/<dataset>/averages.nc``)
    radius_m, gap_m : plate geometry of the parallel-plate tests (averages do not carry it): one value, or a
        mapping test kind -> value (e.g. from :func:`geometry_from_runs`); NaN for homogeneous data
    relaxation : relaxation strain-history treatment (:func:`relaxation_history`)
    tests : restrict to these test kinds (default: every fittable one)
    amplitude : how an amplitude sweep becomes a curve: ``"lve"``, its linear part as an elastic shear curve
        (:func:`amplitude_sweep_lve_curve`, the thesis's linear G); ``"full"``, every amplitude as measured
        between the plates (response ``amplitude_sweep``: G', G'' of the first harmonic)

    Grid points where the mean is missing (fewer samples than needed) are dropped; the time of a CSR curve
    (grid: strain) is strain / nominal rate when the averaged time is absent. A curve the averages do not describe
    fully (an amplitude sweep whose frequency neither the sheet nor a channel gives) is left out with a logged
    warning naming it and why; nothing is assumed in its place.
    """

    out = []
    tests_all = as_str(avg["test"].values)
    labels = as_str(avg["condition"].values)
    for test, label in zip(tests_all, labels):
        test, label = str(test), str(label)
        if tests is not None and test not in tests:
            continue
        if test == "amplitude_sweep" and amplitude == "lve":
            curve = amplitude_sweep_lve_curve(select_average(avg, test, label))
            if curve is not None:
                out.append(curve)
            continue
        if amplitude not in ("lve", "full"):
            raise ValueError(f"amplitude must be 'lve' or 'full', not {amplitude!r}")
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
                  "amplitude_sweep": ("shear_strain", "storage_modulus", "loss_modulus"),
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
        try:
            curve, rows = curve_and_rows(run, relaxation)
        except ValueError as exc:
            # a curve the data do not describe fully (an amplitude sweep with no frequency): left out, and said
            logger.warning("%s|%s left out of the fit: %s", test, label, exc)
            continue
        sd = {k: sds[k][ok][rows] for k in curve.observed if k in sds}
        out.append(replace(curve, sd=sd))
    return out


def amplitude_sweep_curve(ds: xr.Dataset, common: Mapping) -> Curve:
    """An amplitude sweep (run or average as a run) as measured between the plates: response ``amplitude_sweep``.

    Input ``shear_strain`` = the rim strain amplitude [1]; observed ``storage_modulus``/``loss_modulus`` [Pa] as
    the instrument reports them (first harmonic of the apparent rim stress over the rim strain). The frequency is
    the run's ``frequency_hz`` attribute or, failing that, its ``frequency`` or ``angular_frequency`` channel
    (median); without any the sweep cannot be predicted and ``ValueError`` says so.
    """
    nominal = dict(common.get("nominal", {}))
    f_hz = nominal.get("frequency_hz", np.nan)
    if not np.isfinite(f_hz) and "frequency" in ds:
        f_hz = float(np.nanmedian(_var(ds, "frequency")))
    if not np.isfinite(f_hz) and "angular_frequency" in ds:
        f_hz = float(np.nanmedian(_var(ds, "angular_frequency"))) / (2.0 * np.pi)
    if not (np.isfinite(f_hz) and f_hz > 0):
        raise ValueError(f"amplitude sweep {common.get('condition', '')!r} has no frequency (attribute frequency_hz, "
                         "channel frequency or angular_frequency)")
    nominal["frequency_hz"] = float(f_hz)
    strain = np.abs(_var(ds, "shear_strain"))
    return Curve(inputs={"shear_strain": strain},
                 observed={"storage_modulus": _var(ds, "storage_modulus"), "loss_modulus": _var(ds, "loss_modulus")},
                 **{**common, "nominal": nominal})


def amplitude_sweep_lve_curve(sweep: xr.Dataset, tolerance: float = 0.05) -> Curve | None:
    """The linear part of an averaged amplitude sweep as an elastic shear curve (linear shear modulus G).

    Inside the LVE range a linear material's in-phase stress amplitude is ``G' * gamma_0``, so the points with
    amplitude up to the ISO 6721-10 limit of the mean G' (:func:`tissuemech.lve.lve_limit`, 5 % band, with the mean's
    measurement noise ``storage_modulus_noise`` where the averages carry it: the limit of ``lve.csv``) become an
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
    noise = (np.asarray(sweep["storage_modulus_noise"].values, float)[ok] if "storage_modulus_noise" in sweep
             else None)
    try:
        limit = lve_limit(strain[ok], storage[ok], tolerance=tolerance, modulus_sd=noise).strain
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
           "elastic_shear": "shear_strain", "uniaxial": "stretch", "amplitude_sweep": "shear_strain"}[curve.response]
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


def loading_phases(drive: np.ndarray) -> list[np.ndarray]:
    """Loading and unloading phases of a sampled stress-controlled drive, as positions into ``drive``.

    A new phase begins wherever the drive crosses the middle of its range, however finely the instrument sampled
    the change: a creep-recovery test is the lower half of its loading ramp (where the fast modes show), the
    creep, and the recovery from the middle of its unloading on; a step load is two phases and a constant drive
    one.
    """
    drive = np.asarray(drive, float)
    if drive.size == 0 or not np.ptp(drive) > 0:
        return [np.arange(drive.size)]
    high = np.abs(drive - drive.min()) > 0.5 * np.ptp(drive)
    cuts = np.flatnonzero(high[1:] != high[:-1]) + 1
    return [p for p in np.split(np.arange(drive.size), cuts) if p.size]


def _spaced(x: np.ndarray, n_points: int) -> np.ndarray:
    """About ``n_points`` sorted positions into ``x``: log-spaced where ``x`` is mostly positive, else linearly."""
    if x.size <= n_points:
        return np.arange(x.size)
    pos = x > 0
    if pos.sum() > 0.9 * x.size:
        cand = np.nonzero(pos)[0]
        lx = np.log(x[cand])
        grid = np.linspace(lx.min(), lx.max(), n_points)
        return np.sort(cand[np.unique(np.abs(lx[:, None] - grid[None, :]).argmin(axis=0))])
    grid = np.linspace(x.min(), x.max(), n_points)
    return np.unique(np.abs(x[:, None] - grid[None, :]).argmin(axis=0))


def thin(curve: Curve, n_points: int = 40, by_phase: bool = True) -> Curve:
    """Keep about ``n_points`` observation points, log-spaced in the curve's ordering variable
    (time, frequency, rate, strain; linear spacing where it is not positive).

    A creep curve with several phases (:func:`loading_phases` of its imposed stress at the observation points:
    creep, then recovery) shares the points between its phases, each log-spaced in the time since its phase began
    (the last point of the phase before); a phase with fewer points than its share keeps them all. Log-spaced over
    the whole test, a recovery spans a small part of the test's decades and would keep one or two points: a fit
    would not see how the strain recovers, which is what tells a solid from a fluid. ``by_phase=False``: one
    log-spaced set (for a caller that has split the phases itself, e.g. the FEM replay's histories).
    """
    x = _obs_x(curve)
    if x.size <= n_points:
        return curve
    phases = loading_phases(curve.obs_inputs("shear_stress")) if by_phase and curve.response == "creep" \
        else [np.arange(x.size)]
    if len(phases) == 1:
        return _subset(curve, _spaced(x, n_points))
    keep, left = [], n_points
    for i, k in enumerate(sorted(range(len(phases)), key=lambda j: phases[j].size)):
        share = max(2, left // (len(phases) - i))
        since = x[phases[k]] - (x[phases[k - 1][-1]] if k else 0.0)
        chosen = phases[k][_spaced(since, share)]
        keep.append(chosen)
        left -= chosen.size
    return _subset(curve, np.sort(np.concatenate(keep)))


def select_strain(curve: Curve, max_strain: float | None = None, min_strain: float | None = None) -> Curve:
    """Restrict the observations to rim strains (or |stretch - 1|) within ``[min_strain, max_strain]``."""
    if curve.response in ("shear_history", "elastic_shear", "amplitude_sweep"):
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
        if c.response in ("shear_history", "elastic_shear", "amplitude_sweep"):
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
        if c.response == "amplitude_sweep":
            omegas.append(np.array([2.0 * np.pi * c.nominal["frequency_hz"]]))
        if c.response in ("shear_history", "creep"):
            times.append(c.obs_inputs("time"))

    def rng(parts, fn):
        return float(fn(np.concatenate(parts))) if parts else float("nan")

    return {"strain_min": rng(strains, np.min), "strain_max": rng(strains, np.max),
            "rate_min_1_per_s": rng(rates, np.min), "rate_max_1_per_s": rng(rates, np.max),
            "omega_min_rad_per_s": rng(omegas, np.min), "omega_max_rad_per_s": rng(omegas, np.max),
            "time_min_s": rng(times, np.min), "time_max_s": rng(times, np.max)}
