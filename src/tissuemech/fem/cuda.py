"""Optional numba-cuda TLED solver: explicit central difference and dynamic relaxation on a GPU.

Scope: Saint Venant-Kirchhoff and every invariant law ``W(I1bar, I2bar)`` of the fitting code, alone, as the
instantaneous law of QLV or of Pipkin-Rogers (strain-dependent weights) with any number of Prony terms; optional average
nodal pressure (ANP); prescribed displacement / rotation groups, fixed nodes, external nodal loads and frictionless
rigid contact (sphere, cylinder, flat punch); reaction forces and torques per group, contact force and kinetic energy
at the outputs; element inversion reported as on the CPU. Not on the GPU (use :mod:`.tled`): stretch-based laws
(Ogden: a 3x3 eigen-decomposition per element) and the energy balance of explicit runs.

**One definition of every formula.** The kernels call the CPU kernels' own numba functions (numba-cuda compiles
``@njit`` functions for the device): the deformation gradient, cofactor, stress and pull-back of
:mod:`.kinematics`, :mod:`.materials` and :mod:`.vectorised`, the fitting code's law derivatives
(:func:`.vectorised.law_derivatives`), the Prony recursion (:func:`.vectorised.prony_update`), the nodal force and
pressure gathers in the same summation order (:func:`.vectorised.node_force`, :func:`.vectorised.nodal_pressure`),
the central-difference and dynamic-relaxation updates, prescribed motions and contact projection of
:mod:`._kernels`. The storage precision follows the model (float32 halves the traffic); the element arithmetic
follows the CPU's typing of the same functions. In float64 the GPU agrees with the CPU kernel to rounding.

Layout (``fem.md`` section 7): element-major arrays (``d9`` ``(9, n_el)``: ``dN_a/dX`` of local nodes 1-3,
element forces ``(12, n_el)``, QLV states ``(6 n_terms, n_el)``) so that consecutive threads touch consecutive
addresses; nodes gather their element forces through the CPU's CSR incidence list (:func:`.vectorised.node_incidence`;
no atomics, results independent of the thread schedule). Every kernel is **persistent and cooperative**: grid-stride
loops over elements and nodes with ``grid.sync()`` between the phases, so a batch of explicit steps, or a whole
dynamic-relaxation increment, is one launch (launch latency from Python is tens of microseconds, longer than a step of
a 10k-tet mesh). Global sums (Rayleigh quotient, largest update, reactions) are deterministic: each block reduces its
share in shared memory in a fixed order, and every block then reduces the block partials in the same order.

The module imports without a GPU; :func:`available` says whether a CUDA device is usable. The kernels also run in
numba's CUDA simulator (``NUMBA_ENABLE_CUDASIM=1``; one block, so use a small ``threads_per_block``), which the tests
use.
"""
from __future__ import annotations

import functools
import math
import time
from collections import namedtuple

import numpy as np

from ..models.recursion import relaxation_factors
from ..models.beyond_qlv import pipkin_rogers_ratio
from ._kernels import (RELAXATION_CALM_ITERATIONS, central_difference_coefficients, central_difference_dof,
                       dynamic_relaxation_dof, prescribed_displacement, relaxation_calm_iterations,
                       relaxation_coefficients, relaxation_error_bound)
from ._kernels import pipkin_rogers_inverse_total as _pipkin_rogers_inverse_total
from ._kernels import rigid_contact_move as _rigid_contact_move
from .kinematics import cofactor, determinant, left_cauchy_green, pull_back, push_forward
from .materials import KIND_INVARIANT, KIND_INVARIANT_I1, KIND_SVK, j_minus_two_thirds, svk_kirchhoff
from .tled import (DynamicRelaxationError, ElementInversionError, RunResult, TLEDModel, caller_states,
                   critical_time_step, initial_states)
from .vectorised import gathered_deformation_gradient as _gathered_deformation_gradient
from .vectorised import isochoric_kirchhoff, nodal_forces, node_incidence, prony_update
from .vectorised import law_derivatives as _law_derivatives
from .vectorised import nodal_pressure as _nodal_pressure
from .vectorised import node_force as _node_force
from .vectorised import store_nodal_forces as _store_nodal_forces

try:  # the GPU path is optional
    from numba import cuda, float64 as _f64
except ImportError:  # pragma: no cover - numba-cuda missing
    cuda = None

#: the explicit kernel's inversion flag before any element inverted
_NO_ELEMENT = np.iinfo(np.int64).max
#: dynamic-relaxation increment outcomes (``_DeviceProblem.relax``)
DR_CONVERGED, DR_NOT_CONVERGED, DR_INVERTED, DR_NOT_FINITE = 0, 1, 2, 3


def available() -> bool:
    """True when numba can use a CUDA device (or the CUDA simulator is enabled)."""
    if cuda is None:
        return False
    try:
        return bool(cuda.is_available())
    except Exception:  # noqa: BLE001 - driver problems mean "not available"
        return False


def _is_simulator() -> bool:
    from numba import config

    return bool(config.ENABLE_CUDASIM)


def unsupported_reason(model: TLEDModel) -> str | None:
    """Why the GPU cannot run ``model`` (None when it can)."""
    if model.material.kind not in (KIND_INVARIANT, KIND_INVARIANT_I1, KIND_SVK):
        return ("the CUDA kernels run Saint Venant-Kirchhoff and invariant laws; stretch-based laws (Ogden: an "
                "eigen-decomposition per element) run on the CPU solver (tissuemech.fem.tled)")
    if model.material.kind == KIND_SVK and model.material.prony_g.size:
        return "QLV on Saint Venant-Kirchhoff runs on the CPU solver only (tissuemech.fem.tled)"
    return None


# --------------------------------------------------------------------------------------------------
# kernels: one compiled set per law, variant and block size
# --------------------------------------------------------------------------------------------------
@functools.lru_cache(maxsize=None)
def _kernels(w1, w2, kind: int, use_anp: bool, n_terms: int, beyond: bool, contact_kind: int,
             threads: int, max_registers: int | None):
    """Compile-time specialisation of the device code: law functions ``w1``, ``w2``, law kind, ANP, number of
    relaxation terms, Pipkin-Rogers weights (``beyond``), contact shape, block size (a power of 2: the shared-memory
    reductions) and the register limit of the cooperative kernels (None: the compiler's choice). Returns the kernels
    as a dict."""
    svk = kind == KIND_SVK
    i2_dependent = kind == KIND_INVARIANT
    # the simulator runs the kernels as Python, where a compiled CPU function cannot take a simulated device array:
    # there the functions that take arrays (and the laws, which take the parameter array) run as Python too
    python = _is_simulator()
    w1, w2 = (f.py_func for f in (w1, w2)) if python else (w1, w2)
    (gathered_deformation_gradient, law_derivatives, nodal_pressure, node_force, store_nodal_forces,
     rigid_contact_move, pipkin_rogers_inverse_total) = (f.py_func if python else f for f in (
         _gathered_deformation_gradient, _law_derivatives, _nodal_pressure, _node_force, _store_nodal_forces,
         _rigid_contact_move, _pipkin_rogers_inverse_total))

    @cuda.jit(device=True)
    def block_reduce(sm, value, take_max):
        """Sum (or maximum) of ``value`` over the block, the same fixed-order tree in every block."""
        t = cuda.threadIdx.x
        sm[t] = value
        cuda.syncthreads()
        s = threads // 2
        while s > 0:
            if t < s:
                if take_max:
                    if sm[t + s] > sm[t]:
                        sm[t] = sm[t + s]
                else:
                    sm[t] += sm[t + s]
            cuda.syncthreads()
            s //= 2
        total = sm[0]
        cuda.syncthreads()
        return total

    @cuda.jit(device=True)
    def partials_reduce(sm, partials, row, take_max):
        """Sum (or maximum) of the per-block partials of ``row``: every block reduces them in the same order, so every
        block gets the identical total."""
        acc = 0.0
        for b in range(cuda.threadIdx.x, partials.shape[1], threads):
            if take_max:
                if partials[row, b] > acc:
                    acc = partials[row, b]
            else:
                acc += partials[row, b]
        return block_reduce(sm, acc, take_max)

    @cuda.jit(device=True)
    def element_pressure_phase(tid, stride, u, conn, d9, vol0, kappa, pe):
        for e in range(tid, vol0.size, stride):
            f11, f12, f13, f21, f22, f23, f31, f32, f33 = gathered_deformation_gradient(u, conn, d9, e)
            pe[e] = kappa * (determinant(f11, f12, f13, f21, f22, f23, f31, f32, f33) - 1.0) * vol0[e]

    @cuda.jit(device=True)
    def nodal_pressure_phase(tid, stride, pe, node_ptr, inc_elem, inv_vnode, p_node):
        for n in range(tid, p_node.size, stride):
            p_node[n] = nodal_pressure(pe, node_ptr, inc_elem, inv_vnode, n)

    @cuda.jit(device=True)
    def element_force_phase(tid, stride, key0, u, conn, d9, vol0, p_node, params, kappa, pr_params, g_inf, decay,
                            gain, sprev, hstate, wprev, commit, fel, bad):
        """Element nodal forces into ``fel`` (the CPU kernels' formulas); QLV / Pipkin-Rogers states advance (written
        only when ``commit``); an inverted element sets ``bad`` to ``key0 + e`` (smallest wins) and gets no
        force."""
        ne = vol0.size
        for e in range(tid, ne, stride):
            f11, f12, f13, f21, f22, f23, f31, f32, f33 = gathered_deformation_gradient(u, conn, d9, e)
            c11, c12, c13, c21, c22, c23, c31, c32, c33, J = cofactor(f11, f12, f13, f21, f22, f23, f31, f32, f33)
            if not J > 0.0:
                cuda.atomic.min(bad, 0, key0 + e)
                store_nodal_forces(e, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, fel[0], fel[1], fel[2], fel[3],
                                   fel[4], fel[5], fel[6], fel[7], fel[8], fel[9], fel[10], fel[11])
                continue
            b11, b22, b33, b12, b23, b13 = left_cauchy_green(f11, f12, f13, f21, f22, f23, f31, f32, f33)
            if svk:
                t11, t22, t33, t12, t23, t13 = svk_kirchhoff(params[0], kappa - 2.0 * params[0] / 3.0,
                                                             b11, b22, b33, b12, b23, b13)
            else:
                jm23 = j_minus_two_thirds(J)
                w1v, w2v = law_derivatives(w1, w2, params, i2_dependent, jm23, b11, b22, b33, b12, b23, b13)
                t11, t22, t33, t12, t23, t13 = isochoric_kirchhoff(w1v, w2v, jm23, b11, b22, b33, b12, b23, b13)
                if n_terms > 0:
                    se0, se1, se2, se3, se4, se5 = pull_back(c11, c12, c13, c21, c22, c23, c31, c32, c33, J,
                                                             t11, t22, t33, t12, t23, t13)
                    if beyond:
                        # Pipkin-Rogers (_kernels._element_force_pass): weights at x = I1bar - 3, drive increments
                        # g_i(x) S_e - g_i,prev S_prev, S = g_inf(x) S_e + sum h_i
                        sfrac, winf = pipkin_rogers_inverse_total(pr_params, n_terms,
                                                                  jm23 * (b11 + b22 + b33) - 3.0)
                        s0, s1, s2 = winf * se0, winf * se1, winf * se2
                        s3, s4, s5 = winf * se3, winf * se4, winf * se5
                        for i in range(n_terms):
                            wb = pipkin_rogers_ratio(pr_params[i, 0], pr_params[i, 1], sfrac) * winf
                            wo = wprev[i, e]
                            h0, h1, h2, h3, h4, h5 = prony_update(
                                decay[i], gain[i], hstate[6 * i, e], hstate[6 * i + 1, e], hstate[6 * i + 2, e],
                                hstate[6 * i + 3, e], hstate[6 * i + 4, e], hstate[6 * i + 5, e],
                                wb * se0 - wo * sprev[0, e], wb * se1 - wo * sprev[1, e], wb * se2 - wo * sprev[2, e],
                                wb * se3 - wo * sprev[3, e], wb * se4 - wo * sprev[4, e], wb * se5 - wo * sprev[5, e])
                            s0, s1, s2, s3, s4, s5 = s0 + h0, s1 + h1, s2 + h2, s3 + h3, s4 + h4, s5 + h5
                            if commit:
                                hstate[6 * i, e], hstate[6 * i + 1, e], hstate[6 * i + 2, e] = h0, h1, h2
                                hstate[6 * i + 3, e], hstate[6 * i + 4, e], hstate[6 * i + 5, e] = h3, h4, h5
                                wprev[i, e] = wb
                        if commit:
                            sprev[0, e], sprev[1, e], sprev[2, e] = se0, se1, se2
                            sprev[3, e], sprev[4, e], sprev[5, e] = se3, se4, se5
                    else:
                        s0, s1, s2 = g_inf * se0, g_inf * se1, g_inf * se2
                        s3, s4, s5 = g_inf * se3, g_inf * se4, g_inf * se5
                        d0, d1, d2 = se0 - sprev[0, e], se1 - sprev[1, e], se2 - sprev[2, e]
                        d3, d4, d5 = se3 - sprev[3, e], se4 - sprev[4, e], se5 - sprev[5, e]
                        for i in range(n_terms):
                            h0, h1, h2, h3, h4, h5 = prony_update(
                                decay[i], gain[i], hstate[6 * i, e], hstate[6 * i + 1, e], hstate[6 * i + 2, e],
                                hstate[6 * i + 3, e], hstate[6 * i + 4, e], hstate[6 * i + 5, e],
                                d0, d1, d2, d3, d4, d5)
                            s0, s1, s2, s3, s4, s5 = s0 + h0, s1 + h1, s2 + h2, s3 + h3, s4 + h4, s5 + h5
                            if commit:
                                hstate[6 * i, e], hstate[6 * i + 1, e], hstate[6 * i + 2, e] = h0, h1, h2
                                hstate[6 * i + 3, e], hstate[6 * i + 4, e], hstate[6 * i + 5, e] = h3, h4, h5
                        if commit:
                            sprev[0, e], sprev[1, e], sprev[2, e] = se0, se1, se2
                            sprev[3, e], sprev[4, e], sprev[5, e] = se3, se4, se5
                    t11, t22, t33, t12, t23, t13 = push_forward(f11, f12, f13, f21, f22, f23, f31, f32, f33,
                                                                s0, s1, s2, s3, s4, s5)
                if use_anp:
                    pr = 0.25 * (p_node[conn[0, e]] + p_node[conn[1, e]] + p_node[conn[2, e]] + p_node[conn[3, e]])
                else:
                    pr = kappa * (J - 1.0)
                jp = J * pr
                t11, t22, t33 = t11 + jp, t22 + jp, t33 + jp
            r1x, r1y, r1z, r2x, r2y, r2z, r3x, r3y, r3z = nodal_forces(
                t11, t22, t33, t12, t23, t13, c11, c12, c13, c21, c22, c23, c31, c32, c33, vol0[e] / J,
                d9[0, e], d9[1, e], d9[2, e], d9[3, e], d9[4, e], d9[5, e], d9[6, e], d9[7, e], d9[8, e])
            store_nodal_forces(e, r1x, r1y, r1z, r2x, r2y, r2z, r3x, r3y, r3z, fel[0], fel[1], fel[2], fel[3],
                               fel[4], fel[5], fel[6], fel[7], fel[8], fel[9], fel[10], fel[11])

    @cuda.jit(device=True)
    def internal_forces(tid, stride, key0, u, g, commit):
        """ANP phases (synchronised) and the element phase; the caller synchronises before gathering."""
        if use_anp:
            element_pressure_phase(tid, stride, u, g.conn, g.d9, g.vol0, g.kappa[0], g.pe)
            cuda.cg.this_grid().sync()
            nodal_pressure_phase(tid, stride, g.pe, g.node_ptr, g.inc_elem, g.inv_vnode, g.p_node)
            cuda.cg.this_grid().sync()
        element_force_phase(tid, stride, key0, u, g.conn, g.d9, g.vol0, g.p_node, g.params, g.kappa[0],
                            g.pr_params, g.g_inf[0], g.decay, g.gain, g.sprev, g.hstate, g.wprev, commit, g.fel,
                            g.bad)

    @cuda.jit(device=True)
    def project_contact(n, u_new, g, s_contact):
        slot = g.contact_slot[n]
        if contact_kind > 0 and slot >= 0:
            cp = g.cparams
            dx, dy, dz, touching = rigid_contact_move(
                g.X[n, 0] + u_new[n, 0] - (cp[0] + s_contact * cp[3]), g.X[n, 1] + u_new[n, 1] - (cp[1] + s_contact * cp[4]),
                g.X[n, 2] + u_new[n, 2] - (cp[2] + s_contact * cp[5]), contact_kind, cp)
            u_new[n, 0] += dx
            u_new[n, 1] += dy
            u_new[n, 2] += dz
            g.in_contact[slot] = 1 if touching else 0

    @cuda.jit(device=True)
    def prescribe(n, row, g, n_groups):
        """Prescribed displacement of node ``n`` (histories ``row``); zero for a node with no prescribed dof."""
        if g.free[n, 0] and g.free[n, 1] and g.free[n, 2]:
            return 0.0, 0.0, 0.0
        grp = g.node_group[n]
        return prescribed_displacement(row[grp], row[n_groups + grp], g.node_rotate[n], g.node_dir[n, 0],
                                       g.node_dir[n, 1], g.node_dir[n, 2], g.X[n, 0], g.X[n, 1],
                                       g.rot_center[grp, 0], g.rot_center[grp, 1])

    @cuda.jit(device=True)
    def explicit_node_phase(tid, stride, k, u, u_old, u_new, g):
        """Gather the forces of every node, advance its free dofs, prescribe the others (histories at step k + 1),
        project the contact nodes."""
        n_groups = g.rot_center.shape[0]
        ne = g.vol0.size
        s_ext = g.bc_table[k, 2 * n_groups + 1]
        nxt = g.bc_table[k + 1]
        for n in range(tid, u.shape[0], stride):
            fx, fy, fz = node_force(g.fel_flat, g.node_ptr, g.inc_slot, ne, n)
            g.fint[n, 0], g.fint[n, 1], g.fint[n, 2] = fx, fy, fz
            ux, uy, uz = prescribe(n, nxt, g, n_groups)
            for i in range(3):
                if g.free[n, i]:
                    u_new[n, i] = central_difference_dof(g.coef_a[n], g.coef_b[n], g.coef_c[n],
                                                         s_ext * g.fext[n, i], g.fint[n, i], u[n, i], u_old[n, i])
                else:
                    u_new[n, i] = ux if i == 0 else (uy if i == 1 else uz)
            project_contact(n, u_new, g, nxt[2 * n_groups])

    def explicit_steps(k0, n_steps, U, g):
        """``n_steps`` central-difference steps from step ``k0``: step ``k`` evaluates the forces of
        ``u_k = U[k % 3]`` and writes ``u_(k+1)`` (``u_(k-1) = U[(k + 2) % 3]``)."""
        grid = cuda.cg.this_grid()
        tid = cuda.grid(1)
        stride = cuda.gridsize(1)
        ne = g.vol0.size
        for s in range(n_steps):
            k = k0 + s
            u = U[k % 3]
            internal_forces(tid, stride, k * ne, u, g, True)
            grid.sync()
            explicit_node_phase(tid, stride, k, u, U[(k + 2) % 3], U[(k + 1) % 3], g)
            grid.sync()

    def evaluate_forces(u, commit, g):
        """Internal forces of ``u`` into ``g.fint`` (states committed when ``commit``), no update."""
        grid = cuda.cg.this_grid()
        tid = cuda.grid(1)
        stride = cuda.gridsize(1)
        internal_forces(tid, stride, 0, u, g, commit)
        grid.sync()
        for n in range(tid, u.shape[0], stride):
            fx, fy, fz = node_force(g.fel_flat, g.node_ptr, g.inc_slot, g.vol0.size, n)
            g.fint[n, 0], g.fint[n, 1], g.fint[n, 2] = fx, fy, fz

    def relaxation_start(u, u_eq, r, extrapolate, hv, g):
        """Start of a dynamic-relaxation increment (as ``_kernels.dynamic_relaxation_loop``): free dofs extrapolated
        by ``r`` times the change since the previous equilibrium (when ``extrapolate``), prescribed dofs and contact
        from the histories ``hv`` at the increment's time."""
        n_groups = g.rot_center.shape[0]
        for n in range(cuda.grid(1), u.shape[0], cuda.gridsize(1)):
            ux, uy, uz = prescribe(n, hv, g, n_groups)
            for i in range(3):
                du = u[n, i] - u_eq[n, i]
                u_eq[n, i] = u[n, i]
                if extrapolate and g.free[n, i]:
                    u[n, i] += r * du
                if not g.free[n, i]:
                    u[n, i] = ux if i == 0 else (uy if i == 1 else uz)
            project_contact(n, u, g, hv[2 * n_groups])

    def relaxation_iterations(base, min_iter, max_iter, tol_m, lam_prev, s_ext, U, F2, partials, info, g):
        """Dynamic relaxation of one increment (``_kernels.dynamic_relaxation_loop``'s iteration), all on the device:
        ``u = U[(base + it) % 3]``, ``u_old = U[(base + it + 2) % 3]``; forces of iteration ``it`` in
        ``F2[it % 2]``. ``info`` gets (outcome, iterations, final lambda_min, error bound)."""
        grid = cuda.cg.this_grid()
        tid = cuda.grid(1)
        stride = cuda.gridsize(1)
        sm = cuda.shared.array(threads, _f64)
        blk = cuda.blockIdx.x
        nn = U.shape[1]
        lam_max = 1.0
        lam_min = 1e-6
        alpha, beta = relaxation_coefficients(lam_min)
        n_ok = 0
        it = 0
        outcome = DR_NOT_CONVERGED
        err = 0.0
        while it < max_iter:
            u = U[(base + it) % 3]
            u_old = U[(base + it + 2) % 3]
            u_new = U[(base + it + 1) % 3]
            fint = F2[it % 2]
            fprev = F2[(it + 1) % 2]
            internal_forces(tid, stride, 0, u, g, False)
            grid.sync()
            if g.bad[0] != _NO_ELEMENT:
                outcome = DR_INVERTED
                break
            num = 0.0
            den = 0.0
            for n in range(tid, nn, stride):
                fx, fy, fz = node_force(g.fel_flat, g.node_ptr, g.inc_slot, g.vol0.size, n)
                fint[n, 0], fint[n, 1], fint[n, 2] = fx, fy, fz
                if it > 0:
                    for i in range(3):
                        if g.free[n, i]:
                            du = u[n, i] - u_old[n, i]
                            num += du * (fint[n, i] - fprev[n, i])
                            den += du * du * g.dr_mass[n]
            num = block_reduce(sm, num, False)
            den = block_reduce(sm, den, False)
            if cuda.threadIdx.x == 0:
                partials[0, blk] = num
                partials[1, blk] = den
            grid.sync()
            if it > 0:
                num = partials_reduce(sm, partials, 0, False)
                den = partials_reduce(sm, partials, 1, False)
                if den > 0.0 and num > 0.0:
                    est = num / den
                    if est < lam_max:
                        lam_min = est
                        alpha, beta = relaxation_coefficients(lam_min)
            n_groups = g.rot_center.shape[0]
            dmax = 0.0
            for n in range(tid, nn, stride):
                am = alpha * g.inv_dr_mass[n]
                for i in range(3):
                    if g.free[n, i]:
                        u_new[n, i] = dynamic_relaxation_dof(u[n, i], u_old[n, i], beta, am, s_ext * g.fext[n, i],
                                                             fint[n, i])
                    else:
                        u_new[n, i] = u[n, i]
                project_contact(n, u_new, g, g.hv[2 * n_groups])
                for i in range(3):
                    d = abs(u_new[n, i] - u[n, i])
                    if d > dmax or d != d:
                        dmax = d
            dmax = block_reduce(sm, dmax, True)
            if cuda.threadIdx.x == 0:
                partials[2, blk] = dmax
            grid.sync()
            dmax = partials_reduce(sm, partials, 2, True)
            if not math.isfinite(dmax):
                outcome = DR_NOT_FINITE
                break
            err = relaxation_error_bound(min(lam_min, lam_prev), lam_max, dmax)
            it += 1
            n_ok = relaxation_calm_iterations(n_ok, it, min_iter, err, tol_m)
            if n_ok >= RELAXATION_CALM_ITERATIONS:
                outcome = DR_CONVERGED
                break
        if tid == 0:
            info[0] = outcome
            info[1] = it
            info[2] = lam_min
            info[3] = err

    def outputs(u, u_old, dt, g, out):
        """Block ``b < n_groups``: reaction force (sum of internal forces) and z-torque about the centre of group
        ``b`` (``_kernels.group_reactions``); block ``n_groups``: contact force; block ``n_groups + 1``: kinetic
        energy ``sum m |u - u_old|^2 / (2 dt^2)``. ``out`` rows: ``(fx, fy, fz, torque)`` per group, then
        ``(cx, cy, cz, KE)``."""
        sm = cuda.shared.array(threads, _f64)
        b = cuda.blockIdx.x
        t = cuda.threadIdx.x
        n_groups = g.rot_center.shape[0]
        fx = 0.0
        fy = 0.0
        fz = 0.0
        tq = 0.0
        if b < n_groups:
            for k in range(t, g.bc_nodes.size, threads):
                n = g.bc_nodes[k]
                if g.node_group[n] == b:
                    fx += g.fint[n, 0]
                    fy += g.fint[n, 1]
                    fz += g.fint[n, 2]
                    x = g.X[n, 0] + u[n, 0] - g.rot_center[b, 0]
                    y = g.X[n, 1] + u[n, 1] - g.rot_center[b, 1]
                    tq += x * g.fint[n, 1] - y * g.fint[n, 0]
        elif b == n_groups:
            for k in range(t, g.contact_nodes.size, threads):
                if g.in_contact[k]:
                    n = g.contact_nodes[k]
                    fx += g.fint[n, 0]
                    fy += g.fint[n, 1]
                    fz += g.fint[n, 2]
        else:
            for n in range(t, u.shape[0], threads):
                for i in range(3):
                    v = (u[n, i] - u_old[n, i]) / dt
                    tq += 0.5 * g.mass[n] * v * v
        fx = block_reduce(sm, fx, False)
        fy = block_reduce(sm, fy, False)
        fz = block_reduce(sm, fz, False)
        tq = block_reduce(sm, tq, False)
        if t == 0:
            out[b, 0], out[b, 1], out[b, 2], out[b, 3] = fx, fy, fz, tq

    limited = cuda.jit(max_registers=max_registers) if max_registers and not python else cuda.jit
    return {"explicit_steps": limited(explicit_steps), "evaluate_forces": limited(evaluate_forces),
            "relaxation_start": cuda.jit(relaxation_start), "relaxation_iterations": limited(relaxation_iterations),
            "outputs": cuda.jit(outputs)}


# --------------------------------------------------------------------------------------------------
# device-resident problem
# --------------------------------------------------------------------------------------------------
#: the device arrays of a problem, passed to the kernels as one argument (numba flattens a namedtuple of arrays)
DeviceArrays = namedtuple("DeviceArrays", (
    "conn d9 vol0 pe p_node node_ptr inc_elem inc_slot inv_vnode params kappa pr_params g_inf decay gain sprev hstate "
    "wprev fel fel_flat fint bad free fext coef_a coef_b coef_c bc_table node_group node_dir node_rotate rot_center X "
    "contact_slot contact_nodes in_contact cparams bc_nodes mass dr_mass inv_dr_mass hv"))


class DeviceProblem:
    """A TLED model's arrays on the GPU, advanced by explicit steps (:meth:`advance`) or relaxed to equilibrium
    (:meth:`relax`); reactions, torques, contact force and kinetic energy from :meth:`outputs`.

    Parameters
    ----------
    model : from :func:`tissuemech.fem.tled.build_model` (its kernel node and element order is used on the device)
    dt_s : explicit step (s); with ``n_steps_max`` it sizes the table of prescribed motions (dynamic relaxation
        ignores both)
    u0_m, v0_m_s : initial displacement and velocity (caller's node order)
    damping_1_s : mass-proportional damping coefficient (1/s)
    state : viscoelastic ``RunResult.state`` to start from (default virgin)
    threads_per_block : a power of two (the simulator runs one block: keep it small there)
    max_registers : register limit per thread of the cooperative kernels (None: the compiler's choice; a lower limit
        lets more blocks be resident, at the price of spills)
    """

    def __init__(self, model: TLEDModel, dt_s: float = 1.0, n_steps_max: int = 0, u0_m=None, v0_m_s=None,
                 damping_1_s: float = 0.0, state: tuple | None = None, threads_per_block: int = 256,
                 max_registers: int | None = None):
        if cuda is None:
            raise RuntimeError("numba-cuda is not installed (pip install tissuemech[gpu])")
        reason = unsupported_reason(model)
        if reason:
            raise NotImplementedError(reason)
        threads = int(threads_per_block)
        if threads < 1 or threads & (threads - 1):
            raise ValueError("threads_per_block must be a power of two")
        m = model.material
        ft = model.dtype
        mesh = model.kernel_mesh
        nn, ne = mesh.n_nodes, mesh.n_elements
        self.model, self.dt, self.k, self.damping = model, float(dt_s), 0, float(damping_1_s)
        n_terms = int(m.prony_g.size)
        beyond = m.pipkin_rogers
        law = m.law
        self.kernels = _kernels(law.dw_di1, law.dw_di2, int(m.kind), bool(model.use_anp), n_terms,
                                bool(beyond), int(model.contact_kind), threads,
                                None if max_registers is None else int(max_registers))
        self.threads = threads
        node_ptr, inc_elem, inc_slot = node_incidence(mesh.elements, nn)
        n_groups = max(1, len(model.groups))
        node_group = np.zeros(nn, np.int32)
        node_dir = np.zeros((nn, 3))
        node_rotate = np.zeros(nn, np.uint8)
        node_group[model.bc_nodes] = model.bc_group
        node_dir[model.bc_nodes] = model.bc_dir
        node_rotate[model.bc_nodes] = model.bc_rotate
        contact_slot = np.full(nn, -1, np.int32)
        contact_slot[model.contact_nodes] = np.arange(model.contact_nodes.size, dtype=np.int32)
        h_state, s_prev, w_prev = initial_states(model, state)
        n_state = max(1, n_terms)
        hstate = np.zeros((6 * n_state, ne), ft)
        hstate[:6 * n_terms] = h_state.transpose(1, 2, 0).reshape(6 * n_terms, ne)
        wprev = np.zeros((n_state, ne), ft)
        wprev[:n_terms] = w_prev.T
        self.n_steps_max = int(n_steps_max)
        times = self.dt * np.arange(self.n_steps_max + 2)
        bc_table = self._history_table(times)
        to = cuda.to_device
        fel_flat = cuda.device_array(12 * ne, ft)
        g = DeviceArrays(
            conn=to(np.ascontiguousarray(mesh.elements.T, dtype=np.uint32)),
            d9=to(np.ascontiguousarray(model.dndx[:, 3:].T, dtype=ft)), vol0=to(model.vol0.astype(ft)),
            pe=cuda.device_array(ne, ft), p_node=to(np.zeros(nn)), node_ptr=to(node_ptr), inc_elem=to(inc_elem),
            inc_slot=to(inc_slot), inv_vnode=to(1.0 / model.vnode), params=to(np.ascontiguousarray(m.params, float)),
            kappa=to(np.array([m.bulk_modulus_pa])),
            pr_params=to(np.ascontiguousarray(m.pr_params if beyond else np.zeros((1, 3)), float)),
            g_inf=to(np.array([1.0 - m.prony_g.sum()])), decay=to(np.zeros(n_state)), gain=to(np.zeros(n_state)),
            sprev=to(np.ascontiguousarray(s_prev.T)), hstate=to(hstate), wprev=to(wprev),
            fel=fel_flat.reshape(12, ne), fel_flat=fel_flat, fint=to(np.zeros((nn, 3), ft)),
            bad=to(np.array([_NO_ELEMENT], np.int64)), free=to(model.free), fext=to(model.fext_ref),
            coef_a=to(np.zeros(nn)), coef_b=to(np.zeros(nn)), coef_c=to(np.zeros(nn)), bc_table=to(bc_table),
            node_group=to(node_group), node_dir=to(node_dir), node_rotate=to(node_rotate),
            rot_center=to(np.ascontiguousarray(model.rot_center, float)), X=to(mesh.nodes.astype(float)),
            contact_slot=to(contact_slot), contact_nodes=to(model.contact_nodes.astype(np.int64)),
            in_contact=to(np.zeros(max(1, model.contact_nodes.size), np.uint8)),
            cparams=to(np.ascontiguousarray(model.cparams, float)), bc_nodes=to(model.bc_nodes.astype(np.int64)),
            mass=to(model.mass.astype(float)), dr_mass=to(model.dr_mass.astype(float)),
            inv_dr_mass=to(1.0 / model.dr_mass), hv=to(np.zeros(2 * n_groups + 2)))
        self.g = g
        self._set_time_step(self.dt)
        U = np.zeros((3, nn, 3), ft)
        u0 = np.zeros((nn, 3)) if u0_m is None else model.to_kernel_nodes(np.asarray(u0_m, float))
        U[0] = u0
        U[2] = u0 if v0_m_s is None else u0 - self.dt * model.to_kernel_nodes(np.asarray(v0_m_s, float))
        self.U = to(U)
        self._launch_cache: dict[str, int] = {}

    # ---- set-up helpers
    def _history_table(self, times: np.ndarray) -> np.ndarray:
        """Rows of the histories at ``times``: ``s_g`` (n_groups), ``theta_g`` (n_groups), contact position, external
        load scale (as ``_kernels.history_values``)."""
        m = self.model
        rows = [np.interp(times, m.hist_time, row) for row in m.hist_vals]
        return np.ascontiguousarray(np.stack(rows, axis=1), dtype=float)

    def _set_time_step(self, dt: float) -> None:
        """Central-difference coefficients and the QLV factors of the step ``dt``."""
        a, b, c = central_difference_coefficients(self.model.mass, self.damping, dt)
        self.g.coef_a.copy_to_device(a)
        self.g.coef_b.copy_to_device(b)
        self.g.coef_c.copy_to_device(c)
        self._set_relaxation_factors(dt)

    def _set_relaxation_factors(self, dt: float) -> None:
        m = self.model.material
        n = m.prony_tau_s.size
        decay, gain = np.zeros(max(1, n)), np.zeros(max(1, n))
        for i in range(n):
            if dt > 0.0:
                e, f = relaxation_factors(dt, float(m.prony_tau_s[i]))
            else:
                e, f = 1.0, 1.0
            decay[i] = e
            # Pipkin-Rogers: the branch drive carries its own weight (gain = f); QLV: g_i f
            gain[i] = f if m.pipkin_rogers else m.prony_g[i] * f
        self.g.decay.copy_to_device(decay)
        self.g.gain.copy_to_device(gain)

    def cooperative_blocks(self, name: str, args: tuple) -> int:
        """Blocks of a cooperative launch of kernel ``name`` on ``args``: as many as can be resident at once, at
        most one thread per element or node (one block in the simulator). Compiles the kernel for ``args``."""
        if name not in self._launch_cache:
            if _is_simulator():
                blocks = 1
            else:
                from numba import typeof

                kern = self.kernels[name]
                signature = tuple(typeof(a) for a in args)
                compiled = kern.compile(signature) or kern.overloads[signature]
                mesh = self.model.kernel_mesh
                needed = (max(mesh.n_elements, mesh.n_nodes) + self.threads - 1) // self.threads
                try:
                    resident = compiled.max_cooperative_grid_blocks(self.threads)
                except AttributeError:  # a numba-cuda without the occupancy query: one block per multiprocessor
                    resident = cuda.get_current_device().MULTIPROCESSOR_COUNT
                blocks = min(needed, resident)
            self._launch_cache[name] = max(1, int(blocks))
        return self._launch_cache[name]

    def _launch(self, name: str, *args) -> None:
        """Launch a cooperative kernel on :meth:`cooperative_blocks` blocks."""
        self.kernels[name][self.cooperative_blocks(name, args), self.threads](*args)

    def _raise_if_inverted(self, where: str, time_s: float) -> None:
        bad = int(self.g.bad.copy_to_host()[0])
        if bad != _NO_ELEMENT:
            ne = self.model.kernel_mesh.n_elements
            step, element = divmod(bad, ne)
            element = int(self.model.element_order[element])
            raise ElementInversionError(f"element {element} inverted (J <= 0) at {where} {step}, "
                                        f"t = {time_s:.6g} s", element, step, time_s)

    # ---- explicit dynamics
    def advance(self, n_steps: int, batch: int = 1000) -> None:
        """Evaluate steps ``k .. k + n_steps - 1`` (``k`` = :attr:`k`), ``batch`` steps per persistent launch;
        afterwards ``u_k`` is the newest displacement. Raises :class:`~.tled.ElementInversionError` when an element
        inverted."""
        if self.k + n_steps > self.n_steps_max + 1:
            raise ValueError(f"step {self.k + n_steps} is past the prepared history table ({self.n_steps_max + 1} "
                             f"steps: n_steps_max)")
        done = 0
        while done < n_steps:
            n = min(int(batch), n_steps - done)
            self._launch("explicit_steps", self.k, n, self.U, self.g)
            self.k += n
            done += n
        cuda.synchronize()
        self._raise_if_inverted("step", self.k * self.dt)

    def displacements(self, newest: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """``(u, u_previous)`` (m, float64, caller's node order): the last state whose forces were evaluated,
        ``u_(k-1)`` and ``u_(k-2)`` (as the CPU's :func:`~.tled.run_explicit` returns), or with ``newest`` the
        newest, ``u_k`` and ``u_(k-1)``."""
        U = self.U.copy_to_host()
        k = self.k if newest else self.k - 1
        return (self.model.to_caller_nodes(U[k % 3].astype(float)),
                self.model.to_caller_nodes(U[(k + 2) % 3].astype(float)))

    def outputs(self, ring_index: int | None = None, previous_index: int | None = None) -> np.ndarray:
        """``(n_groups + 1, 4)``: reaction force and torque per group, then contact force and kinetic energy, of the
        state whose forces were evaluated last (explicit: ``u_(k-1)``)."""
        n_groups = self.g.rot_center.shape[0]
        cur = (self.k - 1) % 3 if ring_index is None else ring_index
        old = (self.k + 1) % 3 if previous_index is None else previous_index
        out = cuda.device_array((n_groups + 2, 4))
        self.kernels["outputs"][n_groups + 2, self.threads](self.U[cur], self.U[old], self.dt, self.g, out)
        o = out.copy_to_host()
        return np.vstack([o[:n_groups], np.concatenate([o[n_groups, :3], o[n_groups + 1, 3:]])[None, :]])

    def state(self) -> tuple:
        """Viscoelastic states ``(h_state, s_prev, w_prev)`` in the caller's element order (``RunResult.state``)."""
        m = self.model
        nt, ne = m.material.prony_g.size, m.kernel_mesh.n_elements
        h = self.g.hstate.copy_to_host()[:6 * nt].reshape(nt, 6, ne).transpose(2, 0, 1)
        s = self.g.sprev.copy_to_host().T
        w = self.g.wprev.copy_to_host()[:nt].T
        return caller_states(m, np.ascontiguousarray(h), np.ascontiguousarray(s), np.ascontiguousarray(w))

    def internal_forces(self, u_m: np.ndarray, commit: bool = False) -> np.ndarray:
        """Internal nodal forces (N, caller's node order) of the displacement ``u_m`` (caller's order); the
        viscoelastic states advance over the current step only when ``commit``."""
        u = cuda.to_device(np.ascontiguousarray(self.model.to_kernel_nodes(np.asarray(u_m, float)),
                                                dtype=self.model.dtype))
        self._launch("evaluate_forces", u, bool(commit), self.g)
        cuda.synchronize()
        self._raise_if_inverted("evaluation", 0.0)
        return self.model.to_caller_nodes(self.g.fint.copy_to_host().astype(float))


def run_explicit_gpu(model: TLEDModel, t_end_s: float, *, dt_s: float | None = None, safety: float = 0.7,
                     damping_1_s: float = 0.0, n_outputs: int = 100, u0_m=None, v0_m_s=None, state: tuple | None = None,
                     batch: int = 1000, threads_per_block: int = 256) -> RunResult:
    """Explicit dynamic run on the GPU from ``t = 0`` to ``t_end_s``: the CPU's :func:`~.tled.run_explicit` (same
    steps, outputs every ``n_steps // n_outputs`` steps and at the last, reactions, torques, contact force, kinetic
    energy, final displacements and viscoelastic states), without the energy balance (``energy_j`` is empty).
    ``batch``: steps per persistent launch (an output step ends a batch)."""
    dt = critical_time_step(model, safety) if dt_s is None else float(dt_s)
    n_steps = max(1, int(np.ceil(t_end_s / dt - 1e-9)))
    out_every = max(1, n_steps // max(1, n_outputs))
    run = DeviceProblem(model, dt, n_steps, u0_m, v0_m_s, damping_1_s, state, threads_per_block)
    marks = sorted(set(range(0, n_steps + 1, out_every)) | {n_steps})
    rows, times = [], []
    for s in marks:  # evaluate through step s, then its outputs
        while run.k <= s:
            run.advance(min(batch, s + 1 - run.k), batch)
        o = run.outputs()
        if not np.isfinite(o[-1, 3]):
            raise ElementInversionError(f"non-finite state at step {s}, t = {s * dt:.6g} s (unstable time step?)",
                                        -1, s, s * dt)
        rows.append(o)
        times.append(s * dt)
    out = np.array(rows)
    u, u_old = run.displacements()
    names = model.group_names
    return RunResult(np.array(times), {n: out[:, i, :3] for i, n in enumerate(names)},
                     {n: out[:, i, 3] for i, n in enumerate(names)}, out[:, -1, :3], out[:, -1, 3], u, u_old, dt,
                     np.zeros(0, np.int64), run.state(), {}, "cuda")


def solve_quasistatic_gpu(model: TLEDModel, times_s, *, tol_m: float | None = None, min_iter: int = 20,
                          max_iter: int = 200_000, u0_m=None, state: tuple | None = None,
                          threads_per_block: int = 256) -> RunResult:
    """Static equilibrium by dynamic relaxation on the GPU at each time of ``times_s``: the CPU's
    :func:`~.tled.solve_quasistatic` (the same masses, damping estimate, extrapolated start, stop criterion and
    state commit), one cooperative launch per load increment. The global sums of each iteration are reduced in a
    fixed order, so a run is reproducible, but not in the CPU's order: the iteration counts can differ from the
    CPU's by a few and the solutions agree within the stopping tolerance."""
    times = np.atleast_1d(np.asarray(times_s, float))
    if np.any(np.diff(times) < 0):
        raise ValueError("times_s must be non-decreasing")
    tol = 1e-6 * model.min_altitude_m if tol_m is None else float(tol_m)
    run = DeviceProblem(model, 1.0, 0, u0_m, None, 0.0, state, threads_per_block)
    g = run.g
    nn = model.kernel_mesh.n_nodes
    n_groups = g.rot_center.shape[0]
    F2 = cuda.to_device(np.zeros((2, nn, 3), model.dtype))
    u_eq = cuda.to_device(np.zeros((nn, 3), model.dtype))
    info = cuda.to_device(np.zeros(4))
    # the previous equilibrium for the extrapolated start: the unloaded reference state when the run starts there
    hv0 = run._history_table(np.array([0.0]))[0]
    u_start = run.U.copy_to_host()[0]
    have_eq = times.size > 0 and np.all(u_start == 0.0) and np.all(hv0[:2 * n_groups + 1] == 0.0) \
        and (hv0[2 * n_groups + 1] == 0.0 or np.all(model.fext_ref == 0.0))
    t_prev, t_eq, lam_prev = 0.0, 0.0, 1.0
    base = 0
    out_force = np.zeros((times.size, n_groups, 3))
    out_torque = np.zeros((times.size, n_groups))
    out_contact = np.zeros((times.size, 3))
    iters = np.zeros(times.size, np.int64)
    # one partial sum per block of the cooperative grid (its size needs the kernel compiled for these argument types)
    template = (0, min_iter, max_iter, tol, 1.0, 0.0, run.U, F2, cuda.to_device(np.zeros((3, 1))), info, g)
    partials = cuda.to_device(np.zeros((3, run.cooperative_blocks("relaxation_iterations", template))))
    for k, t in enumerate(times):
        dt = t - t_prev
        extrapolate = bool(have_eq and t_prev > t_eq and dt > 0.0)
        r = dt / (t_prev - t_eq) if extrapolate else 0.0
        t_eq = t_prev
        have_eq = True
        run._set_relaxation_factors(dt)
        hv = run._history_table(np.array([t]))[0]
        g.hv.copy_to_device(hv)
        u = run.U[base]
        run.kernels["relaxation_start"][max(1, (nn + run.threads - 1) // run.threads), run.threads](
            u, u_eq, r, extrapolate, g.hv, g)
        run.U[(base + 2) % 3].copy_to_device(u)  # u_old = u
        run._launch("relaxation_iterations", base, min_iter, max_iter, tol, lam_prev, float(hv[2 * n_groups + 1]), run.U,
                    F2, partials, info, g)
        outcome, n_it, lam_min, _ = info.copy_to_host()
        n_it = int(n_it)
        iters[k] = n_it
        if outcome == DR_INVERTED:
            run._raise_if_inverted("increment", float(t))
        if outcome == DR_NOT_FINITE:
            raise ElementInversionError(f"non-finite state at increment {k}, t = {t:.6g} s", -1, k, float(t))
        if outcome == DR_NOT_CONVERGED:
            raise DynamicRelaxationError(f"dynamic relaxation did not converge in {max_iter} iterations at "
                                         f"increment {k} (t = {t:.6g} s)")
        lam_prev = float(lam_min)
        base = (base + n_it) % 3
        # commit the viscoelastic states at the converged configuration; the reactions of that evaluation
        run._launch("evaluate_forces", run.U[base], True, g)
        o = run.outputs(base, base)
        out_force[k] = o[:n_groups, :3]
        out_torque[k] = o[:n_groups, 3]
        out_contact[k] = o[-1, :3]
        t_prev = float(t)
    u = model.to_caller_nodes(run.U.copy_to_host()[base].astype(float))
    names = model.group_names
    return RunResult(times, {n: out_force[:, i] for i, n in enumerate(names)},
                     {n: out_torque[:, i] for i, n in enumerate(names)}, out_contact, np.full(times.size, np.nan), u,
                     u.copy(), float("nan"), iters, run.state(), {}, "cuda")


def time_steps(model: TLEDModel, v0_m_s, n_steps: int, dt_s: float, batch: int = 1000,
               threads_per_block: int = 256) -> float:
    """Wall seconds of ``n_steps`` explicit GPU steps after a compile and warm-up batch (benchmark helper)."""
    run = DeviceProblem(model, dt_s, n_steps + batch + 1, v0_m_s=v0_m_s, threads_per_block=threads_per_block)
    run.advance(min(batch, 10), batch)
    t0 = time.perf_counter()
    run.advance(n_steps, batch)
    return time.perf_counter() - t0
