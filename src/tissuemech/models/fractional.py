"""Fractional (springpot-based) linear viscoelastic models and fractional QLV, ``science.md`` section 1.6.

Models (parameters in Pa, Pa s^alpha, s; ``0 < alpha < 1``):

* ``springpot`` (c, alpha): G* = c (i w)^alpha, G(t) = c t^-alpha / Gamma(1 - alpha),
  J(t) = t^alpha / (c Gamma(1 + alpha))
* ``fractional_kelvin_voigt`` (G_e, c, alpha): G* = G_e + c (i w)^alpha, G(t) = G_e + c t^-alpha/Gamma(1 - alpha),
  J(t) = (1 - E_alpha(-(G_e/c) t^alpha)) / G_e = (t^alpha/c) E_{alpha,1+alpha}(-(G_e/c) t^alpha)
  (= t^alpha/(c Gamma(1 + alpha)) at G_e = 0)
* ``fractional_zener`` (G_e, G_m, tau, alpha): G* = G_e + G_m (i w tau)^alpha / (1 + (i w tau)^alpha),
  G(t) = G_e + G_m E_alpha(-(t/tau)^alpha),
  J(t) = 1/G_e - (1/G_e - 1/G_0) E_alpha(-(G_e/G_0) (t/tau)^alpha), G_0 = G_e + G_m
  (alpha = 1: the standard linear solid ``sls2`` with G1 = G_e, G2 = G_m, eta1 = G_m tau)
* ``qlv_<law>_fzener`` (law parameters, beta_fz, tau_fz, alpha_fz): Fung QLV whose reduced relaxation function
  is a fractional Zener, G_r(t) = g_inf + (1 - g_inf) E_alpha(-(t/tau)^alpha), g_inf = 1/(1 + beta_fz)
  (``beta_fz`` = G_m/G_e >= 0, as the ``beta_i`` of :mod:`tissuemech.models.qlv`), on every instantaneous
  law of the QLV registry (``linear``, ``neo_hookean``, ...).

E_{a,b}(z) is the two-parameter Mittag-Leffler function, evaluated by ``pymittagleffler`` (Garrappa 2015,
doi:10.1137/140971191, accurate to ~1e-15 relative on the negative real axis).

Responses: ``oscillation``, ``shear_history`` (any strain history: ramps with their rise time, constant shear
rate, relaxation with finite rise, oscillation in time) and ``creep`` (any piecewise-linear stress history);
the QLV models add ``elastic_shear`` (and ``normal_stress`` when the law has it).

Arbitrary histories (:func:`hereditary_response`): Boltzmann superposition of the kernel K (G for strain
control, J for stress control) over the input history x(t), taken as piecewise linear between samples with a
step from the virgin state to ``x[0]`` at ``t[0]``::

    y(t_k) = x_0 K(t_k - t_0) + sum_j s_j [Kbar(t_k - t_j) - Kbar(t_k - t_{j+1})],  Kbar(t) = int_0^t K(u) du

with the slope ``s_j`` of segment ``[t_j, t_{j+1}]``. The segment integrals are exact through the closed forms
of Kbar: int_0^t E_a(-(u/tau)^a) du = t E_{a,2}(-(t/tau)^a) and int_0^t u^-a du = t^(1-a)/(1-a), so the only
error is that of the Mittag-Leffler evaluation (ramp-and-hold responses agree with adaptive quadrature of
the hereditary integral to the tested relative 1e-6, ``tests/models/test_fractional.py``). Creep uses the same superposition with J and Jbar
(exact for a piecewise-linear stress, no time stepping). QLV uses it on the elastic-stress history
sigma_e(gamma(t)); QLV creep is sigma_e = int J_r d sigma (J_r the creep compliance of the reduced Zener)
followed by the inversion of the monotone law.

Cost: the superposition needs Kbar at every lag ``t_k - t_j`` between a sample and an end point of a segment
whose input changes; segments where the input is constant (the hold of an ideal ramp or step) cost nothing,
and identical lags (uniform sampling) are evaluated once. A non-uniformly sampled history whose input changes
everywhere costs ~n^2/2 Mittag-Leffler evaluations (~20 us each): ~1 s for n = 300 samples, so long measured
records with noisy holds are slow to fit; use the ``ramp``/``step`` relaxation treatments or resample.
"""
from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from pymittagleffler import mittag_leffler as garrappa_mittag_leffler
import scipy
from scipy.special import gamma as gamma_fn

from .base import ConstitutiveModel, InstantaneousLawModel, ParamSpec, Params, initial_shear_modulus
from .qlv import (available_instantaneous_tags, check_param_names, elastic_stress_nd, instantaneous_law,
                  invert_monotone, sub_params)

Kernel = Callable[[np.ndarray], np.ndarray]


# ------------------------------------------------------------------------------------------------------
# Mittag-Leffler function and the closed-form kernels
# ------------------------------------------------------------------------------------------------------
#: the last few evaluations of :func:`mittag_leffler` on large arrays, keyed by (alpha, beta, the bytes of z) and
#: checked element for element on a hit, so a hit returns exactly what a new evaluation would. A least-squares
#: fit of a fractional Zener perturbs G_e and G_m for its finite-difference Jacobian without changing
#: z = -(t/tau)^alpha, so those columns reuse the evaluation of the point they are taken at.
_ML_CACHE: OrderedDict[tuple, tuple[np.ndarray, np.ndarray]] = OrderedDict()
_ML_CACHE_ENTRIES = 8
_ML_CACHE_MIN_SIZE = 256
#: arrays of at least this many arguments ``z <= 0`` are evaluated on a grid in log(-z) and interpolated
#: (:func:`_mittag_leffler_negative_spline`): a relaxation of a few hundred samples with a noisy measured strain has
#: tens of thousands of distinct lags, and Garrappa's method costs ~5 us per argument
_ML_SPLINE_MIN_SIZE = 4096
#: spline nodes per decade of -z: the largest error seen over alpha 0.05-0.99, beta 1-3, -z 1e-8-1e4 was 3e-10
_ML_SPLINE_NODES_PER_DECADE = 128
#: the spline is used only if it agrees with the exact function at the check points to this (times max |E|)
_ML_SPLINE_TOLERANCE = 1e-9


def mittag_leffler(z: np.ndarray, alpha: float, beta: float = 1.0) -> np.ndarray:
    """Two-parameter Mittag-Leffler function ``E_{alpha,beta}(z)`` for real ``z`` (real result, same shape).

    Garrappa's method (``pymittagleffler``). ``E_{1,1}(z) = exp(z)``; ``E_{1/2,1}(-x) = exp(x^2) erfc(x)``.
    A repeated call on the same large ``z`` is answered from a small cache (``_ML_CACHE``, exact). Large arrays of
    ``z <= 0`` are interpolated between exact values, checked to 1e-9 of ``max |E|``
    (:func:`_mittag_leffler_negative_spline`).
    """
    z = np.asarray(z, float)
    flat = np.ascontiguousarray(z.ravel())
    if flat.size == 0:
        return np.zeros(z.shape)
    key = (float(alpha), float(beta), flat.size, hash(flat.tobytes()))
    cached = _ML_CACHE.get(key)
    if cached is not None and np.array_equal(cached[0], flat):
        _ML_CACHE.move_to_end(key)
        return cached[1].reshape(z.shape).copy()
    out = _mittag_leffler_negative_spline(flat, float(alpha), float(beta)) if flat.size >= _ML_SPLINE_MIN_SIZE else None
    if out is None:
        out = _garrappa(flat, float(alpha), float(beta))
    # E_{a,b}(0) = 1/Gamma(b) exactly (pymittagleffler 0.3.0 returns NaN at z = 0 for alpha = 1, beta = 2)
    out = np.where(flat == 0.0, 1.0 / gamma_fn(beta), out)
    if flat.size >= _ML_CACHE_MIN_SIZE:
        _ML_CACHE[key] = (flat.copy(), out.copy())
        while len(_ML_CACHE) > _ML_CACHE_ENTRIES:
            _ML_CACHE.popitem(last=False)
    return out.reshape(z.shape)


def _garrappa(z: np.ndarray, alpha: float, beta: float) -> np.ndarray:
    return np.real(np.asarray(garrappa_mittag_leffler(np.ascontiguousarray(z, dtype=float), alpha, beta)))


def _mittag_leffler_negative_spline(z: np.ndarray, alpha: float, beta: float) -> np.ndarray | None:
    """``E_{alpha,beta}(z)`` for many ``z <= 0`` by a cubic spline in ``log10(-z)`` through exact values, or ``None``.

    ``x -> E_{alpha,beta}(-x)`` is smooth in ``log x`` (completely monotone for ``0 < alpha <= 1 <= beta``), so
    :data:`_ML_SPLINE_NODES_PER_DECADE` exact nodes per decade reproduce it to ~1e-10. The spline is checked
    against exact values at the midpoints of every fourth node interval (where a cubic spline's error peaks) and
    refused (``None``: evaluate exactly) when one differs by more than :data:`_ML_SPLINE_TOLERANCE` times the
    largest node value, or when some ``z > 0`` or ``alpha`` is outside (0, 1].
    """
    if not (0.0 < alpha <= 1.0) or np.any(z > 0.0) or not np.all(np.isfinite(z)):
        return None
    out = np.empty(z.size)
    on_grid = z < 0.0
    out[~on_grid] = 0.0  # E(0) = 1/Gamma(beta) is set by the caller
    if not on_grid.any():
        return out
    log_x = np.log10(-z[on_grid])
    lo, hi = float(log_x.min()), float(log_x.max())
    n_nodes = max(8, int(np.ceil((hi - lo) * _ML_SPLINE_NODES_PER_DECADE)) + 1)
    if 2 * n_nodes > z.size:
        return None
    nodes = np.linspace(lo, hi, n_nodes)
    values = _garrappa(-(10.0 ** nodes), alpha, beta)
    spline = scipy.interpolate.CubicSpline(nodes, values)
    checks = 0.5 * (nodes[:-1] + nodes[1:])[::4]
    error = np.max(np.abs(spline(checks) - _garrappa(-(10.0 ** checks), alpha, beta)))
    if not error <= _ML_SPLINE_TOLERANCE * np.max(np.abs(values)):
        return None
    out[on_grid] = spline(log_x)
    return out


def mittag_leffler_neg(alpha: float, x: np.ndarray) -> np.ndarray:
    """``E_alpha(-x^alpha)`` for ``0 < alpha <= 1`` and ``x >= 0`` (the completely monotone relaxation shape)."""
    x = np.atleast_1d(np.asarray(x, float))
    return mittag_leffler(-(x ** alpha), alpha, 1.0)


def springpot_relaxation(time_s: np.ndarray, c: float, alpha: float) -> np.ndarray:
    """G(t) = c t^-alpha / Gamma(1 - alpha) in Pa (``c`` in Pa s^alpha); infinite at t = 0."""
    t = np.asarray(time_s, float)
    with np.errstate(divide="ignore"):
        return c * t ** -alpha / gamma_fn(1.0 - alpha)


def springpot_relaxation_integral(time_s: np.ndarray, c: float, alpha: float) -> np.ndarray:
    """int_0^t G = c t^(1-alpha) / Gamma(2 - alpha) in Pa s."""
    return c * np.asarray(time_s, float) ** (1.0 - alpha) / gamma_fn(2.0 - alpha)


def springpot_creep(time_s: np.ndarray, c: float, alpha: float) -> np.ndarray:
    """J(t) = t^alpha / (c Gamma(1 + alpha)) in 1/Pa."""
    return np.asarray(time_s, float) ** alpha / (c * gamma_fn(1.0 + alpha))


def springpot_creep_integral(time_s: np.ndarray, c: float, alpha: float) -> np.ndarray:
    """int_0^t J = t^(1+alpha) / (c Gamma(2 + alpha)) in s/Pa."""
    return np.asarray(time_s, float) ** (1.0 + alpha) / (c * gamma_fn(2.0 + alpha))


def fkv_creep(time_s: np.ndarray, g_e: float, c: float, alpha: float) -> np.ndarray:
    """Creep compliance of the fractional Kelvin-Voigt model (1/Pa).

    J(t) = (1 - E_alpha(-z))/G_e with z = (G_e/c) t^alpha, written without cancellation as
    J(t) = (t^alpha/c) E_{alpha,1+alpha}(-z) (``E_{a,1}(-z) = 1 - z E_{a,1+a}(-z)``); ``g_e = 0`` gives the
    springpot's t^alpha/(c Gamma(1 + alpha)).
    """
    t = np.asarray(time_s, float)
    ta = t ** alpha
    return ta / c * mittag_leffler(-(g_e / c) * ta, alpha, 1.0 + alpha)


def fkv_creep_integral(time_s: np.ndarray, g_e: float, c: float, alpha: float) -> np.ndarray:
    """int_0^t J of the fractional Kelvin-Voigt model (s/Pa): (t^(1+alpha)/c) E_{alpha,2+alpha}(-(G_e/c) t^alpha)."""
    t = np.asarray(time_s, float)
    ta = t ** alpha
    return t * ta / c * mittag_leffler(-(g_e / c) * ta, alpha, 2.0 + alpha)


def fzener_relaxation(time_s: np.ndarray, g_e: float, g_m: float, tau_s: float, alpha: float) -> np.ndarray:
    """G(t) = G_e + G_m E_alpha(-(t/tau)^alpha) in Pa."""
    t = np.asarray(time_s, float)
    return g_e + g_m * mittag_leffler(-(t / tau_s) ** alpha, alpha, 1.0)


def fzener_relaxation_integral(time_s: np.ndarray, g_e: float, g_m: float, tau_s: float, alpha: float) -> np.ndarray:
    """int_0^t G = G_e t + G_m t E_{alpha,2}(-(t/tau)^alpha) in Pa s."""
    t = np.asarray(time_s, float)
    return g_e * t + g_m * t * mittag_leffler(-(t / tau_s) ** alpha, alpha, 2.0)


def fzener_creep(time_s: np.ndarray, g_e: float, g_m: float, tau_s: float, alpha: float) -> np.ndarray:
    """Creep compliance of the fractional Zener model (1/Pa), G_0 = G_e + G_m, w = (G_e/G_0)(t/tau)^alpha.

    J(t) = 1/G_e - (1/G_e - 1/G_0) E_alpha(-w), written without cancellation as
    J(t) = 1/G_0 + (G_m/G_0^2) (t/tau)^alpha E_{alpha,1+alpha}(-w) (valid for ``g_e = 0`` too: fractional Maxwell).
    """
    t = np.asarray(time_s, float)
    g0 = g_e + g_m
    x = (t / tau_s) ** alpha
    return 1.0 / g0 + g_m / g0 ** 2 * x * mittag_leffler(-(g_e / g0) * x, alpha, 1.0 + alpha)


def fzener_creep_integral(time_s: np.ndarray, g_e: float, g_m: float, tau_s: float, alpha: float) -> np.ndarray:
    """int_0^t J of the fractional Zener model (s/Pa): t/G_0 + (G_m/G_0^2) t (t/tau)^alpha E_{alpha,2+alpha}(-w)."""
    t = np.asarray(time_s, float)
    g0 = g_e + g_m
    x = (t / tau_s) ** alpha
    return t / g0 + g_m / g0 ** 2 * t * x * mittag_leffler(-(g_e / g0) * x, alpha, 2.0 + alpha)


# ------------------------------------------------------------------------------------------------------
# Boltzmann superposition over piecewise-linear histories
# ------------------------------------------------------------------------------------------------------
def _on_unique_lags(fun: Kernel, lags: np.ndarray, t_scale: float) -> np.ndarray:
    """``fun`` on an array of lags >= 0, evaluated once per distinct lag (lags equal to a few ulps of the
    time scale are merged: their difference is below double precision of the time stamps themselves)."""
    quantum = 8.0 * np.finfo(float).eps * max(t_scale, np.finfo(float).tiny)
    keys = np.rint(lags / quantum).astype(np.int64)
    _, first, inverse = np.unique(keys.ravel(), return_index=True, return_inverse=True)
    values = np.asarray(fun(lags.ravel()[first]), float)
    return values[inverse].reshape(lags.shape)


def hereditary_response(time_s: np.ndarray, history: np.ndarray, kernel: Kernel,
                        kernel_integral: Kernel) -> np.ndarray:
    """Boltzmann superposition ``y(t) = int_{0-}^t K(t - s) dx(s)`` for histories piecewise linear in time.

    Parameters
    ----------
    time_s : (n,) strictly increasing sample times [s]
    history : (n,) or (m, n) input histories x (strain [1] with K = G [Pa]; stress [Pa] with K = J [1/Pa]);
        ``x[0]`` is reached by a step from the virgin state at ``t[0]``, linear between samples
    kernel : K(lag) for lags >= 0 (vectorised); only called when some ``x[0] != 0``
    kernel_integral : Kbar(lag) = int_0^lag K (vectorised, Kbar(0) = 0)

    Returns
    -------
    y at every sample, same shape as ``history`` (units of K times x). The segment integrals are exact
    through Kbar (see the module docstring); cost: Kbar at every distinct lag to an end point of a segment
    on which some history changes.
    """
    t = np.asarray(time_s, float)
    x = np.asarray(history, float)
    one = x.ndim == 1
    x = np.atleast_2d(x)
    if t.ndim != 1 or x.shape[1] != t.size:
        raise ValueError(f"history shape {np.shape(history)} does not match {t.size} time samples")
    if t.size > 1 and np.any(np.diff(t) <= 0):
        raise ValueError("time_s must be strictly increasing")
    out = np.zeros(x.shape)
    t_scale = float(np.max(np.abs(t))) if t.size else 1.0
    step = x[:, 0]
    if np.any(step != 0.0):
        k_step = _on_unique_lags(kernel, t - t[0], t_scale)
        with np.errstate(invalid="ignore"):
            out += np.where(step[:, None] != 0.0, step[:, None] * k_step[None, :], 0.0)
    if t.size > 1:
        slopes = np.diff(x, axis=1) / np.diff(t)[None, :]
        active = np.nonzero(np.any(slopes != 0.0, axis=0))[0]
        if active.size:
            ends, where = np.unique(np.r_[active, active + 1], return_inverse=True)
            lags = np.maximum(t[:, None] - t[None, ends], 0.0)
            kbar = _on_unique_lags(kernel_integral, lags, t_scale)
            seg = kbar[:, where[:active.size]] - kbar[:, where[active.size:]]  # (n, n_active)
            out += slopes[:, active] @ seg.T
    return out[0] if one else out


# ------------------------------------------------------------------------------------------------------
# linear fractional models
# ------------------------------------------------------------------------------------------------------
@dataclass
class FractionalModel(ConstitutiveModel):
    """A linear viscoelastic model given by closed-form kernels of its parameters.

    Each ``*_fn`` maps ``(p, time_s)`` to an array: ``relax_fn`` G(t) [Pa], ``relax_integral_fn`` int_0^t G
    [Pa s], ``creep_fn`` J(t) [1/Pa], ``creep_integral_fn`` int_0^t J [s/Pa]; ``gstar_fn(p, omega)`` G* [Pa].
    """

    linear_in_strain = True
    family: str = "fractional"
    responses: frozenset[str] = field(default_factory=lambda: frozenset({"oscillation", "shear_history", "creep"}))
    gstar_fn: Callable | None = None
    relax_fn: Callable | None = None
    relax_integral_fn: Callable | None = None
    creep_fn: Callable | None = None
    creep_integral_fn: Callable | None = None

    def complex_modulus(self, p: Params, angular_frequency_rad_s: np.ndarray) -> np.ndarray:
        return self.gstar_fn(p, np.asarray(angular_frequency_rad_s, float))

    def relaxation_modulus(self, p: Params, time_s: np.ndarray) -> np.ndarray:
        """G(t) in Pa."""
        return np.asarray(self.relax_fn(p, np.asarray(time_s, float)), float)

    def creep_compliance(self, p: Params, time_s: np.ndarray) -> np.ndarray:
        """J(t) in 1/Pa."""
        return np.asarray(self.creep_fn(p, np.asarray(time_s, float)), float)

    def shear_stress_histories(self, p: Params, time_s: np.ndarray, strain: np.ndarray) -> np.ndarray:
        """Shear stress (Pa) of a batch of strain histories (k, n) on one time grid (n,)."""
        return hereditary_response(time_s, np.atleast_2d(np.asarray(strain, float)),
                                   lambda u: self.relax_fn(p, u), lambda u: self.relax_integral_fn(p, u))

    def shear_stress_history(self, p: Params, time_s: np.ndarray, strain: np.ndarray) -> np.ndarray:
        return self.shear_stress_histories(p, time_s, np.asarray(strain, float)[None, :])[0]

    def creep_strain(self, p: Params, time_s: np.ndarray, stress_pa: np.ndarray) -> np.ndarray:
        """Strain under an imposed stress history (Boltzmann superposition of J, exact for piecewise-linear stress)."""
        return hereditary_response(time_s, np.asarray(stress_pa, float), lambda u: self.creep_fn(p, u),
                                   lambda u: self.creep_integral_fn(p, u))


def _alpha(name: str = "alpha") -> ParamSpec:
    return ParamSpec(name, "1", 0.3, 0.01, 0.99, description="fractional order")


def _c():
    return ParamSpec("c", "Pa s^alpha", 100.0, 1e-6, 1e9, log=True, description="springpot quasi-property")


def _mod(name, init):
    return ParamSpec(name, "Pa", init, 1e-4, 1e9, log=True)


def _zener_gstar(g_e, g_m, tau, alpha, w):
    x = (1j * w * tau) ** alpha
    return g_e + g_m * x / (1.0 + x)


def springpot() -> FractionalModel:
    return FractionalModel(
        name="springpot", param_specs=(_c(), _alpha()),
        gstar_fn=lambda p, w: p["c"] * (1j * w) ** p["alpha"],
        relax_fn=lambda p, t: springpot_relaxation(t, p["c"], p["alpha"]),
        relax_integral_fn=lambda p, t: springpot_relaxation_integral(t, p["c"], p["alpha"]),
        creep_fn=lambda p, t: springpot_creep(t, p["c"], p["alpha"]),
        creep_integral_fn=lambda p, t: springpot_creep_integral(t, p["c"], p["alpha"]))


def fractional_kelvin_voigt() -> FractionalModel:
    return FractionalModel(
        name="fractional_kelvin_voigt", param_specs=(_mod("G_e", 100.0), _c(), _alpha()),
        gstar_fn=lambda p, w: p["G_e"] + p["c"] * (1j * w) ** p["alpha"],
        relax_fn=lambda p, t: p["G_e"] + springpot_relaxation(t, p["c"], p["alpha"]),
        relax_integral_fn=lambda p, t: p["G_e"] * t + springpot_relaxation_integral(t, p["c"], p["alpha"]),
        creep_fn=lambda p, t: fkv_creep(t, p["G_e"], p["c"], p["alpha"]),
        creep_integral_fn=lambda p, t: fkv_creep_integral(t, p["G_e"], p["c"], p["alpha"]))


def fractional_zener() -> FractionalModel:
    args = ("G_e", "G_m", "tau", "alpha")
    return FractionalModel(
        name="fractional_zener",
        param_specs=(_mod("G_e", 100.0), _mod("G_m", 100.0), ParamSpec("tau", "s", 0.1, 1e-6, 1e6, log=True),
                     _alpha()),
        gstar_fn=lambda p, w: _zener_gstar(*(p[a] for a in args), w),
        relax_fn=lambda p, t: fzener_relaxation(t, *(p[a] for a in args)),
        relax_integral_fn=lambda p, t: fzener_relaxation_integral(t, *(p[a] for a in args)),
        creep_fn=lambda p, t: fzener_creep(t, *(p[a] for a in args)),
        creep_integral_fn=lambda p, t: fzener_creep_integral(t, *(p[a] for a in args)))


# ------------------------------------------------------------------------------------------------------
# QLV with a fractional Zener reduced relaxation function
# ------------------------------------------------------------------------------------------------------
FZENER_QLV_SPECS = (
    ParamSpec("beta_fz", "1", 1.0, 0.0, 1.0e3, False, "relaxing-to-equilibrium modulus ratio G_m/G_e"),
    ParamSpec("tau_fz", "s", 1.0, 1.0e-4, 1.0e5, True, "Mittag-Leffler relaxation time"),
    _alpha("alpha_fz"),
)


class FractionalZenerQLVModel(InstantaneousLawModel):
    """Fung QLV whose reduced relaxation function is a fractional Zener (see the module docstring).

    Parameters
    ----------
    instantaneous : elastic law supporting ``elastic_shear`` (its parameters are taken over unchanged)
    name : registry key / display name

    Parameters (the mapping ``p``): the law's, ``beta_fz`` (G_m/G_e, >= 0), ``tau_fz`` (s), ``alpha_fz``.
    """

    def __init__(self, instantaneous: ConstitutiveModel, name: str | None = None):
        if not instantaneous.supports("elastic_shear"):
            raise ValueError(f"instantaneous law {instantaneous.name!r} has no elastic_shear response")
        specs = check_param_names(instantaneous.param_specs, FZENER_QLV_SPECS)
        responses = {"shear_history", "creep", "oscillation", "elastic_shear"}
        if instantaneous.supports("normal_stress"):
            responses.add("normal_stress")
        super().__init__(name=name or f"qlv_{instantaneous.name}_fzener", family="qlv", param_specs=specs,
                         responses=frozenset(responses),
                         structure={"instantaneous": instantaneous.name, "reduced_relaxation": "fractional_zener",
                                    "weights": "g_inf = 1/(1+beta_fz); G_r = g_inf + (1-g_inf) E_a(-(t/tau)^a)"})
        self.instantaneous = instantaneous

    def reduced_parts(self, p: Params) -> tuple[float, float, float, float]:
        """``(g_inf, 1 - g_inf, tau_fz [s], alpha_fz)`` of G_r(t) = g_inf + (1 - g_inf) E_a(-(t/tau)^a)."""
        beta = float(p["beta_fz"])
        if beta < 0:
            raise ValueError(f"beta_fz must be >= 0, got {beta}")
        g_inf = 1.0 / (1.0 + beta)
        return g_inf, 1.0 - g_inf, float(p["tau_fz"]), float(p["alpha_fz"])

    def reduced_relaxation(self, p: Params, time_s: np.ndarray) -> np.ndarray:
        """G_r(t) (dimensionless, G_r(0) = 1)."""
        return fzener_relaxation(time_s, *self.reduced_parts(p))

    def instantaneous_params(self, p: Params) -> dict[str, float]:
        return sub_params(self.instantaneous, p)

    def elastic_shear_stress(self, p: Params, strain: np.ndarray) -> np.ndarray:
        return elastic_stress_nd(self.instantaneous, self.instantaneous_params(p), strain)

    def _reduced_response(self, p: Params, time_s: np.ndarray, drive: np.ndarray) -> np.ndarray:
        parts = self.reduced_parts(p)
        return hereditary_response(time_s, drive, lambda u: fzener_relaxation(u, *parts),
                                   lambda u: fzener_relaxation_integral(u, *parts))

    def shear_stress_histories(self, p: Params, time_s: np.ndarray, strain: np.ndarray) -> np.ndarray:
        """QLV stress (Pa) of strain histories (k, n) on one time grid (n,): int G_r(t - s) d sigma_e(s)."""
        strain = np.atleast_2d(np.asarray(strain, float))
        return self._reduced_response(p, time_s, self.elastic_shear_stress(p, strain))

    def shear_stress_history(self, p: Params, time_s: np.ndarray, strain: np.ndarray) -> np.ndarray:
        return self.shear_stress_histories(p, time_s, np.asarray(strain, float)[None, :])[0]

    def creep_strain(self, p: Params, time_s: np.ndarray, stress_pa: np.ndarray) -> np.ndarray:
        """Strain under an imposed stress history: sigma_e = int J_r d sigma (J_r the reduced Zener's creep
        compliance, exact for piecewise-linear stress), then gamma = sigma_e^-1 (monotone law)."""
        parts = self.reduced_parts(p)
        se = hereditary_response(time_s, np.asarray(stress_pa, float), lambda u: fzener_creep(u, *parts),
                                 lambda u: fzener_creep_integral(u, *parts))
        return invert_monotone(lambda x: self.elastic_shear_stress(p, x), se)

    def complex_modulus(self, p: Params, angular_frequency_rad_s: np.ndarray) -> np.ndarray:
        """Small-strain G* = G0 G_r*(omega), G0 = sigma_e'(0)."""
        g0 = initial_shear_modulus(self.instantaneous, self.instantaneous_params(p))
        return g0 * _zener_gstar(*self.reduced_parts(p), np.asarray(angular_frequency_rad_s, float))

    def normal_stress_difference_histories(self, p: Params, time_s: np.ndarray,
                                           strain: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """QLV applied to the law's N1 and N2 for strain histories (k, n) (same reduced function)."""
        if not self.supports("normal_stress"):
            self._unsupported("normal_stress")
        strain = np.atleast_2d(np.asarray(strain, float))
        n1, n2 = self.instantaneous.normal_stress_differences(self.instantaneous_params(p), strain.ravel())
        n1 = np.asarray(n1, float).reshape(strain.shape)
        n2 = np.asarray(n2, float).reshape(strain.shape)
        return self._reduced_response(p, time_s, n1), self._reduced_response(p, time_s, n2)


def _fzener_qlv_factory(tag: str) -> Callable[[], FractionalZenerQLVModel]:
    key = f"qlv_{tag}_fzener"
    return lambda: FractionalZenerQLVModel(instantaneous_law(tag), name=key)


MODELS: dict[str, Callable[[], ConstitutiveModel]] = {
    "springpot": springpot,
    "fractional_kelvin_voigt": fractional_kelvin_voigt,
    "fractional_zener": fractional_zener,
    **{f"qlv_{tag}_fzener": _fzener_qlv_factory(tag) for tag in available_instantaneous_tags()},
}
