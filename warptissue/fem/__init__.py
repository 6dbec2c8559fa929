"""Tetrahedral hyperelastic finite elements on Warp: assembly, Newton, indentation by a flat
punch or, through frictionless penalty contact (:mod:`warptissue.fem.contact`), a rigid sphere
or plate.

Public API (CONVENTIONS.md): :class:`IndentationProblem` (a mesh, a material and a
:class:`warptissue.indenter.Indenter`), :func:`simulate_indentation` ->
:class:`IndentationResult`, with the Newton solver's settings in one :class:`NewtonOptions`;
lower level: :class:`Assembler`, :class:`DirichletConditions`, :func:`solve_quasistatic`,
:class:`LinearSolver`; exact force sensitivities to material parameters:
:class:`ForceSensitivity` (``simulate_indentation(..., sensitivities=...)``); many
problems in the same launches: :func:`simulate_indentation_batch` (:mod:`warptissue.fem.batched`).
"""

from warptissue.fem.assembly import FORMULATIONS, Assembler, Assembly, von_mises
from warptissue.fem.elements import ElementGeometry, element_geometry
from warptissue.fem.indentation import (
    IndentationProblem,
    IndentationResult,
    batch_assembler,
    simulate_indentation,
    simulate_indentation_batch,
)
from warptissue.fem.linear import LINEAR_SOLVERS, LinearSolver
from warptissue.fem.newton import (
    DirichletConditions,
    ForceSensitivity,
    NewtonOptions,
    QuasistaticResult,
    SolveInterrupted,
    solve_quasistatic,
    solve_quasistatic_batch,
)
from warptissue.fem.timing import NewtonTimings

__all__ = [
    "FORMULATIONS",
    "LINEAR_SOLVERS",
    "Assembler",
    "Assembly",
    "DirichletConditions",
    "ElementGeometry",
    "ForceSensitivity",
    "IndentationProblem",
    "IndentationResult",
    "LinearSolver",
    "NewtonOptions",
    "NewtonTimings",
    "QuasistaticResult",
    "SolveInterrupted",
    "batch_assembler",
    "element_geometry",
    "simulate_indentation",
    "simulate_indentation_batch",
    "solve_quasistatic",
    "solve_quasistatic_batch",
    "von_mises",
]
