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

Outputs: ``posterior/<scope>.nc`` in ArviZ's InferenceData group layout (groups ``posterior`` with one variable
per parameter in natural units, dims ``chain``/``draw``, and ``sample_stats`` with ``lp``; written with xarray
and h5netcdf, readable by ``arviz.from_netcdf``) whose ``posterior`` attributes carry R-hat, ESS, acceptance,
the warnings, priors and likelihood; ``posterior/<scope>.csv``: per parameter the lmfit value and standard error
next to the 5/50/95 % posterior quantiles and the ratio of the 90 % credible width to the lmfit interval.
"""
from __future__ import annotations

import datetime as _dt
import json
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
from .canonical import atomic_write, read_netcdf, write_text
from .models.registry import get_model
from .stages import scope_curves

#: standard normal quantile of the 95 % point (a 5-95 % interval is +- this many SD for a Gaussian)
Z95 = 1.6448536269514722
#: groups of the InferenceData file, in the order written
IDATA_GROUPS = ("posterior", "sample_stats")


def problem_for_record(averages: xr.Dataset, record: F.FitRecord, tests) -> F.FitProblem:
    """The fit problem a record came from: the scope's curves (``stages.scope_curves``), its plate target,
    relaxation treatment and the registry model with its default bounds and noise model."""
    curves = scope_curves(averages, list(tests), relaxation=record.relaxation or "measured")
    return F.FitProblem(model=get_model(record.model_key), curves=list(curves), target=record.target,
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
                groups[name].to_netcdf(tmp, group=name, mode=mode, engine="h5netcdf")
                mode = "a"
        if mode == "w":  # nothing sampled: an empty file that still states why (root attributes)
            xr.Dataset(attrs=dict(groups.get("", xr.Dataset()).attrs)).to_netcdf(tmp, mode="w", engine="h5netcdf")
    return atomic_write(path, writer)


def read_inference_group(path, group: str = "posterior") -> xr.Dataset:
    """One group of an InferenceData netCDF file, loaded into memory."""
    with xr.open_dataset(path, group=group, engine="h5netcdf") as ds:
        return ds.load()


def run_posterior(ranking_csv, averages_path, fits_dir, scope: str, tests, out_nc, out_csv, walkers=None,
                  steps: int = 800, burn: int = 150, seed: int = 0, dataset: str = "") -> pd.DataFrame:
    """Posterior of the recommended model of one scope (``ranking.csv`` column ``recommended``): the
    InferenceData netCDF and the credible-interval table (module docstring). A scope without a recommendation
    writes a file whose root attribute ``status`` says so, and an empty table."""
    model = R.recommended_models(ranking_csv).get(scope)
    if model is None:
        write_inference_data({"": xr.Dataset(attrs={"status": f"no recommended model in scope {scope}"})}, out_nc)
        table = pd.DataFrame(columns=["dataset", "scope", "model", "parameter"])
        write_text(table.to_csv(index=False), out_csv)
        return table
    record = F.FitRecord.from_netcdf(Path(fits_dir) / f"{model}.nc")
    problem = problem_for_record(read_netcdf(averages_path), record, tests)
    post, info = sample_record_posterior(problem, record, walkers=walkers, steps=steps, burn=burn, seed=seed)
    write_inference_data(inference_data(record, post, info, dataset=dataset, scope=scope), out_nc)
    table = posterior_table(record, post, dataset=dataset, scope=scope)
    table["acceptance"] = post.acceptance
    table["warnings"] = "; ".join(post.warnings)
    write_text(table.to_csv(index=False), out_csv)
    return table


__all__ = ["problem_for_record", "internal_covariance", "sample_record_posterior", "posterior_table",
           "inference_data", "write_inference_data", "read_inference_group", "run_posterior", "Z95", "IDATA_GROUPS"]
