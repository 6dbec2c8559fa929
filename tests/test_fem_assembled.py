"""Tests for warptissue.fem.assembled: an assembly whose energies are read later."""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from warptissue.fem import Assembler
from warptissue.materials import NeoHookean
from warptissue.mesh import block_mesh, to_tet10


def test_energies_read_later_equal_those_read_at_once(device, rng):
    """``assemble(read_scalars=False)`` leaves the energy and smallest det F unread, its
    ``scalars`` are the assembler's (energies, smallest J), and ``with_scalars`` of them gives
    the values of an assembly that read them at once; a second problem's values stay apart."""
    grid = np.linspace(0.0, 1e-2, 3)
    mesh = to_tet10(block_mesh(grid, grid, np.linspace(0.0, 5e-3, 2)))
    assembler = Assembler(mesh, NeoHookean(300.0, 3e4), device=device)
    u = 2e-4 * rng.standard_normal((mesh.node_count, 3))
    now = assembler.assemble(u, with_tangent=False)
    later = assembler.assemble(u, with_tangent=False, read_scalars=False)
    assert math.isnan(later.energy_J) and later.problem_energies_J is None
    assert now.scalars is None and isinstance(later.scalars, wp.array)
    read = later.with_scalars(later.scalars.numpy())
    assert read.scalars is None
    assert read.energy_J == now.energy_J and read.min_jacobian == now.min_jacobian
    np.testing.assert_array_equal(read.problem_energies_J, now.problem_energies_J)
    np.testing.assert_array_equal(read.problem_min_jacobians, now.problem_min_jacobians)
    assert 0.0 < read.min_jacobian < 2.0 and read.energy_J > 0.0
    two = later.with_scalars(np.array([1.0, 2.0, 0.5, 0.25]))
    assert two.energy_J == 3.0 and two.min_jacobian == 0.25
    np.testing.assert_array_equal(two.problem_min_jacobians, [0.5, 0.25])
