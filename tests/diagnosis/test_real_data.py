"""Diagnosis on real instrument exports laid out as a lab would (issue 12, "Done when").

Every dataset is built in a temporary folder: a ``samples.csv`` (one row per test block) and a ``dataset.yaml``
whose ``source_dir`` points at ``../shared/data/real`` (read in place, never copied), then run through the
package API: ingest -> baseline fit (lmfit) -> residual table -> diagnose. Skipped when the real data are absent.

Oracles: the LIMS file is a cooling series of frequency sweeps 150 -> -40 degC (the export's own step list
and temperature channel), so its cause is temperature and not a drift; the TRIOS fungi sweeps carry a raw
phase near 180 deg at high frequency (instrument_formats.md: "raw phase of about 180 deg ... (inertia)"),
read here point by point, and an amplitude sweep at 0.5 Hz whose G' halves by 16 % strain and whose raw phase
passes 90 deg only beyond 25 % strain (read from the export: a sample that yields, not inertia); the ten CNF
relaxations are replicates of one hydrogel at 20 degC (README of the real data), so no cause may be named
between them.
"""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from tissuemech.canonical import read_netcdf
from tissuemech.diagnosis.baseline import baseline_adequacy
from tissuemech.diagnosis.evidence import residual_table
from tissuemech.diagnosis.report import diagnose, diagnose_runs
from tissuemech.io.dispatch import read_export
from tissuemech.io.ingest import ingest_dataset

# the module-scoped datasets (lims, fungi, cnf) are ingested and diagnosed once, on one worker: without a
# group, --dist loadgroup sent the two tests of a fixture to different workers and both built it
pytestmark = pytest.mark.xdist_group("real_data")


def _lab_dataset(root: Path, name: str, rows: list[dict], source: Path, material: str) -> list:
    """Write samples.csv + dataset.yaml (source_dir = the real folder), ingest, return the canonical runs."""
    ds = root / name
    ds.mkdir(parents=True)
    pd.DataFrame(rows).to_csv(ds / "samples.csv", index=False)
    (ds / "dataset.yaml").write_text(f"material: {material}\nlicense: see {source}\ncitation: real export\n"
                                     f"source_dir: {source}\n")
    report = ingest_dataset(ds, root / f"{name}_runs", root / f"{name}_ingest.csv")
    assert (report["status"] == "ok").all(), report.to_string()
    return [read_netcdf(p) for p in sorted((root / f"{name}_runs").rglob("*.nc"))]


def _diagnose(runs, key: str, tests: tuple[str, ...], target: str = "apparent_stress"):
    """The package's runs-only diagnosis (:func:`tissuemech.diagnosis.report.diagnose_runs`: baseline on the
    runs' own window, noise from the data, adequacy check); returns (fitted baseline key, residual table, result)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result, table = diagnose_runs(runs, key, target, "measured", tests, n_points=25, return_table=True)
    return key, table, result


def _finding(result, effect):
    return next(f for f in result["findings"] if f["effect"] == effect)


# ------------------------------------------------------------------------------------------------
# TA LIMS cooling series: temperature, not drift
# ------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def lims(shared_real, tmp_path_factory):
    path = "ta_lims/ares_g2_frequency_sweep_tts.txt"
    blocks = read_export(shared_real / path)
    rows = [{"file": path, "specimen": "468MP", "sample": "a", "test": "frequency_sweep", "order": i + 1,
             "block": b.index} for i, b in enumerate(blocks)]
    runs = _lab_dataset(tmp_path_factory.mktemp("lims"), "lims_tts", rows, shared_real, "polymer (TA LIMS TTS)")
    return runs, *_diagnose(runs, "prony4", ("frequency_sweep",))


@pytest.mark.slow
def test_lims_cooling_series_is_attributed_to_temperature(lims):
    runs, fit, table, result = lims
    temp = _finding(result, "temperature_dependence")
    assert temp["detected"], temp["evidence"]
    # one Prony series cannot describe 12 decades of shift: the baseline is inadequate and says so first, and the
    # temperature dependence, whose fix is scored without the baseline (held-out temperatures), is the cause named
    named = [f["effect"] for f in result["findings"] if f["detected"]]
    assert named[0] == "baseline_inadequate" and named[1:] == ["temperature_dependence"]
    assert temp["baseline_free"] is True
    # shift factors at every one of the 20 temperatures of the export, none NaN, monotonic
    sf = temp["shift_factors"]
    assert len(sf["temperature_c"]) == 20
    assert np.all(np.isfinite(sf["log_aT"])) and np.all(np.diff(sf["log_aT"]) < 0)
    assert temp["wlf"]["success"] and np.isfinite(temp["wlf"]["c1_stderr"])
    # the held-out temperature is predicted far better with the shift than without it
    fix = temp["fix"]
    assert fix["cv"] == "leave-one-temperature-out"
    assert fix["gain"] > 0.5 and fix["after"] < 0.2          # decades of modulus
    assert temp["held_out"]["n_folds"] == 20


@pytest.mark.slow
def test_lims_cooling_series_is_not_called_drift(lims):
    runs, fit, table, result = lims
    drift = _finding(result, "elapsed_time_drift")
    assert not drift["detected"]
    assert "temperature" in drift["evidence"] and "follows the elapsed time" in drift["evidence"]
    # the design's confounding is reported with the design that separates it
    sets = [set(c["covariates"]) for c in result["confounded"]]
    assert any({"channel_temperature", "elapsed_time"} <= s for s in sets)
    c = next(c for c in result["confounded"] if "channel_temperature" in c["covariates"])
    assert "repeat one temperature" in c["design"]
    # the temperature channel is not hidden by a blanket rule: it is explained by the named temperature cause
    assert not any(u["covariate"] in ("channel_temperature", "elapsed_time", "test_order") for u in result["unexplained"])


# ------------------------------------------------------------------------------------------------
# TRIOS fungi sweeps: no crash, inertia-dominated points named
# ------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def fungi(shared_real, tmp_path_factory):
    rows = [{"file": "trios/hr20_fungi_amplitude_sweep.xls", "specimen": "fungi", "sample": "a",
             "test": "amplitude_sweep", "order": 1, "block": "Amplitude sweep - 2"},
            {"file": "trios/hr20_fungi_frequency_sweep.xls", "specimen": "fungi", "sample": "a",
             "test": "frequency_sweep", "order": 2, "block": "Frequency sweep - 2"}]
    runs = _lab_dataset(tmp_path_factory.mktemp("fungi"), "fungi", rows, shared_real, "mushroom meat analogue")
    return runs, *_diagnose(runs, "prony3", ("frequency_sweep",))


def test_fungi_sweeps_run_without_a_detector_failure(fungi):
    runs, fit, table, result = fungi
    failed = [f["effect"] for f in result["findings"] if "detector failed" in (f.get("evidence") or "")]
    assert failed == []
    inertia = _finding(result, "instrument_inertia")
    # no gap in the sweep sheets: the inertial term omega^2 2h/(pi R^4) is not testable, said so
    assert not inertia["tested"] and "not testable" in inertia["evidence"]


def _raw_phase_points(shared_real, file, block):
    data = next(b for b in read_export(shared_real / file) if b.name == block).data
    return data, data["raw_phase"] > np.pi / 2


def test_fungi_inertia_dominated_points_are_named(fungi, shared_real):
    runs, fit, table, result = fungi
    f = _finding(result, "inertia_dominated_points")
    assert f["tested"] and f["detected"], f["evidence"]
    # hand-read oracle: the export's raw phase exceeds 90 deg at every angular frequency >= 6.3 rad/s
    fs, beyond = _raw_phase_points(shared_real, "trios/hr20_fungi_frequency_sweep.xls", "Frequency sweep - 2")
    expected = set(np.round(fs.loc[beyond, "angular_frequency"], 3))
    named = {round(p["angular_frequency_rad_s"], 3) for p in f["points"] if "frequency_sweep" in p["run"]}
    assert len(expected) == 13 and named == expected
    assert min(p["raw_phase_deg"] for p in f["points"]) > 90
    assert f["fix"] is not None and f["fix"]["cv"] == "leave-one-clean-point-out"
    # the amplitude sweep's points beyond 90 deg are at 0.5 Hz, where the linear sample is far from inertia-dominated
    # (raw phase 12-14 deg at small strain): they are not called inertia
    assert not [p for p in f["points"] if "amplitude_sweep" in p["run"]]


def test_fungi_amplitude_softening_is_named(fungi, shared_real):
    """G' of the amplitude sweep halves by 16 % strain (the export: 18.4 kPa at 0.1 %, 9.3 kPa at 8 %, 5.8 kPa at
    16 %), with torques of 1e-7 to 3e-4 N m, all above the sweep's own noise floor."""
    runs, fit, table, result = fungi
    f = _finding(result, "amplitude_softening")
    assert f["tested"] and f["detected"], f["evidence"]
    assert f["effect_size"] < -0.5 and f["baseline_free"]      # G' falls by more than half over the sweep
    assert f["fix"]["after"] < f["fix"]["before"] and f["fix"]["cv"] == "leave-one-point-out"
    # oracle from the export: the strain at which G' has fallen 5 % below its small-strain plateau
    amp, _ = _raw_phase_points(shared_real, "trios/hr20_fungi_amplitude_sweep.xls", "Amplitude sweep - 2")
    plateau = amp["storage_modulus"][amp["shear_strain"] <= 1e-3].median()
    onset = amp.loc[amp["storage_modulus"] < 0.95 * plateau, "shear_strain"].min()
    assert f["fix"]["parameters"]["onset_strain"] == pytest.approx(onset, rel=0.6)
    assert "%" in f["what_to_do"] and "amplitude" in f["what_to_do"]


def test_fungi_large_strain_failure_is_yield_or_slip_not_inertia(fungi, shared_real):
    runs, fit, table, result = fungi
    f = _finding(result, "yield_or_slip")
    assert f["tested"] and f["detected"] and f["baseline_free"], f["evidence"]
    # hand-read oracle: the amplitude sweep's raw phase passes 90 deg from 25 % strain on (5 points)
    amp, beyond = _raw_phase_points(shared_real, "trios/hr20_fungi_amplitude_sweep.xls", "Amplitude sweep - 2")
    assert sorted(p["strain"] for p in f["points"]) == pytest.approx(sorted(amp.loc[beyond, "shear_strain"]))
    assert f["yield_strain"] == pytest.approx(amp.loc[beyond, "shear_strain"].min())
    assert f["fix"]["before"] > f["fix"]["after"]


# ------------------------------------------------------------------------------------------------
# CNF hydrogel: ten replicate relaxations as ten samples raise no false cause
# ------------------------------------------------------------------------------------------------
CNF_FILES = [f"HC1_stressrelaxation_20C_{i}.csv" for i in (2, 3, 5, 6, 7, 8, 9, 10, 11, 12)]


@pytest.fixture(scope="module")
def cnf(shared_real, tmp_path_factory):
    rows = [{"file": f"rheocompass_cnf_hydrogel/{f}", "specimen": "HC1", "sample": f"r{k + 1:02d}",
             "test": "stress_relaxation", "order": 1} for k, f in enumerate(CNF_FILES)]
    runs = _lab_dataset(tmp_path_factory.mktemp("cnf"), "cnf", rows, shared_real, "CNF hydrogel")
    return runs


def test_cnf_replicates_raise_no_false_cause(cnf):
    """Ten replicates of one gel: no cause may be named and no structure left unexplained. The baseline is the
    replicates' own mean relaxation (at every time of the shared grid), so the test reads what the
    detectors and the covariates table make of real replicate scatter, whatever a fitted law makes of it."""
    runs = cnf
    assert len(runs) == 10
    stress = np.array([r["shear_stress"].values for r in runs])
    mean = stress.mean(axis=0)
    table = residual_table(runs, [{"shear_stress": mean} for _ in runs], "replicate_mean")
    adequacy = baseline_adequacy({"model_key": "replicate_mean", "flags": [], "stderr": {}, "varying": [],
                                  "converged": True}, table)
    assert adequacy["adequate"], adequacy
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = diagnose(runs, table, "replicate_mean", {"target": "none", "relaxation": "measured",
                                                          "fitted_tests": ["stress_relaxation"]}, adequacy=[adequacy])
    named = [(f["effect"], f["evidence"]) for f in result["findings"] if f["detected"]]
    assert named == []
    assert result["unexplained"] == [] and result["significant_fix_not_evaluated"] == []
    assert not any("detector failed" in (f.get("evidence") or "") for f in result["findings"])
    # the covariates table lists the logged temperature channel -- here with the reason it cannot be tested: the
    # first second of every hold rings (the stress swings between -4 and +8 Pa around a 0.07 Pa plateau), so the
    # within-curve scatter puts no plateau point 5 noise SDs above zero -- and no specimen rows (one gel)
    cov = {c["covariate"]: c for c in result["covariates"]}
    assert "channel_temperature" in cov and not cov["channel_temperature"].get("significant")
    assert cov["channel_temperature"]["tested"] or "noise floor" in cov["channel_temperature"]["evidence"]
    assert not [c for c in result["covariates"] if c["kind"] == "outlier specimen"]


@pytest.mark.slow
def test_cnf_as_one_sample_reports_the_inadequate_baseline(shared_real, tmp_path):
    """The issue's layout: the ten relaxations as tests of one sample; the two-mode Prony fit collapses
    (relaxation times at the bound, no covariance), which must be the first finding, not "no named cause"."""
    rows = [{"file": f"rheocompass_cnf_hydrogel/{f}", "specimen": "HC1", "sample": "a",
             "test": "stress_relaxation", "order": k + 1} for k, f in enumerate(CNF_FILES)]
    runs = _lab_dataset(tmp_path, "cnf_one", rows, shared_real, "CNF hydrogel")
    fit, table, result = _diagnose(runs, "prony2", ("stress_relaxation",))
    named = [f["effect"] for f in result["findings"] if f["detected"]]
    assert "baseline_inadequate" in named
