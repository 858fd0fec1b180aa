"""Figures of a diagnosis (PNG for the report pattern, SVG beside it): :func:`write_figures` for parallel-plate
data, :func:`write_multimode_figures` for homogeneous multi-mode specimens. matplotlib is imported inside them
(deferred: the diagnosis itself never needs it)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from .findings import curve_levels
from .homogeneous import MODES


def write_figures(table: pd.DataFrame, result: dict, fig_dir: str | Path) -> list[Path]:
    """Residual map (strain x log-rate of the ramps), curve levels vs elapsed time, sweep residuals vs
    frequency, and the before/after held-out metric of every detected cause's fix. Returns the paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..plots import save_pyplot_figure

    fig_dir = Path(fig_dir)
    fig_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    t = table[np.isfinite(table.get("log_ratio", pd.Series(dtype=float)))] if "log_ratio" in table else table
    csr = t[(t["test"] == "constant_shear_rate") & (t["quantity"] == "shear_stress")] if len(t) else t
    fig, ax = plt.subplots(figsize=(6, 4))
    if len(csr):
        sc = ax.scatter(100 * csr["strain"], csr["log_rate"], c=100 * csr["log_ratio"], cmap="RdBu_r",
                        vmin=-20, vmax=20, s=8)
        fig.colorbar(sc, ax=ax, label="ln(observed/predicted) [%]")
        ax.set_xscale("log")
    else:
        ax.text(0.5, 0.5, "no constant-shear-rate ramps", ha="center", transform=ax.transAxes)
    ax.set_xlabel("rim strain [%]")
    ax.set_ylabel("log10 shear rate [1/s]")
    ax.set_title(f"residual map of {result['model']} (red: data above model)")
    paths.append(save_pyplot_figure(fig, fig_dir / "residual_map_strain_rate.png"))  # PNG (report pattern) + SVG

    fig, ax = plt.subplots(figsize=(6, 4))
    if len(t):
        lv = curve_levels(t)
        x = lv["elapsed_h"] if lv["elapsed_h"].notna().all() else lv["test_order"]
        for first, marker in ((0, "o"), (1, "^")):
            sel = lv["first_load"] == first
            ax.scatter(x[sel], 100 * lv.loc[sel, "log_scale"], marker=marker,
                       label="first load" if first else "repeated load", s=14)
        ax.legend()
        ax.set_xlabel("elapsed time [h]" if lv["elapsed_h"].notna().all() else "test order")
    ax.set_ylabel("curve level ln(observed/predicted) [%]")
    ax.axhline(0, color="k", lw=0.5)
    paths.append(save_pyplot_figure(fig, fig_dir / "curve_levels_vs_elapsed.png"))  # PNG (report pattern) + SVG

    fs = t[t["test"] == "frequency_sweep"] if len(t) else t
    fig, ax = plt.subplots(figsize=(6, 4))
    for q, mk in (("storage_modulus", "o"), ("loss_modulus", "s")):
        b = fs[fs["quantity"] == q] if len(fs) else fs
        if len(b):
            ax.scatter(np.sqrt(b["frequency_sq"]) / (2 * np.pi), 100 * b["rel_residual"], marker=mk, s=10,
                       label=q.replace("_", " "))
    ax.set_xscale("log")
    ax.axhline(0, color="k", lw=0.5)
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel("(observed - predicted)/predicted [%]")
    ax.legend() if len(fs) else ax.text(0.5, 0.5, "no frequency sweep", ha="center", transform=ax.transAxes)
    paths.append(save_pyplot_figure(fig, fig_dir / "frequency_sweep_residuals.png"))  # PNG (report pattern) + SVG

    fixes = [f for f in result["findings"] if f["detected"] and f.get("fix")
             and np.isfinite(f["fix"].get("before", np.nan)) and np.isfinite(f["fix"].get("after", np.nan))]
    fig, ax = plt.subplots(figsize=(6, 3 + 0.3 * len(fixes)))
    if fixes:
        y = np.arange(len(fixes))
        ax.barh(y - 0.2, [f["fix"]["before"] for f in fixes], height=0.4, label="before (baseline)")
        ax.barh(y + 0.2, [f["fix"]["after"] for f in fixes], height=0.4, label="after (fix)")
        ax.set_yticks(y, [f"{f['effect']}\n{f['fix']['metric']}" for f in fixes], fontsize=7)
        ax.legend()
        ax.set_xlabel("held-out error (metric of each fix)")
    else:
        ax.text(0.5, 0.5, "no cause detected", ha="center", transform=ax.transAxes)
    paths.append(save_pyplot_figure(fig, fig_dir / "fix_gains.png"))  # PNG (report pattern) + SVG
    return paths


def write_multimode_figures(by_mode, table: pd.DataFrame, result: dict, fig_dir) -> list:
    """Before/after predictions per mode, residual map (log ratio vs strain), C01 profiles and the
    cross-mode held-out errors. Returns the PNG paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..plots import save_pyplot_figure

    fig_dir = Path(fig_dir)
    fig_dir.mkdir(parents=True, exist_ok=True)
    base, ext = result["fit_info"]["baseline"], result["fit_info"]["extension"]
    other = {"compression": "shear+tension", "tension": "shear+compression", "shear": "compression+tension"}
    paths = []

    fig, axes = plt.subplots(1, 3, figsize=(13, 4))
    for ax, m in zip(axes, MODES):
        t = table[table["mode"] == m]
        d = t[(t["model"] == base) & (t["calibration"] == "simple_shear")].sort_values("strain")
        ax.plot(d["strain"], d["observed"] / 1e3, "ko", ms=3, label="data")
        ax.plot(d["strain"], d["predicted"] / 1e3, "C3--", label=f"{base}, shear only")
        j = t[(t["model"] == ext) & (t["calibration"] == "all_modes")].sort_values("strain")
        ax.plot(j["strain"], j["predicted"] / 1e3, "C0-", label=f"{ext}, all modes")
        h = t[(t["model"] == ext) & (t["calibration"] == other[m])].sort_values("strain")
        ax.plot(h["strain"], h["predicted"] / 1e3, "C2:", label=f"{ext}, fit {other[m]} (held out)")
        ax.set_xlabel("amount of shear gamma" if m == "shear" else "lambda - 1")
        ax.set_ylabel("P12 [kPa]" if m == "shear" else "P11 [kPa]")
        ax.set_title(m)
        ax.axhline(0, color="k", lw=0.4)
    axes[0].legend(fontsize=7)
    fig.suptitle("before (shear-calibrated I1 law) and after (I2 term, all modes / held-out mode)")
    paths.append(save_pyplot_figure(fig, fig_dir / "predictions_before_after.png"))  # PNG (report pattern) + SVG

    fig, axes = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
    for ax, (model, calib, title) in zip(axes, ((base, "simple_shear", "shear-calibrated baseline"),
                                                (ext, "all_modes", "I2 extension, all modes"))):
        for m, color in zip(MODES, ("C1", "C3", "C0")):
            d = table[(table["model"] == model) & (table["calibration"] == calib) & (table["mode"] == m)]
            d = d[np.isfinite(d["log_ratio"])].sort_values("strain")
            # negative and positive strains drawn apart so a two-sided shear curve is not joined across zero
            label = m
            for side in (d[d["strain"] < 0], d[d["strain"] > 0]):
                if len(side):
                    ax.plot(side["strain"], 100 * side["log_ratio"], "-o", color=color, ms=3, label=label)
                    label = None
        ax.axhline(0, color="k", lw=0.5)
        ax.set_xlabel("gamma (shear) or lambda - 1 (uniaxial)")
        ax.set_title(f"{title}: {model}", fontsize=9)
    axes[0].set_ylabel("ln(observed / predicted) [%]")
    axes[0].legend(fontsize=8)
    fig.suptitle("residual map per mode (points above the noise floor)")
    paths.append(save_pyplot_figure(fig, fig_dir / "residual_map_modes.png"))  # PNG (report pattern) + SVG

    prof = result["profiles"]
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(np.asarray(prof["c01_pa"]) / 1e3, prof["delta_shear"], "C3-o", ms=3, label="simple shear only (flat)")
    ax.plot(np.asarray(prof["c01_pa"]) / 1e3, prof["delta_all_modes"], "C0-o", ms=3, label="all modes")
    ax.axhline(prof["level_95"], color="k", ls=":", lw=0.8, label="95 % level")
    ax.set_ylim(-0.5, max(10.0, 1.1 * prof["level_95"]))
    ax.set_xlabel(f"C01 of {prof['law']} [kPa] (other parameters refitted)")
    ax.set_ylabel("Delta chi2 / s^2")
    ax.legend(fontsize=8)
    ax.set_title("profile of the I2 coefficient")
    paths.append(save_pyplot_figure(fig, fig_dir / "c01_profile.png"))  # PNG (report pattern) + SVG

    rot = result["cross_mode"]["rotations"]
    fig, ax = plt.subplots(figsize=(7, 4))
    y = np.arange(len(rot))
    ref = "ogden1" if "ogden1" in rot[0] else None
    width = 0.27 if ref else 0.4
    ax.barh(y - width, [r[base] for r in rot], height=width, label=f"{base} (I1 only)")
    ax.barh(y, [r[ext] for r in rot], height=width, label=f"{ext} (+ C01)")
    if ref:
        ax.barh(y + width, [r[ref] for r in rot], height=width, label=f"{ref} (reference)")
    shear_only = [(i, r["shear_only_baseline"]) for i, r in enumerate(rot) if "shear_only_baseline" in r]
    if shear_only:
        ax.plot([v for _, v in shear_only], [i for i, _ in shear_only], "kx", ms=9,
                label=f"{base} calibrated on shear alone")
    ax.set_yticks(y, [r["label"] for r in rot], fontsize=8)
    ax.set_xlabel("held-out NRMSE")
    ax.legend(fontsize=8)
    ax.set_title("cross-mode prediction (leave one mode out)")
    paths.append(save_pyplot_figure(fig, fig_dir / "cross_mode_gains.png"))  # PNG (report pattern) + SVG
    return paths
