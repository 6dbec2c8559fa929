"""How large an indentation specimen's mesh will be, before it is generated.

:func:`estimate_indentation_mesh` counts the tets and nodes that
:func:`~warptissue.mesh.indentation_block` and :func:`~warptissue.mesh.indentation_disc` will
make (exactly for the extruded mesher, from the same 1D spacings; the Delaunay mesher makes
20-65 % fewer tets on the same surface, so the extruded count bounds it) and the host memory
they take: the peak of generating, checking and writing the mesh, and that of a CPU
simulation on it (tangent, direct solver's factors, Newton arrays; a law fitted to measured
runs). :meth:`MeshSizeEstimate.require_fits` refuses, with the numbers, a mesh that would not
fit in the memory available, before any of it is allocated: the generators call it
themselves, and a simulation calls it with ``solve=True``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from warptissue.device import available_host_memory_bytes
from warptissue.errors import InputError, MeshError

__all__ = [
    "GENERATOR_BYTES_PER_TET",
    "MAX_INDEX",
    "SOLVE_BYTES_EXPONENT",
    "SOLVE_BYTES_REFERENCE",
    "MeshSizeEstimate",
    "estimate_indentation_mesh",
]

GENERATOR_BYTES_PER_TET = {"TET4": 1500, "TET10": 1800}
"""Peak memory per tet of generating a specimen, checking its quality and writing it, bytes,
by element type. Measured with ``tracemalloc`` on the extruded block (41 472 tets: generate
430 / 510, ``check_mesh`` 1 100 / 1 400, write 200 / 380 bytes per tet for TET4 / TET10);
the Delaunay mesher's TetGen run adds its own, and makes fewer tets."""
MAX_INDEX = 2**31 - 1
"""Most nodes or tets a mesh may have: connectivity is stored as int32."""
SOLVE_BYTES_REFERENCE = (34_689, 1225 * 2**20)
"""(nodes, bytes): host memory of a whole CPU simulation of a TET10 block beyond the
interpreter's own, as measured (peak RSS 1 475 MiB less about 250 MiB, docs/performance.md,
the meshers' table: 23 760 tets, 104 067 DOFs, PARDISO)."""
SOLVE_BYTES_EXPONENT = 1.26
"""Growth of a simulation's memory with the node count: the direct solver's factors fill in
faster than the mesh grows. Fitted to the extruded TET10 runs of 12 915, 44 325 and 104 067
DOFs (89, 437 and 1 225 MiB, within 3 %); the Delaunay meshes of the same DOFs took 25-35 %
less, and a TET4 mesh has fewer neighbours per node, so the law bounds them."""


@dataclass(frozen=True)
class MeshSizeEstimate:
    """The size of a mesh that is about to be made, and the memory it takes.

    Attributes:
        tet_count: Tets.
        node_count: Nodes (corner and, for TET10, mid-edge nodes).
        element: ``"TET4"`` or ``"TET10"``.
        mesh_bytes: Peak memory while the mesh is generated, checked and written, bytes.
        solve_bytes: Host memory of a simulation on the mesh with a CPU direct solver
            (tangent, factors, Newton arrays), bytes. On a GPU the factors live in device
            memory, where cuDSS's own estimates are checked before the first factorization.
    """

    tet_count: int
    node_count: int
    element: str
    mesh_bytes: int
    solve_bytes: int

    def to_dict(self) -> dict[str, int | str]:
        """The attributes as a dict (for ``--json`` outputs)."""
        return asdict(self)

    def require_fits(
        self, *, solve: bool = False, available_bytes: int | None = None, what: str = "mesh"
    ) -> None:
        """Refuse a mesh that would not fit in memory.

        Args:
            solve: Count a CPU simulation on the mesh too (``warptissue simulate`` on the
                CPU), not only its generation.
            available_bytes: Memory available, bytes (default: the host's available memory,
                :func:`warptissue.device.available_host_memory_bytes`).
            what: What the mesh is, for the message (``"mesh"``, ``"study's mesh"``).

        Raises:
            MeshError: The estimate exceeds the memory available, or the counts exceed
                :data:`MAX_INDEX`; the message gives the tet and node counts, the GiB needed
                and available, and how to coarsen.
        """
        if max(self.tet_count, self.node_count) > MAX_INDEX:
            raise MeshError(
                f"the {what} would have about {self.tet_count:.3g} {self.element} tets and "
                f"{self.node_count:.3g} nodes, beyond the 32-bit indices of a mesh "
                f"({MAX_INDEX:,}): use a larger size_near_m/size_far_m"
            )
        available = available_host_memory_bytes() if available_bytes is None else available_bytes
        needed = max(self.mesh_bytes, self.solve_bytes) if solve else self.mesh_bytes
        if needed <= available:
            return
        task = "to generate and solve (CPU direct solver)" if solve else "to generate"
        raise MeshError(
            f"the {what} would have about {self.tet_count:,} {self.element} tets and "
            f"{self.node_count:,} nodes and need about {_gib(needed)} of memory {task}; "
            f"{_gib(available)} is available: use a larger size_near_m/size_far_m "
            "(the tet count scales as their inverse cube) or a quarter model"
        )


def _gib(value_bytes: float) -> str:
    return f"{value_bytes / 2**30:.1f} GiB"


def estimate_indentation_mesh(
    *,
    shape: str,
    half_extent_m: float,
    thickness_m: float,
    probe_radius_m: float,
    quarter: bool = True,
    element: str = "TET10",
    size_near_m: float,
    size_far_m: float,
    growth: float = 1.2,
    layer_max_m: float | None = None,
) -> MeshSizeEstimate:
    """Count the tets and nodes of an indentation specimen, and its memory, without making it.

    The counts are those of the extruded mesher exactly (see
    :func:`warptissue.mesh.indentation_block`); the Delaunay mesher makes fewer tets on the
    same surface, so they bound its size. Takes the generators' arguments; a size so small
    that even a lower bound of the count is astronomical is counted from that bound, so the
    estimate itself never runs out of time or memory.

    Args:
        shape: ``"block"`` (square in plan) or ``"disc"``.
        half_extent_m: Half the block's width, or the disc's radius, metres.
        thickness_m: Height, metres.
        probe_radius_m: Flat-punch radius, metres.
        quarter: A quarter model (two symmetry planes) instead of the full specimen.
        element: ``"TET4"`` or ``"TET10"``.
        size_near_m: Element size at the probe, metres.
        size_far_m: Largest element size, metres.
        growth: Size ratio of neighbouring cells (>= 1).
        layer_max_m: Largest layer thickness, metres (default ``size_far_m``).

    Returns:
        The estimate.

    Raises:
        InputError: A size that is not positive and finite, or an unknown shape or element.
    """
    from warptissue.mesh.generators import (
        _ogrid_division,
        _ogrid_rings,
        _require_positive,
        graded_spacing,
    )

    if shape not in ("block", "disc"):
        raise InputError("shape must be 'block' or 'disc'", key="shape", value=shape)
    if element not in ("TET4", "TET10"):
        raise InputError("element must be 'TET4' or 'TET10'", key="element", value=element)
    layer_max_m = size_far_m if layer_max_m is None else layer_max_m
    _require_positive(
        half_extent_m=half_extent_m,
        thickness_m=thickness_m,
        probe_radius_m=probe_radius_m,
        size_near_m=size_near_m,
        size_far_m=size_far_m,
        layer_max_m=layer_max_m,
    )
    layer_size_m = max(layer_max_m, size_near_m)
    n = _ogrid_division(probe_radius_m, size_near_m)
    # A lower bound first (the layers are at most layer_size_m thick, the outer rings at
    # most size_far_m wide): where even that is beyond 32-bit indices, counting exactly
    # could take as long as generating.
    layers_low = max(1.0, np.floor(thickness_m / layer_size_m))
    rings_low = max(1.0, np.floor(max(half_extent_m - probe_radius_m, 0.0) / size_far_m))
    triangles_low = 2.0 * (n * n + 2 * n * rings_low) * (1 if quarter else 4)
    lower = _estimate(3.0 * triangles_low * layers_low, triangles_low, layers_low, element)
    if max(lower.tet_count, lower.node_count) > MAX_INDEX:
        return lower
    inner_count, outer_fraction = _ogrid_rings(
        half_extent_m, probe_radius_m, size_near_m, size_far_m, growth=growth
    )
    rings = inner_count + len(outer_fraction)
    # The quarter O-grid: an n x n square, then rings of 2 n cells, two triangles a cell.
    points = (n + 1) ** 2 + rings * (2 * n + 1)
    triangles = 2 * (n * n + rings * 2 * n)
    if not quarter:
        axis_points = n + 1 + rings  # on each half-axis, the origin included
        points = 4 * points - 4 * (axis_points - 1) - 3
        triangles *= 4
    layers = len(graded_spacing(thickness_m, size_near_m, layer_size_m, growth=growth)) - 1
    planar_edges = points + triangles - 1  # Euler's formula for a triangulated disc
    corner_nodes = points * (layers + 1)
    tets = 3 * triangles * layers
    nodes = corner_nodes
    if element == "TET10":  # a node per edge: in-plane, vertical, and the prisms' diagonals
        nodes += planar_edges * (layers + 1) + points * layers + planar_edges * layers
    return _sized(tets, nodes, element)


def _estimate(tets: float, triangles: float, layers: float, element: str) -> MeshSizeEstimate:
    """A lower-bound estimate from counts in floating point (they may exceed any int64)."""
    nodes = 0.5 * triangles * (layers + 1) * (1 if element == "TET4" else 4)
    return _sized(min(tets, 2.0**62), min(nodes, 2.0**62), element)


def _sized(tets: float, nodes: float, element: str) -> MeshSizeEstimate:
    """The estimate of a mesh of ``tets`` tets and ``nodes`` nodes."""
    reference_nodes, reference_bytes = SOLVE_BYTES_REFERENCE
    solve = reference_bytes * (nodes / reference_nodes) ** SOLVE_BYTES_EXPONENT
    return MeshSizeEstimate(
        tet_count=int(tets),
        node_count=int(nodes),
        element=element,
        mesh_bytes=int(min(GENERATOR_BYTES_PER_TET[element] * tets, 2.0**62)),
        solve_bytes=int(min(solve, 2.0**62)),
    )
