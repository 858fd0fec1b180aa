"""``tissuemech check raw/<name>`` (issue 13, item 6): validates a dataset folder before any run, reads only."""
from __future__ import annotations

import hashlib
import shutil
from pathlib import Path

import numpy as np
import pytest

from tissuemech.canonical import make_run_dataset
from tissuemech.cli import main as cli_main
from tissuemech.io.check import describe_run


def tree_digest(folder: Path) -> dict[str, str]:
    return {p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


KEEP = ("batch01_s01_01_as.csv", "batch01_s07_01_sr0.4pct.csv", "batch01_s08_01_sr0.4pct.csv")


@pytest.fixture()
def agar_copy(tmp_path, repo_root) -> Path:
    """A three-run copy of the bundled agar dataset (keeps the tests fast)."""
    folder = tmp_path / "agar"
    shutil.copytree(repo_root / "raw" / "agar_3pct_thesis", folder)
    lines = (folder / "samples.csv").read_text(encoding="utf-8").splitlines()
    (folder / "samples.csv").write_text("\n".join([lines[0]] + [ln for ln in lines[1:] if ln.split(",")[0] in KEEP])
                                        + "\n", encoding="utf-8")
    for p in folder.glob("batch01_*.csv"):
        if p.name not in KEEP:
            p.unlink()
    return folder


def test_good_bundled_dataset_exits_0_and_describes_each_run(repo_root, capsys):
    folder = repo_root / "raw" / "agar_3pct_thesis"
    before = tree_digest(folder)
    assert cli_main(["check", str(folder)]) == 0
    out = capsys.readouterr().out
    assert tree_digest(folder) == before                     # nothing written into the dataset folder
    assert out.count("[ok]") == 12 and "ERROR" not in out
    # first row of samples.csv: batch01_s01_01_as.csv, amplitude sweep at 1 Hz, radius_mm 12.5, gap_mm 2.4312
    block = out.split("run batch01_s01_amplitude_sweep_1 [ok]  file: batch01_s01_01_as.csv\n", 1)[1].split("\nrun ", 1)[0]
    assert "test: amplitude_sweep   condition: frequency_hz=1" in block
    assert "geometry: R = 12.5 mm (samples.csv), gap = 2.431 mm (samples.csv)" in block
    assert "storage_modulus [Pa]" in block and "raw_phase [rad]" in block and "shear_strain [1]" in block
    assert "not testable: torque_below_resolution: no torque resolution declared" in block
    assert out.rstrip().endswith("12 of 12 runs readable, 0 with errors, 0 with warnings -> OK")


def test_a_broken_file_exits_nonzero_and_is_named(agar_copy, capsys):
    (agar_copy / "batch01_s08_01_sr0.4pct.csv").write_text("this is not a rheometer export\n1;2;3\n", encoding="utf-8")
    before = tree_digest(agar_copy)
    assert cli_main(["check", str(agar_copy)]) == 1
    out = capsys.readouterr().out
    assert tree_digest(agar_copy) == before
    error_lines = [line for line in out.splitlines() if "[ERROR]" in line]
    assert len(error_lines) == 1 and "batch01_s08_01_sr0.4pct.csv" in error_lines[0]
    assert "problem: " in out and "batch01_s08_01_sr0.4pct.csv" in out.split("problem: ", 1)[1].splitlines()[0]
    assert out.count("[ok]") == 2                            # the other runs are still described
    assert out.rstrip().endswith("-> FAILED")


def test_missing_description_is_a_dataset_error(agar_copy, capsys):
    (agar_copy / "dataset.yaml").unlink()
    assert cli_main(["check", str(agar_copy)]) == 1
    out = capsys.readouterr().out
    assert "ERROR" in out and "dataset.yaml" in out and "dataset description not found" in out


def test_unreferenced_files_are_noted_not_errors(agar_copy, capsys):
    (agar_copy / "extra_run.csv").write_text("x\n", encoding="utf-8")
    assert cli_main(["check", str(agar_copy)]) == 0
    assert "note: 1 file(s) not named in samples.csv: extra_run.csv" in capsys.readouterr().out


def test_geometry_is_shown_with_its_source_or_as_missing():
    columns = {"shear_strain": np.array([0.01, 0.02]), "storage_modulus": np.array([100.0, 99.0])}
    stated = make_run_dataset(columns, {"test": "amplitude_sweep", "radius_m": 0.004, "radius_source": "export",
                                        "gap_m": 0.003, "gap_source": "samples.csv", "frequency_hz": 1.0})
    lines = describe_run(stated)
    assert "geometry: R = 4 mm (export), gap = 3 mm (samples.csv)" in lines
    assert "columns (2 points): shear_strain [1], storage_modulus [Pa]" in lines
    bare = describe_run(make_run_dataset(columns, {"test": "amplitude_sweep"}))
    assert "geometry: no plate radius, no gap" in bare


def test_a_run_without_plate_radius_says_so_and_names_the_gap_source(agar_copy, capsys):
    (agar_copy / "dataset.yaml").write_text("material: 3 % agar gel\n", encoding="utf-8")   # only material
    lines = (agar_copy / "samples.csv").read_text(encoding="utf-8").splitlines()
    header = lines[0].split(",")
    first = lines[1].split(",")
    first[header.index("radius_mm")] = first[header.index("gap_mm")] = ""
    (agar_copy / "samples.csv").write_text("\n".join([lines[0], ",".join(first)] + lines[2:]) + "\n", encoding="utf-8")
    assert cli_main(["check", str(agar_copy)]) == 0                # warnings, not errors
    out = capsys.readouterr().out
    block = out.split("run batch01_s01_amplitude_sweep_1 [ok]", 1)[1].split("\nrun ", 1)[0]
    # no radius anywhere (the export's measuring system is not stated); the gap from the export's gap channel
    assert "geometry: no plate radius, gap = 2.431 mm (export)" in block
    assert "warnings: no plate radius" in block and "dataset.yaml has no 'citation'" in block
