"""Internal forces of linear tets in a structure-of-arrays layout that LLVM vectorises across elements.

This is the CPU fast path of :mod:`.tled` for the laws whose invariant derivatives are constants
(Saint Venant-Kirchhoff, neo-Hookean, Mooney-Rivlin; alone or as the instantaneous law of QLV). It computes
exactly what the generic per-element kernel computes (same formulas: ``F``, average nodal pressure,
isochoric Kirchhoff stress, the recursive Prony update of the isochoric 2nd Piola-Kirchhoff stress,
``f_a = V0 tau (cof dN_a) / J``), in four or more passes per force evaluation:

1. :func:`kinematics_pass` (elements): ``F`` from gathered displacements, stored as ``F - I`` in 9 arrays; the element
   pressure contribution ``kappa (J - 1) V0``; a count of inverted elements and of elements outside the
   range of the branch-free ``J^(-2/3)``;
2. :func:`nodal_pressure_pass` (nodes): volume-weighted average of the element pressures (ANP);
3. :func:`invariant_force_pass` / :func:`svk_force_pass` (elements): stress and the 12 element nodal forces,
   or for QLV :func:`qlv_elastic_pass`, one :func:`prony_term_pass` per term and :func:`qlv_force_pass`;
4. :func:`gather_nodal_forces` (nodes): every node sums its incident element forces through a CSR incidence
   list (no scatter, no atomics, no per-thread force buffers).

Why this shape (measured in ``docs/fem_timing.md``; the loop that is not vectorised runs at a third of the
speed):

* unsigned indices (``uint32`` connectivity, ``uint64`` loop bounds): numba wraps negative signed indices
  (compare and select per access), which turns each gather into scalar code and blocks vectorisation;
* one output array per stored component: LLVM cannot prove that two rows of one 2-D array do not overlap
  (their distance is the run-time row length) and refuses to vectorise a loop that stores to several rows;
  rows passed as separate arguments of a parallel function are marked ``noalias`` by numba's parfor lowering;
* no calls and no branches in the element loops: the law enters as the constants ``dW/dI1``, ``dW/dI2``
  (evaluated once from the fitting code's law functions), ``J^(-2/3)`` by four Newton steps (exact to
  rounding for ``0.3 < J < 3.5``; elements outside are computed again with ``cbrt``), stores under a flag
  written as selects, and the Prony terms run as separate passes instead of an inner loop.

The arithmetic is double precision; the stored arrays follow the model's precision (float32 halves the
traffic).
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from .materials import FASTMATH, j_minus_two_thirds

#: ``J`` range of the branch-free ``J^(-2/3)`` (:func:`jm23_newton` is within 1e-15 of ``J**(-2/3)`` on
#: (0.25, 3.9)); elements outside it are computed again with ``cbrt``
JM23_NEWTON_MIN = 0.3
JM23_NEWTON_MAX = 3.5

_PASS = dict(parallel=True, cache=True, fastmath=FASTMATH, error_model="numpy")


@njit(cache=True, fastmath=FASTMATH, inline="always")
def jm23_newton(J):
    """``J^(-2/3)`` without branches or calls (vectorisable): four Newton steps on ``y^-3 = J`` from the
    [1/1] Pade approximant ``y0 = (2 + J)/(1 + 2 J)`` of ``J^(-1/3)`` at 1; the relative error squares each
    step: within 1e-15 of ``J**(-2/3)`` for ``0.25 < J < 3.9``."""
    y = (2.0 + J) / (1.0 + 2.0 * J)
    y = y * (4.0 - J * y * y * y) * (1.0 / 3.0)
    y = y * (4.0 - J * y * y * y) * (1.0 / 3.0)
    y = y * (4.0 - J * y * y * y) * (1.0 / 3.0)
    y = y * (4.0 - J * y * y * y) * (1.0 / 3.0)
    return y * y


@njit(cache=True, fastmath=FASTMATH, inline="always")
def _cofactor(f11, f12, f13, f21, f22, f23, f31, f32, f33):
    """Cofactor matrix ``J F^-T`` (row-major) and ``J``."""
    c11 = f22 * f33 - f23 * f32
    c12 = f23 * f31 - f21 * f33
    c13 = f21 * f32 - f22 * f31
    c21 = f13 * f32 - f12 * f33
    c22 = f11 * f33 - f13 * f31
    c23 = f12 * f31 - f11 * f32
    c31 = f12 * f23 - f13 * f22
    c32 = f13 * f21 - f11 * f23
    c33 = f11 * f22 - f12 * f21
    J = f11 * c11 + f12 * c12 + f13 * c13
    return c11, c12, c13, c21, c22, c23, c31, c32, c33, J


@njit(cache=True, fastmath=FASTMATH, inline="always")
def _left_cauchy_green(f11, f12, f13, f21, f22, f23, f31, f32, f33):
    """``b = F F^T`` (11 22 33 12 23 13)."""
    return (f11 * f11 + f12 * f12 + f13 * f13, f21 * f21 + f22 * f22 + f23 * f23,
            f31 * f31 + f32 * f32 + f33 * f33, f11 * f21 + f12 * f22 + f13 * f23,
            f21 * f31 + f22 * f32 + f23 * f33, f11 * f31 + f12 * f32 + f13 * f33)


@njit(cache=True, fastmath=FASTMATH, inline="always")
def _isochoric_kirchhoff_constant(w1, w2, jm23, b11, b22, b33, b12, b23, b13):
    """``tau_iso = dev(2 (W1 + I1bar W2) bbar - 2 W2 bbar^2)`` for constant ``W1 = dW/dI1``, ``W2 = dW/dI2``
    (the formula of ``materials._iso_from_bbar``)."""
    b11 *= jm23
    b22 *= jm23
    b33 *= jm23
    b12 *= jm23
    b23 *= jm23
    b13 *= jm23
    i1 = b11 + b22 + b33
    q11 = b11 * b11 + b12 * b12 + b13 * b13
    q22 = b12 * b12 + b22 * b22 + b23 * b23
    q33 = b13 * b13 + b23 * b23 + b33 * b33
    q12 = b11 * b12 + b12 * b22 + b13 * b23
    q23 = b12 * b13 + b22 * b23 + b23 * b33
    q13 = b11 * b13 + b12 * b23 + b13 * b33
    a = 2.0 * (w1 + i1 * w2)
    c = -2.0 * w2
    t11 = a * b11 + c * q11
    t22 = a * b22 + c * q22
    t33 = a * b33 + c * q33
    m = (t11 + t22 + t33) * (1.0 / 3.0)
    return t11 - m, t22 - m, t33 - m, a * b12 + c * q12, a * b23 + c * q23, a * b13 + c * q13


@njit(cache=True, fastmath=FASTMATH, inline="always")
def _svk_kirchhoff(mu, lam, b11, b22, b33, b12, b23, b13):
    """Saint Venant-Kirchhoff ``tau = F S F^T = lam tr(E) b + mu (b^2 - b)`` (the formula of
    ``materials.kirchhoff_deviatoric``)."""
    tre = 0.5 * (b11 + b22 + b33 - 3.0)
    q11 = b11 * b11 + b12 * b12 + b13 * b13
    q22 = b12 * b12 + b22 * b22 + b23 * b23
    q33 = b13 * b13 + b23 * b23 + b33 * b33
    q12 = b11 * b12 + b12 * b22 + b13 * b23
    q23 = b12 * b13 + b22 * b23 + b23 * b33
    q13 = b11 * b13 + b12 * b23 + b13 * b33
    a = lam * tre - mu
    return (a * b11 + mu * q11, a * b22 + mu * q22, a * b33 + mu * q33,
            a * b12 + mu * q12, a * b23 + mu * q23, a * b13 + mu * q13)


@njit(cache=True, fastmath=FASTMATH, inline="always")
def _nodal_forces(t11, t22, t33, t12, t23, t13, c11, c12, c13, c21, c22, c23, c31, c32, c33, sc,
                  d1x, d1y, d1z, d2x, d2y, d2z, d3x, d3y, d3z):
    """``f_a = tau g_a`` with ``g_a = sc cof dN_a`` (``sc = V0/J``) for nodes 1-3; node 0 is minus their sum."""
    g1x = (c11 * d1x + c12 * d1y + c13 * d1z) * sc
    g1y = (c21 * d1x + c22 * d1y + c23 * d1z) * sc
    g1z = (c31 * d1x + c32 * d1y + c33 * d1z) * sc
    g2x = (c11 * d2x + c12 * d2y + c13 * d2z) * sc
    g2y = (c21 * d2x + c22 * d2y + c23 * d2z) * sc
    g2z = (c31 * d2x + c32 * d2y + c33 * d2z) * sc
    g3x = (c11 * d3x + c12 * d3y + c13 * d3z) * sc
    g3y = (c21 * d3x + c22 * d3y + c23 * d3z) * sc
    g3z = (c31 * d3x + c32 * d3y + c33 * d3z) * sc
    r1x = t11 * g1x + t12 * g1y + t13 * g1z
    r1y = t12 * g1x + t22 * g1y + t23 * g1z
    r1z = t13 * g1x + t23 * g1y + t33 * g1z
    r2x = t11 * g2x + t12 * g2y + t13 * g2z
    r2y = t12 * g2x + t22 * g2y + t23 * g2z
    r2z = t13 * g2x + t23 * g2y + t33 * g2z
    r3x = t11 * g3x + t12 * g3y + t13 * g3z
    r3y = t12 * g3x + t22 * g3y + t23 * g3z
    r3z = t13 * g3x + t23 * g3y + t33 * g3z
    return r1x, r1y, r1z, r2x, r2y, r2z, r3x, r3y, r3z


# --------------------------------------------------------------------------------------------------
# passes
# --------------------------------------------------------------------------------------------------
@njit(**_PASS)
def kinematics_pass(u, conn, d9, vol0, kappa, pe, f11a, f12a, f13a, f21a, f22a, f23a, f31a, f32a, f33a,
                    n_bad, n_far, lo):
    """Displacement gradients ``F - I`` (stored), element pressure contributions ``pe = kappa (J-1) V0`` and, per chunk,
    the number of elements with ``J <= 0`` (or NaN) and outside ``(JM23_NEWTON_MIN, JM23_NEWTON_MAX)``.

    ``u`` (n_nodes, 3) displacements (m); ``conn`` (4, n_elements) uint32; ``d9`` (9, n_elements) ``dN_a/dX``
    of local nodes 1-3 (``dN_0 = -sum``, 1/m); ``lo`` uint64 chunk bounds.
    """
    for c in prange(lo.size - 1):
        bad = 0
        far = 0
        for e in range(lo[c], lo[c + 1]):
            n0, n1, n2, n3 = conn[0, e], conn[1, e], conn[2, e], conn[3, e]
            x0, y0, z0 = u[n0, 0], u[n0, 1], u[n0, 2]
            ax, ay, az = u[n1, 0] - x0, u[n1, 1] - y0, u[n1, 2] - z0
            bx, by, bz = u[n2, 0] - x0, u[n2, 1] - y0, u[n2, 2] - z0
            cx, cy, cz = u[n3, 0] - x0, u[n3, 1] - y0, u[n3, 2] - z0
            d1x, d1y, d1z = d9[0, e], d9[1, e], d9[2, e]
            d2x, d2y, d2z = d9[3, e], d9[4, e], d9[5, e]
            d3x, d3y, d3z = d9[6, e], d9[7, e], d9[8, e]
            f11 = 1.0 + ax * d1x + bx * d2x + cx * d3x
            f12 = ax * d1y + bx * d2y + cx * d3y
            f13 = ax * d1z + bx * d2z + cx * d3z
            f21 = ay * d1x + by * d2x + cy * d3x
            f22 = 1.0 + ay * d1y + by * d2y + cy * d3y
            f23 = ay * d1z + by * d2z + cy * d3z
            f31 = az * d1x + bz * d2x + cz * d3x
            f32 = az * d1y + bz * d2y + cz * d3y
            f33 = 1.0 + az * d1z + bz * d2z + cz * d3z
            J = f11 * (f22 * f33 - f23 * f32) - f12 * (f21 * f33 - f23 * f31) + f13 * (f21 * f32 - f22 * f31)
            pe[e] = kappa * (J - 1.0) * vol0[e]
            # the displacement gradient F - I is stored: in float32 storage F itself would lose the strain
            f11a[e] = f11 - 1.0
            f12a[e] = f12
            f13a[e] = f13
            f21a[e] = f21
            f22a[e] = f22 - 1.0
            f23a[e] = f23
            f31a[e] = f31
            f32a[e] = f32
            f33a[e] = f33 - 1.0
            bad += 0 if J > 0.0 else 1
            far += 0 if (J > JM23_NEWTON_MIN) & (J < JM23_NEWTON_MAX) else 1
        n_bad[c] = bad
        n_far[c] = far


@njit(**_PASS)
def nodal_pressure_pass(pe, node_ptr, inc_elem, inv_vnode, p_node, lo):
    """Average nodal pressure ``p_n = sum_e kappa (J_e - 1) V0_e / sum_e V0_e`` over the incident elements."""
    for c in prange(lo.size - 1):
        for n in range(lo[c], lo[c + 1]):
            s = 0.0
            for k in range(node_ptr[n], node_ptr[n + 1]):
                s += pe[inc_elem[k]]
            p_node[n] = s * inv_vnode[n]


@njit(cache=True, fastmath=FASTMATH, inline="always")
def _element_pressure(anp_weight, kappa, J, p_node, n0, n1, n2, n3):
    """Branch-free choice between the average nodal pressure (weight 1) and the element's own (weight 0)."""
    return (anp_weight * 0.25 * (p_node[n0] + p_node[n1] + p_node[n2] + p_node[n3])
            + (1.0 - anp_weight) * kappa * (J - 1.0))


@njit(cache=True, fastmath=FASTMATH, inline="always")
def _store_nodal_forces(e, r1x, r1y, r1z, r2x, r2y, r2z, r3x, r3y, r3z,
                        fe0, fe1, fe2, fe3, fe4, fe5, fe6, fe7, fe8, fe9, fe10, fe11):
    fe0[e] = -(r1x + r2x + r3x)
    fe1[e] = -(r1y + r2y + r3y)
    fe2[e] = -(r1z + r2z + r3z)
    fe3[e] = r1x
    fe4[e] = r1y
    fe5[e] = r1z
    fe6[e] = r2x
    fe7[e] = r2y
    fe8[e] = r2z
    fe9[e] = r3x
    fe10[e] = r3y
    fe11[e] = r3z


@njit(**_PASS)
def invariant_force_pass(f11a, f12a, f13a, f21a, f22a, f23a, f31a, f32a, f33a, conn, d9, vol0, p_node, w1, w2,
                         kappa, anp_weight, newton, fe0, fe1, fe2, fe3, fe4, fe5, fe6, fe7, fe8, fe9, fe10, fe11, lo):
    """Element nodal forces ``fe[3 a + i]`` (N) of a law with constant ``W1 = dW/dI1``, ``W2 = dW/dI2`` plus the
    volumetric pressure ``anp_weight p_ANP + (1 - anp_weight) kappa (J - 1)`` (weight 1: average nodal
    pressure; 0: the element's own).

    The loop uses the branch-free ``J^(-2/3)``; unless ``newton`` (every element within its range) the
    elements outside are computed again with ``cbrt``.
    """
    for c in prange(lo.size - 1):
        for e in range(lo[c], lo[c + 1]):
            f11, f12, f13 = 1.0 + f11a[e], f12a[e], f13a[e]
            f21, f22, f23 = f21a[e], 1.0 + f22a[e], f23a[e]
            f31, f32, f33 = f31a[e], f32a[e], 1.0 + f33a[e]
            c11, c12, c13, c21, c22, c23, c31, c32, c33, J = _cofactor(f11, f12, f13, f21, f22, f23, f31, f32, f33)
            b11, b22, b33, b12, b23, b13 = _left_cauchy_green(f11, f12, f13, f21, f22, f23, f31, f32, f33)
            t11, t22, t33, t12, t23, t13 = _isochoric_kirchhoff_constant(w1, w2, jm23_newton(J), b11, b22, b33, b12,
                                                                         b23, b13)
            jp = J * _element_pressure(anp_weight, kappa, J, p_node, conn[0, e], conn[1, e], conn[2, e], conn[3, e])
            r1x, r1y, r1z, r2x, r2y, r2z, r3x, r3y, r3z = _nodal_forces(
                t11 + jp, t22 + jp, t33 + jp, t12, t23, t13, c11, c12, c13, c21, c22, c23, c31, c32, c33,
                vol0[e] / J, d9[0, e], d9[1, e], d9[2, e], d9[3, e], d9[4, e], d9[5, e], d9[6, e], d9[7, e], d9[8, e])
            _store_nodal_forces(e, r1x, r1y, r1z, r2x, r2y, r2z, r3x, r3y, r3z,
                                fe0, fe1, fe2, fe3, fe4, fe5, fe6, fe7, fe8, fe9, fe10, fe11)
        if newton:
            continue
        for e in range(lo[c], lo[c + 1]):
            f11, f12, f13 = 1.0 + f11a[e], f12a[e], f13a[e]
            f21, f22, f23 = f21a[e], 1.0 + f22a[e], f23a[e]
            f31, f32, f33 = f31a[e], f32a[e], 1.0 + f33a[e]
            c11, c12, c13, c21, c22, c23, c31, c32, c33, J = _cofactor(f11, f12, f13, f21, f22, f23, f31, f32, f33)
            if J > JM23_NEWTON_MIN and J < JM23_NEWTON_MAX:
                continue
            b11, b22, b33, b12, b23, b13 = _left_cauchy_green(f11, f12, f13, f21, f22, f23, f31, f32, f33)
            t11, t22, t33, t12, t23, t13 = _isochoric_kirchhoff_constant(w1, w2, j_minus_two_thirds(J), b11, b22,
                                                                         b33, b12, b23, b13)
            jp = J * _element_pressure(anp_weight, kappa, J, p_node, conn[0, e], conn[1, e], conn[2, e], conn[3, e])
            r1x, r1y, r1z, r2x, r2y, r2z, r3x, r3y, r3z = _nodal_forces(
                t11 + jp, t22 + jp, t33 + jp, t12, t23, t13, c11, c12, c13, c21, c22, c23, c31, c32, c33,
                vol0[e] / J, d9[0, e], d9[1, e], d9[2, e], d9[3, e], d9[4, e], d9[5, e], d9[6, e], d9[7, e], d9[8, e])
            _store_nodal_forces(e, r1x, r1y, r1z, r2x, r2y, r2z, r3x, r3y, r3z,
                                fe0, fe1, fe2, fe3, fe4, fe5, fe6, fe7, fe8, fe9, fe10, fe11)


@njit(**_PASS)
def svk_force_pass(f11a, f12a, f13a, f21a, f22a, f23a, f31a, f32a, f33a, d9, vol0, mu, lam,
                   fe0, fe1, fe2, fe3, fe4, fe5, fe6, fe7, fe8, fe9, fe10, fe11, lo):
    """Element nodal forces (N) of Saint Venant-Kirchhoff (``lam = kappa - 2 mu / 3``; no pressure split)."""
    for c in prange(lo.size - 1):
        for e in range(lo[c], lo[c + 1]):
            f11, f12, f13 = 1.0 + f11a[e], f12a[e], f13a[e]
            f21, f22, f23 = f21a[e], 1.0 + f22a[e], f23a[e]
            f31, f32, f33 = f31a[e], f32a[e], 1.0 + f33a[e]
            c11, c12, c13, c21, c22, c23, c31, c32, c33, J = _cofactor(f11, f12, f13, f21, f22, f23, f31, f32, f33)
            b11, b22, b33, b12, b23, b13 = _left_cauchy_green(f11, f12, f13, f21, f22, f23, f31, f32, f33)
            t11, t22, t33, t12, t23, t13 = _svk_kirchhoff(mu, lam, b11, b22, b33, b12, b23, b13)
            r1x, r1y, r1z, r2x, r2y, r2z, r3x, r3y, r3z = _nodal_forces(
                t11, t22, t33, t12, t23, t13, c11, c12, c13, c21, c22, c23, c31, c32, c33,
                vol0[e] / J, d9[0, e], d9[1, e], d9[2, e], d9[3, e], d9[4, e], d9[5, e], d9[6, e], d9[7, e], d9[8, e])
            _store_nodal_forces(e, r1x, r1y, r1z, r2x, r2y, r2z, r3x, r3y, r3z,
                                fe0, fe1, fe2, fe3, fe4, fe5, fe6, fe7, fe8, fe9, fe10, fe11)


@njit(cache=True, fastmath=FASTMATH, inline="always")
def _isochoric_pk2(w1, w2, jm23, f11, f12, f13, f21, f22, f23, f31, f32, f33, c11, c12, c13, c21, c22, c23, c31,
                   c32, c33, J):
    """Isochoric 2nd Piola-Kirchhoff ``S = F^-1 tau_iso F^-T`` (11 22 33 12 23 13) of a constant-derivative law."""
    b11, b22, b33, b12, b23, b13 = _left_cauchy_green(f11, f12, f13, f21, f22, f23, f31, f32, f33)
    t11, t22, t33, t12, t23, t13 = _isochoric_kirchhoff_constant(w1, w2, jm23, b11, b22, b33, b12, b23, b13)
    ij = 1.0 / J
    a11, a12, a13 = c11 * ij, c21 * ij, c31 * ij
    a21, a22, a23 = c12 * ij, c22 * ij, c32 * ij
    a31, a32, a33 = c13 * ij, c23 * ij, c33 * ij
    m11 = a11 * t11 + a12 * t12 + a13 * t13
    m12 = a11 * t12 + a12 * t22 + a13 * t23
    m13 = a11 * t13 + a12 * t23 + a13 * t33
    m21 = a21 * t11 + a22 * t12 + a23 * t13
    m22 = a21 * t12 + a22 * t22 + a23 * t23
    m23 = a21 * t13 + a22 * t23 + a23 * t33
    m31 = a31 * t11 + a32 * t12 + a33 * t13
    m32 = a31 * t12 + a32 * t22 + a33 * t23
    m33 = a31 * t13 + a32 * t23 + a33 * t33
    return (m11 * a11 + m12 * a12 + m13 * a13, m21 * a21 + m22 * a22 + m23 * a23, m31 * a31 + m32 * a32 + m33 * a33,
            m11 * a21 + m12 * a22 + m13 * a23, m21 * a31 + m22 * a32 + m23 * a33, m11 * a31 + m12 * a32 + m13 * a33)


@njit(**_PASS)
def qlv_elastic_pass(f11a, f12a, f13a, f21a, f22a, f23a, f31a, f32a, f33a, w1, w2, g_inf, newton, commit,
                     sp0, sp1, sp2, sp3, sp4, sp5, dd0, dd1, dd2, dd3, dd4, dd5, sa0, sa1, sa2, sa3, sa4, sa5, lo):
    """QLV, first stage: instantaneous isochoric 2nd Piola-Kirchhoff stress ``S_e = F^-1 tau_iso F^-T``;
    writes its increment ``dd = S_e - S_e(previous step)`` and ``sa = g_inf S_e`` (components 11 22 33 12
    23 13); ``sp`` (the previous ``S_e``) is overwritten when ``commit``. Elements outside the range of the
    branch-free ``J^(-2/3)`` (only when not ``newton``) are computed again with ``cbrt``."""
    for c in prange(lo.size - 1):
        for e in range(lo[c], lo[c + 1]):
            f11, f12, f13 = 1.0 + f11a[e], f12a[e], f13a[e]
            f21, f22, f23 = f21a[e], 1.0 + f22a[e], f23a[e]
            f31, f32, f33 = f31a[e], f32a[e], 1.0 + f33a[e]
            c11, c12, c13, c21, c22, c23, c31, c32, c33, J = _cofactor(f11, f12, f13, f21, f22, f23, f31, f32, f33)
            se0, se1, se2, se3, se4, se5 = _isochoric_pk2(w1, w2, jm23_newton(J), f11, f12, f13, f21, f22, f23,
                                                          f31, f32, f33, c11, c12, c13, c21, c22, c23, c31, c32,
                                                          c33, J)
            dd0[e] = se0 - sp0[e]
            dd1[e] = se1 - sp1[e]
            dd2[e] = se2 - sp2[e]
            dd3[e] = se3 - sp3[e]
            dd4[e] = se4 - sp4[e]
            dd5[e] = se5 - sp5[e]
            sa0[e] = g_inf * se0
            sa1[e] = g_inf * se1
            sa2[e] = g_inf * se2
            sa3[e] = g_inf * se3
            sa4[e] = g_inf * se4
            sa5[e] = g_inf * se5
            # the previous S_e of an element left for the cbrt loop below must survive this loop
            # (bitwise operators: short-circuit ones would put branches into the loop)
            keep = (not commit) | (not (newton | ((J > JM23_NEWTON_MIN) & (J < JM23_NEWTON_MAX))))
            sp0[e] = sp0[e] if keep else se0
            sp1[e] = sp1[e] if keep else se1
            sp2[e] = sp2[e] if keep else se2
            sp3[e] = sp3[e] if keep else se3
            sp4[e] = sp4[e] if keep else se4
            sp5[e] = sp5[e] if keep else se5
        if newton:
            continue
        for e in range(lo[c], lo[c + 1]):
            f11, f12, f13 = 1.0 + f11a[e], f12a[e], f13a[e]
            f21, f22, f23 = f21a[e], 1.0 + f22a[e], f23a[e]
            f31, f32, f33 = f31a[e], f32a[e], 1.0 + f33a[e]
            c11, c12, c13, c21, c22, c23, c31, c32, c33, J = _cofactor(f11, f12, f13, f21, f22, f23, f31, f32, f33)
            if J > JM23_NEWTON_MIN and J < JM23_NEWTON_MAX:
                continue
            se0, se1, se2, se3, se4, se5 = _isochoric_pk2(w1, w2, j_minus_two_thirds(J), f11, f12, f13, f21, f22,
                                                          f23, f31, f32, f33, c11, c12, c13, c21, c22, c23, c31,
                                                          c32, c33, J)
            dd0[e] = se0 - sp0[e]
            dd1[e] = se1 - sp1[e]
            dd2[e] = se2 - sp2[e]
            dd3[e] = se3 - sp3[e]
            dd4[e] = se4 - sp4[e]
            dd5[e] = se5 - sp5[e]
            sa0[e] = g_inf * se0
            sa1[e] = g_inf * se1
            sa2[e] = g_inf * se2
            sa3[e] = g_inf * se3
            sa4[e] = g_inf * se4
            sa5[e] = g_inf * se5
            if commit:
                sp0[e] = se0
                sp1[e] = se1
                sp2[e] = se2
                sp3[e] = se3
                sp4[e] = se4
                sp5[e] = se5


@njit(**_PASS)
def prony_term_pass(decay, gain, commit, h0, h1, h2, h3, h4, h5, dd0, dd1, dd2, dd3, dd4, dd5,
                    sa0, sa1, sa2, sa3, sa4, sa5, lo):
    """One Prony term of the recursive QLV update (``models.recursion``): ``h+ = decay h + gain dd`` with
    ``decay = exp(-dt/tau)``, ``gain = g (1 - decay)/(dt/tau)``; adds ``h+`` to ``sa``; stores ``h+`` when
    ``commit``."""
    for c in prange(lo.size - 1):
        for e in range(lo[c], lo[c + 1]):
            x0 = decay * h0[e] + gain * dd0[e]
            x1 = decay * h1[e] + gain * dd1[e]
            x2 = decay * h2[e] + gain * dd2[e]
            x3 = decay * h3[e] + gain * dd3[e]
            x4 = decay * h4[e] + gain * dd4[e]
            x5 = decay * h5[e] + gain * dd5[e]
            sa0[e] += x0
            sa1[e] += x1
            sa2[e] += x2
            sa3[e] += x3
            sa4[e] += x4
            sa5[e] += x5
            h0[e] = x0 if commit else h0[e]
            h1[e] = x1 if commit else h1[e]
            h2[e] = x2 if commit else h2[e]
            h3[e] = x3 if commit else h3[e]
            h4[e] = x4 if commit else h4[e]
            h5[e] = x5 if commit else h5[e]


@njit(**_PASS)
def qlv_force_pass(f11a, f12a, f13a, f21a, f22a, f23a, f31a, f32a, f33a, conn, d9, vol0, p_node, kappa, anp_weight,
                   sa0, sa1, sa2, sa3, sa4, sa5, fe0, fe1, fe2, fe3, fe4, fe5, fe6, fe7, fe8, fe9, fe10, fe11, lo):
    """QLV, last stage: ``tau = F S F^T + J p I`` from the relaxed isochoric ``S`` (``sa``) and the nodal forces."""
    for c in prange(lo.size - 1):
        for e in range(lo[c], lo[c + 1]):
            f11, f12, f13 = 1.0 + f11a[e], f12a[e], f13a[e]
            f21, f22, f23 = f21a[e], 1.0 + f22a[e], f23a[e]
            f31, f32, f33 = f31a[e], f32a[e], 1.0 + f33a[e]
            c11, c12, c13, c21, c22, c23, c31, c32, c33, J = _cofactor(f11, f12, f13, f21, f22, f23, f31, f32, f33)
            s0, s1, s2, s3, s4, s5 = sa0[e], sa1[e], sa2[e], sa3[e], sa4[e], sa5[e]
            q11 = f11 * s0 + f12 * s3 + f13 * s5
            q12 = f11 * s3 + f12 * s1 + f13 * s4
            q13 = f11 * s5 + f12 * s4 + f13 * s2
            q21 = f21 * s0 + f22 * s3 + f23 * s5
            q22 = f21 * s3 + f22 * s1 + f23 * s4
            q23 = f21 * s5 + f22 * s4 + f23 * s2
            q31 = f31 * s0 + f32 * s3 + f33 * s5
            q32 = f31 * s3 + f32 * s1 + f33 * s4
            q33 = f31 * s5 + f32 * s4 + f33 * s2
            jp = J * _element_pressure(anp_weight, kappa, J, p_node, conn[0, e], conn[1, e], conn[2, e], conn[3, e])
            t11 = q11 * f11 + q12 * f12 + q13 * f13 + jp
            t22 = q21 * f21 + q22 * f22 + q23 * f23 + jp
            t33 = q31 * f31 + q32 * f32 + q33 * f33 + jp
            t12 = q11 * f21 + q12 * f22 + q13 * f23
            t23 = q21 * f31 + q22 * f32 + q23 * f33
            t13 = q11 * f31 + q12 * f32 + q13 * f33
            r1x, r1y, r1z, r2x, r2y, r2z, r3x, r3y, r3z = _nodal_forces(
                t11, t22, t33, t12, t23, t13, c11, c12, c13, c21, c22, c23, c31, c32, c33,
                vol0[e] / J, d9[0, e], d9[1, e], d9[2, e], d9[3, e], d9[4, e], d9[5, e], d9[6, e], d9[7, e], d9[8, e])
            _store_nodal_forces(e, r1x, r1y, r1z, r2x, r2y, r2z, r3x, r3y, r3z,
                                fe0, fe1, fe2, fe3, fe4, fe5, fe6, fe7, fe8, fe9, fe10, fe11)


@njit(**_PASS)
def gather_nodal_forces(fe_flat, node_ptr, inc_slot, n_elements, fint, lo):
    """``fint[n] = sum`` of the element forces of node ``n``; ``inc_slot = 3 a n_elements + e`` indexes the
    flattened ``(12, n_elements)`` element force array for local node ``a`` of element ``e``."""
    ne = np.uint64(n_elements)
    for c in prange(lo.size - 1):
        for n in range(lo[c], lo[c + 1]):
            fx = 0.0
            fy = 0.0
            fz = 0.0
            for k in range(node_ptr[n], node_ptr[n + 1]):
                s = np.uint64(inc_slot[k])
                fx += fe_flat[s]
                fy += fe_flat[s + ne]
                fz += fe_flat[s + ne + ne]
            fint[n, 0] = fx
            fint[n, 1] = fy
            fint[n, 2] = fz


# --------------------------------------------------------------------------------------------------
# one force evaluation
# --------------------------------------------------------------------------------------------------
@njit(cache=True)
def first_inverted_element(grad_u, lo):
    """Smallest element id with ``J <= 0`` (or NaN), from the stored displacement gradients ``F - I``; -1 if none."""
    for e in range(lo[-1]):
        f11, f12, f13 = 1.0 + grad_u[0, e], grad_u[1, e], grad_u[2, e]
        f21, f22, f23 = grad_u[3, e], 1.0 + grad_u[4, e], grad_u[5, e]
        f31, f32, f33 = grad_u[6, e], grad_u[7, e], 1.0 + grad_u[8, e]
        J = f11 * (f22 * f33 - f23 * f32) - f12 * (f21 * f33 - f23 * f31) + f13 * (f21 * f32 - f22 * f31)
        if not J > 0.0:
            return np.int64(e)
    return np.int64(-1)


@njit(cache=True)
def internal_forces(u, ws, svk, w1, w2, mu, kappa, use_anp, prony_g, prony_e, prony_f, commit, fint):
    """Internal nodal forces ``fint`` (N) of the displacement ``u`` (m) through the passes above.

    ``ws`` is the workspace tuple of :func:`tissuemech.fem.tled.vector_workspace`. QLV (``prony_g.size > 0``)
    advances the states in ``ws`` (committed only when ``commit``). Returns the first inverted element or -1.
    """
    (conn, d9, vol0, node_ptr, inc_elem, inc_slot, inv_vnode, elo, nlo, grad_u, pe, p_node, fe, n_bad, n_far,
     sprev, dd, sacc, hstate) = ws
    kinematics_pass(u, conn, d9, vol0, kappa, pe, grad_u[0], grad_u[1], grad_u[2], grad_u[3], grad_u[4], grad_u[5], grad_u[6], grad_u[7], grad_u[8],
                    n_bad, n_far, elo)
    if n_bad.sum() > 0:
        return first_inverted_element(grad_u, elo)
    newton = n_far.sum() == 0
    anp_weight = 1.0 if use_anp else 0.0
    if svk:
        svk_force_pass(grad_u[0], grad_u[1], grad_u[2], grad_u[3], grad_u[4], grad_u[5], grad_u[6], grad_u[7], grad_u[8], d9, vol0, mu,
                       kappa - 2.0 * mu / 3.0, fe[0], fe[1], fe[2], fe[3], fe[4], fe[5], fe[6], fe[7], fe[8], fe[9],
                       fe[10], fe[11], elo)
    else:
        if use_anp:
            nodal_pressure_pass(pe, node_ptr, inc_elem, inv_vnode, p_node, nlo)
        nterm = prony_g.size
        if nterm == 0:
            invariant_force_pass(grad_u[0], grad_u[1], grad_u[2], grad_u[3], grad_u[4], grad_u[5], grad_u[6], grad_u[7], grad_u[8], conn, d9, vol0, p_node,
                                 w1, w2, kappa, anp_weight, newton, fe[0], fe[1], fe[2], fe[3], fe[4], fe[5], fe[6],
                                 fe[7], fe[8], fe[9], fe[10], fe[11], elo)
        else:
            g_inf = 1.0 - prony_g.sum()
            qlv_elastic_pass(grad_u[0], grad_u[1], grad_u[2], grad_u[3], grad_u[4], grad_u[5], grad_u[6], grad_u[7], grad_u[8], w1, w2, g_inf, newton,
                             commit, sprev[0], sprev[1], sprev[2], sprev[3], sprev[4], sprev[5], dd[0], dd[1], dd[2],
                             dd[3], dd[4], dd[5], sacc[0], sacc[1], sacc[2], sacc[3], sacc[4], sacc[5], elo)
            for i in range(nterm):
                h = hstate[i]
                prony_term_pass(prony_e[i], prony_g[i] * prony_f[i], commit, h[0], h[1], h[2], h[3], h[4], h[5],
                                dd[0], dd[1], dd[2], dd[3], dd[4], dd[5], sacc[0], sacc[1], sacc[2], sacc[3],
                                sacc[4], sacc[5], elo)
            qlv_force_pass(grad_u[0], grad_u[1], grad_u[2], grad_u[3], grad_u[4], grad_u[5], grad_u[6], grad_u[7], grad_u[8], conn, d9, vol0, p_node, kappa,
                           anp_weight, sacc[0], sacc[1], sacc[2], sacc[3], sacc[4], sacc[5], fe[0], fe[1], fe[2], fe[3],
                           fe[4], fe[5], fe[6], fe[7], fe[8], fe[9], fe[10], fe[11], elo)
    gather_nodal_forces(fe.reshape(-1), node_ptr, inc_slot, vol0.size, fint, nlo)
    return np.int64(-1)
