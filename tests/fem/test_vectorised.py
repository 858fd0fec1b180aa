"""The vectorised TLED kernels (tissuemech.fem.vectorised) against the generic per-element kernel."""
import numpy as np
import pytest

from tissuemech.fem.materials import constant_invariant_derivatives, make_material
from tissuemech.fem.mesh import block_mesh, element_volumes
from tissuemech.fem.tled import (ElementInversionError, build_model, fixed_group, run_explicit, solve_quasistatic,
                                 translation_group, vectorised_law)
from tissuemech.fem.vectorised import JM23_NEWTON_MAX, JM23_NEWTON_MIN, jm23_newton

L = 1e-2
MATERIALS = {
    "neo_hookean": ("neo_hookean", {"mu": 1000.0}, (), ()),
    "mooney_rivlin": ("mooney_rivlin", {"C10": 300.0, "C01": 200.0}, (), ()),
    "svk": ("saint_venant_kirchhoff", {"mu": 1000.0}, (), ()),
    "qlv_nh": ("neo_hookean", {"mu": 1000.0}, (0.3, 0.2, 0.1), (0.002, 0.02, 0.2)),
    "qlv_mr": ("mooney_rivlin", {"C10": 300.0, "C01": 200.0}, (0.4,), (0.01,)),
    # laws evaluated per element through the fitting code's functions (I1 only; I1 and I2)
    "rp3": ("reduced_polynomial3", {"C10": 400.0, "C20": 300.0, "C30": 100.0}, (), ()),
    "lp2": ("lopez_pamies2", {"mu1": 900.0, "alpha1": 1.2, "mu2": 100.0, "alpha2": 3.0}, (), ()),
    "polynomial2": ("polynomial2", {"C10": 300.0, "C01": 100.0, "C20": 200.0, "C11": 50.0, "C02": 30.0}, (), ()),
    "qlv_lp2": ("lopez_pamies2", {"mu1": 900.0, "alpha1": 1.2, "mu2": 100.0, "alpha2": 3.0}, (0.3, 0.2, 0.1, 0.05),
                (0.002, 0.02, 0.2, 2.0)),
    # Pipkin-Rogers (strain-dependent weights): a constant-derivative law and a law evaluated per element
    "pr_mr": ("mooney_rivlin", {"C10": 300.0, "C01": 200.0}, (), (0.002, 0.02),
              {"beta": [0.8, 0.4], "kappa": [1.5, -0.5], "gamma_s": 0.05}),
    "pr_rp3": ("reduced_polynomial3", {"C10": 400.0, "C20": 300.0, "C30": 100.0}, (), (0.002, 0.02, 0.2),
               {"beta": [1.4, 0.5, 0.5], "kappa": [0.5, 0.5, 0.5], "gamma_s": 0.12}),
    # more terms than one stress pass takes: two blocks (a full one and a partial one)
    "qlv6_rp3": ("reduced_polynomial3", {"C10": 400.0, "C20": 300.0, "C30": 100.0},
                 (0.2, 0.15, 0.1, 0.1, 0.05, 0.05), (0.001, 0.003, 0.01, 0.03, 0.1, 1.0)),
    "pr5_mr": ("mooney_rivlin", {"C10": 300.0, "C01": 200.0}, (), (0.001, 0.003, 0.01, 0.03, 0.3),
               {"beta": [0.6, 0.4, 0.3, 0.2, 0.5], "kappa": [1.5, -0.5, 0.8, 0.2, 2.0], "gamma_s": 0.05}),
}


def _material(name, nu=0.45):
    key, params, g, tau, *pr = MATERIALS[name]
    return make_material(key, params, poisson_ratio=nu, prony_g=g, prony_tau_s=tau, pipkin_rogers=pr[0] if pr else None)


def _sheared_block(material, anp=True, precision="float64", cells=4):
    mesh = block_mesh((L, L, L), (cells, cells, cells))
    z = mesh.nodes[:, 2]
    groups = [fixed_group("bottom", np.flatnonzero(np.isclose(z, 0))),
              translation_group("top", np.flatnonzero(np.isclose(z, L)), (1, 0, 0.3), [0, 0.02], [0, 2e-3])]
    return build_model(mesh, material, groups, anp=anp, precision=precision, n_chunks=3)


@pytest.mark.parametrize("name", sorted(MATERIALS))
@pytest.mark.parametrize("anp", [True, False])
def test_explicit_run_equals_generic_kernel(name, anp):
    model = _sheared_block(_material(name), anp=anp)
    gen = run_explicit(model, 0.02, damping_1_s=100.0, kernel="generic", n_outputs=10)
    vec = run_explicit(model, 0.02, damping_1_s=100.0, kernel="vectorised", n_outputs=10)
    assert (gen.kernel, vec.kernel) == ("generic", "vectorised")
    f_gen, f_vec = gen.reaction_force_n["top"], vec.reaction_force_n["top"]
    assert np.abs(f_gen).max() > 1e-4  # a real load, not two zeros
    np.testing.assert_allclose(f_vec, f_gen, rtol=0, atol=1e-11 * np.abs(f_gen).max())
    np.testing.assert_allclose(vec.displacement_m, gen.displacement_m, rtol=0, atol=1e-14)
    for a, b in zip(vec.state, gen.state):  # QLV states come back in the generic layout
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-10 * max(1.0, np.abs(b).max(initial=0.0)))
    for k in gen.energy_j:
        np.testing.assert_allclose(vec.energy_j[k], gen.energy_j[k], rtol=1e-10, atol=1e-16)


@pytest.mark.parametrize("name", ["neo_hookean", "qlv_nh", "qlv_lp2", "pr_rp3", "qlv6_rp3", "pr5_mr"])
def test_quasistatic_equals_generic_kernel_and_continues_from_state(name):
    model = _sheared_block(_material(name))
    gen = solve_quasistatic(model, [0.01, 0.02], kernel="generic")
    vec = solve_quasistatic(model, [0.01, 0.02], kernel="vectorised")
    np.testing.assert_allclose(vec.reaction_force_n["top"], gen.reaction_force_n["top"], rtol=1e-9)
    np.testing.assert_array_equal(vec.iterations, gen.iterations)
    # continuing a relaxation from the stored state is kernel-independent too
    gen2 = solve_quasistatic(model, [0.03, 0.05], kernel="generic", u0_m=gen.displacement_m, state=gen.state)
    vec2 = solve_quasistatic(model, [0.03, 0.05], kernel="vectorised", u0_m=vec.displacement_m, state=vec.state)
    np.testing.assert_allclose(vec2.reaction_force_n["top"], gen2.reaction_force_n["top"], rtol=1e-9)


def test_float32_storage_agrees_with_float64_to_single_precision():
    f64 = run_explicit(_sheared_block(_material("qlv_nh")), 0.02, damping_1_s=100.0, kernel="vectorised")
    f32 = run_explicit(_sheared_block(_material("qlv_nh"), precision="float32"), 0.02, damping_1_s=100.0,
                       kernel="vectorised")
    a, b = f64.reaction_force_n["top"], f32.reaction_force_n["top"]
    assert np.abs(b - a).max() < 1e-4 * np.abs(a).max()


@pytest.mark.parametrize("name", ["neo_hookean", "qlv_nh", "lp2"])
def test_large_volume_changes_outside_the_newton_range_take_the_cbrt_path(name):
    """``u_z = c z^2`` gives J = 1 + 2 c z from 1 to 10: elements on both sides of the branch-free range."""
    mat = _material(name, nu=0.3)
    mesh = block_mesh((L, L, L), (6, 6, 6))
    model = build_model(mesh, mat, [fixed_group("bottom", np.flatnonzero(np.isclose(mesh.nodes[:, 2], 0)))],
                        n_chunks=3)
    x = model.mesh.nodes
    u0 = np.zeros_like(x)
    u0[:, 2] = 4.5 / L * x[:, 2] ** 2
    J = element_volumes(x + u0, model.mesh.elements) / element_volumes(x, model.mesh.elements)
    assert np.all(J > 0)
    assert (J < JM23_NEWTON_MAX).any() and (J > JM23_NEWTON_MAX).any()
    dt = 1e-6
    gen = run_explicit(model, 3 * dt, dt_s=dt, u0_m=u0, v0_m_s=np.zeros_like(u0), kernel="generic", n_outputs=3)
    vec = run_explicit(model, 3 * dt, dt_s=dt, u0_m=u0, v0_m_s=np.zeros_like(u0), kernel="vectorised", n_outputs=3)
    scale = np.abs(gen.reaction_force_n["bottom"]).max()
    assert scale > 0
    np.testing.assert_allclose(vec.reaction_force_n["bottom"], gen.reaction_force_n["bottom"], rtol=0,
                               atol=1e-11 * scale)
    np.testing.assert_allclose(vec.displacement_m, gen.displacement_m, rtol=0, atol=1e-12 * L)
    for a, b in zip(vec.state, gen.state):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-10 * max(1.0, np.abs(b).max(initial=0.0)))


@pytest.mark.parametrize("anp", [True, False])
def test_inverted_element_is_reported_by_id(anp):
    model = _sheared_block(_material("neo_hookean"), anp=anp)
    x = model.mesh.nodes
    centre = int(np.argmin(np.linalg.norm(x - 0.5 * L, axis=1)))
    u0 = np.zeros_like(x)
    u0[centre] = (0.0, 0.0, -0.4 * L)  # pushes the centre node through the elements below it
    J = element_volumes(x + u0, model.mesh.elements) / element_volumes(x, model.mesh.elements)
    inverted = set(np.flatnonzero(J <= 0).tolist())
    assert inverted
    with pytest.raises(ElementInversionError, match="inverted") as err:
        run_explicit(model, 1e-5, dt_s=1e-6, u0_m=u0, kernel="vectorised")
    assert err.value.element == min(inverted) and err.value.step == 0


def test_kernel_choice():
    assert vectorised_law(_material("svk"))[0] is True
    assert vectorised_law(_material("neo_hookean")) == (False, True, 500.0, 0.0)
    assert constant_invariant_derivatives(_material("mooney_rivlin")) == (300.0, 200.0)
    assert vectorised_law(_material("rp3"))[:2] == (False, False)  # per-element law evaluation
    ogden = make_material("ogden1", {"mu1": 1000.0, "alpha1": -5.0}, poisson_ratio=0.45)
    eight_terms = make_material("neo_hookean", {"mu": 1e3}, poisson_ratio=0.45, prony_g=[0.1] * 8,
                                prony_tau_s=np.logspace(-2, 5, 8))
    nine_terms = make_material("neo_hookean", {"mu": 1e3}, poisson_ratio=0.45, prony_g=[0.1] * 9,
                               prony_tau_s=np.logspace(-2, 6, 9))
    assert vectorised_law(eight_terms) == (False, True, 500.0, 0.0)
    assert vectorised_law(ogden) is None and vectorised_law(nine_terms) is None
    assert run_explicit(_sheared_block(nine_terms), 1e-3, kernel="auto").kernel == "generic"
    assert run_explicit(_sheared_block(_material("pr5_mr")), 1e-3, kernel="auto").kernel == "vectorised"
    model = _sheared_block(ogden)
    assert run_explicit(model, 1e-3, kernel="auto").kernel == "generic"
    assert run_explicit(_sheared_block(_material("rp3")), 1e-3, kernel="auto").kernel == "vectorised"
    assert run_explicit(_sheared_block(_material("svk")), 1e-3, kernel="auto").kernel == "vectorised"
    with pytest.raises(ValueError, match="ogden1"):
        run_explicit(model, 1e-3, kernel="vectorised")
    with pytest.raises(ValueError, match="kernel must be one of"):
        run_explicit(model, 1e-3, kernel="fast")


def test_branch_free_j_power_is_exact_on_its_range():
    J = np.concatenate([np.linspace(JM23_NEWTON_MIN, JM23_NEWTON_MAX, 20001), 1.0 + np.logspace(-12, -1, 50)])
    approx = np.array([jm23_newton(j) for j in J])
    np.testing.assert_allclose(approx, J ** (-2.0 / 3.0), rtol=2e-15)
