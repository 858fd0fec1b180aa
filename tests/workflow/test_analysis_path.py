"""The one path: :func:`tissuemech.analysis.analyse_dataset` and the Snakemake rules give the same results.

One small dataset folder of the independent generator (``benchmarks/independent_rheometer.py``, seed 1521: one
sample of an Ogden solid with a fractional kernel, two shear ramps and relaxations, a TRIOS text export) is run
through Snakemake (in a copy of the workflow, with the default target ``results/<dataset>/diagnosis.json``) and
through ``analyse_dataset`` in this process, with one pipeline configuration (the repository's, with fewer models
per scope so that the run stays short). The two results folders must hold the same files, the same tables and
the same diagnosis.
"""
from __future__ import annotations

import ast
import json
import sys
from pathlib import Path

import pandas as pd
import pytest
import yaml

from test_workflow_contract import _snakemake, copy_workflow

from tissuemech.analysis import analyse_dataset

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))

import independent_rheometer as ir  # noqa: E402

NAME = "path_1521"
pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("analysis_path")]


def _config(raw: Path) -> dict:
    config = yaml.safe_load((ROOT / "config" / "config.yaml").read_text())
    config.update(raw_dir=str(raw), datasets=[NAME], external_datasets={})
    config["fit"].update(models={"constant_shear_rate": ["linear_elastic", "ogden1"], "stress_relaxation": ["sls1"]},
                         joint_models=["qlv_linear_prony4"], multistart=1)
    config["fem"].update(indentation_datasets=[], brain_mesh=False)
    config["posterior"].update(datasets=[])
    return config


def _same(a, b, path="") -> None:
    """JSON values equal, numbers to 1e-9 relative (the two runs are separate processes of the same code)."""
    if isinstance(a, dict):
        assert set(a) == set(b), f"{path}: keys {sorted(set(a) ^ set(b))}"
        for k in a:
            _same(a[k], b[k], f"{path}/{k}")
    elif isinstance(a, list):
        assert len(a) == len(b), f"{path}: {len(a)} vs {len(b)} items"
        for i, (x, y) in enumerate(zip(a, b)):
            _same(x, y, f"{path}[{i}]")
    elif isinstance(a, float) and isinstance(b, float):
        assert a == pytest.approx(b, rel=1e-9, abs=1e-12, nan_ok=True), path
    else:
        assert a == b, path


@pytest.fixture(scope="module")
def both(tmp_path_factory):
    copy = copy_workflow(tmp_path_factory.mktemp("workflow"), with_raw=False)
    raw = copy / "raw"
    ir.write_dataset_folder(1521, raw / NAME, truth_path=copy / f"{NAME}.truth.json")
    config = _config(raw)
    (copy / "config" / "config.yaml").write_text(yaml.safe_dump(config, sort_keys=False))
    # the findings (rule diagnose): diagnosis.json also waits for the FEM replay, which the function does not run
    _snakemake(copy, "--cores", "2", f"results/{NAME}/diagnosis/findings.json", f"results/{NAME}/fits.csv",
               timeout=900)
    mine = tmp_path_factory.mktemp("analysis") / NAME
    done = analyse_dataset(raw / NAME, mine, config)
    return copy / "results" / NAME, mine, done


def test_the_function_writes_the_rules_files(both):
    rules, mine, done = both
    # Snakemake marks each directory output with a .snakemake_timestamp of its own
    listed = {str(p.relative_to(rules)) for p in rules.rglob("*") if p.is_file() and p.name != ".snakemake_timestamp"}
    # the function also writes diagnosis.json, which the rules write after the FEM replay
    assert {str(p.relative_to(mine)) for p in mine.rglob("*") if p.is_file()} == listed | {"diagnosis.json"}
    assert done["diagnosis_scope"] == "material" and done["scopes"] == [
        "constant_shear_rate", "stress_relaxation", "material"]


def test_the_function_and_the_rules_give_the_same_tables_and_diagnosis(both):
    rules, mine, done = both
    for table in ("ingest_report.csv", "ranking.csv", "fits.csv", "lve.csv"):
        a, b = pd.read_csv(rules / table), pd.read_csv(mine / table)
        for frame in (a, b):   # fits.csv names the record files with their folder
            if "file" in frame:
                frame["file"] = frame["file"].map(lambda f: Path(str(f)).name)
        pd.testing.assert_frame_equal(a, b, check_exact=False, rtol=1e-9)
    ours = json.loads((mine / "diagnosis" / "findings.json").read_text())
    theirs = json.loads((rules / "diagnosis" / "findings.json").read_text())
    _same(ours, theirs)
    assert ours["model"] == done["diagnosis"]["model"]


def _package_calls(path: Path) -> set[str]:
    """Names imported from ``tissuemech`` by a module (what it calls of the package)."""
    tree = ast.parse(path.read_text())
    return {a.name for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)
            and (n.level or (n.module or "").startswith("tissuemech")) for a in n.names}


def test_every_package_function_of_the_stage_scripts_is_called_by_the_function():
    """A stage script that calls a package function the one path does not call would make them differ (job
    logging is the scripts' own)."""
    scripts = ("ingest", "average", "tts", "fit_scope", "rank", "diagnose")
    needed = set().union(*(_package_calls(ROOT / "workflow" / "scripts" / f"{s}.py") for s in scripts)) - {"job_log"}
    assert needed <= _package_calls(ROOT / "src" / "tissuemech" / "analysis.py")
