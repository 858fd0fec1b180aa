"""Honest model ranking: information criteria, cross-validation, identifiability and a recommendation.

Per data scope (a set of curves fitted jointly, with one plate target) every candidate model is fitted
(:func:`tissuemech.fitting.fit`) and judged on

* AICc and BIC (with n and with the effective n from lag-1 residual autocorrelation; dense curves overstate
  n, ``science.md`` §4.2), Akaike weights, in-sample RMSE/NRMSE;
* held-out error from cross-validation folds (:func:`leave_one_condition_out` -- fit three CSR rates,
  predict the fourth; :func:`train_on_tests` -- fit relaxation, predict the frequency sweep and the CSR
  ramps; :func:`leave_one_specimen_out`); condition-level CV is the primary criterion because it does not
  depend on the assumed independence of points;
* a paired comparison with the best model across folds (Wilcoxon signed-rank on per-fold errors);
* identifiability and convergence flags, and the valid strain/rate range of the data.

:func:`recommend` applies the thesis selection criteria (strain <= 10 % and rate-independent -> linear
elastic; larger strain -> hyperelastic; rate matters -> QLV; both plus strain-dependent relaxation ->
beyond-QLV) and states when the ranking of the data says otherwise.
"""
from __future__ import annotations

import math
import multiprocessing as mp
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
import scipy

from .fitting import (Curve, FitProblem, FitResult, NoiseModel, at_bound_parameters, describes, evaluate, fit,
                      has_covariance,
                      prony_start)
from .adequacy import add_assessment, assess, supported_mask, verdict
from .models.base import ConstitutiveModel
from .models.registry import get_model
from .plots import save_figure

#: strain up to which the thesis treats brain tissue as linear elastic (10 %)
LINEAR_STRAIN_LIMIT = 0.10
#: information-criterion difference regarded as strong support (Burnham & Anderson)
STRONG_EVIDENCE = 10.0


@dataclass(frozen=True)
class Fold:
    """One cross-validation fold: fit on ``train`` curve labels, predict ``test`` curve labels."""

    name: str
    design: str
    train: tuple[str, ...]
    test: tuple[str, ...]


@dataclass(frozen=True)
class RegistryFactory:
    """Picklable zero-argument factory of a registry model (lets candidate fits run in worker processes)."""

    key: str

    def __call__(self) -> ConstitutiveModel:
        return get_model(self.key)


def leave_one_condition_out(curves: Sequence[Curve], test: str = "constant_shear_rate") -> list[Fold]:
    """Hold out each condition of ``test`` in turn (e.g. fit three CSR rates + everything else, predict the
    fourth rate). Needs at least two conditions of that test."""
    of_test = [c for c in curves if c.test == test]
    conditions = sorted({c.condition for c in of_test})
    if len(conditions) < 2:
        return []
    folds = []
    for cond in conditions:
        held = tuple(c.label for c in of_test if c.condition == cond)
        folds.append(Fold(name=f"hold {test} {cond}", design="leave_one_condition_out",
                          train=tuple(c.label for c in curves if c.label not in held), test=held))
    return folds


def train_on_tests(curves: Sequence[Curve], train_tests: Sequence[str] = ("stress_relaxation",),
                   predict_tests: Sequence[str] = ("frequency_sweep", "constant_shear_rate")) -> list[Fold]:
    """Fit on the curves of ``train_tests`` only and predict the curves of ``predict_tests`` (one fold)."""
    train = tuple(c.label for c in curves if c.test in train_tests)
    test = tuple(c.label for c in curves if c.test in predict_tests)
    if not train or not test:
        return []
    return [Fold(name=f"fit {'+'.join(train_tests)} -> predict {'+'.join(predict_tests)}",
                 design="leave_one_test_type_out", train=train, test=test)]


def leave_one_specimen_out(curves: Sequence[Curve]) -> list[Fold]:
    """Hold out every curve of one specimen in turn (population models; needs >= 2 specimens)."""
    specimens = sorted({c.specimen for c in curves})
    if len(specimens) < 2:
        return []
    return [Fold(name=f"hold specimen {s}", design="leave_one_specimen_out",
                 train=tuple(c.label for c in curves if c.specimen != s),
                 test=tuple(c.label for c in curves if c.specimen == s)) for s in specimens]


@dataclass
class Candidate:
    """A model to rank: registry key, factory and optional fit settings."""

    key: str
    factory: Callable[[], ConstitutiveModel]
    starts: Callable[[Sequence[Curve]], list[dict]] | None = None
    fixed: Mapping[str, float] = field(default_factory=dict)
    bounds: Mapping[str, tuple[float, float]] = field(default_factory=dict)

    def describes(self, curves: Sequence[Curve]) -> bool:
        model = self.factory()
        return all(describes(model, c.response) for c in curves)


def fit_candidate(cand: Candidate, curves: Sequence[Curve], target: str, scope: str = "",
                  noise: NoiseModel | None = None, n_random: int = 4, seed: int = 0,
                  relaxation: str = "measured") -> FitResult:
    """Fit one candidate to ``curves`` (joint fit, one plate target; ``relaxation`` is recorded)."""
    problem = FitProblem(model=cand.factory(), curves=list(curves), target=target, model_key=cand.key,
                         noise=noise or NoiseModel(), fixed=cand.fixed, bounds=cand.bounds, scope=scope,
                         relaxation=relaxation)
    if cand.starts:
        starts = cand.starts(curves)
    else:  # NNLS Prony start for QLV models (robust; the model default is tried as well)
        nn = prony_start(problem.model, curves, problem.noise)
        starts = [nn] if nn else []
    return fit(problem, starts=starts, n_random=n_random, seed=seed)


def cross_validate(cand: Candidate, curves: Sequence[Curve], folds: Sequence[Fold], target: str,
                   noise: NoiseModel | None = None, n_random: int = 2, seed: int = 0,
                   start: Mapping[str, float] | None = None) -> list[dict]:
    """Held-out errors of a candidate on each fold.

    Returns one record per fold: ``fold``, ``design``, ``model``, held-out ``rmse``/``nrmse``/``chisqr_per_point``,
    ``n_test``, ``train_flags`` and ``status`` (``"ok"``, or why the fold was skipped: a model that cannot
    describe the held-out test kind is *not* scored on it).
    """
    by_label = {c.label: c for c in curves}
    model = cand.factory()
    out = []
    for fold in folds:
        rec = {"fold": fold.name, "design": fold.design, "model": cand.key, "rmse": np.nan, "nrmse": np.nan,
               "chisqr_per_point": np.nan, "n_test": 0, "train_flags": "", "status": "ok"}
        train = [by_label[k] for k in fold.train]
        test = [by_label[k] for k in fold.test]
        if not cand.describes(test):
            rec["status"] = "model cannot describe the held-out test kind"
            out.append(rec)
            continue
        if not cand.describes(train):
            train = [c for c in train if cand.describes([c])]
            if not train:
                rec["status"] = "model cannot describe any training curve"
                out.append(rec)
                continue
        try:
            problem = FitProblem(model=cand.factory(), curves=train, target=target, model_key=cand.key,
                                 noise=noise or NoiseModel(), fixed=cand.fixed, bounds=cand.bounds)
            starts = ([dict(start)] if start else []) + (cand.starts(train) if cand.starts else [])
            # the full-data optimum is a close start for every fold: random restarts only without it
            res = fit(problem, starts=starts, n_random=0 if start else n_random, seed=seed)
            ev = evaluate(model, res.params, test, target, noise)
        except (ValueError, RuntimeError) as exc:
            rec["status"] = f"failed: {exc}"
            out.append(rec)
            continue
        rec.update(rmse=ev["rmse"], nrmse=ev["nrmse"], chisqr_per_point=ev["chisqr"] / max(ev["n"], 1),
                   n_test=ev["n"], train_flags="; ".join(res.flags))
        out.append(rec)
    return out


def _identifiable(flags: Sequence[str]) -> bool:
    return not any(f.startswith(("correlated", "no_covariance", "poorly_determined")) for f in flags)


def paired_comparison(cv: pd.DataFrame, metric: str = "nrmse") -> pd.DataFrame:
    """Per model: mean held-out error, and a paired Wilcoxon signed-rank test against the model with the
    lowest mean error over the folds both were scored on (two-sided; NaN with fewer than 2 shared folds)."""
    ok = cv[cv["status"] == "ok"]
    if ok.empty:
        return pd.DataFrame(columns=["model", f"cv_{metric}", "cv_folds", "cv_best", "cv_p_vs_best"])
    wide = ok.pivot_table(index="fold", columns="model", values=metric)
    means = wide.mean(axis=0)
    best = str(means.idxmin())
    rows = []
    for model in wide.columns:
        both = wide[[best, model]].dropna()
        p = np.nan
        if model != best and len(both) >= 2 and np.any(both[model] != both[best]):
            p = float(scipy.stats.wilcoxon(both[model], both[best]).pvalue)
        rows.append({"model": model, f"cv_{metric}": float(means[model]), "cv_folds": int(wide[model].notna().sum()),
                     "cv_best": best, "cv_p_vs_best": p})
    return pd.DataFrame(rows)


def ranking_table(fits: Mapping[str, FitResult], cv: pd.DataFrame | None = None, scope: str = "",
                  dataset: str = "") -> pd.DataFrame:
    """``ranking.csv`` rows of one scope: criteria, deltas, Akaike weights, CV error, flags, ranges, rank.

    Rank order: mean held-out NRMSE when every model was scored by cross-validation, otherwise AICc.
    Models whose fit did not converge are ranked last. ``recommendable`` says whether a fit may be recommended
    (:func:`recommend`): converged, with a covariance (``has_covariance``) and no varying parameter at a bound
    (``at_bound``, :func:`tissuemech.fitting.at_bound_parameters`).
    """
    rows = []
    for key, r in fits.items():
        at_bound = at_bound_parameters(r.flags)
        cov = has_covariance(r.flags, r.stderr, r.varying)
        rows.append({"dataset": dataset, "scope": scope or r.scope, "target": r.target, "model": key,
                     "family": r.family, "k": r.k, "n": r.n, "n_eff": r.n_eff, "chisqr": r.chisqr, "rmse": r.rmse,
                     "nrmse": r.nrmse, "aic": r.aic, "aicc": r.aicc, "bic": r.bic, "aicc_eff": r.aicc_eff,
                     "bic_eff": r.bic_eff, "converged": r.success, "identifiable": _identifiable(r.flags),
                     "at_bound": "; ".join(at_bound), "has_covariance": cov,
                     "recommendable": bool(r.success and cov and not at_bound),
                     "n_flags": len(r.flags), "flags": "; ".join(r.flags), **r.ranges})
    table = pd.DataFrame(rows)
    if table.empty:
        return table
    for crit in ("aicc", "bic", "aicc_eff"):
        table[f"delta_{crit}"] = table[crit] - table[crit].min()
    rel = np.exp(-0.5 * table["delta_aicc"].to_numpy(float))
    table["akaike_weight"] = rel / rel.sum()
    if cv is not None and not cv.empty:
        table = table.merge(paired_comparison(cv), on="model", how="left")
    else:
        for col in ("cv_nrmse", "cv_folds", "cv_best", "cv_p_vs_best"):
            table[col] = np.nan
    # models scored by cross-validation rank first by held-out error; the others (not cross-validated, e.g.
    # outside the AICc short list) follow by AICc
    table["_bad"] = ~table["converged"]
    table["_no_cv"] = table["cv_nrmse"].isna()
    table = table.sort_values(["_bad", "_no_cv", "cv_nrmse", "aicc"]).reset_index(drop=True)
    table["rank_criterion"] = np.where(table["_no_cv"], "aicc", "cv_nrmse")
    table = table.drop(columns=["_bad", "_no_cv"])
    table["rank"] = np.arange(1, len(table) + 1)
    return table


# ------------------------------------------------------------------------------------------------
# evidence from the data and the thesis selection criteria
# ------------------------------------------------------------------------------------------------
def rate_dependence(curves: Sequence[Curve], noise: NoiseModel | None = None) -> dict:
    """Does the stress at a given strain depend on the shear rate? (CSR curves at >= 2 rates)

    At strains covered by every CSR curve the log-stress is regressed on log-rate; returns the median
    slope ``d ln sigma / d ln rate``, the relative stress change across the rate range, the relative
    uncertainty (mean of SD/mean of the curves and the noise floor), and ``rate_dependent``: the change
    exceeds three times the uncertainty.
    """
    noise = noise or NoiseModel()
    csr = [c for c in curves if c.test == "constant_shear_rate" and "shear_rate_1_per_s" in c.nominal]
    rates = sorted({c.nominal["shear_rate_1_per_s"] for c in csr})
    if len(rates) < 2:
        return {"rate_dependent": None, "reason": "fewer than two CSR rates"}
    lo = max(np.min(c.obs_inputs("shear_strain")) for c in csr)
    hi = min(np.max(c.obs_inputs("shear_strain")) for c in csr)
    lo = max(lo, 0.1 * hi)
    if not hi > lo:
        return {"rate_dependent": None, "reason": "CSR strain ranges do not overlap"}
    grid = np.linspace(lo, hi, 20)
    logs, lr, rel_sd = [], [], []
    for c in csr:
        x = c.obs_inputs("shear_strain")
        y = np.asarray(c.observed["shear_stress"], float)
        order = np.argsort(x)
        yi = np.interp(grid, x[order], y[order])
        logs.append(np.log(np.maximum(yi, 1e-300)))
        lr.append(math.log(c.nominal["shear_rate_1_per_s"]))
        sig = noise.sigma("shear_stress", y, c.sd.get("shear_stress"))
        rel_sd.append(float(np.median(sig / np.maximum(np.abs(y), 1e-300))))
    logs = np.array(logs)
    lr = np.array(lr)
    slopes = np.polyfit(lr, logs, 1)[0]
    change = float(np.median(np.abs(slopes)) * (lr.max() - lr.min()))
    uncertainty = float(np.median(rel_sd))
    return {"rate_dependent": bool(change > 3.0 * uncertainty), "slope_median": float(np.median(slopes)),
            "relative_change": float(math.expm1(change)), "relative_uncertainty": uncertainty,
            "strain_window": (float(lo), float(hi)), "rates_1_per_s": rates}


def time_dependence(curves: Sequence[Curve], noise: NoiseModel | None = None) -> dict:
    """Evidence that the response depends on time or rate, from whatever tests a scope has.

    Constant-shear-rate curves at several rates decide (:func:`rate_dependence`); otherwise relaxation
    (stress decay during the hold larger than 3x the relative uncertainty) or a frequency sweep (loss factor
    G''/G' larger than 3x the relative uncertainty). ``rate_dependent`` is ``None`` when no test can tell.
    """
    noise = noise or NoiseModel()
    rd = rate_dependence(curves, noise)
    if rd.get("rate_dependent") is not None:
        return rd | {"evidence": "csr_rates"}
    decays, uncert = [], []
    for c in curves:
        if c.test == "stress_relaxation":
            y = np.abs(np.asarray(c.observed["shear_stress"], float))
            k = int(np.argmax(y))
            if y.size - k >= 3:
                decays.append(1.0 - y[-1] / y[k])
                sig = noise.sigma("shear_stress", y, c.sd.get("shear_stress"))
                uncert.append(float(np.median(sig / np.maximum(y, 1e-300))))
    if decays:
        d, u = float(np.median(decays)), float(np.median(uncert))
        return {"rate_dependent": bool(d > 3 * u), "evidence": "relaxation_decay", "relative_decay": d,
                "relative_uncertainty": u}
    tans, uncert = [], []
    for c in curves:
        if c.test == "frequency_sweep":
            g1, g2 = np.asarray(c.observed["storage_modulus"], float), np.asarray(c.observed["loss_modulus"], float)
            tans.append(float(np.median(g2 / np.maximum(g1, 1e-300))))
            sig = noise.sigma("storage_modulus", g1, c.sd.get("storage_modulus"))
            uncert.append(float(np.median(sig / np.maximum(np.abs(g1), 1e-300))))
    if tans:
        t, u = float(np.median(tans)), float(np.median(uncert))
        return {"rate_dependent": bool(t > 3 * u), "evidence": "loss_factor", "loss_factor": t,
                "relative_uncertainty": u}
    return rd | {"evidence": "none"}


def thesis_rule(strain_max: float, rate_dependent: bool, nonseparable: bool = False) -> str:
    """The thesis selection criteria as a family: ``linear_elastic``, ``hyperelastic``, ``qlv`` or ``beyond_qlv``."""
    if rate_dependent and strain_max > LINEAR_STRAIN_LIMIT and nonseparable:
        return "beyond_qlv"
    if rate_dependent:
        return "qlv"
    if strain_max > LINEAR_STRAIN_LIMIT:
        return "hyperelastic"
    return "linear_elastic"


def _family_class(row: pd.Series) -> str:
    fam = str(row["family"])
    if fam == "hyperelastic" and str(row["model"]).startswith(("linear", "hooke")):
        return "linear_elastic"
    if fam in ("linear_viscoelastic", "fractional"):
        return "qlv"  # linear viscoelastic = QLV with a linear instantaneous law
    return fam


def _not_recommendable_reason(row: pd.Series) -> str:
    reasons = []
    if not bool(row.get("converged", True)):
        reasons.append("did not converge")
    if isinstance(row.get("at_bound"), str) and row["at_bound"]:
        reasons.append(f"{row['at_bound']} at a bound")
    if not bool(row.get("has_covariance", True)):
        reasons.append("no covariance")
    if "determined" in row and not bool(row["determined"]) and isinstance(row.get("undetermined"), str) \
            and row["undetermined"]:
        reasons.append(f"undetermined {row['undetermined']} (standard error above the value)")
    if "skill" in row and not row["skill"] > 0:
        reasons.append(f"no better than the curves' means (skill {row['skill']:.3g})")
    if "adequate" in row and not bool(row["adequate"]) and np.isfinite(row.get("misfit_noise_units", np.nan)):
        reasons.append(f"misfit {row['misfit_noise_units']:.3g} noise SDs")
    return ", ".join(reasons) or "flagged"


def recommend(table: pd.DataFrame, curves: Sequence[Curve], noise: NoiseModel | None = None,
              decisive_cv_ratio: float = 0.8) -> dict:
    """Recommendation for one scope: the thesis rule, the data's ranking, and whether they agree.

    Evidence: maximum strain of the data; time/rate dependence (:func:`time_dependence`; when no test can
    tell, a time-dependent model beating every elastic one by ΔAICc > 10); strain-dependent relaxation (a
    beyond-QLV model beating the best QLV by ΔAICc > 10 and not worse in CV).

    Only supported fits (:func:`tissuemech.adequacy.supported_mask`: ``recommendable`` and, in an assessed table,
    determined, adequate against the measured noise and better than the curves' means) can be recommended;
    without one the scope's ``verdict`` is ``no_model_supported``. ``recommendable`` (:func:`ranking_table`:
    converged, with a covariance, no parameter at a
    bound) can be recommended; the statement names every fit that is not, and why. Among them the
    rule's family is recommended (best model of that family) unless the top-ranked model of another family is
    *decisively* better: held-out NRMSE below ``decisive_cv_ratio`` times the rule model's, or, without
    cross-validation, ΔAICc > 10. The statement then says that the data say otherwise. When no fit is
    recommendable, ``recommended`` is ``None`` and the statement says why.
    """
    if table.empty:
        return {"recommended": None, "statement": "no model was fitted"}
    strain_max = float(np.nanmax(table["strain_max"])) if "strain_max" in table else float("nan")
    rd = time_dependence(curves, noise)
    classes = table.apply(_family_class, axis=1)
    # best of each family in the table's own rank order (evidence: every fit, flagged or not)
    best_of = {cls: table[classes == cls].iloc[0] for cls in classes.unique()}
    rate_dep = rd.get("rate_dependent")
    if rate_dep is None:
        elastic = [best_of[c]["aicc"] for c in ("linear_elastic", "hyperelastic") if c in best_of]
        timed = [best_of[c]["aicc"] for c in ("qlv", "beyond_qlv") if c in best_of]
        rate_dep = bool(elastic and timed and min(timed) < min(elastic) - STRONG_EVIDENCE)
    nonsep = False
    if "beyond_qlv" in best_of and "qlv" in best_of:
        b, q = best_of["beyond_qlv"], best_of["qlv"]
        cv_ok = not (np.isfinite(b.get("cv_nrmse", np.nan)) and np.isfinite(q.get("cv_nrmse", np.nan))
                     and b["cv_nrmse"] > q["cv_nrmse"])
        nonsep = bool(b["aicc"] < q["aicc"] - STRONG_EVIDENCE and cv_ok)
    rule = thesis_rule(strain_max if np.isfinite(strain_max) else 0.0, rate_dep, nonsep)
    # the choice: recommendable fits only
    ok = supported_mask(table)
    pool, pool_classes = table[ok], classes[ok]
    first = table.iloc[0]
    evidence = (f"Thesis criteria: max strain {100 * strain_max:.3g} %, "
                f"{'rate/time-dependent' if rate_dep else 'rate-independent'} ({rd.get('evidence', 'models')})"
                f"{', strain-dependent relaxation' if nonsep else ''} -> {rule.replace('_', ' ')}")
    passed = [f"{row['model']} ({_not_recommendable_reason(row)})" for (_, row), good in zip(table.iterrows(), ok)
              if not good]
    common = {"rule_family": rule, "strain_max": strain_max, "rate_dependent": rate_dep, "nonseparable": nonsep,
              "rate_evidence": rd}
    if pool.empty:
        why = verdict(table)["reason"] if "determined" in table else (
            "no fit is converged with a covariance and no parameter at a bound")
        statement = (f"{evidence}. Data ranking ({first.get('rank_criterion', 'aicc')}): {first['model']} first. "
                     f"No model is supported: {why} ({'; '.join(passed)}).")
        return common | {"rule_model": None, "data_model": None, "data_family": None, "agree": False,
                         "recommended": None, "verdict": "no_model_supported", "verdict_reason": why,
                         "statement": statement}
    best_ok = {cls: pool[pool_classes == cls].iloc[0] for cls in pool_classes.unique()}
    top = pool.iloc[0]
    top_class = _family_class(top)
    rule_best = best_ok.get(rule)
    statement = (evidence
                 + (f" (best fitted: {rule_best['model']})" if rule_best is not None else " (no such model fitted)")
                 + f". Data ranking ({top['rank_criterion']}): {top['model']} ({top_class.replace('_', ' ')}) first"
                 + (f" among the recommendable fits; not recommendable: {'; '.join(passed)}" if passed else "") + ".")
    agree = top_class == rule
    recommended = str(top["model"])
    if not agree and rule_best is not None:
        cv_top, cv_rule = float(top.get("cv_nrmse", np.nan)), float(rule_best.get("cv_nrmse", np.nan))
        d_aicc = float(rule_best["aicc"] - top["aicc"])
        if np.isfinite(cv_top) and np.isfinite(cv_rule):
            decisive = cv_top < decisive_cv_ratio * cv_rule
            margin = f"held-out NRMSE {cv_top:.3g} vs {cv_rule:.3g}, ΔAICc = {d_aicc:.1f}"
        else:
            decisive = d_aicc > STRONG_EVIDENCE
            margin = f"ΔAICc = {d_aicc:.1f}"
        if decisive:
            statement += f" The data say otherwise: {top['model']} is decisively better than {rule_best['model']} ({margin})."
        else:
            recommended = str(rule_best["model"])
            statement += (f" {top['model']} is not decisively better than {rule_best['model']} ({margin}): "
                          f"the rule's choice stands.")
    elif not agree:
        statement += f" No recommendable {rule.replace('_', ' ')} model was fitted in this scope: the data's choice is used."
    chosen = table[table["model"] == recommended].iloc[0]
    reason = (f"misfit {chosen['misfit_noise_units']:.3g} noise SDs, parameters determined, skill "
              f"{chosen['skill']:.3g}" if "determined" in table else "recommendable")
    return common | {"rule_model": None if rule_best is None else str(rule_best["model"]),
                     "data_model": str(top["model"]), "data_family": top_class, "agree": agree,
                     "recommended": recommended, "verdict": "supported", "verdict_reason": reason,
                     "statement": statement}


def rank_scope(candidates: Sequence[Candidate], curves: Sequence[Curve], target: str, scope: str,
               folds: Sequence[Fold] = (), dataset: str = "", noise: NoiseModel | None = None,
               n_random: int = 4, cv_random: int = 1, seed: int = 0, cv_top: int = 6,
               failures: dict | None = None, workers: int = 1, relaxation: str = "measured") -> tuple[pd.DataFrame, dict[str, FitResult], pd.DataFrame, dict]:
    """Fit, cross-validate and rank every candidate that can describe ``curves``.

    Cross-validation refits every fold, so it runs for the ``cv_top`` best models by AICc; the others are
    ranked after them by AICc (``rank_criterion`` says which). Candidates whose fit raised are recorded in
    ``failures`` (key -> message) when a dict is given. ``workers > 1`` runs the candidate fits and the
    cross-validations in that many processes (candidates must then be picklable, e.g. registry keys through
    :class:`RegistryFactory`).

    Returns ``(ranking table, fits by key, per-fold CV records, recommendation)``; the recommendation
    statement is also stored in the table's ``recommendation`` column, and the boolean ``recommended`` column
    is True for exactly one model of the scope (:func:`recommend`), or for none when no fit is recommendable
    (the statement says why).
    """
    failures = {} if failures is None else failures
    usable = [c for c in candidates if c.describes(curves)]
    fit_jobs = [(_fit_job, (cand, curves, target, scope, noise, n_random, seed, relaxation)) for cand in usable]
    fits, by_key = {}, {c.key: c for c in usable}
    for cand, outcome in zip(usable, _run_jobs(fit_jobs, workers)):
        if isinstance(outcome, str):  # recorded, never silently dropped
            failures[cand.key] = outcome
        else:
            fits[cand.key] = outcome
    cv_rows = []
    if folds and fits:
        # cross-validation (refits per fold) for the AICc short list only: it is the expensive part
        short = sorted(fits, key=lambda k: (not fits[k].success, fits[k].aicc))[:cv_top]
        cv_jobs = [(cross_validate, (by_key[k], curves, folds, target, noise, cv_random, seed, fits[k].params))
                   for k in short]
        for rows in _run_jobs(cv_jobs, workers):
            cv_rows += rows
    cv = pd.DataFrame(cv_rows)
    table = ranking_table(fits, cv, scope=scope, dataset=dataset)
    if not table.empty:
        table = add_assessment(table, {k: assess(by_key[k].factory(), r, curves, target) for k, r in fits.items()})
    rec = recommend(table, curves, noise)
    if not table.empty:
        # the one "best model of the scope": cards, FEM and diagnosis read this column
        table["recommendation"] = rec["statement"]
        table["recommended"] = table["model"] == rec["recommended"]
        table["verdict"] = rec.get("verdict", "no_model_supported")
        table["verdict_reason"] = rec.get("verdict_reason", "")
    return table, fits, cv, rec


def recommended_mask(ranking: pd.DataFrame, column: str = "recommended") -> np.ndarray:
    """The ``recommended`` (or another boolean) column of a ranking table as booleans (missing or empty -> False)."""
    if column not in ranking:
        return np.zeros(len(ranking), bool)
    col = ranking[column]
    if col.dtype != bool:  # read back with empty cells, or as text
        col = col.map(lambda v: str(v).strip().lower() in ("true", "1", "1.0"))
    return col.to_numpy(bool)


def scope_model(scope_ranking_csv, model: str) -> str:
    """The model key a rule's ``model`` wildcard names in one scope's ranking table (``ranking/<scope>.csv``):
    ``baseline`` -> the row with ``baseline`` true (the material scope's baseline, whose key the data decide;
    :func:`tissuemech.material.baseline_model`), any other name -> itself. A missing baseline returns
    ``"baseline"`` (no record of that name: the caller writes files that say so)."""
    if model != "baseline":
        return model
    table = pd.read_csv(scope_ranking_csv) if Path(scope_ranking_csv).stat().st_size > 0 else pd.DataFrame()
    chosen = table[recommended_mask(table, "baseline")] if not table.empty else table
    return str(chosen["model"].iloc[0]) if not chosen.empty else model


def recommended_models(ranking_csv, column: str = "recommended") -> dict[str, str]:
    """``{scope: model}`` of the rows that ``ranking.csv`` marks ``recommended`` (the ranking stage's one choice per
    scope, :func:`recommend`), or another boolean ``column`` (``baseline``: the material scope's baseline,
    :func:`tissuemech.material.baseline_model`); scopes without such a row are absent."""
    ranking = pd.read_csv(ranking_csv)
    if ranking.empty or not {"scope", "model"} <= set(ranking.columns):
        return {}
    rows = ranking[recommended_mask(ranking, column)]
    several = rows["scope"][rows["scope"].duplicated()].unique()
    if len(several):
        raise ValueError(f"{ranking_csv}: more than one {column} model in scope(s) {sorted(map(str, several))}")
    return {str(s): str(m) for s, m in zip(rows["scope"], rows["model"])}


def _fit_job(cand, curves, target, scope, noise, n_random, seed, relaxation="measured"):
    try:
        return fit_candidate(cand, curves, target, scope, noise, n_random=n_random, seed=seed, relaxation=relaxation)
    except (ValueError, RuntimeError) as exc:
        return f"{type(exc).__name__}: {exc}"


def _run_jobs(jobs, workers: int) -> list:
    """Run ``(function, args)`` jobs serially or in a process pool (results in job order)."""
    if workers <= 1 or len(jobs) <= 1:
        return [fn(*args) for fn, args in jobs]
    # fork keeps the compiled numba kernels of the parent; jobs are independent pure computations
    with ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("fork")) as pool:
        futures = [pool.submit(fn, *args) for fn, args in jobs]
        return [f.result() for f in futures]


def plot_ranking(table: pd.DataFrame, path=None, title: str | None = None):
    """The ranking figure: one pair of panels per scope, ΔAICc (log scale, +1) and held-out NRMSE per model, best
    first; the recommended model (column ``recommended``) is marked with a star and its name in bold, flagged fits
    are red. Returns the figure; writes it as PNG + SVG when ``path`` is given.

    ``table`` is one scope's ranking or ``ranking.csv`` (several scopes, in their order; a model named
    ``"<scope>: <model>"`` is shown as ``<model>`` in its scope's panel). The title names the dataset (column
    ``dataset``) unless ``title`` is given.
    """
    from matplotlib.figure import Figure

    table = table.dropna(subset=["model"]) if "model" in table else table
    scopes = list(dict.fromkeys(table["scope"].astype(str))) if "scope" in table and len(table) else [""]
    groups = [table[table["scope"].astype(str) == s] if s else table for s in scopes]
    heights = [max(len(g), 1) + 1.2 for g in groups]
    fig = Figure(figsize=(10, 0.32 * sum(heights) + 1.0), layout="constrained")
    grid = fig.add_gridspec(len(groups), 2, height_ratios=heights)
    recommended_label = False
    for row, (scope, group) in enumerate(zip(scopes, groups)):
        left, right = fig.add_subplot(grid[row, 0]), fig.add_subplot(grid[row, 1])
        names = [str(m).split(": ", 1)[1] if str(m).startswith(f"{scope}: ") else str(m) for m in group["model"]]
        chosen = (group["recommended"].fillna(False).astype(bool).to_numpy() if "recommended" in group
                  else np.zeros(len(group), bool))
        flagged = (pd.to_numeric(group["n_flags"], errors="coerce").fillna(0).to_numpy() > 0 if "n_flags" in group
                   else np.zeros(len(group), bool))
        y = np.arange(len(group))[::-1]
        colours = ["tab:red" if f else "tab:blue" for f in flagged]
        daicc = pd.to_numeric(group["delta_aicc"], errors="coerce").to_numpy(float) + 1.0 if "delta_aicc" in group \
            else np.full(len(group), np.nan)
        cvn = pd.to_numeric(group["cv_nrmse"], errors="coerce").to_numpy(float) if "cv_nrmse" in group \
            else np.full(len(group), np.nan)
        left.barh(y, np.where(np.isfinite(daicc), daicc, 0.0), color=colours)
        right.barh(y, np.nan_to_num(cvn), color=colours)
        for ax, values in ((left, daicc), (right, cvn)):
            for yi, v, c in zip(y, values, chosen):
                if c and np.isfinite(v):
                    ax.plot(v, yi, "*", color="gold", mec="k", ms=12, zorder=5)
                    recommended_label = True
            ax.set_ylim(-0.7, len(group) - 0.3)
        left.set_xscale("log")
        left.set_xlim(left=0.8)
        left.axvline(STRONG_EVIDENCE + 1, color="k", ls=":", lw=1)
        left.set_yticks(y, [f"★ {n}" if c else n for n, c in zip(names, chosen)], fontsize=8)
        for label, c in zip(left.get_yticklabels(), chosen):
            if c:
                label.set_fontweight("bold")
        right.set_yticks(y, [""] * len(y))
        if not np.isfinite(cvn).any():
            right.text(0.5, 0.5, "no held-out prediction in this scope", ha="center", va="center",
                       transform=right.transAxes, fontsize=8, color="0.4")
            right.set_xticks([])
        left.set_title(f"{scope}: ΔAICc + 1 (dotted: strong evidence)" if scope else "ΔAICc + 1", fontsize=9)
        right.set_title(f"{scope}: held-out NRMSE (cross-validation)" if scope else "held-out NRMSE", fontsize=9)
        if row == len(groups) - 1:
            left.set_xlabel("ΔAICc + 1")
            right.set_xlabel("held-out NRMSE")
    dataset = str(table["dataset"].iloc[0]) if "dataset" in table and len(table) else ""
    heading = title or (f"model ranking of {dataset}, every scope" if dataset else "model ranking")
    fig.suptitle(heading + " (red: flagged fit" + ("; ★ recommended" if recommended_label else "") + ")",
                 fontsize=11)
    if path is not None:
        save_figure(fig, path, dpi=110)  # PNG and SVG side by side
    return fig


__all__ = ["Fold", "Candidate", "leave_one_condition_out", "train_on_tests", "leave_one_specimen_out",
           "fit_candidate", "cross_validate", "paired_comparison", "ranking_table", "rate_dependence",
           "time_dependence", "RegistryFactory",
           "thesis_rule", "recommend", "rank_scope", "recommended_mask", "recommended_models", "plot_ranking",
           "LINEAR_STRAIN_LIMIT"]
