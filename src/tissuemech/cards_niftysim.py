"""NiftySim material elements of the material cards, and their reader.

NiftySim (Taylor et al., the GPU TLED package of UCL CMIC) reads a model XML whose element sets each carry one
``<Material Type="...">`` element. What was read, and where (a public mirror of the NiftySim source,
``github.com/eloygarcia/niftysim``: ``tledModel.cpp``, ``tledMaterialNH.cpp``, ``tledMaterialNHV.cpp``,
``tledElementT4.cpp``):

* material types: ``LE``, ``NH``, ``NHV``, ``TI``, ``TIV``, ``AB``, ``PY`` (``tledElementT4``); only ``NHV`` and
  ``TIV`` take viscous terms (``tledModel::GetNumViscIsoTerms``);
* ``<ElasticParams NumParams="2">mu K</ElasticParams>`` for ``NH``/``NHV``: the stress of ``tledMaterialNH(V)`` is
  ``S = mu J^(-2/3) (I - I1/3 C^-1) + K J (J - 1) C^-1``, i.e. ``W = mu/2 (I1~ - 3) + K/2 (J - 1)^2``: the project's
  neo-Hookean law (``mu``) with the FEM's volumetric energy ``kappa/2 (J - 1)^2`` (:mod:`tissuemech.fem.materials`);
* ``<ViscoParams NumIsoTerms="n" NumVolTerms="0">a1 t1 a2 t2 ...</ViscoParams>``: ``tledMaterialNHV`` keeps per term
  a state ``D_i`` with ``D_i <- t_i/(dt + t_i) D_i + dt a_i/(dt + t_i) S_iso`` (backward Euler of
  ``dD_i/dt = (a_i S_iso - D_i)/t_i``) and returns ``S_iso - sum D_i``: a step gives the reduced relaxation function
  ``1 - sum a_i (1 - exp(-t/t_i)) = g_inf + sum a_i exp(-t/t_i)``, so ``a_i`` are the card's normalised Prony
  weights ``g_i`` and ``t_i`` its times ``tau_i`` (isochoric relaxation only, ``NumVolTerms = 0``, as in the FEM).
  NiftySim integrates the convolution with its explicit time step (first order); the project's TLED uses the exact
  exponential recursion, so the two agree to O(dt / tau).

A card gets a NiftySim element only for the neo-Hookean law (with or without a Prony series; a linear shear fit's
card already names its finite-strain extension ``neo_hookean``). Every other card states why not
(``niftysim_reason``): the polynomial (``PY``) and Arruda-Boyce (``AB``) materials were not checked against the
project's laws (so the bundled brain's reduced-polynomial cards get none), no viscous wrapper exists for them (only
``NHV``/``TIV``), and beyond-QLV (strain-dependent) relaxation has no NiftySim form.

The element is written as a fragment ``<stem>.niftysim.xml`` (``<Material>`` inside an ``<ElementSet>``, whose
``Size`` and element list belong to the mesh the user builds); :func:`read_niftysim_material` reads it back into the
card fields the project's TLED solver takes (:func:`tissuemech.fem.experiments.card_material`), which is the round
trip that ``tests/fem/test_card_file_round_trip.py`` runs through the solver.
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Mapping

#: where the NiftySim forms were read (a public mirror of the NiftySim source)
NIFTYSIM_SOURCE = "github.com/eloygarcia/niftysim (tledModel.cpp, tledMaterialNH.cpp, tledMaterialNHV.cpp)"
#: project laws with a NiftySim material type
NIFTYSIM_LAWS = {"neo_hookean": "NH"}


def niftysim_reason(card: Mapping) -> str | None:
    """None when the card has a NiftySim element, else why not (module docstring)."""
    if card.get("pipkin_rogers") or card.get("family") == "beyond_qlv":
        return ("beyond-QLV (strain-dependent) relaxation has no NiftySim material (only NHV/TIV Prony terms, whose "
                "weights are constant)")
    law = card.get("elastic_law")
    if not law:
        return "no solid elastic law (e.g. a fluid-like Prony series without a long-term modulus)"
    if law not in NIFTYSIM_LAWS:
        return (f"NiftySim's material types (LE, NH, NHV, TI, TIV, AB, PY) hold no form of {law} that was checked "
                "against the project's law; viscous terms exist only for NH and TI")
    bulk = card.get("bulk_modulus")
    if bulk is None or not math.isfinite(float(bulk)):
        return "the card states no finite bulk modulus (NiftySim's K)"
    return None


def niftysim_material_element(card: Mapping) -> ET.Element | None:
    """The ``<Material>`` element of a card (``NH``, or ``NHV`` with the card's Prony series), or None
    (:func:`niftysim_reason` says why)."""
    if niftysim_reason(card) is not None:
        return None
    prony = card.get("prony") or {}
    g, tau = list(prony.get("g", ())), list(prony.get("tau", ()))
    mat = ET.Element("Material", Type="NHV" if g else NIFTYSIM_LAWS[card["elastic_law"]])
    el = ET.SubElement(mat, "ElasticParams", NumParams="2")
    el.text = f"{float(card['elastic_parameters']['mu']):.10g} {float(card['bulk_modulus']):.10g}"
    if g:
        vp = ET.SubElement(mat, "ViscoParams", NumIsoTerms=str(len(g)), NumVolTerms="0")
        vp.text = " ".join(f"{float(a):.10g} {float(t):.10g}" for a, t in zip(g, tau))
    return mat


def niftysim_file_text(card: Mapping, material_name: str | None = None) -> str | None:
    """The card's NiftySim fragment: an ``<ElementSet>`` with the ``<Material>`` (Size and element list left to
    the mesh), with the valid range and the source in comments; None where there is no element."""
    mat = niftysim_material_element(card)
    if mat is None:
        return None
    es = ET.Element("ElementSet", Size="0")
    es.append(mat)
    ET.indent(es, space="  ")
    vr = card.get("valid_range") or {}
    lines = [f"tissuemech material card {material_name or card.get('model', '')}: NiftySim element set fragment",
             "set Size and the element list for your mesh; SI units (Pa, s)",
             f"valid range: {vr}" if vr else "valid range: see the JSON card",
             f"forms read from {NIFTYSIM_SOURCE}"]
    header = "".join(f"<!-- {line.replace('--', '-')} -->\n" for line in lines)
    return header + ET.tostring(es, encoding="unicode") + "\n"


def read_niftysim_material(text: str) -> dict:
    """Card fields (``model`` -- the fragment names none: the law's key --, ``elastic_law``, ``elastic_parameters``,
    ``bulk_modulus``, ``prony``) of a NiftySim ``NH`` or ``NHV`` material, from a fragment or a whole model XML (the
    first ``<Material>``); other types raise ``ValueError``."""
    root = ET.fromstring(text)
    mat = root if root.tag == "Material" else root.find(".//Material")
    if mat is None:
        raise ValueError("no <Material> element")
    kind = mat.get("Type")
    if kind not in ("NH", "NHV"):
        raise ValueError(f"NiftySim material type {kind!r} is not read (NH and NHV only)")
    values = [float(v) for v in mat.findtext("ElasticParams", "").split()]
    if len(values) != 2:
        raise ValueError("NH/NHV ElasticParams must be 'mu K'")
    card = {"model": "neo_hookean", "elastic_law": "neo_hookean", "elastic_parameters": {"mu": values[0]},
            "bulk_modulus": values[1], "prony": None}
    vp = mat.find("ViscoParams")
    if kind == "NHV" and vp is not None:
        n_iso, n_vol = int(vp.get("NumIsoTerms", "0")), int(vp.get("NumVolTerms", "0"))
        if n_vol:
            raise ValueError("volumetric viscous terms are not read (the FEM relaxes the isochoric stress only)")
        terms = [float(v) for v in (vp.text or "").split()]
        if len(terms) != 2 * n_iso:
            raise ValueError(f"ViscoParams: {len(terms)} numbers for {n_iso} terms")
        g, tau = terms[0::2], terms[1::2]
        card["prony"] = {"g": g, "tau": tau, "g_inf": 1.0 - sum(g)}
    return card


__all__ = ["NIFTYSIM_SOURCE", "NIFTYSIM_LAWS", "niftysim_reason", "niftysim_material_element", "niftysim_file_text",
           "read_niftysim_material"]
