"""Several independent problems packed into one set of arrays, for one launch over all.

K meshes become one mesh, their disjoint union: nodes and tets follow each other in the
order of the problems, with offsets per problem. One :class:`warptissue.fem.Assembler` over
the union, given one material per problem and each tet's problem, assembles all of them in
the same kernel launches; its tangent is block diagonal (no tet couples two problems), and
its energy and smallest J come per problem (:attr:`warptissue.fem.Assembly.problem_energies_J`).
This is the base of batched forward and inverse FE on one device (issue 23).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from warptissue.errors import InputError
from warptissue.mesh import TetMesh

__all__ = ["PackedMeshes", "pack_meshes", "per_problem"]


@dataclass(frozen=True)
class PackedMeshes:
    """The disjoint union of K meshes, with each problem's offsets.

    Attributes:
        mesh: The union: nodes and tets of problem k follow those of problems 0..k-1. Its
            node and face sets are those of every problem, named ``"k/name"``; its tet
            regions are the problems' own.
        node_offsets: First node of each problem, and the node count at the end, (K + 1,).
        tet_offsets: First tet of each problem, and the tet count at the end, (K + 1,).
    """

    mesh: TetMesh
    node_offsets: np.ndarray
    tet_offsets: np.ndarray

    @property
    def problem_count(self) -> int:
        """K, the number of packed problems."""
        return len(self.node_offsets) - 1

    @property
    def element_problem(self) -> np.ndarray:
        """The problem of each tet of the union, (tet_count,), int32."""
        return np.repeat(
            np.arange(self.problem_count, dtype=np.int32), np.diff(self.tet_offsets)
        ).astype(np.int32)

    @property
    def node_problem(self) -> np.ndarray:
        """The problem of each node of the union, (node_count,), int32."""
        return np.repeat(
            np.arange(self.problem_count, dtype=np.int32), np.diff(self.node_offsets)
        ).astype(np.int32)

    def nodes(self, problem: int) -> slice:
        """Problem ``problem``'s nodes in the union."""
        return slice(int(self.node_offsets[problem]), int(self.node_offsets[problem + 1]))

    def split(self, values: np.ndarray) -> list[np.ndarray]:
        """A nodal array of the union, (N, ...), as one array per problem (views)."""
        values = np.asarray(values)
        if values.shape[0] != self.node_offsets[-1]:
            raise InputError(
                f"a nodal array of the packed mesh has {int(self.node_offsets[-1])} rows",
                value=values.shape,
            )
        return [values[self.nodes(k)] for k in range(self.problem_count)]


def pack_meshes(meshes: Sequence[TetMesh]) -> PackedMeshes:
    """Pack K meshes of one element type into their disjoint union.

    Args:
        meshes: The problems' meshes (at least one), all TET4 or all TET10.

    Returns:
        A :class:`PackedMeshes`.

    Raises:
        InputError: No mesh, or meshes of different element types.
    """
    meshes = list(meshes)
    if not meshes:
        raise InputError("at least one mesh is needed to pack", key="meshes", value=0)
    kinds = sorted({mesh.nodes_per_tet for mesh in meshes})
    if len(kinds) > 1:
        raise InputError(
            "packed meshes must share one element type",
            key="meshes",
            value=[mesh.element_type for mesh in meshes],
        )
    node_offsets = np.concatenate([[0], np.cumsum([mesh.node_count for mesh in meshes])])
    tet_offsets = np.concatenate([[0], np.cumsum([mesh.tet_count for mesh in meshes])])
    node_sets = {
        f"{k}/{name}": nodes + node_offsets[k]
        for k, mesh in enumerate(meshes)
        for name, nodes in mesh.node_sets.items()
    }
    union = TetMesh(
        points=np.concatenate([mesh.points for mesh in meshes]),
        tets=np.concatenate([mesh.tets + node_offsets[k] for k, mesh in enumerate(meshes)]),
        node_sets=node_sets,
        face_sets={
            f"{k}/{name}": faces + node_offsets[k]
            for k, mesh in enumerate(meshes)
            for name, faces in mesh.face_sets.items()
        },
        tet_regions=np.concatenate([mesh.tet_regions for mesh in meshes]),
    )
    return PackedMeshes(
        mesh=union,
        node_offsets=node_offsets.astype(np.int64),
        tet_offsets=tet_offsets.astype(np.int64),
    )


def per_problem(
    value: Any,
    kind: type,
    *,
    count: int,
    node_offsets: np.ndarray | None,
    key: str,
    one: str,
    many: str,
) -> tuple[tuple[Any, ...], list[int]]:
    """Per-problem entries of an assembler's boundary terms (rigid contacts, support springs).

    Args:
        value: One ``kind`` (one problem), a sequence of K entries (each a ``kind`` or None),
            or None (none anywhere).
        kind: The entries' class.
        count: K, the packed problems.
        node_offsets: First node of each problem and N at the end, (K + 1,); None where the
            problems are not packed in contiguous node ranges.
        key: The ``InputError`` key of a wrong count or entry.
        one: What one entry is, for the messages ("contact").
        many: What the entries are, for the messages ("rigid contacts").

    Returns:
        (the K entries, the problems that have one).

    Raises:
        InputError: Not one entry per problem, an entry that is not a ``kind`` or None, or
            entries on problems that are not packed in contiguous node ranges.
    """
    if value is None:
        entries: tuple[Any, ...] = (None,) * count
    elif isinstance(value, kind):
        entries = (value,) if count == 1 else ()
    else:
        entries = tuple(value)
    if len(entries) != count:
        raise InputError(
            f"one {one} (or None) per packed problem: {count} expected",
            key=key,
            value=len(entries) if value is not None and not isinstance(value, kind) else 1,
        )
    for k, each in enumerate(entries):
        if each is not None and not isinstance(each, kind):
            raise InputError(
                f"problem {k}: a {one} must be a {kind.__name__} or None",
                key=key,
                value=type(each).__name__,
            )
    used = [k for k, each in enumerate(entries) if each is not None]
    if used and node_offsets is None:
        raise InputError(
            f"{many} of several problems need them packed in contiguous node ranges "
            "(warptissue.fem.packing.pack_meshes)",
            key="element_problem",
        )
    return entries, used
