"""Tetrahedral hyperelastic finite elements on Warp: a problem, its simulation, its result.

>>> from warptissue.fem import IndentationProblem, simulate_indentation
>>> from warptissue.indenter import Indenter
>>> from warptissue.materials import NeoHookean
>>> from warptissue.mesh import indentation_block
>>> mesh = indentation_block(width_m=0.008, thickness_m=0.004, probe_radius_m=1e-3,
...                          quarter=True, size_near_m=1e-3, size_far_m=2.5e-3)
>>> problem = IndentationProblem(mesh, NeoHookean(287.5, 575e3),
...                              Indenter("flat_punch", radius_m=1e-3),
...                              symmetry_planes=("symmetry_x", "symmetry_y"))
>>> result = simulate_indentation(problem, [1e-4, 2e-4], device="cpu", progress=False)
>>> result.completed, result.depths_m.tolist()
(True, [0.0001, 0.0002])
>>> bool(result.reaction_force_N[1] > result.reaction_force_N[0] > 0.0)
True

Many problems in the same launches: ``simulate_indentation_batch([problem, ...], [depths,
...])`` gives each its own :class:`IndentationResult`, equal to its run alone.

Public API: :class:`IndentationProblem` (a mesh, a material and a
:class:`warptissue.indenter.Indenter`), :func:`simulate_indentation` and
:func:`simulate_indentation_batch` -> :class:`IndentationResult`, with the Newton solver's
settings in one :class:`NewtonOptions`; lower level: :class:`Assembler` (assembly of one or K
packed problems), :class:`DirichletConditions`, :func:`solve_quasistatic` and
:func:`solve_quasistatic_batch` (the one Newton loop, :mod:`warptissue.fem.newton`),
:class:`LinearSolver` (:mod:`warptissue.fem.linear`); exact force sensitivities to material
parameters: :class:`ForceSensitivity` (``simulate_indentation(..., sensitivities=...)``).
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
from warptissue.fem.support import Foundation
from warptissue.fem.timing import NewtonTimings

__all__ = [
    "FORMULATIONS",
    "LINEAR_SOLVERS",
    "Assembler",
    "Assembly",
    "DirichletConditions",
    "ElementGeometry",
    "Foundation",
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
