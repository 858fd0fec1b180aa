"""Models that extend QLV (science.md sections 1.1, 1.3, 1.5), each with a recursive per-step update that
the TLED FEM can reuse.

* :class:`PipkinRogersModel` -- strain-dependent Prony weights = Pipkin-Rogers = modified superposition:
  branch-specific elastic functions ``R_i(gamma) = g_i(gamma) sigma_e(gamma)`` driven through the same exact
  recursion as QLV. Relaxation curves at different strains are *rescaled vertically* (shape change).
* :class:`SchaperyModel` -- strain-controlled Schapery single integral with a strain-dependent reduced time
  ``a_gamma = exp(-c gamma^2)`` (relaxation curves *shift horizontally* in log t) and nonlinear factors
  ``h = 1 + e gamma^2`` (Haj-Ali & Muliana 2004 update).
* :class:`MaxwellBranchModel` -- finite-strain Maxwell branches in the 1-D simple-shear reduction of
  Reese-Govindjee / Bergstroem-Boyce: equilibrium hyperelastic law plus branches
  ``tau_i = f_i(gamma - gamma_v,i)`` with their own (Ogden) branch energies and
  ``d gamma_v,i/dt = tau_i/eta_i(tau_i)``, optionally with the stress-dependent viscosity
  ``eta(tau) = eta_0/(1 + (|tau|/tau_hat)^(m-1))``.

* :class:`StrainRelaxingBranchModel` -- linear dashpots, nonlinear (cubic) springs: branch strains relax
  linearly, stresses are nonlinear functions of them (science.md section 1.2 form).

All reduce to linear viscoelasticity at small strain and expose ``complex_modulus`` in that limit.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from numba import njit

from .base import ConstitutiveModel, InstantaneousLawModel, ParamSpec, Params, initial_shear_modulus
from .qlv import (available_instantaneous_tags, check_param_names, default_taus,
                  elastic_stress_nd, instantaneous_law, prony_ratio_specs,
                  stress_controlled_strain, stress_controlled_strain_by_history, sub_params, tau_specs)
from .recursion import history_starts, prony_branch_sum_batch, relaxation_factors

__all__ = ["PipkinRogersModel", "SchaperyModel", "MaxwellBranchModel", "StrainRelaxingBranchModel", "MODELS",
           "ogden_shear_stress", "pipkin_rogers_strain_fraction", "pipkin_rogers_ratio"]


def _prony_params(model, p: Params) -> tuple[np.ndarray, np.ndarray]:
    beta = np.array([float(p[f"beta_{i + 1}"]) for i in range(model.n_prony)])
    if np.any(beta < 0):
        raise ValueError(f"Prony ratios beta must be >= 0, got {beta}")
    taus = (np.array([float(p[f"tau_{i + 1}"]) for i in range(model.n_prony)]) if model.free_taus
            else model._taus.copy())
    return beta, taus


@njit(cache=True, inline="always")
def pipkin_rogers_strain_fraction(gamma2, gamma_s2):
    """``s = gamma^2 / (gamma^2 + gamma_s^2)`` of the Pipkin-Rogers weight law (0 at small strain, 1 at large).

    The one definition of the law's strain dependence, called by the 1-D model (:func:`_pipkin_rogers_weights_at`)
    and by the TLED kernels (``fem._kernels``, ``fem.vectorised``, ``fem.cuda``), which pass the 3-D strain measure
    ``I1bar - 3`` of the isochoric deformation as ``gamma2``: it equals ``gamma^2`` in simple shear, so the fitted
    ``gamma_s`` goes to the solver unchanged."""
    return gamma2 / (gamma2 + gamma_s2)


@njit(cache=True, inline="always")
def pipkin_rogers_ratio(beta, kappa, s):
    """``beta_i m_i = beta_i (1 + kappa_i s)``: the strain-scaled branch-to-equilibrium modulus ratio of one Prony
    term; the weights are ``g_i = beta_i m_i / (1 + sum_j beta_j m_j)``, ``g_inf = 1 / (1 + sum_j beta_j m_j)``
    (:class:`PipkinRogersModel`; shared with the TLED kernels as :func:`pipkin_rogers_strain_fraction` is)."""
    return beta * (1.0 + kappa * s)


@njit(cache=True)
def _pipkin_rogers_weights_at(gamma2, beta, kappa, gamma_s2, g_out):
    """The weight law of :class:`PipkinRogersModel` at one squared strain: ``g_i`` into ``g_out``, returns ``g_inf``."""
    s = pipkin_rogers_strain_fraction(gamma2, gamma_s2)
    total = 0.0
    for i in range(beta.size):
        g_out[i] = pipkin_rogers_ratio(beta[i], kappa[i], s)
        total += g_out[i]
    denom = 1.0 + total
    for i in range(beta.size):
        g_out[i] /= denom
    return 1.0 / denom


@njit(cache=True)
def _pipkin_rogers_weights(strain, beta, kappa, gamma_s2):
    g = np.empty((beta.size, strain.size))
    g_inf = np.empty(strain.size)
    point = np.empty(beta.size)
    for k in range(strain.size):
        g_inf[k] = _pipkin_rogers_weights_at(strain[k] * strain[k], beta, kappa, gamma_s2, point)
        g[:, k] = point
    return g_inf, g


@njit(cache=True)
def _pipkin_rogers_stress_kernel(time_s, strain, elastic, beta, kappa, gamma_s2, taus, restart):
    # R_inf + sum h_i with h_i the exact recursion driven by R_i = g_i(gamma) sigma_e, without storing the drives
    k_hist, n = strain.shape
    m = beta.size
    out = np.empty((k_hist, n))
    h = np.empty((k_hist, m))
    previous = np.empty((k_hist, m))
    g = np.empty(m)
    e = np.empty(m)
    f = np.empty(m)
    for k in range(n):
        if not restart[k]:
            for i in range(m):
                e[i], f[i] = relaxation_factors(time_s[k] - time_s[k - 1], taus[i])
        for j in range(k_hist):
            g_inf = _pipkin_rogers_weights_at(strain[j, k] * strain[j, k], beta, kappa, gamma_s2, g)
            acc = 0.0
            for i in range(m):
                drive = g[i] * elastic[j, k]
                if restart[k]:
                    h[j, i] = drive
                else:
                    h[j, i] = e[i] * h[j, i] + f[i] * (drive - previous[j, i])
                previous[j, i] = drive
                acc += h[j, i]
            out[j, k] = g_inf * elastic[j, k] + acc
    return out


def _fixed_or_free_taus(n: int, taus_s, free_taus: bool):
    taus = default_taus(n) if taus_s is None else np.asarray(taus_s, float)
    if taus.shape != (n,) or np.any(taus <= 0):
        raise ValueError(f"need {n} positive relaxation times, got {taus!r}")
    return taus, (tau_specs(n, taus) if free_taus else ())


def _creep_by_history(model: ConstitutiveModel, p: Params, time_s: np.ndarray, stress_pa: np.ndarray) -> np.ndarray:
    """Homogeneous stress control by per-step solves on the model's own strain-driven history."""
    return stress_controlled_strain_by_history(
        lambda t, g: model.shear_stress_histories(p, t, g[None, :])[0, -1], time_s, stress_pa)


class _BatchedHistoryModel(ConstitutiveModel):
    """A model defined by its batched ``shear_stress_histories(p, time_s, strain (k, n))``: one history is a batch
    of one, and stress control is per-step solves on the strain-driven update (:func:`_creep_by_history`)."""

    def shear_stress_history(self, p: Params, time_s: np.ndarray, strain: np.ndarray) -> np.ndarray:
        return self.shear_stress_histories(p, time_s, np.asarray(strain, float)[None, :])[0]

    def creep_strain(self, p: Params, time_s: np.ndarray, stress_pa: np.ndarray) -> np.ndarray:
        """Strain under an imposed homogeneous stress history (per-step solves on the strain-driven update;
        O(n^2), see :func:`tissuemech.models.qlv.stress_controlled_strain_by_history`)."""
        return _creep_by_history(self, p, time_s, stress_pa)


# ==========================================================================================================
# 1.1 Pipkin-Rogers / modified superposition with strain-dependent Prony weights
# ==========================================================================================================
class PipkinRogersModel(InstantaneousLawModel):
    """Strain-dependent Prony weights (Pipkin-Rogers first order == modified superposition in 1-D).

    Step response ``R(gamma, t) = R_inf(gamma) + sum_i R_i(gamma) exp(-t/tau_i)`` with
    ``R_i = g_i(gamma) sigma_e(gamma)``, ``R_inf = (1 - sum g_i(gamma)) sigma_e(gamma)``; for any history
    ``sigma = R_inf(gamma(t)) + sum h_i`` with ``h_i`` the exact recursion driven by ``R_i(gamma(t))``.

    Weight law (admissible for every parameter value, nested on QLV at ``kappa = 0``)::

        s(gamma)  = gamma^2 / (gamma^2 + gamma_s^2)               (0 at small strain -> 1 at large strain)
        m_i       = 1 + kappa_i s(gamma)                           (kappa_i > -1)
        g_i(gamma) = beta_i m_i / (1 + sum_j beta_j m_j),   g_inf(gamma) = 1 / (1 + sum_j beta_j m_j)

    i.e. the branch-to-equilibrium modulus ratios ``beta_i`` are scaled by ``m_i(gamma)``; sum g < 1 holds
    automatically. For small sum(g) this is the brief form ``g_i0 + Delta g_i s(gamma)`` with
    ``Delta g_i ~ kappa_i g_i0``. Default (parsimonious, thesis-compatible): one shared ``kappa`` (the
    weights keep their ratios and all grow, ``kappa > 0``, or shrink, ``kappa < 0``, with strain; its sign is
    estimated, not assumed) and one ``gamma_s``: +2 parameters over QLV. ``per_branch=True`` fits
    ``kappa_1..kappa_n``. At ``kappa = 0`` ``gamma_s`` is not identifiable (profile it or test the nested QLV).
    """

    concatenated_histories = True

    def __init__(self, instantaneous: ConstitutiveModel, n_prony: int = 4, taus_s: Sequence[float] | None = None,
                 free_taus: bool = False, per_branch: bool = False, name: str | None = None):
        if not instantaneous.supports("elastic_shear"):
            raise ValueError(f"instantaneous law {instantaneous.name!r} has no elastic_shear response")
        taus, tspecs = _fixed_or_free_taus(n_prony, taus_s, free_taus)
        kappa_names = [f"kappa_{i + 1}" for i in range(n_prony)] if per_branch else ["kappa"]
        nonlinear = tuple(ParamSpec(k, "1", 0.0, -0.95, 50.0, False,
                                    "relative growth of the Prony modulus ratios at large strain")
                          for k in kappa_names)
        nonlinear += (ParamSpec("gamma_s", "1", 0.2, 0.005, 5.0, True,
                                "strain scale of the weight change (half change at gamma = gamma_s)"),)
        specs = check_param_names(instantaneous.param_specs, prony_ratio_specs(n_prony), tspecs, nonlinear)
        super().__init__(name=name or f"pr_{instantaneous.name}_prony{n_prony}", family="beyond_qlv",
                         param_specs=specs,
                         responses=frozenset({"shear_history", "creep", "oscillation", "elastic_shear"}
                                             | ({"normal_stress"} if instantaneous.supports("normal_stress")
                                                else set())),
                         structure={"kind": "pipkin_rogers", "instantaneous": instantaneous.name,
                                    "n_prony": n_prony, "free_taus": bool(free_taus),
                                    "taus_s": None if free_taus else [float(t) for t in taus],
                                    "per_branch": bool(per_branch),
                                    "weights": "g_i = beta_i m_i/(1+sum beta m), m_i = 1+kappa_i g^2/(g^2+gs^2)"})
        self.instantaneous = instantaneous
        self.n_prony = n_prony
        self.free_taus = bool(free_taus)
        self.per_branch = bool(per_branch)
        self._taus = taus
        self._kappa_names = kappa_names

    def instantaneous_params(self, p: Params) -> dict[str, float]:
        return sub_params(self.instantaneous, p)

    def elastic_shear_stress(self, p: Params, strain: np.ndarray) -> np.ndarray:
        """Instantaneous law sigma_e(gamma) = R(gamma, 0) (Pa)."""
        return elastic_stress_nd(self.instantaneous, self.instantaneous_params(p), strain)

    def _weight_params(self, p: Params) -> tuple[np.ndarray, np.ndarray, float]:
        """``(beta, kappa, gamma_s^2)`` with one ``kappa`` per branch."""
        beta, _ = _prony_params(self, p)
        kappa = np.broadcast_to(np.array([float(p[k]) for k in self._kappa_names]), beta.shape)
        return beta, np.ascontiguousarray(kappa, dtype=float), float(p["gamma_s"]) ** 2

    def weight_law_parameters(self, p: Params) -> dict:
        """The weight law's parameters as a material card and the TLED solver take them: ``beta`` and ``kappa``
        per Prony term (a shared ``kappa`` repeated), ``gamma_s`` and the relaxation times ``tau_s``."""
        beta, taus = _prony_params(self, p)
        _, kappa, gamma_s2 = self._weight_params(p)
        return {"beta": [float(b) for b in beta], "kappa": [float(k) for k in kappa],
                "gamma_s": float(np.sqrt(gamma_s2)), "tau_s": [float(t) for t in taus]}

    def weights(self, p: Params, strain: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(g_inf(gamma), g(gamma))`` with shapes ``strain.shape`` and ``(n_prony, *strain.shape)``."""
        strain = np.asarray(strain, float)
        g_inf, g = _pipkin_rogers_weights(np.ascontiguousarray(strain.ravel()), *self._weight_params(p))
        return g_inf.reshape(strain.shape), g.reshape((self.n_prony,) + strain.shape)

    def branch_elastic_functions(self, p: Params, strain: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(R_inf(gamma), R_i(gamma))`` in Pa (shapes as :meth:`weights`)."""
        se = self.elastic_shear_stress(p, strain)
        g_inf, g = self.weights(p, strain)
        return g_inf * se, g * se[None]

    def branch_drives(self, p: Params):
        """``(gamma -> (R_inf, R_i), taus)`` for :func:`tissuemech.models.qlv.stress_controlled_strain`."""
        _, taus = _prony_params(self, p)
        weight_params = self._weight_params(p)
        law, law_p = self.instantaneous, self.instantaneous_params(p)

        def drives(gamma):          # called per solver iteration: parameters unpacked once, above
            gamma = np.asarray(gamma, float)
            se = np.asarray(law.elastic_shear_stress(law_p, gamma), float)
            g_inf, g = _pipkin_rogers_weights(np.ascontiguousarray(gamma.ravel()), *weight_params)
            return g_inf.reshape(gamma.shape) * se, g.reshape((self.n_prony,) + gamma.shape) * se
        return drives, taus

    def creep_strain(self, p: Params, time_s: np.ndarray, stress_pa: np.ndarray) -> np.ndarray:
        """Strain under an imposed homogeneous stress history (per-step scalar solve, science.md 1.0)."""
        drives, taus = self.branch_drives(p)
        return stress_controlled_strain(drives, taus, time_s, stress_pa)

    def shear_stress_histories(self, p: Params, time_s: np.ndarray, strain: np.ndarray,
                               restart: np.ndarray | None = None) -> np.ndarray:
        """Stress (Pa) for strain histories (k, n) on the time grid (n,); ``restart`` (n,) marks where
        concatenated histories start (:func:`.recursion.history_starts`)."""
        _, taus = _prony_params(self, p)
        strain = np.ascontiguousarray(np.atleast_2d(np.asarray(strain, float)))
        elastic = np.ascontiguousarray(self.elastic_shear_stress(p, strain))
        return _pipkin_rogers_stress_kernel(np.ascontiguousarray(time_s, dtype=float), strain, elastic,
                                            *self._weight_params(p), taus, history_starts(strain.shape[1], restart))

    def shear_stress_history(self, p: Params, time_s: np.ndarray, strain: np.ndarray) -> np.ndarray:
        return self.shear_stress_histories(p, time_s, np.asarray(strain, float)[None, :])[0]

    def normal_stress_difference_histories(self, p: Params, time_s: np.ndarray,
                                           strain: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """N1, N2 histories (k, n): the same strain-dependent weights applied to the instantaneous N1, N2."""
        if not self.supports("normal_stress"):
            self._unsupported("normal_stress")
        _, taus = _prony_params(self, p)
        strain = np.atleast_2d(np.asarray(strain, float))
        g_inf, g = self.weights(p, strain)
        out = []
        for n_e in self.instantaneous.normal_stress_differences(self.instantaneous_params(p), strain.ravel()):
            n_e = np.asarray(n_e, float).reshape(strain.shape)
            drive = np.ascontiguousarray(np.moveaxis(g * n_e[None], 0, 1))
            out.append(g_inf * n_e + prony_branch_sum_batch(np.ascontiguousarray(time_s, dtype=float), drive, taus))
        return out[0], out[1]

    def step_relaxation_modulus(self, p: Params, time_s: np.ndarray, strain0: float) -> np.ndarray:
        """Closed form G(t, gamma0) = [R_inf(gamma0) + sum R_i(gamma0) exp(-t/tau_i)] / gamma0 (Pa), ideal step."""
        _, taus = _prony_params(self, p)
        r_inf, r_i = self.branch_elastic_functions(p, np.array([strain0]))
        t = np.asarray(time_s, float)
        return (r_inf[0] + np.sum(r_i[:, 0, None] * np.exp(-t[None, :] / taus[:, None]), axis=0)) / strain0

    def complex_modulus(self, p: Params, angular_frequency_rad_s: np.ndarray) -> np.ndarray:
        """Small-strain limit (weights at gamma -> 0 equal the QLV weights beta_i/(1+sum beta))."""
        beta, taus = _prony_params(self, p)
        g = beta / (1.0 + beta.sum())
        g0 = initial_shear_modulus(self.instantaneous, self.instantaneous_params(p))
        iwt = 1j * np.asarray(angular_frequency_rad_s, float)[None, :] * taus[:, None]
        return g0 * (1.0 - g.sum() + np.sum(g[:, None] * iwt / (1.0 + iwt), axis=0))


# ==========================================================================================================
# 1.3 Schapery single integral, strain controlled
# ==========================================================================================================
_SCHAPERY_TERMS = {
    "a": ParamSpec("c_shift", "1", 0.0, -20.0, 20.0, False,
                   "reduced-time shift a_gamma = exp(-c gamma^2); c > 0 relaxes faster at large strain"),
    "he": ParamSpec("e_e", "1", 0.0, -0.9, 100.0, False, "equilibrium factor h_e = 1 + e_e gamma^2"),
    "h1": ParamSpec("e_1", "1", 0.0, -0.9, 100.0, False, "outer transient factor h_1 = 1 + e_1 gamma^2"),
    "h2": ParamSpec("e_2", "1", 0.0, -0.9, 100.0, False, "inner transient factor h_2 = 1 + e_2 gamma^2"),
}


class SchaperyModel(_BatchedHistoryModel):
    """Schapery single-integral model, strain-controlled form (science.md section 1.3)::

        sigma(t) = h_e G_inf gamma(t) + h_1 sum_i q_i(t),
        q_i = int_0^t G_i exp(-(rho(t) - rho(s))/tau_i) d[h_2 gamma]/ds ds,   rho(t) = int_0^t ds/a_gamma(gamma(s))

    with ``h_* = 1 + e_* gamma^2`` (evaluated at the current strain) and ``a_gamma = exp(-c gamma^2)``.
    Moduli: ``G0`` (instantaneous small-strain modulus) and ``beta_i = G_i/G_inf`` as in QLV, so
    ``G_inf = G0/(1+sum beta)``, ``G_i = beta_i G_inf``. Update (Haj-Ali & Muliana 2004): reduced-time
    increment ``d rho = dt / a_gamma(gamma_{n+1/2})`` (midpoint strain) and the exact exponential recursion in
    ``rho`` driven by ``G_i (h_2 gamma)``. Step ``gamma0``: ``sigma = h_e G_inf gamma0 +
    h_1 h_2 gamma0 sum G_i exp(-t/(a tau_i))`` (horizontal shift in log t).

    ``terms`` selects the nonlinear functions fitted (others fixed to 1); default ``("a", "he", "h2")``:
    h_1 and h_2 enter a step only as a product, so the pair is separable only from ramps/unloading.
    """

    def __init__(self, n_prony: int = 4, taus_s: Sequence[float] | None = None, free_taus: bool = False,
                 terms: Sequence[str] = ("a", "he", "h2"), name: str | None = None):
        unknown = set(terms) - set(_SCHAPERY_TERMS)
        if unknown:
            raise ValueError(f"unknown Schapery terms {sorted(unknown)}; known {sorted(_SCHAPERY_TERMS)}")
        taus, tspecs = _fixed_or_free_taus(n_prony, taus_s, free_taus)
        g0 = ParamSpec("G0", "Pa", 200.0, 1.0e-2, 1.0e7, True, "instantaneous small-strain shear modulus")
        specs = check_param_names((g0,), prony_ratio_specs(n_prony), tspecs,
                                  tuple(_SCHAPERY_TERMS[t] for t in _SCHAPERY_TERMS if t in terms))
        super().__init__(name=name or f"schapery_prony{n_prony}", family="beyond_qlv", param_specs=specs,
                         responses=frozenset({"shear_history", "creep", "oscillation", "elastic_shear"}),
                         structure={"kind": "schapery", "n_prony": n_prony, "free_taus": bool(free_taus),
                                    "taus_s": None if free_taus else [float(t) for t in taus],
                                    "terms": [t for t in _SCHAPERY_TERMS if t in terms]})
        self.n_prony = n_prony
        self.free_taus = bool(free_taus)
        self._taus = taus
        self.terms = tuple(terms)

    def _factor(self, p: Params, term: str, gam2: np.ndarray) -> np.ndarray | float:
        if term not in self.terms:
            return 1.0 if term != "a" else np.ones_like(gam2)
        value = float(p[_SCHAPERY_TERMS[term].name])
        return np.exp(-value * gam2) if term == "a" else 1.0 + value * gam2

    def moduli(self, p: Params) -> tuple[float, np.ndarray, np.ndarray]:
        """``(G_inf, G_i, tau_i)`` in Pa, Pa, s."""
        beta, taus = _prony_params(self, p)
        g_inf = float(p["G0"]) / (1.0 + beta.sum())
        return g_inf, beta * g_inf, taus

    def elastic_shear_stress(self, p: Params, strain: np.ndarray) -> np.ndarray:
        """Instantaneous response to a step: (h_e G_inf + h_1 h_2 sum G_i) gamma (Pa)."""
        g_inf, g_i, _ = self.moduli(p)
        gam = np.asarray(strain, float)
        gam2 = gam * gam
        return (self._factor(p, "he", gam2) * g_inf
                + self._factor(p, "h1", gam2) * self._factor(p, "h2", gam2) * g_i.sum()) * gam

    def shear_stress_histories(self, p: Params, time_s: np.ndarray, strain: np.ndarray) -> np.ndarray:
        g_inf, g_i, taus = self.moduli(p)
        t = np.asarray(time_s, float)
        gam = np.atleast_2d(np.asarray(strain, float))
        gam2 = gam * gam
        mid2 = (0.5 * (gam[:, 1:] + gam[:, :-1])) ** 2
        d_rho = np.diff(t)[None, :] / self._factor(p, "a", mid2)
        rho = np.concatenate([np.zeros((gam.shape[0], 1)), np.cumsum(d_rho, axis=1)], axis=1)
        inner = self._factor(p, "h2", gam2) * gam                      # h_2 gamma
        drive = np.ascontiguousarray(g_i[None, :, None] * inner[:, None, :])   # (k, m, n): G_i h_2 gamma
        out = np.empty_like(gam)
        for j in range(gam.shape[0]):        # the reduced-time clock differs per history
            q = prony_branch_sum_batch(np.ascontiguousarray(rho[j]), drive[j:j + 1], taus)[0]
            out[j] = self._factor(p, "he", gam2[j]) * g_inf * gam[j] + self._factor(p, "h1", gam2[j]) * q
        return out

    def step_relaxation_stress(self, p: Params, time_s: np.ndarray, strain0: float) -> np.ndarray:
        """Closed-form ideal step response (Pa)."""
        g_inf, g_i, taus = self.moduli(p)
        g2 = np.array([strain0 ** 2])
        a = self._factor(p, "a", g2)[0]
        t = np.asarray(time_s, float)
        relax = np.sum(g_i[:, None] * np.exp(-t[None, :] / (a * taus[:, None])), axis=0)
        return (self._factor(p, "he", g2)[0] * g_inf
                + self._factor(p, "h1", g2)[0] * self._factor(p, "h2", g2)[0] * relax) * strain0

    def complex_modulus(self, p: Params, angular_frequency_rad_s: np.ndarray) -> np.ndarray:
        g_inf, g_i, taus = self.moduli(p)
        iwt = 1j * np.asarray(angular_frequency_rad_s, float)[None, :] * taus[:, None]
        return g_inf + np.sum(g_i[:, None] * iwt / (1.0 + iwt), axis=0)


# ==========================================================================================================
# 1.5 finite-strain Maxwell branches (1-D shear reduction)
# ==========================================================================================================
@njit(cache=True)
def _ogden_shear(gamma, mu, alpha):
    """One-term Ogden simple-shear stress (2 mu/alpha)(l^a - l^-a)/(l + 1/l), l = gamma/2 + sqrt(1 + gamma^2/4)."""
    lam = 0.5 * gamma + np.sqrt(1.0 + 0.25 * gamma * gamma)
    if abs(alpha) < 1e-8:       # alpha -> 0 limit: (2 mu/alpha)(l^a - l^-a) -> 4 mu ln(l)
        return 4.0 * mu * np.log(lam) / (lam + 1.0 / lam)
    la = lam ** alpha
    return (2.0 * mu / alpha) * (la - 1.0 / la) / (lam + 1.0 / lam)


@njit(cache=True)
def _ogden_shear_array(flat, mu, alpha):
    out = np.empty(flat.shape[0])
    for k in range(flat.shape[0]):
        out[k] = _ogden_shear(flat[k], mu, alpha)
    return out


def ogden_shear_stress(strain: np.ndarray, mu_pa: float, alpha: float) -> np.ndarray:
    """Vectorised one-term Ogden simple-shear stress (Pa); ``alpha = 2`` is neo-Hookean ``mu gamma``."""
    strain = np.asarray(strain, float)
    return _ogden_shear_array(np.ascontiguousarray(strain.ravel()), float(mu_pa), float(alpha)).reshape(strain.shape)


@njit(cache=True)
def _flow_rate_per_strain(x, mu, alpha, tau, tau_hat, m_exp):
    """Strain-relaxation rate k(x) = (d gamma_v/dt)/x = f(x)/(eta(f) x) of a branch at elastic strain x (1/s),
    eta(f) = mu tau_i/(1 + (|f|/tau_hat)^(m-1)); k(0) = 1/tau_i."""
    if abs(x) < 1e-12:
        return 1.0 / tau
    f = _ogden_shear(x, mu, alpha)
    boost = 1.0
    if tau_hat > 0.0:
        boost += (abs(f) / tau_hat) ** (m_exp - 1.0)
    return f * boost / (mu * tau * x)


@njit(cache=True)
def _branch_residual(y, x, dg, dt, mu, alpha, tau, tau_hat, m_exp):
    """r(y) = y - a x - b dg with a = exp(-dt k), b = (1 - a)/(dt k), k at the midpoint (x + y)/2."""
    kk = _flow_rate_per_strain(0.5 * (x + y), mu, alpha, tau, tau_hat, m_exp) * dt
    a = np.exp(-kk)
    b = (1.0 - a) / kk if kk > 1e-12 else 1.0 - 0.5 * kk
    return y - a * x - b * dg


@njit(cache=True)
def _branch_step(x, dg, dt, mu, alpha, tau, tau_hat, m_exp):
    """New branch elastic strain after one (sub)step: root of :func:`_branch_residual`.

    The root lies in [lo, hi] (a, b in (0, 1] => r(lo) <= 0 <= r(hi)); secant iterations from the
    frozen-rate prediction, falling back to bisection whenever a step leaves the shrinking bracket.
    """
    lo = min(0.0, x) + min(0.0, dg)
    hi = max(0.0, x) + max(0.0, dg)
    kk = _flow_rate_per_strain(x, mu, alpha, tau, tau_hat, m_exp) * dt
    a = np.exp(-kk)
    b = (1.0 - a) / kk if kk > 1e-12 else 1.0 - 0.5 * kk
    y = min(max(a * x + b * dg, lo), hi)
    r = _branch_residual(y, x, dg, dt, mu, alpha, tau, tau_hat, m_exp)
    tol = 1e-14 * (1.0 + abs(x) + abs(dg))
    y_prev = y
    r_prev = r
    y_new = y - r                       # dr/dy = 1 + O(dt k'): a fixed-point step seeds the secant
    for _ in range(200):
        if r == 0.0:
            return y
        if r > 0.0:
            hi = y
        else:
            lo = y
        if not (lo < y_new < hi):
            y_new = 0.5 * (lo + hi)
        if abs(y_new - y) < tol or hi - lo < tol:
            return y_new
        y_prev, r_prev = y, r
        y = y_new
        r = _branch_residual(y, x, dg, dt, mu, alpha, tau, tau_hat, m_exp)
        slope = (r - r_prev) / (y - y_prev)
        y_new = y - r / slope if slope > 0.0 else 0.5 * (lo + hi)
    return y


@njit(cache=True)
def _maxwell_branch_kernel(time_s, strain, mu, alpha, tau, tau_hat, m_exp, rate_change_tol):
    """Sum of branch stresses (k, n). Per (sub)step, the branch elastic strain x solves

        x = exp(-dt k) x_n + (1 - exp(-dt k))/(dt k) d_gamma,   k = k((x_n + x)/2)   (implicit exponential
                                                                                    midpoint update)

    with k(x) = (d gamma_v/dt)/x the branch's strain-relaxation rate. Exact for linear branches at any step
    size (k constant), second order when k varies; the root is bracketed and found by safeguarded secant
    iterations (:func:`_branch_step`). Nonlinear branches are sub-stepped adaptively: a sub-step h is
    accepted when |k(x_pred) - k(x)| h <= rate_change_tol (x_pred the frozen-rate prediction), the next
    one tries 2h -- fine where the branch is strained and relaxing, one step once it has relaxed.
    """
    k_hist, n = strain.shape
    m = mu.shape[0]
    out = np.zeros((k_hist, n))
    for i in range(m):
        linear = (alpha[i] == 2.0) and (tau_hat <= 0.0)
        for j in range(k_hist):
            x = strain[j, 0]                               # a step is instantaneous: no flow yet
            out[j, 0] += _ogden_shear(x, mu[i], alpha[i])
            for k in range(n - 1):
                dt_total = time_s[k + 1] - time_s[k]
                dg_total = strain[j, k + 1] - strain[j, k]
                if linear:                                  # constant rate 1/tau: exact closed form
                    kk = dt_total / tau[i]
                    a = np.exp(-kk)
                    b = (1.0 - a) / kk if kk > 1e-12 else 1.0 - 0.5 * kk
                    x = a * x + b * dg_total
                    out[j, k + 1] += mu[i] * x
                    continue
                if dt_total <= 0.0:                         # a jump: instantaneous, no flow
                    x += dg_total
                    out[j, k + 1] += _ogden_shear(x, mu[i], alpha[i])
                    continue
                # adaptive sub-steps: a sub-step h is accepted when the strain-relaxation rate predicted at
                # its end (frozen-rate prediction) differs from the start value by less than tol/h
                rate = dg_total / dt_total
                t_left = dt_total
                h = dt_total
                while t_left > 0.0:
                    if h >= t_left:
                        h = t_left
                    k0 = _flow_rate_per_strain(x, mu[i], alpha[i], tau[i], tau_hat, m_exp)
                    while h > 1e-9 * dt_total:
                        kk = k0 * h
                        a = np.exp(-kk)
                        b = (1.0 - a) / kk if kk > 1e-12 else 1.0 - 0.5 * kk
                        k1 = _flow_rate_per_strain(a * x + b * rate * h, mu[i], alpha[i], tau[i], tau_hat, m_exp)
                        change = abs(k1 - k0) * h
                        if change <= rate_change_tol:
                            break
                        h *= max(0.1, 0.8 * rate_change_tol / change)
                    x = _branch_step(x, rate * h, h, mu[i], alpha[i], tau[i], tau_hat, m_exp)
                    if h >= t_left:
                        t_left = 0.0
                    else:
                        t_left -= h
                    h *= 2.0
                out[j, k + 1] += _ogden_shear(x, mu[i], alpha[i])
    return out


class MaxwellBranchModel(_BatchedHistoryModel):
    """Equilibrium hyperelastic law + finite-strain Maxwell branches (1-D simple-shear reduction).

    Branch ``i``: ``tau_i = f(gamma - gamma_v,i; mu_i, alpha_i)`` with the one-term Ogden simple-shear law
    ``f`` (``alpha = 2`` is neo-Hookean, i.e. linear in shear), viscosity
    ``eta_i(tau) = mu_i tau_i / (1 + (|tau|/tau_hat)^(m-1))`` (``tau_i`` = small-strain relaxation time;
    the stress-dependent part is Bergstroem-Boyce-like, optional), flow ``d gamma_v,i/dt = tau_i/eta_i``.
    Non-separability comes from ``alpha_i`` differing from the equilibrium law's nonlinearity or from
    the stress-dependent viscosity (m > 1: faster relaxation at high stress, a relaxation modulus that
    falls with strain).

    Parameters
    ----------
    equilibrium : elastic law (``elastic_shear``) of the equilibrium network
    n_branches : number of Maxwell branches
    branch_law : ``"ogden"`` (fitted alpha) or ``"neo_hookean"`` (alpha = 2 fixed)
    shared_alpha : one ``alpha_b`` for every branch (default) or ``alpha_1..alpha_n``
    taus_s : fixed small-strain relaxation times (default log-spaced); ``free_taus`` fits ``tau_i``
    stress_dependent_viscosity : add ``tau_hat`` (Pa) and ``m_exp`` (>= 1)
    rate_change_tol : nonlinear branches are sub-stepped so that the change of the branch's strain
        relaxation rate k over a sub-step, times its length, stays below this (second-order scheme:
        error ~ tol^2); linear branches are exact in one step
    """

    def __init__(self, equilibrium: ConstitutiveModel, n_branches: int = 1, branch_law: str = "ogden",
                 shared_alpha: bool = True, taus_s: Sequence[float] | None = None, free_taus: bool = False,
                 stress_dependent_viscosity: bool = False, rate_change_tol: float = 0.01,
                 name: str | None = None):
        if branch_law not in ("ogden", "neo_hookean"):
            raise ValueError(f"branch_law must be 'ogden' or 'neo_hookean', got {branch_law!r}")
        if not equilibrium.supports("elastic_shear"):
            raise ValueError(f"equilibrium law {equilibrium.name!r} has no elastic_shear response")
        n = n_branches
        taus = default_taus(n) if taus_s is None else np.asarray(taus_s, float)
        if taus.shape != (n,) or np.any(taus <= 0):
            raise ValueError(f"need {n} positive relaxation times, got {taus!r}")
        branch = tuple(ParamSpec(f"mu_b{i + 1}", "Pa", 50.0, 1e-3, 1e7, True,
                                 f"small-strain shear modulus of Maxwell branch {i + 1}") for i in range(n))
        if free_taus:
            branch += tuple(ParamSpec(f"tau_b{i + 1}", "s", float(taus[i]), 1e-3, 1e5, True,
                                      f"small-strain relaxation time of branch {i + 1}") for i in range(n))
        if branch_law == "ogden":
            alpha_names = ["alpha_b"] if shared_alpha else [f"alpha_b{i + 1}" for i in range(n)]
            branch += tuple(ParamSpec(a, "1", 2.0, -30.0, 30.0, False, "Ogden exponent of the branch energy")
                            for a in alpha_names)
        else:
            alpha_names = []
        if stress_dependent_viscosity:
            branch += (ParamSpec("tau_hat", "Pa", 100.0, 1e-2, 1e6, True, "viscosity-softening stress scale"),
                       ParamSpec("m_exp", "1", 1.0, 1.0, 10.0, False, "stress exponent (1 = constant viscosity)"))
        specs = check_param_names(equilibrium.param_specs, branch)
        super().__init__(name=name or f"maxwell_{equilibrium.name}_{branch_law}_b{n}", family="beyond_qlv",
                         param_specs=specs,
                         responses=frozenset({"shear_history", "creep", "oscillation", "elastic_shear"}),
                         structure={"kind": "maxwell_branches", "equilibrium": equilibrium.name,
                                    "n_branches": n, "branch_law": branch_law, "shared_alpha": bool(shared_alpha),
                                    "free_taus": bool(free_taus),
                                    "taus_s": None if free_taus else [float(t) for t in taus],
                                    "stress_dependent_viscosity": bool(stress_dependent_viscosity),
                                    "rate_change_tol": float(rate_change_tol)})
        self.equilibrium = equilibrium
        self.n_branches = n
        self.branch_law = branch_law
        self.free_taus = bool(free_taus)
        self.stress_dependent_viscosity = bool(stress_dependent_viscosity)
        self.rate_change_tol = float(rate_change_tol)
        self._taus = taus
        self._alpha_names = alpha_names

    def branch_params(self, p: Params) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float]:
        """``(mu_i [Pa], alpha_i, tau_i [s], tau_hat [Pa] or 0, m_exp)``."""
        n = self.n_branches
        mu = np.array([float(p[f"mu_b{i + 1}"]) for i in range(n)])
        tau = (np.array([float(p[f"tau_b{i + 1}"]) for i in range(n)]) if self.free_taus else self._taus.copy())
        if self.branch_law == "neo_hookean":
            alpha = np.full(n, 2.0)
        else:
            alpha = np.broadcast_to(np.array([float(p[a]) for a in self._alpha_names]), (n,)).copy()
        if self.stress_dependent_viscosity:
            return mu, alpha, tau, float(p["tau_hat"]), float(p["m_exp"])
        return mu, alpha, tau, 0.0, 1.0

    def equilibrium_stress(self, p: Params, strain: np.ndarray) -> np.ndarray:
        return elastic_stress_nd(self.equilibrium, sub_params(self.equilibrium, p), strain)

    def elastic_shear_stress(self, p: Params, strain: np.ndarray) -> np.ndarray:
        """Instantaneous response (no flow): equilibrium + all branch laws at the total strain (Pa)."""
        mu, alpha, _, _, _ = self.branch_params(p)
        out = self.equilibrium_stress(p, strain)
        for mu_i, a_i in zip(mu, alpha):
            out = out + ogden_shear_stress(strain, mu_i, a_i)
        return out

    def shear_stress_histories(self, p: Params, time_s: np.ndarray, strain: np.ndarray) -> np.ndarray:
        mu, alpha, tau, tau_hat, m_exp = self.branch_params(p)
        gam = np.ascontiguousarray(np.atleast_2d(np.asarray(strain, float)))
        branches = _maxwell_branch_kernel(np.ascontiguousarray(time_s, dtype=float), gam, mu, alpha, tau,
                                          tau_hat, m_exp, self.rate_change_tol)
        return self.equilibrium_stress(p, gam) + branches

    def complex_modulus(self, p: Params, angular_frequency_rad_s: np.ndarray) -> np.ndarray:
        """Small strain: mu_inf + sum mu_i i omega tau_i/(1 + i omega tau_i)."""
        mu, _, tau, _, _ = self.branch_params(p)
        mu_inf = initial_shear_modulus(self.equilibrium, sub_params(self.equilibrium, p))
        iwt = 1j * np.asarray(angular_frequency_rad_s, float)[None, :] * tau[:, None]
        return mu_inf + np.sum(mu[:, None] * iwt / (1.0 + iwt), axis=0)


# ==========================================================================================================
# 1.2-type: nonlinear springs on linearly relaxing branch strains
# ==========================================================================================================
class StrainRelaxingBranchModel(_BatchedHistoryModel):
    """Generalized Maxwell arrangement with *linear* (strain-relaxing) dashpots and *nonlinear* springs.

    The branch strains relax linearly and the stress is a nonlinear function of them (science.md section
    1.2, the formulation recalled there for the adaptive QLV of Nekouzadeh et al. 2007 -- not checked
    against that paper, hence not named "AQLV")::

        x_i(t) = int_0^t exp(-(t - s)/tau_i) d gamma/ds ds       (exact recursion on the strain)
        sigma  = sigma_inf(gamma) + sum_i mu_i (x_i + c x_i^3)

    ``sigma_inf`` is an equilibrium elastic law; the branch springs share the dimensionless cubic
    stiffening ``c`` (``c = 0``: linear branches, i.e. a linear Prony series on top of the equilibrium law).
    Step ``gamma0``: ``sigma = sigma_inf(gamma0) + sum mu_i (gamma0 e^{-t/tau_i} + c gamma0^3 e^{-3t/tau_i})`` --
    the cubic part relaxes three times faster, so the relaxation *shape* depends on strain.
    """

    def __init__(self, equilibrium: ConstitutiveModel, n_branches: int = 4, taus_s: Sequence[float] | None = None,
                 free_taus: bool = False, name: str | None = None):
        if not equilibrium.supports("elastic_shear"):
            raise ValueError(f"equilibrium law {equilibrium.name!r} has no elastic_shear response")
        taus, tspecs = _fixed_or_free_taus(n_branches, taus_s, free_taus)
        branch = tuple(ParamSpec(f"mu_b{i + 1}", "Pa", 50.0, 0.0, 1e7, False,
                                 f"small-strain modulus of branch {i + 1}") for i in range(n_branches))
        branch += (ParamSpec("c_b", "1", 0.0, -1.0, 1e3, False, "cubic stiffening of the branch springs"),)
        specs = check_param_names(equilibrium.param_specs, branch, tspecs)
        # the structure record and attributes of QLVModel's constructor (one layout of the fixed/free Prony times
        # that the cards, the ranking and the diagnosis read), for the branches instead of the Prony terms
        super().__init__(name=name or f"srb_{equilibrium.name}_b{n_branches}", family="beyond_qlv",
                         param_specs=specs,
                         responses=frozenset({"shear_history", "creep", "oscillation", "elastic_shear"}),
                         structure={"kind": "strain_relaxing_branches", "equilibrium": equilibrium.name,
                                    "n_branches": n_branches, "free_taus": bool(free_taus),
                                    "taus_s": None if free_taus else [float(t) for t in taus],
                                    "branch_law": "mu_i (x + c x^3)"})
        self.equilibrium = equilibrium
        self.n_prony = n_branches
        self.free_taus = bool(free_taus)
        self._taus = taus

    def _branch(self, p: Params) -> tuple[np.ndarray, float, np.ndarray]:
        mu = np.array([float(p[f"mu_b{i + 1}"]) for i in range(self.n_prony)])
        taus = (np.array([float(p[f"tau_{i + 1}"]) for i in range(self.n_prony)]) if self.free_taus
                else self._taus.copy())
        return mu, float(p["c_b"]), taus

    def equilibrium_stress(self, p: Params, strain: np.ndarray) -> np.ndarray:
        return elastic_stress_nd(self.equilibrium, sub_params(self.equilibrium, p), strain)

    def elastic_shear_stress(self, p: Params, strain: np.ndarray) -> np.ndarray:
        """Instantaneous response (branch strains = total strain), Pa."""
        mu, c, _ = self._branch(p)
        gam = np.asarray(strain, float)
        return self.equilibrium_stress(p, gam) + mu.sum() * (gam + c * gam ** 3)

    def shear_stress_histories(self, p: Params, time_s: np.ndarray, strain: np.ndarray) -> np.ndarray:
        mu, c, taus = self._branch(p)
        gam = np.atleast_2d(np.asarray(strain, float))
        t = np.ascontiguousarray(time_s, dtype=float)
        out = self.equilibrium_stress(p, gam)
        for mu_i, tau_i in zip(mu, taus):
            drive = np.ascontiguousarray(gam[:, None, :])                     # (k, 1, n)
            x = prony_branch_sum_batch(t, drive, np.array([tau_i]))           # relaxed branch strain
            out = out + mu_i * (x + c * x ** 3)
        return out

    def complex_modulus(self, p: Params, angular_frequency_rad_s: np.ndarray) -> np.ndarray:
        mu, _, taus = self._branch(p)
        mu_inf = initial_shear_modulus(self.equilibrium, sub_params(self.equilibrium, p))
        iwt = 1j * np.asarray(angular_frequency_rad_s, float)[None, :] * taus[:, None]
        return mu_inf + np.sum(mu[:, None] * iwt / (1.0 + iwt), axis=0)


# ==========================================================================================================
# registry
# ==========================================================================================================
def _pr(tag: str, per_branch: bool = False) -> Callable[[], ConstitutiveModel]:
    key = f"pr_{tag}_prony4" + ("_perbranch" if per_branch else "")
    return lambda: PipkinRogersModel(instantaneous_law(tag), 4, per_branch=per_branch, name=key)


def _maxwell(tag: str, n: int, law: str, bb: bool, free: bool) -> Callable[[], ConstitutiveModel]:
    key = f"maxwell_{tag}_{'ogden' if law == 'ogden' else 'nh'}_b{n}" + ("_bb" if bb else "")
    taus = [1.0] if n == 1 else None
    return lambda: MaxwellBranchModel(instantaneous_law(tag), n, law, taus_s=taus, free_taus=free,
                                      stress_dependent_viscosity=bb, name=key)


MODELS: dict[str, Callable[[], ConstitutiveModel]] = {}
for _tag in available_instantaneous_tags():
    MODELS[f"pr_{_tag}_prony4"] = _pr(_tag)
    if _tag in ("linear", "rp3"):
        MODELS[f"pr_{_tag}_prony4_perbranch"] = _pr(_tag, per_branch=True)
    if _tag != "linear":
        MODELS[f"maxwell_{_tag}_ogden_b4"] = _maxwell(_tag, 4, "ogden", False, False)
        MODELS[f"maxwell_{_tag}_ogden_b4_bb"] = _maxwell(_tag, 4, "ogden", True, False)
MODELS["maxwell_linear_nh_b4"] = _maxwell("linear", 4, "neo_hookean", False, False)
MODELS["maxwell_linear_ogden_b4"] = _maxwell("linear", 4, "ogden", False, False)
if "ogden1" in available_instantaneous_tags():
    # Budday et al. 2017b: one finite viscoelastic Ogden mode, 5 parameters (mu_inf, alpha_inf, mu_1, alpha_1, eta)
    MODELS["maxwell_ogden1_ogden_b1"] = _maxwell("ogden1", 1, "ogden", False, True)
for _tag in available_instantaneous_tags():
    MODELS[f"srb_{_tag}_b4"] = (lambda tag: lambda: StrainRelaxingBranchModel(instantaneous_law(tag), 4,
                                                                              name=f"srb_{tag}_b4"))(_tag)
MODELS["schapery_prony4"] = lambda: SchaperyModel(4, name="schapery_prony4")
MODELS["schapery_full_prony4"] = lambda: SchaperyModel(4, terms=("a", "he", "h1", "h2"), name="schapery_full_prony4")
