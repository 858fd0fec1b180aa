"""Total Lagrangian explicit dynamics (TLED) on linear tetrahedra, numba CPU kernels.

Method (Miller, Joldes, Lance & Wittek 2007; Taylor, Cheng & Ourselin 2008; NiftySim):

* precomputed reference shape-function derivatives ``dN_a/dX`` and volumes ``V0`` per element;
* per step, per element: ``F = I + sum_a u_a (x) dN_a/dX``, stress (``materials``), nodal forces
  ``f_a = V0 tau (F^-T dN_a/dX)`` (``tau`` Kirchhoff) accumulated in per-thread force buffers (one fused
  element pass, no atomics), then one node pass that reduces the buffers and advances the nodes;
* lumped mass, central difference with mass-proportional damping ``alpha`` (NiftySim's
  ``u+ = A (R - F) + B u + C u-`` form), automatic critical step ``min altitude / c_d`` times a safety
  factor, ``c_d = sqrt((kappa + 4 mu/3)/rho)``;
* dynamic relaxation (Joldes, Wittek & Miller 2009/2011) for quasi-static solutions: mass scaled per element
  to a unit stable step, damping ``c = 2 sqrt(lambda_min)`` re-estimated from the Rayleigh quotient of the
  iteration, stop when the Joldes error bound ``rho/(1-rho) ||du||_inf`` drops below a tolerance;
* average nodal pressure (ANP, Bonet & Burton 1998 / Joldes et al. 2009) against volumetric locking:
  element pressures ``kappa (J_e - 1)`` averaged to the nodes (reference-volume weighted) and back;
* prescribed displacement / rotation-about-z histories on node groups (fixed nodes = zero history, flat
  punch = prescribed group), frictionless rigid sphere / cylinder contact by projection;
* the mesh is renumbered for memory locality inside :func:`build_model` (reverse Cuthill-McKee; the runs take and
  return the caller's numbering), optional selective mass scaling of the smallest elements, and
  ``n_threads="auto"`` picks the thread count by mesh size and by the CPUs other processes leave free;
* element inversion (``J <= 0``) or a non-finite state stops the run and raises
  :class:`ElementInversionError` with the element id, step and time.

Two kernels compute the internal forces (``kernel=`` of :func:`run_explicit` / :func:`solve_quasistatic`):
the generic one below (any law) and the vectorised structure-of-arrays passes of :mod:`.vectorised` (SVK
and invariant laws, with up to eight Prony terms; chosen by ``"auto"``), which agree to rounding. Explicit runs
of invariant laws can run those passes fused into one parallel region per step (:mod:`.fused`, ``"fused"``).

The whole time loop runs inside one compiled function (no Python per step); the compiled passes and loops are
in :mod:`._kernels` (this module assembles the model and dispatches). The element stress of
:mod:`.materials` is inlined into the kernels: numba's cache does not see changes of inlined code in
another file, so after editing ``materials.py`` touch ``_kernels.py`` (or clear ``NUMBA_CACHE_DIR``). Reaction forces are sums of
internal nodal forces over a constrained group; torques are about the z axis through the group's centre.
Storage precision is float64 or float32; in float32 the arithmetic of an element is done in registers at
double precision and stored in single precision (halves the memory traffic, which bounds the CPU rate).
"""
from __future__ import annotations

import os
import time
from contextlib import contextmanager
from dataclasses import dataclass, field

import numba
import numpy as np

from . import fused, vectorised
from ._kernels import (STATUS_INVERTED, STATUS_NOT_CONVERGED, STATUS_NOT_FINITE, KernelLaws, KernelLoads, KernelMaterial,
                       KernelMesh, dynamic_relaxation_loop, explicit_loop)
from .materials import KIND_INVARIANT, KIND_INVARIANT_I1, KIND_SVK, Material, constant_invariant_derivatives
from .mesh import TetMesh, boundary_nodes, element_min_altitudes, element_volumes, locality_order, mean_element_span

#: cumulative energy terms of an explicit run (``RunResult.energy_j``)
ENERGY_TERMS = ("internal_work", "external_work", "damping_work", "constraint_work")


class ElementInversionError(RuntimeError):
    """An element reached ``J <= 0`` (or the state became non-finite) during a TLED run."""

    def __init__(self, message: str, element: int, step: int, time_s: float):
        super().__init__(message)
        self.element, self.step, self.time_s = element, step, time_s


class DynamicRelaxationError(RuntimeError):
    """Dynamic relaxation did not converge within the iteration limit."""


# --------------------------------------------------------------------------------------------------
# Python API: model assembly, boundary conditions, runs
# --------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class BoundaryGroup:
    """A group of nodes with prescribed displacements; reactions are reported per group.

    The prescribed displacement of node ``X`` at time ``t`` is ``s(t) d + [R_z(theta(t)) (X - c) - (X - c)]``
    on the dofs flagged in ``dofs`` (the rotation term only when ``angle_rad`` is given); ``s``/``theta``
    are piecewise linear in ``time_s``. Fixed nodes: ``s = 0``, no rotation.

    Attributes
    ----------
    name : label of the reaction outputs
    nodes : node indices
    dofs : which of (x, y, z) are prescribed (the others are free, e.g. a frictionless punch prescribes z)
    direction : (3,) unit vector (or (n, 3) per node) multiplying ``s(t)``
    time_s, displacement_m : history of ``s`` (m)
    angle_rad : history of the rotation about the z axis (rad), or None
    center_xy_m : rotation centre in the xy plane (m); also the torque reference point
    """

    name: str
    nodes: np.ndarray
    dofs: tuple[bool, bool, bool] = (True, True, True)
    direction: np.ndarray = field(default_factory=lambda: np.zeros(3))
    time_s: np.ndarray = field(default_factory=lambda: np.zeros(1))
    displacement_m: np.ndarray = field(default_factory=lambda: np.zeros(1))
    angle_rad: np.ndarray | None = None
    center_xy_m: tuple[float, float] = (0.0, 0.0)


def fixed_group(name: str, nodes, dofs=(True, True, True)) -> BoundaryGroup:
    """Nodes held at zero displacement on ``dofs``."""
    return BoundaryGroup(name, np.asarray(nodes, np.int64), tuple(bool(d) for d in dofs))


def translation_group(name: str, nodes, direction, time_s, displacement_m, dofs=(True, True, True)) -> BoundaryGroup:
    """Nodes moved by ``displacement_m(time_s)`` along ``direction`` (normalised)."""
    d = np.asarray(direction, float)
    d = d / np.linalg.norm(d)
    return BoundaryGroup(name, np.asarray(nodes, np.int64), tuple(bool(x) for x in dofs), d,
                         np.asarray(time_s, float), np.asarray(displacement_m, float))


def rotation_group(name: str, nodes, time_s, angle_rad, center_xy_m=(0.0, 0.0)) -> BoundaryGroup:
    """Nodes rotated rigidly about the z axis through ``center_xy_m`` by ``angle_rad(time_s)``, z held fixed
    (the upper rheometer plate, bonded sample)."""
    t = np.asarray(time_s, float)
    return BoundaryGroup(name, np.asarray(nodes, np.int64), (True, True, True), np.zeros(3), t, np.zeros_like(t),
                         np.asarray(angle_rad, float), tuple(center_xy_m))


@dataclass(frozen=True)
class RigidContact:
    """Frictionless rigid sphere, infinite cylinder or flat cylindrical punch moving along ``direction`` by
    ``displacement_m(time_s)``.

    Attributes
    ----------
    shape : ``"sphere"``, ``"cylinder"`` or ``"flat_punch"`` (axis = ``direction``; for a punch on a flat
        surface a prescribed node group is equivalent and cheaper, this is for curved surfaces)
    center_m : initial centre (m); for a cylinder a point on its axis; for a flat punch its face centre
    radius_m : radius (m)
    direction : motion direction (normalised)
    time_s, displacement_m : motion history
    nodes : candidate slave nodes (None: all boundary nodes)
    axis : cylinder axis (normalised)
    """

    shape: str
    center_m: tuple[float, float, float]
    radius_m: float
    direction: tuple[float, float, float] = (0.0, 0.0, -1.0)
    time_s: np.ndarray = field(default_factory=lambda: np.zeros(1))
    displacement_m: np.ndarray = field(default_factory=lambda: np.zeros(1))
    nodes: np.ndarray | None = None
    axis: tuple[float, float, float] = (1.0, 0.0, 0.0)


@dataclass(frozen=True)
class TLEDModel:
    """Precomputed arrays of a TLED problem (build with :func:`build_model`).

    ``mesh`` is the caller's mesh; the solver works on ``kernel_mesh``, the same mesh renumbered for memory
    locality (``kernel_mesh.nodes = mesh.nodes[node_order]``, its element ``k`` is the caller's element
    ``element_order[k]``). Every per-node and per-element array of the model (``mass``, ``dndx``, ``bc_nodes``...)
    is in the kernel order; :func:`run_explicit` and :func:`solve_quasistatic` take and return displacements,
    viscoelastic states and element ids in the caller's order.
    """

    mesh: TetMesh
    kernel_mesh: TetMesh
    node_order: np.ndarray
    element_order: np.ndarray
    material: Material
    groups: tuple[BoundaryGroup, ...]
    contact: RigidContact | None
    use_anp: bool
    dtype: np.dtype
    dndx: np.ndarray
    vol0: np.ndarray
    vnode: np.ndarray
    mass: np.ndarray
    dr_mass: np.ndarray
    min_altitude_m: float
    stable_step_s: float
    added_mass_fraction: float
    chunk_lo: np.ndarray
    bc_nodes: np.ndarray
    bc_group: np.ndarray
    bc_mask: np.ndarray
    bc_dir: np.ndarray
    bc_rotate: np.ndarray
    rot_center: np.ndarray
    free: np.ndarray
    hist_time: np.ndarray
    hist_vals: np.ndarray
    fext_ref: np.ndarray
    contact_kind: int
    cparams: np.ndarray
    contact_nodes: np.ndarray

    @property
    def group_names(self) -> list[str]:
        return [g.name for g in self.groups]

    @property
    def reordered(self) -> bool:
        """Whether the kernel numbering differs from the caller's."""
        return not (np.array_equal(self.node_order, np.arange(self.node_order.size))
                    and np.array_equal(self.element_order, np.arange(self.element_order.size)))

    def to_kernel_nodes(self, a: np.ndarray) -> np.ndarray:
        """A per-node array (first axis = nodes) from the caller's node order to the kernel's."""
        return np.asarray(a)[self.node_order]

    def to_caller_nodes(self, a: np.ndarray) -> np.ndarray:
        """A per-node array from the kernel's node order back to the caller's."""
        out = np.empty_like(a)
        out[self.node_order] = a
        return out

    @property
    def lumped_mass_kg(self) -> np.ndarray:
        """Lumped nodal masses (kg) in the caller's node order."""
        return self.to_caller_nodes(self.mass)


def shape_derivatives(nodes: np.ndarray, elements: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Reference gradients of the linear shape functions and element volumes.

    Returns
    -------
    dndx : (n_elements, 12) ``dN_a/dX_j`` at index ``3 a + j`` (1/m)
    vol0 : (n_elements,) volumes (m^3)
    """
    x = nodes[elements]
    D = np.stack([x[:, 1] - x[:, 0], x[:, 2] - x[:, 0], x[:, 3] - x[:, 0]], axis=1)  # rows = edges
    # N_a (a=1..3) = rows of inv(D^T)^T: grad N_a = inv(D)[:, a-1]
    inv = np.linalg.inv(D)
    g = np.empty((len(elements), 4, 3))
    g[:, 1:, :] = np.transpose(inv, (0, 2, 1))
    g[:, 0, :] = -g[:, 1:, :].sum(axis=1)
    return g.reshape(len(elements), 12), element_volumes(nodes, elements)


def build_model(mesh: TetMesh, material: Material, groups: list[BoundaryGroup] | tuple = (),
                contact: RigidContact | None = None, *, anp: bool = True, precision: str = "float64",
                external_force_n: np.ndarray | None = None, external_time_s=(0.0,), external_scale=(1.0,),
                n_chunks: int | None = None, reorder: bool | str = "auto",
                mass_scaling_step_s: float | None = None) -> TLEDModel:
    """Assemble the arrays of a TLED problem.

    Parameters
    ----------
    mesh, material : geometry (m) and material
    groups : prescribed-displacement groups; a node must not appear in two groups
    contact : optional rigid contact
    anp : average nodal pressure (recommended for nearly incompressible materials; ignored for SVK)
    precision : ``"float64"`` or ``"float32"`` storage of displacements, forces and element data
    external_force_n : optional (n_nodes, 3) nodal forces (N) scaled by ``external_scale(external_time_s)``
    n_chunks : element chunks with private force buffers (default: numba threads)
    reorder : renumber nodes (reverse Cuthill-McKee) and elements (by smallest node) for memory locality
        (:func:`tissuemech.fem.mesh.locality_order`): ``True``, ``False`` or ``"auto"`` (when it at least halves
        the mean node-index span of the elements, :data:`REORDER_SPAN_GAIN`: a mesh in arbitrary order is
        renumbered, a structured or already renumbered one is kept). Node indices of ``groups``, ``contact`` and
        the rows of ``external_force_n`` are the caller's; the runs return the caller's order.
    mass_scaling_step_s : selective mass scaling for explicit runs (None: none): every element whose own stable
        step ``altitude / c_d`` is shorter than this gets the density that makes it this long,
        ``rho (step c_d / altitude)^2``; the lumped masses include the added mass (``added_mass_fraction``) and
        :func:`critical_time_step` follows. Only the smallest elements are affected; it changes the dynamics (not the
        statics: dynamic relaxation has its own masses), see docs/fem_timing.md for its error.
    """
    dtype = np.dtype(precision)
    if dtype not in (np.float32, np.float64):
        raise ValueError("precision must be 'float32' or 'float64'")
    if reorder not in (True, False, "auto"):
        raise ValueError(f"reorder must be True, False or 'auto', not {reorder!r}")
    caller_mesh = mesh
    nn, ne = mesh.n_nodes, mesh.n_elements
    node_order, element_order = np.arange(nn), np.arange(ne)
    new_index = node_order
    if reorder and ne > 0:
        n_order, e_order = locality_order(mesh.elements, nn)
        n_index = np.empty(nn, dtype=np.int64)
        n_index[n_order] = np.arange(nn)
        renumbered = n_index[mesh.elements.astype(np.int64)[e_order]]
        if reorder is True or mean_element_span(renumbered) * REORDER_SPAN_GAIN <= mean_element_span(mesh.elements):
            node_order, element_order, new_index = n_order, e_order, n_index
            mesh = TetMesh(caller_mesh.nodes[node_order], renumbered.astype(np.int32))
    nodes, elements = mesh.nodes, np.ascontiguousarray(mesh.elements, dtype=np.int32)
    dndx, vol0 = shape_derivatives(nodes, elements)
    if np.any(vol0 <= 0):
        raise ValueError(f"mesh has {int((vol0 <= 0).sum())} elements with non-positive volume "
                         f"(first: {int(np.argmax(vol0 <= 0))})")
    alt = element_min_altitudes(nodes, elements)
    vnode = np.bincount(elements.ravel(), weights=np.repeat(vol0, 4), minlength=nn)
    if np.any(vnode <= 0):
        raise ValueError("mesh has nodes not attached to any element")
    c_d = np.sqrt(material.dilatational_modulus_pa / material.density_kg_m3)
    rho_e = np.full(ne, material.density_kg_m3)
    if mass_scaling_step_s is not None:
        rho_e = rho_e * np.maximum(1.0, (float(mass_scaling_step_s) * c_d / alt) ** 2)
    mass = np.bincount(elements.ravel(), weights=np.repeat(0.25 * rho_e * vol0, 4), minlength=nn)
    stable_step = float(np.min(alt * np.sqrt(rho_e / material.density_kg_m3)) / c_d)
    added_mass = float(np.sum((rho_e - material.density_kg_m3) * vol0) / np.sum(material.density_kg_m3 * vol0))
    # dynamic-relaxation mass: element density making the element's stable step 2 (lambda_max ~ 1)
    rho_dr = 4.0 * material.dilatational_modulus_pa / alt**2
    dr_mass = np.bincount(elements.ravel(), weights=np.repeat(0.25 * rho_dr * vol0, 4), minlength=nn)

    groups = tuple(groups)
    ng = max(1, len(groups))
    seen = np.zeros(nn, bool)
    bc_nodes, bc_group, bc_mask, bc_dir, bc_rotate = [], [], [], [], []
    rot_center = np.zeros((ng, 2))
    times = [np.zeros(1)]
    for gi, g in enumerate(groups):
        nodes_g = new_index[np.asarray(g.nodes, np.int64)]
        if nodes_g.size == 0:
            raise ValueError(f"boundary group {g.name!r} has no nodes")
        if np.any(seen[nodes_g]):
            raise ValueError(f"boundary group {g.name!r} shares nodes with an earlier group")
        seen[nodes_g] = True
        bc_nodes.append(nodes_g)
        bc_group.append(np.full(nodes_g.size, gi))
        bc_mask.append(np.tile(np.asarray(g.dofs, np.uint8), (nodes_g.size, 1)))
        d = np.asarray(g.direction, float)
        bc_dir.append(np.tile(d, (nodes_g.size, 1)) if d.ndim == 1 else d)
        bc_rotate.append(np.full(nodes_g.size, g.angle_rad is not None, np.uint8))
        rot_center[gi] = g.center_xy_m
        times.append(np.asarray(g.time_s, float))
    if contact is not None:
        times.append(np.asarray(contact.time_s, float))
    times.append(np.asarray(external_time_s, float))
    hist_time = np.unique(np.concatenate(times))
    if hist_time.size == 1:
        hist_time = np.array([hist_time[0], hist_time[0] + 1.0])
    hist_vals = np.zeros((2 * ng + 2, hist_time.size))
    for gi, g in enumerate(groups):
        hist_vals[gi] = np.interp(hist_time, g.time_s, g.displacement_m)
        if g.angle_rad is not None:
            hist_vals[ng + gi] = np.interp(hist_time, g.time_s, g.angle_rad)
    if contact is not None:
        hist_vals[2 * ng] = np.interp(hist_time, contact.time_s, contact.displacement_m)
    hist_vals[2 * ng + 1] = np.interp(hist_time, np.asarray(external_time_s, float), np.asarray(external_scale, float))

    def cat(parts, shape, dt):
        return np.ascontiguousarray(np.concatenate(parts) if parts else np.zeros(shape, dt), dtype=dt)

    bc_nodes_a = cat(bc_nodes, (0,), np.int64)
    bc_mask_a = cat(bc_mask, (0, 3), np.uint8).reshape(-1, 3)
    free = np.ones((nn, 3), np.uint8)
    free[bc_nodes_a[:, None], np.arange(3)[None, :]] = 1 - bc_mask_a

    if contact is not None:
        kinds = {"sphere": 1, "cylinder": 2, "flat_punch": 3}
        if contact.shape not in kinds:
            raise ValueError(f"unknown rigid contact shape {contact.shape!r}; known: {', '.join(kinds)}")
        kind = kinds[contact.shape]
        d = np.asarray(contact.direction, float)
        a = np.asarray(contact.axis, float)
        cparams = np.concatenate([contact.center_m, d / np.linalg.norm(d), [contact.radius_m], a / np.linalg.norm(a)])
        cnodes = boundary_nodes(elements) if contact.nodes is None else new_index[np.asarray(contact.nodes, np.int64)]
        cnodes = cnodes[free[cnodes].all(axis=1)]
    else:
        kind, cparams, cnodes = 0, np.zeros(10), np.zeros(0, np.int64)

    nchunk = int(n_chunks or numba.get_num_threads())
    nchunk = max(1, min(nchunk, ne))
    chunk_lo = np.linspace(0, ne, nchunk + 1).round().astype(np.int64)
    fext = np.zeros((nn, 3)) if external_force_n is None else np.asarray(external_force_n, float)[node_order]
    return TLEDModel(
        mesh=caller_mesh, kernel_mesh=mesh, node_order=np.asarray(node_order, np.int64),
        element_order=np.asarray(element_order, np.int64), material=material, groups=groups, contact=contact,
        use_anp=bool(anp and material.kind != KIND_SVK), dtype=dtype,
        dndx=np.ascontiguousarray(dndx, dtype=dtype), vol0=np.ascontiguousarray(vol0, dtype=dtype),
        vnode=vnode, mass=mass, dr_mass=dr_mass, min_altitude_m=float(alt.min()), chunk_lo=chunk_lo,
        stable_step_s=stable_step, added_mass_fraction=added_mass,
        bc_nodes=bc_nodes_a, bc_group=cat(bc_group, (0,), np.int64), bc_mask=bc_mask_a,
        bc_dir=cat(bc_dir, (0, 3), np.float64).reshape(-1, 3), bc_rotate=cat(bc_rotate, (0,), np.uint8),
        rot_center=rot_center, free=free, hist_time=hist_time, hist_vals=hist_vals,
        fext_ref=np.ascontiguousarray(fext, dtype=dtype), contact_kind=kind, cparams=cparams,
        contact_nodes=np.ascontiguousarray(cnodes, np.int64))


#: ``build_model(reorder="auto")`` renumbers a mesh when that divides its mean element node span by at least this
#: (docs/fem_timing.md, issue 17: a shuffled 1e5-tet cube 5.4 -> 10.6 Mupd/s; the lexicographic block mesh, whose
#: span RCM cuts only 1.4x, runs faster in its own order, 14 vs 10-12)
REORDER_SPAN_GAIN = 2.0


def critical_time_step(model: TLEDModel, safety: float = 0.7) -> float:
    """``safety * min altitude / c_d`` with ``c_d = sqrt((kappa + 4 mu / 3) / rho)`` (s); with mass scaling the
    smallest element step ``altitude / c_d`` at each element's scaled density."""
    return float(safety * model.stable_step_s)


@dataclass(frozen=True)
class RunResult:
    """Outputs of a TLED run (explicit: per output step; quasi-static: per load increment).

    Attributes
    ----------
    time_s : (nt,) output times
    reaction_force_n : {group: (nt, 3)} sum of internal nodal forces on the group (N); the force the
        body exerts on whatever holds the nodes is its negative
    torque_nm : {group: (nt,)} z-torque of the internal forces about the group centre (N m)
    contact_force_n : (nt, 3) sum of internal forces on the nodes in rigid contact (N)
    kinetic_energy_j : (nt,) (explicit runs; NaN for quasi-static)
    displacement_m : (n_nodes, 3) final displacement
    previous_displacement_m : (n_nodes, 3) displacement one step earlier (explicit) or a copy
    time_step_s : explicit step (NaN for quasi-static)
    iterations : (nt,) dynamic-relaxation iterations per increment (quasi-static) else empty
    state : final viscoelastic element states ``(h_state, s_prev, w_prev)`` (pass as ``state=`` to continue)
    energy_j : explicit runs: cumulative energies (J) at the outputs, keys :data:`ENERGY_TERMS`:
        ``internal_work`` (work of the internal forces = stored + viscously dissipated energy),
        ``external_work`` (applied loads), ``damping_work`` (mass-proportional damping) and
        ``constraint_work`` (prescribed dofs and contact); with ``kinetic_energy_j`` (half-step velocities)
        ``KE + internal + damping = KE(0) + external + constraint``
    kernel : ``"vectorised"`` or ``"generic"``: which internal-force kernel ran
    """

    time_s: np.ndarray
    reaction_force_n: dict
    torque_nm: dict
    contact_force_n: np.ndarray
    kinetic_energy_j: np.ndarray
    displacement_m: np.ndarray
    previous_displacement_m: np.ndarray
    time_step_s: float
    iterations: np.ndarray
    state: tuple
    energy_j: dict = field(default_factory=dict)
    kernel: str = "generic"


def initial_states(model: TLEDModel, state: tuple | None):
    """Viscoelastic element states ``(h_state, s_prev, w_prev)`` in the kernel's element order: virgin or copies of
    a previous run's (given in the caller's element order)."""
    nt, ne = model.material.prony_g.size, model.mesh.n_elements
    if state is None:
        return np.zeros((ne, nt, 6), model.dtype), np.zeros((ne, 6), model.dtype), np.zeros((ne, nt), model.dtype)
    eo = model.element_order
    return (np.ascontiguousarray(state[0][eo], dtype=model.dtype), np.ascontiguousarray(state[1][eo], dtype=model.dtype),
            np.ascontiguousarray(state[2][eo], dtype=model.dtype))


def caller_states(model: TLEDModel, h_state, s_prev, w_prev) -> tuple:
    """The states of a run back in the caller's element order."""
    out = []
    for a in (h_state, s_prev, w_prev):
        b = np.empty_like(a)
        b[model.element_order] = a
        out.append(b)
    return tuple(out)


KERNELS = ("auto", "fused", "vectorised", "generic")

#: above this many elements ``kernel="auto"`` keeps float64 runs on the generic kernel: the vectorised passes
#: move ~3x the bytes per element (stored F, element forces), which costs more than vectorisation gains once
#: the arrays leave the caches (docs/fem_timing.md: 1e6 tets on the 2-core VM, NH 26 vs 29, QLV4 11 vs 21
#: Mupd/s; at 1e5 tets and in float32 at every size the vectorised kernel is faster)
AUTO_VECTORISED_MAX_FLOAT64_ELEMENTS = 300_000


def vectorised_law(material: Material) -> tuple[bool, bool, float, float] | None:
    """``(svk, constant, dW/dI1, dW/dI2)`` when the vectorised kernels (:mod:`.vectorised`) can run this
    material: Saint Venant-Kirchhoff, or any invariant law ``W(I1bar, I2bar)`` (``constant`` with its
    derivatives for laws linear in the invariants, else the law functions are evaluated per element), with
    or without up to :data:`.vectorised.MAX_PRONY_TERMS` QLV or Pipkin-Rogers Prony terms. None for stretch-based laws (Ogden: spectral
    decomposition) and more Prony terms (the generic kernel runs those)."""
    if material.prony_g.size > vectorised.MAX_PRONY_TERMS:
        return None
    if material.pipkin_rogers and material.kind == KIND_SVK:
        return None
    if material.kind == KIND_SVK:
        return True, True, 0.0, 0.0
    if material.kind not in (KIND_INVARIANT, KIND_INVARIANT_I1):
        return None
    w = constant_invariant_derivatives(material)
    return (False, False, 0.0, 0.0) if w is None else (False, True, w[0], w[1])


def _fused_law(model: TLEDModel, kernel: str) -> tuple[bool, bool, float, float] | None:
    """The :func:`vectorised_law` of an explicit run on the fused one-region-per-step kernel (:mod:`.fused`), or
    None when the run takes another kernel. ``kernel="fused"`` requires an invariant law (SVK and
    the generic kernel's laws raise). ``"auto"`` never takes it: on a free machine it measured as fast as the
    vectorised passes (a parallel region costs ~1.3 us of a ~200 us brain step) and it costs a compile of its
    own (~35 CPU s); it holds up better than them with 2 threads on a loaded machine (docs/fem_timing.md,
    "Issue 17, fused step"), where ``n_threads="auto"`` already runs one thread."""
    if kernel not in KERNELS:
        raise ValueError(f"kernel must be one of {KERNELS}, not {kernel!r}")
    if kernel != "fused":
        return None
    law = vectorised_law(model.material)
    if law is None or law[0] or model.material.pipkin_rogers \
            or model.material.prony_g.size > fused.MAX_PRONY_TERMS:
        raise ValueError(f"the fused kernel needs an invariant law with at most {fused.MAX_PRONY_TERMS} QLV Prony "
                         f"terms; {model.material.law_key!r} ({model.material.prony_g.size} terms"
                         f"{', Pipkin-Rogers' if model.material.pipkin_rogers else ''}) runs on the vectorised or "
                         f"generic kernel")
    return law


def _fused_parts(threads: int | None) -> int:
    """Parts of the fused kernel's node partition: one per thread the run gets (``threads`` as from
    :func:`resolve_threads`; None: numba's current setting)."""
    with numba_threads(threads):
        return numba.get_num_threads()


def _vector_setup(model: TLEDModel, kernel: str, h_state, s_prev, w_prev):
    """The ``vec`` argument of the compiled loops and the force buffers of the generic kernel.

    ``kernel``: ``"auto"`` (vectorised when :func:`vectorised_law` allows it, except float64 meshes above
    :data:`AUTO_VECTORISED_MAX_FLOAT64_ELEMENTS`), ``"vectorised"`` (required) or ``"generic"``. The
    vectorised workspace holds the QLV / Pipkin-Rogers states in structure-of-arrays form (copied from
    ``h_state``/``s_prev``/``w_prev``; :func:`_vector_state_back` copies them back). A disabled workspace has the same
    types with zero sizes, so one compiled loop serves both kernels.
    """
    if kernel not in KERNELS:
        raise ValueError(f"kernel must be one of {KERNELS}, not {kernel!r}")
    law = vectorised_law(model.material) if kernel != "generic" else None
    if kernel == "auto" and model.dtype == np.float64 \
            and model.mesh.n_elements > AUTO_VECTORISED_MAX_FLOAT64_ELEMENTS:
        law = None
    if kernel == "vectorised" and law is None:
        raise ValueError(f"the vectorised kernel needs Saint Venant-Kirchhoff or an invariant law with at most "
                         f"{vectorised.MAX_PRONY_TERMS} Prony terms; "
                         f"{model.material.law_key!r} ({model.material.prony_g.size} terms) runs on the generic "
                         f"kernel")
    enabled = law is not None
    el = model.kernel_mesh.elements
    ne, nn = (el.shape[0], model.kernel_mesh.n_nodes) if enabled else (0, 0)
    # whole blocks of the stress pass (unused terms have zero states and weights)
    nt = -(-model.material.prony_g.size // vectorised.PRONY_BLOCK) * vectorised.PRONY_BLOCK if enabled else 0
    dt = model.dtype
    nchunk = model.chunk_lo.size - 1
    if enabled:
        node_ptr, inc_elem, inc_slot = vectorised.node_incidence(el, nn)
        conn = np.ascontiguousarray(el.T, dtype=np.uint32)
        d9 = np.ascontiguousarray(model.dndx[:, 3:].T)
        inv_vnode = 1.0 / model.vnode
        elo = model.chunk_lo.astype(np.uint64)
        nlo = np.linspace(0, nn, nchunk + 1).round().astype(np.uint64)
        sprev = np.ascontiguousarray(s_prev.T)
        hstate = np.zeros((nt, 6, ne), dt)
        hstate[:h_state.shape[1]] = h_state.transpose(1, 2, 0)
        wprev = np.zeros((nt if model.material.pipkin_rogers else 0, ne), dt)
        if wprev.shape[0]:
            wprev[:w_prev.shape[1]] = w_prev.T
    else:
        node_ptr, inc_elem, inc_slot = np.zeros(1, np.uint32), np.zeros(0, np.uint32), np.zeros(0, np.uint32)
        conn, d9, inv_vnode = np.zeros((4, 0), np.uint32), np.zeros((9, 0), dt), np.zeros(0)
        elo, nlo = np.zeros(1, np.uint64), np.zeros(1, np.uint64)
        sprev, hstate, wprev = np.zeros((6, 0), dt), np.zeros((0, 6, 0), dt), np.zeros((0, 0), dt)
    ws = (conn, d9, model.vol0 if enabled else np.zeros(0, dt), node_ptr, inc_elem, inc_slot, inv_vnode, elo, nlo,
          np.zeros((9, ne), dt), np.zeros(ne, dt), np.zeros(nn), np.zeros((12, ne), dt),
          np.zeros(nchunk, np.int64), np.zeros(nchunk, np.int64), sprev, hstate, np.zeros(ne),
          np.zeros((6, ne if nt else 0), dt))
    svk, constant, w1, w2 = law if enabled else (False, True, 0.0, 0.0)
    # per-element law derivatives: filled once for a constant-derivative law, else by the law pass
    ws = ws + (np.full(ne, w1), np.full(ne, w2), wprev)
    vec = (enabled, ws, svk, constant, float(w1), float(w2))
    nbuf = 0 if enabled else nchunk
    fbuf = np.zeros((nbuf, model.kernel_mesh.n_nodes, 3), model.dtype)
    pbuf = np.zeros((nbuf, model.kernel_mesh.n_nodes))
    return vec, fbuf, pbuf


def _vector_state_back(vec, h_state, s_prev, w_prev):
    """Copy the QLV / Pipkin-Rogers states of a vectorised run back into the generic ``(n_el, n_terms, 6)``,
    ``(n_el, 6)`` and ``(n_el, n_terms)`` arrays."""
    if vec[0] and h_state.shape[1] > 0:
        ws = vec[1]
        s_prev[:] = ws[15].T
        h_state[:] = ws[16][:h_state.shape[1]].transpose(2, 0, 1)
        if ws[21].shape[0]:
            w_prev[:] = ws[21][:w_prev.shape[1]].T


@contextmanager
def numba_threads(n_threads: int | None):
    """Temporarily run the parallel kernels on ``n_threads`` threads (None: leave numba's setting).

    On a loaded shared machine one thread is often faster: every parallel region waits for its slowest
    (possibly descheduled) thread, several regions per step.
    """
    if n_threads is None:
        yield
        return
    old = numba.get_num_threads()
    numba.set_num_threads(max(1, min(int(n_threads), numba.config.NUMBA_NUM_THREADS)))
    try:
        yield
    finally:
        numba.set_num_threads(old)


#: ``n_threads="auto"`` runs meshes with fewer elements than this on one thread (a parallel region costs a few
#: microseconds of fork/join, and each step has 3-5; docs/fem_timing.md, issue 17, 2-core VM, two runs: 2 threads
#: were 0.79-1.25x the 1-thread rate at 384 tets, 0.98-1.40x at 1,296 tets and 1.46-1.80x from 3,072 tets up)
AUTO_THREADS_MIN_ELEMENTS = 2000


def busy_cpus(interval_s: float = 0.02) -> float | None:
    """CPUs kept busy by other processes, from ``/proc/stat`` over ``interval_s`` (this process sleeps meanwhile);
    None where ``/proc/stat`` cannot be read."""
    def sample():
        with open("/proc/stat") as f:
            vals = [int(v) for v in f.readline().split()[1:9]]
        return sum(vals), vals[3] + vals[4]  # total, idle + iowait (jiffies)

    try:
        t0, i0 = sample()
        time.sleep(interval_s)
        t1, i1 = sample()
    except (OSError, ValueError, IndexError):
        return None
    if t1 <= t0:
        return None
    return (os.cpu_count() or 1) * (1.0 - (i1 - i0) / (t1 - t0))


def resolve_threads(model: TLEDModel, n_threads: int | str | None) -> int | None:
    """The thread count a run uses: ``"auto"`` is 1 below :data:`AUTO_THREADS_MIN_ELEMENTS` elements; above, numba's
    current setting (None) unless other processes keep the CPUs busy (:func:`busy_cpus`, sampled once per run): then
    only as many threads as CPUs are free, at least 1 (every parallel region waits for its slowest thread, and a
    thread that shares its core with another process stalls each of the 3-5 regions of a step: on the 2-core VM at
    load 3, 2 threads ran the brain at 8 Mupd/s, 1 thread at 23). An int or None is returned as given."""
    if n_threads == "auto":
        if model.kernel_mesh.n_elements < AUTO_THREADS_MIN_ELEMENTS:
            return 1
        wanted = numba.get_num_threads()
        if wanted <= 1:
            return None
        busy = busy_cpus()
        if busy is None:
            return None
        free = int(np.floor((os.cpu_count() or 1) - busy + 0.5))
        return None if free >= wanted else max(1, free)
    if isinstance(n_threads, str):
        raise ValueError(f"n_threads must be an int, None or 'auto', not {n_threads!r}")
    return n_threads


def _check_status(model, status, bad, where, time_s):
    if status == STATUS_INVERTED:
        bad = int(model.element_order[bad])
        raise ElementInversionError(f"element {bad} inverted (J <= 0) at {where}, t = {time_s:.6g} s", bad,
                                    int(where.split()[-1]), time_s)
    if status == STATUS_NOT_FINITE:
        raise ElementInversionError(f"non-finite state at {where}, t = {time_s:.6g} s (unstable time step?)",
                                    -1, int(where.split()[-1]), time_s)


def _kernel_arguments(model: TLEDModel) -> tuple[KernelMesh, KernelMaterial, KernelLaws, KernelLoads]:
    """The model's arrays grouped as the compiled loops take them."""
    m = model.material
    mesh = KernelMesh(model.kernel_mesh.nodes, model.kernel_mesh.elements, model.dndx, model.vol0, model.chunk_lo, model.vnode)
    mat = KernelMaterial(m.kind, m.params, m.bulk_modulus_pa, model.use_anp, m.prony_g, m.prony_tau_s, m.pr_params)
    laws = KernelLaws(*m.functions())
    loads = KernelLoads(model.bc_nodes, model.bc_group, model.bc_mask, model.bc_dir, model.bc_rotate, model.rot_center,
                        max(1, len(model.groups)), model.free, model.hist_time, model.hist_vals, model.fext_ref,
                        model.contact_kind, model.cparams, model.contact_nodes)
    return mesh, mat, laws, loads


def run_explicit(model: TLEDModel, t_end_s: float, *, dt_s: float | None = None, safety: float = 0.7,
                 damping_1_s: float = 0.0, n_outputs: int = 100, u0_m: np.ndarray | None = None,
                 v0_m_s: np.ndarray | None = None, state: tuple | None = None,
                 n_threads: int | str | None = "auto", track_energy: bool = True, kernel: str = "auto") -> RunResult:
    """Explicit dynamic run from ``t = 0`` to ``t_end_s``.

    Parameters
    ----------
    dt_s : time step (s); default :func:`critical_time_step` with ``safety``
    damping_1_s : mass-proportional damping coefficient alpha (1/s)
    n_outputs : approximate number of recorded outputs
    u0_m, v0_m_s : initial displacement (m) and velocity (m/s) fields
    state : viscoelastic ``RunResult.state`` to start from (default virgin)
    n_threads : numba threads for this run (None: numba's current setting; ``"auto"``: :func:`resolve_threads`, one
        thread for small meshes)
    track_energy : accumulate the energy balance (``RunResult.energy_j``; a serial pass over the nodes per
        step, a few % of the step time)
    kernel : ``"auto"`` (the vectorised kernels of :mod:`.vectorised` for SVK and invariant laws, with or
        without up to :data:`.vectorised.MAX_PRONY_TERMS` QLV or Pipkin-Rogers terms, except float64 meshes above
        :data:`AUTO_VECTORISED_MAX_FLOAT64_ELEMENTS` elements; the generic kernel for stretch-based laws, more terms
        and the branch-energy law), ``"fused"`` (opt-in,
        :mod:`.fused`: the vectorised passes of an invariant law
        in one parallel region per step over overlapping node parts, one part per thread), ``"vectorised"`` or
        ``"generic"``; all agree to rounding
    """
    dt = critical_time_step(model, safety) if dt_s is None else float(dt_s)
    n_steps = max(1, int(np.ceil(t_end_s / dt - 1e-9)))
    out_every = max(1, n_steps // max(1, n_outputs))
    law = _fused_law(model, kernel)
    threads = resolve_threads(model, n_threads)
    if law is not None:
        # the same problem with the kernel nodes numbered part after part (the caller's numbering is unchanged)
        model, layout = fused.model_for_parts(model, _fused_parts(threads))
    u = np.zeros((model.mesh.n_nodes, 3), model.dtype) if u0_m is None else \
        np.array(model.to_kernel_nodes(u0_m), dtype=model.dtype)
    u_old = u.copy() if v0_m_s is None else (u - dt * model.to_kernel_nodes(v0_m_s)).astype(model.dtype)
    h_state, s_prev, w_prev = initial_states(model, state)
    with numba_threads(threads):
        if law is not None:
            # one parallel region per step over numba.get_num_threads() overlapping parts (fem.fused)
            fz = fused.fused_workspace(model, layout, law, h_state, s_prev)
            res = fused.fused_explicit_loop(*_kernel_arguments(model), model.mass, dt, n_steps, damping_1_s,
                                            out_every, u, u_old, bool(track_energy), fz)
            fused.fused_state_back(fz, layout, h_state, s_prev)
            ran = "fused"
        else:
            vec, fbuf, pbuf = _vector_setup(model, kernel, h_state, s_prev, w_prev)
            res = explicit_loop(*_kernel_arguments(model), model.mass, h_state, s_prev, w_prev, dt, n_steps,
                                damping_1_s, out_every, u, u_old, fbuf, pbuf, bool(track_energy), vec)
            _vector_state_back(vec, h_state, s_prev, w_prev)
            ran = "vectorised" if vec[0] else "generic"
    status, bad, step, u, u_old, t, force, torque, cforce, ke, energy = res
    _check_status(model, status, bad, f"step {step}", step * dt)
    names = model.group_names
    return RunResult(t, {n: force[:, i] for i, n in enumerate(names)}, {n: torque[:, i] for i, n in enumerate(names)},
                     cforce, ke, model.to_caller_nodes(u), model.to_caller_nodes(u_old), dt, np.zeros(0, np.int64),
                     caller_states(model, h_state, s_prev, w_prev),
                     {k: energy[:, i] for i, k in enumerate(ENERGY_TERMS)} if track_energy else {}, ran)


def solve_quasistatic(model: TLEDModel, times_s, *, tol_m: float | None = None, min_iter: int = 20,
                      max_iter: int = 200_000, u0_m: np.ndarray | None = None, state: tuple | None = None,
                      n_threads: int | str | None = "auto", kernel: str = "auto") -> RunResult:
    """Static equilibrium by dynamic relaxation at each time of ``times_s`` (loads from the histories).

    Parameters
    ----------
    times_s : increasing times; the boundary histories are evaluated there and the viscoelastic states
        advance between them (quasi-static viscoelasticity: inertia neglected)
    tol_m : displacement error bound for the Joldes termination criterion (default 1e-6 of the smallest
        element altitude)
    n_threads : numba threads for this run (None: numba's current setting; ``"auto"``: see :func:`run_explicit`)
    kernel : ``"auto"``, ``"vectorised"`` or ``"generic"`` (see :func:`run_explicit`; dynamic relaxation has no
        fused loop: ``"fused"`` runs the vectorised passes)
    """
    times = np.atleast_1d(np.asarray(times_s, float))
    if np.any(np.diff(times) < 0):
        raise ValueError("times_s must be non-decreasing")
    tol = 1e-6 * model.min_altitude_m if tol_m is None else float(tol_m)
    u = np.zeros((model.mesh.n_nodes, 3), model.dtype) if u0_m is None else \
        np.array(model.to_kernel_nodes(u0_m), dtype=model.dtype)
    h_state, s_prev, w_prev = initial_states(model, state)
    # dynamic relaxation has no fused loop: "fused" runs the vectorised passes
    vec, fbuf, pbuf = _vector_setup(model, "vectorised" if kernel == "fused" else kernel, h_state, s_prev, w_prev)
    with numba_threads(resolve_threads(model, n_threads)):
        res = dynamic_relaxation_loop(*_kernel_arguments(model), model.dr_mass, h_state, s_prev, w_prev, times, tol,
                                      min_iter, max_iter, u, fbuf, pbuf, vec)
    _vector_state_back(vec, h_state, s_prev, w_prev)
    status, bad, k, u, iters, force, torque, cforce = res
    if status == STATUS_NOT_CONVERGED:
        raise DynamicRelaxationError(f"dynamic relaxation did not converge in {max_iter} iterations at "
                                     f"increment {k} (t = {times[k]:.6g} s)")
    _check_status(model, status, bad, f"increment {k}", float(times[min(k, times.size - 1)]))
    names = model.group_names
    u = model.to_caller_nodes(u)
    return RunResult(times, {n: force[:, i] for i, n in enumerate(names)}, {n: torque[:, i] for i, n in enumerate(names)},
                     cforce, np.full(times.size, np.nan), u, u.copy(), float("nan"), iters,
                     caller_states(model, h_state, s_prev, w_prev), {},
                     "vectorised" if vec[0] else "generic")
