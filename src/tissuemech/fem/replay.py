"""The FEM replays the measured tests: every averaged parallel-plate shear test of a dataset, simulated with the
TLED solver on the sample cylinder, per material card, and scored against the measured averages.

What is replayed (``results/<dataset>/averages.nc``, one row per test x condition x card):

* constant-rate ramps at every rate and relaxations with their measured rise: the rim-strain history the fit uses
  (:func:`tissuemech.fitting.curves_from_averages`: the nominal ramp ``rate t``, the measured relaxation strain),
  strain-controlled (:func:`tissuemech.fem.experiments.rheometer_torsion`); observable: the apparent rim stress
  ``2M/(pi R^3)``, as the instrument reports it;
* creep and creep-recovery: the measured apparent-stress history as a torque history, torque-controlled
  (:func:`tissuemech.fem.experiments.rheometer_creep`, feedback on the rigid plate's angle); observable: the rim
  strain;
* frequency and amplitude sweeps: at each kept point a sinusoidal rim strain of the measured amplitude and
  frequency from rest, :attr:`ReplaySettings.cycles` cycles, and the instrument's first-harmonic analysis of the
  last :attr:`ReplaySettings.analysed_cycles` of them
  (:func:`tissuemech.models.plate.first_harmonic_moduli` of the rim strain and the apparent rim stress);
  observables: G' and G''.

Every test uses its own averaged plate radius and gap (``averages.nc`` ``radius_m``/``gap_m``); a test without them
is reported ``not replayed: no plate radius`` / ``no gap`` (no default plate). Flow curves (steady shear flow) and
homogeneous-specimen tests are reported as not replayed with the reason.

Time budget: the observation points of each time curve are thinned (:attr:`ReplaySettings.points_per_curve`, log
spaced in time within each loading phase, :func:`tissuemech.fitting.thin`), the history keeps those points and the
breakpoints needed to follow the measured drive within :attr:`ReplaySettings.history_tolerance` of its range, and
each sweep is thinned to :attr:`ReplaySettings.sweep_points` points (log spaced).

Quasi-static: every solve is dynamic relaxation (inertia neglected). The check that this holds is the
``inertia_number`` of each row, ``rho h^2 / (G0 t_c^2)``: the squared ratio of the shear-wave transit time across
the gap (``h sqrt(rho/G0)``) to the test's fastest time scale ``t_c`` (``1/omega`` of the fastest sweep point;
for a time test the shortest time in which the measured drive changes by half its range: the half-rise time of a
relaxation or creep loading). The sample-inertia correction of a sweep is ``(kh)^2/3 = inertia_number/3``
(``models.plate.apparent_complex_modulus``); the density is the card's, else the solver's (``fem.materials``) -- it
enters this check only.

Error: :func:`tissuemech.stats.nrmse` of the simulated observable at the kept measured points against the
measured means (the fit's per-curve NRMSE; a sweep's G' and G'' pooled as one curve).
"""
from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
import pandas as pd
import xarray as xr

from .. import fitting as F
from ..curves import as_str, select_average
from ..models.plate import first_harmonic_moduli
from ..records import MaterialCard
from ..stats import nrmse
from .experiments import TorqueControlError, card_material, rheometer_creep, rheometer_torsion
from .materials import small_strain_shear_modulus
from .tled import DynamicRelaxationError, ElementInversionError

#: test kinds replayed with a measured time history (strain- or torque-controlled)
TIME_TESTS = ("constant_shear_rate", "stress_relaxation", "creep_recovery")
#: oscillatory test kinds replayed point by point
SWEEP_TESTS = ("frequency_sweep", "amplitude_sweep")
#: test kinds that are not replayed, with the reason
NOT_REPLAYED = {
    "flow_curve": "steady shear flow: the simulated sample is a solid card, which reaches no steady flow stress",
    "simple_shear": "homogeneous-specimen test, not a parallel-plate test",
    "uniaxial": "homogeneous-specimen test, not a parallel-plate test",
}
#: columns of ``replay.csv`` (the first seven are the contract)
REPLAY_COLUMNS = ("test", "condition", "card", "role", "held_out", "nrmse", "n_points", "n_elements", "wall_s",
                  "status", "radius_m", "gap_m", "inertia_number")
#: columns of the replay's point table (``replay_points.csv``: what the figure draws)
POINT_COLUMNS = ("test", "condition", "card", "role", "observable", "x_name", "x", "measured", "simulated")
#: the metric of :func:`fix_simulation`
FIX_SIMULATION_METRIC = "fem_replay_held_out_nrmse"


@dataclass(frozen=True)
class ReplaySettings:
    """How finely the measured tests are replayed.

    Attributes
    ----------
    element_size_m : edge length of the cylinder mesh (m; the pipeline's ``fem.cylinder_element_size_m``)
    points_per_curve : observation points kept per loading phase of a time curve
    sweep_points : frequencies / amplitudes kept per sweep
    cycles, analysed_cycles, points_per_cycle : oscillation from rest; the last ``analysed_cycles`` are analysed
    history_tolerance : the thinned drive follows the measured one within this fraction of its range
    torque_tolerance : torque control accuracy, relative to the largest target torque
    n_threads : numba threads per solve
    """

    element_size_m: float
    points_per_curve: int = 12
    sweep_points: int = 4
    cycles: int = 2
    analysed_cycles: int = 1
    points_per_cycle: int = 16
    history_tolerance: float = 0.01
    torque_tolerance: float = 1e-3
    n_threads: int | str | None = 1


@dataclass(frozen=True)
class PlateTest:
    """One averaged parallel-plate test as the replay drives it.

    Attributes
    ----------
    test, condition : the averaged curve (``averages.nc``)
    radius_m, gap_m : its averaged plate geometry (NaN where not stated)
    control : ``"strain"`` (rim-strain history), ``"torque"`` (apparent-stress history, torque-controlled) or
        ``"oscillation"``
    time_s, drive : the (thinned) history from rest: rim strain (1) or apparent rim stress (Pa) at ``time_s`` (s)
    obs_index : observation points into the history (time tests)
    frequency_hz, amplitude : per observation point (oscillation)
    x_name, x : the ordering variable of the observations (for figures)
    observed : measured means at the observation points (``shear_stress``, ``shear_strain``, ``storage_modulus``,
        ``loss_modulus``)
    time_scale_s : the test's fastest time scale (see the module docstring)
    reason : why the test is not replayed (empty when it is)
    """

    test: str
    condition: str
    radius_m: float
    gap_m: float
    control: str = ""
    time_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    drive: np.ndarray = field(default_factory=lambda: np.zeros(0))
    obs_index: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    frequency_hz: np.ndarray = field(default_factory=lambda: np.zeros(0))
    amplitude: np.ndarray = field(default_factory=lambda: np.zeros(0))
    x_name: str = ""
    x: np.ndarray = field(default_factory=lambda: np.zeros(0))
    observed: Mapping[str, np.ndarray] = field(default_factory=dict)
    time_scale_s: float = float("nan")
    reason: str = ""

    @property
    def n_points(self) -> int:
        return int(self.x.size)


# ------------------------------------------------------------------------------------------------
# the measured tests
# ------------------------------------------------------------------------------------------------
def plate_tests(averages: xr.Dataset, settings: ReplaySettings) -> list[PlateTest]:
    """Every averaged curve of ``averages`` as a :class:`PlateTest` (thinned as ``settings`` says), in the order of
    the averages; curves that cannot be replayed carry the reason."""
    tests = as_str(averages["test"].values)
    conditions = as_str(averages["condition"].values)

    def per_curve(name):
        return np.asarray(averages[name].values, float) if name in averages else np.full(len(tests), np.nan)

    radius, gap, temperature = per_curve("radius_m"), per_curve("gap_m"), per_curve("temperature_c")
    time_curves = {(c.test, c.condition): c for c in F.curves_from_averages(averages, tests=TIME_TESTS)}
    out = []
    for i, (test, condition) in enumerate(zip(tests, conditions)):
        test, condition = str(test), str(condition)
        base = PlateTest(test, condition, float(radius[i]), float(gap[i]))
        temps = {round(float(x), 1) for x, k in zip(temperature, tests) if k == test and np.isfinite(x)}
        missing = [what for what, v in (("no plate radius", radius[i]), ("no gap", gap[i]))
                   if not (np.isfinite(v) and v > 0)]
        if test in NOT_REPLAYED:
            out.append(replace(base, reason=NOT_REPLAYED[test]))
        elif test not in TIME_TESTS + SWEEP_TESTS:
            out.append(replace(base, reason=f"test kind {test!r} is not a parallel-plate test the replay knows"))
        elif missing:
            out.append(replace(base, reason=" and ".join(missing)))
        elif len(temps) > 1:
            out.append(replace(base, reason=f"{test} curves at {len(temps)} temperatures: the replay applies no "
                                            "time-temperature shift"))
        elif test in TIME_TESTS:
            curve = time_curves.get((test, condition))
            out.append(_time_test(base, curve, settings) if curve is not None else
                       replace(base, reason="no usable points in the averages"))
        else:
            out.append(_sweep_test(base, select_average(averages, test, condition), settings))
    return out


def _time_test(base: PlateTest, curve: F.Curve, settings: ReplaySettings) -> PlateTest:
    """A ramp, relaxation or creep curve: thinned observations, thinned history, the measured observable."""
    if curve.response == "creep":
        control, drive_name, observable = "torque", "shear_stress", "shear_strain"
    else:
        control, drive_name, observable = "strain", "shear_strain", "shear_stress"
    t = np.asarray(curve.inputs["time"], float)
    drive = np.asarray(curve.inputs[drive_name], float)
    rows = np.arange(curve.n_points)
    idx = rows if curve.obs_index is None else np.asarray(curve.obs_index)
    # observations at the rest state (t <= 0) are not simulated
    keep_rows = rows[t[idx] > 0]
    if keep_rows.size == 0 or not np.isfinite(drive).all():
        return replace(base, reason="no usable points in the averages")
    kept = []
    for phase in _phases(drive[idx[keep_rows]]):
        sub = keep_rows[phase]
        part = replace(curve, observed={k: np.asarray(v)[sub] for k, v in curve.observed.items()},
                       sd={}, obs_index=idx[sub])
        kept.append(sub[np.searchsorted(idx[sub], F.thin(part, settings.points_per_curve, by_phase=False).obs_index)])
    kept = np.concatenate(kept)
    points = _breakpoints(t, drive, idx[kept], settings.history_tolerance)
    t_h, d_h = t[points], drive[points]
    obs = np.searchsorted(points, idx[kept])
    if t_h[0] <= 0.0:
        if d_h[0] == 0.0:  # the rest state the simulation starts from
            t_h, d_h, obs = t_h[1:], d_h[1:], obs - 1
        else:  # a step at t = 0: applied over a millionth of the first interval
            t_h = t_h.copy()
            t_h[0] = 1e-6 * t_h[1]
    return replace(base, control=control, time_s=t_h, drive=d_h, obs_index=obs,
                   x_name="shear_strain" if curve.test == "constant_shear_rate" else "time",
                   x=(drive if curve.test == "constant_shear_rate" else t)[idx[kept]],
                   observed={observable: np.asarray(curve.observed[observable], float)[kept]},
                   time_scale_s=_fastest_change(t, drive))


def _phases(drive: np.ndarray) -> list[np.ndarray]:
    """Loading phases of a sampled drive: split where it jumps by more than half its range between two points
    (creep -> recovery); positions into ``drive``."""
    span = float(np.ptp(drive)) if drive.size else 0.0
    cuts = np.flatnonzero(np.abs(np.diff(drive)) > 0.5 * span) + 1 if span > 0 else np.zeros(0, int)
    return [p for p in np.split(np.arange(drive.size), cuts) if p.size]


def _breakpoints(time_s: np.ndarray, drive: np.ndarray, keep: np.ndarray, tolerance: float) -> np.ndarray:
    """Sorted history points to simulate: ``keep``, the first and last point, and the points needed for the
    piecewise-linear drive through them to follow the measured drive within ``tolerance`` of its range (greedy:
    the worst point is added until none is off by more)."""
    chosen = set(int(i) for i in keep) | {0, drive.size - 1}
    limit = tolerance * max(float(np.ptp(drive)), np.finfo(float).tiny)
    while True:
        pts = np.array(sorted(chosen))
        err = np.abs(np.interp(time_s, time_s[pts], drive[pts]) - drive)
        worst = int(np.argmax(err))
        if err[worst] <= limit:
            return pts
        chosen.add(worst)


def _fastest_change(time_s: np.ndarray, drive: np.ndarray, fraction: float = 0.5) -> float:
    """Shortest time in which the measured drive changes by ``fraction`` of its range (s)."""
    span = float(np.ptp(drive))
    best = float("inf")
    for i in range(drive.size - 1):
        moved = np.flatnonzero(np.abs(drive[i + 1:] - drive[i]) >= fraction * span)
        if moved.size:
            best = min(best, float(time_s[i + 1 + moved[0]] - time_s[i]))
    return best if np.isfinite(best) and best > 0 else float("nan")


def _sweep_test(base: PlateTest, sweep: xr.Dataset, settings: ReplaySettings) -> PlateTest:
    """A frequency or amplitude sweep: per kept point the frequency and rim-strain amplitude the instrument
    applied (measured per point where the averages carry it, else the nominal condition), and G', G''."""
    grid = np.asarray(sweep[next(iter(sweep.coords))].values, float)

    def mean(name):
        return np.asarray(sweep[f"{name}_mean"].values, float) if f"{name}_mean" in sweep else np.full(grid.size, np.nan)

    if base.test == "frequency_sweep":
        freq = grid if next(iter(sweep.coords)) == "frequency" else mean("angular_frequency") / (2.0 * np.pi)
        amp = np.abs(mean("shear_strain"))
        nominal = float(sweep.attrs.get("strain_pct", np.nan)) / 100.0
        amp = np.where(np.isfinite(amp) & (amp > 0), amp, nominal)
        missing = "no strain amplitude"
    else:
        amp = np.abs(grid)
        freq = mean("frequency")
        freq = np.where(np.isfinite(freq), freq, mean("angular_frequency") / (2.0 * np.pi))
        freq = np.where(np.isfinite(freq) & (freq > 0), freq, float(sweep.attrs.get("frequency_hz", np.nan)))
        missing = "no frequency"
    g1, g2 = mean("storage_modulus"), mean("loss_modulus")
    ok = np.isfinite(g1) & np.isfinite(g2) & np.isfinite(freq) & (freq > 0) & np.isfinite(amp) & (amp > 0)
    if not ok.any():
        reason = missing if not (np.isfinite(freq).any() and np.isfinite(amp).any()) else \
            "no usable points in the averages"
        return replace(base, reason=reason)
    order = "frequency" if base.test == "frequency_sweep" else "shear_strain"
    curve = F.Curve(test=base.test, condition=base.condition,
                    response="oscillation" if order == "frequency" else "elastic_shear",
                    inputs={"angular_frequency": 2.0 * np.pi * freq[ok], "shear_strain": amp[ok]},
                    observed={"storage_modulus": g1[ok], "loss_modulus": g2[ok]})
    curve = F.thin(curve, settings.sweep_points)
    f_k = curve.inputs["angular_frequency"] / (2.0 * np.pi)
    a_k = np.asarray(curve.inputs["shear_strain"], float)
    return replace(base, control="oscillation", frequency_hz=f_k, amplitude=a_k, x_name=order,
                   x=f_k if order == "frequency" else a_k, observed=dict(curve.observed),
                   time_scale_s=float(1.0 / (2.0 * np.pi * f_k.max())))


# ------------------------------------------------------------------------------------------------
# the simulation
# ------------------------------------------------------------------------------------------------
def simulate(card: Mapping, test: PlateTest, settings: ReplaySettings) -> tuple[dict[str, np.ndarray], int]:
    """The simulated observables of ``test`` at its observation points, and the mesh's element count.

    ``card`` is the FEM's view of a material card (:meth:`tissuemech.records.MaterialCard.for_fem`).
    """
    if test.reason:
        raise ValueError(f"{test.test} {test.condition} is not replayable: {test.reason}")
    geometry = dict(radius_m=test.radius_m, gap_m=test.gap_m, element_size_m=settings.element_size_m,
                    n_threads=settings.n_threads)
    if test.control == "strain":
        ds = rheometer_torsion(card, test.time_s, test.drive, test=test.test, **geometry)
        return {"shear_stress": np.asarray(ds["shear_stress"].values, float)[test.obs_index]}, ds.attrs["fem_n_elements"]
    if test.control == "torque":
        torque = test.drive * math.pi * test.radius_m ** 3 / 2.0
        ds = rheometer_creep(card, test.time_s, torque, test=test.test, torque_tolerance=settings.torque_tolerance,
                             **geometry)
        return {"shear_strain": np.asarray(ds["shear_strain"].values, float)[test.obs_index]}, ds.attrs["fem_n_elements"]
    if test.control == "oscillation":
        ppc, n_el = settings.points_per_cycle, 0
        start = (settings.cycles - settings.analysed_cycles) * ppc
        moduli = []
        for f, amp in zip(test.frequency_hz, test.amplitude):
            t = np.arange(1, settings.cycles * ppc + 1) / (ppc * f)
            ds = rheometer_torsion(card, t, amp * np.sin(2.0 * np.pi * f * t), test=test.test, **geometry)
            # whole cycles: the points from the window's start up to (not including) the run's last point
            sel = slice(start - 1, settings.cycles * ppc - 1) if start > 0 else slice(0, settings.cycles * ppc)
            moduli.append(first_harmonic_moduli(t[sel], ds["shear_strain"].values[sel], ds["shear_stress"].values[sel],
                                                float(f)))
            n_el = ds.attrs["fem_n_elements"]
        g = np.asarray(moduli, float)
        return {"storage_modulus": g[:, 0], "loss_modulus": g[:, 1]}, n_el
    raise ValueError(f"unknown control {test.control!r}")


def inertia_number(card: Mapping, test: PlateTest) -> float:
    """``rho h^2 / (G0 t_c^2)`` of a test (see the module docstring); quasi-static needs it << 1."""
    material = card_material(card)
    g0 = small_strain_shear_modulus(material)
    return float(material.density_kg_m3 * test.gap_m ** 2 / (g0 * test.time_scale_s ** 2))


# ------------------------------------------------------------------------------------------------
# cards and the replay table
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ReplayCard:
    """A material card the replay runs.

    Attributes
    ----------
    name : ``<scope>/<model>``
    role : ``"baseline"`` or the named cause whose extension this card is
    card : the card as read (None when it could not be read)
    reason : why the FEM cannot run it (empty when it can); its rows say ``not replayed: <reason>``
    only : the curves (``test|condition``) this card replays, None for every test
    """

    name: str
    role: str
    card: MaterialCard | None
    reason: str = ""
    #: replay only these curves (``test|condition``; None: every test), e.g. a fold card on its held-out curves
    only: frozenset[str] | None = None


def fitted_selection(card: MaterialCard) -> tuple[frozenset[str], frozenset[str]] | None:
    """The test kinds and the ``test|condition`` curves the card's fit saw, as the card records them
    (``valid_range.tests``/``valid_range.conditions``, else ``provenance.curves``); None when it records neither."""
    data = card.data
    valid = data.get("valid_range") or {}
    curves = valid.get("conditions") or (data.get("provenance") or {}).get("curves") or []
    tests = valid.get("tests") or sorted({str(c).split("|", 1)[0] for c in curves})
    if not tests:
        return None
    return frozenset(str(t) for t in tests), frozenset(str(c) for c in curves)


def held_out(card: MaterialCard, test: str, condition: str) -> bool | None:
    """Whether the card's fit left this curve out: its test kind, or (where the card lists its fit's curves) the
    curve itself. None when the card does not record its fit's selection."""
    sel = fitted_selection(card)
    if sel is None:
        return None
    tests, curves = sel
    return test not in tests or (bool(curves) and f"{test}|{condition}" not in curves)


def replay(averages: xr.Dataset, cards: Sequence[ReplayCard], settings: ReplaySettings,
           on_row=None) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Replay every averaged test of a dataset with every card.

    Parameters
    ----------
    averages : ``results/<dataset>/averages.nc``
    cards : the cards, baseline first (:class:`ReplayCard`)
    settings : :class:`ReplaySettings`
    on_row : optional callable receiving each row as it is done (progress logging)

    Returns
    -------
    ``(table, points)``: the replay table (:data:`REPLAY_COLUMNS`, one row per test x condition x card; ``status``
    ``ok``, ``not replayed: <reason>`` or ``failed: <error>``) and the point table (:data:`POINT_COLUMNS`: measured
    and simulated values at the kept points of each replayed row).
    """
    tests = plate_tests(averages, settings)
    rows, points = [], []
    for rc in cards:
        fem_card = rc.card.for_fem() if rc.card is not None and not rc.reason else None
        for pt in tests:
            if rc.only is not None and f"{pt.test}|{pt.condition}" not in rc.only:
                continue
            row = {"test": pt.test, "condition": pt.condition, "card": rc.name, "role": rc.role,
                   "held_out": held_out(rc.card, pt.test, pt.condition) if rc.card is not None else None,
                   "nrmse": float("nan"), "n_points": 0, "n_elements": 0, "wall_s": float("nan"),
                   "radius_m": pt.radius_m, "gap_m": pt.gap_m, "inertia_number": float("nan")}
            if pt.reason or fem_card is None:
                row["status"] = f"not replayed: {pt.reason or rc.reason}"
            else:
                t0 = time.perf_counter()
                try:
                    simulated, n_el = simulate(fem_card, pt, settings)
                except (ElementInversionError, DynamicRelaxationError, TorqueControlError) as err:
                    row.update(status=f"failed: {err}", wall_s=time.perf_counter() - t0)
                else:
                    names = list(pt.observed)
                    measured = np.concatenate([pt.observed[k] for k in names])
                    row.update(nrmse=nrmse(measured, np.concatenate([simulated[k] for k in names])),
                               n_points=pt.n_points, n_elements=int(n_el), wall_s=time.perf_counter() - t0,
                               inertia_number=inertia_number(fem_card, pt), status="ok")
                    for k in names:
                        points += [{"test": pt.test, "condition": pt.condition, "card": rc.name, "role": rc.role,
                                    "observable": k, "x_name": pt.x_name, "x": float(x), "measured": float(m),
                                    "simulated": float(s)} for x, m, s in zip(pt.x, pt.observed[k], simulated[k])]
            rows.append(row)
            if on_row is not None:
                on_row(row)
    table = pd.DataFrame(rows, columns=list(REPLAY_COLUMNS))
    table["held_out"] = table["held_out"].astype("boolean")
    return table, pd.DataFrame(points, columns=list(POINT_COLUMNS))


# ------------------------------------------------------------------------------------------------
# what the diagnosis reads
# ------------------------------------------------------------------------------------------------
def fix_simulation(replay_table: pd.DataFrame, cause: str, extension_card: str,
                   baseline_card: str | None = None) -> dict:
    """The simulation's error on the tests an extension was not fitted to, baseline card vs extension card: the
    ``fix.simulation`` record of a diagnosis finding.

    The curves compared are those the extension card's fit left out (``held_out``) that the baseline card's fit
    left out too (so neither card was fitted to them) and that both cards replayed (``status == "ok"``, finite
    NRMSE). ``before``/``after`` are the mean replay NRMSE of the baseline and of the extension card over them,
    ``gain = (before - after) / before``.

    Parameters
    ----------
    replay_table : the replay table (``replay.csv``, :func:`replay`)
    cause : the named cause (the extension card's ``role``)
    extension_card : the extension card's name (``card`` column, ``<scope>/<model>``)
    baseline_card : the baseline card's name; None: the rows of role ``baseline`` (a fold's baseline, fitted to the
        same training runs as its extension, is named here)

    Returns
    -------
    ``{"metric", "before", "after", "gain", "held_out_tests"}`` (``held_out_tests``: the ``test|condition`` curves
    averaged over); with no such curve the numbers are NaN and ``note`` says why.
    """
    t = replay_table.copy()
    t["held_out"] = t["held_out"].astype("boolean")
    usable = (t["status"] == "ok") & np.isfinite(t["nrmse"].astype(float)) & t["held_out"].fillna(False).astype(bool)
    ext = t[usable & (t["card"] == extension_card) & (t["role"] == cause)]
    base = t[usable & ((t["card"] == baseline_card) if baseline_card is not None else (t["role"] == "baseline"))]
    pairs = ext.merge(base, on=["test", "condition"], suffixes=("_ext", "_base"))
    record = {"metric": FIX_SIMULATION_METRIC, "before": float("nan"), "after": float("nan"), "gain": float("nan"),
              "held_out_tests": sorted(f"{a}|{b}" for a, b in zip(pairs["test"], pairs["condition"]))}
    if pairs.empty:
        n_ext = int(((t["card"] == extension_card) & (t["role"] == cause)).sum())
        record["note"] = (f"no replay rows of card {extension_card!r} for {cause!r}" if n_ext == 0 else
                          "no curve left out of both cards' fits was replayed by both cards")
        return record
    before = float(pairs["nrmse_base"].mean())
    after = float(pairs["nrmse_ext"].mean())
    record.update(before=before, after=after, gain=(before - after) / before if before > 0 else float("nan"))
    return record
