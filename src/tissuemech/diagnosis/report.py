"""Diagnosis of a dataset: named findings, unexplained structure, JSON/netCDF/figures.

Entry points
------------
:func:`diagnose` ``(runs, table, model, fit_info) -> dict``
    runs every catalogue detector (:mod:`.catalogue`) and every generic structure test (:mod:`.generic`)
    on the residual table of the baseline model, controls the family-wise false-alarm rate at
    :data:`tissuemech.diagnosis.stats.ALPHA` (0.01) across *all* of them (alpha/2 to the catalogue and
    alpha/2 to the generic scan, Holm within each; ``p_holm`` is reported on the alpha scale), and names a cause only when it is
    statistically significant after Holm, practically relevant (its effect size exceeds the cause's
    threshold) and -- when a fix was scored -- its fix improves the held-out metric.

:func:`run_diagnosis` ``(runs_dir, fits_dir, out_json, out_nc, fig_dir, baseline=None, extensions=True,
dataset=None) -> dict``
    the Snakemake ``diagnose`` rule's call. Homogeneous-specimen datasets (simple shear + uniaxial
    compression/tension, e.g. Budday) go to :func:`tissuemech.diagnosis.homogeneous.run_homogeneous_diagnosis`
    (cross-mode diagnosis; same JSON contract plus ``cross_mode``). Otherwise: ``runs_dir``: folder of canonical run netCDFs (searched
    recursively, ``*.nc``); ``fits_dir``: folder of fit records ``<model>.nc``
    (:func:`tissuemech.fitting.write_fit_netcdf`); ``baseline``: model key to diagnose (default: the
    QLV-family fit with the lowest AICc, else the lowest AICc overall). Every fit's predictions on every
    run go into the residual netCDF ``out_nc`` (dimension ``row``, column ``model``); the findings of the
    baseline go to ``out_json``; figures (PNG) to ``fig_dir``. ``extensions``: fit the extended models
    (e.g. QLV -> Pipkin-Rogers) for the held-out gain of model-level fixes (costs a few fits).

Output JSON (``diagnosis.json``)
--------------------------------
``findings``: one entry per catalogue id, detected first (strongest first): ``effect``, ``detected``,
``tested``, ``statistic`` (+ ``statistic_name``), ``p_value`` (uncorrected), ``p_holm``, ``effect_size``
(+ unit), ``practical``, ``evidence`` (sentence naming tests/conditions/covariates), ``fix`` {``model``,
``metric``, ``before``, ``after``, ``gain``, ``cv``, ``parameters``} or null.
``unexplained``: structured residual not named by a detected cause: ``covariate``, ``test``,
``quantity``, ``statistic``, ``p_value``, ``p_holm``, ``effect_size`` (log-residual change over the
covariate's range), ``candidates`` (catalogue causes whose signature involves that covariate).
``not_identifiable``: statements such as the I2 dependence from torque-only shear data.
``confounded``: sets of across-curve covariates this design cannot separate, tested jointly, with the design
that would separate them (:func:`tissuemech.diagnosis.generic.confounded_covariates`).
"""
from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd
import xarray as xr

from ..canonical import read_netcdf, write_netcdf, write_text
from . import stats as st
from .catalogue import DiagnosisContext, explains
from .causes import CAUSE_IDS, DETECTORS
from .evidence import residual_table, residual_table_to_xarray
from .generic import confounded_covariates, serial_structure, structure_tests
from .homogeneous import is_homogeneous, run_homogeneous_diagnosis


def _clean(obj):
    """JSON-safe copy: NaN/inf -> None, numpy scalars -> Python."""
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if isinstance(obj, (np.floating, float)):
        return float(obj) if math.isfinite(float(obj)) else None
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, np.ndarray):
        return _clean(obj.tolist())
    return obj


def run_detectors(ctx: DiagnosisContext) -> list[dict]:
    """Every catalogue detector; a detector that fails is reported as untested with the error (never silent)."""
    out = []
    for eff in CAUSE_IDS:
        try:
            out.append(DETECTORS[eff](ctx))
        except Exception as exc:  # noqa: BLE001 -- one broken detector must not hide the others
            out.append({"effect": eff, "tested": False, "statistic": np.nan, "p_value": np.nan, "log10_p": np.nan,
                        "effect_size": np.nan, "practical": False, "fix": None,
                        "evidence": f"detector failed: {type(exc).__name__}: {exc}"})
    return out


def diagnose(runs: Sequence[xr.Dataset], table: pd.DataFrame, model: str = "model", fit_info: dict | None = None,
             alpha: float = st.ALPHA) -> dict:
    """Named findings and unexplained structure of one baseline model (module docstring)."""
    fit_info = dict(fit_info or {})
    ctx = DiagnosisContext(runs=list(runs), table=table, model=model, fit_info=fit_info)
    findings = run_detectors(ctx)
    generic = structure_tests(table)
    tested = [f for f in findings if f.get("tested") and np.isfinite(f.get("p_value", np.nan))]
    pvals = [f["p_value"] for f in tested] + [g["p_value"] for g in generic]
    # family-wise error <= alpha over every test: alpha/2 to the catalogue and alpha/2 to the generic scan
    # (union bound), Holm within each, so the many generic covariates do not drown the named causes
    reject_c, adjusted_c = st.holm([f["p_value"] for f in tested], alpha / 2)
    reject_g, adjusted_g = st.holm([g["p_value"] for g in generic], alpha / 2)
    reject = np.r_[reject_c, reject_g].astype(bool)
    adjusted = np.r_[np.minimum(2 * adjusted_c, 1.0), np.minimum(2 * adjusted_g, 1.0)]
    for f, r, a in zip(tested, reject[:len(tested)], adjusted[:len(tested)]):
        gain = (f.get("fix") or {}).get("gain", np.nan)
        gain_ok = gain is None or not np.isfinite(gain) or gain > 0
        f["p_holm"] = float(a)
        f["significant"] = bool(r)
        f["detected"] = bool(r and f.get("practical") and gain_ok)
    for f in findings:
        f.setdefault("detected", False)
        f.setdefault("p_holm", np.nan)
        f.setdefault("significant", False)
    for g, r, a in zip(generic, reject[len(tested):], adjusted[len(tested):]):
        g["p_holm"] = float(a)
        g["significant"] = bool(r)
    detected = [f for f in findings if f["detected"]]
    detected.sort(key=lambda f: f["log10_p"])
    rest = [f for f in findings if not f["detected"]]
    rest.sort(key=lambda f: f["log10_p"] if np.isfinite(f.get("log10_p", np.nan)) else 1.0)
    unexplained = []
    fitted = set(fit_info.get("fitted_tests") or ())
    confounded = confounded_covariates(table, runs)
    sets = [c["covariates"] for c in confounded]

    def explained(g):
        if any(explains(f["effect"], g["test"], g["covariate"], g["level"], sets) for f in detected):
            return True
        # a test the baseline did not fit is a cross-test prediction: a named cause that distorts the
        # fitted tests distorts the fitted parameters and therefore that prediction too
        return bool(fitted) and g["test"] not in fitted and any(
            explains(f["effect"], t, g["covariate"], g["level"]) for f in detected for t in fitted)

    for g in generic:
        if g["significant"] and g["practical"] and not explained(g):
            candidates = [e for e in CAUSE_IDS if explains(e, g["test"], g["covariate"], g["level"])]
            unexplained.append({"effect": "unexplained_structure", **{k: g[k] for k in (
                "covariate", "test", "quantity", "level", "statistic", "p_value", "p_holm", "effect_size",
                "n_curves")}, "candidates": candidates,
                "evidence": (f"{g['test']} {g['quantity']} residuals of {model} change by "
                             f"{100 * g['effect_size']:+.1f} % (log) over the range of {g['covariate']} "
                             f"({g['level']}, t/F = {g['statistic']:.2f}, Holm p = {g['p_holm']:.2g}); no "
                             f"detected catalogue cause explains it"
                             + (f" (candidates whose signature involves it: {', '.join(candidates)})"
                                if candidates else "") + ".")})
    unexplained.sort(key=lambda u: u["p_value"])
    not_identifiable = [{"effect": f["effect"], "evidence": f["evidence"]} for f in findings
                        if f.get("identifiable") is False]
    return {"model": model, "fit_info": {k: v for k, v in fit_info.items() if k != "fixes"}, "alpha": alpha,
            "n_tests": len(pvals), "findings": detected + rest, "unexplained": unexplained,
            "not_identifiable": not_identifiable, "confounded": confounded, "structure_tests": generic, "serial": serial_structure(table)}


def top_finding(result: dict) -> str | None:
    """Id of the strongest detected cause (None when nothing is detected)."""
    det = [f for f in result["findings"] if f["detected"]]
    return det[0]["effect"] if det else None


def write_diagnosis_json(result: dict, path: str | Path, dataset: str = "") -> Path:
    """Atomically write ``diagnosis.json`` (structure tests are summarised, not dumped)."""
    out = {k: v for k, v in result.items() if k != "structure_tests"}
    out["dataset"] = dataset
    out["n_structure_tests"] = len(result.get("structure_tests", []))
    return write_text(json.dumps(_clean(out), indent=2) + "\n", path)


# ------------------------------------------------------------------------------------------------
# figures
# ------------------------------------------------------------------------------------------------
def write_figures(table: pd.DataFrame, result: dict, fig_dir: str | Path) -> list[Path]:
    """Residual map (strain x log-rate of the ramps), curve levels vs elapsed time, sweep residuals vs
    frequency, and the before/after held-out metric of every detected cause's fix. Returns the paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..plots import save_pyplot_figure

    from .catalogue import curve_levels

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


# ------------------------------------------------------------------------------------------------
# pipeline entry
# ------------------------------------------------------------------------------------------------
def _read_runs(runs_dir: str | Path) -> list[xr.Dataset]:
    files = sorted(Path(runs_dir).rglob("*.nc"))
    runs = [read_netcdf(f) for f in files]
    return [r for r in runs if "test" in r.attrs]


def _choose_baseline(records: list[dict]) -> dict:
    shear = [r for r in records if r["family"] == "qlv" and np.isfinite(r["aicc"])]
    pool = shear or [r for r in records if np.isfinite(r["aicc"])] or records
    return min(pool, key=lambda r: r["aicc"] if np.isfinite(r["aicc"]) else np.inf)


def _nonseparable_fix(runs, baseline_key: str, target: str) -> dict | None:
    """Pipkin-Rogers counterpart of a QLV baseline, scored leaving out the extreme CSR rates."""
    from ..models.registry import available_models
    from .baseline import extension_gain

    if not baseline_key.startswith("qlv_"):
        return None
    ext = "pr_" + baseline_key[len("qlv_"):]
    if ext not in available_models():
        return None
    rates = sorted({float(r.attrs["shear_rate_1_per_s"]) for r in runs
                    if r.attrs.get("test") == "constant_shear_rate" and "shear_rate_1_per_s" in r.attrs})
    if len(rates) < 3:
        return None
    use = [r for r in runs if r.attrs.get("test") in ("constant_shear_rate", "stress_relaxation")]
    folds = [(f"CSR {rate:g} 1/s", (lambda r, rate=rate: r.attrs.get("test") == "constant_shear_rate"
                                    and float(r.attrs.get("shear_rate_1_per_s", -1)) == rate))
             for rate in (rates[0], rates[-1])]
    return extension_gain(use, baseline_key, ext, target, folds)


def run_diagnosis(runs_dir: str | Path, fits_dir: str | Path, out_json: str | Path, out_nc: str | Path,
                  fig_dir: str | Path, baseline: str | None = None, extensions: bool = True,
                  dataset: str | None = None, alpha: float = st.ALPHA) -> dict:
    """Diagnose a dataset from its canonical runs and fit records (module docstring); writes the outputs.

    ``alpha`` is the family-wise false-alarm level (Holm) of every test of the dataset (config ``diagnosis.alpha``).
    """
    from ..models.registry import get_model
    from .baseline import predict_runs, read_fit_record

    runs = _read_runs(runs_dir)
    if not runs:
        raise FileNotFoundError(f"no canonical runs (*.nc) under {runs_dir}")
    if is_homogeneous(runs):
        # homogeneous specimens (simple shear + uniaxial): the multi-mode diagnosis refits its own I1/I2
        # laws per mode combination (closed forms, seconds), so the scope's fit records are not needed
        name = dataset or str(runs[0].attrs.get("dataset", ""))
        return run_homogeneous_diagnosis(runs, out_json, out_nc, fig_dir, dataset=name, alpha=alpha)
    records = [read_fit_record(p) for p in sorted(Path(fits_dir).glob("*.nc"))]
    if not records:
        raise FileNotFoundError(f"no fit records (*.nc) under {fits_dir}")
    chosen = next((r for r in records if r["model_key"] == baseline), None) if baseline else _choose_baseline(records)
    if chosen is None:
        raise KeyError(f"baseline {baseline!r} not among the fits: {[r['model_key'] for r in records]}")
    tables = []
    for rec in records:
        try:
            model = get_model(rec["model_key"])
        except KeyError:
            continue
        preds = predict_runs(model, rec["params"], runs, rec["target"] or "apparent_stress", rec["relaxation"])
        keep = [i for i, p in enumerate(preds) if p]
        if keep:
            tables.append(residual_table([runs[i] for i in keep], [preds[i] for i in keep], rec["model_key"]))
    table = pd.concat(tables, ignore_index=True) if tables else pd.DataFrame()
    base_table = table[table["model"] == chosen["model_key"]].reset_index(drop=True)
    fit_info = {"target": chosen["target"] or "apparent_stress", "relaxation": chosen.get("relaxation", "measured"),
                "fitted_tests": chosen["tests"],
                "correlations": chosen["correlations"], "fixes": {}}
    result = diagnose(runs, base_table, chosen["model_key"], fit_info, alpha=alpha)
    if extensions:
        # model-level fixes cost fits: score them only for causes that pass Holm and practical relevance,
        # then diagnose again so that a fix without held-out gain withdraws the name
        nonsep = next(f for f in result["findings"] if f["effect"] == "nonseparable_relaxation")
        if nonsep["significant"] and nonsep["practical"]:
            fix = _nonseparable_fix(runs, chosen["model_key"], fit_info["target"])
            if fix is not None:
                fit_info["fixes"]["nonseparable_relaxation"] = fix
                result = diagnose(runs, base_table, chosen["model_key"], fit_info, alpha=alpha)
    name = dataset or (runs[0].attrs.get("dataset") if runs else "")
    write_diagnosis_json(result, out_json, dataset=str(name))
    if len(table):
        write_netcdf(residual_table_to_xarray(table), out_nc)
    result["figures"] = [str(p) for p in write_figures(base_table, result, fig_dir)]
    return result
