"""The workflow contract of issue 2: a clean dry run, snakefmt-clean rules, reruns driven by what changed.

Snakemake runs in a copy of the workflow tree under ``tmp_path`` (never in the checkout, whose results and lock
belong to the developer). ``PYTHONPATH`` points at the copy's ``src/`` so the jobs import the copy's package (the
editable install points at the checkout, which would run unedited code), and the rule hashes
(``script_hash`` in ``workflow/rules/common.smk``) read the same copy.

The tiny dataset is written by the virtual rheometer: two amplitude sweeps and two stress relaxations of a linear
QLV gel, fitted with one model per scope, so a full ingest -> averages -> LVE -> fits -> ranking run stays short.
"""
from __future__ import annotations

import ast
import json
import os
import re
import shutil
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pandas as pd
import pytest
import yaml

from tissuemech.synth.generator import generate_dataset
from tissuemech.sourcehash import package_sources

ROOT = Path(__file__).resolve().parents[2]
TINY = "tiny_gel"
SECOND = "second_gel"
#: rule up to which the tiny runs go (``--until``): the cheap stages (ingest, average with LVE and spectra, fits,
#: rank), reached from the default target
UNTIL = ("rank",)
#: jobs of a dataset with amplitude sweeps and stress relaxations, one model per test kind
FULL_CHAIN = Counter({"ingest": 1, "average": 1, "fit_scope": 2, "rank": 1})

pytestmark = pytest.mark.xdist_group("workflow_contract")


def _env(copy: Path) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(copy / "src"), *filter(None, [env.get("PYTHONPATH")])])
    env.setdefault("MPLBACKEND", "Agg")
    env.setdefault("HDF5_USE_FILE_LOCKING", "FALSE")
    # numba keys its cache by source path, so a copy never reuses the checkout's cache: keep the copy's own
    env["NUMBA_CACHE_DIR"] = str(copy / ".numba_cache")
    return env


def _snakemake(copy: Path, *args: str, timeout: float = 300) -> str:
    cmd = [sys.executable, "-m", "snakemake", *args]
    done = subprocess.run(cmd, cwd=copy, env=_env(copy), capture_output=True, text=True, timeout=timeout)
    output = done.stdout + done.stderr
    assert done.returncode == 0, f"{' '.join(cmd)} exited {done.returncode}:\n{output[-5000:]}"
    assert "Traceback" not in output, output[-5000:]
    return output


def scheduled_jobs(dry_run_output: str) -> list[tuple[str, dict[str, str]]]:
    """(rule, wildcards) of every job a ``snakemake -n`` printed, checked against its 'Job stats' total."""
    jobs: list[tuple[str, dict[str, str]]] = []
    for line in dry_run_output.splitlines():
        header = re.fullmatch(r"(?:local)?(?:rule|checkpoint) (\w+):", line.strip())
        if header:
            jobs.append((header.group(1), {}))
            continue
        wildcards = re.fullmatch(r"wildcards: (.*)", line.strip())
        if wildcards and jobs:
            jobs[-1][1].update(item.split("=", 1) for item in wildcards.group(1).split(", "))
    total = re.search(r"^total\s+(\d+)\s*$", dry_run_output, re.M)
    if total is None:
        assert "Nothing to be done" in dry_run_output, dry_run_output[-3000:]
        total_jobs = 0
    else:
        total_jobs = int(total.group(1))
    assert len(jobs) == total_jobs, f"parsed {len(jobs)} jobs, Snakemake counted {total_jobs}"
    return jobs


def jobs_by_dataset(dry_run_output: str) -> dict[str, Counter]:
    out: dict[str, Counter] = {}
    for rule, wildcards in scheduled_jobs(dry_run_output):
        out.setdefault(wildcards.get("dataset", ""), Counter())[rule] += 1
    return out


def copy_workflow(dest: Path, with_raw: bool = True) -> Path:
    """The files a run needs (Snakefile, rules/scripts/schemas, config, package sources, bundled datasets)."""
    dest.mkdir(parents=True, exist_ok=True)
    shutil.copy(ROOT / "Snakefile", dest)
    skip = shutil.ignore_patterns("__pycache__", "*.egg-info")
    for folder in ("workflow", "config", "src") + (("raw",) if with_raw else ()):
        shutil.copytree(ROOT / folder, dest / folder, ignore=skip)
    # Snakemake finds the default workflow profile through profiles/ next to the Snakefile (a link into workflow/)
    if (ROOT / "profiles").is_symlink():
        (dest / "profiles").symlink_to(os.readlink(ROOT / "profiles"), target_is_directory=True)
    elif (ROOT / "profiles").is_dir():
        shutil.copytree(ROOT / "profiles", dest / "profiles")
    # the FEM timing rule runs this script; dry runs only need it to exist in a full copy
    (dest / "benchmarks").mkdir(exist_ok=True)
    shutil.copy(ROOT / "benchmarks" / "fem_timing.py", dest / "benchmarks")
    return dest


def tiny_config(name: str, tests: tuple[str, ...] = ("amplitude_sweep", "stress_relaxation")) -> dict:
    """Virtual-rheometer design: two samples per test kind of a linear QLV gel, few points."""
    settings = {"amplitude_sweep": {"frequency_hz": 1.0, "strain_min": 2e-4, "strain_max": 0.05, "n_points": 8},
                "stress_relaxation": {"strain": 0.01, "hold_s": 60, "n_points": 20}}
    return {"name": name, "temperature_c": 20.0, "geometry": {"radius_mm": 12.5, "gap_mm": [2.0, 3.0]},
            "truth": {"model": {"kind": "qlv", "instantaneous": "linear", "taus_s": [1.0, 20.0]},
                      "params": {"G0": 1000.0, "beta_1": 0.5, "beta_2": 1.0}},
            "variability": {"specimen_log_sd": 0.05, "sample_log_sd": 0.03}, "effects": {},
            "session": {"specimen_prefix": "gel"},
            "groups": [{"test": t, "samples": 2, "specimens": 1, "settings": settings[t]} for t in tests]}


def test_dry_run_of_the_repository_is_clean(tmp_path):
    """`snakemake -n` with the repository's config: exit 0, every dataset's stages, the FEM and summary jobs."""
    copy = copy_workflow(tmp_path / "wf")
    config = yaml.safe_load((ROOT / "config" / "config.yaml").read_text())
    shared = Path(os.environ.get("TISSUEMECH_SHARED_REAL", ROOT.parent / "shared" / "data" / "real"))  # as conftest
    if shared.is_dir():
        # external descriptors name their source relative to the checkout (../shared/...); give the copy the same view
        (tmp_path / "shared" / "data").mkdir(parents=True)
        (tmp_path / "shared" / "data" / "real").symlink_to(shared, target_is_directory=True)
    output = _snakemake(copy, "-n")
    assert "Using workflow specific profile profiles/default" in output
    by_dataset = jobs_by_dataset(output)
    bundled = sorted(p.parent.name for p in (ROOT / "raw").glob("*/samples.csv"))
    assert bundled, "no bundled dataset under raw/"
    external = sorted(config.get("external_datasets", {}))
    expected = bundled + (external if shared.is_dir() else [])
    assert sorted(set(by_dataset) - {""}) == sorted(expected)
    for name in expected:
        for rule in ("ingest", "average", "fit_scope", "rank"):
            assert by_dataset[name][rule] >= 1, f"{name}: no {rule} job in the dry run"
    assert by_dataset[""]["all"] == 1 and by_dataset[""]["fem_timing"] == 1 and by_dataset[""]["summary"] == 1
    # config posterior: the bundled brain's material scope samples its baseline model (one job), and fits.csv is
    # written by the dataset's one rank job, which waits for the posterior tables
    post = config["posterior"]
    if "porcine_brain_thesis" in post["datasets"] and post.get("scopes") == ["material"]:
        assert by_dataset["porcine_brain_thesis"]["posterior"] == 1
    for name in expected:
        assert by_dataset[name]["rank"] == (1 if by_dataset[name]["fit_scope"] else 0), name
    # the averages' LVE limits and spectra are written by the average job: no job of their own
    assert not {"lve", "spectrum", "fits_table"} & {rule for jobs in by_dataset.values() for rule in jobs}
    if not shared.is_dir():
        for name in external:
            assert f"external dataset {name!r}" in output and "skipped" in output


def test_dry_run_of_one_selected_dataset_is_clean(tmp_path):
    """The documented override `--config datasets=[...]` with the repository's config: only that dataset's jobs."""
    copy = copy_workflow(tmp_path / "wf")
    by_dataset = jobs_by_dataset(_snakemake(copy, "-n", "--config", "datasets=['agar_3pct_thesis']"))
    assert set(by_dataset) == {"agar_3pct_thesis", ""}
    assert by_dataset["agar_3pct_thesis"]["ingest"] == 1 and by_dataset[""]["all"] == 1


def test_rules_are_snakefmt_clean():
    snakefmt = Path(sys.executable).with_name("snakefmt")
    cmd = [str(snakefmt) if snakefmt.exists() else shutil.which("snakefmt") or "snakefmt",
           "--check", "Snakefile", "workflow/"]
    done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, f"snakefmt --check failed:\n{done.stdout}{done.stderr}"


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    """A copy of the workflow whose raw/ holds only the tiny dataset, run up to LVE and ranking."""
    copy = copy_workflow(tmp_path_factory.mktemp("contract") / "wf", with_raw=False)
    generate_dataset(tiny_config(TINY), 3, copy / "raw" / TINY)
    config = yaml.safe_load((ROOT / "config" / "config.yaml").read_text())
    config["raw_dir"] = "raw"
    config["datasets"] = []  # discovery: every raw/<name>/samples.csv
    config["external_datasets"] = {}
    config["fit"].update(multistart=1, material={"enabled": False},
                         models={"amplitude_sweep": ["linear_elastic"], "stress_relaxation": ["maxwell"]})
    # FEM off: no indentation experiment, no brain mesh (the runs stop at ranking anyway, but the DAG of the
    # default target must resolve)
    config["fem"].update(indentation_datasets=[], brain_mesh=False)
    (copy / "config" / "config.yaml").write_text(yaml.safe_dump(config, sort_keys=False))
    output = _snakemake(copy, "--cores", "2", "--until", *UNTIL, timeout=600)
    assert jobs_by_dataset(output) == {TINY: FULL_CHAIN}
    return copy


def test_tiny_run_uses_the_copy_and_writes_lve_and_ranking(tiny_run):
    where = subprocess.run([sys.executable, "-c", "import tissuemech; print(tissuemech.__file__)"],
                           env=_env(tiny_run), capture_output=True, text=True, check=True).stdout.strip()
    assert Path(where).is_relative_to(tiny_run / "src"), where
    results = tiny_run / "results" / TINY
    ranking = pd.read_csv(results / "ranking.csv")
    assert set(ranking.astype(str).stack()) >= {"linear_elastic", "maxwell"}
    assert len(pd.read_csv(results / "lve.csv")) >= 2  # one LVE limit per amplitude sweep at least
    # one canonical run per row of the sample sheet
    assert len(list((results / "runs").glob("*.nc"))) == len(pd.read_csv(tiny_run / "raw" / TINY / "samples.csv"))


def test_second_dry_run_has_nothing_to_do(tiny_run):
    assert scheduled_jobs(_snakemake(tiny_run, "-n", "--until", *UNTIL)) == []


@pytest.mark.parametrize(("module", "expected"), [
    # ingest reaches lve.py (io/quality.py flags frequency-sweep points above the LVE limit of the same sample's
    # amplitude sweep), so an edit there reruns the whole chain; the fit stage reaches it too (LVE range)
    ("lve.py", dict(FULL_CHAIN)),
    ("io/rheocompass.py", dict(FULL_CHAIN)),  # ingest reruns, so does everything downstream of it
    # the average job writes the spectra, whose Prony recursion is in the models package: it reruns too
    ("models/base.py", {"average": 1, "fit_scope": 2, "rank": 1}),
], ids=["lve", "io-reader", "models"])
def test_editing_a_module_reruns_only_its_dependants(tiny_run, module, expected):
    source = tiny_run / "src" / "tissuemech" / module
    original = source.read_bytes()
    try:
        source.write_bytes(original + b"\n# edited by the workflow contract test\n")
        by_dataset = jobs_by_dataset(_snakemake(tiny_run, "-n", "--until", *UNTIL))
    finally:
        # same bytes, same hash: the next test sees the tree as the run left it
        source.write_bytes(original)
    assert by_dataset == {TINY: Counter(expected)}


def test_changing_a_fit_setting_reruns_only_the_fits(tmp_path, tiny_run):
    # a config file, not --config: Snakemake reads nested --config values as strings, which the schema refuses
    override = tmp_path / "more_starts.yaml"
    override.write_text(yaml.safe_dump({"fit": {"multistart": 2}}))
    output = _snakemake(tiny_run, "-n", "--configfile", str(override), "--until", *UNTIL)
    assert jobs_by_dataset(output) == {TINY: Counter({"fit_scope": 2, "rank": 1})}


def test_dropping_a_dataset_folder_schedules_only_its_jobs(tiny_run):
    folder = tiny_run / "raw" / SECOND
    try:
        generate_dataset(tiny_config(SECOND, tests=("amplitude_sweep",)), 5, folder)
        by_dataset = jobs_by_dataset(_snakemake(tiny_run, "-n", "--until", *UNTIL))
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    # only amplitude sweeps: one fit scope, and nothing of the dataset already done
    assert by_dataset == {SECOND: Counter({"ingest": 1, "average": 1, "fit_scope": 1, "rank": 1})}



def test_a_failed_job_stops_only_its_own_dataset(tiny_run):
    # the workflow profile sets keep-going: a dataset whose exports are all unreadable fails its own jobs, the
    # other dataset still reaches its ranking, and Snakemake exits non-zero naming the failed job
    good, broken = tiny_run / "raw" / SECOND, tiny_run / "raw" / "broken_gel"
    try:
        generate_dataset(tiny_config(SECOND, tests=("amplitude_sweep",)), 5, good)
        generate_dataset(tiny_config("broken_gel", tests=("amplitude_sweep",)), 6, broken)
        for export in pd.read_csv(broken / "samples.csv")["file"]:
            (broken / export).write_bytes(b"\x00\x01 not an instrument export\n")
        # one core, the broken dataset's chain first: without keep-going nothing of the good one would run
        cmd = [sys.executable, "-m", "snakemake", "--cores", "1", "--until", *UNTIL,
               "--prioritize", "results/broken_gel/ranking.csv"]
        done = subprocess.run(cmd, cwd=tiny_run, env=_env(tiny_run), capture_output=True, text=True, timeout=600)
        output = done.stdout + done.stderr
        assert done.returncode != 0, output[-3000:]
        assert re.search(r"Error in rule \w+:", output), output[-3000:]
        assert "broken_gel" in output[output.index("Error in rule"):], output[-3000:]
        assert "every export was rejected at ingest" in output, output[-3000:]
        assert (tiny_run / "results" / SECOND / "ranking.csv").is_file(), output[-3000:]
        assert not (tiny_run / "results" / "broken_gel" / "ranking.csv").exists()
    finally:
        for folder in (good, broken):
            shutil.rmtree(folder, ignore_errors=True)
        for name in (SECOND, "broken_gel"):
            shutil.rmtree(tiny_run / "results" / name, ignore_errors=True)
            shutil.rmtree(tiny_run / "logs" / name, ignore_errors=True)
            shutil.rmtree(tiny_run / "benchmarks" / "runs" / name, ignore_errors=True)


# --- every package module a stage script imports is part of that rule's rerun hash ------------------------------


def _rules_with_scripts() -> dict[str, tuple[Path, Path | None]]:
    """rule -> (script, script named in its pkg=script_hash(...) param or None) from workflow/rules/*.smk."""
    rules = {}
    for smk in sorted((ROOT / "workflow" / "rules").glob("*.smk")):
        for block in re.split(r"\n(?=rule \w+:)", smk.read_text()):
            name = re.match(r"rule (\w+):", block)
            script = re.search(r"^\s+script:\s*\n\s+\"([^\"]+)\"", block, re.M)
            if not (name and script):
                continue
            pkg = re.search(r"\bpkg=script_hash\(\"([^\"]+)\"\),\n", block)
            rules[name.group(1)] = ((smk.parent / script.group(1)).resolve(), ROOT / pkg.group(1) if pkg else None)
    return rules


def _hashed_files(hashed_script: Path) -> set[str]:
    """Package files ``script_hash(hashed_script)`` reads, relative to src/tissuemech (common.smk's call)."""
    package = ROOT / "src" / "tissuemech"
    return {p.relative_to(package).as_posix() for p in package_sources(hashed_script, ROOT / "src")}


_IMPORTS_OF_SCRIPTS = r"""
import importlib, json, sys
from pathlib import Path
package = Path(sys.argv[1])
out = {}
for script, modules in json.loads(sys.argv[2]).items():
    for name in [n for n in sys.modules if n == "tissuemech" or n.startswith("tissuemech.")]:
        del sys.modules[name]
    for module in modules:
        importlib.import_module(module)
    out[script] = sorted(Path(m.__file__).resolve().relative_to(package).as_posix()
                         for n, m in list(sys.modules.items())
                         if (n == "tissuemech" or n.startswith("tissuemech.")) and getattr(m, "__file__", None))
print(json.dumps(out))
"""


@pytest.fixture(scope="module")
def imported_by_script():
    """script -> package files loaded by importing what the script imports.

    Import time only, in one interpreter that forgets the package between scripts: imports inside functions are
    not seen, so this is a lower bound of what a rule depends on."""
    modules = {}
    for script, _ in _rules_with_scripts().values():
        tree = ast.parse(script.read_text())
        names = {n.module or "" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
        names |= {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
        modules[str(script)] = sorted(n for n in names if n == "tissuemech" or n.startswith("tissuemech."))
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src"), "MPLBACKEND": "Agg"}
    done = subprocess.run([sys.executable, "-c", _IMPORTS_OF_SCRIPTS, str(ROOT / "src" / "tissuemech"),
                           json.dumps(modules)], env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout)


@pytest.mark.parametrize("rule", sorted(_rules_with_scripts()))
def test_rule_hash_covers_the_modules_its_script_imports(rule, imported_by_script):
    script, hashed = _rules_with_scripts()[rule]
    assert hashed is not None, f"rule {rule} has no pkg=script_hash(...) param: edits to the package never rerun it"
    assert hashed.resolve() == script, f"rule {rule} hashes the imports of {hashed}, but runs {script}"
    missing = sorted(set(imported_by_script[str(script)]) - _hashed_files(hashed))
    assert not missing, f"rule {rule}: {script.name} imports {missing}, not in its script_hash"
