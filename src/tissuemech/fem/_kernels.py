"""Compiled TLED kernels (numba): the element and node passes, boundary conditions, contact, reactions, and the
two time loops :func:`explicit_loop` (central difference) and :func:`dynamic_relaxation_loop` (Joldes dynamic
relaxation), each one compiled function (no Python per step).

A numba kernel file, kept whole: the passes call each other and inline :mod:`.materials`' stress routines.
The method, the array layout and the Python API are described in :mod:`.tled`, which assembles the model and
calls the loops. numba's cache does not see changes of inlined code in another file, so after editing
``materials.py`` or the Pipkin-Rogers weight law (``models/beyond_qlv.py``) touch this module and
``vectorised.py`` (or clear ``NUMBA_CACHE_DIR``; the pipeline's source-keyed cache sees them).
"""
from __future__ import annotations

import math
from collections import namedtuple

import numpy as np
from numba import njit, prange

from ..models.beyond_qlv import pipkin_rogers_ratio, pipkin_rogers_strain_fraction
from ..models.recursion import relaxation_factors
from . import vectorised
from .kinematics import cofactor, determinant, left_cauchy_green, pull_back, push_forward
from .materials import FASTMATH, KIND_INVARIANT, KIND_SVK, j_minus_two_thirds, kirchhoff_deviatoric

STATUS_OK = 0
STATUS_INVERTED = 1
STATUS_NOT_FINITE = 2
STATUS_NOT_CONVERGED = 3

#: the arrays the loops take, grouped (numba passes namedtuples of arrays as one typed argument)
KernelMesh = namedtuple("KernelMesh", "X elements dndx vol0 chunk_lo vnode")
KernelMesh.__doc__ = """Reference nodes, elements, dN/dX, element volumes, element chunks, nodal volumes."""
KernelMaterial = namedtuple("KernelMaterial", "kind params kappa use_anp prony_g prony_tau pr_params")
KernelMaterial.__doc__ = """Law kind, law parameters, bulk modulus, ANP on/off, Prony g_i and tau_i, Pipkin-Rogers rows
``(beta_i, kappa_i, gamma_s^2)`` (none: QLV)."""
KernelLaws = namedtuple("KernelLaws", "w1fn w2fn wlfn")
KernelLaws.__doc__ = """The law's compiled functions dW/dI1, dW/dI2 and dW/dlambda."""
KernelLoads = namedtuple("KernelLoads", "bc_nodes bc_group bc_mask bc_dir bc_rotate rot_center n_groups free "
                                        "hist_time hist_vals fext_ref contact_kind cparams contact_nodes")
KernelLoads.__doc__ = """Boundary groups and their histories, free dofs, external load, rigid contact."""


@njit(cache=True, inline="always")
def YES():
    """``True`` typed as ``bool``, not as a literal (see :func:`_internal_forces`)."""
    return np.bool_(True)


@njit(cache=True, inline="always")
def NO():
    """``False`` typed as ``bool``, not as a literal (see :func:`_internal_forces`)."""
    return np.bool_(False)


# --------------------------------------------------------------------------------------------------
# compiled passes
# --------------------------------------------------------------------------------------------------
@njit(cache=True, fastmath=FASTMATH, inline="always")
def element_deformation_gradient(u, dndx, e, n0, n1, n2, n3):
    """``F = I + sum_a u_a (x) dN_a/dX`` of element ``e`` (nodes ``n0..n3``; ``dndx[e, 3 a + j]`` = ``dN_a/dX_j``,
    the generic kernel's row-per-element layout; the vectorised kernel's is
    ``vectorised.gathered_deformation_gradient``)."""
    ux0, ux1, ux2, ux3 = u[n0, 0], u[n1, 0], u[n2, 0], u[n3, 0]
    uy0, uy1, uy2, uy3 = u[n0, 1], u[n1, 1], u[n2, 1], u[n3, 1]
    uz0, uz1, uz2, uz3 = u[n0, 2], u[n1, 2], u[n2, 2], u[n3, 2]
    d0x, d0y, d0z = dndx[e, 0], dndx[e, 1], dndx[e, 2]
    d1x, d1y, d1z = dndx[e, 3], dndx[e, 4], dndx[e, 5]
    d2x, d2y, d2z = dndx[e, 6], dndx[e, 7], dndx[e, 8]
    d3x, d3y, d3z = dndx[e, 9], dndx[e, 10], dndx[e, 11]
    return (1.0 + ux0 * d0x + ux1 * d1x + ux2 * d2x + ux3 * d3x, ux0 * d0y + ux1 * d1y + ux2 * d2y + ux3 * d3y,
            ux0 * d0z + ux1 * d1z + ux2 * d2z + ux3 * d3z,
            uy0 * d0x + uy1 * d1x + uy2 * d2x + uy3 * d3x, 1.0 + uy0 * d0y + uy1 * d1y + uy2 * d2y + uy3 * d3y,
            uy0 * d0z + uy1 * d1z + uy2 * d2z + uy3 * d3z,
            uz0 * d0x + uz1 * d1x + uz2 * d2x + uz3 * d3x, uz0 * d0y + uz1 * d1y + uz2 * d2y + uz3 * d3y,
            1.0 + uz0 * d0z + uz1 * d1z + uz2 * d2z + uz3 * d3z)


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _anp_element_pass(u, elements, dndx, vol0, chunk_lo, pbuf, kappa, bad):
    """Accumulate ``kappa (J_e - 1) V0_e`` into per-chunk nodal pressure buffers."""
    nchunk = chunk_lo.size - 1
    for c in prange(nchunk):
        for e in range(chunk_lo[c], chunk_lo[c + 1]):
            n0, n1, n2, n3 = elements[e, 0], elements[e, 1], elements[e, 2], elements[e, 3]
            f11, f12, f13, f21, f22, f23, f31, f32, f33 = element_deformation_gradient(u, dndx, e, n0, n1, n2, n3)
            J = determinant(f11, f12, f13, f21, f22, f23, f31, f32, f33)
            if not J > 0.0:
                bad[c] = e
            pv = kappa * (J - 1.0) * vol0[e]
            pbuf[c, n0] += pv
            pbuf[c, n1] += pv
            pbuf[c, n2] += pv
            pbuf[c, n3] += pv


@njit(parallel=True, cache=True)
def _anp_node_pass(pbuf, vnode, p_node):
    nchunk = pbuf.shape[0]
    for n in prange(p_node.size):
        s = 0.0
        for c in range(nchunk):
            s += pbuf[c, n]
            pbuf[c, n] = 0.0
        p_node[n] = s / vnode[n]


@njit(cache=True, fastmath=FASTMATH, inline="always")
def pipkin_rogers_inverse_total(pr_params, nterm, x):
    """``(s, 1 / (1 + sum_j beta_j m_j))`` of the Pipkin-Rogers weight law at the strain measure ``x = I1bar - 3``
    (the fitting code's ``pipkin_rogers_strain_fraction`` and ``pipkin_rogers_ratio``); ``g_inf`` is the second
    value and ``g_i = pipkin_rogers_ratio(beta_i, kappa_i, s)`` times it. Shared by :func:`_element_force_pass` and
    :mod:`.cuda`."""
    s = pipkin_rogers_strain_fraction(x, pr_params[0, 2])
    total = 0.0
    for i in range(nterm):
        total += pipkin_rogers_ratio(pr_params[i, 0], pr_params[i, 1], s)
    return s, 1.0 / (1.0 + total)


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _element_force_pass(u, elements, dndx, vol0, chunk_lo, fbuf, kind, w1fn, w2fn, wlfn, params, kappa,
                        use_anp, p_node, prony_g, prony_e, prony_f, h_state, s_prev, pr_params, w_prev, commit, bad):
    """Internal nodal forces of all elements into per-chunk buffers ``fbuf[chunk, node, dof]``.

    QLV (``prony_g.size > 0``): isochoric 2nd PK ``S = g_inf S_e + sum_i h_i``, ``h_i`` advanced with the
    exact factors ``prony_e = exp(-dt/tau)``, ``prony_f = (1 - exp(-dt/tau))/(dt/tau)``; the new states are
    written only when ``commit`` (dynamic relaxation evaluates trial states without committing).
    Pipkin-Rogers (``pr_params`` with one row ``(beta_i, kappa_i, gamma_s^2)`` per term): the weights depend on
    ``x = I1bar - 3`` (:func:`pipkin_rogers_inverse_total`), ``S = g_inf(x) S_e + sum_i h_i`` with ``h_i`` driven
    by the increments of ``g_i(x) S_e``; ``s_prev`` holds the previous ``S_e`` and ``w_prev`` the previous ``g_i``.
    """
    nchunk = chunk_lo.size - 1
    nterm = prony_g.size
    g_inf = 1.0
    for i in range(nterm):
        g_inf -= prony_g[i]
    for c in prange(nchunk):
        for e in range(chunk_lo[c], chunk_lo[c + 1]):
            n0, n1, n2, n3 = elements[e, 0], elements[e, 1], elements[e, 2], elements[e, 3]
            f11, f12, f13, f21, f22, f23, f31, f32, f33 = element_deformation_gradient(u, dndx, e, n0, n1, n2, n3)
            c11, c12, c13, c21, c22, c23, c31, c32, c33, J = cofactor(f11, f12, f13, f21, f22, f23, f31, f32, f33)
            if not J > 0.0:
                bad[c] = e
                continue
            t11, t22, t33, t12, t23, t13 = kirchhoff_deviatoric(kind, w1fn, w2fn, wlfn, params, kappa,
                                                                f11, f12, f13, f21, f22, f23, f31, f32, f33, J)
            if nterm > 0:
                se0, se1, se2, se3, se4, se5 = pull_back(c11, c12, c13, c21, c22, c23, c31, c32, c33, J,
                                                         t11, t22, t33, t12, t23, t13)
                if pr_params.shape[0] > 0:
                    # Pipkin-Rogers: weights at x = I1bar - 3 (gamma^2 in simple shear), drive g_i(x) S_e
                    b11, b22, b33, b12, b23, b13 = left_cauchy_green(f11, f12, f13, f21, f22, f23, f31, f32, f33)
                    sfrac, winf = pipkin_rogers_inverse_total(pr_params, nterm,
                                                              j_minus_two_thirds(J) * (b11 + b22 + b33) - 3.0)
                    s0, s1, s2 = winf * se0, winf * se1, winf * se2
                    s3, s4, s5 = winf * se3, winf * se4, winf * se5
                    for i in range(nterm):
                        ee = prony_e[i]
                        ff = prony_f[i]
                        wb = pipkin_rogers_ratio(pr_params[i, 0], pr_params[i, 1], sfrac) * winf
                        wo = w_prev[e, i]
                        h0 = ee * h_state[e, i, 0] + ff * (wb * se0 - wo * s_prev[e, 0])
                        h1 = ee * h_state[e, i, 1] + ff * (wb * se1 - wo * s_prev[e, 1])
                        h2 = ee * h_state[e, i, 2] + ff * (wb * se2 - wo * s_prev[e, 2])
                        h3 = ee * h_state[e, i, 3] + ff * (wb * se3 - wo * s_prev[e, 3])
                        h4 = ee * h_state[e, i, 4] + ff * (wb * se4 - wo * s_prev[e, 4])
                        h5 = ee * h_state[e, i, 5] + ff * (wb * se5 - wo * s_prev[e, 5])
                        s0 += h0
                        s1 += h1
                        s2 += h2
                        s3 += h3
                        s4 += h4
                        s5 += h5
                        if commit:
                            h_state[e, i, 0] = h0
                            h_state[e, i, 1] = h1
                            h_state[e, i, 2] = h2
                            h_state[e, i, 3] = h3
                            h_state[e, i, 4] = h4
                            h_state[e, i, 5] = h5
                            w_prev[e, i] = wb
                else:
                    d0 = se0 - s_prev[e, 0]
                    d1 = se1 - s_prev[e, 1]
                    d2 = se2 - s_prev[e, 2]
                    d3 = se3 - s_prev[e, 3]
                    d4 = se4 - s_prev[e, 4]
                    d5 = se5 - s_prev[e, 5]
                    s0, s1, s2 = g_inf * se0, g_inf * se1, g_inf * se2
                    s3, s4, s5 = g_inf * se3, g_inf * se4, g_inf * se5
                    # the same six-component recursion as the Pipkin-Rogers branch above with constant weights: its
                    # drive g_i (S_e - S_prev); written out per component (registers)
                    for i in range(nterm):
                        ee = prony_e[i]
                        gf = prony_g[i] * prony_f[i]
                        h0 = ee * h_state[e, i, 0] + gf * d0
                        h1 = ee * h_state[e, i, 1] + gf * d1
                        h2 = ee * h_state[e, i, 2] + gf * d2
                        h3 = ee * h_state[e, i, 3] + gf * d3
                        h4 = ee * h_state[e, i, 4] + gf * d4
                        h5 = ee * h_state[e, i, 5] + gf * d5
                        s0 += h0
                        s1 += h1
                        s2 += h2
                        s3 += h3
                        s4 += h4
                        s5 += h5
                        if commit:
                            h_state[e, i, 0] = h0
                            h_state[e, i, 1] = h1
                            h_state[e, i, 2] = h2
                            h_state[e, i, 3] = h3
                            h_state[e, i, 4] = h4
                            h_state[e, i, 5] = h5
                if commit:  # both laws: the previous instantaneous stress S_e
                    s_prev[e, 0] = se0
                    s_prev[e, 1] = se1
                    s_prev[e, 2] = se2
                    s_prev[e, 3] = se3
                    s_prev[e, 4] = se4
                    s_prev[e, 5] = se5
                t11, t22, t33, t12, t23, t13 = push_forward(f11, f12, f13, f21, f22, f23, f31, f32, f33,
                                                            s0, s1, s2, s3, s4, s5)
            if kind != KIND_SVK:
                if use_anp:
                    pr = 0.25 * (p_node[n0] + p_node[n1] + p_node[n2] + p_node[n3])
                else:
                    pr = kappa * (J - 1.0)
                jp = J * pr
                t11 += jp
                t22 += jp
                t33 += jp
            # f_a = V0 tau (cof dN_a) / J
            sc = vol0[e] / J
            for a in range(4):
                dx, dy, dz = dndx[e, 3 * a], dndx[e, 3 * a + 1], dndx[e, 3 * a + 2]
                gx = (c11 * dx + c12 * dy + c13 * dz) * sc
                gy = (c21 * dx + c22 * dy + c23 * dz) * sc
                gz = (c31 * dx + c32 * dy + c33 * dz) * sc
                na = elements[e, a]
                fbuf[c, na, 0] += t11 * gx + t12 * gy + t13 * gz
                fbuf[c, na, 1] += t12 * gx + t22 * gy + t23 * gz
                fbuf[c, na, 2] += t13 * gx + t23 * gy + t33 * gz


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _reduce_forces(fbuf, fint):
    """``fint[n] = sum_chunks fbuf[chunk, n]`` and clear the buffers for the next pass."""
    nchunk = fbuf.shape[0]
    for n in prange(fint.shape[0]):
        for i in range(3):
            s = 0.0
            for c in range(nchunk):
                s += fbuf[c, n, i]
                fbuf[c, n, i] = 0.0
            fint[n, i] = s


@njit(cache=True)
def _first_bad(bad):
    for c in range(bad.size):
        if bad[c] >= 0:
            return bad[c]
    return -1


@njit(cache=True)
def _internal_forces(u, elements, dndx, vol0, chunk_lo, fbuf, pbuf, vnode, p_node, fint, kind, w1fn, w2fn,
                     wlfn, params, kappa, use_anp, prony_g, prony_e, prony_f, h_state, s_prev, pr_params, w_prev,
                     commit, bad, vec, reduce):
    """One complete internal-force evaluation (optional ANP passes + element pass + optional reduction
    into ``fint``; without it the forces stay in ``fbuf`` for a fused node pass).

    ``vec = (enabled, workspace, svk, constant, dW/dI1, dW/dI2)``: when enabled the vectorised passes
    (:func:`.vectorised.internal_forces`, QLV states in the workspace) compute the forces instead and
    ``fbuf`` is not used; without ``reduce`` they stay as element forces in the workspace for
    :func:`_cd_node_pass`. Returns the id of an inverted element or -1.

    The loops pass ``commit`` and ``reduce`` as :data:`NO`/:data:`YES` (typed ``bool``), never as literals: numba
    compiles a separate specialisation of a function for every literal value of an argument, and of everything
    it calls with it (with literals this stack was compiled three times, issue 17).
    """
    if vec[0]:
        return vectorised.internal_forces(u, vec[1], vec[2], vec[3], vec[4], vec[5], w1fn, w2fn, params,
                                          kind == KIND_INVARIANT, kappa, use_anp, prony_g, prony_e, prony_f,
                                          pr_params, commit, fint, reduce)
    bad[:] = -1
    if use_anp:
        _anp_element_pass(u, elements, dndx, vol0, chunk_lo, pbuf, kappa, bad)
        _anp_node_pass(pbuf, vnode, p_node)
    _element_force_pass(u, elements, dndx, vol0, chunk_lo, fbuf, kind, w1fn, w2fn, wlfn, params, kappa,
                        use_anp, p_node, prony_g, prony_e, prony_f, h_state, s_prev, pr_params, w_prev, commit, bad)
    if reduce:
        _reduce_forces(fbuf, fint)
    return _first_bad(bad)


@njit(cache=True)
def history_values(t, hist_time, hist_vals, out):
    for r in range(hist_vals.shape[0]):
        out[r] = np.interp(t, hist_time, hist_vals[r])


@njit(cache=True, inline="always")
def prescribed_displacement(s, theta, rotate, dir_x, dir_y, dir_z, x, y, center_x, center_y):
    """Prescribed displacement ``s d + [R_z(theta) (X - c) - (X - c)]`` of a node at ``(x, y)`` (the rotation term
    only when ``rotate``); shared by :func:`apply_bcs` and the CUDA node phase (:mod:`.cuda`)."""
    ux = s * dir_x
    uy = s * dir_y
    uz = s * dir_z
    if rotate:
        ct, st = math.cos(theta), math.sin(theta)
        rx, ry = x - center_x, y - center_y
        ux += ct * rx - st * ry - rx
        uy += st * rx + ct * ry - ry
    return ux, uy, uz


@njit(cache=True)
def apply_bcs(u, X, bc_nodes, bc_group, bc_mask, bc_dir, bc_rotate, rot_center, hv, n_groups):
    """Set prescribed dofs: ``u = s_g dir`` (+ rotation about z by angle theta_g around the group centre)."""
    for k in range(bc_nodes.size):
        n = bc_nodes[k]
        g = bc_group[k]
        ux, uy, uz = prescribed_displacement(hv[g], hv[n_groups + g], bc_rotate[k], bc_dir[k, 0], bc_dir[k, 1],
                                             bc_dir[k, 2], X[n, 0], X[n, 1], rot_center[g, 0], rot_center[g, 1])
        if bc_mask[k, 0]:
            u[n, 0] = ux
        if bc_mask[k, 1]:
            u[n, 1] = uy
        if bc_mask[k, 2]:
            u[n, 2] = uz


@njit(cache=True)
def group_reactions(fint, u, X, bc_nodes, bc_group, rot_center, force_out, torque_out):
    """Reaction force (sum of internal forces) and z-torque about the group centre, per group."""
    force_out[:] = 0.0
    torque_out[:] = 0.0
    for k in range(bc_nodes.size):
        n = bc_nodes[k]
        g = bc_group[k]
        fx, fy, fz = fint[n, 0], fint[n, 1], fint[n, 2]
        force_out[g, 0] += fx
        force_out[g, 1] += fy
        force_out[g, 2] += fz
        x = X[n, 0] + u[n, 0] - rot_center[g, 0]
        y = X[n, 1] + u[n, 1] - rot_center[g, 1]
        torque_out[g] += x * fy - y * fx


@njit(cache=True, inline="always")
def rigid_contact_move(px, py, pz, contact_kind, cparams):
    """``(dx, dy, dz, touching)``: the frictionless projection of a node at ``p`` (relative to the rigid body's
    current centre) onto the surface of a rigid sphere (kind 1), infinite cylinder (kind 2) or flat cylindrical
    punch (kind 3), zero when the node is outside (see :func:`contact_project`); shared with the CUDA node phase."""
    r = cparams[6]
    if contact_kind == 3:
        dx, dy, dz = cparams[3], cparams[4], cparams[5]
        ahead = px * dx + py * dy + pz * dz
        qx, qy, qz = px - ahead * dx, py - ahead * dy, pz - ahead * dz
        if ahead < 0.0 and qx * qx + qy * qy + qz * qz <= r * r * (1.0 + 1e-9):
            return -ahead * dx, -ahead * dy, -ahead * dz, True
        return 0.0, 0.0, 0.0, False
    if contact_kind == 2:
        ax, ay, az = cparams[7], cparams[8], cparams[9]
        along = px * ax + py * ay + pz * az
        px -= along * ax
        py -= along * ay
        pz -= along * az
    d = math.sqrt(px * px + py * py + pz * pz)
    if d < r and d > 0.0:
        fac = (r - d) / d
        return fac * px, fac * py, fac * pz, True
    return 0.0, 0.0, 0.0, False


@njit(cache=True)
def contact_project(u, X, contact_nodes, in_contact, contact_kind, cparams, s_contact):
    """Project nodes inside a rigid sphere (kind 1), infinite cylinder (kind 2) or flat cylindrical punch
    (kind 3) onto its surface.

    ``cparams = [c0x, c0y, c0z, dx, dy, dz, radius, ax, ay, az]``: centre at ``c0 + s d``; cylinder axis ``a``.
    The flat punch is the half-infinite cylinder of radius ``radius`` behind its face centre ``c0 + s d``
    (it advances along ``d``): a node within the radius that has fallen behind the face is moved back onto
    the face along ``d``. Frictionless: the projection is along the surface normal. Returns the number of
    nodes in contact.
    """
    cx = cparams[0] + s_contact * cparams[3]
    cy = cparams[1] + s_contact * cparams[4]
    cz = cparams[2] + s_contact * cparams[5]
    count = 0
    for k in range(contact_nodes.size):
        n = contact_nodes[k]
        dx, dy, dz, touching = rigid_contact_move(X[n, 0] + u[n, 0] - cx, X[n, 1] + u[n, 1] - cy,
                                                  X[n, 2] + u[n, 2] - cz, contact_kind, cparams)
        u[n, 0] += dx
        u[n, 1] += dy
        u[n, 2] += dz
        in_contact[k] = 1 if touching else 0
        count += 1 if touching else 0
    return count


@njit(cache=True)
def contact_force(fint, contact_nodes, in_contact, out):
    out[:] = 0.0
    for k in range(contact_nodes.size):
        if in_contact[k]:
            n = contact_nodes[k]
            out[0] += fint[n, 0]
            out[1] += fint[n, 1]
            out[2] += fint[n, 2]


@njit(cache=True)
def central_difference_coefficients(mass, damping, dt):
    """Per-node coefficients ``(a, b, c)`` of the central-difference update with mass-proportional damping
    (:func:`central_difference_dof`): ``a = 1 / (m/dt^2 + D m/(2 dt))``, ``b = 2 m a / dt^2``,
    ``c = D m a / (2 dt) - b / 2``."""
    nn = mass.size
    coef_a = np.empty(nn)
    coef_b = np.empty(nn)
    coef_c = np.empty(nn)
    for n in range(nn):
        m = mass[n]
        a = 1.0 / (m / dt**2 + damping * m / (2.0 * dt))
        coef_a[n] = a
        coef_b[n] = 2.0 * m * a / dt**2
        coef_c[n] = damping * m * a / (2.0 * dt) - 0.5 * coef_b[n]
    return coef_a, coef_b, coef_c


@njit(cache=True, fastmath=FASTMATH, inline="always")
def central_difference_dof(a, b, c, f_ext, f_int, u, u_old):
    """Next displacement of one free dof: ``a (f_ext - f_int) + b u + c u_old`` (coefficients of
    :func:`central_difference_coefficients`)."""
    return a * (f_ext - f_int) + b * u + c * u_old


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _cd_node_pass(fbuf, fint, fext_ref, s_ext, u, u_old, u_new, coef_a, coef_b, coef_c, free, vec):
    """Collect the internal forces into ``fint`` (reduce the chunk force buffers and clear them, or with
    the vectorised kernel gather the element forces of the workspace) and advance the free dofs."""
    nchunk = fbuf.shape[0]
    gather = vec[0]
    ws = vec[1]
    node_ptr, inc_slot, fe_flat, ne = ws[3], ws[5], ws[12].reshape(-1), ws[12].shape[1]
    for n in prange(u.shape[0]):
        if gather:
            fint[n, 0], fint[n, 1], fint[n, 2] = vectorised.node_force(fe_flat, node_ptr, inc_slot, ne, n)
        a, b, cc = coef_a[n], coef_b[n], coef_c[n]
        for i in range(3):
            if nchunk > 0:
                f = 0.0
                for c in range(nchunk):
                    f += fbuf[c, n, i]
                    fbuf[c, n, i] = 0.0
                fint[n, i] = f
            else:
                f = fint[n, i]
            if free[n, i]:
                u_new[n, i] = central_difference_dof(a, b, cc, s_ext * fext_ref[n, i], f, u[n, i], u_old[n, i])
            else:
                u_new[n, i] = u[n, i]


@njit(cache=True)
def energy_increments(u_new, u, u_old, fint, fext_ref, s_ext, mass, damping, dt, acc):
    """Add one central-difference step's energy increments to ``acc``.

    With ``dc = (u_new - u_old)/2`` (the displacement over the step centred at ``u``):
    ``acc[0]`` internal work ``sum f_int . dc`` (equals the stored energy for a conservative law),
    ``acc[1]`` work of the applied loads, ``acc[2]`` mass-proportional damping dissipation
    ``alpha m |dc|^2 / dt`` (all dofs: a prescribed node's drag is carried by its support), ``acc[3]`` work of the kinematic constraints (prescribed dofs
    and contact projection): the force ``m a + alpha m v + f_int - f_ext`` they exert, times ``dc``.
    Discretely, ``KE_(n+1/2) - KE_(1/2) + W_int + W_damp = W_ext + W_constraint`` holds for the
    update actually performed, so the balance checks the integrator against the damping law it claims.
    """
    idt2 = 1.0 / (dt * dt)
    for n in range(u.shape[0]):
        m = mass[n]
        for i in range(3):
            dc = 0.5 * (u_new[n, i] - u_old[n, i])
            fe = s_ext * fext_ref[n, i]
            acc[0] += fint[n, i] * dc
            damp = damping * m * dc / dt
            acc[1] += fe * dc
            acc[2] += damp * dc
            r = m * (u_new[n, i] - 2.0 * u[n, i] + u_old[n, i]) * idt2 + damp + fint[n, i] - fe
            # free dofs carry no constraint force except where the contact projection moved them
            acc[3] += r * dc
    return acc


@njit(cache=True)
def record_explicit_output(k_out, t, u, u_old, fint, mass, dt, energy, X, bc_nodes, bc_group, rot_center,
                           contact_nodes, in_contact, force_g, torque_g, cforce, out_t, out_energy, out_force,
                           out_torque, out_contact, out_ke):
    """Store output ``k_out`` of an explicit run (time, energy terms, group reactions and torques, contact force,
    kinetic energy ``sum m v^2 / 2`` with ``v = (u - u_old)/dt``); False (nothing stored) when the kinetic energy
    is not finite. Shared by :func:`explicit_loop` and the fused loop (:mod:`.fused`)."""
    group_reactions(fint, u, X, bc_nodes, bc_group, rot_center, force_g, torque_g)
    contact_force(fint, contact_nodes, in_contact, cforce)
    ke = 0.0
    for n in range(u.shape[0]):
        for i in range(3):
            v = (u[n, i] - u_old[n, i]) / dt
            ke += 0.5 * mass[n] * v * v
    if not np.isfinite(ke):
        return False
    out_t[k_out] = t
    out_energy[k_out] = energy
    out_force[k_out] = force_g
    out_torque[k_out] = torque_g
    out_contact[k_out] = cforce
    out_ke[k_out] = ke
    return True


@njit(cache=True)
def constrain_explicit_step(u_new, u, u_old, fint, fext_ref, s_ext, mass, damping, dt, X, bc_nodes, bc_group, bc_mask,
                            bc_dir, bc_rotate, rot_center, hv, n_groups, contact_kind, contact_nodes, in_contact,
                            cparams, track_energy, energy):
    """After the node update of an explicit step: prescribed displacements, rigid-contact projection and (with
    ``track_energy``) the energy increments of the step. Shared by :func:`explicit_loop` and :mod:`.fused`."""
    apply_bcs(u_new, X, bc_nodes, bc_group, bc_mask, bc_dir, bc_rotate, rot_center, hv, n_groups)
    if contact_kind > 0:
        contact_project(u_new, X, contact_nodes, in_contact, contact_kind, cparams, hv[2 * n_groups])
    if track_energy:
        energy_increments(u_new, u, u_old, fint, fext_ref, s_ext, mass, damping, dt, energy)


@njit(cache=True)
def explicit_loop(mesh, mat, laws, loads, mass, h_state, s_prev, w_prev, dt, n_steps, damping, out_every, u, u_old,
                  fbuf, pbuf, track_energy, vec):
    """Central-difference time loop. ``u``/``u_old`` hold the state at steps 0 and -1 on entry and the
    last two states on exit (``u`` newest). ``mesh``, ``mat``, ``laws``, ``loads``: :class:`KernelMesh`,
    :class:`KernelMaterial`, :class:`KernelLaws`, :class:`KernelLoads`; ``mass``: lumped nodal masses."""
    # the unpacking and workspace below repeat the other time loop's: each loop is one compiled function, and a
    # helper returning some twenty arrays would be no clearer
    X, elements, dndx, vol0, chunk_lo, vnode = mesh
    kind, params, kappa, use_anp, prony_g, prony_tau, pr_params = mat
    w1fn, w2fn, wlfn = laws
    (bc_nodes, bc_group, bc_mask, bc_dir, bc_rotate, rot_center, n_groups, free, hist_time, hist_vals, fext_ref,
     contact_kind, cparams, contact_nodes) = loads
    nn = X.shape[0]
    n_out = n_steps // out_every + 2  # every out_every-th step and always the last one
    out_t = np.zeros(n_out)
    out_force = np.zeros((n_out, n_groups, 3))
    out_torque = np.zeros((n_out, n_groups))
    out_contact = np.zeros((n_out, 3))
    out_ke = np.zeros(n_out)
    out_energy = np.zeros((n_out, 4))
    energy = np.zeros(4)
    fint = np.zeros((nn, 3), dtype=u.dtype)
    u_new = np.empty_like(u)
    p_node = np.zeros(nn)
    hv = np.zeros(hist_vals.shape[0])
    in_contact = np.zeros(contact_nodes.size, dtype=np.uint8)
    bad = np.full(chunk_lo.size - 1, -1, dtype=np.int64)
    force_g = np.zeros((n_groups, 3))
    torque_g = np.zeros(n_groups)
    cforce = np.zeros(3)
    coef_a, coef_b, coef_c = central_difference_coefficients(mass, damping, dt)
    nterm = prony_g.size
    prony_e = np.empty(nterm)
    prony_f = np.empty(nterm)
    for i in range(nterm):
        prony_e[i], prony_f[i] = relaxation_factors(dt, prony_tau[i])
    k_out = 0
    for step in range(n_steps + 1):
        t = step * dt
        bad_e = _internal_forces(u, elements, dndx, vol0, chunk_lo, fbuf, pbuf, vnode, p_node, fint, kind,
                                 w1fn, w2fn, wlfn, params, kappa, use_anp, prony_g, prony_e, prony_f, h_state,
                                 s_prev, pr_params, w_prev, YES(), bad, vec, NO())
        if bad_e >= 0:
            return STATUS_INVERTED, bad_e, step, u, u_old, out_t[:k_out], out_force[:k_out], \
                out_torque[:k_out], out_contact[:k_out], out_ke[:k_out], out_energy[:k_out]
        # the balance at step n uses the loads at t_n; the prescribed motions are needed at t_(n+1)
        history_values(t, hist_time, hist_vals, hv)
        s_ext = hv[2 * n_groups + 1]
        history_values(t + dt, hist_time, hist_vals, hv)
        # reduces fbuf into fint and computes u_new on the free dofs
        _cd_node_pass(fbuf, fint, fext_ref, s_ext, u, u_old, u_new, coef_a, coef_b, coef_c, free, vec)
        if step % out_every == 0 or step == n_steps:
            if not record_explicit_output(k_out, t, u, u_old, fint, mass, dt, energy, X, bc_nodes, bc_group,
                                          rot_center, contact_nodes, in_contact, force_g, torque_g, cforce, out_t,
                                          out_energy, out_force, out_torque, out_contact, out_ke):
                return STATUS_NOT_FINITE, -1, step, u, u_old, out_t[:k_out], out_force[:k_out], \
                    out_torque[:k_out], out_contact[:k_out], out_ke[:k_out], out_energy[:k_out]
            k_out += 1
        if step == n_steps:
            break
        constrain_explicit_step(u_new, u, u_old, fint, fext_ref, s_ext, mass, damping, dt, X, bc_nodes, bc_group,
                                bc_mask, bc_dir, bc_rotate, rot_center, hv, n_groups, contact_kind, contact_nodes,
                                in_contact, cparams, track_energy, energy)
        u_old, u, u_new = u, u_new, u_old
    return STATUS_OK, -1, n_steps, u, u_old, out_t[:k_out], out_force[:k_out], out_torque[:k_out], \
        out_contact[:k_out], out_ke[:k_out], out_energy[:k_out]


@njit(cache=True, fastmath=FASTMATH, inline="always")
def dynamic_relaxation_dof(u, u_old, beta, alpha_over_mass, f_ext, f_int):
    """Next iterate of one free dof in dynamic relaxation: ``u + beta (u - u_old) + alpha/m (f_ext - f_int)``
    (shared by :func:`_dr_node_pass` and the CUDA relaxation kernel)."""
    return u + beta * (u - u_old) + alpha_over_mass * (f_ext - f_int)


@njit(cache=True, inline="always")
def relaxation_coefficients(lam_min):
    """``(alpha, beta)`` of the dynamic-relaxation update for the lowest-mode estimate ``lam_min`` (unit step, largest
    eigenvalue 1): damping ``c = 2 sqrt(lam_min)``, ``alpha = 2 / (2 + c)``, ``beta = (2 - c) / (2 + c)``."""
    c = 2.0 * math.sqrt(lam_min)
    return 2.0 / (2.0 + c), (2.0 - c) / (2.0 + c)


@njit(cache=True, inline="always")
def relaxation_error_bound(lam_min, lam_max, dmax):
    """Joldes et al.'s bound ``rho / (1 - rho) ||du||_inf`` on the distance to equilibrium, with the convergence rate
    ``rho = (1 - sqrt(lam_min/lam_max)) / (1 + sqrt(lam_min/lam_max))``."""
    sq = math.sqrt(lam_min / lam_max)
    rho = (1.0 - sq) / (1.0 + sq)
    return rho / (1.0 - rho) * dmax


#: dynamic relaxation stops after this many consecutive iterations with the error bound under the tolerance
RELAXATION_CALM_ITERATIONS = 3


@njit(cache=True, inline="always")
def relaxation_calm_iterations(n_calm, iteration, min_iter, err, tol_m):
    """Consecutive iterations so far with the error bound ``err`` under ``tol_m`` (counted from ``min_iter`` on; the
    run stops at :data:`RELAXATION_CALM_ITERATIONS`); shared by :func:`dynamic_relaxation_loop` and :mod:`.cuda`."""
    return n_calm + 1 if iteration >= min_iter and err < tol_m else 0


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _dr_node_pass(fint, fext_ref, s_ext, u, u_old, u_new, inv_mass, alpha, beta, free):
    for n in prange(u.shape[0]):
        am = alpha * inv_mass[n]
        for i in range(3):
            if free[n, i]:
                u_new[n, i] = dynamic_relaxation_dof(u[n, i], u_old[n, i], beta, am, s_ext * fext_ref[n, i],
                                                     fint[n, i])
            else:
                u_new[n, i] = u[n, i]


@njit(cache=True)
def dynamic_relaxation_loop(mesh, mat, laws, loads, dr_mass, h_state, s_prev, w_prev, times, tol_m, min_iter, max_iter,
                            u, fbuf, pbuf, vec):
    """Dynamic relaxation to static equilibrium at each time in ``times`` (quasi-static loading path).

    Unit fictitious time step; ``dr_mass`` makes every element's stable step ~2 (lambda_max ~ 1). The
    viscoelastic states advance between consecutive times with ``dt = times[k] - times[k-1]`` and are
    committed after convergence. Returns status, failing increment, iterations used per increment and
    the reactions/torques/contact forces per increment.

    Each increment starts from the linear extrapolation of the two previous equilibria in time (free dofs; the
    unloaded reference state at ``t = 0`` counts as one when the run starts from it), so that only the nonlinear
    part of the change is relaxed (issue 17: about half the iterations of the later increments).
    """
    # the unpacking and workspace below repeat the other time loop's: each loop is one compiled function, and a
    # helper returning some twenty arrays would be no clearer
    X, elements, dndx, vol0, chunk_lo, vnode = mesh
    kind, params, kappa, use_anp, prony_g, prony_tau, pr_params = mat
    w1fn, w2fn, wlfn = laws
    (bc_nodes, bc_group, bc_mask, bc_dir, bc_rotate, rot_center, n_groups, free, hist_time, hist_vals, fext_ref,
     contact_kind, cparams, contact_nodes) = loads
    nn = X.shape[0]
    nk = times.size
    out_force = np.zeros((nk, n_groups, 3))
    out_torque = np.zeros((nk, n_groups))
    out_contact = np.zeros((nk, 3))
    iters = np.zeros(nk, dtype=np.int64)
    fint = np.zeros((nn, 3), dtype=u.dtype)
    fint_prev = np.zeros((nn, 3), dtype=u.dtype)
    u_old = u.copy()
    u_new = u.copy()
    p_node = np.zeros(nn)
    hv = np.zeros(hist_vals.shape[0])
    in_contact = np.zeros(contact_nodes.size, dtype=np.uint8)
    bad = np.full(chunk_lo.size - 1, -1, dtype=np.int64)
    force_g = np.zeros((n_groups, 3))
    torque_g = np.zeros(n_groups)
    cforce = np.zeros(3)
    inv_mass = 1.0 / dr_mass
    nterm = prony_g.size
    prony_e = np.empty(nterm)
    prony_f = np.empty(nterm)
    lam_max = 1.0
    t_prev = 0.0
    # the previous equilibrium before u (for the extrapolated start): the reference state at t = 0 when the run
    # starts there, unloaded (zero displacement, zero histories at t = 0)
    u_eq = u.copy()
    t_eq = 0.0
    lam_prev = lam_max
    history_values(0.0, hist_time, hist_vals, hv)
    have_eq = times.size > 0 and np.all(u == 0.0) and np.all(hv[:2 * n_groups + 1] == 0.0) \
        and (hv[2 * n_groups + 1] == 0.0 or np.all(fext_ref == 0.0))
    for k in range(nk):
        dt = times[k] - t_prev
        if have_eq and t_prev > t_eq and dt > 0.0:
            r = dt / (t_prev - t_eq)
            for n in range(nn):
                for i in range(3):
                    du = u[n, i] - u_eq[n, i]
                    u_eq[n, i] = u[n, i]
                    if free[n, i]:
                        u[n, i] += r * du
        else:
            u_eq[:] = u
        t_eq = t_prev
        have_eq = True
        for i in range(nterm):
            if dt > 0.0:
                prony_e[i], prony_f[i] = relaxation_factors(dt, prony_tau[i])
            else:
                prony_e[i], prony_f[i] = 1.0, 1.0
        history_values(times[k], hist_time, hist_vals, hv)
        apply_bcs(u, X, bc_nodes, bc_group, bc_mask, bc_dir, bc_rotate, rot_center, hv, n_groups)
        if contact_kind > 0:
            contact_project(u, X, contact_nodes, in_contact, contact_kind, cparams, hv[2 * n_groups])
        u_old[:] = u
        lam_min = 1e-6
        alpha, beta = relaxation_coefficients(lam_min)
        n_ok = 0
        converged = False
        it = 0
        while it < max_iter:
            bad_e = _internal_forces(u, elements, dndx, vol0, chunk_lo, fbuf, pbuf, vnode, p_node, fint, kind,
                                     w1fn, w2fn, wlfn, params, kappa, use_anp, prony_g, prony_e, prony_f,
                                     h_state, s_prev, pr_params, w_prev, NO(), bad, vec, YES())
            if bad_e >= 0:
                return STATUS_INVERTED, bad_e, k, u, iters, out_force, out_torque, out_contact
            if it > 0:
                # Rayleigh quotient of the last increment: lowest-mode estimate (Joldes et al. 2011)
                num = 0.0
                den = 0.0
                for n in range(nn):
                    for i in range(3):
                        if free[n, i]:
                            du = u[n, i] - u_old[n, i]
                            num += du * (fint[n, i] - fint_prev[n, i])
                            den += du * du * dr_mass[n]
                if den > 0.0 and num > 0.0:
                    est = num / den
                    if est < lam_max:
                        lam_min = est
                        alpha, beta = relaxation_coefficients(lam_min)
            _dr_node_pass(fint, fext_ref, hv[2 * n_groups + 1], u, u_old, u_new, inv_mass, alpha, beta, free)
            if contact_kind > 0:
                contact_project(u_new, X, contact_nodes, in_contact, contact_kind, cparams, hv[2 * n_groups])
            dmax = 0.0
            for n in range(nn):
                for i in range(3):
                    d = abs(u_new[n, i] - u[n, i])
                    if d > dmax:
                        dmax = d
            if not np.isfinite(dmax):
                return STATUS_NOT_FINITE, -1, k, u, iters, out_force, out_torque, out_contact
            # the error bound takes the smaller of this increment's estimate and the previous increment's final one:
            # from an extrapolated start the first Rayleigh quotients see only high modes and would stop too early
            err = relaxation_error_bound(min(lam_min, lam_prev), lam_max, dmax)
            fint_prev, fint = fint, fint_prev
            u_old, u, u_new = u, u_new, u_old
            it += 1
            n_ok = relaxation_calm_iterations(n_ok, it, min_iter, err, tol_m)
            if n_ok >= RELAXATION_CALM_ITERATIONS:
                converged = True
                break
        iters[k] = it
        lam_prev = lam_min
        if not converged:
            return STATUS_NOT_CONVERGED, -1, k, u, iters, out_force, out_torque, out_contact
        # commit viscoelastic states at the converged configuration and record reactions
        _internal_forces(u, elements, dndx, vol0, chunk_lo, fbuf, pbuf, vnode, p_node, fint, kind, w1fn, w2fn,
                         wlfn, params, kappa, use_anp, prony_g, prony_e, prony_f, h_state, s_prev, pr_params, w_prev,
                         YES(), bad, vec, YES())
        group_reactions(fint, u, X, bc_nodes, bc_group, rot_center, force_g, torque_g)
        contact_force(fint, contact_nodes, in_contact, cforce)
        out_force[k] = force_g
        out_torque[k] = torque_g
        out_contact[k] = cforce
        t_prev = times[k]
    return STATUS_OK, -1, nk, u, iters, out_force, out_torque, out_contact
