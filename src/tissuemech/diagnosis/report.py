"""The report stage of the diagnosis: it runs the stages in order and writes what they found.

The package reads as the pipeline: :mod:`.baseline` (the fitted model on the runs) -> :mod:`.noise` (the noise of
the data) -> :mod:`.evidence` (the residual table) -> the detectors of the registry :mod:`.causes` (with
:mod:`.generic` and :mod:`.covariates` for unnamed structure) -> :mod:`.decision` (the one rule) -> :mod:`.fixes`
(fixes that refit the baseline) -> this module (the ``diagnosis.json`` result, the residual netCDF and
:mod:`.figures`). Homogeneous multi-mode specimens go through :mod:`.homogeneous` under the same rule.

Entry points
------------
:func:`diagnose` ``(runs, table, model, fit_info) -> dict``
    runs every detector of the registry and every structure test on the residual table of the baseline model,
    applies :data:`tissuemech.diagnosis.decision.DECISION_RULE` (Holm at alpha/2 to the named causes and alpha/2 to
    the scan for unnamed structure, practical relevance, a fix that beats the noise margin on held-out data) and
    assembles the result. An inadequate baseline (``adequacy``) is the first finding, ``baseline_inadequate``, and
    only baseline-free causes may be named when no adequate model is left.

:func:`run_diagnosis` ``(runs_dir, fits_dir, out_json, out_nc, fig_dir, baseline=None, extensions=True,
dataset=None, alpha=ALPHA, ranking=None) -> dict``
    the Snakemake ``diagnose`` rule's call. Homogeneous-specimen datasets (simple shear + uniaxial
    compression/tension, e.g. Budday) go to :func:`run_homogeneous_diagnosis` (cross-mode diagnosis; same JSON
    contract plus ``cross_mode``). Otherwise: ``runs_dir``: folder of canonical run netCDFs (searched
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
``decision_rule`` (the sentence of :data:`~tissuemech.diagnosis.decision.DECISION_RULE`); ``noise_model``
(:func:`~tissuemech.noise.estimate_noise` plus ``relative_level`` eps); ``baseline`` {``model``, ``adequate``, ``tried``: adequacy of every candidate,
``cross_test_shape``: the misfit shape shared by every frequency sweep the baseline predicted without being
fitted to it (:func:`tissuemech.diagnosis.generic.shared_shape`: ``range_log``, ``degree``, ``wald_p``,
``evidence``), removed before the covariate scan of those curves};
``findings``: ``baseline_inadequate`` first when a candidate was rejected (``models``, ``evidence``), then one
entry per catalogue id, detected first (strongest first): ``effect``, ``detected``,
``tested``, ``statistic`` (+ ``statistic_name``), ``p_value`` (uncorrected), ``p_holm``, ``effect_size``
(+ unit), ``practical``, ``evidence`` (sentence naming tests/conditions/covariates), ``fix`` {``model``,
``metric``, ``before``, ``after``, ``gain``, ``cv``, ``parameters``, ``margin``, ``improvement``,
``beats_margin``} or null, ``decision`` (why it is or is not named) and ``what_to_do`` (the next step in plain
words, :func:`tissuemech.diagnosis.causes.what_to_do`).
``significant_fix_not_evaluated``: ``effect``, ``p_holm``, ``effect_size`` (+ unit), ``evidence`` of causes that
pass Holm and practical relevance but whose fix was not scored (not named).
``unexplained``: structured residual not named by a detected cause: ``covariate``, ``test``,
``quantity``, ``statistic``, ``p_value``, ``p_holm``, ``effect_size`` (log-residual change over the
covariate's range), ``candidates`` (catalogue causes whose signature involves that covariate),
``separating_design`` (structure across curves), ``what_to_do``.
``covariates``: every sample-sheet column, logged channel and session-clock covariate tested against the curve
levels with specimen and sample as random effects, significant or not, and the outlier specimen and sample rows
(:mod:`.covariates`).
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
from statsmodels.tools.sm_exceptions import MissingDataError

from .. import fitting
from ..canonical import read_netcdf, write_netcdf
from ..models.registry import FIXED_TIME_KEY, get_model, model_on_times
from .. import stats as st
from ..material import REFINE_DECADES
from . import homogeneous
from .baseline import (NNLS_RESPONSES, baseline_adequacy, fit_runs, level_normalised, nnls_relaxation_times,
                       polished_times, predict_runs, ranked_candidates, read_fit_record, resolved_window_s,
                       window_taus)
from .causes import CAUSE_IDS, DETECTORS, what_to_do
from .covariates import covariate_tests, curve_frame, outlier_rows
from .decision import DECISION_RULE, apply_rule, ordered, top_finding, unexplained_structure  # noqa: F401 (top_finding: API)
from .evidence import residual_table, residual_table_to_xarray
from .figures import write_figures, write_multimode_figures
from .findings import DiagnosisContext, write_diagnosis_json
from .fixes import score_model_fixes
from .generic import confounded_covariates, serial_structure, structure_tests
from .noise import OSCILLATORY_TESTS, estimate_noise, relative_noise_level
from .simulation_cards import write_simulation_cards


def run_detectors(ctx: DiagnosisContext) -> list[dict]:
    """Every detector of the registry (:data:`tissuemech.diagnosis.causes.DETECTORS`); a detector that fails is
    reported as untested with the error (never silent)."""
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


def diagnose(runs: Sequence[xr.Dataset], table: pd.DataFrame, model: str = "model", fit_info: dict | None = None,
             alpha: float = st.ALPHA, noise: dict | None = None, adequacy: Sequence[dict] = ()) -> dict:
    """Named findings, unexplained structure and the covariates table of one baseline model (module docstring).

    ``runs``: every run of the dataset (the baseline-free detectors read them; the residual ``table`` covers the
    runs the baseline predicts). ``noise``: the :func:`tissuemech.noise.estimate_noise` model of
    ``runs`` (estimated when None); ``adequacy``: :func:`tissuemech.diagnosis.baseline.baseline_adequacy` of every
    model tried before and including this one; an inadequate entry becomes the ``baseline_inadequate`` finding,
    and when the last entry (this model) is inadequate only baseline-free causes may be named.
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
    frame = curve_frame(ctx) if len(table) else pd.DataFrame()
    covariates = covariate_tests(frame)
    scanned = [c for c in covariates if c.get("tested")]
    not_evaluated = apply_rule(findings, generic + scanned, alpha, eps, n_curves, usable)
    for c in covariates:
        c.setdefault("p_holm", np.nan)
        c.setdefault("significant", False)
    covariates += outlier_rows(ctx, findings, alpha) if len(table) else []
    confounded = confounded_covariates(table, runs)
    sets = [c["covariates"] for c in confounded]
    unexplained = unexplained_structure(generic + scanned, findings, model, sets, fitted) if usable else []
    not_identifiable = [{"effect": f["effect"], "evidence": f["evidence"]} for f in findings
                        if f.get("identifiable") is False]
    head = []
    if rejected:
        head = [{"effect": "baseline_inadequate", "detected": True, "tested": True, "significant": True,
                 "practical": True, "statistic": rejected[0]["misfit_noise_units"],
                 "statistic_name": "RMS misfit in noise SDs", "p_value": np.nan, "p_holm": np.nan, "log10_p": np.nan,
                 "effect_size": rejected[0]["misfit_factor"], "effect_size_unit": "x (typical point off by)",
                 "fix": None, "models": [a["model"] for a in rejected],
                 "decision": "the baseline is reported before any cause",
                 "evidence": " ".join(f"{a['model']}: " + "; ".join(a["reasons"]) + "." for a in rejected)
                 + (f" Diagnosed with the next adequate model, {model}." if usable else
                    " No fitted model is adequate: only causes whose test and fix do not use its predictions "
                    "may be named.")}]
        head[0]["what_to_do"] = what_to_do(head[0])
    n_tests = sum(1 for f in findings if f.get("tested") and np.isfinite(f.get("p_value", np.nan))) \
        + len(generic) + len(covariates)
    return {"model": model, "fit_info": {k: v for k, v in fit_info.items() if k not in ("fixes", "simulation_fits")},
            "alpha": alpha,
            "decision_rule": DECISION_RULE,
            "noise_model": {**noise, "relative_level": eps},
            "baseline": {"model": model, "adequate": usable, "tried": list(adequacy),
                         "cross_test_shape": [dict(sh, evidence=_shape_evidence(sh, model)) for sh in shapes]},
            "n_tests": n_tests, "findings": head + ordered(findings), "unexplained": unexplained,
            "significant_fix_not_evaluated": not_evaluated, "covariates": covariates,
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


def with_model_fixes(result: dict, runs: Sequence[xr.Dataset], table: pd.DataFrame, fit_info: dict,
                     alpha: float = st.ALPHA, noise: dict | None = None, adequacy: Sequence[dict] = (),
                     all_runs: Sequence[xr.Dataset] | None = None) -> dict:
    """Score the model-level fixes of the causes that pass Holm and practical relevance
    (:func:`tissuemech.diagnosis.fixes.score_model_fixes`, refits on ``runs``), then diagnose again, so that such a
    cause is named only when its fix beats the margin on held-out data. ``result`` and ``fit_info`` are those of
    :func:`diagnose` (``fit_info["fixes"]`` receives the scored fixes); ``all_runs``: every run of the dataset for
    the second diagnosis (default ``runs``). Returns the new result."""
    if not score_model_fixes(result, runs, fit_info, noise):
        return result
    return diagnose(list(all_runs) if all_runs is not None else runs, table, result["model"], fit_info,
                    alpha=alpha, noise=noise, adequacy=adequacy)


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
                  simulation_fits: dict | None = None,
                  fit_stage_taus_s: Sequence[float] = ()) -> dict | tuple[dict, pd.DataFrame]:
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
    scored when ``extensions``. ``fit_stage_taus_s``: the relaxation times the fit stage's model chose from every
    test kind (its fit record); those that only the sweeps resolve join the NNLS times
    (:func:`_with_sweep_times`). Returns the :func:`diagnose` result with ``fit_info.taus_s``,
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
    first = _with_sweep_times(_linear_law_spectrum(fitted, target, relaxation, window), fitted, fit_stage_taus_s)

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
                                     "weights": [float(w) for w in spectrum["weights"]],
                                     **({"nnls_taus_s": [float(t) for t in spectrum["nnls_taus_s"]]}
                                        if "nnls_taus_s" in spectrum else {})},
                "params": {k: float(v) for k, v in fit.params.items()},
                "baseline_order": order_source or ("aicc" if len(keys) > 1 else "requested"),
                "baseline_aicc": {k: float(f.aicc) for k, f in fits.items()}}
    if simulation_fits is not None:
        # the model-level fixes' fold and full-data fits, for the cards the simulator replays (not written to JSON)
        fit_info["simulation_fits"] = simulation_fits
    # every run reaches the detectors (those that read the runs themselves, e.g. an amplitude sweep the baseline
    # cannot predict); the model-level fixes refit the runs the baseline predicts
    result = diagnose(runs, table, key, fit_info, alpha=alpha, noise=noise, adequacy=adequacy)
    if extensions:
        result = with_model_fixes(result, kept, table, fit_info, alpha=alpha, noise=noise, adequacy=adequacy,
                                  all_runs=runs)
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


#: a fit-stage time joins the NNLS times only this far (factor) from every one of them: nearer, NNLS already has it
SWEEP_TIME_SEPARATION = 10 ** 0.5


def _with_sweep_times(spectrum: dict, runs: Sequence[xr.Dataset], fit_stage_taus_s: Sequence[float]) -> dict:
    """``spectrum`` with the fit stage's times that only the sweeps resolve: those outside the histories' window
    (:func:`~tissuemech.diagnosis.baseline.resolved_window_s` of the ramps, relaxations and creep) and more than
    :data:`SWEEP_TIME_SEPARATION` from every NNLS time. The NNLS reads the histories only
    (:data:`~tissuemech.diagnosis.baseline.NNLS_RESPONSES`), so a mode that shapes G*(omega) faster than any ramp
    sample (a 7 ms mode under 0.01-1 1/s ramps) was missing from the baseline and left its shape along every
    frequency sweep as unexplained structure. Unchanged without sweeps or histories among ``runs`` (sweeps alone:
    the NNLS had nothing to read and the window's grid stands in; adding every fit-stage time there cost 7x the
    CPU of a temperature series' diagnosis), or without such a time."""
    taus = np.asarray(spectrum["taus_s"], float)
    extra = np.asarray(fit_stage_taus_s, float)
    extra = extra[np.isfinite(extra) & (extra > 0)]
    if not extra.size or not any(r.attrs.get("test") in OSCILLATORY_TESTS for r in runs):
        return spectrum
    histories = resolved_window_s([r for r in runs if fitting.TEST_RESPONSE.get(r.attrs.get("test"))
                                   in NNLS_RESPONSES])
    lo, hi = histories["t_min_s"], histories["t_max_s"]
    if not (np.isfinite(lo) and np.isfinite(hi)):
        return spectrum
    far = np.array([not taus.size or np.min(np.abs(np.log(t / taus))) > np.log(SWEEP_TIME_SEPARATION)
                    for t in extra])
    return _joined(spectrum, taus, extra[((extra < lo) | (extra > hi)) & far])


def _joined(spectrum: dict, taus: np.ndarray, sweep_taus: np.ndarray) -> dict:
    """``spectrum`` on ``taus`` with the sweep-only times ``sweep_taus`` added (kept as ``sweep_taus_s`` for a
    later NNLS of the same runs, :func:`_fit_on_data_times`); unchanged when there are none."""
    if not sweep_taus.size:
        return spectrum
    return {**spectrum, "taus_s": np.sort(np.r_[taus, sweep_taus]), "sweep_taus_s": sweep_taus,
            "method": spectrum["method"] + "; with the fit stage's time(s) "
            + ", ".join(f"{t:.3g}" for t in sweep_taus) + " s that only the sweeps resolve"}


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
    normalised = level_normalised(runs, spectrum["levels"])
    fit = fit_runs(key, normalised, target, relaxation, n_points=n_points, taus_s=taus if taus.size else None)
    law = getattr(model_on_times(key, taus), "instantaneous", None) if taus.size else None
    # a one-parameter law is its modulus times a fixed shape, absorbed by the weights: nothing to repeat
    if law is not None and len(law.param_names) > 1 and fit.success:
        again = nnls_relaxation_times(runs, target, relaxation, window, model_key=key, law_params=fit.params)
        if again["taus_s"].size:
            again = _joined(again, again["taus_s"], np.asarray(spectrum.get("sweep_taus_s", ()), float))
        if again["taus_s"].size and not np.array_equal(again["taus_s"], taus):
            fit = fit_runs(key, normalised, target, relaxation, n_points=n_points, taus_s=again["taus_s"])
            taus = again["taus_s"]
            spectrum = {**again, "levels": spectrum["levels"],
                        "method": again["method"] + ", repeated with the fitted instantaneous law"}
    polished, fit_polished = polished_times(key, normalised, target, relaxation, n_points, taus, fit)
    if fit_polished is not fit:
        spectrum = {**spectrum, "taus_s": polished, "nnls_taus_s": np.asarray(taus, float),
                    "method": spectrum["method"] + "; times then fitted with the model (within "
                    f"{REFINE_DECADES:g} decade of each)"}
        fit = fit_polished
    return fit, spectrum


def _read_runs(runs_dir: str | Path) -> list[xr.Dataset]:
    files = sorted(Path(runs_dir).rglob("*.nc"))
    runs = [read_netcdf(f) for f in files]
    return [r for r in runs if "test" in r.attrs]


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
    if homogeneous.is_homogeneous(runs):
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
            simulation_fits=simulation_fits, fit_stage_taus_s=lead.get("taus_s", ()))
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


def run_homogeneous_diagnosis(runs: Sequence[xr.Dataset], out_json, out_nc, fig_dir, dataset: str = "",
                              alpha: float = st.ALPHA, seed: int = 0) -> dict:
    """Pipeline entry for multi-mode homogeneous data (:func:`tissuemech.diagnosis.homogeneous.diagnose_homogeneous`
    with :data:`~tissuemech.diagnosis.homogeneous.SETTINGS`): ``diagnosis.json``, the residual netCDF, figures."""
    result, table = homogeneous.diagnose_homogeneous(runs, alpha=alpha, seed=seed, **homogeneous.SETTINGS)
    write_diagnosis_json(result, out_json, dataset=dataset)
    ds = residual_table_to_xarray(table)
    for name, unit in (("observed", "Pa"), ("predicted", "Pa"), ("residual", "Pa"), ("sigma", "Pa")):
        ds[name].attrs["units"] = unit
    ds.attrs.update({"dataset": dataset, "kind": "homogeneous_multimode", "baseline": result["model"],
                     "extension": result["fit_info"]["extension"]})
    write_netcdf(ds, out_nc)
    result["figures"] = [str(p) for p in write_multimode_figures(homogeneous.mode_curves(runs), table, result,
                                                                 fig_dir)]
    return result


def _write_outputs(result: dict, table: pd.DataFrame, out_json, out_nc, fig_dir, dataset: str) -> dict:
    """diagnosis.json, the diagnosed baseline's residual netCDF and the figures (atomic writes)."""
    write_diagnosis_json(result, out_json, dataset=dataset)
    if len(table):
        write_netcdf(residual_table_to_xarray(table), out_nc)
    result["figures"] = [str(p) for p in write_figures(table, result, fig_dir)]
    return result
