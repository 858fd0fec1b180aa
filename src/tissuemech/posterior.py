"""Posterior sampling of fitted parameters with emcee (optional extra ``uq``), started at the lmfit optimum.

Model (stated in every result's ``priors`` and ``likelihood``):

* likelihood: Gaussian in the fit's residual vector ``r(theta)`` (the same weighted residuals lmfit minimises),
  ``log L = -chi2(theta) / (2 s2)``. ``s2 = 1`` when the residuals are already divided by a known measurement
  standard deviation; ``s2 = chi2_min / (n - k)`` (lmfit's ``redchi``) reproduces lmfit's default covariance
  scaling (``scale_covar=True``), so a near-Gaussian posterior then has the lmfit standard errors as its spread.
* priors: independent uniform priors on the given bounds (each parameter's fit bounds); nothing else.
* start: ``n_walkers`` points around the optimum: drawn from the fit's Laplace approximation ``N(optimum, cov)``
  (lmfit's covariance) when ``cov`` is given, else a small Gaussian ball (``1e-3`` of each parameter's scale);
  points outside the bounds are clipped into them.

Moves (all leave the posterior invariant; emcee's ensemble framework):

* burn-in (``burn`` steps): with ``cov``, an independence Metropolis-Hastings move whose proposal is a Student-t
  (5 degrees of freedom) centred on the optimum with scale matrix ``1.5^2 cov`` (weight 0.6) and a Gaussian
  random walk with covariance ``2.38^2 / d cov`` (0.4); without ``cov``, differential evolution (``DEMove`` 0.8,
  ``DESnookerMove`` 0.2; ter Braak & Vrugt 2008, needs ``n_walkers >= 2 d``);
* kept steps: the independence move with a Student-t proposal (10 degrees of freedom) fitted to the second half of
  the burn-in (mean and covariance of the walkers; frozen before the kept steps, so each walker is a plain
  Metropolis-Hastings chain) with weight 0.7, and the Gaussian random walk with the burn-in covariance (0.3,
  robust where the posterior is far from the proposal, e.g. truncated at a bound). Both are single-walker moves, so a few
  long chains (e.g. 8) can be run: split R-hat needs many effective draws *per chain*, the ESS only in total.
  On the bundled brain's QLV fit this gives integrated autocorrelation times of ~6 steps, against ~30 for
  emcee's default stretch move; on its beyond-QLV (Pipkin-Rogers) fit, whose posterior is truncated at a Prony
  weight's bound, ~20 steps. With ``burn < 20`` the burn-in moves are used throughout (no adaptation).

Diagnostics (Gelman et al., *Bayesian Data Analysis*, 3rd ed., section 11.4, split R-hat; emcee's integrated
autocorrelation time, Foreman-Mackey et al. 2013 PASP 125:306):

* ``rhat``: split-R-hat over the walkers (each walker's kept chain split in halves);
* ``ess``: ``n_walkers * n_kept / tau`` with ``tau`` from :meth:`emcee.EnsembleSampler.get_autocorr_time`
  (``quiet=True``; a chain shorter than 50 tau makes emcee warn, and the ESS is then an estimate only);
* ``acceptance``: mean acceptance fraction of the walkers.

``warnings`` names every parameter with ``rhat >= 1.01`` or ``ess < 400`` (the thresholds of issue 16) and an
acceptance fraction below 0.2, the lower end of the range Foreman-Mackey et al. recommend for the stretch move
(its upper end, 0.5, is routinely exceeded by well-mixed chains in two or three dimensions -- 0.71 on the
two-parameter test problem -- so a high fraction alone is not flagged).
"""
from __future__ import annotations

import importlib.util
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import lazy_loader
import numpy as np

# optional dependency (extra "uq"), loaded on first use: importing it (with tqdm, h5py) costs every job that
# imports the package ~0.1 s (issue 17)
emcee = lazy_loader.load("emcee") if importlib.util.find_spec("emcee") is not None else None

#: thresholds of a usable posterior (issue 16)
RHAT_MAX = 1.01
ESS_MIN = 400.0
#: lowest acceptance fraction not flagged (lower end of Foreman-Mackey et al. 2013's 0.2-0.5)
ACCEPTANCE_MIN = 0.2
#: scale factor and degrees of freedom of the kept steps' Student-t independence proposal (module docstring)
KEPT_PROPOSAL_SCALE = 1.0
KEPT_PROPOSAL_DF = 10.0


@dataclass
class PosteriorResult:
    """Samples and diagnostics of :func:`sample_posterior` (``samples``: shape ``(n_draws, n_params)``)."""

    names: list[str]
    samples: np.ndarray
    #: kept chain, shape ``(n_walkers, n_kept, n_params)`` (ArviZ's chain/draw order)
    chain: np.ndarray
    #: log posterior of the kept chain, shape ``(n_walkers, n_kept)``
    log_prob: np.ndarray
    rhat: dict[str, float]
    ess: dict[str, float]
    tau: dict[str, float]
    acceptance: float
    priors: dict[str, str]
    likelihood: str
    warnings: list[str] = field(default_factory=list)

    def credible_interval(self, name: str, level: float = 0.9) -> tuple[float, float]:
        """Equal-tailed credible interval of one parameter (``level`` = 0.9 -> 5-95 %)."""
        x = self.samples[:, self.names.index(name)]
        q = (1.0 - level) / 2.0
        lo, hi = np.quantile(x, [q, 1.0 - q])
        return float(lo), float(hi)

    def summary(self) -> dict[str, dict[str, float]]:
        """Per parameter: mean, sd, 5/50/95 % quantiles, rhat, ess (JSON-ready)."""
        out = {}
        for i, n in enumerate(self.names):
            x = self.samples[:, i]
            q5, q50, q95 = np.quantile(x, [0.05, 0.5, 0.95])
            out[n] = {"mean": float(x.mean()), "sd": float(x.std(ddof=1)), "q05": float(q5), "q50": float(q50),
                      "q95": float(q95), "rhat": self.rhat[n], "ess": self.ess[n]}
        return out


def split_rhat(chains: np.ndarray) -> float:
    """Split-R-hat of one scalar from ``chains`` of shape ``(n_chains, n_draws)`` (Gelman et al. BDA3, 11.4)."""
    c = np.asarray(chains, float)
    half = c.shape[1] // 2
    split = np.concatenate([c[:, :half], c[:, half:2 * half]], axis=0)
    m, n = split.shape
    means = split.mean(axis=1)
    w = split.var(axis=1, ddof=1).mean()
    b = n * means.var(ddof=1)
    var_plus = (n - 1) / n * w + b / n
    return float(np.sqrt(var_plus / w)) if w > 0 else float("nan")


def _student_t_move(mean: np.ndarray, scale_cov: np.ndarray, df: float = 5.0):
    """Independence Metropolis-Hastings move: proposals from a multivariate Student-t (``mean``, ``scale_cov``)."""
    chol = np.linalg.cholesky(scale_cov)
    inv = np.linalg.inv(chol)
    d = mean.size

    def log_q(x):
        z = (x - mean) @ inv.T
        return -0.5 * (df + d) * np.log1p(np.sum(z * z, axis=1) / df)

    def propose(coords, random):
        k = coords.shape[0]
        z = random.standard_normal((k, d)) * np.sqrt(df / random.chisquare(df, k))[:, None]
        q = mean + z @ chol.T
        return q, log_q(coords) - log_q(q)

    return emcee.moves.MHMove(propose)


def _positive_definite(cov: np.ndarray, max_condition: float = 1e12) -> bool:
    """Finite, positive definite and not near-singular (correlation condition number below ``max_condition``)."""
    cov = np.atleast_2d(np.asarray(cov, float))
    if not np.all(np.isfinite(cov)) or np.any(np.diag(cov) <= 0):
        return False
    sd = np.sqrt(np.diag(cov))
    evals = np.linalg.eigvalsh(cov / np.outer(sd, sd))
    return bool(evals[0] > 0 and evals[-1] / evals[0] < max_condition)


def sample_posterior(residual: Callable[[np.ndarray], np.ndarray], optimum: Mapping[str, float],
                     bounds: Mapping[str, tuple[float, float]], noise_variance: float = 1.0, n_walkers: int = 32,
                     n_steps: int = 3000, burn: int = 1000, seed: int = 0,
                     cov: np.ndarray | None = None) -> PosteriorResult:
    """Sample the posterior of parameters whose residual vector a fit minimised.

    Parameters
    ----------
    residual : callable
        ``residual(theta) -> r`` with ``theta`` ordered as ``optimum``; ``chi2 = sum r^2`` (weighted residuals).
    optimum : mapping
        Parameter name -> value at the lmfit optimum (the walkers start around it).
    bounds : mapping
        Parameter name -> ``(lower, upper)`` of its uniform prior (the fit bounds; may be infinite).
    noise_variance : float
        ``s2`` of the likelihood (see the module docstring); 1 for residuals in units of a known noise SD.
    n_walkers, n_steps, burn, seed : int
        Ensemble size, kept steps per walker (after the burn-in), burn-in steps, random seed.
    cov : array, optional
        Covariance of the Laplace approximation at the optimum (lmfit's), in the order of ``optimum``: the start
        and the burn-in proposal (see the module docstring). Ignored when not finite and positive definite.

    Returns
    -------
    PosteriorResult
    """
    if emcee is None:
        raise ImportError("posterior sampling needs emcee: pip install 'tissuemech[uq]'")
    names = list(optimum)
    x0 = np.array([float(optimum[n]) for n in names])
    lo = np.array([float(bounds[n][0]) for n in names])
    hi = np.array([float(bounds[n][1]) for n in names])
    d = x0.size

    def log_prob(theta):
        if np.any(theta < lo) or np.any(theta > hi):
            return -np.inf
        r = np.asarray(residual(theta), float)
        chi2 = float(r @ r)
        return -0.5 * chi2 / noise_variance if np.isfinite(chi2) else -np.inf

    rng = np.random.default_rng(seed)
    laplace = cov is not None and _positive_definite(np.asarray(cov, float))
    if laplace:
        start = rng.multivariate_normal(x0, np.asarray(cov, float), size=n_walkers)
    else:
        scale = np.where(x0 != 0, 1e-3 * np.abs(x0), 1e-6)
        start = x0 + scale * rng.standard_normal((n_walkers, d))
    width = np.where(np.isfinite(hi - lo), hi - lo, np.abs(x0) + 1.0)
    start = np.clip(start, lo + 1e-9 * width, hi - 1e-9 * width)
    rw = 2.38 ** 2 / d  # optimal random-walk scale for a Gaussian target (Gelman, Roberts & Gilks 1996)
    burn_moves = [(emcee.moves.DEMove(), 0.8), (emcee.moves.DESnookerMove(), 0.2)]
    if laplace:
        burn_moves = [(_student_t_move(x0, 1.5 ** 2 * np.asarray(cov, float)), 0.6),
                      (emcee.moves.GaussianMove(rw * np.asarray(cov, float)), 0.4)]

    def sampler_with(moves):
        s = emcee.EnsembleSampler(n_walkers, d, log_prob, moves=moves)
        s.random_state = np.random.RandomState(int(rng.integers(2 ** 31))).get_state()
        return s

    state = start
    if burn >= 20:
        pre = sampler_with(burn_moves)
        state = pre.run_mcmc(start, burn, progress=False, skip_initial_state_check=True)
        tail = pre.get_chain(discard=burn // 2, flat=True)
        mean, tail_cov = tail.mean(axis=0), np.atleast_2d(np.cov(tail.T))
        kept = _student_t_move(mean, KEPT_PROPOSAL_SCALE ** 2 * tail_cov, df=KEPT_PROPOSAL_DF)
        moves = ([(kept, 0.7), (emcee.moves.GaussianMove(rw * tail_cov), 0.3)]
                 if _positive_definite(tail_cov) else burn_moves)
    else:
        moves = burn_moves
        if burn > 0:
            pre = sampler_with(burn_moves)
            state = pre.run_mcmc(start, burn, progress=False, skip_initial_state_check=True)
    sampler = sampler_with(moves)
    sampler.run_mcmc(state, n_steps, progress=False, skip_initial_state_check=True)
    chain = sampler.get_chain()  # (steps, walkers, params)
    tau = np.atleast_1d(sampler.get_autocorr_time(quiet=True))
    n_kept = chain.shape[0]
    rhat = {n: split_rhat(chain[:, :, i].T) for i, n in enumerate(names)}
    ess = {n: float(n_walkers * n_kept / tau[i]) for i, n in enumerate(names)}
    acceptance = float(np.mean(sampler.acceptance_fraction))
    warnings = [f"{n}: split R-hat {rhat[n]:.4f} >= {RHAT_MAX}" for n in names if not rhat[n] < RHAT_MAX]
    warnings += [f"{n}: ESS {ess[n]:.0f} < {ESS_MIN:.0f}" for n in names if not ess[n] >= ESS_MIN]
    if not acceptance >= ACCEPTANCE_MIN:
        warnings.append(f"acceptance fraction {acceptance:.2f} < {ACCEPTANCE_MIN}")
    priors = {n: f"uniform on [{lo[i]:.6g}, {hi[i]:.6g}]" for i, n in enumerate(names)}
    likelihood = f"Gaussian in the fit residuals, log L = -chi2 / (2 s2), s2 = {noise_variance:.6g}"
    return PosteriorResult(names=names, samples=chain.reshape(-1, d), chain=np.swapaxes(chain, 0, 1),
                           log_prob=sampler.get_log_prob().T, rhat=rhat, ess=ess,
                           tau={n: float(tau[i]) for i, n in enumerate(names)}, acceptance=acceptance,
                           priors=priors, likelihood=likelihood, warnings=warnings)


__all__ = ["sample_posterior", "split_rhat", "PosteriorResult", "RHAT_MAX", "ESS_MIN", "ACCEPTANCE_MIN"]
