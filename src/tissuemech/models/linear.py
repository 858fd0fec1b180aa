"""Linear viscoelastic models (Boltzmann superposition), all expressed through one discrete spectrum.

Every model of this module maps its parameters to a relaxation spectrum

    G(t) = G_inf + sum_i G_i exp(-t/tau_i) + eta_inf delta(t)

(``eta_inf``: a dashpot in parallel, Kelvin-Voigt), so one implementation serves every response:

* arbitrary strain history: ``sigma = G_inf gamma + sum_i h_i + eta_inf d gamma/dt`` with the exact recursion of
  :mod:`tissuemech.models.recursion` (strain piecewise linear in time);
* oscillation: ``G* = G_inf + sum_i G_i i w tau_i/(1 + i w tau_i) + i w eta_inf``;
* creep (stress control): the same recursion solved step by step for the strain (linear in the new strain,
  so each step is explicit), on a refined time grid;
* relaxation modulus ``G(t)``.

Arrangements (Pa, Pa s, s):

``maxwell`` (G, eta)          spring and dashpot in series: G(t) = G exp(-t G/eta)
``kelvin_voigt`` (G, eta)     spring and dashpot in parallel: G(t) = G + eta delta(t)
``sls1`` (G1, G2, eta1)       standard linear solid I (Kelvin form, "SLM I"): spring G1 in series with a
                              Kelvin-Voigt unit (G2, eta1): G_inf = G1 G2/(G1 + G2), G(0) = G1,
                              tau = eta1/(G1 + G2)
``sls2`` (G1, G2, eta1)       standard linear solid II (Zener/Maxwell form, "SLM II"): spring G1 in parallel
                              with a Maxwell arm (G2, eta1): G(t) = G1 + G2 exp(-t G2/eta1); creep
                              J(t) = 1/G1 - (1/G1 - 1/(G1 + G2)) exp(-t G1 G2/(eta1 (G1 + G2)))
``burgers`` (G1, eta1, G2, eta2)  Maxwell (G1, eta1) in series with Kelvin-Voigt (G2, eta2): creep
                              J(t) = 1/G1 + t/eta1 + (1 - exp(-t G2/eta2))/G2; relaxation = two exponentials
``prony{n}`` (G_inf, G_1..G_n, tau_1..tau_n)   generalized Maxwell solid (n = 1..6, 8, 10, 12: ``PRONY_ORDERS``)
``prony{n}_liquid`` (G_1..G_n, tau_1..tau_n)   generalized Maxwell liquid (no equilibrium spring)
``gkv{n}`` (G0, G_1..G_n, tau_ret_1..tau_ret_n)  generalized Kelvin-Voigt solid: spring G0 in series with n
                              Kelvin-Voigt units (spring G_i, retardation time tau_ret_i = eta_i/G_i): creep
                              compliance J(t) = 1/G0 + sum_i (1 - exp(-t/tau_ret_i))/G_i (closed-form creep);
                              relaxation spectrum by exact interconversion (:func:`gkv_relaxation_spectrum`)
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numba import njit
from scipy.linalg import eigh

from .base import ConstitutiveModel, ParamSpec, Params
from .recursion import prony_branch_histories, relaxation_factors

_RESPONSES = frozenset({"shear_history", "oscillation", "creep"})


def _mod(name: str, init: float, lower: float = 1e-4) -> ParamSpec:
    return ParamSpec(name, "Pa", init, lower, 1e9, log=True, description="modulus")


def _visc(name: str, init: float) -> ParamSpec:
    return ParamSpec(name, "Pa s", init, 1e-4, 1e12, log=True, description="viscosity")


def _time(name: str, init: float) -> ParamSpec:
    return ParamSpec(name, "s", init, 1e-5, 1e6, log=True, description="relaxation time")


@njit(cache=True)
def _creep_solve(time_s, stress, g_inf, g_i, taus, eta_inf):
    """Strain under a stress history (piecewise linear in time) for a discrete spectrum, step by step.

    Each step solves ``sigma_{n+1} = G_inf g_{n+1} + sum_i [e_i h_i + G_i f_i (g_{n+1} - g_n)]
    + eta_inf (g_{n+1} - g_n)/dt`` for ``g_{n+1}`` (linear). The first sample is a step from the virgin state.
    """
    n = time_s.size
    m = g_i.size
    gamma = np.zeros(n)
    h = np.zeros(m)
    g0 = g_inf + g_i.sum()
    if eta_inf == 0.0:
        gamma[0] = stress[0] / g0
        for i in range(m):
            h[i] = g_i[i] * gamma[0]
    for k in range(n - 1):
        dt = time_s[k + 1] - time_s[k]
        rhs = stress[k + 1]
        coef = g_inf + eta_inf / dt
        for i in range(m):
            e, f = relaxation_factors(dt, taus[i])
            rhs -= e * h[i] - g_i[i] * f * gamma[k]
            coef += g_i[i] * f
        rhs += eta_inf / dt * gamma[k]
        gamma[k + 1] = rhs / coef
        for i in range(m):
            e, f = relaxation_factors(dt, taus[i])
            h[i] = e * h[i] + g_i[i] * f * (gamma[k + 1] - gamma[k])
    return gamma


def refine_time_grid(time_s: np.ndarray, substeps: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """Insert ``substeps - 1`` equally spaced points in every interval; returns ``(fine_t, index_of_original)``."""
    t = np.asarray(time_s, float)
    if t.size < 2:
        return t.copy(), np.arange(t.size)
    frac = np.arange(substeps) / substeps
    fine = (t[:-1, None] + np.diff(t)[:, None] * frac[None, :]).ravel()
    fine = np.append(fine, t[-1])
    return fine, np.arange(t.size) * substeps


@dataclass
class SpectrumModel(ConstitutiveModel):
    """A linear viscoelastic model given by ``spectrum(p) -> (G_inf, G_i, tau_i, eta_inf)``."""

    linear_in_strain = True
    family: str = "linear_viscoelastic"
    responses: frozenset[str] = field(default_factory=lambda: _RESPONSES)
    spectrum_fn: Callable[[Params], tuple[float, np.ndarray, np.ndarray, float]] | None = None

    def spectrum(self, p: Params) -> tuple[float, np.ndarray, np.ndarray, float]:
        """``(G_inf [Pa], G_i [Pa], tau_i [s], eta_inf [Pa s])`` of the model."""
        g_inf, g_i, taus, eta = self.spectrum_fn(p)
        return float(g_inf), np.atleast_1d(np.asarray(g_i, float)), np.atleast_1d(np.asarray(taus, float)), float(eta)

    def relaxation_modulus(self, p: Params, time_s: np.ndarray) -> np.ndarray:
        """G(t) in Pa (without the delta term of a parallel dashpot)."""
        g_inf, g_i, taus, _ = self.spectrum(p)
        t = np.asarray(time_s, float)
        return g_inf + np.sum(g_i[:, None] * np.exp(-t[None, :] / taus[:, None]), axis=0).reshape(t.shape)

    def shear_stress_history(self, p: Params, time_s: np.ndarray, strain: np.ndarray) -> np.ndarray:
        g_inf, g_i, taus, eta = self.spectrum(p)
        t = np.ascontiguousarray(time_s, dtype=float)
        gamma = np.ascontiguousarray(strain, dtype=float)
        stress = g_inf * gamma
        if g_i.size:
            stress = stress + prony_branch_histories(t, g_i[:, None] * gamma[None, :], taus).sum(axis=0)
        if eta > 0.0:
            stress = stress + eta * np.gradient(gamma, t)
        return stress

    def complex_modulus(self, p: Params, angular_frequency_rad_s: np.ndarray) -> np.ndarray:
        g_inf, g_i, taus, eta = self.spectrum(p)
        w = np.asarray(angular_frequency_rad_s, float)
        iwt = 1j * w[None, :] * taus[:, None]
        return g_inf + np.sum(g_i[:, None] * iwt / (1 + iwt), axis=0) + 1j * w * eta

    def creep_strain(self, p: Params, time_s: np.ndarray, stress_pa: np.ndarray) -> np.ndarray:
        g_inf, g_i, taus, eta = self.spectrum(p)
        t = np.asarray(time_s, float)
        fine, idx = refine_time_grid(t)
        s_fine = np.interp(fine, t, np.asarray(stress_pa, float))
        gamma = _creep_solve(fine, s_fine, g_inf, g_i, taus, eta)
        return gamma[idx]


def _maxwell(p):
    return 0.0, [p["G"]], [p["eta"] / p["G"]], 0.0


def _kelvin_voigt(p):
    return p["G"], [], [], p["eta"]


def _sls1(p):
    g1, g2, eta1 = p["G1"], p["G2"], p["eta1"]
    g_inf = g1 * g2 / (g1 + g2)
    return g_inf, [g1 - g_inf], [eta1 / (g1 + g2)], 0.0


def _sls2(p):
    return p["G1"], [p["G2"]], [p["eta1"] / p["G2"]], 0.0


def _burgers(p):
    g1, eta1, g2, eta2 = p["G1"], p["eta1"], p["G2"], p["eta2"]
    # G*(s) = G1 eta1 s (G2 + eta2 s) / (eta1 eta2 s^2 + (eta1 G2 + G1 eta2 + G1 eta1) s + G1 G2)
    b = eta1 * g2 + g1 * eta2 + g1 * eta1
    disc = np.sqrt(max(b * b - 4 * eta1 * eta2 * g1 * g2, 0.0))
    a1 = (b - disc) / (2 * eta1 * eta2)
    a2 = (b + disc) / (2 * eta1 * eta2)
    c1 = g1 * (g2 - eta2 * a1) / (eta2 * (a2 - a1))
    c2 = -g1 * (g2 - eta2 * a2) / (eta2 * (a2 - a1))
    return 0.0, [c1, c2], [1 / a1, 1 / a2], 0.0


def maxwell() -> SpectrumModel:
    return SpectrumModel(name="maxwell", param_specs=(_mod("G", 200.0), _visc("eta", 200.0)), spectrum_fn=_maxwell)


def kelvin_voigt() -> SpectrumModel:
    return SpectrumModel(name="kelvin_voigt", param_specs=(_mod("G", 200.0), _visc("eta", 200.0)),
                         spectrum_fn=_kelvin_voigt)


def sls1() -> SpectrumModel:
    return SpectrumModel(name="sls1", param_specs=(_mod("G1", 300.0), _mod("G2", 300.0), _visc("eta1", 1e3)),
                         spectrum_fn=_sls1)


def sls2() -> SpectrumModel:
    return SpectrumModel(name="sls2", param_specs=(_mod("G1", 100.0), _mod("G2", 100.0), _visc("eta1", 1e3)),
                         spectrum_fn=_sls2)


def burgers() -> SpectrumModel:
    return SpectrumModel(name="burgers", param_specs=(_mod("G1", 300.0), _visc("eta1", 1e5), _mod("G2", 300.0),
                                                      _visc("eta2", 1e3)), spectrum_fn=_burgers)


def prony(n_terms: int, liquid: bool = False) -> SpectrumModel:
    """Generalized Maxwell model with ``n_terms`` modes (free times, initialised one per decade from 0.1 s)."""
    specs = [] if liquid else [_mod("G_inf", 100.0)]
    specs += [_mod(f"G_{i}", 50.0) for i in range(1, n_terms + 1)]
    specs += [_time(f"tau_{i}", 0.1 * 10.0 ** (i - 1)) for i in range(1, n_terms + 1)]

    def spectrum(p, n=n_terms, liquid=liquid):
        return (0.0 if liquid else p["G_inf"], [p[f"G_{i}"] for i in range(1, n + 1)],
                [p[f"tau_{i}"] for i in range(1, n + 1)], 0.0)

    name = f"prony{n_terms}" + ("_liquid" if liquid else "")
    return SpectrumModel(name=name, param_specs=tuple(specs), spectrum_fn=spectrum,
                         structure={"terms": n_terms, "equilibrium_spring": not liquid})


# ------------------------------------------------------------------------------------------------------
# generalized Kelvin-Voigt: a retardation spectrum, converted exactly to the relaxation spectrum
# ------------------------------------------------------------------------------------------------------
def gkv_relaxation_spectrum(g0: float, g_voigt: np.ndarray, tau_ret: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Relaxation spectrum ``(G_inf, G_k, theta_k)`` of a spring ``g0`` in series with Kelvin-Voigt units.

    Under a strain step the Voigt strains ``e`` obey ``D de/dt = G0 gamma 1 - K e`` with ``D = diag(eta_i)``,
    ``K = diag(G_i) + G0 1 1^T`` (the series spring carries ``G0 (gamma - sum e)``). The relaxation rates are
    the eigenvalues ``l_k`` of the symmetric ``S = D^-1/2 K D^-1/2`` (``scipy.linalg.eigh``), and with
    ``w = V^T D^-1/2 1`` the step response is ``G(t) = G0 - G0^2 sum_k w_k^2/l_k (1 - exp(-l_k t))``, i.e.
    ``G_k = G0^2 w_k^2 / l_k``, ``theta_k = 1/l_k`` and ``G_inf = 1/(1/G0 + sum 1/G_i)``. The relaxation times
    interlace the retardation times (``theta_1 < tau_1 < theta_2 < ...``).
    """
    g_voigt = np.atleast_1d(np.asarray(g_voigt, float))
    tau_ret = np.atleast_1d(np.asarray(tau_ret, float))
    eta = g_voigt * tau_ret
    inv_sqrt_eta = 1.0 / np.sqrt(eta)
    stiffness = np.diag(g_voigt) + g0
    rates, vectors = eigh(inv_sqrt_eta[:, None] * stiffness * inv_sqrt_eta[None, :])
    w = vectors.T @ inv_sqrt_eta
    g_k = g0 * g0 * w * w / rates
    g_inf = 1.0 / (1.0 / g0 + np.sum(1.0 / g_voigt))
    order = np.argsort(1.0 / rates)
    return float(g_inf), g_k[order], (1.0 / rates)[order]


def _gkv_parts(p: Params, n: int) -> tuple[float, np.ndarray, np.ndarray]:
    return (float(p["G0"]), np.array([p[f"G_{i}"] for i in range(1, n + 1)], float),
            np.array([p[f"tau_ret_{i}"] for i in range(1, n + 1)], float))


@dataclass
class GeneralizedKelvinVoigt(SpectrumModel):
    """Spring ``G0`` in series with ``n_units`` Kelvin-Voigt units (``G_i``, ``tau_ret_i``).

    Creep is evaluated in closed form from the creep compliance (Boltzmann superposition, exact for a
    piecewise-linear stress history); strain-controlled histories, oscillation and the relaxation modulus go
    through the exactly interconverted relaxation spectrum (:func:`gkv_relaxation_spectrum`), so
    ``G*(omega) J*(omega) = 1``.
    """

    n_units: int = 1

    def spectrum(self, p: Params) -> tuple[float, np.ndarray, np.ndarray, float]:
        g_inf, g_k, theta = gkv_relaxation_spectrum(*_gkv_parts(p, self.n_units))
        return g_inf, g_k, theta, 0.0

    def relaxation_spectrum(self, p: Params) -> tuple[float, np.ndarray, np.ndarray]:
        """``(G_inf, G_k, theta_k)`` (Pa, Pa, s): the Prony (generalized Maxwell) form of the model."""
        return gkv_relaxation_spectrum(*_gkv_parts(p, self.n_units))

    def creep_compliance(self, p: Params, time_s: np.ndarray) -> np.ndarray:
        """``J(t) = 1/G0 + sum_i (1 - exp(-t/tau_ret_i))/G_i`` in 1/Pa."""
        g0, g_v, tau = _gkv_parts(p, self.n_units)
        t = np.asarray(time_s, float)
        return 1.0 / g0 + np.sum((1.0 - np.exp(-t[..., None] / tau)) / g_v, axis=-1)

    def complex_compliance(self, p: Params, angular_frequency_rad_s: np.ndarray) -> np.ndarray:
        """``J*(omega) = 1/G0 + sum_i 1/(G_i (1 + i omega tau_ret_i))`` in 1/Pa (``J' - i J''``)."""
        g0, g_v, tau = _gkv_parts(p, self.n_units)
        w = np.asarray(angular_frequency_rad_s, float)
        return 1.0 / g0 + np.sum(1.0 / (g_v * (1.0 + 1j * w[..., None] * tau)), axis=-1)

    def creep_strain(self, p: Params, time_s: np.ndarray, stress_pa: np.ndarray) -> np.ndarray:
        """``gamma(t) = sigma(t) J(inf) - sum_i q_i(t)/G_i`` with ``q_i = int exp(-(t-s)/tau_ret_i) dsigma(s)``,
        updated exactly for a stress piecewise linear in time (the first sample is a step from rest)."""
        g0, g_v, tau = _gkv_parts(p, self.n_units)
        t = np.ascontiguousarray(time_s, dtype=float)
        sigma = np.ascontiguousarray(stress_pa, dtype=float)
        q = prony_branch_histories(t, np.tile(sigma, (self.n_units, 1)), tau)
        return sigma * (1.0 / g0 + np.sum(1.0 / g_v)) - np.sum(q / g_v[:, None], axis=0)


def gkv(n_units: int) -> GeneralizedKelvinVoigt:
    """Generalized Kelvin-Voigt solid with ``n_units`` Voigt units (retardation times initialised one per
    decade from 0.1 s)."""
    specs = [_mod("G0", 200.0)]
    specs += [ParamSpec(f"G_{i}", "Pa", 200.0, 1e-4, 1e9, log=True, description=f"spring modulus of Voigt unit {i}")
              for i in range(1, n_units + 1)]
    specs += [ParamSpec(f"tau_ret_{i}", "s", 0.1 * 10.0 ** (i - 1), 1e-5, 1e6, log=True,
                        description=f"retardation time of Voigt unit {i}") for i in range(1, n_units + 1)]
    return GeneralizedKelvinVoigt(name=f"gkv{n_units}", param_specs=tuple(specs), n_units=n_units,
                                  structure={"voigt_units": n_units})


#: registry key -> factory (every model family's MODELS has this shape; models.registry merges them)
MODELS: dict[str, Callable[[], ConstitutiveModel]] = {
    "maxwell": maxwell,
    "kelvin_voigt": kelvin_voigt,
    "sls1": sls1,
    "sls2": sls2,
    "burgers": burgers,
}
for _n in range(1, 7):
    MODELS[f"gkv{_n}"] = (lambda n=_n: gkv(n))
#: Prony orders in the registry; 8-12 modes are for spectra over many decades (a TTS mastercurve spans ~14)
PRONY_ORDERS = (1, 2, 3, 4, 5, 6, 8, 10, 12)
for _n in PRONY_ORDERS:
    MODELS[f"prony{_n}"] = (lambda n=_n: prony(n))
    MODELS[f"prony{_n}_liquid"] = (lambda n=_n: prony(n, liquid=True))
