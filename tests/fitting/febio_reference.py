"""FEBio's documented equations, evaluated independently of the card builder (a uniquely named test helper module).

The card builder checks every FEBio block with its own evaluator (``cards_febio.febio_simple_shear_stress``: FEBio's
*stress* forms, closed-form derivatives). The tests must not use that evaluator as their oracle, so this module
starts from FEBio's *strain energies* as the FEBio User Manual (febiosoftware/FEBio, ``Documentation/
FEBio_User_Manual.lyx``, commit 65622b5) writes them and differentiates them numerically along the incompressible
simple-shear path (``sigma_12 = dPsi/dgamma``, ``I1~ = I2~ = 3 + gamma^2``, principal stretches ``l, 1/l, 1`` with
``l = gamma/2 + sqrt(1 + gamma^2/4)``):

* ``Mooney-Rivlin`` (manual "Mooney-Rivlin"): ``Psi = c1 (I1~ - 3) + c2 (I2~ - 3) + K/2 (ln J)^2``;
* ``Ogden`` (manual "Ogden"): ``Psi = sum_i c_i / m_i^2 (l1~^m_i + l2~^m_i + l3~^m_i - 3) + U(J)``;
* ``Gent`` (manual "Gent"): ``Psi~ = -G Jm / 2 ln(1 - (I1~ - 3) / Jm)``;
* ``polynomial`` (not in the manual; ``FEPolynomialHyperElastic``, registered as "polynomial" in
  ``FEBioMechModule.cpp``): ``Psi = sum_{i,j <= 2} c_ij (I1~ - 3)^i (I2~ - 3)^j + D1 (J - 1)^2 + D2 (J - 1)^4``;
* ``uncoupled viscoelastic`` (manual "Uncoupled Viscoelastic Materials"): ``S(t) = int_0^t G(t - s) dS~e/ds ds``
  with ``G(t) = g0 + sum_i g_i exp(-t / t_i)`` (``g0`` defaults to 1, ``g_i`` to 0): an ideal step relaxes as
  ``G(t) sigma_e``.
"""
from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np


def _material(text: str) -> ET.Element:
    root = ET.fromstring(text)
    mat = root if root.tag == "material" else root.find("Material/material")
    assert mat is not None, "no <material> in the FEBio text"
    return mat


def _value(el: ET.Element, tag: str, default: float = 0.0) -> float:
    node = el.find(tag)
    return default if node is None else float(node.text)


def documented_energy(el: ET.Element, gamma: np.ndarray) -> np.ndarray:
    """FEBio's documented isochoric strain energy of an elastic material element along incompressible simple
    shear (J = 1: the volumetric terms vanish)."""
    g = np.asarray(gamma, float)
    kind = el.get("type")
    x = g**2  # I1~ - 3 = I2~ - 3
    if kind == "Mooney-Rivlin":
        return _value(el, "c1") * x + _value(el, "c2") * x
    if kind == "Ogden":
        lam = g / 2 + np.sqrt(1 + g**2 / 4)
        out = np.zeros_like(g)
        for i in range(1, 7):
            if el.find(f"c{i}") is not None:
                c, m = _value(el, f"c{i}"), _value(el, f"m{i}")
                out = out + c / m**2 * (lam**m + lam**-m + 1.0 - 3.0)
        return out
    if kind == "Gent":
        G, jm = _value(el, "G"), _value(el, "Jm")
        return -G * jm / 2 * np.log(1 - x / jm)
    if kind == "polynomial":
        return sum(_value(el, f"c{i}{j}") * x**i * x**j for i in range(3) for j in range(3) if i + j > 0)
    raise AssertionError(f"no documented energy for FEBio material type {kind!r} in this oracle")


def documented_shear_stress(text: str, gamma: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """Instantaneous simple-shear Cauchy stress (Pa) of a FEBio material block or document: ``dPsi/dgamma`` by a
    central difference of the documented energy; an ``uncoupled viscoelastic`` wrapper scales its ``elastic`` base
    by ``G(0) = g0 + sum g_i``."""
    mat = _material(text)
    g = np.asarray(gamma, float)
    base = mat.find("elastic") if mat.get("type") == "uncoupled viscoelastic" else mat
    stress = (documented_energy(base, g + h) - documented_energy(base, g - h)) / (2 * h)
    return documented_relaxation(text, np.array([0.0]))[0] * stress


def documented_relaxation(text: str, time_s: np.ndarray) -> np.ndarray:
    """``G(t) = g0 + sum_i g_i exp(-t / t_i)`` of an ``uncoupled viscoelastic`` material (1 for an elastic one)."""
    mat = _material(text)
    t = np.asarray(time_s, float)
    if mat.get("type") != "uncoupled viscoelastic":
        return np.ones_like(t)
    out = np.full_like(t, _value(mat, "g0", 1.0))
    for i in range(1, 7):
        if mat.find(f"g{i}") is not None:
            out = out + _value(mat, f"g{i}") * np.exp(-t / _value(mat, f"t{i}", 1.0))
    return out
