"""Analytic references shared by the FEM tests (a uniquely named module: ``from conftest import`` would
resolve to whichever conftest.py pytest put on sys.path first)."""
from __future__ import annotations

import numpy as np

from tissuemech.fem.mesh import element_volumes


def polar_moment_m4(nodes: np.ndarray, elements: np.ndarray, height_m: float) -> float:
    """``int r^2 dA`` of the meshed cross-section (exact quadrature of x^2 + y^2 over linear tets)."""
    x = nodes[elements]
    vol = element_volumes(nodes, elements)
    second = sum((vol / 20.0) * ((x[:, :, c] ** 2).sum(1) + x[:, :, c].sum(1) ** 2) for c in (0, 1))
    return float(second.sum() / height_m)


def neo_hookean_energy_j(nodes, elements, u, mu, kappa) -> float:
    """Stored energy ``sum V0 [mu/2 (I1bar - 3) + kappa/2 (J - 1)^2]`` of a displacement field."""
    from tissuemech.fem.tled import shape_derivatives

    dndx, vol = shape_derivatives(nodes, elements)
    g = dndx.reshape(-1, 4, 3)
    F = np.eye(3) + np.einsum("eai,eaj->eij", u[elements], g)
    J = np.linalg.det(F)
    i1 = np.einsum("eij,eij->e", F, F)
    return float(np.sum(vol * (0.5 * mu * (J ** (-2.0 / 3.0) * i1 - 3.0) + 0.5 * kappa * (J - 1.0) ** 2)))
