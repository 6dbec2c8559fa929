"""The linear solve of a Newton iteration on the assembler's device.

Linear solver per device (measured on a 2-core x86_64 CPU and on an H100/H200, docs/performance.md):

- ``"pardiso"``: Intel MKL PARDISO through pypardiso (CPU; the default on x86_64 where it
  imports), symmetric indefinite, with the symbolic analysis done once per sparsity pattern
  (:mod:`warptissue.fem.linear.direct`). Fastest direct solver measured here.
- ``"superlu"``: SciPy's SuperLU (CPU; the default where MKL is not available, e.g. ARM).
- ``"cudss"``: NVIDIA cuDSS sparse direct solver on the GPU through nvmath-python
  (:mod:`warptissue.fem.linear.cudss`; the optional extra ``warptissue[gpu]``): analysis once
  per mesh, a numerical LDL^T factorization and solve per Newton iteration. The default on
  CUDA where it loads.
- ``"cg"``: Warp's preconditioned conjugate gradient (``warp.optim.linear.cg``) on the
  device's own arrays (the CUDA default without cuDSS), with Warp's adaptive factorized sparse
  approximate inverse (FSAI) preconditioner by default: on a 3k-dof nearly incompressible
  indentation tangent (K/mu = 1000) it needed 1020 iterations against 2460 for the diagonal
  (Jacobi) one. Warp's Krylov solvers are slow on the CPU backend, and nearly incompressible
  tangents are ill conditioned, so expect many iterations; the iteration count is reported.

A Newton iteration may instead be solved by GMRES with the last factorization
(:meth:`LinearSolver.solve_newton`, :mod:`warptissue.fem.linear.krylov`).
"""

from __future__ import annotations

import math
import weakref
from time import perf_counter
from typing import Any

import numpy as np
import warp as wp
import warp.sparse as wps

from warptissue.errors import InputError
from warptissue.fem.arrays import DeviceArrays
from warptissue.fem.linear.cudss import CudssSolver, cudss_available
from warptissue.fem.linear.direct import CpuDirectSolver, pardiso_available
from warptissue.fem.linear.krylov import KrylovOutcome, gmres
from warptissue.fem.timing import PhaseTimer

__all__ = ["LINEAR_SOLVERS", "LinearSolver"]

LINEAR_SOLVERS = ("auto", "pardiso", "superlu", "cudss", "cg")
REUSE_BUDGET = 0.5
"""A GMRES solve with old factors (:meth:`LinearSolver.solve_newton`) gives up after this
share of the measured wall time of the last factorization with its solve."""
REUSE_PREDICT_AFTER = 3
"""From this many GMRES iterations on, a solve with old factors also gives up when the mean
residual reduction per iteration so far predicts that it would overrun its budget."""
REUSE_MAX_ITERATIONS = 40
"""Most GMRES iterations of one solve with old factors (the basis is kept in memory)."""

_ANALYSED: weakref.WeakKeyDictionary[Any, dict[str, tuple[int, Any]]] = weakref.WeakKeyDictionary()
"""The direct solvers analysed for an owner's matrix (an assembler's: kept while the
assembler lives, not longer), by method, with the matrix's block count at the analysis."""


def analysed_solver(matrix: wps.BsrMatrix, method: str, *, owner: Any = None) -> Any:
    """The direct solver of ``matrix``: the one analysed before for ``owner``'s matrix and
    this method where it is the same matrix with the same sparsity pattern, else a new one
    (its analysis runs now).

    Args:
        matrix: Square 3x3-block BSR matrix (N x N blocks).
        method: ``"cudss"``, ``"pardiso"`` or ``"superlu"``.
        owner: The object that owns ``matrix`` and outlives the runs that solve it (the
            :class:`~warptissue.fem.Assembler`); None keeps nothing.

    Returns:
        A :class:`~warptissue.fem.linear.cudss.CudssSolver` or
        :class:`~warptissue.fem.linear.direct.CpuDirectSolver`; its next ``solve``
        factorizes the matrix's values then.
    """
    kept = {} if owner is None else _ANALYSED.setdefault(owner, {})
    blocks = matrix.nnz_sync()
    if method in kept and kept[method][1].matrix is matrix and kept[method][0] == blocks:
        return kept[method][1]
    solver = CudssSolver(matrix) if method == "cudss" else CpuDirectSolver(matrix, method=method)
    kept[method] = (blocks, solver)
    return solver


class LinearSolver:
    """Solves the eliminated tangent system on the assembler's device.

    Args:
        method: ``"auto"`` (PARDISO or SuperLU on the CPU; cuDSS on CUDA where it loads,
            else CG), ``"pardiso"``, ``"superlu"``, ``"cudss"`` or ``"cg"``.
        device: The Warp device of the matrices.
        tolerance: Relative residual tolerance of CG.
        max_iterations: Iteration limit of CG (None: 30 x the number of dofs).
        preconditioner: CG preconditioner, any ``ptype`` of
            ``warp.optim.linear.preconditioner`` (``"fsai"``, ``"diag"``, ...).
        owner: The owner of the matrices, which outlives this solver (the
            :class:`~warptissue.fem.Assembler` of a run): a direct solver's symbolic
            analysis of its matrix is kept with it for its later runs
            (:func:`analysed_solver`). None: kept by this solver alone.

    Attributes:
        direct: The CPU direct solver of the last matrix (PARDISO or SuperLU), or None. It
            holds the matrix's scalar pattern and PARDISO's symbolic analysis, and is reused
            while the same matrix object (fixed pattern, new values) is passed in.
        factorizations: Numerical factorizations so far (direct methods; 0 for CG).
        timer: The :class:`warptissue.fem.timing.PhaseTimer` that the analysis,
            factorizations and solves are charged to (disabled by default;
            :func:`solve_quasistatic` sets its own when it profiles).
        reused_solves: Newton solves done by GMRES with earlier factors
            (:meth:`solve_newton`).
        krylov_iterations: GMRES iterations of those solves and of the attempts that gave up.
        failed_reuses: GMRES attempts that gave up (each followed by a factorization).
        arrays: The array library of the Newton loop on ``device``
            (:class:`warptissue.fem.arrays.DeviceArrays`): right-hand sides of that library
            (CuPy on a CUDA device) are solved without leaving the device.
    """

    def __init__(
        self,
        *,
        method: str = "auto",
        device: wp.Device,
        tolerance: float = 1e-12,
        max_iterations: int | None = None,
        preconditioner: str = "fsai",
        owner: Any = None,
    ) -> None:
        if method not in LINEAR_SOLVERS:
            raise InputError(
                f"linear solver must be one of {LINEAR_SOLVERS}",
                key="linear_solver",
                value=method,
            )
        if method == "auto":
            if device.is_cuda:
                method = "cudss" if cudss_available() else "cg"
            else:
                method = "pardiso" if pardiso_available() else "superlu"
        if method == "pardiso" and not pardiso_available():
            raise InputError(
                "pypardiso (Intel MKL) is not installed on this machine",
                key="linear_solver",
                value=method,
            )
        if method in ("pardiso", "superlu") and device.is_cuda:
            raise InputError(
                f"{method!r} runs on the CPU; use linear_solver='cg' on {device}",
                key="linear_solver",
                value=method,
            )
        if method == "cudss" and not device.is_cuda:
            raise InputError(
                f"'cudss' runs on CUDA devices; use 'pardiso' or 'superlu' on {device}",
                key="linear_solver",
                value=method,
            )
        if method == "cudss" and not cudss_available():
            raise InputError(
                "the cuDSS solver needs nvmath-python, nvidia-cudss-cu13 and cupy-cuda13x "
                "(pip install 'warptissue[gpu]')",
                key="linear_solver",
                value=method,
            )
        self.method = method
        self.device = device
        self.owner = owner
        self.arrays = DeviceArrays(device)
        self.timer = PhaseTimer(enabled=False)
        self.factorizations = 0
        self._cudss: CudssSolver | None = None
        self.direct: CpuDirectSolver | None = None
        self.tolerance = tolerance
        self.max_iterations = max_iterations
        self.preconditioner = preconditioner
        self.reused_solves = 0
        self.krylov_iterations = 0
        self.failed_reuses = 0
        self._factorization_s = math.inf  # wall time of the last factorization with its solve
        self._factored_matrix: wps.BsrMatrix | None = None
        self._krylov: tuple[Any, ...] | None = None

    def solve(self, matrix: wps.BsrMatrix, rhs: Any) -> tuple[Any, int]:
        """Solve ``matrix x = rhs``.

        Args:
            matrix: Square 3x3-block BSR matrix (N x N blocks).
            rhs: Right-hand side, shape (N, 3): NumPy, or CuPy on the matrix's CUDA device.

        Returns:
            (x of shape (N, 3), of ``rhs``'s library; iterations): Krylov iterations, or 1
            for a direct solve. cuDSS with a CuPy ``rhs`` returns without waiting for the
            device.
        """
        if self.method == "cg":
            return self._solve_cg(matrix, rhs)
        self.factorizations += 1
        if self.method == "cudss":
            if self._cudss is None or self._cudss.matrix is not matrix:
                with self.timer.phase("analysis"):
                    self._cudss = analysed_solver(matrix, "cudss", owner=self.owner)
            self._cudss.timer = self.timer
            started = perf_counter()
            x = self._cudss.solve(rhs)  # NumPy: ends on the host; CuPy: stays on the device
        else:
            if self.direct is None or self.direct.matrix is not matrix:
                with self.timer.phase("analysis"):
                    self.direct = analysed_solver(matrix, self.method, owner=self.owner)
            self.direct.timer = self.timer
            started = perf_counter()
            x = self.direct.solve(rhs)
        self._factorization_s = perf_counter() - started
        self._factored_matrix = matrix
        return x, 1

    def statistics(self) -> dict[str, int]:
        """The counts so far: ``factorizations``, ``reused_solves``, ``krylov_iterations``,
        ``failed_reuses``."""
        return {
            "factorizations": self.factorizations,
            "reused_solves": self.reused_solves,
            "krylov_iterations": self.krylov_iterations,
            "failed_reuses": self.failed_reuses,
        }

    def solve_newton(
        self, matrix: wps.BsrMatrix, rhs: Any, *, rtol: float, reuse: bool = True
    ) -> tuple[Any, int]:
        """Newton's linear solve: with the last factorization where that is cheaper.

        Where ``matrix`` was factorized before (its values have changed since), GMRES solves
        it with the old factors as a right preconditioner
        (:func:`warptissue.fem.linear.krylov.gmres`) to ``|rhs - matrix x| <= rtol |rhs|``,
        for at most :data:`REUSE_BUDGET` times the measured wall time of the last
        factorization with its solve; from :data:`REUSE_PREDICT_AFTER` iterations on it gives
        up as soon as its mean residual reduction per iteration predicts an overrun. Where it
        gets there, no factorization is made; where not, the matrix is factorized and solved
        (:meth:`solve`), and the next iteration starts from those fresh factors.

        Args:
            matrix: Square 3x3-block BSR matrix (N x N blocks), the eliminated tangent.
            rhs: Right-hand side, shape (N, 3): NumPy, or CuPy on the matrix's CUDA device.
            rtol: Relative residual the GMRES solve must reach, in (0, 1).
            reuse: Try the old factors first (False: :meth:`solve`).

        Returns:
            (x of shape (N, 3), of ``rhs``'s library; iterations): GMRES iterations of a
            solve with earlier factors, or 1 for a factorization (with its GMRES attempt's
            iterations added).

        Notes:
            The budget makes the decision a measurement on the mesh and device at hand: a
            solve with existing factors costs 0.1 of a factorization with PARDISO at 20k
            TET10 tets on two cores and 0.02-0.1 with cuDSS on an H100, so a tangent that has
            changed little since its factorization (the later iterations of a load step, the
            first iteration of the next) is solved in a few GMRES iterations, while an
            attempt that does not converge costs at most half a factorization. Inexact
            Newton (Dembo, Eisenstat and Steihaug 1982, SIAM J. Numer. Anal. 19): the
            convergence test of the Newton loop is unchanged, so is the converged state.
        """
        if (
            not reuse
            or self.method == "cg"
            or self._factored_matrix is not matrix
            or not math.isfinite(self._factorization_s)
        ):
            return self.solve(matrix, rhs)
        budget_s = REUSE_BUDGET * self._last_factorization_s()
        started = perf_counter()

        def keep_going(iterations: int, relative_residual: float) -> bool:
            # Go on while the iterations that the mean rate so far predicts fit the budget.
            elapsed = perf_counter() - started
            if elapsed >= budget_s:
                return False
            if iterations < REUSE_PREDICT_AFTER:
                return True
            if not 0.0 < relative_residual < 1.0:
                return False
            needed = iterations * math.log(rtol) / math.log(relative_residual)
            return needed * elapsed / iterations <= budget_s

        with self.timer.phase("solve"):
            outcome = self._gmres(matrix, rhs, rtol=rtol, keep_going=keep_going)
        self.krylov_iterations += outcome.iterations
        if outcome.converged:
            self.reused_solves += 1
            return outcome.x, outcome.iterations
        self.failed_reuses += 1
        x, _ = self.solve(matrix, rhs)
        return x, 1 + outcome.iterations

    def _last_factorization_s(self) -> float:
        """The wall time of the last factorization with its solve, s. cuDSS returns before
        the device has done that work, so its host time alone may be the launches' only:
        the device time (CUDA events) counts where it is longer."""
        if self.method == "cudss" and self._cudss is not None:
            return max(self._factorization_s, self._cudss.last_solve_device_s())
        return self._factorization_s

    def _gmres(self, matrix: wps.BsrMatrix, rhs: Any, *, rtol: float, keep_going):
        """GMRES on ``matrix`` preconditioned by the current factors; x (N, 3) of ``rhs``'s
        library (on CUDA the Krylov basis stays on the device either way)."""
        n = matrix.nrow
        if self._krylov is None or self._krylov[0] is not matrix:
            x_wp = wp.zeros(n, dtype=wp.vec3d, device=self.device)
            y_wp = wp.zeros(n, dtype=wp.vec3d, device=self.device)
            self._krylov = (matrix, x_wp, y_wp)
        _, x_wp, y_wp = self._krylov
        if self.method == "cudss":
            cudss = self._cudss
            cupy = cudss._cupy
            with cupy.cuda.Device(self.device.ordinal), cudss._stream:
                x_view, y_view = cupy.asarray(x_wp), cupy.asarray(y_wp)

                def matvec(v):
                    x_view[...] = v
                    wps.bsr_mv(matrix, x_wp, y_wp, alpha=1.0, beta=0.0)
                    return y_view.copy()

                outcome = gmres(
                    matvec,
                    cudss.apply_factors,
                    cupy.ascontiguousarray(cupy.asarray(rhs, dtype=cupy.float64)),
                    rtol=rtol,
                    max_iterations=REUSE_MAX_ITERATIONS,
                    xp=cupy,
                    keep_going=keep_going,
                )
                x = (
                    cupy.asnumpy(outcome.x, stream=cudss._stream)
                    if isinstance(rhs, np.ndarray)
                    else outcome.x
                )
            return KrylovOutcome(
                x, outcome.iterations, outcome.converged, outcome.relative_residual
            )
        x_view, y_view = x_wp.numpy(), y_wp.numpy()
        direct = self.direct

        def matvec(v):
            x_view[...] = v
            wps.bsr_mv(matrix, x_wp, y_wp, alpha=1.0, beta=0.0)
            return y_view.copy()

        return gmres(
            matvec,
            lambda v: direct.solve_factorized(v, refine=False),
            np.ascontiguousarray(rhs, dtype=np.float64),
            rtol=rtol,
            max_iterations=REUSE_MAX_ITERATIONS,
            keep_going=keep_going,
        )

    def solve_factorized(self, matrix: wps.BsrMatrix, rhs: np.ndarray) -> tuple[np.ndarray, int]:
        """Solve with the factorization of the last :meth:`solve`, without a new one.

        Direct methods reuse their factors of ``matrix`` as it was at the last :meth:`solve`
        (its values may have changed since); where there is none yet for this matrix object,
        this is :meth:`solve`. CG has no factorization: it solves with ``matrix`` as it is.

        Args:
            matrix: The matrix object passed to the last :meth:`solve`.
            rhs: Right-hand side, shape (N, 3).

        Returns:
            (x of shape (N, 3), iterations).
        """
        if self.method == "cg":
            return self._solve_cg(matrix, rhs)
        if self.method == "cudss":
            if self._cudss is None or self._cudss.matrix is not matrix:
                return self.solve(matrix, rhs)
            self._cudss.timer = self.timer
            return self._cudss.solve_factorized(rhs), 1
        if self.direct is None or self.direct.matrix is not matrix:
            return self.solve(matrix, rhs)
        self.direct.timer = self.timer
        return self.direct.solve_factorized(rhs), 1

    def _solve_cg(self, matrix: wps.BsrMatrix, rhs: Any) -> tuple[Any, int]:
        from warp.optim.linear import cg, preconditioner

        on_host = isinstance(rhs, np.ndarray)
        b = wp.array(rhs, dtype=wp.vec3d, device=self.device)
        if not on_host:
            b = wp.clone(b)  # Warp's CG may work in b; keep the caller's array
        x = wp.zeros_like(b)
        max_iterations = self.max_iterations or 30 * rhs.size
        with self.timer.phase("solve"):
            iterations, residual, tolerance = cg(
                matrix,
                b,
                x,
                tol=self.tolerance,
                maxiter=max_iterations,
                M=preconditioner(matrix, ptype=self.preconditioner),
                use_cuda_graph=False,
            )
            return (x.numpy() if on_host else self.arrays.view(x)), int(iterations)
