"""Virtual experiments with the TLED solver: rheometer torsion (strain- and torque-controlled) and flat-punch
indentation.

All are quasi-static (inertia is irrelevant at rheometer/indenter speeds): at every output time the
solver relaxes to equilibrium (dynamic relaxation) while the viscoelastic states advance between the
times with the exact Prony recursion, so the time history (rate, hold) is honoured.

A material is given as a card dict (the JSON shape written by ``tissuemech.cards``)::

    {"model": "neo_hookean", "parameters": {"mu": 900.0},
     "prony": {"g": [0.4, 0.2], "tau": [0.3, 6.0]},          # optional (QLV on the isochoric stress)
     "poisson_ratio": 0.49}                                  # or "bulk_modulus" (Pa); optional "density"

Outputs are canonical run datasets (:func:`tissuemech.canonical.make_run_dataset`, dim ``point``, SI units).
"""
from __future__ import annotations

import time
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import xarray as xr

from ..canonical import make_run_dataset
from ..models.plate import torsion_geometry_factor
from .materials import Material, make_material, material_from_card, small_strain_shear_modulus
from .mesh import (TetMesh, block_mesh, boundary_nodes, brain_mesh, cylinder_mesh, graded_layers, graded_ring_radii,
                   mesh_quality, write_mesh)
from .tled import (RigidContact, build_model, fixed_group, rotation_group, run_explicit, solve_quasistatic,
                   translation_group)

RHEOMETER_RADIUS_M = 12.5e-3
RHEOMETER_GAP_M = 2.0e-3


def card_material(card: Mapping) -> Material:
    """Material of a card. The card states its compressibility, ``bulk_modulus`` or ``poisson_ratio`` (the cards of
    ``tissuemech.cards`` carry the configuration's ``fem.poisson_ratio``); there is no default Poisson ratio."""
    if "bulk_modulus" not in card and "poisson_ratio" not in card:
        raise ValueError("the card states neither bulk_modulus nor poisson_ratio (the configuration's "
                         "fem.poisson_ratio belongs in the card)")
    return material_from_card(card)


def constant_shear_rate_history(rate_1_s: float, max_strain: float, n_points: int = 40) -> tuple[np.ndarray, np.ndarray]:
    """Rim-strain ramp ``gamma_R = rate t`` up to ``max_strain``: ``(time_s, rim_strain)`` without t = 0."""
    t_end = max_strain / rate_1_s
    t = np.linspace(0.0, t_end, n_points + 1)[1:]
    return t, rate_1_s * t


def relaxation_history(strain: float, rise_time_s: float, hold_time_s: float,
                       n_rise: int = 5, n_hold: int = 40) -> tuple[np.ndarray, np.ndarray]:
    """Ramp to ``strain`` in ``rise_time_s`` then hold, log-spaced hold times (``(time_s, rim_strain)``)."""
    t_rise = np.linspace(0.0, rise_time_s, n_rise + 1)[1:]
    t_hold = rise_time_s + np.geomspace(rise_time_s * 1e-2, hold_time_s, n_hold)
    t = np.concatenate([t_rise, t_hold])
    return t, np.where(t <= rise_time_s, strain * t / rise_time_s, strain)


def rheometer_sample_mesh(radius_m: float = RHEOMETER_RADIUS_M, gap_m: float = RHEOMETER_GAP_M,
                          element_size_m: float = 1.5e-3) -> TetMesh:
    """Cylinder mesh of the parallel-plate sample with about ``element_size_m`` edges (at least 2 layers)."""
    n_rings = max(3, int(np.ceil(radius_m / element_size_m)))
    n_layers = max(2, int(np.ceil(gap_m / element_size_m)))
    return cylinder_mesh(radius_m, gap_m, n_rings=n_rings, n_layers=n_layers)


def rheometer_torsion(card: Mapping, time_s, rim_strain, *, radius_m: float = RHEOMETER_RADIUS_M,
                      gap_m: float = RHEOMETER_GAP_M, element_size_m: float = 1.5e-3,
                      test: str = "torsion", anp: bool = True,
                      vtu_path: str | Path | None = None, n_threads: int | str | None = "auto") -> xr.Dataset:
    """Torsion of the bonded cylindrical sample between parallel plates, driven by a rim-strain history.

    The lower plate is fixed, the upper plate rotates by ``theta = gamma_R gap / R`` at fixed gap. Torque is
    the z-moment the upper plate applies to the sample; normal force is positive when the sample pushes
    the plates apart (rheometer convention).

    Parameters
    ----------
    card : material card dict (see module docstring)
    time_s, rim_strain : increasing times (s, > 0) and rim shear strain (1) at those times; the history
        starts from the undeformed state at t = 0 and is linear between the points
    radius_m, gap_m : sample geometry (default 25 mm plate, 2 mm gap)
    element_size_m : target element edge (m)
    vtu_path : optional VTU file for the final displacement field
    n_threads : numba threads (None: numba's setting; "auto": one for small meshes, see
        :func:`tissuemech.fem.tled.resolve_threads`; 1 is faster on a loaded shared machine)

    Returns
    -------
    canonical dataset with ``time``, ``shear_strain`` (rim), ``deflection_angle``, ``torque``,
    ``normal_force``, ``shear_stress`` (apparent 2M/(pi R^3)) and ``gap``.
    """
    t = np.asarray(time_s, float)
    gamma = np.asarray(rim_strain, float)
    if t.shape != gamma.shape or t.ndim != 1 or np.any(np.diff(t) <= 0) or t[0] <= 0:
        raise ValueError("time_s must be increasing, positive and of the same length as rim_strain")
    material = card_material(card)
    mesh = rheometer_sample_mesh(radius_m, gap_m, element_size_m)
    angle = gamma * gap_m / radius_m
    groups = _plate_groups(mesh, gap_m, np.concatenate([[0.0], t]), np.concatenate([[0.0], angle]))
    res = solve_quasistatic(build_model(mesh, material, groups, anp=anp), t, n_threads=n_threads)
    torque = res.torque_nm["upper_plate"]
    normal = -res.reaction_force_n["upper_plate"][:, 2]
    if vtu_path is not None:
        write_mesh(vtu_path, mesh, {"displacement": np.asarray(res.displacement_m, float)})
    return _torsion_dataset(t, angle, torque, normal, radius_m, gap_m,
                            {"test": test, "source": "tissuemech.fem TLED (dynamic relaxation)",
                             **_provenance(card, material, mesh, res.iterations)})


def _plate_groups(mesh: TetMesh, gap_m: float, time_s, angle_rad) -> list:
    """The rheometer's boundary groups: the upper plate (z = gap) rotated rigidly by ``angle_rad(time_s)``, the
    lower plate (z = 0) fixed (bonded sample, fixed gap)."""
    z = mesh.nodes[:, 2]
    return [rotation_group("upper_plate", np.flatnonzero(np.isclose(z, gap_m)), time_s, angle_rad),
            fixed_group("lower_plate", np.flatnonzero(np.isclose(z, 0.0)))]


def _torsion_dataset(t, angle, torque, normal, radius_m: float, gap_m: float, attrs: Mapping) -> xr.Dataset:
    """Canonical run of a torsion simulation: rim strain ``theta R / h``, apparent rim stress ``2M/(pi R^3)``."""
    return make_run_dataset(
        {"time": t, "shear_strain": angle * radius_m / gap_m, "deflection_angle": angle, "torque": torque,
         "normal_force": normal, "shear_stress": 2.0 * torque / (np.pi * radius_m**3), "gap": np.full(t.size, gap_m)},
        {"radius_m": radius_m, "gap_m": gap_m, **attrs})


class TorqueControlError(RuntimeError):
    """The torque controller of :func:`rheometer_creep` did not reach the target torque at some time."""


def rheometer_creep(card: Mapping, time_s, torque_nm, *, radius_m: float, gap_m: float,
                    element_size_m: float = 1.5e-3, test: str = "creep_recovery", anp: bool = True,
                    torque_tolerance: float = 1e-3, max_solves: int = 12,
                    n_threads: int | str | None = "auto") -> xr.Dataset:
    """Torque-controlled torsion of the bonded sample (creep, creep-recovery), quasi-static.

    The solver's boundary conditions prescribe displacements, so the torque is controlled as a stress-controlled
    rheometer does it, by feedback on the plate angle: at each output time the upper plate is rotated *rigidly*
    (the same prescribed rotation as :func:`rheometer_torsion`, so the plate stays a rigid plate and the torque is
    the plate's reaction moment) by the angle at which the equilibrium torque equals the target. That angle is found
    by a secant iteration, each trial a dynamic-relaxation solve from the previous time's equilibrium and
    viscoelastic state (advanced over the step as in :func:`rheometer_torsion`); only the accepted trial's state is
    kept. The first trial continues the previous step's creep rate, the slope starts at the elastic torsional
    stiffness ``G0 pi R^4 / (2h)`` and is then updated from the trials. Neither a distributed external moment on
    the plate nodes (the TLED has no rigid tie: the plate would warp) nor a torsional spring (a new boundary type
    in the kernels) is needed.

    Parameters
    ----------
    card : material card dict (see module docstring)
    time_s : increasing times (s, > 0); the sample starts at rest at t = 0
    torque_nm : target torque (N m) at those times (linear in between, as the strain of :func:`rheometer_torsion`)
    radius_m, gap_m : plate radius and gap (m), from the measurement (no defaults)
    torque_tolerance : accepted torque error, relative to the largest target magnitude
    max_solves : trials per time before :class:`TorqueControlError`

    Returns
    -------
    canonical dataset as :func:`rheometer_torsion` (``shear_strain`` is the rim strain the controller reached,
    ``torque`` the reached torque), attrs ``fem_torque_solves_total``.
    """
    t = np.asarray(time_s, float)
    target = np.asarray(torque_nm, float)
    if t.shape != target.shape or t.ndim != 1 or t.size == 0 or np.any(np.diff(t) <= 0) or t[0] <= 0:
        raise ValueError("time_s must be increasing, positive and of the same length as torque_nm")
    material = card_material(card)
    mesh = rheometer_sample_mesh(radius_m, gap_m, element_size_m)
    tol = torque_tolerance * max(float(np.max(np.abs(target))), np.finfo(float).tiny)
    stiffness = small_strain_shear_modulus(material) * torsion_geometry_factor(radius_m, gap_m)  # N m / rad
    angle, torque, normal, iterations = (np.zeros(t.size) for _ in range(4))
    u, state = np.zeros((mesh.n_nodes, 3)), None
    t_prev = theta_prev = theta_prev2 = dt_prev = 0.0
    m_prev, solves = 0.0, 0

    def trial(theta: float, dt: float, start):
        groups = _plate_groups(mesh, gap_m, np.array([0.0, dt]), np.array([theta_prev, theta]))
        model = build_model(mesh, material, groups, anp=anp, reorder=False)
        return solve_quasistatic(model, [dt], u0_m=start, state=state, n_threads=n_threads)

    for k, (tk, mk) in enumerate(zip(t, target)):
        dt = tk - t_prev
        creep = (theta_prev - theta_prev2) * dt / dt_prev if k > 0 else 0.0
        theta = theta_prev + creep + (mk - m_prev) / stiffness
        tried: list[tuple[float, float]] = []
        start = u
        while True:
            if len(tried) >= max_solves:
                raise TorqueControlError(f"torque control: no angle within {max_solves} trials gives the torque "
                                         f"{mk:.6g} N m at t = {tk:.6g} s (last {tried[-1][1]:.6g} N m)")
            res = trial(theta, dt, start)
            solves += 1
            m = float(res.torque_nm["upper_plate"][0])
            tried.append((theta, m))
            if abs(m - mk) <= tol:
                break
            if len(tried) >= 2:
                (ta, ma), (tb, mb) = tried[-2], tried[-1]
                if tb != ta and (mb - ma) / (tb - ta) > 0:
                    stiffness = (mb - ma) / (tb - ta)
            theta = theta + (mk - m) / stiffness
            start = res.displacement_m
        u, state = res.displacement_m, res.state
        angle[k], torque[k], normal[k] = theta, m, -res.reaction_force_n["upper_plate"][0, 2]
        iterations[k] = res.iterations[0]
        theta_prev2, theta_prev, m_prev, t_prev, dt_prev = theta_prev, theta, m, tk, dt
    return _torsion_dataset(t, angle, torque, normal, radius_m, gap_m,
                            {"test": test, "source": "tissuemech.fem TLED (dynamic relaxation, torque control by "
                                                     "the plate angle)",
                             "fem_torque_solves_total": solves, "fem_torque_tolerance_nm": tol,
                             **_provenance(card, material, mesh, iterations)})


def flat_punch_indentation(card: Mapping, punch_diameter_m: float = 8e-3, max_depth_m: float = 2e-3,
                           speed_m_s: float = 1e-4, *, sample_radius_m: float = 20e-3, sample_height_m: float = 10e-3,
                           element_size_m: float | None = None, growth: float = 1.3, bonded_punch: bool = False,
                           n_increments: int = 20, anp: bool = True,
                           vtu_path: str | Path | None = None, n_threads: int | str | None = "auto") -> xr.Dataset:
    """Rigid flat cylindrical punch pressed at constant speed into a sample bonded to a rigid base.

    The sample is a cylinder (radius ``sample_radius_m``) so that the punch edge coincides with a node ring;
    elements are ``element_size_m`` under the punch (default: punch radius / 4) and grow by ``growth``
    towards the rim and the base.

    Parameters
    ----------
    punch_diameter_m : 8 or 15 mm in the thesis protocol
    max_depth_m, speed_m_s : final depth (m) and constant indentation speed (m/s)
    bonded_punch : punch face bonded (no lateral slip) instead of frictionless
    vtu_path, n_threads : as in :func:`rheometer_torsion`

    Returns
    -------
    canonical dataset with ``time``, ``displacement`` (depth, m) and ``force`` (N, positive = compressive
    force on the punch).
    """
    a = 0.5 * punch_diameter_m
    if not 0 < a < sample_radius_m:
        raise ValueError("the punch must be narrower than the sample")
    h = a / 4.0 if element_size_m is None else min(float(element_size_m), a / 2.0)
    n_inner = max(2, int(np.ceil(a / h)))
    mesh = cylinder_mesh(sample_radius_m, sample_height_m, ring_radii_m=graded_ring_radii(sample_radius_m, a, n_inner, growth),
                         z_m=graded_layers(sample_height_m, a / n_inner, growth))
    material = card_material(card)
    x = mesh.nodes
    punch = np.flatnonzero(np.isclose(x[:, 2], sample_height_m) & (np.hypot(x[:, 0], x[:, 1]) <= a * (1 + 1e-9)))
    t_end = max_depth_m / speed_m_s
    t = np.linspace(0.0, t_end, n_increments + 1)[1:]
    dofs = (True, True, True) if bonded_punch else (False, False, True)
    groups = [translation_group("punch", punch, (0, 0, -1), [0.0, t_end], [0.0, max_depth_m], dofs=dofs),
              fixed_group("base", np.flatnonzero(np.isclose(x[:, 2], 0.0)))]
    res = solve_quasistatic(build_model(mesh, material, groups, anp=anp), t, n_threads=n_threads)
    if vtu_path is not None:
        write_mesh(vtu_path, mesh, {"displacement": np.asarray(res.displacement_m, float)})
    return make_run_dataset(
        {"time": t, "displacement": speed_m_s * t, "force": -res.reaction_force_n["punch"][:, 2]},
        {"test": "indentation", "punch_diameter_m": punch_diameter_m, "speed_m_s": speed_m_s,
         "sample_radius_m": sample_radius_m, "sample_height_m": sample_height_m, "bonded_punch": bonded_punch,
         "source": "tissuemech.fem TLED (dynamic relaxation)", **_provenance(card, material, mesh, res.iterations)})


def brain_indentation(card: Mapping, punch_diameter_m: float = 8e-3, max_depth_m: float = 2e-3,
                      speed_m_s: float = 1e-4, *, mesh: TetMesh | None = None, cache_dir: str | Path | None = None,
                      support_height_m: float = 25e-3, n_increments: int = 10,
                      anp: bool = True, vtu_path: str | Path | None = None,
                      n_threads: int | str | None = "auto") -> xr.Dataset:
    """Rigid flat cylindrical punch pressed vertically into the top of the MNI brain geometry.

    The punch (axis -z, frictionless, contact by projection) starts touching the highest surface node and
    advances at constant speed; the brain rests on a rigid support that holds every node less than
    ``support_height_m`` above its lowest point (brain stem and cerebellum, as the skull base would).

    Parameters
    ----------
    card : material card dict (see module docstring)
    punch_diameter_m, max_depth_m, speed_m_s : punch and loading (m, m/s)
    mesh : brain mesh in m (default :func:`tissuemech.fem.mesh.brain_mesh`, cached in ``cache_dir``)
    support_height_m : height of the supported base region (m)
    vtu_path, n_threads : as in :func:`rheometer_torsion`

    Returns
    -------
    canonical dataset with ``time``, ``displacement`` (punch depth, m), ``force`` (N, compressive on the
    punch positive) and ``contact_nodes`` (number of surface nodes under the punch at each output).
    """
    mesh = brain_mesh(cache_dir=cache_dir) if mesh is None else mesh
    x = mesh.nodes
    surface = boundary_nodes(mesh.elements)
    top = surface[np.argmax(x[surface, 2])]
    a = 0.5 * punch_diameter_m
    base = np.flatnonzero(x[:, 2] < x[:, 2].min() + support_height_m)
    under = np.hypot(x[surface, 0] - x[top, 0], x[surface, 1] - x[top, 1]) <= a + max_depth_m
    t_end = max_depth_m / speed_m_s
    t = np.linspace(0.0, t_end, n_increments + 1)[1:]
    punch = RigidContact("flat_punch", tuple(x[top]), a, (0.0, 0.0, -1.0), np.array([0.0, t_end]),
                         np.array([0.0, max_depth_m]), nodes=surface[under])
    material = card_material(card)
    model = build_model(mesh, material, [fixed_group("support", base)], punch, anp=anp)
    res = solve_quasistatic(model, t, n_threads=n_threads)
    u = np.asarray(res.displacement_m, float)
    on_face = np.isclose(x[surface[under], 2] + u[surface[under], 2], x[top, 2] - max_depth_m, atol=1e-9) & (
        np.hypot(x[surface[under], 0] - x[top, 0], x[surface[under], 1] - x[top, 1]) <= a)
    if vtu_path is not None:
        write_mesh(vtu_path, mesh, {"displacement": u})
    return make_run_dataset(
        {"time": t, "displacement": speed_m_s * t, "force": -res.contact_force_n[:, 2]},
        {"test": "indentation", "geometry": "MNI ICBM152-2009 brain (nilearn wheel)", "punch_diameter_m": punch_diameter_m,
         "speed_m_s": speed_m_s, "support_height_m": support_height_m, "punch_nodes_at_max_depth": int(on_face.sum()),
         "source": "tissuemech.fem TLED (dynamic relaxation, flat-punch contact)",
         **_provenance(card, material, mesh, res.iterations)})


def _provenance(card: Mapping, material: Material, mesh: TetMesh, iterations: np.ndarray) -> dict:
    q = mesh_quality(mesh)
    return {"model": str(card["model"]), "fem_n_elements": int(mesh.n_elements), "fem_n_nodes": int(mesh.n_nodes),
            "fem_min_altitude_m": q["min_altitude_m"], "fem_bulk_modulus_pa": material.bulk_modulus_pa,
            "fem_shear_modulus_pa": material.shear_modulus_pa, "fem_prony_terms": int(material.prony_g.size),
            "fem_dr_iterations_total": int(np.sum(iterations))}


def precompile_kernels(n_threads: int | None = 1) -> dict[str, float]:
    """Compile the TLED time loops the pipeline's FEM jobs and its timing rule run, into numba's cache.

    numba compiles the loops anew in every process whose cache is cold (~85-90 CPU s each on the 2-core VM since
    issue 17, 140 before, against ~1.5 s to load them from the cache); jobs that start together each compile them. This runs dynamic
    relaxation (with and without rigid contact) and explicit steps, with both internal-force kernels, on a
    one-cell block (neo-Hookean, ANP, float64, the types every experiment passes), once, before the jobs
    that need them. Returns the CPU seconds of each case.
    """
    mesh = block_mesh((1e-2, 1e-2, 5e-3), (2, 2, 1))
    x = mesh.nodes
    top = np.flatnonzero(np.isclose(x[:, 2], x[:, 2].max()))
    base = [fixed_group("base", np.flatnonzero(np.isclose(x[:, 2], 0.0)))]
    # a compile case only: no result is kept, so its moduli (and nu) reach nothing (the experiments take nu from
    # the card, i.e. the configuration's fem.poisson_ratio)
    material = make_material("neo_hookean", {"mu": 1000.0}, poisson_ratio=0.49)
    push = translation_group("push", top, (0, 0, -1), [0.0, 1.0], [0.0, 1e-5], dofs=(False, False, True))
    punch = RigidContact("flat_punch", tuple(x[top[0]]), 2e-3, (0.0, 0.0, -1.0), np.array([0.0, 1.0]),
                         np.array([0.0, 1e-5]), nodes=top)
    cases = {"dynamic_relaxation": (build_model(mesh, material, [push, *base]), "dr"),
             "dynamic_relaxation_contact": (build_model(mesh, material, base, punch), "dr"),
             "explicit": (build_model(mesh, material, base), "explicit")}
    seconds = {}
    for name, (model, loop) in cases.items():
        for kernel in ("vectorised", "generic"):
            t0 = time.process_time()
            if loop == "dr":
                solve_quasistatic(model, [1.0], n_threads=n_threads, kernel=kernel)
            else:
                run_explicit(model, 1e-5, dt_s=1e-6, n_outputs=1, track_energy=False, n_threads=n_threads,
                             kernel=kernel)
            seconds[f"{name}/{kernel}"] = time.process_time() - t0
    return seconds
