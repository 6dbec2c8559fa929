"""The settings of the Newton solver: one :class:`NewtonOptions` from a study's ``[solver]``
table to the loop that follows the load paths (:mod:`warptissue.fem.newton.path`)."""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

from warptissue.errors import InputError
from warptissue.fem.linear import LINEAR_SOLVERS

__all__ = [
    "ELIMINATION_MIN_TETS_CUDA",
    "PREDICTORS",
    "REUSE_MIN_TETS_CUDA",
    "NewtonOptions",
    "checked_options",
    "elimination_pays",
    "reuse_pays",
]

PREDICTORS = ("linearized", "extrapolated")

ELIMINATION_MIN_TETS_CUDA = 16_000
"""Tets of one problem from which the nonlinear elimination pays on a CUDA device, run alone.

Measured on an H100 and an H200 (docs/performance.md, "Factorization reuse and the nonlinear
elimination", and docs/design-notes/nonlinear-elimination.md): it saves 26-66 Newton
iterations from 16 118 tets on and costs more than it saves at 8 828 tets and fewer, where
its patch solves (host round trips, one problem after another) take longer than the few
factorizations they save."""


def elimination_pays(*, is_cuda: bool, tets_per_problem: int, problem_count: int) -> bool:
    """Whether the nonlinear elimination is on where the options say ``"auto"``.

    The rule, as measured: on the CPU always; on a CUDA device only for one problem of at
    least :data:`ELIMINATION_MIN_TETS_CUDA` tets. Of K > 1 problems on a CUDA device the
    patches are relaxed one problem after another while the factorization is shared, so the
    elimination's cost grows with K and its saving does not: 32 inverse fits of C10 on
    1 260 tets ran 116 fits per minute without it and 33 with it on an H200
    (``bench_batch_fe.py --what fits``, docs/performance.md).

    Args:
        is_cuda: The device is a CUDA device.
        tets_per_problem: Tets of one problem (the largest of a batch).
        problem_count: Problems solved together, K >= 1.
    """
    if not is_cuda:
        return True
    return problem_count == 1 and tets_per_problem >= ELIMINATION_MIN_TETS_CUDA


REUSE_MIN_TETS_CUDA = 5_000
"""Tets of the whole system (all problems solved together) from which solving a Newton
iteration by GMRES with earlier factors pays on a CUDA device.

Measured on an H100 (docs/performance.md, "Newton iterations of small problems on a GPU";
docs/design-notes/device-newton-loop.md): with a factorization at every iteration instead,
the main job's forward run (576 tets) took 7.0 ms per Newton iteration against 9.1 and its
fit 8.0 s against 10.0 s; the flat-punch curve of 2 471 tets 1.15 s against 1.25 s; at
8 828 tets the reuse was faster, 2.42 s against 2.55 s. On a small system cuDSS factorizes
in about the time of a GMRES attempt's kernel launches, so an attempt saves little where it
succeeds and costs the most where it fails."""


def reuse_pays(*, is_cuda: bool, tet_count: int) -> bool:
    """Whether Newton's solves with earlier factors are on where the options say ``"auto"``.

    The rule, as measured: on the CPU always (a solve with existing factors costs about a
    tenth of a PARDISO factorization); on a CUDA device from :data:`REUSE_MIN_TETS_CUDA` tets
    of the whole system on.

    Args:
        is_cuda: The device is a CUDA device.
        tet_count: Tets of all the problems solved together (the factorized system's).
    """
    return not is_cuda or tet_count >= REUSE_MIN_TETS_CUDA


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
            of the residual with the others fixed (fewer factorizations at a punch edge):
            ``True``, ``False`` or ``"auto"`` (the measured rule of
            :func:`elimination_pays`: on the CPU; on a CUDA device for one problem of
            16 000 tets or more).
        predictor: Start of each increment: ``"linearized"`` (the tangent's response to the
            prescribed increment) or ``"extrapolated"`` (the last two converged states
            extrapolated linearly in the load).
        damping: Levenberg-Marquardt damping of the tangent after a Newton step that the line
            search cut below a quarter of its length.
        reuse_factorization: Solve a Newton iteration's tangent by GMRES preconditioned with
            the last factorization where that is measured to cost less than a new one
            (:meth:`LinearSolver.solve_newton`): ``True``, ``False`` (every iteration
            factorizes) or ``"auto"`` (the measured rule of :func:`reuse_pays`: on the CPU;
            on a CUDA device from 5 000 tets on). Direct solvers only; CG ignores it.

    Raises:
        InputError: A value of the wrong type or out of range (``column`` names the key).
    """

    linear_solver: str = "auto"
    tolerance: float = 1.0e-9
    max_newton_iterations: int = 25
    max_cutbacks: int = 8
    nonlinear_elimination: bool | str = "auto"
    predictor: str = "linearized"
    damping: bool = True
    reuse_factorization: bool | str = "auto"

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
        for key in ("nonlinear_elimination", "reuse_factorization"):
            value = getattr(self, key)
            if not (isinstance(value, bool) or value == "auto"):
                raise InputError('must be true, false or "auto"', key=key, value=value)
        if not isinstance(self.damping, bool):
            raise InputError("must be true or false", key="damping", value=self.damping)

    def eliminates(self, *, is_cuda: bool, tets_per_problem: int, problem_count: int) -> bool:
        """Whether the nonlinear elimination runs for these problems on this device: the
        option itself, or for ``"auto"`` the rule of :func:`elimination_pays`."""
        if self.nonlinear_elimination == "auto":
            return elimination_pays(
                is_cuda=is_cuda, tets_per_problem=tets_per_problem, problem_count=problem_count
            )
        return bool(self.nonlinear_elimination)

    def reuses(self, *, is_cuda: bool, tet_count: int) -> bool:
        """Whether Newton's solves with earlier factors are on for this system on this
        device: the option itself, or for ``"auto"`` the rule of :func:`reuse_pays`."""
        if self.reuse_factorization == "auto":
            return reuse_pays(is_cuda=is_cuda, tet_count=tet_count)
        return bool(self.reuse_factorization)

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
