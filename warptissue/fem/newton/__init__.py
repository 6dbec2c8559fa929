"""Newton's method along load paths: one loop for one problem or K problems at once.

:func:`solve_quasistatic` follows one displacement-controlled load path,
:func:`solve_quasistatic_batch` follows K paths of problems packed into one mesh in the same
launches; both run the one loop of :mod:`~warptissue.fem.newton.loop`, whose increments
(:mod:`~warptissue.fem.newton.increment`) take every decision per problem: the predictor,
the step search (:mod:`~warptissue.fem.newton.search`), Levenberg-Marquardt damping and
factorization reuse (:mod:`~warptissue.fem.newton.steering`), the nonlinear elimination
(:mod:`~warptissue.fem.newton.elimination`), convergence, cutbacks, and the exact force
sensitivities at converged states (:mod:`~warptissue.fem.newton.sensitivity`).
"""

from warptissue.fem.newton.options import PREDICTORS, NewtonOptions
from warptissue.fem.newton.path import (
    QuasistaticResult,
    SolveInterrupted,
    solve_quasistatic,
    solve_quasistatic_batch,
)
from warptissue.fem.newton.problems import DirichletConditions
from warptissue.fem.newton.sensitivity import ForceSensitivity

__all__ = [
    "PREDICTORS",
    "DirichletConditions",
    "ForceSensitivity",
    "NewtonOptions",
    "QuasistaticResult",
    "SolveInterrupted",
    "solve_quasistatic",
    "solve_quasistatic_batch",
]
