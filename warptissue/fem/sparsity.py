"""The sparsity pattern of the tangent of a tet mesh: its distinct node pairs as 3x3 blocks,
and where each element block goes among them (:class:`warptissue.fem.assembly.Assembler`
builds it once per mesh).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from warptissue.errors import InputError

__all__ = [
    "block_ranges",
    "element_pattern",
    "packed_ranges",
    "sparsity_pattern",
    "tet_problems",
]


def block_ranges(offsets: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Indices of all blocks of the given block rows of a BSR pattern, row after row."""
    starts = offsets[rows]
    counts = offsets[rows + 1] - starts
    shift = np.repeat(starts - np.concatenate([[0], np.cumsum(counts)[:-1]]), counts)
    return shift + np.arange(int(counts.sum()))


def sparsity_pattern(
    tets: np.ndarray, node_count: int, element_problems: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The distinct node pairs of the element blocks, row-major, and each block's place.

    Packed problems (:func:`warptissue.fem.packing.pack_meshes`: each problem's tets and
    nodes one contiguous range, in problem order) have a block-diagonal pattern: each
    problem's own pattern, shifted. It is computed once per distinct mesh (several rates or
    sites on one specimen's mesh share it), instead of sorting the node pairs of the union.

    Args:
        tets: Element connectivity, (M, npe).
        node_count: N.
        element_problems: The problem of each tet, (M,).

    Returns:
        (block rows (B,), block columns (B,), block index (M, npe * npe)), int32: the
        distinct (row, column) node pairs in row-major order, and for each element block
        ``(a, b)`` (row-major over the element's nodes) its index among them.
    """
    ranges = packed_ranges(tets, node_count, element_problems)
    if ranges is None:
        return element_pattern(tets, node_count)
    rows, cols = [], []
    index = np.empty((tets.shape[0], tets.shape[1] ** 2), dtype=np.int32)
    known: dict[tuple[int, int, int], tuple[np.ndarray, ...]] = {}
    blocks = 0
    for first_tet, last_tet, first_node, last_node in ranges:
        local = tets[first_tet:last_tet] - first_node
        key = (last_node - first_node, local.shape[0], hash(local.tobytes()))
        found = known.get(key)
        if found is None or not np.array_equal(found[0], local):
            found = (local, *element_pattern(local, last_node - first_node))
            known[key] = found
        _, local_rows, local_cols, local_index = found
        rows.append(local_rows + first_node)
        cols.append(local_cols + first_node)
        index[first_tet:last_tet] = local_index + blocks
        blocks += local_rows.shape[0]
    return np.concatenate(rows), np.concatenate(cols), index


def packed_ranges(
    tets: np.ndarray, node_count: int, element_problems: np.ndarray
) -> list[tuple[int, int, int, int]] | None:
    """(first tet, end tet, first node, end node) of each problem where the problems are
    packed (contiguous, ordered, disjoint tet and node ranges covering the mesh); else None
    (and for a single problem)."""
    if element_problems.size == 0 or element_problems[-1] == element_problems[0]:
        return None
    if np.any(np.diff(element_problems) < 0):
        return None
    starts = np.flatnonzero(np.diff(element_problems)) + 1
    bounds = np.concatenate([[0], starts, [len(element_problems)]])
    ranges = []
    next_node = 0
    for first_tet, last_tet in zip(bounds[:-1], bounds[1:], strict=True):
        part = tets[first_tet:last_tet]
        if int(part.min()) != next_node:
            return None
        end_node = int(part.max()) + 1
        ranges.append((int(first_tet), int(last_tet), next_node, end_node))
        next_node = end_node
    return ranges if next_node == node_count else None


def element_pattern(tets: np.ndarray, node_count: int) -> tuple[np.ndarray, ...]:
    """:func:`sparsity_pattern` of one mesh, by one sort of the element blocks' node pairs."""
    npe = tets.shape[1]
    n = node_count
    rows = np.repeat(tets, npe, axis=1).astype(np.int64)  # (M, npe*npe): a-major
    cols = np.tile(tets, (1, npe)).astype(np.int64)
    keys = (rows * n + cols).reshape(-1)
    # One sort gives the distinct node pairs and each element block's place among them
    # (NumPy's hash-based np.unique took 4x longer on these keys).
    order = np.argsort(keys)
    sorted_keys = keys[order]
    first = np.empty(len(keys), dtype=bool)
    first[0] = True
    np.not_equal(sorted_keys[1:], sorted_keys[:-1], out=first[1:])
    unique_keys = sorted_keys[first]
    block_index = np.empty(len(keys), dtype=np.int32)
    block_index[order] = np.cumsum(first) - 1
    return (
        (unique_keys // n).astype(np.int32),
        (unique_keys % n).astype(np.int32),
        block_index.reshape(rows.shape),
    )


def tet_problems(element_problem: Any, tet_count: int, problem_count: int) -> np.ndarray:
    """The problem of each tet, checked: (tet_count,) integers in [0, problem_count)."""
    if element_problem is None:
        if problem_count != 1:
            raise InputError(
                f"{problem_count} materials need element_problem, the problem of each tet",
                key="element_problem",
            )
        return np.zeros(tet_count, dtype=np.int32)
    problems = np.asarray(element_problem)
    if problems.shape != (tet_count,) or not np.issubdtype(problems.dtype, np.integer):
        raise InputError(
            f"element_problem must hold one integer per tet ({tet_count})",
            key="element_problem",
            value=(problems.shape, str(problems.dtype)),
        )
    if problems.size and (problems.min() < 0 or problems.max() >= problem_count):
        raise InputError(
            f"element_problem must lie in [0, {problem_count})",
            key="element_problem",
            value=(int(problems.min()), int(problems.max())),
        )
    return problems.astype(np.int32)
