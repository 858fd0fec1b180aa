"""The workflow runs on SLURM through Snakemake's executor plugin and gives the same results as a local run.

A single-node SLURM (Debian ``slurm-wlm`` + ``munge``, no accounting daemon) is started on localhost by
``start_local_slurm.sh``. A small dataset (nine exports of the bundled agar set: amplitude sweeps, flow
curves, creep) goes through ingest, average, LVE and two fit scopes twice, in two copies of the workflow:
``snakemake --cores 2`` and ``snakemake --workflow-profile workflow/profiles/slurm`` (``executor: slurm``).
The runs overlap in time (the SLURM one spends much of its time in job start-up and status polling).
Skipped where SLURM cannot be started (not root, no apt-get, packages not installable, a real cluster's
slurm.conf on the machine) and where another cluster than the local test cluster answers.
"""
from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import xarray as xr
import yaml

# slow: two small workflow runs (~2-4 min on 2 shared cores); `make test-fast` leaves it out
pytestmark = [pytest.mark.slurm, pytest.mark.slow, pytest.mark.xdist_group("slurm")]

ROOT = Path(__file__).resolve().parents[2]
START_SCRIPT = Path(__file__).with_name("start_local_slurm.sh")
SOURCE_DATASET = ROOT / "raw" / "agar_3pct_thesis"
DATASET = "agar_mini"
#: amplitude sweeps (LVE), flow curves and creep at 40 Pa: two fit scopes, so the "fits" group has two members
EXPORT_SUFFIXES = ("_as.csv", "_fc.csv", "_cr40Pa.csv")
FIT_MODELS = {"flow_curve": ["newton", "power_law"], "creep_recovery": ["kelvin_voigt", "sls1"]}
TARGETS = [
    f"results/{DATASET}/ingest_report.csv",
    f"results/{DATASET}/averages.nc",
    f"results/{DATASET}/lve.csv",
    *(f"results/{DATASET}/ranking/{scope}.csv" for scope in FIT_MODELS),
]
#: workflow/scripts of the rules that produce TARGETS (ingest, average with the LVE limits, fit_scope)
JOB_SCRIPTS = {"ingest.py", "average.py", "fit_scope.py"}
RUN_TIMEOUT_S = 540
#: ClusterName written by start_local_slurm.sh
LOCAL_CLUSTER = "tissuemech-ci"
SLURM_OPTIONS = [
    # the local cluster has no accounts and no accounting database: finished jobs are read from squeue
    # (MinJobAge=3600 keeps them there)
    "--slurm-no-account",
    "--slurm-status-command", "squeue",
    # status checks come 5, 20, 45, 80 s after a submission (the plugin adds 10 s per check without news):
    # the jobs here take 10-50 s
    "--slurm-init-seconds-before-status-checks", "5",
    # keep the per-job SLURM logs as evidence that the jobs ran there
    "--slurm-keep-successful-logs",
    # one local filesystem: no NFS delay to wait for
    "--latency-wait", "10",
]


def _job_env() -> dict[str, str]:
    env = dict(os.environ)
    env.setdefault("NUMBA_CACHE_DIR", str(ROOT / ".numba_cache"))
    env.setdefault("MPLBACKEND", "Agg")
    env.setdefault("HDF5_USE_FILE_LOCKING", "FALSE")
    # the SLURM jobs run `python -m snakemake` of this interpreter (sbatch --export=ALL keeps PATH)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    return env


def _slurm_answers() -> bool:
    if shutil.which("sinfo") is None:
        return False
    if shutil.which("slurmctld") and subprocess.run(["pgrep", "-x", "slurmctld"], capture_output=True).returncode:
        # the local test cluster is installed but stopped (sinfo would retry its controller for ~10 s)
        return False
    done = subprocess.run(["sinfo", "-h", "-o", "%t"], capture_output=True, text=True, timeout=20)
    return done.returncode == 0 and done.stdout.split()[:1] in (["idle"], ["mix"], ["alloc"])


def _cluster_name() -> str:
    config = subprocess.run(["scontrol", "show", "config"], capture_output=True, text=True, timeout=20).stdout
    return next((line.split("=", 1)[1].strip() for line in config.splitlines()
                 if line.startswith("ClusterName")), "")


@pytest.fixture(scope="module")
def local_slurm():
    """A running single-node SLURM; daemons this fixture started are stopped afterwards."""
    pytest.importorskip("snakemake_executor_plugin_slurm", reason="snakemake-executor-plugin-slurm not installed")
    if shutil.which("bash") is None:
        pytest.skip("no bash to run start_local_slurm.sh")
    was_running = _slurm_answers()
    if not was_running:
        if os.geteuid() != 0:
            pytest.skip("SLURM is not running and installing/starting it needs root")
        if shutil.which("apt-get") is None and shutil.which("slurmctld") is None:
            pytest.skip("SLURM is not installed and there is no apt-get to install slurm-wlm")
    started = subprocess.run(["bash", str(START_SCRIPT), "start"], capture_output=True, text=True, timeout=600)
    reason = (started.stderr or started.stdout).strip()
    if started.returncode in (2, 3, 4):
        pytest.skip(f"local SLURM unavailable (start_local_slurm.sh exit {started.returncode}): {reason}")
    assert started.returncode == 0, f"start_local_slurm.sh failed:\n{started.stdout}\n{started.stderr}"
    if _cluster_name() != LOCAL_CLUSTER:
        # never submit test jobs to a real cluster that happens to answer on this host
        pytest.skip(f"SLURM cluster {_cluster_name()!r} answers here, not the local test cluster {LOCAL_CLUSTER!r}")
    yield
    if not was_running:
        subprocess.run(["bash", str(START_SCRIPT), "stop"], capture_output=True, text=True, timeout=60)


def _small_workflow(folder: Path) -> Path:
    """A copy of the workflow whose config runs a nine-export subset of the bundled agar dataset."""
    folder.mkdir(parents=True)
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    shutil.copy2(ROOT / "Snakefile", folder / "Snakefile")
    for part in ("workflow", "config", "src"):
        shutil.copytree(ROOT / part, folder / part, ignore=ignore)
    # only the scripts of the rules this run executes: every Snakemake start (the submitting one and two per SLURM
    # job) hashes the package sources each present rule script reaches (common.smk script_hash, ~1-2 s per
    # script on a shared 2-core machine); an absent script hashes as "script-absent" (a partial copy of the
    # workflow that never runs that rule). The rules, the DAG and the jobs run are the same.
    for script in (folder / "workflow" / "scripts").glob("*.py"):
        if script.name not in JOB_SCRIPTS:
            script.unlink()
    raw = folder / "raw" / DATASET
    raw.mkdir(parents=True)
    sheet = pd.read_csv(SOURCE_DATASET / "samples.csv", dtype=str, keep_default_na=False)
    sheet = sheet[sheet["file"].str.endswith(EXPORT_SUFFIXES)]
    assert len(sheet) == 9, "the agar dataset no longer has 3 amplitude sweeps, flow curves and creep runs"
    sheet.to_csv(raw / "samples.csv", index=False)
    for name in [*sheet["file"], "dataset.yaml", "truth.json"]:
        shutil.copy2(SOURCE_DATASET / name, raw / name)
    config_path = folder / "config" / "config.yaml"
    config = yaml.safe_load(config_path.read_text())
    config.update(raw_dir="raw", datasets=[DATASET], external_datasets={})
    config["fit"].update(multistart=1, models=FIT_MODELS, material={"enabled": False})
    config_path.write_text(yaml.safe_dump(config, sort_keys=False))
    return folder


def _snakemake(folder: Path, *options: str, niceness: int = 0) -> subprocess.Popen:
    log = open(folder / "snakemake_console.log", "w")
    command = ["nice", "-n", str(niceness), sys.executable, "-m", "snakemake", *options, *TARGETS]
    # own process group: a timeout interrupts snakemake (which then cancels its SLURM jobs)
    return subprocess.Popen(command, cwd=folder, env=_job_env(), stdout=log, stderr=subprocess.STDOUT,
                            start_new_session=True)


def _wait(process: subprocess.Popen, folder: Path) -> None:
    try:
        rc = process.wait(timeout=RUN_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGINT)
        process.wait(timeout=60)
        rc = f"timeout after {RUN_TIMEOUT_S} s"
    console = (folder / "snakemake_console.log").read_text()
    assert rc == 0, f"snakemake in {folder} ended with {rc}:\n{console[-6000:]}"


def _csv(path: Path) -> pd.DataFrame:
    return pd.read_csv(path, keep_default_na=False, na_values=[""])


def _assert_same_results(local: Path, slurm: Path) -> list[str]:
    """Every netCDF and CSV result of the two runs agrees (attributes and figures aside)."""
    results_local = local / "results" / DATASET
    files = sorted(p.relative_to(results_local) for p in results_local.rglob("*")
                   if p.suffix in (".nc", ".csv") and p.is_file())
    files_slurm = sorted(p.relative_to(slurm / "results" / DATASET)
                         for p in (slurm / "results" / DATASET).rglob("*")
                         if p.suffix in (".nc", ".csv") and p.is_file())
    assert files == files_slurm
    for rel in files:
        a, b = results_local / rel, slurm / "results" / DATASET / rel
        if rel.suffix == ".csv":
            pd.testing.assert_frame_equal(_csv(a), _csv(b), check_exact=False, rtol=1e-9, atol=0,
                                          obj=str(rel))
        else:
            with xr.open_dataset(a) as da, xr.open_dataset(b) as db:
                xr.testing.assert_allclose(da.load(), db.load(), rtol=1e-9, atol=0)
    return [str(rel) for rel in files]


def _megabytes(squeue_memory: str) -> int:
    """squeue's %m field (``1500M``, ``2G``) in MB."""
    factor = {"K": 1 / 1024, "M": 1, "G": 1024, "T": 1024**2}[squeue_memory[-1]]
    return round(float(squeue_memory[:-1]) * factor)


def _slurm_jobs() -> dict[str, dict]:
    """Job id -> state, comment (rule and wildcards), CPUs and memory (MB), as slurmctld reports them."""
    out = subprocess.run(["squeue", "--states=all", "-h", "-o", "%i|%T|%k|%C|%m"],
                         capture_output=True, text=True, timeout=20, check=True).stdout
    jobs = {}
    for line in out.splitlines():
        job_id, state, comment, cpus, memory = line.split("|")
        jobs[job_id] = {"state": state, "comment": comment, "cpus": int(cpus), "mem_mb": _megabytes(memory)}
    return jobs


def test_slurm_run_matches_local_run(local_slurm, tmp_path):
    local = _small_workflow(tmp_path / "local")
    slurm = _small_workflow(tmp_path / "slurm")
    slurm_run = _snakemake(slurm, "--workflow-profile", "workflow/profiles/slurm", *SLURM_OPTIONS)
    # the SLURM run is the longer one (four jobs one after another): the local run gives way to it
    local_run = _snakemake(local, "--cores", "2", niceness=10)
    _wait(local_run, local)
    _wait(slurm_run, slurm)

    compared = _assert_same_results(local, slurm)
    assert {f"ranking/{scope}.csv" for scope in FIT_MODELS} <= set(compared)
    assert "averages.nc" in compared and "lve.nc" in compared
    assert {f"fits/{scope}/{model}.nc" for scope, models in FIT_MODELS.items() for model in models} <= set(compared)

    # the results are right, not only equal: the flow-curve truth of the agar set is a power-law fluid
    truth = yaml.safe_load((slurm / "raw" / DATASET / "truth.json").read_text())["by_test"]["flow_curve"]
    assert truth["name"] == "power_law"
    with xr.open_dataset(slurm / "results" / DATASET / "fits" / "flow_curve" / "power_law.nc") as fit:
        fitted = dict(zip(fit["param"].values.tolist(), fit["value"].values.tolist()))
    np.testing.assert_allclose(fitted["K"], truth["params"]["K"], rtol=0.05)
    np.testing.assert_allclose(fitted["n"], truth["params"]["n"], atol=0.01)
    ranking = _csv(slurm / "results" / DATASET / "ranking" / "flow_curve.csv").set_index("model")
    assert ranking.loc["power_law", "rank"] == 1 and ranking.loc["newton", "rank"] == 2

    # every job went through SLURM: one submission per rule job, both fits in one group submission
    logs = slurm / ".snakemake" / "slurm_logs"
    submitted = {
        "ingest": sorted((logs / "rule_ingest" / DATASET).glob("*.log")),
        "average": sorted((logs / "rule_average" / DATASET).glob("*.log")),
        "fits": sorted((logs / "group_fits_fit_scope").glob("*.log")),
    }
    assert {name: len(paths) for name, paths in submitted.items()} == dict.fromkeys(submitted, 1), submitted
    group_log = submitted["fits"][0].read_text()
    assert all(f"scope={scope}" in group_log for scope in FIT_MODELS), group_log[-3000:]
    jobs = _slurm_jobs()
    profile = yaml.safe_load((slurm / "workflow" / "profiles" / "slurm" / "config.yaml").read_text())
    fit_mem_mb = profile["set-resources"]["fit_scope"]["mem_mb"]
    expected = {
        "ingest": (f"rule_ingest_wildcards_{DATASET}", 1, profile["default-resources"]["mem_mb"]),
        "average": (f"rule_average_wildcards_{DATASET}", 1, profile["set-resources"]["average"]["mem_mb"]),
        # independent members of a group run side by side: their CPUs and memory add up
        "fits": ("rule_fits_fit_scope", len(FIT_MODELS), len(FIT_MODELS) * fit_mem_mb),
    }
    for name, (comment, cpus, mem_mb) in expected.items():
        job_id = submitted[name][0].stem
        assert jobs[job_id] == {"state": "COMPLETED", "comment": comment, "cpus": cpus, "mem_mb": mem_mb}, name
    console = (slurm / "snakemake_console.log").read_text()
    assert console.count("has been submitted with SLURM jobid") == 3
    assert not (local / ".snakemake" / "slurm_logs").exists()
