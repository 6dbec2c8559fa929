"""Tetrahedral meshes: the container, generators, checks and file I/O."""

from warptissue.mesh.core import TET4_EDGES, TetMesh, signed_volumes, to_tet10
from warptissue.mesh.generators import (
    HEX_TO_FIVE_TETS,
    HEX_TO_SIX_TETS,
    block_mesh,
    graded_coordinates,
)

__all__ = [
    "HEX_TO_FIVE_TETS",
    "HEX_TO_SIX_TETS",
    "TET4_EDGES",
    "TetMesh",
    "block_mesh",
    "graded_coordinates",
    "signed_volumes",
    "to_tet10",
]
