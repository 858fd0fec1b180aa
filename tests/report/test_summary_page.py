"""The summary pages answer per dataset: a verdict card (recommended model per scope, misfit in noise units,
held-out and cross-test prediction, the diagnosis in plain words with what to do), a table of contents whose links
all land, every table in full with its CSV, cards as HTML tables, figures linked (not embedded) and loaded lazily,
no template placeholder and no "nan" shown as a value.

A small results tree with known contents is built here; the same checks run on the pipeline's own ``results/``
when it exists (``TISSUEMECH_RESULTS`` names another results folder), and in a headless Chromium where one is
installed (the ``headless`` fixture of ``conftest.py``; skipped with the reason otherwise)."""
from __future__ import annotations

import json
import os
import re
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote

import pandas as pd
import pytest
import yaml

from tissuemech.diagnosis.findings import fix_record, make_finding, untested_finding, write_diagnosis_json
from tissuemech.plots import plot_timings
from tissuemech.summary import build_summary, results_datasets

ROOT = Path(__file__).resolve().parents[2]
RESULTS = Path(os.environ.get("TISSUEMECH_RESULTS", ROOT / "results"))
MAX_MAIN_PAGE_BYTES = 8_000_000


class _Page(HTMLParser):
    """Ids, links, image sources and visible text of a page."""

    def __init__(self):
        super().__init__()
        self.ids: set[str] = set()
        self.links: list[str] = []
        self.sources: list[str] = []
        self.text: list[str] = []
        self.lazy: list[bool] = []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if "id" in a:
            self.ids.add(a["id"])
        if tag == "a" and "href" in a:
            self.links.append(a["href"])
        if tag == "img":
            self.sources.append(a.get("src", ""))
            self.lazy.append(a.get("loading") == "lazy")

    def handle_data(self, data):
        self.text.append(data)


def _parse(path: Path) -> _Page:
    page = _Page()
    page.feed(path.read_text(encoding="utf-8"))
    return page


def check_pages(main: Path) -> list[Path]:
    """The checks every summary must pass; returns the pages checked (the main page and the dataset pages)."""
    assert main.stat().st_size < MAX_MAIN_PAGE_BYTES
    pages = [main] + sorted(main.parent.glob("*/summary.html"))
    for path in pages:
        page = _parse(path)
        raw = path.read_text(encoding="utf-8")
        assert "data:image" not in raw, f"{path}: embedded figure"
        text = " ".join(page.text)
        placeholders = re.findall(r"<(?:model|scope|figure|dataset|test|condition|variable|sweep|case|experiment)>",
                                  text)
        assert not placeholders, f"{path}: template placeholders {placeholders}"
        shown_nan = re.findall(r".{40}\bnan\b.{20}", text)
        assert not re.search(r"\bnan\b", text), f"{path}: nan shown as a value: {shown_nan}"
        assert "not produced" not in text
        for link in page.links:
            if link.startswith("#"):
                assert link[1:] in page.ids, f"{path}: table-of-contents link {link} lands nowhere"
            elif not re.match(r"\w+:", link):
                assert (path.parent / unquote(link)).exists(), f"{path}: broken link {link}"
        for src in page.sources:
            assert (path.parent / unquote(src)).is_file(), f"{path}: missing figure {src}"
        assert all(page.lazy), f"{path}: a figure loaded eagerly"
    return pages


def _results_tree(root: Path) -> Path:
    """results/ of two datasets: ``gel`` (two scopes, one without a recommendable fit; a diagnosis with a named
    cause that says what to do; figures; a card; constant-shear-rate runs but no FEM result) and ``bare`` (ingest
    only: every file rejected)."""
    gel = root / "gel"
    (gel / "cards" / "stress_relaxation").mkdir(parents=True)
    pd.DataFrame({"run": ["g1", "g2", "g3"], "file": ["a.csv", "b.csv", "c.csv"],
                  "test": ["stress_relaxation", "constant_shear_rate", "frequency_sweep"],
                  "status": ["ok", "ok", "error"], "reason": ["", "", "c.csv line 4, column 2: not a number"]}
                 ).to_csv(gel / "ingest_report.csv", index=False)
    pd.DataFrame({
        "dataset": "gel", "scope": ["stress_relaxation", "stress_relaxation", "frequency_sweep"],
        "model": ["prony2", "sls1", "springpot"], "rank": [1, 2, 1], "nrmse": [0.031, 0.05, 0.2],
        "cv_nrmse": [0.042, float("nan"), float("nan")], "misfit_noise_units": [1.7, 2.5, 40.0],
        "recommended": [True, False, False], "n_flags": [0, 0, 2], "flags": ["", "", "at_bound: alpha"],
        "recommendation": ["Thesis criteria: max strain 10 %, rate/time-dependent -> qlv.",
                           "Thesis criteria: max strain 10 %, rate/time-dependent -> qlv.",
                           "Thesis criteria: max strain nan %, rate-independent (loss_factor) -> linear elastic. "
                           "No model is recommended: no fit is converged with a covariance and no parameter at a "
                           "bound (springpot (alpha at a bound))."]}).to_csv(gel / "ranking.csv", index=False)
    pd.DataFrame({"held_out_test": ["constant_shear_rate"], "model": ["prony2"], "nrmse": [0.123],
                  "n_points": [80]}).to_csv(gel / "cross_test.csv", index=False)
    (gel / "cards" / "stress_relaxation" / "prony2.json").write_text(json.dumps({
        "model": "prony2", "elastic_law": "neo_hookean", "elastic_parameters": {"mu": 812.5},
        "initial_shear_modulus": 812.5, "bulk_modulus": 4.0e4, "prony": {"g": [0.3, 0.2], "tau": [0.5, 20.0]},
        "fit_quality": {"nrmse": 0.031, "flags": []}}))
    test = {"statistic": 8.1, "p_value": 1e-12, "log10_p": -12.0}
    named = make_finding("instrument_inertia", test, "t", 4.5e-8, "kg m2", True, "G' bends down as omega^2",
                         fix_record("inertia term", "rms_rel_residual", 0.021, 0.016, "leave-one-sweep-out"),
                         detected=True, significant=True, p_holm=1e-11,
                         what_to_do="calibrate the motor inertia again before the next sweeps")
    quiet = make_finding("wall_slip", test, "t", 0.01, "x", False, "no loss above a critical stress", None,
                         detected=False, significant=True, p_holm=1e-3)
    write_diagnosis_json({"model": "prony2", "alpha": 0.01, "baseline": {"model": "prony2", "adequate": True},
                          "findings": [named, quiet, untested_finding("temperature_dependence",
                                                                      "not testable here: runs at 1 temperature")],
                          "not_identifiable": [{"effect": "unidentified_i2_dependence", "evidence": "shear only"}],
                          "unexplained": [], "confounded": []}, gel / "diagnosis.json", dataset="gel")
    plot_timings(["a", "b"], [1.0, 2.0], gel / "figures" / "fits" / "stress_relaxation" / "prony2")
    plot_timings(["a"], [1.0], gel / "figures" / "averages" / "stress_relaxation__default__shear_stress")
    bare = root / "bare"
    bare.mkdir()
    pd.DataFrame({"run": ["x"], "file": ["x.csv"], "test": ["amplitude_sweep"], "status": ["error"],
                  "reason": ["x.csv: unrecognised export format"]}).to_csv(bare / "ingest_report.csv", index=False)
    return root


@pytest.fixture(scope="module")
def summary(tmp_path_factory) -> Path:
    root = _results_tree(tmp_path_factory.mktemp("results"))
    config = {"fit": {"seed": 424242, "plate_target": "torque"}, "fem": {"poisson_ratio": 0.45},
              "diagnosis": {"alpha": 0.01}}
    return build_summary(root, results_datasets(root), root / "summary.html",
                         captions_dir=ROOT / "workflow" / "report", config=config)


def test_pages_are_small_linked_and_free_of_placeholders(summary):
    pages = check_pages(summary)
    assert [p.parent.name for p in pages[1:]] == ["bare", "gel"]
    main = _parse(summary)
    assert {"ds-gel", "ds-bare"} <= main.ids and "gel/summary.html" in main.links
    gel = _parse(summary.parent / "gel" / "summary.html")
    assert {"verdict", "diagnosis", "ranking", "cards", "fem", "ingest", "fits", "averages"} <= gel.ids
    assert sorted(gel.sources) == ["figures/averages/stress_relaxation__default__shear_stress.png",
                                   "figures/fits/stress_relaxation/prony2.png"]


def test_verdict_card_answers_which_model_how_good_and_what_is_wrong(summary):
    text = summary.read_text()
    verdict = text[text.index('id="ds-gel"'):]
    row = re.search(r"<tr><td>stress_relaxation</td>(.*?)</tr>", verdict).group(1)
    assert re.findall(r"<td>(.*?)</td>", row) == ["prony2", "1.7", "0.031", "0.042",
                                                  "constant_shear_rate: NRMSE 0.123 (80 points)"]
    assert ("no model recommended: no fit is converged with a covariance and no parameter at a bound "
            "(springpot (alpha at a bound))") in verdict
    assert "The instrument&#x27;s inertia correction is off" in verdict
    assert "What to do: calibrate the motor inertia again before the next sweeps" in verdict
    assert "gain 0.238" in verdict                                      # (0.021 - 0.016) / 0.021
    assert "wall_slip" not in verdict[:verdict.index("</section>")]   # not named, so not in the verdict
    assert "max strain not measured" in verdict


def test_dataset_page_has_full_tables_csv_links_and_cards_as_html(summary):
    gel = (summary.parent / "gel" / "summary.html").read_text()
    assert '<a href="ranking.csv" download>ranking.csv</a>: 3 rows' in gel
    assert '<a href="ingest_report.csv" download>ingest_report.csv</a>: 3 rows' in gel
    assert "c.csv line 4, column 2: not a number" in gel
    cards = gel[gel.index('id="cards"'):gel.index('id="fem"')]
    assert "<img" not in cards and "<td>prony2</td>" in cards and "<td>mu=812.5</td>" in cards
    # why there is no torsion, in words: the dataset has ramps, so the job did not finish
    assert "No FEM torsion result: the fem_torsion job did not finish (logs/gel/fem_torsion.log)" in gel
    diagnosis = gel[gel.index('id="diagnosis"'):gel.index('id="ranking"')]
    assert "significant, too small to matter" in diagnosis and "not testable" in diagnosis
    assert "not testable here: runs at 1 temperature" in diagnosis
    bare = (summary.parent / "bare" / "summary.html").read_text()
    assert "No model was fitted: no run was ingested" in bare
    assert "x.csv: unrecognised export format" in bare


def test_verdict_says_not_available_where_the_tables_lack_the_columns(tmp_path):
    root = _results_tree(tmp_path / "results")
    ranking = pd.read_csv(root / "gel" / "ranking.csv").drop(columns=["misfit_noise_units"])
    ranking.to_csv(root / "gel" / "ranking.csv", index=False)
    (root / "gel" / "cross_test.csv").unlink()
    page = build_summary(root, ["gel"], root / "summary.html")
    row = re.search(r"<tr><td>stress_relaxation</td>(.*?)</tr>", page.read_text()).group(1)
    assert re.findall(r"<td>(.*?)</td>", row) == ["prony2", "not available", "0.031", "0.042", "not available"]


def test_verdict_shows_a_scope_where_no_model_is_supported(tmp_path):
    root = _results_tree(tmp_path / "results")
    ranking = pd.read_csv(root / "gel" / "ranking.csv")
    ranking["verdict"] = ["no_model_supported", "no_model_supported", ""]
    ranking["verdict_reason"] = ["every candidate misfits by more than 10 noise SDs"] * 2 + [""]
    ranking.to_csv(root / "gel" / "ranking.csv", index=False)
    text = build_summary(root, ["gel"], root / "summary.html").read_text()
    assert ("<td>stress_relaxation</td><td colspan='5' class='none'>no model supported: every candidate misfits by "
            "more than 10 noise SDs</td>") in text


def test_the_pipeline_results_pass_the_same_checks(tmp_path):
    """The summary of the shipped results (after `make run`), written to a temporary folder."""
    if not (RESULTS / "summary.html").is_file():
        pytest.skip(f"no pipeline results in {RESULTS} (run `make run` first, or set TISSUEMECH_RESULTS)")
    config = yaml.safe_load((ROOT / "config" / "config.yaml").read_text())
    main = build_summary(RESULTS, results_datasets(RESULTS), tmp_path / "summary.html",
                         captions_dir=ROOT / "workflow" / "report", config=config)
    pages = check_pages(main)
    assert len(pages) == len(results_datasets(RESULTS)) + 1


def test_pages_render_in_a_headless_browser_without_console_errors(summary, headless, tmp_path):
    """Each page in Chromium: no console message (a script error, a refused resource), every table-of-contents link
    lands in the rendered page, and every figure of the dataset page decodes (loaded in a frame of a probe page)."""
    for path in (summary, summary.parent / "gel" / "summary.html"):
        done = headless(path, "--dump-dom")
        console = [line for line in done.stderr.splitlines() if ":CONSOLE" in line]
        assert console == [], console
        rendered = _Page()
        rendered.feed(done.stdout)
        for link in rendered.links:
            if link.startswith("#"):
                assert link[1:] in rendered.ids, f"{path}: {link} lands nowhere in the rendered page"
        assert "<nav>" in done.stdout and "Contents" in done.stdout
    page = summary.parent / "gel" / "summary.html"
    sources = [str((page.parent / unquote(s)).resolve().as_uri()) for s in _parse(page).sources]
    probe = tmp_path / "probe.html"
    probe.write_text("<html><body>" + "".join(f'<img src="{s}">' for s in sources) + "<script>"
                     "window.addEventListener('load', () => {const imgs = [...document.images];"
                     "document.body.setAttribute('data-loaded', imgs.filter(i => i.naturalWidth > 0).length);"
                     "document.body.setAttribute('data-broken', imgs.filter(i => !(i.naturalWidth > 0)).length);});"
                     "</script></body></html>")
    dom = headless(probe, "--dump-dom", "--allow-file-access-from-files").stdout
    assert sources and f'data-loaded="{len(sources)}"' in dom and 'data-broken="0"' in dom
