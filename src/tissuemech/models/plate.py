"""Parallel-plate (torsion) forward model: what the rheometer measures for a given constitutive model.

Kinematics (science.md section 2.1): the shear strain is linear in radius, ``gamma(r, t) = gamma_R(t) r/R``,
so every radius is an independent homogeneous simple-shear history. The torque

    M(t) = 2 pi int_0^R sigma(r, t) r^2 dr

is evaluated by Gauss-Legendre quadrature on [0, R] with each node carrying its own strain history through
the model (any viscoelastic model; the models' batched ``shear_stress_histories`` evaluate all radii in
one compiled pass). The instrument reports the *apparent* rim stress ``2M/(pi R^3)``, exact only for a
linear material; the Rabinowitsch-type correction ``sigma_R = M/(2 pi R^3) [3 + d lnM/d ln gamma_R]``
recovers the true rim stress. Normal force (thrust) follows science.md section 2.2:

    F = pi int_0^R (N1 - N2) r dr,   positive when the sample pushes the plates apart

(the canonical ``normal_force`` convention). fem.md section 4 quotes the same magnitude as an axial force
with the opposite sign (``N = -2 pi psi^2 int (W1 + 2 W2) r^3 dr``, compressive); the two agree.

A note on the gap: with the rim strain ``gamma_R = theta R/h`` given, the quasi-static torsion kinematics
do not depend on the gap ``h`` separately (twist per length ``psi = gamma_R/R``); the gap enters the
high-frequency inertia effects (section 2.5, :func:`apparent_complex_modulus`).
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import scipy

from .base import ConstitutiveModel
from .qlv import invert_monotone, stress_controlled_strain, stress_controlled_strain_by_history

Params = Mapping[str, float]

TARGETS = ("apparent_stress", "corrected_stress", "torque", "normal_force")


# ----------------------------------------------------------------------------------------------------------
# quadrature and batched model evaluation
# ----------------------------------------------------------------------------------------------------------
@lru_cache(maxsize=32)
def _unit_gauss(n: int) -> tuple[np.ndarray, np.ndarray]:
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (x + 1.0), 0.5 * w


def gauss_radii(n: int = 8, radius_m: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre nodes on [0, R] and weights for ``int_0^R f(r) dr ~ sum w_j f(r_j)``.

    Returns ``(r_j, w_j)`` in m (the torque is ``2 pi sum w_j sigma_j r_j^2``). ``n`` nodes integrate
    polynomials in r of degree 2n-1 exactly (neo-Hookean/Mooney-Rivlin torque and thrust are exact for
    n >= 2; an RP3 law ~ r^7 needs n >= 4).
    """
    if n < 1:
        raise ValueError("need at least one Gauss radius")
    x, w = _unit_gauss(int(n))
    return radius_m * x, radius_m * w


def stress_histories(model: ConstitutiveModel, p: Params, time_s: np.ndarray, strain: np.ndarray,
                     restart: np.ndarray | None = None) -> np.ndarray:
    """Shear stress (Pa) of a batch of strain histories ``strain`` (k, n) sharing the time grid (n,).

    Uses the model's batched ``shear_stress_histories`` when it has one, else ``shear_stress_history``
    per row, else (purely elastic laws) ``elastic_shear_stress``. ``restart`` (n,) marks where concatenated
    histories start; only models with ``concatenated_histories`` take it.
    """
    strain = np.atleast_2d(np.asarray(strain, float))
    if restart is not None:
        if not model.concatenated_histories:
            raise ValueError(f"model {model.name!r} cannot evaluate concatenated histories")
        return np.asarray(model.shear_stress_histories(p, time_s, strain, restart), float)
    if hasattr(model, "shear_stress_histories"):
        return np.asarray(model.shear_stress_histories(p, time_s, strain), float)
    if model.supports("shear_history"):
        return np.stack([np.asarray(model.shear_stress_history(p, time_s, row), float) for row in strain])
    if model.supports("elastic_shear"):
        return np.asarray(model.elastic_shear_stress(p, strain.ravel()), float).reshape(strain.shape)
    raise ValueError(f"model {model.name!r} cannot give a shear-stress history")


def apparent_elastic_stress(model: ConstitutiveModel, p: Params, rim_strain: np.ndarray, n_gauss: int = 8) -> np.ndarray:
    """Apparent rim stress 2 M_e/(pi R^3) of the instantaneous elastic law of a ``separable`` (QLV) model at rim
    strains ``rim_strain`` (any shape) [Pa]: ``4 int_0^1 sigma_e(x gamma_R) x^2 dx`` by Gauss-Legendre.

    QLV applies one reduced relaxation function to sigma_e at every radius, so the plate's apparent stress is the
    QLV response of this apparent elastic stress (exact, the quadrature aside): one history per measurement
    instead of one per radius."""
    x, w = _unit_gauss(int(n_gauss))
    rim = np.asarray(rim_strain, float)
    law, law_p = model.instantaneous, model.instantaneous_params(p)
    s = np.asarray(law.elastic_shear_stress(law_p, (x[:, None] * rim.ravel()[None, :]).ravel()), float)
    return (4.0 * (w * x * x) @ s.reshape(x.size, rim.size)).reshape(rim.shape)


#: relative Newton step of :func:`invert_increasing` after which the inversion stops (the next step would be ~1e-12)
NEWTON_SETTLED = 1e-6


def invert_increasing(fun, target: np.ndarray, n_table: int = 128, n_newton: int = 4) -> np.ndarray:
    """Solve ``fun(x) = target`` for an increasing odd ``fun`` of strain: a monotone table inverted by
    interpolation, then Newton steps on the exact function with central-difference slopes (at most ``n_newton``;
    they stop once a step is below :data:`NEWTON_SETTLED` of the strain). The table spans the strains the targets need (the first of 2^-10 ... 512 whose stress holds them; beyond: ValueError). A law that
    softens beyond some strain (a fitted Ogden or Lopez-Pamies law with negative exponents, at strains far beyond
    the data) is inverted on its rising branch from zero strain when that branch holds every target; only a law
    that is not increasing below the targets goes to bisection (:func:`tissuemech.models.qlv.invert_monotone`).

    ``fun`` is called on whole arrays, once per stage (the candidate table tops, the table, each Newton step with
    its two slope points): its cost per call, not per point, dominates a fit's creep curves."""
    target = np.asarray(target, float)
    need = float(np.max(np.abs(target))) if target.size else 0.0
    tops = 2.0 ** np.arange(-10, 10)
    reached = np.flatnonzero(np.asarray(fun(tops), float) >= need)
    if not reached.size:
        raise ValueError(f"cannot invert the elastic law: stress {need:g} Pa not reached for strains <= 1e3")
    top = float(tops[reached[0]])
    grid = np.concatenate([[0.0], np.geomspace(1e-9 * top, top, n_table)])
    table = np.asarray(fun(grid), float)
    falls = np.flatnonzero(~(np.diff(table) > 0))
    if falls.size:
        rising = falls[0] + 1           # table[:rising] is increasing
        if rising < 3 or not table[rising - 1] >= need:
            # not increasing in floating point below the targets (a locking or softening law at these parameters)
            return invert_monotone(fun, target)
        grid, table = grid[:rising], table[:rising]
    x = np.sign(target) * np.interp(np.abs(target), table, grid)
    for _ in range(n_newton):
        h = 1e-7 * np.maximum(np.abs(x), 1e-9 * top)
        f0, f_up, f_down = np.asarray(fun(np.stack([x, x + h, x - h])), float)
        slope = (f_up - f_down) / (2.0 * h)
        step = np.where(slope > 0, (f0 - target) / np.where(slope > 0, slope, 1.0), 0.0)
        x = x - step
        # Newton converges quadratically: after a step below NEWTON_SETTLED of the strain the next would be of the
        # order of its square, below the rounding of the law
        if not np.any(np.abs(step) > NEWTON_SETTLED * np.maximum(np.abs(x), 1e-9 * top)):
            break
    return x


def torque_from_history(model: ConstitutiveModel, p: Params, time_s: np.ndarray, rim_strain: np.ndarray,
                        radius_m: float, n_gauss: int = 8) -> np.ndarray:
    """Torque M(t) in N m for a rim-strain history ``gamma_R(t)`` (each radius with its own history)."""
    r, w = gauss_radii(n_gauss, radius_m)
    rim = np.asarray(rim_strain, float)
    if model.linear_in_strain:
        # sigma(x gamma_R) = x sigma(gamma_R): one history serves every radius (and M = pi R^3 sigma(gamma_R) / 2)
        sigma = (r / radius_m)[:, None] * stress_histories(model, p, np.asarray(time_s, float), rim[None, :])
    else:
        sigma = stress_histories(model, p, np.asarray(time_s, float), (r / radius_m)[:, None] * rim[None, :])
    return 2.0 * np.pi * np.sum((w * r * r)[:, None] * sigma, axis=0)


# ----------------------------------------------------------------------------------------------------------
# torque <-> rim stress
# ----------------------------------------------------------------------------------------------------------
def apparent_rim_stress(torque_nm: np.ndarray, radius_m: float) -> np.ndarray:
    """Rim stress as the instrument reports it, 2M/(pi R^3) (Pa); exact for linear materials only."""
    return 2.0 * np.asarray(torque_nm, float) / (np.pi * radius_m ** 3)


def n_exponent(torque_nm: np.ndarray, rim_strain: np.ndarray, window: int = 7, polyorder: int = 2) -> np.ndarray:
    """Local log-log slope ``n = d lnM / d ln gamma_R`` of a loading curve.

    Method: the points with ``gamma_R > 0`` and ``M > 0`` are sorted by strain, ln M is interpolated onto a
    uniform ln gamma_R grid (same number of points), differentiated with a Savitzky-Golay filter
    (``window`` points, polynomial ``polyorder``; smooths noise while differentiating exactly any
    polynomial of that order in ln gamma) and interpolated back. Points with non-positive strain or torque
    get NaN. |n - 1| > 0.1 means the apparent stress is > 2.5 % off (science.md section 2.1).
    """
    m = np.asarray(torque_nm, float)
    g = np.asarray(rim_strain, float)
    out = np.full(m.shape, np.nan)
    ok = (g > 0) & (m > 0) & np.isfinite(g) & np.isfinite(m)
    if ok.sum() < 3:
        return out
    order = np.argsort(g[ok])
    lg, lm = np.log(g[ok][order]), np.log(m[ok][order])
    keep = np.concatenate([[True], np.diff(lg) > 0])                  # drop repeated strains
    lg, lm = lg[keep], lm[keep]
    npts = lg.size
    if npts < 3:
        return out
    grid = np.linspace(lg[0], lg[-1], npts)
    lm_grid = np.interp(grid, lg, lm)
    win = min(window if window % 2 else window + 1, npts if npts % 2 else npts - 1)
    poly = min(polyorder, win - 1)
    slope = scipy.signal.savgol_filter(lm_grid, win, poly, deriv=1, delta=grid[1] - grid[0], mode="interp")
    out[ok] = np.interp(np.log(g[ok]), grid, slope)
    return out


def rabinowitsch_rim_stress(torque_nm: np.ndarray, rim_strain: np.ndarray, radius_m: float,
                            window: int = 7, polyorder: int = 2) -> np.ndarray:
    """True rim stress from a torque-strain loading curve, M/(2 pi R^3) [3 + d lnM/d ln gamma_R] (Pa).

    The slope comes from :func:`n_exponent` (Savitzky-Golay on log-log). Valid for monotone loading
    (constant-rate ramps, amplitude sweeps of amplitudes); for a linear material it equals the apparent
    stress.
    """
    n = n_exponent(torque_nm, rim_strain, window, polyorder)
    return np.asarray(torque_nm, float) / (2.0 * np.pi * radius_m ** 3) * (3.0 + n)


def creep_rim_strain(model: ConstitutiveModel, p: Params, time_s: np.ndarray, apparent_stress_pa: np.ndarray,
                     radius_m: float, n_gauss: int = 8) -> np.ndarray:
    """Rim strain of a torque-controlled (creep/creep-recovery) test.

    The instrument imposes the torque so that the *apparent* rim stress 2M/(pi R^3) follows
    ``apparent_stress_pa(t)``; each radius carries its own history and the rim strain is solved per time
    step from the torque balance. QLV (``separable``) inverts its apparent elastic law once (exact: one relaxation
    function acts at every radius); other models with ``branch_drives`` (Pipkin-Rogers) use the O(n) stepper
    :func:`tissuemech.models.qlv.stress_controlled_strain`; any other shear-history model the generic
    O(n^2) :func:`tissuemech.models.qlv.stress_controlled_strain_by_history`. For a linear material the
    result equals the homogeneous ``creep_strain``.
    """
    if getattr(model, "separable", False):
        # QLV: M(t) = int G_r(t - s) dM_e(gamma_R(s)), M_e the elastic torque, so the apparent stress is the QLV
        # response of the apparent elastic stress; its history is one pass, the rim strain one monotone inversion
        return creep_rim_strains(model, p, [(time_s, apparent_stress_pa)], n_gauss)[0]
    r, w = gauss_radii(n_gauss, radius_m)
    if hasattr(model, "branch_drives"):
        drives, taus = model.branch_drives(p)
        return stress_controlled_strain(drives, taus, time_s, apparent_stress_pa, strain_factors=r / radius_m,
                                        weights=4.0 * w * r * r / radius_m ** 3)

    def apparent_at_end(t, rim):
        sigma = stress_histories(model, p, t, (r / radius_m)[:, None] * rim[None, :])[:, -1]
        return 4.0 * np.sum(w * r * r * sigma) / radius_m ** 3
    return stress_controlled_strain_by_history(apparent_at_end, time_s, apparent_stress_pa)


def creep_rim_strains(model: ConstitutiveModel, p: Params,
                      histories: Sequence[tuple[np.ndarray, np.ndarray]], n_gauss: int = 8) -> list[np.ndarray]:
    """:func:`creep_rim_strain` of several torque-controlled tests ``(time_s, apparent_stress_pa)`` of a
    ``separable`` (QLV) model, with one inversion of the apparent elastic law for all of them (the law and the
    plate are the same in every test; the inversion's cost is per call, not per point). QLV: ``M(t) = int G_r(t - s)
    dM_e(gamma_R(s))``, ``M_e`` the elastic torque, so the apparent stress is the QLV response of the apparent
    elastic stress; its history is one pass, the rim strain one monotone inversion. Raises ValueError as
    :func:`invert_increasing` does when any test's stress is out of the law's reach."""
    if not getattr(model, "separable", False):
        raise ValueError(f"model {model.name!r} is not separable: invert its creep tests one at a time")
    elastic = [np.asarray(model.elastic_stress_for(p, t, s), float) for t, s in histories]
    rim = invert_increasing(lambda x: apparent_elastic_stress(model, p, x, n_gauss), np.concatenate(elastic))
    return np.split(rim, np.cumsum([e.size for e in elastic])[:-1])


# ----------------------------------------------------------------------------------------------------------
# normal force
# ----------------------------------------------------------------------------------------------------------
def thrust_normal_force(model: ConstitutiveModel, p: Params, rim_strain: np.ndarray, radius_m: float,
                        time_s: np.ndarray | None = None, n_gauss: int = 8) -> np.ndarray:
    """Normal force F = pi int_0^R (N1 - N2) r dr (N; positive = sample pushes the plates apart).

    Without ``time_s`` the model's elastic ``normal_stress_differences`` are used at each rim strain;
    with ``time_s`` and a model that has ``normal_stress_difference_histories`` (QLV) the normal stresses
    carry their history. Mooney-Rivlin: F = (pi/4) gamma_R^2 R^2 (mu + 2 C2).
    """
    r, w = gauss_radii(n_gauss, radius_m)
    rim = np.asarray(rim_strain, float)
    strain = (r / radius_m)[:, None] * rim[None, :]
    if time_s is not None and hasattr(model, "normal_stress_difference_histories"):
        n1, n2 = model.normal_stress_difference_histories(p, np.asarray(time_s, float), strain)
    else:
        n1, n2 = model.normal_stress_differences(p, strain.ravel())
        n1 = np.asarray(n1, float).reshape(strain.shape)
        n2 = np.asarray(n2, float).reshape(strain.shape)
    return np.pi * np.sum((w * r)[:, None] * (n1 - n2), axis=0)


def rim_normal_stress_difference(force_n: np.ndarray, rim_strain: np.ndarray, radius_m: float,
                                 window: int = 7, polyorder: int = 2) -> np.ndarray:
    """Rim value of N1 - N2 from a thrust-strain loading curve: F/(pi R^2) [2 + d lnF/d ln gamma_R] (Pa).

    Inversion of F = pi int_0^R (N1 - N2) r dr (science.md section 2.2); the log-log slope is taken as in
    :func:`n_exponent` (Savitzky-Golay). Needs F > 0 (positive Poynting effect).
    """
    slope = n_exponent(force_n, rim_strain, window, polyorder)
    return np.asarray(force_n, float) / (np.pi * radius_m ** 2) * (2.0 + slope)


# ----------------------------------------------------------------------------------------------------------
# what a fit compares against
# ----------------------------------------------------------------------------------------------------------
def forward_plate(model: ConstitutiveModel, p: Params, time_s: np.ndarray, rim_strain: np.ndarray,
                  radius_m: float, gap_m: float | None = None, target: str = "apparent_stress",
                  n_gauss: int = 8) -> np.ndarray:
    """Model prediction of a parallel-plate measurement, in the quantity the fit compares against.

    Parameters
    ----------
    time_s, rim_strain : the measured rim-strain history (s, 1), real ramps/rise times included
    radius_m : plate radius (m)
    gap_m : not used: with the rim strain given, quasi-static torsion does not depend on the gap
        (accepted so callers can pass the run's geometry uniformly)
    target :
        ``"apparent_stress"`` -- 2M/(pi R^3), the rim stress as the instrument reports it (thesis method);
        ``"corrected_stress"`` -- the true rim stress sigma(gamma_R(t)) that a (perfect) Rabinowitsch
        correction of the data returns, i.e. the model's stress for the rim history itself;
        ``"torque"`` -- M (N m); ``"normal_force"`` -- thrust F (N), see :func:`thrust_normal_force`.
    """
    t = np.asarray(time_s, float)
    rim = np.asarray(rim_strain, float)
    if target == "apparent_stress":
        return apparent_rim_stress(torque_from_history(model, p, t, rim, radius_m, n_gauss), radius_m)
    if target == "torque":
        return torque_from_history(model, p, t, rim, radius_m, n_gauss)
    if target == "corrected_stress":
        return stress_histories(model, p, t, rim[None, :])[0]
    if target == "normal_force":
        return thrust_normal_force(model, p, rim, radius_m, time_s=t, n_gauss=n_gauss)
    raise ValueError(f"unknown target {target!r}; choose one of {TARGETS}")


@dataclass(frozen=True)
class PlateHistories:
    """Several parallel-plate measurements concatenated for :func:`forward_plate_batch`.

    Attributes
    ----------
    time_s, rim_strain : (N,) the histories one after another (s, 1)
    restart : (N,) true at the first sample of each history
    bounds : (n_histories + 1,) start of each history in the concatenation, and N
    radius_m : (n_histories,) plate radius of each history (m)
    """

    time_s: np.ndarray
    rim_strain: np.ndarray
    restart: np.ndarray
    bounds: np.ndarray
    radius_m: np.ndarray

    @classmethod
    def of(cls, histories: Sequence[tuple[np.ndarray, np.ndarray, float]]) -> PlateHistories:
        """From ``(time_s, rim_strain, radius_m)`` of each measurement."""
        sizes = [np.asarray(t).size for t, _, _ in histories]
        bounds = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        restart = np.zeros(int(bounds[-1]), dtype=np.bool_)
        restart[bounds[:-1][np.asarray(sizes) > 0]] = True
        return cls(np.concatenate([np.asarray(t, float) for t, _, _ in histories]),
                   np.concatenate([np.asarray(g, float) for _, g, _ in histories]), restart, bounds,
                   np.array([float(r) for _, _, r in histories]))


def forward_plate_batch(model: ConstitutiveModel, p: Params, histories: PlateHistories,
                        target: str = "apparent_stress", n_gauss: int = 8) -> list[np.ndarray]:
    """:func:`forward_plate` of several measurements in one compiled pass (targets ``apparent_stress``, ``torque``).

    With Gauss radii ``r_j = R x_j`` (weights ``R w_j``) each radius sees the strain ``x_j gamma_R(t)`` whatever
    the plate, so all measurements share one strain batch: the apparent stress is ``4 sum_j w_j x_j^2
    sigma_j(t)`` and the torque ``2 pi R^3 sum_j w_j x_j^2 sigma_j(t)`` -- :func:`torque_from_history`'s sum,
    regrouped; a ``separable`` (QLV) model relaxes the apparent elastic stress once (:func:`apparent_elastic_stress`).
    Models without ``concatenated_histories`` are evaluated one measurement at a time. Returns one array per
    measurement, in order.
    """
    if target not in ("apparent_stress", "torque"):
        raise ValueError(f"batched plate prediction supports 'apparent_stress' and 'torque', not {target!r}")
    b = histories.bounds
    if not model.concatenated_histories:
        return [forward_plate(model, p, histories.time_s[lo:hi], histories.rim_strain[lo:hi], radius, target=target,
                              n_gauss=n_gauss) for lo, hi, radius in zip(b[:-1], b[1:], histories.radius_m)]
    if getattr(model, "separable", False):
        # QLV: one relaxation pass of the apparent elastic stress (apparent_elastic_stress)
        elastic = apparent_elastic_stress(model, p, histories.rim_strain, n_gauss)
        apparent = model.relaxed_stress(p, histories.time_s, elastic[None, :], restart=histories.restart)[0]
    else:
        x, w = _unit_gauss(int(n_gauss))
        sigma = stress_histories(model, p, histories.time_s, x[:, None] * histories.rim_strain[None, :],
                                 restart=histories.restart)
        apparent = 4.0 * ((w * x * x) @ sigma)
    out = [apparent[lo:hi] for lo, hi in zip(b[:-1], b[1:])]
    if target == "torque":
        out = [a * (0.5 * np.pi * radius ** 3) for a, radius in zip(out, histories.radius_m)]
    return out


# ----------------------------------------------------------------------------------------------------------
# oscillation, analysed like the instrument
# ----------------------------------------------------------------------------------------------------------
def first_harmonic_moduli(time_s: np.ndarray, strain: np.ndarray, stress: np.ndarray,
                          frequency_hz: float, n_harmonics: int = 9) -> tuple[float, float] | tuple[np.ndarray, np.ndarray]:
    """G', G'' (Pa) from the first Fourier harmonic of periodic stress and strain signals.

    ``strain`` and ``stress`` are (n,) signals, or (k, n) batches on the one time grid (one least-squares solve
    for all of them); a batch returns two (k,) arrays.

    Both signals are regressed (least squares) on ``1, t`` and ``cos k wt, sin k wt`` for
    ``k = 1..n_harmonics`` (capped below the Nyquist limit of the sampling); the constant and linear terms
    absorb offsets and a slowly decaying start-up transient, the higher harmonics (nonlinear response)
    are fitted alongside so they cannot leak into the first one. ``G* = S_1/Gamma_1`` with the complex
    first-harmonic amplitudes ``X_1 = a - i b`` of ``x = a cos wt + b sin wt = Re(X_1 exp(i wt))`` -- the instrument's
    first-harmonic analysis. Use whole cycles of a (near) steady state.
    """
    t = np.asarray(time_s, float)
    w = 2.0 * np.pi * frequency_hz
    samples_per_cycle = t.size / max((t[-1] - t[0]) * frequency_hz, 1e-300)
    k_max = int(max(1, min(n_harmonics, np.floor(samples_per_cycle / 2.0) - 1)))
    cols = [np.ones_like(t), t - t.mean()]
    for k in range(1, k_max + 1):
        cols += [np.cos(k * w * t), np.sin(k * w * t)]
    strain, stress = np.asarray(strain, float), np.asarray(stress, float)
    batch = strain.ndim == 2
    strain, stress = np.atleast_2d(strain), np.atleast_2d(stress)
    coef, *_ = np.linalg.lstsq(np.column_stack(cols), np.vstack([strain, stress]).T, rcond=None)
    k = strain.shape[0]
    strain_c = coef[2, :k] - 1j * coef[3, :k]
    stress_c = coef[2, k:] - 1j * coef[3, k:]
    g_star = stress_c / strain_c
    if batch:
        return g_star.real.copy(), g_star.imag.copy()
    return float(g_star.real[0]), float(g_star.imag[0])


def oscillation_moduli(model: ConstitutiveModel, p: Params, frequency_hz: float, strain_amplitude,
                       radius_m: float, n_cycles: int = 10, n_analysed: int = 2, points_per_cycle: int = 128,
                       n_gauss: int = 8, target: str = "apparent_stress") -> tuple[np.ndarray, np.ndarray]:
    """Instrument-style G', G'' (Pa) for sinusoidal rim strains ``gamma_R = gamma_0 sin(wt)`` started from rest.

    Each amplitude's rim history is pushed through the torque quadrature (all radii and amplitudes in one
    batched model call), converted to apparent rim stress 2M/(pi R^3) (``target="apparent_stress"``, what
    the instrument reports) or kept as the true rim stress (``"corrected_stress"``), and the last
    ``n_analysed`` of ``n_cycles`` cycles are analysed with :func:`first_harmonic_moduli`. For a linear
    material this equals G*(omega) of the model; for nonlinear ones it gives the amplitude-sweep moduli.
    """
    amps = np.atleast_1d(np.asarray(strain_amplitude, float))
    period = 1.0 / frequency_hz
    t = np.linspace(0.0, n_cycles * period, n_cycles * points_per_cycle + 1)
    rim = amps[:, None] * np.sin(2.0 * np.pi * frequency_hz * t)[None, :]
    if getattr(model, "separable", False) and target in ("apparent_stress", "corrected_stress"):
        # QLV: the relaxation function applied once per amplitude to the (apparent) elastic stress
        elastic = (apparent_elastic_stress(model, p, rim, n_gauss) if target == "apparent_stress"
                   else np.asarray(model.elastic_shear_stress(p, rim.ravel()), float).reshape(rim.shape))
        stress = model.relaxed_stress(p, t, elastic)
    elif target == "apparent_stress":
        r, w = gauss_radii(n_gauss, radius_m)
        strain = ((r / radius_m)[None, :, None] * rim[:, None, :]).reshape(-1, t.size)
        sigma = stress_histories(model, p, t, strain).reshape(amps.size, n_gauss, t.size)
        torque = 2.0 * np.pi * np.einsum("j,ajn->an", w * r * r, sigma)
        stress = apparent_rim_stress(torque, radius_m)
    elif target == "corrected_stress":
        stress = stress_histories(model, p, t, rim)
    else:
        raise ValueError("target must be 'apparent_stress' or 'corrected_stress'")
    sel = t >= (n_cycles - n_analysed) * period - 1e-12 * period
    return first_harmonic_moduli(t[sel][:-1], rim[:, sel][:, :-1], stress[:, sel][:, :-1], frequency_hz)


# ----------------------------------------------------------------------------------------------------------
# inertia at high frequency (science.md section 2.5), linear (small-amplitude) frequency domain
# ----------------------------------------------------------------------------------------------------------
def torsion_geometry_factor(radius_m: float, gap_m: float) -> float:
    """b = pi R^4/(2h) (m^3): torque amplitude M = G* theta b for a linear material."""
    return np.pi * radius_m ** 4 / (2.0 * gap_m)


def apparent_complex_modulus(g_star: np.ndarray, frequency_hz: np.ndarray, radius_m: float, gap_m: float,
                             density_kg_m3: float = 0.0, inertia_error_kg_m2: float = 0.0,
                             sensing: str = "moving") -> np.ndarray:
    """Complex modulus an instrument reports when inertia is not (fully) corrected (Pa).

    * Sample inertia (shear wave across the gap, ``k = omega sqrt(rho/G*)``): the torque sensed at the
      moving plate gives ``G* kh cot(kh)`` (~ G* - rho omega^2 h^2/3), at the fixed plate (separate motor
      and transducer) ``G* kh/sin(kh)`` (~ G* + rho omega^2 h^2/6).
    * Instrument inertia calibrated with an error ``dI = I - I_cal`` (kg m^2; combined motor-transducer
      instruments subtract ``I_cal theta''``): ``G*_app = G*_sample - dI omega^2 / b``, b = pi R^4/(2h).

    ``density_kg_m3 = 0`` and ``inertia_error_kg_m2 = 0`` return ``g_star`` unchanged.
    """
    g_star = np.asarray(g_star, complex)
    omega = 2.0 * np.pi * np.asarray(frequency_hz, float)
    out = g_star.copy()
    if density_kg_m3 > 0.0:
        kh = omega * np.sqrt(density_kg_m3 / g_star) * gap_m
        small = np.abs(kh) < 1e-4
        kh_safe = np.where(small, 1.0, kh)
        if sensing == "moving":
            factor = np.where(small, 1.0 - kh ** 2 / 3.0, kh_safe / np.tan(kh_safe))
        elif sensing == "fixed":
            factor = np.where(small, 1.0 + kh ** 2 / 6.0, kh_safe / np.sin(kh_safe))
        else:
            raise ValueError("sensing must be 'moving' or 'fixed'")
        out = g_star * factor
    if inertia_error_kg_m2 != 0.0:
        out = out - inertia_error_kg_m2 * omega ** 2 / torsion_geometry_factor(radius_m, gap_m)
    return out
