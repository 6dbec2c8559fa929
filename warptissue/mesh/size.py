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

:func:`size_near_for_force_accuracy` chooses the near size itself: the coarsest near-probe
element size whose flat-punch force was measured within a stated relative accuracy
(:data:`FLAT_PUNCH_FORCE_ERRORS`, the study key ``specimen.force_accuracy``).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from warptissue.device import available_host_memory_bytes
from warptissue.errors import InputError, MeshError
from warptissue.mesh._grading import graded_spacing, ogrid_division, ogrid_rings, require_positive

__all__ = [
    "FLAT_PUNCH_FORCE_ERRORS",
    "FORCE_ACCURACY_DEPTH_RATIO",
    "FORCE_ACCURACY_FLOOR",
    "GENERATOR_BYTES_PER_TET",
    "MAX_INDEX",
    "SOLVE_BYTES_EXPONENT",
    "SOLVE_BYTES_REFERENCE",
    "MeshSizeEstimate",
    "NearSizeChoice",
    "estimate_indentation_mesh",
    "force_accuracy_depth_warning",
    "near_size_choice",
    "size_near_for_force_accuracy",
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
    if shape not in ("block", "disc"):
        raise InputError("shape must be 'block' or 'disc'", key="shape", value=shape)
    if element not in ("TET4", "TET10"):
        raise InputError("element must be 'TET4' or 'TET10'", key="element", value=element)
    layer_max_m = size_far_m if layer_max_m is None else layer_max_m
    require_positive(
        half_extent_m=half_extent_m,
        thickness_m=thickness_m,
        probe_radius_m=probe_radius_m,
        size_near_m=size_near_m,
        size_far_m=size_far_m,
        layer_max_m=layer_max_m,
    )
    layer_size_m = max(layer_max_m, size_near_m)
    n = ogrid_division(probe_radius_m, size_near_m)
    # A lower bound first (the layers are at most layer_size_m thick, the outer rings at
    # most size_far_m wide): where even that is beyond 32-bit indices, counting exactly
    # could take as long as generating.
    layers_low = max(1.0, np.floor(thickness_m / layer_size_m))
    rings_low = max(1.0, np.floor(max(half_extent_m - probe_radius_m, 0.0) / size_far_m))
    triangles_low = 2.0 * (n * n + 2 * n * rings_low) * (1 if quarter else 4)
    lower = _estimate(3.0 * triangles_low * layers_low, triangles_low, layers_low, element)
    if max(lower.tet_count, lower.node_count) > MAX_INDEX:
        return lower
    inner_count, outer_fraction = ogrid_rings(
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


FLAT_PUNCH_FORCE_ERRORS: dict[str, tuple[tuple[float, float], ...]] = {
    "extruded": (
        (1.0, 0.0081),
        (0.7, 0.0076),
        (0.5, 0.0136),
        (0.35, 0.0124),
        (0.25, 0.0108),
        (0.18, 0.0074),
        (0.125, 0.0057),
    ),
    "delaunay": (
        (1.0, 0.0022),
        (0.7, 0.0050),
        (0.5, 0.0041),
        (0.35, 0.0014),
        (0.25, 0.0006),
        (0.18, 0.0051),
        (0.125, 0.0036),
    ),
}
"""Measured force errors of the flat-punch benchmark against the near-probe element size, by
mesher: ``(size_near_m / probe radius, |F / F_ref - 1|)`` from coarse to fine.

The benchmark (docs/performance.md, "The flat-punch benchmark"): a quarter of a 20 x 20 x
10 mm block on a fixed base, a bonded flat punch of radius a = 1 mm pressed to a / 2 in 20
load steps, neo-Hookean tissue with K / mu = 1000, TET10 mixed elements, Newton tolerance
1e-8; the far size fixed at a study's default for that block, min(thickness, half width) / 4
= 2.5 a; F_ref = 2.460 mN, the Richardson extrapolation of FElupe's hexahedral runs.
Measured on the 2-core CPU on 2026-11-27 with ``bench_flat_punch.py --sizes ""
--size-near-ratios 1,0.7,0.5,0.35,0.25,0.18,0.125 --mesher extruded|delaunay``
(``scripts/results/bench_flat_punch_size_near_{extruded,extruded_fine,delaunay}_2core_cpu.json``;
a test checks the table against those files).

The errors are not monotone in the size: the extruded meshes are 0.8 % off at the probe
radius, 1.4 % at half of it and 0.7 % and 0.6 % at 0.18 and 0.125 of it, and every Delaunay
mesh is within 0.51 %, so :func:`size_near_for_force_accuracy` reads their running maximum
from fine to coarse."""
FORCE_ACCURACY_FLOOR = 0.01
"""The smallest relative force accuracy :func:`size_near_for_force_accuracy` takes: the
reference force itself is uncertain by about 1 % (the axisymmetric FElupe model of the round
counterpart converges to 2.434 mN, 1.1 % below it), so a smaller error cannot be told from
the measurement."""

FORCE_ACCURACY_DEPTH_RATIO = 0.5
"""The deepest depth, over the probe radius, that :data:`FLAT_PUNCH_FORCE_ERRORS` was
measured to (the benchmark presses to half the probe radius): the range of
:func:`size_near_for_force_accuracy`. Deeper, the force of the meshes it chose for
``force_accuracy = 0.01`` was measured further off against converged references (issue 36):
+2.0 % at depth / radius 0.8 and +3.5 % at 1.04 (neo-Hookean), -2.4 % at a 2 mm depth
(reduced polynomial)."""


def force_accuracy_depth_warning(
    accuracy: float, *, depth_m: float, probe_radius_m: float
) -> str | None:
    """The warning for a force accuracy asked of depths beyond its measured range, or None.

    Args:
        accuracy: The relative force accuracy asked for (``specimen.force_accuracy``).
        depth_m: The deepest depth the study asks for (its protocol's and its records'), m.
        probe_radius_m: Probe (punch) radius, m.

    Returns:
        One line naming ``specimen.force_accuracy``, the depth and the measured range where
        ``depth_m`` exceeds :data:`FORCE_ACCURACY_DEPTH_RATIO` probe radii; else None.
    """
    ratio = depth_m / probe_radius_m
    if not ratio > FORCE_ACCURACY_DEPTH_RATIO:
        return None
    limit_m = FORCE_ACCURACY_DEPTH_RATIO * probe_radius_m
    return (
        f"specimen.force_accuracy = {accuracy:g} was measured for depths up to "
        f"{FORCE_ACCURACY_DEPTH_RATIO:g} probe radii ({limit_m:.4g} m); "
        f"the study goes to {depth_m:.4g} m ({ratio:.3g} probe radii), where the chosen "
        "meshes were measured up to 3.5 % off (for 0.01): give a finer specimen.size_near_m "
        "where the force must be that accurate"
    )


@dataclass(frozen=True)
class NearSizeChoice:
    """The near-probe element size chosen for a relative force accuracy, and why.

    Attributes:
        accuracy: The relative force accuracy asked for (0.01 is 1 %).
        size_near_m: The chosen element size under the probe and at its edge, m.
        size_ratio: ``size_near_m`` over the probe radius.
        measured_error: The force error measured at that ratio on the flat-punch benchmark
            (relative), at most ``accuracy``, as are those of all the finer measured sizes.
        mesher: ``"extruded"`` or ``"delaunay"``.
    """

    accuracy: float
    size_near_m: float
    size_ratio: float
    measured_error: float
    mesher: str

    def reason(self) -> str:
        """One sentence: the size, and the measurement it was read from."""
        return (
            f"size_near_m = {self.size_near_m:.4g} m ({self.size_ratio:g} of the probe "
            f"radius) for force_accuracy = {self.accuracy:g}: the coarsest near size whose "
            f"flat-punch benchmark force, and that of every finer size measured, was within "
            f"{100 * self.accuracy:g} % of the reference ({self.mesher} TET10 mixed mesh, far "
            f"size 2.5 probe radii, depths up to {FORCE_ACCURACY_DEPTH_RATIO:g} probe radii; "
            f"measured {100 * self.measured_error:.2f} %)"
        )


def near_size_choice(
    accuracy: float,
    *,
    probe_radius_m: float,
    mesher: str = "extruded",
    element: str = "TET10",
    indenter: str = "flat_punch",
) -> NearSizeChoice:
    """The near-probe element size for a relative force accuracy, with the reason for it.

    See :func:`size_near_for_force_accuracy`, which returns only the size.

    Args:
        accuracy: Relative force accuracy (0.01 is 1 %), at least :data:`FORCE_ACCURACY_FLOOR`
            and below 1.
        probe_radius_m: Probe (punch) radius, metres.
        mesher: ``"extruded"`` or ``"delaunay"``.
        element: ``"TET10"`` (the only element measured).
        indenter: ``"flat_punch"`` (the only indenter measured).

    Returns:
        The choice.

    Raises:
        InputError: An accuracy that is not a number in [:data:`FORCE_ACCURACY_FLOOR`, 1)
            (the message names the measured range), a radius that is not positive, or a
            mesher, element or indenter that was not measured.
    """
    if isinstance(accuracy, bool) or not isinstance(accuracy, int | float):
        raise InputError("must be a number", key="force_accuracy", value=accuracy)
    if mesher not in FLAT_PUNCH_FORCE_ERRORS:
        raise InputError(
            f"must be one of {', '.join(map(repr, FLAT_PUNCH_FORCE_ERRORS))}",
            key="mesher",
            value=mesher,
        )
    if element != "TET10":
        raise InputError(
            "force_accuracy was measured for TET10 (mixed) elements only: give size_near_m",
            key="element",
            value=element,
        )
    if indenter != "flat_punch":
        raise InputError(
            "force_accuracy was measured for the sharp bonded flat punch only: give size_near_m",
            key="indenter",
            value=indenter,
        )
    if not (math.isfinite(probe_radius_m) and probe_radius_m > 0):
        raise InputError("must be positive", key="probe_radius_m", value=probe_radius_m)
    ratios, errors = _error_envelope(mesher)
    if not (math.isfinite(accuracy) and FORCE_ACCURACY_FLOOR <= accuracy < 1.0):
        raise InputError(
            f"must lie in [{FORCE_ACCURACY_FLOOR:g}, 1): the force errors measured with the "
            f"{mesher} mesher range from {errors[0]:.3g} to {errors[-1]:.3g}, and the "
            f"reference force is uncertain by about {FORCE_ACCURACY_FLOOR:g}",
            key="force_accuracy",
            value=accuracy,
        )
    within = np.flatnonzero(errors <= accuracy)
    if within.size == 0:  # no measured size was that accurate
        raise InputError(
            f"no measured near size of the {mesher} mesher was that accurate: the force "
            f"errors measured range from {errors[0]:.3g} (size_near_m = {ratios[0]:g} probe "
            f"radii) to {errors[-1]:.3g}; give size_near_m",
            key="force_accuracy",
            value=accuracy,
        )
    index = int(within[-1])
    return NearSizeChoice(
        accuracy=float(accuracy),
        size_near_m=float(ratios[index] * probe_radius_m),
        size_ratio=float(ratios[index]),
        measured_error=float(_measured(mesher)[ratios[index]]),
        mesher=mesher,
    )


def size_near_for_force_accuracy(
    accuracy: float,
    *,
    probe_radius_m: float,
    mesher: str = "extruded",
    element: str = "TET10",
    indenter: str = "flat_punch",
) -> float:
    """The coarsest near-probe element size measured to give a relative force accuracy.

    Read from :data:`FLAT_PUNCH_FORCE_ERRORS` without interpolation: the largest measured
    ratio ``size_near_m / probe_radius_m`` at which the benchmark's force, and the force of
    every finer measured size, was within ``accuracy`` of the reference. (The error of a mesh
    family does not fall monotonically with its size, so the finer sizes count too: the
    relation is the errors' running maximum from fine to coarse, which is monotone.) An
    accuracy above every measured error gives the coarsest size measured, the probe radius
    itself.

    The measurement is the flat-punch benchmark (:data:`FLAT_PUNCH_FORCE_ERRORS`): a block
    10 probe radii thick, the far size 2.5 probe radii, nearly incompressible neo-Hookean
    tissue pressed to half the probe radius. Other geometries, depths and far sizes scale
    it by the probe radius only; a far size coarser than 2.5 probe radii, or a much
    thinner or deeper-indented specimen, is outside what was measured.

    Range: depths up to :data:`FORCE_ACCURACY_DEPTH_RATIO` (0.5) probe radii. Deeper, the
    force of the chosen mesh was measured further off than asked (for 0.01: +2.0 % at depth
    / radius 0.8, +3.5 % at 1.04 for neo-Hookean tissue, -2.4 % at a 2 mm depth for a
    reduced polynomial), and a study that goes deeper is warned at load
    (:func:`force_accuracy_depth_warning`).

    Args:
        accuracy: Relative force accuracy (0.01 is 1 %), at least :data:`FORCE_ACCURACY_FLOOR`
            and below 1.
        probe_radius_m: Probe (punch) radius, metres.
        mesher: ``"extruded"`` or ``"delaunay"`` (see
            :func:`warptissue.mesh.indentation_block`).
        element: ``"TET10"`` (the only element measured, with the mixed formulation).
        indenter: ``"flat_punch"`` (the only indenter measured: sharp and bonded).

    Returns:
        The near size, metres.

    Raises:
        InputError: See :func:`near_size_choice`.
    """
    return near_size_choice(
        accuracy,
        probe_radius_m=probe_radius_m,
        mesher=mesher,
        element=element,
        indenter=indenter,
    ).size_near_m


def _measured(mesher: str) -> dict[float, float]:
    return dict(FLAT_PUNCH_FORCE_ERRORS[mesher])


def _error_envelope(mesher: str) -> tuple[np.ndarray, np.ndarray]:
    """(ratios ascending, the running maximum of the errors from the finest ratio up)."""
    points = sorted(FLAT_PUNCH_FORCE_ERRORS[mesher])
    ratios = np.array([ratio for ratio, _ in points], dtype=np.float64)
    errors = np.maximum.accumulate(np.array([error for _, error in points], dtype=np.float64))
    return ratios, errors
