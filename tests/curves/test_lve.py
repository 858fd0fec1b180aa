"""LVE limit by the 5 % rule: closed-form Kraus curves, flow point, the real TRIOS fungi sweep."""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from tissuemech import curves, fitting, lve
from tissuemech.canonical import make_run_dataset, read_netcdf

from ._real import read_trios_fungi_amplitude_sweep, read_trios_fungi_frequency_sweep

G0, G_INF, GAMMA_C, M = 1000.0, 700.0, 0.03, 0.75


def kraus(strain, g0=G0, g_inf=G_INF, gamma_c=GAMMA_C, m=M):
    """Kraus amplitude softening G'(γ) = G∞ + (G0 - G∞) / (1 + (γ/γc)^{2m})."""
    return g_inf + (g0 - g_inf) / (1.0 + (strain / gamma_c) ** (2 * m))


def kraus_strain_at(level, g0=G0, g_inf=G_INF, gamma_c=GAMMA_C, m=M):
    """Closed-form inverse of :func:`kraus`."""
    return gamma_c * ((g0 - g_inf) / (level - g_inf) - 1.0) ** (1.0 / (2 * m))


def _as_run(strain, storage, loss, sample="s1", specimen="B1", stress=None):
    columns = {"shear_strain": strain, "storage_modulus": storage, "loss_modulus": loss}
    if stress is not None:
        columns["shear_stress"] = stress
    return make_run_dataset(columns, {"test": "amplitude_sweep", "specimen": specimen, "sample": sample,
                                      "run": f"as-{specimen}-{sample}", "frequency_hz": 1.0})


def test_kraus_five_percent_point_is_recovered():
    strain = np.geomspace(1e-4, 1.0, 41)  # 10 points per decade
    limit = lve.lve_limit(strain, kraus(strain))
    assert limit.direction == -1
    # the plateau (median of the flat window) sits within 0.3 % of G0
    assert limit.plateau == pytest.approx(G0, rel=3e-3)
    # the crossing of 0.95 x plateau, against the closed form for that plateau (log-log interpolation error only)
    assert limit.strain == pytest.approx(kraus_strain_at(0.95 * limit.plateau), rel=0.01)
    # and against the textbook value for the exact G0: 0.03 * 0.2^(2/3) = 1.026 %
    assert limit.strain == pytest.approx(kraus_strain_at(0.95 * G0), rel=0.03)


def test_kraus_with_noise_and_noisy_first_points():
    strain = np.geomspace(1e-4, 1.0, 41)
    truth = kraus_strain_at(0.95 * G0)
    # relative noise sigma shifts the crossing by ~ sigma / |d ln G' / d ln γ| in ln γ; the slope at the
    # 5 % point is -1.5 u (G0 - G∞) / ((1 + u)^2 G) with u = 0.2
    slope = 1.5 * 0.2 * (G0 - G_INF) / (1.2**2 * 0.95 * G0)
    sigma = 0.005
    for seed in range(5):
        rng = np.random.default_rng(seed)
        noisy = kraus(strain) * (1 + sigma * rng.standard_normal(strain.size))
        noisy[0] *= 0.93  # low-torque first point 7 % low: must not end the plateau
        limit = lve.lve_limit(strain, noisy)
        assert limit.plateau_points > 10, seed
        assert abs(math.log(limit.strain / truth)) < 3 * sigma / slope + 0.05, seed


def test_stiffening_and_never_leaving_the_band():
    strain = np.geomspace(1e-3, 0.5, 30)
    stiffening = 500.0 * (1 + (strain / 0.1) ** 2)  # +5 % at γ = 0.1 * sqrt(0.05)
    limit = lve.lve_limit(strain, stiffening)
    assert limit.direction == 1
    assert limit.strain == pytest.approx(0.1 * math.sqrt(0.05), rel=0.03)
    flat = lve.lve_limit(strain, np.full(strain.size, 500.0))
    assert flat.direction == 0 and math.isnan(flat.strain) and flat.plateau == 500.0
    with pytest.raises(ValueError, match="at least 4 finite points"):
        lve.lve_limit(strain[:3], stiffening[:3])


def test_flow_point_yield_stress_and_class():
    strain = np.geomspace(1e-3, 1.0, 61)
    storage = 1000.0 / (1 + (strain / 0.05) ** 2)
    loss = np.full(strain.size, 200.0)
    stress = np.hypot(storage, loss) * strain
    res = lve.analyse_amplitude_sweep(strain, storage, loss, stress)
    # G' = G'' at 1000 / (1 + x^2) = 200 -> x = 2 -> γ = 0.1; stress there |G*| γ = 200 √2 * 0.1
    assert res["flow_point_strain"] == pytest.approx(0.1, rel=0.01)
    assert res["flow_point_stress_pa"] == pytest.approx(200 * math.sqrt(2) * 0.1, rel=0.02)
    # G' 5 % point for plateau P: 1000 / (1 + x^2) = 0.95 P -> γ = 0.05 sqrt(1000 / (0.95 P) - 1)
    plateau = res["plateau_storage_pa"]
    assert plateau == pytest.approx(1000.0, rel=0.015)  # window median of a curve with no strict plateau
    gamma_l = 0.05 * math.sqrt(1000.0 / (0.95 * plateau) - 1)
    assert res["lve_strain"] == pytest.approx(gamma_l, rel=0.01)
    assert res["yield_stress_pa"] == pytest.approx(math.hypot(0.95 * plateau, 200.0) * gamma_l, rel=0.01)
    assert res["loss_factor_class"] == "gel" and res["tan_delta_plateau"] == pytest.approx(0.2, rel=0.01)
    assert res["direction_loss"] == 0 and math.isnan(res["lve_strain_loss"])
    liquid = lve.analyse_amplitude_sweep(strain, np.full(strain.size, 10.0), np.full(strain.size, 50.0))
    assert liquid["loss_factor_class"] == "liquid" and math.isnan(liquid["flow_point_strain"])


def test_summary_runs_average_and_frequency_sweep_flags(tmp_path):
    strain = np.geomspace(1e-4, 1.0, 41)
    runs = [_as_run(strain, kraus(strain, g0=g0, g_inf=0.7 * g0), np.full(strain.size, 0.1 * g0), sample=s)
            for g0, s in ((900.0, "s1"), (1000.0, "s2"), (1100.0, "s3"))]
    # a sweep without G'' is reported, not fatal
    runs.append(make_run_dataset({"shear_strain": strain, "storage_modulus": kraus(strain)},
                                 {"test": "amplitude_sweep", "sample": "bad", "run": "as-bad", "frequency_hz": 1.0}))
    for sample, pct in (("s1", 0.5), ("s2", 5.0), ("s9", 0.5)):
        runs.append(make_run_dataset(
            {"frequency": np.geomspace(0.1, 10, 9), "shear_strain": np.full(9, pct / 100),
             "storage_modulus": np.full(9, 1000.0)},
            {"test": "frequency_sweep", "specimen": "B1", "sample": sample, "run": f"fs-{sample}", "strain_pct": pct}))
    # averages as the lve stage gets them: read back from averages.nc (text variables come back as objects)
    averages = read_netcdf(curves.write_averages(curves.average_runs(runs), tmp_path / "averages.nc"))
    summary = lve.lve_summary(runs, averages)
    assert list(summary["source"].values) == ["run", "run", "run", "run", "average"]
    bad = list(summary["name"].values).index("as-bad")
    assert "needs shear_strain, storage_modulus and loss_modulus" in str(summary["note"].values[bad])
    assert math.isnan(summary["lve_strain"].values[bad])
    good = np.array([i for i in range(5) if i != bad])
    # Kraus with G∞ = 0.7 G0 gives the same 5 % strain for every G0, and so does their average
    np.testing.assert_allclose(summary["lve_strain"].values[good], kraus_strain_at(0.95 * G0), rtol=0.03)
    assert int(summary["n_samples"].values[4]) == 4  # the bad run is a sample of the average (no G'' there)
    assert list(summary["fs_outside_lve"].values) == [0, 1, 0]
    assert str(summary["fs_reference"].values[0]) == "same sample: as-B1-s1"
    assert str(summary["fs_reference"].values[2]).startswith("dataset average")
    nc, csv = lve.write_lve(summary, tmp_path / "lve.nc", tmp_path / "lve.csv")
    back = read_netcdf(nc)
    np.testing.assert_allclose(back["lve_strain"].values, summary["lve_strain"].values)
    table = pd.read_csv(csv)
    assert list(table["kind"]) == ["amplitude_sweep"] * 5 + ["frequency_sweep"] * 3
    assert table.loc[table["name"] == "fs-s2", "outside_lve"].item() == 1


def test_real_trios_fungi_amplitude_sweep(shared_real):
    run = read_trios_fungi_amplitude_sweep(shared_real / "trios" / "hr20_fungi_amplitude_sweep.xls")
    strain = run["shear_strain"].values
    # hand-read: G' flat at ~18.3-18.5 kPa from 0.01 % to 0.3 %, 17551 Pa at 0.502 %, 17230 Pa at 0.632 %
    assert strain[0] == pytest.approx(0.0100365e-2) and run["storage_modulus"].values[17] == 17551.2
    res = lve.analyse_amplitude_sweep(strain, run["storage_modulus"].values, run["loss_modulus"].values)
    # 0.95 x 18.33 kPa = 17.41 kPa is crossed between 0.502 % and 0.632 %, at ~0.55 %
    assert res["plateau_storage_pa"] == pytest.approx(18330, rel=0.01)
    assert res["lve_strain"] == pytest.approx(0.0055, abs=0.0004)
    assert res["direction_storage"] == -1
    # yield stress = |G*| γ_L ≈ 17.7 kPa * 0.0055 ≈ 98 Pa
    assert res["yield_stress_pa"] == pytest.approx(98.0, rel=0.08)
    # tan δ peaks at 0.93 at 60 %: G' never falls below G'', no flow point; a gel
    assert math.isnan(res["flow_point_strain"])
    assert res["loss_factor_class"] == "gel" and res["tan_delta_plateau"] == pytest.approx(0.17, abs=0.02)


def test_real_fungi_frequency_sweep_is_outside_the_lve_range(shared_real):
    runs = [read_trios_fungi_amplitude_sweep(shared_real / "trios" / "hr20_fungi_amplitude_sweep.xls"),
            read_trios_fungi_frequency_sweep(shared_real / "trios" / "hr20_fungi_frequency_sweep.xls")]
    summary = lve.lve_summary(runs)
    # 0.0426 rad * 4 mm / 8.518 mm = 2.0 % strain, about 4x the 0.55 % limit
    assert float(summary["fs_strain_amplitude"].values[0]) == pytest.approx(0.020, rel=0.02)
    assert int(summary["fs_outside_lve"].values[0]) == 1


def _torque_noise_sweeps(storage_of, stress_noise_pa: float, n: int = 8, seed: int = 0):
    """``n`` amplitude sweeps whose stress amplitude carries a constant noise SD (a torque noise): the moduli's
    noise is ``stress_noise_pa`` / strain, large at the smallest amplitudes."""
    rng = np.random.default_rng(seed)
    strain = np.geomspace(1e-4, 0.011, 13)
    runs = []
    for k in range(n):
        g1, g2 = storage_of(strain), 0.05 * storage_of(strain)
        s1 = g1 * strain + stress_noise_pa * rng.standard_normal(strain.size)
        s2 = g2 * strain + stress_noise_pa * rng.standard_normal(strain.size)
        runs.append(_as_run(strain, np.abs(s1) / strain, np.abs(s2) / strain, sample=f"s{k}"))
    return strain, runs


def test_torque_noise_at_the_smallest_amplitudes_is_not_an_lve_limit():
    """A linear gel (G' = 150 Pa to 1.1 %) measured near the torque floor: at 0.01-0.03 % the moduli scatter by
    30-70 %, so the 5 % band alone ends the 'plateau' at the first points. With the noise read from the sweeps, those
    points are noise and nothing leaves the band; the frequency sweep at 0.24 % stays inside."""
    strain, runs = _torque_noise_sweeps(lambda g: np.full(g.size, 150.0), stress_noise_pa=0.01)
    band_only = [lve.lve_limit(r["shear_strain"].values, r["storage_modulus"].values) for r in runs]
    assert sum(lim.direction != 0 for lim in band_only) >= 4       # the failure this guards against
    runs.append(make_run_dataset(
        {"frequency": np.geomspace(0.01, 6, 9), "shear_strain": np.full(9, 0.0024),
         "storage_modulus": np.full(9, 150.0)},
        {"test": "frequency_sweep", "specimen": "B1", "sample": "s0", "run": "fs-s0"}))
    summary = lve.lve_summary(runs)
    runs_only = summary["source"].values == "run"
    assert not summary["lve_reached"].values[runs_only].any()
    assert (summary["points_below_noise"].values[runs_only] >= 1).all()
    assert list(summary["fs_outside_lve"].values) == [0]


def test_kraus_softening_is_found_through_torque_noise():
    """Torque noise on a Kraus sweep with a flat plateau (m = 1.5): the limit is still the 5 % point of the closed
    form, within the grid's resolution (6 points a decade)."""
    for seed in range(3):
        strain, runs = _torque_noise_sweeps(lambda g: kraus(g, gamma_c=0.004, m=1.5), stress_noise_pa=0.005, seed=seed)
        summary = lve.lve_summary(runs)
        limits = summary["lve_strain"].values[summary["source"].values == "run"]
        np.testing.assert_allclose(limits, kraus_strain_at(0.95 * G0, gamma_c=0.004, m=1.5), rtol=0.12)


def test_the_fit_stage_and_lve_csv_read_one_limit_of_an_averaged_sweep_through_torque_noise():
    """Eight sweeps of a linear gel (G' = 1000 Pa) through a stress-amplitude noise of 0.04 Pa: the averages carry the
    noise SD of the mean, at the smallest amplitudes within 40 % of the injected one (0.04 Pa / strain / sqrt(8));
    the averaged sweep's limit in
    lve.csv and the fit stage's selection of the sweep's linear part are the same rule on the same floor, and both
    keep the whole sweep (the band alone cut one of these averages at 0.06 %)."""
    for seed in range(3):
        strain, runs = _torque_noise_sweeps(lambda g: np.full(g.size, 1000.0), stress_noise_pa=0.04, seed=seed)
        averages = curves.average_runs(runs)
        sweep = curves.select_average(averages, "amplitude_sweep")
        noise = sweep["storage_modulus_noise"].values
        np.testing.assert_allclose(noise[:3], 0.04 / strain[:3] / np.sqrt(8), rtol=0.4)
        linear = fitting.amplitude_sweep_lve_curve(sweep)
        summary = lve.lve_summary(runs, averages)
        average_row = list(summary["source"].values).index("average")
        assert math.isnan(linear.nominal["lve_limit_strain"]) and linear.n_points == strain.size
        assert math.isnan(float(summary["lve_strain"].values[average_row]))
