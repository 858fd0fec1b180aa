"""Report figures and the summary page, on small inputs with known answers (no workflow run).

Also the figure faults a first reading of the results found, each drawn again and checked: overlapping log-axis
labels, hidden torsion curves, a ranking figure titled after one scope without a mark on the recommended model, a
"log axes" relaxation panel with a linear y axis, amplitude-sweep fits against point index."""
from __future__ import annotations

import json
import re

import numpy as np
import pandas as pd
import pytest
import xarray as xr
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from PIL import Image

from tissuemech.fem.mesh import block_mesh, write_mesh
from tissuemech.fitting import Curve
from tissuemech.plots import figure_curves, plain_text_log_ticks
from tissuemech.ranking import plot_ranking
from tissuemech.summary import (boundary_faces, build_summary, caption_text, card_table, figure_scope_fit,
                                figure_timing, fit_panels, plot_cards, plot_meshes, plot_scope_fits, plot_timing)


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
    assert ">NH<" in svg and ">LP2<" in svg and "(float64, cpu)" in svg  # constant columns go to the title
    pd.DataFrame(rows).drop(columns=["real_time_factor"]).to_csv(table, index=False)
    with pytest.raises(ValueError, match=r"timing\.csv: timing table lacks columns \['real_time_factor'\]"):
        plot_timing(table, tmp_path / "step", tmp_path / "realtime")


def test_timing_legend_has_one_entry_per_value_and_distinct_styles():
    """4 laws x 2 kernels x 2 meshes: 16 lines, each with its own (colour, line style, marker), and 8 legend
    entries (the figure of the pipeline had 16 entries in 10 colours)."""
    rows = [{"n_elements": n, "law": law, "precision": "float64", "device": "cpu", "kernel": kernel, "mesh": mesh,
             "steps_per_s": 1e7 / n, "real_time_factor": 1e3 / n}
            for n in (1000, 10000) for law in ("SVK", "NH", "LP2", "QLV4-NH") for kernel in ("generic", "vectorised")
            for mesh in ("cube", "brain")]
    fig = figure_timing(pd.DataFrame(rows), "real_time_factor", ylabel="x", title="t")
    ax = fig.axes[0]
    lines = [line for line in ax.get_lines() if len(line.get_xdata())]
    styles = {(line.get_color(), line.get_linestyle(), line.get_marker()) for line in lines}
    assert len(lines) == 16 and len(styles) == 16
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert len(labels) == 8 and "NH" in labels and "kernel vectorised" in labels and "mesh brain" in labels


def test_caption_text_drops_markup_and_templates(tmp_path):
    rst = tmp_path / "x.rst"
    rst.write_text("Model **{{ snakemake.wildcards.model }}** of ``scope``\n\n.. note:: hidden\n")
    assert caption_text(rst) == "Model of scope"
    assert caption_text(tmp_path / "missing.rst") == ""


def test_summary_pages_link_every_figure_with_its_caption(tmp_path, repo_root):
    from tissuemech.plots import plot_timings

    results = tmp_path / "results"
    plot_timings(["a", "b"], [1.0, 2.0], results / "demo" / "figures" / "averages" / "flow_curve__default__x")
    plot_timings(["a"], [1.0], results / "demo" / "figures" / "fits" / "flow_curve" / "cross")
    pd.DataFrame({"scope": ["flow_curve"], "model": ["cross"], "rank": [1], "recommended": [True],
                  "recommendation": ["cross fits best"]}).to_csv(results / "demo" / "ranking.csv", index=False)
    config = {"fit": {"seed": 424242, "plate_target": "torque"}, "fem": {"poisson_ratio": 0.45},
              "diagnosis": {"alpha": 0.05}}
    main = build_summary(results, ["demo"], results / "summary.html", captions_dir=repo_root / "workflow" / "report",
                         config=config)
    text = main.read_text()
    assert "multistart seed 424242" in text and "Poisson ratio 0.45" in text   # the workflow caption
    assert "cross fits best" in text                                         # the scope's recommendation
    page = (results / "demo" / "summary.html").read_text()
    assert "Raw runs (thin grey lines) and the sample average" in page
    # captions rendered like the Snakemake report: Jinja with the config and dataset, then reStructuredText; a
    # wildcard that differs between the figures of a section is named under each figure
    assert ("Model <strong>each model below</strong> fitted to scope <strong>flow_curve</strong> of dataset\ndemo"
            in page)
    sources = re.findall(r'<img loading="lazy" decoding="async" src="([^"]+)"', page)
    assert sorted(sources) == ["figures/averages/flow_curve__default__x.png", "figures/fits/flow_curve/cross.png"]
    for src in sources:
        with Image.open(results / "demo" / src) as image:
            image.verify()


# ---- figure faults ----
def _labels_overlap(fig: Figure, axis) -> list[tuple[str, str]]:
    """Pairs of visible, non-empty tick labels of ``axis`` whose drawn boxes intersect."""
    renderer = FigureCanvasAgg(fig).get_renderer()
    fig.draw(renderer)
    boxes = [(t.get_text(), t.get_window_extent(renderer)) for t in
             axis.get_majorticklabels() + axis.get_minorticklabels() if t.get_visible() and t.get_text()]
    boxes.sort(key=lambda item: item[1].x0)
    return [(a, b) for (a, ba), (b, bb) in zip(boxes, boxes[1:]) if ba.x1 > bb.x0]


def test_log_axis_over_two_decades_has_readable_labels():
    """The residual map's strain axis (1.25-50 %, one power of ten inside it) labelled 2×10⁰ 3×10⁰ 4×10⁰ ...
    on top of each other; now its minor labels are plain numbers at 2 and 5 and none overlap."""
    fig = Figure(figsize=(6, 4), layout="constrained")
    ax = fig.add_subplot()
    x = np.logspace(np.log10(1.25), np.log10(50), 40)
    ax.scatter(x, np.zeros_like(x), s=8)
    ax.set_xscale("log")
    fig.colorbar(ax.collections[0], ax=ax)
    plain_text_log_ticks(fig)
    assert _labels_overlap(fig, ax.xaxis) == []
    shown = [t.get_text() for t in ax.xaxis.get_minorticklabels() + ax.xaxis.get_majorticklabels() if t.get_text()]
    assert {"2", "5", "10", "20", "50"} <= set(shown)


def test_identical_torsion_curves_stay_visible_and_in_the_legend():
    """A rate-independent card gives the same torque at both rates: the second curve is dashed over the first and
    the legend names all of them (6 curves + 2 measurements; the pipeline's figure showed 4 of 6)."""
    strain = np.linspace(0.05, 0.5, 10)
    series = {}
    for rate in (0.001, 0.1):
        series[f"rp3 {rate:g} 1/s"] = (strain, 300.0 * strain)          # rate-independent: identical
        series[f"prony4 {rate:g} 1/s"] = (strain, (150.0 + 1e3 * rate) * strain)
        series[f"linear {rate:g} 1/s"] = (strain, 500.0 * strain)
    reference = {f"measured {rate:g} 1/s": (strain, 210.0 * strain) for rate in (0.001, 0.1)}
    fig = figure_curves(series, xlabel="rim strain", ylabel="torque", reference=reference)
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert len(labels) == 8
    assert "rp3 0.1 1/s (dashed: same as rp3 0.001 1/s)" in labels
    assert "linear 0.1 1/s (dashed: same as linear 0.001 1/s)" in labels
    dashed = [line for line in fig.axes[0].get_lines() if line.get_linestyle() == "--"]
    assert len(dashed) == 2 and all(line.get_zorder() > 2 for line in dashed)
    assert "prony4 0.1 1/s" in labels  # a different curve keeps its plain entry


def _ranking():
    rows = []
    for scope, models, chosen in (("stress_relaxation", ["prony4", "prony3", "sls1"], "prony3"),
                                  ("constant_shear_rate", ["rp3", "neo_hookean"], "rp3")):
        for i, model in enumerate(models):
            rows.append({"dataset": "demo", "scope": scope, "model": f"{scope}: {model}", "delta_aicc": 3.0 * i,
                         "cv_nrmse": 0.1 + 0.01 * i if scope == "stress_relaxation" else np.nan,
                         "n_flags": int(model == "prony4"), "recommended": model == chosen})
    return pd.DataFrame(rows)


def test_ranking_figure_has_a_panel_per_scope_and_marks_the_recommended_model():
    fig = plot_ranking(_ranking())
    assert fig.get_suptitle().startswith("model ranking of demo, every scope")
    titles = [ax.get_title() for ax in fig.axes]
    assert sum(t.startswith("stress_relaxation:") for t in titles) == 2
    assert sum(t.startswith("constant_shear_rate:") for t in titles) == 2
    ticks = [t.get_text() for ax in fig.axes for t in ax.get_yticklabels() if t.get_text()]
    assert "★ prony3" in ticks and "★ rp3" in ticks and "prony4" in ticks  # names without the scope prefix
    stars = [line for ax in fig.axes for line in ax.get_lines() if line.get_marker() == "*"]
    assert len(stars) == 3  # both panels of stress_relaxation, the ΔAICc panel of CSR (it has no CV)


def test_relaxation_log_panel_has_a_log_y_axis_when_a_few_values_ring_below_zero():
    t = np.logspace(-2, 1.5, 30)
    stress = 0.08 + 8.0 * np.exp(-t / 0.01) * np.cos(2 * np.pi * t / 0.06)   # rings through zero early
    curve = Curve(test="stress_relaxation", condition="default", response="relaxation", inputs={"time": t},
                  observed={"shear_stress": stress})
    fig = figure_scope_fit(_fit_record([curve], np.arange(t.size)), [curve])
    log_panel = fig.axes[1]
    assert (log_panel.get_xscale(), log_panel.get_yscale()) == ("log", "log")
    n_hidden = int(np.sum(np.concatenate([stress, 1.05 * stress]) <= 0))
    assert n_hidden > 0 and log_panel.get_title() == f"stress_relaxation: log axes; {n_hidden} value(s) ≤ 0 not shown"


def test_amplitude_sweep_fit_is_drawn_against_strain_amplitude():
    gamma = np.logspace(-3.3, -1.9, 8)
    curve = Curve(test="amplitude_sweep", condition="frequency_hz=1", response="elastic_shear",
                  inputs={"shear_strain": gamma}, observed={"shear_stress": 190.0 * gamma})
    fig = figure_scope_fit(_fit_record([curve], np.arange(8)), [curve])
    assert fig.axes[0].get_xlabel() == "strain amplitude γ₀ [–]"
    np.testing.assert_allclose(fig.axes[0].get_lines()[0].get_xdata(), gamma)
