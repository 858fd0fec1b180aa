"""Verification of the TLED solver against the fitting code's closed forms, FElupe and the energy balance.

Complements ``test_tled.py`` (patch tests, Sneddon, Hertz, ANP locking) with the checks issue 6 lists:
single-element simple shear equals the *fitting code's* closed form for every hyperelastic law and for
QLV; torsion of the rheometer cylinder equals FElupe's implicit solution on the same mesh; a damped,
loaded dynamic run balances its energy; inversion is reported in explicit runs too.
"""
import felupe as fem  # test extra: a missing felupe is an error, not a skip
import numpy as np
import pytest
from fem_reference import neo_hookean_energy_j, polar_moment_m4

from tissuemech.fem.materials import make_material
from tissuemech.fem.mesh import block_mesh, cylinder_mesh
from tissuemech.fem.tled import (ElementInversionError, build_model, critical_time_step, fixed_group,
                                 rotation_group, run_explicit, shape_derivatives, solve_quasistatic,
                                 translation_group)
from tissuemech.models.hyperelastic import MODELS as HYPERELASTIC_MODELS

L = 1e-2  # cube edge, m


def _shear_cube(material, time_s, gamma, anp=True):
    mesh = block_mesh((L, L, L), (1, 1, 1))
    y = mesh.nodes[:, 1]
    groups = [translation_group("top", np.flatnonzero(np.isclose(y, L)), (1, 0, 0), time_s, np.asarray(gamma) * L),
              fixed_group("bottom", np.flatnonzero(np.isclose(y, 0)))]
    return build_model(mesh, material, groups, anp=anp)


def _law_parameters(model):
    """The registry's initial values, with zero coefficients made non-zero so that every term acts."""
    return {s.name: (s.init if s.init != 0 else 15.0) for s in model.param_specs}


@pytest.mark.parametrize("key", sorted(k for k in HYPERELASTIC_MODELS if k != "linear_elastic"))
def test_single_element_simple_shear_equals_fitting_closed_form(key):
    """TLED reaction of one sheared cube (6 tets, J = 1) vs models.hyperelastic's incompressible closed
    forms: top traction P12 = sigma12, P22 = sigma22 = (N2 - N1)/3 (deviatoric stress, no pressure)."""
    law = HYPERELASTIC_MODELS[key]()
    p = _law_parameters(law)
    gammas = np.array([0.05, 0.3, 0.6])
    mat = make_material(key, p, poisson_ratio=0.45)
    res = solve_quasistatic(_shear_cube(mat, [0.0, 1.0], [0.0, 1.0]), gammas, tol_m=1e-13)
    sigma12 = law.elastic_shear_stress(p, gammas)
    n1, n2 = law.normal_stress_differences(p, gammas)
    fx, fy = res.reaction_force_n["top"][:, 0] / L**2, res.reaction_force_n["top"][:, 1] / L**2
    np.testing.assert_allclose(fx, sigma12, rtol=1e-9)
    np.testing.assert_allclose(fy, (n2 - n1) / 3.0, rtol=1e-8, atol=1e-9 * np.abs(sigma12).max())


@pytest.mark.parametrize("qlv_key, elastic_key", [("qlv_neo_hookean_prony4", "neo_hookean"),
                                                  ("qlv_rp2_prony4", "reduced_polynomial2")])
def test_single_element_qlv_ramp_hold_equals_fitting_recursion(qlv_key, elastic_key):
    """QLV (thesis relaxation times 0.1-100 s) on a ramp-and-hold simple shear.

    The FEM applies the Prony recursion to the isochoric 2nd Piola-Kirchhoff stress, so the exact
    reference is the fitting code's recursion (``models.recursion.qlv_stress``) applied to
    ``S12 = sigma12 - gamma sigma22`` and ``S22 = sigma22`` of the fitting closed forms, recombined as
    ``P12 = S12 + gamma S22``. At small strain this is the fitting code's 1-D QLV prediction itself.
    """
    from tissuemech.models.qlv import qlv_params
    from tissuemech.models.recursion import qlv_stress
    from tissuemech.models.registry import get_model

    qlv = get_model(qlv_key)
    law = HYPERELASTIC_MODELS[elastic_key]()
    p_el = _law_parameters(law)
    g = np.array([0.25, 0.2, 0.1, 0.05])
    p = qlv_params(qlv, p_el, g)
    g_inf, g_fit, taus = qlv.prony_weights(p)
    np.testing.assert_allclose(g_fit, g)
    for gamma_max, rtol_1d in ((0.5, None), (0.01, 2e-4)):
        t = np.concatenate([[0.0], np.linspace(0.05, 0.2, 4), 0.2 + np.array([0.05, 0.3, 1.0, 3.0, 10.0, 40.0])])
        gamma = np.minimum(t / 0.2, 1.0) * gamma_max
        mat = make_material(elastic_key, p_el, poisson_ratio=0.45, prony_g=g, prony_tau_s=taus)
        res = solve_quasistatic(_shear_cube(mat, t, gamma), t[1:], tol_m=1e-14)
        s12 = law.elastic_shear_stress(p_el, gamma)
        n1, n2 = law.normal_stress_differences(p_el, gamma)
        s22 = (n2 - n1) / 3.0
        S12 = qlv_stress(t, s12 - gamma * s22, g, taus)
        S22 = qlv_stress(t, s22, g, taus)
        fx = res.reaction_force_n["top"][:, 0] / L**2
        fy = res.reaction_force_n["top"][:, 1] / L**2
        np.testing.assert_allclose(fx, (S12 + gamma * S22)[1:], rtol=1e-9)
        np.testing.assert_allclose(fy, S22[1:], rtol=1e-8, atol=1e-10 * np.abs(fx).max())
        assert fx[-1] < 0.8 * fx[3]  # it relaxed
        if rtol_1d is not None:
            one_d = qlv.shear_stress_history(p, t, gamma)[1:]
            np.testing.assert_allclose(fx, one_d, rtol=rtol_1d)


def _anp_energy_j(nodes, elements, u, mu, kappa):
    """Stored energy of the ANP element: isochoric neo-Hookean per element plus ``sum_n V_n/4 kappa/2
    (J_n - 1)^2`` with the volume-averaged nodal ``J_n`` (the kernel's averaged pressure derives from it)."""
    dndx, vol = shape_derivatives(nodes, elements)
    F = np.eye(3) + np.einsum("eai,eaj->eij", u[elements], dndx.reshape(-1, 4, 3))
    J = np.linalg.det(F)
    iso = np.sum(vol * 0.5 * mu * (J ** (-2.0 / 3.0) * np.einsum("eij,eij->e", F, F) - 3.0))
    vn = np.bincount(elements.ravel(), np.repeat(vol, 4), minlength=len(nodes))
    jn = np.bincount(elements.ravel(), np.repeat(vol * J, 4), minlength=len(nodes)) / vn
    return float(iso + np.sum(0.25 * vn * 0.5 * kappa * (jn - 1.0) ** 2))


@pytest.mark.parametrize("anp", [False, True])
def test_damped_loaded_dynamic_run_balances_energy(anp):
    """Kinetic + internal + damping = initial kinetic + external + constraint work (supports), and the
    internal work equals the stored energy of the final state computed from W itself."""
    mu, nu, rho, alpha = 1000.0, 0.45, 1000.0, 40.0
    mat = make_material("neo_hookean", {"mu": mu}, poisson_ratio=nu, density_kg_m3=rho)
    mesh = block_mesh((L, L, L), (3, 3, 3))
    x = mesh.nodes
    side = np.isclose(x[:, 0], L) & ~np.isclose(x[:, 2], 0) & ~np.isclose(x[:, 2], L)
    fext = np.zeros_like(x)
    fext[side, 1] = 2e-3  # N per node, ramped in below
    groups = [translation_group("top", np.flatnonzero(np.isclose(x[:, 2], L)), (1, 0, -0.3), [0, 0.01, 1],
                                [0, 0.1 * L, 0.1 * L]),
              fixed_group("bottom", np.flatnonzero(np.isclose(x[:, 2], 0)))]
    model = build_model(mesh, mat, groups, anp=anp, external_force_n=fext, external_time_s=[0, 0.02, 1],
                        external_scale=[0, 1, 1])
    v0 = np.zeros_like(x)
    v0[:, 1] = 0.02 * x[:, 2] / L
    ke0 = 0.5 * np.sum(model.lumped_mass_kg * (v0**2).sum(1))
    dt = critical_time_step(model, 0.5)
    res = run_explicit(model, 0.03, dt_s=dt, damping_1_s=alpha, v0_m_s=v0, n_outputs=30)
    e = res.energy_j
    ke = res.kinetic_energy_j
    balance = ke + e["internal_work"] + e["damping_work"] - e["external_work"] - e["constraint_work"] - ke0
    scale = e["internal_work"].max()
    assert np.abs(balance).max() < 1e-9 * scale
    assert e["damping_work"][-1] > 0.05 * scale and e["external_work"][-1] > 0.05 * scale  # all terms act
    assert e["constraint_work"][-1] > 0.3 * scale
    u_mid = 0.5 * (res.displacement_m + res.previous_displacement_m)
    energy = _anp_energy_j if anp else neo_hookean_energy_j
    psi = energy(x, mesh.elements, u_mid, mu, mat.bulk_modulus_pa)
    psi0 = energy(x, mesh.elements, -0.5 * dt * v0, mu, mat.bulk_modulus_pa)
    assert e["internal_work"][-1] == pytest.approx(psi - psi0, rel=1e-3)  # O(dt^2): 2e-4 at safety 0.5


def test_explicit_inversion_is_reported_with_element_and_step():
    mat = make_material("neo_hookean", {"mu": 1000.0}, poisson_ratio=0.3, density_kg_m3=1000.0)
    mesh = block_mesh((L, L, L), (2, 2, 2))
    z = mesh.nodes[:, 2]
    groups = [translation_group("top", np.flatnonzero(np.isclose(z, L)), (0, 0, -1), [0, 1e-3], [0, 1.5 * L]),
              fixed_group("bottom", np.flatnonzero(np.isclose(z, 0)))]
    model = build_model(mesh, mat, groups)
    with pytest.raises(ElementInversionError, match=r"element \d+ inverted \(J <= 0\) at step \d+") as info:
        run_explicit(model, 2e-3, dt_s=1e-5)
    # the plate passes the mid-plane nodes (5 mm) after 0.33 ms
    assert 0 <= info.value.element < mesh.n_elements and 2e-4 < info.value.time_s < 1e-3



def _felupe_torsion(mesh, mu, kappa, height, angles):
    """Torque and axial force on the upper plate from FElupe (Newton, linear tets, same NeoHooke)."""
    x = mesh.nodes
    region = fem.RegionTetra(fem.Mesh(x.copy(), mesh.elements.astype(np.int64), "tetra"))
    field = fem.FieldContainer([fem.Field(region, dim=3)])
    top = np.isclose(x[:, 2], height)
    plate = fem.Boundary(field[0], mask=top)
    bcs = {"bottom": fem.Boundary(field[0], mask=np.isclose(x[:, 2], 0)), "top": plate}
    xt = x[top]
    ramp = np.array([np.column_stack([np.cos(a) * xt[:, 0] - np.sin(a) * xt[:, 1] - xt[:, 0],
                                      np.sin(a) * xt[:, 0] + np.cos(a) * xt[:, 1] - xt[:, 1],
                                      np.zeros(len(xt))]).ravel() for a in angles])
    solid = fem.SolidBody(fem.NeoHooke(mu=mu, bulk=kappa), field)
    fem.Job(steps=[fem.Step(items=[solid], ramp={plate: ramp}, boundaries=bcs)]).evaluate(verbose=0, tol=1e-10)
    f = solid.assemble.vector().toarray().reshape(-1, 3)[top]
    xc = xt + field[0].values[top]
    return float(np.sum(xc[:, 0] * f[:, 1] - xc[:, 1] * f[:, 0])), float(f[:, 2].sum()), field[0].values


def test_rheometer_torsion_matches_felupe_and_closed_form():
    """Same mesh, same law: torque and Poynting thrust within 1e-6 of FElupe (the brief asks for 2 %);
    the production ANP element against M = (pi/2) mu psi R^4 (meshed polygon's polar moment)."""
    R, H, mu, nu, gamma_rim = 12.5e-3, 2e-3, 1000.0, 0.49, 0.1
    mesh = cylinder_mesh(R, H, n_rings=6, n_layers=3)
    mat = make_material("neo_hookean", {"mu": mu}, poisson_ratio=nu)
    psi = gamma_rim / R
    angles = np.linspace(0, psi * H, 5)[1:]
    torque_ref, thrust_ref, u_ref = _felupe_torsion(mesh, mu, mat.bulk_modulus_pa, H, angles)
    z = mesh.nodes[:, 2]
    groups = [rotation_group("top", np.flatnonzero(np.isclose(z, H)), [0, 1], [0, psi * H]),
              fixed_group("bottom", np.flatnonzero(np.isclose(z, 0)))]
    res = solve_quasistatic(build_model(mesh, mat, groups, anp=False), [0.25, 0.5, 0.75, 1.0], tol_m=1e-13)
    assert res.torque_nm["top"][-1] == pytest.approx(torque_ref, rel=1e-6)
    assert res.reaction_force_n["top"][-1, 2] == pytest.approx(thrust_ref, rel=1e-5)
    np.testing.assert_allclose(res.displacement_m, u_ref, atol=1e-7 * R * psi * H)
    ip = polar_moment_m4(mesh.nodes, mesh.elements, H)
    anp = solve_quasistatic(build_model(mesh, mat, groups, anp=True), [1.0])
    assert anp.torque_nm["top"][0] / (mu * psi * ip) == pytest.approx(1.0, abs=0.025)
    assert abs(anp.torque_nm["top"][0] / torque_ref - 1) > 0.02  # plain tets lock, ANP relieves it


@pytest.mark.slow
def test_torsion_thrust_converges_to_closed_form_when_incompressible():
    """Thrust N = -(pi/4) mu psi^2 R^4 (Poynting, incompressible). With ANP tets at nu = 0.4999 the
    thrust error falls roughly with h^2 (measured: 3.56, 1.87, 1.45 x closed form at 2k, 9k, 26k tets);
    at nu = 0.49 the compressible continuum thrust is well below the incompressible value (FElupe
    quadratic tets: 0.63), so the closed form is only a limit."""
    R, H, mu, psi = 12.5e-3, 2e-3, 1000.0, 0.1 / 12.5e-3
    mat = make_material("neo_hookean", {"mu": mu}, poisson_ratio=0.4999)
    ratios = []
    for n_rings, n_layers in ((6, 3), (10, 5)):
        mesh = cylinder_mesh(R, H, n_rings=n_rings, n_layers=n_layers)
        z = mesh.nodes[:, 2]
        groups = [rotation_group("top", np.flatnonzero(np.isclose(z, H)), [0, 1], [0, psi * H]),
                  fixed_group("bottom", np.flatnonzero(np.isclose(z, 0)))]
        res = solve_quasistatic(build_model(mesh, mat, groups), [1.0])
        ip = polar_moment_m4(mesh.nodes, mesh.elements, H)
        ratios.append(res.reaction_force_n["top"][0, 2] / (-0.5 * mu * psi**2 * ip))
    h_ratio = 10 / 6
    assert (ratios[0] - 1) / (ratios[1] - 1) > 0.8 * h_ratio**2  # about second order
    extrapolated = ratios[1] + (ratios[1] - ratios[0]) / (h_ratio**2 - 1)
    assert extrapolated == pytest.approx(1.0, abs=0.12)


def test_flat_punch_contact_equals_prescribed_punch_on_a_flat_surface():
    """The rigid flat cylindrical punch by projection (for curved surfaces such as the brain) gives the same
    equilibrium as prescribing u_z on the face nodes (frictionless) where the surface is flat."""
    from tissuemech.fem.mesh import graded_layers, graded_ring_radii
    from tissuemech.fem.tled import RigidContact

    a, size, depth = 2e-3, 8e-3, 0.3e-3
    mesh = cylinder_mesh(size, size, ring_radii_m=graded_ring_radii(size, a, 2, 1.6), z_m=graded_layers(size, 1e-3, 1.6))
    x = mesh.nodes
    mat = make_material("neo_hookean", {"mu": 1000.0}, poisson_ratio=0.45)
    base = fixed_group("base", np.flatnonzero(np.isclose(x[:, 2], 0)))
    face = np.flatnonzero(np.isclose(x[:, 2], size) & (np.hypot(x[:, 0], x[:, 1]) <= a * (1 + 1e-9)))
    prescribed = solve_quasistatic(build_model(mesh, mat, [translation_group(
        "punch", face, (0, 0, -1), [0, 1], [0, depth], dofs=(False, False, True)), base]), [0.5, 1.0], tol_m=1e-12)
    # the nodes of the punch-edge ring slide outwards (frictionless); a face radius between that ring and
    # the next keeps them on the face, as the prescribed group does
    punch = RigidContact("flat_punch", (0.0, 0.0, size), 1.2 * a, (0, 0, -1), np.array([0, 1.0]),
                         np.array([0, depth]))
    contact = solve_quasistatic(build_model(mesh, mat, [base], punch), [0.5, 1.0], tol_m=1e-12)
    np.testing.assert_allclose(contact.contact_force_n[:, 2], prescribed.reaction_force_n["punch"][:, 2], rtol=1e-6)
    np.testing.assert_allclose(contact.displacement_m, prescribed.displacement_m, atol=1e-6 * depth)
    with pytest.raises(ValueError, match="unknown rigid contact shape 'cone'"):
        build_model(mesh, mat, [base], RigidContact("cone", (0, 0, size), a))
