"""Selective mass scaling: added mass on the smallest elements only, a longer stable step."""
import numpy as np
import pytest

from tissuemech.fem.materials import make_material
from tissuemech.fem.mesh import TetMesh, block_mesh, element_min_altitudes, element_volumes
from tissuemech.fem.tled import ElementInversionError, build_model, critical_time_step, fixed_group, run_explicit

L = 3e-3


def _block_with_one_thin_element():
    mesh = block_mesh((L, L, L), (3, 3, 3))
    x = mesh.nodes.copy()
    inner = int(np.argmin(np.linalg.norm(x - 1e-3, axis=1)))
    x[inner] += np.array([0.45e-3, 0.4e-3, 0.42e-3])  # towards a face: a few thin elements around this node
    return TetMesh(x, mesh.elements)


def test_scaled_model_has_the_requested_step_and_mass_only_on_small_elements():
    mesh = _block_with_one_thin_element()
    mat = make_material("neo_hookean", {"mu": 1000.0}, poisson_ratio=0.49, density_kg_m3=1000.0)
    plain = build_model(mesh, mat)
    c_d = np.sqrt(mat.dilatational_modulus_pa / mat.density_kg_m3)
    alt = element_min_altitudes(mesh.nodes, mesh.elements)
    assert critical_time_step(plain, 1.0) == pytest.approx(alt.min() / c_d, rel=1e-12)
    target = np.quantile(alt, 0.1) / c_d  # the 10 % smallest elements get mass
    scaled = build_model(mesh, mat, mass_scaling_step_s=target)
    assert critical_time_step(scaled, 1.0) == pytest.approx(target, rel=1e-12)
    assert plain.added_mass_fraction == 0.0
    # the added mass is that of the scaled elements, (target c_d / alt)^2 - 1 times their own
    vol = element_volumes(mesh.nodes, mesh.elements)
    small = alt < target * c_d
    expected = np.sum(((target * c_d / alt[small]) ** 2 - 1.0) * vol[small]) / vol.sum()
    assert scaled.added_mass_fraction == pytest.approx(expected, rel=1e-12) and 0 < expected < 0.2
    extra = scaled.lumped_mass_kg - plain.lumped_mass_kg
    untouched = np.setdiff1d(np.arange(mesh.n_nodes), np.unique(mesh.elements[small]))
    np.testing.assert_allclose(extra[untouched], 0.0, atol=1e-15 * plain.lumped_mass_kg.max())
    assert extra.sum() == pytest.approx(expected * mat.density_kg_m3 * vol.sum(), rel=1e-10)


def test_scaled_model_is_stable_at_its_longer_step():
    """At 1.5x the unscaled critical step the unscaled model diverges, the scaled one conserves energy."""
    mesh = _block_with_one_thin_element()
    mat = make_material("neo_hookean", {"mu": 1000.0}, poisson_ratio=0.49, density_kg_m3=1000.0)
    bottom = fixed_group("bottom", np.flatnonzero(np.isclose(mesh.nodes[:, 2], 0.0)))
    plain = build_model(mesh, mat, [bottom], anp=False)
    dt = 1.5 * critical_time_step(plain, 1.0)
    scaled = build_model(mesh, mat, [bottom], anp=False, mass_scaling_step_s=dt / 0.6)  # dt = 0.6 x its step
    v0 = np.zeros_like(mesh.nodes)
    v0[:, 0] = 1e-3 * mesh.nodes[:, 2] / L
    n = 400
    ok = run_explicit(scaled, n * dt, dt_s=dt, v0_m_s=v0, n_outputs=20)
    energy0 = ok.kinetic_energy_j[0] + ok.energy_j["internal_work"][0]
    total = ok.kinetic_energy_j + ok.energy_j["internal_work"]
    assert np.abs(total - energy0).max() < 2e-2 * energy0
    with pytest.raises((ElementInversionError, AssertionError)):
        res = run_explicit(plain, n * dt, dt_s=dt, v0_m_s=v0, n_outputs=20)
        assert np.all(np.isfinite(res.displacement_m)) and np.abs(res.displacement_m).max() < L
