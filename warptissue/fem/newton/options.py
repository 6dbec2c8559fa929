"""The settings of the Newton solver: one :class:`NewtonOptions` from a study's ``[solver]``
table to the loop that follows the load paths (:mod:`warptissue.fem.newton.path`)."""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

from warptissue.errors import InputError
from warptissue.fem.linear import LINEAR_SOLVERS

__all__ = ["PREDICTORS", "NewtonOptions", "checked_options"]

PREDICTORS = ("linearized", "extrapolated")


@dataclass(frozen=True, kw_only=True)
class NewtonOptions:
    """Settings of the load-stepping Newton solver: one object from the study to the solver.

    A study's ``[solver]`` table carries these keys under the same names
    (:func:`warptissue.study.load_study`), and :func:`warptissue.fem.simulate_indentation` and
    :func:`solve_quasistatic` take the object as ``options=``. Only ``tolerance``,
    ``max_newton_iterations`` and ``max_cutbacks`` change the converged result; the other
    settings change the path to it (and its cost), not the convergence test.

    Args:
        linear_solver: ``"auto"`` (PARDISO where pypardiso imports, else SuperLU, on the CPU;
            cuDSS on CUDA where it loads, else conjugate gradients), ``"pardiso"``,
            ``"superlu"``, ``"cudss"`` or ``"cg"`` (see :class:`LinearSolver`).
        tolerance: Converged when the free-dof residual norm is at most ``tolerance`` times
            the reaction-force norm (dimensionless, in (0, 1)).
        max_newton_iterations: Newton iterations per load increment before a cutback (>= 1).
        max_cutbacks: Halvings of a failed increment allowed per requested load before the
            run stops early, keeping what converged (>= 0).
        nonlinear_elimination: After each global Newton step, relax the nodes that hold most
            of the residual with the others fixed (fewer factorizations at a punch edge).
        predictor: Start of each increment: ``"linearized"`` (the tangent's response to the
            prescribed increment) or ``"extrapolated"`` (the last two converged states
            extrapolated linearly in the load).
        damping: Levenberg-Marquardt damping of the tangent after a Newton step that the line
            search cut below a quarter of its length.
        reuse_factorization: Solve a Newton iteration's tangent by GMRES preconditioned with
            the last factorization where that is measured to cost less than a new one
            (:meth:`LinearSolver.solve_newton`); off, every iteration factorizes (direct
            solvers only; CG ignores it).

    Raises:
        InputError: A value of the wrong type or out of range (``column`` names the key).
    """

    linear_solver: str = "auto"
    tolerance: float = 1.0e-9
    max_newton_iterations: int = 25
    max_cutbacks: int = 8
    nonlinear_elimination: bool = True
    predictor: str = "linearized"
    damping: bool = True
    reuse_factorization: bool = True

    def __post_init__(self) -> None:
        choices = {"linear_solver": LINEAR_SOLVERS, "predictor": PREDICTORS}
        for key, allowed in choices.items():
            value = getattr(self, key)
            if value not in allowed:
                raise InputError(
                    f"must be one of {', '.join(map(repr, allowed))}", key=key, value=value
                )
        tolerance = self.tolerance
        if isinstance(tolerance, bool) or not isinstance(tolerance, int | float):
            raise InputError("must be a number", key="tolerance", value=tolerance)
        if not 0.0 < tolerance < 1.0:
            raise InputError("must lie between 0 and 1", key="tolerance", value=tolerance)
        object.__setattr__(self, "tolerance", float(tolerance))
        for key, minimum in (("max_newton_iterations", 1), ("max_cutbacks", 0)):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, int):
                raise InputError("must be an integer", key=key, value=value)
            if value < minimum:
                raise InputError(f"must be at least {minimum}", key=key, value=value)
        for key in ("nonlinear_elimination", "damping", "reuse_factorization"):
            if not isinstance(getattr(self, key), bool):
                raise InputError("must be true or false", key=key, value=getattr(self, key))

    @classmethod
    def keys(cls) -> tuple[str, ...]:
        """The option names, in the order of the ``[solver]`` table."""
        return tuple(f.name for f in fields(cls))

    def to_dict(self) -> dict[str, Any]:
        """The options by name (the Newton part of a study's ``[solver]`` table)."""
        return {key: getattr(self, key) for key in self.keys()}


def checked_options(options: NewtonOptions | None) -> NewtonOptions:
    """The options, or the defaults for None; anything else is refused."""
    if options is None:
        return NewtonOptions()
    if not isinstance(options, NewtonOptions):
        raise InputError(
            "options must be a warptissue.fem.NewtonOptions", value=type(options).__name__
        )
    return options
