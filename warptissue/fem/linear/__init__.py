"""The linear solve of Newton's iterations: one :class:`LinearSolver` that dispatches to a
direct solver per device (PARDISO or SuperLU on the CPU, cuDSS on CUDA,
:mod:`~warptissue.fem.linear.direct`, :mod:`~warptissue.fem.linear.cudss`), Warp's conjugate
gradients, or GMRES with the last factors (:mod:`~warptissue.fem.linear.krylov`)."""

from warptissue.fem.linear.solver import LINEAR_SOLVERS, LinearSolver

__all__ = ["LINEAR_SOLVERS", "LinearSolver"]
