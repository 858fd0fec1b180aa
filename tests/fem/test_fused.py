"""The fused one-region-per-step kernel (tissuemech.fem.fused) against the vectorised passes (the oracle)."""
import numpy as np
import pytest

from tissuemech.fem import fused, tled
from tissuemech.fem.materials import make_material
from tissuemech.fem.mesh import block_mesh, element_volumes
from tissuemech.fem.tled import (ElementInversionError, RigidContact, build_model, fixed_group, run_explicit,
                                 translation_group)

L = 1e-2
MATERIALS = {
    "neo_hookean": ("neo_hookean", {"mu": 1000.0}, (), ()),
    "mooney_rivlin": ("mooney_rivlin", {"C10": 300.0, "C01": 200.0}, (), ()),
    # law derivatives per element through the fitting code's functions (I1 only; I1 and I2)
    "rp3": ("reduced_polynomial3", {"C10": 400.0, "C20": 300.0, "C30": 100.0}, (), ()),
    "lp2": ("lopez_pamies2", {"mu1": 900.0, "alpha1": 1.2, "mu2": 100.0, "alpha2": 3.0}, (), ()),
    "qlv4_nh": ("neo_hookean", {"mu": 1000.0}, (0.3, 0.2, 0.1, 0.05), (0.002, 0.02, 0.2, 2.0)),
    "qlv2_mr": ("mooney_rivlin", {"C10": 300.0, "C01": 200.0}, (0.4, 0.1), (0.01, 0.1)),
}


def _material(name, nu=0.45):
    key, params, g, tau = MATERIALS[name]
    return make_material(key, params, poisson_ratio=nu, prony_g=g, prony_tau_s=tau)


def _model(material, anp=True, precision="float64", cells=(5, 4, 4), reorder="auto", shuffle=False, **kw):
    """A block with its bottom fixed, its top moved along (1, 0, 0.3) and a lateral face held in y only."""
    mesh = block_mesh((L, L, L), cells)
    if shuffle:  # an arbitrary node and element order (renumbered by build_model's reverse Cuthill-McKee)
        rng = np.random.default_rng(3)
        p = rng.permutation(mesh.n_nodes)
        inv = np.empty_like(p)
        inv[p] = np.arange(p.size)
        mesh = type(mesh)(mesh.nodes[p], inv[mesh.elements][rng.permutation(mesh.n_elements)])
    x = mesh.nodes
    groups = [fixed_group("bottom", np.flatnonzero(np.isclose(x[:, 2], 0))),
              translation_group("top", np.flatnonzero(np.isclose(x[:, 2], L)), (1, 0, 0.3), [0, 0.01, 0.02],
                                [0, 2e-3, 1e-3]),
              fixed_group("side", np.flatnonzero(np.isclose(x[:, 1], 0) & (x[:, 2] > 0) & (x[:, 2] < L)),
                          dofs=(False, True, False))]
    return build_model(mesh, material, groups, anp=anp, precision=precision, reorder=reorder, **kw)


@pytest.fixture(params=[1, 2, 3], ids=lambda p: f"{p}parts")
def parts(request, monkeypatch):
    """Run the fused kernel on this many parts (whatever the thread count: the parts then run one after the other,
    with the same results)."""
    monkeypatch.setattr(tled, "_fused_parts", lambda threads: request.param)
    return request.param


@pytest.fixture
def kernel():
    """The fused kernel: one parallel region per step over overlapping node parts."""
    return "fused"


def _assert_same_run(a, b, rtol=1e-12, energy=True):
    for g in a.reaction_force_n:
        fa, fb = a.reaction_force_n[g], b.reaction_force_n[g]
        np.testing.assert_allclose(fb, fa, rtol=0, atol=rtol * np.abs(fa).max())
    u = np.abs(a.displacement_m).max()
    np.testing.assert_allclose(b.displacement_m, a.displacement_m, rtol=0, atol=rtol * u)
    np.testing.assert_allclose(b.previous_displacement_m, a.previous_displacement_m, rtol=0, atol=rtol * u)
    np.testing.assert_allclose(b.kinetic_energy_j, a.kinetic_energy_j, rtol=0,
                               atol=rtol * np.abs(a.kinetic_energy_j).max())
    for x, y in zip(b.state, a.state):
        np.testing.assert_allclose(x, y, rtol=0, atol=rtol * max(1e-30, np.abs(y).max(initial=0.0)))
    for k in (a.energy_j if energy else ()):
        np.testing.assert_allclose(b.energy_j[k], a.energy_j[k], rtol=0, atol=rtol * np.abs(a.energy_j[k]).max())


@pytest.mark.parametrize("name", sorted(MATERIALS))
@pytest.mark.parametrize("anp", [True, False])
def test_explicit_run_equals_vectorised_kernel(name, anp, parts, kernel):
    """Displacements, reactions of fixed, moved and partly fixed groups, energies and QLV states over 400 steps."""
    model = _model(_material(name), anp=anp)
    vec = run_explicit(model, 0.02, damping_1_s=50.0, kernel="vectorised", n_outputs=20)
    fus = run_explicit(model, 0.02, damping_1_s=50.0, kernel=kernel, n_outputs=20)
    assert (vec.kernel, fus.kernel) == ("vectorised", kernel)
    assert np.abs(vec.reaction_force_n["top"]).max() > 1e-4  # a real load
    assert np.abs(vec.reaction_force_n["side"][:, 1]).max() > 1e-6
    _assert_same_run(vec, fus)


@pytest.mark.parametrize("threads", [1, 2])
def test_threads_give_the_same_run(threads, kernel):
    """Through the real thread count (2 threads: 2 parts in parallel, where the machine has 2 CPUs)."""
    model = _model(_material("qlv4_nh"))
    vec = run_explicit(model, 0.01, damping_1_s=50.0, kernel="vectorised", n_threads=threads)
    fus = run_explicit(model, 0.01, damping_1_s=50.0, kernel=kernel, n_threads=threads)
    _assert_same_run(vec, fus)


def test_external_load_contact_renumbered_mesh_and_continued_state(parts, kernel):
    """A shuffled mesh renumbered by build_model, an external nodal load, rigid sphere contact, a QLV run continued
    from its state and displacement."""
    mat = _material("qlv4_nh")
    mesh_model = _model(mat, shuffle=True, reorder=True)
    assert mesh_model.reordered
    fext = np.zeros((mesh_model.mesh.n_nodes, 3))
    fext[np.argmax(mesh_model.mesh.nodes[:, 0]), 0] = 1e-3
    sphere = RigidContact("sphere", (0.5 * L, 0.5 * L, 1.5 * L + 0.4e-3), 0.5 * L, (0, 0, -1), np.array([0, 0.02]),
                          np.array([0, 1e-3]))
    model = build_model(mesh_model.mesh, mat, mesh_model.groups[:1], sphere, external_force_n=fext,
                        external_time_s=(0.0, 0.01), external_scale=(0.0, 1.0), reorder=True)
    runs = {}
    for k in ("vectorised", kernel):
        first = run_explicit(model, 0.01, damping_1_s=50.0, kernel=k, n_outputs=10)
        dt = first.time_step_s
        runs[k] = (first, run_explicit(model, 0.01, damping_1_s=50.0, kernel=k, n_outputs=10,
                                            u0_m=first.displacement_m,
                                            v0_m_s=(first.displacement_m - first.previous_displacement_m) / dt,
                                            state=first.state))
    for a, b in zip(runs["vectorised"], runs[kernel]):
        assert np.abs(a.contact_force_n).max() > 0
        # two runs of contact steps: the parts sum the nodal forces in another order, and the rounding grows to
        # ~1e-12 of the largest reaction (1.05e-12 seen with 3 parts)
        _assert_same_run(a, b, rtol=1e-11)
        np.testing.assert_allclose(b.contact_force_n, a.contact_force_n, rtol=0,
                                   atol=1e-12 * np.abs(a.contact_force_n).max())


def test_float32_storage_equals_vectorised_float32(parts, kernel):
    model = _model(_material("qlv4_nh"), precision="float32")
    vec = run_explicit(model, 0.02, damping_1_s=50.0, kernel="vectorised")
    fus = run_explicit(model, 0.02, damping_1_s=50.0, kernel=kernel)
    _assert_same_run(vec, fus, rtol=1e-5)


@pytest.mark.parametrize("name", ["neo_hookean", "qlv4_nh", "lp2"])
def test_large_volume_changes_outside_the_newton_range(name, parts, kernel):
    """``u_z = c z^2``: elements on both sides of the branch-free ``J^(-2/3)`` range (the cbrt fix-up)."""
    mesh = block_mesh((L, L, L), (4, 4, 6))
    model = build_model(mesh, _material(name, nu=0.3),
                        [fixed_group("bottom", np.flatnonzero(np.isclose(mesh.nodes[:, 2], 0)))])
    x = model.mesh.nodes
    u0 = np.zeros_like(x)
    u0[:, 2] = 4.5 / L * x[:, 2] ** 2
    J = element_volumes(x + u0, model.mesh.elements) / element_volumes(x, model.mesh.elements)
    assert np.all(J > 0) and (J > 3.5).any()
    kw = dict(dt_s=1e-6, u0_m=u0, v0_m_s=np.zeros_like(u0), n_outputs=3)
    # (not the energies: over three steps from rest they are differences of large forces times tiny increments)
    _assert_same_run(run_explicit(model, 3e-6, kernel="vectorised", **kw),
                     run_explicit(model, 3e-6, kernel=kernel, **kw), energy=False)


@pytest.mark.parametrize("anp", [True, False])
def test_inverted_element_is_reported_by_id(anp, parts, kernel):
    model = _model(_material("neo_hookean"), anp=anp)
    x = model.mesh.nodes
    centre = int(np.argmin(np.linalg.norm(x - 0.5 * L, axis=1)))
    u0 = np.zeros_like(x)
    u0[centre] = (0.0, 0.0, -0.4 * L)
    J = element_volumes(x + u0, model.mesh.elements) / element_volumes(x, model.mesh.elements)
    inverted = set(np.flatnonzero(J <= 0).tolist())
    assert inverted
    with pytest.raises(ElementInversionError, match="inverted") as err:
        run_explicit(model, 1e-5, dt_s=1e-6, u0_m=u0, kernel=kernel)
    assert err.value.element == min(inverted) and err.value.step == 0


@pytest.mark.parametrize("anp", [True, False])
@pytest.mark.parametrize("n_parts", [2, 3, 5])
def test_halo_layout_covers_what_each_part_needs(anp, n_parts):
    model = _model(_material("neo_hookean"), cells=(6, 5, 4))
    el = model.kernel_mesh.elements
    nn = model.kernel_mesh.n_nodes
    lay = fused.halo_layout(el, nn, n_parts, anp, model.kernel_mesh.nodes)
    owned = np.sort(lay.onode.astype(np.int64))
    np.testing.assert_array_equal(owned, np.arange(nn))  # every node owned by exactly one part
    for p in range(n_parts):
        nodes_p = lay.onode[lay.olo[p]:lay.olo[p + 1]].astype(np.int64)
        ext = lay.glob[lay.ebeg[p]:lay.eend[p]]
        e1 = set(lay.glob[lay.ebeg[p]:lay.emid[p]].tolist())
        assert len(ext) == len(set(ext.tolist()))  # no element twice within a part
        need1 = set(np.flatnonzero(np.isin(el, nodes_p).any(axis=1)).tolist())
        assert e1 == need1
        if anp:
            n1 = np.unique(el[sorted(need1)])
            need2 = set(np.flatnonzero(np.isin(el, n1).any(axis=1)).tolist())
            assert set(ext.tolist()) == need2
            assert set(lay.pnode[lay.plo[p]:lay.plo[p + 1]].tolist()) == set(n1.tolist())
        else:
            assert lay.eend[p] == lay.emid[p]
    # every element's states are read back from an E1 copy
    assert np.all(lay.glob[lay.first] == np.arange(el.shape[0]))
    ext_part = np.searchsorted(lay.ebeg, lay.first, side="right") - 1
    assert np.all(lay.first < lay.emid[ext_part])


def test_kernel_choice():
    nh = _model(_material("neo_hookean"), cells=(2, 2, 2))
    # "auto" keeps the vectorised passes (the fused step is opt-in: no faster on a free machine)
    assert run_explicit(nh, 1e-4, kernel="auto").kernel == "vectorised"
    assert run_explicit(nh, 1e-4, kernel="fused").kernel == "fused"
    with pytest.raises(ValueError, match="kernel must be one of"):
        run_explicit(nh, 1e-4, kernel="fused2")  # the two-region variant was measured and removed
    assert run_explicit(_model(_material("qlv4_nh"), anp=False, cells=(2, 2, 2)), 1e-4).kernel == "vectorised"
    svk = _model(make_material("saint_venant_kirchhoff", {"mu": 1000.0}, poisson_ratio=0.45), cells=(2, 2, 2))
    assert run_explicit(svk, 1e-4, kernel="auto").kernel == "vectorised"
    ogden = _model(make_material("ogden1", {"mu1": 1000.0, "alpha1": -5.0}, poisson_ratio=0.45), cells=(2, 2, 2))
    assert run_explicit(ogden, 1e-4, kernel="auto").kernel == "generic"
    five_terms = _model(make_material("neo_hookean", {"mu": 1000.0}, poisson_ratio=0.45, prony_g=[0.1] * 5,
                                      prony_tau_s=[0.01, 0.1, 1, 10, 100]), cells=(2, 2, 2))
    assert run_explicit(five_terms, 1e-4, kernel="auto").kernel == "vectorised"
    for model in (svk, ogden, five_terms):
        with pytest.raises(ValueError, match="fused kernel needs"):
            run_explicit(model, 1e-4, kernel="fused")
