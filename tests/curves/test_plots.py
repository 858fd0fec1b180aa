"""Report figures: files written atomically as PNG + SVG, axes and annotations as the data demand."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from tissuemech import curves, lve, plots
from tissuemech.canonical import make_run_dataset

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _check_files(paths, tmp_path, stem):
    assert [p.name for p in paths] == [f"{stem}.png", f"{stem}.svg"]
    assert paths[0].read_bytes()[:8] == PNG_MAGIC
    svg = paths[1].read_text(encoding="utf-8")
    assert svg.lstrip().startswith("<?xml") and "</svg>" in svg
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]  # no temporary left behind
    return svg


def _relaxation_runs():
    t = np.geomspace(0.01, 100, 60)
    return [make_run_dataset({"time": t, "relaxation_modulus": s * 100 * t**-0.2},
                             {"test": "stress_relaxation", "sample": f"s{i}", "run": f"r{i}"})
            for i, s in enumerate((0.9, 1.0, 1.1))]


def test_average_figure_has_band_log_axes_and_count(tmp_path):
    runs = _relaxation_runs()
    curve = curves.select_average(curves.average_runs(runs), "stress_relaxation")
    fig = plots.figure_average(curve, "relaxation_modulus", runs)
    ax = fig.axes[0]
    assert ax.get_xscale() == "log" and ax.get_yscale() == "log"
    band = ax.collections[0].get_paths()[0].vertices
    # the ±SD band spans mean ± 0.1 * 100 t^-0.2 at the first grid point t = 0.01
    assert band[:, 1].max() == pytest.approx(110 * 0.01**-0.2, rel=1e-6)
    assert band[:, 1].min() == pytest.approx(90 * 100**-0.2, rel=1e-6)
    assert len(ax.lines) == 3 + 1 + 1  # raw runs, mean, legend proxy
    svg = _check_files(plots.plot_average(curve, "relaxation_modulus", tmp_path / "avg.png", runs), tmp_path, "avg")
    assert "mean (n = 3)" in svg


def test_linear_grid_average_keeps_linear_axes():
    runs = [make_run_dataset({"shear_strain": np.linspace(0, 0.5, 20), "shear_stress": k * np.linspace(0, 40, 20)},
                             {"test": "constant_shear_rate", "sample": f"s{k}", "shear_rate_1_per_s": 0.1})
            for k in (1, 2)]
    curve = curves.select_average(curves.average_runs(runs), "constant_shear_rate")
    ax = plots.figure_average(curve, "shear_stress", runs).axes[0]
    assert ax.get_xscale() == "linear" and ax.get_yscale() == "linear"


def test_lve_figure_marks_limit_and_flow_point(tmp_path):
    strain = np.geomspace(1e-3, 1.0, 40)
    storage = 1000.0 / (1 + (strain / 0.05) ** 2)
    loss = np.full(strain.size, 200.0)
    result = lve.analyse_amplitude_sweep(strain, storage, loss)
    fig = plots.figure_lve(strain, storage, loss, result)
    vertical = [line.get_xdata()[0] for line in fig.axes[0].lines if len(set(line.get_xdata())) == 1]
    assert vertical == pytest.approx([result["lve_strain"], result["flow_point_strain"]])
    svg = _check_files(plots.plot_lve(strain, storage, loss, result, tmp_path / "lve"), tmp_path, "lve")
    assert f"γ_L = {100 * result['lve_strain']:.3g} %" in svg and "flow point" in svg


def test_fit_figure_linear_and_log_panels(tmp_path):
    t = np.geomspace(0.1, 100, 30)
    fig = plots.figure_fit(t, 2 * t**-0.3, 2.1 * t**-0.3, xlabel="t [s]", ylabel="G [Pa]", observed_sd=0.1 * t**-0.3)
    left, right = fig.axes[:2]
    assert (left.get_xscale(), left.get_yscale()) == ("linear", "linear")
    assert (right.get_xscale(), right.get_yscale()) == ("log", "log")
    # signed data keep a linear y axis in the "log" panel
    signed = plots.figure_fit(t, np.sin(t), np.sin(t), xlabel="t", ylabel="σ")
    assert signed.axes[1].get_yscale() == "linear" and signed.axes[1].get_xscale() == "log"
    _check_files(plots.plot_fit(t, 2 * t**-0.3, 2.1 * t**-0.3, tmp_path / "fit", xlabel="t", ylabel="G"),
                 tmp_path, "fit")


def test_table_residual_map_curves_and_timings(tmp_path):
    table = pd.DataFrame({"model": ["QLV", "PR", "Zener"], "AICc": [120.0, 95.5, np.nan], "k": [6, 9, 3]})
    fig = plots.figure_table(table, highlight_column="AICc")
    cells = fig.axes[0].tables[0].get_celld()
    assert cells[(2, 0)].get_text().get_text() == "PR"
    assert cells[(2, 0)].get_facecolor()[:3] != cells[(1, 0)].get_facecolor()[:3]  # best row shaded
    assert cells[(3, 1)].get_text().get_text() == "–"
    svg = _check_files(plots.plot_table(table, tmp_path / "ranking", highlight_column="AICc"), tmp_path, "ranking")
    assert "Zener" in svg

    x = np.geomspace(0.01, 0.5, 8)
    res = np.array([np.linspace(-2, 2, 8), np.full(8, np.nan)])
    fig = plots.figure_residual_map(res, x, ["0.1 1/s", "0.001 1/s"], xlabel="γ", log_x=True)
    norm = fig.axes[0].collections[0].norm
    assert (norm.vmin, norm.vcenter, norm.vmax) == (-2.0, 0.0, 2.0)
    with pytest.raises(ValueError, match="does not match"):
        plots.figure_residual_map(res, x[:5], ["a", "b"], xlabel="γ")
    _check_files(plots.plot_residual_map(res, x, ["a", "b"], tmp_path / "res", xlabel="γ"), tmp_path, "res")

    depth = np.linspace(0, 2e-3, 20)
    sub = tmp_path / "fem"
    sub.mkdir()
    paths = plots.plot_force_depth({"TLED": (depth, 0.5 * depth**1.5)}, sub / "force_depth",
                                   reference={"Hertz": (depth, 0.5 * depth**1.5)})
    _check_files(paths, sub, "force_depth")
    fig = plots.figure_timings(["CPU step", "GPU step"], [2e-3, 1e-4], budget_s=1e-3)
    colours = [bar.get_facecolor() for bar in fig.axes[0].patches]
    assert colours[0] != colours[1]  # over-budget bar drawn differently
    with pytest.raises(ValueError, match="2 names for 1 timings"):
        plots.figure_timings(["a", "b"], [1.0])


def test_svg_is_deterministic(tmp_path):
    t = np.geomspace(0.1, 10, 10)
    a = plots.plot_fit(t, t, t, tmp_path / "a", xlabel="x", ylabel="y")[1].read_bytes()
    b = plots.plot_fit(t, t, t, tmp_path / "b", xlabel="x", ylabel="y")[1].read_bytes()
    assert a == b


def test_stage_figure_sets(tmp_path):
    runs = _relaxation_runs()[:1]
    strain = np.geomspace(1e-4, 0.5, 30)
    for i, g0 in enumerate((900.0, 1100.0)):
        runs.append(make_run_dataset(
            {"shear_strain": strain, "storage_modulus": g0 / (1 + (strain / 0.05) ** 1.5),
             "loss_modulus": np.full(strain.size, 0.2 * g0)},
            {"test": "amplitude_sweep", "sample": f"a{i}", "run": f"as{i}", "frequency_hz": 1.0}))
    averages = curves.average_runs(runs)
    written = plots.plot_all_averages(averages, runs, tmp_path / "avg")
    names = sorted(p.name for p in written)
    assert "amplitude_sweep__frequency_hz-1__storage_modulus.svg" in names
    assert "stress_relaxation__default__relaxation_modulus.png" in names
    assert len(names) == 2 * 3  # G', G'' and G(t), PNG + SVG each (no shear stress in these runs)
    # a curve whose variable is absent is skipped, not drawn empty
    assert not [n for n in names if "shear_stress" in n]
    summary = lve.lve_summary(runs, averages)
    written = plots.plot_all_lve(summary, runs, averages, tmp_path / "lve")
    assert sorted(p.name for p in written) == sorted(
        f"lve__{src}__{name}.{ext}" for src, name in (("run", "as0"), ("run", "as1"), ("average", "frequency_hz-1"))
        for ext in ("png", "svg"))


@pytest.mark.parametrize("value, label", [(1e-3, "10⁻³"), (1.0, "10⁰"), (100.0, "10²"), (2e-3, "2×10⁻³"),
                                          (5e4, "5×10⁴"), (0.25, "0.25")])
def test_log_ticks_are_plain_unicode_powers_of_ten(value, label):
    assert plots.PowerOfTenFormatter(10)._num_to_string(value, 1e-4, 1e5) == label


def test_log_axes_of_saved_figures_carry_unicode_tick_labels(tmp_path):
    runs = _relaxation_runs()
    curve = curves.select_average(curves.average_runs(runs), "stress_relaxation")
    svg = _check_files(plots.plot_average(curve, "relaxation_modulus", tmp_path / "avg", runs), tmp_path, "avg")
    # time axis 0.01..100 s: its decade labels are text, not mathtext glyph paths
    for label in ("10⁻²", "10⁰", "10²"):
        assert f">{label}<" in svg
