"""The tissuemech command: run and report lead to the pipeline (checked with Snakemake's dry run in a copy of the
workflow, never in the checkout), --version, and help text in plain words (no reStructuredText markup)."""
from __future__ import annotations

import os
import re
import shutil
from importlib.metadata import version
from pathlib import Path

import pandas as pd
import pytest

from tissuemech.cli import SUBCOMMANDS, main

ROOT = Path(__file__).resolve().parents[2]


def _project(dest: Path, datasets: tuple[str, ...] = ("agar_3pct_thesis",)) -> Path:
    """A project folder: the Snakefile, workflow/, config/, the workflow profile and some bundled datasets."""
    dest.mkdir(parents=True)
    shutil.copy(ROOT / "Snakefile", dest)
    for folder in ("workflow", "config"):
        shutil.copytree(ROOT / folder, dest / folder, ignore=shutil.ignore_patterns("__pycache__"))
    if (ROOT / "profiles").is_symlink():
        (dest / "profiles").symlink_to(os.readlink(ROOT / "profiles"), target_is_directory=True)
    for name in datasets:
        shutil.copytree(ROOT / "raw" / name, dest / "raw" / name)
    return dest


def test_version(capsys):
    with pytest.raises(SystemExit) as done:
        main(["--version"])
    assert done.value.code == 0
    assert capsys.readouterr().out.strip() == f"tissuemech {version('tissuemech')}"


@pytest.mark.parametrize("command", [[], ["--help"]] + [[name, "--help"] for name in SUBCOMMANDS])
def test_help_is_plain_text(command, capsys):
    try:
        code = main(command)
    except SystemExit as done:       # argparse ends a sub-command's --help this way
        code = done.code
    out = capsys.readouterr().out
    assert code == 0
    assert not re.search(r"``|:func:|:mod:|\*\*", out), out
    if command and command[0] in SUBCOMMANDS:
        assert out.startswith(f"usage: tissuemech {command[0]}")
    else:
        for name in SUBCOMMANDS:
            assert re.search(rf"^  {name} +\S", out, re.M), f"{name} missing from the help"


def test_run_dry_run_restricts_the_pipeline_to_the_named_dataset(tmp_path, capfd):
    project = _project(tmp_path / "project", ("agar_3pct_thesis", "porcine_brain_thesis"))
    assert main(["run", "agar_3pct_thesis", "-n", "--directory", str(project)]) == 0
    out = "".join(capfd.readouterr())
    assert f"--snakefile {project / 'Snakefile'}" in out and "datasets=['agar_3pct_thesis']" in out
    scheduled = set(re.findall(r"wildcards: dataset=(\w+)", out))
    assert scheduled == {"agar_3pct_thesis"}
    assert re.search(r"^rule ingest:", out, re.M) and re.search(r"^rule summary:", out, re.M)
    assert not (project / "results").exists()                     # a dry run writes no result
    assert "--report" not in out                                  # and makes no report


def test_run_refuses_an_unknown_dataset(tmp_path, capfd):
    project = _project(tmp_path / "project")
    assert main(["run", "no_such_gel", "-n", "--directory", str(project)]) != 0
    assert "configured datasets not found under raw/: ['no_such_gel']" in "".join(capfd.readouterr())


def test_report_builds_the_pages_from_the_results(tmp_path, capsys):
    project = _project(tmp_path / "project", ())
    results = project / "results" / "gel"
    results.mkdir(parents=True)
    pd.DataFrame({"run": ["g1"], "file": ["a.csv"], "test": ["stress_relaxation"], "status": ["ok"],
                  "reason": [""]}).to_csv(results / "ingest_report.csv", index=False)
    assert main(["report", "-n", "--directory", str(project)]) == 0
    out = capsys.readouterr().out
    assert "summary pages of 1 dataset(s): gel" in out
    assert f"would run: " in out and "--report results/report.html" in out
    assert not (project / "results" / "summary.html").exists()
    assert main(["report", "--no-snakemake-report", "--directory", str(project)]) == 0
    assert (project / "results" / "summary.html").is_file() and (results / "summary.html").is_file()
    assert "gel" in (project / "results" / "summary.html").read_text()


def test_report_without_results_says_what_to_run(tmp_path, capsys):
    project = _project(tmp_path / "project", ())
    assert main(["report", "--directory", str(project)]) == 1
    assert 'run "tissuemech run" first' in capsys.readouterr().err
