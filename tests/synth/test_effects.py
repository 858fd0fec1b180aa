"""Each hidden-effect injector leaves its signature in the generated data (not its detection), and the null
configuration injects nothing."""
import numpy as np
import pytest

from tissuemech.models.qlv import LinearElasticShear, QLVModel, qlv_params
from tissuemech.synth import effects as fx
from tissuemech.synth.generator import generate_dataset
from tissuemech.synth.instrument import Artefacts, Geometry, InstrumentSettings, run_protocol
from tissuemech.synth.protocols import (amplitude_sweep, constant_shear_rate, creep_recovery, frequency_sweep,
                                        stress_relaxation)

QUIET = InstrumentSettings(torque_noise_floor_nm=0.0, torque_noise_rel=0.0, torque_resolution_nm=0.0,
                           normal_force_noise_n=0.0, temperature_noise_c=0.0, gap_noise_m=0.0)
GEOM = Geometry(radius_m=0.0125, gap_m=0.003)
TAUS = [0.1, 1.0, 10.0, 100.0]
G = [0.05, 0.25, 0.2, 0.12]


def qlv():
    model = QLVModel(LinearElasticShear(), 4, taus_s=TAUS)
    return model, qlv_params(model, {"G0": 200.0}, G)


def simulate(protocol, effects, model=None, params=None):
    model, params = (model, params) if model is not None else qlv()
    eff = fx.resolve(effects)
    m, p, _ = fx.modify_truth(model, params, eff)
    return run_protocol(protocol, m, p, GEOM, QUIET, fx.build_artefacts(eff, QUIET.motor_inertia_kg_m2))


def test_null_configuration_injects_nothing():
    assert fx.resolve({}) == {} and fx.resolve(None) == {}
    model, p = qlv()
    m, p2, rec = fx.modify_truth(model, p, {})
    assert m is model and p2 == p and rec == {}
    a = fx.build_artefacts({}, 1e-5)
    assert a == Artefacts()
    assert fx.modulus_factor({}, elapsed_h=5.0, first_load=True, specimen_index=0) == 1.0
    assert fx.protocol_overrides("stress_relaxation", {}) == {}


def test_unknown_effect_or_parameter_is_refused():
    with pytest.raises(ValueError, match="unknown effect 'slip'"):
        fx.resolve({"slip": {}})
    with pytest.raises(ValueError, match="has no parameter"):
        fx.resolve({"wall_slip": {"sigma_pa": 3}})


def _normalised_relaxation(effects):
    curves = []
    for strain in (0.01, 0.4):
        out = simulate(stress_relaxation(strain, rise_time_s=0.01, n_points=30), effects)
        curves.append(out["shear_stress"] / out["shear_stress"][0])
    return curves


def test_nonseparable_relaxation_signature():
    small, large = _normalised_relaxation({})
    np.testing.assert_allclose(small, large, rtol=1e-6)             # QLV: one shape at every strain
    small, large = _normalised_relaxation({"nonseparable_relaxation": {"kappa": 0.6}})
    assert large[-1] < small[-1] - 0.03                               # relaxes further at 40 %


def test_rim_stress_nonlinearity_signature():
    proto = constant_shear_rate(0.1, n_points=20)
    for stiff, expect_n_above_one in ((0.0, False), (2.0, True)):
        out = simulate(proto, {"rim_stress_nonlinearity": {"stiffening": stiff}} if stiff else {})
        n = np.gradient(np.log(out["torque"]), np.log(out["shear_strain"]))
        model, p = qlv()
        if expect_n_above_one:
            assert n[-1] > 1.1
            eff = fx.resolve({"rim_stress_nonlinearity": {"stiffening": stiff}})
            m, p2, _ = fx.modify_truth(model, p, eff)
            true_rim = m.shear_stress_history(p2, proto.time_s, proto.setpoint)[proto.report_index]
            assert out["shear_stress"][-1] < 0.97 * true_rim[-1]     # 2M/(pi R^3) under-reports a stiffening law
        else:
            assert n[-1] < 1.0                                        # linear viscoelastic: relaxation only


def test_wall_slip_signature():
    proto = constant_shear_rate(0.01, n_points=20)
    base = simulate(proto, {})
    slip = simulate(proto, {"wall_slip": {"sigma_c_pa": 20.0, "beta_s_m_per_pa": 3e-6}})
    below = base["shear_stress"] < 19.0
    np.testing.assert_allclose(slip["shear_stress"][below], base["shear_stress"][below], rtol=1e-9)
    assert slip["shear_stress"][-1] < 0.95 * base["shear_stress"][-1]    # plateau above sigma_c
    cr = simulate(creep_recovery(40.0, 60.0, 60.0, n_points=20), {"wall_slip": {"sigma_c_pa": 20.0}})
    cr0 = simulate(creep_recovery(40.0, 60.0, 60.0, n_points=20), {})
    assert cr["shear_strain"][5] > cr0["shear_strain"][5]


def test_instrument_inertia_signature():
    proto = frequency_sweep(0.5, 20.0, n_points=4)
    base = simulate(proto, {})
    dI = 0.01
    out = simulate(proto, {"instrument_inertia": {"calibration_error": dI}})
    b = np.pi * GEOM.radius_m ** 4 / (2 * GEOM.gap_m)
    expected = dI * QUIET.motor_inertia_kg_m2 * (2 * np.pi * proto.frequency_hz) ** 2 / b
    np.testing.assert_allclose(base["storage_modulus"] - out["storage_modulus"], expected, rtol=1e-3)
    np.testing.assert_allclose(out["loss_modulus"], base["loss_modulus"], rtol=1e-6)


def test_amplitude_softening_signature():
    proto = amplitude_sweep(1.0, 1e-3, 0.5, 6)
    base = simulate(proto, {})
    out = simulate(proto, {"amplitude_softening": {"gamma_c": 0.03, "m": 1.0, "ratio_storage": 0.7}})
    ratio = out["storage_modulus"] / base["storage_modulus"]
    assert ratio[0] == pytest.approx(1.0, abs=2e-3)
    assert ratio[-1] == pytest.approx(0.7 + 0.3 / (1 + (0.5 / 0.03) ** 2), rel=1e-6)
    assert np.all(np.diff(ratio) < 0)


def test_torque_offset_signature():
    proto = stress_relaxation(0.01, n_points=20)
    base = simulate(proto, {})
    out = simulate(proto, {"torque_offset": {"offset_unm": 0.2, "drift_unm_per_s": 1e-3}})
    np.testing.assert_allclose(out["torque"] - base["torque"], 0.2e-6 + 1e-9 * base["time"], rtol=1e-8)


def test_finite_rise_time_signature():
    slow = fx.protocol_overrides("stress_relaxation", fx.resolve({"finite_rise_time": {"rise_time_s": 1.0}}))
    assert slow == {"rise_time_s": 1.0}
    fast_out = simulate(stress_relaxation(0.05, rise_time_s=0.01, n_points=30), {})
    slow_out = simulate(stress_relaxation(0.05, **slow, n_points=30), {})
    early = fast_out["time"] < 0.5
    assert np.all(slow_out["shear_strain"][early] < 0.05)                 # the ramp is in the strain column
    assert slow_out["shear_stress"].max() < 0.9 * fast_out["shear_stress"].max()   # fast modes relax during the ramp
    late = fast_out["time"] > 50
    np.testing.assert_allclose(slow_out["shear_stress"][late], fast_out["shear_stress"][late], rtol=0.02)


def test_unidentified_i2_dependence_signature():
    proto = constant_shear_rate(0.1, n_points=10)
    rp = {"rim_stress_nonlinearity": {"stiffening": 0.5}}
    base = simulate(proto, rp)
    out = simulate(proto, {**rp, "unidentified_i2_dependence": {"c01_ratio": 0.5}})
    np.testing.assert_allclose(out["shear_stress"], base["shear_stress"], rtol=1e-12)   # invisible in torque
    assert np.all(out["normal_force"][1:] > 1.05 * base["normal_force"][1:])          # visible in thrust


def _dataset_config(effects, design):
    return {"name": "t", "temperature_c": 37.0, "geometry": {"radius_mm": 12.5, "gap_mm": 3.0},
            "truth": {"model": {"kind": "qlv", "instantaneous": "linear", "taus_s": TAUS},
                      "params": qlv_params(QLVModel(LinearElasticShear(), 4, taus_s=TAUS), {"G0": 200.0}, G)},
            "instrument": dict(QUIET.__dict__), "effects": effects, **design}


SEQUENCE = {"sequence": {"specimens": 2, "samples_per_specimen": 2,
                         "tests": [{"test": "stress_relaxation", "settings": {"strain": 0.01, "n_points": 10}}] * 3}}


def _level(result):
    return {(m["meta"]["specimen"], m["meta"]["sample"], m["meta"]["order"]): m["channels"]["shear_stress"][-1]
            for m in result["runs"].values()}


def test_elapsed_time_drift_signature(tmp_path):
    null = _level(generate_dataset(_dataset_config({}, SEQUENCE), 1, tmp_path / "a"))
    res = generate_dataset(_dataset_config({"elapsed_time_drift": {"kappa_per_h": 0.2}}, SEQUENCE), 1, tmp_path / "b")
    drift = _level(res)
    for run in res["truth"]["runs"]:
        key = (run["specimen"], run["sample"], run["order"])
        assert drift[key] / null[key] == pytest.approx(1 + 0.2 * run["elapsed_h"], rel=1e-9)
    assert max(r["elapsed_h"] for r in res["truth"]["runs"]) > 0.2


def test_preconditioning_signature(tmp_path):
    null = _level(generate_dataset(_dataset_config({}, SEQUENCE), 1, tmp_path / "a"))
    pre = _level(generate_dataset(_dataset_config({"preconditioning": {"first_load_factor": 0.2}}, SEQUENCE), 1,
                                  tmp_path / "b"))
    for key in null:
        assert pre[key] / null[key] == pytest.approx(1.2 if key[2] == 1 else 1.0, rel=1e-9)


def test_outlier_specimen_signature(tmp_path):
    null = _level(generate_dataset(_dataset_config({}, SEQUENCE), 1, tmp_path / "a"))
    out = _level(generate_dataset(_dataset_config({"outlier_specimen": {"factor": 2.5, "specimen": 1}}, SEQUENCE), 1,
                                  tmp_path / "b"))
    for key in null:
        assert out[key] / null[key] == pytest.approx(2.5 if key[0] == "specimen02" else 1.0, rel=1e-9)


def test_every_catalogue_id_has_an_injector():
    assert set(fx.EFFECT_IDS) == set(fx.DEFAULTS)
    assert len(fx.EFFECT_IDS) == 11


def test_torque_offset_in_creep_leaves_a_recovery_plateau():
    proto = creep_recovery(5.0, 60.0, 120.0, n_points=30)
    base = simulate(proto, {})
    out = simulate(proto, {"torque_offset": {"offset_unm": 0.3, "drift_unm_per_s": 0.0}})
    np.testing.assert_allclose(out["shear_stress"], base["shear_stress"], rtol=1e-12)   # reports the set point
    offset_pa = 2 * 0.3e-6 / (np.pi * GEOM.radius_m ** 3)
    shift = out["shear_strain"] - base["shear_strain"]
    assert np.all(shift < 0)                                                         # sample held at set - offset
    assert shift[-1] < -0.5 * offset_pa / 200.0                                      # recovery plateau below zero


def test_sample_inertia_lowers_moving_plate_modulus():
    proto = frequency_sweep(5.0, 20.0, n_points=2)
    base = simulate(proto, {})
    out = simulate(proto, {"instrument_inertia": {"calibration_error": 0.0, "sample_density_kg_m3": 1040.0}})
    omega = 2 * np.pi * proto.frequency_hz
    # G*_app ~ G* - rho omega^2 h^2/3 (torque sensed at the moving plate, science.md 2.5)
    np.testing.assert_allclose(base["storage_modulus"] - out["storage_modulus"],
                               1040.0 * omega ** 2 * GEOM.gap_m ** 2 / 3, rtol=0.08)   # leading order in (kh)^2
