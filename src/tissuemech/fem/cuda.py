"""Optional numba-cuda TLED kernel (explicit central difference, linear tets).

Scope: invariant hyperelastic laws (the same scalar ``dW/dI1``, ``dW/dI2`` functions, compiled as CUDA
device functions from their Python source) and Saint Venant-Kirchhoff, optional ANP, prescribed
displacement / rotation groups and fixed nodes. Not on the GPU (use the CPU solver): Ogden (spectral) laws,
QLV states, contact, dynamic relaxation, reaction outputs per step.

Layout follows the measured lessons of ``fem.md`` section 7: element kernel writes its 12 nodal forces to a
``(12, n_elements)`` array (coalesced), a node phase gathers them through a node -> (element, corner) CSR
map (no atomics). All steps of a batch run inside **one persistent cooperative kernel** (grid-stride loops,
``grid.sync()`` between the element and node phases), so there is one launch per batch instead of two to
four per step -- launch latency (60-100 us from Python) otherwise dominates small meshes.

The module imports without a GPU; :func:`available` says whether a CUDA device is usable. The kernels also
run in numba's CUDA simulator (``NUMBA_ENABLE_CUDASIM=1``, one block), which the tests use.
"""
from __future__ import annotations

import functools
import math
import time

import numpy as np

from .materials import KIND_INVARIANT, KIND_INVARIANT_I1, KIND_SVK
from .tled import TLEDModel, critical_time_step

try:  # the GPU path is optional
    from numba import cuda
except ImportError:  # pragma: no cover - numba always ships numba.cuda today
    cuda = None


def available() -> bool:
    """True when numba can use a CUDA device (or the CUDA simulator is enabled)."""
    if cuda is None:
        return False
    try:
        return bool(cuda.is_available())
    except Exception:  # noqa: BLE001 - driver problems mean "not available"
        return False


@functools.lru_cache(maxsize=None)
def _make_kernel(w1_py, w2_py, kind: int, use_anp: bool, float_name: str):
    """Compile the persistent step kernel for one law / variant / precision."""
    ftype = np.float32 if float_name == "float32" else np.float64
    w1_dev = cuda.jit(device=True)(w1_py)
    w2_dev = cuda.jit(device=True)(w2_py)

    @cuda.jit
    def steps_kernel(k0, n_steps, U, elements, dndx, vol0, fel, p_elem, p_node, vnode, node_ptr, node_slot,
                     coef_a, coef_b, coef_c, free, bc_group, bc_dir, bc_rotate, rot_center, bc_table, X,
                     params, kappa):
        grid = cuda.cg.this_grid()
        tid = cuda.grid(1)
        stride = cuda.gridsize(1)
        ne = elements.shape[0]
        nn = X.shape[0]
        one = ftype(1.0)
        half = ftype(0.5)
        third = ftype(1.0 / 3.0)
        kap = ftype(kappa)
        n_groups = rot_center.shape[0]
        # Repeated on purpose: the tensor algebra below (F, cof F, b, b.b, pull-back) is fem.kinematics written out in
        # the kernel's precision ftype, and F is computed again in the element phase after the ANP pre-pass
        # (nothing per element is stored between the phases); tests/fem/test_cuda.py checks it against the CPU kernel
        for s in range(n_steps):
            k = k0 + s
            cur = k % 3
            old = (k + 2) % 3
            new = (k + 1) % 3
            if use_anp:
                for e in range(tid, ne, stride):
                    n0, n1, n2, n3 = elements[e, 0], elements[e, 1], elements[e, 2], elements[e, 3]
                    f11 = one + U[cur, n0, 0] * dndx[0, e] + U[cur, n1, 0] * dndx[3, e] + U[cur, n2, 0] * dndx[6, e] + U[cur, n3, 0] * dndx[9, e]
                    f12 = U[cur, n0, 0] * dndx[1, e] + U[cur, n1, 0] * dndx[4, e] + U[cur, n2, 0] * dndx[7, e] + U[cur, n3, 0] * dndx[10, e]
                    f13 = U[cur, n0, 0] * dndx[2, e] + U[cur, n1, 0] * dndx[5, e] + U[cur, n2, 0] * dndx[8, e] + U[cur, n3, 0] * dndx[11, e]
                    f21 = U[cur, n0, 1] * dndx[0, e] + U[cur, n1, 1] * dndx[3, e] + U[cur, n2, 1] * dndx[6, e] + U[cur, n3, 1] * dndx[9, e]
                    f22 = one + U[cur, n0, 1] * dndx[1, e] + U[cur, n1, 1] * dndx[4, e] + U[cur, n2, 1] * dndx[7, e] + U[cur, n3, 1] * dndx[10, e]
                    f23 = U[cur, n0, 1] * dndx[2, e] + U[cur, n1, 1] * dndx[5, e] + U[cur, n2, 1] * dndx[8, e] + U[cur, n3, 1] * dndx[11, e]
                    f31 = U[cur, n0, 2] * dndx[0, e] + U[cur, n1, 2] * dndx[3, e] + U[cur, n2, 2] * dndx[6, e] + U[cur, n3, 2] * dndx[9, e]
                    f32 = U[cur, n0, 2] * dndx[1, e] + U[cur, n1, 2] * dndx[4, e] + U[cur, n2, 2] * dndx[7, e] + U[cur, n3, 2] * dndx[10, e]
                    f33 = one + U[cur, n0, 2] * dndx[2, e] + U[cur, n1, 2] * dndx[5, e] + U[cur, n2, 2] * dndx[8, e] + U[cur, n3, 2] * dndx[11, e]
                    J = f11 * (f22 * f33 - f23 * f32) - f12 * (f21 * f33 - f23 * f31) + f13 * (f21 * f32 - f22 * f31)
                    p_elem[e] = kap * (J - one) * vol0[e]
                grid.sync()
                for n in range(tid, nn, stride):
                    acc = ftype(0.0)
                    for j in range(node_ptr[n], node_ptr[n + 1]):
                        acc += p_elem[node_slot[j] % ne]
                    p_node[n] = acc / vnode[n]
                grid.sync()
            # ---- element phase: nodal forces into fel[(3a+i), e]
            for e in range(tid, ne, stride):
                n0, n1, n2, n3 = elements[e, 0], elements[e, 1], elements[e, 2], elements[e, 3]
                f11 = one + U[cur, n0, 0] * dndx[0, e] + U[cur, n1, 0] * dndx[3, e] + U[cur, n2, 0] * dndx[6, e] + U[cur, n3, 0] * dndx[9, e]
                f12 = U[cur, n0, 0] * dndx[1, e] + U[cur, n1, 0] * dndx[4, e] + U[cur, n2, 0] * dndx[7, e] + U[cur, n3, 0] * dndx[10, e]
                f13 = U[cur, n0, 0] * dndx[2, e] + U[cur, n1, 0] * dndx[5, e] + U[cur, n2, 0] * dndx[8, e] + U[cur, n3, 0] * dndx[11, e]
                f21 = U[cur, n0, 1] * dndx[0, e] + U[cur, n1, 1] * dndx[3, e] + U[cur, n2, 1] * dndx[6, e] + U[cur, n3, 1] * dndx[9, e]
                f22 = one + U[cur, n0, 1] * dndx[1, e] + U[cur, n1, 1] * dndx[4, e] + U[cur, n2, 1] * dndx[7, e] + U[cur, n3, 1] * dndx[10, e]
                f23 = U[cur, n0, 1] * dndx[2, e] + U[cur, n1, 1] * dndx[5, e] + U[cur, n2, 1] * dndx[8, e] + U[cur, n3, 1] * dndx[11, e]
                f31 = U[cur, n0, 2] * dndx[0, e] + U[cur, n1, 2] * dndx[3, e] + U[cur, n2, 2] * dndx[6, e] + U[cur, n3, 2] * dndx[9, e]
                f32 = U[cur, n0, 2] * dndx[1, e] + U[cur, n1, 2] * dndx[4, e] + U[cur, n2, 2] * dndx[7, e] + U[cur, n3, 2] * dndx[10, e]
                f33 = one + U[cur, n0, 2] * dndx[2, e] + U[cur, n1, 2] * dndx[5, e] + U[cur, n2, 2] * dndx[8, e] + U[cur, n3, 2] * dndx[11, e]
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
                b11 = f11 * f11 + f12 * f12 + f13 * f13
                b22 = f21 * f21 + f22 * f22 + f23 * f23
                b33 = f31 * f31 + f32 * f32 + f33 * f33
                b12 = f11 * f21 + f12 * f22 + f13 * f23
                b23 = f21 * f31 + f22 * f32 + f23 * f33
                b13 = f11 * f31 + f12 * f32 + f13 * f33
                if kind == KIND_SVK:
                    mu = ftype(params[0])
                    lam = kap - ftype(2.0) * mu * third
                    q11 = b11 * b11 + b12 * b12 + b13 * b13
                    q22 = b12 * b12 + b22 * b22 + b23 * b23
                    q33 = b13 * b13 + b23 * b23 + b33 * b33
                    q12 = b11 * b12 + b12 * b22 + b13 * b23
                    q23 = b12 * b13 + b22 * b23 + b23 * b33
                    q13 = b11 * b13 + b12 * b23 + b13 * b33
                    aa = lam * half * (b11 + b22 + b33 - ftype(3.0)) - mu
                    t11, t22, t33 = aa * b11 + mu * q11, aa * b22 + mu * q22, aa * b33 + mu * q33
                    t12, t23, t13 = aa * b12 + mu * q12, aa * b23 + mu * q23, aa * b13 + mu * q13
                else:
                    cr = ftype(J ** third) if J > 0 else ftype(1e-30)
                    jm = one / (cr * cr)
                    b11, b22, b33, b12, b23, b13 = jm * b11, jm * b22, jm * b33, jm * b12, jm * b23, jm * b13
                    i1 = b11 + b22 + b33
                    q11 = b11 * b11 + b12 * b12 + b13 * b13
                    q22 = b12 * b12 + b22 * b22 + b23 * b23
                    q33 = b13 * b13 + b23 * b23 + b33 * b33
                    q12 = b11 * b12 + b12 * b22 + b13 * b23
                    q23 = b12 * b13 + b22 * b23 + b23 * b33
                    q13 = b11 * b13 + b12 * b23 + b13 * b33
                    i2 = half * (i1 * i1 - (q11 + q22 + q33))
                    w1 = ftype(w1_dev(params, i1, i2))
                    w2 = ftype(w2_dev(params, i1, i2))
                    aa = ftype(2.0) * (w1 + i1 * w2)
                    cc = ftype(-2.0) * w2
                    t11, t22, t33 = aa * b11 + cc * q11, aa * b22 + cc * q22, aa * b33 + cc * q33
                    m = (t11 + t22 + t33) * third
                    if use_anp:
                        pr = ftype(0.25) * (p_node[n0] + p_node[n1] + p_node[n2] + p_node[n3])
                    else:
                        pr = kap * (J - one)
                    t11 = t11 - m + J * pr
                    t22 = t22 - m + J * pr
                    t33 = t33 - m + J * pr
                    t12, t23, t13 = aa * b12 + cc * q12, aa * b23 + cc * q23, aa * b13 + cc * q13
                sc = vol0[e] / J
                for a in range(4):
                    dx, dy, dz = dndx[3 * a, e], dndx[3 * a + 1, e], dndx[3 * a + 2, e]
                    gx = (c11 * dx + c12 * dy + c13 * dz) * sc
                    gy = (c21 * dx + c22 * dy + c23 * dz) * sc
                    gz = (c31 * dx + c32 * dy + c33 * dz) * sc
                    fel[3 * a, e] = t11 * gx + t12 * gy + t13 * gz
                    fel[3 * a + 1, e] = t12 * gx + t22 * gy + t23 * gz
                    fel[3 * a + 2, e] = t13 * gx + t23 * gy + t33 * gz
            grid.sync()
            # ---- node phase: gather, central difference, boundary conditions
            for n in range(tid, nn, stride):
                g = bc_group[n]
                for i in range(3):
                    if free[n, i]:
                        acc = ftype(0.0)
                        for j in range(node_ptr[n], node_ptr[n + 1]):
                            slot = node_slot[j]
                            acc += fel[slot // ne + i, slot % ne]
                        U[new, n, i] = (coef_a[n] * (-acc) + coef_b[n] * U[cur, n, i] + coef_c[n] * U[old, n, i])
                    else:
                        sv = bc_table[k + 1, g]
                        val = sv * bc_dir[n, i]
                        if bc_rotate[n] and i < 2:
                            th = bc_table[k + 1, n_groups + g]
                            rx = X[n, 0] - rot_center[g, 0]
                            ry = X[n, 1] - rot_center[g, 1]
                            if i == 0:
                                val += math.cos(th) * rx - math.sin(th) * ry - rx
                            else:
                                val += math.sin(th) * rx + math.cos(th) * ry - ry
                        U[new, n, i] = val
            grid.sync()

    return steps_kernel


class DeviceRun:
    """Device-resident arrays of a TLED model prepared for :meth:`advance` (explicit steps on the GPU)."""

    def __init__(self, model: TLEDModel, dt_s: float, n_steps_max: int, u0_m=None, v0_m_s=None,
                 damping_1_s: float = 0.0, threads_per_block: int = 256):
        m = model.material
        if m.kind not in (KIND_INVARIANT, KIND_INVARIANT_I1, KIND_SVK):
            raise NotImplementedError("the CUDA kernel supports invariant laws and SVK only (Ogden: use the CPU)")
        if m.prony_g.size or model.contact_kind:
            raise NotImplementedError("the CUDA kernel has no viscoelastic states or contact (use the CPU)")
        if np.any(model.fext_ref != 0):
            raise NotImplementedError("the CUDA kernel has no external nodal forces (use the CPU)")
        ft = model.dtype
        nn, ne = model.kernel_mesh.n_nodes, model.kernel_mesh.n_elements
        self.model, self.dt, self.k = model, float(dt_s), 0
        law = m.law
        self.kernel = _make_kernel(law.dw_di1.py_func, law.dw_di2.py_func, int(m.kind), bool(model.use_anp), ft.name)
        # node -> (element, corner) CSR; slot = 3 a ne + e addresses fel[3a, e] in a flat view
        el = model.kernel_mesh.elements.astype(np.int64)
        corner = np.tile(np.arange(4), ne)
        elem = np.repeat(np.arange(ne), 4)
        order = np.argsort(el.ravel(), kind="stable")
        node_ptr = np.concatenate([[0], np.cumsum(np.bincount(el.ravel(), minlength=nn))]).astype(np.int64)
        node_slot = (3 * corner[order] * ne + elem[order]).astype(np.int64)
        mass = model.mass
        a = 1.0 / (mass / self.dt**2 + damping_1_s * mass / (2 * self.dt))
        b = 2 * mass * a / self.dt**2
        c = damping_1_s * mass * a / (2 * self.dt) - 0.5 * b
        ng = max(1, len(model.groups))
        bc_group = np.zeros(nn, np.int64)
        bc_dir = np.zeros((nn, 3))
        bc_rotate = np.zeros(nn, np.uint8)
        bc_group[model.bc_nodes] = model.bc_group
        bc_dir[model.bc_nodes] = model.bc_dir
        bc_rotate[model.bc_nodes] = model.bc_rotate
        times = self.dt * np.arange(n_steps_max + 2)
        bc_table = np.stack([np.interp(times, model.hist_time, row) for row in model.hist_vals[: 2 * ng]], axis=1)
        U = np.zeros((3, nn, 3), ft)
        # the model's kernel numbering (build_model may renumber the caller's mesh for locality)
        u0 = np.zeros((nn, 3)) if u0_m is None else model.to_kernel_nodes(np.asarray(u0_m, float))
        U[0] = u0
        U[2] = u0 if v0_m_s is None else u0 - self.dt * model.to_kernel_nodes(np.asarray(v0_m_s, float))
        to = cuda.to_device
        self.d = dict(
            U=to(U), elements=to(np.ascontiguousarray(model.kernel_mesh.elements)),
            dndx=to(np.ascontiguousarray(model.dndx.T, dtype=ft)), vol0=to(model.vol0.astype(ft)),
            fel=cuda.device_array((12, ne), ft), p_elem=cuda.device_array(ne, ft), p_node=cuda.device_array(nn, ft),
            vnode=to(model.vnode.astype(ft)), node_ptr=to(node_ptr), node_slot=to(node_slot),
            coef_a=to(a.astype(ft)), coef_b=to(b.astype(ft)), coef_c=to(c.astype(ft)), free=to(model.free),
            bc_group=to(bc_group), bc_dir=to(bc_dir.astype(ft)), bc_rotate=to(bc_rotate),
            rot_center=to(model.rot_center.astype(ft)), bc_table=to(bc_table.astype(ft)),
            X=to(model.kernel_mesh.nodes.astype(ft)), params=to(m.params.astype(np.float64)))
        self.kappa = float(m.bulk_modulus_pa)
        self.threads = int(threads_per_block)
        self.blocks = max(1, (max(ne, nn) + self.threads - 1) // self.threads)
        self.n_steps_max = n_steps_max

    def _grid_blocks(self) -> int:
        """Blocks of a cooperative launch: all must be resident at once (grid-stride loops do the rest)."""
        if _is_simulator():
            return 1  # the simulator supports grid sync within one block only
        blocks = min(self.blocks, cuda.get_current_device().MULTIPROCESSOR_COUNT)
        try:  # after the first compile the exact residency limit is known
            kern = next(iter(self.kernel.overloads.values()))
            blocks = min(self.blocks, kern.max_cooperative_grid_blocks(self.threads))
        except (StopIteration, AttributeError):
            pass
        return max(1, int(blocks))

    def _args(self, k0, n):
        d = self.d
        return (k0, n, d["U"], d["elements"], d["dndx"], d["vol0"], d["fel"], d["p_elem"], d["p_node"], d["vnode"],
                d["node_ptr"], d["node_slot"], d["coef_a"], d["coef_b"], d["coef_c"], d["free"], d["bc_group"],
                d["bc_dir"], d["bc_rotate"], d["rot_center"], d["bc_table"], d["X"], d["params"], self.kappa)

    def advance(self, n_steps: int, batch: int = 200) -> None:
        """Advance ``n_steps`` explicit steps, ``batch`` steps per (persistent, cooperative) launch."""
        if self.k + n_steps > self.n_steps_max:
            raise ValueError("more steps than prepared boundary-condition table (n_steps_max)")
        done = 0
        while done < n_steps:
            n = min(batch, n_steps - done)
            self.kernel[self._grid_blocks(), self.threads](*self._args(self.k, n))
            self.k += n
            done += n
        cuda.synchronize()

    def displacement(self) -> tuple[np.ndarray, np.ndarray]:
        """``(u, u_previous)`` at the current step (float64 copies, the caller's node order)."""
        U = self.d["U"].copy_to_host()
        return (self.model.to_caller_nodes(U[self.k % 3].astype(float)),
                self.model.to_caller_nodes(U[(self.k + 2) % 3].astype(float)))


def _is_simulator() -> bool:
    from numba import config

    return bool(config.ENABLE_CUDASIM)


def run_explicit_gpu(model: TLEDModel, t_end_s: float, *, dt_s: float | None = None, safety: float = 0.7,
                     damping_1_s: float = 0.0, u0_m=None, v0_m_s=None, batch: int = 200) -> tuple[np.ndarray, np.ndarray, float]:
    """Explicit run on the GPU; returns ``(u, u_previous, dt)`` after ``ceil(t_end / dt)`` steps."""
    dt = critical_time_step(model, safety) if dt_s is None else float(dt_s)
    n_steps = max(1, int(np.ceil(t_end_s / dt - 1e-9)))
    run = DeviceRun(model, dt, n_steps, u0_m, v0_m_s, damping_1_s)
    run.advance(n_steps, batch)
    u, u_old = run.displacement()
    return u, u_old, dt


def time_steps(model: TLEDModel, v0_m_s, n_steps: int, dt_s: float, batch: int = 200) -> float:
    """Wall seconds of ``n_steps`` GPU steps after a compile/warm-up batch (benchmark helper)."""
    run = DeviceRun(model, dt_s, n_steps + batch + 1, v0_m_s=v0_m_s)
    run.advance(min(batch, 10), batch)
    t0 = time.perf_counter()
    run.advance(n_steps, batch)
    return time.perf_counter() - t0
