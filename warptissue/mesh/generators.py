"""Structured tetrahedral mesh generators."""

from __future__ import annotations

import numpy as np

from warptissue.errors import InputError, MeshError
from warptissue.mesh._grading import (
    INNER_SQUARE_FRACTION,
    graded_spacing,
    ogrid_division,
    ogrid_rings,
    require_positive,
)
from warptissue.mesh.core import (
    TET4_EDGES,
    TetMesh,
    boundary_faces,
    signed_volumes,
    to_tet10,
    unique_sorted_rows,
)
from warptissue.mesh.size import estimate_indentation_mesh, size_near_for_force_accuracy
from warptissue.mesh.surface import tetrahedralize_surface

__all__ = [
    "HEX_TO_FIVE_TETS",
    "HEX_TO_SIX_TETS",
    "MESHERS",
    "block_mesh",
    "extrude_triangles",
    "graded_coordinates",
    "hex_to_tets",
    "indentation_block",
    "indentation_disc",
]

MESHERS = ("extruded", "delaunay")
"""How :func:`indentation_block` and :func:`indentation_disc` fill the specimen."""

# Hexahedron corners: 0 (0,0,0), 1 (1,0,0), 2 (1,1,0), 3 (0,1,0), 4 (0,0,1), 5 (1,0,1),
# 6 (1,1,1), 7 (0,1,1).
HEX_TO_SIX_TETS: np.ndarray = np.array(
    [[0, 1, 2, 6], [0, 2, 3, 6], [0, 3, 7, 6], [0, 7, 4, 6], [0, 4, 5, 6], [0, 5, 1, 6]],
    dtype=np.int32,
)
"""Kuhn split along the 0-6 diagonal: conforming when every cell is split the same way."""

HEX_TO_FIVE_TETS: np.ndarray = np.array(
    [
        [[1, 3, 4, 6], [0, 1, 3, 4], [2, 3, 1, 6], [5, 4, 6, 1], [7, 6, 4, 3]],
        [[0, 2, 5, 7], [1, 0, 2, 5], [3, 2, 0, 7], [4, 5, 7, 0], [6, 7, 5, 2]],
    ],
    dtype=np.int32,
)
"""Five-tet splits (Tong et al.): a central tet and four corners. Cells alternate between the
two mirror splits by the parity of i + j + k, which makes neighbouring face diagonals match."""


def graded_coordinates(length_m: float, count: int, *, ratio: float = 1.0) -> np.ndarray:
    """Coordinates from 0 to ``length_m`` in ``count`` intervals, graded geometrically.

    Args:
        length_m: Total length, metres.
        count: Number of intervals (>= 1).
        ratio: Size of the last interval over the first. 1 is uniform; < 1 refines toward
            ``length_m``, > 1 toward 0.

    Returns:
        Increasing coordinates, shape (count + 1,), float64.
    """
    if count < 1:
        raise MeshError(f"need at least one interval, got count={count}")
    if not length_m > 0:
        raise MeshError(f"length must be positive, got {length_m} m")
    if not ratio > 0:
        raise MeshError(f"grading ratio must be positive, got {ratio}")
    if count == 1 or ratio == 1.0:
        sizes = np.ones(count)
    else:
        sizes = ratio ** (np.arange(count) / (count - 1))
    return np.concatenate([[0.0], np.cumsum(sizes) / sizes.sum() * length_m])


def block_mesh(
    x_m: np.ndarray,
    y_m: np.ndarray,
    z_m: np.ndarray,
    *,
    split: str = "six",
) -> TetMesh:
    """A box meshed with hexahedral cells split into tetrahedra.

    Node sets ``xmin``, ``xmax``, ``ymin``, ``ymax``, ``zmin``, ``zmax`` hold the nodes on each
    face of the box, and face sets of the same names hold the boundary triangles there.
    ``tet_regions`` holds the index of the hexahedral cell each tet came from
    (i + nx * (j + ny * k)), so that per-cell parameters (Tong et al.) can be grouped.

    Args:
        x_m: Increasing x coordinates of the grid planes, shape (nx + 1,), metres.
        y_m: Increasing y coordinates, shape (ny + 1,).
        z_m: Increasing z coordinates, shape (nz + 1,).
        split: ``"six"`` (Kuhn) or ``"five"`` (Tong et al., alternating).

    Returns:
        A positively oriented TET4 mesh.
    """
    axes = [np.asarray(a, dtype=np.float64) for a in (x_m, y_m, z_m)]
    for name, a in zip("xyz", axes, strict=True):
        if a.ndim != 1 or len(a) < 2 or np.any(np.diff(a) <= 0):
            raise MeshError(
                f"{name}_m must be at least two strictly increasing coordinates, got {a}"
            )
    if split not in ("five", "six"):
        raise MeshError(f"split must be 'five' or 'six', got {split!r}")
    nx, ny, nz = (len(a) - 1 for a in axes)
    gx, gy, gz = np.meshgrid(*axes, indexing="ij")
    points = np.column_stack([gx.ravel(order="F"), gy.ravel(order="F"), gz.ravel(order="F")])

    def node(i: np.ndarray, j: np.ndarray, k: np.ndarray) -> np.ndarray:
        return i + (nx + 1) * (j + (ny + 1) * k)

    ci, cj, ck = (
        c.ravel(order="F")
        for c in np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij")
    )
    offsets = np.array(
        [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]]
    )
    hexes = np.stack([node(ci + o[0], cj + o[1], ck + o[2]) for o in offsets], axis=1)
    tets = _split_hexes(points, hexes, split=split, parity=(ci + cj + ck) % 2)
    regions = np.repeat(np.arange(len(hexes), dtype=np.int32), 5 if split == "five" else 6)

    node_sets, face_sets = {}, {}
    faces = boundary_faces(tets)
    for axis, label in enumerate("xyz"):
        for side, value in (("min", axes[axis][0]), ("max", axes[axis][-1])):
            on_plane = np.isclose(
                points[:, axis], value, rtol=0.0, atol=1e-12 * max(1.0, abs(value))
            )
            node_sets[f"{label}{side}"] = np.flatnonzero(on_plane).astype(np.int32)
            face_sets[f"{label}{side}"] = faces[on_plane[faces].all(axis=1)]
    return TetMesh(
        points=points, tets=tets, node_sets=node_sets, face_sets=face_sets, tet_regions=regions
    )


def hex_to_tets(
    points_m: np.ndarray,
    hexes: np.ndarray,
    *,
    split: str = "six",
    parity: np.ndarray | None = None,
) -> TetMesh:
    """Split an unstructured hexahedral mesh into tets with the tables of :func:`block_mesh`.

    Corner order is VTK's: 0-3 counter-clockwise on one face, 4-7 above them. The split is
    conforming when neighbouring hexes number their shared face compatibly (as structured and
    block-structured meshes do); this is checked, and a mismatch raises an error rather than
    returning a mesh with cracks.

    Args:
        points_m: Node coordinates, shape (N, 3), metres.
        hexes: Corner connectivity, shape (H, 8), int.
        split: ``"six"`` (:data:`HEX_TO_SIX_TETS`) or ``"five"``
            (:data:`HEX_TO_FIVE_TETS`, alternating between the two mirror splits).
        parity: For ``"five"``: which of the two splits each hex uses, shape (H,), 0 or 1.
            Neighbours across a face need different parities. None 2-colours the face
            adjacency graph by breadth-first search.

    Returns:
        A positively oriented TET4 mesh with ``tet_regions`` = source hex index and node and
        face set ``"boundary"``.

    Raises:
        MeshError: Bad shapes, a hex mesh whose face graph cannot be 2-coloured (``"five"``),
            or a split whose face diagonals do not match across hexes (non-conforming).
    """
    points = np.asarray(points_m, dtype=np.float64)
    cells = np.asarray(hexes, dtype=np.int64)
    if cells.ndim != 2 or cells.shape[1] != 8 or len(cells) == 0:
        raise MeshError(f"hexes must have shape (H >= 1, 8), got {cells.shape}")
    if split not in ("five", "six"):
        raise MeshError(f"split must be 'five' or 'six', got {split!r}")
    quads = cells[:, _HEX_FACES].reshape(-1, 4)
    _, quad_inverse, quad_counts = unique_sorted_rows(quads, return_counts=True)
    if quad_counts.max() > 2:
        raise MeshError("a hex face is shared by more than two hexes (non-manifold mesh)")
    if split == "five" and parity is None:
        parity = _two_colouring(quad_inverse.reshape(-1, 6), quad_counts)
    tets = _split_hexes(points, cells, split=split, parity=parity)
    per_hex = 5 if split == "five" else 6
    faces = boundary_faces(tets)
    boundary_quads = int((quad_counts == 1).sum())
    if len(faces) != 2 * boundary_quads:
        raise MeshError(
            f"the {split}-tet split is not conforming: {len(faces)} boundary triangles where "
            f"{2 * boundary_quads} were expected (neighbouring hexes cut a shared face along "
            "different diagonals); renumber the hexes consistently or use the other split"
        )
    return TetMesh(
        points=points,
        tets=tets,
        node_sets={"boundary": np.unique(faces).astype(np.int32)},
        face_sets={"boundary": faces},
        tet_regions=np.repeat(np.arange(len(cells), dtype=np.int32), per_hex),
    )


_HEX_FACES = np.array(
    [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]
)
"""The six quadrilateral faces of a VTK-ordered hexahedron."""


def _split_hexes(
    points: np.ndarray, hexes: np.ndarray, *, split: str, parity: np.ndarray | None
) -> np.ndarray:
    """Apply the five- or six-tet table to each hex; orient every tet positively."""
    if split == "six":
        tets = hexes[:, HEX_TO_SIX_TETS].reshape(-1, 4)
    else:
        parity = np.asarray(parity, dtype=np.int64)
        if parity.shape != (len(hexes),) or not np.all((parity == 0) | (parity == 1)):
            raise MeshError(f"parity must be 0 or 1 per hex, shape ({len(hexes)},)")
        tets = np.take_along_axis(
            hexes[:, None, :], HEX_TO_FIVE_TETS[parity].reshape(len(hexes), 1, 20), axis=2
        ).reshape(-1, 4)
    tets = tets.astype(np.int32)
    negative = signed_volumes(points, tets) < 0
    tets[negative, 1], tets[negative, 2] = tets[negative, 2].copy(), tets[negative, 1].copy()
    return tets


def _two_colouring(hex_faces: np.ndarray, face_counts: np.ndarray) -> np.ndarray:
    """Parity 0/1 per hex such that hexes sharing a face differ, by breadth-first search."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import breadth_first_order, connected_components

    hex_count = len(hex_faces)
    owner = np.repeat(np.arange(hex_count), 6)
    face_id = hex_faces.ravel()
    shared = face_counts[face_id] == 2
    order = np.argsort(face_id[shared], kind="stable")
    pairs = owner[shared][order].reshape(-1, 2)
    graph = coo_matrix(
        (np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(hex_count, hex_count)
    ).tocsr()
    _, component = connected_components(graph, directed=False)
    parity = np.full(hex_count, -1, dtype=np.int64)
    for root in np.unique(component, return_index=True)[1]:
        visit, predecessor = breadth_first_order(graph, root, directed=False)
        parity[root] = 0
        for node in visit[1:]:
            parity[node] = 1 - parity[predecessor[node]]
    if np.any(parity[pairs[:, 0]] == parity[pairs[:, 1]]):
        raise MeshError(
            "the five-tet split needs neighbouring hexes in alternating parity, but this hex "
            "mesh's face graph has an odd cycle; use split='six'"
        )
    return parity


def extrude_triangles(
    points_2d_m: np.ndarray, triangles: np.ndarray, z_m: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Extrude a planar triangulation through layers and split each prism into three tets.

    Every vertical quadrilateral face is cut by the diagonal through its node of smallest
    global index, so neighbouring prisms always agree and the mesh is conforming for any
    triangulation and node numbering.

    Args:
        points_2d_m: Planar nodes, shape (P, 2), metres.
        triangles: Triangles (either orientation), shape (T, 3), int.
        z_m: Increasing layer heights, shape (L + 1,), metres.

    Returns:
        ``(points (P * (L + 1), 3), tets (3 * T * L, 4))``: node ``p`` of layer ``k`` has index
        ``p + P * k``; tets are positively oriented and ordered layer by layer.
    """
    points_2d_m = np.asarray(points_2d_m, dtype=np.float64)
    z_m = np.asarray(z_m, dtype=np.float64)
    plane_count, layer_count = len(points_2d_m), len(z_m) - 1
    if z_m.ndim != 1 or layer_count < 1 or np.any(np.diff(z_m) <= 0):
        raise MeshError(f"z_m must be at least two strictly increasing heights, got {z_m}")
    triangles = np.asarray(triangles)
    if triangles.ndim != 2 or triangles.shape[1] != 3 or triangles.size == 0:
        raise MeshError(f"triangles must have shape (T >= 1, 3), got {triangles.shape}")
    if triangles.min() < 0 or triangles.max() >= plane_count:
        raise MeshError(f"triangles index nodes outside [0, {plane_count})")
    a, b, c = np.sort(np.asarray(triangles, dtype=np.int64), axis=1).T
    prism = np.stack(
        [
            [a, b, c, c + plane_count],
            [a, b, c + plane_count, b + plane_count],
            [a, b + plane_count, c + plane_count, a + plane_count],
        ],
        axis=1,
    ).transpose(2, 1, 0)  # (T, 3, 4)
    points = np.column_stack(
        [np.tile(points_2d_m, (layer_count + 1, 1)), np.repeat(z_m, plane_count)]
    )
    # Orientation depends only on the triangle and the pattern, not on the layer: fix it on the
    # first layer, then stack the layers.
    prism = prism.reshape(-1, 4)
    negative = signed_volumes(points, prism) < 0
    prism[negative, 1], prism[negative, 2] = prism[negative, 2].copy(), prism[negative, 1].copy()
    layers = plane_count * np.arange(layer_count, dtype=np.int64)
    tets = (prism[None, :, :] + layers[:, None, None]).reshape(-1, 4).astype(np.int32)
    return points, tets


def indentation_block(
    *,
    width_m: float,
    thickness_m: float,
    probe_radius_m: float,
    quarter: bool = True,
    element: str = "TET10",
    size_near_m: float | None = None,
    size_far_m: float,
    growth: float = 1.2,
    layer_max_m: float | None = None,
    force_accuracy: float | None = None,
    mesher: str = "extruded",
) -> TetMesh:
    """A square block for indentation, graded toward the probe at its top centre.

    The block spans ``|x|, |y| <= width_m / 2`` (``x, y >= 0`` when ``quarter``) and
    ``0 <= z <= thickness_m``; the probe indents the top face at ``x = y = 0``. In the plane
    the mesh is an O-grid: a square of cells under the probe's centre, mapped rings out to a
    ring of nodes exactly at ``r = probe_radius_m`` (so the punch edge is resolved), then
    radial rays out to the block's sides. Sizes start at ``size_near_m`` under and around the
    probe and grow by ``growth`` per cell outward and downward, up to ``size_far_m``. Layers
    of triangular prisms are split into three tets each (see :func:`extrude_triangles`).

    With ``mesher="delaunay"`` TetGen refills that mesh's boundary surface with quality tets
    (radius-edge ratio <= 1.4, dihedral angles aimed above 12 degrees): the same graded sizes
    on the surface, but near-isotropic tets inside, where the layered mesh has cells stretched
    by the independent grading in the plane and in depth. The probe ring, the sets and the
    outline are kept; the tet count at the same sizes is 20-45 % lower.

    Node and face sets: ``top`` (z = thickness), ``bottom`` (z = 0), ``side`` (the lateral
    outer faces), ``symmetry_x`` (x = 0) and ``symmetry_y`` (y = 0) when ``quarter``, and
    ``probe`` (top nodes, and top faces, with r <= probe radius).

    Args:
        width_m: Edge length of the full square block, metres.
        thickness_m: Height, metres.
        probe_radius_m: Flat-punch radius, metres (< width_m / 2).
        quarter: Mesh the quarter x, y >= 0 (two symmetry planes) instead of the full block.
        element: ``"TET10"`` (straight-sided, mid-edge nodes) or ``"TET4"``.
        size_near_m: Element size under the probe and at its edge, metres (give it or
            ``force_accuracy``).
        size_far_m: Largest element size, far from the probe, metres.
        growth: Size ratio of neighbouring cells along the grading (>= 1).
        layer_max_m: Largest layer thickness in z, metres (default ``size_far_m``). A few
            times ``size_near_m`` bounds the vertical stretch of the cells below the probe.
        mesher: ``"extruded"`` (layers of split prisms) or ``"delaunay"`` (TetGen inside the
            extruded mesh's surface).
        force_accuracy: Instead of ``size_near_m``: the relative force accuracy (0.01 is
            1 %) that the near size is chosen for, the coarsest measured to reach it on the
            flat-punch benchmark (:func:`warptissue.mesh.size_near_for_force_accuracy`;
            TET10 only).

    Returns:
        A positively oriented, conforming mesh. Refine it by scaling both sizes: the tet count
        grows roughly as the inverse cube of the scale.
    """
    require_positive(width_m=width_m, thickness_m=thickness_m)
    return _indentation_specimen(
        outer="square",
        half_extent_m=0.5 * width_m,
        thickness_m=thickness_m,
        probe_radius_m=probe_radius_m,
        quarter=quarter,
        element=element,
        size_near_m=size_near_m,
        size_far_m=size_far_m,
        growth=growth,
        layer_max_m=layer_max_m,
        curved_side=False,
        mesher=mesher,
        force_accuracy=force_accuracy,
    )


def indentation_disc(
    *,
    radius_m: float,
    thickness_m: float,
    probe_radius_m: float,
    quarter: bool = True,
    element: str = "TET10",
    size_near_m: float | None = None,
    size_far_m: float,
    growth: float = 1.2,
    layer_max_m: float | None = None,
    force_accuracy: float | None = None,
    curved_side: bool = False,
    mesher: str = "extruded",
) -> TetMesh:
    """A cylindrical disc specimen for indentation, graded toward the probe at its top centre.

    The disc spans ``r <= radius_m`` (the quarter ``x, y >= 0`` when ``quarter``) and
    ``0 <= z <= thickness_m``. The layout, grading and node/face sets are those of
    :func:`indentation_block`; ``side`` is the cylinder ``r = radius_m``.

    Args:
        radius_m: Specimen radius, metres.
        thickness_m: Height, metres.
        probe_radius_m: Flat-punch radius, metres (< radius_m).
        quarter: Mesh the quarter x, y >= 0 instead of the full disc.
        element: ``"TET10"`` or ``"TET4"``.
        size_near_m: Element size under the probe and at its edge, metres (give it or
            ``force_accuracy``).
        size_far_m: Largest element size, metres.
        growth: Size ratio of neighbouring cells along the grading (>= 1).
        layer_max_m: Largest layer thickness in z, metres (default ``size_far_m``). A few
            times ``size_near_m`` bounds the vertical stretch of the cells below the probe.
        curved_side: For TET10 only: move the mid-edge nodes of the edges on the cylinder onto
            it (curved, isoparametric side faces). By default every TET10 is straight-sided,
            and the side is the inscribed polygonal prism.
        mesher: ``"extruded"`` or ``"delaunay"`` (see :func:`indentation_block`). With
            ``curved_side`` the Delaunay mesh's side nodes also move onto the cylinder.
        force_accuracy: Instead of ``size_near_m``: the relative force accuracy it is chosen
            for (see :func:`indentation_block`).

    Returns:
        A positively oriented, conforming mesh.
    """
    require_positive(radius_m=radius_m, thickness_m=thickness_m)
    return _indentation_specimen(
        outer="circle",
        half_extent_m=radius_m,
        thickness_m=thickness_m,
        probe_radius_m=probe_radius_m,
        quarter=quarter,
        element=element,
        size_near_m=size_near_m,
        size_far_m=size_far_m,
        growth=growth,
        layer_max_m=layer_max_m,
        curved_side=curved_side,
        mesher=mesher,
        force_accuracy=force_accuracy,
    )


def _indentation_specimen(
    *,
    outer: str,
    half_extent_m: float,
    thickness_m: float,
    probe_radius_m: float,
    quarter: bool,
    element: str,
    size_near_m: float | None,
    size_far_m: float,
    growth: float,
    layer_max_m: float | None,
    curved_side: bool,
    mesher: str,
    force_accuracy: float | None = None,
) -> TetMesh:
    """Shared body of the block and disc generators (``outer`` is "square" or "circle")."""
    size_near_m = _checked_near_size(
        size_near_m=size_near_m,
        force_accuracy=force_accuracy,
        half_extent_m=half_extent_m,
        probe_radius_m=probe_radius_m,
        size_far_m=size_far_m,
        growth=growth,
        element=element,
        mesher=mesher,
    )
    estimate_indentation_mesh(
        shape="disc" if outer == "circle" else "block",
        half_extent_m=half_extent_m,
        thickness_m=thickness_m,
        probe_radius_m=probe_radius_m,
        quarter=quarter,
        element=element,
        size_near_m=size_near_m,
        size_far_m=size_far_m,
        growth=growth,
        layer_max_m=layer_max_m,
    ).require_fits()
    points_2d, triangles = _ogrid_quarter(
        outer=outer,
        half_extent_m=half_extent_m,
        probe_radius_m=probe_radius_m,
        size_near_m=size_near_m,
        size_far_m=size_far_m,
        growth=growth,
    )
    if not quarter:
        points_2d, triangles = _mirror_quarter(points_2d, triangles)
    layer_max_m = size_far_m if layer_max_m is None else layer_max_m
    require_positive(layer_max_m=layer_max_m)
    depth = graded_spacing(thickness_m, size_near_m, max(layer_max_m, size_near_m), growth=growth)
    z = thickness_m - depth[::-1]
    z[0] = 0.0
    points, tets = extrude_triangles(points_2d, triangles, z)
    node_sets, face_sets = _extruded_sets(
        points_2d,
        tets,
        layer_count=len(z) - 1,
        outer=outer,
        half_extent_m=half_extent_m,
        probe_radius_m=probe_radius_m,
        quarter=quarter,
    )
    mesh = TetMesh(points=points, tets=tets, node_sets=node_sets, face_sets=face_sets)
    if mesher == "delaunay":
        mesh = _delaunay_refill(mesh)
        if curved_side and outer == "circle":
            # TetGen's Steiner points on the side lie on its flat facets: onto the cylinder.
            _project_to_cylinder(mesh, mesh.node_sets["side"], half_extent_m)
    side = np.zeros(mesh.node_count, dtype=bool)
    side[mesh.node_sets["side"]] = True
    if element == "TET4":
        return mesh
    mesh = to_tet10(mesh)
    if curved_side and outer == "circle":
        _project_midnodes_to_cylinder(mesh, side, half_extent_m)
    return mesh


def _checked_near_size(
    *,
    size_near_m: float | None,
    force_accuracy: float | None,
    half_extent_m: float,
    probe_radius_m: float,
    size_far_m: float,
    growth: float,
    element: str,
    mesher: str,
) -> float:
    """The specimen generator's sizes and choices checked, and its near size, m: the one
    given, or the one of ``force_accuracy`` (:func:`size_near_for_force_accuracy`)."""
    if (size_near_m is None) == (force_accuracy is None):
        raise InputError(
            "give either size_near_m or force_accuracy"
            + (", not both" if force_accuracy is not None else ""),
            key="force_accuracy" if force_accuracy is not None else "size_near_m",
            value=force_accuracy,
        )
    if force_accuracy is not None:
        size_near_m = size_near_for_force_accuracy(
            force_accuracy, probe_radius_m=probe_radius_m, mesher=mesher, element=element
        )
    require_positive(probe_radius_m=probe_radius_m, size_near_m=size_near_m, size_far_m=size_far_m)
    if element not in ("TET4", "TET10"):
        raise InputError("element must be 'TET4' or 'TET10'", key="element", value=element)
    if mesher not in MESHERS:
        raise InputError(f"mesher must be one of {MESHERS}", key="mesher", value=mesher)
    if probe_radius_m >= half_extent_m:
        raise InputError(
            f"probe_radius_m must be smaller than the specimen's half-width ({half_extent_m} m)",
            key="probe_radius_m",
            value=probe_radius_m,
        )
    if size_far_m < size_near_m:
        raise InputError(
            f"size_far_m must not be smaller than size_near_m ({size_near_m} m)",
            key="size_far_m",
            value=size_far_m,
        )
    if not (np.isfinite(growth) and growth >= 1.0):
        raise InputError("growth must be a finite number >= 1", key="growth", value=growth)
    return size_near_m


def _extruded_sets(
    points_2d: np.ndarray,
    tets: np.ndarray,
    *,
    layer_count: int,
    outer: str,
    half_extent_m: float,
    probe_radius_m: float,
    quarter: bool,
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """The node and face sets of a specimen extruded from ``points_2d`` (its plane's points,
    (P, 2), m) in ``layer_count`` layers, bottom plane first: top, bottom, side, probe, and
    on a quarter the symmetry planes."""
    plane_count = len(points_2d)
    point_count = plane_count * (layer_count + 1)
    radius_2d = np.hypot(points_2d[:, 0], points_2d[:, 1])
    tolerance = 1e-9 * half_extent_m
    on_top = np.zeros(point_count, dtype=bool)
    on_top[plane_count * layer_count :] = True
    on_bottom = np.zeros(point_count, dtype=bool)
    on_bottom[:plane_count] = True
    in_plane = {
        "symmetry_x": points_2d[:, 0] == 0.0,
        "symmetry_y": points_2d[:, 1] == 0.0,
        "probe_disc": radius_2d <= probe_radius_m + tolerance,
    }
    if outer == "circle":
        side_planes = [np.abs(radius_2d - half_extent_m) <= tolerance]
    else:
        side_planes = [
            np.abs(np.abs(points_2d[:, axis]) - half_extent_m) <= tolerance for axis in (0, 1)
        ]
    columns = {name: np.tile(mask, layer_count + 1) for name, mask in in_plane.items()}
    side_columns = [np.tile(mask, layer_count + 1) for mask in side_planes]
    masks = {
        "top": on_top,
        "bottom": on_bottom,
        "side": np.logical_or.reduce(side_columns),
        "probe": on_top & columns["probe_disc"],
    }
    if quarter:
        masks["symmetry_x"] = columns["symmetry_x"]
        masks["symmetry_y"] = columns["symmetry_y"]
    faces = boundary_faces(tets)
    face_sets = {name: faces[mask[faces].all(axis=1)] for name, mask in masks.items()}
    face_sets["side"] = np.concatenate([faces[m[faces].all(axis=1)] for m in side_columns])
    node_sets = {name: np.flatnonzero(mask).astype(np.int32) for name, mask in masks.items()}
    return node_sets, face_sets


_DELAUNAY_RADIUS_EDGE_RATIO = 1.4
_DELAUNAY_MIN_DIHEDRAL_DEG = 12.0


def _delaunay_refill(extruded: TetMesh) -> TetMesh:
    """TetGen quality tets inside the boundary surface of an extruded specimen, with its
    named face and node sets carried over (``top`` holds the ``probe`` faces too)."""

    faces = boundary_faces(extruded.tets)
    keys = {tuple(face): index for index, face in enumerate(np.sort(faces, axis=1))}
    groups = {}
    for name in ("probe", "top", "bottom", "side", "symmetry_x", "symmetry_y"):
        if name not in extruded.face_sets:
            continue
        indices = np.array([keys[tuple(f)] for f in np.sort(extruded.face_sets[name], axis=1)])
        groups[name] = indices if name != "top" else np.setdiff1d(indices, groups["probe"])
    used, surface_triangles = np.unique(faces, return_inverse=True)
    mesh = tetrahedralize_surface(
        extruded.points[used],
        surface_triangles.reshape(-1, 3),
        quality=_DELAUNAY_RADIUS_EDGE_RATIO,
        min_dihedral_deg=_DELAUNAY_MIN_DIHEDRAL_DEG,
        surface_sets=groups,
    )
    mesh.face_sets["top"] = np.concatenate([mesh.face_sets["top"], mesh.face_sets["probe"]])
    mesh.node_sets["top"] = np.unique(mesh.face_sets["top"]).astype(np.int32)
    del mesh.face_sets["surface"], mesh.node_sets["surface"]
    return mesh


def _project_to_cylinder(mesh: TetMesh, nodes: np.ndarray, radius_m: float) -> None:
    """Move ``nodes`` radially (in x, y) onto the cylinder r = radius."""
    xy = mesh.points[nodes, :2]
    mesh.points[nodes, :2] = xy * (radius_m / np.hypot(xy[:, 0], xy[:, 1]))[:, None]


def _ogrid_quarter(
    *,
    outer: str,
    half_extent_m: float,
    probe_radius_m: float,
    size_near_m: float,
    size_far_m: float,
    growth: float,
) -> tuple[np.ndarray, np.ndarray]:
    """The planar O-grid of the quarter x, y >= 0, split into triangles.

    Returns:
        ``(points (P, 2), triangles (T, 3))`` with counter-clockwise triangles. Nodes on the
        axes have a coordinate of exactly 0; the ring nodes at the probe radius and the outer
        boundary nodes lie on their curves to rounding.
    """
    a = probe_radius_m
    n = ogrid_division(probe_radius_m, size_near_m)
    c = INNER_SQUARE_FRACTION * a
    step = np.arange(n + 1) / n
    # The central square: (n + 1)^2 nodes, (i, j) -> i + (n + 1) j.
    square = np.column_stack([np.tile(c * step, n + 1), np.repeat(c * step, n + 1)])
    square_index = np.arange((n + 1) ** 2).reshape(n + 1, n + 1).T  # [i, j]
    # Its outer boundary in angular order: up the side x = c, then left along y = c.
    t = np.arange(2 * n + 1)
    boundary_i = np.where(t <= n, n, 2 * n - t)
    boundary_j = np.where(t <= n, t, n)
    boundary_index = square_index[boundary_i, boundary_j]
    angle = t * (0.25 * np.pi / n)
    direction = np.column_stack([np.cos(angle), np.sin(angle)])
    direction[-1] = (0.0, 1.0)
    # Rings from the square to the probe edge (uniform), then out to the outer boundary.
    inner_count, outer_fraction = ogrid_rings(
        half_extent_m, probe_radius_m, size_near_m, size_far_m, growth=growth
    )
    if outer == "circle":
        reach = np.full(len(t), half_extent_m)
    else:
        reach = half_extent_m / np.maximum(np.abs(direction[:, 0]), np.abs(direction[:, 1]))
    inner_fraction = np.arange(1, inner_count + 1) / inner_count
    start = square[boundary_index]
    arc = a * direction
    inner_rings = start[None] + inner_fraction[:, None, None] * (arc - start)[None]
    radius = a + outer_fraction[:, None] * (reach - a)[None, :]
    outer_rings = radius[:, :, None] * direction[None]
    rings = np.concatenate([inner_rings, outer_rings])  # (ring_count, 2n + 1, 2)
    rings[:, 0, 1] = 0.0
    rings[:, -1, 0] = 0.0
    if outer == "square":
        on_x_side = direction[:, 0] >= direction[:, 1]
        rings[-1, on_x_side, 0] = half_extent_m
        rings[-1, ~on_x_side, 1] = half_extent_m
    ring_count = len(rings)
    ring_index = len(square) + np.arange(ring_count * len(t)).reshape(ring_count, len(t))
    ring_index = np.vstack([boundary_index[None], ring_index])  # [k, t], k = 0 is the square
    points = np.vstack([square, rings.reshape(-1, 2)])

    quads = np.vstack([_grid_quads(square_index), _grid_quads(ring_index)])
    return points, _split_quads(points, quads)


def _grid_quads(node_index: np.ndarray) -> np.ndarray:
    """The cells of a structured grid of nodes as quadrilaterals.

    Args:
        node_index: Node numbers of the grid, shape (I + 1, J + 1), int.

    Returns:
        Cell (i, j) as ``[node (i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1)]``, row-major
        in (i, j), shape (I * J, 4).
    """
    return np.stack(
        [node_index[:-1, :-1], node_index[1:, :-1], node_index[1:, 1:], node_index[:-1, 1:]],
        axis=-1,
    ).reshape(-1, 4)


def _split_quads(points_2d: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """Split counter-clockwise convex quads along their shorter diagonal into two triangles."""
    p = points_2d[quads]
    diagonal_02 = np.linalg.norm(p[:, 2] - p[:, 0], axis=1)
    diagonal_13 = np.linalg.norm(p[:, 3] - p[:, 1], axis=1)
    use_02 = (diagonal_02 <= diagonal_13)[:, None]
    first = np.where(use_02, quads[:, [0, 1, 2]], quads[:, [0, 1, 3]])
    second = np.where(use_02, quads[:, [0, 2, 3]], quads[:, [1, 2, 3]])
    return np.vstack([first, second]).astype(np.int64)


def _mirror_quarter(points_2d: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Reflect a quarter (x, y >= 0) triangulation into the full plane, merging axis nodes."""
    signs = np.array([[1.0, 1.0], [-1.0, 1.0], [-1.0, -1.0], [1.0, -1.0]])
    copies = (points_2d[None] * signs[:, None]) + 0.0  # + 0.0 turns -0.0 into 0.0
    merged, inverse = np.unique(copies.reshape(-1, 2), axis=0, return_inverse=True)
    inverse = inverse.reshape(4, -1)
    full = np.vstack([inverse[q][triangles] for q in range(4)])
    return merged, full


def _project_midnodes_to_cylinder(mesh: TetMesh, side: np.ndarray, radius_m: float) -> None:
    """Move mid-edge nodes of edges with both corners on the cylinder r = radius onto it."""
    corners = mesh.tets[:, TET4_EDGES.ravel()].reshape(-1, 6, 2)
    on_side = side[corners].all(axis=2)
    _project_to_cylinder(mesh, np.unique(mesh.tets[:, 4:][on_side]), radius_m)
