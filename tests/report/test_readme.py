"""The README is for users: short, every link lands, its Python examples and the key docstrings run (doctest), every
command it shows exists, no commit hash, date or word about how the work was organised, and the figures it quotes
are those of the committed reference tables (always) and of the shipped results (after `make run`; skipped with the
reason before)."""
from __future__ import annotations

import doctest
import importlib
import json
import os
import re
from pathlib import Path

import pandas as pd
import pytest

from tissuemech.cli import SUBCOMMANDS

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
RESULTS = Path(os.environ.get("TISSUEMECH_RESULTS", ROOT / "results"))
#: modules whose docstring examples are part of the documentation
DOCTEST_MODULES = ("tissuemech.plots", "tissuemech.summary", "tissuemech.cli")


@pytest.fixture(scope="module")
def text() -> str:
    return README.read_text(encoding="utf-8")


def _flat(text: str) -> str:
    """The text with every run of white space as one blank (a quoted figure may break across lines)."""
    return " ".join(text.split())


def _sci(value: float, digits: int = 3) -> str:
    """``4.49e-8`` (as written in the README) for 4.49e-08."""
    return re.sub(r"e([+-])0*(\d)", lambda m: "e" + ("-" if m.group(1) == "-" else "") + m.group(2),
                  f"{value:.{digits}g}")


def test_readme_is_short_and_says_nothing_about_how_the_work_was_organised(text):
    assert len(text.splitlines()) <= 300
    hashes = [h for h in re.findall(r"\b[0-9a-f]{7,40}\b", text) if re.search(r"\d", h) and re.search(r"[a-f]", h)]
    assert hashes == [], f"commit hashes: {hashes}"
    assert re.findall(r"\b20\d\d-\d\d-\d\d\b|\b\d{1,2} (?:Jan|Feb|Mar|Apr|May|Jun|Jul|Aug|Sep|Oct|Nov|Dec)\w* 20\d\d",
                      text) == []
    for word in (r"\bsessions?\b", r"\bissues? ?#?\d", r"\bloan", r"\blent\b", r"science\.md", r"\bhelpers?\b"):
        assert not re.search(word, text, re.I), word


def test_every_link_lands(text):
    for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text):
        if not re.match(r"\w+://", target):
            assert (ROOT / target).exists(), f"README links to a missing {target}"
    for doc in sorted((ROOT / "docs").glob("*.md")):
        for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", doc.read_text(encoding="utf-8")):
            if not re.match(r"\w+://", target):
                assert (doc.parent / target).exists(), f"{doc.name} links to a missing {target}"


def test_readme_examples_run():
    failures, tried = doctest.testfile(str(README), module_relative=False, optionflags=doctest.ELLIPSIS)
    assert tried >= 4 and failures == 0


@pytest.mark.parametrize("name", DOCTEST_MODULES)
def test_docstring_examples_run(name):
    failures, tried = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS)
    assert tried >= 1 and failures == 0


def test_every_command_shown_exists(text):
    code = re.findall(r"```.*?```", text, re.S) + re.findall(r"`[^`\n]+`", text)   # code blocks and code spans
    shown = {name for chunk in code for name in re.findall(r"tissuemech ([a-z]\w*)", chunk)}
    assert shown and shown <= set(SUBCOMMANDS), shown - set(SUBCOMMANDS)
    assert {"run", "report", "check"} <= shown


def _reference(dataset: str, scope: str, model: str, parameter: str) -> pd.Series:
    table = pd.read_csv(ROOT / "tests" / "regression" / f"{dataset}.csv")
    row = table[(table.scope == scope) & (table.model == model) & (table.parameter == parameter)]
    assert len(row) == 1, (dataset, scope, model, parameter)
    return row.iloc[0]


def test_fitted_figures_are_those_of_the_reference_tables(text):
    brain = _reference("porcine_brain_thesis", "amplitude_sweep", "linear_elastic", "G")
    text = _flat(text)
    assert f"G = {brain.value:.1f} ± {brain.stderr:.1f} Pa" in text
    agar = _reference("agar_3pct_thesis", "amplitude_sweep", "linear_elastic", "G")
    assert f"linear G = {agar.value:.0f} ± {agar.stderr:.0f} Pa" in text
    k = _reference("agar_3pct_thesis", "flow_curve", "power_law", "K")
    n = _reference("agar_3pct_thesis", "flow_curve", "power_law", "n")
    assert f"K = {k.value:.1f} Pa sⁿ, n = {n.value:.3g}" in text


def _results(dataset: str, name: str) -> Path:
    path = RESULTS / dataset / name
    if not path.exists():
        pytest.skip(f"{path} absent (run `make run` first, or set TISSUEMECH_RESULTS)")
    return path


def _named(dataset: str) -> dict[str, dict]:
    findings = json.loads(_results(dataset, "diagnosis.json").read_text())["findings"]
    return {f["effect"]: f for f in findings if f["detected"]}


def test_brain_figures_are_those_of_the_shipped_results(text):
    text = _flat(text)
    ranking = pd.read_csv(_results("porcine_brain_thesis", "ranking.csv"))
    material = ranking[ranking.scope == "material"].set_index("model")
    chosen = material[material["recommended"].astype(bool)]
    assert len(chosen) == 1 and chosen.index[0] == "qlv_rp3_prony4" and f"`{chosen.index[0]}`" in text
    assert f"misfit {chosen['misfit_noise_units'].iloc[0]:.2g} noise SDs" in text
    cross = pd.read_csv(_results("porcine_brain_thesis", "cross_test.csv"))
    sweep = cross[(cross.scope == "material") & (cross.held_out_test == "amplitude_sweep")]["skill"].iloc[0]
    assert f"amplitude sweep (skill {sweep:.2f})".replace("-", "−") in text
    named = _named("porcine_brain_thesis")
    assert set(named) == {"nonseparable_relaxation", "amplitude_softening", "instrument_inertia"}
    nonsep = named["nonseparable_relaxation"]["fix"]
    assert f"with gain {nonsep['gain']:.2g};" in text
    sim = nonsep["simulation"]
    assert (f"the NRMSE falls from {sim['before']:.2g} to {sim['after']:.2g}, gain {sim['gain']:.2g};") in text
    felt = pd.read_csv(_results("porcine_brain_thesis", "uq/extension_indentation.csv"))
    felt = felt[felt["cause"] == "nonseparable_relaxation"].set_index("geometry")
    flat, brain = felt.loc["flat punch on a tissue block"], felt.loc["MNI brain"]
    band = "outside" if flat["outside_measurement_band"] else "inside"
    change = f"{100 * flat['relative_difference']:.2g}".replace("-", "−")
    assert (f"in a {1e3 * flat['depth_m']:.2g} mm flat-punch indentation its card changes the force by "
            f"{change} %, {band} the baseline's posterior band") in text
    band = "outside" if brain["outside_measurement_band"] else "inside"
    spread = "outside" if brain["outside_specimen_band"] else "inside"
    change = f"{100 * brain['relative_difference']:.2g}".replace("-", "−")
    assert (f"pressed {1e3 * brain['depth_m']:.2g} mm into the MNI brain it changes the force by {change} %, "
            f"{band} the posterior band taken relative, {spread} the specimen spread, with "
            f"{int(brain['punch_nodes'])} surface node") in text
    assert f"`amplitude_softening` (gain {named['amplitude_softening']['fix']['gain']:.2g})" in text
    inertia = named["instrument_inertia"]
    assert f"dI = {_sci(inertia['effect_size'])} kg m², gain {inertia['fix']['gain']:.2g})" in text
    torsion = pd.read_csv(_results("porcine_brain_thesis", "fem/torsion.csv")).set_index(["card", "rate_1_s"])["nrmse"]
    card = f"material/{chosen.index[0]}"
    assert (f"within {torsion[card, 0.001]:.2g} (NRMSE) of the measured torque at 0.001 1/s and "
            f"{torsion[card, 0.1]:.2g} at 0.1 1/s") in text


def test_real_data_figures_are_those_of_the_shipped_results(text):
    import xarray as xr

    text = _flat(text)
    assert "amplitude_softening" in _named("agar_3pct_thesis")
    for name in ("agar_3pct_thesis", "trios", "rheocompass_cnf_hydrogel"):
        ranking = pd.read_csv(_results(name, "ranking.csv"))
        assert (ranking.loc[ranking.scope == "material", "verdict"] == "no_model_supported").all(), name
    assert {"amplitude_softening", "yield_or_slip"} <= set(_named("trios"))
    tts = xr.open_dataset(_results("ta_lims", "tts.nc"))
    a = tts.attrs
    assert "temperature_dependence" in _named("ta_lims")
    assert (f"WLF C1 = {a['wlf_c1']:.3g}, C2 = {a['wlf_c2_k']:.3g} K at {a['t_ref_c']:.1f} °C, and a held-out "
            f"temperature is predicted to {a['held_out_rms_decades']:.2g} decades against "
            f"{a['held_out_rms_unshifted_decades']:.3g} without") in text
    points = _named("trios")["inertia_dominated_points"]
    n_osc = int(re.search(r"of (\d+) oscillation points", points["evidence"]).group(1))
    assert f"{len(points['points'])} of {n_osc} oscillation points are dominated by instrument inertia" in text
    assert f"(gain {points['fix']['gain']:.2g})" in text
    for region in ("cortex", "corona_radiata", "basal_ganglia", "corpus_callosum"):
        assert {"tension_compression_asymmetry", "unidentified_i2_dependence"} <= set(_named(f"budday_{region}"))
