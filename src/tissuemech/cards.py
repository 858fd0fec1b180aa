"""Material cards: canonical JSON, Abaqus input blocks and FEBio material blocks from fitted models.

Card shape (JSON, SI units)::

    {"schema_version": "1.0", "model": key, "family": ..., "parameters": {...}, "units": {...},
     "standard_errors": {...}, "elastic_law": law key, "elastic_parameters": {...}, "initial_shear_modulus": Pa,
     "prony": {"g": [...], "tau": [...], "g_inf": ..., "normalisation": ..., "source": ...} | null,
     "pipkin_rogers": {"beta": [...], "kappa": [...], "gamma_s": ..., "weights": ..., "strain_measure": ...} | null,
     "poisson_ratio": nu, "bulk_modulus": Pa, "validity": {...}, "provenance": {...},
     "fit_quality": {...}, "abaqus_form": ... | null, "abaqus_constants": [...],
     "abaqus_marlow_table": {"nominal_strain": [...], "nominal_stress_pa": [...]},   # MARLOW cards only
     "abaqus_reason": str,   # cards without an Abaqus form
     "febio_form": type | null, "febio_parameters": {...} | null, "febio_reason": str | null,
     "niftysim_reason": str | null, "valid_range": {...}, "uncertainty": {...}, "notes": [...],
     "time_temperature_shift": {...}}   # only cards fitted to a TTS mastercurve (tts.tts_card)

The card holds plain JSON values only (``records.MaterialCard`` reads and validates it, schema version included),
and every file format is written from it alone (:func:`write_card_files`), so a card read back from disk writes the
same Abaqus, FEBio and NiftySim files.

``elastic_law``/``elastic_parameters`` are the (instantaneous) hyperelastic law a FE code needs -- for a
QLV or Pipkin-Rogers model the instantaneous law, for a linear viscoelastic model a linear law with the instantaneous
modulus G0 (a neo-Hookean law is exactly linear in simple shear).

The nonseparable extension (Pipkin-Rogers, ``models.beyond_qlv.PipkinRogersModel``) is a TLED law: its card holds
the small-strain Prony series (weights ``beta_i / (1 + sum beta)``) and the fitted weight law in ``pipkin_rogers``
unchanged (:func:`pipkin_rogers_block`); the solver reads both (``fem.materials.material_from_card``). Abaqus has no
strain-dependent Prony weights (:data:`ABAQUS_PIPKIN_ROGERS_REASON`) and FEBio's reactive viscoelasticity does not
hold the law (``cards_febio.FEBIO_PIPKIN_ROGERS_REASON``): no block, the reason in ``abaqus_reason`` /
``febio_reason``.

Conventions (checked by :func:`abaqus_simple_shear_stress`, an independent evaluation of the Abaqus energy
forms, against the fitted model):

* Abaqus polynomial forms: W = sum C_ij (I1-3)^i (I2-3)^j + sum 1/D_i (J-1)^(2i); C10 = mu/2 for
  neo-Hooke; D1 = 2/K with K = 2 mu0 (1 + nu) / (3 (1 - 2 nu)) and mu0 the initial shear modulus; D_i = 0
  for i > 1.
* Abaqus Ogden: W = sum 2 mu_i / alpha_i^2 (l1^a_i + l2^a_i + l3^a_i - 3) -- the same "2 mu / alpha^2" form
  as Budday et al. and the project's Ogden law, so mu_i, alpha_i pass unchanged (mu0 = sum mu_i). A
  classical-form Ogden W = sum mu_i/alpha_i (...) converts with mu_i(Abaqus) = mu_i alpha_i / 2.
* Abaqus Arruda-Boyce: W = mu sum C_i / lambda_m^(2i-2) (I1^i - 3^i), C = 1/2, 1/20, 11/1050, 19/7000,
  519/673750.
* Abaqus ``*VISCOELASTIC, TIME=PRONY`` data lines ``g_i, k_i, tau_i``: g_i are *relative* shear moduli of the
  instantaneous modulus, g_R(t) = 1 - sum g_i (1 - exp(-t/tau_i)) = g_inf + sum g_i exp(-t/tau_i) -- the QLV
  reduced relaxation function unchanged. Shear-only relaxation (rheometer data say nothing about bulk
  relaxation): k_i = 0. The elastic constants are written with ``MODULI=INSTANTANEOUS`` so the hyperelastic
  constants are read as the instantaneous response (the Abaqus default is long-term).
* Laws without a native Abaqus form (Lopez-Pamies, Gent, Nunes, Amin, ...) are written as ``MARLOW`` with
  ``*UNIAXIAL TEST DATA`` generated from the *fitted simple-shear law* through the I1-only equivalence
  W'(I1 = 3 + gamma^2) = sigma(gamma) / (2 gamma), P(lambda) = 2 (lambda - lambda^-2) W'(lambda^2 + 2/lambda):
  exact in simple shear over the validity range; an I2 dependence of the original law is not carried over.
  A fit that gives no strain range (sweeps, relaxation moduli) gets no MARLOW table, no strain validity
  (``marlow_strain_max`` None) and, for a law with an unbounded initial tangent, no secant modulus; a linear
  viscoelastic or fractional model fitted without a time or frequency window gets no Prony series. Nothing is
  assumed in their place (the card's notes say what is not given).
* A generalized Kelvin-Voigt model (retardation spectrum) is written through its exactly interconverted
  relaxation spectrum: ``*HYPERELASTIC, NEO HOOKE, MODULI=INSTANTANEOUS`` with C10 = G0/2 plus
  ``*VISCOELASTIC, TIME=PRONY`` on the relaxation times (which interlace the retardation times).
* Full polynomial laws of order N <= 6 are written as ``POLYNOMIAL, N=k`` with the constants in Abaqus's order
  C10, C01, C20, C11, C02, C30, C21, C12, C03, ... followed by D1..DN, eight values per data line (the layout
  of the Abaqus-compatible CalculiX ``*HYPERELASTIC`` documentation for N=3: line 1 C10..C12, line 2 C03, D1-D3).
* The Nunes law has an infinite initial tangent modulus (W2 ~ (I2-3)^(-1/4)); its card's
  ``initial_shear_modulus`` (and the bulk modulus derived from it) is the secant modulus at gamma_max/20 (any
  law whose tangent keeps growing as gamma -> 0 is treated so) and the notes say so.
* FEBio: :mod:`tissuemech.cards_febio` (type strings, parameter names and stress forms checked against the FEBio
  source and manual, cited there). Native blocks: ``Mooney-Rivlin`` (neo-Hooke, Mooney-Rivlin), ``Ogden`` (<= 6
  terms, c_i = 2 mu_i, m_i = alpha_i), ``Gent`` (G = mu, Jm), ``polynomial`` (full/reduced polynomial of order 2,
  coupled, D1 = K/2), each uncoupled one with ``k`` = the card's bulk modulus, and the ``uncoupled viscoelastic``
  wrapper (g0 = g_inf, g_i, t_i = tau_i, <= 6 terms) around the instantaneous law. Yeoh/reduced polynomial of
  order >= 3, Arruda-Boyce, Lopez-Pamies, Nunes, Amin, higher polynomials and beyond-QLV laws get no block and
  ``febio_reason`` says why. Every block is checked in simple shear against the fitted law (1 %).
  ``febio_block`` gives the ``<material>`` element, ``febio_file_text`` the ``febio_spec`` 4.0 document written
  as ``<stem>.feb.xml``.

Valid range and uncertainty (every card): ``valid_range`` = the fitted data selection's shear strain, shear rate,
time and angular-frequency spans (``None`` and listed in ``not_given`` when the data carry none), its tests and
conditions; ``uncertainty`` = lmfit standard errors, relative standard errors, parameters without a finite
standard error, and the initial shear modulus's standard error (delta method). The Poisson ratio (hence ``k``)
is the configuration's ``fem.poisson_ratio``, a required argument of :func:`make_card` (passed in by
``stages.run_fit_scope``); ``k`` = ``models.base.bulk_modulus(G0, nu)``.
"""
from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import scipy

from .canonical import write_text
from .cards_febio import (FEBIO_PIPKIN_ROGERS_REASON, FEBIO_SOURCE_COMMIT, febio_card_material, febio_document,
                          febio_material_element, febio_simple_shear_stress)
from .cards_niftysim import niftysim_file_text, niftysim_reason
from .fitting import FitResult
from .models.base import ConstitutiveModel, bulk_modulus, initial_shear_modulus
from .models.qlv import LinearElasticShear
from .models.registry import get_model
from .records import MaterialCard, finite_strain_law
from .spectra import prony_nnls_weights, prony_oscillation_basis, prony_relaxation_basis

#: Abaqus Arruda-Boyce series coefficients
ARRUDA_BOYCE_C = (0.5, 1.0 / 20.0, 11.0 / 1050.0, 19.0 / 7000.0, 519.0 / 673750.0)
#: number of points of a MARLOW uniaxial table
MARLOW_POINTS = 40


# ------------------------------------------------------------------------------------------------
# the elastic law and the Prony series of a fitted model
# ------------------------------------------------------------------------------------------------
def _law_and_params(model: ConstitutiveModel, p: Mapping[str, float]) -> tuple[ConstitutiveModel | None, dict]:
    """The (instantaneous) elastic law of a model and its parameters; ``(None, {})`` when there is none."""
    if model.family == "hyperelastic":
        return model, {k: float(p[k]) for k in model.param_names}
    inst = getattr(model, "instantaneous", None)
    if model.family == "qlv" and inst is not None:
        return inst, {k: float(p[k]) for k in inst.param_names}
    return None, {}


def prony_from_step_response(model: ConstitutiveModel, p: Mapping[str, float], taus: np.ndarray,
                             t_min_s: float, t_max_s: float, strain: float = 1e-3) -> dict:
    """Prony series of a linear(ised) viscoelastic model by NNLS on its step relaxation modulus.

    G(t) = sigma(t)/strain of an ideal step (small strain) on ``[t_min_s, t_max_s]`` (log-spaced) is fitted
    with G_inf + sum G_i exp(-t/tau_i), G_i >= 0. Exact for generalized-Maxwell models on their own taus; an
    approximation for fractional models (``fit_rel_error`` reports the relative RMS misfit).
    """
    t = np.r_[0.0, np.geomspace(t_min_s, t_max_s, 200)]
    stress = np.asarray(model.shear_stress_history(p, t, np.full(t.size, strain)), float)
    g_t = stress[1:] / strain
    tt = t[1:]
    w = 1.0 / np.maximum(np.abs(g_t), 1e-12 * np.max(np.abs(g_t)))  # relative misfit
    g_e, g_i, _ = prony_nnls_weights(tt, g_t, taus, row_weights=w)
    coef = np.r_[g_e, g_i]
    fitted = prony_relaxation_basis(tt, taus) @ coef
    g0 = float(coef.sum())
    return {"g_inf": float(coef[0] / g0), "g": (coef[1:] / g0).tolist(), "tau": np.asarray(taus, float).tolist(),
            "G0": g0, "fit_rel_error": float(np.sqrt(np.mean(((fitted - g_t) / g_t) ** 2)))}


def prony_from_complex_modulus(model: ConstitutiveModel, p: Mapping[str, float], taus: np.ndarray,
                               omega_min: float, omega_max: float) -> dict:
    """Prony series of a linear viscoelastic model by NNLS on its G'(omega), G''(omega) (relative misfit) over
    ``[omega_min, omega_max]`` rad/s -- for models that define only the oscillatory response."""
    w = np.geomspace(omega_min, omega_max, 120)
    gs = np.asarray(model.complex_modulus(p, w))
    re, im = prony_oscillation_basis(w, taus)
    A = np.vstack([re / np.abs(gs.real)[:, None], im / np.abs(gs.imag)[:, None]])
    b = np.r_[np.ones(w.size), np.ones(w.size)]
    coef, _ = scipy.optimize.nnls(A, b)
    fitted = np.r_[re @ coef, im @ coef]
    target = np.r_[gs.real, gs.imag]
    g0 = float(coef.sum())
    return {"g_inf": float(coef[0] / g0), "g": (coef[1:] / g0).tolist(), "tau": np.asarray(taus, float).tolist(),
            "G0": g0, "fit_rel_error": float(np.sqrt(np.mean(((fitted - target) / target) ** 2)))}


def _model_taus(model: ConstitutiveModel, p: Mapping[str, float]) -> np.ndarray | None:
    for key in ("taus_s", "taus", "tau_s"):
        v = model.structure.get(key) if isinstance(model.structure, Mapping) else None
        if v is not None:
            return np.asarray(v, float)
    names = sorted((n for n in model.param_names if re.fullmatch(r"tau_?\d+", n)), key=lambda s: int(re.sub(r"\D", "", s)))
    if names:
        return np.array([float(p[n]) for n in names])
    return None


# ------------------------------------------------------------------------------------------------
# native Abaqus forms
# ------------------------------------------------------------------------------------------------
def _indexed(p: Mapping[str, float], stem: str) -> list[float]:
    """Values of ``stem1, stem2, ...`` or ``stem_1, stem_2, ...`` in order."""
    found = {}
    for k, v in p.items():
        m = re.fullmatch(rf"{stem}_?(\d+)", k)
        if m:
            found[int(m.group(1))] = float(v)
    return [found[i] for i in sorted(found)]


def abaqus_hyperelastic_form(law_key: str, lp: Mapping[str, float]) -> tuple[str, list[float]] | None:
    """Native Abaqus ``*HYPERELASTIC`` option and its constants (without D_i) for a law, or ``None``.

    Returns e.g. ``("REDUCED POLYNOMIAL, N=3", [C10, C20, C30])``.
    """
    key = law_key
    try:
        if key.startswith("linear_elastic") or key in ("linear_elastic_shear", "hooke"):
            g0 = lp.get("G0", lp.get("G", lp.get("mu")))
            return "NEO HOOKE", [0.5 * float(g0)]
        if key.startswith("neo_hook"):
            return "NEO HOOKE", [float(lp["C10"]) if "C10" in lp else 0.5 * float(lp["mu"])]
        if key.startswith("mooney_rivlin"):
            return "MOONEY-RIVLIN", [float(lp["C10"]), float(lp["C01"])]
        if key.startswith("yeoh"):
            return "YEOH", [float(lp["C10"]), float(lp["C20"]), float(lp["C30"])]
        m = re.fullmatch(r"reduced_polynomial(\d+)", key)
        if m:
            n = int(m.group(1))
            if n > 6:
                return None
            return f"REDUCED POLYNOMIAL, N={n}", [float(lp[f"C{i}0"]) for i in range(1, n + 1)]
        m = re.fullmatch(r"polynomial(\d+)", key)
        if m:
            n = int(m.group(1))
            if n > 6:
                return None
            vals = []
            for total in range(1, n + 1):  # Abaqus order: C10, C01, C20, C11, C02, C30, C21, ...
                for j in range(0, total + 1):
                    vals.append(float(lp.get(f"C{total - j}{j}", 0.0)))
            return f"POLYNOMIAL, N={n}", vals
        m = re.fullmatch(r"ogden(\d+)", key)
        if m:
            mus, alphas = _indexed(lp, "mu"), _indexed(lp, "alpha")
            if len(mus) != int(m.group(1)) or len(alphas) != len(mus):
                return None
            vals = [x for pair in zip(mus, alphas) for x in pair]
            return f"OGDEN, N={len(mus)}", vals
        if key.startswith("arruda_boyce"):
            mu = float(lp["mu"])
            lam_m = float(lp["lambda_m"]) if "lambda_m" in lp else math.sqrt(float(lp["N"]))
            return "ARRUDA-BOYCE", [mu, lam_m]
    except KeyError:
        return None
    return None


def _abaqus_d_terms(form: str, bulk_modulus: float) -> list[float]:
    """D_i of an Abaqus form: D1 = 2/K, higher D_i = 0 (polynomial forms have N of them)."""
    d1 = 2.0 / bulk_modulus
    m = re.search(r"N=(\d+)", form)
    n = int(m.group(1)) if m and not form.startswith("OGDEN") else 1
    if form.startswith("OGDEN"):
        n = int(m.group(1))
    if form == "YEOH":
        n = 3
    return [d1] + [0.0] * (n - 1)


def _data_lines(values: list[float], per_line: int = 8) -> str:
    return "\n".join(", ".join(f"{v:.10g}" for v in values[i:i + per_line]) for i in range(0, len(values), per_line))


def marlow_uniaxial_table(law: ConstitutiveModel, lp: Mapping[str, float], strain_max: float,
                          n_points: int = MARLOW_POINTS, spacing: str = "linear") -> tuple[np.ndarray, np.ndarray]:
    """Uniaxial nominal stress (Pa) vs nominal strain table equivalent in simple shear to an elastic law.

    Uses the I1-only equivalence W'(I1) = sigma(gamma) / (2 gamma) at I1 = 3 + gamma^2, with the stretch range
    chosen so that lambda^2 + 2/lambda - 3 covers gamma up to ``strain_max``. ``spacing="geometric"`` places
    the stretches log-uniformly in ``lambda - 1`` over three decades, for laws whose W' is singular at
    I1 = 3 (unbounded initial tangent modulus), which a linear grid cannot resolve at small strain.
    """
    i1_max = 3.0 + strain_max ** 2
    lam_max = scipy.optimize.brentq(lambda lam: lam ** 2 + 2.0 / lam - i1_max, 1.0 + 1e-12, 10.0 + strain_max * 10)
    if spacing == "geometric":
        lam = 1.0 + np.geomspace(1e-3 * (lam_max - 1.0), lam_max - 1.0, n_points - 1)
    elif spacing == "linear":
        lam = np.linspace(1.0, lam_max, n_points)[1:]
    else:
        raise ValueError(f"unknown MARLOW table spacing {spacing!r}; use 'linear' or 'geometric'")
    gamma = np.sqrt(np.maximum(lam ** 2 + 2.0 / lam - 3.0, 0.0))
    w1 = np.asarray(law.elastic_shear_stress(lp, gamma), float) / (2.0 * gamma)
    nominal = 2.0 * (lam - lam ** -2) * w1
    return np.r_[0.0, lam - 1.0], np.r_[0.0, nominal]


# ------------------------------------------------------------------------------------------------
# the card
# ------------------------------------------------------------------------------------------------
def _span(lo: float, hi: float) -> list[float] | None:
    lo, hi = float(lo), float(hi)
    return [lo, hi] if np.isfinite(lo) and np.isfinite(hi) else None


def _range_text(vr: Mapping) -> str:
    parts = []
    for key, label in (("shear_strain", "shear strain"), ("shear_rate_1_per_s", "shear rate 1/s"),
                       ("time_s", "time s"), ("angular_frequency_rad_per_s", "angular frequency rad/s")):
        span = vr.get(key)
        parts.append(f"{label} {span[0]:.4g}..{span[1]:.4g}" if span else f"{label} not given by the data")
    return "; ".join(parts)


def valid_range(result: FitResult) -> dict:
    """Range of the fitted data selection in which a card is valid (from ``result.ranges``/``result.selection``).

    Returns ``{"shear_strain": [min, max] | None, "shear_rate_1_per_s": [...] | None, "time_s": [...] | None,
    "angular_frequency_rad_per_s": [...] | None, "tests": [...], "conditions": [...], "not_given": [...]}``:
    strain is the shear strain amount gamma (``|stretch - 1|`` for uniaxial curves, the creep strain for creep
    curves); the shear rate is the nominal rate of the fitted ramps or the measured rates of flow curves. A
    quantity the fitted data do not carry is ``None`` and listed in ``not_given``, never filled in.
    """
    r = result.ranges
    out = {"shear_strain": _span(r.get("strain_min", np.nan), r.get("strain_max", np.nan)),
           "shear_rate_1_per_s": _span(r.get("rate_min_1_per_s", np.nan), r.get("rate_max_1_per_s", np.nan)),
           "time_s": _span(r.get("time_min_s", np.nan), r.get("time_max_s", np.nan)),
           "angular_frequency_rad_per_s": _span(r.get("omega_min_rad_per_s", np.nan),
                                                r.get("omega_max_rad_per_s", np.nan))}
    out["not_given"] = [k for k, v in out.items() if v is None]
    sel = result.selection or []
    out["tests"] = sorted({str(s.get("test")) for s in sel if s.get("test")})
    out["conditions"] = [str(s.get("label", s.get("condition", ""))) for s in sel]
    return out


def parameter_uncertainty(result: FitResult, law: ConstitutiveModel | None = None,
                          lp: Mapping[str, float] | None = None) -> dict:
    """Uncertainty of a card's parameters from the fit (lmfit's linearised covariance).

    Returns ``{"method", "standard_errors", "relative_standard_errors", "not_determined",
    "initial_shear_modulus_stderr"}``: standard errors in the parameters' units; ``not_determined`` lists the
    varied parameters without a finite standard error (covariance not estimable); the initial shear modulus's
    standard error (Pa) is propagated from the covariance (delta method, central differences) when the elastic
    law's parameters all have one, else ``None``.
    """
    se = {k: float(v) for k, v in result.stderr.items()}
    rel = {k: (abs(se[k] / result.params[k]) if k in result.params and result.params[k] != 0 and np.isfinite(se[k])
               else float("nan")) for k in se}
    varying = list(result.varying)
    not_det = [k for k in varying if not np.isfinite(se.get(k, np.nan))]
    out = {"method": "lmfit covariance at the optimum (linearised; see fit_quality.flags for poorly determined fits)",
           "standard_errors": se, "relative_standard_errors": rel, "not_determined": not_det,
           "initial_shear_modulus_stderr": None}
    if law is None or lp is None:
        return out
    names = [k for k in varying if k in lp]
    corr = np.asarray(result.correlation, float)
    if (not names or any(k in not_det for k in names) or corr.shape != (len(varying), len(varying))
            or not np.all(np.isfinite(corr))):
        return out
    idx = [varying.index(k) for k in names]
    sd = np.array([se[k] for k in names])
    cov = corr[np.ix_(idx, idx)] * np.outer(sd, sd)
    grad = np.zeros(len(names))
    for j, k in enumerate(names):
        h = 1e-4 * max(abs(lp[k]), sd[j], 1e-12)
        up, dn = dict(lp), dict(lp)
        up[k], dn[k] = lp[k] + h, lp[k] - h
        grad[j] = (initial_shear_modulus(law, up) - initial_shear_modulus(law, dn)) / (2 * h)
    var = float(grad @ cov @ grad)
    out["initial_shear_modulus_stderr"] = math.sqrt(var) if np.isfinite(var) and var >= 0 else None
    return out


#: largest shear strain of the grid on which a card's Abaqus and FEBio constants are checked against the fitted law
#: when the fit gives no strain range (sweeps, relaxation moduli): a check of the conversion only; such a card states
#: no strain validity (``marlow_strain_max`` None) and no secant modulus
CONVERSION_CHECK_STRAIN_MAX = 0.5


def fitted_strain_max(ranges: Mapping) -> float | None:
    """The largest fitted shear strain of a fit's (or a card's ``validity``) ranges; None where they do not give
    it."""
    strain_max = ranges.get("strain_max", float("nan"))
    return float(strain_max) if strain_max is not None and np.isfinite(strain_max) else None


def material_fields(law: ConstitutiveModel | None, lp: Mapping[str, float], poisson_ratio: float,
                    prony: dict | None = None, strain_max: float | None = None,
                    pipkin_rogers: dict | None = None) -> tuple[dict, list[str], bool]:
    """The material part of a card, the one place it is assembled (:func:`make_card` and the cards of posterior
    draws, ``uq.elastic_card``): from the elastic law, its parameters ``lp``, the Poisson ratio, the Prony
    series (``g``, ``tau``, ``g_inf``, ``source``, ... or None) and the Pipkin-Rogers weight law
    (:func:`pipkin_rogers_block`, or None).

    Returns ``(fields, notes, singular_origin)``: ``fields`` = ``prony`` (with its ``normalisation`` statement),
    ``pipkin_rogers``, ``elastic_law``, ``elastic_parameters``, ``initial_shear_modulus``, ``poisson_ratio`` and
    ``bulk_modulus`` (``models.base.bulk_modulus(G0, nu)``). A law whose tangent still grows as gamma -> 0
    (``singular_origin``) gets the secant modulus at ``strain_max / 20`` as its initial shear modulus (NaN, with a
    note, when ``strain_max`` -- the fit's largest strain -- is not given); a linear elastic shear law is written as
    the neo-Hookean law with mu = G0 (``records.finite_strain_law``). ``law`` None (no solid law): NaN moduli,
    ``elastic_law`` None.
    """
    notes: list[str] = []
    if prony is not None:
        prony = {**prony, "normalisation": ("g_i relative to the instantaneous shear modulus: "
                                            "G(t) = G0 (g_inf + sum g_i exp(-t/tau_i)), g_inf = 1 - sum g_i "
                                            "(Abaqus g_i)")}
        if len(prony["g"]) > 6:
            notes.append("more than 6 Prony terms: the FEBio block cannot hold them")
    mu0 = initial_shear_modulus(law, lp) if law is not None else float("nan")
    singular_origin = law is not None and np.isfinite(mu0) and not math.isclose(
        mu0, initial_shear_modulus(law, lp, step=1e-4), rel_tol=1e-3)
    if singular_origin and strain_max is None:
        mu0 = float("nan")
        notes.append("the law has an unbounded initial tangent modulus and the fit gives no strain range: no "
                     "secant modulus, so initial_shear_modulus and bulk_modulus are not given")
    elif singular_origin:
        # tangent still growing as gamma -> 0 (Nunes, Amin with a negative exponent): the law has no finite
        # initial modulus, so the bulk modulus is based on the secant modulus at the smallest checked strain
        gamma_ref = strain_max / 20.0
        mu0 = float(np.asarray(law.elastic_shear_stress(lp, np.array([gamma_ref])), float)[0] / gamma_ref)
        notes.append(f"the law has an unbounded initial tangent modulus; initial_shear_modulus is its secant "
                     f"modulus at gamma = {gamma_ref:.3g}")
    fields = {"prony": prony, "pipkin_rogers": pipkin_rogers, "elastic_law": None if law is None else law.name,
              "elastic_parameters": dict(lp)}
    if law is not None:
        name, params = finite_strain_law(law.name, dict(lp), mu0)
        if name != law.name:
            fields["elastic_law"], fields["elastic_parameters"] = name, params
            notes.append("linear elastic shear law written as neo-Hookean (mu = G0; identical in simple shear)")
    fields["initial_shear_modulus"] = mu0
    fields["poisson_ratio"] = float(poisson_ratio)
    fields["bulk_modulus"] = bulk_modulus(mu0, poisson_ratio) if np.isfinite(mu0) else float("nan")
    return fields, notes, singular_origin


# ------------------------------------------------------------------------------------------------
# the material of a card, per model family
# ------------------------------------------------------------------------------------------------
#: what family_material returns: the elastic law (None: no solid law), its parameters, the Prony series
#: (``g``, ``tau``, ``g_inf``, ``source``, ... or None) and notes for the card
FamilyMaterial = tuple[ConstitutiveModel | None, dict, dict | None, list[str]]


def _qlv_material(model: ConstitutiveModel, p: Mapping[str, float], ranges: Mapping) -> FamilyMaterial:
    """QLV: the instantaneous law and the reduced relaxation function's Prony series, unchanged."""
    law, lp = _law_and_params(model, p)
    g_inf, g, taus = model.prony_weights(p)
    prony = {"g": [float(x) for x in g], "tau": [float(x) for x in taus], "g_inf": float(g_inf),
             "source": "QLV reduced relaxation function"}
    return law, lp, prony, []


def _kelvin_voigt_material(model: ConstitutiveModel, p: Mapping[str, float], ranges: Mapping) -> FamilyMaterial:
    """Retardation-spectrum models (generalized Kelvin-Voigt): their Prony series is known exactly; the linear
    shear law with the instantaneous modulus."""
    g_inf, g_k, theta = model.relaxation_spectrum(p)
    g0 = initial_shear_modulus(model, p)  # G(0) = g_inf + sum g_k of the interconverted spectrum
    prony = {"g": [float(x) for x in g_k / g0], "tau": [float(x) for x in theta], "g_inf": float(g_inf / g0),
             "fit_rel_error": 0.0,
             "source": "exact interconversion of the Kelvin-Voigt retardation spectrum (relaxation times "
                       "= eigenvalues of the series chain)"}
    return LinearElasticShear(), {"G0": g0}, prony, []


def _spectrum_material(model: ConstitutiveModel, p: Mapping[str, float], ranges: Mapping) -> FamilyMaterial:
    """Other linear viscoelastic and fractional models: a Prony series by NNLS on the model's step relaxation
    modulus (or its G*(omega)) over the fitted time (or 1/omega) window, on the model's own times where it has
    them; the linear shear law with the instantaneous modulus, none for a fluid-like model."""
    notes: list[str] = []
    taus = _model_taus(model, p)
    t_lo = ranges.get("time_min_s", np.nan)
    t_hi = ranges.get("time_max_s", np.nan)
    w_rng = (ranges.get("omega_min_rad_per_s", np.nan), ranges.get("omega_max_rad_per_s", np.nan))
    if not np.isfinite(t_lo) and np.all(np.isfinite(w_rng)):  # frequency-sweep fits: times = 1/omega
        t_lo, t_hi = 1.0 / w_rng[1], 1.0 / w_rng[0]
    if not (np.isfinite(t_lo) and np.isfinite(t_hi) and 0 < t_lo < t_hi):
        return None, {}, None, ["the fit gives no time or frequency window: no Prony series is derived (the "
                                "model is not sampled over an assumed window), so the card has no solid law"]
    t_lo, t_hi = float(t_lo), float(t_hi)
    if taus is None:
        taus = np.geomspace(t_lo, t_hi, max(int(round(math.log10(t_hi / t_lo))) + 1, 2))
    if model.supports("shear_history"):
        pr = prony_from_step_response(model, p, taus, t_lo, t_hi)
        source = f"NNLS on the model's step relaxation modulus over [{t_lo:g}, {t_hi:g}] s"
    else:
        w_lo, w_hi = 1.0 / t_hi, 1.0 / t_lo
        pr = prony_from_complex_modulus(model, p, taus, w_lo, w_hi)
        source = f"NNLS on the model's G'(omega), G''(omega) over [{w_lo:g}, {w_hi:g}] rad/s"
    prony = {"g": pr["g"], "tau": pr["tau"], "g_inf": pr["g_inf"], "fit_rel_error": pr["fit_rel_error"],
             "source": source}
    if pr["fit_rel_error"] > 0.02:
        notes.append(f"Prony approximation of the model has {100 * pr['fit_rel_error']:.1f} % relative RMS error")
    law = LinearElasticShear()
    if pr["g_inf"] < 1e-6:
        notes.append("no long-term modulus (fluid-like): not a solid material law; no FE block written")
        law = None
    return law, {"G0": pr["G0"]}, prony, notes


def is_pipkin_rogers(model: ConstitutiveModel) -> bool:
    """True for a Pipkin-Rogers model (``models.beyond_qlv.PipkinRogersModel``: strain-dependent Prony weights)."""
    return isinstance(model.structure, Mapping) and model.structure.get("kind") == "pipkin_rogers" and \
        hasattr(model, "weight_law_parameters")


def pipkin_rogers_block(model: ConstitutiveModel, p: Mapping[str, float]) -> dict:
    """The card's ``pipkin_rogers`` block of a Pipkin-Rogers fit: the fitted ``beta_i``, ``kappa_i`` and ``gamma_s``
    unchanged (``PipkinRogersModel.weight_law_parameters``), the weight law and the 3-D strain measure the TLED
    solver uses (``I1bar - 3`` of the isochoric deformation, ``gamma^2`` in simple shear)."""
    w = model.weight_law_parameters(p)
    return {"beta": w["beta"], "kappa": w["kappa"], "gamma_s": w["gamma_s"],
            "weights": "g_i = beta_i m_i / (1 + sum_j beta_j m_j), g_inf = 1 / (1 + sum_j beta_j m_j), "
                       "m_i = 1 + kappa_i s, s = x / (x + gamma_s^2)",
            "strain_measure": "x = I1bar - 3 of the isochoric deformation (= gamma^2 in simple shear)",
            "source": "models.beyond_qlv.PipkinRogersModel (the fitted parameters, unchanged)"}


def _pipkin_rogers_material(model: ConstitutiveModel, p: Mapping[str, float], ranges: Mapping) -> FamilyMaterial:
    """Pipkin-Rogers: the instantaneous law and the small-strain Prony series (weights ``beta_i / (1 + sum beta)``,
    the model's times); the strain-dependent weights are the card's ``pipkin_rogers`` block
    (:func:`pipkin_rogers_block`)."""
    law, lp = model.instantaneous, {k: float(p[k]) for k in model.instantaneous.param_names}
    w = model.weight_law_parameters(p)
    beta = np.asarray(w["beta"], float)
    prony = {"g": [float(x) for x in beta / (1.0 + beta.sum())], "tau": w["tau_s"],
             "g_inf": float(1.0 / (1.0 + beta.sum())),
             "source": "Pipkin-Rogers weights at small strain (gamma -> 0); the strain-dependent weights are the "
                       "card's 'pipkin_rogers' block"}
    return law, lp, prony, []


def family_material(model: ConstitutiveModel, p: Mapping[str, float], ranges: Mapping) -> FamilyMaterial:
    """The material of a fitted model's card, per family: QLV (:func:`_qlv_material`), Pipkin-Rogers
    (:func:`_pipkin_rogers_material`), generalized Kelvin-Voigt (:func:`_kelvin_voigt_material`), other linear
    viscoelastic and fractional models (:func:`_spectrum_material`); any other model (hyperelastic, viscous, the
    other beyond-QLV laws) its elastic law (``None`` where there is none) without a Prony series. ``ranges`` are
    the fit's data ranges (the time window of the NNLS)."""
    if model.family == "qlv" and hasattr(model, "prony_weights"):
        return _qlv_material(model, p, ranges)
    if is_pipkin_rogers(model):
        return _pipkin_rogers_material(model, p, ranges)
    if model.family == "linear_viscoelastic" and hasattr(model, "relaxation_spectrum"):
        return _kelvin_voigt_material(model, p, ranges)
    if model.family in ("linear_viscoelastic", "fractional") and (model.supports("shear_history")
                                                                    or model.supports("oscillation")):
        return _spectrum_material(model, p, ranges)
    law, lp = _law_and_params(model, p)
    return law, lp, None, []


#: why a Pipkin-Rogers card has no Abaqus block (the card's ``abaqus_reason``)
ABAQUS_PIPKIN_ROGERS_REASON = (
    "Abaqus has no strain-dependent Prony weights: *VISCOELASTIC, TIME=PRONY holds constant relative moduli g_i, and "
    "the nonlinear viscoelastic networks (*VISCOELASTIC, NONLINEAR: parallel rheological framework) scale the "
    "equilibrium law by a constant stiffness ratio per network and make the flow, not the weight, nonlinear; the "
    "Pipkin-Rogers weights g_i(gamma) need a user material (UMAT/VUMAT); the TLED solver runs the card as written")


def _abaqus_fields(card: dict, law: ConstitutiveModel, lp: Mapping[str, float], strain_max: float | None,
                   check_max: float, notes: list[str]) -> None:
    """``abaqus_form``, ``abaqus_constants`` (and for MARLOW ``abaqus_marlow_table``) of a card with a solid law:
    the first native form whose energy reproduces the fitted law in simple shear (1 %), else MARLOW with the
    uniaxial table equivalent in simple shear when the fit gives a strain range."""
    native = abaqus_hyperelastic_form(card["elastic_law"], card["elastic_parameters"])
    options = []
    if native is not None:
        options.append(native)
        if native[0].startswith("OGDEN"):
            # a classical-form Ogden law W = sum mu_i/alpha_i (...) converts with mu_i alpha_i / 2
            c = list(native[1])
            options.append((native[0], [c[k] * c[k + 1] / 2.0 if k % 2 == 0 else c[k] for k in range(len(c))]))
    card["abaqus_form"], card["abaqus_constants"] = ("MARLOW" if strain_max is not None else None), []
    gamma = np.linspace(check_max / 20.0, check_max, 20)
    target = np.asarray(law.elastic_shear_stress(lp, gamma), float)
    for form, consts in options:
        # self-check: the Abaqus energy with these constants must reproduce the fitted law (1 %)
        trial = {**card, "abaqus_form": form, "abaqus_constants": consts}
        err = np.max(np.abs(abaqus_simple_shear_stress(abaqus_block(trial), gamma) - target) / np.abs(target))
        if err <= 0.01:
            card["abaqus_form"], card["abaqus_constants"] = form, consts
            card["abaqus_check_max_rel_error"] = float(err)
            break
        notes.append(f"native {form} constants do not reproduce the law ({100 * err:.2g} % off); not used")
    if card["abaqus_form"] == "MARLOW":
        strain, stress = marlow_uniaxial_table(law, lp, float(card["validity"]["marlow_strain_max"]),
                                               spacing=card["validity"].get("marlow_spacing", "linear"))
        card["abaqus_marlow_table"] = {"nominal_strain": strain.tolist(), "nominal_stress_pa": stress.tolist()}
        notes.append("no native Abaqus form: MARLOW with uniaxial data equivalent in simple shear (I1-only)")
    elif card["abaqus_form"] is None:
        card["abaqus_reason"] = "no native Abaqus form, and no fitted strain range for a MARLOW table"
        notes.append(f"{card['abaqus_reason']}: no Abaqus block")


def make_card(result: FitResult, model: ConstitutiveModel, poisson_ratio: float,
              dataset: str = "", fit_file: str = "", strain_margin: float = 1.2) -> dict:
    """Canonical card of a fitted model (see the module docstring for the shape and conventions); ``poisson_ratio``
    is the configuration's ``fem.poisson_ratio`` (no default). The card holds plain JSON values only: every file
    format is written from it alone (:func:`write_card_files`), also from a card read back from disk
    (``records.MaterialCard``)."""
    p = result.params
    notes: list[str] = []
    card = {"model": result.model_key, "family": result.family, "parameters": dict(p), "units": dict(result.units),
            "standard_errors": dict(result.stderr), "structure": result.structure}
    strain_max = fitted_strain_max(result.ranges)
    check_max = strain_max if strain_max is not None else CONVERSION_CHECK_STRAIN_MAX
    law, lp, prony, family_notes = family_material(model, p, result.ranges)
    notes += family_notes
    pr = pipkin_rogers_block(model, p) if is_pipkin_rogers(model) else None
    fields, law_notes, singular_origin = material_fields(law, lp, poisson_ratio, prony, strain_max, pr)
    card.update(fields)
    notes += law_notes
    prony = card["prony"]
    card["validity"] = {**result.ranges, "plate_target": result.target,
                        "marlow_strain_max": strain_max * strain_margin if strain_max is not None else None}
    if strain_max is None and law is not None:
        notes.append(f"the fit gives no strain range: the card states no strain validity; its Abaqus/FEBio "
                     f"constants were checked against the law up to gamma = {check_max:g}")
    if singular_origin:
        card["validity"]["marlow_spacing"] = "geometric"
    card["provenance"] = {"dataset": dataset, "scope": result.scope, "target": result.target,
                          "curves": result.curve_labels, "fit_file": fit_file, "software": "tissuemech"}
    card["fit_quality"] = {"success": result.success, "chisqr": result.chisqr, "rmse": result.rmse,
                           "nrmse": result.nrmse, "aicc": result.aicc, "bic": result.bic, "n": result.n,
                           "n_eff": result.n_eff, "k": result.k, "flags": list(result.flags)}
    if law is None:
        card["abaqus_form"] = None
        if model.family == "viscous":
            notes.append("viscous flow law: no solid material card")
        elif model.family == "beyond_qlv":
            notes.append("beyond-QLV law: no native Abaqus/FEBio form and no TLED law; needs a user material "
                         "(UMAT/VUMAT or a FEBio plugin)")
        card["abaqus_reason"] = notes[-1] if notes else "no solid elastic law"
    elif pr is not None:
        card["abaqus_form"], card["abaqus_constants"], card["abaqus_reason"] = None, [], ABAQUS_PIPKIN_ROGERS_REASON
        notes.append(f"no Abaqus block: {ABAQUS_PIPKIN_ROGERS_REASON}")
    else:
        _abaqus_fields(card, law, lp, strain_max, check_max, notes)
    if law is None:
        card.update(febio_form=None, febio_parameters=None, febio_check_max_rel_error=None,
                    febio_reason=notes[-1] if notes else "no solid elastic law")
    elif pr is not None:
        card.update(febio_form=None, febio_parameters=None, febio_check_max_rel_error=None,
                    febio_reason=FEBIO_PIPKIN_ROGERS_REASON)
        notes.append(f"no FEBio block: {FEBIO_PIPKIN_ROGERS_REASON}")
    else:
        ogden = card["abaqus_constants"] if str(card["abaqus_form"]).startswith("OGDEN") else None
        card.update(febio_card_material(card["elastic_law"], card["elastic_parameters"], card["bulk_modulus"],
                                        prony, lambda g: law.elastic_shear_stress(lp, g), check_max,
                                        ogden_constants=ogden))
        if card["febio_form"] is None:
            notes.append(f"no FEBio block: {card['febio_reason']}")
    card["valid_range"] = valid_range(result)
    card["uncertainty"] = parameter_uncertainty(result, law, lp)
    card["niftysim_reason"] = niftysim_reason(card)  # None: <model>.niftysim.xml is written (cards_niftysim)
    card["notes"] = notes
    return card


def card_json(card: Mapping | MaterialCard) -> str:
    """Canonical JSON text of a card (``records.MaterialCard.json_text``: sorted keys, the schema version)."""
    return _as_card(card).json_text()


def _as_card(card: Mapping | MaterialCard) -> MaterialCard:
    """The validated card of a card dict (or the card itself)."""
    return card if isinstance(card, MaterialCard) else MaterialCard.from_dict(dict(card))


# ------------------------------------------------------------------------------------------------
# Abaqus
# ------------------------------------------------------------------------------------------------
def abaqus_block(card: Mapping | MaterialCard, material_name: str | None = None) -> str | None:
    """Abaqus ``*MATERIAL`` block of a card (a card dict, or a ``records.MaterialCard`` read back from disk), written
    from the card's content alone; ``None`` when the card has no Abaqus form (``abaqus_reason`` says why)."""
    card = card.data if isinstance(card, MaterialCard) else card
    if card.get("abaqus_form") is None:
        return None
    name = material_name or re.sub(r"[^A-Za-z0-9_]", "_", str(card["model"])).upper()
    lines = [f"** tissuemech material card: model {card['model']} ({card.get('family', '')}), units N, m, s, Pa",
             f"** initial shear modulus {card['initial_shear_modulus']:.6g} Pa, nu = {card['poisson_ratio']}, "
             f"K = {card['bulk_modulus']:.6g} Pa",
             f"*MATERIAL, NAME={name}"]
    form = card["abaqus_form"]
    moduli = ", MODULI=INSTANTANEOUS" if card.get("prony") else ""
    if form == "MARLOW":
        table = card.get("abaqus_marlow_table")
        if table is not None:
            strain, stress = table["nominal_strain"], table["nominal_stress_pa"]
        else:  # a card of schema 0 (no table in the card): the table of its registered elastic law
            strain, stress = marlow_uniaxial_table(get_model(card["elastic_law"]), card["elastic_parameters"],
                                                   float(card["validity"]["marlow_strain_max"]),
                                                   spacing=card["validity"].get("marlow_spacing", "linear"))
        # compressibility of the Marlow form through its POISSON parameter (no data line)
        lines.append(f"*HYPERELASTIC, MARLOW, POISSON={card['poisson_ratio']:g}{moduli}")
        lines.append("*UNIAXIAL TEST DATA")
        lines += [f"{s:.10g}, {e:.10g}" for e, s in zip(strain, stress)]
    else:
        form, consts = card["abaqus_form"], list(card["abaqus_constants"])
        d_terms = _abaqus_d_terms(form, card["bulk_modulus"])
        lines.append(f"*HYPERELASTIC, {form}{moduli}")
        lines.append(_data_lines(consts + d_terms))
    if card.get("prony"):
        lines.append("*VISCOELASTIC, TIME=PRONY")
        lines += [f"{g:.10g}, 0., {tau:.10g}" for g, tau in zip(card["prony"]["g"], card["prony"]["tau"])]
        # a card fitted to a TTS mastercurve: its Prony times are those at Tref, and the shift function follows
        trs = (card.get("time_temperature_shift") or {}).get("abaqus_trs")
        if trs:
            lines.append(trs.rstrip("\n"))
    return "\n".join(lines) + "\n"


def parse_abaqus_block(text: str) -> dict:
    """Parse a block written by :func:`abaqus_block` (keyword lines -> list of numeric data rows)."""
    out: dict[str, list[list[float]]] = {}
    key = None
    for raw in text.splitlines():
        line = raw.strip()
        if not line or line.startswith("**"):
            continue
        if line.startswith("*"):
            key = line
            out[key] = []
            continue
        if key is None:
            raise ValueError(f"data line before any keyword: {line!r}")
        out[key].append([float(x) for x in line.split(",") if x.strip()])
    return out


def abaqus_simple_shear_stress(block: str, strain: np.ndarray) -> np.ndarray:
    """Incompressible simple-shear stress of an Abaqus hyperelastic block, evaluated from Abaqus's own energy
    forms (an independent check of the parameter conversions). sigma_12 = 2 gamma (W1 + W2) for invariant
    forms; Ogden sigma_12 = sum (2 mu_i/alpha_i)(l^a - l^-a)/(l + 1/l); Marlow: W'(I1) from the uniaxial table."""
    parsed = parse_abaqus_block(block)
    g = np.asarray(strain, float)
    x = g ** 2  # I1 - 3 = I2 - 3 in simple shear
    hyper = next(k for k in parsed if k.startswith("*HYPERELASTIC"))
    values = [v for row in parsed[hyper] for v in row]
    opts = hyper.upper()
    if "MARLOW" in opts:
        table_key = next(k for k in parsed if k.startswith("*UNIAXIAL TEST DATA"))
        stress, nom_strain = np.array(parsed[table_key]).T
        lam = 1.0 + nom_strain[1:]
        w1 = stress[1:] / (2.0 * (lam - lam ** -2))
        i1 = lam ** 2 + 2.0 / lam
        # W'(I1) at I1 -> 3 is the limit of the table (linear extrapolation of the first points)
        i1 = np.r_[3.0, i1]
        w1 = np.r_[w1[0] - (w1[1] - w1[0]) * (i1[1] - 3.0) / (i1[2] - i1[1]), w1]
        return 2.0 * g * np.interp(3.0 + x, i1, w1)
    n = int(re.search(r"N=(\d+)", opts).group(1)) if "N=" in opts else 1
    if "NEO HOOKE" in opts:
        return 2.0 * g * values[0]
    if "MOONEY-RIVLIN" in opts:
        return 2.0 * g * (values[0] + values[1])
    if "REDUCED POLYNOMIAL" in opts or "YEOH" in opts:
        n = 3 if "YEOH" in opts else n
        return 2.0 * g * sum(i * values[i - 1] * x ** (i - 1) for i in range(1, n + 1))
    if "POLYNOMIAL" in opts:
        s, idx = 0.0, 0
        for total in range(1, n + 1):
            for j in range(0, total + 1):
                i = total - j
                c = values[idx]
                idx += 1
                # d/dI1 + d/dI2 of C_ij x^i y^j at x = y
                s = s + c * (i * x ** (i - 1 + j) if i else 0.0) + c * (j * x ** (i + j - 1) if j else 0.0)
        return 2.0 * g * s
    if "OGDEN" in opts:
        lam = g / 2.0 + np.sqrt(1.0 + g ** 2 / 4.0)
        return sum(2.0 * values[2 * k] / values[2 * k + 1] * (lam ** values[2 * k + 1] - lam ** -values[2 * k + 1])
                   / (lam + 1.0 / lam) for k in range(n))
    if "ARRUDA-BOYCE" in opts:
        mu, lam_m = values[0], values[1]
        i1 = 3.0 + x
        w1 = mu * sum((i + 1) * ARRUDA_BOYCE_C[i] * i1 ** i / lam_m ** (2 * i) for i in range(5))
        return 2.0 * g * w1
    raise ValueError(f"cannot evaluate Abaqus option {hyper!r}")


# ------------------------------------------------------------------------------------------------
# FEBio (forms and checks in :mod:`tissuemech.cards_febio`)
# ------------------------------------------------------------------------------------------------
def febio_block(card: Mapping | MaterialCard, material_id: int = 1, material_name: str | None = None) -> str | None:
    """FEBio ``<material>`` XML element (FEBio 4 spec) or ``None`` when the card has no verified FEBio form
    (``card["febio_reason"]`` says why)."""
    card = card.data if isinstance(card, MaterialCard) else card
    if card.get("febio_form") is None:
        return None
    mat = febio_material_element(card["febio_form"], card["febio_parameters"], card.get("prony"),
                                 material_id=material_id, name=material_name or str(card["model"]))
    ET.indent(mat)
    return ET.tostring(mat, encoding="unicode") + "\n"


def febio_file_text(card: Mapping | MaterialCard, material_id: int = 1,
                    material_name: str | None = None) -> str | None:
    """A FEBio input document (``febio_spec`` 4.0, ``Material`` section) of the card, with its valid range and
    provenance as XML comments; ``None`` when the card has no FEBio form."""
    card = card.data if isinstance(card, MaterialCard) else card
    if card.get("febio_form") is None:
        return None
    mat = febio_material_element(card["febio_form"], card["febio_parameters"], card.get("prony"),
                                 material_id=material_id, name=material_name or str(card["model"]))
    vr = card.get("valid_range") or {}
    comments = [f"tissuemech material card: model {card['model']} ({card.get('family', '')}), units N, m, s, Pa",
                f"valid range (fitted data): {_range_text(vr)}",
                f"Poisson ratio {card['poisson_ratio']} (configuration) -> k = {card['bulk_modulus']:.6g} Pa",
                f"FEBio forms checked against febiosoftware/FEBio {FEBIO_SOURCE_COMMIT[:7]}"]
    return febio_document(mat, comments)


# ------------------------------------------------------------------------------------------------
# files
# ------------------------------------------------------------------------------------------------
def write_card_files(card: Mapping | MaterialCard, folder, stem: str | None = None) -> dict[str, Path]:
    """Write ``<stem>.json``, ``<stem>.inp`` (Abaqus), ``<stem>.feb.xml`` (FEBio document) and
    ``<stem>.niftysim.xml`` (NiftySim element-set fragment, :mod:`tissuemech.cards_niftysim`) where they exist, each
    from the card's content alone (a card dict of :func:`make_card`, or a ``records.MaterialCard`` read back).

    Returns the written paths by kind (``json``, ``abaqus``, ``febio``, ``niftysim``).
    """
    typed = _as_card(card)  # validated: a card that the reader would refuse is not written
    card = typed.data
    folder = Path(folder)
    stem = stem or str(card["model"])
    out = {"json": typed.write_json(folder / f"{stem}.json")}
    ab = abaqus_block(card)
    if ab is not None:
        out["abaqus"] = write_text(ab, folder / f"{stem}.inp")
    fb = febio_file_text(card)
    if fb is not None:
        out["febio"] = write_text(fb, folder / f"{stem}.feb.xml")
    ns = niftysim_file_text(card, stem)
    if ns is not None:
        out["niftysim"] = write_text(ns, folder / f"{stem}.niftysim.xml")
    return out


__all__ = ["make_card", "family_material", "material_fields", "pipkin_rogers_block", "is_pipkin_rogers",
           "ABAQUS_PIPKIN_ROGERS_REASON", "fitted_strain_max", "CONVERSION_CHECK_STRAIN_MAX", "card_json",
           "abaqus_block", "parse_abaqus_block", "abaqus_simple_shear_stress", "abaqus_hyperelastic_form",
           "marlow_uniaxial_table", "febio_block", "febio_file_text", "febio_simple_shear_stress", "valid_range",
           "parameter_uncertainty", "prony_from_step_response", "prony_from_complex_modulus", "write_card_files"]
