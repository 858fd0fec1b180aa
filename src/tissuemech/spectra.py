"""Relaxation and retardation spectra, exact interconversion and Kramers-Kronig consistency (issue 15, item 3).

Science layer: pure functions on numpy arrays (SI units: s, rad/s, Pa, 1/Pa, Pa s); imports only numpy,
scipy, xarray and :mod:`tissuemech.models`.

Spectra by regularised inversion
--------------------------------
A relaxation spectrum is a generalized Maxwell (Prony) series on a dense log-spaced grid of times
``tau_i`` (``per_decade`` per decade, 10 by default),

    G(t)  = G_e + sum_i h_i exp(-t/tau_i),
    G'(w) = G_e + sum_i h_i (w tau_i)^2 / (1 + (w tau_i)^2),    G''(w) = sum_i h_i w tau_i / (1 + (w tau_i)^2),

with discrete weights ``h_i >= 0`` (Pa); the continuous spectrum is ``H(tau_i) = h_i / d ln(tau)`` (Pa), so
that ``G(t) = G_e + int H(tau) exp(-t/tau) d ln tau``. A retardation spectrum is likewise a generalized
Kelvin-Voigt series (``J_g`` glassy compliance, ``j_i >= 0`` in 1/Pa, ``L(tau_i) = j_i / d ln(tau)``,
optional fluidity ``1/eta_0``):

    J(t)  = J_g + sum_i j_i (1 - exp(-t/tau_i)) + t/eta_0,
    J'(w) = J_g + sum_i j_i / (1 + (w tau_i)^2),    J''(w) = sum_i j_i w tau_i / (1 + (w tau_i)^2) + 1/(w eta_0).

* **Grid span (stated rule)**: ``tau`` from ``1/(10 w_max)`` to ``10/w_min`` for frequency data (the
  window widened by one decade on each side: modes just outside it still shape G', G'' polynomially), and
  from ``t_min`` to ``10 t_max`` for time data (``t_min`` the smallest positive time; no widening below it:
  a mode one decade faster than the first sample has decayed by ``exp(-10)`` there, cannot be told from
  zero, and took unbounded weight in trials). Modes outside that span are not identifiable from the data.
* **Fit**: rows are relative residuals (each datum divided by its magnitude, or by its standard deviation
  when one is given), weights ``>= 0`` by NNLS (``scipy.optimize.nnls``), with Tikhonov regularisation
  ``lambda^2 ||D2 h / s||^2`` on the second differences ``D2`` of the spectrum weights (scaled by the largest
  datum ``s``; the equilibrium/glassy/flow terms are not penalised), solved as one stacked NNLS.
* **lambda (stated criterion)**: generalised cross-validation (GCV, Golub, Heath & Wahba 1979) over a
  log grid ``1e-8 .. 10`` (46 values; ``lambda`` is relative to the largest singular value of the weighted kernel): ``V(lambda) = n ||r||^2 / (n - tr A)^2``, with the influence
  matrix ``A`` of the Tikhonov problem restricted to the columns active (``> 0``) at the NNLS solution
  (the constrained estimator is linear on its active set). The smallest ``V`` wins; the whole curve is kept
  (:attr:`Spectrum.lambda_grid`, :attr:`Spectrum.gcv`).
* **Ideal steps**: ``G(t)`` and ``J(t)`` data are taken as responses to an ideal step. A relaxation whose
  strain ramp matters is inverted through its strain history instead (``strain=`` in
  :func:`relaxation_spectrum_from_relaxation`, exact recursion of :mod:`tissuemech.models.recursion`).

Interconversion
---------------
The discrete series interconvert exactly (:func:`prony_to_kelvin_voigt`, :func:`kelvin_voigt_to_prony`):
the retardation (relaxation) times are the eigenvalues of a symmetric matrix (a diagonal minus / plus a
rank-one term, ``scipy.linalg.eigh``), the weights follow from the eigenvectors. Round trips on exact Prony
data agree to ~1e-12 relative (tested to 1e-6). For *data* the route is: data -> regularised spectrum
(above) -> exact interconversion of that discrete series -> any of ``G(t)``, ``G*(w)``, ``J(t)``,
``J*(w)``. Its accuracy is that of the spectrum fit inside the data window (:attr:`Spectrum.rel_rms_residual`):
measured on a 3-mode Prony truth (G', G'' over 6 decades with 1 % noise, 20 noise seeds) J(t) within 0.6 %
and G(t) within 1.2 % for ``t`` inside the window, mode times within 2 % and mode weights within 2 %. Outside
the window (``w`` beyond the ``1/t`` range of the data, or the reverse) the result is an extrapolation and
is marked as such by the consistency functions.

The continuous spectrum itself is identified only in an integral sense: for a power law (springpot,
``H = S tau^-a / Gamma(a)``) H summed over a decade in the middle of a 4-decade sweep is within 5 % on exact
data and within 26 % with 1 % noise (8 noise seeds; most within 10 %), while pointwise H can oscillate by tens
of percent and show holes, most where GCV picks a small ``lambda`` (GCV is known to under-smooth at times). Use :meth:`Spectrum.peaks` or integrals, not single
points of H.

Kramers-Kronig consistency
--------------------------
G' and G'' of a linear viscoelastic material are Kramers-Kronig transforms of each other; any positive Prony
series satisfies them. :func:`kramers_kronig_check` reports the normalised discrepancy (RMS over ``|G*|``)
of the one spectrum fitted to both components (the criterion), and the one-sided predictions G'' from G'
alone and G' from G'' alone (diagnostics, ill-posed at the window edges). :func:`relaxation_predicts_sweep` and
:func:`sweep_predicts_relaxation` do the same across test kinds. All return plain dicts; whether a
discrepancy is "too large" is decided against a ``tolerance`` the caller supplies (e.g. from the measured
scatter); none is assumed.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import xarray as xr
from scipy.linalg import eigh
import scipy

from .canonical import read_netcdf, write_netcdf
from .curves import as_str, select_average
from .models.recursion import prony_branch_histories

#: test kinds whose averaged curves get a relaxation (or retardation) spectrum (:func:`run_spectrum`)
SPECTRUM_TESTS = ("frequency_sweep", "stress_relaxation", "creep_recovery")

#: default density of the inversion grid, times per decade
PER_DECADE = 10
#: decades added on each side of the data window (the grid-span rule of the module docstring)
EXTEND_DECADES = 1.0
#: regularisation parameters scanned by GCV (dimensionless: data rows are relative, weights scaled)
LAMBDA_GRID = np.logspace(-8, 1, 46)


# ------------------------------------------------------------------------------------------------
# grids
# ------------------------------------------------------------------------------------------------
def log_spaced_taus(t_min_s: float, t_max_s: float, per_decade: float = 1.0) -> np.ndarray:
    """Times log-spaced from ``t_min_s`` to ``t_max_s`` inclusive, ``per_decade`` per decade (>= 1 time), s."""
    n = max(int(round(per_decade * math.log10(t_max_s / t_min_s))) + 1, 1)
    return np.geomspace(t_min_s, t_max_s, n)


def decade_aligned_taus(t_min_s: float, t_max_s: float, per_decade: float = 1.0) -> np.ndarray:
    """Times ``per_decade`` per decade from the decade at or below ``t_min_s`` to the one at or above
    ``t_max_s`` (s): the grid 10^k, 10^(k + 1/per_decade), ... that does not move with the window's ends."""
    lo, hi = math.floor(math.log10(t_min_s)), math.ceil(math.log10(t_max_s))
    return 10.0 ** np.arange(lo, hi + 1e-9, 1.0 / per_decade)


def tau_window_from_frequency(omega_rad_s: np.ndarray, extend_decades: float = EXTEND_DECADES) -> tuple[float, float]:
    """Span of identifiable times of a frequency window: ``(1/w_max, 1/w_min)`` widened by ``extend_decades``, s."""
    w = np.asarray(omega_rad_s, float)
    w = w[np.isfinite(w) & (w > 0)]
    if w.size == 0:
        raise ValueError("no positive finite angular frequency")
    f = 10.0 ** extend_decades
    return 1.0 / (f * w.max()), f / w.min()


def tau_window_from_time(time_s: np.ndarray, extend_decades: float = EXTEND_DECADES) -> tuple[float, float]:
    """Span of identifiable times of a time window: ``(t_min, t_max)`` (``t_min`` smallest positive time)
    widened by ``extend_decades``, s."""
    t = np.asarray(time_s, float)
    t = t[np.isfinite(t) & (t > 0)]
    if t.size == 0:
        raise ValueError("no positive finite time")
    f = 10.0 ** extend_decades
    return t.min() / f, t.max() * f


# ------------------------------------------------------------------------------------------------
# forward functions of the discrete series
# ------------------------------------------------------------------------------------------------
def prony_relaxation_modulus(g_e_pa: float, g_pa: np.ndarray, tau_s: np.ndarray, time_s: np.ndarray) -> np.ndarray:
    """``G(t) = G_e + sum g_i exp(-t/tau_i)``, Pa."""
    t = np.asarray(time_s, float)[..., None]
    return g_e_pa + np.sum(np.asarray(g_pa, float) * np.exp(-t / np.asarray(tau_s, float)), axis=-1)


def prony_complex_modulus(g_e_pa: float, g_pa: np.ndarray, tau_s: np.ndarray, omega_rad_s: np.ndarray) -> np.ndarray:
    """``G*(w) = G' + i G''`` of a Prony series, Pa."""
    x = np.asarray(omega_rad_s, float)[..., None] * np.asarray(tau_s, float)
    return g_e_pa + np.sum(np.asarray(g_pa, float) * (1j * x) / (1.0 + 1j * x), axis=-1)


def prony_relaxation_basis(time_s: np.ndarray, tau_s: np.ndarray, equilibrium: bool = True) -> np.ndarray:
    """Design matrix of ``G(t)`` of a Prony series: columns ``[1,] exp(-t/tau_i)`` (``(n_t, [1 +] n_tau)``).

    The weights it multiplies are ``[G_e,] g_i`` (Pa); ``equilibrium=False`` drops the constant column (a liquid).
    """
    t = np.asarray(time_s, float)
    basis = np.exp(-t[:, None] / np.asarray(tau_s, float)[None, :])
    return np.hstack([np.ones((t.size, 1)), basis]) if equilibrium else basis


def prony_oscillation_basis(omega_rad_s: np.ndarray, tau_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Design matrices of ``G'(w)`` and ``G''(w)`` of a Prony series, with the equilibrium column first:
    ``[1, x_i^2/(1 + x_i^2)]`` and ``[0, x_i/(1 + x_i^2)]``, ``x_i = w tau_i`` (each ``(n_w, 1 + n_tau)``)."""
    w = np.asarray(omega_rad_s, float)
    x = w[:, None] * np.asarray(tau_s, float)[None, :]
    storage = np.column_stack([np.ones_like(w), x ** 2 / (1 + x ** 2)])
    loss = np.column_stack([np.zeros_like(w), x / (1 + x ** 2)])
    return storage, loss


def prony_nnls_weights(time_s: np.ndarray, modulus_pa: np.ndarray, tau_s: np.ndarray, equilibrium: bool = True,
                       row_weights: np.ndarray | None = None) -> tuple[float, np.ndarray, float]:
    """Non-negative Prony weights on fixed relaxation times from a relaxation modulus ``G(t)``.

    Solves ``min || w (G_e + sum_i g_i exp(-t/tau_i) - G(t)) ||`` with ``G_e, g_i >= 0`` (scipy ``nnls``; the
    design matrix is :func:`prony_relaxation_basis`), ``w`` the ``row_weights`` (none: 1, e.g.
    ``1/|G(t)|`` for a relative misfit). Without ``equilibrium`` ``G_e`` is 0 (a liquid).

    Returns ``(G_e [Pa], g_i [Pa], residual norm of the weighted rows)``.
    """
    basis = prony_relaxation_basis(time_s, tau_s, equilibrium)
    y = np.asarray(modulus_pa, float)
    if row_weights is not None:
        w = np.asarray(row_weights, float)
        basis, y = basis * w[:, None], y * w
    weights, resid = scipy.optimize.nnls(basis, y)
    if equilibrium:
        return float(weights[0]), weights[1:], float(resid)
    return 0.0, weights, float(resid)


def kv_creep_compliance(j_g_per_pa: float, j_per_pa: np.ndarray, tau_s: np.ndarray, time_s: np.ndarray,
                        fluidity_per_pa_s: float = 0.0) -> np.ndarray:
    """``J(t) = J_g + sum j_i (1 - exp(-t/tau_i)) + t/eta_0`` (``fluidity = 1/eta_0``), 1/Pa."""
    t = np.asarray(time_s, float)
    e = np.exp(-t[..., None] / np.asarray(tau_s, float))
    return j_g_per_pa + np.sum(np.asarray(j_per_pa, float) * (1.0 - e), axis=-1) + fluidity_per_pa_s * t


def kv_complex_compliance(j_g_per_pa: float, j_per_pa: np.ndarray, tau_s: np.ndarray, omega_rad_s: np.ndarray,
                          fluidity_per_pa_s: float = 0.0) -> np.ndarray:
    """``J*(w) = J' - i J'' = J_g + sum j_i/(1 + i w tau_i) + 1/(i w eta_0)``, 1/Pa (so ``G* J* = 1``)."""
    w = np.asarray(omega_rad_s, float)
    x = w[..., None] * np.asarray(tau_s, float)
    out = j_g_per_pa + np.sum(np.asarray(j_per_pa, float) / (1.0 + 1j * x), axis=-1)
    return out + (fluidity_per_pa_s / (1j * w) if fluidity_per_pa_s else 0.0)


# ------------------------------------------------------------------------------------------------
# exact interconversion of the discrete series
# ------------------------------------------------------------------------------------------------
def prony_to_kelvin_voigt(g_e_pa: float, g_pa: np.ndarray, tau_s: np.ndarray
                          ) -> tuple[float, np.ndarray, np.ndarray, float]:
    """Exact retardation form of a generalized Maxwell series.

    Under stress control the dashpot strains ``e`` of the Maxwell arms obey ``D de/dt = -K e + g sigma/G_0``
    with ``D = diag(g_i tau_i)``, ``K = diag(g) - g g^T/G_0`` and ``G_0 = G_e + sum g``. With the eigenpairs
    ``(l_k, v_k)`` of the symmetric ``S = D^-1/2 K D^-1/2`` and ``b = D^-1/2 g / G_0`` the creep compliance is
    ``J(t) = 1/G_0 + sum_k (v_k.b)^2 (1 - exp(-l_k t))/l_k``. For a liquid (``G_e = 0``) one rate is zero: it is
    the flow term, with ``1/eta_0 = 1/sum(g_i tau_i)`` exactly.

    Parameters
    ----------
    g_e_pa : equilibrium modulus G_e >= 0, Pa
    g_pa, tau_s : mode weights (Pa, > 0 used; zero weights are dropped) and relaxation times (s)

    Returns
    -------
    ``(J_g [1/Pa], j_k [1/Pa], tau_ret_k [s] ascending, fluidity 1/eta_0 [1/(Pa s)])``
    """
    g = np.asarray(g_pa, float)
    tau = np.asarray(tau_s, float)
    keep = g > 0
    g, tau = g[keep], tau[keep]
    g0 = float(g_e_pa + g.sum())
    if not g0 > 0:
        raise ValueError("prony_to_kelvin_voigt needs a positive instantaneous modulus G_e + sum g_i")
    if g.size == 0:
        return 1.0 / g0, np.zeros(0), np.zeros(0), 0.0
    eta = g * tau
    c = np.sqrt(g / tau / g0)                       # D^-1/2 g / sqrt(G_0)
    rates, v = eigh(np.diag(1.0 / tau) - np.outer(c, c))
    proj = (v.T @ (c / math.sqrt(g0))) ** 2          # (v_k . b)^2
    fluidity = 0.0
    if g_e_pa <= 0:                                 # liquid: the smallest rate is the flow mode
        k = int(np.argmin(rates))
        fluidity = 1.0 / float(eta.sum())
        rates, proj = np.delete(rates, k), np.delete(proj, k)
    j = proj / rates
    order = np.argsort(1.0 / rates)
    return 1.0 / g0, j[order], (1.0 / rates)[order], fluidity


def kelvin_voigt_to_prony(j_g_per_pa: float, j_per_pa: np.ndarray, tau_s: np.ndarray,
                          fluidity_per_pa_s: float = 0.0) -> tuple[float, np.ndarray, np.ndarray]:
    """Exact relaxation form of a generalized Kelvin-Voigt series (spring ``1/J_g`` in series with Voigt units
    ``(1/j_k, tau_k)`` and, when ``fluidity > 0``, a dashpot ``eta_0 = 1/fluidity``).

    Under a strain step the Voigt (and dashpot) strains ``e`` obey ``D de/dt = G_0 gamma 1 - K e`` with
    ``D = diag(eta_k)``, ``K = diag(G_k) + G_0 1 1^T`` (the dashpot is a unit with ``G = 0``). With the
    eigenpairs ``(l_k, v_k)`` of ``S = D^-1/2 K D^-1/2`` and ``w = V^T D^-1/2 1``:
    ``G_k = G_0^2 w_k^2 / l_k``, ``theta_k = 1/l_k``, ``G_e = 1/(J_g + sum j)`` (0 with flow). This is the
    construction of :func:`tissuemech.models.linear.gkv_relaxation_spectrum`, extended to a flow term.

    Returns
    -------
    ``(G_e [Pa], G_k [Pa], theta_k [s] ascending)``
    """
    if not j_g_per_pa > 0:
        raise ValueError("kelvin_voigt_to_prony needs a positive glassy compliance J_g (a Voigt series without "
                         "an instantaneous spring has no finite relaxation modulus)")
    j = np.asarray(j_per_pa, float)
    tau = np.asarray(tau_s, float)
    keep = j > 0
    stiff, eta = 1.0 / j[keep], tau[keep] / j[keep]
    if fluidity_per_pa_s > 0:
        stiff, eta = np.r_[stiff, 0.0], np.r_[eta, 1.0 / fluidity_per_pa_s]
    g0 = 1.0 / j_g_per_pa
    if stiff.size == 0:
        return g0, np.zeros(0), np.zeros(0)
    inv_sqrt_eta = 1.0 / np.sqrt(eta)
    rates, v = eigh(inv_sqrt_eta[:, None] * (np.diag(stiff) + g0) * inv_sqrt_eta[None, :])
    w = v.T @ inv_sqrt_eta
    g_k = g0 * g0 * w * w / rates
    g_e = 0.0 if fluidity_per_pa_s > 0 else 1.0 / (j_g_per_pa + float(j[keep].sum()))
    order = np.argsort(1.0 / rates)
    return g_e, g_k[order], (1.0 / rates)[order]


# ------------------------------------------------------------------------------------------------
# regularised NNLS with GCV
# ------------------------------------------------------------------------------------------------
def second_difference(m: int) -> np.ndarray:
    """``(m-2, m)`` second-difference operator (rows ``[1, -2, 1]``); empty for ``m < 3``."""
    if m < 3:
        return np.zeros((0, m))
    return np.diff(np.eye(m), n=2, axis=0)


def regularised_nnls(kernel: np.ndarray, data: np.ndarray, sigma: np.ndarray, n_free: int = 0,
                     lam: float | None = None, lambda_grid: np.ndarray = LAMBDA_GRID) -> dict:
    """Non-negative Tikhonov (second-difference) least squares with lambda by GCV.

    Minimises ``||(K x - y)/sigma||^2 + lam^2 ||A||_2^2 ||D2 x_spec / s||^2`` over ``x >= 0``, where the first
    ``n_free`` columns of ``K`` (equilibrium, glassy, flow terms) are not penalised, ``x_spec`` are the
    remaining (spectrum) columns, ``s = max|y|`` and ``||A||_2`` (largest singular value of the weighted,
    scaled kernel ``K s / sigma``) make ``lam`` dimensionless and independent of how the rows are weighted.

    Parameters
    ----------
    kernel : (n, n_free + m) design matrix
    data, sigma : (n,) data and their scales (standard deviations or magnitudes), same units
    n_free : number of unpenalised leading columns
    lam : fixed regularisation parameter; ``None`` chooses it by GCV over ``lambda_grid``
    lambda_grid : candidate values of ``lam``

    Returns
    -------
    dict with ``x`` (solution, data units), ``lam``, ``lambda_grid``, ``gcv`` (one score per candidate;
    NaN when ``lam`` was fixed), ``dof`` (trace of the influence matrix), ``rms_weighted_residual``
    (RMS of ``(K x - y)/sigma``) and ``rel_rms_residual`` (RMS of ``(K x - y)/|y|``).
    """
    K = np.asarray(kernel, float)
    y = np.asarray(data, float)
    sig = np.asarray(sigma, float)
    n, p = K.shape
    scale = float(np.max(np.abs(y)))
    Aw = K / sig[:, None] * scale                    # unknowns u = x / scale
    bw = y / sig
    L = np.zeros((max(p - n_free - 2, 0), p))
    L[:, n_free:] = second_difference(p - n_free) * np.linalg.norm(Aw, 2)  # lam relative to the kernel's scale
    colnorm = np.linalg.norm(Aw, axis=0)
    colnorm = np.where(colnorm > 0, colnorm, 1.0)

    def solve(lmb: float) -> tuple[np.ndarray, float, float]:
        A = np.vstack([Aw, lmb * L]) / colnorm
        b = np.r_[bw, np.zeros(L.shape[0])]
        z, _ = scipy.optimize.nnls(A, b, maxiter=100 * p)
        u = z / colnorm
        r = Aw @ u - bw
        act = u > 0
        Aa, La = Aw[:, act], L[:, act]
        if act.any():
            M = Aa.T @ Aa + lmb * lmb * La.T @ La
            dof = float(np.trace(np.linalg.solve(M, Aa.T @ Aa))) if np.linalg.cond(M) < 1e14 else float(act.sum())
        else:
            dof = 0.0
        return u, float(r @ r), dof

    grid = np.atleast_1d(np.asarray(lambda_grid if lam is None else [lam], float))
    sols = [solve(float(lmb)) for lmb in grid]
    gcv = np.array([n * rss / max(n - dof, 1e-12) ** 2 for _, rss, dof in sols])
    k = int(np.nanargmin(gcv)) if lam is None else 0
    u, rss, dof = sols[k]
    x = u * scale
    rel = (K @ x - y) / np.maximum(np.abs(y), 1e-12 * scale)
    return {"x": x, "lam": float(grid[k]), "lambda_grid": grid,
            "gcv": gcv if lam is None else np.full(1, np.nan), "dof": dof,
            "rms_weighted_residual": float(math.sqrt(rss / n)),
            "rel_rms_residual": float(math.sqrt(np.mean(rel ** 2)))}


# ------------------------------------------------------------------------------------------------
# the spectrum record
# ------------------------------------------------------------------------------------------------
@dataclass
class Spectrum:
    """A relaxation (``kind='relaxation'``) or retardation (``kind='retardation'``) spectrum on a log grid.

    Attributes
    ----------
    kind : ``"relaxation"`` (weights in Pa, ``equilibrium`` = G_e in Pa) or ``"retardation"`` (weights in
        1/Pa, ``equilibrium`` = J_g in 1/Pa, ``fluidity`` = 1/eta_0 in 1/(Pa s))
    tau_s : grid of relaxation/retardation times, s
    weights : discrete weights ``h_i`` (Pa) or ``j_i`` (1/Pa)
    equilibrium, fluidity : see ``kind``
    lam : regularisation parameter used; ``lambda_grid``/``gcv``: the GCV curve
    rel_rms_residual : RMS relative residual ``(fit - data)/|data|`` of the fit
    source : what was inverted (``"G'+G''"``, ``"G(t)"``, ``"J(t)"``, ``"J'+J''"``, ...)
    window_s : ``(tau_min, tau_max)`` of the data window before widening, s
    """

    kind: str
    tau_s: np.ndarray
    weights: np.ndarray
    equilibrium: float
    fluidity: float = 0.0
    lam: float = float("nan")
    lambda_grid: np.ndarray = field(default_factory=lambda: np.zeros(0))
    gcv: np.ndarray = field(default_factory=lambda: np.zeros(0))
    rel_rms_residual: float = float("nan")
    source: str = ""
    window_s: tuple[float, float] = (float("nan"), float("nan"))

    @property
    def dlntau(self) -> float:
        """Grid step in ln(tau)."""
        return float(np.log(self.tau_s[1] / self.tau_s[0])) if self.tau_s.size > 1 else 1.0

    @property
    def continuous(self) -> np.ndarray:
        """Continuous spectrum ``H(tau)`` (Pa) or ``L(tau)`` (1/Pa): weights per unit ln(tau)."""
        return self.weights / self.dlntau

    def as_prony(self) -> tuple[float, np.ndarray, np.ndarray]:
        """``(G_e, g_i, tau_i)`` in Pa, Pa, s (exact interconversion for a retardation spectrum)."""
        if self.kind == "relaxation":
            return self.equilibrium, self.weights, self.tau_s
        return kelvin_voigt_to_prony(self.equilibrium, self.weights, self.tau_s, self.fluidity)

    def as_kelvin_voigt(self) -> tuple[float, np.ndarray, np.ndarray, float]:
        """``(J_g, j_k, tau_k, 1/eta_0)`` in 1/Pa, 1/Pa, s, 1/(Pa s) (exact for a relaxation spectrum)."""
        if self.kind == "retardation":
            return self.equilibrium, self.weights, self.tau_s, self.fluidity
        return prony_to_kelvin_voigt(self.equilibrium, self.weights, self.tau_s)

    def relaxation_modulus(self, time_s: np.ndarray) -> np.ndarray:
        """G(t), Pa."""
        return prony_relaxation_modulus(*self.as_prony(), time_s)

    def complex_modulus(self, omega_rad_s: np.ndarray) -> np.ndarray:
        """G*(w) = G' + i G'', Pa."""
        return prony_complex_modulus(*self.as_prony(), omega_rad_s)

    def creep_compliance(self, time_s: np.ndarray) -> np.ndarray:
        """J(t), 1/Pa."""
        j_g, j, tau, fl = self.as_kelvin_voigt()
        return kv_creep_compliance(j_g, j, tau, time_s, fl)

    def complex_compliance(self, omega_rad_s: np.ndarray) -> np.ndarray:
        """J*(w) = J' - i J'', 1/Pa."""
        j_g, j, tau, fl = self.as_kelvin_voigt()
        return kv_complex_compliance(j_g, j, tau, omega_rad_s, fl)

    def peaks(self) -> list[dict]:
        """Modes of the spectrum: one per local maximum of the weights. The grid is split at the smallest
        weight between consecutive maxima; each part gives ``weight`` (its summed weights, Pa or 1/Pa),
        ``tau_s`` (their weighted geometric mean time) and ``tau_peak_s`` (the maximum's time). Sorted by
        decreasing weight."""
        h = np.asarray(self.weights, float)
        n = h.size
        maxima = [i for i in range(n) if h[i] > 0 and (i == 0 or h[i] >= h[i - 1]) and (i == n - 1 or h[i] > h[i + 1])]
        edges = [0] + [a + 1 + int(np.argmin(h[a + 1:b + 1])) for a, b in zip(maxima[:-1], maxima[1:])] + [n]
        out = []
        for i, lo, hi in zip(maxima, edges[:-1], edges[1:]):
            w, t = h[lo:hi], self.tau_s[lo:hi]
            out.append({"tau_s": float(np.exp(np.sum(w * np.log(t)) / w.sum())), "weight": float(w.sum()),
                        "tau_peak_s": float(self.tau_s[i])})
        return sorted(out, key=lambda d: -d["weight"])

    def to_xarray(self) -> xr.Dataset:
        """The spectrum as an xarray Dataset (dim ``tau``) with CF-style units and the fit's metadata."""
        unit = "Pa" if self.kind == "relaxation" else "1/Pa"
        sym = "H" if self.kind == "relaxation" else "L"
        ds = xr.Dataset(
            {"weight": ("tau", self.weights, {"units": unit, "long_name": f"discrete {self.kind} weight"}),
             "spectrum": ("tau", self.continuous, {"units": unit,
                                                    "long_name": f"continuous {self.kind} spectrum {sym}(tau)"}),
             "gcv": ("lambda", np.asarray(self.gcv, float), {"long_name": "generalised cross-validation score"})},
            coords={"tau": ("tau", self.tau_s, {"units": "s"}),
                    "lambda": ("lambda", np.asarray(self.lambda_grid, float), {"units": "1"})})
        ds.attrs.update({"kind": self.kind, "equilibrium": self.equilibrium,
                         "equilibrium_units": "Pa" if self.kind == "relaxation" else "1/Pa",
                         "fluidity_per_pa_s": self.fluidity, "lambda": self.lam, "lambda_criterion": "GCV",
                         "rel_rms_residual": self.rel_rms_residual, "source": self.source,
                         "window_tau_min_s": self.window_s[0], "window_tau_max_s": self.window_s[1],
                         "grid_rule": f"data window widened by {EXTEND_DECADES:g} decade each side"})
        return ds


# ------------------------------------------------------------------------------------------------
# inversions
# ------------------------------------------------------------------------------------------------
def _grid(window: tuple[float, float], taus_s: np.ndarray | None, per_decade: float,
          below: float = EXTEND_DECADES) -> np.ndarray:
    if taus_s is not None:
        return np.asarray(taus_s, float)
    return log_spaced_taus(window[0] / 10.0 ** below, window[1] * 10.0 ** EXTEND_DECADES, per_decade)


def _scales(y: np.ndarray, sd: np.ndarray | None) -> np.ndarray:
    s = np.abs(y) if sd is None else np.asarray(sd, float)
    floor = 1e-12 * float(np.max(np.abs(y)))
    return np.maximum(s, floor)


def _finite(*arrays: np.ndarray) -> np.ndarray:
    mask = np.ones(np.asarray(arrays[0]).shape, bool)
    for a in arrays:
        mask &= np.isfinite(np.asarray(a, float))
    return mask


def relaxation_spectrum_from_modulus(omega_rad_s: np.ndarray, storage_pa: np.ndarray | None,
                                     loss_pa: np.ndarray | None, *, equilibrium: bool = True,
                                     taus_s: np.ndarray | None = None, per_decade: float = PER_DECADE,
                                     sd_storage_pa: np.ndarray | None = None, sd_loss_pa: np.ndarray | None = None,
                                     lam: float | None = None) -> Spectrum:
    """Relaxation spectrum from G'(w) and G''(w) jointly (or either alone: pass ``None`` for the other).

    Parameters
    ----------
    omega_rad_s : angular frequencies, rad/s
    storage_pa, loss_pa : G' and G'', Pa (``None``: not used)
    equilibrium : include an equilibrium modulus G_e (solid); ``False`` for a liquid
    taus_s : explicit grid (default: the stated rule, ``per_decade`` per decade)
    sd_storage_pa, sd_loss_pa : standard deviations (default: relative misfit, i.e. the magnitudes)
    lam : fixed regularisation parameter (default: GCV)

    Non-finite and non-positive moduli (e.g. a G'' lost in the noise) are left out of the fit.
    """
    w = np.asarray(omega_rad_s, float)
    window = tau_window_from_frequency(w, 0.0)
    taus = _grid(window, taus_s, per_decade)
    x = w[:, None] * taus[None, :]
    e = np.ones((w.size, 1)) if equilibrium else np.zeros((w.size, 0))
    blocks = []
    for y, sd, part, eq in ((storage_pa, sd_storage_pa, x * x / (1 + x * x), e),
                            (loss_pa, sd_loss_pa, x / (1 + x * x), 0 * e)):
        if y is None:
            continue
        y = np.asarray(y, float)
        m = _finite(y, w) & (y > 0)
        blocks.append((np.hstack([eq, part])[m], y[m], _scales(y[m], None if sd is None else np.asarray(sd)[m])))
    if not blocks:
        raise ValueError("relaxation_spectrum_from_modulus needs G' or G''")
    n_free = int(equilibrium)
    K = np.vstack([b[0] for b in blocks])
    r = regularised_nnls(K, np.concatenate([b[1] for b in blocks]), np.concatenate([b[2] for b in blocks]),
                         n_free=n_free, lam=lam)
    src = "+".join(s for s, y in (("G'", storage_pa), ("G''", loss_pa)) if y is not None)
    return Spectrum("relaxation", taus, r["x"][n_free:], float(r["x"][0]) if equilibrium else 0.0, 0.0, r["lam"],
                    r["lambda_grid"], r["gcv"], r["rel_rms_residual"], src, window)


def relaxation_spectrum_from_relaxation(time_s: np.ndarray, modulus_pa: np.ndarray, *,
                                        strain: np.ndarray | None = None, equilibrium: bool = True,
                                        taus_s: np.ndarray | None = None, per_decade: float = PER_DECADE,
                                        sd_pa: np.ndarray | None = None, lam: float | None = None) -> Spectrum:
    """Relaxation spectrum from a relaxation test.

    Parameters
    ----------
    time_s : times, s (from the step, or from the start of the strain ramp when ``strain`` is given)
    modulus_pa : G(t) = sigma/gamma_0 in Pa for an ideal step; with ``strain`` given, the shear *stress* in Pa
    strain : optional strain history (same points): the kernel is then the exact hereditary response to it
        (:func:`tissuemech.models.recursion.prony_branch_histories`), so ramps of any rise time are exact
    equilibrium, taus_s, per_decade, sd_pa, lam : as in :func:`relaxation_spectrum_from_modulus`
    """
    t = np.asarray(time_s, float)
    y = np.asarray(modulus_pa, float)
    window = tau_window_from_time(t, 0.0)
    taus = _grid(window, taus_s, per_decade, below=0.0)
    if strain is None:
        m = _finite(t, y) & (t > 0)
        part = np.exp(-t[m, None] / taus[None, :])
        eq = np.ones((int(m.sum()), 1))
        src = "G(t)"
    else:
        g = np.asarray(strain, float)
        m = _finite(t, y, g)
        part = prony_branch_histories(t[m], np.repeat(g[m][None, :], taus.size, axis=0), taus).T
        eq = g[m][:, None]
        src = "stress history"
    K = np.hstack([eq, part]) if equilibrium else part
    n_free = int(equilibrium)
    r = regularised_nnls(K, y[m], _scales(y[m], None if sd_pa is None else np.asarray(sd_pa)[m]),
                         n_free=n_free, lam=lam)
    return Spectrum("relaxation", taus, r["x"][n_free:], float(r["x"][0]) if equilibrium else 0.0, 0.0, r["lam"],
                    r["lambda_grid"], r["gcv"], r["rel_rms_residual"], src, window)


def retardation_spectrum_from_creep(time_s: np.ndarray, compliance_per_pa: np.ndarray, *, flow: bool = True,
                                    taus_s: np.ndarray | None = None, per_decade: float = PER_DECADE,
                                    sd_per_pa: np.ndarray | None = None, lam: float | None = None) -> Spectrum:
    """Retardation spectrum from a creep compliance J(t) = gamma(t)/sigma_0 (ideal stress step), 1/Pa.

    ``flow`` adds a steady-flow term ``t/eta_0`` (unpenalised, >= 0); the glassy compliance ``J_g >= 0`` is
    always included.
    """
    t = np.asarray(time_s, float)
    y = np.asarray(compliance_per_pa, float)
    window = tau_window_from_time(t, 0.0)
    taus = _grid(window, taus_s, per_decade, below=0.0)
    m = _finite(t, y) & (t > 0)
    free = [np.ones(int(m.sum()))] + ([t[m]] if flow else [])
    K = np.hstack([np.column_stack(free), 1.0 - np.exp(-t[m, None] / taus[None, :])])
    n_free = len(free)
    r = regularised_nnls(K, y[m], _scales(y[m], None if sd_per_pa is None else np.asarray(sd_per_pa)[m]),
                         n_free=n_free, lam=lam)
    x = r["x"]
    return Spectrum("retardation", taus, x[n_free:], float(x[0]), float(x[1]) if flow else 0.0, r["lam"],
                    r["lambda_grid"], r["gcv"], r["rel_rms_residual"], "J(t)", window)


def retardation_spectrum_from_compliance(omega_rad_s: np.ndarray, storage_compliance_per_pa: np.ndarray,
                                         loss_compliance_per_pa: np.ndarray, *, flow: bool = True,
                                         taus_s: np.ndarray | None = None, per_decade: float = PER_DECADE,
                                         lam: float | None = None) -> Spectrum:
    """Retardation spectrum from J'(w) and J''(w) (``J* = J' - i J''``, both >= 0, 1/Pa) jointly.

    J* may come from measured G* as ``1/G*``: ``J' = G'/|G*|^2``, ``J'' = G''/|G*|^2``.
    """
    w = np.asarray(omega_rad_s, float)
    window = tau_window_from_frequency(w, 0.0)
    taus = _grid(window, taus_s, per_decade)
    x = w[:, None] * taus[None, :]
    jp, jpp = np.asarray(storage_compliance_per_pa, float), np.asarray(loss_compliance_per_pa, float)
    m1, m2 = _finite(w, jp) & (jp > 0), _finite(w, jpp) & (jpp > 0)
    one, zero = np.ones((w.size, 1)), np.zeros((w.size, 1))
    fl1, fl2 = (zero, 1.0 / w[:, None]) if flow else (zero[:, :0], zero[:, :0])
    K = np.vstack([np.hstack([one, fl1, 1.0 / (1 + x * x)])[m1], np.hstack([zero, fl2, x / (1 + x * x)])[m2]])
    y = np.r_[jp[m1], jpp[m2]]
    n_free = 2 if flow else 1
    r = regularised_nnls(K, y, _scales(y, None), n_free=n_free, lam=lam)
    xx = r["x"]
    return Spectrum("retardation", taus, xx[n_free:], float(xx[0]), float(xx[1]) if flow else 0.0, r["lam"],
                    r["lambda_grid"], r["gcv"], r["rel_rms_residual"], "J'+J''", window)


# ------------------------------------------------------------------------------------------------
# consistency checks (for the diagnosis)
# ------------------------------------------------------------------------------------------------
def _rel_rms(pred: np.ndarray, meas: np.ndarray, scale: np.ndarray | None = None) -> float:
    """RMS of ``(pred - meas)/scale`` (``scale`` defaults to ``|meas|``) over the points a fit can use
    (finite, positive measured values)."""
    scale = np.abs(meas) if scale is None else np.asarray(scale, float)
    m = np.isfinite(pred) & np.isfinite(meas) & (meas > 0) & np.isfinite(scale) & (scale > 0)
    return float(np.sqrt(np.mean(((pred[m] - meas[m]) / scale[m]) ** 2))) if m.any() else float("nan")


def _verdict(discrepancy: float, tolerance: float | None) -> tuple[bool | None, str]:
    if tolerance is None:
        return None, "not testable: no tolerance given (the discrepancy is reported, not judged)"
    ok = bool(discrepancy <= tolerance)
    return ok, f"discrepancy {discrepancy:.3g} {'<=' if ok else '>'} tolerance {tolerance:.3g}"


def kramers_kronig_check(omega_rad_s: np.ndarray, storage_pa: np.ndarray, loss_pa: np.ndarray, *,
                         equilibrium: bool = True, tolerance: float | None = None,
                         per_decade: float = PER_DECADE) -> dict:
    """Kramers-Kronig consistency of G' and G'' through the regularised spectrum.

    Every positive relaxation spectrum satisfies the Kramers-Kronig relations, so KK-consistent data are
    fitted by *one* spectrum in both components at their noise level, and KK-inconsistent data (a G''
    scaled by 2, inertia, a phase offset) leave a systematic residual. The reported ``discrepancy`` is that
    joint residual: the spectrum fitted to G' and G'' together predicts each component, and the RMS of
    ``(predicted - measured)/|G*|`` over both components and all points is returned. Differences are
    normalised by ``|G*|`` point by point (the scale of the measurement error of both components: torque
    amplitude and phase), so a small G'' far from its peak does not dominate.

    The one-sided predictions are reported as well: G'' predicted by the spectrum of G' alone, and G'
    predicted by the spectrum of G'' alone plus the least-squares constant ``storage_offset_pa`` (G'' on a
    finite window fixes G' only up to a constant: the equilibrium modulus and modes outside the window add a
    flat G' and almost no G''). They are ill-posed near the window edges (modes just outside the window are
    seen by one component only): on a 2-decade window G'' from G' alone misses by ~8 % of ``|G*|`` on exact
    3-mode data, so they are diagnostics, not the criterion.

    Parameters
    ----------
    omega_rad_s, storage_pa, loss_pa : one frequency sweep (rad/s, Pa, Pa)
    equilibrium : allow an equilibrium modulus
    tolerance : discrepancy (fraction of ``|G*|``) above which the sweep is flagged, e.g. from the measured
        scatter of G', G''; ``None``: no verdict (``consistent`` is ``None``)

    Returns
    -------
    dict with ``discrepancy`` (joint, above), ``discrepancy_storage``/``discrepancy_loss`` (its two parts),
    ``storage_pred``/``loss_pred`` (joint spectrum, Pa), ``loss_from_storage``/``storage_from_loss``
    (one-sided predictions, Pa) with ``discrepancy_loss_from_storage``/``discrepancy_storage_from_loss``,
    ``storage_offset_pa``, ``consistent`` (bool or None), ``verdict`` (text), ``lambda`` (joint fit) and
    ``spectrum`` (the joint :class:`Spectrum`).
    """
    w = np.asarray(omega_rad_s, float)
    gp, gpp = np.asarray(storage_pa, float), np.asarray(loss_pa, float)
    mag = np.hypot(gp, gpp)
    joint = relaxation_spectrum_from_modulus(w, gp, gpp, equilibrium=equilibrium, per_decade=per_decade)
    g = joint.complex_modulus(w)
    d_storage, d_loss = _rel_rms(g.real, gp, mag), _rel_rms(g.imag, gpp, mag)
    d = float(np.sqrt(0.5 * (d_storage ** 2 + d_loss ** 2)))
    s1 = relaxation_spectrum_from_modulus(w, gp, None, equilibrium=equilibrium, per_decade=per_decade)
    s2 = relaxation_spectrum_from_modulus(w, None, gpp, equilibrium=False, per_decade=per_decade)
    loss_from_storage = s1.complex_modulus(w).imag
    storage_from_loss = s2.complex_modulus(w).real
    ok_pts = np.isfinite(gp) & np.isfinite(storage_from_loss) & (mag > 0)
    wgt = 1.0 / mag[ok_pts] ** 2
    offset = float(np.sum((gp[ok_pts] - storage_from_loss[ok_pts]) * wgt) / np.sum(wgt))
    storage_from_loss = storage_from_loss + offset
    ok, text = _verdict(d, tolerance)
    return {"discrepancy": d, "discrepancy_storage": d_storage, "discrepancy_loss": d_loss,
            "storage_pred": g.real, "loss_pred": g.imag,
            "loss_from_storage": loss_from_storage, "storage_from_loss": storage_from_loss,
            "discrepancy_loss_from_storage": _rel_rms(loss_from_storage, gpp, mag),
            "discrepancy_storage_from_loss": _rel_rms(storage_from_loss, gp, mag),
            "storage_offset_pa": offset, "consistent": ok, "verdict": text, "lambda": joint.lam,
            "spectrum": joint}


def relaxation_predicts_sweep(time_s: np.ndarray, modulus_pa: np.ndarray, omega_rad_s: np.ndarray,
                              storage_pa: np.ndarray, loss_pa: np.ndarray, *, tolerance: float | None = None,
                              per_decade: float = PER_DECADE) -> dict:
    """Predict a frequency sweep from a relaxation modulus G(t) (ideal step) through its spectrum.

    Returns
    -------
    dict with ``storage_pred``/``loss_pred`` (Pa), ``in_window`` (bool per frequency: ``1/w`` inside the
    relaxation's time window; outside it the prediction is an extrapolation), ``discrepancy_storage``,
    ``discrepancy_loss`` (RMS of the differences over ``|G*|`` on in-window points), ``discrepancy`` (the
    RMS of both),
    ``consistent``, ``verdict``, ``spectrum`` (the :class:`Spectrum`).
    """
    spec = relaxation_spectrum_from_relaxation(time_s, modulus_pa, per_decade=per_decade)
    w = np.asarray(omega_rad_s, float)
    g = spec.complex_modulus(w)
    inside = (1.0 / w >= spec.window_s[0]) & (1.0 / w <= spec.window_s[1])
    gp, gpp = np.asarray(storage_pa, float), np.asarray(loss_pa, float)
    mag = np.hypot(gp, gpp)[inside]
    d1, d2 = _rel_rms(g.real[inside], gp[inside], mag), _rel_rms(g.imag[inside], gpp[inside], mag)
    d = float(np.sqrt(0.5 * (d1 ** 2 + d2 ** 2)))
    ok, text = _verdict(d, tolerance)
    if not inside.any():
        ok, text = None, "not testable: no frequency inside the relaxation's time window"
    return {"storage_pred": g.real, "loss_pred": g.imag, "in_window": inside, "discrepancy_storage": d1,
            "discrepancy_loss": d2, "discrepancy": d, "consistent": ok, "verdict": text, "spectrum": spec}


def sweep_predicts_relaxation(omega_rad_s: np.ndarray, storage_pa: np.ndarray, loss_pa: np.ndarray,
                              time_s: np.ndarray, modulus_pa: np.ndarray, *, tolerance: float | None = None,
                              per_decade: float = PER_DECADE) -> dict:
    """Predict a relaxation modulus G(t) from a frequency sweep through its spectrum.

    Returns
    -------
    dict with ``modulus_pred`` (Pa), ``in_window`` (``t`` inside the sweep's ``1/w`` window),
    ``discrepancy`` (RMS relative difference on in-window points), ``consistent``, ``verdict``, ``spectrum``.
    """
    spec = relaxation_spectrum_from_modulus(omega_rad_s, storage_pa, loss_pa, per_decade=per_decade)
    t = np.asarray(time_s, float)
    pred = spec.relaxation_modulus(t)
    inside = (t >= spec.window_s[0]) & (t <= spec.window_s[1])
    d = _rel_rms(pred[inside], np.asarray(modulus_pa, float)[inside])
    ok, text = _verdict(d, tolerance)
    if not inside.any():
        ok, text = None, "not testable: no time inside the sweep's 1/omega window"
    return {"modulus_pred": pred, "in_window": inside, "discrepancy": d, "consistent": ok, "verdict": text,
            "spectrum": spec}


__all__ = [
    "PER_DECADE", "EXTEND_DECADES", "LAMBDA_GRID", "log_spaced_taus", "tau_window_from_frequency",
    "tau_window_from_time", "prony_relaxation_modulus", "prony_complex_modulus", "prony_relaxation_basis",
    "prony_oscillation_basis", "prony_nnls_weights", "kv_creep_compliance",
    "kv_complex_compliance", "prony_to_kelvin_voigt", "kelvin_voigt_to_prony", "second_difference",
    "regularised_nnls", "Spectrum", "relaxation_spectrum_from_modulus", "relaxation_spectrum_from_relaxation",
    "retardation_spectrum_from_creep", "retardation_spectrum_from_compliance", "kramers_kronig_check",
    "relaxation_predicts_sweep", "sweep_predicts_relaxation",
]


# ------------------------------------------------------------------------------------------------------
# spectra of a dataset's averaged curves (spectrum.nc)
# ------------------------------------------------------------------------------------------------------
def _finite_sd(curve: xr.Dataset, name: str) -> np.ndarray | None:
    sd = curve.get(f"{name}_sd")
    if sd is None:
        return None
    sd = np.asarray(sd.values, float)
    return sd if np.all(np.isfinite(sd) & (sd > 0)) else None


def _curve_spectrum(c: xr.Dataset, test: str) -> tuple[Spectrum, float]:
    """Spectrum of one averaged curve and its Kramers-Kronig discrepancy (NaN when not a sweep)."""
    if test == "frequency_sweep":
        w = (c["angular_frequency"].values if "angular_frequency" in c.coords
             else 2.0 * np.pi * c["frequency"].values)  # averages grid sweeps on frequency [Hz]
        gp, gpp = c["storage_modulus_mean"].values, c["loss_modulus_mean"].values
        spec = relaxation_spectrum_from_modulus(w, gp, gpp, sd_storage_pa=_finite_sd(c, "storage_modulus"),
                                                  sd_loss_pa=_finite_sd(c, "loss_modulus"))
        return spec, kramers_kronig_check(w, gp, gpp)["discrepancy"]
    t, stress = c["time"].values, c["shear_stress_mean"].values
    strain = c["shear_strain_mean"].values
    if test == "creep_recovery":
        # the creep phase: the first contiguous run of points carrying at least half the peak stress (the
        # recovery that follows has none); J(t) = gamma/sigma_0, an ideal stress step at t = 0
        on = np.abs(stress) >= 0.5 * np.nanmax(np.abs(stress))
        i0 = int(np.argmax(on))
        i1 = i0 + (int(np.argmin(on[i0:])) if not on[i0:].all() else int(on[i0:].size))
        sigma0 = float(np.mean(stress[i0:i1]))
        sd = _finite_sd(c, "shear_strain")
        spec = retardation_spectrum_from_creep(t[i0:i1], strain[i0:i1] / sigma0,
                                                 sd_per_pa=None if sd is None else sd[i0:i1] / abs(sigma0))
        return spec, float("nan")
    sd = _finite_sd(c, "shear_stress")
    if np.nanmin(np.abs(strain)) >= 0.98 * np.nanmax(np.abs(strain)):
        # the averaged curve holds the hold only: G(t) = sigma/gamma, step at t = 0 (thesis analysis)
        gamma0 = float(np.nanmean(strain))
        spec = relaxation_spectrum_from_relaxation(t, stress / gamma0, sd_pa=None if sd is None else sd / abs(gamma0))
    else:  # the ramp is in the curve: invert through the strain history
        spec = relaxation_spectrum_from_relaxation(t, stress, strain=strain, sd_pa=sd)
    return spec, float("nan")


def spectra_from_averages(averages: xr.Dataset) -> xr.Dataset:
    """Relaxation or retardation spectrum of every averaged sweep, relaxation and creep (``tissuemech.spectra``).

    Frequency sweeps: relaxation spectrum of G' and G'' jointly, plus the Kramers-Kronig discrepancy of the
    sweep; relaxations: relaxation spectrum of the shear stress through the averaged strain history when the
    curve holds the ramp, else of ``G(t) = sigma/gamma_0`` as the response to an ideal step at ``t = 0`` (the
    averaged curve then starts in the hold); creep: retardation spectrum (with a flow term) of
    ``J(t) = gamma/sigma_0`` over the creep phase (first run of points with at least half the peak stress;
    the recovery is not used). Rows are weighted by the sample SD where every point has one (>= 2 samples),
    else by the relative misfit.

    Returns
    -------
    xarray.Dataset with dims ``curve`` and ``tau_index`` (per-curve grids padded with NaN): ``tau`` [s],
    ``kind`` (``relaxation``/``retardation``); relaxation curves: ``weight`` and ``spectrum`` (H(tau)) [Pa],
    ``equilibrium_modulus`` [Pa]; retardation curves: ``retardation_weight`` and ``retardation_spectrum``
    (L(tau)) [1/Pa], ``glassy_compliance`` [1/Pa], ``fluidity`` [1/(Pa s)] (NaN where not applicable);
    all: ``lambda``, ``rel_rms_residual``, ``kk_discrepancy`` (sweeps; NaN otherwise), ``test``,
    ``condition``, ``source``. No ``curve`` when the dataset has none of these tests.
    """
    tests = as_str(averages["test"].values)
    labels = as_str(averages["condition"].values)
    rows = []
    for test, label in zip(tests, labels):
        if test in SPECTRUM_TESTS:
            spec, kk = _curve_spectrum(select_average(averages, test, label), test)
            rows.append((test, label, spec, kk))
    n, n_tau = len(rows), max((r[2].tau_s.size for r in rows), default=0)

    def per_tau(kind: str, get) -> np.ndarray:
        out = np.full((n, n_tau), np.nan)
        for i, r in enumerate(rows):
            if kind in ("any", r[2].kind):
                values = get(r[2])
                out[i, : values.size] = values
        return out

    def per_curve(kind: str, get) -> np.ndarray:
        return np.array([get(r[2]) if r[2].kind == kind else np.nan for r in rows], float)

    rel, ret = "relaxation", "retardation"
    return xr.Dataset(
        {"tau": (("curve", "tau_index"), per_tau("any", lambda s: s.tau_s),
                 {"units": "s", "long_name": "relaxation or retardation time of the inversion grid"}),
         "kind": ("curve", np.array([r[2].kind for r in rows], dtype=str)),
         "weight": (("curve", "tau_index"), per_tau(rel, lambda s: s.weights),
                    {"units": "Pa", "long_name": "discrete relaxation weight h_i"}),
         "spectrum": (("curve", "tau_index"), per_tau(rel, lambda s: s.continuous),
                      {"units": "Pa", "long_name": "continuous relaxation spectrum H(tau) = h_i / d ln tau"}),
         "equilibrium_modulus": ("curve", per_curve(rel, lambda s: s.equilibrium), {"units": "Pa"}),
         "retardation_weight": (("curve", "tau_index"), per_tau(ret, lambda s: s.weights),
                                {"units": "1/Pa", "long_name": "discrete retardation weight j_i"}),
         "retardation_spectrum": (("curve", "tau_index"), per_tau(ret, lambda s: s.continuous),
                                  {"units": "1/Pa",
                                   "long_name": "continuous retardation spectrum L(tau) = j_i / d ln tau"}),
         "glassy_compliance": ("curve", per_curve(ret, lambda s: s.equilibrium), {"units": "1/Pa"}),
         "fluidity": ("curve", per_curve(ret, lambda s: s.fluidity),
                      {"units": "1/(Pa s)", "long_name": "1/eta_0 (steady flow term of the creep)"}),
         "lambda": ("curve", np.array([r[2].lam for r in rows], float),
                    {"long_name": "Tikhonov parameter chosen by GCV"}),
         "rel_rms_residual": ("curve", np.array([r[2].rel_rms_residual for r in rows], float)),
         "kk_discrepancy": ("curve", np.array([r[3] for r in rows], float),
                            {"long_name": "Kramers-Kronig discrepancy: joint-spectrum residual over |G*|"}),
         "test": ("curve", np.array([r[0] for r in rows], dtype=str)),
         "condition": ("curve", np.array([r[1] for r in rows], dtype=str)),
         "source": ("curve", np.array([r[2].source for r in rows], dtype=str))},
        attrs={"method": "NNLS + second-difference Tikhonov, lambda by GCV (tissuemech.spectra)",
               **({} if rows else {"not_testable": "no frequency sweep, relaxation or creep in the averages"}),
               "grid_rule": "tau 1/(10 w_max)..10/w_min for sweeps, t_min..10 t_max for time data, "
                            f"{PER_DECADE} per decade"})


def run_spectrum(averages_path, out_nc) -> xr.Dataset:
    """Read ``averages.nc``, compute :func:`spectra_from_averages` and write it atomically to ``out_nc``."""
    ds = spectra_from_averages(read_netcdf(averages_path))
    write_netcdf(ds, out_nc)
    return ds
