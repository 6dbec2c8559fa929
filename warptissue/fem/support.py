"""An elastic foundation under the specimen: linear springs from its supported surface to the
ground (a Winkler bed), for an organ resting on a soft bed instead of held.

A foundation of normal stiffness ``k_n`` and tangential stiffness ``k_t`` per unit area
(Pa/m: a pressure per metre of displacement) puts on the supported surface the traction
``t = -P u``, ``P = k_n n n^T + k_t (I - n n^T)``, ``n`` the surface's normal in the reference
configuration. Its virtual work gives the consistent stiffness, block ``(a, b)`` of the nodes
of each surface triangle (3-node on a TET4 face, 6-node on a TET10 face, curved where the
face is)

    S_ab = integral over the triangle of N_a N_b P dA,

integrated by the 6-point degree-4 rule of Dunavant (1985), exact on a flat triangle. The
residual gains ``S u``, the tangent ``S`` and the energy ``u . S u / 2`` (device code:
``support_spring_kernel`` in ``kernels/contact.py``). The springs are linear: the model is a
bed for small support motions, like the foundations of FEBio and Abaqus (``*FOUNDATION``).
Lumped beds were measured and not kept: the row sums of S give a 6-node triangle's corners
no spring (``integral of N_a dA = 0``), so a bed of 1e12 Pa/m stayed 0.57 % softer than the
fixed base; a positive lumping (A/12 per corner, A/4 per mid-edge node) was 2.3 % off the
analytic column of tests/test_fem_support.py. The consistent matrix holds every node of the
support and meets both to 1e-5.

The probe force of a body on a foundation is the springs' reaction: ``F = d . sum S u`` along
the probe's direction d, which equals the force on the probe at equilibrium (the internal
forces sum to zero). With reaction weights ``w`` on the support
(:meth:`warptissue.fem.IndentationProblem.reaction_weights`) the solver sums
``w . (R - S u)``, the internal and contact forces alone; :mod:`warptissue.fem.newton.path`
and :class:`warptissue.fem.ForceSensitivity` add ``-(S w) . u`` for that.

A sliding support that is not flat on a plane x, y or z = const (a tilted table, a curved
bed) is a frictionless bed (:meth:`SupportSprings.sliding_bed`): the same consistent springs
with ``k_t = 0`` and a stiff ``k_n`` (a penalty on the normal displacement, as the rigid
contact's), plus pin springs at two nodes across the support's mean normal that hold the
rigid motions the bed leaves free (the two slides and the turn about the normal), as the
pins of a flat sliding base do.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import warp as wp

from warptissue.errors import InputError
from warptissue.fem.contact import ContactSurface
from warptissue.fem.packing import per_problem
from warptissue.fem.surface_contact import block_ids
from warptissue.kernels import contact as kc
from warptissue.mesh import TetMesh

__all__ = ["SLIDING_PIN_SHARE", "Foundation", "SupportSprings", "support_edge_m"]

SLIDING_PIN_SHARE = 1.0
"""A pin spring of a sliding bed: its stiffness (N/m) as a share of ``k_n`` times the
support's mean triangle area (the springs of about one node)."""


@dataclass(frozen=True)
class Foundation:
    """An elastic foundation: springs per unit area of the supported surface.

    Args:
        normal_Pa_per_m: Stiffness along the surface's normal, Pa/m (> 0).
        tangential_Pa_per_m: Stiffness across it, Pa/m (> 0: a bed without it leaves the
            body free to slide and turn); None: equal to the normal one.

    Raises:
        InputError: A stiffness that is not a positive finite number.
    """

    normal_Pa_per_m: float
    tangential_Pa_per_m: float | None = None

    def __post_init__(self) -> None:
        if self.tangential_Pa_per_m is None:
            object.__setattr__(self, "tangential_Pa_per_m", self.normal_Pa_per_m)
        for key in ("normal_Pa_per_m", "tangential_Pa_per_m"):
            value = getattr(self, key)
            number = isinstance(value, int | float) and not isinstance(value, bool)
            if not (number and math.isfinite(value) and value > 0):
                raise InputError(
                    "a foundation's stiffness must be a positive number of Pa/m (a bed that "
                    "does not hold tangentially leaves the body free to slide)",
                    key=key,
                    value=value,
                )


# Dunavant's 6-point rule on the reference triangle (xi, eta): points and weights (sum 1/2).
_A, _B = 0.445948490915965, 0.091576213509771
_QUADRATURE_POINTS = np.array(
    [[_A, _A], [1 - 2 * _A, _A], [_A, 1 - 2 * _A], [_B, _B], [1 - 2 * _B, _B], [_B, 1 - 2 * _B]]
)
_QUADRATURE_WEIGHTS = 0.5 * np.array([0.223381589678011] * 3 + [0.109951743655322] * 3)


def _triangle_shapes(xi: float, eta: float, nodes: int) -> tuple[np.ndarray, np.ndarray]:
    """Shape functions (n,) and their derivatives by (xi, eta) (n, 2) of a 3- or 6-node
    triangle (corners, then the mid-edge nodes of the edges (0, 1), (1, 2), (2, 0))."""
    l1, l2, l3 = 1.0 - xi - eta, xi, eta
    dl = np.array([[-1.0, -1.0], [1.0, 0.0], [0.0, 1.0]])
    if nodes == 3:
        return np.array([l1, l2, l3]), dl
    lam = (l1, l2, l3)
    shapes = [each * (2.0 * each - 1.0) for each in lam]
    slopes = [(4.0 * each - 1.0) * dl[a] for a, each in enumerate(lam)]
    for a, b in ((0, 1), (1, 2), (2, 0)):
        shapes.append(4.0 * lam[a] * lam[b])
        slopes.append(4.0 * (lam[a] * dl[b] + lam[b] * dl[a]))
    return np.array(shapes), np.array(slopes)


@dataclass(frozen=True)
class SupportSprings:
    """Springs from some nodes of one problem to the ground: the nonzero blocks of a constant
    symmetric stiffness matrix ``S``.

    Attributes:
        rows: Node i of each block, (m,) int64, in the problem's own numbering.
        columns: Node j of each block, (m,) int64 (both (i, j) and (j, i) are held).
        blocks: ``S_ij``, (m, 3, 3), N/m.
    """

    rows: np.ndarray
    columns: np.ndarray
    blocks: np.ndarray

    @property
    def nodes(self) -> np.ndarray:
        """The sprung nodes, sorted, (k,) int64."""
        return np.unique(self.rows)

    @classmethod
    def foundation(cls, mesh: TetMesh, foundation: Foundation, *, surface: str) -> SupportSprings:
        """The consistent springs of ``foundation`` under node set ``surface`` (its boundary
        triangles; module docstring).

        Raises:
            InputError: No boundary triangle lies on ``surface``.
        """
        tri = ContactSurface.for_mesh(mesh, surface=surface).triangles
        return cls._integrated(
            mesh, tri, foundation.normal_Pa_per_m, foundation.tangential_Pa_per_m
        )

    @classmethod
    def _integrated(cls, mesh: TetMesh, tri: np.ndarray, k_n: float, k_t: float) -> SupportSprings:
        """``S_ab = integral of N_a N_b (k_n n n^T + k_t (I - n n^T)) dA`` over triangles
        ``tri`` (F, 3 or 6)."""
        corners = mesh.points[tri]  # (F, n, 3)
        count = tri.shape[1]
        local = np.zeros((len(tri), count, count, 3, 3))
        for (xi, eta), weight in zip(_QUADRATURE_POINTS, _QUADRATURE_WEIGHTS, strict=True):
            shapes, slopes = _triangle_shapes(xi, eta, count)
            tangents = np.einsum("ak,fai->fki", slopes, corners)
            cross = np.cross(tangents[:, 0], tangents[:, 1])
            jacobian = np.linalg.norm(cross, axis=1)
            normal = cross / jacobian[:, None]
            bed = k_t * np.eye(3) + (k_n - k_t) * np.einsum("fi,fj->fij", normal, normal)
            local += np.einsum("f,ab,fij->fabij", weight * jacobian, np.outer(shapes, shapes), bed)
        return cls(
            rows=np.repeat(tri, count, axis=1).reshape(-1).astype(np.int64),
            columns=np.tile(tri, (1, count)).reshape(-1).astype(np.int64),
            blocks=local.reshape(-1, 3, 3),
        ).merged(mesh.node_count)

    @classmethod
    def sliding_bed(cls, mesh: TetMesh, *, surface: str, normal_Pa_per_m: float) -> SupportSprings:
        """A frictionless bed under node set ``surface``: normal springs of
        ``normal_Pa_per_m`` per unit area (consistent, tangential stiffness 0) and pin
        springs for the rigid motions it leaves free (module docstring).

        Raises:
            InputError: No boundary triangle lies on ``surface``, or a stiffness that is not
                a positive number.
        """
        if not (math.isfinite(normal_Pa_per_m) and normal_Pa_per_m > 0.0):
            raise InputError(
                "the sliding bed's stiffness must be a positive number of Pa/m",
                key="sliding_bed_Pa_per_m",
                value=normal_Pa_per_m,
            )
        tri = ContactSurface.for_mesh(mesh, surface=surface).triangles
        corners = mesh.points[tri[:, :3]]
        cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        areas = 0.5 * np.linalg.norm(cross, axis=1)
        normal = cross.sum(axis=0)
        normal /= np.linalg.norm(normal)
        bed = cls._integrated(mesh, tri, normal_Pa_per_m, 0.0)
        nodes = np.unique(tri[:, :3])
        points = mesh.points[nodes]
        centre = int(np.argmin(np.linalg.norm(points - points.mean(axis=0), axis=1)))
        reach = points - points[centre]
        reach -= np.outer(reach @ normal, normal)
        far = int(np.argmax(np.linalg.norm(reach, axis=1)))
        turn = np.cross(normal, reach[far])
        turn /= np.linalg.norm(turn)
        pin = SLIDING_PIN_SHARE * normal_Pa_per_m * float(areas.mean())
        pins = np.stack([pin * (np.eye(3) - np.outer(normal, normal)), pin * np.outer(turn, turn)])
        pinned = nodes[[centre, far]].astype(np.int64)
        return cls(
            rows=np.concatenate([bed.rows, pinned]),
            columns=np.concatenate([bed.columns, pinned]),
            blocks=np.concatenate([bed.blocks, pins]),
        ).merged(mesh.node_count)

    def merged(self, node_count: int) -> SupportSprings:
        """The same springs with one block per node pair (repeated pairs summed)."""
        keys, inverse = np.unique(self.rows * node_count + self.columns, return_inverse=True)
        blocks = np.zeros((len(keys), 3, 3))
        np.add.at(blocks, inverse.reshape(-1), self.blocks)
        return SupportSprings(
            rows=(keys // node_count).astype(np.int64),
            columns=(keys % node_count).astype(np.int64),
            blocks=blocks,
        )

    def product(self, values: np.ndarray) -> np.ndarray:
        """``S x`` of nodal vectors ``values`` (N, 3) of the problem, (N, 3)."""
        values = np.asarray(values, dtype=np.float64)
        out = np.zeros_like(values)
        np.add.at(out, self.rows, np.einsum("mij,mj->mi", self.blocks, values[self.columns]))
        return out


class SupportSpringSet:
    """The support springs of the K problems of one assembler's mesh and their launch of
    ``support_spring_kernel``. :class:`warptissue.fem.assembly.Assembler` holds one
    (``set_springs``, ``spring_product``).

    Args:
        pattern_offsets: The tangent's BSR row offsets, (N + 1,).
        pattern_columns: Its block columns, (B,), sorted within each row.
        node_offsets: First node of each packed problem and N at the end, (K + 1,); None
            where the problems are not packed in contiguous node ranges.
        problem_count: K.
        device: The assembler's Warp device.
    """

    def __init__(
        self,
        *,
        pattern_offsets: np.ndarray,
        pattern_columns: np.ndarray,
        node_offsets: np.ndarray | None,
        problem_count: int,
        device: Any,
    ) -> None:
        self._pattern_offsets = pattern_offsets
        self._pattern_columns = pattern_columns
        self._node_offsets = node_offsets
        self.problem_count = problem_count
        self.device = device
        self.springs: tuple[SupportSprings | None, ...] = (None,) * problem_count
        self._count = 0

    def set(self, springs: SupportSprings | Sequence[SupportSprings | None] | None) -> None:
        """The springs from the next launch on: one :class:`SupportSprings` (one problem),
        one entry per problem, or None.

        Raises:
            InputError: Not one entry per problem, a node outside its problem or a block
                outside the tangent's pattern, or springs on problems that are not packed in
                contiguous node ranges.
        """
        count = self.problem_count
        offsets = self._node_offsets
        entries, used = per_problem(
            springs,
            SupportSprings,
            count=count,
            node_offsets=offsets,
            key="springs",
            one="set of support springs",
            many="support springs",
        )
        rows, columns, blocks, problems = [], [], [], []
        for k in used:
            own = entries[k]
            size = int(offsets[k + 1] - offsets[k])
            for nodes in (own.rows, own.columns):
                if nodes.size and (nodes.min() < 0 or nodes.max() >= size):
                    raise InputError(
                        "spring nodes must be nodes of the mesh"
                        + ("" if count == 1 else f" (of problem {k}, in its own numbering)"),
                        key="springs",
                    )
            rows.append(own.rows + offsets[k])
            columns.append(own.columns + offsets[k])
            blocks.append(own.blocks)
            problems.append(np.full(len(own.rows), k, dtype=np.int32))
        self.springs = entries
        self._count = int(sum(len(each) for each in rows))
        if not self._count:
            return
        row, column = np.concatenate(rows), np.concatenate(columns)
        try:
            ids = block_ids(self._pattern_offsets, self._pattern_columns, row, column)
        except InputError:
            raise InputError(
                "support springs couple nodes that share no element", key="springs"
            ) from None
        dev = self.device
        self._rows, self._columns = row, column
        self._blocks_host = np.concatenate(blocks)
        self._inputs = [
            wp.array(row, dtype=wp.int32, device=dev),
            wp.array(column, dtype=wp.int32, device=dev),
            wp.array(ids, dtype=wp.int32, device=dev),
            wp.array(np.concatenate(problems), dtype=wp.int32, device=dev),
            wp.array(self._blocks_host, dtype=wp.mat33d, device=dev),
        ]

    @property
    def has_springs(self) -> bool:
        """Whether any problem has support springs."""
        return self._count > 0

    def launch(
        self,
        u: wp.array,
        with_tangent: int,
        residual: wp.array,
        values: wp.array,
        energy: wp.array,
    ) -> None:
        """One launch of ``support_spring_kernel``: adds ``S u`` to ``residual`` (vec3d (N,)),
        ``S`` to the blocks of ``values`` where ``with_tangent``, and ``u . S u / 2`` to each
        problem's ``energy`` (J)."""
        if not self._count:
            return
        wp.launch(
            kc.support_spring_kernel,
            dim=self._count,
            inputs=[*self._inputs, u, with_tangent],
            outputs=[residual, values, energy],
            device=self.device,
        )

    def product(self, values: np.ndarray) -> np.ndarray:
        """``S x`` of nodal vectors ``values`` (N, 3) of the whole mesh, (N, 3) (host)."""
        values = np.asarray(values, dtype=np.float64)
        out = np.zeros_like(values)
        if self._count:
            products = np.einsum("mij,mj->mi", self._blocks_host, values[self._columns])
            np.add.at(out, self._rows, products)
        return out


def support_edge_m(mesh: TetMesh, surface: str) -> float:
    """The mean corner-edge length of the boundary triangles on node set ``surface``, m."""
    tri = ContactSurface.for_mesh(mesh, surface=surface).triangles[:, :3]
    corners = mesh.points[tri]
    lengths = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2)
    return float(lengths.mean())
