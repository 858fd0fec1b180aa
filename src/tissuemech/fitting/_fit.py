"""The fit (lmfit, multistart), :class:`FitResult` with its flags, and the fit record outputs (netCDF through
:class:`tissuemech.records.FitRecord`, the ``fits.csv`` row) (part of :mod:`tissuemech.fitting`, which
re-exports every public name)."""
from __future__ import annotations

import math
import re
import warnings
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import lazy_loader
import numpy as np
import pandas as pd
import xarray as xr

from ..canonical import to_jsonable
from ..models.base import ConstitutiveModel
from ..records import FitRecord
from ..stats import effective_sample_size, information_criteria, nrmse
from ._data import Curve, curve_ranges
from ._problem import FitProblem, NoiseModel

# loaded on first use (why: tissuemech.fitting._problem)
lmfit = lazy_loader.load("lmfit")

#: relative chi-square difference under which two starts count as the same optimum (see :func:`fit`)
EQUIVALENT_CHISQR_RTOL = 1e-7
#: ``xtol``/``ftol``/``gtol`` of the final polish of the chosen optimum (see :func:`fit`)
POLISH_TOL = 1e-12

#: |correlation| above which a parameter pair is flagged as not separately identifiable
CORRELATION_FLAG = 0.95


# ------------------------------------------------------------------------------------------------
# fit result
# ------------------------------------------------------------------------------------------------
@dataclass
class FitResult:
    """Everything recorded about one fit (JSON/netCDF-ready through :func:`fit_to_dataset`)."""

    model_key: str
    family: str
    scope: str
    target: str
    params: dict[str, float]
    stderr: dict[str, float]
    units: dict[str, str]
    varying: list[str]
    correlation: np.ndarray
    flags: list[str]
    success: bool
    message: str
    chisqr: float
    redchi: float
    rmse: float
    nrmse: float
    n: int
    n_eff: float
    k: int
    aic: float
    aicc: float
    bic: float
    aicc_eff: float
    bic_eff: float
    nfev: int
    n_starts: int
    curve_labels: list[str]
    curve_rmse: dict[str, float]
    curve_nrmse: dict[str, float]
    residuals: list[dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]]
    ranges: dict[str, float]
    selection: list[dict]
    structure: dict
    start_chisqr: list[float] = field(default_factory=list)
    #: condition number of the correlation matrix and its sloppiest direction (science.md §4.5)
    condition_number: float = float("nan")
    sloppy_direction: dict[str, float] = field(default_factory=dict)
    #: strain-history treatment of relaxation curves ("measured", "ramp", "step")
    relaxation: str = "measured"

    @property
    def ok(self) -> bool:
        """Converged and no flag raised."""
        return self.success and not self.flags


def _flags(problem: FitProblem, best, names: list[str]) -> tuple[list[str], np.ndarray]:
    flags = []
    if not best.success:
        flags.append(f"not_converged: {best.message}")
    k = len(names)
    corr = np.full((k, k), np.nan)
    if best.covar is not None and np.all(np.isfinite(best.covar)):
        cov = np.asarray(best.covar)
        sd = np.sqrt(np.clip(np.diag(cov), 0, None))
        with np.errstate(invalid="ignore", divide="ignore"):
            corr = cov / np.outer(sd, sd)
        np.fill_diagonal(corr, 1.0)
        if not np.all(sd > 0):
            # a finite covariance with a zero variance: lmfit's inverse of a singular Jacobian
            flags.append("no_covariance: the Jacobian is singular (parameters not identifiable from these data)")
        for i in range(k):
            for j in range(i + 1, k):
                if np.isfinite(corr[i, j]) and abs(corr[i, j]) > CORRELATION_FLAG:
                    flags.append(f"correlated: {names[i]}~{names[j]} (rho={corr[i, j]:+.3f})")
    elif k:
        flags.append("no_covariance: the Jacobian is singular (parameters not identifiable from these data)")
    for iname in names:
        par = best.params[iname]
        lo, hi = par.min, par.max
        # "at a bound" relative to the parameter's own scale (not to a possibly huge box)
        init = par.init_value if par.init_value is not None else par.value
        scale = max(abs(init), abs(par.value), 1e-12)
        tol = 1e-4 * scale
        for bound, side in ((lo, "lower"), (hi, "upper")):
            if np.isfinite(bound) and abs(par.value - bound) <= tol:
                flags.append(f"at_bound: {iname.removeprefix('log10_')} at its {side} bound {bound:g}"
                             + (" (log10)" if iname.startswith("log10_") else ""))
    return flags, corr


#: the ``at_bound`` flag of :func:`fit` (parameter, side, bound)
_AT_BOUND = re.compile(r"at_bound: (\S+) at its (lower|upper) bound (\S+)")


def at_bound_parameters(flags: Iterable[str]) -> list[str]:
    """Varying parameters a fit left at a bound, from its flags (``at_bound: <name> at its <side> bound <b>``).

    A Prony weight ``beta_i`` at its lower bound 0 is not listed: that relaxation mode is simply absent (the
    NNLS answer "not needed"), not a collapse of the fit.
    """
    out = []
    for f in flags:
        m = _AT_BOUND.match(str(f))
        if m and not (re.fullmatch(r"beta_\d+", m.group(1)) and m.group(2) == "lower" and float(m.group(3)) == 0.0):
            out.append(m.group(1))
    return sorted(set(out))


def weights_at_upper_bound(flags: Iterable[str]) -> list[int]:
    """0-based indices ``i`` of the Prony ratios ``beta_{i+1}`` a fit left at their upper bound, from its flags:
    the equilibrium modulus is below 1/bound of that mode's, the direction in which a mode outside the resolved
    window trades its weight against the equilibrium modulus (a slow one) or acts as a viscosity (a fast one)."""
    out = []
    for f in flags:
        m = _AT_BOUND.match(str(f))
        if m and m.group(2) == "upper" and re.fullmatch(r"beta_\d+", m.group(1)):
            out.append(int(m.group(1).split("_")[1]) - 1)
    return sorted(set(out))


def has_covariance(flags: Iterable[str], stderr: Mapping[str, float], varying: Sequence[str]) -> bool:
    """Whether a fit has a covariance: no ``no_covariance`` flag and a finite standard error of some varying
    parameter (true for a fit with nothing varying)."""
    if any(str(f).startswith("no_covariance") for f in flags):
        return False
    return not varying or any(np.isfinite(stderr.get(n, np.nan)) for n in varying)


def _random_start(problem: FitProblem, rng: np.random.Generator) -> dict[str, float]:
    """One random start around the model's defaults: log parameters within +-1 decade of the default, positive
    linear ones within a factor 10, others within +-max(|default|, 1); narrow finite bounds (less than ten
    times the default's scale wide) are sampled uniformly. Always clipped to the bounds."""
    out = {}
    for spec in problem.model.param_specs:
        if spec.name in problem.fixed:
            continue
        lo, hi = problem.param_bounds(spec)
        init = float(spec.init)
        if problem.is_log(spec):
            v = init * 10.0 ** rng.uniform(-1.0, 1.0)
        elif np.isfinite(lo) and np.isfinite(hi) and (hi - lo) <= 10.0 * max(abs(init), 1e-300):
            v = rng.uniform(lo, hi)
        elif lo >= 0 and init > 0:
            v = init * 10.0 ** rng.uniform(-1.0, 1.0)
        else:
            v = init + rng.uniform(-1.0, 1.0) * max(abs(init), 1.0)
        out[spec.name] = float(min(max(v, lo), hi))
    return out


def fit(problem: FitProblem, starts: Iterable[Mapping[str, float]] = (), n_random: int = 4, seed: int = 0,
        max_nfev: int | None = None, method: str = "least_squares") -> FitResult:
    """Fit ``problem`` from several starts and return the best fit with its full record.

    Parameters
    ----------
    problem : :class:`FitProblem`
    starts : explicit natural-unit starts (e.g. from :func:`prony_nnls`), tried before the model default
    n_random : number of seeded random starts around the defaults (:func:`_random_start`)
    seed : random seed (the result is reproducible)
    max_nfev : function-evaluation limit per start
    method : lmfit method (``least_squares`` = scipy TRF with bounds)
    """
    rng = np.random.default_rng(seed)
    start_list = [dict(s) for s in starts] + [problem.model.default_params()]
    start_list += [_random_start(problem, rng) for _ in range(n_random)]

    results, chis, nfev = [], [], 0
    for s in start_list:
        pars = problem.make_params(s)
        kws = {"max_nfev": max_nfev} if max_nfev else {}
        try:
            with warnings.catch_warnings():
                # lmfit divides by zero standard errors of singular fits; the flags below report them
                warnings.filterwarnings("ignore", "invalid value encountered", RuntimeWarning)
                res = lmfit.minimize(problem.residual, pars, method=method, **kws)
        except (ValueError, FloatingPointError, ZeroDivisionError) as exc:  # a start in a bad region
            chis.append(float("inf"))
            last_error = exc
            continue
        nfev += int(res.nfev)
        chis.append(float(res.chisqr))
        results.append(res)
    if not results:
        raise RuntimeError(f"every start of {problem.model_key!r} failed: {last_error}")
    # Starts that reach the same optimum within solver tolerance can differ by a relabelling (e.g. two Prony
    # modes swapped); taking the first such start, not the strictly smallest chi-square, keeps the reported
    # labels the same on every machine.
    lowest = min(float(r.chisqr) for r in results)
    best = next(r for r in results if float(r.chisqr) <= lowest * (1.0 + EQUIVALENT_CHISQR_RTOL) + 1e-300)
    if method == "least_squares":
        # scipy's default tolerances (1e-8) stop TRF early in a flat valley, where the stopping point then depends on
        # the machine's rounding (Burgers creep: eta2 394.446 on a Zen 4 VM, 394.393 on Zen 5, 1 % of its standard
        # error): polishing the chosen optimum to 1e-12 makes the result the optimum's, not the path's
        best, polish_nfev = _polish(problem, best, method, kws)
        nfev += polish_nfev
    return _record(problem, best, nfev, chis)


def _polish(problem: FitProblem, best, method: str, kws: dict):
    """``(result, nfev)``: ``best`` refined from its own parameters with :data:`POLISH_TOL` (kept if not lower)."""
    try:
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", "invalid value encountered", RuntimeWarning)
            res = lmfit.minimize(problem.residual, best.params, method=method, xtol=POLISH_TOL, ftol=POLISH_TOL,
                                 gtol=POLISH_TOL, **kws)
    except (ValueError, FloatingPointError, ZeroDivisionError):
        return best, 0
    return (res if float(res.chisqr) <= float(best.chisqr) else best), int(res.nfev)


def _record(problem: FitProblem, best, nfev: int, chis: list[float]) -> FitResult:
    model = problem.model
    p = problem.natural(best.params)
    names = [n for n in best.var_names]
    flags, corr = _flags(problem, best, names)
    stderr = {}
    for s in model.param_specs:
        par = best.params[problem.internal_name(s)]
        if not par.vary:
            stderr[s.name] = 0.0
        elif par.stderr is None or not np.isfinite(par.stderr):
            stderr[s.name] = float("nan")
        elif problem.is_log(s):
            # delta method: d(10^u)/du = ln(10) 10^u
            stderr[s.name] = float(math.log(10.0) * p[s.name] * par.stderr)
        else:
            stderr[s.name] = float(par.stderr)
    terms = problem.curve_terms(p)
    weighted = [np.concatenate([w for (_, _, w) in t.values()]) for t in terms]
    n = int(sum(w.size for w in weighted))
    k = len(names)
    chisqr = float(sum(np.sum(w ** 2) for w in weighted))
    n_eff = float(sum(effective_sample_size(w) for w in weighted))
    raw = np.concatenate([f - y for t in terms for (y, f, _) in t.values()])
    curve_rmse, curve_nrmse = {}, {}
    for c, t in zip(problem.curves, terms):
        y = np.concatenate([y for (y, _, _) in t.values()])
        f = np.concatenate([f for (_, f, _) in t.values()])
        curve_rmse[c.label] = float(np.sqrt(np.mean((f - y) ** 2)))
        curve_nrmse[c.label] = nrmse(y, f)
    ic = information_criteria(chisqr, n, k)
    ic_eff = information_criteria(chisqr * n_eff / n, n_eff, k)  # chi2 rescaled to n_eff independent points
    for name in names:
        spec_name = name.removeprefix("log10_")
        se, v = stderr.get(spec_name, np.nan), p.get(spec_name, np.nan)
        if np.isfinite(se) and v != 0 and se > abs(v):
            flags.append(f"poorly_determined: {spec_name} standard error {se:.3g} exceeds |value| {abs(v):.3g}")
    cond, sloppy = float("nan"), {}
    if corr.size and np.all(np.isfinite(corr)):
        # sloppy direction = least-constrained combination = largest-variance eigenvector of the
        # (standardised) covariance, i.e. the smallest eigenvalue of the Fisher matrix J^T W J
        evals, evecs = np.linalg.eigh(corr)
        cond = float(evals[-1] / max(evals[0], np.finfo(float).tiny))
        sloppy = {n.removeprefix("log10_"): float(v) for n, v in zip(names, evecs[:, -1])}
    selection = [{"label": c.label, "test": c.test, "condition": c.condition, "specimen": c.specimen,
                  "n_points": c.n_points, "n_samples": c.n_samples, "response": c.response,
                  "observables": sorted(o.keys()), "radius_m": c.radius_m, "gap_m": c.gap_m,
                  **{f"nominal_{k2}": v2 for k2, v2 in c.nominal.items()}}
                 for c, (o, _) in zip(problem.curves, problem.observations)]
    return FitResult(
        model_key=problem.model_key, family=model.family, scope=problem.scope, target=problem.target,
        params=p, stderr=stderr, units={s.name: s.unit for s in model.param_specs},
        varying=[n.removeprefix("log10_") for n in names], correlation=corr, flags=flags,
        success=bool(best.success), message=str(best.message), chisqr=chisqr, redchi=chisqr / max(n - k, 1),
        rmse=float(np.sqrt(np.mean(raw ** 2))), nrmse=float(np.sqrt(np.mean(np.square(list(curve_nrmse.values()))))),
        n=n, n_eff=n_eff, k=k, aic=ic["aic"], aicc=ic["aicc"], bic=ic["bic"], aicc_eff=ic_eff["aicc"],
        bic_eff=ic_eff["bic"], nfev=nfev, n_starts=len(chis), curve_labels=[c.label for c in problem.curves],
        curve_rmse=curve_rmse, curve_nrmse=curve_nrmse, residuals=terms, ranges=curve_ranges(problem.curves),
        selection=selection, structure=to_jsonable(model.structure, nonfinite_as_null=False), start_chisqr=chis,
        condition_number=cond, sloppy_direction=sloppy, relaxation=problem.relaxation)


def evaluate(model: ConstitutiveModel, params: Mapping[str, float], curves: Sequence[Curve], target: str,
             noise: NoiseModel | None = None) -> dict[str, float]:
    """Prediction error of fixed parameters on (held-out) curves.

    Returns ``rmse`` (observed units, pooled), ``nrmse`` (RMS over curves of RMSE / mean |observed|),
    ``chisqr`` (weighted) and ``n``.
    """
    prob = FitProblem(model=model, curves=list(curves), target=target, noise=noise or NoiseModel())
    terms = prob.curve_terms(dict(params))
    raw, nr, chi, n = [], [], 0.0, 0
    for t in terms:
        e = np.concatenate([f - y for (y, f, _) in t.values()])
        y = np.concatenate([y for (y, _, _) in t.values()])
        w = np.concatenate([w for (_, _, w) in t.values()])
        raw.append(e)
        nr.append(nrmse(y, np.concatenate([f for (_, f, _) in t.values()])))
        chi += float(np.sum(w ** 2))
        n += w.size
    raw = np.concatenate(raw)
    return {"rmse": float(np.sqrt(np.mean(raw ** 2))), "nrmse": float(np.sqrt(np.mean(np.square(nr)))),
            "chisqr": chi, "n": n}


# ------------------------------------------------------------------------------------------------
# outputs
# ------------------------------------------------------------------------------------------------
def fit_to_dataset(result: FitResult) -> xr.Dataset:
    """The fit record as an xarray Dataset (dims ``param``, ``param_b``, ``point``, ``curve``), written by
    :meth:`tissuemech.records.FitRecord.to_dataset` (the one layout; read back with ``FitRecord.from_dataset``)."""
    return FitRecord.from_result(result).to_dataset()


def write_fit_netcdf(result: FitResult, path) -> None:
    """Atomically write the fit record (``results/<dataset>/fits/<scope>/<model>.nc``); read it back with
    :meth:`tissuemech.records.FitRecord.from_netcdf`."""
    FitRecord.from_result(result).to_netcdf(path)


#: scalar attributes of a fit record copied to ``fits.csv`` (in this order, after ``dataset``/``file``/``model``)
FITS_CSV_ATTRS = ("family", "scope", "target", "relaxation", "success", "n", "n_eff", "k", "chisqr", "redchi", "rmse",
                  "nrmse", "aic", "aicc", "bic", "aicc_eff", "bic_eff", "condition_number", "nfev", "n_starts",
                  "message")


def fits_csv_row(record: FitRecord | xr.Dataset, dataset: str = "", file: str = "",
                 posterior: pd.DataFrame | None = None) -> dict:
    """One tidy ``fits.csv`` row of a fit record (a :class:`~tissuemech.records.FitRecord`, or its Dataset
    :func:`fit_to_dataset` / a ``fits/<scope>/<model>.nc`` read back): criteria, flags, ranges and
    ``param_<name>``/``se_<name>`` columns. The one ``fits.csv`` schema:
    ``dataset, file, model, <FITS_CSV_ATTRS>, n_flags, flags ("; "), curves ("; "), <ranges>, param_*, se_*``,
    and with ``posterior`` (the record's rows of a posterior table, ``tissuemech.uq.posterior_table``: columns
    ``parameter``, ``ci05``, ``ci50``, ``ci95``, ``rhat``, ``ess``, ``acceptance``, ``warnings``) the 5/50/95 %
    credible quantiles ``ci05_<name>``/``ci50_<name>``/``ci95_<name>`` after each sampled parameter's ``se_<name>``
    and ``posterior_rhat_max``, ``posterior_ess_min``, ``posterior_acceptance``, ``posterior_warnings``. Without a
    posterior those columns are absent from the row (empty in the table).
    """
    rec = record if isinstance(record, FitRecord) else FitRecord.from_dataset(record)
    row = {"dataset": dataset, "file": str(file), "model": rec.model_key}
    for name in FITS_CSV_ATTRS:
        row[name] = bool(rec.success) if name == "success" else getattr(rec, name)
    row["n_flags"] = len(rec.flags)
    row["flags"] = "; ".join(rec.flags)
    row["curves"] = "; ".join(rec.curve_labels)
    row.update(rec.ranges)
    sampled = ({str(r["parameter"]): r for _, r in posterior.iterrows()}
               if posterior is not None and not posterior.empty else {})
    for name, value in rec.params.items():
        row[f"param_{name}"] = float(value)
        row[f"se_{name}"] = float(rec.stderr[name])
        if name in sampled:
            for q in ("ci05", "ci50", "ci95"):
                row[f"{q}_{name}"] = float(sampled[name][q])
    if sampled:
        row["posterior_rhat_max"] = float(posterior["rhat"].max())
        row["posterior_ess_min"] = float(posterior["ess"].min())
        row["posterior_acceptance"] = float(posterior["acceptance"].iloc[0]) if "acceptance" in posterior else None
        warn = posterior["warnings"].iloc[0] if "warnings" in posterior else ""
        row["posterior_warnings"] = "" if pd.isna(warn) else str(warn)
    return row
