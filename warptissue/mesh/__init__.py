"""Tetrahedral meshes: the container, generators, checks and file I/O."""

from warptissue.mesh.core import (
    TET4_EDGES,
    TET4_FACES,
    TetMesh,
    boundary_faces,
    signed_volumes,
    to_tet10,
)
from warptissue.mesh.generators import (
    HEX_TO_FIVE_TETS,
    HEX_TO_SIX_TETS,
    block_mesh,
    extrude_triangles,
    graded_coordinates,
    graded_spacing,
    indentation_block,
    indentation_disc,
)

__all__ = [
    "HEX_TO_FIVE_TETS",
    "HEX_TO_SIX_TETS",
    "TET4_EDGES",
    "TET4_FACES",
    "TetMesh",
    "block_mesh",
    "boundary_faces",
    "extrude_triangles",
    "graded_coordinates",
    "graded_spacing",
    "indentation_block",
    "indentation_disc",
    "signed_volumes",
    "to_tet10",
]
