"""Tensor algebra of one linear tetrahedron shared by the TLED kernels (scalar arguments, inlined by numba).

Symmetric tensors are passed and returned as six components in the order 11 22 33 12 23 13; the deformation
gradient ``F`` as nine components row by row.
"""
from __future__ import annotations

import math

from numba import njit

#: LLVM fast-math flags of the kernels: reassociation and contraction (FMA) but IEEE NaN/inf semantics,
#: so that inverted or non-finite states are still detected
FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}


@njit(cache=True, fastmath=FASTMATH, inline="always")
def determinant(f11, f12, f13, f21, f22, f23, f31, f32, f33):
    """``J = det F`` by expansion along the first row (the passes that need ``J`` without the cofactor)."""
    return f11 * (f22 * f33 - f23 * f32) - f12 * (f21 * f33 - f23 * f31) + f13 * (f21 * f32 - f22 * f31)


@njit(cache=True, fastmath=FASTMATH, inline="always")
def cofactor(f11, f12, f13, f21, f22, f23, f31, f32, f33):
    """Cofactor matrix ``cof F = J F^-T`` (nine components, row by row) and ``J = det F``."""
    c11 = f22 * f33 - f23 * f32
    c12 = f23 * f31 - f21 * f33
    c13 = f21 * f32 - f22 * f31
    c21 = f13 * f32 - f12 * f33
    c22 = f11 * f33 - f13 * f31
    c23 = f12 * f31 - f11 * f32
    c31 = f12 * f23 - f13 * f22
    c32 = f13 * f21 - f11 * f23
    c33 = f11 * f22 - f12 * f21
    return c11, c12, c13, c21, c22, c23, c31, c32, c33, f11 * c11 + f12 * c12 + f13 * c13


@njit(cache=True, fastmath=FASTMATH, inline="always")
def left_cauchy_green(f11, f12, f13, f21, f22, f23, f31, f32, f33):
    """``b = F F^T``."""
    return (f11 * f11 + f12 * f12 + f13 * f13, f21 * f21 + f22 * f22 + f23 * f23,
            f31 * f31 + f32 * f32 + f33 * f33, f11 * f21 + f12 * f22 + f13 * f23,
            f21 * f31 + f22 * f32 + f23 * f33, f11 * f31 + f12 * f32 + f13 * f33)


@njit(cache=True, fastmath=FASTMATH, inline="always")
def symmetric_square(b11, b22, b33, b12, b23, b13):
    """``b b`` of a symmetric tensor."""
    return (b11 * b11 + b12 * b12 + b13 * b13, b12 * b12 + b22 * b22 + b23 * b23,
            b13 * b13 + b23 * b23 + b33 * b33, b11 * b12 + b12 * b22 + b13 * b23,
            b12 * b13 + b22 * b23 + b23 * b33, b11 * b13 + b12 * b23 + b13 * b33)


@njit(cache=True, fastmath=FASTMATH, inline="always")
def pull_back(c11, c12, c13, c21, c22, c23, c31, c32, c33, J, t11, t22, t33, t12, t23, t13):
    """``F^-1 t F^-T`` of a symmetric spatial tensor ``t`` (e.g. Kirchhoff stress -> 2nd Piola-Kirchhoff),
    with ``F^-1 = cof^T / J``."""
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


@njit(cache=True, fastmath=FASTMATH, inline="always")
def push_forward(f11, f12, f13, f21, f22, f23, f31, f32, f33, s0, s1, s2, s3, s4, s5):
    """``F S F^T`` of a symmetric material tensor ``S`` (2nd Piola-Kirchhoff -> Kirchhoff stress)."""
    q11 = f11 * s0 + f12 * s3 + f13 * s5
    q12 = f11 * s3 + f12 * s1 + f13 * s4
    q13 = f11 * s5 + f12 * s4 + f13 * s2
    q21 = f21 * s0 + f22 * s3 + f23 * s5
    q22 = f21 * s3 + f22 * s1 + f23 * s4
    q23 = f21 * s5 + f22 * s4 + f23 * s2
    q31 = f31 * s0 + f32 * s3 + f33 * s5
    q32 = f31 * s3 + f32 * s1 + f33 * s4
    q33 = f31 * s5 + f32 * s4 + f33 * s2
    return (q11 * f11 + q12 * f12 + q13 * f13, q21 * f21 + q22 * f22 + q23 * f23, q31 * f31 + q32 * f32 + q33 * f33,
            q11 * f21 + q12 * f22 + q13 * f23, q21 * f31 + q22 * f32 + q23 * f33, q11 * f31 + q12 * f32 + q13 * f33)


@njit(cache=True, fastmath=FASTMATH, inline="always")
def _jacobi_rotation(app, aqq, apq):
    """``t = tan(theta)`` and ``c = cos(theta)`` of the Jacobi rotation that zeroes ``a_pq``."""
    theta = (aqq - app) / (2.0 * apq)
    t = 1.0 / (abs(theta) + math.sqrt(theta * theta + 1.0))
    if theta < 0.0:
        t = -t
    return t, 1.0 / math.sqrt(t * t + 1.0)


@njit(cache=True, fastmath=FASTMATH)
def symmetric_eigen3(a11, a22, a33, a12, a23, a13):
    """Eigenvalues and unit eigenvectors of a symmetric 3x3 matrix by cyclic Jacobi rotations (Numerical
    Recipes 11.1): ``(l1, l2, l3, v11, v21, v31, v12, v22, v32, v13, v23, v33)`` with eigenvector ``k`` =
    ``(v1k, v2k, v3k)``. Exact for repeated eigenvalues (no division by eigenvalue gaps); a near-identity
    ``bbar`` converges in one or two sweeps. About 3x faster per element than LAPACK ``eigh`` through numba
    (call and workspace overhead dominate a 3x3 problem)."""
    v11, v12, v13 = 1.0, 0.0, 0.0
    v21, v22, v23 = 0.0, 1.0, 0.0
    v31, v32, v33 = 0.0, 0.0, 1.0
    for _sweep in range(16):
        off = abs(a12) + abs(a23) + abs(a13)
        if off <= 1e-16 * (abs(a11) + abs(a22) + abs(a33)):
            break
        # the three plane rotations are written out (not a loop over index pairs): the matrix and the eigenvectors
        # stay scalars in registers, as everywhere in the kernels
        if a12 != 0.0:  # rotation in the (1, 2) plane
            t, c = _jacobi_rotation(a11, a22, a12)
            s = t * c
            a11 -= t * a12
            a22 += t * a12
            a12 = 0.0
            a13, a23 = c * a13 - s * a23, s * a13 + c * a23
            v11, v12 = c * v11 - s * v12, s * v11 + c * v12
            v21, v22 = c * v21 - s * v22, s * v21 + c * v22
            v31, v32 = c * v31 - s * v32, s * v31 + c * v32
        if a13 != 0.0:  # (1, 3)
            t, c = _jacobi_rotation(a11, a33, a13)
            s = t * c
            a11 -= t * a13
            a33 += t * a13
            a13 = 0.0
            a12, a23 = c * a12 - s * a23, s * a12 + c * a23
            v11, v13 = c * v11 - s * v13, s * v11 + c * v13
            v21, v23 = c * v21 - s * v23, s * v21 + c * v23
            v31, v33 = c * v31 - s * v33, s * v31 + c * v33
        if a23 != 0.0:  # (2, 3)
            t, c = _jacobi_rotation(a22, a33, a23)
            s = t * c
            a22 -= t * a23
            a33 += t * a23
            a23 = 0.0
            a12, a13 = c * a12 - s * a13, s * a12 + c * a13
            v12, v13 = c * v12 - s * v13, s * v12 + c * v13
            v22, v23 = c * v22 - s * v23, s * v22 + c * v23
            v32, v33 = c * v32 - s * v33, s * v32 + c * v33
    return a11, a22, a33, v11, v21, v31, v12, v22, v32, v13, v23, v33
