"""Fitted-parameter regression: fresh fits of the bundled datasets against the committed tables in this folder."""
from __future__ import annotations

import logging

import math
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from tissuemech import regression as REG
from tissuemech.models.registry import FIXED_TIME_KEY

# one worker computes the fresh fits once for every test of this module (make test runs with --dist loadgroup)
pytestmark = pytest.mark.xdist_group("fit_regression")


@pytest.fixture(scope="module")
def reference_dir(repo_root):
    return repo_root / "tests" / "regression"


@pytest.fixture(scope="module")
def fresh(repo_root):
    return REG.fresh_table(repo_root / "raw", repo_root / "config" / "config.yaml")


@pytest.fixture
def reference_copy(tmp_path, reference_dir):
    for path in reference_dir.glob("*.csv"):
        shutil.copy(path, tmp_path / path.name)
    return tmp_path


def _perturb(folder, dataset, scope, model, parameter, tolerances):
    """Shift one committed value by ``tolerances`` of its own tolerance; return (old value, tolerance)."""
    path = folder / f"{dataset}.csv"
    table = pd.read_csv(path)
    row = (table["scope"] == scope) & (table["model"] == model) & (table["parameter"] == parameter)
    assert row.sum() == 1, f"{dataset}/{scope}/{model}/{parameter} not exactly once in {path}"
    old, tol = float(table.loc[row, "value"].iloc[0]), float(table.loc[row, "tolerance"].iloc[0])
    table.loc[row, "value"] = old + tolerances * tol
    table.to_csv(path, index=False)
    return old, tol


def test_fresh_fits_pass_the_committed_table(reference_dir, fresh):
    passed, comparison, message = REG.check(reference_dir, fresh=fresh)
    assert passed, message
    fitted = set(zip(comparison["dataset"], comparison["scope"], comparison["model"]))
    wanted = {(d, s, m) for d, scopes in REG.REFERENCE_FITS.items() for s, models in scopes.items() for m in models
              if m != REG.MATERIAL_BASELINE}
    # the material scope's baseline is held under the key the data chose (one fixed-time QLV model)
    material = {(d, s) for d, scopes in REG.REFERENCE_FITS.items() for s, models in scopes.items()
                if REG.MATERIAL_BASELINE in models}
    assert {f for f in fitted if f[:2] not in material} == wanted
    chosen = [f for f in fitted if f[:2] in material]
    assert {f[:2] for f in chosen} == material and len(chosen) == len(material)
    assert all(FIXED_TIME_KEY.fullmatch(m) for _, _, m in chosen), chosen
    # a deterministic refit reproduces the table far inside the tolerance (the chosen optimum is polished to 1e-12,
    # so a flat valley's stopping point does not depend on the machine's rounding: fitting.POLISH_TOL)
    assert comparison["difference/tolerance"].abs().max() < 0.01


@pytest.mark.parametrize("dataset, scope, model, parameter", [
    ("porcine_brain_thesis", "constant_shear_rate", "reduced_polynomial3", "C10"),
    ("agar_3pct_thesis", "flow_curve", "power_law", "n"),
])
def test_a_perturbed_reference_value_fails_naming_the_parameter(reference_copy, fresh, dataset, scope, model,
                                                                parameter):
    _perturb(reference_copy, dataset, scope, model, parameter, 5.0)
    passed, comparison, message = REG.check(reference_copy, fresh=fresh)
    assert not passed
    bad = comparison[comparison["status"] != "ok"]
    failing = list(zip(bad["dataset"], bad["scope"], bad["model"], bad["parameter"]))
    assert failing == [(dataset, scope, model, parameter)]
    # fresh - reference = -5 tolerances; the message table names the row and says by how much
    assert bad["difference/tolerance"].iloc[0] == pytest.approx(-5.0, abs=0.01)
    line = next(ln for ln in message.splitlines() if f" {model} " in ln and f" {parameter} " in ln)
    assert dataset in line and scope in line and "-5" in line and "moved" in line
    assert "difference/tolerance" in message


def test_a_shift_inside_the_tolerance_passes(reference_copy, fresh):
    _perturb(reference_copy, "porcine_brain_thesis", "constant_shear_rate", "reduced_polynomial3", "C10", 0.5)
    passed, _, message = REG.check(reference_copy, fresh=fresh)
    assert passed, message


def test_check_command_exits_1_with_the_table(reference_copy, fresh, monkeypatch, capsys):
    _perturb(reference_copy, "agar_3pct_thesis", "creep_recovery", "sls2", "eta1", 5.0)
    monkeypatch.setattr(REG, "fresh_table", lambda *a, **k: fresh)
    package = logging.getLogger("tissuemech")
    level = package.level
    assert REG.main(["--check", "--reference-dir", str(reference_copy)]) == 1
    assert package.level == level  # the CLI's quiet logging does not leak into the calling process
    out = capsys.readouterr().out
    assert "1 of" in out and "creep_recovery" in out and "eta1" in out and "make regression-update" in out


def test_a_changed_pipeline_setting_fails_the_check(repo_root, reference_dir, monkeypatch):
    """A code-side regression: fitting 20 instead of 40 points per curve moves the agar fits beyond tolerance."""
    from tissuemech import stages

    monkeypatch.setattr(stages, "POINTS_PER_CURVE", 20)
    passed, comparison, message = REG.check(reference_dir, raw_dir=repo_root / "raw",
                                            config_path=repo_root / "config" / "config.yaml",
                                            datasets=["agar_3pct_thesis"])
    assert not passed
    assert set(comparison["dataset"]) == {"agar_3pct_thesis"}
    moved = comparison[comparison["status"] == "moved"]
    assert len(moved) >= 3 and (moved["difference/tolerance"].abs() > 1).all()
    assert all(f" {p} " in message for p in moved["parameter"])


def test_update_of_one_dataset_leaves_the_other_table(platform_reference, fresh):
    reference_copy = platform_reference
    brain = (reference_copy / "porcine_brain_thesis.csv").read_text()
    (reference_copy / "porcine_brain_thesis.csv").write_text(brain.replace("0.1 x standard error", "edited"))
    written, diff = REG.update(reference_copy, fresh=fresh, datasets=["agar_3pct_thesis"])
    assert written == [reference_copy / "agar_3pct_thesis.csv"]
    assert diff.startswith("reference unchanged: 11 parameters")
    assert "edited" in (reference_copy / "porcine_brain_thesis.csv").read_text()


@pytest.fixture
def platform_reference(reference_copy, fresh):
    """The committed tables rewritten with this machine's fits: the last bits of a refit differ between
    processors (far inside the tolerance, see above), and the update tests are about the diff they print."""
    REG.update(reference_copy, fresh=fresh)
    return reference_copy


def test_update_rewrites_the_tables_and_prints_the_diff(platform_reference, fresh, monkeypatch, capsys):
    reference_copy = platform_reference
    old, _ = _perturb(reference_copy, "porcine_brain_thesis", "frequency_sweep", "springpot", "alpha", 3.0)
    monkeypatch.setattr(REG, "fresh_table", lambda *a, **k: fresh)
    assert REG.main(["--update", "--reference-dir", str(reference_copy)]) == 0
    out = capsys.readouterr().out
    assert out.startswith("1 of ") and "springpot" in out and "alpha" in out and "-3" in out
    rewritten = REG.read_reference_file(reference_copy / "porcine_brain_thesis.csv")
    alpha = rewritten[(rewritten["model"] == "springpot") & (rewritten["parameter"] == "alpha")]["value"].iloc[0]
    assert alpha == old  # full float precision round trip
    assert REG.check(reference_copy, fresh=fresh)[0]


@pytest.mark.parametrize("path", sorted(Path(__file__).parent.glob("*.csv")), ids=lambda p: p.name)
def test_committed_table_is_well_formed(path):
    table = REG.read_reference_file(path)  # raises naming line and column on a bad row
    assert (table["tolerance"] > 0).all() and np.isfinite(table["tolerance"]).all()
    assert table["reason"].str.strip().str.len().gt(0).all()
    assert (table["dataset"] == path.stem).all()
    # the stated rule, row by row: max(k * stderr, 1e-6 |value|), never a blanket percentage
    for row in table.itertuples():
        expected, _ = REG.tolerance_for(row.value, row.stderr)
        assert math.isclose(row.tolerance, expected, rel_tol=1e-12), row
    assert table["tolerance"].div(table["value"].abs()).nunique() > 1


@pytest.mark.filterwarnings("ignore:All-NaN axis encountered:RuntimeWarning")  # ranking of strain-free flow curves
def test_the_regression_refits_what_the_pipeline_writes(repo_root, tmp_path, fresh):
    """``stages.run_fit_scope`` (the Snakemake fit rule) gives the same values as the regression's refit."""
    from tissuemech.curves import write_averages
    from tissuemech.records import FitRecord
    from tissuemech.stages import run_fit_scope

    settings = REG.fit_settings(repo_root / "config" / "config.yaml")
    averages, _ = REG.dataset_averages(repo_root / "raw" / "agar_3pct_thesis", tmp_path / "work")
    write_averages(averages, tmp_path / "averages.nc")
    models = list(REG.REFERENCE_FITS["agar_3pct_thesis"]["flow_curve"])
    run_fit_scope(tmp_path / "averages.nc", "flow_curve", {"tests": ["flow_curve"], "models": models},
                  target=settings["plate_target"], seed=settings["seed"], multistart=settings["multistart"],
                  fits_dir=tmp_path / "fits", cards_dir=tmp_path / "cards", ranking_path=tmp_path / "ranking.csv",
                  dataset="agar_3pct_thesis", poisson_ratio=0.49)
    for model in models:
        fit = FitRecord.from_netcdf(tmp_path / "fits" / f"{model}.nc")
        mine = fresh[(fresh["dataset"] == "agar_3pct_thesis") & (fresh["model"] == model)].set_index("parameter")
        for name, value in fit.params.items():
            assert value == pytest.approx(mine.loc[name, "value"], rel=1e-12)


def test_malformed_tables_are_rejected_with_line_and_column(reference_copy):
    path = reference_copy / "agar_3pct_thesis.csv"
    table = pd.read_csv(path)
    table.loc[2, "tolerance"] = 0.0
    table.to_csv(path, index=False)
    with pytest.raises(REG.ReferenceTableError, match=r"agar_3pct_thesis\.csv, line 4, column 'tolerance'.*positive"):
        REG.read_reference(reference_copy)
    table.loc[2, "tolerance"] = 1.0
    table.loc[5, "reason"] = ""
    table.to_csv(path, index=False)
    with pytest.raises(REG.ReferenceTableError, match=r"line 7, column 'reason': empty reason"):
        REG.read_reference(reference_copy)
    table.loc[5, "reason"] = "ok"
    table = pd.concat([table, table.iloc[[0]]], ignore_index=True)
    table.to_csv(path, index=False)
    # the appended copy of row 0 is the last data line of the file
    with pytest.raises(REG.ReferenceTableError, match=rf"line {len(table) + 1}: duplicated parameter"):
        REG.read_reference(reference_copy)


def test_unmatched_and_failed_fits_fail_the_comparison():
    def row(model, parameter, value, tolerance=1.0, reason="0.1 x standard error 10"):
        return {"dataset": "d", "scope": "s", "model": model, "parameter": parameter, "unit": "Pa", "value": value,
                "stderr": 10.0, "tolerance": tolerance, "reason": reason}

    reference = pd.DataFrame([row("a", "G", 100.0), row("a", "eta", 5.0), row("b", "mu", 7.0)])
    fresh = pd.DataFrame([row("a", "G", 100.5), row("a", "tau", 1.0),
                          row("b", "<fit failed>", float("nan"), float("nan"), "RuntimeError: every start failed")])
    comparison = REG.compare(reference, fresh).set_index(["model", "parameter"])["status"]
    assert comparison[("a", "G")] == "ok"
    assert comparison[("a", "eta")] == "missing from fresh fits"
    assert comparison[("a", "tau")] == "not in reference"
    assert comparison[("b", "mu")] == "missing from fresh fits"
    assert comparison[("b", "<fit failed>")] == "fit failed: RuntimeError: every start failed"


def test_tolerance_rule():
    assert REG.tolerance_for(100.0, 2.0) == (pytest.approx(0.2), "0.1 x standard error 2")
    tol, why = REG.tolerance_for(100.0, 1e-9)
    assert tol == pytest.approx(1e-4) and why.startswith("reproducibility floor 1e-06")
    tol, why = REG.tolerance_for(100.0, float("nan"))
    assert tol == pytest.approx(1e-4) and "not estimated" in why
    tol, _ = REG.tolerance_for(0.0, 0.0)
    assert tol == REG.ABSOLUTE_FLOOR > 0


def test_exchangeable_prony_modes_are_numbered_by_time():
    """A permuted labelling of the same Prony spectrum (seen among the multistart optima) gives the same rows."""
    from types import SimpleNamespace

    spectrum = {"G_inf": 73.1, "G_1": 231.7, "G_2": 73.7, "G_3": 48.2, "tau_1": 0.0138, "tau_2": 0.428, "tau_3": 6.35}
    permuted = {"G_inf": 73.1, "G_1": 231.7, "G_2": 48.2, "G_3": 73.7, "tau_1": 0.0138, "tau_2": 6.35, "tau_3": 0.428}

    def rows(params):
        result = SimpleNamespace(params=params, stderr={k: 0.1 * v for k, v in params.items()}, flags=[],
                                 success=True, message="", scope="stress_relaxation", model_key="prony3",
                                 units={k: "s" if k.startswith("tau") else "Pa" for k in params})
        return {r["parameter"]: (r["value"], r["stderr"]) for r in REG.reference_rows("d", result)}

    assert rows(permuted) == rows(spectrum)
    assert REG.mode_labels(permuted)["tau_2"] == "tau_3" and REG.mode_labels(spectrum)["tau_2"] == "tau_2"
    gkv = {"G0": 1.0, "G_1": 2.0, "G_2": 3.0, "tau_ret_1": 5.0, "tau_ret_2": 0.5}
    assert REG.mode_labels(gkv) == {"G0": "G0", "G_1": "G_2", "G_2": "G_1", "tau_ret_1": "tau_ret_2",
                                    "tau_ret_2": "tau_ret_1"}
    qlv = {"C10": 1.0, "beta_1": 2.0, "beta_2": 0.1}  # fixed relaxation times: labels are not exchangeable
    assert REG.mode_labels(qlv) == {k: k for k in qlv}
