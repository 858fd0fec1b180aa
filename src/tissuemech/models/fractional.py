"""Fractional (springpot-based) linear viscoelastic models, ``science.md`` section 1.6.

* ``springpot`` (c [Pa s^alpha], alpha): G* = c (i w)^alpha, G(t) = c t^-alpha / Gamma(1 - alpha)
* ``fractional_kelvin_voigt`` (G_e, c, alpha): G* = G_e + c (i w)^alpha
* ``fractional_zener`` (G_e, G_m, tau, alpha): G* = G_e + G_m (i w tau)^alpha / (1 + (i w tau)^alpha),
  G(t) = G_e + G_m E_alpha(-(t/tau)^alpha)

These models describe oscillation (frequency sweeps); their relaxation modulus is available as a helper.
The Mittag-Leffler function uses its power series for small arguments and the spectral integral
``E_a(-x^a) = int_0^inf exp(-r x) K_a(r) dr`` otherwise (the two agree to ~1e-8 where both converge).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.integrate import quad
from scipy.special import gamma as gamma_fn

from .base import ConstitutiveModel, ParamSpec, Params


def mittag_leffler_neg(alpha: float, x: np.ndarray) -> np.ndarray:
    """``E_alpha(-x^alpha)`` for ``0 < alpha < 1`` and ``x >= 0`` (complete monotone relaxation function)."""
    x = np.atleast_1d(np.asarray(x, float))
    out = np.empty_like(x)
    for k, xv in enumerate(x):
        z = xv ** alpha
        if z < 1.0:
            terms = np.arange(80)
            out[k] = np.sum((-z) ** terms / gamma_fn(alpha * terms + 1))
        else:
            s = np.sin(alpha * np.pi)
            c = np.cos(alpha * np.pi)

            def kernel(r):
                ra = r ** alpha
                return np.exp(-r * xv) * r ** (alpha - 1) * s / (np.pi * (ra * ra + 2 * ra * c + 1))

            val, _ = quad(kernel, 0.0, np.inf, limit=400, epsabs=1e-12, epsrel=1e-10)
            out[k] = val
    return out


@dataclass
class FractionalModel(ConstitutiveModel):
    family: str = "fractional"
    responses: frozenset[str] = field(default_factory=lambda: frozenset({"oscillation"}))
    gstar_fn: Callable | None = None
    relax_fn: Callable | None = None

    def complex_modulus(self, p: Params, angular_frequency_rad_s: np.ndarray) -> np.ndarray:
        return self.gstar_fn(p, np.asarray(angular_frequency_rad_s, float))

    def relaxation_modulus(self, p: Params, time_s: np.ndarray) -> np.ndarray:
        """G(t) in Pa."""
        return self.relax_fn(p, np.asarray(time_s, float))


def _alpha():
    return ParamSpec("alpha", "1", 0.3, 0.01, 0.99, description="fractional order")


def _c():
    return ParamSpec("c", "Pa s^alpha", 100.0, 1e-6, 1e9, log=True, description="springpot quasi-property")


def _mod(name, init):
    return ParamSpec(name, "Pa", init, 1e-4, 1e9, log=True)


MODELS: dict[str, Callable[[], ConstitutiveModel]] = {
    "springpot": lambda: FractionalModel(
        name="springpot", param_specs=(_c(), _alpha()),
        gstar_fn=lambda p, w: p["c"] * (1j * w) ** p["alpha"],
        relax_fn=lambda p, t: p["c"] * t ** -p["alpha"] / gamma_fn(1 - p["alpha"])),
    "fractional_kelvin_voigt": lambda: FractionalModel(
        name="fractional_kelvin_voigt", param_specs=(_mod("G_e", 100.0), _c(), _alpha()),
        gstar_fn=lambda p, w: p["G_e"] + p["c"] * (1j * w) ** p["alpha"],
        relax_fn=lambda p, t: p["G_e"] + p["c"] * t ** -p["alpha"] / gamma_fn(1 - p["alpha"])),
    "fractional_zener": lambda: FractionalModel(
        name="fractional_zener",
        param_specs=(_mod("G_e", 100.0), _mod("G_m", 100.0), ParamSpec("tau", "s", 0.1, 1e-6, 1e6, log=True), _alpha()),
        gstar_fn=lambda p, w: p["G_e"] + p["G_m"] * (1j * w * p["tau"]) ** p["alpha"]
        / (1 + (1j * w * p["tau"]) ** p["alpha"]),
        relax_fn=lambda p, t: p["G_e"] + p["G_m"] * mittag_leffler_neg(p["alpha"], t / p["tau"])),
}
