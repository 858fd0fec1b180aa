"""Sample averaging on common grids: exact closed forms on synthetic runs, real replicate relaxation runs."""
from __future__ import annotations

import math

import numpy as np
import pytest

from tissuemech import curves
from tissuemech.canonical import make_run_dataset

from ._real import read_rheocompass_relaxation


def _relaxation_run(scale, time_s, sample, specimen="B1", strain_pct=10.0, run=None):
    """Power-law relaxation G(t) = scale * 100 t^-0.2: exact under log-log interpolation."""
    modulus = scale * 100.0 * time_s**-0.2
    return make_run_dataset(
        {"time": time_s, "relaxation_modulus": modulus, "shear_stress": modulus * strain_pct / 100,
         "shear_strain": np.full_like(time_s, strain_pct / 100), "total_time": time_s + 1000.0},
        {"test": "stress_relaxation", "specimen": specimen, "sample": sample, "strain_pct": strain_pct,
         "run": run or f"{specimen}-{sample}-{strain_pct}", "radius_m": 0.0125, "gap_m": 0.002 * scale},
    )


def test_mean_sd_n_match_closed_form_on_a_log_time_grid():
    scales = np.array([0.8, 1.0, 1.3])
    runs = [
        _relaxation_run(scales[0], np.geomspace(0.01, 100, 120), "s1"),
        _relaxation_run(scales[1], np.geomspace(0.02, 120, 97), "s2"),   # other grid, other range
        _relaxation_run(scales[2], np.geomspace(0.005, 80, 150), "s3"),
    ]
    avg = curves.average_runs(runs)
    curve = curves.select_average(avg, "stress_relaxation", {"strain_pct": 10})
    t = curve["time"].values
    # common range of the three samples: latest start, earliest end
    assert t[0] == pytest.approx(0.02) and t[-1] == pytest.approx(80.0)
    assert np.allclose(np.diff(np.log(t)), np.log(t[1] / t[0]))  # log-spaced
    assert t.size == 120  # median point count
    assert np.all(curve["relaxation_modulus_n"].values == 3)
    expected = 100.0 * t**-0.2
    np.testing.assert_allclose(curve["relaxation_modulus_mean"].values, scales.mean() * expected, rtol=1e-9)
    np.testing.assert_allclose(curve["relaxation_modulus_sd"].values, scales.std(ddof=1) * expected, rtol=1e-9)
    # a majority range (2 of 3) reaches further; there only the covering runs count, none is extrapolated
    wide = curves.select_average(curves.average_runs(runs, min_fraction=0.5), "stress_relaxation")
    tw, n = wide["time"].values, wide["relaxation_modulus_n"].values
    assert tw[0] == pytest.approx(0.01) and tw[-1] == pytest.approx(100.0)
    low = tw < 0.02
    assert np.all(n[low] == 2) and np.all(n[tw > 80.0] == 2) and np.all(n[(tw >= 0.02) & (tw <= 80.0)] == 3)
    np.testing.assert_allclose(wide["relaxation_modulus_mean"].values[low],
                               scales[[0, 2]].mean() * 100.0 * tw[low] ** -0.2, rtol=1e-9)
    assert "total_time_mean" not in curve  # session clock is not averaged
    assert curve.attrs["n_samples"] == 3 and curve.attrs["samples"] == "s1,s2,s3"
    assert curve.attrs["count_check"] == "ok"
    # geometry travels with the average (median over members); unset settings are left out
    assert curve.attrs["radius_m"] == 0.0125 and curve.attrs["gap_m"] == pytest.approx(0.002)
    assert "rise_time_s" not in curve.attrs


def test_conditions_are_separate_curves_and_file_roundtrip(tmp_path):
    t = np.geomspace(0.01, 10, 50)
    runs = [_relaxation_run(1.0, t, f"s{i}", strain_pct=p) for p in (1.0, 10.0) for i in range(2)]
    runs.append(make_run_dataset({"shear_strain": np.linspace(0, 0.5, 30), "shear_stress": np.linspace(0, 40, 30)},
                                 {"test": "constant_shear_rate", "shear_rate_1_per_s": 0.1, "specimen": "B1",
                                  "sample": "s0", "run": "csr"}))
    avg = curves.average_runs(runs)
    assert list(avg["condition"].values) == ["shear_rate_1_per_s=0.1", "strain_pct=1", "strain_pct=10"]
    assert all(avg[v].dtype != object for v in avg.data_vars)
    path = curves.write_averages(avg, tmp_path / "averages.nc")
    one = curves.load_average(path, "stress_relaxation", "strain_pct=1")
    np.testing.assert_allclose(one["shear_stress_mean"].values, 0.01 * 100 * one["time"].values ** -0.2, rtol=1e-9)
    assert one.attrs["strain_pct"] == 1.0 and one.attrs["n_samples"] == 2
    csr = curves.load_average(path, "constant_shear_rate")
    assert csr.attrs["grid_scale"] == "linear"
    np.testing.assert_allclose(csr["shear_stress_mean"].values, 80.0 * csr["shear_strain"].values, rtol=1e-12)
    assert np.all(np.isnan(csr["shear_stress_sd"].values))  # one sample: no SD
    with pytest.raises(KeyError, match="several conditions"):
        curves.load_average(path, "stress_relaxation")
    with pytest.raises(KeyError, match="no average for test 'creep_recovery'"):
        curves.load_average(path, "creep_recovery")


def test_count_check_flags_a_sparse_or_short_replicate():
    runs = [_relaxation_run(1.0, np.geomspace(0.01, 100, 100), f"s{i}") for i in range(3)]
    runs.append(_relaxation_run(1.0, np.geomspace(0.01, 100, 40), "sparse", run="sparse-run"))
    runs.append(_relaxation_run(1.0, np.geomspace(0.01, 1.0, 100), "short", run="short-run"))
    avg = curves.average_runs(runs)
    flags = dict(zip(avg["member_run"].values, avg["member_flag"].values))
    assert "40 points vs median 100" in flags["sparse-run"]
    assert "ends 2 decades from the median end" in flags["short-run"]
    assert sum(bool(f) for f in flags.values()) == 2
    assert "sparse-run" in str(avg["count_check"].values[0])
    # the flagged short run does not truncate the grid; it counts within its own range only
    curve = curves.select_average(avg, "stress_relaxation")
    t, n = curve["time"].values, curve["relaxation_modulus_n"].values
    assert t[-1] == pytest.approx(100.0)
    assert np.all(n[t <= 1.0] == 5) and np.all(n[t > 1.0] == 4)


def test_repeated_runs_of_one_sample_count_once():
    t = np.geomspace(0.1, 10, 30)
    runs = [_relaxation_run(1.0, t, "a", run="a1"), _relaxation_run(3.0, t, "a", run="a2"),
            _relaxation_run(2.0, t, "b", run="b1")]
    curve = curves.select_average(curves.average_runs(runs), "stress_relaxation")
    # sample a = (1 + 3)/2 = 2, sample b = 2 -> mean 2, SD 0, n 2
    np.testing.assert_allclose(curve["relaxation_modulus_mean"].values, 200 * t**-0.2, rtol=1e-9)
    np.testing.assert_allclose(curve["relaxation_modulus_sd"].values, 0.0, atol=1e-9)
    assert set(curve["relaxation_modulus_n"].values) == {2}
    assert curve.attrs["n_runs"] == 3 and curve.attrs["n_samples"] == 2


def test_ramp_uses_loading_branch_only():
    up = np.linspace(0, 0.5, 51)
    strain = np.concatenate([up, up[::-1][1:]])
    stress = np.concatenate([100 * up, 20 * up[::-1][1:]])  # unloading far below loading
    run = make_run_dataset({"shear_strain": strain, "shear_stress": stress},
                           {"test": "constant_shear_rate", "sample": "s1", "shear_rate_1_per_s": 0.01})
    curve = curves.select_average(curves.average_runs([run]), "constant_shear_rate")
    np.testing.assert_allclose(curve["shear_stress_mean"].values, 100 * curve["shear_strain"].values, rtol=1e-12)


def test_descending_frequency_sweep_from_angular_frequency():
    omega = np.geomspace(100, 0.1, 31)  # sweeps often run from high to low frequency
    runs = [make_run_dataset({"angular_frequency": omega, "storage_modulus": k * 1e3 * omega**0.1},
                             {"test": "frequency_sweep", "sample": f"s{k}", "strain_pct": 1.0})
            for k in (1, 2)]
    curve = curves.select_average(curves.average_runs(runs), "frequency_sweep")
    f = curve["frequency"].values
    assert f[0] == pytest.approx(0.1 / (2 * np.pi)) and f[-1] == pytest.approx(100 / (2 * np.pi))
    np.testing.assert_allclose(curve["storage_modulus_mean"].values, 1.5e3 * (2 * np.pi * f) ** 0.1, rtol=1e-9)


def test_no_usable_run_is_an_error():
    with pytest.raises(ValueError, match="no run to average"):
        curves.average_runs([make_run_dataset({"force": [1.0, 2.0]}, {"test": "unknown"})])


def test_no_ingested_run_names_the_ingest_report():
    with pytest.raises(ValueError, match="no ingested run .*rejected at ingest"):
        curves.average_runs([])


def test_real_rheocompass_replicates_average_into_one_curve(shared_real, tmp_path):
    folder = shared_real / "rheocompass_cnf_hydrogel"
    files = sorted(folder.glob("HC1_stressrelaxation_20C_*.csv"))
    assert len(files) == 10
    runs = [read_rheocompass_relaxation(p, sample=p.stem.rsplit("_", 1)[1]) for p in files]
    avg = curves.average_runs(runs)
    assert avg.sizes["curve"] == 1
    path = curves.write_averages(avg, tmp_path / "averages.nc")
    curve = curves.load_average(path, "stress_relaxation")
    t = curve["time"].values
    assert t[0] == pytest.approx(0.010, abs=1e-3) and t[-1] == pytest.approx(57.0, abs=0.2)
    assert curve.attrs["n_samples"] == 10
    n = curve["shear_stress_n"].values
    assert np.all(n[1:-1] == 10)
    # late plateau: hand-read from the files, the stress at t ~ 50-57 s lies at 0.08 Pa in run 10
    late = t > 40
    mean_late = curve["shear_stress_mean"].values[late]
    assert np.all((mean_late > 0.04) & (mean_late < 0.15))
    # check the averaging against a direct mean of the raw points nearest 30 s
    direct = [float(r["shear_stress"].values[np.argmin(np.abs(r["time"].values - 30.0))]) for r in runs]
    i30 = np.argmin(np.abs(t - 30.0))
    assert curve["shear_stress_mean"].values[i30] == pytest.approx(np.mean(direct), abs=3 * np.std(direct) / np.sqrt(10) + 0.01)
    assert np.all(curve["shear_stress_sd"].values[1:-1] > 0)
    # strain is held at 0.1 % after the ramp in every replicate
    np.testing.assert_allclose(curve["shear_strain_mean"].values[t > 1], 0.001, rtol=0.01)


def test_condition_missing_a_sample_is_reported():
    t = np.geomspace(0.1, 10, 20)
    runs = [_relaxation_run(1.0, t, s, strain_pct=p) for p in (1.0, 10.0) for s in ("a", "b", "c")
            if not (p == 10.0 and s == "b")]
    avg = curves.average_runs(runs)
    low = curves.select_average(avg, "stress_relaxation", "strain_pct=1")
    high = curves.select_average(avg, "stress_relaxation", "strain_pct=10")
    assert low.attrs["missing_samples"] == "" and low.attrs["count_check"] == "ok"
    assert high.attrs["missing_samples"] == "B1/b"
    assert "1 sample(s) of other stress_relaxation conditions missing" in high.attrs["count_check"]
    assert high.attrs["n_samples"] == 2


def test_majority_range_is_exact_coverage():
    # three shifted replicates: at least 2 of 3 cover [0.5, 9]
    assert curves._majority_range([(0.0, 9.0), (1.0, 10.0), (0.5, 8.0)], 0.5) == (0.5, 9.0)
    assert curves._majority_range([(0.0, 1.0), (2.0, 3.0)], 1.0) == (math.inf, -math.inf)


def test_disjoint_replicates_keep_the_union_and_are_flagged():
    runs = [_relaxation_run(1.0, np.geomspace(0.01, 0.1, 20), "a"), _relaxation_run(1.0, np.geomspace(1, 10, 20), "b")]
    curve = curves.select_average(curves.average_runs(runs, min_fraction=1.0), "stress_relaxation")
    assert curve["time"].values[0] == pytest.approx(0.01) and curve["time"].values[-1] == pytest.approx(10.0)
    assert "replicate ranges do not overlap" in curve.attrs["count_check"]
    assert curve["relaxation_modulus_n"].values.max() == 1  # nothing extrapolated into the gap


def test_sweeps_at_several_temperatures_are_separate_curves():
    """A temperature series (TTS) of one sample is one curve per temperature, never an average across them;
    a single temperature leaves the condition label as it was."""
    w = np.geomspace(0.1, 100.0, 12)

    def sweep(t_c, sample="a", factor=1.0):
        return make_run_dataset({"angular_frequency": w, "storage_modulus": factor * 1e3 * w ** 0.2,
                                 "loss_modulus": factor * 3e2 * w ** 0.3},
                                {"test": "frequency_sweep", "specimen": "x", "sample": sample, "temperature_c": t_c,
                                 "run": f"x-{sample}-{t_c}"})

    avg = curves.average_runs([sweep(20.0), sweep(40.0, factor=0.1), sweep(60.0, factor=0.01)])
    assert list(curves.as_str(avg["condition"].values)) == [f"temperature_c={t}" for t in (20, 40, 60)]
    hot = curves.select_average(avg, "frequency_sweep", "temperature_c=60")
    np.testing.assert_allclose(hot["storage_modulus_mean"].values, 10.0 * w ** 0.2, rtol=1e-9)
    assert hot.attrs["temperature_c"] == 60.0 and hot.attrs["n_runs"] == 1
    one = curves.average_runs([sweep(20.0, "a"), sweep(20.04, "b")])
    assert list(curves.as_str(one["condition"].values)) == ["default"] and int(one["n_samples"].values[0]) == 2
