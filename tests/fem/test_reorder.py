"""Locality renumbering inside ``build_model``: the caller's numbering in, the caller's numbering out."""
import numpy as np
import pytest

from tissuemech.fem.materials import make_material
from tissuemech.fem.mesh import TetMesh, block_mesh, element_volumes, mean_element_span
from tissuemech.fem.tled import (ElementInversionError, RigidContact, build_model, fixed_group, run_explicit,
                                 solve_quasistatic, translation_group)

L = 1e-2


def _shuffled_block(seed=3, cells=(4, 4, 3)):
    """A block mesh with nodes and elements in random order, and the permutations used."""
    mesh = block_mesh((L, L, 0.75 * L), cells)
    rng = np.random.default_rng(seed)
    node_perm = rng.permutation(mesh.n_nodes)  # new node k is old node node_perm[k]
    new_index = np.empty_like(node_perm)
    new_index[node_perm] = np.arange(node_perm.size)
    elem_perm = rng.permutation(mesh.n_elements)
    return mesh, TetMesh(mesh.nodes[node_perm], new_index[mesh.elements][elem_perm].astype(np.int32)), node_perm, elem_perm


def _qlv():
    return make_material("neo_hookean", {"mu": 1000.0}, poisson_ratio=0.45, prony_g=[0.3, 0.2], prony_tau_s=[0.01, 0.1])


def _groups(mesh):
    z = mesh.nodes[:, 2]
    top = np.flatnonzero(np.isclose(z, z.max()))
    return [fixed_group("bottom", np.flatnonzero(np.isclose(z, 0.0))),
            translation_group("top", top, (1.0, 0.2, 0.0), [0.0, 0.01], [0.0, 0.05 * L], dofs=(True, True, False))]


def test_auto_renumbers_a_shuffled_mesh_and_keeps_a_structured_one():
    mesh, shuffled, _, _ = _shuffled_block()
    mat = _qlv()
    kept = build_model(mesh, mat, _groups(mesh))
    assert not kept.reordered
    model = build_model(shuffled, mat, _groups(shuffled))
    assert model.reordered
    assert mean_element_span(model.kernel_mesh.elements) * 2 <= mean_element_span(shuffled.elements)
    # same geometry, same elements
    np.testing.assert_array_equal(model.kernel_mesh.nodes, shuffled.nodes[model.node_order])
    np.testing.assert_array_equal(model.node_order[model.kernel_mesh.elements], shuffled.elements[model.element_order])
    np.testing.assert_allclose(model.lumped_mass_kg, kept.lumped_mass_kg[_shuffled_block()[2]], rtol=1e-12)


def test_explicit_run_is_invariant_under_the_renumbering():
    """A QLV run with prescribed motion and an external load, on a shuffled mesh renumbered and not renumbered, and on
    the original block: the same displacements (caller's node order), reactions and element states (caller's
    element order)."""
    mesh, shuffled, node_perm, elem_perm = _shuffled_block()
    mat = _qlv()
    fext = np.zeros((mesh.n_nodes, 3))
    fext[np.argmax(mesh.nodes[:, 0] + mesh.nodes[:, 1] + mesh.nodes[:, 2]), 2] = -1e-4
    runs = []
    for m, reorder, f in ((mesh, False, fext), (shuffled, True, fext[node_perm]), (shuffled, False, fext[node_perm])):
        model = build_model(m, mat, _groups(m), reorder=reorder, external_force_n=f)
        v0 = np.zeros((m.n_nodes, 3))
        v0[:, 1] = 1e-3 * m.nodes[:, 2] / L
        runs.append(run_explicit(model, 0.01, damping_1_s=50.0, v0_m_s=v0, n_outputs=4))
    ref, renumbered, plain = runs
    scale_u = np.abs(ref.displacement_m).max()
    assert scale_u > 1e-3 * L  # the block moved
    for res in (renumbered, plain):
        np.testing.assert_allclose(res.displacement_m, ref.displacement_m[node_perm], rtol=0, atol=1e-10 * scale_u)
        for name in ("top", "bottom"):
            np.testing.assert_allclose(res.reaction_force_n[name], ref.reaction_force_n[name], rtol=0,
                                       atol=1e-9 * np.abs(ref.reaction_force_n[name]).max())
        for a, b in zip(res.state, ref.state):
            np.testing.assert_allclose(a, b[elem_perm], rtol=0, atol=1e-9 * np.abs(b).max())
    assert np.abs(ref.state[0]).max() > 0  # the viscoelastic states were exercised


def test_quasistatic_contact_and_continuation_are_invariant_under_the_renumbering():
    mesh, shuffled, node_perm, elem_perm = _shuffled_block(seed=5)
    mat = _qlv()
    z = mesh.nodes[:, 2]
    centre = (0.5 * L, 0.5 * L, z.max())
    results = []
    for m, reorder in ((mesh, False), (shuffled, True)):
        zz = m.nodes[:, 2]
        punch = RigidContact("sphere", (centre[0], centre[1], centre[2] + 3e-3), 3e-3, (0.0, 0.0, -1.0),
                             np.array([0.0, 1.0]), np.array([0.0, 0.6e-3]))
        model = build_model(m, mat, [fixed_group("bottom", np.flatnonzero(np.isclose(zz, 0.0)))], punch,
                            reorder=reorder)
        first = solve_quasistatic(model, [0.5])
        results.append(solve_quasistatic(model, [1.0], u0_m=first.displacement_m, state=first.state))
    ref, renumbered = results
    assert abs(ref.contact_force_n[-1, 2]) > 0
    np.testing.assert_allclose(renumbered.contact_force_n, ref.contact_force_n, rtol=1e-6)
    np.testing.assert_allclose(renumbered.displacement_m, ref.displacement_m[node_perm], rtol=0,
                               atol=1e-6 * np.abs(ref.displacement_m).max())


@pytest.mark.parametrize("kernel", ["vectorised", "generic"])
def test_inverted_element_id_is_the_callers(kernel):
    _, shuffled, _, _ = _shuffled_block(seed=7)
    model = build_model(shuffled, make_material("neo_hookean", {"mu": 1000.0}, poisson_ratio=0.45),
                        _groups(shuffled), reorder=True)
    assert model.reordered
    x = shuffled.nodes
    centre = int(np.argmin(np.linalg.norm(x - np.array([0.5, 0.5, 0.4]) * L, axis=1)))
    u0 = np.zeros_like(x)
    u0[centre] = (0.0, 0.0, -0.5 * L)
    inverted = set(np.flatnonzero(element_volumes(x + u0, shuffled.elements) <= 0).tolist())
    assert inverted
    with pytest.raises(ElementInversionError) as err:
        run_explicit(model, 1e-5, dt_s=1e-6, u0_m=u0, kernel=kernel)
    assert err.value.element in inverted


def test_auto_threads_runs_small_meshes_on_one_thread():
    from tissuemech.fem.tled import AUTO_THREADS_MIN_ELEMENTS, resolve_threads

    mat = make_material("neo_hookean", {"mu": 1000.0}, poisson_ratio=0.45)
    small = build_model(block_mesh((L, L, L), (2, 2, 2)), mat)
    large = build_model(block_mesh((L, L, L), (8, 8, 8)), mat)
    assert small.mesh.n_elements < AUTO_THREADS_MIN_ELEMENTS <= large.mesh.n_elements
    assert resolve_threads(small, "auto") == 1
    assert resolve_threads(large, 2) == 2 and resolve_threads(large, None) is None
    with pytest.raises(ValueError, match="n_threads"):
        resolve_threads(small, "all")


def test_auto_threads_leave_out_cpus_that_other_processes_keep_busy(monkeypatch):
    import numba

    from tissuemech.fem import tled

    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("needs 2 numba threads")
    large = build_model(block_mesh((L, L, L), (8, 8, 8)), make_material("neo_hookean", {"mu": 1000.0}, poisson_ratio=0.45))
    monkeypatch.setattr(tled.os, "cpu_count", lambda: 2)
    with tled.numba_threads(2):
        monkeypatch.setattr(tled, "busy_cpus", lambda interval_s=0.05: 0.1)
        assert tled.resolve_threads(large, "auto") is None  # both CPUs free: numba's 2 threads
        monkeypatch.setattr(tled, "busy_cpus", lambda interval_s=0.05: 1.2)
        assert tled.resolve_threads(large, "auto") == 1  # one CPU taken by another process
        monkeypatch.setattr(tled, "busy_cpus", lambda interval_s=0.05: None)
        assert tled.resolve_threads(large, "auto") is None  # no /proc/stat: numba's setting
    with tled.numba_threads(1):
        monkeypatch.setattr(tled, "busy_cpus", lambda interval_s=0.05: 0.0)
        assert tled.resolve_threads(large, "auto") is None  # never more than numba's setting
    busy = tled.busy_cpus(0.01)
    assert busy is None or -0.1 <= busy <= 2.1
