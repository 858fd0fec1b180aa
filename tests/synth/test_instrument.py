"""Virtual rheometer physics against closed forms (plate integral closed forms are tested in tests/models)."""
import numpy as np
import pytest

from tissuemech.models.qlv import LinearElasticShear, QLVModel, qlv_params
from tissuemech.synth.instrument import Geometry, InstrumentSettings, run_protocol
from tissuemech.synth.protocols import (amplitude_sweep, constant_shear_rate, creep_recovery, frequency_sweep,
                                        stress_relaxation)

QUIET = InstrumentSettings(torque_noise_floor_nm=0.0, torque_noise_rel=0.0, torque_resolution_nm=0.0,
                           normal_force_noise_n=0.0, temperature_noise_c=0.0, gap_noise_m=0.0)
GEOM = Geometry(radius_m=0.0125, gap_m=0.003)


def prony_model(taus=(0.1, 1.0, 10.0), g=(0.2, 0.25, 0.15), g0=200.0):
    model = QLVModel(LinearElasticShear(), len(taus), taus_s=list(taus))
    return model, qlv_params(model, {"G0": g0}, list(g))


@pytest.mark.parametrize("protocol", [constant_shear_rate(0.01, n_points=25), stress_relaxation(0.05, rise_time_s=0.2)])
def test_linear_material_reported_stress_is_true_rim_stress(protocol):
    model, p = prony_model()
    out = run_protocol(protocol, model, p, GEOM, QUIET)
    true_rim = model.shear_stress_history(p, protocol.time_s, protocol.setpoint)[protocol.report_index]
    np.testing.assert_allclose(out["shear_stress"], true_rim, rtol=1e-10)
    np.testing.assert_allclose(out["shear_strain"], protocol.setpoint[protocol.report_index], rtol=1e-14)
    # the torque channel is the torque of that stress: M = pi R^3 sigma / 2
    np.testing.assert_allclose(out["torque"], np.pi * GEOM.radius_m ** 3 * true_rim / 2, rtol=1e-10)


def test_prony_oscillation_matches_analytic_transform():
    model, p = prony_model()
    proto = frequency_sweep(0.1, 20.0, n_points=6, strain=0.01)
    inst = InstrumentSettings(**{**QUIET.__dict__, "n_cycles": 8, "points_per_cycle": 128})
    out = run_protocol(proto, model, p, GEOM, inst)
    g_star = model.complex_modulus(p, 2 * np.pi * proto.frequency_hz)
    np.testing.assert_allclose(out["storage_modulus"], g_star.real, rtol=2e-3)
    np.testing.assert_allclose(out["loss_modulus"], g_star.imag, rtol=1e-2, atol=0.05)
    # no inertia error: the calibrated motor inertia is removed exactly; raw phase carries it
    assert out["raw_phase"][0] > np.radians(170)      # 20 Hz: raw torque inertia-dominated
    assert out["raw_phase"][-1] == pytest.approx(np.arctan2(g_star.imag[-1], g_star.real[-1] - 1e-5 * (2 * np.pi * 0.1) ** 2
                                                            / (np.pi * GEOM.radius_m ** 4 / (2 * GEOM.gap_m))), abs=2e-3)


def test_linear_amplitude_sweep_is_flat():
    model, p = prony_model()
    out = run_protocol(amplitude_sweep(1.0, 1e-3, 0.3, 5), model, p, GEOM, QUIET)
    g_star = model.complex_modulus(p, np.array([2 * np.pi]))[0]
    np.testing.assert_allclose(out["storage_modulus"], g_star.real, rtol=2e-3)


def test_standard_linear_solid_creep_closed_form():
    g_inf, g1, tau = 60.0, 140.0, 2.0                 # G(t) = G_inf + G1 exp(-t/tau)
    model, p = prony_model(taus=(tau,), g=(g1 / (g_inf + g1),), g0=g_inf + g1)
    stress, t_c = 10.0, 40.0
    proto = creep_recovery(stress, creep_s=t_c, recovery_s=40.0, rise_time_s=1e-4, n_points=40, first_point_s=0.05,
                           n_sim=2000)
    out = run_protocol(proto, model, p, GEOM, QUIET)
    g0 = g_inf + g1
    tau_c = tau * g0 / g_inf

    def compliance(t):
        t = np.asarray(t, float)
        return np.where(t > 0, 1 / g0 + (1 / g_inf - 1 / g0) * (1 - np.exp(-np.clip(t, 0, None) / tau_c)), 0.0)
    t = out["time"]
    expected = stress * (compliance(t) - compliance(t - t_c))
    np.testing.assert_allclose(out["shear_strain"], expected, rtol=2e-3, atol=1e-6)
    np.testing.assert_allclose(out["creep_compliance"][t < t_c], compliance(t[t < t_c]), rtol=2e-3)


def test_noise_model_floor_and_relative():
    inst = InstrumentSettings(torque_resolution_nm=0.0)
    model, p = prony_model()
    proto = stress_relaxation(0.4, rise_time_s=0.01, n_points=400)
    rng = np.random.default_rng(1)
    out = run_protocol(proto, model, p, GEOM, inst, rng=rng)
    true = np.pi * GEOM.radius_m ** 3 / 2 * model.shear_stress_history(p, proto.time_s, proto.setpoint)[proto.report_index]
    z = (out["torque"] - true) / inst.torque_sd(true)
    assert abs(z.std() - 1) < 0.1 and abs(z.mean()) < 0.15


def test_needs_eight_gauss_radii():
    model, p = prony_model()
    with pytest.raises(ValueError, match="8 Gauss radii"):
        run_protocol(constant_shear_rate(0.1), model, p, GEOM, InstrumentSettings(n_gauss=4))
