import numpy as np
import pytest

from warptissue.errors import InputError
from warptissue.mesh import check_mesh, fill_surface_file
from warptissue.mesh.surface import check_closed_surface, tetrahedralize_surface

BOX_VERTICES = (
    np.array(
        [[0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0], [0, 0, 3], [2, 0, 3], [2, 1, 3], [0, 1, 3]],
        dtype=float,
    )
    * 0.01
)
BOX_TRIANGLES = np.array(
    [[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4],
     [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]]
)  # fmt: skip


def icosphere(subdivisions):
    """A unit sphere triangulated by subdividing an icosahedron."""
    t = (1 + 5**0.5) / 2
    corners = [[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
               [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]]  # fmt: skip
    faces = [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4],
             [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8],
             [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]]  # fmt: skip
    vertices = [np.array(v, float) / np.linalg.norm(v) for v in corners]
    for _ in range(subdivisions):
        midpoint_of, refined = {}, []
        for face in faces:
            mids = []
            for i, j in ((face[0], face[1]), (face[1], face[2]), (face[2], face[0])):
                key = (min(i, j), max(i, j))
                if key not in midpoint_of:
                    m = vertices[i] + vertices[j]
                    vertices.append(m / np.linalg.norm(m))
                    midpoint_of[key] = len(vertices) - 1
                mids.append(midpoint_of[key])
            ab, bc, ca = mids
            a, b, c = face
            refined += [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
        faces = refined
    return np.array(vertices), np.array(faces)


def enclosed_volume(vertices, triangles):
    """Volume inside a closed, consistently outward-oriented surface (divergence theorem)."""
    x = vertices[triangles]
    return np.einsum("ij,ij->i", x[:, 0], np.cross(x[:, 1], x[:, 2])).sum() / 6


def test_box_volume_and_surface():
    mesh = tetrahedralize_surface(BOX_VERTICES, BOX_TRIANGLES, max_volume_m3=2e-8)
    assert np.all(mesh.volumes() > 0)
    assert mesh.volumes().sum() == pytest.approx(6e-6, rel=1e-12)
    assert mesh.tet_count > 6e-6 / 2e-8  # the volume bound forced refinement
    assert mesh.volumes().max() < 1.5 * 2e-8
    np.testing.assert_array_equal(mesh.points[:8], BOX_VERTICES)  # inputs keep their index
    surface = mesh.points[mesh.node_sets["surface"]]
    on_box = np.isclose(surface, 0).any(1) | np.isclose(surface, BOX_VERTICES.max(0)).any(1)
    assert np.all(on_box)
    assert enclosed_volume(mesh.points, mesh.face_sets["surface"]) == pytest.approx(6e-6)
    check_mesh(mesh)


def test_sphere_volume():
    vertices, triangles = icosphere(3)
    radius = 0.02
    mesh = tetrahedralize_surface(radius * vertices, triangles, quality=1.3, min_dihedral_deg=15)
    polyhedron = enclosed_volume(radius * vertices, triangles)
    assert mesh.volumes().sum() == pytest.approx(polyhedron, rel=1e-10)
    assert mesh.volumes().sum() == pytest.approx(4 / 3 * np.pi * radius**3, rel=0.015)
    quality = check_mesh(mesh)
    rough = check_mesh(tetrahedralize_surface(radius * vertices, triangles, quality=None))
    assert quality.min_dihedral_deg > rough.min_dihedral_deg
    assert quality.mean_radius_ratio > rough.mean_radius_ratio


def test_open_surface_is_rejected_naming_the_edge():
    with pytest.raises(InputError, match=r"not closed: edge \[\d+, \d+\] belongs to 1"):
        tetrahedralize_surface(BOX_VERTICES, BOX_TRIANGLES[:-1])


def test_non_manifold_and_malformed_surfaces_are_rejected():
    doubled = np.vstack([BOX_TRIANGLES, BOX_TRIANGLES[:1]])
    with pytest.raises(InputError, match="non-manifold"):
        check_closed_surface(BOX_VERTICES, doubled)
    with pytest.raises(InputError, match="triangle 3 indexes a vertex"):
        check_closed_surface(BOX_VERTICES, np.vstack([BOX_TRIANGLES[:3], [[0, 1, 99]]]))
    flat = BOX_TRIANGLES.copy()
    flat[5] = [0, 1, 1]
    with pytest.raises(InputError, match="triangle 5 is degenerate"):
        check_closed_surface(BOX_VERTICES, flat)
    with pytest.raises(InputError, match="quality"):
        tetrahedralize_surface(BOX_VERTICES, BOX_TRIANGLES, quality=0.9)


def test_surface_sets_become_face_and_node_sets_of_the_filled_mesh():
    # Box triangles come in pairs, one pair per side: bottom, top, y = 0, x = 2, y = 1, x = 0.
    sides = {"bottom": (2, 0.0), "top": (2, 0.03), "front": (1, 0.0), "right": (0, 0.02)}
    sets = {name: np.array([2 * k, 2 * k + 1]) for k, name in enumerate(sides)}
    mesh = tetrahedralize_surface(
        BOX_VERTICES, BOX_TRIANGLES, max_volume_m3=2e-8, surface_sets=sets
    )
    boundary = {tuple(f) for f in np.sort(mesh.face_sets["surface"], axis=1)}
    named = []
    for name, (axis, value) in sides.items():
        faces = mesh.face_sets[name]
        assert len(faces) > 2  # TetGen split the input pair
        assert np.all(mesh.points[faces, axis] == value), name
        np.testing.assert_array_equal(mesh.node_sets[name], np.unique(faces))
        named += [tuple(f) for f in np.sort(faces, axis=1)]
        area = (
            0.5
            * np.linalg.norm(
                np.cross(
                    *(mesh.points[faces[:, 1:]] - mesh.points[faces[:, :1]]).transpose(1, 0, 2)
                ),
                axis=1,
            ).sum()
        )
        expected = np.prod(np.delete(BOX_VERTICES.max(0), axis))
        assert area == pytest.approx(expected, rel=1e-12), name
    assert len(set(named)) == len(named) and set(named) <= boundary
    # The named faces keep the outward orientation of "surface".
    for name, (axis, value) in sides.items():
        x = mesh.points[mesh.face_sets[name]]
        normal = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])[:, axis]
        assert np.all(normal > 0 if value > 0 else normal < 0), name


def test_an_empty_surface_set_gives_empty_sets():
    mesh = tetrahedralize_surface(BOX_VERTICES, BOX_TRIANGLES, surface_sets={"none": []})
    assert mesh.face_sets["none"].shape == (0, 3)
    assert mesh.node_sets["none"].size == 0


def test_surface_sets_must_index_distinct_existing_triangles():
    with pytest.raises(InputError, match="triangle 1 is in surface sets 'a' and 'b'"):
        tetrahedralize_surface(
            BOX_VERTICES, BOX_TRIANGLES, surface_sets={"a": np.array([0, 1]), "b": np.array([1])}
        )
    with pytest.raises(InputError, match="indexes triangle 12, outside"):
        tetrahedralize_surface(BOX_VERTICES, BOX_TRIANGLES, surface_sets={"a": np.array([12])})
    with pytest.raises(InputError, match="1-D array of triangle indices"):
        tetrahedralize_surface(BOX_VERTICES, BOX_TRIANGLES, surface_sets={"a": np.array([0.5])})


def test_fill_surface_file_reads_a_closed_stl_in_mm(tmp_path) -> None:
    """A tetrahedron's surface in mm: filled, in metres, its volume exactly the solid's."""
    import meshio

    from warptissue.mesh import fill_surface_file

    points = np.array([[0.0, 0.0, 0.0], [3.0, 0.0, 0.0], [0.0, 3.0, 0.0], [0.0, 0.0, 3.0]])
    faces = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
    meshio.write(tmp_path / "tet.ply", meshio.Mesh(points, [("triangle", faces)]))
    mesh = fill_surface_file(tmp_path / "tet.ply", unit_m=1e-3)
    corners = mesh.points[mesh.tets]
    volume = (
        np.einsum(
            "ij,ij->i",
            np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]),
            corners[:, 3] - corners[:, 0],
        ).sum()
        / 6.0
    )
    np.testing.assert_allclose(volume, 0.003**3 / 6.0, rtol=1e-12)
    meshio.write(tmp_path / "open.ply", meshio.Mesh(points, [("triangle", faces[:3])]))
    with pytest.raises(InputError, match="not a closed surface"):
        fill_surface_file(tmp_path / "open.ply")
    with pytest.raises(InputError, match="no such file"):
        fill_surface_file(tmp_path / "absent.stl")


def _usd_cube(path, *, drop_face: bool = False) -> None:
    """A 10 mm cube of six quads under an Xform scaled by 1e-3 (drawn in millimetres)."""
    from pxr import Gf, Usd, UsdGeom

    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.Xform.Define(stage, "/Organ").AddScaleOp().Set(Gf.Vec3f(1e-3, 1e-3, 1e-3))
    mesh = UsdGeom.Mesh.Define(stage, "/Organ/Surface")
    corners = [(x, y, z) for z in (0, 10) for y in (0, 10) for x in (0, 10)]
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    if drop_face:
        quads = quads[:-1]
    mesh.CreatePointsAttr(corners)
    mesh.CreateFaceVertexCountsAttr([4] * len(quads))
    mesh.CreateFaceVertexIndicesAttr([i for quad in quads for i in quad])
    stage.GetRootLayer().Save()


def test_a_usd_mesh_surface_is_filled_where_its_xforms_place_it(tmp_path) -> None:
    """A USD stage with a closed Mesh (quads, under a scaled Xform) and no TetMesh is a
    surface to fill: 1e-6 m^3 for the 10 mm cube; an open one is refused naming the file."""
    from warptissue.mesh import usd_holds_tetmesh

    _usd_cube(tmp_path / "cube.usda")
    assert not usd_holds_tetmesh(tmp_path / "cube.usda")
    mesh = fill_surface_file(tmp_path / "cube.usda")
    assert check_mesh(mesh).total_volume_m3 == pytest.approx(1e-6, rel=1e-9)
    np.testing.assert_allclose(np.ptp(mesh.points, axis=0), 0.01, rtol=1e-6)
    _usd_cube(tmp_path / "open.usda", drop_face=True)
    with pytest.raises(InputError, match="open.usda.*not a closed surface"):
        fill_surface_file(tmp_path / "open.usda")
