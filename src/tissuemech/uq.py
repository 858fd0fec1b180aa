"""Uncertainty of the recommended fits (issue 16): posteriors of the fitted parameters.

``run_posterior`` (the pipeline's rule ``posterior``) rebuilds the fit problem of a scope's recommended model
from ``averages.nc`` and its fit record (the same curves, plate target, noise model and bounds that
``stages.run_fit_scope`` fitted; the rebuilt chi-square equals the record's), and samples its posterior with
:func:`tissuemech.posterior.sample_posterior`:

* sampled space: the fit's internal parameters (``log10`` of moduli and times, as lmfit fitted them);
* priors: independent uniform priors on the fit bounds in that space (log-uniform for the ``log10`` ones), stated
  per parameter in the output;
* likelihood: Gaussian in the weighted residuals with ``s2`` = the fit's reduced chi-square (lmfit's covariance
  scaling), so a near-Gaussian posterior has the lmfit standard errors as its spread;
* start and burn-in proposal: the Laplace approximation (lmfit's covariance).

Outputs, one pair per sampled fit (config ``posterior.models``; empty: every model the scope fits, so the QLV and
the beyond-QLV fits of the joint scope both, and always the recommended one): ``posterior/<scope>/<model>.nc`` in
ArviZ's InferenceData group layout (groups ``posterior`` with one variable per parameter in natural units, dims
``chain``/``draw``, ``sample_stats`` with ``lp``, ``posterior_predictive`` with the model responses of 64 draws at
the fitted points and ``observed_data``; written with xarray and netCDF4) whose ``posterior`` attributes carry
R-hat, ESS, acceptance, the warnings, priors and likelihood; ``posterior/<scope>/<model>.csv``: per parameter the
lmfit value and standard error next to the 5/50/95 % posterior quantiles and the ratio of the 90 % credible width
to the lmfit interval. The sampling does not read the ranking, so ``fits.csv`` (written after the posteriors by
:func:`tissuemech.stages.write_fits_table`) carries the credible intervals next to the standard errors without a
cycle in the workflow; the FEM bands below read the posterior of the recommended model.

Specimen variability (``run_population``, rule ``population``): every run of the scope's tests is one loaded piece
(a sample cut from a specimen). Its *level* is the factor ``s`` that scales the recommended fit's prediction onto
the run (``log s`` = weighted mean of ``log(observed / predicted)`` over the run's unflagged points, the run's own
strain history and plate geometry); for the QLV and hyperelastic laws a common factor on the moduli scales the
stress exactly, so ``log G0_piece = log G0_fit + log s`` is the piece's log initial shear modulus. A linear
mixed-effects model (:func:`tissuemech.stats.mixed_effects`: statsmodels ``MixedLM``, REML)
``log G0 = mu + b_specimen + e`` with a specimen random intercept (``b ~ N(0, sd_specimen^2)``) and, when a piece
has several runs, a sample variance component nested in the specimen, gives the population mean ``mu`` and the SDs
with standard errors (``MixedLM``'s covariance of the variance parameters, times the residual scale; ``sqrt(2/df)``
for the residual variance; the delta method for the SDs). With one run per piece the residual SD *is* the
sample-to-sample SD (it also holds the within-run misfit; stated in the output). The JSON written next to the card
carries that population distribution.

Propagation to the FEM (``run_uq_indentation`` / ``run_uq_torsion``, rules ``uq_indentation`` / ``uq_torsion``,
both through ``propagate``): the flat-punch indentation of ``fem.experiments.flat_punch_indentation`` (small mesh,
few increments), or the rheometer torsion of ``fem.experiments.rheometer_torsion``, is run for the elastic law of the
recommended fit at the optimum and at ``n_draws`` posterior draws (*measurement* uncertainty: the fit's parameters
given the averaged curves); *specimen* variability is the population distribution of the modulus level,
``log s ~ N(mu - log G0_fit, sd_specimen^2 + sd_sample^2)``, and because the bulk modulus follows the shear
modulus through the card's Poisson ratio, a factor ``s`` on every modulus scales the quasi-static force exactly by
``s`` (same displacement field), so the population band needs no further solve. The *total* band multiplies
independent posterior and population draws. The elastic law is the card's, or, for a fit whose card has none
(the beyond-QLV laws), the instantaneous law of its structure, with the Prony series of the draw's small-strain step
response (for a beyond-QLV law the QLV linearisation: its strain-dependent weights are not in the FEM).
"""
from __future__ import annotations

import datetime as _dt
import json
import logging
import math
import time
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pandas as pd
import xarray as xr

from . import fitting as F
from . import posterior as P
from . import ranking as R
from .cards import (family_material, fitted_strain_max, is_pipkin_rogers, material_fields, pipkin_rogers_block,
                    prony_from_step_response)
from .canonical import NETCDF_ENGINE, atomic_write, read_netcdf, write_json, write_netcdf, write_text
from .curves import drop_flagged, select_average
from .models.base import initial_shear_modulus
from .fem.experiments import brain_indentation, flat_punch_indentation, rheometer_torsion
from .fem.tled import DynamicRelaxationError, ElementInversionError
from .models.registry import build_model, get_model
from .pipeline import load_runs
from .plots import new_figure, save_figure
from .records import SIMULATION_CARDS_INDEX, MaterialCard
from .stats import mixed_effects
from .stages import spec_curves

logger = logging.getLogger(__name__)

#: standard normal quantile of the 95 % point (a 5-95 % interval is +- this many SD for a Gaussian)
Z95 = 1.6448536269514722
#: groups of the InferenceData file, in the order written
IDATA_GROUPS = ("posterior", "posterior_predictive", "sample_stats", "observed_data")


def problem_for_record(averages: xr.Dataset, record: F.FitRecord, spec) -> F.FitProblem:
    """The fit problem a record came from: the scope's curves (``stages.spec_curves`` of the scope's spec or test
    kinds), its plate target, relaxation treatment and the record's model (``models.registry.build_model``: the
    registered model, or a fixed-time QLV on the record's relaxation times) with its default bounds and noise
    model."""
    curves = spec_curves(averages, spec, relaxation=record.relaxation or "measured")
    return F.FitProblem(model=build_model(record.model_key, record.structure), curves=list(curves), target=record.target,
                        model_key=record.model_key, scope=record.scope, relaxation=record.relaxation or "measured")


def internal_covariance(problem: F.FitProblem, record: F.FitRecord, internal: list[str]) -> np.ndarray | None:
    """lmfit's covariance of the varying internal parameters, rebuilt from the record's standard errors (natural
    units, delta method undone for ``log10`` parameters) and correlation matrix; None where not finite."""
    names = list(record.params)
    se, idx = [], []
    for n in internal:
        nat = n.removeprefix("log10_")
        s = float(record.stderr.get(nat, np.nan))
        if n.startswith("log10_"):
            s = s / (math.log(10.0) * float(record.params[nat]))
        se.append(s)
        idx.append(names.index(nat))
    se = np.asarray(se)
    corr = np.asarray(record.correlation, float)
    if corr.shape != (len(names), len(names)) or not np.all(np.isfinite(se)):
        return None
    c = corr[np.ix_(idx, idx)]
    return c * np.outer(se, se) if np.all(np.isfinite(c)) else None


def sample_record_posterior(problem: F.FitProblem, record: F.FitRecord, walkers: int | None = None,
                            steps: int = 800, burn: int = 150, seed: int = 0) -> tuple[P.PosteriorResult, dict]:
    """Sample the posterior of a fit record's varying parameters (module docstring).

    ``walkers`` None: ``max(16, 2 k + 2)`` for ``k`` varying parameters. Returns the result (in the internal,
    sampled space) and a dict of what was done (``internal`` names, ``noise_variance``, ``walkers``, ``seconds``,
    ``seconds_per_evaluation``).
    """
    pars = problem.make_params(record.params)
    internal = [n for n in pars if pars[n].vary]
    x0 = {n: float(pars[n].value) for n in internal}
    bounds = {n: (float(pars[n].min), float(pars[n].max)) for n in internal}

    def residual(theta):
        for n, v in zip(internal, theta):
            pars[n].value = float(v)
        return problem.residual(pars)

    r0 = residual(np.array(list(x0.values())))  # the first call compiles the numba kernels
    t0 = time.perf_counter()
    for _ in range(5):
        residual(np.array(list(x0.values())))
    t_eval = (time.perf_counter() - t0) / 5
    s2 = float(record.redchi) if np.isfinite(record.redchi) and record.redchi > 0 else float(r0 @ r0) / max(
        r0.size - len(internal), 1)
    k = len(internal)
    walkers = int(walkers) if walkers else max(16, 2 * k + 2)
    cov = internal_covariance(problem, record, internal)
    t0 = time.perf_counter()
    post = P.sample_posterior(residual, x0, bounds, noise_variance=s2, n_walkers=walkers, n_steps=int(steps),
                              burn=int(burn), seed=int(seed), cov=cov)
    seconds = time.perf_counter() - t0
    info = {"internal": internal, "noise_variance": s2, "walkers": walkers, "steps": int(steps), "burn": int(burn),
            "seed": int(seed), "seconds": seconds, "seconds_per_evaluation": t_eval,
            "laplace_start": cov is not None}
    return post, info


def _natural(name: str, x: np.ndarray) -> np.ndarray:
    return 10.0 ** x if name.startswith("log10_") else x


def posterior_table(record: F.FitRecord, post: P.PosteriorResult, dataset: str = "", scope: str = "") -> pd.DataFrame:
    """Per varying parameter: lmfit value and standard error next to the posterior 5/50/95 % quantiles (natural
    units), posterior mean and SD, the ratio of the 90 % credible width to lmfit's ``2 z95 se`` in the sampled space
    (1 for a Gaussian posterior that matches lmfit), R-hat, ESS, the prior and the sampled coordinate."""
    rows = []
    for i, n in enumerate(post.names):
        nat = n.removeprefix("log10_")
        x = post.samples[:, i]
        v = _natural(n, x)
        q05, q50, q95 = np.quantile(v, [0.05, 0.5, 0.95])
        se = float(record.stderr.get(nat, np.nan))
        se_int = se / (math.log(10.0) * float(record.params[nat])) if n.startswith("log10_") else se
        lo, hi = np.quantile(x, [0.05, 0.95])
        rows.append({"dataset": dataset, "scope": scope, "model": record.model_key, "parameter": nat,
                     "unit": record.units.get(nat, ""), "sampled_as": "log10" if n.startswith("log10_") else "linear",
                     "value": float(record.params[nat]), "stderr": se, "ci05": float(q05), "ci50": float(q50),
                     "ci95": float(q95), "post_mean": float(v.mean()), "post_sd": float(v.std(ddof=1)),
                     "ci90_over_lmfit": float((hi - lo) / (2 * Z95 * se_int)) if se_int > 0 else float("nan"),
                     "rhat": post.rhat[n], "ess": post.ess[n], "tau": post.tau[n], "prior": post.priors[n]})
    return pd.DataFrame(rows)


def inference_data(record: F.FitRecord, post: P.PosteriorResult, info: Mapping, dataset: str = "",
                   scope: str = "") -> dict[str, xr.Dataset]:
    """ArviZ InferenceData groups (``posterior``, ``sample_stats``) as xarray Datasets; diagnostics, priors,
    likelihood and warnings in the ``posterior`` group's attributes (JSON strings for mappings)."""
    n_chain, n_draw = post.chain.shape[:2]
    coords = {"chain": np.arange(n_chain), "draw": np.arange(n_draw)}
    variables = {}
    for i, n in enumerate(post.names):
        nat = n.removeprefix("log10_")
        variables[nat] = xr.DataArray(_natural(n, post.chain[:, :, i]), dims=("chain", "draw"),
                                      attrs={"units": record.units.get(nat, ""), "prior": post.priors[n],
                                             "sampled_as": "log10" if n.startswith("log10_") else "linear",
                                             "lmfit_value": float(record.params[nat]),
                                             "lmfit_stderr": float(record.stderr.get(nat, np.nan))})
    created = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    common = {"created_at": created, "inference_library": "emcee",
              "inference_library_version": str(getattr(P.emcee, "__version__", "")), "dataset": dataset,
              "scope": scope, "model": record.model_key}
    attrs = dict(common)
    attrs.update({
        "rhat": json.dumps({n.removeprefix("log10_"): v for n, v in post.rhat.items()}),
        "ess": json.dumps({n.removeprefix("log10_"): v for n, v in post.ess.items()}),
        "tau": json.dumps({n.removeprefix("log10_"): v for n, v in post.tau.items()}),
        "acceptance": post.acceptance,
        "warnings": json.dumps(post.warnings),
        "priors": json.dumps({n.removeprefix("log10_"): f"{post.priors[n]} in {n}" for n in post.names}),
        "likelihood": post.likelihood,
        "fixed_parameters": json.dumps({k: v for k, v in record.params.items() if k not in record.varying}),
        "walkers": int(info["walkers"]), "steps": int(info["steps"]), "burn": int(info["burn"]),
        "seed": int(info["seed"]), "sampling_seconds": float(info["seconds"]),
        "seconds_per_evaluation": float(info["seconds_per_evaluation"]),
        "start": "Laplace approximation (lmfit covariance)" if info.get("laplace_start") else "ball at the optimum",
        "rhat_max": P.RHAT_MAX, "ess_min": P.ESS_MIN,
    })
    posterior = xr.Dataset(variables, coords=coords, attrs=attrs)
    stats = xr.Dataset({"lp": xr.DataArray(post.log_prob, dims=("chain", "draw"))}, coords=coords, attrs=common)
    return {"posterior": posterior, "sample_stats": stats}


def write_inference_data(groups: Mapping[str, xr.Dataset], path) -> Path:
    """Write InferenceData groups into one netCDF4 file (one HDF5 group per InferenceData group), atomically."""
    def writer(tmp):
        mode = "w"
        for name in IDATA_GROUPS:
            if name in groups:
                groups[name].to_netcdf(tmp, group=name, mode=mode, engine=NETCDF_ENGINE)
                mode = "a"
        if mode == "w":  # nothing sampled: an empty file that still states why (root attributes)
            xr.Dataset(attrs=dict(groups.get("", xr.Dataset()).attrs)).to_netcdf(tmp, mode="w", engine=NETCDF_ENGINE)
    return atomic_write(path, writer)


def read_inference_group(path, group: str = "posterior") -> xr.Dataset:
    """One group of an InferenceData netCDF file, loaded into memory."""
    with xr.open_dataset(path, group=group, engine=NETCDF_ENGINE) as ds:
        return ds.load()


#: posterior draws whose predictions make the posterior-predictive band
N_PREDICTIVE = 64


def predictive_draws(problem: F.FitProblem, record: F.FitRecord, post: P.PosteriorResult,
                     n_draws: int = N_PREDICTIVE, seed: int = 0) -> list[dict[str, np.ndarray]]:
    """Model predictions of ``n_draws`` posterior draws per curve and observable: a list (one per curve) of
    ``{observable: array (n_draws, n_points)}`` (the posterior-predictive mean response; the noise model's spread
    is not added)."""
    rng = np.random.default_rng(seed)
    picks = rng.choice(post.samples.shape[0], size=min(n_draws, post.samples.shape[0]), replace=False)
    out: list[dict[str, list]] = [{} for _ in problem.curves]
    for k in picks:
        p = dict(record.params)
        p.update({n.removeprefix("log10_"): float(_natural(n, post.samples[k, i])) for i, n in enumerate(post.names)})
        for ci, terms in enumerate(problem.curve_terms(p)):
            for name, (_, f, _) in terms.items():
                out[ci].setdefault(name, []).append(np.asarray(f, float))
    return [{name: np.array(v) for name, v in d.items()} for d in out]


def predictive_band(idata_path) -> dict[str, np.ndarray] | None:
    """5/50/95 % quantiles per fitted point of the ``posterior_predictive`` group of a posterior file (points in
    the fit record's order: curve by curve, observable by observable); None for a file without that group (a
    model that was not sampled)."""
    try:
        pp = read_inference_group(idata_path, "posterior_predictive")
    except (OSError, KeyError, ValueError):
        return None
    draws = np.asarray(pp["response"].values, float)
    return band(draws.reshape(-1, draws.shape[-1]))


def run_posterior(averages_path, fits_dir, scope: str, model: str, tests, out_nc, out_csv, walkers=None,
                  steps: int = 800, burn: int = 150, seed: int = 0, dataset: str = "") -> pd.DataFrame:
    """Posterior of the fit record ``<fits_dir>/<model>.nc`` of one scope: the InferenceData netCDF (with the
    model responses of :data:`N_PREDICTIVE` posterior draws in its ``posterior_predictive`` group, aligned with the
    record's points) and the credible-interval table (module docstring). A model without a fit record writes a file
    whose root attribute ``status`` says so, and an empty table. The table is the source of the credible-interval
    columns of ``fits.csv`` (:func:`tissuemech.stages.write_fits_table`); the posterior-predictive band is drawn
    into the fit figure by :func:`tissuemech.summary.plot_posterior_fit`."""
    path = Path(fits_dir) / f"{model}.nc"
    if not path.is_file():
        write_inference_data({"": xr.Dataset(attrs={"status": f"no fit record of {model} in scope {scope}"})}, out_nc)
        table = pd.DataFrame(columns=["dataset", "scope", "model", "parameter"])
        write_text(table.to_csv(index=False), out_csv)
        return table
    record = F.FitRecord.from_netcdf(path)
    problem = problem_for_record(read_netcdf(averages_path), record, tests)
    post, info = sample_record_posterior(problem, record, walkers=walkers, steps=steps, burn=burn, seed=seed)
    groups = inference_data(record, post, info, dataset=dataset, scope=scope)
    predictions = predictive_draws(problem, record, post, seed=seed)
    flat = np.concatenate([np.concatenate([v for v in d.values()], axis=1) for d in predictions], axis=1)
    observed = np.concatenate([np.asarray(y, float) for obs, _ in problem.observations for y in obs.values()])
    groups["posterior_predictive"] = xr.Dataset(
        {"response": (("chain", "draw", "point"), flat[None], {"meaning": "model response of posterior draws "
                                                                         "(plate target), noise not added; points "
                                                                         "in the fit record's order"})},
        coords={"chain": [0], "draw": np.arange(flat.shape[0])})
    groups["observed_data"] = xr.Dataset({"response": ("point", observed)})
    write_inference_data(groups, out_nc)
    table = posterior_table(record, post, dataset=dataset, scope=scope)
    table["acceptance"] = post.acceptance
    table["warnings"] = "; ".join(post.warnings)
    write_text(table.to_csv(index=False), out_csv)
    return table


# ------------------------------------------------------------------------------------------------------
# specimen variability: per-piece levels and the mixed-effects model (tissuemech.stats.mixed_effects)
# ------------------------------------------------------------------------------------------------------
def reference_shear_modulus(model, params: Mapping[str, float]) -> float:
    """Initial shear modulus of a fitted model (Pa): ``models.base.initial_shear_modulus``, the one rule (the
    elastic law's small-strain tangent, or a linear viscoelastic model's relaxation modulus at t = 0); NaN where
    neither is defined. ``model``: the model or its registry key."""
    return float(initial_shear_modulus(get_model(model) if isinstance(model, str) else model, params))


def piece_levels(runs, record: F.FitRecord, tests, exclude_flagged: bool = True) -> pd.DataFrame:
    """One row per run of ``tests``: specimen, sample, test, condition, ``log_level`` (natural log of the factor
    that scales the fit's prediction onto the run; module docstring), ``log_g0`` and the points used."""
    model = build_model(record.model_key, record.structure)
    g0 = reference_shear_modulus(model, record.params)
    noise = F.NoiseModel()
    rows = []
    for run in runs:
        test = str(run.attrs.get("test", ""))
        if test not in tests:
            continue
        run = drop_flagged(run) if exclude_flagged else run
        try:
            curve = F.thin(F.curve_from_run(run, relaxation=record.relaxation or "measured"), 40)
            obs, sd = F.target_observations(curve, record.target)
            pred = F.predict(model, record.params, curve, record.target)
        except (ValueError, KeyError) as exc:
            rows.append({"run": run.attrs.get("run", ""), "test": test, "status": f"skipped: {exc}"})
            continue
        logs, weights = [], []
        for k, y in obs.items():
            y, f = np.asarray(y, float), np.asarray(pred[k], float)
            sig = noise.sigma(k, y, sd.get(k))
            ok = np.isfinite(y) & np.isfinite(f) & (y > 0) & (f > 0) & (np.abs(y) > 3 * sig)
            logs.append(np.log(y[ok] / f[ok]))
            weights.append((np.abs(y[ok]) / sig[ok]) ** 2)  # 1 / var(log y)
        lr, w = np.concatenate(logs), np.concatenate(weights)
        level = float(np.sum(w * lr) / np.sum(w)) if lr.size else float("nan")
        rows.append({"run": str(run.attrs.get("run", "")), "specimen": str(run.attrs.get("specimen", "")),
                     "sample": str(run.attrs.get("sample", "")), "test": test, "condition": curve.condition,
                     "n_points": int(lr.size), "log_level": level, "log_g0": math.log(g0) + level if g0 > 0 else
                     float("nan"), "status": "ok" if lr.size else "no usable point"})
    return pd.DataFrame(rows)


def run_population(ranking_csv, runs_dir, fits_dir, cards_dir, scope: str, tests, out_json, out_csv,
                   dataset: str = "", exclude_flagged: bool = True) -> dict:
    """Specimen variability of the recommended fit of one scope: per-run levels (``out_csv``) and the mixed
    model, written with the recommended card into ``out_json`` (the card with ``uncertainty.population``)."""
    model = R.recommended_models(ranking_csv).get(scope)
    if model is None:
        write_text("run,specimen,sample,test,log_level,log_g0,status\n", out_csv)
        write_json({"status": f"no recommended model in scope {scope}"}, out_json)
        return {}
    record = F.FitRecord.from_netcdf(Path(fits_dir) / f"{model}.nc")
    levels = piece_levels(load_runs(runs_dir), record, list(tests), exclude_flagged=exclude_flagged)
    write_text(levels.to_csv(index=False), out_csv)
    ok = levels[levels.get("status", pd.Series(dtype=str)) == "ok"] if not levels.empty else levels
    g0 = reference_shear_modulus(build_model(record.model_key, record.structure), record.params)
    value = "log_g0" if g0 > 0 else "log_level"
    pop = {"status": "no run of the scope's tests"}
    if not ok.empty:  # the population JSON holds the model's counts, mean and SDs (not the diagnosis's BLUPs / ICC)
        pop = {k: v for k, v in mixed_effects(ok, value).items() if k not in ("blup_z", "icc")}
    pop.update({"model": model, "scope": scope, "dataset": dataset, "reference_shear_modulus_pa": g0,
                "quantity": ("natural log of the initial shear modulus (Pa) per loaded piece" if value == "log_g0"
                             else "natural log of the level factor on the fit's stress per loaded piece"),
                "by_test_mean": {str(t): float(v) for t, v in ok.groupby("test")[value].mean().items()}
                if not ok.empty else {}})
    card_path = Path(cards_dir) / f"{model}.json"
    card = dict(MaterialCard.from_json(card_path).data) if card_path.is_file() else {"model": model}
    unc = card.get("uncertainty")
    unc = dict(unc) if isinstance(unc, Mapping) else {"lmfit": unc}
    unc["population"] = pop
    card["uncertainty"] = unc
    card["card_source"] = str(card_path)
    write_json(card, out_json)
    return pop


# ------------------------------------------------------------------------------------------------------
# propagation to the FEM: indentation bands from posterior and population draws
# ------------------------------------------------------------------------------------------------------
def elastic_card(card: Mapping, record: F.FitRecord, params: Mapping[str, float]) -> dict | None:
    """A FEM card of the fit's elastic law at ``params``: the card's ``elastic_law`` or, without one, the
    instantaneous law of the record's structure; for QLV and beyond-QLV fits the Prony series of the small-strain
    step response at ``params`` (exact for QLV; for a beyond-QLV law its small-strain linearisation), for a
    Pipkin-Rogers fit its card's own material at ``params`` (small-strain Prony series and the ``pipkin_rogers``
    weight law, which the FEM runs: ``cards.pipkin_rogers_block``). The material
    fields (moduli, bulk modulus from the card's Poisson ratio, Prony normalisation) are assembled by
    :func:`tissuemech.cards.material_fields`, as in the fit's own card. None where the law has no parameters among
    ``params``."""
    law = card.get("elastic_law") or (record.structure or {}).get("instantaneous")
    if not law:
        return None
    law = get_model(law)
    names = [sp.name for sp in law.param_specs]
    if not all(n in params for n in names):
        return None
    prony, pr = None, None
    taus = (record.structure or {}).get("taus_s")
    model = build_model(record.model_key, record.structure)
    if is_pipkin_rogers(model) and all(n in params for n in model.param_names):
        _, _, prony, _ = family_material(model, params, {})
        pr = pipkin_rogers_block(model, params)
    elif record.family in ("qlv", "beyond_qlv") and taus:
        # the small-strain Prony series of the draw (exact for QLV; the small-strain linearisation of another
        # beyond-QLV law, which the FEM does not have)
        taus = np.asarray(taus, float)
        step = prony_from_step_response(model, params, taus, taus.min() / 10, taus.max() * 10)
        prony = {"g": step["g"], "tau": step["tau"], "g_inf": step["g_inf"],
                 "source": "small-strain step response of the fit (tissuemech.uq)"}
    fields, _, _ = material_fields(law, {n: float(params[n]) for n in names}, float(card["poisson_ratio"]), prony,
                                   fitted_strain_max(card.get("validity") or {}), pr)
    out = {k: v for k, v in card.items() if k not in fields}
    out.update(fields)
    return out


def band(values: np.ndarray) -> dict[str, np.ndarray]:
    """5/50/95 % quantiles over axis 0 (draws), NaN-aware."""
    q = np.nanquantile(np.asarray(values, float), [0.05, 0.5, 0.95], axis=0)
    return {"q05": q[0], "q50": q[1], "q95": q[2]}


def recommended_posterior(posterior_ncs, model: str) -> Path:
    """The posterior file of ``model`` among a scope's posterior files (``posterior/<scope>/<model>.nc``); a clear
    error when the recommended model was not sampled (config ``posterior.models`` left it out)."""
    paths = {Path(p).stem: Path(p) for p in ([posterior_ncs] if isinstance(posterior_ncs, (str, Path))
                                             else posterior_ncs)}
    if model not in paths and "baseline" in paths and paths["baseline"].is_file():
        # the material scope samples its baseline, a file named after the role, not the data-chosen key
        if read_inference_group(paths["baseline"], "posterior").attrs.get("model") == model:
            return paths["baseline"]
    if model not in paths:
        raise FileNotFoundError(f"the recommended model {model} has no posterior (sampled: {sorted(paths)}); "
                                "add it to config posterior.models or leave that list empty")
    return paths[model]


def _load_uq_inputs(posterior_ncs, population_json, fits_dir):
    """The population card, its population dict, the recommended model's posterior group and the fit record."""
    card = MaterialCard.from_json(population_json).data
    unc = card.get("uncertainty")
    pop = unc.get("population", {}) if isinstance(unc, Mapping) else {}
    post = read_inference_group(recommended_posterior(posterior_ncs, str(pop.get("model", card.get("model")))),
                                "posterior")
    record = F.FitRecord.from_netcdf(Path(fits_dir) / f"{post.attrs['model']}.nc")
    if elastic_card(card, record, record.params) is None:
        raise ValueError(f"{record.model_key}: no elastic law the FEM can run")
    return card, pop, post, record


def propagate(solve, card: Mapping, pop: Mapping, post: xr.Dataset, record: F.FitRecord, n_draws: int,
              seed: int = 0, solve_draw=None) -> dict:
    """Run ``solve(card) -> (x, y)`` at the optimum and at ``n_draws`` posterior draws; population draws scale the
    optimum response (module docstring). ``solve_draw`` (optional, e.g. a coarser mesh) solves the draws instead:
    each draw's response is multiplied by ``solve(optimum) / solve_draw(optimum)`` point by point, so the
    discretisation error of the cheap solve cancels to first order. Returns ``x``, ``optimum``, ``measurement``,
    ``specimen``, ``total`` (draws x points), ``failed`` (messages), ``population_log_sd``/``offset``, ``measurement_share`` (of the variance of
    log y at the last point) and ``seconds``."""
    t0 = time.perf_counter()
    x, y_opt = solve(elastic_card(card, record, record.params))
    ratio = 1.0
    if solve_draw is not None:
        ratio = y_opt / solve_draw(elastic_card(card, record, record.params))[1]
    else:
        solve_draw = solve
    rng = np.random.default_rng(seed)
    flat = {n: np.asarray(post[n].values, float).ravel() for n in post.data_vars}
    picks = rng.choice(next(iter(flat.values())).size, size=n_draws, replace=False)
    meas = np.full((n_draws, np.size(x)), np.nan)
    failed = []
    for row, k in enumerate(picks):
        params = dict(record.params)
        params.update({n: float(v[k]) for n, v in flat.items()})
        try:
            meas[row] = ratio * solve_draw(elastic_card(card, record, params))[1]
        except (ElementInversionError, DynamicRelaxationError) as exc:  # a NaN row, reported
            failed.append(f"draw {k}: {exc}")
            logger.warning("uq FEM: draw %d failed: %s", k, exc)
    g0_fit = reference_shear_modulus(build_model(record.model_key, record.structure), record.params)
    sd_pop = math.hypot(float(pop.get("sd_specimen", 0.0)), float(pop.get("sd_sample", 0.0)))
    offset = float(pop["mean"]) - math.log(g0_fit) if pop.get("value") == "log_g0" and "mean" in pop else 0.0
    factor = np.exp(offset + sd_pop * rng.standard_normal(n_draws))
    spec, total = factor[:, None] * y_opt[None, :], factor[:, None] * meas
    vm, vs = np.nanvar(np.log(np.abs(meas[:, -1]))), np.nanvar(np.log(np.abs(spec[:, -1])))
    return {"x": np.asarray(x, float), "optimum": np.asarray(y_opt, float), "measurement": meas, "specimen": spec,
            "total": total, "failed": failed, "population_log_sd": sd_pop, "population_log_offset": offset,
            "var_log_measurement": float(vm), "var_log_specimen": float(vs),
            "measurement_share": float(vm / (vm + vs)) if vm + vs > 0 else float("nan"),
            "seconds": time.perf_counter() - t0}


SOURCES = ("measurement", "specimen", "total")


def bands_dataset(res: Mapping, x_name: str, x_units: str, y_name: str, y_units: str, attrs: Mapping) -> xr.Dataset:
    """The draws and 5/50/95 % bands per source of :func:`propagate` as a Dataset (dims ``draw``, ``point``)."""
    data = {f"{y_name}_optimum": ("point", res["optimum"], {"units": y_units})}
    for src in SOURCES:
        data[f"{y_name}_{src}"] = (("draw", "point"), res[src], {"units": y_units})
        for q, v in band(res[src]).items():
            data[f"{src}_{q}"] = ("point", v, {"units": y_units})
    return xr.Dataset(data, coords={x_name: ("point", res["x"], {"units": x_units}),
                                    "draw": np.arange(res["measurement"].shape[0])},
                      attrs={**attrs, "population_log_sd": res["population_log_sd"],
                             "population_log_offset": res["population_log_offset"],
                             "var_log_measurement": res["var_log_measurement"],
                             "var_log_specimen": res["var_log_specimen"],
                             "measurement_share_of_variance": res["measurement_share"],
                             "seconds": res["seconds"], "failed_draws": json.dumps(res["failed"]),
                             "method": "posterior draws solved one by one; specimen band = population factor x "
                                       "optimum response (exact: the bulk modulus follows mu through the Poisson "
                                       "ratio and the relative Prony weights are unchanged, so every stress scales "
                                       "with the factor)"})


def plot_bands(ds: xr.Dataset, path, x_name: str, y_name: str, x_scale: float, y_scale: float, xlabel: str,
               ylabel: str, title: str, reference: tuple[np.ndarray, np.ndarray] | None = None,
               reference_label: str = "") -> list[Path]:
    """5-95 % bands of the three sources with the optimum (and an optional measured reference curve)."""
    fig, (ax,) = new_figure()
    x = x_scale * np.asarray(ds[x_name].values)
    styles = (("total", "0.75", 0.6), ("specimen", "tab:orange", 0.45), ("measurement", "tab:blue", 0.7))
    for src, colour, alpha in styles:
        ax.fill_between(x, y_scale * ds[f"{src}_q05"].values, y_scale * ds[f"{src}_q95"].values, color=colour,
                        alpha=alpha, lw=0, label=f"{src} 5-95 %")
    ax.plot(x, y_scale * ds[f"{y_name}_optimum"].values, "k-", lw=1.2, label="fit optimum")
    if reference is not None:
        ax.plot(x_scale * reference[0], y_scale * reference[1], "ko", ms=3, mfc="none", label=reference_label)
    share = ds.attrs.get("measurement_share_of_variance", float("nan"))
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(f"{title}, measurement share {100 * share:.0f} %", fontsize=9)
    ax.legend(fontsize=8, loc="upper left")
    return save_figure(fig, path)


def run_uq_indentation(posterior_ncs, population_json, fits_dir, out_nc, figure_path, n_draws: int = 32,
                       punch_diameter_m: float = 8e-3, max_depth_m: float = 1.5e-3, speed_m_s: float = 1e-4,
                       element_size_m: float = 2e-3, n_increments: int = 6, seed: int = 0,
                       n_threads: int = 1) -> xr.Dataset:
    """Force-depth bands of the flat-punch indentation (module docstring): netCDF with the draws and the 5/50/95 %
    bands per source (``measurement``, ``specimen``, ``total``) and a figure."""
    card, pop, post, record = _load_uq_inputs(posterior_ncs, population_json, fits_dir)

    def solve(c):
        ds = flat_punch_indentation(c, punch_diameter_m, max_depth_m, speed_m_s, element_size_m=element_size_m,
                                    n_increments=n_increments, n_threads=n_threads)
        return np.asarray(ds["displacement"].values, float), np.asarray(ds["force"].values, float)

    res = propagate(solve, card, pop, post, record, n_draws, seed)
    ds = bands_dataset(res, "depth", "m", "force", "N",
                       {"experiment": "flat-punch indentation", "model": record.model_key,
                        "elastic_law": elastic_card(card, record, record.params)["elastic_law"],
                        "punch_diameter_m": punch_diameter_m, "max_depth_m": max_depth_m, "speed_m_s": speed_m_s,
                        "element_size_m": element_size_m, "n_increments": n_increments, "n_draws": n_draws,
                        "seed": seed})
    write_netcdf(ds, out_nc)
    plot_bands(ds, figure_path, "depth", "force", 1e3, 1e3, "indentation depth [mm]", "force [mN]",
               f"{record.model_key}: {punch_diameter_m * 1e3:g} mm punch")
    return ds


def run_uq_torsion(posterior_ncs, population_json, fits_dir, averages_path, out_nc, figure_path, n_draws: int = 32,
                   n_points: int = 8, element_size_m: float = 1.5e-3, draw_element_size_m: float = 2.5e-3,
                   seed: int = 0, n_threads: int = 1) -> xr.Dataset:
    """Torque-rim strain bands of the rheometer torsion at the dataset's fastest constant shear rate (the plate
    geometry and the measured mean torque of that rate from ``averages.nc``), as :func:`run_uq_indentation`. The
    optimum is solved on the ``element_size_m`` mesh (the pipeline's torsion mesh), the draws on the coarser
    ``draw_element_size_m`` mesh corrected point by point by the optimum's fine/coarse ratio (:func:`propagate`;
    on the bundled brain the coarse mesh alone is 3 % stiffer and 3.5 times cheaper)."""
    card, pop, post, record = _load_uq_inputs(posterior_ncs, population_json, fits_dir)
    avg = read_netcdf(averages_path)
    idx = [i for i, t in enumerate(avg["test"].values) if str(t) == "constant_shear_rate"]
    if not idx:
        raise ValueError("no constant_shear_rate curve: no torsion to compare with")
    rates = np.array([float(avg["shear_rate_1_per_s"].values[i]) for i in idx])
    i = idx[int(np.argmax(rates))]
    rate = float(rates.max())
    radius = float(np.nanmedian(np.asarray(avg["radius_m"].values, float)[idx]))
    gap = float(np.nanmedian(np.asarray(avg["gap_m"].values, float)[idx]))
    one = select_average(avg, "constant_shear_rate", str(avg["condition"].values[i]))
    strain = np.asarray(one[next(iter(one.coords))].values, float)
    stress = np.asarray(one["shear_stress_mean"].values, float)
    ok = np.isfinite(strain) & np.isfinite(stress) & (strain > 0)
    strain, torque = strain[ok], stress[ok] * math.pi * radius ** 3 / 2.0
    gamma = np.linspace(strain.max() / n_points, strain.max(), n_points)

    def solver(h):
        def solve(c):
            ds = rheometer_torsion(c, gamma / rate, gamma, radius_m=radius, gap_m=gap, element_size_m=h,
                                   n_threads=n_threads)
            return gamma, np.asarray(ds["torque"].values, float)
        return solve

    coarse = solver(draw_element_size_m) if draw_element_size_m > element_size_m else None
    res = propagate(solver(element_size_m), card, pop, post, record, n_draws, seed, solve_draw=coarse)
    ds = bands_dataset(res, "rim_strain", "1", "torque", "N m",
                       {"experiment": "rheometer torsion", "model": record.model_key, "rate_1_per_s": rate,
                        "radius_m": radius, "gap_m": gap, "element_size_m": element_size_m,
                        "draw_element_size_m": max(draw_element_size_m, element_size_m), "n_draws": n_draws,
                        "seed": seed})
    ds["torque_measured"] = ("point", np.interp(gamma, strain, torque), {"units": "N m",
                                                                         "meaning": "mean measured torque"})
    write_netcdf(ds, out_nc)
    plot_bands(ds, figure_path, "rim_strain", "torque", 1.0, 1e6, "rim strain [-]", "torque [µN m]",
               f"{record.model_key}: torsion {rate:g} 1/s", reference=(gamma, ds["torque_measured"].values),
               reference_label="measured mean")
    return ds


__all__ = ["problem_for_record", "internal_covariance", "sample_record_posterior", "posterior_table",
           "inference_data", "write_inference_data", "read_inference_group", "run_posterior", "Z95", "IDATA_GROUPS",
           "reference_shear_modulus", "piece_levels", "run_population", "elastic_card", "band",
           "run_uq_indentation", "run_uq_torsion", "propagate", "recommended_posterior",
           "bands_dataset", "plot_bands", "SOURCES", "predictive_draws", "predictive_band", "N_PREDICTIVE"]


#: columns of :func:`extension_indentation`'s table
EXTENSION_INDENTATION_COLUMNS = (
    "cause", "geometry", "extension_model", "baseline_model", "depth_m", "baseline_force_n", "extension_force_n",
    "difference_n", "relative_difference", "measurement_q05_n", "measurement_q95_n", "specimen_q05_n",
    "specimen_q95_n", "outside_measurement_band", "outside_specimen_band", "punch_nodes", "status")
#: ``geometry`` of the rows of :func:`extension_indentation`
FLAT_PUNCH_GEOMETRY, BRAIN_GEOMETRY = "flat punch on a tissue block", "MNI brain"


def extension_indentation(bands_nc, simulation_cards_dir, out_csv, n_threads: int = 1,
                          brain_mesh=None) -> pd.DataFrame:
    """The flat-punch indentation of :func:`run_uq_indentation` with each named extension's card beside its baseline:
    what the extension changes in the force a surgeon would feel, against the baseline's posterior and specimen bands.

    For every cause in the simulation cards' index (:mod:`tissuemech.diagnosis.simulation_cards`) with both
    full-data cards (the extension and the baseline fitted to the same runs by the same path, so that the difference
    is the extension's and not a different fit's), both are pressed to the bands' depth with the bands' punch,
    speed, mesh and increments (read from ``bands_nc``). The baseline's 5-95 % bands at that depth are taken relative
    to the fit optimum they were drawn around and applied to the baseline card's force: the extension's force
    outside the measurement band is a difference the parameter uncertainty of the data cannot produce; outside the
    specimen band, one larger than the spread between specimens.

    With ``brain_mesh`` (a :class:`tissuemech.fem.mesh.TetMesh` in m) both cards are also pressed into the top of
    the MNI brain (:func:`tissuemech.fem.experiments.brain_indentation`) with the same punch, depth, speed and
    increments. The posterior draws are not run on the brain (32 brain solves); its band columns are the flat
    punch's bands relative to their optimum, applied to the brain's baseline force: the relative parameter
    uncertainty, not a band drawn on that geometry. ``punch_nodes``: the brain's surface nodes on the punch face at
    the final depth (how finely the mesh resolves the punch; NaN on the block).

    A card that fails to run gives a row with its status. Writes ``out_csv`` (columns
    :data:`EXTENSION_INDENTATION_COLUMNS`; no rows when nothing was named).
    """
    bands = read_netcdf(bands_nc)
    a = bands.attrs
    settings = dict(punch_diameter_m=float(a["punch_diameter_m"]), max_depth_m=float(a["max_depth_m"]),
                    speed_m_s=float(a["speed_m_s"]))
    n_increments = int(a.get("n_increments", 6))
    optimum = float(bands["force_optimum"].values[-1])
    rel = {f"{src}_{q}": float(bands[f"{src}_{q}"].values[-1]) / optimum
           for src in ("measurement", "specimen") for q in ("q05", "q95")}
    geometries = {FLAT_PUNCH_GEOMETRY: lambda card: flat_punch_indentation(
        card, **settings, element_size_m=float(a["element_size_m"]), n_increments=n_increments, n_threads=n_threads)}
    if brain_mesh is not None:
        geometries[BRAIN_GEOMETRY] = lambda card: brain_indentation(
            card, **settings, mesh=brain_mesh, n_increments=n_increments, n_threads=n_threads)
    folder = Path(simulation_cards_dir)
    index_path = folder / SIMULATION_CARDS_INDEX
    index = json.loads(index_path.read_text()) if index_path.is_file() else {}
    rows = []
    for cause, entry in (index.get("causes") or {}).items():
        if not entry.get("card") or not entry.get("baseline_card"):
            continue
        cards = {role: MaterialCard.from_json(folder / entry[key]).for_fem()
                 for role, key in (("baseline", "baseline_card"), ("extension", "card"))}
        for geometry, press in geometries.items():
            row = {"cause": cause, "geometry": geometry, "extension_model": entry.get("extension_model"),
                   "baseline_model": entry.get("baseline_model"), "depth_m": settings["max_depth_m"]}
            try:
                runs = {role: press(card) for role, card in cards.items()}
            except (ElementInversionError, DynamicRelaxationError, ValueError) as exc:
                rows.append({**row, "status": f"not run: {exc}"})
                continue
            base, ext = (float(runs[r]["force"].values[-1]) for r in ("baseline", "extension"))
            row.update(baseline_force_n=base, extension_force_n=ext, difference_n=ext - base,
                       relative_difference=(ext - base) / base,
                       punch_nodes=runs["baseline"].attrs.get("punch_nodes_at_max_depth", float("nan")),
                       **{f"{k}_n": base * v for k, v in rel.items()}, status="ok")
            row["outside_measurement_band"] = bool(not row["measurement_q05_n"] <= ext <= row["measurement_q95_n"])
            row["outside_specimen_band"] = bool(not row["specimen_q05_n"] <= ext <= row["specimen_q95_n"])
            rows.append(row)
    table = pd.DataFrame(rows, columns=list(EXTENSION_INDENTATION_COLUMNS))
    write_text(table.to_csv(index=False), out_csv)
    return table
