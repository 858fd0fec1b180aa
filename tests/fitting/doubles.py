"""Small, exact reference models used to test the fitter independently of the model library.

They implement the ``models.base.ConstitutiveModel`` API with closed forms, so a failing fitter test points
at the fitter, not at a model.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tissuemech.models.base import ConstitutiveModel, ParamSpec
from tissuemech.models.recursion import prony_branch_histories


@dataclass
class ProxyProny(ConstitutiveModel):
    """Generalized Maxwell with equilibrium spring, fixed taus: G(t) = G_inf + sum G_i exp(-t/tau_i)."""

    taus: tuple[float, ...] = (0.1, 1.0, 10.0, 100.0)
    name: str = "proxy_prony"
    family: str = "linear_viscoelastic"
    responses: frozenset = frozenset({"shear_history", "oscillation"})

    def __post_init__(self):
        specs = [ParamSpec("G_inf", "Pa", 50.0, 1e-6, 1e6, log=True)]
        specs += [ParamSpec(f"G_{i + 1}", "Pa", 20.0, 1e-8, 1e6, log=True) for i in range(len(self.taus))]
        self.param_specs = tuple(specs)
        self.structure = {"taus_s": list(self.taus)}

    def _moduli(self, p):
        return np.array([p[f"G_{i + 1}"] for i in range(len(self.taus))])

    def shear_stress_history(self, p, time_s, strain):
        gi = self._moduli(p)
        h = prony_branch_histories(np.asarray(time_s, float), gi[:, None] * np.asarray(strain, float)[None, :],
                                   np.asarray(self.taus, float))
        return p["G_inf"] * np.asarray(strain, float) + h.sum(axis=0)

    def complex_modulus(self, p, omega):
        x = np.asarray(omega, float)[:, None] * np.asarray(self.taus)[None, :]
        gi = self._moduli(p)
        return p["G_inf"] + (gi * (1j * x) / (1 + 1j * x)).sum(axis=1)


@dataclass
class ProxyReducedPolynomial(ConstitutiveModel):
    """Reduced polynomial of order N in simple shear: sigma = sum_k 2k C_k0 gamma^(2k-1)."""

    order: int = 3
    name: str = "reduced_polynomial3"
    family: str = "hyperelastic"
    responses: frozenset = frozenset({"elastic_shear"})

    def __post_init__(self):
        self.name = f"reduced_polynomial{self.order}"
        self.param_specs = tuple(ParamSpec(f"C{k}0", "Pa", 50.0, 0.0, 1e6) for k in range(1, self.order + 1))
        self.structure = {"order": self.order}

    def elastic_shear_stress(self, p, strain):
        g = np.asarray(strain, float)
        return sum(2 * k * p[f"C{k}0"] * g ** (2 * k - 1) for k in range(1, self.order + 1))


@dataclass
class ProxyMooneyRivlin(ConstitutiveModel):
    """Mooney-Rivlin W = C10 (I1-3) + C01 (I2-3): simple shear sigma = 2 (C10 + C01) gamma."""

    name: str = "mooney_rivlin"
    family: str = "hyperelastic"
    responses: frozenset = frozenset({"elastic_shear", "uniaxial"})
    param_specs: tuple = (ParamSpec("C10", "Pa", 50.0, 0.0, 1e5), ParamSpec("C01", "Pa", 20.0, 0.0, 1e5))

    def elastic_shear_stress(self, p, strain):
        return 2.0 * (p["C10"] + p["C01"]) * np.asarray(strain, float)

    def uniaxial_nominal_stress(self, p, stretch):
        lam = np.asarray(stretch, float)
        return 2.0 * (p["C10"] + p["C01"] / lam) * (lam - lam ** -2)


@dataclass
class ProxyPowerLaw(ConstitutiveModel):
    """Ostwald-de Waele flow curve tau = K rate^n."""

    name: str = "proxy_power_law"
    family: str = "viscous"
    responses: frozenset = frozenset({"flow"})
    param_specs: tuple = (ParamSpec("K", "Pa s^n", 1.0, 1e-8, 1e8, log=True), ParamSpec("n", "1", 0.8, 0.01, 3.0))

    def steady_shear_stress(self, p, rate):
        return p["K"] * np.asarray(rate, float) ** p["n"]


@dataclass
class ProxyNewton(ConstitutiveModel):
    """Newtonian flow curve tau = eta rate."""

    name: str = "proxy_newton"
    family: str = "viscous"
    responses: frozenset = frozenset({"flow"})
    param_specs: tuple = (ParamSpec("eta", "Pa s", 1.0, 1e-8, 1e8, log=True),)

    def steady_shear_stress(self, p, rate):
        return p["eta"] * np.asarray(rate, float)


@dataclass
class ProxyOgden(ConstitutiveModel):
    """One-term Ogden in the 2 mu/alpha^2 form: simple shear sigma = (2 mu/alpha)(l^a - l^-a)/(l + 1/l)."""

    name: str = "ogden1"
    family: str = "hyperelastic"
    responses: frozenset = frozenset({"elastic_shear"})
    param_specs: tuple = (ParamSpec("mu1", "Pa", 500.0, 1e-3, 1e6, log=True), ParamSpec("alpha1", "1", -10.0, -50.0, 50.0))

    def elastic_shear_stress(self, p, strain):
        g = np.asarray(strain, float)
        lam = g / 2 + np.sqrt(1 + g ** 2 / 4)
        a = p["alpha1"]
        return 2 * p["mu1"] / a * (lam ** a - lam ** -a) / (lam + 1 / lam)


@dataclass
class ProxyLopezPamies(ConstitutiveModel):
    """One-term Lopez-Pamies: simple shear sigma = mu gamma ((3 + gamma^2)/3)^(a - 1) (science.md §2.1)."""

    name: str = "lopez_pamies1"
    family: str = "hyperelastic"
    responses: frozenset = frozenset({"elastic_shear"})
    param_specs: tuple = (ParamSpec("mu1", "Pa", 500.0, 1e-3, 1e6, log=True), ParamSpec("alpha1", "1", 2.0, -20.0, 20.0))

    def elastic_shear_stress(self, p, strain):
        g = np.asarray(strain, float)
        return p["mu1"] * g * ((3 + g ** 2) / 3) ** (p["alpha1"] - 1)
