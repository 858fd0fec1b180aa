"""Fung's quasi-linear viscoelasticity (QLV) on any instantaneous elastic law (science.md section 1.0).

    sigma(t) = int_0^t G_r(t - s) d sigma_e(gamma(s))/ds ds,    G_r(t) = g_inf + sum_i g_i exp(-t/tau_i)

evaluated with the exact exponential recursion of :mod:`tissuemech.models.recursion` on the *real* strain
history (finite ramps of any rate, relaxation with its rise time, oscillation ...), never on an idealised
step.

Parametrisation of the Prony weights
------------------------------------
The constraint ``g_i >= 0, sum g_i < 1`` is enforced by the parametrisation, not by a fit-time constraint:
the fitted parameters are the branch-to-equilibrium modulus ratios

    beta_i = G_i / G_inf >= 0      (Simo/Holzapfel's beta_i),   g_i = beta_i / (1 + sum_j beta_j),
    g_inf = 1 / (1 + sum_j beta_j)

so every non-negative ``beta`` is admissible and ``g_inf > 0`` always. Use :meth:`QLVModel.prony_weights`
to report ``g_inf, g_i, tau_i`` (thesis/Abaqus convention) and :func:`qlv_params` to build a parameter
mapping from published ``g_i`` (e.g. the thesis Prony series).

Relaxation times are either fixed (default, log-spaced 0.1, 1, 10, 100 s as in the thesis; fixing them
makes the fit well posed, Babaei et al. 2016) or free parameters ``tau_1 ... tau_n`` (s, fitted on a log
scale; their order is not enforced, so branches may swap labels between fits).
"""
from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from numba import njit
import scipy

from . import hyperelastic
from .base import ConstitutiveModel, InstantaneousLawModel, ParamSpec, Params, initial_shear_modulus
from .recursion import qlv_stress_batch, relaxation_factors

#: thesis relaxation times (log-spaced decades) used as the default fixed Prony times, s
THESIS_TAUS_S = (0.1, 1.0, 10.0, 100.0)


# ----------------------------------------------------------------------------------------------------------
# helpers shared with beyond_qlv.py and plate.py
# ----------------------------------------------------------------------------------------------------------
def sub_params(model: ConstitutiveModel, p: Params) -> dict[str, float]:
    """The entries of ``p`` that belong to ``model`` (by its parameter names)."""
    return {name: float(p[name]) for name in model.param_names}


def elastic_stress_nd(model: ConstitutiveModel, p: Params, strain: np.ndarray) -> np.ndarray:
    """Evaluate ``model.elastic_shear_stress`` on an array of any shape (laws may expect 1-D input)."""
    strain = np.asarray(strain, float)
    return np.asarray(model.elastic_shear_stress(p, strain.ravel()), float).reshape(strain.shape)


def check_param_names(*groups: Sequence[ParamSpec]) -> tuple[ParamSpec, ...]:
    """Concatenate parameter groups, refusing duplicate names (e.g. an instantaneous law with a ``beta_1``)."""
    specs = tuple(s for g in groups for s in g)
    names = [s.name for s in specs]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ValueError(f"duplicate parameter names {dup}")
    return specs


def prony_ratio_specs(n: int, init: float = 0.25) -> tuple[ParamSpec, ...]:
    """``beta_1..beta_n`` = G_i/G_inf (dimensionless, >= 0)."""
    return tuple(ParamSpec(f"beta_{i + 1}", "1", init, 0.0, 1.0e3, False,
                           f"modulus ratio G_{i + 1}/G_inf of Prony branch {i + 1}") for i in range(n))


def tau_specs(n: int, taus_init: Sequence[float]) -> tuple[ParamSpec, ...]:
    return tuple(ParamSpec(f"tau_{i + 1}", "s", float(taus_init[i]), 1.0e-3, 1.0e5, True,
                           f"relaxation time of Prony branch {i + 1}") for i in range(n))


def default_taus(n: int) -> np.ndarray:
    """Log-spaced relaxation times: the thesis decades 0.1..100 s for n = 4, otherwise n per 0.1..100 s."""
    if n == len(THESIS_TAUS_S):
        return np.array(THESIS_TAUS_S)
    return np.logspace(-1.0, 2.0, n) if n > 1 else np.array([1.0])


def invert_monotone(fun: Callable[[np.ndarray], np.ndarray], target: np.ndarray,
                    bracket: float = 1.0, max_bracket: float = 1.0e3, n_bisect: int = 64) -> np.ndarray:
    """Solve ``fun(x) = target`` elementwise for an increasing ``fun`` (vectorised bisection).

    The bracket ``[-b, b]`` is doubled until it contains every target (up to ``max_bracket``); 64 halvings
    reach machine precision. Raises ``ValueError`` if a target lies outside ``fun([-max, max])``.
    """
    target = np.asarray(target, float)
    b = float(bracket)
    while True:
        lo_val, hi_val = fun(np.full(1, -b))[0], fun(np.full(1, b))[0]
        if np.all((target >= lo_val) & (target <= hi_val)):
            break
        b *= 2.0
        if b > max_bracket:
            raise ValueError(f"cannot invert the elastic law: target stress outside [{lo_val:g}, {hi_val:g}] Pa "
                             f"for |strain| <= {max_bracket:g}")
    lo = np.full(target.shape, -b)
    hi = np.full(target.shape, b)
    for _ in range(n_bisect):
        mid = 0.5 * (lo + hi)
        above = fun(mid) > target
        hi = np.where(above, mid, hi)
        lo = np.where(above, lo, mid)
    return 0.5 * (lo + hi)


@njit(cache=True)
def _qlv_creep_elastic_kernel(time_s, stress, rates_per_s, coupling):
    """Elastic-stress history sigma_e(t) whose QLV response is ``stress``, exact for a stress linear between samples.

    In the eigenbasis of the branches' symmetric stress-control matrix (:func:`creep_retardation_basis`) the
    states decouple, ``y' = lambda y + c sigma'``, and ``sigma_e' = sigma' + c.y``; over a step with constant
    ``sigma'`` both integrate in closed form (``phi1 = (e^{lambda dt} - 1)/lambda``,
    ``phi2 = (phi1 - dt)/lambda``, their series near ``lambda dt = 0`` for the flow mode of a fluid).
    The first sample is a step from rest: ``sigma_e = sigma`` and ``y = c sigma``.
    """
    n = time_s.shape[0]
    m = rates_per_s.shape[0]
    se = np.empty(n)
    y = np.empty(m)
    se[0] = stress[0]
    for j in range(m):
        y[j] = coupling[j] * stress[0]
    for k in range(n - 1):
        dt = time_s[k + 1] - time_s[k]
        slope = (stress[k + 1] - stress[k]) / dt if dt > 0.0 else 0.0
        growth = 0.0
        for j in range(m):
            x = rates_per_s[j] * dt
            if abs(x) < 1.0e-2:
                phi1 = dt * (1.0 + x * (0.5 + x * (1.0 / 6.0 + x * (1.0 / 24.0 + x / 120.0))))
                phi2 = dt * dt * (0.5 + x * (1.0 / 6.0 + x * (1.0 / 24.0 + x * (1.0 / 120.0 + x / 720.0))))
            else:
                phi1 = np.expm1(x) / rates_per_s[j]
                phi2 = (phi1 - dt) / rates_per_s[j]
            growth += coupling[j] * (phi1 * y[j] + coupling[j] * slope * phi2)
            y[j] = np.exp(x) * y[j] + coupling[j] * slope * phi1
        se[k + 1] = se[k] + (stress[k + 1] - stress[k]) + growth
    return se


def creep_retardation_basis(g: np.ndarray, taus_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eigen-rates (1/s, <= 0) and input couplings of QLV's branches under stress control.

    With the branch stresses ``h_i`` (``sigma = g_inf sigma_e + sum h_i``, ``h_i' = -h_i/tau_i + g_i sigma_e'``)
    an imposed ``sigma(t)`` gives ``sigma_e' = sigma' + sum h_i/tau_i``. Scaled by ``sqrt(g_i tau_i)`` the states
    obey ``z' = (-diag(1/tau) + u u^T) z + u sigma'`` with ``u_i = sqrt(g_i/tau_i)`` and ``sigma_e' = sigma' + u.z``,
    a symmetric system (the retardation spectrum of :func:`tissuemech.spectra.prony_to_kelvin_voigt` in QLV's
    reduced form). Returns the eigenvalues ``lambda`` of ``-diag(1/tau) + u u^T`` and ``c = Q^T u``. Every
    ``lambda <= 0``; ``lambda = 0`` is the flow mode of a fluid (``g_inf = 0``).
    """
    g = np.asarray(g, float)
    rates = 1.0 / np.asarray(taus_s, float)
    u = np.sqrt(np.clip(g, 0.0, None) * rates)
    lam, q = scipy.linalg.eigh(np.outer(u, u) - np.diag(rates))
    return np.minimum(lam, 0.0), q.T @ u


def stress_controlled_strain(branch_drives: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
                             taus: np.ndarray, time_s: np.ndarray, target: np.ndarray,
                             strain_factors: np.ndarray | None = None,
                             weights: np.ndarray | None = None) -> np.ndarray:
    """Strain history under load control for any "drive" model (QLV, Pipkin-Rogers).

    Drive models have ``sigma = D_inf(gamma) + sum_i h_i``, the branch states ``h_i`` following the exact
    recursion driven by ``D_i(gamma)`` (QLV: ``D_inf = g_inf sigma_e``, ``D_i = g_i sigma_e``;
    Pipkin-Rogers: ``R_inf``, ``R_i``). The controlled quantity is ``Q = sum_j w_j sigma(c_j gamma)``:
    ``c = w = [1]`` for homogeneous shear (creep), Gauss radii ``c_j = r_j/R`` and torque weights for a
    torque-controlled plate (:func:`tissuemech.models.plate.creep_rim_strain`). Per step the scalar
    equation ``Q(gamma_{n+1}) = target_{n+1}`` is solved by safeguarded secant iterations (science.md
    section 1.0), bracketed by expansion when needed; the states are then updated. Python loop over steps
    (each iteration one vectorised drive evaluation over the radii).

    Parameters
    ----------
    branch_drives : ``gamma (k,) -> (D_inf (k,), D (m, k))`` in Pa
    taus : (m,) relaxation times in s
    time_s, target : (n,) imposed history of Q (Pa)
    strain_factors, weights : (k,) radial strain factors and weights (default homogeneous)
    """
    t = np.asarray(time_s, float)
    target = np.asarray(target, float)
    c = np.ones(1) if strain_factors is None else np.asarray(strain_factors, float)
    w = np.ones(1) if weights is None else np.asarray(weights, float)
    taus = np.asarray(taus, float)

    def evaluate(gamma, h_rel, d_old):
        d_inf, d = branch_drives(gamma * c)
        return float(w @ (d_inf + (h_rel + f_fac[:, None] * (d - d_old)).sum(axis=0))), d

    gamma_hist = np.empty(t.size)
    # first sample: an instantaneous step from the virgin state, h_i = D_i(gamma_0)
    f_fac = np.ones(taus.size)
    zero_h = np.zeros((taus.size, c.size))
    zero_d = np.zeros((taus.size, c.size))
    g0 = _solve_scalar(lambda g: evaluate(g, zero_h, zero_d)[0] - target[0], 0.0, 1e-3)
    gamma_hist[0] = g0
    _, h = branch_drives(g0 * c)
    d_old = h.copy()
    for k in range(t.size - 1):
        dt = t[k + 1] - t[k]
        x = dt / taus
        e_fac = np.exp(-x)
        f_fac = np.where(x < 1e-8, 1.0 - 0.5 * x, -np.expm1(-x) / np.maximum(x, 1e-300))
        h_rel = e_fac[:, None] * h
        prev = gamma_hist[k]
        step = prev - gamma_hist[k - 1] if k > 0 else 0.0
        guess2 = prev + step if step != 0.0 else prev + 1e-3 * (1.0 + abs(prev))
        g_new = _solve_scalar(lambda g: evaluate(g, h_rel, d_old)[0] - target[k + 1], prev, guess2)
        gamma_hist[k + 1] = g_new
        _, d_new = branch_drives(g_new * c)
        h = h_rel + f_fac[:, None] * (d_new - d_old)
        d_old = d_new
    return gamma_hist


def stress_controlled_strain_by_history(stress_at_end: Callable[[np.ndarray, np.ndarray], float],
                                        time_s: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Load-controlled strain history for *any* strain-driven model (the generic fallback).

    ``stress_at_end(t[:k+1], gamma[:k+1])`` returns the controlled quantity (Pa) at the last sample of a
    strain history; step ``k`` solves ``stress_at_end(..., gamma_k) = target_k`` with the earlier strains
    fixed (secant iterations, Brent fallback). Each evaluation recomputes the history, so the cost is
    O(n^2) model steps: fine for creep-recovery records of a few hundred to a few thousand samples; drive
    models (QLV, Pipkin-Rogers) use the O(n) :func:`stress_controlled_strain` instead.
    """
    t = np.asarray(time_s, float)
    target = np.asarray(target, float)
    gamma = np.zeros(t.size)
    for k in range(t.size):
        hist = gamma[:k + 1].copy()

        def residual(g, hist=hist, k=k):
            hist[k] = g
            return float(stress_at_end(t[:k + 1], hist)) - target[k]
        prev = gamma[k - 1] if k > 0 else 0.0
        step = prev - gamma[k - 2] if k > 1 else 0.0
        guess2 = prev + step if step != 0.0 else prev + 1e-3 * (1.0 + abs(prev))
        gamma[k] = _solve_scalar(residual, prev, guess2)
    return gamma


def _solve_scalar(fun: Callable[[float], float], x0: float, x1: float, tol: float = 1e-13,
                  max_iter: int = 60) -> float:
    """Root of an increasing scalar function: secant from (x0, x1), Brent on an expanded bracket if needed."""
    f0, f1 = fun(x0), fun(x1)
    for _ in range(max_iter):
        if f1 == 0.0:
            return x1
        if f1 == f0:
            break
        x2 = x1 - f1 * (x1 - x0) / (f1 - f0)
        if not np.isfinite(x2):
            break
        if abs(x2 - x1) <= tol * (1.0 + abs(x2)):
            return x2
        x0, f0, x1, f1 = x1, f1, x2, fun(x2)
    # fall back: bracket around the best point and use Brent
    lo = hi = x1 if abs(f1) < abs(f0) else x0
    width = 1e-3 * (1.0 + abs(lo))
    while fun(lo) > 0.0:
        lo -= width
        width *= 2.0
        if width > 1e6:
            raise ValueError("stress-controlled step: no bracket found (non-monotone law?)")
    width = 1e-3 * (1.0 + abs(hi))
    while fun(hi) < 0.0:
        hi += width
        width *= 2.0
        if width > 1e6:
            raise ValueError("stress-controlled step: no bracket found (non-monotone law?)")
    return scipy.optimize.brentq(fun, lo, hi, xtol=1e-15, rtol=4.5e-16)


# ----------------------------------------------------------------------------------------------------------
# a linear instantaneous law (small-strain shear), the thesis's "if sigma_e were linear" case
# ----------------------------------------------------------------------------------------------------------
@dataclass
class LinearElasticShear(hyperelastic.LinearElasticShear):
    """Linear elastic shear ``sigma_e = G0 gamma`` (Pa) as a QLV instantaneous law: the one linear-elastic law
    (:class:`tissuemech.models.hyperelastic.LinearElasticShear`) with the QLV family's defaults -- the modulus named
    ``G0`` with its bounds, and only the ``elastic_shear`` response (no normal stresses: small-strain theory),
    as in the fit records and cards of the ``qlv_linear_*`` models."""

    name: str = "linear_elastic_shear"
    param_specs: tuple[ParamSpec, ...] = (ParamSpec("G0", "Pa", 200.0, 1.0e-2, 1.0e7, True,
                                                    "instantaneous shear modulus"),)
    responses: frozenset[str] = frozenset({"elastic_shear"})


# ----------------------------------------------------------------------------------------------------------
# QLV
# ----------------------------------------------------------------------------------------------------------
class QLVModel(InstantaneousLawModel):
    """Fung QLV: reduced Prony relaxation function on an instantaneous elastic law.

    Parameters
    ----------
    instantaneous : elastic law supporting ``elastic_shear`` (its parameters are taken over unchanged)
    n_prony : number of Prony branches
    taus_s : fixed relaxation times (s); default :func:`default_taus`. Ignored when ``free_taus``.
    free_taus : fit ``tau_1..tau_n`` (initial values ``taus_s``/defaults)
    name : registry key / display name

    Parameters (the mapping ``p``): the instantaneous law's, ``beta_1..beta_n`` (see module docstring),
    and ``tau_1..tau_n`` when ``free_taus``.

    Responses: ``shear_history`` (plus the batched :meth:`shear_stress_histories` used by the plate
    quadrature), ``creep`` (homogeneous stress control), ``oscillation`` (small-strain limit),
    ``elastic_shear`` (the instantaneous law) and, when the instantaneous law has them, ``normal_stress``
    (instantaneous N1, N2; their QLV histories via :meth:`normal_stress_difference_histories`).
    """

    concatenated_histories = True
    #: one reduced relaxation function acts on sigma_e at every strain: a plate's torque is the QLV response of the
    #: plate's elastic torque (:func:`tissuemech.models.plate.creep_rim_strain`)
    separable: ClassVar[bool] = True

    def __init__(self, instantaneous: ConstitutiveModel, n_prony: int = 4, taus_s: Sequence[float] | None = None,
                 free_taus: bool = False, name: str | None = None, fluid: bool = False):
        if not instantaneous.supports("elastic_shear"):
            raise ValueError(f"instantaneous law {instantaneous.name!r} has no elastic_shear response")
        if n_prony < 1:
            raise ValueError("n_prony must be >= 1")
        taus = default_taus(n_prony) if taus_s is None else np.asarray(taus_s, float)
        if taus.shape != (n_prony,) or np.any(taus <= 0):
            raise ValueError(f"need {n_prony} positive relaxation times, got {taus!r}")
        if fluid and free_taus:
            raise ValueError("a fluid QLV model has fixed relaxation times")
        if fluid:
            # the slowest branch is the reference (its modulus ratio is 1): the terminal relaxation of a fluid
            taus = np.sort(taus)
        specs = check_param_names(instantaneous.param_specs, prony_ratio_specs(n_prony - 1 if fluid else n_prony),
                                  tau_specs(n_prony, taus) if free_taus else ())
        responses = {"shear_history", "creep", "oscillation", "elastic_shear"}
        if instantaneous.supports("normal_stress"):
            responses.add("normal_stress")
        weights = ("beta_i = G_i/G_n (n: the slowest branch); g_i = beta_i/(1+sum beta), g_n = 1/(1+sum beta), "
                   "g_inf = 0" if fluid else "beta_i = G_i/G_inf; g_i = beta_i/(1+sum beta)")
        super().__init__(name=name or f"qlv_{instantaneous.name}_{'fluid' if fluid else 'prony'}{n_prony}",
                         family="qlv", param_specs=specs, responses=frozenset(responses),
                         structure={"instantaneous": instantaneous.name, "n_prony": n_prony,
                                    "free_taus": bool(free_taus),
                                    "taus_s": None if free_taus else [float(t) for t in taus],
                                    "weights": weights, **({"fluid": True} if fluid else {})})
        self.instantaneous = instantaneous
        self.n_prony = n_prony
        self.free_taus = bool(free_taus)
        self.fluid = bool(fluid)
        self._taus = taus

    # --- parameter views ----------------------------------------------------------------------------
    def taus(self, p: Params) -> np.ndarray:
        """Relaxation times (s)."""
        if self.free_taus:
            return np.array([float(p[f"tau_{i + 1}"]) for i in range(self.n_prony)])
        return self._taus.copy()

    def prony_weights(self, p: Params) -> tuple[float, np.ndarray, np.ndarray]:
        """``(g_inf, g, taus)`` of the reduced relaxation function G_r(t) = g_inf + sum g_i exp(-t/tau_i)
        (``g_inf = 0`` for a fluid)."""
        n_beta = self.n_prony - 1 if self.fluid else self.n_prony
        beta = np.array([float(p[f"beta_{i + 1}"]) for i in range(n_beta)])
        if np.any(beta < 0):
            raise ValueError(f"Prony ratios beta must be >= 0, got {beta}")
        denom = 1.0 + beta.sum()
        if self.fluid:
            return 0.0, np.append(beta, 1.0) / denom, self.taus(p)
        return 1.0 / denom, beta / denom, self.taus(p)

    def instantaneous_params(self, p: Params) -> dict[str, float]:
        return sub_params(self.instantaneous, p)

    # --- responses ----------------------------------------------------------------------------------
    def elastic_shear_stress(self, p: Params, strain: np.ndarray) -> np.ndarray:
        """Instantaneous elastic law sigma_e(gamma) (Pa)."""
        return elastic_stress_nd(self.instantaneous, self.instantaneous_params(p), strain)

    def branch_drives(self, p: Params) -> tuple[Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]], np.ndarray]:
        """``(gamma -> (g_inf sigma_e, g_i sigma_e), taus)`` for :func:`stress_controlled_strain`."""
        g_inf, g, taus = self.prony_weights(p)
        law, law_p = self.instantaneous, self.instantaneous_params(p)
        g = g[:, None]

        def drives(gamma):
            se = np.asarray(law.elastic_shear_stress(law_p, gamma), float)
            return g_inf * se, g * se
        return drives, taus

    def relaxed_stress(self, p: Params, time_s: np.ndarray, elastic_stress: np.ndarray,
                       restart: np.ndarray | None = None) -> np.ndarray:
        """QLV stress (Pa) of elastic-stress histories ``elastic_stress`` (k, n) on one time grid (n,): the reduced
        relaxation function applied to them (any quantity linear in sigma_e, e.g. a plate's apparent elastic stress);
        ``restart`` as in :meth:`shear_stress_histories`."""
        _, g, taus = self.prony_weights(p)
        return qlv_stress_batch(time_s, elastic_stress, g, taus, restart)

    def shear_stress_histories(self, p: Params, time_s: np.ndarray, strain: np.ndarray,
                               restart: np.ndarray | None = None) -> np.ndarray:
        """QLV stress (Pa) of a batch of strain histories ``strain`` (k, n) on one time grid ``time_s`` (n,).

        ``restart`` (n,) marks where concatenated histories start (:func:`.recursion.history_starts`).
        """
        _, g, taus = self.prony_weights(p)
        strain = np.atleast_2d(np.asarray(strain, float))
        return qlv_stress_batch(time_s, self.elastic_shear_stress(p, strain), g, taus, restart)

    def shear_stress_history(self, p: Params, time_s: np.ndarray, strain: np.ndarray) -> np.ndarray:
        return self.shear_stress_histories(p, time_s, np.asarray(strain, float)[None, :])[0]

    def step_relaxation_stress(self, p: Params, time_s: np.ndarray, strain0: float) -> np.ndarray:
        """Closed form for an ideal step to ``strain0`` at t = 0: sigma_e(gamma0) G_r(t) (QLV separability)."""
        g_inf, g, taus = self.prony_weights(p)
        t = np.asarray(time_s, float)
        g_r = g_inf + np.sum(g[:, None] * np.exp(-t[None, :] / taus[:, None]), axis=0)
        return float(self.elastic_shear_stress(p, np.array([strain0]))[0]) * g_r

    def elastic_stress_for(self, p: Params, time_s: np.ndarray, stress_pa: np.ndarray) -> np.ndarray:
        """The elastic-stress history sigma_e(t) (Pa) whose QLV response is the imposed ``stress_pa(time_s)``.

        Exact for an imposed stress linear between samples (:func:`creep_retardation_basis`), so a sparse sample
        grid (a creep logged at a few points a decade) costs no accuracy; one compiled pass. Because QLV applies
        one reduced relaxation function to sigma_e, the same holds for any quantity linear in sigma_e (the plate's
        apparent rim stress: :func:`tissuemech.models.plate.creep_rim_strain`).
        """
        _, g, taus = self.prony_weights(p)
        rates, coupling = creep_retardation_basis(g, taus)
        return _qlv_creep_elastic_kernel(np.ascontiguousarray(time_s, dtype=float),
                                         np.ascontiguousarray(stress_pa, dtype=float), rates, coupling)

    def creep_strain(self, p: Params, time_s: np.ndarray, stress_pa: np.ndarray) -> np.ndarray:
        """Strain under a homogeneous imposed stress history (stress control, e.g. creep-recovery).

        :meth:`elastic_stress_for`, then the strain by inverting the (monotone) instantaneous law -- the per-step
        scalar Newton of science.md section 1.0 collapses to this inversion. ``forward(creep(stress))`` returns
        ``stress`` to the accuracy of the forward recursion (exact for an elastic stress linear between samples,
        which a creep's is not: second order in the step).
        """
        return invert_monotone(lambda x: self.elastic_shear_stress(p, x), self.elastic_stress_for(p, time_s, stress_pa))

    def complex_modulus(self, p: Params, angular_frequency_rad_s: np.ndarray) -> np.ndarray:
        """Small-strain G*(omega) = G0 [g_inf + sum g_i i omega tau_i/(1 + i omega tau_i)], G0 = sigma_e'(0)."""
        g_inf, g, taus = self.prony_weights(p)
        g0 = initial_shear_modulus(self.instantaneous, self.instantaneous_params(p))
        iwt = 1j * np.asarray(angular_frequency_rad_s, float)[None, :] * taus[:, None]
        return g0 * (g_inf + np.sum(g[:, None] * iwt / (1.0 + iwt), axis=0))

    def normal_stress_difference_histories(self, p: Params, time_s: np.ndarray,
                                           strain: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """QLV applied to N1 and N2 of the instantaneous law for strain histories (k, n) -> two (k, n) arrays.

        Same reduced relaxation function as the shear stress (isotropic QLV on the extra stress); note
        that N1 = gamma sigma_12 (universal relation) then no longer holds during relaxation.
        """
        if not self.supports("normal_stress"):
            self._unsupported("normal_stress")
        _, g, taus = self.prony_weights(p)
        strain = np.atleast_2d(np.asarray(strain, float))
        n1, n2 = self.instantaneous.normal_stress_differences(self.instantaneous_params(p), strain.ravel())
        n1 = np.asarray(n1, float).reshape(strain.shape)
        n2 = np.asarray(n2, float).reshape(strain.shape)
        return qlv_stress_batch(time_s, n1, g, taus), qlv_stress_batch(time_s, n2, g, taus)


def qlv_params(model: QLVModel, instantaneous_params: Mapping[str, float], g: Sequence[float],
               taus_s: Sequence[float] | None = None) -> dict[str, float]:
    """Parameter mapping for ``model`` from published Prony weights ``g_i`` (``sum g < 1``; a fluid model's
    weights sum to 1, in the order of its ascending times).

    Example: the thesis series ``g = (0.00033, 0.23447, 0.21368, 0.14447)`` with a linear law
    ``{"G0": 200.0}``.
    """
    g = np.asarray(g, float)
    p = {k: float(v) for k, v in instantaneous_params.items()}
    if getattr(model, "fluid", False):
        # weights in the order of the model's (ascending) times; they sum to 1, the slowest is the reference
        if g.shape != (model.n_prony,) or np.any(g < 0) or not np.isclose(g.sum(), 1.0) or g[-1] <= 0:
            raise ValueError(f"a fluid needs {model.n_prony} weights g >= 0 summing to 1 (the slowest > 0), got {g}")
        p.update({f"beta_{i + 1}": float(gi / g[-1]) for i, gi in enumerate(g[:-1])})
        return p
    if g.shape != (model.n_prony,) or np.any(g < 0) or g.sum() >= 1.0:
        raise ValueError(f"need {model.n_prony} weights g >= 0 with sum < 1, got {g}")
    g_inf = 1.0 - g.sum()
    p.update({f"beta_{i + 1}": float(gi / g_inf) for i, gi in enumerate(g)})
    if model.free_taus:
        if taus_s is None:
            raise ValueError("model has free relaxation times: pass taus_s")
        p.update({f"tau_{i + 1}": float(t) for i, t in enumerate(taus_s)})
    elif taus_s is not None and not np.allclose(taus_s, model.taus({})):
        raise ValueError(f"model has fixed taus {model.taus({})}, got {list(taus_s)}")
    return p


# ----------------------------------------------------------------------------------------------------------
# registry
# ----------------------------------------------------------------------------------------------------------
#: short instantaneous-law tag in QLV/beyond-QLV keys -> hyperelastic registry key
INSTANTANEOUS_KEYS = {
    "neo_hookean": "neo_hookean",
    "gent": "gent",
    "exp": "exponential",
    "mooney_rivlin": "mooney_rivlin",
    "rp2": "reduced_polynomial2",
    "rp3": "reduced_polynomial3",
    "rp4": "reduced_polynomial4",
    "lp2": "lopez_pamies2",
    "ogden1": "ogden1",
}


def instantaneous_law(tag: str) -> ConstitutiveModel:
    """Instantaneous law by short tag: ``linear`` (built in) or a hyperelastic model
    (``hyperelastic.MODELS``; this module does not go through the registry, which imports it)."""
    if tag == "linear":
        return LinearElasticShear()
    return hyperelastic.MODELS[INSTANTANEOUS_KEYS[tag]]()


def available_instantaneous_tags() -> tuple[str, ...]:
    """Tags whose instantaneous law exists (``linear`` always; hyperelastic ones that family registers),
    so no key is registered for a law that cannot be built."""
    known = hyperelastic.MODELS
    return ("linear", *(tag for tag, key in INSTANTANEOUS_KEYS.items() if key in known))


def _qlv_factory(tag: str, n: int) -> Callable[[], QLVModel]:
    key = f"qlv_{tag}_prony{n}"
    return lambda: QLVModel(instantaneous_law(tag), n_prony=n, name=key)


MODELS: dict[str, Callable[[], ConstitutiveModel]] = {
    f"qlv_{tag}_prony4": _qlv_factory(tag, 4) for tag in available_instantaneous_tags()
}
MODELS["qlv_linear_prony4_free"] = lambda: QLVModel(LinearElasticShear(), 4, free_taus=True,
                                                    name="qlv_linear_prony4_free")
