"""Diagnosis of a dataset: named findings, unexplained structure, JSON/netCDF/figures.

Entry points
------------
:func:`diagnose` ``(runs, table, model, fit_info) -> dict``
    runs every catalogue detector (:mod:`.catalogue`) and every generic structure test (:mod:`.generic`)
    on the residual table of the baseline model, controls the family-wise false-alarm rate at
    :data:`tissuemech.stats.ALPHA` (0.01) across *all* of them (alpha/2 to the catalogue and
    alpha/2 to the generic scan, Holm within each; ``p_holm`` is reported on the alpha scale), and names a cause
    by :data:`DECISION_RULE`: significant after Holm, practically relevant, and its fix scored on held-out data
    beats the noise-calibrated margin of :func:`fix_margin`. Significant, relevant causes without a scored fix
    go to ``significant_fix_not_evaluated``. An inadequate baseline (``adequacy``) is the first finding,
    ``baseline_inadequate``, and blocks every other name when no adequate model is left.

:func:`run_diagnosis` ``(runs_dir, fits_dir, out_json, out_nc, fig_dir, baseline=None, extensions=True,
dataset=None, alpha=ALPHA, ranking=None) -> dict``
    the Snakemake ``diagnose`` rule's call. Homogeneous-specimen datasets (simple shear + uniaxial
    compression/tension, e.g. Budday) go to :func:`tissuemech.diagnosis.homogeneous.run_homogeneous_diagnosis`
    (cross-mode diagnosis; same JSON contract plus ``cross_mode``). Otherwise: ``runs_dir``: folder of canonical run netCDFs (searched
    recursively, ``*.nc``); ``fits_dir``: folder of fit records ``<model>.nc``
    (:func:`tissuemech.fitting.write_fit_netcdf`); ``ranking``: the dataset's ``ranking.csv``, which orders the
    candidate baselines (QLV family first, :func:`tissuemech.diagnosis.baseline.ranked_candidates`); the first
    candidate that passes :func:`tissuemech.diagnosis.baseline.baseline_adequacy` is diagnosed (``baseline``:
    a requested model key instead). Fixed-time QLV candidates (``qlv_<law>_prony<n>``) are not taken with the
    fit stage's relaxation times: in the ranking's order, each is rebuilt on the times the data ask for and
    refitted (:func:`diagnose_runs`); other baselines (no QLV fit in the scope) are diagnosed with their fit
    records' parameters. The diagnosed baseline's residual table goes into the netCDF ``out_nc``
    (dimension ``row``, column ``model``); its findings to ``out_json``; figures (PNG) to ``fig_dir``. ``extensions``: fit the extended models
    (e.g. QLV -> Pipkin-Rogers, on the relaxation times the tests resolve) for the held-out gain of
    model-level fixes (costs a few fits).

Output JSON (``diagnosis.json``)
--------------------------------
``decision_rule`` (the sentence of :data:`DECISION_RULE`); ``noise_model`` (:func:`estimate_noise` plus
``relative_level`` eps); ``baseline`` {``model``, ``adequate``, ``tried``: adequacy of every candidate,
``cross_test_shape``: the misfit shape shared by every frequency sweep the baseline predicted without being
fitted to it (:func:`tissuemech.diagnosis.generic.shared_shape`: ``range_log``, ``degree``, ``wald_p``,
``evidence``), removed before the covariate scan of those curves};
``findings``: ``baseline_inadequate`` first when a candidate was rejected (``models``, ``evidence``), then one
entry per catalogue id, detected first (strongest first): ``effect``, ``detected``,
``tested``, ``statistic`` (+ ``statistic_name``), ``p_value`` (uncorrected), ``p_holm``, ``effect_size``
(+ unit), ``practical``, ``evidence`` (sentence naming tests/conditions/covariates), ``fix`` {``model``,
``metric``, ``before``, ``after``, ``gain``, ``cv``, ``parameters``, ``margin``, ``improvement``,
``beats_margin``} or null.
``significant_fix_not_evaluated``: ``effect``, ``p_holm``, ``effect_size`` (+ unit), ``evidence`` of causes that
pass Holm and practical relevance but whose fix was not scored (not named).
``unexplained``: structured residual not named by a detected cause: ``covariate``, ``test``,
``quantity``, ``statistic``, ``p_value``, ``p_holm``, ``effect_size`` (log-residual change over the
covariate's range), ``candidates`` (catalogue causes whose signature involves that covariate).
``not_identifiable``: statements such as the I2 dependence from torque-only shear data.
``confounded``: sets of across-curve covariates this design cannot separate, tested jointly, with the design
that would separate them (:func:`tissuemech.diagnosis.generic.confounded_covariates`).
"""
from __future__ import annotations


from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd
import xarray as xr
import scipy
from statsmodels.tools.sm_exceptions import MissingDataError

from .. import fitting
from ..canonical import read_netcdf, write_netcdf
from ..models.registry import FIXED_TIME_KEY, available_models, get_model, model_on_times
from .. import stats as st
from .baseline import (baseline_adequacy, curves_of_runs, extension_gain, fit_runs, level_normalised, predict_runs,
                       ranked_candidates, nnls_relaxation_times, read_fit_record, resolved_window_s, window_taus)
from .catalogue import DiagnosisContext, curve_levels, explains
from .findings import write_diagnosis_json
from .causes import CAUSE_IDS, DETECTORS
from .evidence import estimate_noise, nominal_strain, residual_table, residual_table_to_xarray
from .generic import confounded_covariates, serial_structure, structure_tests
from .time_domain import offset_intercept
from .homogeneous import is_homogeneous, run_homogeneous_diagnosis
from .simulation_cards import write_simulation_cards

DECISION_RULE = (
    "A cause is named (detected) only when (1) its test is significant after Holm at the family-wise alpha, "
    "(2) its effect size passes the cause's practical threshold, and (3) its fix, scored on held-out data with "
    "the baseline refitted or re-estimated inside every fold, lowers the held-out error (before - after, in the "
    "fix's relative metric) by more than the noise-calibrated margin z_(1-alpha) * eps / sqrt(2 n), where eps "
    "is the typical relative noise SD of the measured responses (noise_model.relative_level) and n the held-out "
    "values the fix's metric pools (the number of curves for curve-level fixes that do not report it): the "
    "standard error of an RMS of n noise values of SD eps is eps / sqrt(2 n). "
    "Significant, practically relevant causes whose fix was not scored are listed in "
    "significant_fix_not_evaluated, not named. An inadequate baseline (parameters at a bound, no covariance, "
    "no convergence, or the typical point off by more than a factor 2) is the first finding, "
    "baseline_inadequate; the next adequate model is diagnosed, and when none is adequate no cause is named "
    "except a baseline-free one (baseline_free: its fix is scored without the baseline's predictions, e.g. "
    "temperature_dependence by time-temperature superposition on held-out temperatures, "
    "inertia_dominated_points).")


def run_detectors(ctx: DiagnosisContext) -> list[dict]:
    """Every catalogue detector; a detector that fails is reported as untested with the error (never silent)."""
    out = []
    for eff in CAUSE_IDS:
        try:
            out.append(DETECTORS[eff](ctx))
        except (MissingDataError, KeyError) as exc:
            # a quantity the detector needs is absent from these data (a NaN covariate, a missing channel)
            out.append({"effect": eff, "tested": False, "statistic": np.nan, "p_value": np.nan, "log10_p": np.nan,
                        "effect_size": np.nan, "practical": False, "fix": None,
                        "evidence": f"not testable here: a quantity it needs is absent from these data "
                                    f"({type(exc).__name__}: {exc})"})
        except Exception as exc:  # noqa: BLE001 -- one broken detector must not hide the others
            out.append({"effect": eff, "tested": False, "statistic": np.nan, "p_value": np.nan, "log10_p": np.nan,
                        "effect_size": np.nan, "practical": False, "fix": None,
                        "evidence": f"detector failed: {type(exc).__name__}: {exc}"})
    return out


#: imposed inputs, not responses: their scatter does not set the noise of a fix's metric
INPUT_QUANTITIES = ("shear_strain",)


def relative_noise_level(noise: dict) -> float:
    """Typical relative noise SD eps [1] of the measured responses.

    Per (test, quantity) block of an :func:`estimate_noise` model, the relative SD at the block's median
    magnitude, sqrt(relative^2 + (absolute / median|y|)^2); eps is the median over the response blocks
    (imposed inputs of :data:`INPUT_QUANTITIES` excluded). NaN without such a block.
    """
    rel = []
    for key, b in noise.get("blocks", {}).items():
        if key.split("|")[-1] in INPUT_QUANTITIES:
            continue
        med = b.get("median_abs", np.nan)
        a = b.get("absolute", 0.0) / med if np.isfinite(med) and med > 0 else 0.0
        r = float(np.hypot(b.get("relative", np.nan), a))
        if np.isfinite(r):
            rel.append(r)
    return float(np.median(rel)) if rel else np.nan


def fix_margin(fix: dict | None, eps: float, alpha: float = st.ALPHA, n_default: float = np.nan) -> float:
    """Noise-calibrated margin [metric units, relative] that a fix's held-out improvement must exceed.

    ``z_(1-alpha) eps / sqrt(2 n)``: eps the relative noise SD of the data, n the held-out values the fix's
    metric pools (``fix["parameters"]["n_held_out_points"]``), else ``n_default`` (the number of curves: a
    curve-level fix holds out about one level per curve, and the per-point eps overstates a level's noise,
    so this is conservative). NaN without a noise estimate or a count (the fix is then not credited).
    """
    n = (fix or {}).get("parameters", {}).get("n_held_out_points", np.nan)
    n = float(n) if n is not None and np.isfinite(n) and n > 0 else float(n_default)
    if not (np.isfinite(eps) and np.isfinite(n) and n > 0):
        return np.nan
    return float(scipy.stats.norm.ppf(1.0 - alpha) * eps / np.sqrt(2.0 * n))


def diagnose(runs: Sequence[xr.Dataset], table: pd.DataFrame, model: str = "model", fit_info: dict | None = None,
             alpha: float = st.ALPHA, noise: dict | None = None, adequacy: Sequence[dict] = ()) -> dict:
    """Named findings and unexplained structure of one baseline model (module docstring).

    ``noise``: the :func:`tissuemech.diagnosis.evidence.estimate_noise` model of ``runs`` (estimated when
    None); ``adequacy``: :func:`tissuemech.diagnosis.baseline.baseline_adequacy` of every model tried before
    and including this one; an inadequate entry becomes the ``baseline_inadequate`` finding, and when the
    last entry (this model) is inadequate no cause is named.
    """
    fit_info = dict(fit_info or {})
    noise = estimate_noise(runs) if noise is None else noise
    eps = relative_noise_level(noise)
    n_curves = float(table["curve"].nunique()) if "curve" in table and len(table) else np.nan
    rejected = [a for a in adequacy if not a["adequate"]]
    usable = not adequacy or bool(adequacy[-1]["adequate"])
    ctx = DiagnosisContext(runs=list(runs), table=table, model=model, fit_info=fit_info)
    findings = run_detectors(ctx)
    # a baseline without residuals on these runs (e.g. an inadequate model that predicts none of them) has
    # no structure to scan
    fitted = set(fit_info.get("fitted_tests") or ())
    predicted_tests = sorted(set(table["test"]) - fitted) if fitted and len(table) else []
    shapes: list[dict] = []
    generic = structure_tests(table, predicted_tests, shapes) if len(table) else []
    tested = [f for f in findings if f.get("tested") and np.isfinite(f.get("p_value", np.nan))]
    pvals = [f["p_value"] for f in tested] + [g["p_value"] for g in generic]
    # family-wise error <= alpha over every test: alpha/2 to the catalogue and alpha/2 to the generic scan
    # (union bound), Holm within each, so the many generic covariates do not drown the named causes
    reject_c, adjusted_c = st.holm([f["p_value"] for f in tested], alpha / 2)
    reject_g, adjusted_g = st.holm([g["p_value"] for g in generic], alpha / 2)
    reject = np.r_[reject_c, reject_g].astype(bool)
    adjusted = np.r_[np.minimum(2 * adjusted_c, 1.0), np.minimum(2 * adjusted_g, 1.0)]
    not_evaluated = []
    for f, r, a in zip(tested, reject[:len(tested)], adjusted[:len(tested)]):
        fix = f.get("fix") or {}
        before, after = fix.get("before", np.nan), fix.get("after", np.nan)
        scored = fix and before is not None and after is not None and np.isfinite(before) and np.isfinite(after)
        margin = fix_margin(fix, eps, alpha, n_curves) if scored else np.nan
        if scored:
            fix["margin"] = margin
            fix["improvement"] = float(before - after)
            fix["beats_margin"] = bool(np.isfinite(margin) and before - after > margin)
        f["p_holm"] = float(a)
        f["significant"] = bool(r)
        # a baseline-free cause (test statistic or fix computed without the baseline's predictions, e.g. the
        # time-temperature shift scored on held-out temperatures) may be named under an inadequate baseline
        admissible = usable or bool(f.get("baseline_free"))
        f["detected"] = bool(admissible and r and f.get("practical") and scored and fix["beats_margin"])
        if admissible and r and f.get("practical") and not scored:
            not_evaluated.append({"effect": f["effect"], "p_holm": float(a), "effect_size": f.get("effect_size"),
                                  "effect_size_unit": f.get("effect_size_unit", ""), "evidence": f["evidence"]})
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
    if not usable:
        unexplained = []  # nothing is blamed on an effect while the baseline itself does not describe the data
    head = []
    if rejected:
        head = [{"effect": "baseline_inadequate", "detected": True, "tested": True, "significant": True,
                 "practical": True, "statistic": rejected[0]["misfit_noise_units"],
                 "statistic_name": "RMS misfit in noise SDs", "p_value": np.nan, "p_holm": np.nan, "log10_p": np.nan,
                 "effect_size": rejected[0]["misfit_factor"], "effect_size_unit": "x (typical point off by)",
                 "fix": None, "models": [a["model"] for a in rejected],
                 "evidence": " ".join(f"{a['model']}: " + "; ".join(a["reasons"]) + "." for a in rejected)
                 + (f" Diagnosed with the next adequate model, {model}." if usable else
                    " No fitted model is adequate: no cause is named.")}]
    return {"model": model, "fit_info": {k: v for k, v in fit_info.items() if k not in ("fixes", "simulation_fits")},
            "alpha": alpha,
            "decision_rule": DECISION_RULE,
            "noise_model": {**noise, "relative_level": eps},
            "baseline": {"model": model, "adequate": usable, "tried": list(adequacy),
                         "cross_test_shape": [dict(sh, evidence=_shape_evidence(sh, model)) for sh in shapes]},
            "n_tests": len(pvals), "findings": head + detected + rest, "unexplained": unexplained,
            "significant_fix_not_evaluated": not_evaluated,
            "not_identifiable": not_identifiable, "confounded": confounded, "structure_tests": generic,
            "serial": serial_structure(table) if len(table) else []}


def _shape_evidence(shape: dict, model: str) -> str:
    size = 100 * (np.exp(shape["range_log"]) - 1)
    return (f"the {shape['test']} {shape['quantity']} predicted by {model} (not fitted to these curves) misfits by a "
            f"shape along the frequency shared by all {shape['n_curves']} curves ({size:.1f} % from its lowest to "
            f"its highest point, degree-{shape['degree']} polynomial in log frequency chosen by BIC, Wald p = "
            f"{shape['wald_p']:.2g}): the baseline's relaxation spectrum does not carry over to these tests. "
            f"It is removed before the covariate scan of these curves, which then tests only structure that "
            f"differs between curves; it is not a covariate effect, and instrument inertia, the catalogue's "
            f"frequency-shaped cause, is tested separately.")


def top_finding(result: dict) -> str | None:
    """Id of the strongest detected cause (None when nothing is detected)."""
    det = [f for f in result["findings"] if f["detected"]]
    return det[0]["effect"] if det else None


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


def _nonseparable_fix(runs, baseline_key: str, target: str, taus_s: Sequence[float] | None = None,
                      fits_out: list | None = None) -> dict | None:
    """Pipkin-Rogers counterpart of a QLV baseline, scored on held-out extremes of the design: the lowest and
    the highest CSR rate when there are >= 3 rates, else the relaxations at the lowest and at the highest
    nominal strain when there are >= 2 (non-separability is a strain dependence of the relaxation, so a model
    trained on the other strains must predict the extreme one). Both models are refitted in every fold on the
    baseline's relaxation times ``taus_s`` [s] (the runs-only path's NNLS times), or, when None, on a
    one-per-decade grid spanning the window the tests resolve. None when the design has neither."""
    if not baseline_key.startswith("qlv_"):
        return None
    ext = "pr_" + baseline_key[len("qlv_"):]
    if ext not in available_models() and not (FIXED_TIME_KEY.fullmatch(ext) and "_fluid" not in ext):
        # a fixed-time Pipkin-Rogers model on the baseline's times (models.registry.model_on_times); a fluid QLV
        # has no Pipkin-Rogers counterpart
        return None
    use = [r for r in runs if r.attrs.get("test") in ("constant_shear_rate", "stress_relaxation")]
    rates = sorted({float(r.attrs["shear_rate_1_per_s"]) for r in use
                    if r.attrs.get("test") == "constant_shear_rate" and "shear_rate_1_per_s" in r.attrs})
    strains = sorted({round(nominal_strain(r), 6) for r in use if r.attrs.get("test") == "stress_relaxation"}
                     - {np.nan})
    strains = [g for g in strains if np.isfinite(g)]
    if len(rates) >= 3:
        folds = [(f"CSR {rate:g} 1/s", (lambda r, rate=rate: r.attrs.get("test") == "constant_shear_rate"
                                        and float(r.attrs.get("shear_rate_1_per_s", -1)) == rate))
                 for rate in (rates[0], rates[-1])]
    elif len(strains) >= 2:
        folds = [(f"relaxation at {100 * g:g} %", (lambda r, g=g: r.attrs.get("test") == "stress_relaxation"
                                                   and round(nominal_strain(r), 6) == g))
                 for g in (strains[0], strains[-1])]
    else:
        return None
    # both models on the relaxation times these tests resolve (never the registry's fixed 0.1-100 s)
    window = resolved_window_s(use)
    taus = np.asarray(taus_s, float) if taus_s is not None and len(taus_s) else window_taus(window)
    fix = extension_gain(use, baseline_key, ext, target, folds, taus_s=taus if taus.size else None,
                         fits_out=fits_out)
    fix["parameters"]["window_t_min_s"] = window["t_min_s"]
    fix["parameters"]["window_t_max_s"] = window["t_max_s"]
    return fix


def _offset_removed(runs: Sequence[xr.Dataset], offset_nm: float) -> list[xr.Dataset]:
    """Ramps and relaxations with an additive torque offset ``offset_nm`` [N m] removed from the torque, the
    apparent shear stress (2 M0/(pi R^3)) and the relaxation modulus derived from it; other runs unchanged."""
    out = []
    for r in runs:
        radius = float(r.attrs.get("radius_m", np.nan) or np.nan)
        if r.attrs.get("test") not in RUNS_BASELINE_TESTS or not np.isfinite(radius):
            out.append(r)
            continue
        d = r.copy()
        stress_pa = 2.0 * offset_nm / (np.pi * radius ** 3)
        strain = nominal_strain(r)
        for var, shift in (("torque", offset_nm), ("shear_stress", stress_pa),
                           ("relaxation_modulus", stress_pa / strain if strain else np.nan)):
            if var in d and np.isfinite(shift):
                d[var] = d[var].copy(data=d[var].values - shift)
        out.append(d)
    return out


def _condition(run: xr.Dataset) -> str:
    """A ramp's rate or a relaxation's nominal strain: the condition a held-out fold leaves out."""
    if run.attrs.get("test") == "constant_shear_rate":
        return f"CSR {float(run.attrs.get('shear_rate_1_per_s', np.nan)):g} 1/s"
    return f"relaxation at {100 * nominal_strain(run):g} %"


def _held_out_nrmse(model, params, curves, target: str, reference_curves, free_level: bool = False) -> float:
    """RMS over curves of RMSE / mean |observed| (:func:`tissuemech.fitting.evaluate`), the observed mean taken
    from ``reference_curves`` (the raw measurement) so that a model fitted to offset-removed data is scored on
    the same scale as one fitted to the raw data. ``free_level``: each curve's prediction gets its own
    least-squares factor first (a held-out sample's stiffness level is specimen variability, not the fix's
    business; its shape is)."""
    terms = fitting.FitProblem(model=model, curves=list(curves), target=target).curve_terms(dict(params))
    ref = fitting.FitProblem(model=model, curves=list(reference_curves), target=target).observations
    per = []
    for t, (obs, _) in zip(terms, ref):
        y = np.concatenate([y for (y, _, _) in t.values()])
        f = np.concatenate([f for (_, f, _) in t.values()])
        if free_level and np.dot(f, f) > 0:
            f = f * (np.dot(f, y) / np.dot(f, f))
        per.append(np.sqrt(np.mean((f - y) ** 2)) / np.mean(np.abs(np.concatenate(list(obs.values())))))
    return float(np.sqrt(np.mean(np.square(per)))) if per else np.nan


def _offset_fix(runs: Sequence[xr.Dataset], baseline_key: str, fit_info: dict, noise: dict | None,
                n_points: int = 16) -> dict | None:
    """The baseline refitted with a torque offset removed, scored on held-out conditions.

    Folds: with three or more ramp/relaxation conditions (rate or nominal strain), the condition with the
    smallest median |torque| (where an offset is the largest share of the signal) and the one with the largest;
    with two, the training runs must keep both (an offset is told from a level only across conditions), so up
    to three samples are held out in turn and each held-out curve keeps its own level (``free_level`` of
    :func:`_held_out_nrmse`). In each fold the baseline is fitted
    to the training runs as measured; the offset M0 is read from its training residuals
    (:func:`tissuemech.diagnosis.time_domain.offset_intercept`, converted at the median plate radius); the
    baseline is refitted to the training runs with M0 removed; both predict the held-out runs (the refit on the
    held-out runs with the training M0 removed). ``before``/``after``: mean held-out NRMSE over folds, both
    normalised by the raw held-out observations. None without two conditions, a plate radius, or a torque /
    apparent-stress target.
    """
    target = fit_info.get("target", "apparent_stress")
    relaxation = fit_info.get("relaxation", "measured")
    taus = fit_info.get("taus_s") or None
    use = [r for r in runs if r.attrs.get("test") in RUNS_BASELINE_TESTS]
    radii = np.array([float(r.attrs.get("radius_m", np.nan) or np.nan) for r in use])
    if target not in ("torque", "apparent_stress") or not use or not np.isfinite(radii).all():
        return None
    groups: dict[str, list[xr.Dataset]] = {}
    for r in use:
        groups.setdefault(_condition(r), []).append(r)
    if len(groups) < 2:
        return None

    def level(rs):
        vals = [np.abs(r["torque"].values) if "torque" in r else np.abs(r["shear_stress"].values) * radius ** 3
                for r, radius in ((r, float(r.attrs["radius_m"])) for r in rs)]
        return float(np.nanmedian(np.concatenate(vals)))

    def piece(r):
        return f"specimen {r.attrs.get('specimen')} sample {r.attrs.get('sample')}"

    if len(groups) >= 3:
        order = sorted(groups, key=lambda k: level(groups[k]))
        folds = [(label, _condition, groups[label]) for label in (order[0], order[-1])]
    else:
        pieces = list(dict.fromkeys(piece(r) for r in use))[:3]
        folds = [(p, piece, [r for r in use if piece(r) == p]) for p in pieces if len(pieces) >= 2]
    free_level = len(groups) < 3
    model = model_on_times(baseline_key, taus) if taus else get_model(baseline_key)
    before, after, labels, n_held, offsets = [], [], [], [], []
    for label, key_of, held in folds:
        train = [r for r in use if key_of(r) != label]
        test_curves = curves_of_runs(held, relaxation, n_points)
        if not train or not test_curves or len({_condition(r) for r in train}) < 2:
            continue
        raw = fit_runs(baseline_key, train, target, relaxation, n_points, taus_s=taus)
        preds = predict_runs(model, raw.params, train, target, relaxation)
        kept = [(r, p) for r, p in zip(train, preds) if p]
        est = offset_intercept(residual_table([r for r, _ in kept], [p for _, p in kept], baseline_key, noise=noise)) \
            if kept else None
        if est is None:
            continue
        offset_nm = float(est["estimate"]) * np.pi * float(np.median(radii)) ** 3 / 2.0
        refit = fit_runs(baseline_key, _offset_removed(train, offset_nm), target, relaxation, n_points,
                         start=raw.params, taus_s=taus)
        corrected = curves_of_runs(_offset_removed(held, offset_nm), relaxation, n_points)
        before.append(_held_out_nrmse(model, raw.params, test_curves, target, test_curves, free_level))
        after.append(_held_out_nrmse(model, refit.params, corrected, target, test_curves, free_level))
        labels.append(label)
        offsets.append(offset_nm)
        n_held.append(int(sum(min(np.size(v) for v in c.observed.values()) for c in test_curves if c.observed)))
    if not before:
        return None
    b, a = float(np.mean(before)), float(np.mean(after))
    return {"model": f"{baseline_key} refitted with the torque offset M0 removed (M0 read from the training "
                     "residuals)", "metric": "held_out_nrmse", "before": b, "after": a,
            "gain": (b - a) / b if b > 0 else np.nan,
            "cv": ("leave-one-sample-out, levels free (" if free_level else "leave-one-condition-out (")
            + ", ".join(labels) + ")",
            "parameters": {"offset_uNm_per_fold": [1e6 * m for m in offsets],
                           # the folds' metrics are averaged, so the margin pools all held-out points
                           "n_held_out_points": float(sum(n_held)) if min(n_held) > 0 else np.nan},
            "folds": [{"label": lab, "before": b_, "after": a_} for lab, b_, a_ in zip(labels, before, after)]}


#: model-level fixes (refits) scored by :func:`with_model_fixes`: cause -> scorer(runs, baseline, fit_info, noise)
MODEL_FIXES = {
    "nonseparable_relaxation": lambda runs, key, info, noise: _nonseparable_fix(
        runs, key, info.get("target", "apparent_stress"), info.get("taus_s"),
        fits_out=info.get("simulation_fits", {}).setdefault("nonseparable_relaxation", [])
        if isinstance(info.get("simulation_fits"), dict) else None),
    "torque_offset": _offset_fix,
}


def with_model_fixes(result: dict, runs: Sequence[xr.Dataset], table: pd.DataFrame, fit_info: dict,
                     alpha: float = st.ALPHA, noise: dict | None = None, adequacy: Sequence[dict] = ()) -> dict:
    """Score the model-level fixes (refits) of the causes that pass Holm and practical relevance, then
    diagnose again, so that such a cause is named only when its fix beats the margin on held-out data.

    Model-level fixes cost fits, so they are scored only when needed (:data:`MODEL_FIXES`:
    ``nonseparable_relaxation``, QLV -> Pipkin-Rogers, :func:`_nonseparable_fix`; ``torque_offset``, the
    baseline refitted without the offset, :func:`_offset_fix`). ``result`` and ``fit_info`` are those of
    :func:`diagnose` (``fit_info["fixes"]`` receives the scored fixes); returns the new result.
    """
    if not result["baseline"]["adequate"]:
        return result
    scored = False
    for effect, scorer in MODEL_FIXES.items():
        f = next((f for f in result["findings"] if f["effect"] == effect), None)
        if f is None or not (f["significant"] and f["practical"]):
            continue
        fix = scorer(runs, result["model"], fit_info, noise)
        if fix is not None:
            fit_info.setdefault("fixes", {})[effect] = fix
            scored = True
    if not scored:
        return result
    return diagnose(runs, table, result["model"], fit_info, alpha=alpha, noise=noise, adequacy=adequacy)


#: tests the runs-only baseline is fitted to (the ramps and relaxations; sweeps and the rest are predicted)
RUNS_BASELINE_TESTS = ("constant_shear_rate", "stress_relaxation")
#: candidate baselines of the runs-only path, simplest first: the instantaneous law is chosen from the data
#: (AICc of the joint fit), as the pipeline takes it from the ranking; one-term Ogden nests the neo-Hookean
#: (alpha = 2), which is linear in simple shear, and describes stiffening and softening laws
RUNS_BASELINE_CANDIDATES = ("qlv_linear_prony4", "qlv_ogden1_prony4")


def diagnose_runs(runs: Sequence[xr.Dataset], baseline: str | Sequence[str] = RUNS_BASELINE_CANDIDATES,
                  target: str = "torque", relaxation: str = "measured",
                  fitted_tests: Sequence[str] = RUNS_BASELINE_TESTS, n_points: int = 16, alpha: float = st.ALPHA,
                  extensions: bool = True, return_table: bool = False,
                  order_source: str | None = None,
                  simulation_fits: dict | None = None) -> dict | tuple[dict, pd.DataFrame]:
    """Diagnose canonical runs on a baseline whose relaxation times come from the data: the one path from runs
    to a diagnosis (the pipeline's :func:`run_diagnosis` takes its candidate laws from the ranking and comes here).

    ``baseline``: a fixed-time QLV key, or a sequence of candidate keys (default
    :data:`RUNS_BASELINE_CANDIDATES`). Each is rebuilt on the relaxation times the runs resolve
    (:func:`tissuemech.diagnosis.baseline.resolved_window_s`; the times NNLS selects on a dense grid over that
    window, :func:`~tissuemech.diagnosis.baseline.nnls_relaxation_times`; never a fixed grid) and
    fitted jointly to the ``fitted_tests`` runs (``target``: plate target of :mod:`tissuemech.fitting`).
    Without ``order_source`` the candidates are ranked by AICc of that fit (the instantaneous law comes from
    the data, so that a law the data do not follow is not reported as residual structure); with it they are
    taken in the given order (e.g. the dataset's ranking, ``order_source`` saying so) and fitted only as far as
    needed. They are checked in that order with :func:`~tissuemech.diagnosis.baseline.baseline_adequacy`, and
    the first adequate one is diagnosed under the noise model estimated from the runs; model-level fixes are
    scored when ``extensions`` (``simulation_fits``: a dict that receives, per cause, the fits of its model-level
    fix, :func:`tissuemech.diagnosis.baseline.extension_gain` ``fits_out``). Returns the :func:`diagnose` result with
    ``fit_info.taus_s``,
    ``fit_info.window`` and ``fit_info.baseline_aicc`` ({key: AICc} of the candidates fitted) (and the
    diagnosed model's residual table with ``return_table``).
    """
    keys = [baseline] if isinstance(baseline, str) else list(baseline)
    noise = estimate_noise(runs)
    window = resolved_window_s(runs)
    fitted = [r for r in runs if r.attrs.get("test") in fitted_tests]
    if not fitted:
        raise ValueError(f"no run of the fitted tests {list(fitted_tests)} to fit the baseline {baseline!r} to")
    fits, spectra = {}, {}
    first = _linear_law_spectrum(fitted, target, relaxation, window)

    def candidate(k):
        if k not in fits:
            fits[k], spectra[k] = _fit_on_data_times(k, fitted, target, relaxation, window, n_points, first)
        return fits[k], spectra[k]

    if order_source is None:
        for k in keys:
            candidate(k)
        aicc = {k: float(f.aicc) for k, f in fits.items()}
        order = sorted(keys, key=lambda k: (aicc[k] if np.isfinite(aicc[k]) else np.inf, keys.index(k)))
    else:
        order = keys
    def assessed(key, fit, taus):
        model = model_on_times(key, taus)
        preds = predict_runs(model, fit.params, runs, target, relaxation)
        keep = [i for i, p in enumerate(preds) if p]
        kept = [runs[i] for i in keep]
        table = residual_table(kept, [preds[i] for i in keep], key, noise=noise) if keep else pd.DataFrame()
        record = {"model_key": key, "flags": fit.flags, "stderr": fit.stderr, "varying": fit.varying,
                  "converged": fit.success}
        return kept, table, baseline_adequacy(record, table)

    adequacy = []
    for key in order:
        fit, spectrum = candidate(key)
        taus = spectrum["taus_s"]
        kept, table, verdict = assessed(key, fit, taus)
        degenerate = fitting.weights_at_upper_bound(fit.flags)
        if (not verdict["adequate"] and degenerate and len(degenerate) < taus.size
                and set(verdict["at_bound"]) == {f"beta_{i + 1}" for i in degenerate}
                and verdict["reasons"] == [f"parameters at a bound: {', '.join(verdict['at_bound'])}"]):
            # only Prony ratios at their upper bound: the equilibrium modulus runs to zero against those modes,
            # the direction in which a time outside what the data resolve trades its weight against the
            # equilibrium modulus; the candidate is refitted without those times and judged again (reported)
            drop = np.asarray(taus)[degenerate]
            taus = np.delete(np.asarray(taus), degenerate)
            fit = fit_runs(key, level_normalised(fitted, spectrum["levels"]), target, relaxation,
                           n_points=n_points, taus_s=taus)
            verdict["reasons"].append("refitted without the relaxation time(s) "
                                      + ", ".join(f"{t:.3g} s" for t in drop) + " whose ratio was at its bound")
            kept, table, again = assessed(key, fit, taus)
            again["refitted_without_taus_s"] = [float(t) for t in drop]
            adequacy.append(verdict)
            fits[key], spectra[key] = fit, {**spectrum, "taus_s": taus}
            verdict = again
        adequacy.append(verdict)
        if verdict["adequate"]:
            break
    fit_info = {"target": target, "relaxation": relaxation, "fitted_tests": list(fitted_tests),
                "correlations": {}, "taus_s": [float(t) for t in taus], "window": window, "fixes": {},
                "relaxation_times": {"method": spectrum["method"], "grid_s": [float(t) for t in spectrum["grid_s"]],
                                     "levels": spectrum["levels"],
                                     "weights": [float(w) for w in spectrum["weights"]]},
                "params": {k: float(v) for k, v in fit.params.items()},
                "baseline_order": order_source or ("aicc" if len(keys) > 1 else "requested"),
                "baseline_aicc": {k: float(f.aicc) for k, f in fits.items()}}
    if simulation_fits is not None:
        # the model-level fixes' fold and full-data fits, for the cards the simulator replays (not written to JSON)
        fit_info["simulation_fits"] = simulation_fits
    result = diagnose(kept, table, key, fit_info, alpha=alpha, noise=noise, adequacy=adequacy)
    if extensions:
        result = with_model_fixes(result, kept, table, fit_info, alpha=alpha, noise=noise, adequacy=adequacy)
    return (result, table) if return_table else result


def _linear_law_spectrum(runs: Sequence[xr.Dataset], target: str, relaxation: str, window: dict) -> dict:
    """NNLS times and per-piece levels with the linear law (:func:`~tissuemech.diagnosis.baseline.
    nnls_relaxation_times`), shared by every candidate; the window's one-per-decade grid where NNLS selects
    nothing."""
    spectrum = nnls_relaxation_times(runs, target, relaxation, window)
    if not spectrum["taus_s"].size:
        spectrum = {**spectrum, "taus_s": window_taus(window),
                    "method": "one time per decade spanning the resolved window (NNLS selected none)"}
    return spectrum


def _fit_on_data_times(key: str, runs: Sequence[xr.Dataset], target: str, relaxation: str, window: dict,
                       n_points: int, spectrum: dict):
    """One candidate of the runs-only path on the relaxation times the data ask for.

    ``spectrum`` (:func:`_linear_law_spectrum`) gives first times and the level of every loaded piece; the
    candidate is fitted on those times to the runs divided by their piece's level (the shape common to every
    piece; residuals are later taken against the unscaled runs, so level differences between pieces stay in
    the evidence). A law that is not linear in shear changes the elastic drive, so NNLS is repeated with the
    fitted law and the candidate refitted when the times change; the levels stay those of ``spectrum``, so
    that every candidate is fitted to the same data and their AICc compare. Returns ``(FitResult, spectrum
    dict with the times used as taus_s)``."""
    taus = spectrum["taus_s"]
    fit = fit_runs(key, level_normalised(runs, spectrum["levels"]), target, relaxation, n_points=n_points,
                   taus_s=taus if taus.size else None)
    law = getattr(model_on_times(key, taus), "instantaneous", None) if taus.size else None
    # a one-parameter law is its modulus times a fixed shape, absorbed by the weights: nothing to repeat
    if law is not None and len(law.param_names) > 1 and fit.success:
        again = nnls_relaxation_times(runs, target, relaxation, window, model_key=key, law_params=fit.params)
        if again["taus_s"].size and not np.array_equal(again["taus_s"], taus):
            refit = fit_runs(key, level_normalised(runs, spectrum["levels"]), target, relaxation,
                             n_points=n_points, taus_s=again["taus_s"])
            return refit, {**again, "levels": spectrum["levels"],
                           "method": again["method"] + ", repeated with the fitted instantaneous law"}
    return fit, spectrum


def _read_ranking(path: str | Path | None) -> pd.DataFrame | None:
    if path is None or not Path(path).is_file() or Path(path).stat().st_size == 0:
        return None
    return pd.read_csv(path)


def run_diagnosis(runs_dir: str | Path, fits_dir: str | Path, out_json: str | Path, out_nc: str | Path,
                  fig_dir: str | Path, baseline: str | None = None, extensions: bool = True,
                  dataset: str | None = None, alpha: float = st.ALPHA, ranking: str | Path | None = None,
                  extension_cards_dir: str | Path | None = None, poisson_ratio: float | None = None) -> dict:
    """Diagnose a dataset from its canonical runs and fit records (module docstring); writes the outputs.

    ``alpha`` is the family-wise false-alarm level (Holm) of every test of the dataset (config ``diagnosis.alpha``).
    ``ranking``: the dataset's ``ranking.csv``; it orders the candidate baselines
    (:func:`tissuemech.diagnosis.baseline.ranked_candidates`). Each candidate is checked with
    :func:`tissuemech.diagnosis.baseline.baseline_adequacy`; the first adequate one is diagnosed (an explicit
    ``baseline`` is checked too and reported inadequate if it is).

    ``extension_cards_dir`` (with ``poisson_ratio``, the configuration's): the cards of every named cause's material
    extension, fitted to all runs and to each fold's training runs, beside the baseline fitted to the same training
    runs (:func:`tissuemech.diagnosis.simulation_cards.write_simulation_cards`): what the simulator replays to score
    the extension on tests it was not fitted to. The folder is written (possibly empty) whenever it is given.
    """
    runs = _read_runs(runs_dir)
    if not runs:
        raise FileNotFoundError(f"no canonical runs (*.nc) under {runs_dir}")
    if is_homogeneous(runs):
        # homogeneous specimens (simple shear + uniaxial): the multi-mode diagnosis refits its own I1/I2
        # laws per mode combination (closed forms, seconds), so the scope's fit records are not needed
        name = dataset or str(runs[0].attrs.get("dataset", ""))
        if extension_cards_dir is not None:  # no material extension of a homogeneous law is replayed
            write_simulation_cards({}, {}, extension_cards_dir, poisson_ratio, name)
        return run_homogeneous_diagnosis(runs, out_json, out_nc, fig_dir, dataset=name, alpha=alpha)
    records = [read_fit_record(p) for p in sorted(Path(fits_dir).glob("*.nc"))]
    if not records:
        raise FileNotFoundError(f"no fit records (*.nc) under {fits_dir}")
    if baseline:
        order = [r for r in records if r["model_key"] == baseline]
        if not order:
            raise KeyError(f"baseline {baseline!r} not among the fits: {[r['model_key'] for r in records]}")
        order_source = "requested"
    else:
        order, order_source = ranked_candidates(records, _read_ranking(ranking))
    name = str(dataset or runs[0].attrs.get("dataset", ""))
    fixed_time = [r for r in order if is_fixed_time_qlv(str(r["model_key"]))]
    if fixed_time:
        # the ranking chooses the instantaneous law; the relaxation times come from the data (diagnose_runs),
        # never from the registry's grid the fit stage used
        lead = fixed_time[0]
        simulation_fits: dict = {}
        result, base_table = diagnose_runs(
            runs, [str(r["model_key"]) for r in fixed_time], target=lead["target"] or "apparent_stress",
            relaxation=lead.get("relaxation", "measured"), fitted_tests=lead["tests"], alpha=alpha,
            extensions=extensions, return_table=True,
            order_source=order_source + "; relaxation times of each candidate from the data (NNLS)",
            simulation_fits=simulation_fits)
        if extension_cards_dir is not None:
            write_simulation_cards(result, simulation_fits, extension_cards_dir, poisson_ratio, name)
        return _write_outputs(result, base_table, out_json, out_nc, fig_dir, name)
    noise = estimate_noise(runs)
    tables = {}
    for rec in records:
        try:
            model = get_model(rec["model_key"])
        except KeyError:
            continue
        preds = predict_runs(model, rec["params"], runs, rec["target"] or "apparent_stress", rec["relaxation"])
        keep = [i for i, p in enumerate(preds) if p]
        if keep:
            tables[rec["model_key"]] = residual_table([runs[i] for i in keep], [preds[i] for i in keep],
                                                      rec["model_key"], noise=noise)
    adequacy = []
    chosen = order[0]
    for rec in order:
        adequacy.append(baseline_adequacy(rec, tables.get(rec["model_key"], pd.DataFrame())))
        chosen = rec
        if adequacy[-1]["adequate"]:
            break
    base_table = tables.get(chosen["model_key"], pd.DataFrame(columns=["model", "curve", "test", "quantity",
                                                                        "observed", "predicted", "residual",
                                                                        "log_ratio", "sigma"]))
    base_table = base_table.reset_index(drop=True)
    fit_info = {"target": chosen["target"] or "apparent_stress", "relaxation": chosen.get("relaxation", "measured"),
                "fitted_tests": chosen["tests"], "baseline_order": order_source,
                "correlations": chosen["correlations"], "fixes": {}}
    result = diagnose(runs, base_table, chosen["model_key"], fit_info, alpha=alpha, noise=noise, adequacy=adequacy)
    if extensions:
        result = with_model_fixes(result, runs, base_table, fit_info, alpha=alpha, noise=noise, adequacy=adequacy)
    if extension_cards_dir is not None:
        write_simulation_cards(result, {}, extension_cards_dir, poisson_ratio, name)
    return _write_outputs(result, base_table, out_json, out_nc, fig_dir, name)


def is_fixed_time_qlv(model_key: str) -> bool:
    """A fixed-time QLV key (``qlv_<law>_prony<n>``, :data:`~tissuemech.models.registry.FIXED_TIME_KEY`): the
    baselines :func:`run_diagnosis` rebuilds on the data's times."""
    m = FIXED_TIME_KEY.fullmatch(model_key)
    return bool(m) and m.group(1) == "qlv"


def _write_outputs(result: dict, table: pd.DataFrame, out_json, out_nc, fig_dir, dataset: str) -> dict:
    """diagnosis.json, the diagnosed baseline's residual netCDF and the figures (atomic writes)."""
    write_diagnosis_json(result, out_json, dataset=dataset)
    if len(table):
        write_netcdf(residual_table_to_xarray(table), out_nc)
    result["figures"] = [str(p) for p in write_figures(table, result, fig_dir)]
    return result
