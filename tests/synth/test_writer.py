"""RheoCompass writer layout (against the real export), round trip through ingest, determinism from the seed."""
import json

import numpy as np
import pandas as pd
import pytest
import yaml

from tissuemech.models.qlv import LinearElasticShear, QLVModel, qlv_params
from tissuemech.synth.generator import generate_dataset
from tissuemech.synth.writer import format_number, rheocompass_text, write_rheocompass_csv

TAUS = [0.1, 1.0, 10.0, 100.0]
REAL = "rheocompass_cnf_hydrogel/HC1_stressrelaxation_20C_2.csv"


def small_config(effects=None):
    params = qlv_params(QLVModel(LinearElasticShear(), 4, taus_s=TAUS), {"G0": 200.0}, [0.05, 0.25, 0.2, 0.12])
    return {"name": "tiny", "temperature_c": 37.0, "geometry": {"radius_mm": 12.5, "gap_mm": [2.0, 4.0]},
            "truth": {"model": {"kind": "pipkin_rogers", "instantaneous": "linear", "taus_s": TAUS}, "params": params},
            "variability": {"specimen_log_sd": 0.2, "sample_log_sd": 0.1}, "effects": effects or {},
            "session": {"specimen_prefix": "brain"},
            "groups": [{"test": "amplitude_sweep", "samples": 1, "specimens": 1, "settings": {"n_points": 5}},
                       {"test": "frequency_sweep", "samples": 1, "specimens": 1, "settings": {"n_points": 4}},
                       {"test": "constant_shear_rate", "samples": 2, "specimens": 2,
                        "settings": {"shear_rate_1_s": 0.1, "n_points": 10}},
                       {"test": "stress_relaxation", "samples": 1, "specimens": 1,
                        "settings": {"strain": 0.1, "n_points": 12}},
                       {"test": "creep_recovery", "samples": 1, "specimens": 1,
                        "settings": {"stress_pa": 5.0, "n_points": 12, "creep_s": 30, "recovery_s": 30}}]}


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    out = tmp_path_factory.mktemp("tiny")
    return out, generate_dataset(small_config({"nonseparable_relaxation": {"kappa": 0.5}}), 7, out)


def test_number_format_is_rheocompass():
    assert format_number(0.036378) == "0,036378"
    assert format_number(2.21e4) == "22100"
    assert format_number(1.5e-7) == "1,5E-07"
    assert format_number(np.nan) == ""


def test_layout_matches_real_export_bytes(shared_real, tmp_path):
    real = (shared_real / REAL).read_bytes()
    path = write_rheocompass_csv(tmp_path / "x.csv", {"time": np.array([0.01, 0.021]),
                                                      "shear_strain": np.array([1.9e-4, 4.99e-4]),
                                                      "shear_stress": np.array([7.922, -1.2326]),
                                                      "relaxation_modulus": np.array([41761.0, -2471.3]),
                                                      "torque": np.array([3.6378e-5, -5.6603e-6]),
                                                      "temperature": np.array([20.0, 20.0])},
                                 "HC1_stressrelaxation_20C_2", "Step strain")
    ours = path.read_bytes()
    assert ours[:2] == real[:2] == b"\xff\xfe"
    real_lines = real[2:].decode("utf-16-le").split("\r\n")
    our_lines = ours[2:].decode("utf-16-le").split("\r\n")
    assert our_lines[:6] == real_lines[:6]                     # header, column, sub-label and unit rows identical
    assert our_lines[6].split("\t")[0] == "1" and our_lines[6].endswith("\tDy_auto")
    assert our_lines[6].split("\t")[5] == "0,036378"
    assert our_lines[-2:] == real_lines[-2:] == ["", ""]      # trailing CRLF CRLF


def test_project_header_variant():
    text = rheocompass_text({"time": np.array([1.0, 2.0])}, "t", "Creep recovery", header="project")
    lines = text.split("\r\n")
    assert lines[0].startswith("Project:\t") and lines[6] == "Interval and data points:\t1\t2"
    assert lines[7] == "Interval data:\tPoint No.\tTime\tStatus" and lines[9] == "\t\t[s]\t"
    assert lines[10] == "\t1\t1\tDy_auto"


def test_dataset_folder_contents(dataset):
    out, result = dataset
    samples = pd.read_csv(out / "samples.csv")
    assert list(samples.columns[:5]) == ["file", "specimen", "sample", "test", "order"]
    assert len(samples) == 6 and all((out / f).is_file() for f in samples["file"])
    assert set(samples["test"]) == {"amplitude_sweep", "frequency_sweep", "constant_shear_rate",
                                    "stress_relaxation", "creep_recovery"}
    meta = yaml.safe_load((out / "dataset.yaml").read_text())
    assert meta["provenance"]["type"] == "synthetic" and meta["provenance"]["seed"] == 7
    truth = json.loads((out / "truth.json").read_text())
    assert truth["effects"]["nonseparable_relaxation"]["kappa"] == 0.5
    assert truth["truth_model"]["params"]["kappa"] == 0.5
    assert {r["file"] for r in truth["runs"]} == set(samples["file"])
    # per-run parameters = population x specimen x sample log-normal factor
    run = truth["runs"][0]
    assert run["params"]["G0"] == pytest.approx(200.0 * run["modulus_factor"])


def test_determinism_from_seed(tmp_path):
    a = generate_dataset(small_config(), 3, tmp_path / "a")
    generate_dataset(small_config(), 3, tmp_path / "b")
    generate_dataset(small_config(), 4, tmp_path / "c")
    for f in a["runs"]:
        assert (tmp_path / "a" / f).read_bytes() == (tmp_path / "b" / f).read_bytes()
    assert (tmp_path / "a" / "truth.json").read_bytes() == (tmp_path / "b" / "truth.json").read_bytes()
    differs = [(tmp_path / "a" / f).read_bytes() != (tmp_path / "c" / f).read_bytes()
               for f in a["runs"] if (tmp_path / "c" / f).is_file()]
    assert differs and all(differs)


@pytest.mark.parametrize("header", ["simple", "project"])
def test_round_trip_through_ingest(dataset, header, tmp_path):
    from tissuemech.io.dispatch import read_export
    out, result = dataset
    if header == "project":
        out = tmp_path
        result = generate_dataset(small_config({"nonseparable_relaxation": {"kappa": 0.5}}), 7, out, header="project")
    for fname, gen in result["runs"].items():
        blocks = read_export(out / fname)
        assert len(blocks) == 1
        data = blocks[0].data
        assert set(gen["channels"]) <= set(data.columns), f"{fname}: not read back {set(gen['channels']) - set(data.columns)}"
        for name, values in gen["channels"].items():
            np.testing.assert_allclose(data[name].to_numpy(float), values, rtol=1e-11, atol=1e-300,
                                       err_msg=f"{fname}:{name}")


def test_cli_writes_a_dataset(tmp_path, capsys):
    from tissuemech.cli import main
    cfg = small_config()
    cfg["groups"] = cfg["groups"][2:3]
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(cfg))
    assert main(["synth", "--config", str(tmp_path / "c.yaml"), "--seed", "5", "--out", str(tmp_path / "d")]) == 0
    assert "wrote 2 runs" in capsys.readouterr().out
    assert len(pd.read_csv(tmp_path / "d" / "samples.csv")) == 2
    assert json.loads((tmp_path / "d" / "truth.json").read_text())["seed"] == 5
