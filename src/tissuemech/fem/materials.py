"""3-D hyperelastic and viscoelastic material routines for the TLED solver.

Stress is evaluated per element from the deformation gradient ``F`` with the usual isochoric/volumetric
split (nearly incompressible): ``W = W_iso(I1bar, I2bar) + U(J)``, ``U = kappa/2 (J - 1)^2`` (the FElupe /
NiftySim choice), ``I1bar = J^(-2/3) I1``, ``I2bar = J^(-4/3) I2``. The isochoric Kirchhoff stress is

    tau_iso = 2 dev[(W1 + I1bar W2) bbar - W2 bbar^2]           (invariant laws)
    tau_iso = sum_a (beta_a - mean(beta)) n_a (x) n_a,  beta_a = lbar_a dW/dlbar_a   (stretch laws, Ogden)

and the first Piola-Kirchhoff stress ``P = (tau_iso + J p I) F^-T`` with ``p = U'(J)`` (or the averaged
nodal pressure of the ANP element). Saint Venant-Kirchhoff is the compressible ``S = lambda tr(E) I + 2 mu E``.

The scalar laws are the *same* numba functions the 1-D fitting code uses (``models.hyperelastic
.HYPERELASTIC_LAWS``: ``dW/dI1(params, I1, I2)``, ``dW/dI2(params, I1, I2)`` or Ogden stretch
derivatives); no law is written twice. They reach the compiled TLED
kernels as first-class function pointers (numba ``cfunc``), so one cached kernel serves every law.

Viscoelasticity (QLV / Prony) acts on the isochoric 2nd Piola-Kirchhoff stress as in NiftySim's
``tledMaterialNHV``: ``S_iso = g_inf S_e + sum_i h_i`` with the exact recursion of
:mod:`tissuemech.models.recursion` (``relaxation_factors``) per element and term; the volumetric response
stays elastic.

The nonseparable extension is Pipkin-Rogers (``models.beyond_qlv.PipkinRogersModel``, the model the fits and the
diagnosis use for ``nonseparable_relaxation``), with the fitted parameters unchanged: the Prony weights depend on the
strain, ``g_i(x) = beta_i m_i / (1 + sum_j beta_j m_j)``, ``g_inf(x) = 1 / (1 + sum_j beta_j m_j)``, ``m_i = 1 +
kappa_i s``, ``s = x / (x + gamma_s^2)``, with the 3-D strain measure ``x = I1bar - 3`` of the isochoric deformation
(exactly ``gamma^2`` in simple shear; the weight law is the fitting code's own numba functions
``pipkin_rogers_strain_fraction`` and ``pipkin_rogers_ratio``). Per element and term the recursion is driven by the
branch stress ``g_i(x) S_e``: ``h_i <- exp(-dt/tau_i) h_i + f_i (g_i(x_n+1) S_e,n+1 - g_i(x_n) S_e,n)`` and ``S_iso
= g_inf(x) S_e + sum_i h_i`` -- in 1-D the 1-D model's recursion (``_pipkin_rogers_stress_kernel``). Why
Pipkin-Rogers and not the Holzapfel/Simo overstress with branch energies the solver had: the branch-energy law has no
fitted model (no fit, card or diagnosis produces its parameters), so it could never run a measured material, while
Pipkin-Rogers goes from the fit through the card into the solver unchanged (docs/architecture.md).

Temperature enters through the card's time-temperature shift as a time scale: at a temperature ``T`` the relaxation
times are ``a_T tau_i`` (``tts.wlf_log_aT``; the card's times are those at its reference temperature), see
:func:`material_from_card`; :func:`make_material` takes the shift factor ``a_T`` itself.
"""
from __future__ import annotations

import functools
import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from ..models.base import bulk_modulus, initial_shear_modulus
from ..models.hyperelastic import (HYPERELASTIC_LAWS, INVARIANT_SIG, STRETCH_SIG, as_cfunc, lopez_pamies_dw_di1,
                                  mooney_rivlin_dw_di1, mooney_rivlin_dw_di2,
                                  neo_hookean_dw_di1, ogden_dw_dlambda, reduced_polynomial_dw_di1, zero_dw_di2)
from ..records import MaterialCard
from ..tts import wlf_log_aT
from .kinematics import FASTMATH, left_cauchy_green, symmetric_eigen3, symmetric_square

KIND_INVARIANT = 0
KIND_STRETCH = 1
KIND_SVK = 2
#: an invariant law with ``dW/dI2 = 0`` (neo-Hookean, reduced polynomial, Lopez-Pamies, Gent, ...): the
#: kernels skip the ``dW/dI2`` call and ``bbar^2`` (an indirect call costs ~8 ns of a ~70 ns element update)
KIND_INVARIANT_I1 = 3




# --------------------------------------------------------------------------------------------------
# the zero derivative of laws without an I2 (or stretch) part; the laws themselves are the fitting code's
# --------------------------------------------------------------------------------------------------
@njit(cache=True)
def _zero_w(p, i1, i2):
    return 0.0


@njit(cache=True)
def _zero_wl(p, lam):
    return 0.0


@dataclass(frozen=True)
class LawSpec:
    """A hyperelastic law as the kernels see it.

    Attributes
    ----------
    kind : ``"invariant"``, ``"stretch"`` or ``"svk"``
    dw_di1, dw_di2 : njit ``(params, I1bar, I2bar) -> float`` (invariant laws)
    dw_dlambda : njit ``(params, lambda_bar) -> float`` (stretch laws, Valanis-Landel form)
    param_names : order of the parameter vector
    """

    kind: str
    param_names: tuple[str, ...]
    dw_di1: object = _zero_w
    dw_di2: object = _zero_w
    dw_dlambda: object = _zero_wl


def _fallback_laws() -> dict[str, LawSpec]:
    """Keys the fitting code's table does not list (SVK, RP1, LP3), built from the same law functions."""
    laws = {
        "neo_hookean": LawSpec("invariant", ("mu",), neo_hookean_dw_di1),
        "mooney_rivlin": LawSpec("invariant", ("C10", "C01"), mooney_rivlin_dw_di1, mooney_rivlin_dw_di2),
        "saint_venant_kirchhoff": LawSpec("svk", ("mu",)),
    }
    for n in (1, 2, 3):
        laws[f"reduced_polynomial{n}"] = LawSpec(
            "invariant", tuple(f"C{i}0" for i in range(1, n + 1)), reduced_polynomial_dw_di1)
        names = tuple(x for r in range(1, n + 1) for x in (f"mu{r}", f"alpha{r}"))
        laws[f"lopez_pamies{n}"] = LawSpec("invariant", names, lopez_pamies_dw_di1)
        laws[f"ogden{n}"] = LawSpec("stretch", names, dw_dlambda=ogden_dw_dlambda)
    return laws


@functools.lru_cache(maxsize=1)
def available_laws() -> dict[str, LawSpec]:
    """Law table: ``models.hyperelastic.HYPERELASTIC_LAWS`` completed by the fallbacks of this module
    (:func:`laws_from_table`). Cached."""
    return laws_from_table(HYPERELASTIC_LAWS)


class LawCompileError(ValueError):
    """A law of the table whose functions do not compile with the kernels' signatures."""


def laws_from_table(table: Mapping) -> dict[str, LawSpec]:
    """The fallback laws of this module, overridden by the entries of ``table`` (``HYPERELASTIC_LAWS`` form).

    Every entry of a recognised shape must compile with the kernel signatures ``(params, I1bar, I2bar)`` /
    ``(params, lambda_bar)``: one that does not raises :class:`LawCompileError` naming it (a broken law is an
    error, not a law that silently goes missing). Entries of another shape are not laws and are skipped.
    """
    laws = _fallback_laws()
    for key, entry in table.items():
        spec = _law_from_table_entry(entry)
        if spec is not None:
            _compile(key, spec)
            laws[key] = spec
    return laws


def _compile(key: str, spec: LawSpec) -> None:
    """Compile the law's functions with the kernels' signatures; numba's typing error becomes a
    :class:`LawCompileError` naming the law."""
    try:
        if spec.kind == "invariant":
            as_cfunc(spec.dw_di1, INVARIANT_SIG)
            as_cfunc(spec.dw_di2, INVARIANT_SIG)
        elif spec.kind == "stretch":
            as_cfunc(spec.dw_dlambda, STRETCH_SIG)
    except Exception as exc:  # numba raises TypingError and others; re-raised with the law's key
        raise LawCompileError(f"hyperelastic law {key!r} does not compile with the FEM kernel signature: {exc}") from exc


def _law_from_table_entry(entry) -> LawSpec | None:
    """Adapt one ``HYPERELASTIC_LAWS`` entry to a :class:`LawSpec`.

    Accepted shapes: a mapping with ``kind`` and ``dW_dI1``/``dW_dI2`` or ``dW_dlambda`` plus
    ``param_names``; or a tuple ``(kind, f1[, f2], param_names)`` / ``(kind, (f1, f2), param_names)``.
    Entries of another shape (or of another kind) are skipped: the fallback law of the same key, if any,
    is kept.
    """
    if isinstance(entry, Mapping):
        kind = entry.get("kind")
        names = tuple(entry.get("param_names", entry.get("params", ())))
        if kind == "invariant" and "dW_dI1" in entry:
            return LawSpec("invariant", names, entry["dW_dI1"], entry.get("dW_dI2") or _zero_w)
        if kind == "stretch" and "dW_dlambda" in entry:
            return LawSpec("stretch", names, dw_dlambda=entry["dW_dlambda"])
        return None
    if not isinstance(entry, tuple) or len(entry) < 3 or entry[0] not in ("invariant", "stretch"):
        return None
    kind, names = entry[0], entry[-1]
    if not all(isinstance(n, str) for n in names):
        return None
    funcs = [f for part in entry[1:-1] for f in (part if isinstance(part, (tuple, list)) else (part,))]
    funcs = [f for f in funcs if f is not None]
    if not funcs or not all(callable(f) for f in funcs):
        return None
    if kind == "invariant":
        return LawSpec("invariant", tuple(names), funcs[0], funcs[1] if len(funcs) > 1 else _zero_w)
    return LawSpec("stretch", tuple(names), dw_dlambda=funcs[0])


# --------------------------------------------------------------------------------------------------
# material record
# --------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Material:
    """Everything the kernels need about a material (SI units).

    Attributes
    ----------
    law_key : key of the hyperelastic law
    kind : KIND_INVARIANT, KIND_INVARIANT_I1 (no I2 dependence), KIND_STRETCH or KIND_SVK
    params : float64 parameter vector in the law's order (Pa, 1)
    bulk_modulus_pa : kappa of ``U = kappa/2 (J-1)^2`` (for SVK: lambda = kappa - 2 mu/3)
    density_kg_m3 : mass density
    prony_g : Prony weights (sum < 1) of the isochoric stress; with Pipkin-Rogers the small-strain weights
        ``beta_i / (1 + sum beta)``
    prony_tau_s : relaxation times at the simulation's temperature (the card's times times ``shift_factor``)
    shear_modulus_pa : instantaneous small-strain shear modulus (computed; sets the wave speed)
    pr_params : Pipkin-Rogers weight law, one row ``(beta_i, kappa_i, gamma_s^2)`` per Prony term (no rows: QLV)
    shift_factor : time-temperature shift ``a_T`` the relaxation times were multiplied by (1: the card's reference
        temperature)
    """

    law_key: str
    kind: int
    params: np.ndarray
    bulk_modulus_pa: float
    density_kg_m3: float = 1040.0
    prony_g: np.ndarray = field(default_factory=lambda: np.zeros(0))
    prony_tau_s: np.ndarray = field(default_factory=lambda: np.ones(0))
    shear_modulus_pa: float = float("nan")
    pr_params: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    shift_factor: float = 1.0

    @property
    def law(self) -> LawSpec:
        return available_laws()[self.law_key]

    def functions(self):
        """The three C function pointers ``(dw_di1, dw_di2, dw_dlambda)`` for the kernels."""
        law = self.law
        return (as_cfunc(law.dw_di1, INVARIANT_SIG), as_cfunc(law.dw_di2, INVARIANT_SIG),
                as_cfunc(law.dw_dlambda, STRETCH_SIG))

    @property
    def pipkin_rogers(self) -> bool:
        """True with strain-dependent (Pipkin-Rogers) Prony weights."""
        return self.pr_params.shape[0] > 0

    @property
    def dilatational_modulus_pa(self) -> float:
        """``lambda + 2 mu = kappa + 4 mu/3`` (small strain), for the wave speed."""
        return self.bulk_modulus_pa + 4.0 / 3.0 * self.shear_modulus_pa


def _is_zero_law(fn) -> bool:
    """True for the shared ``dW/dI2 = 0`` functions (this module's and the fitting code's)."""
    return getattr(fn, "py_func", fn) in {_zero_w.py_func, zero_dw_di2.py_func}


def _invariant_independent_functions() -> set:
    """The shared law derivatives whose value does not depend on the invariants (``W`` linear in ``I1``,
    ``I2``: neo-Hookean, Mooney-Rivlin, and the zero ``dW/dI2`` of I1-only laws)."""
    fns = {_zero_w, neo_hookean_dw_di1, mooney_rivlin_dw_di1, mooney_rivlin_dw_di2, zero_dw_di2}
    return {getattr(f, "py_func", f) for f in fns}


def constant_invariant_derivatives(material: Material) -> tuple[float, float] | None:
    """``(dW/dI1, dW/dI2)`` (Pa) when the material's law is linear in the invariants (both derivatives
    constant: neo-Hookean, Mooney-Rivlin), evaluated once with the fitting code's law functions; None for
    any other law and for stretch-based and SVK laws.

    Such laws run on the vectorised kernels (:mod:`.vectorised`), which take the derivatives as constants.
    """
    if material.kind not in (KIND_INVARIANT, KIND_INVARIANT_I1):
        return None
    law = material.law
    constant = _invariant_independent_functions()
    if getattr(law.dw_di1, "py_func", law.dw_di1) not in constant or \
            getattr(law.dw_di2, "py_func", law.dw_di2) not in constant:
        return None
    p = np.ascontiguousarray(material.params, dtype=np.float64)
    return float(law.dw_di1(p, 3.0, 3.0)), float(law.dw_di2(p, 3.0, 3.0))


def make_material(law_key: str, parameters: Mapping[str, float] | np.ndarray, *,
                  bulk_modulus_pa: float | None = None, poisson_ratio: float | None = None,
                  density_kg_m3: float = 1040.0, prony_g=(), prony_tau_s=(), pipkin_rogers: Mapping | None = None,
                  shift_factor: float = 1.0) -> Material:
    """Build a :class:`Material`; give either ``bulk_modulus_pa`` or ``poisson_ratio``.

    ``kappa = models.base.bulk_modulus(mu, nu)`` = 2 mu (1 + nu) / (3 (1 - 2 nu)) with ``mu`` the instantaneous
    small-strain shear modulus (:func:`small_strain_shear_modulus`).

    Pipkin-Rogers (the nonseparable extension, module docstring): ``pipkin_rogers = {"beta": [...], "kappa": [...],
    "gamma_s": ...}`` (a card's ``pipkin_rogers`` block, the fitted parameters unchanged), one ``beta_i``,
    ``kappa_i`` per time in ``prony_tau_s``; ``prony_g`` is then the small-strain weights ``beta_i / (1 + sum beta)``
    (computed when not given; given ones must agree). ``shift_factor``: the time-temperature shift ``a_T``
    (the relaxation times run as ``a_T tau_i``; :func:`material_from_card` derives it from a temperature).
    """
    laws = available_laws()
    if law_key not in laws:
        raise KeyError(f"unknown hyperelastic law {law_key!r}; known: {', '.join(sorted(laws))}")
    law = laws[law_key]
    if isinstance(parameters, Mapping):
        missing = [n for n in law.param_names if n not in parameters]
        if missing:
            raise KeyError(f"law {law_key!r} needs parameters {law.param_names}; missing {missing}")
        params = np.array([float(parameters[n]) for n in law.param_names])
    else:
        params = np.asarray(parameters, float).copy()
    kind = {"invariant": KIND_INVARIANT, "stretch": KIND_STRETCH, "svk": KIND_SVK}[law.kind]
    if kind == KIND_INVARIANT and _is_zero_law(law.dw_di2):
        kind = KIND_INVARIANT_I1
    g = np.asarray(prony_g, float)
    tau = np.asarray(prony_tau_s, float)
    if not (np.isfinite(shift_factor) and shift_factor > 0):
        raise ValueError(f"the time-temperature shift factor must be positive, not {shift_factor}")
    pr_params = np.zeros((0, 3))
    if pipkin_rogers is not None:
        beta = np.asarray(pipkin_rogers["beta"], float)
        kappa = np.broadcast_to(np.asarray(pipkin_rogers["kappa"], float), beta.shape)
        gamma_s = float(pipkin_rogers["gamma_s"])
        if beta.shape != tau.shape or beta.size == 0:
            raise ValueError(f"Pipkin-Rogers needs one beta and kappa per relaxation time: {beta.size} for {tau.size}")
        if np.any(beta < 0) or np.any(kappa <= -1) or not gamma_s > 0:
            raise ValueError("Pipkin-Rogers needs beta_i >= 0, kappa_i > -1 and gamma_s > 0")
        small = beta / (1.0 + beta.sum())
        if g.size and not np.allclose(g, small, rtol=1e-6, atol=1e-12):
            raise ValueError(f"prony_g {g} are not the Pipkin-Rogers small-strain weights {small}")
        g = small
        pr_params = np.column_stack([beta, kappa, np.full(beta.size, gamma_s ** 2)])
    if g.shape != tau.shape:
        raise ValueError("prony g and tau must have the same length")
    if g.size and (g.sum() >= 1.0 or np.any(g < 0) or np.any(tau <= 0)):
        raise ValueError("Prony weights must be >= 0 with sum < 1 and times > 0")
    provisional = Material(law_key, kind, params, 1.0, density_kg_m3, g, tau)
    mu = small_strain_shear_modulus(provisional)
    if not mu > 0:
        raise ValueError(f"law {law_key!r} with parameters {params} has non-positive shear modulus {mu}")
    if (bulk_modulus_pa is None) == (poisson_ratio is None):
        raise ValueError("give exactly one of bulk_modulus_pa and poisson_ratio")
    if bulk_modulus_pa is None:
        bulk_modulus_pa = bulk_modulus(mu, poisson_ratio)
    return Material(law_key, kind, params, float(bulk_modulus_pa), density_kg_m3, g, tau * float(shift_factor),
                    float(mu), pr_params, float(shift_factor))


def card_shift_factor(card: MaterialCard, temperature_c: float | None) -> float:
    """The time-temperature shift ``a_T`` of a card at ``temperature_c`` (degC): 1 at None (the card's own state:
    its relaxation times are those at its reference temperature), else from the card's ``time_temperature_shift``
    (WLF, ``tts.wlf_log_aT``). Refused, with the reason: a temperature for a card without a shift function, outside
    the temperatures the shift was fitted on, or with a vertical shift (the card gives no b_T(T))."""
    if temperature_c is None:
        return 1.0
    shift = card.time_temperature_shift
    if not shift or shift.get("shift_function") != "WLF" or not shift.get("wlf"):
        raise ValueError(f"card {card.model}: a temperature ({temperature_c} degC) needs the card's "
                         "time_temperature_shift with a WLF function; this card has none (not fitted to a mastercurve, "
                         "or its WLF fit failed)")
    if shift.get("vertical_shift"):
        raise ValueError(f"card {card.model}: its shift has a vertical factor b_T the card does not give as a function "
                         "of temperature; only the reference temperature can be run")
    span = (shift.get("valid_range") or {}).get("temperature_c")
    if span is None or not span[0] <= temperature_c <= span[1]:
        raise ValueError(f"card {card.model}: {temperature_c} degC is outside the temperatures its shift was fitted on "
                         f"({span} degC)")
    wlf = shift["wlf"]
    return float(10.0 ** wlf_log_aT(float(temperature_c), float(wlf["c1"]), float(wlf["c2_k"]),
                                    float(shift["t_ref_c"])))


def material_from_card(card: Mapping | MaterialCard, *, temperature_c: float | None = None,
                       shift_factor: float | None = None) -> Material:
    """The solver material of a card, read through ``records.MaterialCard`` (a dict is validated by it first).

    Accepted: the ``tissuemech.cards`` card -- ``elastic_law``/``elastic_parameters`` (a linear shear law as
    neo-Hookean, ``MaterialCard.fem_law``), ``prony``, ``pipkin_rogers`` (the nonseparable extension, the fitted
    parameters unchanged), ``bulk_modulus`` and/or ``poisson_ratio`` (a finite ``bulk_modulus`` wins; the cards write
    both, consistently), optional ``density`` -- and the minimal shape ``{"model": law key, "parameters": {...},
    "prony": {"g", "tau"} | None, "bulk_modulus" | "poisson_ratio"}``.

    Temperature: ``temperature_c`` (degC) runs the card at that temperature through its time-temperature shift
    (:func:`card_shift_factor`: relaxation times ``a_T tau_i``), or ``shift_factor`` gives ``a_T`` directly; neither:
    the card's reference temperature.
    """
    card = card if isinstance(card, MaterialCard) else MaterialCard.from_dict(dict(card))
    if temperature_c is not None and shift_factor is not None:
        raise ValueError("give a temperature or a shift factor, not both")
    a_t = card_shift_factor(card, temperature_c) if shift_factor is None else float(shift_factor)
    prony = card.prony or {}
    bulk, nu = card.bulk_modulus, card.poisson_ratio
    if bulk is not None and np.isfinite(float(bulk)):
        nu = None
    else:
        bulk = None
    return make_material(
        card.fem_law, card.fem_parameters, bulk_modulus_pa=None if bulk is None else float(bulk),
        poisson_ratio=None if nu is None else float(nu), density_kg_m3=float(card.data.get("density", 1040.0)),
        prony_g=prony.get("g", ()), prony_tau_s=prony.get("tau", ()), pipkin_rogers=card.pipkin_rogers,
        shift_factor=a_t)


class _SimpleShearOfMaterial:
    """A :class:`Material`'s simple-shear Cauchy stress as an elastic shear law, so that the one initial-modulus rule
    (``models.base.initial_shear_modulus``) differentiates the FEM's own stress routine on its compiled law vector."""

    def __init__(self, material: Material):
        self.material = material

    @staticmethod
    def supports(response: str) -> bool:
        return response == "elastic_shear"

    def elastic_shear_stress(self, p, strain):
        out = []
        for gamma in np.atleast_1d(np.asarray(strain, float)):
            F = np.eye(3)
            F[0, 1] = gamma
            out.append(cauchy_stress(self.material, F)[0, 1])
        return np.array(out)


def small_strain_shear_modulus(material: Material) -> float:
    """Instantaneous small-strain shear modulus (Pa) of a FEM :class:`Material`: ``models.base.initial_shear_modulus``
    (the one rule: central difference of the simple-shear stress) of the FEM's own stress routine on its compiled law
    vector (:func:`cauchy_stress`; a material has no model object). With Prony terms (QLV or Pipkin-Rogers) this is
    the instantaneous modulus: the weights sum to 1 at t = 0."""
    return float(initial_shear_modulus(_SimpleShearOfMaterial(material), {}))


# --------------------------------------------------------------------------------------------------
# element stress (scalar code, inlined into the kernels)
# --------------------------------------------------------------------------------------------------
@njit(cache=True, fastmath=FASTMATH, inline="always")
def isochoric_kirchhoff_invariant(w1, w2, b11, b22, b33, b12, b23, b13):
    """``tau_iso = dev(2 (W1 + I1bar W2) bbar - 2 W2 bbar^2)`` of an invariant law ``W(I1bar, I2bar)`` from the
    isochoric left Cauchy-Green tensor ``bbar`` and the derivatives ``W1 = dW/dI1bar``, ``W2 = dW/dI2bar``
    there (Pa)."""
    i1 = b11 + b22 + b33
    q11, q22, q33, q12, q23, q13 = symmetric_square(b11, b22, b33, b12, b23, b13)
    a = 2.0 * (w1 + i1 * w2)
    c = -2.0 * w2
    t11 = a * b11 + c * q11
    t22 = a * b22 + c * q22
    t33 = a * b33 + c * q33
    m = (t11 + t22 + t33) * (1.0 / 3.0)
    return t11 - m, t22 - m, t33 - m, a * b12 + c * q12, a * b23 + c * q23, a * b13 + c * q13


@njit(cache=True, fastmath=FASTMATH, inline="always")
def svk_kirchhoff(mu, lam, b11, b22, b33, b12, b23, b13):
    """Saint Venant-Kirchhoff ``tau = F S F^T = lam tr(E) b + mu (b^2 - b)`` with ``E = (C - I)/2`` (Pa)."""
    tre = 0.5 * (b11 + b22 + b33 - 3.0)
    q11, q22, q33, q12, q23, q13 = symmetric_square(b11, b22, b33, b12, b23, b13)
    a = lam * tre - mu
    return (a * b11 + mu * q11, a * b22 + mu * q22, a * b33 + mu * q33,
            a * b12 + mu * q12, a * b23 + mu * q23, a * b13 + mu * q13)


@njit(cache=True, fastmath=FASTMATH, inline="always")
def _iso_from_bbar(kind, w1fn, w2fn, wlfn, p, b11, b22, b33, b12, b23, b13):
    """Isochoric Kirchhoff stress (6 comps: 11 22 33 12 23 13) from the isochoric left Cauchy-Green tensor."""
    if kind == KIND_INVARIANT_I1:
        # W = W(I1bar): tau_iso = 2 W1 dev(bbar); I2bar is not an argument of such a law (3 passed)
        i1 = b11 + b22 + b33
        a = 2.0 * w1fn(p, i1, 3.0)
        m = a * i1 / 3.0
        return (a * b11 - m, a * b22 - m, a * b33 - m, a * b12, a * b23, a * b13)
    if kind == KIND_INVARIANT:
        i1 = b11 + b22 + b33
        i2 = 0.5 * (i1 * i1 - (b11 * b11 + b22 * b22 + b33 * b33 + 2.0 * (b12 * b12 + b23 * b23 + b13 * b13)))
        return isochoric_kirchhoff_invariant(w1fn(p, i1, i2), w2fn(p, i1, i2), b11, b22, b33, b12, b23, b13)
    # stretch-based (Valanis-Landel): tau_iso = sum_k (beta_k - mean beta) n_k n_k, beta_k = lam_k dW/dlam_k,
    # from the spectral decomposition of bbar
    l1, l2, l3, n11, n21, n31, n12, n22, n32, n13, n23, n33 = symmetric_eigen3(b11, b22, b33, b12, b23, b13)
    s1, s2, s3 = math.sqrt(l1), math.sqrt(l2), math.sqrt(l3)
    beta1, beta2, beta3 = s1 * wlfn(p, s1), s2 * wlfn(p, s2), s3 * wlfn(p, s3)
    m = (beta1 + beta2 + beta3) / 3.0
    d1, d2, d3 = beta1 - m, beta2 - m, beta3 - m
    return (d1 * n11 * n11 + d2 * n12 * n12 + d3 * n13 * n13, d1 * n21 * n21 + d2 * n22 * n22 + d3 * n23 * n23,
            d1 * n31 * n31 + d2 * n32 * n32 + d3 * n33 * n33, d1 * n11 * n21 + d2 * n12 * n22 + d3 * n13 * n23,
            d1 * n21 * n31 + d2 * n22 * n32 + d3 * n23 * n33, d1 * n11 * n31 + d2 * n12 * n32 + d3 * n13 * n33)


@njit(cache=True, fastmath=FASTMATH, inline="always")
def j_minus_two_thirds(J):
    """``J^(-2/3)`` to machine precision without a libm ``cbrt`` call (about 22 ns, a quarter of a
    neo-Hookean element update) in the nearly incompressible range: three Newton steps on ``y^-3 = J`` for
    ``y = J^(-1/3)`` from the first-order guess; the relative error squares each step (2e-3, 1e-5, 2e-10,
    1e-19 at ``|J - 1| = 0.1``). Outside ``|J - 1| < 0.1`` it falls back to ``|J|^(1/3)`` by a power."""
    d = J - 1.0
    if d > -0.1 and d < 0.1:
        y = 1.0 - d / 3.0
        y = y * (4.0 - J * y * y * y) * (1.0 / 3.0)
        y = y * (4.0 - J * y * y * y) * (1.0 / 3.0)
        y = y * (4.0 - J * y * y * y) * (1.0 / 3.0)
        return y * y
    # |J|^(1/3) with J's sign, as cbrt: numba's CUDA target (.cuda calls this too) has no np.cbrt and its CPU
    # target no math.cbrt
    cr = math.copysign(abs(J) ** (1.0 / 3.0), J)
    return 1.0 / (cr * cr)


@njit(cache=True, fastmath=FASTMATH, inline="always")
def kirchhoff_deviatoric(kind, w1fn, w2fn, wlfn, p, kappa, f11, f12, f13, f21, f22, f23, f31, f32, f33, J):
    """Kirchhoff stress without the volumetric pressure term (6 comps).

    For split laws this is the isochoric part; for Saint Venant-Kirchhoff (compressible, no split) it is the
    whole ``tau = F S F^T`` and the caller must not add a pressure.
    """
    b11, b22, b33, b12, b23, b13 = left_cauchy_green(f11, f12, f13, f21, f22, f23, f31, f32, f33)
    if kind == KIND_SVK:
        return svk_kirchhoff(p[0], kappa - 2.0 * p[0] / 3.0, b11, b22, b33, b12, b23, b13)
    jm23 = j_minus_two_thirds(J)
    return _iso_from_bbar(kind, w1fn, w2fn, wlfn, p, jm23 * b11, jm23 * b22, jm23 * b33,
                          jm23 * b12, jm23 * b23, jm23 * b13)


@njit(cache=True)
def _cauchy_kernel(kind, w1fn, w2fn, wlfn, p, kappa, F):
    J = (F[0, 0] * (F[1, 1] * F[2, 2] - F[1, 2] * F[2, 1]) - F[0, 1] * (F[1, 0] * F[2, 2] - F[1, 2] * F[2, 0])
         + F[0, 2] * (F[1, 0] * F[2, 1] - F[1, 1] * F[2, 0]))
    t = kirchhoff_deviatoric(kind, w1fn, w2fn, wlfn, p, kappa, F[0, 0], F[0, 1], F[0, 2], F[1, 0], F[1, 1],
                             F[1, 2], F[2, 0], F[2, 1], F[2, 2], J)
    pr = 0.0 if kind == KIND_SVK else kappa * (J - 1.0) * J
    s = np.empty((3, 3))
    s[0, 0], s[1, 1], s[2, 2] = t[0] + pr, t[1] + pr, t[2] + pr
    s[0, 1] = s[1, 0] = t[3]
    s[1, 2] = s[2, 1] = t[4]
    s[0, 2] = s[2, 0] = t[5]
    return s / J


def cauchy_stress(material: Material, F: np.ndarray) -> np.ndarray:
    """Elastic Cauchy stress (Pa) of a homogeneous deformation gradient ``F`` (3x3), for checks and cards."""
    w1, w2, wl = material.functions()
    return _cauchy_kernel(material.kind, w1, w2, wl, material.params, material.bulk_modulus_pa,
                          np.ascontiguousarray(F, dtype=np.float64))
