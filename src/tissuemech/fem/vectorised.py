"""Internal forces of linear tets in a structure-of-arrays layout that LLVM vectorises across elements.

The CPU fast path of :mod:`.tled` for Saint Venant-Kirchhoff and every invariant law ``W(I1bar, I2bar)``,
alone or as the instantaneous law of QLV or of Pipkin-Rogers (strain-dependent weights) with up to eight Prony
terms, in blocks of four (stretch-based laws and more terms stay on the generic kernel). It computes what the generic per-element kernel
computes (the
same formulas: ``F``, average nodal pressure, isochoric Kirchhoff stress, the recursive Prony update of the
isochoric 2nd Piola-Kirchhoff stress, ``f_a = V0 tau (cof dN_a) / J``), in passes:

1. :func:`kinematics_pass` (elements): ``F`` from gathered displacements, stored as ``F - I`` in 9 arrays;
   ``J^(-2/3)``; the element pressure contribution ``kappa (J - 1) V0``; counts of inverted elements and of
   elements outside the range of the branch-free ``J^(-2/3)``;
2. :func:`invariant_law_pass` (elements, only for laws whose derivatives depend on the invariants): the
   fitting code's ``dW/dI1``, ``dW/dI2`` at every element (function pointers: this loop is scalar);
3. :func:`nodal_pressure_pass` (nodes): volume-weighted average of the element pressures (ANP);
4. :func:`invariant_force_pass` (elements): stress and the 12 element nodal forces, or for QLV
   :func:`qlv_stress_pass` (Pipkin-Rogers: :func:`pipkin_rogers_stress_pass`; relaxed stress, advances the element
   states) and :func:`pk2_force_pass`;
5. :func:`gather_nodal_forces` (nodes; or the caller's node pass through :func:`node_force`): every node
   sums its incident element forces through a CSR incidence list (no scatter, no atomics, no per-thread
   force buffers).

Without average nodal pressure and viscoelastic states a law with constant derivatives (neo-Hookean,
Mooney-Rivlin) and Saint Venant-Kirchhoff run one fused :func:`element_force_pass` instead of 1-4.

Why this shape (measured in ``docs/fem_timing.md``; a loop that is not vectorised runs at a third of the
speed):

* unsigned indices (``uint32`` connectivity, ``uint64`` loop bounds): numba wraps negative signed indices
  (compare and select per access), which turns each gather into scalar code and blocks vectorisation;
* one output array per stored component: LLVM cannot prove that two rows of one 2-D array do not overlap
  (their distance is the run-time row length) and refuses to vectorise a loop that stores to several rows;
  rows passed as separate arguments of a parallel function are marked ``noalias`` by numba's parfor lowering;
* no calls and no branches in the vectorised loops: the law's derivatives come in as arrays (or constants),
  ``J^(-2/3)`` by four Newton steps (exact to rounding for ``0.3 < J < 3.5``; a serial pass corrects the
  elements outside, or in the fused pass they are computed again with ``cbrt``), stores under a flag are
  written as selects, and the Prony terms are unrolled (a fixed four, unused ones with zero weight).

The arithmetic is double precision; the stored arrays follow the model's precision (float32 halves the
traffic, which is what bounds large meshes).
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..models.beyond_qlv import pipkin_rogers_ratio, pipkin_rogers_strain_fraction
from .kinematics import FASTMATH, cofactor, determinant, left_cauchy_green, pull_back, push_forward
from .materials import isochoric_kirchhoff_invariant, j_minus_two_thirds, svk_kirchhoff

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
def isochoric_kirchhoff(w1, w2, jm23, b11, b22, b33, b12, b23, b13):
    """Isochoric Kirchhoff stress of an invariant law from ``b``, ``J^(-2/3)`` and the law's derivatives."""
    return isochoric_kirchhoff_invariant(w1, w2, jm23 * b11, jm23 * b22, jm23 * b33, jm23 * b12, jm23 * b23,
                                         jm23 * b13)


@njit(cache=True, fastmath=FASTMATH, inline="always")
def nodal_forces(t11, t22, t33, t12, t23, t13, c11, c12, c13, c21, c22, c23, c31, c32, c33, sc,
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


@njit(cache=True, fastmath=FASTMATH, inline="always")
def gathered_deformation_gradient(u, conn, d9, e):
    """``F`` of element ``e`` from the displacements of its nodes (gathered through ``conn``)."""
    n0, n1, n2, n3 = conn[0, e], conn[1, e], conn[2, e], conn[3, e]
    x0, y0, z0 = u[n0, 0], u[n0, 1], u[n0, 2]
    ax, ay, az = u[n1, 0] - x0, u[n1, 1] - y0, u[n1, 2] - z0
    bx, by, bz = u[n2, 0] - x0, u[n2, 1] - y0, u[n2, 2] - z0
    cx, cy, cz = u[n3, 0] - x0, u[n3, 1] - y0, u[n3, 2] - z0
    d1x, d1y, d1z = d9[0, e], d9[1, e], d9[2, e]
    d2x, d2y, d2z = d9[3, e], d9[4, e], d9[5, e]
    d3x, d3y, d3z = d9[6, e], d9[7, e], d9[8, e]
    return (1.0 + ax * d1x + bx * d2x + cx * d3x, ax * d1y + bx * d2y + cx * d3y, ax * d1z + bx * d2z + cx * d3z,
            ay * d1x + by * d2x + cy * d3x, 1.0 + ay * d1y + by * d2y + cy * d3y, ay * d1z + by * d2z + cy * d3z,
            az * d1x + bz * d2x + cz * d3x, az * d1y + bz * d2y + cz * d3y, 1.0 + az * d1z + bz * d2z + cz * d3z)


@njit(cache=True, fastmath=FASTMATH, inline="always")
def store_element_kinematics(u, conn, d9, vol0, kappa, e, pe, jm23a, f11a, f12a, f13a, f21a, f22a, f23a, f31a, f32a,
                             f33a):
    """Kinematics of element ``e`` into the pass arrays: ``F - I`` (9 arrays), ``pe = kappa (J-1) V0`` and the
    branch-free ``J^(-2/3)``; returns ``J``. Shared by :func:`kinematics_pass` and the fused step (:mod:`.fused`)."""
    f11, f12, f13, f21, f22, f23, f31, f32, f33 = gathered_deformation_gradient(u, conn, d9, e)
    J = determinant(f11, f12, f13, f21, f22, f23, f31, f32, f33)
    pe[e] = kappa * (J - 1.0) * vol0[e]
    jm23a[e] = jm23_newton(J)
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
    return J


# --------------------------------------------------------------------------------------------------
# passes
# --------------------------------------------------------------------------------------------------
@njit(**_PASS)
def kinematics_pass(u, conn, d9, vol0, kappa, pe, jm23a, f11a, f12a, f13a, f21a, f22a, f23a, f31a, f32a, f33a,
                    n_bad, n_far, lo):
    """Displacement gradients ``F - I`` (stored), element pressure contributions ``pe = kappa (J-1) V0``,
    the branch-free ``J^(-2/3)`` (``jm23a``; :func:`exact_far_jm23` corrects the elements outside its range)
    and, per chunk, the number of elements with ``J <= 0`` (or NaN) and outside that range.

    ``u`` (n_nodes, 3) displacements (m); ``conn`` (4, n_elements) uint32; ``d9`` (9, n_elements) ``dN_a/dX``
    of local nodes 1-3 (``dN_0 = -sum``, 1/m); ``lo`` uint64 chunk bounds.
    """
    for c in prange(lo.size - 1):
        bad = 0
        far = 0
        for e in range(lo[c], lo[c + 1]):
            J = store_element_kinematics(u, conn, d9, vol0, kappa, e, pe, jm23a, f11a, f12a, f13a, f21a, f22a, f23a,
                                         f31a, f32a, f33a)
            bad += 0 if J > 0.0 else 1
            far += 0 if (J > JM23_NEWTON_MIN) & (J < JM23_NEWTON_MAX) else 1
        n_bad[c] = bad
        n_far[c] = far


@njit(cache=True)
def exact_far_jm23(grad_u, jm23a, n_elements):
    """``J^(-2/3)`` with ``cbrt`` for the elements outside the range of the branch-free form (a serial pass,
    run only in a step that has such elements)."""
    for e in range(np.uint64(n_elements)):
        f11, f12, f13 = 1.0 + grad_u[0, e], grad_u[1, e], grad_u[2, e]
        f21, f22, f23 = grad_u[3, e], 1.0 + grad_u[4, e], grad_u[5, e]
        f31, f32, f33 = grad_u[6, e], grad_u[7, e], 1.0 + grad_u[8, e]
        J = determinant(f11, f12, f13, f21, f22, f23, f31, f32, f33)
        if not (J > JM23_NEWTON_MIN and J < JM23_NEWTON_MAX):
            jm23a[e] = j_minus_two_thirds(J)


@njit(cache=True, fastmath=FASTMATH, inline="always")
def law_derivatives(w1fn, w2fn, params, i2_dependent, jm23, b11, b22, b33, b12, b23, b13):
    """``(dW/dI1, dW/dI2)`` of an invariant law at the isochoric invariants ``I1bar = J^-2/3 tr b``,
    ``I2bar = (I1bar^2 - J^-4/3 tr b^2) / 2`` of ``b = F F^T``, through the law's functions (C pointers on the CPU,
    the jitted functions themselves in :mod:`.cuda`); ``i2_dependent`` False: ``W(I1bar)`` only, ``dW/dI2 = 0``
    without a call."""
    i1 = jm23 * (b11 + b22 + b33)
    if i2_dependent:
        q = b11 * b11 + b22 * b22 + b33 * b33 + 2.0 * (b12 * b12 + b23 * b23 + b13 * b13)
        i2 = 0.5 * (i1 * i1 - jm23 * jm23 * q)
        return w1fn(params, i1, i2), w2fn(params, i1, i2)
    return w1fn(params, i1, 3.0), 0.0


@njit(cache=True, fastmath=FASTMATH, inline="always")
def store_law_derivatives(e, f11a, f12a, f13a, f21a, f22a, f23a, f31a, f32a, f33a, jm23a, w1fn, w2fn, params,
                          i2_dependent, w1a, w2a):
    """``w1a[e], w2a[e]`` = :func:`law_derivatives` of element ``e`` (stored ``F - I`` and ``J^-2/3``);
    ``i2_dependent`` False: ``w2a`` untouched. Shared by :func:`invariant_law_pass` and the fused step
    (:mod:`.fused`); inlined (as a plain call it made the loop ~30 % slower for a law evaluated through its
    functions: LP2, 10k-tet cube, 1 thread)."""
    f11, f12, f13 = 1.0 + f11a[e], f12a[e], f13a[e]
    f21, f22, f23 = f21a[e], 1.0 + f22a[e], f23a[e]
    f31, f32, f33 = f31a[e], f32a[e], 1.0 + f33a[e]
    b11, b22, b33, b12, b23, b13 = left_cauchy_green(f11, f12, f13, f21, f22, f23, f31, f32, f33)
    w1, w2 = law_derivatives(w1fn, w2fn, params, i2_dependent, jm23a[e], b11, b22, b33, b12, b23, b13)
    w1a[e] = w1
    if i2_dependent:
        w2a[e] = w2


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def invariant_law_pass(f11a, f12a, f13a, f21a, f22a, f23a, f31a, f32a, f33a, jm23a, w1fn, w2fn, params,
                       i2_dependent, w1a, w2a, lo):
    """The law's derivatives ``dW/dI1``, ``dW/dI2`` at every element's isochoric invariants, through the
    fitting code's law functions (C function pointers, so this loop is scalar; the stress passes that
    follow are not). ``i2_dependent`` False: ``W(I1bar)`` only, ``dW/dI2 = 0`` without a call."""
    for c in prange(lo.size - 1):
        for e in range(lo[c], lo[c + 1]):
            store_law_derivatives(e, f11a, f12a, f13a, f21a, f22a, f23a, f31a, f32a, f33a, jm23a, w1fn, w2fn, params,
                                  i2_dependent, w1a, w2a)


@njit(cache=True, fastmath=FASTMATH, inline="always")
def nodal_pressure(pe, node_ptr, inc_elem, inv_vnode, n):
    """Average nodal pressure of node ``n``: ``sum_e kappa (J_e - 1) V0_e / sum_e V0_e`` over its incident elements
    (two partial sums, as in :func:`node_force`; shared with :mod:`.cuda`)."""
    one, two = np.uint64(1), np.uint64(2)
    k, end = np.uint64(node_ptr[n]), np.uint64(node_ptr[n + 1])
    even = 0.0
    odd = 0.0
    while k + one < end:
        even += pe[inc_elem[k]]
        odd += pe[inc_elem[k + one]]
        k += two
    if k < end:
        even += pe[inc_elem[k]]
    return (even + odd) * inv_vnode[n]


@njit(**_PASS)
def nodal_pressure_pass(pe, node_ptr, inc_elem, inv_vnode, p_node, lo):
    """:func:`nodal_pressure` of every node into ``p_node`` (ANP)."""
    for c in prange(lo.size - 1):
        for n in range(lo[c], lo[c + 1]):
            p_node[n] = nodal_pressure(pe, node_ptr, inc_elem, inv_vnode, n)


@njit(cache=True, fastmath=FASTMATH, inline="always")
def element_pressure(anp_weight, kappa, J, p_node, n0, n1, n2, n3):
    """Branch-free choice between the average nodal pressure (weight 1) and the element's own (weight 0)."""
    return (anp_weight * 0.25 * (p_node[n0] + p_node[n1] + p_node[n2] + p_node[n3])
            + (1.0 - anp_weight) * kappa * (J - 1.0))


@njit(cache=True, fastmath=FASTMATH, inline="always")
def store_nodal_forces(e, r1x, r1y, r1z, r2x, r2y, r2z, r3x, r3y, r3z,
                        fe0, fe1, fe2, fe3, fe4, fe5, fe6, fe7, fe8, fe9, fe10, fe11):
    # The passes repeat "F from the stored F - I, cofactor, pressure, nodal_forces, store_nodal_forces" instead
    # of one helper: numba 0.68 refuses an inlined helper that takes these arrays and calls other inlined helpers
    # inside a parfor ("Calling a closure with *args is unsupported").
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
def invariant_force_pass(f11a, f12a, f13a, f21a, f22a, f23a, f31a, f32a, f33a, jm23a, conn, d9, vol0, p_node, w1a, w2a,
                         kappa, anp_weight, fe0, fe1, fe2, fe3, fe4, fe5, fe6, fe7, fe8, fe9, fe10, fe11, lo):
    """Element nodal forces ``fe[3 a + i]`` (N) of an invariant law (``W1 = dW/dI1``, ``W2 = dW/dI2`` of every
    element in ``w1a``, ``w2a``: constants, or from :func:`invariant_law_pass`) plus the volumetric pressure
    ``anp_weight p_ANP + (1 - anp_weight) kappa (J - 1)`` (weight 1: average nodal pressure; 0: the
    element's own); ``J^(-2/3)`` from :func:`kinematics_pass`."""
    for c in prange(lo.size - 1):
        for e in range(lo[c], lo[c + 1]):
            f11, f12, f13 = 1.0 + f11a[e], f12a[e], f13a[e]
            f21, f22, f23 = f21a[e], 1.0 + f22a[e], f23a[e]
            f31, f32, f33 = f31a[e], f32a[e], 1.0 + f33a[e]
            c11, c12, c13, c21, c22, c23, c31, c32, c33, J = cofactor(f11, f12, f13, f21, f22, f23, f31, f32, f33)
            b11, b22, b33, b12, b23, b13 = left_cauchy_green(f11, f12, f13, f21, f22, f23, f31, f32, f33)
            t11, t22, t33, t12, t23, t13 = isochoric_kirchhoff(w1a[e], w2a[e], jm23a[e], b11, b22, b33, b12,
                                                                         b23, b13)
            jp = J * element_pressure(anp_weight, kappa, J, p_node, conn[0, e], conn[1, e], conn[2, e], conn[3, e])
            r1x, r1y, r1z, r2x, r2y, r2z, r3x, r3y, r3z = nodal_forces(
                t11 + jp, t22 + jp, t33 + jp, t12, t23, t13, c11, c12, c13, c21, c22, c23, c31, c32, c33,
                vol0[e] / J, d9[0, e], d9[1, e], d9[2, e], d9[3, e], d9[4, e], d9[5, e], d9[6, e], d9[7, e], d9[8, e])
            store_nodal_forces(e, r1x, r1y, r1z, r2x, r2y, r2z, r3x, r3y, r3z,
                                fe0, fe1, fe2, fe3, fe4, fe5, fe6, fe7, fe8, fe9, fe10, fe11)


@njit(cache=True, fastmath=FASTMATH, inline="always")
def isochoric_pk2(w1, w2, jm23, f11, f12, f13, f21, f22, f23, f31, f32, f33, c11, c12, c13, c21, c22, c23, c31,
                   c32, c33, J):
    """Isochoric 2nd Piola-Kirchhoff ``S = F^-1 tau_iso F^-T`` (11 22 33 12 23 13) of an invariant law."""
    b11, b22, b33, b12, b23, b13 = left_cauchy_green(f11, f12, f13, f21, f22, f23, f31, f32, f33)
    t11, t22, t33, t12, t23, t13 = isochoric_kirchhoff(w1, w2, jm23, b11, b22, b33, b12, b23, b13)
    return pull_back(c11, c12, c13, c21, c22, c23, c31, c32, c33, J, t11, t22, t33, t12, t23, t13)


@njit(cache=True, fastmath=FASTMATH, inline="always")
def prony_update(decay, gain, h0, h1, h2, h3, h4, h5, d0, d1, d2, d3, d4, d5):
    """One term of the recursive QLV update (``models.recursion``): ``h+ = decay h + gain dS_e`` with
    ``decay = exp(-dt/tau)`` and ``gain = g (1 - decay)/(dt/tau)``."""
    return (decay * h0 + gain * d0, decay * h1 + gain * d1, decay * h2 + gain * d2,
            decay * h3 + gain * d3, decay * h4 + gain * d4, decay * h5 + gain * d5)


@njit(cache=True, fastmath=FASTMATH, inline="always")
def equilibrium_start(weight, accumulate, se0, se1, se2, se3, se4, se5, a0, a1, a2, a3, a4, a5):
    """The start of a stress pass's sum: ``weight S_e`` (the equilibrium part), plus with ``accumulate`` the stress
    ``a`` that the passes of the other Prony blocks left (a select, not a branch: the loop stays vectorisable)."""
    return (weight * se0 + (a0 if accumulate else 0.0), weight * se1 + (a1 if accumulate else 0.0),
            weight * se2 + (a2 if accumulate else 0.0), weight * se3 + (a3 if accumulate else 0.0),
            weight * se4 + (a4 if accumulate else 0.0), weight * se5 + (a5 if accumulate else 0.0))


#: Prony terms of one call of :func:`qlv_stress_pass` / :func:`pipkin_rogers_stress_pass` (written out: see there)
PRONY_BLOCK = 4
#: Prony terms of the vectorised kernel: :func:`internal_forces` calls the stress pass once per block of
#: :data:`PRONY_BLOCK` terms (materials with more run on the generic kernel)
MAX_PRONY_TERMS = 2 * PRONY_BLOCK


@njit(**_PASS)
def qlv_stress_pass(f11a, f12a, f13a, f21a, f22a, f23a, f31a, f32a, f33a, jm23a, w1a, w2a, g_inf, accumulate,
                    commit_prev, commit,
                    sp0, sp1, sp2, sp3, sp4, sp5, decay, gain, ha0, ha1, ha2, ha3, ha4, ha5,
                    hb0, hb1, hb2, hb3, hb4, hb5, hc0, hc1, hc2, hc3, hc4, hc5, hd0, hd1, hd2, hd3, hd4, hd5,
                    s0a, s1a, s2a, s3a, s4a, s5a, lo):
    """QLV with up to four Prony terms per call (the generic kernel's formulas): the instantaneous isochoric 2nd
    Piola-Kirchhoff stress ``S_e = F^-1 tau_iso F^-T`` of an invariant law (derivatives per element in
    ``w1a``, ``w2a``) and the relaxed ``S = g_inf S_e + sum_i h_i`` (into ``s0a``...``s5a``) with the
    recursive update of every term (states
    ``h_i`` = rows ``ha``...``hd``, previous ``S_e`` = ``sp``; unused terms have ``decay = gain = 0``). The
    states are written only when ``commit``, the previous ``S_e`` only when ``commit_prev``. With ``accumulate`` the
    stress is added to what ``s0a``... hold: a material with more than :data:`PRONY_BLOCK` terms runs one call per
    block, the equilibrium part ``g_inf S_e`` and ``commit_prev`` in the last call only. (Stress and forces in one
    pass would hold ~70 values per element and spill the vector registers: two passes are faster.)
    """
    da, db, dc, dd = decay[0], decay[1], decay[2], decay[3]
    ga, gb, gc, gd = gain[0], gain[1], gain[2], gain[3]
    for c in prange(lo.size - 1):
        for e in range(lo[c], lo[c + 1]):
            f11, f12, f13 = 1.0 + f11a[e], f12a[e], f13a[e]
            f21, f22, f23 = f21a[e], 1.0 + f22a[e], f23a[e]
            f31, f32, f33 = f31a[e], f32a[e], 1.0 + f33a[e]
            c11, c12, c13, c21, c22, c23, c31, c32, c33, J = cofactor(f11, f12, f13, f21, f22, f23, f31, f32, f33)
            se0, se1, se2, se3, se4, se5 = isochoric_pk2(w1a[e], w2a[e], jm23a[e], f11, f12, f13, f21, f22, f23,
                                                          f31, f32, f33, c11, c12, c13, c21, c22, c23, c31, c32,
                                                          c33, J)
            d0, d1, d2 = se0 - sp0[e], se1 - sp1[e], se2 - sp2[e]
            d3, d4, d5 = se3 - sp3[e], se4 - sp4[e], se5 - sp5[e]
            # selects, not branches, so that the loop stays vectorisable
            sp0[e] = se0 if commit_prev else sp0[e]
            sp1[e] = se1 if commit_prev else sp1[e]
            sp2[e] = se2 if commit_prev else sp2[e]
            sp3[e] = se3 if commit_prev else sp3[e]
            sp4[e] = se4 if commit_prev else sp4[e]
            sp5[e] = se5 if commit_prev else sp5[e]
            # the four Prony terms are written out, each with its own six state arrays (ha..hd): one array per stored
            # component keeps the loop vectorisable (module note), so no loop over terms of a 2-D state
            s0, s1, s2, s3, s4, s5 = equilibrium_start(g_inf, accumulate, se0, se1, se2, se3, se4, se5,
                                                       s0a[e], s1a[e], s2a[e], s3a[e], s4a[e], s5a[e])
            x0, x1, x2, x3, x4, x5 = prony_update(da, ga, ha0[e], ha1[e], ha2[e], ha3[e], ha4[e], ha5[e],
                                                   d0, d1, d2, d3, d4, d5)
            ha0[e], ha1[e], ha2[e] = (x0 if commit else ha0[e]), (x1 if commit else ha1[e]), (x2 if commit else ha2[e])
            ha3[e], ha4[e], ha5[e] = (x3 if commit else ha3[e]), (x4 if commit else ha4[e]), (x5 if commit else ha5[e])
            s0, s1, s2, s3, s4, s5 = s0 + x0, s1 + x1, s2 + x2, s3 + x3, s4 + x4, s5 + x5
            x0, x1, x2, x3, x4, x5 = prony_update(db, gb, hb0[e], hb1[e], hb2[e], hb3[e], hb4[e], hb5[e],
                                                   d0, d1, d2, d3, d4, d5)
            hb0[e], hb1[e], hb2[e] = (x0 if commit else hb0[e]), (x1 if commit else hb1[e]), (x2 if commit else hb2[e])
            hb3[e], hb4[e], hb5[e] = (x3 if commit else hb3[e]), (x4 if commit else hb4[e]), (x5 if commit else hb5[e])
            s0, s1, s2, s3, s4, s5 = s0 + x0, s1 + x1, s2 + x2, s3 + x3, s4 + x4, s5 + x5
            x0, x1, x2, x3, x4, x5 = prony_update(dc, gc, hc0[e], hc1[e], hc2[e], hc3[e], hc4[e], hc5[e],
                                                   d0, d1, d2, d3, d4, d5)
            hc0[e], hc1[e], hc2[e] = (x0 if commit else hc0[e]), (x1 if commit else hc1[e]), (x2 if commit else hc2[e])
            hc3[e], hc4[e], hc5[e] = (x3 if commit else hc3[e]), (x4 if commit else hc4[e]), (x5 if commit else hc5[e])
            s0, s1, s2, s3, s4, s5 = s0 + x0, s1 + x1, s2 + x2, s3 + x3, s4 + x4, s5 + x5
            x0, x1, x2, x3, x4, x5 = prony_update(dd, gd, hd0[e], hd1[e], hd2[e], hd3[e], hd4[e], hd5[e],
                                                   d0, d1, d2, d3, d4, d5)
            hd0[e], hd1[e], hd2[e] = (x0 if commit else hd0[e]), (x1 if commit else hd1[e]), (x2 if commit else hd2[e])
            hd3[e], hd4[e], hd5[e] = (x3 if commit else hd3[e]), (x4 if commit else hd4[e]), (x5 if commit else hd5[e])
            s0a[e], s1a[e], s2a[e] = s0 + x0, s1 + x1, s2 + x2
            s3a[e], s4a[e], s5a[e] = s3 + x3, s4 + x4, s5 + x5


@njit(cache=True, fastmath=FASTMATH, inline="always")
def pipkin_rogers_update(decay, fac, wnew, wold, h0, h1, h2, h3, h4, h5, se0, se1, se2, se3, se4, se5,
                         sp0, sp1, sp2, sp3, sp4, sp5):
    """One term of the Pipkin-Rogers update: :func:`prony_update` with gain ``(1 - decay)/(dt/tau)`` driven by the
    increment ``g_i(x_n+1) S_e,n+1 - g_i(x_n) S_e,n`` of the branch stress (weights ``wnew``, ``wold``)."""
    return prony_update(decay, fac, h0, h1, h2, h3, h4, h5, wnew * se0 - wold * sp0, wnew * se1 - wold * sp1,
                        wnew * se2 - wold * sp2, wnew * se3 - wold * sp3, wnew * se4 - wold * sp4,
                        wnew * se5 - wold * sp5)


@njit(**_PASS)
def pipkin_rogers_stress_pass(f11a, f12a, f13a, f21a, f22a, f23a, f31a, f32a, f33a, jm23a, w1a, w2a, inf_weight,
                              beta_other, beta_kappa_other, accumulate, commit_prev, commit,
                              sp0, sp1, sp2, sp3, sp4, sp5, decay, fac, beta, kappa, gamma_s2, wpa, wpb, wpc, wpd,
                              ha0, ha1, ha2, ha3, ha4, ha5, hb0, hb1, hb2, hb3, hb4, hb5,
                              hc0, hc1, hc2, hc3, hc4, hc5, hd0, hd1, hd2, hd3, hd4, hd5,
                              s0a, s1a, s2a, s3a, s4a, s5a, lo):
    """Pipkin-Rogers with up to four Prony terms per call (the generic kernel's formulas, ``_kernels._element_force_pass``):
    the weights at ``x = I1bar - 3`` by the fitting code's weight law (``models.beyond_qlv``:
    ``pipkin_rogers_strain_fraction``, ``pipkin_rogers_ratio``; rows ``beta``, ``kappa``, one ``gamma_s^2``),
    ``S = g_inf(x) S_e + sum_i h_i`` with every term driven by the increment of ``g_i(x) S_e`` (previous weights in
    ``wpa``...``wpd``, previous ``S_e`` in ``sp``; unused terms have ``beta = decay = fac = 0``). States written only
    when ``commit``; the layout and vectorisation notes of :func:`qlv_stress_pass` apply, and so does its block
    scheme (``accumulate``, ``commit_prev``; the equilibrium part ``inf_weight = 1`` in the last call only). The
    ratio sum of the terms outside this block is linear in the strain fraction ``s``:
    ``sum_j beta_j (1 + kappa_j s) = beta_other + beta_kappa_other s``."""
    da, db, dc, dd = decay[0], decay[1], decay[2], decay[3]
    fa, fb, fc, fd = fac[0], fac[1], fac[2], fac[3]
    ba, bb, bc, bd = beta[0], beta[1], beta[2], beta[3]
    ka, kb, kc, kd = kappa[0], kappa[1], kappa[2], kappa[3]
    for c in prange(lo.size - 1):
        for e in range(lo[c], lo[c + 1]):
            f11, f12, f13 = 1.0 + f11a[e], f12a[e], f13a[e]
            f21, f22, f23 = f21a[e], 1.0 + f22a[e], f23a[e]
            f31, f32, f33 = f31a[e], f32a[e], 1.0 + f33a[e]
            c11, c12, c13, c21, c22, c23, c31, c32, c33, J = cofactor(f11, f12, f13, f21, f22, f23, f31, f32, f33)
            se0, se1, se2, se3, se4, se5 = isochoric_pk2(w1a[e], w2a[e], jm23a[e], f11, f12, f13, f21, f22, f23,
                                                          f31, f32, f33, c11, c12, c13, c21, c22, c23, c31, c32,
                                                          c33, J)
            trb = (f11 * f11 + f12 * f12 + f13 * f13 + f21 * f21 + f22 * f22 + f23 * f23
                   + f31 * f31 + f32 * f32 + f33 * f33)
            sfrac = pipkin_rogers_strain_fraction(jm23a[e] * trb - 3.0, gamma_s2)
            ra = pipkin_rogers_ratio(ba, ka, sfrac)
            rb = pipkin_rogers_ratio(bb, kb, sfrac)
            rc = pipkin_rogers_ratio(bc, kc, sfrac)
            rd = pipkin_rogers_ratio(bd, kd, sfrac)
            winf = 1.0 / (1.0 + ra + rb + rc + rd + beta_other + beta_kappa_other * sfrac)
            wa, wb, wc, wd = ra * winf, rb * winf, rc * winf, rd * winf
            p0, p1, p2, p3, p4, p5 = sp0[e], sp1[e], sp2[e], sp3[e], sp4[e], sp5[e]
            # selects, not branches, so that the loop stays vectorisable
            sp0[e] = se0 if commit_prev else p0
            sp1[e] = se1 if commit_prev else p1
            sp2[e] = se2 if commit_prev else p2
            sp3[e] = se3 if commit_prev else p3
            sp4[e] = se4 if commit_prev else p4
            sp5[e] = se5 if commit_prev else p5
            s0, s1, s2, s3, s4, s5 = equilibrium_start(inf_weight * winf, accumulate, se0, se1, se2, se3, se4, se5,
                                                       s0a[e], s1a[e], s2a[e], s3a[e], s4a[e], s5a[e])
            x0, x1, x2, x3, x4, x5 = pipkin_rogers_update(da, fa, wa, wpa[e], ha0[e], ha1[e], ha2[e], ha3[e], ha4[e],
                                                          ha5[e], se0, se1, se2, se3, se4, se5, p0, p1, p2, p3, p4, p5)
            ha0[e], ha1[e], ha2[e] = (x0 if commit else ha0[e]), (x1 if commit else ha1[e]), (x2 if commit else ha2[e])
            ha3[e], ha4[e], ha5[e] = (x3 if commit else ha3[e]), (x4 if commit else ha4[e]), (x5 if commit else ha5[e])
            wpa[e] = wa if commit else wpa[e]
            s0, s1, s2, s3, s4, s5 = s0 + x0, s1 + x1, s2 + x2, s3 + x3, s4 + x4, s5 + x5
            x0, x1, x2, x3, x4, x5 = pipkin_rogers_update(db, fb, wb, wpb[e], hb0[e], hb1[e], hb2[e], hb3[e], hb4[e],
                                                          hb5[e], se0, se1, se2, se3, se4, se5, p0, p1, p2, p3, p4, p5)
            hb0[e], hb1[e], hb2[e] = (x0 if commit else hb0[e]), (x1 if commit else hb1[e]), (x2 if commit else hb2[e])
            hb3[e], hb4[e], hb5[e] = (x3 if commit else hb3[e]), (x4 if commit else hb4[e]), (x5 if commit else hb5[e])
            wpb[e] = wb if commit else wpb[e]
            s0, s1, s2, s3, s4, s5 = s0 + x0, s1 + x1, s2 + x2, s3 + x3, s4 + x4, s5 + x5
            x0, x1, x2, x3, x4, x5 = pipkin_rogers_update(dc, fc, wc, wpc[e], hc0[e], hc1[e], hc2[e], hc3[e], hc4[e],
                                                          hc5[e], se0, se1, se2, se3, se4, se5, p0, p1, p2, p3, p4, p5)
            hc0[e], hc1[e], hc2[e] = (x0 if commit else hc0[e]), (x1 if commit else hc1[e]), (x2 if commit else hc2[e])
            hc3[e], hc4[e], hc5[e] = (x3 if commit else hc3[e]), (x4 if commit else hc4[e]), (x5 if commit else hc5[e])
            wpc[e] = wc if commit else wpc[e]
            s0, s1, s2, s3, s4, s5 = s0 + x0, s1 + x1, s2 + x2, s3 + x3, s4 + x4, s5 + x5
            x0, x1, x2, x3, x4, x5 = pipkin_rogers_update(dd, fd, wd, wpd[e], hd0[e], hd1[e], hd2[e], hd3[e], hd4[e],
                                                          hd5[e], se0, se1, se2, se3, se4, se5, p0, p1, p2, p3, p4, p5)
            hd0[e], hd1[e], hd2[e] = (x0 if commit else hd0[e]), (x1 if commit else hd1[e]), (x2 if commit else hd2[e])
            hd3[e], hd4[e], hd5[e] = (x3 if commit else hd3[e]), (x4 if commit else hd4[e]), (x5 if commit else hd5[e])
            wpd[e] = wd if commit else wpd[e]
            s0a[e], s1a[e], s2a[e] = s0 + x0, s1 + x1, s2 + x2
            s3a[e], s4a[e], s5a[e] = s3 + x3, s4 + x4, s5 + x5


@njit(**_PASS)
def pk2_force_pass(f11a, f12a, f13a, f21a, f22a, f23a, f31a, f32a, f33a, s0a, s1a, s2a, s3a, s4a, s5a, conn, d9, vol0,
                   p_node, kappa, anp_weight, fe0, fe1, fe2, fe3, fe4, fe5, fe6, fe7, fe8, fe9, fe10, fe11, lo):
    """Element nodal forces (N) from an isochoric 2nd Piola-Kirchhoff stress ``S`` (``s0a``...; e.g. of
    :func:`qlv_stress_pass`): ``tau = F S F^T + J p I`` with the pressure as in :func:`invariant_force_pass`."""
    for c in prange(lo.size - 1):
        for e in range(lo[c], lo[c + 1]):
            f11, f12, f13 = 1.0 + f11a[e], f12a[e], f13a[e]
            f21, f22, f23 = f21a[e], 1.0 + f22a[e], f23a[e]
            f31, f32, f33 = f31a[e], f32a[e], 1.0 + f33a[e]
            c11, c12, c13, c21, c22, c23, c31, c32, c33, J = cofactor(f11, f12, f13, f21, f22, f23, f31, f32, f33)
            t11, t22, t33, t12, t23, t13 = push_forward(f11, f12, f13, f21, f22, f23, f31, f32, f33,
                                                         s0a[e], s1a[e], s2a[e], s3a[e], s4a[e], s5a[e])
            jp = J * element_pressure(anp_weight, kappa, J, p_node, conn[0, e], conn[1, e], conn[2, e], conn[3, e])
            r1x, r1y, r1z, r2x, r2y, r2z, r3x, r3y, r3z = nodal_forces(
                t11 + jp, t22 + jp, t33 + jp, t12, t23, t13, c11, c12, c13, c21, c22, c23, c31, c32, c33,
                vol0[e] / J, d9[0, e], d9[1, e], d9[2, e], d9[3, e], d9[4, e], d9[5, e], d9[6, e], d9[7, e], d9[8, e])
            store_nodal_forces(e, r1x, r1y, r1z, r2x, r2y, r2z, r3x, r3y, r3z,
                                fe0, fe1, fe2, fe3, fe4, fe5, fe6, fe7, fe8, fe9, fe10, fe11)


@njit(**_PASS)
def element_force_pass(u, conn, d9, vol0, svk, w1, w2, mu, kappa, n_bad,
                       fe0, fe1, fe2, fe3, fe4, fe5, fe6, fe7, fe8, fe9, fe10, fe11, lo):
    """One fused element pass without average nodal pressure and without viscoelastic states: ``F`` from the
    gathered displacements, stress (Saint Venant-Kirchhoff when ``svk``, else the constant-derivative law
    with the element pressure ``kappa (J - 1)``) and the 12 element nodal forces; ``n_bad`` counts the
    elements with ``J <= 0`` per chunk. Elements outside the branch-free ``J^(-2/3)`` range are computed
    again with ``cbrt`` after the vectorised loop."""
    lam = kappa - 2.0 * mu / 3.0
    for c in prange(lo.size - 1):
        bad = 0
        far = 0
        for e in range(lo[c], lo[c + 1]):
            f11, f12, f13, f21, f22, f23, f31, f32, f33 = gathered_deformation_gradient(u, conn, d9, e)
            c11, c12, c13, c21, c22, c23, c31, c32, c33, J = cofactor(f11, f12, f13, f21, f22, f23, f31, f32, f33)
            b11, b22, b33, b12, b23, b13 = left_cauchy_green(f11, f12, f13, f21, f22, f23, f31, f32, f33)
            if svk:
                t11, t22, t33, t12, t23, t13 = svk_kirchhoff(mu, lam, b11, b22, b33, b12, b23, b13)
            else:
                t11, t22, t33, t12, t23, t13 = isochoric_kirchhoff(w1, w2, jm23_newton(J), b11, b22, b33,
                                                                             b12, b23, b13)
                jp = J * kappa * (J - 1.0)
                t11 += jp
                t22 += jp
                t33 += jp
            r1x, r1y, r1z, r2x, r2y, r2z, r3x, r3y, r3z = nodal_forces(
                t11, t22, t33, t12, t23, t13, c11, c12, c13, c21, c22, c23, c31, c32, c33,
                vol0[e] / J, d9[0, e], d9[1, e], d9[2, e], d9[3, e], d9[4, e], d9[5, e], d9[6, e], d9[7, e], d9[8, e])
            store_nodal_forces(e, r1x, r1y, r1z, r2x, r2y, r2z, r3x, r3y, r3z,
                                fe0, fe1, fe2, fe3, fe4, fe5, fe6, fe7, fe8, fe9, fe10, fe11)
            bad += 0 if J > 0.0 else 1
            far += 0 if (J > JM23_NEWTON_MIN) & (J < JM23_NEWTON_MAX) else 1
        n_bad[c] = bad
        if svk or far == 0:
            continue
        for e in range(lo[c], lo[c + 1]):
            f11, f12, f13, f21, f22, f23, f31, f32, f33 = gathered_deformation_gradient(u, conn, d9, e)
            c11, c12, c13, c21, c22, c23, c31, c32, c33, J = cofactor(f11, f12, f13, f21, f22, f23, f31, f32, f33)
            if J > JM23_NEWTON_MIN and J < JM23_NEWTON_MAX:
                continue
            b11, b22, b33, b12, b23, b13 = left_cauchy_green(f11, f12, f13, f21, f22, f23, f31, f32, f33)
            t11, t22, t33, t12, t23, t13 = isochoric_kirchhoff(w1, w2, j_minus_two_thirds(J), b11, b22,
                                                                         b33, b12, b23, b13)
            jp = J * kappa * (J - 1.0)
            r1x, r1y, r1z, r2x, r2y, r2z, r3x, r3y, r3z = nodal_forces(
                t11 + jp, t22 + jp, t33 + jp, t12, t23, t13, c11, c12, c13, c21, c22, c23, c31, c32, c33,
                vol0[e] / J, d9[0, e], d9[1, e], d9[2, e], d9[3, e], d9[4, e], d9[5, e], d9[6, e], d9[7, e], d9[8, e])
            store_nodal_forces(e, r1x, r1y, r1z, r2x, r2y, r2z, r3x, r3y, r3z,
                                fe0, fe1, fe2, fe3, fe4, fe5, fe6, fe7, fe8, fe9, fe10, fe11)


@njit(cache=True)
def first_inverted_element_of(u, conn, d9, n_elements):
    """Smallest element id with ``J <= 0`` (or NaN) of the displacement ``u``; -1 if none."""
    for e in range(np.uint64(n_elements)):
        f11, f12, f13, f21, f22, f23, f31, f32, f33 = gathered_deformation_gradient(u, conn, d9, e)
        J = determinant(f11, f12, f13, f21, f22, f23, f31, f32, f33)
        if not J > 0.0:
            return np.int64(e)
    return np.int64(-1)


def node_incidence(elements: np.ndarray, n_nodes: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Node -> incident element CSR of the element-force layout (shared by the CPU passes and :mod:`.cuda`).

    Returns ``node_ptr`` (n_nodes + 1), ``inc_elem`` (element of each incidence, elements ascending per node) and
    ``inc_slot = 3 a n_elements + e`` (the x force of local node ``a`` of element ``e`` in the flattened
    ``(12, n_elements)`` element-force array), all ``uint32``.
    """
    ne = elements.shape[0]
    if 12 * ne >= 2**32:
        raise ValueError("the element-force layout indexes with uint32: at most 357M elements")
    flat = np.asarray(elements).ravel()
    order = np.argsort(flat, kind="stable")
    node_ptr = np.zeros(n_nodes + 1, np.uint32)
    node_ptr[1:] = np.cumsum(np.bincount(flat, minlength=n_nodes))
    return node_ptr, (order // 4).astype(np.uint32), (3 * (order % 4) * ne + order // 4).astype(np.uint32)


@njit(cache=True, fastmath=FASTMATH, inline="always")
def node_force(fe_flat, node_ptr, inc_slot, n_elements, n):
    """Internal force of node ``n``: the sum of its element forces; ``inc_slot = 3 a n_elements + e``
    indexes the flattened ``(12, n_elements)`` element force array for local node ``a`` of element ``e``.

    Two incidences per iteration into two partial sums: a node has ~15-25 incidences, too few for LLVM's
    vectorised reduction (two 8-wide gathers, then horizontal sums and a scalar remainder), and one sum is a
    chain of dependent additions; the unrolled scalar loop halved the gather pass (10k-tet cube, 62 -> 31 us on
    1 thread, docs/fem_timing.md)."""
    ne = np.uint64(n_elements)
    one, two = np.uint64(1), np.uint64(2)
    k, end = np.uint64(node_ptr[n]), np.uint64(node_ptr[n + 1])
    ax = 0.0
    ay = 0.0
    az = 0.0
    bx = 0.0
    by = 0.0
    bz = 0.0
    while k + one < end:
        s = np.uint64(inc_slot[k])
        t = np.uint64(inc_slot[k + one])
        ax += fe_flat[s]
        ay += fe_flat[s + ne]
        az += fe_flat[s + ne + ne]
        bx += fe_flat[t]
        by += fe_flat[t + ne]
        bz += fe_flat[t + ne + ne]
        k += two
    if k < end:
        s = np.uint64(inc_slot[k])
        ax += fe_flat[s]
        ay += fe_flat[s + ne]
        az += fe_flat[s + ne + ne]
    return ax + bx, ay + by, az + bz


@njit(**_PASS)
def gather_nodal_forces(fe_flat, node_ptr, inc_slot, n_elements, fint, lo):
    """``fint[n]`` = :func:`node_force` for every node."""
    for c in prange(lo.size - 1):
        for n in range(lo[c], lo[c + 1]):
            fint[n, 0], fint[n, 1], fint[n, 2] = node_force(fe_flat, node_ptr, inc_slot, n_elements, n)


@njit(cache=True)
def first_inverted_element(grad_u, lo):
    """Smallest element id with ``J <= 0`` (or NaN), from the stored displacement gradients ``F - I``; -1 if none."""
    for e in range(lo[-1]):
        f11, f12, f13 = 1.0 + grad_u[0, e], grad_u[1, e], grad_u[2, e]
        f21, f22, f23 = grad_u[3, e], 1.0 + grad_u[4, e], grad_u[5, e]
        f31, f32, f33 = grad_u[6, e], grad_u[7, e], 1.0 + grad_u[8, e]
        J = determinant(f11, f12, f13, f21, f22, f23, f31, f32, f33)
        if not J > 0.0:
            return np.int64(e)
    return np.int64(-1)


@njit(cache=True)
def internal_forces(u, ws, svk, constant, w1, w2, w1fn, w2fn, params, i2_dependent, kappa, use_anp, prony_g, prony_e,
                    prony_f, pr_params, commit, fint, gather):
    """Internal nodal forces ``fint`` (N) of the displacement ``u`` (m) through the passes above.

    ``ws`` is the workspace tuple of ``tissuemech.fem.tled._vector_setup``. The law: Saint Venant-Kirchhoff
    (``svk``, shear modulus ``params[0]``), constant derivatives ``w1``, ``w2`` (``constant``: neo-Hookean,
    Mooney-Rivlin; the workspace arrays hold them) or the law functions ``w1fn``, ``w2fn`` of ``params``
    evaluated per element by :func:`invariant_law_pass`. Without average nodal pressure and viscoelastic
    states a constant-derivative law (and SVK) runs in one fused element pass; otherwise kinematics, nodal
    pressure and stress passes. QLV (``prony_g.size > 0``) and Pipkin-Rogers (``pr_params`` rows ``(beta_i, kappa_i,
    gamma_s^2)``, :func:`pipkin_rogers_stress_pass`) advance the states in ``ws`` (committed only when ``commit``).
    Without ``gather`` the element forces stay in ``ws`` (the caller's node pass gathers them into ``fint``).
    Returns the first inverted element or -1.
    """
    (conn, d9, vol0, node_ptr, inc_elem, inc_slot, inv_vnode, elo, nlo, grad_u, pe, p_node, fe, n_bad, n_far,
     sprev, hstate, jm23a, s_relaxed, w1a, w2a, wprev) = ws
    mu = params[0]
    if svk or (constant and not use_anp and prony_g.size == 0):
        element_force_pass(u, conn, d9, vol0, svk, w1, w2, mu, kappa, n_bad, fe[0], fe[1], fe[2], fe[3], fe[4],
                           fe[5], fe[6], fe[7], fe[8], fe[9], fe[10], fe[11], elo)
        if n_bad.sum() > 0:
            return first_inverted_element_of(u, conn, d9, vol0.size)
        if gather:
            gather_nodal_forces(fe.reshape(-1), node_ptr, inc_slot, vol0.size, fint, nlo)
        return np.int64(-1)
    g0, g1, g2, g3, g4, g5, g6, g7, g8 = grad_u[0], grad_u[1], grad_u[2], grad_u[3], grad_u[4], grad_u[5], grad_u[6], \
        grad_u[7], grad_u[8]
    kinematics_pass(u, conn, d9, vol0, kappa, pe, jm23a, g0, g1, g2, g3, g4, g5, g6, g7, g8, n_bad, n_far, elo)
    if n_bad.sum() > 0:
        return first_inverted_element(grad_u, elo)
    if n_far.sum() > 0:
        exact_far_jm23(grad_u, jm23a, vol0.size)
    if not constant:
        invariant_law_pass(g0, g1, g2, g3, g4, g5, g6, g7, g8, jm23a, w1fn, w2fn, params, i2_dependent, w1a, w2a, elo)
    anp_weight = 1.0 if use_anp else 0.0
    if use_anp:
        nodal_pressure_pass(pe, node_ptr, inc_elem, inv_vnode, p_node, nlo)
    nterm = prony_g.size
    if nterm == 0:
        invariant_force_pass(g0, g1, g2, g3, g4, g5, g6, g7, g8, jm23a, conn, d9, vol0, p_node,
                             w1a, w2a, kappa, anp_weight, fe[0], fe[1], fe[2], fe[3], fe[4], fe[5], fe[6],
                             fe[7], fe[8], fe[9], fe[10], fe[11], elo)
    else:
        # one stress pass per block of PRONY_BLOCK terms, the last block (with the equilibrium part and the
        # previous S_e) last
        n_block = (nterm + PRONY_BLOCK - 1) // PRONY_BLOCK
        for b in range(n_block - 1, -1, -1):
            t0 = b * PRONY_BLOCK
            nb = min(nterm, t0 + PRONY_BLOCK) - t0
            decay = np.zeros(PRONY_BLOCK)
            gain = np.zeros(PRONY_BLOCK)
            decay[:nb] = prony_e[t0:t0 + nb]
            accumulate = b < n_block - 1
            last = b == 0
            inf_weight = 1.0 if last else 0.0
            commit_prev = commit and last
            ha, hb, hc, hd = hstate[t0], hstate[t0 + 1], hstate[t0 + 2], hstate[t0 + 3]
            if pr_params.shape[0] > 0:
                gain[:nb] = prony_f[t0:t0 + nb]
                beta = np.zeros(PRONY_BLOCK)
                kap = np.zeros(PRONY_BLOCK)
                beta[:nb] = pr_params[t0:t0 + nb, 0]
                kap[:nb] = pr_params[t0:t0 + nb, 1]
                beta_other = pr_params[:, 0].sum() - beta.sum()
                beta_kappa_other = (pr_params[:, 0] * pr_params[:, 1]).sum() - (beta * kap).sum()
                wa, wb, wc, wd = wprev[t0], wprev[t0 + 1], wprev[t0 + 2], wprev[t0 + 3]
                pipkin_rogers_stress_pass(g0, g1, g2, g3, g4, g5, g6, g7, g8, jm23a, w1a, w2a, inf_weight,
                                          beta_other, beta_kappa_other, accumulate, commit_prev, commit,
                                          sprev[0], sprev[1], sprev[2], sprev[3], sprev[4], sprev[5], decay, gain,
                                          beta, kap, pr_params[0, 2], wa, wb, wc, wd,
                                          ha[0], ha[1], ha[2], ha[3], ha[4], ha[5], hb[0], hb[1], hb[2], hb[3], hb[4],
                                          hb[5], hc[0], hc[1], hc[2], hc[3], hc[4], hc[5], hd[0], hd[1], hd[2], hd[3],
                                          hd[4], hd[5],
                                          s_relaxed[0], s_relaxed[1], s_relaxed[2], s_relaxed[3], s_relaxed[4],
                                          s_relaxed[5], elo)
            else:
                gain[:nb] = prony_g[t0:t0 + nb] * prony_f[t0:t0 + nb]
                qlv_stress_pass(g0, g1, g2, g3, g4, g5, g6, g7, g8, jm23a, w1a, w2a,
                                inf_weight * (1.0 - prony_g.sum()), accumulate, commit_prev, commit,
                                sprev[0], sprev[1], sprev[2], sprev[3], sprev[4], sprev[5], decay, gain,
                                ha[0], ha[1], ha[2], ha[3], ha[4], ha[5], hb[0], hb[1], hb[2], hb[3], hb[4], hb[5],
                                hc[0], hc[1], hc[2], hc[3], hc[4], hc[5], hd[0], hd[1], hd[2], hd[3], hd[4], hd[5],
                                s_relaxed[0], s_relaxed[1], s_relaxed[2], s_relaxed[3], s_relaxed[4],
                                s_relaxed[5], elo)
        pk2_force_pass(g0, g1, g2, g3, g4, g5, g6, g7, g8, s_relaxed[0], s_relaxed[1], s_relaxed[2], s_relaxed[3],
                       s_relaxed[4], s_relaxed[5], conn, d9, vol0, p_node, kappa, anp_weight, fe[0], fe[1], fe[2],
                       fe[3], fe[4], fe[5], fe[6], fe[7], fe[8], fe[9], fe[10], fe[11], elo)
    if gather:
        gather_nodal_forces(fe.reshape(-1), node_ptr, inc_slot, vol0.size, fint, nlo)
    return np.int64(-1)
