"""Hidden effects of science.md section 3 as opt-in injectors, each with magnitude parameters.

An effect configuration is a mapping ``{effect_id: {parameter: value}}``; an empty mapping (the null
configuration) injects nothing. Effects act at four places of the generator:

* the material model (``nonseparable_relaxation``, ``rim_stress_nonlinearity``, ``unidentified_i2_dependence``):
  :func:`modify_truth` returns the model and parameters actually simulated;
* the parameters of one run (``elapsed_time_drift``, ``preconditioning``, ``outlier_specimen``):
  :func:`modulus_factor` scales every parameter with a unit in Pa (moduli, viscosities);
* the instrument (``wall_slip``, ``instrument_inertia``, ``amplitude_softening``, ``torque_offset``):
  :func:`build_artefacts`;
* the protocol (``finite_rise_time``): :func:`protocol_overrides`.

Magnitude parameters and defaults (science.md section 3 "realistic magnitude"):

=============================  ================================================================================
``nonseparable_relaxation``    ``kappa`` (0.6): growth of the Prony modulus ratios at large strain, ``gamma_s`` (0.2)
``rim_stress_nonlinearity``    ``stiffening`` (1.0): adds ``C20 = stiffening G0/4`` (sigma += stiffening G0 gamma^3)
``wall_slip``                  ``sigma_c_pa`` (30), ``beta_s_m_per_pa`` (2e-6): u_s = beta_s max(0, sigma - sigma_c)
                               per wall, on ramps, relaxations and creep (not on oscillation points)
``elapsed_time_drift``         ``kappa_per_h`` (0.1): moduli x (1 + kappa t_elapsed)
``preconditioning``            ``first_load_factor`` (0.2): first test of each sample stiffer by this fraction
                               (a constant virgin-loading factor, not the Ogden-Roxburgh damage function)
``instrument_inertia``         ``calibration_error`` (0.01): dI/I, ``sample_density_kg_m3`` (0)
``torque_offset``              ``offset_unm`` (0.2 uN m), ``drift_unm_per_s`` (1e-3 uN m/s)
``outlier_specimen``           ``factor`` (2.5), ``specimen`` (index, default 0)
``amplitude_softening``        ``gamma_c`` (0.03), ``m`` (1), ``ratio_storage`` (0.7); optional ``ratio_loss``,
                               ``gamma_c_loss``, ``m_loss`` for G'' (default: the G' values)
``finite_rise_time``           ``rise_time_s`` (0.5)
``unidentified_i2_dependence`` ``c01_ratio`` (0.4): C01 = ratio C10 with C10 + C01 fixed (torque unchanged)
=============================  ================================================================================
"""
from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..models.base import ConstitutiveModel, Params, initial_shear_modulus
from ..models.qlv import QLVModel, sub_params
from .instrument import Artefacts
from ..models.beyond_qlv import PipkinRogersModel

EFFECT_IDS: tuple[str, ...] = (
    "nonseparable_relaxation", "rim_stress_nonlinearity", "wall_slip", "elapsed_time_drift",
    "preconditioning", "instrument_inertia", "torque_offset", "outlier_specimen", "amplitude_softening",
    "finite_rise_time", "unidentified_i2_dependence",
)

DEFAULTS: dict[str, dict[str, float]] = {
    "nonseparable_relaxation": {"kappa": 0.6, "gamma_s": 0.2},
    "rim_stress_nonlinearity": {"stiffening": 1.0},
    "wall_slip": {"sigma_c_pa": 30.0, "beta_s_m_per_pa": 2e-6},
    "elapsed_time_drift": {"kappa_per_h": 0.1},
    "preconditioning": {"first_load_factor": 0.2},
    "instrument_inertia": {"calibration_error": 0.01, "sample_density_kg_m3": 0.0},
    "torque_offset": {"offset_unm": 0.2, "drift_unm_per_s": 1e-3},
    "outlier_specimen": {"factor": 2.5, "specimen": 0},
    "amplitude_softening": {"gamma_c": 0.03, "m": 1.0, "ratio_storage": 0.7},
    "finite_rise_time": {"rise_time_s": 0.5},
    "unidentified_i2_dependence": {"c01_ratio": 0.4},
}


def resolve(effects: Mapping[str, Mapping[str, float]] | None) -> dict[str, dict[str, float]]:
    """Validate an effect configuration and fill defaults. Unknown ids or parameters raise ``ValueError``."""
    out: dict[str, dict[str, float]] = {}
    for eff, params in (effects or {}).items():
        if eff not in DEFAULTS:
            raise ValueError(f"unknown effect {eff!r}; known: {', '.join(EFFECT_IDS)}")
        params = dict(params or {})
        optional = {"ratio_loss", "gamma_c_loss", "m_loss"} if eff == "amplitude_softening" else set()
        unknown = set(params) - set(DEFAULTS[eff]) - optional
        if unknown:
            raise ValueError(f"effect {eff!r} has no parameter(s) {sorted(unknown)}; known: {sorted(DEFAULTS[eff])}")
        merged = {**DEFAULTS[eff], **{k: float(v) for k, v in params.items()}}
        if eff == "amplitude_softening":
            merged.setdefault("ratio_loss", merged["ratio_storage"])
            merged.setdefault("gamma_c_loss", merged["gamma_c"])
            merged.setdefault("m_loss", merged["m"])
        out[eff] = merged
    return out


# ----------------------------------------------------------------------------------------------------------
# material-model effects
# ----------------------------------------------------------------------------------------------------------
class AugmentedElasticLaw(ConstitutiveModel):
    """An instantaneous law with a hidden extra energy ``C20x (I1-3)^2 + C01x [(I2-3) - (I1-3)]``.

    In simple shear (I1 = I2 = 3 + gamma^2) the ``C20x`` term adds ``4 C20x gamma^3`` to the shear stress
    (stiffening) and ``gamma`` times that to N1; the ``C01x`` term moves stiffness from I1 to I2 at constant
    W1 + W2, so the shear stress and N1 are unchanged and only ``N2 = -2 gamma^2 W2`` changes by
    ``-2 C01x gamma^2`` -- invisible in torque, visible in the normal force (science.md sections 2.2, 2.3).

    ``c20_extra_pa``/``c01_extra_pa`` are the extras at the population parameters (initial shear modulus
    ``g0_ref_pa``); a specimen or sample whose moduli are scaled (:func:`scale_moduli`) carries extras scaled by
    the same factor, so the hidden term keeps its share of the stiffness in every sample.
    """

    def __init__(self, base: ConstitutiveModel, c20_extra_pa: float = 0.0, c01_extra_pa: float = 0.0,
                 g0_ref_pa: float | None = None):
        super().__init__(name=f"{base.name}+hidden", family=base.family, param_specs=base.param_specs,
                         responses=base.responses | {"normal_stress"},
                         structure={**base.structure, "c20_extra_pa": c20_extra_pa, "c01_extra_pa": c01_extra_pa})
        self.base = base
        self.c20 = float(c20_extra_pa)
        self.c01 = float(c01_extra_pa)
        self.g0_ref = None if g0_ref_pa is None else float(g0_ref_pa)

    def _share(self, p: Params) -> float:
        return 1.0 if not self.g0_ref else initial_shear_modulus(self.base, p) / self.g0_ref

    def elastic_shear_stress(self, p: Params, strain: np.ndarray) -> np.ndarray:
        g = np.asarray(strain, float)
        return np.asarray(self.base.elastic_shear_stress(p, g), float) + 4.0 * self.c20 * self._share(p) * g ** 3

    def normal_stress_differences(self, p: Params, strain: np.ndarray):
        g = np.asarray(strain, float)
        k = self._share(p)
        if self.base.supports("normal_stress"):
            n1, n2 = self.base.normal_stress_differences(p, g)
        else:                                    # a law without normal stresses: universal N1 of the shear law
            n1, n2 = g * np.asarray(self.base.elastic_shear_stress(p, g), float), np.zeros_like(g)
        return (np.asarray(n1, float) + g * 4.0 * self.c20 * k * g ** 3,
                np.asarray(n2, float) - 2.0 * self.c01 * k * g ** 2)


def _rebuild_with_law(model: ConstitutiveModel, law: ConstitutiveModel, kappa: float | None = None,
                      gamma_s: float | None = None):
    """Same viscoelastic structure (QLV or Pipkin-Rogers) on a new instantaneous law."""
    taus = list(model._taus)
    if isinstance(model, PipkinRogersModel):
        return PipkinRogersModel(law, model.n_prony, taus_s=taus, per_branch=model.per_branch, name=model.name)
    if isinstance(model, QLVModel):
        if kappa is not None:
            return PipkinRogersModel(law, model.n_prony, taus_s=taus, name=model.name.replace("qlv", "pr", 1))
        return QLVModel(law, model.n_prony, taus_s=taus, name=model.name)
    raise ValueError(f"model {model.name!r} has no instantaneous law to modify (need a QLV or Pipkin-Rogers truth)")


def modify_truth(model: ConstitutiveModel, params: Params, effects: Mapping[str, Mapping[str, float]]):
    """Apply the material-model effects; returns ``(model, params, record)`` with ``record`` the derived
    magnitudes written to truth.json (e.g. the C20/C01 actually added, in Pa)."""
    params = dict(params)
    record: dict[str, dict] = {}
    if not any(e in effects for e in ("nonseparable_relaxation", "rim_stress_nonlinearity",
                                      "unidentified_i2_dependence")):
        return model, params, record
    law = getattr(model, "instantaneous", None)
    if law is None:
        raise ValueError(f"material effects need a QLV or Pipkin-Rogers truth, got {model.name!r}")
    g0 = initial_shear_modulus(law, sub_params(law, params))
    c20 = c01 = 0.0
    if "rim_stress_nonlinearity" in effects:
        c20 = effects["rim_stress_nonlinearity"]["stiffening"] * g0 / 4.0
        record["rim_stress_nonlinearity"] = {"c20_extra_pa": c20, "instantaneous_g0_pa": g0}
    if "unidentified_i2_dependence" in effects:
        ratio = effects["unidentified_i2_dependence"]["c01_ratio"]
        c01 = ratio / (1.0 + ratio) * g0 / 2.0         # C10 + C01 = G0/2 kept; C01/C10 = ratio
        record["unidentified_i2_dependence"] = {"c01_pa": c01, "c10_pa": g0 / 2.0 - c01}
    new_law = AugmentedElasticLaw(law, c20, c01, g0_ref_pa=g0) if (c20 or c01) else law
    nonsep = effects.get("nonseparable_relaxation")
    model = _rebuild_with_law(model, new_law, kappa=nonsep["kappa"] if nonsep else None) if (
        new_law is not law or (nonsep and not isinstance(model, PipkinRogersModel))) else model
    if nonsep:
        if not isinstance(model, PipkinRogersModel):
            raise ValueError("nonseparable_relaxation needs a QLV or Pipkin-Rogers truth")
        if model.per_branch:
            params.update({f"kappa_{i + 1}": nonsep["kappa"] for i in range(model.n_prony)})
        else:
            params["kappa"] = nonsep["kappa"]
        params["gamma_s"] = nonsep["gamma_s"]
        g_inf0, _ = model.weights(params, np.array([1e-6]))
        g_inf40, _ = model.weights(params, np.array([0.4]))
        record["nonseparable_relaxation"] = {"long_term_fraction_small_strain": float(g_inf0[0]),
                                             "long_term_fraction_at_40pct": float(g_inf40[0])}
    elif isinstance(model, PipkinRogersModel) and "kappa" not in params:
        params["kappa"], params["gamma_s"] = 0.0, 0.2
    return model, params, record


# ----------------------------------------------------------------------------------------------------------
# run-level parameter scaling
# ----------------------------------------------------------------------------------------------------------
def modulus_factor(effects: Mapping[str, Mapping[str, float]], elapsed_h: float, first_load: bool,
                   specimen_index: int) -> float:
    """Multiplicative factor on every Pa-valued parameter of one run (drift, preconditioning, outlier)."""
    factor = 1.0
    if "elapsed_time_drift" in effects:
        factor *= 1.0 + effects["elapsed_time_drift"]["kappa_per_h"] * elapsed_h
    if "preconditioning" in effects and first_load:
        factor *= 1.0 + effects["preconditioning"]["first_load_factor"]
    if "outlier_specimen" in effects and specimen_index == int(effects["outlier_specimen"]["specimen"]):
        factor *= effects["outlier_specimen"]["factor"]
    return factor


def scale_moduli(model: ConstitutiveModel, params: Params, factor: float) -> dict[str, float]:
    """Multiply every parameter whose unit starts with ``Pa`` (moduli, viscosities, consistencies) by ``factor``;
    ratios, exponents and times are unchanged, so the relaxation spectrum keeps its shape."""
    units = {s.name: s.unit for s in model.param_specs}
    return {k: (v * factor if units.get(k, "").startswith("Pa") else v) for k, v in params.items()}


# ----------------------------------------------------------------------------------------------------------
# instrument artefacts and protocol overrides
# ----------------------------------------------------------------------------------------------------------
def kraus_factor(gamma0: np.ndarray, gamma_c: float, m: float, ratio: float) -> np.ndarray:
    """Kraus (Payne-effect) factor ``ratio + (1 - ratio)/(1 + (gamma0/gamma_c)^(2m))``: 1 at small amplitude,
    ``ratio`` at large amplitude."""
    return ratio + (1.0 - ratio) / (1.0 + (np.asarray(gamma0, float) / gamma_c) ** (2.0 * m))


def build_artefacts(effects: Mapping[str, Mapping[str, float]], motor_inertia_kg_m2: float) -> Artefacts:
    """Instrument-side artefacts of an effect configuration (all off for the null configuration)."""
    a = Artefacts()
    if "wall_slip" in effects:
        sc, beta = effects["wall_slip"]["sigma_c_pa"], effects["wall_slip"]["beta_s_m_per_pa"]
        a.slip_length = lambda sigma: beta * np.maximum(0.0, np.asarray(sigma) - sc)
    if "instrument_inertia" in effects:
        a.inertia_error_kg_m2 = effects["instrument_inertia"]["calibration_error"] * motor_inertia_kg_m2
        a.sample_density_kg_m3 = effects["instrument_inertia"]["sample_density_kg_m3"]
    if "amplitude_softening" in effects:
        e = effects["amplitude_softening"]
        a.amplitude_factors = lambda g0: (kraus_factor(g0, e["gamma_c"], e["m"], e["ratio_storage"]),
                                          kraus_factor(g0, e["gamma_c_loss"], e["m_loss"], e["ratio_loss"]))
    if "torque_offset" in effects:
        m0 = effects["torque_offset"]["offset_unm"] * 1e-6
        rate = effects["torque_offset"]["drift_unm_per_s"] * 1e-6
        a.torque_offset = lambda t: m0 + rate * np.asarray(t, float)
    return a


def protocol_overrides(kind: str, effects: Mapping[str, Mapping[str, float]]) -> dict[str, float]:
    """Protocol settings changed by effects (the finite rise time of relaxation steps)."""
    if kind == "stress_relaxation" and "finite_rise_time" in effects:
        return {"rise_time_s": effects["finite_rise_time"]["rise_time_s"]}
    return {}

