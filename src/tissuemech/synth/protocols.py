"""Test protocols of a rotational rheometer: what the motor (or the torque controller) is told to do and
when the instrument records a data point.

Every protocol returns a :class:`Protocol`: the *simulation* history (a time grid on which the material
model is evaluated; the exact Prony recursion is exact for strain piecewise linear in time, so the grid only
has to represent the strain path) and the indices of the grid that the instrument reports as points.
Oscillatory protocols instead list one (frequency, amplitude) pair per reported point; flow curves list
the steady shear rates. Strains are rim strains (dimensionless), stresses apparent rim stresses 2M/(pi R^3)
in Pa (what a torque-controlled instrument imposes), times in s.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Protocol:
    """One test as the instrument runs it.

    Attributes
    ----------
    kind : test kind (``canonical.TEST_KINDS``)
    control : ``"strain"`` (rim strain imposed), ``"stress"`` (apparent rim stress imposed),
        ``"oscillation"`` (sinusoidal rim strain per point) or ``"steady_rate"`` (flow curve)
    time_s : (n,) simulation grid (strain/stress control), s
    setpoint : (n,) imposed rim strain (1) or apparent rim stress (Pa) on ``time_s``
    report_index : indices of ``time_s`` reported as data points
    frequency_hz, strain_amplitude : per reported point (oscillation)
    shear_rate_1_s : per reported point (flow curve)
    point_duration_s : measuring time per point (oscillation, flow curve), s
    condition : nominal condition written to samples.csv (``shear_rate_1_per_s``, ``strain_pct``,
        ``stress_pa``, ``frequency_hz``)
    rise_time_s : ramp time of a step (relaxation, creep), s
    """

    kind: str
    control: str
    time_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    setpoint: np.ndarray = field(default_factory=lambda: np.zeros(0))
    report_index: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    frequency_hz: np.ndarray = field(default_factory=lambda: np.zeros(0))
    strain_amplitude: np.ndarray = field(default_factory=lambda: np.zeros(0))
    shear_rate_1_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    point_duration_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    condition: dict = field(default_factory=dict)
    rise_time_s: float = 0.0

    @property
    def duration_s(self) -> float:
        """Total duration of the test (s)."""
        if self.control in ("oscillation", "steady_rate"):
            return float(np.sum(self.point_duration_s))
        return float(self.time_s[-1]) if self.time_s.size else 0.0


def _oscillation_point_duration(frequency_hz: np.ndarray, n_cycles: int, min_s: float = 5.0) -> np.ndarray:
    # the instrument waits a few cycles per point and at least a few seconds at high frequency
    return np.maximum(n_cycles / np.asarray(frequency_hz, float), min_s)


def amplitude_sweep(frequency_hz: float = 1.0, strain_min: float = 1e-4, strain_max: float = 0.1,
                    n_points: int = 16, n_cycles: int = 10) -> Protocol:
    """Strain-amplitude sweep at fixed frequency, log-spaced rim strain amplitudes (1 = 100 %)."""
    amps = np.geomspace(strain_min, strain_max, n_points)
    f = np.full(n_points, float(frequency_hz))
    return Protocol("amplitude_sweep", "oscillation", frequency_hz=f, strain_amplitude=amps,
                    point_duration_s=_oscillation_point_duration(f, n_cycles),
                    condition={"frequency_hz": float(frequency_hz)})


def frequency_sweep(frequency_min_hz: float = 0.1, frequency_max_hz: float = 20.0, n_points: int = 12,
                    strain: float = 0.01, n_cycles: int = 10) -> Protocol:
    """Frequency sweep at fixed rim strain amplitude, log-spaced frequencies, from high to low as the
    instrument usually runs it."""
    f = np.geomspace(frequency_max_hz, frequency_min_hz, n_points)
    return Protocol("frequency_sweep", "oscillation", frequency_hz=f, strain_amplitude=np.full(n_points, strain),
                    point_duration_s=_oscillation_point_duration(f, n_cycles),
                    condition={"strain_pct": 100.0 * strain})


def constant_shear_rate(shear_rate_1_s: float, final_strain: float = 0.5, n_points: int = 40,
                        n_sim: int = 400) -> Protocol:
    """Constant rim shear rate ramp from rest to ``final_strain`` (strain linear in time).

    Points are linear in strain (the instrument samples at a fixed interval), the first at 1/n of the ramp.
    """
    duration = final_strain / shear_rate_1_s
    t = np.linspace(0.0, duration, n_sim + 1)
    report = np.unique(np.round(np.linspace(0, n_sim, n_points + 1)[1:]).astype(int))
    return Protocol("constant_shear_rate", "strain", time_s=t, setpoint=shear_rate_1_s * t, report_index=report,
                    condition={"shear_rate_1_per_s": float(shear_rate_1_s)})


def stress_relaxation(strain: float, rise_time_s: float = 0.01, hold_s: float = 300.0, n_points: int = 60,
                      first_point_s: float = 0.01, n_rise: int = 20, n_hold_sim: int = 400) -> Protocol:
    """Step strain with a finite rise time (linear ramp of ``rise_time_s``) then hold.

    The reported points are log-spaced from ``first_point_s`` to the end (as RheoCompass's log time
    profile), so the ramp is visible in the strain column when it is slow.
    """
    rise = max(float(rise_time_s), 1e-6)
    t_rise = np.linspace(0.0, rise, n_rise + 1)
    t_hold = rise + np.geomspace(1e-4, hold_s - rise, n_hold_sim) if hold_s > rise else np.zeros(0)
    t_report = np.geomspace(first_point_s, hold_s, n_points)
    t = np.unique(np.concatenate([t_rise, t_hold, t_report]))
    setpoint = strain * np.clip(t / rise, 0.0, 1.0)
    report = np.searchsorted(t, t_report)
    return Protocol("stress_relaxation", "strain", time_s=t, setpoint=setpoint, report_index=report,
                    condition={"strain_pct": 100.0 * strain}, rise_time_s=rise)


def creep_recovery(stress_pa: float, creep_s: float = 300.0, recovery_s: float = 300.0, rise_time_s: float = 0.05,
                   n_points: int = 60, first_point_s: float = 0.05, n_sim: int = 300) -> Protocol:
    """Stress-controlled creep (apparent rim stress ``stress_pa`` applied with a ramp of ``rise_time_s``)
    then recovery at zero stress. Points log-spaced in each phase."""
    rise = max(float(rise_time_s), 1e-6)
    half = n_points // 2
    t_c = np.geomspace(first_point_s, creep_s, half)
    t_r = creep_s + np.geomspace(first_point_s, recovery_s, n_points - half)
    sim_c = np.concatenate([np.linspace(0, rise, 11), np.geomspace(rise, creep_s, n_sim // 2)])
    sim_r = creep_s + np.concatenate([np.linspace(0, rise, 11), np.geomspace(rise, recovery_s, n_sim // 2)])
    t = np.unique(np.concatenate([sim_c, sim_r, t_c, t_r]))
    load = np.clip(t / rise, 0.0, 1.0) - np.clip((t - creep_s) / rise, 0.0, 1.0)
    report = np.searchsorted(t, np.concatenate([t_c, t_r]))
    return Protocol("creep_recovery", "stress", time_s=t, setpoint=stress_pa * load, report_index=report,
                    condition={"stress_pa": float(stress_pa)}, rise_time_s=rise)


def flow_curve(shear_rate_min_1_s: float = 0.01, shear_rate_max_1_s: float = 0.8, n_points: int = 15,
               point_duration_s: float = 10.0) -> Protocol:
    """Steady-state flow curve: log-spaced rim shear rates, each held ``point_duration_s``."""
    rates = np.geomspace(shear_rate_min_1_s, shear_rate_max_1_s, n_points)
    return Protocol("flow_curve", "steady_rate", shear_rate_1_s=rates,
                    point_duration_s=np.full(n_points, float(point_duration_s)))


PROTOCOLS = {
    "amplitude_sweep": amplitude_sweep,
    "frequency_sweep": frequency_sweep,
    "constant_shear_rate": constant_shear_rate,
    "stress_relaxation": stress_relaxation,
    "creep_recovery": creep_recovery,
    "flow_curve": flow_curve,
}


def build_protocol(kind: str, **settings) -> Protocol:
    """Protocol of a test kind from keyword settings (the config's test entry)."""
    if kind not in PROTOCOLS:
        raise ValueError(f"unknown test kind {kind!r}; known: {sorted(PROTOCOLS)}")
    return PROTOCOLS[kind](**settings)
