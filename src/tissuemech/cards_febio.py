"""FEBio material blocks of the material cards (FEBio 4 input spec), and an independent evaluation of FEBio's
own stress forms in incompressible simple shear that checks every written block against the fitted law.

What was checked, and where (FEBio source ``github.com/febiosoftware/FEBio`` at commit
``65622b536bab6aab02a6121f771b05743f9a1584``, 2026-01-29; FEBio User Manual ``Documentation/FEBio_User_Manual.lyx``
at the same commit; FEBio feature manual ``febiosoftware.github.io/febio-feature-manual``):

* type strings: ``REGISTER_FECORE_CLASS`` in ``FEBioMech/FEBioMechModule.cpp`` -- ``"Mooney-Rivlin"``
  (FEMooneyRivlin), ``"Ogden"`` (FEOgdenMaterial), ``"Gent"`` (FEGentMaterial), ``"Yeoh"`` (FEYeoh),
  ``"Arruda-Boyce"`` (FEArrudaBoyce), ``"polynomial"`` (FEPolynomialHyperElastic), ``"uncoupled viscoelastic"``
  (FEUncoupledViscoElasticMaterial), ``"viscoelastic"`` (FEViscoElasticMaterial), ``"neo-Hookean"`` (FENeoHookean,
  coupled, ``E``/``v``), ``"uncoupled Holmes-Mow"`` (FEHolmesMowUC).
* parameter names: ``ADD_PARAMETER`` in each class's ``.cpp``; the bulk modulus ``k`` of every uncoupled material
  is declared once in ``FEUncoupledMaterial.cpp`` (``U(J) = k/2 (ln J)^2`` by default).
* stress forms, read from each ``DevStress``/``Stress``:

  - ``Mooney-Rivlin`` (``c1``, ``c2``, ``k``): ``W = c1 (I1~ - 3) + c2 (I2~ - 3)``, so ``c1 = C10``, ``c2 = C01``;
    neo-Hooke ``c1 = mu/2``, ``c2 = 0``.
  - ``Ogden`` (``c1..c6``, ``m1..m6``, ``k``): principal deviatoric stress ``sum c_i/m_i (lambda^m_i - 1)/J``, i.e.
    ``W = sum c_i/m_i^2 (l1^m + l2^m + l3^m - 3)``; the project's ``2 mu_i/alpha_i^2`` form gives ``c_i = 2 mu_i``,
    ``m_i = alpha_i``.
  - ``Gent`` (``G``, ``Jm``, ``k``): ``W1 = G Jm / (2 (Jm - I1~ + 3))`` -- the project's Gent law unchanged
    (``G = mu``).
  - ``polynomial`` (``c01, c02, c10, c11, c12, c20, c21, c22``, ``D1``, ``D2``): *coupled* (derived from
    FEElasticMaterial), ``W = sum_{i,j<=2} c_ij (I1~-3)^i (I2~-3)^j + D1 (J-1)^2 + D2 (J-1)^4``. Note FEBio's
    ``D1`` multiplies ``(J-1)^2`` (Abaqus divides by it): ``K = 2 D1``. Holds the full polynomial of order 2 and
    the reduced polynomial of order 2; a law with a cubic term has no place in it.
  - ``uncoupled viscoelastic`` (``g0``, ``g1..g6``, ``t1..t6``, property ``elastic``, which must be an uncoupled
    material): ``S = g0 S_e + sum g_i H_i`` with ``H_i`` the usual recursive convolution of ``S_e`` with
    ``exp(-t/t_i)`` (``FEUncoupledViscoElasticMaterial::DevStress``). Only the deviatoric stress relaxes and the
    wrapper's ``k`` is added to its base's (``Init``: ``m_K += m_pBase->m_K``), so ``k`` is written once, on the
    wrapper, as in the manual's example. With the instantaneous law as base, ``g0 = g_inf``, ``g_i`` = the card's
    Prony ``g_i``, ``t_i = tau_i``: the QLV reduced relaxation function, at most six terms.

Laws for which **no block is written** (the card's ``febio_reason`` says why):

* ``Yeoh`` / reduced polynomial of order >= 3: the manual and ``FEYeoh::DevStrainEnergyDensity`` give
  ``W = sum c_i (I1~-3)^i``, but ``FEYeoh::DevStress`` computes ``W1 = sum c_i (I1~-3)^(i-1)`` (no factor ``i``):
  energy and stress disagree for ``c2..c6``, so no choice of ``c_i`` is right for both. (``c_i = i C_i0`` reproduces
  the stress that FEBio computes today; we do not write it, because the energy FEBio reports would then be wrong and
  a fix of FEYeoh would silently change the card.)
* ``Arruda-Boyce``: FEBio's ``W1 = mu sum_k k a_k (I1~/N)^(k-1)`` with ``a = 1/2, 1/10, 11/350, 19/1750,
  519/134750`` -- ``a_k`` is ``k`` times the series coefficient of Arruda-Boyce/Abaqus (``1/2, 1/20, 11/1050, ...``),
  so no ``(mu, N)`` reproduces the project's law.
* Lopez-Pamies, Nunes, Amin, full polynomials with cubic or higher terms: no native FEBio material.
* Pipkin-Rogers (the nonseparable extension, strain-dependent Prony weights): FEBio's nonlinear viscoelastic
  material is reactive viscoelasticity (``"reactive viscoelastic"`` / ``"uncoupled reactive viscoelastic"``,
  FEBio User Manual section "Reactive Viscoelastic Solid", ``FEUncoupledReactiveViscoelastic.cpp``), and it does not
  hold the Pipkin-Rogers law (:data:`FEBIO_PIPKIN_ROGERS_REASON`): (1) its weak bonds of generation ``u`` reform
  stress-free and carry the bond law of the *relative* deformation ``F(t) U(u)^-1`` (``DevStressWeakBonds``), not
  the hereditary sum of increments of a strain-dependent branch stress ``R_i(gamma) = g_i(gamma) sigma_e(gamma)``;
  (2) its strain-dependent weight, the optional recruitment ``F(Xi)`` of eq. ``rvs-reformed-with-recruitment``, is
  stored per generation at the strain where that generation starts to break (``UpdateSpecializedMaterialPoints``:
  ``m_wv``) and stays fixed while it relaxes, whereas the Pipkin-Rogers weights follow the current strain; (3) the
  strong bonds are one elastic material, while the Pipkin-Rogers equilibrium stress ``sigma_e(gamma) / (1 + sum_j beta_j
  m_j(gamma))`` is the instantaneous law times a strain-dependent factor no FEBio elastic material has. Its
  strain-dependent relaxation functions (``relaxation-exp-distortion``, ``relaxation-exp-dist-user``, ...) make the
  relaxation *time* depend on the distortion (a horizontal shift, the Schapery kind), not the weight. Only an ideal
  step is reproduced (one generation: ``sigma_e + F(Xi) sigma_b g(t)``). A FEBio plugin would be needed.
* Other beyond-QLV laws (Schapery, Maxwell branches): no native form (needs a plugin).
* a Prony series on a coupled base (``polynomial``): FEBio's coupled ``viscoelastic`` wrapper relaxes the whole
  stress including the pressure; the rheometer data say nothing about bulk relaxation, so it is not written.
* more than six Prony terms.
* Holmes-Mow (``uncoupled Holmes-Mow``: ``mu``, ``beta``) is an exponential law no project model fits; not used.

Every block is checked before it is written: :func:`febio_simple_shear_stress` (FEBio's forms above, evaluated
independently of the project's laws) must reproduce the fitted law's simple-shear stress within 1 % over the
card's strain range; otherwise no block, and the reason names the error.
"""
from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from collections.abc import Callable, Mapping

import numpy as np

#: FEBio input spec version of the written documents
FEBIO_SPEC_VERSION = "4.0"
#: FEBio's limit on Prony terms (MAX_TERMS of FEUncoupledViscoElasticMaterial)
FEBIO_MAX_PRONY_TERMS = 6
#: relative tolerance of the simple-shear self-check of a block against the fitted law
FEBIO_CHECK_RTOL = 0.01
#: FEBio commit the type strings, parameter names and stress forms were read from
FEBIO_SOURCE_COMMIT = "65622b536bab6aab02a6121f771b05743f9a1584"

#: why a Pipkin-Rogers card has no FEBio block (module docstring)
FEBIO_PIPKIN_ROGERS_REASON = (
    "FEBio's nonlinear viscoelastic material, 'uncoupled reactive viscoelastic' (FEBio User Manual 'Reactive "
    "Viscoelastic Solid'; FEUncoupledReactiveViscoelastic.cpp, commit 65622b5), does not hold Pipkin-Rogers: its weak "
    "bonds reform stress-free and carry the bond law of the deformation relative to their generation, not the sum of "
    "increments of the branch stresses g_i(gamma) sigma_e(gamma); its strain-dependent weight (the recruitment "
    "F(Xi)) is fixed per bond generation at the strain where that generation starts to break, while the "
    "Pipkin-Rogers weights follow the current strain; its equilibrium stress is one elastic material, not "
    "sigma_e(gamma) / (1 + sum beta_j m_j(gamma)); its distortion-dependent relaxation functions change the "
    "relaxation time, not the weight. Only an ideal step would match; a FEBio plugin would be needed")

_REASON_YEOH = ("FEBio 'Yeoh' (FEYeoh.cpp, commit 65622b5) computes its stress with W1 = sum c_i (I1-3)^(i-1) but "
                "documents and integrates W = sum c_i (I1-3)^i; energy and stress disagree for terms of order >= 2, "
                "so no block is written (c_i = i C_i0 would reproduce the stress FEBio computes today)")
_REASON_AB = ("FEBio 'Arruda-Boyce' uses W1 = mu sum k a_k (I1/N)^(k-1) with a_k = k times the Arruda-Boyce series "
              "coefficients of the fitted law; no (mu, N) reproduces it")


def _ogden_terms(lp: Mapping[str, float]) -> list[tuple[float, float]]:
    found: dict[int, dict[str, float]] = {}
    for k, v in lp.items():
        m = re.fullmatch(r"(mu|alpha)_?(\d+)", k)
        if m:
            found.setdefault(int(m.group(2)), {})[m.group(1)] = float(v)
    return [(found[i]["mu"], found[i]["alpha"]) for i in sorted(found) if {"mu", "alpha"} <= set(found[i])]


def febio_elastic_parameters(law_key: str, lp: Mapping[str, float], bulk_modulus_pa: float,
                             ogden_constants: list[float] | None = None) -> tuple[str | None, dict, str]:
    """FEBio material type and parameters of an elastic law, or ``(None, {}, reason)``.

    Parameters
    ----------
    law_key : str
        Card ``elastic_law`` (registry key of the hyperelastic law, e.g. ``"mooney_rivlin"``, ``"ogden2"``).
    lp : mapping
        Card ``elastic_parameters`` (Pa for moduli).
    bulk_modulus_pa : float
        Bulk modulus K of the card (Pa), from the card's Poisson ratio (configuration), never a default here.
    ogden_constants : list of float, optional
        Verified Abaqus Ogden constants ``[mu1, alpha1, ...]`` of the card (in the ``2 mu/alpha^2`` form); used
        instead of ``lp`` for Ogden laws so that a converted classical-form law keeps its conversion.

    Returns
    -------
    (type, parameters, reason)
        ``parameters`` in FEBio's names and the card's SI units; ``reason`` is ``""`` when a type is returned.
    """
    k = float(bulk_modulus_pa)
    try:
        if law_key.startswith("neo_hook"):
            mu = float(lp["mu"]) if "mu" in lp else 2.0 * float(lp["C10"])
            return "Mooney-Rivlin", {"c1": 0.5 * mu, "c2": 0.0, "k": k}, ""
        if law_key.startswith("mooney_rivlin"):
            return "Mooney-Rivlin", {"c1": float(lp["C10"]), "c2": float(lp["C01"]), "k": k}, ""
        if re.fullmatch(r"ogden\d+", law_key):
            if ogden_constants:
                terms = [(ogden_constants[i], ogden_constants[i + 1]) for i in range(0, len(ogden_constants), 2)]
            else:
                terms = _ogden_terms(lp)
            if not terms or len(terms) > 6:
                return None, {}, f"FEBio 'Ogden' holds 1 to 6 terms; the law has {len(terms)}"
            params = {}
            for i, (mu, alpha) in enumerate(terms, start=1):
                params[f"c{i}"], params[f"m{i}"] = 2.0 * mu, alpha
            return "Ogden", {**params, "k": k}, ""
        if law_key == "gent":
            return "Gent", {"G": float(lp["mu"]), "Jm": float(lp["Jm"]), "k": k}, ""
        if law_key in ("reduced_polynomial2", "polynomial2"):
            names = ("C10", "C01", "C20", "C11", "C02")
            params = {f"c{n[1:]}": float(lp.get(n, 0.0)) for n in names}
            return "polynomial", {**params, "D1": 0.5 * k}, ""
        m = re.fullmatch(r"reduced_polynomial(\d+)", law_key)
        if law_key == "yeoh" or (m and int(m.group(1)) >= 3):
            return None, {}, _REASON_YEOH
        if law_key.startswith("arruda_boyce"):
            return None, {}, _REASON_AB
    except KeyError as exc:
        return None, {}, f"parameter {exc} of {law_key!r} missing"
    return None, {}, f"FEBio has no native material for the {law_key!r} law"


def febio_material_element(febio_type: str, params: Mapping[str, float], prony: Mapping | None = None,
                           material_id: int = 1, name: str = "material") -> ET.Element:
    """``<material>`` element: the elastic law alone, or wrapped in ``uncoupled viscoelastic`` with the Prony
    series (``g0 = g_inf``, ``g_i``, ``t_i`` in s; ``k`` on the wrapper as in the FEBio manual's example)."""
    attrs = {"id": str(material_id), "name": name}
    if prony:
        mat = ET.Element("material", {**attrs, "type": "uncoupled viscoelastic"})
        ET.SubElement(mat, "g0").text = f"{float(prony['g_inf']):.10g}"
        for i, (g, tau) in enumerate(zip(prony["g"], prony["tau"]), start=1):
            ET.SubElement(mat, f"g{i}").text = f"{float(g):.10g}"
            ET.SubElement(mat, f"t{i}").text = f"{float(tau):.10g}"
        ET.SubElement(mat, "k").text = f"{float(params['k']):.10g}"
        el = ET.SubElement(mat, "elastic", {"type": febio_type})
        for pname, v in params.items():
            if pname != "k":
                ET.SubElement(el, pname).text = f"{float(v):.10g}"
        return mat
    mat = ET.Element("material", {**attrs, "type": febio_type})
    for pname, v in params.items():
        ET.SubElement(mat, pname).text = f"{float(v):.10g}"
    return mat


def febio_document(material: ET.Element, comments: list[str] | None = None) -> str:
    """A FEBio input document ``<febio_spec version="4.0"><Material>...</Material></febio_spec>`` holding one
    material (the Material section alone: include it in a model, or paste the ``<material>`` element)."""
    root = ET.Element("febio_spec", {"version": FEBIO_SPEC_VERSION})
    for text in comments or []:
        root.append(ET.Comment(" " + text.replace("--", "- -") + " "))
    section = ET.SubElement(root, "Material")
    section.append(material)
    ET.indent(root)
    return '<?xml version="1.0" encoding="ISO-8859-1"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def _shear_stretch(g: np.ndarray) -> np.ndarray:
    return g / 2.0 + np.sqrt(1.0 + g ** 2 / 4.0)


def _elastic_shear(el: ET.Element, g: np.ndarray) -> np.ndarray:
    """Incompressible simple-shear Cauchy stress of an elastic FEBio material element (FEBio's own forms)."""
    def val(tag, default=0.0):
        t = el.findtext(tag)
        return float(t) if t is not None else default

    kind = el.get("type")
    x = g ** 2  # I1 - 3 = I2 - 3 in simple shear
    if kind == "Mooney-Rivlin":
        return 2.0 * g * (val("c1") + val("c2"))
    if kind == "Ogden":
        lam = _shear_stretch(g)
        out = np.zeros_like(g)
        for i in range(1, 7):
            c, m = val(f"c{i}"), val(f"m{i}", 1.0)
            out = out + (c / m) * (lam ** m - lam ** -m) / (lam + 1.0 / lam)
        return out
    if kind == "Gent":
        jm = val("Jm")
        return 2.0 * g * 0.5 * val("G") * jm / (jm - x)
    if kind == "polynomial":
        c = {f"{i}{j}": val(f"c{i}{j}") for i in range(3) for j in range(3)}
        w1 = c["10"] + c["11"] * x + c["12"] * x ** 2 + 2.0 * x * (c["20"] + c["21"] * x + c["22"] * x ** 2)
        w2 = c["01"] + c["11"] * x + c["21"] * x ** 2 + 2.0 * x * (c["02"] + c["12"] * x + c["22"] * x ** 2)
        return 2.0 * g * (w1 + w2)
    if kind == "Yeoh":  # the stress FEBio computes (see the module docstring), not the documented energy
        return 2.0 * g * sum(val(f"c{i + 1}") * x ** i for i in range(6))
    raise ValueError(f"cannot evaluate FEBio material type {kind!r}")


def febio_simple_shear_stress(xml_text: str, strain: np.ndarray) -> np.ndarray:
    """Instantaneous incompressible simple-shear Cauchy stress (Pa) of a FEBio material block or document.

    Evaluates FEBio's own stress forms (module docstring) independently of the project's laws; an
    ``uncoupled viscoelastic`` wrapper scales its base by ``g0 + sum g_i`` (its response at t = 0+, 1 for cards).
    """
    root = ET.fromstring(xml_text)
    mat = root if root.tag == "material" else root.find("Material/material")
    if mat is None:
        raise ValueError("no <material> element in the FEBio text")
    g = np.asarray(strain, float)
    if mat.get("type") in ("uncoupled viscoelastic", "viscoelastic"):
        scale = float(mat.findtext("g0", "1")) + sum(float(c.text) for c in mat if re.fullmatch(r"g[1-6]", c.tag))
        return scale * _elastic_shear(mat.find("elastic"), g)
    return _elastic_shear(mat, g)


def febio_card_material(law_key: str, lp: Mapping[str, float], bulk_modulus_pa: float, prony: Mapping | None,
                        shear_stress: Callable[[np.ndarray], np.ndarray], strain_max: float,
                        ogden_constants: list[float] | None = None) -> dict:
    """The FEBio part of a card: ``{"febio_form", "febio_parameters", "febio_reason", "febio_check_max_rel_error"}``.

    ``shear_stress(gamma)`` is the fitted law's elastic simple-shear stress (Pa); the block is kept only when
    FEBio's form reproduces it within :data:`FEBIO_CHECK_RTOL` on ``gamma`` in ``[strain_max/20, strain_max]``.
    """
    out = {"febio_form": None, "febio_parameters": None, "febio_reason": None, "febio_check_max_rel_error": None}
    ftype, params, reason = febio_elastic_parameters(law_key, lp, bulk_modulus_pa, ogden_constants)
    if ftype is not None and prony:
        if len(prony["g"]) > FEBIO_MAX_PRONY_TERMS:
            ftype, reason = None, (f"{len(prony['g'])} Prony terms: FEBio's viscoelastic materials hold at most "
                                   f"{FEBIO_MAX_PRONY_TERMS}")
        elif ftype == "polynomial":
            ftype, reason = None, ("FEBio 'polynomial' is a coupled material: its 'viscoelastic' wrapper would relax "
                                   "the pressure too, which the shear data do not support; 'uncoupled viscoelastic' "
                                   "needs an uncoupled base")
    if ftype is None:
        out["febio_reason"] = reason
        return out
    if not (math.isfinite(bulk_modulus_pa) and bulk_modulus_pa > 0):
        out["febio_reason"] = "no finite bulk modulus"
        return out
    gamma = np.linspace(strain_max / 20.0, strain_max, 20)
    target = np.asarray(shear_stress(gamma), float)
    block = ET.tostring(febio_material_element(ftype, params), encoding="unicode")
    err = float(np.max(np.abs(febio_simple_shear_stress(block, gamma) - target) / np.abs(target)))
    if not err <= FEBIO_CHECK_RTOL:
        out["febio_reason"] = (f"FEBio '{ftype}' with the converted parameters is {100 * err:.2g} % off the fitted "
                               f"law in simple shear; not written")
        return out
    out.update(febio_form=ftype, febio_parameters=params, febio_check_max_rel_error=err)
    return out


__all__ = ["febio_elastic_parameters", "febio_material_element", "febio_document", "febio_simple_shear_stress",
           "febio_card_material", "FEBIO_SPEC_VERSION", "FEBIO_MAX_PRONY_TERMS", "FEBIO_CHECK_RTOL",
           "FEBIO_SOURCE_COMMIT", "FEBIO_PIPKIN_ROGERS_REASON"]
