"""Quasi-static TLED (dynamic relaxation) against FElupe's implicit Newton solution on the same mesh."""
import felupe as fem
import numpy as np
import pytest

from tissuemech.fem.materials import make_material
from tissuemech.fem.mesh import block_mesh
from tissuemech.fem.tled import build_model, fixed_group, solve_quasistatic, translation_group

# felupe is in the test extra: a missing felupe is an error, not a skip


def test_square_punch_indentation_matches_felupe():
    lx, lz, mu, nu, depth = 10e-3, 5e-3, 1000.0, 0.45, 0.5e-3  # 10 % of the thickness
    mesh = block_mesh((lx, lx, lz), (4, 4, 2))
    x = mesh.nodes
    punch = np.isclose(x[:, 2], lz) & (x[:, 0] <= 2.5e-3 + 1e-12) & (x[:, 1] <= 2.5e-3 + 1e-12)
    bottom = np.isclose(x[:, 2], 0)
    mat = make_material("neo_hookean", {"mu": mu}, poisson_ratio=nu)

    region = fem.RegionTetra(fem.Mesh(x.copy(), mesh.elements.astype(np.int64), "tetra"))
    field = fem.FieldContainer([fem.Field(region, dim=3)])
    bcs = {"bottom": fem.Boundary(field[0], mask=bottom),
           "punch": fem.Boundary(field[0], mask=punch, skip=(1, 1, 0))}
    solid = fem.SolidBody(fem.NeoHooke(mu=mu, bulk=mat.bulk_modulus_pa), field)
    step = fem.Step(items=[solid], ramp={bcs["punch"]: fem.math.linsteps([0, 1], num=4) * (-depth)}, boundaries=bcs)
    fem.Job(steps=[step]).evaluate(verbose=0)
    f_ref = solid.assemble.vector().toarray().reshape(-1, 3)[punch, 2].sum()

    groups = [translation_group("punch", np.flatnonzero(punch), (0, 0, -1), [0, 1], [0, depth], dofs=(False, False, True)),
              fixed_group("bottom", np.flatnonzero(bottom))]
    res = solve_quasistatic(build_model(mesh, mat, groups, anp=False), [0.25, 0.5, 0.75, 1.0], tol_m=1e-12)
    assert res.reaction_force_n["punch"][-1, 2] == pytest.approx(f_ref, rel=1e-6)
    np.testing.assert_allclose(res.displacement_m, field[0].values, atol=1e-8 * depth)
