"""Residual-table builder and cross-test consistency (closed forms and the thesis numbers, science.md 0)."""
from __future__ import annotations

import numpy as np
import pytest

from tissuemech.canonical import make_run_dataset
from tissuemech.diagnosis import evidence as ev
from tissuemech.diagnosis import noise as nz
from tissuemech.models.recursion import prony_branch_histories
from tissuemech.spectra import prony_complex_modulus

THESIS_TAUS = np.array([0.1, 1.09, 9.91, 100.0])
THESIS_G = np.array([0.00033, 0.23447, 0.21368, 0.14447])


def test_thesis_prony_interconversion_reproduces_science_table():
    g0 = 200.0
    gi = g0 * THESIS_G
    g_inf = g0 * (1 - THESIS_G.sum())
    assert g_inf == pytest.approx(81.4, abs=0.05)
    gs = prony_complex_modulus(g_inf, gi, THESIS_TAUS, 2 * np.pi * np.array([0.1, 1.0, 20.0]))
    assert gs.real == pytest.approx([166.9, 199.0, 200.0], abs=0.1)
    assert gs.imag == pytest.approx([29.0, 7.5, 0.4], abs=0.1)


def test_booij_thoone_exact_for_power_law():
    w = np.logspace(-1, 2, 40)
    n = 0.09
    g1 = 150.0 * w ** n
    assert ev.booij_thoone(w, g1)[1:-1] == pytest.approx(0.5 * np.pi * n * g1[1:-1], rel=1e-3)


def test_ramp_aware_prony_recovers_fast_mode_that_step_analysis_loses():
    taus = np.array([0.1, 1.0, 10.0])
    g_true = np.array([30.0, 20.0, 10.0])
    g_inf = 40.0
    t_r, gamma0 = 0.5, 0.01
    t = np.r_[np.linspace(0, t_r, 11), np.logspace(np.log10(0.6), np.log10(200), 60)]
    strain = np.minimum(t / t_r, 1.0) * gamma0
    h = prony_branch_histories(t, g_true[:, None] * strain[None, :], taus)
    stress = g_inf * strain + h.sum(axis=0)
    ramp = ev.fit_prony_relaxation(t, stress, strain, taus, ramp_aware=True)
    assert ramp["g_inf_pa"] == pytest.approx(g_inf, rel=1e-6)
    assert ramp["g_pa"] == pytest.approx(g_true, rel=1e-6)
    step = ev.fit_prony_relaxation(t, stress, strain, taus, ramp_aware=False)
    # the step analysis rescales each mode by (tau/t_r)(e^{t_r/tau} - 1) (science.md 1.0 ramp closed form)
    factor = taus / t_r * (np.exp(t_r / taus) - 1)
    assert step["g_pa"] == pytest.approx(g_true * factor, rel=1e-3)


def _run(test, order, sample="s1", **cols):
    attrs = {"dataset": "t", "run": f"{sample}-{order}", "test": test, "specimen": "b1", "sample": sample,
             "order": order, "source_file": "x", "source_sha256": "0", "radius_m": 10e-3, "gap_m": 2e-3,
             "covariate_region": 2.0}
    if test == "constant_shear_rate":
        attrs["shear_rate_1_per_s"] = 0.1
    return make_run_dataset(cols, attrs)


def test_residual_table_columns_and_noise_model():
    strain = np.linspace(0.01, 0.5, 10)
    r1 = _run("constant_shear_rate", 2, time=strain / 0.1, shear_strain=strain, shear_stress=100 * strain,
              temperature=np.full(10, 37.0), total_time=np.full(10, 600.0))
    r2 = _run("constant_shear_rate", 1, sample="s1", time=strain / 0.1, shear_strain=strain,
              shear_stress=110 * strain, total_time=np.full(10, 0.0))
    pred = [{"shear_stress": 100 * strain}, {"shear_stress": 100 * strain}]
    tab = ev.residual_table([r1, r2], pred, "m")
    assert len(tab) == 20
    assert tab.loc[tab["curve"] == "s1-1", "first_load"].eq(1).all()
    assert tab.loc[tab["curve"] == "s1-2", "first_load"].eq(0).all()
    assert tab["log_rate"].eq(-1.0).all()
    assert tab["covariate_region"].eq(2.0).all()
    assert "channel_temperature" in tab
    first = tab[tab["curve"] == "s1-1"]
    assert first["log_ratio"].to_numpy() == pytest.approx(np.log(1.1))
    # noise-free curves: the data-derived noise model finds round-off scatter only, never a generator constant
    # (the old 1 % + 0.05 uN m model gave sigma >= 1 % of the stress here)
    assert (first["sigma"] < 1e-12 * first["observed"].abs()).all()
    assert tab["radius_m"].eq(10e-3).all()
    assert tab["condition"].iloc[0] == "constant_shear_rate@0.1/s"
    with pytest.raises(ValueError, match="shape"):
        ev.residual_table([r1], [{"shear_stress": np.ones(3)}])


def _noisy_relaxations(rel, floor_pa, n_curves=6, seed=0):
    rng = np.random.default_rng(seed)
    runs = []
    for k in range(n_curves):
        t = np.linspace(0.5, 300.0, 200)
        true = (40.0 + 60.0 * np.exp(-t / 5.0) + 30.0 * np.exp(-t / 80.0)) * (k + 1) / 3.0
        obs = true + rng.normal(0.0, 1.0, t.size) * np.sqrt((rel * true) ** 2 + floor_pa ** 2)
        runs.append(_run("stress_relaxation", k + 1, sample=f"s{k}", time=t, shear_stress=obs,
                         shear_strain=np.full(t.size, 0.01)))
    return runs


def test_noise_model_is_read_from_the_within_curve_scatter():
    """Known truth: 2 % relative noise on smooth relaxations -> the estimate finds 2 %, not the 1 % constant."""
    noise = nz.estimate_noise(_noisy_relaxations(0.02, 0.0))
    block = noise["blocks"]["stress_relaxation|shear_stress"]
    assert block["relative"] == pytest.approx(0.02, rel=0.15)
    assert block["n_curves"] == 6 and "differences of order 2-4" in block["source"]
    noise3 = nz.estimate_noise(_noisy_relaxations(0.003, 0.0))
    assert noise3["blocks"]["stress_relaxation|shear_stress"]["relative"] == pytest.approx(0.003, rel=0.2)


def test_absolute_floor_is_separated_from_the_relative_noise():
    noise = nz.estimate_noise(_noisy_relaxations(0.005, 2.0))
    block = noise["blocks"]["stress_relaxation|shear_stress"]
    assert block["absolute"] == pytest.approx(2.0, rel=0.35)
    assert block["relative"] < 0.012


def test_robust_noise_sd_of_white_noise_on_a_trend():
    rng = np.random.default_rng(1)
    x = np.linspace(0, 10, 4000)
    assert nz.robust_noise_sd(3.0 * x ** 2 / 100 + rng.normal(0, 0.5, x.size)) == pytest.approx(0.5, rel=0.06)


def test_declared_torque_resolution_sets_the_floor_only_with_a_radius():
    noise = {"blocks": {"stress_relaxation|shear_stress": {"relative": 0.0, "absolute": 0.0}}}
    sd = nz.noise_sd(noise, "stress_relaxation", "shear_stress", np.array([10.0]), radius_m=0.01,
                     torque_resolution_nm=1e-7)
    assert sd == pytest.approx(2 * 1e-7 / (np.pi * 0.01 ** 3))
    sd = nz.noise_sd(noise, "stress_relaxation", "shear_stress", np.array([10.0]), torque_resolution_nm=1e-7)
    assert np.isnan(sd).all()


def test_missing_radius_is_nan_and_rows_filter_on_observed_magnitude():
    runs = _noisy_relaxations(0.01, 0.0, n_curves=3)
    r = runs[0].copy()
    r.attrs = {k: v for k, v in r.attrs.items() if k != "radius_m"}
    obs = r["shear_stress"].values
    # a collapsed model predicting ~0 everywhere: the filter reads the observed stress, so every row stays
    tab = ev.residual_table([r] + runs[1:], [{"shear_stress": np.full(obs.size, 1e-9)}]
                            + [{"shear_stress": x["shear_stress"].values} for x in runs[1:]], "m")
    first = tab[tab["curve"] == r.attrs["run"]]
    assert first["radius_m"].isna().all()
    assert first["above_noise"].all()
