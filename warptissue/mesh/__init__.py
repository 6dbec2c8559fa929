"""Tetrahedral meshes: the container, generators, checks and file I/O."""

from warptissue.mesh._ball import ball_mesh
from warptissue.mesh._coarsen import coarsen_mesh
from warptissue.mesh._grading import graded_spacing
from warptissue.mesh._locate import locate_points
from warptissue.mesh._refine import refine_near_sites
from warptissue.mesh._usd import (
    FACE_SET_FAMILY,
    NODE_SET_FAMILY,
    REGION_FAMILY,
    USD_SUFFIXES,
    tetmesh_prim,
    usd_holds_tetmesh,
)
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
    hex_to_tets,
    indentation_block,
    indentation_disc,
)
from warptissue.mesh.io import NODE_SET_PREFIX, TET_REGION_KEY, read_mesh, write_mesh
from warptissue.mesh.quality import (
    TET10_SWAP_1_2,
    MeshQuality,
    check_mesh,
    dihedral_angles,
    edge_lengths,
    fix_orientation,
    move_midnodes_keeping_jacobian,
    radius_ratios,
    tet10_jacobian_determinants,
)
from warptissue.mesh.size import (
    FLAT_PUNCH_FORCE_ERRORS,
    FORCE_ACCURACY_DEPTH_RATIO,
    FORCE_ACCURACY_FLOOR,
    MeshSizeEstimate,
    NearSizeChoice,
    estimate_indentation_mesh,
    force_accuracy_depth_warning,
    near_size_choice,
    size_near_for_force_accuracy,
)
from warptissue.mesh.surface import (
    SURFACE_SUFFIXES,
    check_closed_surface,
    fill_surface_file,
    tetrahedralize_surface,
)

__all__ = [
    "FACE_SET_FAMILY",
    "NODE_SET_FAMILY",
    "REGION_FAMILY",
    "USD_SUFFIXES",
    "FLAT_PUNCH_FORCE_ERRORS",
    "FORCE_ACCURACY_DEPTH_RATIO",
    "FORCE_ACCURACY_FLOOR",
    "HEX_TO_FIVE_TETS",
    "HEX_TO_SIX_TETS",
    "ball_mesh",
    "MeshQuality",
    "MeshSizeEstimate",
    "NearSizeChoice",
    "NODE_SET_PREFIX",
    "TET10_SWAP_1_2",
    "TET_REGION_KEY",
    "TET4_EDGES",
    "TET4_FACES",
    "TetMesh",
    "block_mesh",
    "boundary_faces",
    "check_closed_surface",
    "check_mesh",
    "coarsen_mesh",
    "dihedral_angles",
    "edge_lengths",
    "estimate_indentation_mesh",
    "fix_orientation",
    "force_accuracy_depth_warning",
    "extrude_triangles",
    "graded_coordinates",
    "graded_spacing",
    "hex_to_tets",
    "indentation_block",
    "indentation_disc",
    "locate_points",
    "near_size_choice",
    "move_midnodes_keeping_jacobian",
    "radius_ratios",
    "refine_near_sites",
    "read_mesh",
    "signed_volumes",
    "size_near_for_force_accuracy",
    "tetrahedralize_surface",
    "fill_surface_file",
    "SURFACE_SUFFIXES",
    "tet10_jacobian_determinants",
    "tetmesh_prim",
    "to_tet10",
    "usd_holds_tetmesh",
    "write_mesh",
]
