"""Tests of warptissue.fem.sparsity: the tangent's block pattern against direct counts."""

from __future__ import annotations

import numpy as np
import pytest

from warptissue.errors import InputError
from warptissue.fem.packing import pack_meshes
from warptissue.fem.sparsity import block_ranges, element_pattern, sparsity_pattern, tet_problems
from warptissue.mesh import block_mesh, to_tet10


def _mesh(cells: int):
    grid = np.linspace(0.0, 1e-2, cells + 1)
    return to_tet10(block_mesh(grid, grid, np.linspace(0.0, 5e-3, 2)))


def test_element_pattern_holds_every_node_pair_once_and_places_each_block():
    """Against a set of the node pairs built in Python: sorted row-major, each element block
    ``(a, b)`` of tet e at the index of its pair."""
    mesh = _mesh(2)
    rows, cols, index = element_pattern(mesh.tets, mesh.node_count)
    pairs = sorted({(int(a), int(b)) for tet in mesh.tets for a in tet for b in tet})
    assert list(zip(rows.tolist(), cols.tolist(), strict=True)) == pairs
    npe = mesh.tets.shape[1]
    for e in (0, len(mesh.tets) - 1):
        for a in range(npe):
            for b in range(npe):
                k = index[e, a * npe + b]
                assert (rows[k], cols[k]) == (mesh.tets[e, a], mesh.tets[e, b])


def test_packed_problems_get_the_pattern_of_their_union():
    """The sparsity pattern of packed problems, built once per distinct mesh and shifted, is
    the one a sort of the union's node pairs gives: three problems, two of them one mesh;
    problems that are not packed (interleaved tets) take the sort of the union."""
    small = _mesh(2)
    large = _mesh(3)
    packed = pack_meshes([small, large, small])
    tets, n = packed.mesh.tets, packed.mesh.node_count
    union = element_pattern(tets, n)
    for got, expected in zip(sparsity_pattern(tets, n, packed.element_problem), union, strict=True):
        np.testing.assert_array_equal(got, expected)
    interleaved = np.arange(len(tets), dtype=np.int32) % 3
    for got, expected in zip(sparsity_pattern(tets, n, interleaved), union, strict=True):
        np.testing.assert_array_equal(got, expected)
    assert union[0].dtype == np.int32 and union[2].shape == (len(tets), 100)


def test_block_ranges_lists_the_blocks_of_the_rows():
    offsets = np.array([0, 2, 5, 6, 9])
    rows = np.array([3, 1])
    expected = np.concatenate([np.arange(6, 9), np.arange(2, 5)])
    np.testing.assert_array_equal(block_ranges(offsets, rows), expected)


def test_tet_problems_are_checked():
    np.testing.assert_array_equal(tet_problems(None, 3, 1), [0, 0, 0])
    assert tet_problems(np.array([0, 1, 1]), 3, 2).dtype == np.int32
    with pytest.raises(InputError, match="element_problem"):
        tet_problems(None, 3, 2)
    with pytest.raises(InputError, match="one integer per tet"):
        tet_problems(np.array([0.0, 1.0, 1.0]), 3, 2)
    with pytest.raises(InputError, match=r"\[0, 2\)"):
        tet_problems(np.array([0, 2, 1]), 3, 2)
