import meshio
import numpy as np
import pytest

from warptissue.errors import InputError
from warptissue.mesh import TetMesh, block_mesh, indentation_disc, read_mesh, write_mesh


def sorted_rows(rows):
    rows = np.sort(np.asarray(rows), axis=1)
    return rows[np.lexsort(rows.T[::-1])]


def small_disc(element):
    return indentation_disc(
        radius_m=0.01,
        thickness_m=0.004,
        probe_radius_m=0.003,
        element=element,
        size_near_m=0.001,
        size_far_m=0.002,
    )


def assert_same_mesh(read, written):
    np.testing.assert_array_equal(read.tets, written.tets)
    np.testing.assert_array_equal(read.points, written.points)
    np.testing.assert_array_equal(read.tet_regions, written.tet_regions)
    assert set(read.node_sets) == set(written.node_sets)
    for name, nodes in written.node_sets.items():
        np.testing.assert_array_equal(np.sort(read.node_sets[name]), np.sort(nodes))
    assert set(read.face_sets) == set(written.face_sets)
    for name, faces in written.face_sets.items():
        np.testing.assert_array_equal(sorted_rows(read.face_sets[name]), sorted_rows(faces))


@pytest.mark.parametrize("suffix", [".vtu", ".msh"])
@pytest.mark.parametrize("element", ["TET4", "TET10"])
def test_round_trip(tmp_path, suffix, element, rng):
    mesh = small_disc(element)
    mesh.tet_regions[::3] = 2
    displacement = rng.normal(size=(mesh.node_count, 3))
    stress = rng.normal(size=(mesh.tet_count, 6))
    path = write_mesh(
        tmp_path / f"disc{suffix}",
        mesh,
        point_data={"displacement_m": displacement},
        cell_data={"cauchy_stress_Pa": stress, "von_mises_Pa": stress[:, 0]},
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name]  # no temporary left
    assert_same_mesh(read_mesh(path), mesh)
    raw = meshio.read(path)
    np.testing.assert_array_equal(raw.point_data["displacement_m"], displacement)
    np.testing.assert_array_equal(raw.cell_data["von_mises_Pa"][0], stress[:, 0])
    if suffix == ".vtu":
        np.testing.assert_array_equal(raw.cell_data["cauchy_stress_Pa"][0], stress)
    else:  # Gmsh takes 1, 3 or 9 components: six become six scalar fields.
        for i in range(6):
            np.testing.assert_array_equal(raw.cell_data[f"cauchy_stress_Pa[{i}]"][0], stress[:, i])


def test_reads_gmsh_v2_written_by_meshio(tmp_path):
    mesh = small_disc("TET10")
    path = tmp_path / "v2.msh"
    meshio.write(path, meshio.Mesh(mesh.points, [("tetra10", mesh.tets)]), file_format="gmsh22")
    assert path.read_text(errors="ignore").startswith("$MeshFormat\n2.2")
    read = read_mesh(path)
    np.testing.assert_array_equal(read.tets, mesh.tets)
    np.testing.assert_allclose(read.points, mesh.points, rtol=1e-15, atol=0)


CORNERS = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 2.0]])


def midpoint(i, j):
    return 0.5 * (CORNERS[i] + CORNERS[j])


def assert_vtk_midnodes(mesh):
    corners = mesh.points[mesh.tets[:, :4]]
    expected = 0.5 * (corners[:, [0, 1, 0, 0, 1, 2]] + corners[:, [1, 2, 2, 3, 3, 3]])
    np.testing.assert_allclose(mesh.points[mesh.tets[:, 4:]], expected)


GMSH_PHYSICAL_NAMES = """$PhysicalNames
2
2 5 "base"
3 7 "tissue"
$EndPhysicalNames
"""


def gmsh_text(version, points):
    """A one-tet Gmsh file: a TET10 (type 11) in physical volume 7 "tissue" and its base
    triangle (type 2) in physical surface 5 "base"."""
    tags = "\n".join(str(k + 1) for k in range(len(points)))
    coordinates = "\n".join(f"{x:g} {y:g} {z:g}" for x, y, z in points)
    if version == "2.2":
        nodes = "\n".join(f"{k + 1} {x:g} {y:g} {z:g}" for k, (x, y, z) in enumerate(points))
        return f"""$MeshFormat
2.2 0 8
$EndMeshFormat
{GMSH_PHYSICAL_NAMES}$Nodes
10
{nodes}
$EndNodes
$Elements
2
1 2 2 5 1 1 3 2
2 11 2 7 1 1 2 3 4 5 6 7 8 9 10
$EndElements
"""
    return f"""$MeshFormat
4.1 0 8
$EndMeshFormat
{GMSH_PHYSICAL_NAMES}$Entities
0 0 1 1
1 0 0 0 2 2 0 1 5 0
1 0 0 0 2 2 2 1 7 1 1
$EndEntities
$Nodes
1 10 1 10
3 1 0 10
{tags}
{coordinates}
$EndNodes
$Elements
2 2 1 2
2 1 2 1
1 1 3 2
3 1 11 1
2 1 2 3 4 5 6 7 8 9 10
$EndElements
"""


@pytest.mark.parametrize("version", ["2.2", "4.1"])
def test_gmsh_tet10_node_order_and_physical_groups(tmp_path, version):
    # Hand-written in Gmsh's own order: nodes 9 and 10 (1-based) of a 10-node tet sit on
    # edges (3,4) and (2,4), the reverse of VTK's (2,4), (3,4).
    gmsh_mid = [(0, 1), (1, 2), (0, 2), (0, 3), (2, 3), (1, 3)]
    points = np.vstack([CORNERS, [midpoint(i, j) for i, j in gmsh_mid]])
    path = tmp_path / "one.msh"
    path.write_text(gmsh_text(version, points))
    mesh = read_mesh(path)
    assert mesh.element_type == "TET10" and mesh.tet_count == 1
    assert_vtk_midnodes(mesh)
    np.testing.assert_array_equal(np.sort(mesh.node_sets["base"]), [0, 1, 2])
    assert len(mesh.node_sets["tissue"]) == 10
    assert mesh.tet_regions.tolist() == [6]  # physical tag 7, regions count from 0
    # The base face set points out of the tet (-z).
    base = mesh.points[mesh.face_sets["base"][0]]
    assert np.cross(base[1] - base[0], base[2] - base[0])[2] < 0


INP = """*HEADING
hand-written two-tet model, C3D10 in Abaqus node order, ids not consecutive
*NODE
10, 0.0, 0.0, 0.0
20, 2.0, 0.0, 0.0
30, 0.0, 2.0, 0.0
40, 0.0, 0.0, 2.0
50, 1.0, 0.0, 0.0
60, 1.0, 1.0, 0.0
70, 0.0, 1.0, 0.0
80, 0.0, 0.0, 1.0
90, 1.0, 0.0, 1.0
100, 0.0, 1.0, 1.0
999, 5.0, 5.0, 5.0
*ELEMENT, TYPE=C3D10, ELSET=TISSUE
7, 10, 20, 30, 40, 50, 60, 70, 80, 90, 100
*NSET, NSET=BASE
10, 20, 30, 50, 60, 70
*NSET, NSET=APEX
40
*ELSET, ELSET=ALLTETS
7
"""


def test_abaqus_inp_import(tmp_path):
    path = tmp_path / "model.inp"
    path.write_text(INP)
    mesh = read_mesh(path)
    assert mesh.element_type == "TET10" and mesh.tet_count == 1
    assert mesh.node_count == 10  # node 999 is used by no element and is dropped
    np.testing.assert_array_equal(mesh.points[mesh.tets[0, :4]], CORNERS)
    assert_vtk_midnodes(mesh)  # Abaqus C3D10 order is VTK's
    assert np.all(mesh.points[mesh.node_sets["BASE"], 2] == 0.0)
    assert len(mesh.node_sets["BASE"]) == 6
    np.testing.assert_array_equal(mesh.points[mesh.node_sets["APEX"]], [[0.0, 0.0, 2.0]])
    assert len(mesh.node_sets["ALLTETS"]) == 10
    assert len(mesh.face_sets["BASE"]) == 1 and "APEX" not in mesh.face_sets
    assert mesh.volumes()[0] == pytest.approx(8 / 6)


def test_reorients_left_handed_tets(tmp_path):
    mesh = block_mesh(np.linspace(0, 1, 3), np.linspace(0, 1, 2), np.linspace(0, 1, 2))
    flipped = mesh.tets[:, [0, 2, 1, 3]]
    path = tmp_path / "left.vtu"
    meshio.write(path, meshio.Mesh(mesh.points, [("tetra", flipped)]))
    assert np.all(read_mesh(path).volumes() > 0)
    assert np.all(read_mesh(path, reorient=False).volumes() < 0)


def test_read_errors_name_the_file(tmp_path):
    with pytest.raises(InputError, match="missing.vtu.*not found"):
        read_mesh(tmp_path / "missing.vtu")
    garbage = tmp_path / "garbage.msh"
    garbage.write_text("this is not a mesh\n")
    with pytest.raises(InputError, match="garbage.msh.*cannot read"):
        read_mesh(garbage)
    with pytest.raises(InputError, match="unknown mesh format"):
        read_mesh(tmp_path / "mesh.stl")
    surface = tmp_path / "surface.vtu"
    meshio.write(surface, meshio.Mesh(CORNERS, [("triangle", np.array([[0, 1, 2]]))]))
    with pytest.raises(InputError, match="surface.vtu.*no tetrahedra.*triangle"):
        read_mesh(surface)


def test_write_errors(tmp_path, unit_cube_tet4):
    with pytest.raises(InputError, match="point_data field 'u'"):
        write_mesh(tmp_path / "a.vtu", unit_cube_tet4, point_data={"u": np.zeros(3)})
    with pytest.raises(InputError, match="cannot write"):
        write_mesh(tmp_path / "a.inp", unit_cube_tet4)
    assert not list(tmp_path.iterdir())


def test_tetmesh_round_trip_keeps_empty_node_sets_out(tmp_path):
    mesh = TetMesh(points=CORNERS, tets=[[0, 1, 2, 3]], node_sets={"tip": [3]})
    read = read_mesh(write_mesh(tmp_path / "t.vtu", mesh))
    np.testing.assert_array_equal(read.node_sets["tip"], [3])
    assert "tip" not in read.face_sets


def test_unit_scaling(tmp_path):
    path = tmp_path / "model.inp"
    path.write_text(INP)
    mesh = read_mesh(path, unit_m=1e-3)
    np.testing.assert_allclose(mesh.points[mesh.tets[0, :4]], CORNERS * 1e-3)
    with pytest.raises(InputError, match="unit_m"):
        read_mesh(path, unit_m=0.0)


def test_a_usd_tetmesh_asset_reads_as_a_mesh(tmp_path):
    """A scene written by warptissue.usd reads back through read_mesh: points (float32 in
    USD), tets, the surface node sets; in millimetres with unit_m; a prim that is not a
    TetMesh, or a prim_path for another format, is refused."""
    from warptissue.usd import write_simulation_usd

    grid = np.linspace(0.0, 0.004, 3)
    mesh = block_mesh(grid, grid, grid)
    paths = write_simulation_usd(tmp_path / "cube.usda", mesh)
    for path in (paths.root, paths.asset):
        read = read_mesh(path)
        np.testing.assert_allclose(read.points, mesh.points, atol=1e-9)
        np.testing.assert_array_equal(read.tets, mesh.tets)
        np.testing.assert_array_equal(np.sort(read.node_sets["zmax"]), mesh.node_sets["zmax"])
    in_mm = read_mesh(paths.asset, unit_m=1e-3)
    np.testing.assert_allclose(in_mm.points, mesh.points * 1e-3, atol=1e-12)
    with pytest.raises(InputError, match="no TetMesh prim at /World"):
        read_mesh(paths.asset, prim_path="/World")
    write_mesh(tmp_path / "cube.vtu", mesh)
    with pytest.raises(InputError, match="prim_path is for a USD file"):
        read_mesh(tmp_path / "cube.vtu", prim_path="/World/Specimen/Volume")


def test_reading_a_usd_mesh_first_keeps_the_tissue_schema_registered(tmp_path):
    """USD builds its schema registry once: a USD mesh read (a study's specimen) before
    warptissue.usd is imported must not leave TissueMaterialAPI unknown."""
    import subprocess
    import sys
    from pathlib import Path

    scene = Path(__file__).resolve().parents[1] / "scenes" / "liver_organ.asset.usda"
    code = (
        "from warptissue.mesh import read_mesh\n"
        f"read_mesh({str(scene)!r})\n"
        "import warptissue.usd\n"
        "from pxr import Usd\n"
        "print(Usd.SchemaRegistry().FindAppliedAPIPrimDefinition('TissueMaterialAPI') is not None)"
    )
    shown = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, check=True
    )
    assert shown.stdout.strip().splitlines()[-1] == "True"
