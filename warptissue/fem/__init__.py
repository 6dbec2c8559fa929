"""Tetrahedral hyperelastic finite elements on Warp: assembly, Newton, indentation."""

from warptissue.fem.assembly import FORMULATIONS, Assembler, Assembly, von_mises
from warptissue.fem.elements import ElementGeometry, element_geometry

__all__ = [
    "FORMULATIONS",
    "Assembler",
    "Assembly",
    "ElementGeometry",
    "element_geometry",
    "von_mises",
]
