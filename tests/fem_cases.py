"""Shared FE test cases: homogeneous uniaxial compression of a cube."""

from __future__ import annotations

import numpy as np

from warptissue.fem import DirichletConditions


def compression_conditions(mesh) -> DirichletConditions:
    """Frictionless plates on a block mesh: symmetry on x = 0, y = 0, z = 0 and
    ``uz = -load`` on the top (homogeneous uniaxial compression, free lateral faces)."""
    parts = []
    for name, axis, value in (
        ("xmin", 0, 0.0),
        ("ymin", 1, 0.0),
        ("zmin", 2, 0.0),
        ("zmax", 2, -1.0),
    ):
        nodes = mesh.node_sets[name]
        parts.append(
            DirichletConditions(nodes, np.full(len(nodes), axis), np.full(len(nodes), value))
        )
    return DirichletConditions.combine(*parts)
