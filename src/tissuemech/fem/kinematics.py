"""Tensor algebra of one linear tetrahedron shared by the TLED kernels (scalar arguments, inlined by numba).

Symmetric tensors are passed and returned as six components in the order 11 22 33 12 23 13; the deformation
gradient ``F`` as nine components row by row.
"""
from __future__ import annotations

from numba import njit

#: LLVM fast-math flags of the kernels: reassociation and contraction (FMA) but IEEE NaN/inf semantics,
#: so that inverted or non-finite states are still detected
FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}


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
