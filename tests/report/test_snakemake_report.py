"""`snakemake --report` on a small run of the bundled agar dataset: categories, captions, embedded figures.

The workflow runs in a copy of the workflow tree under ``tmp_path`` (never in the checkout, whose results and
lock belong to the developer), restricted to ingest, averages, LVE and the flow-curve fits of one dataset.
"""
from __future__ import annotations

import base64
import io
import json
import os
import re
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from html.parser import HTMLParser
from pathlib import Path

import pandas as pd
import pytest
import yaml
from PIL import Image

# one worker runs the module-scoped workflow (small_run) for every test of this module: without a group,
# --dist loadgroup spreads the tests over both workers and each ran the workflow and the report once
pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("snakemake_report")]

DATASET = "agar_3pct_thesis"
TARGETS = [f"results/{DATASET}/lve.csv", f"results/{DATASET}/figures/fits/flow_curve"]
#: workflow/scripts of the rules that produce TARGETS
JOB_SCRIPTS = {"ingest.py", "average.py", "fit_scope.py"}


class _Scripts(HTMLParser):
    """Text of every ``<script id=...>`` and the page text outside scripts."""

    def __init__(self):
        super().__init__()
        self.scripts: dict[str, str] = {}
        self.text: list[str] = []
        self._current: str | None = None
        self._in_script = False

    def handle_starttag(self, tag, attrs):
        if tag == "script":
            self._in_script = True
            self._current = dict(attrs).get("id")
            if self._current:
                self.scripts[self._current] = ""

    def handle_endtag(self, tag):
        if tag == "script":
            self._in_script, self._current = False, None

    def handle_data(self, data):
        if self._current:
            self.scripts[self._current] += data
        elif not self._in_script:
            self.text.append(data)


def _script_json(scripts: dict[str, str], script_id: str, name: str):
    match = re.fullmatch(rf"\s*var {name} = (.*);\s*", scripts[script_id], re.S)
    assert match, f"<script id={script_id}> does not assign {name}"
    return json.loads(match.group(1))


def _snakemake(workdir: Path, *args: str) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    env.setdefault("MPLBACKEND", "Agg")
    env.setdefault("HDF5_USE_FILE_LOCKING", "FALSE")
    cmd = [sys.executable, "-m", "snakemake", "--cores", "2", *args, "--config", f'datasets=["{DATASET}"]']
    done = subprocess.run(cmd, cwd=workdir, env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, f"{' '.join(cmd)} failed:\n{done.stderr[-4000:]}"
    return done


@pytest.fixture(scope="module")
def small_run(tmp_path_factory, repo_root):
    work = tmp_path_factory.mktemp("report_wf")
    shutil.copy(repo_root / "Snakefile", work)
    for folder in ("workflow", "config"):
        shutil.copytree(repo_root / folder, work / folder, ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copytree(repo_root / "raw" / DATASET, work / "raw" / DATASET)
    # only the scripts of the rules TARGETS run: each Snakemake start hashes the package sources every present
    # rule script reaches (common.smk script_hash); an absent script hashes as "script-absent" (a partial copy
    # of the workflow that never runs that rule). The rules, the DAG, the jobs and the report are the same.
    for script in (work / "workflow" / "scripts").glob("*.py"):
        if script.name not in JOB_SCRIPTS:
            script.unlink()
    _snakemake(work, *TARGETS)
    _snakemake(work, "--report", "results/report.html", *TARGETS)
    return work


@pytest.fixture(scope="module")
def report(small_run):
    parser = _Scripts()
    parser.feed((small_run / "results" / "report.html").read_text(encoding="utf-8"))
    return parser


def test_report_has_a_category_per_dataset_and_stage(report, repo_root):
    categories = _script_json(report.scripts, "categories", "categories")
    assert set(categories) == {DATASET}
    assert set(categories[DATASET]) == {"0 ingest", "1 raw runs vs averages", "2 LVE limit", "3 fits: flow_curve"}
    results = _script_json(report.scripts, "results", "results")
    fits = [results[path] for path in categories[DATASET]["3 fits: flow_curve"]]
    config = yaml.safe_load((repo_root / "config" / "config.yaml").read_text())
    assert {r["labels"]["model"] for r in fits} == set(config["fit"]["models"]["flow_curve"])
    sweeps = [results[path]["labels"] for path in categories[DATASET]["2 LVE limit"]]
    assert {"source": "average", "sweep": "frequency_hz-1"} in sweeps
    workflow_text = json.loads(report.scripts["workflow-desc"].split("=", 1)[1].strip().rstrip(";"))
    assert "soft-tissue rheometry" in workflow_text and "20261122" in workflow_text  # Jinja saw the config


def test_embedded_results_decode_and_carry_their_captions(report):
    results = _script_json(report.scripts, "results", "results")
    kinds = {}
    for path, result in results.items():
        header, payload = result["data_uri"].split(",", 1)
        assert header.endswith(";base64"), f"{path} is not embedded"
        data = base64.b64decode(payload)
        mime = result["mime_type"]
        kinds[mime] = kinds.get(mime, 0) + 1
        if mime == "image/png":
            with Image.open(io.BytesIO(data)) as image:
                image.verify()
                assert image.size[0] >= 300 and image.size[1] >= 200, path
        elif mime == "image/svg+xml":
            assert ET.fromstring(data).tag.endswith("svg")
        elif mime == "text/csv":
            assert len(pd.read_csv(io.BytesIO(data))) > 0, path
        assert DATASET in result["caption"], f"{path}: caption does not name its dataset"
    assert kinds.get("image/png", 0) >= 8 + 4 + 5  # averages, LVE sweeps, flow-curve fits
    assert kinds.get("text/csv", 0) == 2  # ingest report, LVE table


def test_figures_have_svg_twins_and_jobs_have_logs_and_benchmarks(small_run):
    figures = small_run / "results" / DATASET / "figures"
    pngs = sorted(figures.rglob("*.png"))
    assert pngs and all(p.with_suffix(".svg").is_file() for p in pngs)
    for job in ("ingest", "average", "fit_flow_curve"):
        assert (small_run / "logs" / DATASET / f"{job}.log").is_file(), job
        assert (small_run / "benchmarks" / "runs" / DATASET / f"{job}.tsv").is_file(), job
    # the fit job draws its scope's figures itself (no separate figure job paying the start-up again)
    assert "fit figures" in (small_run / "logs" / DATASET / "fit_flow_curve.log").read_text()


def test_report_renders_in_headless_chromium(small_run, tmp_path, headless):
    report_html = small_run / "results" / "report.html"
    dom = headless(report_html, "--dump-dom").stdout
    rendered = _Scripts()
    rendered.feed(dom)
    text = " ".join(rendered.text)
    # the sidebar and the workflow description are built by the report's JavaScript from its data scripts:
    # outside <script> they exist only when the app ran
    assert "Statistics" in text and "Results" in text and "soft-tissue rheometry" in text
    shot = tmp_path / "report.png"
    headless(report_html, f"--screenshot={shot}", "--window-size=1280,900")
    with Image.open(shot) as image:
        colours = image.convert("L").getcolors(maxcolors=1 << 16)
        assert colours is not None and len(colours) > 20, "blank screenshot"


def test_embedded_figures_decode_in_chromium(report, tmp_path, headless):
    results = _script_json(report.scripts, "results", "results")
    uris = [r["data_uri"] for r in results.values() if r["mime_type"].startswith("image/")]
    images = "".join(f'<img src="{uri}">' for uri in uris)
    page = tmp_path / "images.html"
    page.write_text(
        "<html><body>" + images + "<script>window.addEventListener('load', () => {"
        "const imgs = [...document.images];"
        "document.body.setAttribute('data-loaded', imgs.filter(i => i.complete && i.naturalWidth > 0).length);"
        "document.body.setAttribute('data-broken', imgs.filter(i => !(i.naturalWidth > 0)).length);});"
        "</script></body></html>")
    dom = headless(page, "--dump-dom").stdout
    assert f'data-loaded="{len(uris)}"' in dom and 'data-broken="0"' in dom
