"""Tetrahedral hyperelastic finite elements on Warp: assembly, Newton, flat-punch indentation.

Public API (CONVENTIONS.md): :class:`FlatPunch`, :class:`IndentationProblem`,
:func:`simulate_indentation` -> :class:`IndentationResult`; lower level: :class:`Assembler`,
:class:`DirichletConditions`, :func:`solve_quasistatic`, :class:`LinearSolver`.
"""

from warptissue.fem.assembly import FORMULATIONS, Assembler, Assembly, von_mises
from warptissue.fem.elements import ElementGeometry, element_geometry
from warptissue.fem.indentation import (
    FlatPunch,
    IndentationProblem,
    IndentationResult,
    simulate_indentation,
)
from warptissue.fem.solvers import (
    LINEAR_SOLVERS,
    DirichletConditions,
    LinearSolver,
    QuasistaticResult,
    solve_quasistatic,
)

__all__ = [
    "FORMULATIONS",
    "LINEAR_SOLVERS",
    "Assembler",
    "Assembly",
    "DirichletConditions",
    "ElementGeometry",
    "FlatPunch",
    "IndentationProblem",
    "IndentationResult",
    "LinearSolver",
    "QuasistaticResult",
    "element_geometry",
    "simulate_indentation",
    "solve_quasistatic",
    "von_mises",
]
