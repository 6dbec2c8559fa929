import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from warptissue.errors import InputError, MeshError
from warptissue.mesh import (
    TET4_FACES,
    block_mesh,
    check_mesh,
    extrude_triangles,
    graded_coordinates,
    graded_spacing,
    hex_to_tets,
    indentation_block,
    indentation_disc,
)

WIDTH, RADIUS, THICKNESS, PROBE = 0.02, 0.01, 0.008, 0.0025
SIZES = {"size_near_m": 0.0006, "size_far_m": 0.003}


def specimen(kind, *, quarter=True, element="TET4", **options):
    """A small block or disc, a few thousand tets."""
    shape = {"width_m": WIDTH} if kind == "block" else {"radius_m": RADIUS}
    generator = indentation_block if kind == "block" else indentation_disc
    return generator(
        **shape,
        thickness_m=THICKNESS,
        probe_radius_m=PROBE,
        quarter=quarter,
        element=element,
        **(SIZES | options),
    )


def triangle_areas(points, triangles):
    p = points[triangles]
    return 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)


def face_counts(tets):
    """How many tets hold each distinct corner face (counted with a Python dict)."""
    counts = {}
    for face in np.sort(tets[:, :4][:, TET4_FACES].reshape(-1, 3), axis=1):
        key = tuple(face)
        counts[key] = counts.get(key, 0) + 1
    return np.array(list(counts.values()))


def polygon_area(points_2d):
    """Shoelace area of a polygon given by its vertices in order."""
    x, y = points_2d[:, 0], points_2d[:, 1]
    return 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def ring_polygon(mesh, nodes, *, quarter):
    """Vertices of the top-face polygon through ``nodes``, by angle (closed through 0 for a
    quarter)."""
    xy = mesh.points[nodes, :2]
    order = np.argsort(np.arctan2(xy[:, 1], xy[:, 0]))
    xy = xy[order]
    return np.vstack([[0.0, 0.0], xy]) if quarter else xy


@pytest.mark.parametrize(("split", "per_cell"), [("five", 5), ("six", 6)])
def test_block_volume_orientation_and_conformity(split, per_cell):
    x = graded_coordinates(0.03, 3, ratio=0.5)
    y = np.linspace(0.0, 0.02, 4)
    z = np.linspace(0.0, 0.01, 3)
    mesh = block_mesh(x, y, z, split=split)
    assert mesh.tet_count == 3 * 3 * 2 * per_cell
    volumes = mesh.volumes()
    assert np.all(volumes > 0)
    assert volumes.sum() == pytest.approx(0.03 * 0.02 * 0.01, rel=1e-12)
    # A conforming mesh's boundary is the box surface alone: its area is the box's.
    faces = np.concatenate(list(mesh.face_sets.values()))
    p = mesh.points[faces]
    area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1).sum()
    assert area == pytest.approx(2 * (0.03 * 0.02 + 0.03 * 0.01 + 0.02 * 0.01), rel=1e-12)
    assert np.allclose(mesh.points[mesh.node_sets["zmax"], 2], 0.01)


def test_graded_coordinates_ratio():
    x = graded_coordinates(1.0, 4, ratio=0.25)
    sizes = np.diff(x)
    assert x[-1] == pytest.approx(1.0)
    assert sizes[-1] / sizes[0] == pytest.approx(0.25)


def test_graded_spacing_sizes():
    x = graded_spacing(1.0, 0.01, 0.1, growth=1.25)
    sizes = np.diff(x)
    assert x[0] == 0.0 and x[-1] == 1.0
    assert sizes[0] == pytest.approx(0.01, rel=0.15)
    assert np.all(sizes[1:] / sizes[:-1] <= 1.25 + 1e-12)
    assert np.all(sizes[1:] / sizes[:-1] >= 1.0 - 1e-12)
    assert sizes.max() == pytest.approx(0.1, rel=0.15)
    # Shorter than the ramp: only the first few growing intervals.
    short = np.diff(graded_spacing(0.05, 0.01, 0.1, growth=1.25))
    assert len(short) == 4 and np.allclose(short[1:] / short[:-1], 1.25)


def test_graded_spacing_growth_just_above_one_is_uniform():
    # log(growth) ~ 2e-16 once asked for a ramp of ~1e16 intervals; with growth -> 1 the
    # spacing is uniform: ten intervals of the requested first size.
    sizes = np.diff(graded_spacing(0.01, 0.001, 0.002, growth=1.0 + 2.0**-52))
    assert len(sizes) == 10
    assert np.allclose(sizes, 0.001, rtol=1e-12)


def test_graded_spacing_rejects_bad_sizes():
    with pytest.raises(InputError, match="largest_m"):
        graded_spacing(1.0, 0.1, 0.01)
    with pytest.raises(InputError, match="growth"):
        graded_spacing(1.0, 0.01, 0.1, growth=0.9)


def test_extrusion_is_conforming_for_any_numbering(rng):
    # Two triangles of a square with a random node numbering, three layers.
    points = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    order = rng.permutation(4)
    points = points[order]
    inverse = np.argsort(order)
    triangles = inverse[np.array([[0, 1, 2], [0, 2, 3]])]
    mesh_points, tets = extrude_triangles(points, triangles, np.array([0.0, 0.3, 0.5, 1.0]))
    volumes = np.linalg.det(mesh_points[tets[:, 1:]] - mesh_points[tets[:, :1]]) / 6
    assert np.all(volumes > 0)
    assert volumes.sum() == pytest.approx(1.0)
    counts = face_counts(tets)
    assert set(counts) == {1, 2}
    assert (counts == 1).sum() == 2 * 2 + 4 * 3 * 2  # top, bottom and four sides


@pytest.mark.parametrize("kind", ["block", "disc"])
@pytest.mark.parametrize("quarter", [True, False])
def test_indentation_specimen_volume_and_conformity(kind, quarter):
    mesh = specimen(kind, quarter=quarter)
    volumes = mesh.volumes()
    assert np.all(volumes > 0)
    quality = check_mesh(mesh)
    assert quality.min_radius_ratio > 0.15  # in-plane stretch below the probe is 5:1 here
    counts = face_counts(mesh.tets)
    assert counts.max() == 2  # every interior face is shared by exactly two tets
    # The named surfaces (probe lies inside top) cover the whole boundary, once.
    surfaces = [f for name, f in mesh.face_sets.items() if name != "probe"]
    assert (counts == 1).sum() == sum(len(f) for f in surfaces)
    boundary_area = sum(triangle_areas(mesh.points, f).sum() for f in surfaces)
    if kind == "block":
        half = WIDTH / 2 if quarter else WIDTH
        expected_volume = half * half * THICKNESS
        lateral = 4 * half * THICKNESS / (2 if quarter else 1)
        symmetry = 2 * (WIDTH / 2) * THICKNESS if quarter else 0.0
        expected_area = 2 * half * half + lateral + symmetry
        assert volumes.sum() == pytest.approx(expected_volume, rel=1e-12)
        assert boundary_area == pytest.approx(expected_area, rel=1e-12)
    else:
        rim = ring_polygon(
            mesh, np.intersect1d(mesh.node_set("side"), mesh.node_set("top")), quarter=quarter
        )
        assert np.allclose(np.hypot(rim[int(quarter) :, 0], rim[int(quarter) :, 1]), RADIUS)
        area = polygon_area(rim)
        assert volumes.sum() == pytest.approx(area * THICKNESS, rel=1e-12)
        circle = np.pi * RADIUS**2 / (4 if quarter else 1)
        assert 0.99 * circle < area < circle
        rim_length = np.linalg.norm(np.diff(rim[int(quarter) :], axis=0), axis=1).sum()
        if not quarter:
            rim_length += np.linalg.norm(rim[0] - rim[-1])
        symmetry = 2 * RADIUS * THICKNESS if quarter else 0.0
        expected_area = 2 * area + rim_length * THICKNESS + symmetry
        assert boundary_area == pytest.approx(expected_area, rel=1e-12)


@pytest.mark.parametrize("kind", ["block", "disc"])
@pytest.mark.parametrize("quarter", [True, False])
def test_indentation_node_sets_and_probe_ring(kind, quarter):
    mesh = specimen(kind, quarter=quarter)
    p = mesh.points
    radius = np.hypot(p[:, 0], p[:, 1])
    assert np.all(p[mesh.node_set("top"), 2] == THICKNESS)
    assert np.all(p[mesh.node_set("bottom"), 2] == 0.0)
    assert len(mesh.node_set("top")) == np.count_nonzero(p[:, 2] == THICKNESS)
    if kind == "block":
        side = p[mesh.node_set("side"), :2]
        assert np.allclose(np.abs(side).max(axis=1), WIDTH / 2, rtol=1e-12)
    else:
        assert np.allclose(radius[mesh.node_set("side")], RADIUS, rtol=1e-12)
    if quarter:
        assert np.all(p[:, :2] >= 0.0)
        assert np.all(p[mesh.node_set("symmetry_x"), 0] == 0.0)
        assert np.all(p[mesh.node_set("symmetry_y"), 1] == 0.0)
        assert len(mesh.node_set("symmetry_x")) == np.count_nonzero(p[:, 0] == 0.0)
    else:
        assert "symmetry_x" not in mesh.node_sets
        assert p[:, 0].min() < 0 and p[:, 1].min() < 0
    # Each face set lies in its surface.
    for name, column, value in (("top", 2, THICKNESS), ("bottom", 2, 0.0)):
        assert np.all(p[mesh.face_sets[name], column] == value)
    # The probe set: top nodes with r <= a; its boundary is a ring of nodes at r = a exactly.
    probe = mesh.node_set("probe")
    top = mesh.node_set("top")
    assert np.array_equal(np.sort(probe), np.sort(top[radius[top] <= PROBE * (1 + 1e-12)]))
    ring = top[np.abs(radius[top] - PROBE) <= 1e-12 * PROBE]
    assert len(ring) >= (9 if quarter else 32)
    angles = np.sort(np.arctan2(p[ring, 1], p[ring, 0]))
    gaps = np.diff(angles)
    assert gaps.max() < 0.25  # the ring goes all the way round, densely
    if quarter:
        assert angles[0] == 0.0 and angles[-1] == pytest.approx(np.pi / 2)
    # Probe faces tile the ring polygon exactly.
    probe_area = triangle_areas(p, mesh.face_sets["probe"]).sum()
    assert probe_area == pytest.approx(polygon_area(ring_polygon(mesh, ring, quarter=quarter)))


def test_indentation_grading():
    mesh = specimen("block", growth=1.3)
    z = np.unique(mesh.points[:, 2])
    layers = np.diff(z)[::-1]  # from the top down
    assert layers[0] == pytest.approx(SIZES["size_near_m"], rel=0.2)
    assert np.all(layers[1:] / layers[:-1] <= 1.3 + 1e-9)
    assert np.all(layers[1:] / layers[:-1] >= 1.0 - 1e-9)
    # In the plane: edges of the top face grow from ~size_near at the probe to ~size_far.
    top = mesh.face_sets["top"]
    p = mesh.points
    edges = np.concatenate([top[:, [0, 1]], top[:, [1, 2]], top[:, [2, 0]]])
    length = np.linalg.norm(p[edges[:, 0]] - p[edges[:, 1]], axis=1)
    mid_radius = np.hypot(*(0.5 * (p[edges[:, 0], :2] + p[edges[:, 1], :2])).T)
    near = length[mid_radius < 1.2 * PROBE]
    far = length[mid_radius > 0.9 * WIDTH / 2]
    assert near.max() < 1.6 * SIZES["size_near_m"] * np.sqrt(2)
    assert far.mean() > 3 * near.mean()
    assert far.max() < 1.5 * SIZES["size_far_m"] * np.sqrt(2)


def test_refinement_scales_tet_count():
    coarse = specimen("block")
    fine = specimen("block", size_near_m=0.0003, size_far_m=0.0015)
    assert 3 < fine.tet_count / coarse.tet_count < 8


def test_indentation_tet10():
    mesh = specimen("disc", element="TET10")
    assert mesh.element_type == "TET10"
    p = mesh.points
    corners = p[mesh.tets[:, :4]]
    expected = 0.5 * (corners[:, [0, 1, 0, 0, 1, 2]] + corners[:, [1, 2, 2, 3, 3, 3]])
    np.testing.assert_allclose(p[mesh.tets[:, 4:]], expected)
    radius = np.hypot(p[:, 0], p[:, 1])
    top = mesh.node_set("top")
    probe = mesh.node_set("probe")
    assert np.array_equal(np.sort(probe), np.sort(top[radius[top] <= PROBE * (1 + 1e-12)]))
    assert np.all(p[mesh.node_set("symmetry_x"), 0] == 0.0)


def test_disc_curved_side_moves_midnodes_onto_cylinder():
    mesh = specimen("disc", element="TET10", curved_side=True)
    side = mesh.node_set("side")
    radius = np.hypot(mesh.points[side, 0], mesh.points[side, 1])
    np.testing.assert_allclose(radius, RADIUS, rtol=1e-12)
    assert len(side) > len(specimen("disc").node_set("side"))
    # Interior mid-edge nodes stay at their edge midpoints.
    straight = specimen("disc", element="TET10")
    moved = np.flatnonzero(np.any(mesh.points != straight.points, axis=1))
    assert np.all(np.isin(moved, side))


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"probe_radius_m": 0.02}, "probe_radius_m"),
        ({"size_far_m": 0.0001}, "size_far_m"),
        ({"element": "HEX8"}, "element"),
        ({"thickness_m": -1.0}, "thickness_m"),
    ],
)
def test_indentation_rejects_bad_parameters(options, message):
    arguments = {
        "width_m": WIDTH,
        "thickness_m": THICKNESS,
        "probe_radius_m": PROBE,
        **SIZES,
    } | options
    with pytest.raises(InputError, match=message):
        indentation_block(**arguments)


def structured_hexes(n=3):
    """Corner grid and VTK-ordered hexes of an n x n x n unit cube, listed in random order."""
    grid = np.linspace(0.0, 1.0, n + 1)
    x, y, z = np.meshgrid(grid, grid, grid, indexing="ij")
    points = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
    index = np.arange(len(points)).reshape(n + 1, n + 1, n + 1)
    i, j, k = (a.ravel() for a in np.meshgrid(*[np.arange(n)] * 3, indexing="ij"))
    offsets = [
        (0, 0, 0),
        (1, 0, 0),
        (1, 1, 0),
        (0, 1, 0),
        (0, 0, 1),
        (1, 0, 1),
        (1, 1, 1),
        (0, 1, 1),
    ]
    hexes = np.stack([index[i + a, j + b, k + c] for a, b, c in offsets], axis=1)
    return points, hexes


@pytest.mark.parametrize(("split", "per_hex"), [("five", 5), ("six", 6)])
def test_hex_to_tets_on_shuffled_distorted_hexes(split, per_hex, rng):
    points, hexes = structured_hexes()
    hexes = hexes[rng.permutation(len(hexes))]
    interior = np.all((points > 0) & (points < 1), axis=1)
    points[interior] += rng.uniform(-0.05, 0.05, size=(interior.sum(), 3))
    mesh = hex_to_tets(points, hexes, split=split)
    assert mesh.tet_count == per_hex * len(hexes)
    assert np.all(mesh.volumes() > 0)
    assert mesh.volumes().sum() == pytest.approx(1.0, rel=1e-12)
    counts = face_counts(mesh.tets)
    assert counts.max() == 2 and (counts == 1).sum() == 6 * 9 * 2
    assert triangle_areas(mesh.points, mesh.face_sets["boundary"]).sum() == pytest.approx(6.0)
    assert np.array_equal(np.bincount(mesh.tet_regions), np.full(len(hexes), per_hex))


def test_hex_to_tets_rejects_mismatched_diagonals():
    points, hexes = structured_hexes(2)
    # Renumber one hex by a quarter turn about z: its Kuhn diagonals no longer match.
    hexes[0] = hexes[0][[1, 2, 3, 0, 5, 6, 7, 4]]
    with pytest.raises(MeshError, match="not conforming"):
        hex_to_tets(points, hexes, split="six")


def test_layer_max_bounds_vertical_stretch():
    loose = specimen("block", size_far_m=0.004)
    tight = specimen("block", size_far_m=0.004, layer_max_m=0.0012)
    layers = np.diff(np.unique(tight.points[:, 2]))
    assert layers.max() <= 0.0012 * (1 + 1e-9) * 1.1  # fitted to the thickness: within 10 %
    assert np.diff(np.unique(loose.points[:, 2])).max() > 0.0015
    assert check_mesh(tight).min_radius_ratio > check_mesh(loose).min_radius_ratio
    # The plane is unchanged: same top-face triangulation.
    assert len(tight.face_sets["top"]) == len(loose.face_sets["top"])


@settings(max_examples=20, deadline=None)
@given(
    probe_fraction=st.floats(0.05, 0.9),
    near_fraction=st.floats(0.1, 3.0),
    far_ratio=st.floats(1.0, 8.0),
    growth=st.floats(1.0, 1.6),
    thickness_fraction=st.floats(0.1, 1.5),
    quarter=st.booleans(),
    disc=st.booleans(),
)
def test_indentation_meshes_are_valid_over_parameter_space(
    probe_fraction, near_fraction, far_ratio, growth, thickness_fraction, quarter, disc
):
    half = 0.01
    probe = probe_fraction * half
    near = near_fraction * probe
    shape = {"radius_m": half} if disc else {"width_m": 2 * half}
    mesh = (indentation_disc if disc else indentation_block)(
        **shape,
        thickness_m=thickness_fraction * half,
        probe_radius_m=probe,
        quarter=quarter,
        element="TET4",
        size_near_m=near,
        size_far_m=far_ratio * near,
        growth=growth,
    )
    assume(mesh.tet_count < 30000)
    quality = check_mesh(mesh)  # raises on inverted, degenerate or crowded tets
    assert quality.unused_node_count == 0
    counts = face_counts(mesh.tets)
    assert counts.max() == 2
    assert (counts == 1).sum() == sum(len(f) for n, f in mesh.face_sets.items() if n != "probe")
    top = mesh.node_set("top")
    radius = np.hypot(mesh.points[top, 0], mesh.points[top, 1])
    assert np.count_nonzero(np.abs(radius - probe) <= 1e-12 * probe) >= (5 if quarter else 16)
    if not disc:
        area = (half if quarter else 2 * half) ** 2
        assert mesh.volumes().sum() == pytest.approx(area * thickness_fraction * half)


def test_extrusion_rejects_bad_input():
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
    with pytest.raises(MeshError, match="strictly increasing"):
        extrude_triangles(square, [[0, 1, 2]], np.array([0.0, 0.0]))
    with pytest.raises(MeshError, match="outside"):
        extrude_triangles(square, [[0, 1, 3]], np.array([0.0, 1.0]))


@pytest.mark.parametrize("kind", ["block", "disc"])
@pytest.mark.parametrize("quarter", [True, False])
def test_delaunay_specimen_fills_the_same_surface_with_the_same_sets(kind, quarter):
    extruded = specimen(kind, quarter=quarter)
    mesh = specimen(kind, quarter=quarter, mesher="delaunay")
    p = mesh.points
    assert np.all(mesh.volumes() > 0)
    counts = face_counts(mesh.tets)
    assert counts.max() == 2
    # The same polyhedron: the volume, and the named surfaces tile the whole boundary once.
    assert mesh.volumes().sum() == pytest.approx(extruded.volumes().sum(), rel=1e-12)
    surfaces = [f for name, f in mesh.face_sets.items() if name != "probe"]
    assert (counts == 1).sum() == sum(len(f) for f in surfaces)
    for name, f in mesh.face_sets.items():
        assert triangle_areas(p, f).sum() == pytest.approx(
            triangle_areas(extruded.points, extruded.face_sets[name]).sum(), rel=1e-12
        ), name
        assert np.array_equal(np.unique(f), np.sort(mesh.node_set(name))), name
    assert set(mesh.node_sets) == set(extruded.node_sets)
    # Each set lies in its surface.
    assert np.all(p[mesh.node_set("top"), 2] == THICKNESS)
    assert np.all(p[mesh.node_set("bottom"), 2] == 0.0)
    assert len(mesh.node_set("top")) == np.count_nonzero(p[:, 2] == THICKNESS)
    if quarter:
        assert np.all(p[mesh.node_set("symmetry_x"), 0] == 0.0)
        assert np.all(p[mesh.node_set("symmetry_y"), 1] == 0.0)
    radius = np.hypot(p[:, 0], p[:, 1])
    if kind == "block":
        assert np.allclose(np.abs(p[mesh.node_set("side"), :2]).max(axis=1), WIDTH / 2)
    else:
        # Steiner points sit on the flat facets of the inscribed polygonal prism.
        rim = np.intersect1d(extruded.node_set("side"), extruded.node_set("top"))
        angles = np.sort(np.arctan2(extruded.points[rim, 1], extruded.points[rim, 0]))
        widest_facet = np.diff(
            angles if quarter else np.append(angles, angles[0] + 2 * np.pi)
        ).max()
        inscribed = RADIUS * np.cos(0.5 * widest_facet)
        side_radius = radius[mesh.node_set("side")]
        assert side_radius.max() <= RADIUS * (1 + 1e-12)
        assert side_radius.min() >= 0.999 * inscribed
    # The probe: top nodes with r <= a, bounded by the extruded mesh's ring of nodes at r = a
    # (TetGen keeps every input vertex).
    top = mesh.node_set("top")
    probe = mesh.node_set("probe")
    assert np.array_equal(np.sort(probe), np.sort(top[radius[top] <= PROBE * (1 + 1e-12)]))

    def ring(points, nodes):
        on_ring = np.abs(np.hypot(points[nodes, 0], points[nodes, 1]) - PROBE) <= 1e-12 * PROBE
        return points[np.sort(nodes[on_ring])]

    expected = ring(extruded.points, extruded.node_set("probe"))
    found = ring(p, probe)
    assert len(found) >= len(expected)
    assert {tuple(x) for x in expected} <= {tuple(x) for x in found}


def test_delaunay_specimen_tets_are_isotropic():
    from warptissue.mesh import edge_lengths, radius_ratios

    shapes = {}
    for mesher in ("extruded", "delaunay"):
        mesh = specimen("block", mesher=mesher)
        lengths = edge_lengths(mesh.points, mesh.tets)
        edge_ratio = lengths.max(axis=1) / lengths.min(axis=1)
        shapes[mesher] = (
            np.percentile(edge_ratio, 90),
            np.percentile(radius_ratios(mesh.points, mesh.tets), 10),
        )
    # 90th percentile of the longest / shortest edge, 10th of the radius ratio (1 = regular).
    assert shapes["delaunay"][0] < 2.5 < shapes["extruded"][0]
    assert shapes["delaunay"][1] > 0.45 > shapes["extruded"][1]


def test_delaunay_disc_curved_side_puts_every_side_node_on_the_cylinder():
    mesh = specimen("disc", element="TET10", curved_side=True, mesher="delaunay")
    side = mesh.node_set("side")
    np.testing.assert_allclose(np.hypot(*mesh.points[side, :2].T), RADIUS, rtol=1e-12)
    assert check_mesh(mesh).min_scaled_jacobian > 0


def test_unknown_mesher_is_rejected():
    with pytest.raises(InputError, match="mesher"):
        specimen("block", mesher="octree")
