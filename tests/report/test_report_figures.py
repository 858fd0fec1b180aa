"""Report figures and the summary page, on small inputs with known answers (no workflow run)."""
from __future__ import annotations

import base64
import io
import json
import re

import numpy as np
import pandas as pd
import pytest
import xarray as xr
from PIL import Image

from tissuemech.fem.mesh import block_mesh, write_mesh
from tissuemech.fitting import Curve
from tissuemech.summary import (boundary_faces, build_summary, caption_text, card_table, figure_scope_fit,
                                fit_panels, plot_cards, plot_meshes, plot_scope_fits, plot_timing)


def _fit_record(curves, keep, target="apparent_stress", offset=1.05):
    """A fit record in the layout of ``fitting.fit_to_dataset`` over the points ``keep`` of each curve."""
    observed, predicted, index, names = [], [], [], []
    for ci, curve in enumerate(curves):
        for name, values in curve.observed.items():
            y = np.asarray(values, float)[keep]
            observed.append(y)
            predicted.append(offset * y)
            index.append(np.full(y.size, ci))
            names += [name] * y.size
    return xr.Dataset(
        {"observed": ("point", np.concatenate(observed)), "predicted": ("point", np.concatenate(predicted)),
         "curve_index": ("point", np.concatenate(index)), "observable": ("point", np.array(names)),
         "curve_label": ("curve", [c.label for c in curves])},
        attrs={"model_key": "springpot", "scope": "frequency_sweep", "target": target, "nrmse": 0.05,
               "aicc": -12.0, "flags": "[]"})


def _frequency_sweep():
    omega = np.logspace(-1, 2, 12)
    storage, loss = 1e3 * omega**0.2, 3e2 * omega**0.2
    return Curve(test="frequency_sweep", condition="strain_pct=1", response="oscillation",
                 inputs={"angular_frequency": omega}, observed={"storage_modulus": storage, "loss_modulus": loss},
                 sd={"storage_modulus": 0.1 * storage})


def test_fit_panels_put_each_fitted_point_at_its_frequency():
    curve = _frequency_sweep()
    keep = np.arange(0, 12, 3)  # the fit saw a subset of the curve
    panels = fit_panels(_fit_record([curve], keep), [curve])
    assert set(panels) == {("frequency_sweep", "storage_modulus"), ("frequency_sweep", "loss_modulus")}
    (storage,) = panels[("frequency_sweep", "storage_modulus")]
    assert storage["xname"] == "frequency"
    np.testing.assert_allclose(storage["x"], curve.inputs["angular_frequency"][keep] / (2 * np.pi))
    np.testing.assert_allclose(storage["sd"], curve.sd["storage_modulus"][keep])
    np.testing.assert_allclose(storage["predicted"] / storage["observed"], 1.05)
    (loss,) = panels[("frequency_sweep", "loss_modulus")]
    assert loss["sd"] is None


def test_fit_panels_fall_back_to_point_index_when_data_changed():
    curve = _frequency_sweep()
    record = _fit_record([curve], np.arange(4))
    record["observed"] = record["observed"] * 3.0  # no longer the curve's values
    (storage,) = fit_panels(record, [curve])[("frequency_sweep", "storage_modulus")]
    assert storage["xname"] == "point"
    np.testing.assert_array_equal(storage["x"], np.arange(4))


def test_scope_fit_figure_uses_log_axes_only_for_positive_data():
    sweep = _frequency_sweep()
    fig = figure_scope_fit(_fit_record([sweep], np.arange(12)), [sweep])
    scales = [(ax.get_xscale(), ax.get_yscale()) for ax in fig.axes]
    assert scales == [("linear", "linear"), ("log", "log")] * 2
    strain = np.linspace(-0.2, 0.2, 9)
    shear = Curve(test="simple_shear", condition="strain_pct=20", response="elastic_shear",
                  inputs={"shear_strain": strain}, observed={"shear_stress": 500.0 * strain})
    fig = figure_scope_fit(_fit_record([shear], np.arange(9)), [shear])
    assert [(ax.get_xscale(), ax.get_yscale()) for ax in fig.axes] == [("linear", "linear")] * 2
    assert fig.axes[0].get_xlabel().startswith("shear strain")


def test_plot_scope_fits_writes_png_and_svg_per_model(tmp_path):
    """Averages -> curves -> fit record -> figure, through the same curve builder as the fit stage."""
    from tissuemech.stages import scope_curves

    from tissuemech.canonical import make_run_dataset, write_netcdf
    from tissuemech.curves import average_runs, write_averages

    frequency = np.logspace(-1, 1, 15)
    runs = [make_run_dataset({"frequency": frequency, "angular_frequency": 2 * np.pi * frequency,
                              "storage_modulus": k * 1e3 * frequency**0.1, "loss_modulus": k * 2e2 * frequency**0.1,
                              "shear_strain": np.full(15, 0.01)},
                             {"test": "frequency_sweep", "specimen": "s", "sample": f"s{i}", "run": f"r{i}",
                              "strain_pct": 1.0, "radius_m": 0.0125, "gap_m": 0.002})
            for i, k in enumerate((0.9, 1.0, 1.1))]
    write_averages(average_runs(runs), tmp_path / "averages.nc")
    curves = scope_curves(xr.load_dataset(tmp_path / "averages.nc"), ["frequency_sweep"])
    assert len(curves) == 1
    fits = tmp_path / "fits"
    fits.mkdir()
    record = _fit_record(curves, slice(None))
    record.to_netcdf(fits / "springpot.nc")
    (storage,) = fit_panels(record, curves)[("frequency_sweep", "storage_modulus")]
    np.testing.assert_allclose(storage["x"], frequency, rtol=1e-6)  # the measured frequencies, in Hz
    written = plot_scope_fits(tmp_path / "averages.nc", fits, ["frequency_sweep"], tmp_path / "figures")
    assert sorted(p.name for p in written) == ["springpot.png", "springpot.svg"]
    with Image.open(written[0]) as image:
        assert image.size[0] > 600


def test_boundary_faces_of_a_block_are_its_surface_triangles():
    assert len(boundary_faces(block_mesh((1.0, 1.0, 1.0), (1, 1, 1)).elements)) == 12
    # 2 x 1 x 1 cells: 10 square faces on the outside, 2 triangles each; the shared square is interior
    assert len(boundary_faces(block_mesh((2.0, 1.0, 1.0), (2, 1, 1)).elements)) == 20


def test_mesh_pictures_from_vtu(tmp_path):
    mesh = block_mesh((0.01, 0.01, 0.005), (3, 3, 2))
    u = np.zeros_like(mesh.nodes)
    u[:, 2] = -0.1 * mesh.nodes[:, 2]
    write_mesh(tmp_path / "vtu" / "cards__model__8mm.vtu", mesh, {"displacement": u})
    written = plot_meshes({"indentation": tmp_path / "vtu"}, tmp_path / "meshes")
    assert [p.name for p in written] == ["indentation__cards_model_8mm.png", "indentation__cards_model_8mm.svg"]
    svg = written[1].read_text()
    assert "|u| [mm]" in svg and "108 tetrahedra" in svg


def test_card_table_ranks_and_counts_prony_terms(tmp_path):
    cards = tmp_path / "cards" / "stress_relaxation"
    cards.mkdir(parents=True)
    for model, mu, g in (("sls1", 900.0, [0.4]), ("prony2", 1000.0, [0.3, 0.0, 0.2])):
        (cards / f"{model}.json").write_text(json.dumps({
            "model": model, "elastic_law": "neo_hookean", "elastic_parameters": {"mu": mu},
            "initial_shear_modulus": mu, "bulk_modulus": 50 * mu, "prony": {"g": g, "tau": [1.0] * len(g)},
            "fit_quality": {"nrmse": 0.01 if model == "prony2" else 0.05, "flags": ["x"] if model == "sls1" else []}}))
    ranking = tmp_path / "ranking.csv"
    pd.DataFrame({"scope": ["stress_relaxation"] * 2, "model": ["prony2", "sls1"], "rank": [1, 2],
                  "recommended": [False, True]}).to_csv(ranking)
    table = card_table(tmp_path / "cards", ranking)
    assert table["model"].tolist() == ["prony2", "sls1"]
    assert table["recommended"].tolist() == [False, True]  # the ranking's column, not the rank order
    assert table["prony_terms"].tolist() == [2, 1]
    assert table["n_flags"].tolist() == [0, 1]
    assert table.loc[0, "elastic_parameters"] == "mu=1000"
    written = plot_cards(tmp_path / "cards", ranking, tmp_path / "figures", tmp_path / "cards.csv")
    assert [p.name for p in written] == ["stress_relaxation.png", "stress_relaxation.svg"]
    assert pd.read_csv(tmp_path / "cards.csv")["G0_pa"].tolist() == [1000.0, 900.0]


def test_timing_figures_and_bad_table(tmp_path):
    rows = [{"n_elements": n, "law": law, "precision": "float64", "device": "cpu", "steps_per_s": 1e7 / n / k,
             "real_time_factor": 1e-4 * 1e7 / n / k} for n in (1000, 8000) for law, k in (("NH", 1.0), ("LP2", 2.0))]
    table = tmp_path / "timing.csv"
    pd.DataFrame(rows).to_csv(table, index=False)
    written = plot_timing(table, tmp_path / "step", tmp_path / "realtime")
    assert [p.name for p in written] == ["step.png", "step.svg", "realtime.png", "realtime.svg"]
    svg = written[3].read_text()
    assert "NH float64 cpu" in svg and "LP2 float64 cpu" in svg
    pd.DataFrame(rows).drop(columns=["real_time_factor"]).to_csv(table, index=False)
    with pytest.raises(ValueError, match=r"timing\.csv: timing table lacks columns \['real_time_factor'\]"):
        plot_timing(table, tmp_path / "step", tmp_path / "realtime")


def test_caption_text_drops_markup_and_templates(tmp_path):
    rst = tmp_path / "x.rst"
    rst.write_text("Model **{{ snakemake.wildcards.model }}** of ``scope``\n\n.. note:: hidden\n")
    assert caption_text(rst) == "Model of scope"
    assert caption_text(tmp_path / "missing.rst") == ""


def test_summary_page_embeds_every_figure_with_its_caption(tmp_path, repo_root):
    from tissuemech.plots import plot_timings

    results = tmp_path / "results"
    plot_timings(["a", "b"], [1.0, 2.0], results / "demo" / "figures" / "averages" / "flow_curve__default__x")
    plot_timings(["a"], [1.0], results / "demo" / "figures" / "fits" / "flow_curve" / "cross")
    pd.DataFrame({"scope": ["flow_curve"], "model": ["cross"], "rank": [1],
                  "recommendation": ["cross fits best"]}).to_csv(results / "demo" / "ranking.csv", index=False)
    config = {"fit": {"seed": 424242, "plate_target": "torque"}, "fem": {"poisson_ratio": 0.45},
              "diagnosis": {"alpha": 0.05}}
    page = build_summary(results, ["demo"], tmp_path / "summary.html", captions_dir=repo_root / "workflow" / "report",
                         config=config)
    text = page.read_text()
    assert "Raw runs (thin grey lines) and the sample average" in text
    # captions rendered like the Snakemake report: Jinja with the config and dataset, then reStructuredText
    assert "Model <strong>&lt;model&gt;</strong> fitted to scope <strong>&lt;scope&gt;</strong> of dataset\ndemo" in text
    assert "multistart seed 424242" in text and "Poisson ratio 0.45" in text
    assert "cross fits best" in text
    images = re.findall(r'src="data:image/png;base64,([^"]+)"', text)
    assert len(images) == 2
    for data in images:
        with Image.open(io.BytesIO(base64.b64decode(data))) as image:
            image.verify()
