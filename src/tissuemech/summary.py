"""Report figures the stages do not draw themselves, and the HTML summary of the results.

Figures (PNG + SVG, written through :func:`tissuemech.plots.save_figure`):

* :func:`plot_scope_fits` -- every fitted model of a scope over its averaged data, linear and log axes;
* :func:`plot_posterior_fit` -- the same figure of one sampled fit with its 5-95 % posterior-predictive band
  (rule ``posterior``, after the fit job that draws the plain figures);
* :func:`plot_cards` -- the material cards of a dataset as tables, one per scope (``cards.csv`` alongside);
* :func:`plot_meshes` -- the deformed TLED meshes of the FEM experiments (VTU files), coloured by |u|;
* :func:`plot_timing` -- TLED step time and real-time factor against mesh size.

:func:`build_summary` writes ``results/summary.html``, the page a rheologist reads first: per dataset a verdict
card (:func:`verdict_card`: the recommended model per scope, its misfit in noise units, its held-out and cross-test
prediction, and the diagnosis in plain words with what to do), and a page per dataset,
``results/<dataset>/summary.html`` (:func:`dataset_page`: every table in full with its CSV file, the material cards
as tables, every figure loaded lazily with its caption). ``snakemake --report`` adds provenance, runtimes and the
rule graph to the same figures.
"""
from __future__ import annotations

import html
import json
import math
import os
import re
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd
import xarray as xr
from matplotlib import colormaps
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Normalize
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from .canonical import read_netcdf, write_text
from .fem.mesh import TET_FACES, read_mesh
from .fitting import target_observations
from .pipeline import progress
from .plots import all_positive, axis_label, figure_table, new_figure, safe_name, save_figure
from .ranking import recommended_models
from .records import Finding, FitRecord, MaterialCard
from .stages import run_fit_scope, spec_curves
from .uq import BRAIN_GEOMETRY, predictive_band

# ------------------------------------------------------------------------------------------------------
# fits over their data
# ------------------------------------------------------------------------------------------------------
#: abscissa of a fitted curve per test kind: the variable the field plots that test against
FIT_ABSCISSA: dict[str, str] = {
    "stress_relaxation": "time",
    "creep_recovery": "time",
    "amplitude_sweep": "shear_strain",
    "constant_shear_rate": "shear_strain",
    "frequency_sweep": "angular_frequency",
    "flow_curve": "shear_rate",
    "simple_shear": "shear_strain",
    "uniaxial": "stretch",
}

#: observables drawn in a more readable unit: name -> (factor, axis label)
_DISPLAY_UNITS: dict[str, tuple[float, str]] = {"torque": (1e6, "torque M [µN m]")}

#: abscissa labels that differ from the canonical variable's for a test: (test, variable) -> label
_ABSCISSA_LABELS: dict[tuple[str, str], str] = {("amplitude_sweep", "shear_strain"): "strain amplitude γ₀ [–]"}


def _match_in_order(values: np.ndarray, reference: np.ndarray) -> np.ndarray | None:
    """Indices into ``reference`` of ``values`` (same numbers, same order, possibly a subset); None if absent."""
    out, start = [], 0
    for v in values:
        hits = np.nonzero(np.isclose(reference[start:], v, rtol=1e-9, atol=0.0, equal_nan=False))[0]
        if hits.size == 0:
            return None
        out.append(start + hits[0])
        start += hits[0] + 1
    return np.asarray(out, int)


def fit_panels(fit: FitRecord | xr.Dataset, curves: Sequence,
               band: Mapping[str, np.ndarray] | None = None) -> dict[tuple[str, str], list[dict]]:
    """Group the points of a fit record by (test, observable), with their abscissa recovered from the curves.

    Parameters
    ----------
    fit : a fit record (:class:`tissuemech.records.FitRecord`, or its Dataset): ``observed``, ``predicted``,
        ``curve_index``, ``observable`` per point and ``curve_label`` per curve.
    curves : the curves the fit was made on (:func:`tissuemech.stages.scope_curves`), matched by label.
    band : optional per-point arrays ``q05``/``q95`` in the record's point order (the posterior-predictive band,
        :func:`tissuemech.uq.predictive_band`); each series then carries ``"band": (q05, q95)``.

    Returns
    -------
    ``{(test, observable): [{"label", "x", "xname", "observed", "predicted", "sd"[, "band"]}, ...]}``. ``x`` is the
    abscissa of :data:`FIT_ABSCISSA` at the fitted points; when a curve cannot be matched (its data changed
    since the fit) the point index is used and ``xname`` is ``"point"``.
    """
    by_label = {c.label: c for c in curves}
    rec = fit if isinstance(fit, FitRecord) else FitRecord.from_dataset(fit)
    observed, predicted = rec.observed, rec.predicted
    curve_index, observable = rec.curve_index, rec.observable.astype(str)
    labels = rec.curve_labels
    target = rec.target or "apparent_stress"
    panels: dict[tuple[str, str], list[dict]] = {}
    for ci, label in enumerate(labels):
        test = label.split("|", 1)[0]
        for name in dict.fromkeys(observable[curve_index == ci]):
            sel = (curve_index == ci) & (observable == name)
            y, f = observed[sel], predicted[sel]
            x, xname, sd = np.arange(y.size, dtype=float), "point", None
            curve = by_label.get(label)
            if curve is not None:
                obs, sds = target_observations(curve, target)
                if name in obs:
                    idx = _match_in_order(y, np.asarray(obs[name], float))
                    xname = FIT_ABSCISSA.get(test, "time")
                    if idx is not None and xname in curve.inputs:
                        x = curve.obs_inputs(xname)[idx]
                        sd = np.asarray(sds[name], float)[idx] if name in sds else None
                    else:
                        xname = "point"
            if xname == "angular_frequency":
                x, xname = x / (2 * np.pi), "frequency"
            series = {"label": label.split("|", 1)[-1], "x": x, "xname": xname, "observed": y, "predicted": f,
                      "sd": sd}
            if band is not None and np.size(band["q05"]) == observed.size:
                series["band"] = (np.asarray(band["q05"], float)[sel], np.asarray(band["q95"], float)[sel])
            panels.setdefault((test, str(name)), []).append(series)
    return panels


def _log_y_share(values: np.ndarray) -> tuple[bool, int]:
    """Whether a "log axes" panel can draw ``values`` on a log y axis, and how many of them it leaves out.

    A log axis shows only positive values: it is used when at least half of the finite values are positive (a
    relaxation whose stress rings through zero just after the step keeps its log axis, the few points at or below
    zero left out and counted in the panel title); signed data (simple shear through zero) stay linear.
    """
    finite = np.asarray(values, float)
    finite = finite[np.isfinite(finite)]
    positive = int(np.sum(finite > 0))
    return (finite.size > 0 and positive >= 0.5 * finite.size), int(finite.size - positive)


def figure_scope_fit(fit: FitRecord | xr.Dataset, curves: Sequence, title: str | None = None,
                     band: Mapping[str, np.ndarray] | None = None) -> Figure:
    """A fitted model over its data: one row per (test, observable), linear axes left, log axes right.

    Data are markers (± SD bars of the sample average where known), the model a line of the same colour per
    curve. A log axis is used only where every value along it is positive (signed stress stays linear). With
    ``band`` (per-point ``q05``/``q95`` in the record's point order, :func:`fit_panels`) each model line carries its
    shaded 5-95 % posterior-predictive band.
    """
    rec = fit if isinstance(fit, FitRecord) else FitRecord.from_dataset(fit)
    panels = fit_panels(rec, curves, band)
    fig, axes = new_figure(ncols=2, nrows=max(len(panels), 1), width=4.6, height=3.4)
    axes = axes.reshape(-1, 2)
    for row, ((test, name), series) in enumerate(panels.items()):
        factor, ylabel = _DISPLAY_UNITS.get(name, (1.0, axis_label(name)))
        xs = np.concatenate([s["x"] for s in series])
        ys = np.concatenate([np.concatenate([s["observed"], s["predicted"]]) for s in series])
        for ax, log in zip(axes[row], (False, True)):
            for i, s in enumerate(series):
                colour = f"C{i % 10}"
                order = np.argsort(s["x"], kind="stable")
                x, y, f = s["x"][order], factor * s["observed"][order], factor * s["predicted"][order]
                if s["sd"] is not None:
                    ax.errorbar(x, y, yerr=factor * s["sd"][order], fmt="o", ms=3, color=colour, ecolor=colour,
                                elinewidth=0.6, alpha=0.8, label=f"{s['label']} data")
                else:
                    ax.plot(x, y, "o", ms=3, color=colour, alpha=0.8, label=f"{s['label']} data")
                ax.plot(x, f, "-", color=colour, lw=1.6 if "band" not in s else 0.8)
                if "band" in s:
                    ax.fill_between(x, factor * s["band"][0][order], factor * s["band"][1][order], color=colour,
                                    alpha=0.35, lw=0)
            panel = "linear axes"
            if log:
                log_x = all_positive(xs)
                log_y, hidden = _log_y_share(ys)
                if log_x:
                    ax.set_xscale("log")
                if log_y:
                    ax.set_yscale("log")
                panel = ("log axes" if log_x and log_y else "log x, linear y (signed values)" if log_x
                         else "log y, linear x (signed values)" if log_y else "linear axes (signed values)")
                if log_y and hidden:
                    panel += f"; {hidden} value(s) ≤ 0 not shown"
            xname = series[0]["xname"]
            ax.set_xlabel("point index (curve not found)" if xname == "point"
                          else _ABSCISSA_LABELS.get((test, xname), axis_label(xname)))
            ax.set_ylabel(ylabel)
            ax.set_title(f"{test}: {panel}", fontsize=9)
        if len(series) <= 8:
            axes[row][0].plot([], [], "-", color="0.3", label="model")
            axes[row][0].legend(fontsize=7)
    if not panels:
        for ax in axes.ravel():
            ax.axis("off")
        axes[0][0].text(0.5, 0.5, "no fitted points", ha="center", va="center")
    quality = f"NRMSE = {rec.nrmse:.3g}, AICc = {rec.aicc:.4g}"
    if band is not None:
        width = (np.asarray(band["q95"], float) - np.asarray(band["q05"], float)) / np.abs(rec.predicted)
        width = width[np.isfinite(width)]
        quality += (", shaded: 5-95 % posterior-predictive band"
                    + (f" (median width {100 * np.median(width):.2g} % of the response)" if width.size else ""))
    flags = rec.flags
    fig.suptitle((title or f"{rec.model_key} ({rec.scope}, target {rec.target})")
                 + f"\n{quality}" + (f", {len(flags)} flag(s)" if flags else ""), fontsize=10)
    return fig


def plot_scope_fits(averages_path, fits_dir, spec: Mapping | Sequence[str], out_dir, tts_path=None,
                    models: Sequence[str] | None = None) -> list[Path]:
    """``<out_dir>/<model>.png/.svg`` for every fit record ``<fits_dir>/<model>.nc`` of a scope.

    The curves are rebuilt from the averages exactly as the fit stage builds them from the scope's ``spec`` (or
    its test kinds) (:func:`tissuemech.stages.spec_curves`, with the dataset's ``tts.nc`` as ``tts_path`` for the ``mastercurve``
    scope, whose one curve is drawn in reduced frequency), so each fitted point is drawn at its own
    time/strain/rate/frequency. ``models``: only these records (the material scope draws its baseline and
    recommended model, not every candidate law).
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    averages = read_netcdf(averages_path)
    tts = read_netcdf(tts_path) if tts_path is not None else None
    curves_by_relaxation: dict[str, list] = {}
    written: list[Path] = []
    paths = [p for p in sorted(Path(fits_dir).glob("*.nc")) if models is None or p.stem in models]
    for path in progress(paths, f"fit figures {Path(fits_dir).name}"):
        fit = FitRecord.from_netcdf(path)
        relaxation = fit.relaxation
        if relaxation not in curves_by_relaxation:
            curves_by_relaxation[relaxation] = spec_curves(averages, spec, relaxation=relaxation, tts=tts)
        fig = figure_scope_fit(fit, curves_by_relaxation[relaxation])
        written += save_figure(fig, out_dir / safe_name(path.stem), dpi=110)
    return written


def plot_posterior_fit(averages_path, record_path, posterior_nc, spec: Mapping | Sequence[str], out) -> list[Path]:
    """The fit figure of one sampled fit record (:func:`figure_scope_fit`, as drawn by :func:`plot_scope_fits`)
    with the 5-95 % posterior-predictive band of its posterior file (``posterior/<scope>/<model>.nc``,
    :func:`tissuemech.uq.predictive_band`); a figure that says so where the record or its posterior is absent."""
    band = predictive_band(posterior_nc) if Path(posterior_nc).is_file() else None
    if not Path(record_path).is_file() or band is None:
        fig, (ax,) = new_figure()
        ax.text(0.5, 0.5, f"no posterior of {Path(record_path).stem}", ha="center", va="center")
        ax.set_axis_off()
        return save_figure(fig, out)
    fit = FitRecord.from_netcdf(record_path)
    curves = spec_curves(read_netcdf(averages_path), spec, relaxation=fit.relaxation)
    return save_figure(figure_scope_fit(fit, curves, band=band), out, dpi=110)


# ------------------------------------------------------------------------------------------------------
# material cards
# ------------------------------------------------------------------------------------------------------
def card_table(cards_root, ranking_csv=None) -> pd.DataFrame:
    """One row per material card ``<cards_root>/<scope>/<model>.json``: law, moduli, Prony terms, fit quality.

    With ``ranking_csv`` the rows carry the model's rank in its scope and whether the ranking recommends it
    (column ``recommended``, :func:`tissuemech.ranking.recommended_models`), sorted by scope and rank.
    """
    rows = []
    for path in sorted(Path(cards_root).glob("*/*.json")):
        card = MaterialCard.from_json(path).data
        prony = card.get("prony") or {}
        quality = card.get("fit_quality") or {}
        law_parameters = card.get("elastic_parameters") or {}
        rows.append({
            "scope": path.parent.name, "model": card.get("model", path.stem),
            "elastic_law": card.get("elastic_law", ""),
            "elastic_parameters": ", ".join(f"{k}={v:.4g}" for k, v in law_parameters.items()
                                            if isinstance(v, (int, float))),
            "G0_pa": card.get("initial_shear_modulus", np.nan), "K_pa": card.get("bulk_modulus", np.nan),
            "prony_terms": int(sum(1 for g in prony.get("g", []) if g)) if prony else 0,
            "nrmse": quality.get("nrmse", np.nan), "n_flags": len(quality.get("flags", []) or []),
        })
    table = pd.DataFrame(rows, columns=["scope", "model", "elastic_law", "elastic_parameters", "G0_pa", "K_pa",
                                        "prony_terms", "nrmse", "n_flags"])
    if ranking_csv is not None and Path(ranking_csv).is_file() and Path(ranking_csv).stat().st_size and len(table):
        ranking = pd.read_csv(ranking_csv)
        if {"scope", "model", "rank"} <= set(ranking.columns):
            table = table.merge(ranking[["scope", "model", "rank"]], on=["scope", "model"], how="left")
            table = table.sort_values(["scope", "rank"], kind="stable").reset_index(drop=True)
            table.insert(2, "rank", table.pop("rank"))
            chosen = recommended_models(ranking_csv)
            table.insert(3, "recommended", [chosen.get(s) == m for s, m in zip(table["scope"], table["model"])])
    return table


def plot_cards(cards_root, ranking_csv, out_dir, out_csv) -> list[Path]:
    """``out_csv`` (every card) and ``<out_dir>/<scope>.png/.svg``: the cards of a scope, the recommended one
    (``ranking.csv``) shaded; without a ranking, the lowest NRMSE."""
    table = card_table(cards_root, ranking_csv)
    write_text(table.to_csv(index=False), out_csv)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    for scope, rows in table.groupby("scope", sort=True):
        shown = rows.drop(columns=["scope"]).reset_index(drop=True)
        if "recommended" in shown:
            fig = figure_table(shown, highlight_column="recommended" if shown["recommended"].any() else None,
                               lowest_is_best=False, title=f"material cards: {scope} (shaded: recommended)")
        else:
            fig = figure_table(shown, highlight_column="nrmse", title=f"material cards: {scope} (shaded: lowest NRMSE)")
        written += save_figure(fig, out_dir / safe_name(str(scope)), dpi=110)
    return written


# ------------------------------------------------------------------------------------------------------
# meshes
# ------------------------------------------------------------------------------------------------------
def boundary_faces(elements: np.ndarray) -> np.ndarray:
    """Triangles (node triples) that belong to exactly one tetrahedron: the surface of the mesh."""
    faces = np.asarray(elements, np.int64)[:, TET_FACES].reshape(-1, 3)
    keys = np.sort(faces, axis=1)
    _, first, counts = np.unique(keys, axis=0, return_index=True, return_counts=True)
    return faces[first[counts == 1]]


def figure_mesh(nodes_m: np.ndarray, elements: np.ndarray, displacement_m: np.ndarray | None = None,
                title: str | None = None, scale: float = 1.0) -> Figure:
    """Surface of a tetrahedral mesh in 3-D (mm), deformed by ``scale * displacement`` and coloured by |u|."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    nodes = np.asarray(nodes_m, float)
    magnitude = np.zeros(len(nodes))
    if displacement_m is not None:
        u = np.asarray(displacement_m, float)
        nodes = nodes + scale * u
        magnitude = np.linalg.norm(u, axis=1)
    faces = boundary_faces(elements)
    fig = Figure(figsize=(5.6, 4.4), layout="constrained")
    ax = fig.add_subplot(projection="3d")
    xyz = 1e3 * nodes
    norm = Normalize(vmin=0.0, vmax=max(float(magnitude.max()) * 1e3, 1e-12))
    cmap = colormaps["viridis"]
    face_values = 1e3 * magnitude[faces].mean(axis=1)
    poly = Poly3DCollection(xyz[faces], facecolors=cmap(norm(face_values)), edgecolors="k", linewidths=0.1)
    ax.add_collection3d(poly)
    lo, hi = xyz.min(axis=0), xyz.max(axis=0)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_zlim(lo[2], hi[2])
    ax.set_box_aspect(np.maximum(hi - lo, 1e-3 * np.max(hi - lo)))
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_zlabel("z [mm]")
    for axis, bins in ((ax.xaxis, 4), (ax.yaxis, 4), (ax.zaxis, 1 if hi[2] - lo[2] < 0.3 * np.ptp(xyz[:, 0]) else 4)):
        axis.set_major_locator(MaxNLocator(bins))  # a thin sample (2 mm gap) has room for its bounds only
    if displacement_m is not None:
        fig.colorbar(ScalarMappable(norm=norm, cmap=cmap), ax=ax, shrink=0.6, pad=0.12, label="|u| [mm]")
    ax.set_title(title or f"{len(elements)} tetrahedra, {len(nodes)} nodes", fontsize=9)
    return fig


def plot_meshes(vtu_dirs: Mapping[str, str | Path], out_dir, max_per_experiment: int = 4) -> list[Path]:
    """``<out_dir>/<experiment>__<case>.png/.svg`` for the first VTU files of each FEM experiment folder.

    Parameters
    ----------
    vtu_dirs : experiment name (``torsion``, ``indentation``) -> folder of ``*.vtu`` written by the FEM rules.
    max_per_experiment : pictures per experiment (the meshes of one experiment differ only by card).
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    for experiment, folder in vtu_dirs.items():
        for path in progress(sorted(Path(folder).glob("*.vtu"))[:max_per_experiment], f"{experiment} meshes"):
            mesh, point_data = read_mesh(path)
            u = point_data.get("displacement")
            case = path.stem.replace("__", " ")
            fig = figure_mesh(mesh.nodes, mesh.elements, u, title=f"{experiment}: {case}\n"
                              f"{mesh.n_elements} tetrahedra, final displacement (true scale)")
            written += save_figure(fig, out_dir / f"{experiment}__{safe_name(path.stem)}", dpi=110)
    return written


# ------------------------------------------------------------------------------------------------------
# timing
# ------------------------------------------------------------------------------------------------------
#: line styles and markers of the timing figures' second and third varying column
_LINESTYLES = ("-", "--", ":", "-.")
_MARKERS = ("o", "s", "^", "D", "v")


def figure_timing(table: pd.DataFrame, column: str, *, ylabel: str, title: str) -> Figure:
    """One timing quantity against the number of tetrahedra, one line per law / kernel / mesh / ... .

    The grouping columns (``law``, ``precision``, ``device`` and, where the ``benchmarks/fem_timing.py`` table has
    them, ``kernel`` and ``mesh``) that take one value are named in the title; the first varying one sets the
    colour, the second the line style, the third the marker, and the legend has one entry per value of each (4
    laws x 2 kernels x 2 meshes: 8 entries, not 16). A fourth varying column joins the third.
    """
    keys = ["law", "precision", "device"] + [k for k in ("kernel", "mesh") if k in table.columns]
    varying = [k for k in keys if table[k].astype(str).nunique() > 1]
    fixed = [f"{table[k].astype(str).iloc[0]}" for k in keys if k not in varying and len(table)]
    if len(varying) > 3:
        merged = " ".join(varying[2:])
        table = table.assign(**{merged: table[varying[2:]].astype(str).agg(" ".join, axis=1)})
        varying = varying[:2] + [merged]
    values = {k: sorted(table[k].astype(str).unique()) for k in varying}
    fig, (ax,) = new_figure(width=6.4, height=4.4)
    for key, rows in table.groupby(varying, sort=True) if varying else [((), table)]:
        key = (key,) if not isinstance(key, tuple) else key
        rows = rows.sort_values("n_elements")
        style = {"color": "C0", "ls": "-", "marker": "o"}
        for dim, value in zip(varying, key):
            i = values[dim].index(str(value))
            slot = varying.index(dim)
            if slot == 0:
                style["color"] = f"C{i % 10}"
            elif slot == 1:
                style["ls"] = _LINESTYLES[i % len(_LINESTYLES)]
            else:
                style["marker"] = _MARKERS[i % len(_MARKERS)]
        ax.plot(rows["n_elements"].to_numpy(float), rows[column].to_numpy(float), lw=1.4, ms=4, **style)
    handles, labels = [], []
    for slot, dim in enumerate(varying):
        for i, value in enumerate(values[dim]):
            style = ({"color": f"C{i % 10}", "ls": "-"} if slot == 0 else
                     {"color": "0.3", "ls": _LINESTYLES[i % len(_LINESTYLES)]} if slot == 1 else
                     {"color": "0.3", "ls": "none", "marker": _MARKERS[i % len(_MARKERS)]})
            handles += ax.plot([], [], lw=1.4, **style)
            labels.append(f"{dim} {value}" if slot else value)
    ax.set_xscale("log")
    positive = table[column].to_numpy(float)
    if all_positive(positive):
        ax.set_yscale("log")
    ax.set_xlabel("tetrahedra")
    ax.set_ylabel(ylabel)
    ax.set_title(title + (f" ({', '.join(fixed)})" if fixed else ""), fontsize=10)
    if handles:
        ax.legend(handles, labels, fontsize=7, ncols=2 if len(handles) > 5 else 1)
    return fig


def plot_timing(timing_csv, step_path, realtime_path) -> list[Path]:
    """TLED wall time per explicit step and real-time factor against the number of tetrahedra
    (:func:`figure_timing`); the real-time figure marks factor 1 (a simulated second costs one wall-clock
    second) as the reference."""
    table = pd.read_csv(timing_csv)
    required = {"n_elements", "law", "precision", "device", "steps_per_s", "real_time_factor"}
    missing = sorted(required - set(table.columns))
    if missing:
        raise ValueError(f"{timing_csv}: timing table lacks columns {missing}")
    table = table.assign(step_s=1.0 / table["steps_per_s"].to_numpy(float))
    written = save_figure(figure_timing(table, "step_s", ylabel="wall time per step [s]",
                                        title="TLED explicit step time"), step_path)
    fig = figure_timing(table, "real_time_factor", ylabel="real-time factor [–]",
                        title="TLED real-time factor (> 1: faster than real time)")
    fig.axes[0].axhline(1.0, color="k", ls="--", lw=1)
    written += save_figure(fig, realtime_path)
    return written


# ------------------------------------------------------------------------------------------------------
# HTML summary: results/summary.html (a verdict card per dataset) + results/<dataset>/summary.html (everything)
# ------------------------------------------------------------------------------------------------------
_STYLE = """body{font-family:sans-serif;margin:2em auto;max-width:1200px;padding:0 1em;color:#222}
table{border-collapse:collapse;font-size:12px;margin:4px 0}td,th{border:1px solid #ccc;padding:2px 6px;
vertical-align:top}th{background:#eef}h2{border-bottom:2px solid #345;margin-top:1.6em}
img{max-width:560px;height:auto;margin:4px}figure{display:inline-block;vertical-align:top;margin:4px}
figcaption{font-size:11px;max-width:560px}.caption{color:#333;font-size:13px;max-width:900px}
.card{border:2px solid #345;border-radius:6px;padding:6px 12px;margin:8px 0;background:#fafcff}
.finding{background:#fff3e0;padding:4px 8px;margin:4px 0;list-style:none}.todo{font-weight:bold;color:#7a3b00}
tr.chosen td{background:#dff0d8}.none{color:#a00}nav ol{columns:2}.wide{overflow-x:auto}
details summary{cursor:pointer;color:#345}.muted{color:#666}"""

#: figure sections of a dataset page: (anchor, title, caption file stem, glob of figures under results/<dataset>/)
SECTIONS: tuple[tuple[str, str, str, str], ...] = (
    ("fits", "Fits over their data", "fits", "figures/fits/*/*.png"),
    ("posterior", "Fits with posterior-predictive bands", "posterior_predictive", "figures/posterior/*/*.png"),
    ("ranking-figure", "Model ranking", "ranking", "figures/ranking.png"),
    ("diagnosis-figures", "Diagnosis figures", "diagnosis", "figures/diagnosis/*.png"),
    ("fem-torsion-figure", "FEM torsion", "fem_torsion", "figures/fem_torsion.png"),
    ("fem-indentation-figure", "FEM indentation", "fem_indentation", "figures/fem_indentation.png"),
    ("uq-indentation", "Indentation bands: measurement and specimen variability", "uq_indentation",
     "figures/uq_indentation_*.png"),
    ("uq-torsion", "Torsion bands: measurement and specimen variability", "uq_torsion", "figures/uq_torsion_*.png"),
    ("meshes", "FEM meshes", "meshes", "figures/meshes/*.png"),
    ("tts", "Time-temperature superposition", "tts", "figures/tts_mastercurve.png"),
    ("averages", "Raw runs vs sample averages", "averages", "figures/averages/*.png"),
    ("lve-figures", "LVE limit of the amplitude sweeps", "lve", "figures/lve/*.png"),
)

#: what a caption says for a wildcard that differs between the figures of a section (named under each figure)
_SECTION_WILDCARDS: dict[str, str] = {
    "model": "each model below", "scope": "each scope below", "test": "each test below",
    "condition": "each condition below", "variable": "each variable below", "sweep": "each sweep below",
    "figure": "each figure below", "experiment": "each experiment below", "case": "each case below",
}

#: plain-language names of the diagnosis causes (a finding's own ``title`` is used first where it has one)
CAUSE_TITLES: dict[str, str] = {
    "nonseparable_relaxation": "Relaxation depends on strain (not separable: beyond quasi-linear viscoelasticity)",
    "rim_stress_nonlinearity": "The instrument's rim-stress formula is off for this nonlinear sample",
    "wall_slip": "The sample slips at the plates above a critical stress",
    "elapsed_time_drift": "The sample stiffens or softens over the session (drift)",
    "preconditioning": "First loads differ from later loads (preconditioning)",
    "instrument_inertia": "The instrument's inertia correction is off (G' bends with frequency squared)",
    "torque_offset": "A constant torque offset in the readings",
    "outlier_specimen": "One specimen differs from the others",
    "amplitude_softening": "G' softens with strain amplitude within the sweeps",
    "finite_rise_time": "The strain step is not instantaneous (rise time)",
    "unidentified_i2_dependence": "The strain energy depends on the second invariant I2",
    "temperature_dependence": "The response depends on temperature (time-temperature shift)",
    "inertia_dominated_points": "Some oscillation points are dominated by instrument inertia",
    "inertial_ringing": "The stress rings just after the strain step",
    "tension_compression_asymmetry": "Compression and tension differ from what shear predicts",
    "baseline_inadequate": "No fitted model describes the data closely enough to be diagnosed",
    "unexplained_structure": "Residual structure that no named cause explains",
}

NOT_AVAILABLE = "not available"
NOT_MEASURED = "not measured"


def caption_text(path: Path) -> str:
    """Plain text of a report caption (reStructuredText with Jinja): markup and template tags removed."""
    if not path.is_file():
        return ""
    text = re.sub(r"\{[{%].*?[%}]\}", "", path.read_text(encoding="utf-8"))
    text = re.sub(r"^\.\. .*$", "", text, flags=re.M)
    text = re.sub(r"[`*]+", "", text)
    return " ".join(text.split())


class _Wildcards:
    """Wildcards of a caption rendered for a whole section: known ones by value, the others as the words of
    :data:`_SECTION_WILDCARDS` (the figure captions below name them)."""

    def __init__(self, known: Mapping[str, str]):
        self._known = dict(known)

    def __getattr__(self, name: str) -> str:
        if name.startswith("__"):
            raise AttributeError(name)
        return self._known.get(name, _SECTION_WILDCARDS.get(name, f"each {name} below"))


def render_caption(path: Path, config: Mapping | None = None, wildcards: Mapping[str, str] | None = None,
                   keep_title: bool = False) -> str:
    """HTML of a report caption, rendered as ``snakemake --report`` does (Jinja, then reStructuredText).

    ``snakemake.config`` is ``config``; a wildcard not given reads "each <name> below" (a section caption stands
    for every figure of the section, whose own captions name it). Without jinja2/docutils (Snakemake's own
    dependencies) the caption's plain text (:func:`caption_text`) is returned, escaped.
    """
    if not path.is_file():
        return ""
    try:
        from docutils.core import publish_parts
        from jinja2 import Template
    except ImportError:
        return f"<p>{html.escape(caption_text(path))}</p>"
    context = type("Snakemake", (), {"config": dict(config or {}), "wildcards": _Wildcards(wildcards or {})})
    text = Template(path.read_text(encoding="utf-8")).render(snakemake=context)
    parts = publish_parts(text, writer="html", settings_overrides={"report_level": 5, "halt_level": 5})
    return parts["html_body"] if keep_title else parts["body"]


def plain_statement(text) -> str:
    """A table's text for a reader: a number that was not measured reads "not measured", not "nan".

    >>> plain_statement("Thesis criteria: max strain nan %, rate-independent")
    'Thesis criteria: max strain not measured, rate-independent'
    >>> plain_statement(float("nan"))
    ''
    """
    if text is None or (isinstance(text, float) and not math.isfinite(text)):
        return ""
    return re.sub(r"\bnan\b(\s*%)?", NOT_MEASURED, str(text))


def _esc(value) -> str:
    return html.escape(plain_statement(value))


def _number(value, fmt: str = "{:.3g}", missing: str = NOT_MEASURED) -> str:
    try:
        v = float(value)
    except (TypeError, ValueError):
        return missing
    return fmt.format(v) if math.isfinite(v) else missing


def _read_csv(path: Path) -> pd.DataFrame | None:
    if not path.is_file() or path.stat().st_size == 0:
        return None
    try:
        return pd.read_csv(path)
    except pd.errors.EmptyDataError:
        return None


def _href(target: Path, page: Path) -> str:
    """Link from ``page`` to ``target`` (relative, with forward slashes, characters quoted)."""
    from urllib.parse import quote

    return quote(Path(os.path.relpath(target, page.parent)).as_posix())


def _long_text(text: str, limit: int = 40) -> str:
    """Escaped text; a long one folded behind its beginning (click to read it all), so that table rows stay short."""
    if len(text) <= limit:
        return html.escape(text)
    cut = text[:limit].rsplit(" ", 1)[0]
    return f"<details><summary>{html.escape(cut)} …</summary>{html.escape(text)}</details>"


def html_table(frame: pd.DataFrame, chosen: Sequence[bool] | None = None) -> str:
    """An HTML table of every row of ``frame``: numbers to 4 significant digits, missing values as "–", text
    escaped (a long text folded behind its beginning); rows where ``chosen`` is true are shaded (class
    ``chosen``)."""
    head = "".join(f"<th>{html.escape(str(c))}</th>" for c in frame.columns)
    rows = []
    marks = list(chosen) if chosen is not None else [False] * len(frame)
    for mark, row in zip(marks, frame.itertuples(index=False)):
        cells = []
        for v in row:
            if isinstance(v, (bool, np.bool_)):
                text = "yes" if v else "no"
            elif isinstance(v, (int, float, np.integer, np.floating)):
                text = f"{v:.4g}" if math.isfinite(float(v)) else "–"
            elif v is None or (isinstance(v, float) and math.isnan(v)):
                text = "–"
            else:
                cells.append(f"<td>{_long_text(plain_statement(v))}</td>")
                continue
            cells.append(f"<td>{html.escape(text)}</td>")
        rows.append(("<tr class='chosen'>" if mark else "<tr>") + "".join(cells) + "</tr>")
    return f'<div class="wide"><table><thead><tr>{head}</tr></thead><tbody>{"".join(rows)}</tbody></table></div>'


def _csv_section(path: Path, page: Path, columns: Sequence[str] | None = None, missing: str = "") -> str:
    """Every row of a CSV file as an HTML table (only ``columns``, in that order, when given) with a link to
    download it; rows with a true ``recommended`` column are shaded."""
    frame = _read_csv(path)
    if frame is None:
        return f"<p class='muted'>{html.escape(missing)}</p>" if missing else ""
    shown = frame[[c for c in columns if c in frame]] if columns else frame
    note = (f" (the table shows {shown.shape[1]} of its {frame.shape[1]} columns)" if shown.shape[1] < frame.shape[1]
            else "")
    table = html_table(shown, shown["recommended"].fillna(False).astype(bool).tolist() if "recommended" in shown
                       else None)
    if len(frame) > 40:  # a long table is folded (still complete in the page)
        table = f"<details><summary>show all {len(frame)} rows</summary>{table}</details>"
    return (f'<p><a href="{_href(path, page)}" download>{html.escape(path.name)}</a>: {len(frame)} rows{note}.</p>'
            + table)


def _png_size(path: Path) -> tuple[int, int] | None:
    head = path.read_bytes()[:24]
    if head[:8] != b"\x89PNG\r\n\x1a\n":
        return None
    return int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")


def _figure_label(path: Path, root: Path) -> str:
    return " / ".join(p.replace("__", " · ") for p in path.relative_to(root).with_suffix("").parts[1:])


def _lazy_figure(path: Path, root: Path, page: Path) -> str:
    """A figure that the browser loads when it scrolls into view, linked to its SVG when there is one."""
    label = html.escape(_figure_label(path, root))
    size = _png_size(path)
    dims = f' width="{size[0]}" height="{size[1]}"' if size else ""
    img = f'<img loading="lazy" decoding="async" src="{_href(path, page)}" alt="{label}"{dims}>'
    svg = path.with_suffix(".svg")
    link = f'<a href="{_href(svg, page)}">{img}</a>' if svg.is_file() else img
    return f"<figure>{link}<figcaption>{label}</figcaption></figure>"


# ---- the verdict ---------------------------------------------------------------------------------------
def _finding_title(finding: Mapping) -> str:
    return str(finding.get("title") or CAUSE_TITLES.get(str(finding.get("effect")), finding.get("effect", "")))


def _what_to_do(finding: Mapping) -> str:
    todo = finding.get("what_to_do")
    if not todo:
        return ""
    items = [todo] if isinstance(todo, str) else [str(t) for t in todo]
    return "".join(f'<div class="todo">What to do: {_esc(t)}</div>' for t in items)


def _extension_indentation(path: Path) -> dict[str, str]:
    """Per cause, the sentences on what its extension changes in the indentation force: the flat punch on a tissue
    block against the baseline's bands, and the MNI brain where it was pressed
    (:func:`tissuemech.uq.extension_indentation`); empty without the table."""
    if not path.is_file():
        return {}
    out: dict[str, str] = {}
    for r in pd.read_csv(path).to_dict("records"):
        brain = r.get("geometry") == BRAIN_GEOMETRY
        where_run = "MNI brain indentation" if brain else "flat-punch indentation"
        if r.get("status") != "ok":
            text = f" {where_run.capitalize()} with the extension's card: {_esc(str(r.get('status')))}."
        else:
            band = ("outside" if r["outside_measurement_band"] else "inside") + " the baseline's posterior 5-95 % band"
            spread = ("outside" if r["outside_specimen_band"] else "inside") + " the spread between specimens"
            change = (f"changes the force from {_number(1e3 * r['baseline_force_n'])} to "
                      f"{_number(1e3 * r['extension_force_n'])} mN ({_number(100 * r['relative_difference'])} %)")
            if brain:
                nodes = r.get("punch_nodes", np.nan)
                resolved = (f"; the mesh puts {int(nodes)} surface node{'s' if int(nodes) != 1 else ''} on the "
                            "punch face, so the force is a mesh-level estimate" if np.isfinite(nodes) else "")
                text = (f" Pressed {_number(1e3 * r['depth_m'])} mm into the MNI brain, it {change}: {band} taken "
                        f"relative, {spread}{resolved}.")
            else:
                text = (f" In a {_number(1e3 * r['depth_m'])} mm flat-punch indentation the extension's card {change}, "
                        f"{band} ({_number(1e3 * r['measurement_q05_n'])}-{_number(1e3 * r['measurement_q95_n'])} "
                        f"mN) and {spread}.")
        out[r["cause"]] = out.get(r["cause"], "") + text
    return out


def diagnosis_html(path: Path) -> str:
    """The diagnosis of ``diagnosis.json`` in plain words: each named cause with its fix, the held-out gain of the
    fix and, where the finding carries one, what to do next; then what the data cannot identify.

    Only named causes (``detected``) are listed; every other test is in the dataset page's full table
    (:func:`diagnosis_table`)."""
    if not path.is_file():
        return ""
    d = json.loads(path.read_text())
    felt = _extension_indentation(path.parent / "uq" / "extension_indentation.csv")
    out = []
    for f in (Finding.from_dict(x) for x in d.get("findings", [])):
        if not f.detected:
            continue
        fix = f.fix or {}
        gain = (f" The fix, {_esc(fix['model'])}, predicts data it was not fitted to better: "
                f"{_esc(fix['metric'])} {_number(fix.get('before'))} → {_number(fix.get('after'))} "
                f"(gain {_number(f.fix_gain)})." if fix else "")
        sim = fix.get("simulation") if isinstance(fix, dict) else None
        if isinstance(sim, dict) and sim.get("held_out_tests"):
            gain += (f" In the simulator (TLED replay of the tests neither card was fitted to: "
                     f"{_esc(', '.join(sim['held_out_tests']))}) the extension's card brings the NRMSE from "
                     f"{_number(sim.get('before'))} to {_number(sim.get('after'))} (gain {_number(sim.get('gain'))}).")
        gain += felt.get(f.effect, "")
        out.append(f'<li class="finding"><b>{html.escape(_finding_title(f.data))}</b> '
                   f'(<code>{html.escape(f.effect)}</code>).{gain}{_what_to_do(f.data)}'
                   f"<details><summary>evidence</summary>{_esc(f.evidence)}</details></li>")
    tested = [x for x in d.get("findings", []) if x.get("tested", True) and x.get("effect") != "baseline_inadequate"]
    if not out:
        alpha = d.get("alpha")
        out.append(f"<li>No named cause: none of the {len(tested)} causes tested passed the decision rule "
                   f"(significant at the family-wise α = {_number(alpha)}, large enough to matter, and a fix that "
                   f"predicts held-out data better).</li>")
    for s in d.get("not_identifiable", []):
        effect = s.get("effect", "") if isinstance(s, dict) else ""
        evidence = s.get("evidence", "") if isinstance(s, dict) else str(s)
        name = CAUSE_TITLES.get(effect, effect) or "a model feature"
        scope = (f"the {str(s['data']).replace('_', ' ')} tests alone" if isinstance(s, dict) and s.get("data")
                 else "these data")
        out.append(f"<li>Not identifiable from {html.escape(scope)}: {html.escape(name[:1].lower() + name[1:])}."
                   f"<details><summary>why</summary>{_esc(evidence)}</details></li>")
    n_unexplained = len(d.get("unexplained", []))
    if n_unexplained:
        out.append(f"<li>{n_unexplained} residual structure(s) that no named cause explains (dataset page, "
                   "diagnosis table).</li>")
    return "<ul>" + "".join(out) + "</ul>"


def _diagnosed_model(path: Path) -> str:
    if not path.is_file():
        return ""
    d = json.loads(path.read_text())
    baseline = d.get("baseline") or {}
    model = d.get("model") or baseline.get("model")
    if not model:
        return ""
    adequate = baseline.get("adequate")
    state = ("" if adequate is None else " (adequate: it describes the data closely enough to be diagnosed)"
             if adequate else " (no candidate was adequate: only causes that need no baseline can be named)")
    return f"<p>Diagnosed model: <b>{html.escape(str(model))}</b>{state}.</p>"


def _dataset_tests(d: Path) -> list[str]:
    ingest = _read_csv(d / "ingest_report.csv")
    if ingest is None or "test" not in ingest:
        return []
    ok = ingest[ingest["status"].astype(str) == "ok"] if "status" in ingest else ingest
    return sorted(set(ok["test"].dropna().astype(str)))


def _no_diagnosis_reason(d: Path) -> str:
    if not (d / "ranking.csv").is_file():
        return ("No diagnosis: no model was fitted to this dataset (no ranking.csv), so there is no fit whose "
                "residuals could be examined.")
    return ("No diagnosis for this dataset: the workflow diagnoses a dataset through a fitted scope of "
            "relaxations, ramps, creep, sweeps or of simple shear with uniaxial tests, and this one has none, or its "
            f"diagnose job did not finish (logs/{d.name}/diagnose.log).")


def _cross_test(d: Path, model: str) -> str:
    table = _read_csv(d / "cross_test.csv")
    if table is None:
        return NOT_AVAILABLE
    rows = table[table["model"].astype(str) == model] if "model" in table else table.iloc[0:0]
    if rows.empty:
        return "none for this model"
    return "; ".join(f"{r.get('held_out_test', '?')}: NRMSE {_number(r.get('nrmse'))}"
                     + (f" ({int(r['n_points'])} points)" if pd.notna(r.get("n_points")) else "")
                     for _, r in rows.iterrows())


def _no_recommendation_reason(rows: pd.DataFrame) -> str:
    if "verdict_reason" in rows and rows["verdict_reason"].notna().any():
        return plain_statement(rows["verdict_reason"].dropna().iloc[0])
    statement = plain_statement(rows["recommendation"].iloc[0]) if "recommendation" in rows else ""
    match = re.search(r"No model is recommended: (.*)", statement)
    return match.group(1) if match else statement or "no fit is recommendable"


def verdict_rows(ranking: pd.DataFrame, d: Path) -> list[dict[str, str]]:
    """One row per scope of ``ranking.csv``: the recommended model (or why there is none), its misfit in units of
    the measurement noise (column ``misfit_noise_units``), NRMSE, held-out (cross-validated) NRMSE, and its
    prediction of other test kinds (``cross_test.csv``); "not available" where a table lacks the column, "not
    measured" where the value is missing. A ``material`` scope comes first."""
    scopes = list(dict.fromkeys(ranking["scope"].astype(str)))
    scopes.sort(key=lambda s: s != "material")
    out = []
    for scope in scopes:
        rows = ranking[ranking["scope"].astype(str) == scope]
        chosen = rows[rows["recommended"].fillna(False).astype(bool)] if "recommended" in rows else rows.iloc[0:0]
        verdict = str(rows["verdict"].dropna().iloc[0]) if "verdict" in rows and rows["verdict"].notna().any() else ""
        if chosen.empty or verdict == "no_model_supported":
            label = "no model supported" if verdict == "no_model_supported" else "no model recommended"
            out.append({"scope": scope, "model": f"{label}: {_no_recommendation_reason(rows)}", "none": "1",
                        "misfit": "", "nrmse": "", "cv": "", "cross": ""})
            continue
        row = chosen.iloc[0]
        model = str(row["model"])
        out.append({
            "scope": scope, "model": model, "none": "",
            "misfit": (_number(row["misfit_noise_units"]) if "misfit_noise_units" in row.index else NOT_AVAILABLE),
            "nrmse": _number(row.get("nrmse")),
            "cv": _number(row.get("cv_nrmse")),
            "cross": _cross_test(d, model),
        })
    return out


def _fem_line(d: Path) -> str:
    table = _read_csv(d / "fem" / "torsion.csv")
    if table is None or "nrmse" not in table:
        return ""
    ok = table[table["status"].astype(str) == "ok"] if "status" in table else table
    if ok.empty:
        return "<p>FEM torsion: every simulation failed (dataset page, FEM).</p>"
    rates = sorted(ok["rate_1_s"].unique())
    head = "".join(f"<th>NRMSE at {_number(r, '{:g}')} 1/s</th>" for r in rates)
    rows = "".join(f"<tr><td>{html.escape(str(card))}</td>" + "".join(
        f"<td>{_number(g.loc[g['rate_1_s'] == r, 'nrmse'].iloc[0]) if (g['rate_1_s'] == r).any() else '–'}</td>"
        for r in rates) + "</tr>" for card, g in ok.groupby("card", sort=False))
    return ("<h4>FEM check: rheometer torsion with the recommended cards against the measured torque</h4>"
            f"<table><thead><tr><th>card (scope/model)</th>{head}</tr></thead><tbody>{rows}</tbody></table>")


def verdict_card(results_dir, dataset: str, page) -> str:
    """The answer for one dataset, first on both pages: which model to use per scope, how good it is and what is
    wrong with it (:func:`verdict_rows`, :func:`diagnosis_html`), and the FEM torsion check."""
    d = Path(results_dir) / dataset
    page = Path(page)
    ranking = _read_csv(d / "ranking.csv")
    parts = ['<div class="card">']
    if ranking is None or "scope" not in ranking:
        tests = _dataset_tests(d)
        parts.append("<p class='none'>No model was fitted: "
                     + ("no run was ingested (ingest report below)." if not tests else
                        f"none of the test kinds ({', '.join(tests)}) has candidate models in the configuration, "
                        "or the fit jobs did not finish.") + "</p>")
    else:
        rows = verdict_rows(ranking, d)
        head = ("<tr><th>scope</th><th>recommended model</th><th>misfit (noise units)</th><th>NRMSE</th>"
                "<th>held-out NRMSE (cross-validation)</th><th>cross-test prediction</th></tr>")
        body = []
        for r in rows:
            if r["none"]:
                body.append(f"<tr><td>{html.escape(r['scope'])}</td><td colspan='5' class='none'>"
                            f"{html.escape(r['model'])}</td></tr>")
            else:
                body.append("<tr>" + "".join(f"<td>{html.escape(r[k])}</td>" for k in
                                             ("scope", "model", "misfit", "nrmse", "cv", "cross")) + "</tr>")
        parts.append(f"<table class='verdict'><thead>{head}</thead><tbody>{''.join(body)}</tbody></table>"
                     "<p class='muted'>Held-out NRMSE: the model refitted without a condition, specimen or test kind "
                     "and scored on it (not measured where the scope has no such design). Cross-test: a model "
                     "fitted to some test kinds predicting another.</p>")
        if "recommendation" in ranking:
            statements = ranking.groupby("scope", sort=False)["recommendation"].first()
            parts.append("<details><summary>why these models (the thesis rule and the data's ranking, per scope)"
                         "</summary><ul>" + "".join(f"<li><b>{html.escape(str(s))}</b>: {_esc(t)}</li>"
                                                    for s, t in statements.items()) + "</ul></details>")
    parts.append("<h4>What the diagnosis finds</h4>")
    if (d / "diagnosis.json").is_file():
        parts.append(_diagnosed_model(d / "diagnosis.json") + diagnosis_html(d / "diagnosis.json"))
    else:
        parts.append(f"<p class='muted'>{html.escape(_no_diagnosis_reason(d))}</p>")
    parts.append(_fem_line(d))
    parts.append("</div>")
    return "".join(parts)


# ---- the dataset page -----------------------------------------------------------------------------------
def _outcome(f: Finding) -> str:
    if not f.tested:
        return "not testable"
    if f.detected:
        return "named"
    if f.significant and f.practical:
        return "significant, but its fix does not predict held-out data better"
    if f.significant:
        return "significant, too small to matter"
    return "not significant"


def diagnosis_table(path: Path) -> str:
    """Every cause the diagnosis tested (named or not, testable or not, with the reason), the residual structure no
    cause explains, and the covariates the design cannot separate."""
    d = json.loads(path.read_text())
    rows = []
    for f in (Finding.from_dict(x) for x in d.get("findings", [])):
        fix = f"{_number(f.fix_gain)} ({_esc((f.fix or {}).get('model', ''))})" if f.fix else "–"
        rows.append(f"<tr><td><b>{html.escape(_finding_title(f.data))}</b><br><code>{html.escape(f.effect)}</code>"
                    f"</td><td>{html.escape(_outcome(f))}</td><td>{_number(f.p_holm, missing='–')}</td>"
                    f"<td>{_number(f.effect_size, missing='–')}</td><td>{fix}</td>"
                    f"<td>{_what_to_do(f.data) or '–'}</td><td>{_long_text(plain_statement(f.evidence), 160)}</td></tr>")
    out = ["<div class='wide'><table><thead><tr><th>cause</th><th>outcome</th><th>p (Holm)</th><th>effect size</th>"
           "<th>held-out gain of the fix</th><th>what to do</th><th>evidence</th></tr></thead><tbody>"
           + "".join(rows) + "</tbody></table></div>"]
    unexplained = d.get("unexplained", [])
    if unexplained:
        frame = pd.DataFrame(unexplained)
        keep = [c for c in ("test", "quantity", "curve", "covariate", "level", "statistic", "p_value", "p_holm",
                            "effect_size", "evidence") if c in frame]
        out.append("<h4>Residual structure no named cause explains</h4>" + html_table(frame[keep]))
    confounded = d.get("confounded", [])
    if confounded:
        out.append("<h4>Covariates this design cannot separate</h4><ul>" + "".join(
            f"<li>{html.escape(', '.join(map(str, c.get('covariates', []))))}: {_esc(c.get('design', ''))}</li>"
            for c in confounded if isinstance(c, dict)) + "</ul>")
    return "".join(out)


def cards_html(d: Path, page: Path) -> str:
    """The material cards of a dataset as HTML tables, one per scope, the recommended card shaded, each model
    linked to its JSON card."""
    root = d / "cards"
    if not root.is_dir() or not any(root.glob("*/*.json")):
        return "<p class='muted'>No material card: no model was fitted to this dataset.</p>"
    table = card_table(root, d / "ranking.csv")
    out = []
    csv = d / "cards.csv"
    if csv.is_file():
        out.append(f'<p><a href="{_href(csv, page)}" download>cards.csv</a>: every card of the dataset. Files per '
                   "card: JSON (the input of the TLED solver), Abaqus .inp, FEBio .feb.xml and NiftySim .niftysim.xml "
                   "where the law has a checked form (the JSON card says why not otherwise).</p>")
    for scope, rows in table.groupby("scope", sort=False):
        shown = rows.drop(columns=["scope"]).reset_index(drop=True)
        chosen = shown["recommended"].tolist() if "recommended" in shown else None
        links = [f'<a href="{_href(root / str(scope) / f"{m}.json", page)}">{html.escape(str(m))}</a>'
                 for m in shown["model"]]
        out.append(f"<h4>{html.escape(str(scope))}</h4><p>JSON cards: {', '.join(links)}</p>"
                   + html_table(shown, chosen))
    return "".join(out)


def _torsion_html(d: Path, page: Path) -> str:
    path = d / "fem" / "torsion.csv"
    if path.is_file():
        frame = _read_csv(path)
        if frame is None:
            return ("<p class='muted'>The torsion table is empty: no recommended card of this dataset has a law the "
                    f"TLED solver runs (logs/{d.name}/fem_torsion.log names the cards left out).</p>")
        return _csv_section(path, page)
    if "constant_shear_rate" not in _dataset_tests(d):
        return ("<p class='muted'>No FEM torsion: the torsion experiment replays the constant-shear-rate ramps of a "
                "dataset, and this one has none.</p>")
    return (f"<p class='muted'>No FEM torsion result: the fem_torsion job did not finish "
            f"(logs/{d.name}/fem_torsion.log).</p>")


def _uq_html(d: Path, page: Path) -> str:
    parts = []
    for path in sorted((d / "population").glob("*.levels.csv")):
        parts.append(f"<h4>Specimen variability, scope {html.escape(path.name.split('.')[0])}</h4>"
                     + _csv_section(path, page))
    for path in sorted((d / "posterior").glob("*/*.csv")):
        parts.append(f"<h4>Posterior of {html.escape(path.stem)} ({html.escape(path.parent.name)})</h4>"
                     + _csv_section(path, page))
    return "".join(parts)


def dataset_page(results_dir, dataset: str, page, captions_dir=None, config: Mapping | None = None,
                 main_page=None) -> Path:
    """Write the page of one dataset: its verdict card, the full diagnosis, ranking, cards, FEM and data tables
    (every row; each CSV linked for download) and its figures, loaded lazily, with their captions."""
    root = Path(results_dir)
    d = root / dataset
    page = Path(page)

    def caption(stem: str, wildcards: Mapping[str, str] | None = None) -> str:
        if captions_dir is None:
            return ""
        body = render_caption(Path(captions_dir) / f"{stem}.rst", config, {"dataset": dataset, **(wildcards or {})})
        return f'<div class="caption">{body}</div>' if body else ""

    sections: list[tuple[str, str, str]] = [("verdict", "Verdict", verdict_card(root, dataset, page))]
    if (d / "diagnosis.json").is_file():
        sections.append(("diagnosis", "Diagnosis: every cause tested", caption("diagnosis_json")
                         + diagnosis_table(d / "diagnosis.json")))
    if (d / "ranking.csv").is_file():
        sections.append(("ranking", "Ranking", caption("ranking_table") + _csv_section(
            d / "ranking.csv", page, ["scope", "model", "family", "rank", "recommended", "verdict", "verdict_reason",
                                      "misfit_noise_units", "nrmse", "cv_nrmse", "aicc", "delta_aicc",
                                      "akaike_weight", "bic", "n", "k", "converged", "has_covariance", "at_bound",
                                      "recommendable", "n_flags", "flags"])))
    if (d / "cross_test.csv").is_file():
        sections.append(("cross-test", "Cross-test prediction", _csv_section(d / "cross_test.csv", page)))
    sections.append(("cards", "Material cards", caption("cards", {"scope": "each scope below"}) + cards_html(d, page)))
    sections.append(("fem", "FEM", "<h4>Rheometer torsion</h4>" + caption("fem_torsion_table")
                     + _torsion_html(d, page)))
    uq = _uq_html(d, page)
    if uq:
        sections.append(("uncertainty", "Uncertainty", uq))
    sections.append(("ingest", "Ingest", caption("ingest") + _csv_section(
        d / "ingest_report.csv", page, missing="No ingest report: the ingest job did not finish "
                                               f"(logs/{dataset}/ingest.log).")))
    if (d / "lve.csv").is_file():
        sections.append(("lve", "LVE limits", caption("lve_table") + _csv_section(d / "lve.csv", page)))
    for anchor, title, stem, pattern in SECTIONS:
        paths = sorted(d.glob(pattern))
        if not paths:
            continue
        if stem == "fits":
            groups: dict[str, list[Path]] = {}
            for p in paths:
                groups.setdefault(p.parent.name, []).append(p)
            body = "".join(f"<h4>{html.escape(scope)}</h4>" + caption(stem, {"scope": scope})
                           + "".join(_lazy_figure(p, root, page) for p in group) for scope, group in groups.items())
        else:
            body = caption(stem) + "".join(_lazy_figure(p, root, page) for p in paths)
        sections.append((anchor, title, body))
    back = (f'<p><a href="{_href(Path(main_page), page)}">← every dataset</a></p>' if main_page is not None else "")
    toc = "<nav><h2>Contents</h2><ol>" + "".join(f'<li><a href="#{a}">{html.escape(t)}</a></li>'
                                                 for a, t, _ in sections) + "</ol></nav>"
    body = "".join(f'<section id="{a}"><h2>{html.escape(t)}</h2>{b}</section>' for a, t, b in sections)
    text = (f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>{html.escape(dataset)}: tissuemech "
            f"results</title><style>{_STYLE}</style></head><body>{back}<h1>{html.escape(dataset)}</h1>{toc}{body}"
            "</body></html>")
    return write_text(text, page)


def results_datasets(results_dir) -> list[str]:
    """Datasets with results (a folder ``results/<name>/`` holding an ingest report), by name."""
    return sorted(p.parent.name for p in Path(results_dir).glob("*/ingest_report.csv"))


def build_summary(results_dir, datasets: Sequence[str], out_html, captions_dir=None,
                  config: Mapping | None = None) -> Path:
    """Write the summary: ``out_html`` answers per dataset (a table of contents, then a verdict card per dataset,
    :func:`verdict_card`) and links a page per dataset, ``<folder of out_html>/<dataset>/summary.html``
    (:func:`dataset_page`: every table in full with its CSV, every figure, loaded lazily, with its caption).

    Figures are linked, not embedded, so the pages stay small (kilobytes); they are read from ``results_dir``,
    so keep the results folder together when moving the pages (in the pipeline the pages sit inside it).

    Parameters
    ----------
    results_dir : the ``results`` folder.
    datasets : dataset names, in display order.
    out_html : the main page.
    captions_dir : folder of the report captions (``workflow/report``); each heads its section, rendered by
        :func:`render_caption` with ``config`` and the dataset name.
    config : the workflow configuration the captions may quote.
    """
    root = Path(results_dir)
    out_html = Path(out_html)
    cards, toc = [], []
    for name in datasets:
        page = out_html.parent / name / "summary.html"
        dataset_page(root, name, page, captions_dir, config, main_page=out_html)
        anchor = f"ds-{safe_name(name)}"
        toc.append(f'<li><a href="#{anchor}">{html.escape(name)}</a> (<a href="{_href(page, out_html)}">full page'
                   "</a>)</li>")
        cards.append(f'<section id="{anchor}"><h2>{html.escape(name)}</h2>{verdict_card(root, name, out_html)}'
                     f'<p><a href="{_href(page, out_html)}">{html.escape(name)}: diagnosis, ranking, cards, FEM, '
                     "ingest and LVE tables (with their CSV files) and every figure →</a></p></section>")
    timing = root / "fem" / "timing.csv"
    caption = (render_caption(Path(captions_dir) / "timing.rst", config) if captions_dir is not None else "")
    timing_html = ""
    if timing.is_file():
        timing_html = (f'<section id="timing"><h2>TLED timing</h2><div class="caption">{caption}</div>'
                       + _csv_section(timing, out_html, ["mesh", "n_elements", "law", "precision", "device", "kernel",
                                                         "element_updates_per_s", "real_time_factor", "threads"])
                       + "".join(_lazy_figure(p, root, out_html) for p in sorted((root / "fem").glob("figures/*.png")))
                       + "</section>")
        toc.append('<li><a href="#timing">TLED timing</a></li>')
    workflow = render_caption(Path(captions_dir) / "workflow.rst", config) if captions_dir is not None else ""
    if workflow:
        toc.append('<li><a href="#workflow">How these results were made</a></li>')
        workflow = f'<section id="workflow"><h2>How these results were made</h2>{workflow}</section>'
    intro = ("<p>Per dataset: the model to use in each scope (a set of tests fitted together), how closely it fits "
             "(misfit in units of the measurement noise, NRMSE), how well it predicts data it was not fitted to "
             "(held-out and cross-test NRMSE), and what the diagnosis finds wrong with it. Each dataset's own page "
             "has every table in full, with its CSV file, and every figure.</p>")
    text = ("<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>tissuemech results</title>"
            f"<style>{_STYLE}</style></head><body><h1>tissuemech results</h1>{intro}"
            f"<nav><h2>Contents</h2><ol>{''.join(toc)}</ol></nav>{''.join(cards)}{timing_html}{workflow}"
            "</body></html>")
    return write_text(text, out_html)


__all__ = ["CAUSE_TITLES", "FIT_ABSCISSA", "SECTIONS", "boundary_faces", "build_summary", "caption_text",
           "card_table", "cards_html", "dataset_page", "diagnosis_html", "diagnosis_table", "figure_mesh",
           "figure_scope_fit", "figure_timing", "fit_panels", "html_table", "plain_statement", "plot_cards",
           "plot_meshes", "plot_posterior_fit", "plot_scope_fits", "plot_timing", "render_caption",
           "results_datasets", "verdict_card", "verdict_rows"]


# ------------------------------------------------------------------------------------------------------
# the fit and rank jobs (the workflow's scripts and tissuemech.analysis run the same functions)
# ------------------------------------------------------------------------------------------------------
def fit_scope_job(averages_path, scope: str, spec: Mapping, target: str, seed: int, multistart: int, fits_dir,
                  cards_dir, ranking_path, poisson_ratio: float, dataset: str = "", tts_path=None,
                  figures_dir=None) -> pd.DataFrame:
    """Rule ``fit_scope``: :func:`tissuemech.stages.run_fit_scope` and, with ``figures_dir``, the fit figures
    (:func:`plot_scope_fits`; the material scope draws its baseline and recommended model). Returns the ranking."""
    table = run_fit_scope(averages_path, scope, spec, target=target, seed=seed, multistart=multistart,
                          fits_dir=fits_dir, cards_dir=cards_dir, ranking_path=ranking_path, dataset=dataset,
                          poisson_ratio=poisson_ratio, tts_path=tts_path)
    if figures_dir is not None:
        shown = None
        if spec.get("material") and not table.empty and "baseline" in table:
            shown = set(table.loc[table["baseline"].astype(bool) | table["recommended"].astype(bool), "model"])
        plot_scope_fits(averages_path, fits_dir, spec, figures_dir, tts_path=tts_path, models=shown)
    return table
