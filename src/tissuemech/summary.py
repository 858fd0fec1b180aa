"""Report figures the stages do not draw themselves, and a self-contained HTML summary of the results.

Figures (PNG + SVG, written through :func:`tissuemech.plots.save_figure`):

* :func:`plot_scope_fits` -- every fitted model of a scope over its averaged data, linear and log axes;
* :func:`plot_posterior_fit` -- the same figure of one sampled fit with its 5-95 % posterior-predictive band
  (rule ``posterior``, after the fit job that draws the plain figures);
* :func:`plot_cards` -- the material cards of a dataset as tables, one per scope (``cards.csv`` alongside);
* :func:`plot_meshes` -- the deformed TLED meshes of the FEM experiments (VTU files), coloured by |u|;
* :func:`plot_timing` -- TLED step time and real-time factor against mesh size.

:func:`build_summary` writes ``results/summary.html``: the page a rheologist reads first (tables, named
diagnosis findings, every figure with its caption) without any Snakemake machinery. ``snakemake --report``
adds provenance, runtimes and the rule graph to the same figures.
"""
from __future__ import annotations

import base64
import html
import json
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
from matplotlib.ticker import MaxNLocator, NullFormatter

from .canonical import read_netcdf, write_text
from .fem.mesh import TET_FACES, read_mesh
from .fitting import target_observations
from .pipeline import progress
from .plots import (all_positive, axis_label, figure_curves, figure_table, new_figure, safe_name,
                    save_figure)
from .ranking import recommended_models
from .records import Finding, FitRecord, MaterialCard
from .stages import scope_curves
from .uq import predictive_band

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


def plot_scope_fits(averages_path, fits_dir, tests: Sequence[str], out_dir, tts_path=None) -> list[Path]:
    """``<out_dir>/<model>.png/.svg`` for every fit record ``<fits_dir>/<model>.nc`` of a scope.

    The curves are rebuilt from the averages exactly as the fit stage builds them
    (:func:`tissuemech.stages.scope_curves`, with the dataset's ``tts.nc`` as ``tts_path`` for the ``mastercurve``
    scope, whose one curve is drawn in reduced frequency), so each fitted point is drawn at its own
    time/strain/rate/frequency.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    averages = read_netcdf(averages_path)
    tts = read_netcdf(tts_path) if tts_path is not None else None
    curves_by_relaxation: dict[str, list] = {}
    written: list[Path] = []
    for path in progress(sorted(Path(fits_dir).glob("*.nc")), f"fit figures {Path(fits_dir).name}"):
        fit = FitRecord.from_netcdf(path)
        relaxation = fit.relaxation
        if relaxation not in curves_by_relaxation:
            curves_by_relaxation[relaxation] = scope_curves(averages, list(tests), relaxation=relaxation, tts=tts)
        fig = figure_scope_fit(fit, curves_by_relaxation[relaxation])
        written += save_figure(fig, out_dir / safe_name(path.stem), dpi=110)
    return written


def plot_posterior_fit(averages_path, record_path, posterior_nc, tests: Sequence[str], out) -> list[Path]:
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
    curves = scope_curves(read_netcdf(averages_path), list(tests), relaxation=fit.relaxation)
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
# HTML summary
# ------------------------------------------------------------------------------------------------------
_STYLE = """body{font-family:sans-serif;margin:2em;max-width:1200px}table{border-collapse:collapse;font-size:12px}
td,th{border:1px solid #ccc;padding:2px 6px}h2{border-bottom:2px solid #345}img{max-width:560px;margin:4px}
figure{display:inline-block;vertical-align:top;margin:4px}figcaption{font-size:11px;max-width:560px}
.finding{background:#fff3e0;padding:4px;margin:4px 0}.caption{color:#333;font-size:13px;max-width:900px}"""

#: summary sections: (title, caption file stem, glob of figures under results/<dataset>/)
SECTIONS: tuple[tuple[str, str, str], ...] = (
    ("Raw runs vs sample averages", "averages", "figures/averages/*.png"),
    ("LVE limit of the amplitude sweeps", "lve", "figures/lve/*.png"),
    ("Fits over their data", "fits", "figures/fits/*/*.png"),
    ("Fits with posterior-predictive bands", "posterior_predictive", "figures/posterior/*/*.png"),
    ("Model ranking", "ranking", "figures/ranking.png"),
    ("Diagnosis", "diagnosis", "figures/diagnosis/*.png"),
    ("Material cards", "cards", "figures/cards/*.png"),
    ("FEM experiments", "fem", "figures/fem_*.png"),
    ("Indentation bands: measurement and specimen variability", "uq_indentation", "figures/uq_indentation_*.png"),
    ("Torsion bands: measurement and specimen variability", "uq_torsion", "figures/uq_torsion_*.png"),
    ("FEM meshes", "meshes", "figures/meshes/*.png"),
)


def caption_text(path: Path) -> str:
    """Plain text of a report caption (reStructuredText with Jinja): markup and template tags removed."""
    if not path.is_file():
        return ""
    text = re.sub(r"\{[{%].*?[%}]\}", "", path.read_text(encoding="utf-8"))
    text = re.sub(r"^\.\. .*$", "", text, flags=re.M)
    text = re.sub(r"[`*]+", "", text)
    return " ".join(text.split())


class _Wildcards:
    """Wildcards of a caption rendered for a whole section: known ones by value, the others as ``<name>``."""

    def __init__(self, known: Mapping[str, str]):
        self._known = dict(known)

    def __getattr__(self, name: str) -> str:
        if name.startswith("__"):
            raise AttributeError(name)
        return self._known.get(name, f"<{name}>")


def render_caption(path: Path, config: Mapping | None = None, wildcards: Mapping[str, str] | None = None,
                   keep_title: bool = False) -> str:
    """HTML of a report caption, rendered as ``snakemake --report`` does (Jinja, then reStructuredText).

    ``snakemake.config`` is ``config``; wildcards not given appear as ``<name>`` (a section caption stands for
    every figure of the section). Without jinja2/docutils (Snakemake's own dependencies) the caption's plain
    text (:func:`caption_text`) is returned, escaped.
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


def _table(path: Path, columns: list[str] | None = None, rows: int = 25) -> str:
    if not path.is_file() or path.stat().st_size == 0:
        return f"<p><i>{html.escape(path.name)} not produced</i></p>"
    frame = pd.read_csv(path)
    if columns:
        frame = frame[[c for c in columns if c in frame]]
    return frame.head(rows).to_html(index=False, float_format=lambda v: f"{v:.4g}", na_rep="")


def _img(path: Path, label: str) -> str:
    data = base64.b64encode(path.read_bytes()).decode()
    name = html.escape(label)
    return (f'<figure><img alt="{name}" title="{name}" src="data:image/png;base64,{data}">'
            f"<figcaption>{name}</figcaption></figure>")


def _g(value) -> str:
    """A number with 3 significant digits (text and None as they are)."""
    return f"{value:.3g}" if isinstance(value, (int, float)) and not isinstance(value, bool) else str(value)


def _diagnosis(path: Path) -> str:
    if not path.is_file():
        return "<p><i>no diagnosis</i></p>"
    d = json.loads(path.read_text())
    out = []
    for f in (Finding.from_dict(x) for x in d.get("findings", [])):
        if not f.detected:
            continue
        fix = f.fix or {}
        out.append(f'<div class="finding"><b>{html.escape(f.effect)}</b> (p = {_g(f.p_value)}, '
                   f'effect size {_g(f.effect_size)}): {html.escape(f.evidence)}'
                   + (f"<br>fix: {html.escape(fix['model'])} — {html.escape(fix['metric'])} "
                      f"{_g(fix.get('before'))} → {_g(fix.get('after'))} (gain {_g(f.fix_gain)})" if fix else "")
                   + "</div>")
    for s in d.get("not_identifiable", []):
        if isinstance(s, dict):
            text = f"<b>{html.escape(str(s.get('effect', '')))}</b>: {html.escape(str(s.get('evidence', '')))}"
        else:
            text = html.escape(str(s))
        out.append(f'<div class="finding">not identifiable from these data — {text}</div>')
    for u in d.get("unexplained", [])[:10]:
        out.append(f"<div>unexplained structure vs <b>{html.escape(str(u.get('covariate')))}</b> "
                   f"(p = {_g(u.get('p_value'))}, effect {_g(u.get('effect_size'))})</div>")
    return "".join(out) or "<p>no named cause and no unexplained structure at the family-wise α</p>"


def _figures(root: Path, pattern: str) -> str:
    paths = sorted(root.glob(pattern))
    if not paths:
        return "<p><i>no figures</i></p>"
    return "".join(_img(p, str(p.relative_to(root).with_suffix(""))) for p in paths)


def build_summary(results_dir, datasets: list[str], out_html, captions_dir=None, config: Mapping | None = None) -> Path:
    """Write ``out_html``: per dataset its ingest, LVE, ranking, diagnosis and FEM tables and every figure.

    Parameters
    ----------
    results_dir : the ``results`` folder.
    datasets : dataset names, in display order.
    out_html : the page to write (figures are embedded as base64 PNG: one file to mail or archive).
    captions_dir : folder of the report captions (``workflow/report``); each heads its section, rendered by
        :func:`render_caption` with ``config`` and the dataset name.
    config : the workflow configuration the captions may quote.
    """
    root = Path(results_dir)
    captions = Path(captions_dir) if captions_dir is not None else None

    def caption(stem: str, dataset: str | None = None, keep_title: bool = False) -> str:
        if captions is None:
            return ""
        body = render_caption(captions / f"{stem}.rst", config, {"dataset": dataset} if dataset else {},
                              keep_title=keep_title)
        return f'<div class="caption">{body}</div>' if body else ""

    parts = [f"<html><head><meta charset='utf-8'><title>tissuemech results</title><style>{_STYLE}</style></head><body>",
             "<h1>tissuemech results</h1>", caption("workflow", keep_title=False)]
    for name in datasets:
        d = root / name
        parts.append(f'<h2 id="{html.escape(name)}">{html.escape(name)}</h2>')
        parts.append("<h3>Ingest</h3>" + _table(d / "ingest_report.csv", ["run", "file", "test", "status", "reason"], 12))
        parts.append("<h3>LVE limits</h3>" + _table(d / "lve.csv"))
        # flags are spelled out in ranking.csv; here their count keeps the table readable
        parts.append("<h3>Ranking</h3>" + _table(d / "ranking.csv", ["scope", "model", "family", "rank", "aicc",
                                                                     "delta_aicc", "bic", "rmse", "nrmse", "cv_nrmse",
                                                                     "n_flags", "recommended"], 40))
        rec = d / "ranking.csv"
        if rec.is_file() and rec.stat().st_size:
            frame = pd.read_csv(rec)
            if "recommendation" in frame:
                for scope, text in frame.groupby("scope")["recommendation"].first().items():
                    parts.append(f"<p><b>{html.escape(str(scope))}</b>: {html.escape(str(text))}</p>")
        parts.append("<h3>Diagnosis findings</h3>" + _diagnosis(d / "diagnosis.json"))
        parts.append("<h3>FEM torsion vs measured torque</h3>" + _table(d / "fem" / "torsion.csv"))
        for title, stem, pattern in SECTIONS:
            if any(d.glob(pattern)):
                parts.append(f"<h3>{html.escape(title)}</h3>" + caption(stem, name) + _figures(d, pattern))
    parts.append("<h2>TLED timing</h2>" + caption("timing") + _table(root / "fem" / "timing.csv", rows=60)
                 + _figures(root / "fem", "figures/*.png"))
    parts.append("</body></html>")
    return write_text("\n".join(parts), out_html)


__all__ = ["FIT_ABSCISSA", "SECTIONS", "boundary_faces", "build_summary", "caption_text", "card_table",
           "figure_mesh", "figure_scope_fit", "fit_panels", "plot_cards", "plot_meshes", "plot_posterior_fit",
           "plot_scope_fits",
           "plot_timing", "render_caption"]
