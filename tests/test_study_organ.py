"""A specimen from a mesh file indented at a site (issue 34): ``[specimen] mesh``,
``[indenter] site_m``/``direction``, ``[boundary] support``, through the study file."""

from __future__ import annotations

import dataclasses
import tomllib
from pathlib import Path

import numpy as np
import pytest

from warptissue.errors import InputError
from warptissue.fem import simulate_indentation
from warptissue.fem.support import support_edge_m
from warptissue.materials import NeoHookean
from warptissue.mesh import TetMesh, boundary_faces, check_mesh, write_mesh
from warptissue.simulate import build_mesh, build_problem, record_problems
from warptissue.study import load_study, save_study, study_from_dict

BLOCK = """\
schema_version = 1
name = "block"

[specimen]
shape = "block"
width_m = 0.008
thickness_m = 0.004
quarter = false
element = "TET10"
size_near_m = 0.001
size_far_m = 0.002
growth = 1.5

[indenter]
kind = "flat_punch"
radius_m = 0.001
contact = "bonded"

[protocol]
max_depth_m = 0.0002
steps = 2

[material]
model = "neo_hookean"
C10_Pa = 287.5
bulk_modulus_Pa = 575000.0

[solver]
device = "cpu"
"""


def _organ_study(mesh_file: str, *, site, direction=None, support="bottom", unit="m") -> str:
    text = BLOCK.split("[specimen]")[0] + f'[specimen]\nmesh = "{mesh_file}"\nunit = "{unit}"\n\n'
    indenter = '[indenter]\nkind = "flat_punch"\nradius_m = 0.001\ncontact = "bonded"\n'
    indenter += f"site_m = {_toml_vector(site)}\n"
    if direction is not None:
        indenter += f"direction = {_toml_vector(direction)}\n"
    rest = BLOCK.split("[protocol]")[1]
    return text + indenter + "\n[protocol]" + rest + f'\n[boundary]\nsupport = "{support}"\n'


def _toml_vector(values) -> str:
    return "[" + ", ".join(repr(float(v)) for v in values) + "]"


@pytest.fixture(scope="module")
def block_files(tmp_path_factory):
    """The block study, its mesh as a VTU file, and a copy turned by a rotation."""
    folder = tmp_path_factory.mktemp("organ")
    (folder / "block.toml").write_text(BLOCK, encoding="utf-8")
    block = load_study(folder / "block.toml")
    mesh = build_mesh(block)
    write_mesh(folder / "block.vtu", mesh)
    rotation = _rotation()
    turned = TetMesh(mesh.points @ rotation.T, mesh.tets, node_sets=dict(mesh.node_sets))
    write_mesh(folder / "turned.vtu", turned)
    return folder, block, rotation


def _force_N(study) -> np.ndarray:
    problem = build_problem(study, build_mesh(study))
    result = simulate_indentation(problem, study.protocol.depths_m, progress=False)
    assert result.completed
    return result.reaction_force_N


def _rotation() -> np.ndarray:
    angles = np.radians([23.0, -41.0, 67.0])
    c, s = np.cos(angles), np.sin(angles)
    rx = np.array([[1, 0, 0], [0, c[0], -s[0]], [0, s[0], c[0]]])
    ry = np.array([[c[1], 0, s[1]], [0, 1, 0], [-s[1], 0, c[1]]])
    rz = np.array([[c[2], -s[2], 0], [s[2], c[2], 0], [0, 0, 1]])
    return rz @ ry @ rx


@pytest.mark.slow
def test_the_block_as_a_mesh_file_gives_the_block_s_force_curve(block_files):
    """The same mesh through [specimen] mesh (site at the top centre, support = the file's
    "bottom" node set): the block study's force curve to 1e-9; turned by a rotation together
    with its site and direction: the same curve to 1e-6."""
    folder, block, rotation = block_files
    reference = _force_N(block)
    top = [0.0, 0.0, 0.004]
    path = folder / "organ.toml"
    path.write_text(_organ_study("block.vtu", site=top), encoding="utf-8")
    organ = load_study(path)
    assert organ.specimen.shape == "mesh" and organ.specimen.thickness_m == pytest.approx(0.004)
    force = _force_N(organ)
    np.testing.assert_allclose(force, reference, rtol=1e-9)
    path.write_text(
        _organ_study("turned.vtu", site=rotation @ top, direction=rotation @ [0.0, 0.0, -1.0]),
        encoding="utf-8",
    )
    turned = _force_N(load_study(path))
    np.testing.assert_allclose(turned, reference, rtol=1e-6)


@pytest.mark.slow
def test_a_sphere_on_the_block_as_a_mesh_file_gives_the_block_s_force_curve(tmp_path):
    """Issue 44 item 4 (a report of 1.5e-2 between the two): the sphere (R = 2 mm, two
    depths to 0.2 mm, near size 0.5 mm) on the block study and on its mesh through
    [specimen] mesh: the same contact nodes under it, the same penalty and the same force
    curve (measured: equal in every bit, 11 and 20 Newton iterations both)."""
    sphere = 'kind = "sphere"\nradius_m = 0.002'
    punch = 'kind = "flat_punch"\nradius_m = 0.001\ncontact = "bonded"'
    text = BLOCK.replace("size_near_m = 0.001", "size_near_m = 0.0005").replace(punch, sphere)
    (tmp_path / "block.toml").write_text(text, encoding="utf-8")
    block = load_study(tmp_path / "block.toml")
    write_mesh(tmp_path / "block.vtu", build_mesh(block))
    organ_text = _organ_study("block.vtu", site=[0.0, 0.0, 0.004]).replace(punch, sphere)
    (tmp_path / "organ.toml").write_text(organ_text, encoding="utf-8")
    organ = load_study(tmp_path / "organ.toml")
    stiffness = [
        build_problem(s, build_mesh(s)).rigid_contact().stiffness_N_per_m for s in (block, organ)
    ]
    assert stiffness[0] == stiffness[1]
    np.testing.assert_allclose(_force_N(organ), _force_N(block), rtol=1e-9)


def test_a_mesh_study_round_trips_and_finds_the_support_opposite(block_files):
    folder, _, _ = block_files
    path = folder / "opposite.toml"
    path.write_text(_organ_study("block.vtu", site=[0.0, 0.0, 0.004], support="opposite"))
    study = load_study(path)
    again = study_from_dict(study.to_dict(), path=path)
    assert again.site_m == study.site_m and again.boundary.support == "opposite"
    mesh = build_mesh(study)
    bottom = mesh.points[mesh.node_sets["bottom"]]
    assert np.all(bottom[:, 2] < 0.002 + 1e-12) and np.any(np.isclose(bottom[:, 2], 0.0))
    problem = build_problem(study, mesh)
    np.testing.assert_allclose(problem.probe_direction, [0.0, 0.0, -1.0], atol=1e-12)


@pytest.mark.parametrize(
    ("change", "key", "message"),
    [
        ({"site": [0.0, 0.0, 0.009]}, "indenter.site_m", "from node set 'surface'"),
        (
            {"site": [0.0, 0.0, 0.004], "direction": [0.0, 0.0, 1.0]},
            "indenter.direction",
            "points out of the body",
        ),  # fmt: skip
        ({"site": [0.0, 0.0, 4.0], "unit": "mm"}, "indenter.site_m", "m from node set"),
        ({"site": [0.0, 0.0, 0.004], "support": "base"}, "boundary.support", "no node set"),
        ({"site": [0.0, 0.0, 0.004], "mesh": "missing.vtu"}, "specimen.mesh", "not found"),
    ],
)
def test_bad_organ_input_is_one_line_naming_the_key(block_files, change, key, message):
    folder, _, _ = block_files
    path = folder / "bad.toml"
    mesh_file = change.pop("mesh", "block.vtu")
    path.write_text(_organ_study(mesh_file, **change), encoding="utf-8")
    _assert_refused_in_one_line(path, key, message)


def _assert_refused_in_one_line(path, key: str, message: str) -> None:
    """Loading the study at ``path`` raises one line naming the file, ``key`` and ``message``."""
    with pytest.raises(InputError) as caught:
        load_study(path)
    text = str(caught.value)
    assert f"{path.name}:" in text and f": {key}: " in text and message in text, text
    assert "\n" not in text


def test_a_mesh_in_millimetres_read_as_metres_is_refused(block_files):
    folder, _, _ = block_files
    mesh = build_mesh(load_study(folder / "block.toml"))
    write_mesh(folder / "mm.vtu", TetMesh(mesh.points * 1e3, mesh.tets, node_sets=mesh.node_sets))
    path = folder / "mm.toml"
    path.write_text(_organ_study("mm.vtu", site=[0.0, 0.0, 4.0]), encoding="utf-8")
    with pytest.raises(InputError, match='specimen.unit: .* give unit = "mm"'):
        load_study(path)
    # site_m is in metres whatever the file's unit
    path.write_text(_organ_study("mm.vtu", site=[0.0, 0.0, 0.004], unit="mm"), encoding="utf-8")
    assert load_study(path).specimen.thickness_m == pytest.approx(0.004)


def test_site_m_needs_a_mesh_specimen(tmp_path):
    text = BLOCK.replace('contact = "bonded"', 'contact = "bonded"\nsite_m = [0.0, 0.0, 0.004]')
    with pytest.raises(InputError, match=r"indenter.site_m: needs \[specimen\] mesh"):
        study_from_dict(tomllib.loads(text))


def _cube_surface(folder, name: str, *, drop_one: bool = False) -> None:
    """The surface of a 4 mm cube (z from 0 to 4 mm), as 12 triangles; ``drop_one``: open."""
    import meshio

    points = 0.004 * np.array(
        [[x - 0.5, y - 0.5, z] for z in (0.0, 1.0) for y in (0.0, 1.0) for x in (0.0, 1.0)]
    )
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    triangles = [t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))]
    if drop_one:
        triangles = triangles[1:]
    meshio.write(folder / name, meshio.Mesh(points, [("triangle", np.array(triangles))]))


def test_a_closed_surface_is_filled_with_tetgen(tmp_path) -> None:
    """An STL cube becomes a TET10 specimen (TetGen's tets fill exactly its volume), held on
    the face opposite the site."""
    _cube_surface(tmp_path, "cube.stl")
    text = _organ_study("cube.stl", site=[0.0, 0.0, 0.004], support="opposite")
    (tmp_path / "cube.toml").write_text(text, encoding="utf-8")
    study = load_study(tmp_path / "cube.toml")
    mesh = build_mesh(study)
    assert mesh.nodes_per_tet == 10
    corners = mesh.points[mesh.tets[:, :4]]
    volumes = np.einsum(
        "ij,ij->i",
        np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]),
        corners[:, 3] - corners[:, 0],
    )
    np.testing.assert_allclose(volumes.sum() / 6.0, 0.004**3, rtol=1e-12)
    np.testing.assert_allclose(mesh.points[mesh.node_set("bottom"), 2], 0.0, atol=1e-15)
    build_problem(study, mesh)


def test_a_usd_mesh_without_a_tetmesh_is_a_surface_to_fill(tmp_path) -> None:
    """[specimen] mesh naming a USD stage with a closed Mesh and no TetMesh: TetGen fills it,
    as an STL surface is (the same 4 mm cube, its volume exactly)."""
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.CreateNew(str(tmp_path / "cube.usda"))
    surface = UsdGeom.Mesh.Define(stage, "/Cube")
    corners = [(0.004 * (x - 0.5), 0.004 * (y - 0.5), 0.004 * z) for z in (0, 1) for y in (0, 1)
               for x in (0, 1)]  # fmt: skip
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    surface.CreatePointsAttr(corners)
    surface.CreateFaceVertexCountsAttr([4] * 6)
    surface.CreateFaceVertexIndicesAttr([i for quad in quads for i in quad])
    stage.GetRootLayer().Save()
    text = _organ_study("cube.usda", site=[0.0, 0.0, 0.004], support="opposite")
    (tmp_path / "cube.toml").write_text(text, encoding="utf-8")
    mesh = build_mesh(load_study(tmp_path / "cube.toml"))
    assert mesh.nodes_per_tet == 10
    assert check_mesh(mesh).total_volume_m3 == pytest.approx(0.004**3, rel=1e-12)


def test_an_open_surface_is_refused_in_one_line(tmp_path) -> None:
    _cube_surface(tmp_path, "open.stl", drop_one=True)
    text = _organ_study("open.stl", site=[0.0, 0.0, 0.004], support="opposite")
    (tmp_path / "open.toml").write_text(text, encoding="utf-8")
    with pytest.raises(InputError) as caught:
        load_study(tmp_path / "open.toml")
    message = str(caught.value)
    assert "specimen.mesh" in message and "not a closed surface" in message
    assert "\n" not in message


def _with_support(text: str, support: str) -> str:
    head, _ = text.split("\n[boundary]\n")
    return head + f"\n[boundary]\nsupport = {support}\n"


def test_a_box_support_holds_the_nodes_inside_it(block_files):
    """A box around the base z = 0 holds exactly the file's "bottom" node set; a box that
    holds no node or only the nodes of one edge (the body could turn about it), or a
    malformed one, is refused in one line naming boundary.support."""
    folder, _, _ = block_files
    path = folder / "box.toml"
    text = _organ_study("block.vtu", site=[0.0, 0.0, 0.004])
    path.write_text(_with_support(text, "{ box = [[-1.0, -1.0, -1e-9], [1.0, 1.0, 1e-9]] }"))
    study = load_study(path)
    assert study.boundary.support == {"box": [[-1.0, -1.0, -1e-9], [1.0, 1.0, 1e-9]]}
    assert study_from_dict(study.to_dict(), path=path).boundary == study.boundary
    path.write_text(text)
    named = build_mesh(load_study(path))
    boxed = build_mesh(study)
    np.testing.assert_array_equal(
        np.sort(boxed.node_sets["bottom"]), np.sort(named.node_sets["bottom"])
    )
    for support, message in (
        ("{ box = [[1.0, 1.0, 1.0], [2.0, 2.0, 2.0]] }", "holds no node"),
        ("{ box = [[-1.0, -1.0, -1e-9], [-0.0039, 1.0, 1e-9]] }", "on one line"),
        ("{ box = [[1.0, 1.0, 1.0], [0.0, 2.0, 2.0]] }", "each min below its max"),
        ("{ region = 'far' }", "each min below its max"),
    ):
        path.write_text(_with_support(text, support))
        with pytest.raises(InputError) as caught:
            load_study(path)
        assert "boundary.support" in str(caught.value) and message in str(caught.value)
        assert "\n" not in str(caught.value)


def _sites_study(folder, records: str) -> str:
    """A version-2 study of the block as a mesh file with ``[[data]]`` ``records`` (each
    record's CSV written: a short ramp)."""
    csv = "time_s,displacement_m,force_N\n0.1,0.0001,0.001\n0.2,0.0002,0.002\n"
    for name in ("a.csv", "b.csv", "c.csv"):
        (folder / name).write_text(csv, encoding="utf-8")
    text = _organ_study("block.vtu", site=[0.0, 0.0, 0.004]).replace(
        "schema_version = 1", "schema_version = 2"
    )
    return text + records


SITES = """
[[data]]
file = "a.csv"

[[data]]
file = "b.csv"
site_m = [0.0015, -0.001, 0.004]
indenter = { kind = "sphere", radius_m = 0.0015 }

[[data]]
file = "c.csv"
site_m = [0.0015, -0.001, 0.004]
indenter = { kind = "sphere", radius_m = 0.0015 }
"""


def test_records_at_their_own_sites_read_write_back_and_share_problems(block_files):
    """Each [[data]] record may carry its own site, direction and indenter: read, written
    back, and one FE problem per distinct probe, all on one mesh where the support is one
    node set."""
    folder, _, _ = block_files
    path = folder / "sites.toml"
    path.write_text(_sites_study(folder, SITES), encoding="utf-8")
    study = load_study(path)
    first, second, third = study.data
    assert not first.placed and second.placed
    assert study.probe_of(second) == study.probe_of(third)
    assert study.probe_of(first) == (study.indenter, study.site_m, None)
    sphere, site, direction = study.probe_of(second)
    assert sphere.kind == "sphere" and sphere.radius_m == 0.0015
    assert site == (0.0015, -0.001, 0.004) and direction is None
    again = study_from_dict(study.to_dict(relative_to=folder), path=path)
    assert again.data[1].indenter == sphere and again.data[1].site_m == site
    problems, index = record_problems(study)
    assert index == [0, 1, 1] and len(problems) == 2
    assert problems[0].mesh is problems[1].mesh  # one support: one mesh, one assembler
    assert problems[1].is_contact and not problems[0].is_contact
    np.testing.assert_allclose(problems[1].frame.origin_m, site, atol=1e-12)


@pytest.mark.parametrize(
    ("record", "key", "message"),
    [
        ("site_m = [0.0, 0.0, 0.009]", "data[1].site_m", "from node set 'surface'"),
        (
            "site_m = [0.0015, -0.001, 0.004]\ndirection = [0.0, 0.0, 1.0]",
            "data[1].direction",
            "points out of the body",
        ),
        ("site_m = [0.0, 0.0]", "data[1].site_m", "three numbers"),
        ('indenter = { kind = "sphere" }', "data[1].indenter.radius_m", "missing"),
        (
            'indenter = { kind = "sphere", radius_m = 0.001, site_m = [0.0, 0.0, 0.004] }',
            "data[1].indenter.site_m",
            "unknown key",
        ),
    ],
    ids=["off_surface", "out_of_body", "two_numbers", "no_radius", "site_in_indenter"],
)
def test_a_bad_record_probe_is_one_line_naming_the_key(block_files, record, key, message):
    folder, _, _ = block_files
    path = folder / "bad_sites.toml"
    path.write_text(
        _sites_study(folder, f'\n[[data]]\nfile = "a.csv"\n\n[[data]]\nfile = "b.csv"\n{record}\n'),
        encoding="utf-8",
    )
    _assert_refused_in_one_line(path, key, message)


def test_a_record_s_own_site_needs_a_mesh_specimen(tmp_path):
    (tmp_path / "a.csv").write_text("time_s,displacement_m,force_N\n0.1,0.0001,0.001\n")
    text = BLOCK.replace("schema_version = 1", "schema_version = 2")
    text += '\n[[data]]\nfile = "a.csv"\nsite_m = [0.0, 0.0, 0.004]\n'
    (tmp_path / "s.toml").write_text(text, encoding="utf-8")
    with pytest.raises(InputError, match=r"data\[0\].site_m: a record's own probe needs"):
        load_study(tmp_path / "s.toml")


ORGAN = Path(__file__).resolve().parents[1] / "scenes" / "liver_organ.asset.usda"


def _liver_study(folder, specimen_extra: str = "") -> Path:
    text = f"""\
schema_version = 1
name = "liver"

[specimen]
mesh = "{ORGAN.as_posix()}"
{specimen_extra}
[indenter]
kind = "sphere"
radius_m = 0.008
site_m = [0.0, 0.0, 0.045]

[protocol]
max_depth_m = 0.002
steps = 2

[material]
model = "neo_hookean"
C10_Pa = 287.5
bulk_modulus_Pa = 575000.0

[boundary]
support = {{ box = [[-1.0, -1.0, -1.0], [1.0, 1.0, -0.035]] }}
"""
    path = folder / "liver.toml"
    path.write_text(text, encoding="utf-8")
    return path


def test_a_usd_tetmesh_asset_is_a_specimen(tmp_path):
    """The liver organ's USD asset as [specimen] mesh: its TetMesh read (TET4, promoted to
    TET10), the site on its top, the support a box under it."""
    study = load_study(_liver_study(tmp_path))
    assert study.specimen.shape == "mesh" and not study.specimen.refine_zones
    assert study.specimen.thickness_m == pytest.approx(0.113, rel=0.02)  # along the normal
    mesh = build_mesh(study)
    assert mesh.nodes_per_tet == 10 and mesh.tet_count == 10_733
    assert np.all(mesh.points[mesh.node_sets["bottom"], 2] <= -0.035)


def test_size_near_m_refines_the_organ_around_the_site(tmp_path):
    """size_near_m with a mesh: the surface within the sphere's zone (1.5 sqrt(R d) = 6 mm)
    is no coarser than it; the organ's volume is kept; the key is written back."""
    coarse = build_mesh(load_study(_liver_study(tmp_path)))
    study = load_study(_liver_study(tmp_path, "size_near_m = 0.003\n"))
    (zone,) = study.specimen.refine_zones
    assert zone[3] == pytest.approx(1.5 * np.sqrt(0.008 * 0.002)) and zone[4] == 0.003
    assert study.to_dict()["specimen"]["size_near_m"] == 0.003
    mesh = build_mesh(study)
    site = np.array(zone[:3])
    faces = boundary_faces(mesh.tets[:, :4])
    edges = np.sort(faces[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2), axis=1)
    ends = mesh.points[np.unique(edges, axis=0)]
    near = np.linalg.norm(ends.mean(axis=1) - site, axis=1) < zone[3]
    assert np.linalg.norm(ends[near, 1] - ends[near, 0], axis=1).max() <= 0.003 + 1e-9
    assert np.count_nonzero(near) > 30
    assert check_mesh(mesh).total_volume_m3 == pytest.approx(
        check_mesh(coarse).total_volume_m3, rel=1e-6
    )
    with pytest.raises(InputError, match="force_accuracy .* or size_near_m, not both"):
        load_study(_liver_study(tmp_path, "size_near_m = 0.003\nforce_accuracy = 0.05\n"))


def _wedge_study(folder, edge, mesh_file: str = "block.vtu") -> Path:
    text = _organ_study(mesh_file, site=[0.0, 0.0, 0.004]).replace(
        'kind = "flat_punch"\nradius_m = 0.001\ncontact = "bonded"\n',
        'kind = "wedge"\nradius_m = 0.0005\nangle_deg = 30.0\n'
        + ("" if edge is None else f"edge = {_toml_vector(edge)}\n"),
    )
    path = folder / "wedge.toml"
    path.write_text(text.replace("max_depth_m = 0.0002", "max_depth_m = 0.0001"))
    return path


@pytest.mark.slow
def test_a_wedge_s_edge_turns_with_the_study_s_edge_key(block_files):
    """[indenter] edge: the block turned a quarter about z, indented by a wedge whose edge
    is turned with it (-x), gives the unturned block's force with the default edge (y) to
    1e-6; the frame's second axis is the edge given; an edge along the direction, or on
    another indenter, is one line naming indenter.edge."""
    folder, block, _ = block_files
    mesh = build_mesh(block)
    quarter = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    write_mesh(
        folder / "quarter.vtu",
        TetMesh(mesh.points @ quarter.T, mesh.tets, node_sets=dict(mesh.node_sets)),
    )
    along_y = load_study(_wedge_study(folder, None))
    reference = _force_N(along_y)
    turned = load_study(_wedge_study(folder, quarter @ [0.0, 1.0, 0.0], "quarter.vtu"))
    assert turned.edge == (-1.0, 0.0, 0.0)
    assert turned.to_dict()["indenter"]["edge"] == [-1.0, 0.0, 0.0]
    problem = build_problem(turned, build_mesh(turned))
    np.testing.assert_allclose(problem.frame.axes[1], [-1.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(_force_N(turned), reference, rtol=1e-6)
    with pytest.raises(InputError, match="indenter.edge: the edge must not be along"):
        load_study(_wedge_study(folder, [0.0, 0.0, 1.0]))
    sphere = _organ_study("block.vtu", site=[0.0, 0.0, 0.004]).replace(
        'contact = "bonded"\n', 'contact = "bonded"\nedge = [1.0, 0.0, 0.0]\n'
    )
    (folder / "edge.toml").write_text(sphere)
    with pytest.raises(InputError, match=r"indenter.edge: is the edge of a wedge"):
        load_study(folder / "edge.toml")


@pytest.mark.slow
def test_a_run_at_a_site_records_its_probe_frame_and_exports_it(block_files, tmp_path):
    """warptissue simulate of a mesh specimen writes the probe's frame (the snapped site, the
    direction, the axes) to result.json; warptissue export draws the indenter there."""
    import json

    from warptissue.simulate import run_study
    from warptissue.usd import validate_stage
    from warptissue.usd.export import export_result_dir

    folder, _, rotation = block_files
    path = folder / "turned_run.toml"
    site, direction = rotation @ [0.0, 0.0, 0.004], rotation @ [0.0, 0.0, -1.0]
    path.write_text(_organ_study("turned.vtu", site=site, direction=direction))
    run_study(load_study(path), out_dir=tmp_path / "run", progress=False, announce=False)
    probe = json.loads((tmp_path / "run" / "result.json").read_text())["probe"]
    np.testing.assert_allclose(probe["site_m"], site, atol=1e-12)
    np.testing.assert_allclose(probe["direction"], direction, atol=1e-12)
    np.testing.assert_allclose(np.asarray(probe["axes"])[2], -direction, atol=1e-12)
    paths = export_result_dir(tmp_path / "run", tmp_path / "turned.usda")
    assert validate_stage(paths.root) == []


def _with_boundary(text: str, lines: str) -> str:
    head, _ = text.split("\n[boundary]\n")
    return head + "\n[boundary]\n" + lines


def test_a_half_space_support_holds_the_nodes_beyond_its_plane(block_files):
    folder, _, _ = block_files
    path = folder / "half.toml"
    text = _organ_study("block.vtu", site=[0.0, 0.0, 0.004])
    path.write_text(_with_support(text, "{ half_space = [[0.0, 0.0, 0.0], [0.0, 0.0, -1.0]] }"))
    study = load_study(path)
    assert study_from_dict(study.to_dict(), path=path).boundary == study.boundary
    path.write_text(text)
    named = build_mesh(load_study(path))
    np.testing.assert_array_equal(
        np.sort(build_mesh(study).node_sets["bottom"]), np.sort(named.node_sets["bottom"])
    )
    for support in (
        "{ half_space = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]] }",
        "{ half_space = [[0.0, 0.0], [0.0, 0.0, 1.0]] }",
    ):
        path.write_text(_with_support(text, support))
        _assert_refused_in_one_line(path, "boundary.support", "a nonzero normal")
    path.write_text(_with_support(text, "{ half_space = [[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]] }"))
    _assert_refused_in_one_line(path, "boundary.support", "holds no node")


def test_a_flat_support_slides_and_one_that_is_not_flat_rests_on_a_bed(block_files):
    """base = "sliding" on a mesh specimen holds the normal of its flat support (z on the
    base z = 0 of the block as a file); the "opposite" support (the base and the lower half
    of the sides) is not flat: it rests on the frictionless bed, whose stiffness the study's
    problem fixes from the [material] (a fit keeps it as the parameters move)."""
    folder, _, _ = block_files
    path = folder / "sliding.toml"
    text = _organ_study("block.vtu", site=[0.0, 0.0, 0.004])
    path.write_text(_with_boundary(text, 'base = "sliding"\nsupport = "bottom"\n'))
    study = load_study(path)
    conditions = build_problem(study, build_mesh(study)).dirichlet_conditions()
    bottom = build_mesh(study).node_sets["bottom"]
    on_base = np.isin(conditions.nodes, bottom)
    assert np.all(conditions.components[on_base] == 2)  # a bonded punch: no pins needed
    assert np.sum(on_base) == len(bottom)
    path.write_text(_with_boundary(text, 'base = "sliding"\nsupport = "opposite"\n'))
    study = load_study(path)
    problem = build_problem(study, build_mesh(study))
    assert problem.on_sliding_bed
    held = problem.dirichlet_conditions().nodes
    assert not np.isin(held, problem.mesh.node_sets["bottom"]).any()
    expected = 1000.0 * 2.0 * 287.5 / support_edge_m(problem.mesh, "bottom")
    assert problem.sliding_bed_Pa_per_m == pytest.approx(expected)
    softer = dataclasses.replace(problem, material=NeoHookean(100.0, 575000.0))
    assert softer.sliding_bed_stiffness() == pytest.approx(expected)


@pytest.mark.parametrize(
    ("lines", "key", "message"),
    [
        ('base = "foundation"\n', "boundary.foundation_Pa_per_m", "is needed with base"),
        ('base = "foundation"\nfoundation_Pa_per_m = -5.0\n', "boundary.foundation_Pa_per_m",
         "must be positive"),
        ('base = "foundation"\nfoundation_Pa_per_m = 5.0\nfoundation_tangential_Pa_per_m = 0\n',
         "boundary.foundation_tangential_Pa_per_m", "must be positive"),
        ("foundation_Pa_per_m = 5.0\n", "boundary.foundation_Pa_per_m",
         'needs base = "foundation"'),
    ],
)  # fmt: skip
def test_bad_foundation_keys_are_one_line_naming_the_key(block_files, lines, key, message):
    folder, _, _ = block_files
    path = folder / "bed.toml"
    path.write_text(_with_boundary(_organ_study("block.vtu", site=[0.0, 0.0, 0.004]), lines))
    _assert_refused_in_one_line(path, key, message)


def test_an_organ_on_a_foundation_round_trips_and_is_held_by_springs(block_files):
    folder, _, _ = block_files
    path = folder / "bed.toml"
    text = _organ_study("block.vtu", site=[0.0, 0.0, 0.004], support="opposite")
    path.write_text(_with_boundary(text, 'base = "foundation"\nfoundation_Pa_per_m = 2e5\n'))
    study = load_study(path)
    assert study.boundary.foundation.tangential_Pa_per_m == 2e5
    again = study_from_dict(study.to_dict(), path=path)
    assert again.boundary == study.boundary
    problem = build_problem(study, build_mesh(study))
    assert len(problem.dirichlet_conditions().nodes) == len(problem.punch_nodes) * 3
    springs = problem.support_springs()  # the support's triangles: the base, the sides' lower half
    held = problem.mesh.node_sets["bottom"]
    assert set(springs.nodes) <= set(held)
    base = held[np.isclose(problem.mesh.points[held, 2], 0.0)]
    assert set(base) <= set(springs.nodes)
    assert np.any(problem.mesh.points[springs.nodes, 2] > 1e-3)


def test_a_block_on_a_stiff_foundation_gives_the_held_block_s_curve(block_files):
    """The block as a file, on a foundation of 1e12 Pa/m under its base: the held block's
    force curve to 1e-6; on 1e5 Pa/m it gives way."""
    folder, block, _ = block_files
    reference = _force_N(block)
    path = folder / "stiff_bed.toml"
    text = _organ_study("block.vtu", site=[0.0, 0.0, 0.004])
    forces = []
    for stiffness in (1e12, 1e5):
        lines = f'base = "foundation"\nfoundation_Pa_per_m = {stiffness}\nsupport = "bottom"\n'
        path.write_text(_with_boundary(text, lines))
        forces.append(_force_N(load_study(path)))
    np.testing.assert_allclose(forces[0], reference, rtol=1e-6)
    assert np.all(forces[1] < 0.9 * reference)


def test_a_self_intersecting_surface_is_refused_in_one_line(tmp_path) -> None:
    """Two closed cubes that overlap, in one STL: each is closed, their union crosses itself
    (TetGen finds the intersecting faces); one line naming specimen.mesh, exit status 2."""
    import meshio

    from warptissue.cli import main

    points = 0.004 * np.array(
        [[x - 0.5, y - 0.5, z] for z in (0.0, 1.0) for y in (0.0, 1.0) for x in (0.0, 1.0)]
    )
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    triangles = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))])
    shifted = points + np.array([0.002, 0.001, 0.0015])
    meshio.write(
        tmp_path / "crossed.stl",
        meshio.Mesh(
            np.vstack([points, shifted]), [("triangle", np.vstack([triangles, triangles + 8]))]
        ),
    )
    text = _organ_study("crossed.stl", site=[0.0, 0.0, 0.004], support="opposite")
    path = tmp_path / "crossed.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(InputError) as caught:
        load_study(path)
    message = str(caught.value)
    assert "specimen.mesh" in message and "crossed.stl" in message and "\n" not in message
    assert main(["simulate", str(path), "--out", str(tmp_path / "out"), "--quiet"]) == 2
    assert not (tmp_path / "out").exists()
    assert not list(Path.cwd().glob("_skipped.*"))  # TetGen's report of the crossing faces


REGIONS = """
[material.regions.right]
tet_regions = [1]
C10_Pa = 900.0
"""


def _halves(block_files) -> Path:
    """The block as a mesh file whose half x > 0 is tet region 1, the other half 0."""
    folder, block, _ = block_files
    mesh = build_mesh(block)
    mesh.tet_regions = (mesh.points[mesh.tets[:, :4]].mean(axis=1)[:, 0] > 0).astype(np.int32)
    write_mesh(folder / "halves.vtu", mesh)
    return folder


def test_material_regions_are_read_and_written_back(block_files):
    folder = _halves(block_files)
    path = folder / "regions.toml"
    path.write_text(_organ_study("halves.vtu", site=[0.0, 0.0, 0.004]) + REGIONS)
    study = load_study(path)
    assert study.material.parameter_names == ("C10_Pa", "right.C10_Pa")
    right = study.material.materials["right"]
    assert (right.C10_Pa, right.bulk_modulus_Pa) == (900.0, 575000.0)  # the default's K
    assert study.material.tet_regions == {"right": (1,)}
    saved = folder / "saved.toml"
    save_study(study, saved)
    assert load_study(saved).material == study.material


@pytest.mark.parametrize(
    ("change", "key", "message"),
    [
        ({"tet_regions = [1]": "tet_regions = [5]"}, "material.regions.right.tet_regions",
         "tet region 5 is not in the mesh"),
        ({"C10_Pa = 900.0": "C10_pa = 900.0"}, "material.regions.right.C10_pa",
         "unknown parameter for model"),
        ({"regions.right]": 'regions."my.tumour"]'}, "material.regions.my.tumour",
         "a region's name is a letter"),
        ({'unit = "m"': 'unit = "m"\nsize_near_m = 0.001'}, "specimen.size_near_m",
         "cannot be refined around a site"),
    ],
    ids=["region_not_in_mesh", "typo", "dotted_name", "refined"],
)  # fmt: skip
def test_bad_material_regions_are_one_line_naming_the_key(block_files, change, key, message):
    folder = _halves(block_files)
    text = _organ_study("halves.vtu", site=[0.0, 0.0, 0.004]) + REGIONS
    for old, new in change.items():
        assert old in text
        text = text.replace(old, new)
    path = folder / "bad_regions.toml"
    path.write_text(text)
    _assert_refused_in_one_line(path, key, message)


def test_material_regions_need_a_mesh_file(block_files):
    folder, _, _ = block_files
    path = folder / "block_regions.toml"
    path.write_text(BLOCK + REGIONS)
    _assert_refused_in_one_line(path, "material.regions", "the tet regions of a mesh file")
