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
def jacobi_eigen3(a11, a22, a33, a12, a23, a13):
    """Eigenvalues and unit eigenvectors of a symmetric 3x3 matrix by cyclic Jacobi rotations (Numerical
    Recipes 11.1), in the output order of :func:`symmetric_eigen3`. Exact for repeated eigenvalues (no division by
    eigenvalue gaps), but ~270 ns per matrix on the 2-core VM (three sweeps of three rotations, each a chain of
    divisions and square roots), whatever the gaps: :func:`symmetric_eigen3` calls it only for close eigenvalues.
    About 3x faster than LAPACK ``eigh`` through numba (call and workspace overhead dominate a 3x3 problem)."""
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


#: relative eigenvalue gap (smallest gap / spread) below which :func:`symmetric_eigen3` leaves the closed form
#: for Jacobi rotations: the closed-form eigenvectors are accurate to ~eps/gap, and at 0.05 the decomposition
#: reconstructs random matrices as closely as the rotations do (docs/fem_timing.md, "Ogden")
CLOSED_FORM_MIN_GAP = 0.05


@njit(cache=True, fastmath=FASTMATH, inline="always")
def _eigenvector_by_cross_product(d11, d22, d33, d12, d23, d13, mu):
    """Unit eigenvector of the symmetric ``D`` for its simple eigenvalue ``mu``: the longest of the three cross
    products of two rows of ``D - mu I`` (each is orthogonal to both rows, i.e. in the null space)."""
    r11, r22, r33 = d11 - mu, d22 - mu, d33 - mu
    ax, ay, az = d12 * d23 - d13 * r22, d13 * d12 - r11 * d23, r11 * r22 - d12 * d12  # row 1 x row 2
    bx, by, bz = d12 * r33 - d13 * d23, d13 * d13 - r11 * r33, r11 * d23 - d12 * d13  # row 1 x row 3
    cx, cy, cz = r22 * r33 - d23 * d23, d23 * d13 - d12 * r33, d12 * d23 - r22 * d13  # row 2 x row 3
    na, nb, nc = ax * ax + ay * ay + az * az, bx * bx + by * by + bz * bz, cx * cx + cy * cy + cz * cz
    if na >= nb and na >= nc:
        s = 1.0 / math.sqrt(na)
        return ax * s, ay * s, az * s
    if nb >= nc:
        s = 1.0 / math.sqrt(nb)
        return bx * s, by * s, bz * s
    s = 1.0 / math.sqrt(nc)
    return cx * s, cy * s, cz * s


@njit(cache=True, fastmath=FASTMATH)
def symmetric_eigen3(a11, a22, a33, a12, a23, a13):
    r"""Eigenvalues and unit eigenvectors of a symmetric 3x3 matrix ``A``:
    ``(l1, l2, l3, v11, v21, v31, v12, v22, v32, v13, v23, v33)`` with eigenvector ``k`` = ``(v1k, v2k, v3k)``.

    Closed form on the scaled deviator ``D = (A - m I) / s`` (``m = tr A / 3``, ``s`` its largest entry, so that
    a near-identity ``bbar`` loses no digits to the trace):

    .. math::

        J_2 = \tfrac12 \operatorname{tr} D^2, \quad J_3 = \det D, \quad
        \cos 3\theta = \frac{J_3}{2} \Big(\frac{3}{J_2}\Big)^{3/2}, \quad
        \mu_k = 2 \sqrt{J_2 / 3}\, \cos\big(\theta - 2\pi k / 3\big),

    eigenvalues ``m + s mu_k``; the eigenvectors of the largest and the smallest ``mu`` are cross products of two
    rows of ``D - mu I``, the second is made orthogonal to the first, and the middle one is their cross product.
    The cross products lose accuracy as ~eps/gap, so when the smallest eigenvalue gap is below
    :data:`CLOSED_FORM_MIN_GAP` of the spread (repeated or close eigenvalues, e.g. uniaxial or axisymmetric
    states) it returns :func:`jacobi_eigen3` instead. ~100 ns against Jacobi's ~270 ns per matrix (2-core VM).
    """
    m = (a11 + a22 + a33) / 3.0
    d11, d22, d33 = a11 - m, a22 - m, a33 - m
    s = max(abs(d11), abs(d22), abs(d33), abs(a12), abs(a23), abs(a13))
    if s == 0.0:
        return a11, a22, a33, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0
    inv = 1.0 / s
    d11, d22, d33, d12, d23, d13 = d11 * inv, d22 * inv, d33 * inv, a12 * inv, a23 * inv, a13 * inv
    j2 = 0.5 * (d11 * d11 + d22 * d22 + d33 * d33) + d12 * d12 + d23 * d23 + d13 * d13
    j3 = d11 * (d22 * d33 - d23 * d23) - d12 * (d12 * d33 - d23 * d13) + d13 * (d12 * d23 - d22 * d13)
    rho = math.sqrt(j2 / 3.0)
    cos3 = min(1.0, max(-1.0, 0.5 * j3 / (rho * rho * rho)))
    theta = math.acos(cos3) / 3.0
    mu1 = 2.0 * rho * math.cos(theta)
    mu3 = 2.0 * rho * math.cos(theta + 2.0 * math.pi / 3.0)
    mu2 = -mu1 - mu3
    if min(mu1 - mu2, mu2 - mu3) < CLOSED_FORM_MIN_GAP * (mu1 - mu3):
        return jacobi_eigen3(a11, a22, a33, a12, a23, a13)
    x1, y1, z1 = _eigenvector_by_cross_product(d11, d22, d33, d12, d23, d13, mu1)
    x3, y3, z3 = _eigenvector_by_cross_product(d11, d22, d33, d12, d23, d13, mu3)
    p = x1 * x3 + y1 * y3 + z1 * z3
    x3, y3, z3 = x3 - p * x1, y3 - p * y1, z3 - p * z1
    q = 1.0 / math.sqrt(x3 * x3 + y3 * y3 + z3 * z3)
    x3, y3, z3 = x3 * q, y3 * q, z3 * q
    x2, y2, z2 = y3 * z1 - z3 * y1, z3 * x1 - x3 * z1, x3 * y1 - y3 * x1
    return m + s * mu1, m + s * mu2, m + s * mu3, x1, y1, z1, x2, y2, z2, x3, y3, z3
