import numpy as np
import pytest

from tissuemech.fem.mesh import (block_mesh, boundary_faces, cylinder_mesh, element_volumes, graded_layers,
                                 graded_ring_radii, mesh_quality, read_mesh, reorder_for_locality, subdivide,
                                 write_mesh)


def _face_area(nodes, faces):
    x = nodes[faces]
    return 0.5 * np.linalg.norm(np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), axis=1).sum()


def test_block_is_conforming_and_exact():
    mesh = block_mesh((2e-3, 3e-3, 4e-3), (2, 3, 4))
    q = mesh_quality(mesh)
    assert q["n_elements"] == 6 * 24
    assert q["volume_m3"] == pytest.approx(24e-9, rel=1e-12)
    assert q["min_volume_m3"] > 0
    # conforming: the boundary faces are exactly the box surface
    assert _face_area(mesh.nodes, boundary_faces(mesh.elements)) == pytest.approx(2 * (6 + 8 + 12) * 1e-6, rel=1e-12)


def test_subdivision_is_conforming_and_keeps_the_shape():
    parent = cylinder_mesh(12.5e-3, 2e-3, n_rings=4, n_layers=2)
    fine = subdivide(parent)
    q0, q1 = mesh_quality(parent), mesh_quality(fine)
    assert q1["n_elements"] == 8 * q0["n_elements"]
    assert q1["volume_m3"] == pytest.approx(q0["volume_m3"], rel=1e-12)
    assert q1["min_volume_m3"] > 0
    # conforming: each boundary triangle is cut into four, and the surface area is unchanged
    assert boundary_faces(fine.elements).shape[0] == 4 * boundary_faces(parent.elements).shape[0]
    assert _face_area(fine.nodes, boundary_faces(fine.elements)) == pytest.approx(
        _face_area(parent.nodes, boundary_faces(parent.elements)), rel=1e-12)
    # one midpoint per edge: nodes = parent nodes + parent edges
    edges = np.unique(np.sort(parent.elements[:, [[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]]], axis=2).reshape(-1, 2),
                      axis=0)
    assert fine.n_nodes == parent.n_nodes + edges.shape[0]
    # the shortest-diagonal split keeps the shape: altitudes halve, within a fixed factor
    assert q1["min_altitude_m"] > 0.4 * q0["min_altitude_m"]
    assert q1["max_aspect"] < 1.5 * q0["max_aspect"]


def test_rheometer_cylinder_quality_and_conformity():
    mesh = cylinder_mesh(12.5e-3, 2e-3, n_rings=6, n_layers=3)
    q = mesh_quality(mesh)
    faces = boundary_faces(mesh.elements)
    x = mesh.nodes
    # polygonal cross-section: area from the bottom faces, perimeter from the side
    bottom = faces[np.all(np.isclose(x[faces, 2], 0.0), axis=1)]
    area = _face_area(x, bottom)
    assert q["volume_m3"] == pytest.approx(area * 2e-3, rel=1e-10)
    assert area == pytest.approx(np.pi * 12.5e-3**2, rel=0.01)
    assert q["min_volume_m3"] > 0
    # no slivers: smallest altitude of the same order as the mean (structured extrusion)
    assert q["min_altitude_m"] > 0.5 * q["mean_altitude_m"]
    # a conforming mesh has no boundary faces inside the sample
    r = np.hypot(x[faces, 0], x[faces, 1]).max(axis=1)
    z = x[faces, 2]
    on_surface = np.isclose(r, 12.5e-3) | np.all(np.isclose(z, 0), axis=1) | np.all(np.isclose(z, 2e-3), axis=1)
    assert on_surface.all()


def test_graded_rings_hit_punch_edge_and_rim():
    rings = graded_ring_radii(10e-3, 2e-3, 4, 1.3)
    assert np.isclose(rings, 2e-3).any() and rings[-1] == pytest.approx(10e-3)
    assert np.all(np.diff(rings) > 0)
    z = graded_layers(5e-3, 0.25e-3, 1.3)
    assert z[0] == 0 and z[-1] == pytest.approx(5e-3) and np.diff(z)[-1] == pytest.approx(0.25e-3, rel=0.2)
    with pytest.raises(ValueError, match="inner_radius_m"):
        graded_ring_radii(1e-3, 2e-3, 4)


@pytest.mark.parametrize("suffix", [".vtu", ".xdmf"])
def test_roundtrip_with_displacement(tmp_path, suffix):
    mesh = reorder_for_locality(cylinder_mesh(5e-3, 1e-3, n_rings=3, n_layers=2))
    u = np.random.default_rng(1).normal(size=(mesh.n_nodes, 3)) * 1e-6
    path = write_mesh(tmp_path / f"m{suffix}", mesh, {"displacement": u})
    back, data = read_mesh(path)
    assert np.array_equal(back.elements, mesh.elements)
    np.testing.assert_allclose(back.nodes, mesh.nodes)
    np.testing.assert_allclose(data["displacement"], u)


def test_reordering_keeps_geometry():
    mesh = cylinder_mesh(5e-3, 1e-3, n_rings=4, n_layers=2, reorder=False)
    re = reorder_for_locality(mesh)
    assert mesh_quality(re)["volume_m3"] == pytest.approx(mesh_quality(mesh)["volume_m3"], rel=1e-12)
    bw = lambda m: np.max(m.elements.max(1) - m.elements.min(1))  # noqa: E731
    assert bw(re) < bw(mesh)


def test_brain_mesh_from_wheel_data_is_sliver_free(tmp_path):
    """MNI ICBM152-2009 brain from the nilearn wheel (no network), meshed at the default explicit-dynamics size
    (~10k tets, ~10 s), deterministic, close to the marching-cubes surface, then read back from the cache."""
    from tissuemech.fem import mesh as fm

    for module in ("nibabel", "pyvista", "pyacvd"):
        pytest.importorskip(module)
    try:
        fm.import_gmsh()
    except ImportError as exc:  # not installed, or its shared library lacks the X11/OpenGL client libraries
        pytest.skip(str(exc))
    try:
        path = fm._wheel_file(fm.MNI_GM)
    except ModuleNotFoundError:
        pytest.skip("nilearn wheel not installed (mesh extra)")
    import nibabel as nib

    assert nib.load(path).shape == (197, 233, 189)
    mesh = fm.brain_mesh(cache_dir=tmp_path)
    q = mesh_quality(mesh)
    assert 1.5e-3 < q["volume_m3"] < 2.0e-3  # MNI-space brain incl. cerebellum and stem, ~1.76 l
    assert 7_000 < q["n_elements"] < 14_000
    # no slivers: the smallest altitude is a fair share of a ~12 mm element (a regular tet's is 0.82 of its edge)
    assert q["min_volume_m3"] > 0 and q["min_altitude_m"] > 3.0e-3
    assert q["max_aspect"] < 6
    extent = mesh.nodes.max(0) - mesh.nodes.min(0)
    assert 0.13 < extent[0] < 0.16 and 0.16 < extent[1] < 0.20  # left-right, anterior-posterior (m)
    surface = fm.brain_surface()
    assert surface.volume * 1e-9 == pytest.approx(q["volume_m3"], rel=0.02)
    deviation = fm.surface_deviation(mesh, surface)
    assert deviation["mean_m"] < 0.5e-3 and deviation["max_m"] < 3.5e-3
    fresh = fm.brain_mesh(surface=surface)  # no cache, the caller's surface: the same mesh again
    assert np.array_equal(fresh.elements, mesh.elements) and np.allclose(fresh.nodes, mesh.nodes, rtol=0, atol=1e-12)
    again = fm.brain_mesh(cache_dir=tmp_path)  # from the VTU cache
    assert again.n_elements == mesh.n_elements and np.allclose(again.nodes, mesh.nodes)


def _distorted_block(inner_shift_m, face_shift_m):
    """A 3x3x3-cell block (1 mm cells) with the interior node at (1, 1, 1) mm and the surface node at (1, 1, 0) mm
    (on the z = 0 face, not on an edge) shifted: thin elements around them."""
    from tissuemech.fem.mesh import TetMesh

    mesh = block_mesh((3e-3, 3e-3, 3e-3), (3, 3, 3))
    x = mesh.nodes.copy()
    inner = int(np.argmin(np.linalg.norm(x - 1e-3, axis=1)))
    on_face = int(np.argmin(np.linalg.norm(x - np.array([1e-3, 1e-3, 0.0]), axis=1)))
    x[inner] += inner_shift_m
    x[on_face] += face_shift_m
    assert element_volumes(x, mesh.elements).min() > 0
    return TetMesh(x, mesh.elements), inner, on_face


def test_improve_min_altitude_raises_the_worst_element_and_keeps_the_boundary():
    from tissuemech.fem.mesh import boundary_nodes, element_min_altitudes, improve_min_altitude

    regular = 1e-3 / np.sqrt(2.0)  # smallest altitude of the Kuhn tets of a 1 mm cell
    # an interior node pushed towards a face of its star: interior moves alone repair it
    mesh, inner, _ = _distorted_block(np.array([0.45e-3, 0.4e-3, 0.42e-3]), np.zeros(3))
    bnodes = boundary_nodes(mesh.elements)
    assert element_min_altitudes(mesh.nodes, mesh.elements).min() < 0.8 * regular
    fixed = improve_min_altitude(mesh)
    np.testing.assert_array_equal(fixed.nodes[bnodes], mesh.nodes[bnodes])
    np.testing.assert_array_equal(fixed.elements, mesh.elements)
    assert element_min_altitudes(fixed.nodes, fixed.elements).min() > 0.95 * regular
    assert np.linalg.norm(fixed.nodes[inner] - mesh.nodes[inner]) > 0.1e-3
    # a surface node pushed along its face almost onto an element edge: interior moves cannot repair that element,
    # sliding the node within its face plane does, and the box stays the box
    mesh, _, on_face = _distorted_block(np.zeros(3), np.array([0.8e-3, 0.75e-3, 0.0]))
    before = element_min_altitudes(mesh.nodes, mesh.elements).min()
    assert before < 0.3 * regular
    assert element_min_altitudes(improve_min_altitude(mesh).nodes, mesh.elements).min() < 1.1 * before
    slid = improve_min_altitude(mesh, boundary_slide_m=0.9e-3)
    assert element_min_altitudes(slid.nodes, slid.elements).min() > 0.9 * regular
    assert np.linalg.norm(slid.nodes[on_face] - mesh.nodes[on_face]) > 0.3e-3
    assert np.linalg.norm(slid.nodes - mesh.nodes, axis=1)[bnodes].max() <= 0.9e-3 + 1e-15
    x0, x1 = mesh.nodes[bnodes], slid.nodes[bnodes]
    on_plane = np.isclose(x0, 0.0, atol=1e-15) | np.isclose(x0, 3e-3, rtol=1e-12)
    np.testing.assert_array_equal(x1[on_plane], x0[on_plane])  # boundary nodes stay on their face planes
    feature = on_plane.sum(axis=1) >= 2
    np.testing.assert_array_equal(x1[feature], x0[feature])  # edge and corner nodes do not move
    assert element_volumes(slid.nodes, slid.elements).sum() == pytest.approx(27e-9, rel=1e-12)
    assert element_volumes(slid.nodes, slid.elements).min() > 0


def test_surface_deviation_of_a_block_against_a_larger_box():
    """Known truth: the boundary of a 10 mm cube against the surface of a 12 mm box with the same centre lies
    1 mm away everywhere on the faces; the box's corners are sqrt(3) mm from the cube's."""
    pv = pytest.importorskip("pyvista")
    from tissuemech.fem.mesh import surface_deviation

    mesh = block_mesh((10e-3, 10e-3, 10e-3), (4, 4, 4))
    box = pv.Box(bounds=(-1.0, 11.0, -1.0, 11.0, -1.0, 11.0), level=6).triangulate()  # mm
    deviation = surface_deviation(mesh, box)
    assert deviation["face_centroid_max_m"] == pytest.approx(1e-3, rel=1e-6)
    assert deviation["max_m"] == pytest.approx(np.sqrt(3.0) * 1e-3, rel=1e-6)
    assert 1e-3 <= deviation["mean_m"] < 1.2e-3


def test_gmsh_without_its_system_libraries_gets_an_error_that_says_what_to_install(monkeypatch):
    import builtins

    from tissuemech.fem import mesh as fm

    real_import = builtins.__import__

    def failing_import(name, *args, **kwargs):
        if name == "gmsh":
            raise OSError("libGLU.so.1: cannot open shared object file: No such file or directory")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", failing_import)
    with pytest.raises(ImportError, match=r"libGLU\.so\.1.*apt-get install libglu1-mesa libxcursor1 libxft2 "
                                          r"libxinerama1.*fem\.brain_mesh: false"):
        fm.import_gmsh()
