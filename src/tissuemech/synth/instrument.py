"""Virtual parallel-plate rheometer: runs a :class:`~tissuemech.synth.protocols.Protocol` on a material
model and returns the channels the instrument records.

Physics (science.md section 2): the rim strain is ``gamma_R = theta R/h``; every radius carries its own
history ``gamma_R r/R`` and the torque is the Gauss-Legendre radial integral of the model's stress
(:func:`tissuemech.models.plate.torque_from_history`); the reported "shear stress" is ``2M/(pi R^3)``
(:func:`tissuemech.models.plate.apparent_rim_stress`), so the rim-stress error of nonlinear materials is in
the data as in a real export. Stress-controlled tests solve the torque balance for the rim strain
(:func:`tissuemech.models.plate.creep_rim_strain`). Oscillation is simulated in time from rest and analysed
as the instrument does (first harmonic of the last cycles, :func:`tissuemech.models.plate.first_harmonic_moduli`),
with the motor inertia torque ``I theta''`` added to the raw torque and the calibrated ``I_cal theta''``
subtracted. The normal force is the thrust integral where the model defines normal stresses.

Instrument imperfections: torque noise ``sd = sqrt(floor^2 + (rel M)^2)`` (0.05 uN m + 1 %), torque
resolution (quantisation), normal-force noise, temperature and gap channels with small noise. The hidden
effects of :mod:`tissuemech.synth.effects` reach the simulation through :class:`Artefacts`.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from ..models.base import ConstitutiveModel
from ..models.plate import (apparent_complex_modulus, apparent_rim_stress, creep_rim_strain,
                            first_harmonic_moduli, gauss_radii, stress_histories, thrust_normal_force,
                            torque_from_history)
from .protocols import Protocol


@dataclass
class Geometry:
    """Plate geometry of one loading: radius and gap in m."""

    radius_m: float = 0.0125
    gap_m: float = 0.003


@dataclass
class InstrumentSettings:
    """Instrument model (defaults: a combined motor-transducer rheometer such as an Anton Paar MCR 302).

    Attributes
    ----------
    torque_noise_floor_nm : absolute torque noise SD (N m), 0.05 uN m
    torque_noise_rel : relative torque noise SD (1 %)
    torque_resolution_nm : torque quantisation step (N m)
    normal_force_noise_n : normal force noise SD (N)
    motor_inertia_kg_m2 : motor/measuring-system inertia I (kg m^2); the calibration error is an effect
    temperature_noise_c : temperature channel noise SD (degC)
    gap_noise_m : gap channel noise SD (m)
    n_gauss : Gauss-Legendre radii of the torque integral (>= 8)
    n_cycles, n_analysed, points_per_cycle : oscillation simulation (cycles from rest, cycles analysed)
    """

    torque_noise_floor_nm: float = 0.05e-6
    torque_noise_rel: float = 0.01
    torque_resolution_nm: float = 1e-10
    normal_force_noise_n: float = 2e-4
    motor_inertia_kg_m2: float = 1e-5
    temperature_noise_c: float = 0.01
    gap_noise_m: float = 1e-7
    n_gauss: int = 8
    n_cycles: int = 6
    n_analysed: int = 2
    points_per_cycle: int = 64

    def torque_sd(self, torque_nm: np.ndarray) -> np.ndarray:
        """Torque noise SD (N m) at a torque level."""
        return np.sqrt(self.torque_noise_floor_nm ** 2 + (self.torque_noise_rel * np.asarray(torque_nm)) ** 2)


@dataclass
class Artefacts:
    """Hooks through which the hidden effects act inside the instrument simulation (all off by default).

    Attributes
    ----------
    slip_length : ``u_s(sigma)`` wall-slip displacement per wall (m) as a function of the local shear
        stress (Pa); the sample's strain at radius r is ``theta r/h - 2 u_s/h``
    inertia_error_kg_m2 : ``I - I_cal`` of the motor-inertia calibration (kg m^2)
    sample_density_kg_m3 : sample inertia (shear wave across the gap) when > 0
    amplitude_factors : ``gamma0 -> (f', f'')`` multiplying G', G'' of the oscillation (Payne-like softening)
    torque_offset : ``time_s -> offset (N m)`` added to every recorded torque
    """

    slip_length: Callable[[np.ndarray], np.ndarray] | None = None
    inertia_error_kg_m2: float = 0.0
    sample_density_kg_m3: float = 0.0
    amplitude_factors: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]] | None = None
    torque_offset: Callable[[np.ndarray], np.ndarray] | None = None


def _has_normal_force(model: ConstitutiveModel) -> bool:
    return model.supports("normal_stress")


def _measure_torque(torque: np.ndarray, instrument: InstrumentSettings, rng: np.random.Generator) -> np.ndarray:
    noisy = torque + rng.normal(0.0, 1.0, np.shape(torque)) * instrument.torque_sd(torque)
    if instrument.torque_resolution_nm > 0:
        noisy = np.round(noisy / instrument.torque_resolution_nm) * instrument.torque_resolution_nm
    return noisy


def _sample_strain_with_slip(model, p, t, rim, geometry, n_gauss, slip_length, n_iter: int = 30):
    """Sample strain at the Gauss radii under wall slip: fixed point ``gamma = theta r/h - 2 u_s(sigma)/h``.

    Converges when ``2 du_s/dsigma G/h < 1`` (slip compliance small against the sample's); 30 iterations of
    one batched model evaluation each.
    """
    r, _ = gauss_radii(n_gauss, geometry.radius_m)
    imposed = (r / geometry.radius_m)[:, None] * rim[None, :]
    gamma = imposed.copy()
    for _ in range(n_iter):
        sigma = stress_histories(model, p, t, gamma)
        new = imposed - np.sign(imposed) * 2.0 * slip_length(np.abs(sigma)) / geometry.gap_m
        if np.max(np.abs(new - gamma)) < 1e-12:
            gamma = new
            break
        gamma = 0.5 * gamma + 0.5 * new          # damped: robust near the slip threshold
    return gamma, sigma


def _torque_time_domain(model, p, t, rim, geometry, instrument, artefacts):
    """(torque (N m), sigma at the radii or None) of a strain-controlled history."""
    if artefacts.slip_length is None:
        return torque_from_history(model, p, t, rim, geometry.radius_m, instrument.n_gauss), None
    r, w = gauss_radii(instrument.n_gauss, geometry.radius_m)
    gamma, sigma = _sample_strain_with_slip(model, p, t, rim, geometry, instrument.n_gauss, artefacts.slip_length)
    return 2.0 * np.pi * np.sum((w * r * r)[:, None] * sigma, axis=0), gamma


def _common_channels(n: int, geometry: Geometry, temperature_c: float, instrument: InstrumentSettings,
                     rng: np.random.Generator) -> dict[str, np.ndarray]:
    temperature = temperature_c + instrument.temperature_noise_c * rng.normal(size=n)
    gap = geometry.gap_m + instrument.gap_noise_m * rng.normal(size=n)
    # channel resolution as exported (0.01 degC, 0.1 um)
    return {"temperature": np.round(temperature, 2), "gap": np.round(gap, 7)}


def _rim_channels(t: np.ndarray, rim: np.ndarray, idx: np.ndarray, torque_meas: np.ndarray,
                  geometry: Geometry) -> dict[str, np.ndarray]:
    """The channels a time-domain test reports at ``idx`` from its rim strain history ``rim(t)`` and the measured
    torque: time, rim strain, apparent rim stress, rim rate, torque and the motor's deflection angle."""
    strain = rim[idx]
    return {"time": t[idx], "shear_strain": strain, "shear_stress": apparent_rim_stress(torque_meas, geometry.radius_m),
            "shear_rate": np.gradient(rim, t)[idx], "torque": torque_meas,
            "deflection_angle": strain * geometry.gap_m / geometry.radius_m}


def simulate_strain_controlled(protocol: Protocol, model: ConstitutiveModel, p: Mapping[str, float],
                               geometry: Geometry, instrument: InstrumentSettings, artefacts: Artefacts,
                               temperature_c: float, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Constant-rate ramps and relaxation: imposed rim strain -> recorded channels (SI)."""
    t, rim = protocol.time_s, protocol.setpoint
    torque, gamma_radii = _torque_time_domain(model, p, t, rim, geometry, instrument, artefacts)
    idx = protocol.report_index
    t_rep = t[idx]
    torque_true = torque[idx]
    if artefacts.torque_offset is not None:
        torque_true = torque_true + artefacts.torque_offset(t_rep)
    out = _rim_channels(t, rim, idx, _measure_torque(torque_true, instrument, rng), geometry)
    if _has_normal_force(model):
        rim_sample = rim if gamma_radii is None else gamma_radii[-1] * geometry.radius_m / gauss_radii(
            instrument.n_gauss, geometry.radius_m)[0][-1]
        force = thrust_normal_force(model, p, rim_sample, geometry.radius_m, time_s=t, n_gauss=instrument.n_gauss)
        out["normal_force"] = force[idx] + instrument.normal_force_noise_n * rng.normal(size=idx.size)
    if protocol.kind == "stress_relaxation":
        strain0 = protocol.condition["strain_pct"] / 100.0
        out["relaxation_modulus"] = out["shear_stress"] / strain0
    out.update(_common_channels(idx.size, geometry, temperature_c, instrument, rng))
    return out


def simulate_stress_controlled(protocol: Protocol, model: ConstitutiveModel, p: Mapping[str, float],
                               geometry: Geometry, instrument: InstrumentSettings, artefacts: Artefacts,
                               temperature_c: float, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Creep-recovery: the torque follows the set apparent rim stress; the rim strain is solved from the
    torque balance over the radii (drive models) or from the model's homogeneous ``creep_strain`` (linear
    models, for which the two coincide). Wall slip adds ``2 u_s(sigma_R)/h`` to the motor's rim strain."""
    t, target = protocol.time_s, protocol.setpoint
    if artefacts.torque_offset is not None:
        # the controller holds the *measured* torque (true + offset) at the set point, so the sample
        # carries set point - offset: a creep offset and a non-zero recovery plateau
        target = target - apparent_rim_stress(artefacts.torque_offset(t), geometry.radius_m)
    if hasattr(model, "branch_drives"):
        rim = creep_rim_strain(model, p, t, target, geometry.radius_m, instrument.n_gauss)
    elif model.supports("creep"):
        rim = np.asarray(model.creep_strain(p, t, target), float)
    else:
        raise ValueError(f"model {model.name!r} cannot run a stress-controlled test")
    if artefacts.slip_length is not None:
        # slip displacement accumulates irreversibly only in the sense of the rim stress history here:
        # u_s follows the instantaneous stress (rate-independent slip law)
        rim = rim + 2.0 * artefacts.slip_length(np.abs(target)) / geometry.gap_m * np.sign(target)
    # the channel tail of simulate_strain_controlled (the shared part is _rim_channels and _common_channels; what
    # still looks alike is each test's own quantity: relaxation modulus there, creep compliance here)
    idx = protocol.report_index
    torque_set = protocol.setpoint[idx] * np.pi * geometry.radius_m ** 3 / 2.0
    out = _rim_channels(t, rim, idx, _measure_torque(torque_set, instrument, rng), geometry)
    stress0 = protocol.condition["stress_pa"]
    out["creep_compliance"] = out["shear_strain"] / stress0
    out.update(_common_channels(idx.size, geometry, temperature_c, instrument, rng))
    return out


def simulate_oscillation(protocol: Protocol, model: ConstitutiveModel, p: Mapping[str, float],
                         geometry: Geometry, instrument: InstrumentSettings, artefacts: Artefacts,
                         temperature_c: float, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Amplitude and frequency sweeps: per point, a sinusoidal rim strain from rest through the torque
    quadrature; motor inertia torque added (raw) and the calibrated part subtracted; first-harmonic
    analysis of the last cycles; torque noise on the complex torque amplitude."""
    n_pts = protocol.frequency_hz.size
    r, w = gauss_radii(instrument.n_gauss, geometry.radius_m)
    inertia = instrument.motor_inertia_kg_m2
    storage = np.empty(n_pts)
    loss = np.empty(n_pts)
    raw_phase = np.empty(n_pts)
    torque_amp = np.empty(n_pts)
    # points sharing a frequency are simulated in one batched call
    for f in np.unique(protocol.frequency_hz):
        sel = np.flatnonzero(protocol.frequency_hz == f)
        amps = protocol.strain_amplitude[sel]
        period = 1.0 / f
        n_cyc = instrument.n_cycles
        t = np.linspace(0.0, n_cyc * period, n_cyc * instrument.points_per_cycle + 1)
        omega = 2.0 * np.pi * f
        rim = amps[:, None] * np.sin(omega * t)[None, :]
        strain = ((r / geometry.radius_m)[None, :, None] * rim[:, None, :]).reshape(-1, t.size)
        sigma = stress_histories(model, p, t, strain).reshape(amps.size, r.size, t.size)
        torque_sample = 2.0 * np.pi * np.einsum("j,ajn->an", w * r * r, sigma)
        theta_ddot = -omega ** 2 * rim * geometry.gap_m / geometry.radius_m
        torque_raw = torque_sample + inertia * theta_ddot
        # the instrument subtracts its calibrated inertia I_cal = I - dI
        torque_corr = torque_raw - (inertia - artefacts.inertia_error_kg_m2) * theta_ddot
        keep = t >= (n_cyc - instrument.n_analysed) * period - 1e-12 * period
        keep[-1] = False
        for k, i in enumerate(sel):
            s_app = apparent_rim_stress(torque_corr[k, keep], geometry.radius_m)
            g1, g2 = first_harmonic_moduli(t[keep], rim[k, keep], s_app, f)
            g_star = complex(g1, g2)
            if artefacts.sample_density_kg_m3 > 0:
                g_star = complex(apparent_complex_modulus(np.array([g_star]), np.array([f]), geometry.radius_m,
                                                          geometry.gap_m, artefacts.sample_density_kg_m3)[0])
            if artefacts.amplitude_factors is not None:
                fp, fpp = artefacts.amplitude_factors(np.array([amps[k]]))
                g_star = complex(g_star.real * float(fp[0]), g_star.imag * float(fpp[0]))
            # complex torque amplitude (a constant or slowly drifting torque offset has no first harmonic)
            m_star = g_star * amps[k] * np.pi * geometry.radius_m ** 3 / 2.0
            sd = instrument.torque_sd(abs(m_star)) / np.sqrt(2.0)
            m_star = m_star + sd * complex(rng.normal(), rng.normal())
            g_meas = m_star / (amps[k] * np.pi * geometry.radius_m ** 3 / 2.0)
            storage[i], loss[i] = g_meas.real, g_meas.imag
            torque_amp[i] = abs(m_star)
            rw1, rw2 = first_harmonic_moduli(t[keep], rim[k, keep], torque_raw[k, keep], f)
            raw_phase[i] = np.arctan2(rw2, rw1)
    if instrument.torque_resolution_nm > 0:
        torque_amp = np.round(torque_amp / instrument.torque_resolution_nm) * instrument.torque_resolution_nm
    amps = protocol.strain_amplitude
    g_abs = np.hypot(storage, loss)
    time = np.cumsum(protocol.point_duration_s)
    out = {"time": time, "frequency": protocol.frequency_hz.copy(),
           "angular_frequency": 2.0 * np.pi * protocol.frequency_hz,
           "shear_strain": amps.copy(), "shear_stress": g_abs * amps, "storage_modulus": storage,
           "loss_modulus": loss, "phase_angle": np.arctan2(loss, storage), "raw_phase": raw_phase,
           "torque": torque_amp, "deflection_angle": amps * geometry.gap_m / geometry.radius_m}
    out.update(_common_channels(n_pts, geometry, temperature_c, instrument, rng))
    return out


def simulate_flow_curve(protocol: Protocol, model: ConstitutiveModel, p: Mapping[str, float],
                        geometry: Geometry, instrument: InstrumentSettings, artefacts: Artefacts,
                        temperature_c: float, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Steady flow curve: torque = 2 pi int tau(rate r/R) r^2 dr of the model's steady shear stress,
    reported as 2M/(pi R^3) (the shear-thinning rim error 4/(n+3) is in the data)."""
    rates = protocol.shear_rate_1_s
    r, w = gauss_radii(max(instrument.n_gauss, 16), geometry.radius_m)
    local = (r / geometry.radius_m)[:, None] * rates[None, :]
    tau = np.asarray(model.steady_shear_stress(p, local.ravel()), float).reshape(local.shape)
    torque = 2.0 * np.pi * np.sum((w * r * r)[:, None] * tau, axis=0)
    time = np.cumsum(protocol.point_duration_s)
    if artefacts.torque_offset is not None:
        torque = torque + artefacts.torque_offset(time)
    torque_meas = _measure_torque(torque, instrument, rng)
    stress = apparent_rim_stress(torque_meas, geometry.radius_m)
    out = {"time": time, "shear_rate": rates.copy(), "shear_stress": stress, "viscosity": stress / rates,
           "torque": torque_meas}
    out.update(_common_channels(rates.size, geometry, temperature_c, instrument, rng))
    return out


SIMULATORS = {
    "strain": simulate_strain_controlled,
    "stress": simulate_stress_controlled,
    "oscillation": simulate_oscillation,
    "steady_rate": simulate_flow_curve,
}


def run_protocol(protocol: Protocol, model: ConstitutiveModel, p: Mapping[str, float], geometry: Geometry,
                 instrument: InstrumentSettings | None = None, artefacts: Artefacts | None = None,
                 temperature_c: float = 20.0, rng: np.random.Generator | None = None) -> dict[str, np.ndarray]:
    """Run one protocol on the virtual rheometer.

    Returns
    -------
    dict canonical variable -> (n_points,) array in SI units (``canonical.CANONICAL_VARIABLES``), as the
    instrument records them (noise, resolution and artefacts included).
    """
    instrument = instrument or InstrumentSettings()
    artefacts = artefacts or Artefacts()
    rng = rng or np.random.default_rng(0)
    if instrument.n_gauss < 8:
        raise ValueError("the torque integral needs at least 8 Gauss radii")
    return SIMULATORS[protocol.control](protocol, model, p, geometry, instrument, artefacts, temperature_c, rng)
