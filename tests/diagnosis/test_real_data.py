"""Diagnosis on real instrument exports laid out as a lab would (issue 12, "Done when").

Every dataset is built in a temporary folder: a ``samples.csv`` (one row per test block) and a ``dataset.yaml``
whose ``source_dir`` points at ``../shared/data/real`` (read in place, never copied), then run through the
package API: ingest -> baseline fit (lmfit) -> residual table -> diagnose. Skipped when the real data are absent.

Oracles: the LIMS file is a cooling series of frequency sweeps 150 -> -40 degC (the export's own step list
and temperature channel), so its cause is temperature and not a drift; the TRIOS fungi sweeps carry a raw
phase near 180 deg at high frequency (instrument_formats.md: "raw phase of about 180 deg ... (inertia)"),
read here point by point; the ten CNF relaxations are replicates of one hydrogel at 20 degC (README of the
real data), so no cause may be named between them.
"""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from tissuemech.canonical import read_netcdf
from tissuemech.diagnosis.report import diagnose_runs
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
    # no strain column in the frequency sweep, no plate radius in the rows: not testable, said so
    assert not inertia["tested"] and "not testable" in inertia["evidence"]


def test_fungi_inertia_dominated_points_are_named(fungi, shared_real):
    runs, fit, table, result = fungi
    f = _finding(result, "inertia_dominated_points")
    assert f["tested"] and f["detected"], f["evidence"]
    # hand-read oracle: the export's raw phase exceeds 90 deg at every angular frequency >= 6.3 rad/s
    fs = next(b for b in read_export(shared_real / "trios/hr20_fungi_frequency_sweep.xls")
              if b.name == "Frequency sweep - 2").data
    expected = set(np.round(fs.loc[fs["raw_phase"] > np.pi / 2, "angular_frequency"], 3))
    named = {round(p["angular_frequency_rad_s"], 3) for p in f["points"] if "frequency_sweep" in p["run"]}
    assert len(expected) == 13 and named == expected
    assert min(p["raw_phase_deg"] for p in f["points"]) > 90
    assert f["fix"] is not None and f["fix"]["cv"] == "leave-one-clean-point-out"


# ------------------------------------------------------------------------------------------------
# CNF hydrogel: ten replicate relaxations as ten samples raise no false cause
# ------------------------------------------------------------------------------------------------
CNF_FILES = [f"HC1_stressrelaxation_20C_{i}.csv" for i in (2, 3, 5, 6, 7, 8, 9, 10, 11, 12)]


@pytest.fixture(scope="module")
def cnf(shared_real, tmp_path_factory):
    rows = [{"file": f"rheocompass_cnf_hydrogel/{f}", "specimen": "HC1", "sample": f"r{k + 1:02d}",
             "test": "stress_relaxation", "order": 1} for k, f in enumerate(CNF_FILES)]
    runs = _lab_dataset(tmp_path_factory.mktemp("cnf"), "cnf", rows, shared_real, "CNF hydrogel")
    return runs, *_diagnose(runs, "prony2", ("stress_relaxation",))


@pytest.mark.slow
def test_cnf_replicates_raise_no_false_cause(cnf):
    runs, fit, table, result = cnf
    assert len(runs) == 10
    detected = [f["effect"] for f in result["findings"] if f["detected"]]
    assert detected == [] or detected == ["baseline_inadequate"], [
        (f["effect"], f["evidence"]) for f in result["findings"] if f["detected"]]
    assert not any("detector failed" in (f.get("evidence") or "") for f in result["findings"])


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
