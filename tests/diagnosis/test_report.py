"""diagnosis.json / residual netCDF / figures, and the pipeline entry on fitted runs."""
from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from constructed import make_design
from tissuemech import fitting
from tissuemech.canonical import read_netcdf, write_netcdf
from tissuemech.diagnosis.baseline import fit_runs, predict_runs
from tissuemech.diagnosis.report import run_diagnosis, write_diagnosis_json, write_figures
from tissuemech.models.registry import model_on_times
from tissuemech.models.qlv import default_taus

FINDING_KEYS = {"effect", "detected", "statistic", "p_value", "effect_size", "evidence", "fix"}
FIX_KEYS = {"model", "metric", "before", "after", "gain"}
UNEXPLAINED_KEYS = {"covariate", "statistic", "p_value", "effect_size"}


def test_json_and_figures_follow_the_output_contract(diagnosed, tmp_path):
    _, table, res = diagnosed("torque_offset", n_specimens=4, n_samples=2, n_points=16)
    path = write_diagnosis_json(res, tmp_path / "diagnosis.json", dataset="constructed")
    out = json.loads(path.read_text())
    assert out["dataset"] == "constructed" and out["alpha"] == 0.01
    assert out["findings"][0]["effect"] == "torque_offset" and out["findings"][0]["detected"] is True
    for f in out["findings"]:
        assert FINDING_KEYS <= set(f)
        if f["fix"] is not None:
            assert FIX_KEYS <= set(f["fix"])
    assert out["findings"][0]["fix"]["gain"] == pytest.approx(
        (out["findings"][0]["fix"]["before"] - out["findings"][0]["fix"]["after"]) / out["findings"][0]["fix"]["before"])
    figs = write_figures(table, res, tmp_path / "figs")
    assert len(figs) == 4 and all(p.stat().st_size > 5000 for p in figs)
    # PNG for the Snakemake report pattern {figure}.png, SVG beside it (plots.save_figure)
    assert all(p.suffix == ".png" and p.with_suffix(".svg").stat().st_size > 5000 for p in figs)


def test_run_diagnosis_on_fitted_runs(tmp_path):
    """Pipeline entry: canonical runs + a fit record on disk -> diagnosis.json, residual netCDF, figures.

    The baseline is a linear QLV fitted to data of a strain-stiffening truth, so its misfit grows with strain
    -- a model-form error no catalogue cause names: it must come out as unexplained structure in strain.
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        runs, _, _ = make_design(None, n_specimens=3, n_samples=1, n_points=16)
        (tmp_path / "runs").mkdir()
        (tmp_path / "fits").mkdir()
        for r in runs:
            write_netcdf(r, tmp_path / "runs" / f"{r.attrs['run']}.nc")
        shear = [r for r in runs if r.attrs["test"] in ("constant_shear_rate", "stress_relaxation")]
        fit = fit_runs("qlv_linear_prony4", shear, "torque", n_points=16)
        fitting.write_fit_netcdf(fit, tmp_path / "fits" / "qlv_linear_prony4.nc")
        res = run_diagnosis(tmp_path / "runs", tmp_path / "fits", tmp_path / "out" / "diagnosis.json",
                            tmp_path / "out" / "residuals.nc", tmp_path / "out" / "figs", extensions=False,
                            alpha=0.02)
    out = json.loads((tmp_path / "out" / "diagnosis.json").read_text())
    assert out["model"] == "qlv_linear_prony4" and out["fit_info"]["target"] == "torque"
    assert out["alpha"] == 0.02  # config diagnosis.alpha reaches the Holm control
    # data stiffen above the linear model: significant structure in strain, a model-form error no catalogue cause
    # names (the baseline is fitted through the torque, so the rim-stress cause does not apply): nothing is named
    # and the strain structure is listed as unexplained, with what to do
    strain_hits = [g for g in res["structure_tests"] if g["test"] == "constant_shear_rate"
                   and g["covariate"] == "strain" and g["significant"]]
    assert strain_hits and strain_hits[0]["effect_size"] > 0.1
    assert [f["effect"] for f in out["findings"] if f["detected"]] == []
    strain = [u for u in out["unexplained"] if u["covariate"] == "strain" and u["test"] == "constant_shear_rate"]
    assert strain, out["unexplained"]
    assert strain[0]["effect_size"] > 0.1 and strain[0]["what_to_do"].startswith("Check the lab notes")
    assert out["noise_model"]["relative_level"] > 0 and out["baseline"]["adequate"] is True
    assert all(UNEXPLAINED_KEYS <= set(u) for u in out["unexplained"])
    nc = read_netcdf(tmp_path / "out" / "residuals.nc")
    assert set(np.unique(nc["test"].values)) >= {"constant_shear_rate", "stress_relaxation", "frequency_sweep"}
    # the fit stage's registry times are not the diagnosis's: the baseline is rebuilt on the times NNLS selects
    # from the data and refitted; the netCDF holds the residuals of that diagnosed baseline
    info = out["fit_info"]
    assert "from the data" in info["baseline_order"] and info["taus_s"] != [float(t) for t in default_taus(4)]
    assert set(np.unique(nc["model"].values)) == {"qlv_linear_prony4"}
    model = model_on_times("qlv_linear_prony4", info["taus_s"])
    preds = predict_runs(model, info["params"], shear[:1], "torque")
    row = nc["curve"].values == shear[0].attrs["run"]
    assert nc["predicted"].values[row] == pytest.approx(preds[0]["shear_stress"][np.isfinite(preds[0]["shear_stress"])])
    assert len(res["figures"]) == 4


def fitting_model():
    from tissuemech.models.registry import model_on_times, get_model
    return get_model("qlv_linear_prony4")
