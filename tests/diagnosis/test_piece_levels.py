"""One modulus level per loaded piece for every test kind of the diagnosis's baseline (creep included).

Oracle: the closed forms of a standard linear solid in shear (linear law, so the plate's apparent stress is the
rim stress): relaxation ``G(t) = G_inf + G_1 exp(-t/tau)``, creep compliance
``J(t) = 1/G_inf - (1/G_inf - 1/G_0) exp(-t G_inf/(G_0 tau))``; a piece ``k`` times stiffer has ``k G`` and ``J/k``.
"""
import numpy as np
import pytest
import xarray as xr

from tissuemech.diagnosis.baseline import level_normalised, loading_unit, nnls_relaxation_times, resolved_window_s

G_INF, G_1, TAU_S = 600.0, 400.0, 2.0
G_0 = G_INF + G_1
RADIUS_M, GAP_M = 0.0125, 0.002
TIME_S = np.geomspace(1e-4, 60.0, 120)


def _run(test, specimen, sample, data, **attrs):
    ds = xr.Dataset({k: ("point", np.asarray(v, float)) for k, v in data.items()})
    ds.attrs.update(test=test, specimen=specimen, sample=sample, radius_m=RADIUS_M, gap_m=GAP_M, **attrs)
    return ds


def _relaxation(specimen, sample, level, strain=0.02):
    stress = level * (G_INF + G_1 * np.exp(-TIME_S / TAU_S)) * strain
    torque = stress * np.pi * RADIUS_M ** 3 / 2.0
    return _run("stress_relaxation", specimen, sample,
                {"time": TIME_S, "shear_strain": np.full(TIME_S.size, strain), "shear_stress": stress,
                 "torque": torque}, strain_pct=100 * strain)


def _creep(specimen, sample, level, stress_pa=5.0):
    compliance = (1.0 / G_INF - (1.0 / G_INF - 1.0 / G_0) * np.exp(-TIME_S * G_INF / (G_0 * TAU_S))) / level
    stress = np.full(TIME_S.size, stress_pa)
    return _run("creep_recovery", specimen, sample,
                {"time": TIME_S, "shear_stress": stress, "shear_strain": stress * compliance,
                 "torque": stress * np.pi * RADIUS_M ** 3 / 2.0, "creep_compliance": compliance},
                stress_pa=stress_pa)


def test_creep_pieces_get_their_level_and_their_time_scale():
    runs = [_relaxation("A", "1", 1.0), _creep("A", "1", 1.0),
            _creep("B", "1", 1.6),                                   # a piece measured in creep only
            _relaxation("C", "1", 0.8), _creep("C", "1", 0.8, stress_pa=3.0)]
    found = nnls_relaxation_times(runs, "apparent_stress", "measured", resolved_window_s(runs))
    levels = found["levels"]
    assert set(levels) == {"A/1", "B/1", "C/1"}
    assert levels["B/1"] / levels["A/1"] == pytest.approx(1.6, rel=0.02)
    assert levels["C/1"] / levels["A/1"] == pytest.approx(0.8, rel=0.02)
    # the one relaxation time of the truth (creep retardation time 3.33 s is not a relaxation time)
    assert np.min(np.abs(np.log10(found["taus_s"]) - np.log10(TAU_S))) < 0.3, found["taus_s"]
    # equilibrium share of the instantaneous modulus
    assert found["equilibrium_share"] == pytest.approx(G_INF / G_0, abs=0.05)


def test_level_normalised_creep_is_the_level_one_piece_under_a_scaled_stress():
    run = _creep("B", "1", 1.6)
    (scaled,) = level_normalised([run], {loading_unit(run): 1.6})
    np.testing.assert_allclose(scaled["shear_stress"], run["shear_stress"] / 1.6)
    np.testing.assert_allclose(scaled["torque"], run["torque"] / 1.6)
    np.testing.assert_allclose(scaled["creep_compliance"], run["creep_compliance"] * 1.6)
    np.testing.assert_allclose(scaled["shear_strain"], run["shear_strain"])   # the measured response is kept
    # the level-1 piece under the scaled stress strains as much as the measured piece under the measured one
    level_one = _creep("A", "1", 1.0, stress_pa=5.0 / 1.6)
    np.testing.assert_allclose(scaled["shear_strain"], level_one["shear_strain"], rtol=1e-12)
