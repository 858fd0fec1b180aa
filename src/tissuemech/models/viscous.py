"""Steady-shear (flow-curve) models: shear stress as a function of shear rate.

=====================  ==========================================  =====================================
key                    law                                         parameters
=====================  ==========================================  =====================================
``newton``             tau = eta g                                 eta [Pa s]
``power_law``          tau = K g^n (Ostwald-de Waele)              K [Pa s^n], n [1]
``bingham``            tau = tau_B + eta_B g                       tau_B [Pa], eta_B [Pa s]
``herschel_bulkley``   tau = tau_y + K g^n                         tau_y [Pa], K [Pa s^n], n [1]
``cross``              eta = eta_inf + (eta0 - eta_inf)/(1 + (lam g)^m)   eta0, eta_inf [Pa s], lam [s], m [1]
``carreau``            eta = eta_inf + (eta0 - eta_inf)(1 + (lam g)^2)^((n-1)/2)  eta0, eta_inf [Pa s], lam [s], n [1]
=====================  ==========================================  =====================================
(g = shear rate in 1/s, tau in Pa.) The thesis fitted the power law (c, p) and Bingham models to agar.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from .base import ConstitutiveModel, ParamSpec, Params


@dataclass
class FlowModel(ConstitutiveModel):
    """A viscous flow law ``stress_fn(p, shear_rate) -> shear stress``."""

    family: str = "viscous"
    responses: frozenset[str] = field(default_factory=lambda: frozenset({"flow"}))
    stress_fn: Callable[[Params, np.ndarray], np.ndarray] | None = None

    def steady_shear_stress(self, p: Params, shear_rate_1_s: np.ndarray) -> np.ndarray:
        return self.stress_fn(p, np.asarray(shear_rate_1_s, float))


def _visc(name, init):
    return ParamSpec(name, "Pa s", init, 1e-6, 1e12, log=True, description="viscosity")


def _stress(name, init):
    return ParamSpec(name, "Pa", init, 1e-6, 1e8, log=True, description="yield stress")


def _index(name, init):
    return ParamSpec(name, "1", init, 1e-3, 3.0, description="flow index")


MODELS: dict[str, Callable[[], ConstitutiveModel]] = {
    "newton": lambda: FlowModel(name="newton", param_specs=(_visc("eta", 1.0),),
                                stress_fn=lambda p, g: p["eta"] * g),
    "power_law": lambda: FlowModel(
        name="power_law",
        param_specs=(ParamSpec("K", "Pa s^n", 100.0, 1e-6, 1e9, log=True, description="consistency"),
                     _index("n", 0.5)),
        stress_fn=lambda p, g: p["K"] * np.abs(g) ** p["n"] * np.sign(g)),
    "bingham": lambda: FlowModel(name="bingham", param_specs=(_stress("tau_B", 10.0), _visc("eta_B", 1.0)),
                                 stress_fn=lambda p, g: np.sign(g) * p["tau_B"] + p["eta_B"] * g),
    "herschel_bulkley": lambda: FlowModel(
        name="herschel_bulkley",
        param_specs=(_stress("tau_y", 10.0), ParamSpec("K", "Pa s^n", 10.0, 1e-6, 1e9, log=True), _index("n", 0.5)),
        stress_fn=lambda p, g: np.sign(g) * (p["tau_y"] + p["K"] * np.abs(g) ** p["n"])),
    "cross": lambda: FlowModel(
        name="cross",
        param_specs=(_visc("eta0", 100.0), _visc("eta_inf", 0.01), ParamSpec("lam", "s", 1.0, 1e-6, 1e6, log=True),
                     _index("m", 0.8)),
        stress_fn=lambda p, g: (p["eta_inf"] + (p["eta0"] - p["eta_inf"]) / (1 + (p["lam"] * np.abs(g)) ** p["m"])) * g),
    "carreau": lambda: FlowModel(
        name="carreau",
        param_specs=(_visc("eta0", 100.0), _visc("eta_inf", 0.01), ParamSpec("lam", "s", 1.0, 1e-6, 1e6, log=True),
                     _index("n", 0.5)),
        stress_fn=lambda p, g: (p["eta_inf"] + (p["eta0"] - p["eta_inf"])
                                * (1 + (p["lam"] * g) ** 2) ** ((p["n"] - 1) / 2)) * g),
}
