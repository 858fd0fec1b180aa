"""Report figures (matplotlib, object-oriented API on the Agg canvas; no pyplot global state).

Every ``plot_*`` function takes data (numpy arrays, xarray datasets, pandas frames) and an output path, builds
the figure with the matching ``figure_*`` function (public so callers and tests can inspect it) and writes
``<path>.png`` and ``<path>.svg`` atomically (temporary name + rename; a suffix on ``path`` is replaced). SVG
output is deterministic (fixed hash salt, no date) so a rebuild with unchanged data gives identical files; SVG text stays text (searchable).

Axes follow the field's conventions: log-log for relaxation moduli, sweeps and flow curves, log time for
relaxation/creep, linear strain for ramps (see :data:`tissuemech.curves.GRID_SPECS`); fits are shown on both
linear and log axes.
"""
from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from pathlib import Path

import matplotlib
import numpy as np
import pandas as pd
import xarray as xr
from matplotlib.colors import TwoSlopeNorm
from matplotlib.figure import Figure
from matplotlib.ticker import LogFormatter, LogFormatterSciNotation

from .canonical import CANONICAL_VARIABLES, atomic_write
from .curves import QUALITY_FLAG_VARIABLE, select_average, unflagged_points

#: axis labels (symbol [unit]) of canonical variables
AXIS_LABELS: dict[str, str] = {
    "time": "time t [s]",
    "shear_strain": "shear strain γ [–]",
    "shear_stress": "shear stress σ [Pa]",
    "shear_rate": "shear rate γ̇ [1/s]",
    "viscosity": "viscosity η [Pa s]",
    "frequency": "frequency f [Hz]",
    "angular_frequency": "angular frequency ω [rad/s]",
    "storage_modulus": "storage modulus G' [Pa]",
    "loss_modulus": "loss modulus G'' [Pa]",
    "complex_modulus": "|G*| [Pa]",
    "relaxation_modulus": "relaxation modulus G(t) [Pa]",
    "creep_compliance": "creep compliance J(t) [1/Pa]",
    "normal_force": "normal force F_N [N]",
    "torque": "torque M [N m]",
    "stretch": "stretch λ [–]",
    "nominal_stress": "nominal stress P [Pa]",
    "force": "force F [N]",
    "displacement": "displacement [m]",
}

_FORMATS = ("png", "svg")

_SUPERSCRIPT = str.maketrans("-0123456789", "\u207b\u2070\u00b9\u00b2\u00b3\u2074\u2075\u2076\u2077\u2078\u2079")


class PowerOfTenFormatter(LogFormatter):
    """Log-axis tick labels as plain Unicode text: ``10⁻³``, ``2×10⁻³``.

    matplotlib's default log labels are mathtext (``$\\mathdefault{10^{-3}}$``); parsing them (pyparsing) and
    laying them out took a third of the time of drawing our figures (26 average figures: 12.7 -> 8.9 CPU s,
    issue 17). Which ticks get a label is :class:`matplotlib.ticker.LogFormatter`'s choice, unchanged.

    An axis spanning one or two decades has its minor ticks labelled too: matplotlib picks 2, 3, 4 and 6 × each
    power, here 2 and 5 (:meth:`set_locs`), and every label between 0.01 and 10⁵ is written as a plain number
    (``0.02``, ``5``, ``20``), so that the labels fit side by side (``2×10⁰ 3×10⁰ 4×10⁰`` overlapped on a 6-inch
    residual map).

    >>> PowerOfTenFormatter()._num_to_string(2e-3, 1e-4, 1.0)
    '2×10⁻³'
    >>> f = PowerOfTenFormatter(); f._sublabels = {1, 2, 3, 4, 6, 10}
    >>> [f._num_to_string(x, 1.0, 60.0) for x in (2.0, 10.0, 40.0)]
    ['2', '10', '40']
    """

    def set_locs(self, locs=None):
        super().set_locs(locs)
        if self._base == 10 and self._sublabels is not None and 1 < len(self._sublabels) < 10:
            self._sublabels = {1.0, 2.0, 5.0, 10.0}

    def _num_to_string(self, x, vmin, vmax):
        if self._base != 10:
            return super()._num_to_string(x, vmin, vmax)
        exponent = math.floor(math.log10(x) + 1e-10)
        coefficient = x / 10.0 ** exponent
        if not math.isclose(coefficient, round(coefficient), rel_tol=1e-6):
            return f"{x:.3g}"
        if self._sublabels is not None and len(self._sublabels) > 1 and 1e-2 <= x < 1e5:
            return f"{x:g}"
        power = "10" + str(exponent).translate(_SUPERSCRIPT)
        return power if round(coefficient) == 1 else f"{round(coefficient)}×{power}"


def plain_text_log_ticks(fig: Figure) -> None:
    """Replace matplotlib's default (mathtext) log-axis formatters of ``fig`` by :class:`PowerOfTenFormatter`."""
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            if axis.get_scale() != "log":
                continue
            if type(axis.get_major_formatter()) is LogFormatterSciNotation:
                axis.set_major_formatter(PowerOfTenFormatter(axis.get_transform().base))
            minor = axis.get_minor_formatter()
            if type(minor) is LogFormatterSciNotation:
                axis.set_minor_formatter(PowerOfTenFormatter(axis.get_transform().base, labelOnlyBase=minor.labelOnlyBase))


def axis_label(name: str) -> str:
    """Axis label of a canonical variable (falls back to its long name and units)."""
    if name in AXIS_LABELS:
        return AXIS_LABELS[name]
    if name in CANONICAL_VARIABLES:
        units, long_name = CANONICAL_VARIABLES[name]
        return f"{long_name} [{units}]"
    return name


def save_figure(fig: Figure, path: str | Path, dpi: int = 150) -> list[Path]:
    """Write ``fig`` as ``<path>.png`` and ``<path>.svg`` atomically; returns the written paths."""
    base = Path(path)
    base = base.with_suffix("") if base.suffix.lower() in (".png", ".svg", ".pdf") else base
    written = []
    plain_text_log_ticks(fig)
    with matplotlib.rc_context({"svg.hashsalt": "tissuemech", "svg.fonttype": "none"}):
        if fig.get_layout_engine() is not None:
            # lay the figure out once, then drop the engine: with an engine attached, even a placeholder one,
            # every savefig lays it out again. The engine runs on its own (what Figure.draw runs first), not
            # through draw_without_rendering, whose draw after the layout is wasted (same PNG bytes, ~8 % less
            # figure time, issue 17)
            fig.set_dpi(dpi)      # text extents (hence the layout) as in the PNG
            fig.get_layout_engine().execute(fig)
            fig.set_layout_engine(None)
            if fig.get_layout_engine() is not None:  # rcParams ask for a default engine: keep the layout frozen
                fig.set_layout_engine("none")
        for fmt in _FORMATS:
            target = base.parent / f"{base.name}.{fmt}"
            metadata = {"Date": None} if fmt == "svg" else {"Software": None}
            written.append(atomic_write(
                target, lambda tmp, fmt=fmt, metadata=metadata: fig.savefig(tmp, format=fmt, dpi=dpi,
                                                                            metadata=metadata)))
    return written


def save_pyplot_figure(fig, path: str | Path, dpi: int = 120) -> Path:
    """Lay out a pyplot figure, write it as PNG + SVG (:func:`save_figure`) and close it; returns the PNG path."""
    import matplotlib.pyplot as plt

    fig.tight_layout()
    save_figure(fig, path, dpi=dpi)
    plt.close(fig)
    return Path(path)


def new_figure(ncols: int = 1, nrows: int = 1, width: float = 5.0, height: float = 3.8) -> tuple[Figure, np.ndarray]:
    fig = Figure(figsize=(width * ncols, height * nrows), layout="constrained")
    axes = np.atleast_1d(fig.subplots(nrows, ncols, squeeze=False)).ravel()
    return fig, axes


def all_positive(values: np.ndarray) -> bool:
    finite = np.asarray(values, dtype=float)
    finite = finite[np.isfinite(finite)]
    return finite.size > 0 and bool(np.all(finite > 0))


# ----------------------------------------------------------------------------------------------------------------
# raw runs vs sample average


def figure_average(curve: xr.Dataset, variable: str, runs: Sequence[xr.Dataset] = (), title: str | None = None) -> Figure:
    """Raw runs (thin lines) and the sample mean with a ±1 SD band; quality-flagged points as hollow markers.

    Parameters
    ----------
    curve : one averaged curve (:func:`tissuemech.curves.select_average`): grid coordinate, ``<variable>_mean``,
        ``<variable>_sd``, attrs ``grid_scale``, ``n_samples``, ``test``, ``condition``.
    variable : canonical variable on the y axis.
    runs : the member runs, drawn raw (their own points, not resampled). Points with a non-zero
        ``quality_flags`` (:mod:`tissuemech.io.quality`) are drawn as hollow red circles; the legend names the
        flags that occur (``flagged: inertia_dominated`` ...).
    """
    grid_name = next(iter(curve.coords))
    x = np.asarray(curve[grid_name].values, dtype=float)
    mean = np.asarray(curve[f"{variable}_mean"].values, dtype=float)
    sd = np.asarray(curve[f"{variable}_sd"].values, dtype=float) if f"{variable}_sd" in curve else np.full_like(mean, np.nan)
    fig, (ax,) = new_figure()
    meanings: set[str] = set()
    for run in runs:
        if variable not in run:
            continue
        if grid_name in run:
            rx = np.asarray(run[grid_name].values, dtype=float)
        elif grid_name == "frequency" and "angular_frequency" in run:
            rx = np.asarray(run["angular_frequency"].values, dtype=float) / (2 * np.pi)
        else:
            continue
        ax.plot(rx, run[variable].values, color="0.6", lw=0.7, alpha=0.7, zorder=1)
        flagged = ~unflagged_points(run)
        if flagged.any():
            ax.plot(rx[flagged], np.asarray(run[variable].values, dtype=float)[flagged], "o", mfc="none",
                    mec="C3", ms=4, mew=0.8, zorder=4)
            meanings.update(flag_meanings(run, flagged))
    band = np.isfinite(sd)
    ax.fill_between(x, np.where(band, mean - sd, np.nan), np.where(band, mean + sd, np.nan), color="C0",
                    alpha=0.3, lw=0, label="±1 SD", zorder=2)
    n = int(curve.attrs.get("n_samples", 0))
    ax.plot(x, mean, color="C0", lw=2, label=f"mean (n = {n})", zorder=3)
    if runs:
        ax.plot([], [], color="0.6", lw=0.7, label="runs")
    if meanings:
        ax.plot([], [], "o", mfc="none", mec="C3", ms=4, mew=0.8, label="flagged: " + ", ".join(sorted(meanings)))
    log = curve.attrs.get("grid_scale") == "log"
    if log:
        ax.set_xscale("log")
        if all_positive(mean) and variable != "temperature":
            ax.set_yscale("log")
    ax.set_xlabel(axis_label(grid_name))
    ax.set_ylabel(axis_label(variable))
    ax.set_title(title or f"{curve.attrs.get('test', '')} [{curve.attrs.get('condition', '')}]", fontsize=10)
    ax.legend(fontsize=8)
    return fig


def flag_meanings(run: xr.Dataset, points: np.ndarray | None = None) -> list[str]:
    """Names of the quality flags set on ``points`` (bool mask; all points when None) of a run, from the CF
    ``flag_masks``/``flag_meanings`` attributes of its ``quality_flags`` variable."""
    if QUALITY_FLAG_VARIABLE not in run:
        return []
    var = run[QUALITY_FLAG_VARIABLE]
    flags = np.asarray(var.values)
    if points is not None:
        flags = flags[points]
    masks = np.atleast_1d(var.attrs.get("flag_masks", []))
    names = str(var.attrs.get("flag_meanings", "")).split()
    return [name for mask, name in zip(masks, names) if np.any(flags & int(mask))]


def plot_average(curve: xr.Dataset, variable: str, path: str | Path, runs: Sequence[xr.Dataset] = (),
                 title: str | None = None) -> list[Path]:
    """Write :func:`figure_average` as PNG + SVG."""
    return save_figure(figure_average(curve, variable, runs, title), path)


# ----------------------------------------------------------------------------------------------------------------
# LVE limit on an amplitude sweep


def figure_lve(strain: np.ndarray, storage: np.ndarray, loss: np.ndarray, result: Mapping[str, float],
               storage_sd: np.ndarray | None = None, loss_sd: np.ndarray | None = None,
               title: str | None = None) -> Figure:
    """Amplitude sweep G', G'' (log-log) with the G' tolerance band, LVE limit and flow point.

    Parameters
    ----------
    strain, storage, loss : strain amplitude [1], G', G'' [Pa].
    result : output of :func:`tissuemech.lve.analyse_amplitude_sweep` (``lve_strain``, ``plateau_storage_pa``,
        ``tolerance`` optional, ``flow_point_strain``, ``yield_stress_pa``).
    storage_sd, loss_sd : optional SD bands (averaged sweeps).
    """
    strain = np.asarray(strain, dtype=float)
    fig, (ax,) = new_figure()
    for values, sd, colour, label in ((storage, storage_sd, "C0", "G'"), (loss, loss_sd, "C1", "G''")):
        values = np.asarray(values, dtype=float)
        ax.plot(strain, values, "o-", ms=3, color=colour, label=label)
        if sd is not None:
            sd = np.asarray(sd, dtype=float)
            ax.fill_between(strain, values - sd, values + sd, color=colour, alpha=0.25, lw=0)
    tolerance = float(result.get("tolerance", 0.05))
    plateau = float(result.get("plateau_storage_pa", math.nan))
    if math.isfinite(plateau):
        for factor in (1 - tolerance, 1 + tolerance):
            ax.axhline(plateau * factor, color="C0", ls=":", lw=0.8)
    limit = float(result.get("lve_strain", math.nan))
    if math.isfinite(limit):
        ax.axvline(limit, color="k", ls="--", lw=1,
                   label=f"LVE limit γ_L = {100 * limit:.3g} % (τ_y = {result.get('yield_stress_pa', math.nan):.3g} Pa)")
    flow = float(result.get("flow_point_strain", math.nan))
    if math.isfinite(flow):
        ax.axvline(flow, color="C3", ls="-.", lw=1, label=f"flow point γ_f = {100 * flow:.3g} %")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(axis_label("shear_strain"))
    ax.set_ylabel("G', G'' [Pa]")
    ax.set_title(title or f"amplitude sweep, ±{100 * tolerance:g} % band on G'", fontsize=10)
    ax.legend(fontsize=8)
    return fig


def plot_lve(strain, storage, loss, result: Mapping[str, float], path: str | Path, storage_sd=None, loss_sd=None,
             title: str | None = None) -> list[Path]:
    """Write :func:`figure_lve` as PNG + SVG."""
    return save_figure(figure_lve(strain, storage, loss, result, storage_sd, loss_sd, title), path)


# ----------------------------------------------------------------------------------------------------------------
# a fit over its data


def figure_fit(x: np.ndarray, observed: np.ndarray, predicted: np.ndarray, *, xlabel: str, ylabel: str,
               observed_sd: np.ndarray | None = None, label: str = "model", title: str | None = None,
               x_model: np.ndarray | None = None) -> Figure:
    """Data (with SD error bars) and a model prediction on linear axes (left) and log axes (right).

    Parameters
    ----------
    x, observed : data points.
    predicted : model values at ``x_model`` (default: at ``x``).
    xlabel, ylabel : axis labels with units.
    observed_sd : optional SD of the data.

    Notes
    -----
    Log axes drop non-positive values (matplotlib masks them); a log axis is only used when the data along it
    are positive, otherwise the right panel keeps that axis linear (e.g. signed stress).
    """
    x = np.asarray(x, dtype=float)
    observed = np.asarray(observed, dtype=float)
    predicted = np.asarray(predicted, dtype=float)
    xm = x if x_model is None else np.asarray(x_model, dtype=float)
    fig, axes = new_figure(ncols=2)
    for ax, log in zip(axes, (False, True)):
        if observed_sd is not None:
            ax.errorbar(x, observed, yerr=np.asarray(observed_sd, dtype=float), fmt="o", ms=3, color="0.3",
                        ecolor="0.7", elinewidth=0.8, label="data ± SD")
        else:
            ax.plot(x, observed, "o", ms=3, color="0.3", label="data")
        ax.plot(xm, predicted, "-", color="C3", lw=1.8, label=label)
        if log:
            if all_positive(x):
                ax.set_xscale("log")
            if all_positive(observed) and all_positive(predicted):
                ax.set_yscale("log")
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
        ax.set_title("log axes" if log else "linear axes", fontsize=9)
    axes[0].legend(fontsize=8)
    if title:
        fig.suptitle(title, fontsize=10)
    return fig


def plot_fit(x, observed, predicted, path: str | Path, *, xlabel: str, ylabel: str, observed_sd=None,
             label: str = "model", title: str | None = None, x_model=None) -> list[Path]:
    """Write :func:`figure_fit` as PNG + SVG."""
    return save_figure(figure_fit(x, observed, predicted, xlabel=xlabel, ylabel=ylabel, observed_sd=observed_sd,
                                  label=label, title=title, x_model=x_model), path)


# ----------------------------------------------------------------------------------------------------------------
# ranking table


def figure_table(table: pd.DataFrame, *, highlight_column: str | None = None, lowest_is_best: bool = True,
                 title: str | None = None, float_format: str = "{:.4g}") -> Figure:
    """A table figure (e.g. model ranking); the best row by ``highlight_column`` is shaded.

    Parameters
    ----------
    table : rows to show, in display order.
    highlight_column : numeric column that decides the best row (lowest, or highest when
        ``lowest_is_best`` is False); None for no highlight.
    """
    cells = [[float_format.format(v) if isinstance(v, (float, np.floating)) and math.isfinite(v) else
              ("–" if isinstance(v, (float, np.floating)) else str(v)) for v in row]
             for row in table.itertuples(index=False)]
    fig = Figure(figsize=(max(4.0, 1.2 * table.shape[1]), 0.6 + 0.3 * (len(table) + 1)), layout="constrained")
    ax = fig.add_subplot()
    ax.axis("off")
    shown = ax.table(cellText=cells or [[""] * table.shape[1]], colLabels=[str(c) for c in table.columns],
                     loc="center", cellLoc="center")
    shown.auto_set_font_size(False)
    shown.set_fontsize(8)
    for col in range(table.shape[1]):
        shown[0, col].set_facecolor("0.85")
    if highlight_column is not None and len(table):
        values = pd.to_numeric(table[highlight_column], errors="coerce").to_numpy(dtype=float)
        if np.isfinite(values).any():
            best = int(np.nanargmin(values) if lowest_is_best else np.nanargmax(values))
            for col in range(table.shape[1]):
                shown[best + 1, col].set_facecolor("#cfe8cf")
    if title:
        ax.set_title(title, fontsize=10)
    return fig


def plot_table(table: pd.DataFrame, path: str | Path, *, highlight_column: str | None = None,
               lowest_is_best: bool = True, title: str | None = None) -> list[Path]:
    """Write :func:`figure_table` as PNG + SVG (the ranking table of the report)."""
    return save_figure(figure_table(table, highlight_column=highlight_column, lowest_is_best=lowest_is_best,
                                    title=title), path)


# ----------------------------------------------------------------------------------------------------------------
# residual map


def figure_residual_map(residuals: np.ndarray, x: np.ndarray, row_labels: Sequence[str], *, xlabel: str,
                        colorbar_label: str = "normalised residual", log_x: bool = False,
                        title: str | None = None) -> Figure:
    """Residuals as a diverging colour map: one row per curve/condition, columns along ``x``.

    Parameters
    ----------
    residuals : array (rows, len(x)); NaN where a curve has no point.
    x : column positions (e.g. common strain or time grid), increasing.
    row_labels : one label per row.
    log_x : log-spaced column edges (for log grids).
    """
    residuals = np.asarray(residuals, dtype=float)
    x = np.asarray(x, dtype=float)
    if residuals.shape != (len(row_labels), x.size):
        raise ValueError(f"residuals shape {residuals.shape} does not match ({len(row_labels)} rows, {x.size} x values)")
    # cell edges halfway between columns (in log space for log grids)
    u = np.log(x) if log_x else x
    mid = (u[1:] + u[:-1]) / 2 if u.size > 1 else np.array([])
    first = u[0] - (mid[0] - u[0] if mid.size else 0.5)
    last = u[-1] + (u[-1] - mid[-1] if mid.size else 0.5)
    edges = np.concatenate([[first], mid, [last]])
    edges = np.exp(edges) if log_x else edges
    limit = float(np.nanmax(np.abs(residuals))) if np.isfinite(residuals).any() else 1.0
    limit = limit if limit > 0 else 1.0
    fig, (ax,) = new_figure(width=6.0, height=1.2 + 0.35 * len(row_labels))
    mesh = ax.pcolormesh(edges, np.arange(len(row_labels) + 1), np.ma.masked_invalid(residuals), cmap="RdBu_r",
                         norm=TwoSlopeNorm(vcenter=0.0, vmin=-limit, vmax=limit))
    ax.set_yticks(np.arange(len(row_labels)) + 0.5, labels=list(row_labels), fontsize=8)
    if log_x:
        ax.set_xscale("log")
    ax.set_xlabel(xlabel)
    fig.colorbar(mesh, ax=ax, label=colorbar_label)
    if title:
        ax.set_title(title, fontsize=10)
    return fig


def plot_residual_map(residuals, x, row_labels, path: str | Path, *, xlabel: str,
                      colorbar_label: str = "normalised residual", log_x: bool = False,
                      title: str | None = None) -> list[Path]:
    """Write :func:`figure_residual_map` as PNG + SVG."""
    return save_figure(figure_residual_map(residuals, x, row_labels, xlabel=xlabel, colorbar_label=colorbar_label,
                                           log_x=log_x, title=title), path)


# ----------------------------------------------------------------------------------------------------------------
# curves (FEM force-depth, torque-time, before/after comparisons)


def _same_curve(a: tuple[np.ndarray, np.ndarray], b: tuple[np.ndarray, np.ndarray], rtol: float = 1e-3) -> bool:
    """Whether two (x, y) curves would be drawn on top of each other (same x, y within ``rtol`` of the y span)."""
    (xa, ya), (xb, yb) = ((np.asarray(x, float), np.asarray(y, float)) for x, y in (a, b))
    if xa.shape != xb.shape or ya.shape != yb.shape or not np.allclose(xa, xb, rtol=1e-9, equal_nan=True):
        return False
    span = np.nanmax(np.abs(np.concatenate([ya, yb]))) if np.isfinite(ya).any() else 0.0
    return bool(np.allclose(ya, yb, rtol=0.0, atol=rtol * span, equal_nan=True))


def figure_curves(series: Mapping[str, tuple[np.ndarray, np.ndarray]], *, xlabel: str, ylabel: str,
                  reference: Mapping[str, tuple[np.ndarray, np.ndarray]] | None = None, log_x: bool = False,
                  log_y: bool = False, title: str | None = None) -> Figure:
    """Named (x, y) curves as lines, optional reference curves (e.g. closed form, measurement) as markers.

    Every curve stays visible and in the legend: a curve that lies on an earlier one (a rate-independent card
    simulated at two rates gives the same torque) is drawn dashed over it and its legend entry says which curve it
    covers. With more than six entries the legend goes below the axes, so that it hides no curve.
    """
    fig, (ax,) = new_figure()
    drawn: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for i, (name, (x, y)) in enumerate(series.items()):
        under = next((other for other, curve in drawn.items() if _same_curve(curve, (x, y))), None)
        style = {"ls": (0, (4, 3)), "lw": 2.2, "zorder": 3} if under else {"ls": "-", "lw": 1.6, "zorder": 2}
        ax.plot(np.asarray(x, dtype=float), np.asarray(y, dtype=float), color=f"C{i % 10}",
                label=name if under is None else f"{name} (dashed: same as {under})", **style)
        drawn[name] = (x, y)
    for i, (name, (x, y)) in enumerate((reference or {}).items()):
        ax.plot(np.asarray(x, dtype=float), np.asarray(y, dtype=float), "o", ms=3.5, mfc="none",
                color=f"C{(i + len(series)) % 10}", label=name, zorder=4)
    if log_x:
        ax.set_xscale("log")
    if log_y:
        ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if title:
        ax.set_title(title, fontsize=10)
    n_entries = len(series) + len(reference or {})
    if n_entries > 6:
        fig.set_size_inches(fig.get_figwidth() * 1.3, fig.get_figheight() + 0.17 * n_entries)
        fig.legend(loc="outside lower center", fontsize=7, ncols=1)
    elif n_entries:
        ax.legend(fontsize=8)
    return fig


def figure_mastercurve(tts: xr.Dataset, title: str | None = None) -> Figure:
    """Time-temperature superposition (a ``tts.nc`` dataset): the reduced G', G'' against a_T omega coloured by
    temperature (left), log a_T(T) with its standard errors and the fitted WLF/Arrhenius curves (right)."""
    fig, axes = new_figure(ncols=2)
    temps = np.asarray(tts["temperature_c"].values, float)
    mt = np.asarray(tts["master_temperature_c"].values, float)
    x = 10.0 ** np.asarray(tts["log_omega_reduced"].values, float)
    span = (np.nanmin(temps), np.nanmax(temps)) if temps.size else (0.0, 1.0)
    norm = matplotlib.colors.Normalize(*span) if span[1] > span[0] else matplotlib.colors.Normalize(span[0] - 1,
                                                                                                    span[0] + 1)
    cmap = matplotlib.colormaps["coolwarm"]
    for name, marker in (("log_storage_reduced", "o"), ("log_loss_reduced", "^")):
        sc = axes[0].scatter(x, 10.0 ** np.asarray(tts[name].values, float), c=mt, cmap=cmap, norm=norm, s=9,
                             marker=marker)
        axes[0].plot([], [], marker, color="0.4", ms=4, label="G′ (reduced)" if "storage" in name else "G″ (reduced)")
    axes[0].set_xscale("log")
    axes[0].set_yscale("log")
    axes[0].set_xlabel("reduced angular frequency a_T ω [rad/s]")
    axes[0].set_ylabel("b_T G′, b_T G″ [Pa]")
    axes[0].set_title(f"mastercurve at T_ref = {tts.attrs['t_ref_c']:.1f} °C", fontsize=9)
    axes[0].legend(fontsize=8)
    fig.colorbar(sc, ax=axes[0], label="temperature [°C]")
    ax = axes[1]
    ax.errorbar(temps, tts["log_aT"].values, yerr=tts["log_aT_stderr"].values, fmt="o", ms=3.5, color="0.2",
                ecolor="0.6", label="shift factors ± se")
    fine = np.linspace(*span, 200)
    a = tts.attrs
    if a.get("wlf_success"):
        d = fine - a["t_ref_c"]
        ax.plot(fine, -a["wlf_c1"] * d / (a["wlf_c2_k"] + d), "-", color="C3",
                label=f"WLF C1 = {a['wlf_c1']:.3g}, C2 = {a['wlf_c2_k']:.3g} K")
    if a.get("arrhenius_success"):
        ax.plot(temps, tts["log_aT_arrhenius"].values, "--", color="C0",
                label=f"Arrhenius Ea = {a['arrhenius_ea_j_per_mol'] / 1e3:.3g} kJ/mol")
    ax.set_xlabel("temperature T [°C]")
    ax.set_ylabel("log10 a_T")
    ax.set_title("shift function", fontsize=9)
    ax.legend(fontsize=8)
    if title:
        fig.suptitle(title, fontsize=10)
    return fig


def plot_mastercurve(tts: xr.Dataset, path: str | Path, title: str | None = None) -> list[Path]:
    """Write :func:`figure_mastercurve` as PNG + SVG."""
    return save_figure(figure_mastercurve(tts, title=title), path)


def plot_force_depth(series: Mapping[str, tuple[np.ndarray, np.ndarray]], path: str | Path, *,
                     reference: Mapping[str, tuple[np.ndarray, np.ndarray]] | None = None,
                     title: str | None = None) -> list[Path]:
    """FEM indentation force [N] vs depth [m], plotted in mm and mN; reference curves as markers."""
    scale = {k: (1e3 * np.asarray(d, dtype=float), 1e3 * np.asarray(f, dtype=float)) for k, (d, f) in series.items()}
    ref = {k: (1e3 * np.asarray(d, dtype=float), 1e3 * np.asarray(f, dtype=float))
           for k, (d, f) in (reference or {}).items()}
    return save_figure(figure_curves(scale, xlabel="indentation depth [mm]", ylabel="force [mN]", reference=ref,
                                     title=title), path)


def plot_torque(series: Mapping[str, tuple[np.ndarray, np.ndarray]], path: str | Path, *, xlabel: str = "time t [s]",
                reference: Mapping[str, tuple[np.ndarray, np.ndarray]] | None = None,
                title: str | None = None) -> list[Path]:
    """Torque [N m] curves (FEM plate simulation vs measurement), plotted in µN m."""
    scale = {k: (np.asarray(x, dtype=float), 1e6 * np.asarray(m, dtype=float)) for k, (x, m) in series.items()}
    ref = {k: (np.asarray(x, dtype=float), 1e6 * np.asarray(m, dtype=float)) for k, (x, m) in (reference or {}).items()}
    return save_figure(figure_curves(scale, xlabel=xlabel, ylabel="torque M [µN m]", reference=ref, title=title), path)


# ----------------------------------------------------------------------------------------------------------------
# timings


def figure_timings(names: Sequence[str], seconds: Sequence[float], *, budget_s: float | None = None,
                   budget_label: str = "budget", xlabel: str = "wall time [s]", title: str | None = None) -> Figure:
    """Horizontal bars of wall times (log axis), with an optional budget line (e.g. real-time step budget)."""
    seconds = np.asarray(seconds, dtype=float)
    if len(names) != seconds.size:
        raise ValueError(f"{len(names)} names for {seconds.size} timings")
    fig, (ax,) = new_figure(width=6.0, height=1.0 + 0.3 * max(len(names), 1))
    positions = np.arange(len(names))
    colours = ["C3" if budget_s is not None and s > budget_s else "C0" for s in seconds]
    ax.barh(positions, seconds, color=colours)
    ax.set_yticks(positions, labels=list(names), fontsize=8)
    ax.invert_yaxis()
    if all_positive(seconds):
        ax.set_xscale("log")
    if budget_s is not None:
        ax.axvline(budget_s, color="k", ls="--", lw=1, label=f"{budget_label} ({budget_s:.3g} s)")
        ax.legend(fontsize=8)
    ax.set_xlabel(xlabel)
    if title:
        ax.set_title(title, fontsize=10)
    return fig


def plot_timings(names: Sequence[str], seconds: Sequence[float], path: str | Path, *, budget_s: float | None = None,
                 budget_label: str = "budget", xlabel: str = "wall time [s]", title: str | None = None) -> list[Path]:
    """Write :func:`figure_timings` as PNG + SVG."""
    return save_figure(figure_timings(names, seconds, budget_s=budget_s, budget_label=budget_label, xlabel=xlabel,
                                      title=title), path)


def figure_scaling(x: np.ndarray, series: Mapping[str, np.ndarray], *, xlabel: str, ylabel: str = "wall time [s]",
                   title: str | None = None) -> Figure:
    """Timing scaling curves (e.g. time per step vs number of elements, CPU vs GPU) on log-log axes."""
    x = np.asarray(x, dtype=float)
    return figure_curves({k: (x, np.asarray(v, dtype=float)) for k, v in series.items()}, xlabel=xlabel,
                         ylabel=ylabel, log_x=all_positive(x),
                         log_y=all(all_positive(v) for v in series.values()), title=title)


def plot_scaling(x, series: Mapping[str, np.ndarray], path: str | Path, *, xlabel: str,
                 ylabel: str = "wall time [s]", title: str | None = None) -> list[Path]:
    """Write :func:`figure_scaling` as PNG + SVG."""
    return save_figure(figure_scaling(x, series, xlabel=xlabel, ylabel=ylabel, title=title), path)


# ----------------------------------------------------------------------------------------------------------------
# stage-level figure sets (keep workflow scripts thin)

#: variables drawn per test in the averages figures (those present in a curve)
PRIMARY_VARIABLES: dict[str, tuple[str, ...]] = {
    "stress_relaxation": ("relaxation_modulus", "shear_stress"),
    "creep_recovery": ("shear_strain", "creep_compliance"),
    "amplitude_sweep": ("storage_modulus", "loss_modulus"),
    "frequency_sweep": ("storage_modulus", "loss_modulus"),
    "flow_curve": ("shear_stress", "viscosity"),
    "constant_shear_rate": ("shear_stress", "normal_force"),
    "simple_shear": ("shear_stress", "nominal_stress", "normal_force"),
    "uniaxial": ("nominal_stress",),
    "indentation": ("force",),
}


def safe_name(text: str) -> str:
    """File-name-safe form of a label (``"strain_pct=10"`` -> ``"strain_pct-10"``)."""
    return re.sub(r"[^A-Za-z0-9.+-]+", "_", text.replace("=", "-")).strip("_") or "default"


def plot_all_averages(averages: xr.Dataset, runs: Sequence[xr.Dataset], folder: str | Path) -> list[Path]:
    """One raw-vs-average figure per curve and primary variable: ``<folder>/<test>__<condition>__<variable>``.

    Parameters
    ----------
    averages : output of :func:`tissuemech.curves.average_runs`.
    runs : the canonical runs it was built from (matched to curves through the member table).
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    by_name = {str(r.attrs.get("run", "")): r for r in runs}
    written = []
    for test, label in zip(averages["test"].values, averages["condition"].values):
        curve = select_average(averages, str(test), str(label))
        members = [by_name[name] for name in curve.attrs["runs"].split(",") if name in by_name]
        for variable in PRIMARY_VARIABLES.get(str(test), ()):
            if f"{variable}_mean" not in curve:
                continue
            stem = f"{test}__{safe_name(str(label))}__{variable}"
            written += plot_average(curve, variable, folder / stem, members)
    return written


def plot_all_lve(summary: xr.Dataset, runs: Sequence[xr.Dataset], averages: xr.Dataset | None,
                 folder: str | Path) -> list[Path]:
    """One LVE figure per analysed amplitude sweep (runs and averages) of an :func:`tissuemech.lve.lve_summary`."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    by_name = {str(r.attrs.get("run", "")): r for r in runs}
    written = []
    for i in range(summary.sizes.get("sweep", 0)):
        row = {name: summary[name].values[i].item() for name in summary.data_vars if summary[name].dims == ("sweep",)}
        source, name = str(row["source"]), str(row["name"])
        if source == "run" and name in by_name:
            run = by_name[name]
            strain, storage, loss = (run[v].values for v in ("shear_strain", "storage_modulus", "loss_modulus"))
            sds = (None, None)
        elif source == "average" and averages is not None:
            curve = select_average(averages, "amplitude_sweep", name)
            strain = curve["shear_strain"].values
            storage, loss = curve["storage_modulus_mean"].values, curve["loss_modulus_mean"].values
            sds = (curve["storage_modulus_sd"].values, curve["loss_modulus_sd"].values)
        else:
            continue
        title = f"amplitude sweep {source} {name}" + (f" (n = {row['n_samples']})" if source == "average" else "")
        written += plot_lve(strain, storage, loss, row, folder / f"lve__{source}__{safe_name(name)}",
                            storage_sd=sds[0], loss_sd=sds[1], title=title)
    return written


# ----------------------------------------------------------------------------------------------------------------
# fit one test kind, predict the others
# ----------------------------------------------------------------------------------------------------------------
def plot_cross_test(table: pd.DataFrame, path: str | Path, adequacy_factor: float) -> list[Path]:
    """The dataset's ``cross_test.csv`` as one figure: for each held-out test kind (x), the held-out misfit in noise
    units (left, log axis; the adequacy limit ``adequacy_factor`` dashed) and the held-out NRMSE (right) of each model that predicted it
    (one colour per scope/model), unscored kinds left empty."""
    fig, (left, right) = new_figure(ncols=2, width=5.5, height=4.0)
    scored = table[table["status"] == "ok"] if "status" in table else table
    if scored.empty:
        left.text(0.5, 0.5, "no test kind could be predicted from another", ha="center", va="center",
                  transform=left.transAxes)
        left.set_axis_off()
        right.set_axis_off()
        return save_figure(fig, path)
    kinds = sorted(set(table["held_out_test"]))
    series = list(dict.fromkeys(f"{s}: {m}" for s, m in zip(scored["scope"], scored["model"])))
    width = 0.8 / max(len(series), 1)
    colours = matplotlib.colormaps["tab10"]
    for j, name in enumerate(series):
        rows = scored[(scored["scope"] + ": " + scored["model"]) == name]
        x = np.array([kinds.index(k) for k in rows["held_out_test"]]) + (j - (len(series) - 1) / 2) * width
        left.bar(x, rows["misfit_noise_units"], width, color=colours(j % 10), label=name)
        right.bar(x, rows["nrmse"], width, color=colours(j % 10))
    left.axhline(adequacy_factor, color="0.3", ls="--", lw=1, label=f"adequate: <= {adequacy_factor:g} noise SDs")
    left.set_yscale("log")
    left.set_ylabel("held-out misfit (noise SDs)")
    right.set_ylabel("held-out NRMSE")
    for ax in (left, right):
        ax.set_xticks(range(len(kinds)), [k.replace("_", "\n") for k in kinds], fontsize=8)
        ax.set_xlabel("predicted test kind (not fitted)")
    left.legend(fontsize=7, loc="upper left")
    fig.suptitle("Fit one test kind, predict the others")
    return save_figure(fig, path)
