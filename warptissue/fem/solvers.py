"""Linear solvers and the load-stepping Newton solver with line search and cutback.

Linear solver per device (measured on a 2-core x86_64 CPU, see README "Finite elements"):

- ``"pardiso"``: Intel MKL PARDISO through pypardiso (CPU; the default on x86_64 where it
  imports), symmetric indefinite, with the symbolic analysis done once per sparsity pattern
  (:mod:`warptissue.fem.direct`). Fastest direct solver measured here.
- ``"superlu"``: SciPy's SuperLU (CPU; the default where MKL is not available, e.g. ARM).
- ``"cudss"``: NVIDIA cuDSS sparse direct solver on the GPU through nvmath-python
  (:mod:`warptissue.fem.cudss`; the optional extra ``warptissue[gpu]``): analysis once per
  mesh, a numerical LDL^T factorization and solve per Newton iteration. The default on CUDA
  where it loads (measured on an H100, see README "Performance").
- ``"cg"``: Warp's preconditioned conjugate gradient (``warp.optim.linear.cg``) on the
  device's own arrays (the CUDA default without cuDSS), with Warp's adaptive factorized sparse
  approximate inverse (FSAI) preconditioner by default: on a 3k-dof nearly incompressible
  indentation tangent (K/mu = 1000) it needed 1020 iterations against 2460 for the diagonal
  (Jacobi) one. The mean-dilatation tangent is symmetric and positive definite at stable
  states. Warp's Krylov solvers are slow on the CPU backend, and nearly incompressible tangents
  are ill conditioned, so expect many iterations; the iteration count is reported.

Dirichlet conditions are imposed by elimination: rows and columns of prescribed dofs are zeroed
with 1 on the diagonal. By default the first Newton iteration of each load increment carries
the prescribed increment to the right-hand side (``-K_fp du_p``), so the predictor is the
linearized solution rather than a jump of the constrained nodes alone. The other predictor,
``"extrapolated"`` (Abaqus's default), starts from the free dofs extrapolated linearly in the
load from the last two converged states: fewer iterations along smooth paths, more at a finely
meshed punch edge (measured, README "Performance").

After each global Newton step, the few nodes that hold most of the residual are relaxed by a
local Newton solve with all other nodes fixed (nonlinear elimination, see
:func:`_nonlinear_elimination`); the convergence test stays global.
"""

from __future__ import annotations

import importlib.util
import math
from dataclasses import dataclass, field, fields
from time import perf_counter
from typing import Any

import numpy as np
import scipy.sparse.linalg
import warp as wp
import warp.sparse as wps

from warptissue.errors import InputError
from warptissue.fem.arrays import DeviceArrays
from warptissue.fem.assembly import Assembler, Assembly, scatter_vectors
from warptissue.fem.cudss import CudssSolver, cudss_available
from warptissue.fem.direct import CpuDirectSolver
from warptissue.fem.timing import NewtonTimings, PhaseTimer

__all__ = [
    "LINEAR_SOLVERS",
    "PREDICTORS",
    "DirichletConditions",
    "LinearSolver",
    "NewtonOptions",
    "QuasistaticResult",
    "SolveInterrupted",
    "solve_quasistatic",
]

LINEAR_SOLVERS = ("auto", "pardiso", "superlu", "cudss", "cg")
PREDICTORS = ("linearized", "extrapolated")
REUSE_BUDGET = 0.5
"""A GMRES solve with old factors (:meth:`LinearSolver.solve_newton`) gives up after this
share of the measured wall time of the last factorization with its solve."""
REUSE_PREDICT_AFTER = 3
"""From this many GMRES iterations on, a solve with old factors also gives up when the mean
residual reduction per iteration so far predicts that it would overrun its budget."""
REUSE_MAX_ITERATIONS = 40
"""Most GMRES iterations of one solve with old factors (the basis is kept in memory)."""


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


def _pardiso_available() -> bool:
    try:
        import pypardiso  # noqa: F401
    except ImportError:
        return False
    return True


@dataclass(frozen=True)
class DirichletConditions:
    """Prescribed displacement components ``u[node, component] = load * value_per_load``.

    Attributes:
        nodes: Node indices, shape (k,), int.
        components: 0, 1 or 2 (x, y, z) for each entry, shape (k,), int.
        values_per_load: Displacement per unit load, shape (k,), m (0 for a fixed dof).
    """

    nodes: np.ndarray
    components: np.ndarray
    values_per_load: np.ndarray

    def __post_init__(self) -> None:
        nodes = np.asarray(self.nodes, dtype=np.int64).ravel()
        comps = np.asarray(self.components, dtype=np.int64).ravel()
        values = np.asarray(self.values_per_load, dtype=np.float64).ravel()
        if not (nodes.shape == comps.shape == values.shape):
            raise InputError("nodes, components and values_per_load must have the same length")
        if comps.size and (comps.min() < 0 or comps.max() > 2):
            raise InputError("components must be 0, 1 or 2", value=comps)
        if not np.all(np.isfinite(values)):
            raise InputError("prescribed values must be finite")
        keys = nodes * 3 + comps
        order = np.argsort(keys, kind="stable")
        keys, values = keys[order], values[order]
        first = np.ones(len(keys), dtype=bool)
        first[1:] = keys[1:] != keys[:-1]
        # duplicates must agree
        group = np.cumsum(first) - 1
        reference = values[first][group]
        if np.any(np.abs(values - reference) > 1e-12 * (1.0 + np.abs(reference))):
            bad = int(keys[np.flatnonzero(np.abs(values - reference) > 0)[0]])
            raise InputError(
                f"conflicting prescribed values for node {bad // 3}, component {bad % 3}"
            )
        object.__setattr__(self, "nodes", (keys[first] // 3).astype(np.int64))
        object.__setattr__(self, "components", (keys[first] % 3).astype(np.int64))
        object.__setattr__(self, "values_per_load", values[first])

    @staticmethod
    def combine(*conditions: DirichletConditions) -> DirichletConditions:
        """Union of several condition sets (shared dofs must prescribe the same value)."""
        return DirichletConditions(
            np.concatenate([c.nodes for c in conditions]),
            np.concatenate([c.components for c in conditions]),
            np.concatenate([c.values_per_load for c in conditions]),
        )

    def mask(self, node_count: int) -> np.ndarray:
        """1.0 where a dof is prescribed, else 0.0, shape (node_count, 3)."""
        out = np.zeros((node_count, 3))
        out[self.nodes, self.components] = 1.0
        return out

    def values(self, load: float, node_count: int) -> np.ndarray:
        """Prescribed displacement field at ``load`` (0 on free dofs), shape (node_count, 3)."""
        out = np.zeros((node_count, 3))
        out[self.nodes, self.components] = load * self.values_per_load
        return out


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
                method = "pardiso" if _pardiso_available() else "superlu"
        if method == "pardiso" and not _pardiso_available():
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
                    self._cudss = CudssSolver(matrix)
            self._cudss.timer = self.timer
            started = perf_counter()
            x = self._cudss.solve(rhs)  # NumPy: ends on the host; CuPy: stays on the device
        else:
            if self.direct is None or self.direct.matrix is not matrix:
                with self.timer.phase("analysis"):
                    self.direct = CpuDirectSolver(matrix, method=self.method)
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
        it with the old factors as a right preconditioner (:func:`warptissue.fem.krylov.gmres`)
        to ``|rhs - matrix x| <= rtol |rhs|``, for at most :data:`REUSE_BUDGET` times the
        measured wall time of the last factorization with its solve; from
        :data:`REUSE_PREDICT_AFTER` iterations on it gives up as soon as its mean residual
        reduction per iteration predicts an overrun. Where it gets there,
        no factorization is made; where not, the matrix is factorized and solved
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
        budget_s = REUSE_BUDGET * self._factorization_s
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

    def _gmres(self, matrix: wps.BsrMatrix, rhs: Any, *, rtol: float, keep_going):
        """GMRES on ``matrix`` preconditioned by the current factors; x (N, 3) of ``rhs``'s
        library (on CUDA the Krylov basis stays on the device either way)."""
        from warptissue.fem.krylov import KrylovOutcome, gmres

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


@dataclass
class QuasistaticResult:
    """Converged states of a displacement-controlled load path.

    Attributes:
        loads: Load factors reached, shape (S,) (a prefix of the requested ones).
        displacement_m: Nodal displacements at each, shape (S, N, 3).
        reaction: ``sum(reaction_weights * f_int)`` at each, shape (S,).
        newton_iterations: Newton iterations per requested load (all substeps), shape (S,).
        linear_iterations: Linear-solver iterations per requested load, shape (S,).
        local_iterations: Local Newton iterations of the nonlinear elimination per requested
            load, shape (S,).
        completed: Whether every requested load converged.
        message: What happened, in one sentence.
        cutbacks: Increment halvings used.
        linear_solver: The linear solver used.
        history: One record per attempted increment (load, converged, iterations,
            local_iterations, reason).
        reaction_sensitivity: ``d reaction / d theta`` at each converged load, shape (S, n),
            for the n parameters of the ``sensitivity`` passed in (n = 0 without one).
        times_s: The time of each converged load of a timed path, s; else the load-step
            number 1..S, shape (S,).
        timings: Where the wall time went, per phase (:class:`warptissue.fem.NewtonTimings`),
            when the path was profiled (``profile=True``); else None.
        linear_solver_statistics: The linear solver's counts over the path:
            ``factorizations``, ``reused_solves`` (Newton solves by GMRES with earlier
            factors, :meth:`LinearSolver.solve_newton`), ``krylov_iterations`` and
            ``failed_reuses`` (GMRES attempts that gave up for a factorization).
    """

    loads: np.ndarray
    displacement_m: np.ndarray
    reaction: np.ndarray
    newton_iterations: np.ndarray
    linear_iterations: np.ndarray
    local_iterations: np.ndarray
    completed: bool
    message: str
    cutbacks: int = 0
    linear_solver: str = ""
    history: list[dict] = field(default_factory=list)
    reaction_sensitivity: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    times_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    timings: NewtonTimings | None = None
    linear_solver_statistics: dict[str, int] = field(default_factory=dict)


def _norm(values: np.ndarray) -> float:
    """Euclidean norm of all entries.

    ``np.einsum`` sums in NumPy's own loop; ``np.linalg.norm`` goes through the BLAS dot
    product, whose thread start-up costs about 100x more on the (N, 3) arrays of the Newton
    loop on a busy 2-core machine.
    """
    return math.sqrt(float(np.einsum("ij,ij->", values, values)))


@dataclass
class _Step:
    """Outcome of one load increment's Newton iterations.

    ``residual`` is the internal force at ``displacement`` (N, 3), N, of a converged step:
    a view of the assembler's residual where it lives on the CPU, valid until the next
    assembly (the reaction is summed from it at once, without assembling again).
    """

    converged: bool
    displacement: np.ndarray
    iterations: int
    linear_iterations: int
    reason: str
    local_iterations: int = 0
    from_guess: bool = False
    residual: np.ndarray | None = None


@dataclass
class _Search:
    """Outcome of a line search: the accepted state and its assembly (None if none).

    ``current``: the assembler's residual buffer still holds ``assembly`` (the accepted state
    was the last one assembled), so its residual needs no new assembly.
    """

    alpha: float
    state: np.ndarray
    assembly: Assembly | None
    reason: str = ""
    current: bool = False


def _first_iteration_step(
    assembler: Assembler, start: Any, direction: Any, *, arrays: DeviceArrays | None = None
) -> _Search:
    """Step of a load increment's first iteration (prescribed increment applied whole).

    The state with only the prescribed dofs moved is no reference for a descent test, so the
    free part of the step is only halved while an element inverts. ``start`` and
    ``direction`` (N, 3), m, are arrays of ``arrays`` (None: of the assembler's device).
    """
    if arrays is None:  # called alone: the device's arrays, on Warp's stream
        arrays = DeviceArrays(assembler.device)
        with arrays.context():
            return _first_iteration_step(assembler, start, direction, arrays=arrays)
    start, direction = arrays.asarray(start), arrays.asarray(direction)
    alpha = 1.0
    for _ in range(8):
        trial = start + alpha * direction
        check = assembler.assemble(trial, with_tangent=False)
        if check.min_jacobian > 0.0 and math.isfinite(check.energy_J):
            return _Search(alpha, trial, check, current=True)
        alpha *= 0.5
    return _Search(alpha, start, None, "an element inverted (J <= 0)")


def _line_search(
    assembler: Assembler,
    u: Any,
    direction: Any,
    free: Any,
    energy_J: float,
    slope: float,
    residual_norm: float,
    *,
    max_evaluations: int = 10,
    curvature: float = 0.5,
    arrays: DeviceArrays | None = None,
) -> _Search:
    """Step length along a Newton direction of the free dofs.

    The full step is taken when it decreases the energy (Armijo) or the free residual, and
    the directional derivative of the energy has dropped to ``curvature`` times its start
    value (or is still negative). Otherwise a safeguarded secant search on that derivative,
    ``g(alpha) = r(u + alpha d) . d`` (free dofs), brackets the energy minimum along the
    direction; states with an inverted element shrink the bracket. A residual-only assembly
    is far cheaper than the factorization of a Newton iteration, so a few of them that save
    an iteration pay for themselves.

    Args:
        assembler: The discretized body.
        u: Current displacement (N, 3), m.
        direction: Newton direction, zero on prescribed dofs (N, 3), m.
        free: 1 on free dofs, 0 on prescribed ones (N, 3).
        energy_J: Energy at ``u``, J.
        slope: ``g(0)``, J.
        residual_norm: Free residual norm at ``u``, N.
        max_evaluations: Residual assemblies allowed.
        curvature: The strong-Wolfe factor on ``|g|``.
        arrays: The array library of ``u``, ``direction`` and ``free`` (None: that of the
            assembler's device, :class:`warptissue.fem.arrays.DeviceArrays`); each trial
            reads two scalars from the device.

    Returns:
        The accepted step, or the one with the lowest energy that passed the decrease test,
        or a failed :class:`_Search`.
    """
    if arrays is None:  # called alone: the device's arrays, on Warp's stream
        arrays = DeviceArrays(assembler.device)
        with arrays.context():
            return _line_search(
                assembler,
                u,
                direction,
                free,
                energy_J,
                slope,
                residual_norm,
                max_evaluations=max_evaluations,
                curvature=curvature,
                arrays=arrays,
            )
    u, direction, free = arrays.asarray(u), arrays.asarray(direction), arrays.asarray(free)
    low, g_low = 0.0, slope
    high, g_high = math.inf, math.nan
    alpha = 1.0
    best: _Search | None = None
    best_energy = math.inf
    inverted = False
    for _ in range(max_evaluations):
        trial = u + alpha * direction
        check = assembler.assemble(trial, with_tangent=False)
        if check.min_jacobian <= 0.0 or not math.isfinite(check.energy_J):
            inverted = True
            high, g_high = alpha, math.nan
        else:
            free_residual = arrays.view(check.residual) * free
            g, squared = arrays.floats(
                arrays.dot(free_residual, direction), arrays.squared_norm(free_residual)
            )
            decrease = (
                check.energy_J <= energy_J + 1e-4 * alpha * slope
                or math.sqrt(squared) < residual_norm
            )
            if decrease and (abs(g) <= curvature * abs(slope) or (g < 0.0 and alpha >= 1.0)):
                return _Search(alpha, trial, check, current=True)
            if decrease and check.energy_J < best_energy:
                best, best_energy = _Search(alpha, trial, check), check.energy_J
            if g < 0.0 and decrease:
                low, g_low = alpha, g
            else:
                high, g_high = alpha, g
        if slope >= 0.0:
            # Not a descent direction (indefinite tangent): plain halving.
            alpha *= 0.5
            continue
        width = high - low
        if math.isfinite(g_high) and g_high > g_low:
            alpha = low - g_low * width / (g_high - g_low)
            alpha = min(max(alpha, low + 0.1 * width), high - 0.1 * width)
        else:
            alpha = low + 0.5 * width
    if best is not None:
        return best
    reason = "an element inverted (J <= 0)" if inverted else "the line search found no decrease"
    return _Search(alpha, u, None, reason)


def _nonlinear_elimination(
    assembler: Assembler,
    assembly: Assembly,
    u: Any,
    free: Any,
    limit: float,
    *,
    seed_count: int = 50,
    max_iterations: int = 4,
    ratio: float = 0.3,
    arrays: DeviceArrays | None = None,
) -> tuple[Any, Assembly, int]:
    """Relax the nodes that hold most of the residual, all other nodes fixed.

    The patch is the (up to) ``seed_count`` free nodes with the largest residual (at least
    1e-3 of the largest) and their neighbours; where it would hold more than a quarter of the
    nodes the residual is not local and nothing is done. Newton's method on the patch alone
    (its block of the tangent, a sparse direct solve, backtracking until the energy decreases
    (Armijo), every J > 0 and the whole free residual norm decreases) runs until the patch's
    residual norm is below ``ratio`` times the rest's, or the whole residual is below
    ``limit``, or ``max_iterations``; it stops early where the patch's tangent gives no
    descent or no step passes.

    Args:
        assembler: The discretized body.
        assembly: Residual and tangent at ``u`` (the tangent not yet eliminated).
        u: Current displacement (N, 3), m.
        free: 1 on free dofs, 0 on prescribed ones (N, 3).
        limit: The global convergence limit on the free residual norm, N.
        seed_count: Most nodes taken by residual size.
        max_iterations: Local Newton iterations.
        ratio: Stop when the patch's residual is this fraction of the rest's.
        arrays: The array library of ``u`` and ``free`` (None: that of the assembler's
            device, :class:`warptissue.fem.arrays.DeviceArrays`). The arrays of the whole
            mesh stay there; only the patch's and its tets' nodes go to the host.

    Returns:
        (displacement (N, 3), an array of ``arrays``; its assembly; local iterations
        taken). The assembly's residual is that of the returned displacement; after an
        accepted local step its tangent is not assembled (``assembly.matrix`` is None, and
        the assembler's matrix holds only the patch's blocks correctly): the caller
        assembles it where it needs one, which it does not at a converged state. The trials
        and the patch's tangents assemble only the tets that hold a patch node
        (:meth:`warptissue.fem.Assembler.assemble_part`); the whole residual and energy are
        updated by their change, and ``min_jacobian`` is the smaller of the one passed in
        and the patch's.

    Notes:
        Nonlinear elimination (Lanzkron, Rose and Wilkes 1996; Cai and Li 2011, SIAM J. Sci.
        Comput. 33). At the singular edge of a bonded punch the energy stiffens far beyond
        its quadratic model: after a global step the residual sits on a few dozen nodes there,
        and the next global step overshoots them (on the 86 400-tet benchmark the energy
        minimum along it lay at 0.2-0.6 of the step), costing extra factorizations. Relaxing
        them locally costs a few assemblies of the patch's tets and a small solve; the global
        convergence test is unchanged, so the converged state is the same.
    """
    if arrays is None:  # called alone: the device's arrays, on Warp's stream
        arrays = DeviceArrays(assembler.device)
        with arrays.context():
            return _nonlinear_elimination(
                assembler,
                assembly,
                u,
                free,
                limit,
                seed_count=seed_count,
                max_iterations=max_iterations,
                ratio=ratio,
                arrays=arrays,
            )
    xp = arrays.xp
    u, free = arrays.asarray(u), arrays.asarray(free)
    residual = arrays.view(assembly.residual)
    free_residual = residual * free
    norms = arrays.row_norms(free_residual)
    count = min(seed_count, len(norms))
    seeds = xp.argpartition(norms, len(norms) - count)[len(norms) - count :]
    seeds, seed_norms = arrays.host(seeds), arrays.host(norms[seeds])
    largest = float(seed_norms.max())
    if largest == 0.0:
        return u, assembly, 0
    seeds = seeds[seed_norms >= 1e-3 * largest]
    patch = assembler.node_patch(seeds)
    if 4 * len(patch) > assembler.node_count:
        return u, assembly, 0
    # Only the tets holding a patch node change, and with them the residual at their nodes:
    # the whole residual and energy follow from the last ones and the change of that part.
    # The host works on the part's nodes alone (no array of the whole mesh per trial).
    part = assembler.element_part(nodes=patch)
    nodes = part.nodes
    nodes_at = xp.asarray(nodes)
    patch_at = xp.asarray(patch)
    at_patch = np.searchsorted(nodes, patch)
    free_part = arrays.host(free[nodes_at])
    free_patch = free_part[at_patch]
    patch_free = free_patch.reshape(-1) > 0.5
    residual_part = arrays.host(residual[nodes_at])
    device = assembler.device
    patch_wp = wp.array(patch.astype(np.int32), dtype=wp.int32, device=device)
    patch_values = wp.zeros(len(patch), dtype=wp.vec3d, device=device)
    trial_state = u.copy()  # the trials are scattered into it
    u_device = arrays.warp(trial_state)
    outside = xp.ones(len(u), dtype=bool)
    outside[nodes_at] = False
    rest_squared, total_squared = arrays.floats(
        arrays.squared_norm(free_residual[outside]), arrays.squared_norm(free_residual)
    )
    total = math.sqrt(total_squared)
    forces, part_energy, _ = assembler.assemble_part(u_device, part)
    u_patch = arrays.host(u[patch_at])
    energy = assembly.energy_J
    min_jacobian = assembly.min_jacobian
    iterations = 0
    for _ in range(max_iterations):
        if iterations:  # the patch's tangent at the new state (the whole matrix is spoilt)
            forces, part_energy, _ = assembler.assemble_part(u_device, part, with_tangent=True)
        local_residual = (residual_part[at_patch] * free_patch).reshape(-1)[patch_free]
        step = _patch_solve(assembler, patch, patch_free, local_residual)
        if step is None:
            break
        slope = float(local_residual @ step)
        if not (np.all(np.isfinite(step)) and slope < 0.0):
            break
        patch_step = np.zeros(3 * len(patch))
        patch_step[patch_free] = step
        direction = patch_step.reshape(-1, 3)
        alpha, accepted = 1.0, None
        for _ in range(8):
            trial = u_patch + alpha * direction
            patch_values.assign(trial)
            scatter_vectors(patch_values, patch_wp, u_device)
            trial_forces, trial_part_energy, trial_min_jacobian = assembler.assemble_part(
                u_device, part
            )
            trial_residual = residual_part + (trial_forces - forces)
            trial_energy = energy + (trial_part_energy - part_energy)
            trial_free = trial_residual * free_part
            trial_total = math.sqrt(rest_squared + np.einsum("ij,ij->", trial_free, trial_free))
            if (
                trial_min_jacobian > 0.0
                and math.isfinite(trial_energy)
                and trial_energy <= energy + 1e-4 * alpha * slope
                and trial_total < total
            ):
                accepted = trial
                break
            alpha *= 0.5
        if accepted is None:
            break
        iterations += 1
        u_patch, residual_part, energy, total = accepted, trial_residual, trial_energy, trial_total
        forces, part_energy = trial_forces, trial_part_energy
        min_jacobian = min(min_jacobian, trial_min_jacobian)
        local = _norm(residual_part[at_patch] * free_patch)
        if total <= limit or local <= ratio * math.sqrt(max(total**2 - local**2, 0.0)):
            break
    if iterations == 0:
        # Nothing moved and the tangent is untouched (it is only reassembled after a step).
        return u, assembly, 0
    u = u.copy()
    u[patch_at] = arrays.asarray(u_patch)
    residual = residual.copy()
    residual[nodes_at] = arrays.asarray(residual_part)
    assembly = Assembly(
        residual=assembler.set_residual(residual),
        matrix=None,
        energy_J=energy,
        min_jacobian=min_jacobian,
    )
    return u, assembly, iterations


REUSE_STATE_CHANGE = 0.5
"""A Newton solve tries the last factorization only where the state has moved less than this
fraction of the last load increment's first Newton step since the factorized tangent was
assembled (:class:`_ReuseTracker`)."""


@dataclass
class _ReuseTracker:
    """Where the factorized tangent was assembled, for :meth:`LinearSolver.solve_newton`.

    Measured on the flat-punch benchmark (2 471 tets, 3 Newton iterations per load step):
    the first iteration of a step (its tangent at the last converged state, the factors of
    the step before's second iteration) and the third (a small correction since the second)
    were solved by GMRES in 2-4 iterations, while the second, after the first iteration's
    long step, failed in every step. So a solve tries the old factors only where the state
    has moved by less than :data:`REUSE_STATE_CHANGE` times the last first-iteration step
    (``step_scale``) since the factorization, with the same damping; the time budget of
    :meth:`LinearSolver.solve_newton` still decides the rest.

    Attributes:
        state: The displacement (N, 3) whose tangent was factorized last (an array of the
            Newton loop's :class:`warptissue.fem.arrays.DeviceArrays`), or None.
        damping: The Levenberg-Marquardt factor of that factorization.
        step_scale: Norm of the free part of the last first Newton step of an increment, m.
    """

    state: Any = None
    damping: float = 0.0
    step_scale: float = math.inf

    def promising(self, u: Any, damping: float, arrays: DeviceArrays) -> bool:
        """Whether a solve at ``u`` (an array of ``arrays``) with ``damping`` should try the
        old factors."""
        if self.state is None or damping != self.damping:
            return False
        return arrays.norm(u - self.state) <= REUSE_STATE_CHANGE * self.step_scale

    def factorized(self, u: Any, damping: float) -> None:
        """The tangent at ``u`` with ``damping`` was just factorized."""
        self.state, self.damping = u, damping


FORCING_MAX = 1.0e-3
"""Loosest relative residual of a Newton step solved by GMRES with old factors."""
FORCING_MIN = 1.0e-10
"""Tightest relative residual asked of such a solve (a direct solve's roundoff)."""


def _forcing_term(limit: float, rhs_norm: float) -> float:
    """Relative residual of a Newton step solved with old factors (GMRES).

    A tenth of the Newton loop's convergence limit on the free residual, relative to the
    right-hand side, within [:data:`FORCING_MIN`, :data:`FORCING_MAX`]: far from the
    solution the step needs only to point the right way, near it the linear residual must
    not keep the nonlinear one above the limit (Eisenstat and Walker 1996, SIAM J. Sci.
    Comput. 17, "choosing the forcing terms"; here tied to the final tolerance rather than
    to the last residual reduction).
    """
    if rhs_norm <= 0.0 or not math.isfinite(rhs_norm):
        return FORCING_MAX
    return min(FORCING_MAX, max(0.1 * limit / rhs_norm, FORCING_MIN))


def _patch_solve(
    assembler: Assembler, patch: np.ndarray, patch_free: np.ndarray, local_residual: np.ndarray
) -> np.ndarray | None:
    """The patch's Newton step ``-K_pp^-1 r_p`` on its free dofs, or None where singular.

    On a CUDA device with CuPy the patch's tangent is written dense on the device and solved
    there by LU (cuSOLVER; a patch holds at most a few thousand dofs), so nothing but the
    step leaves the device; on the CPU its sparse block goes to SciPy's SuperLU.
    """
    if assembler.device.is_cuda and importlib.util.find_spec("cupy") is not None:
        import cupy

        stream = cupy.cuda.Stream.from_external(assembler.device.stream)
        with cupy.cuda.Device(assembler.device.ordinal), stream:
            dense = cupy.asarray(assembler.tangent_submatrix_dense(patch))
            free_dofs = cupy.asarray(np.flatnonzero(patch_free))
            matrix = dense[free_dofs[:, None], free_dofs[None, :]]
            try:
                step = cupy.linalg.solve(matrix, cupy.asarray(-local_residual))
            except cupy.linalg.LinAlgError:
                return None
            return cupy.asnumpy(step, stream=stream)  # non-finite where singular: refused
    matrix = assembler.tangent_submatrix(patch)[patch_free][:, patch_free]
    try:
        return scipy.sparse.linalg.splu(matrix.tocsc()).solve(-local_residual)
    except RuntimeError:
        return None


DAMPING_START = 1.0
"""Levenberg-Marquardt factor lambda set when the line search first cuts a step below
:data:`DAMPING_CUT` (each free diagonal entry K_ii of the tangent becomes K_ii + lambda |K_ii|);
multiplied by 4 at each further cut, divided by 4 after each full step and dropped to 0 below
``DAMPING_START / 8``."""
DAMPING_CUT = 0.25


def _next_damping(factor: float, alpha: float) -> float:
    """The damping factor for the next Newton iteration, after a step of length ``alpha``.

    Notes:
        Levenberg (1944), Marquardt (1963), with Marquardt's scaling by the diagonal; the
        update follows the line search instead of a trust-region ratio. At a finely meshed
        punch edge a large load increment leaves the tangent of the predictor state a poor
        model: undamped, the line search cut many Newton steps there to 0.002-0.05 of their
        length. Damped, the steps shorten and turn toward the scaled steepest descent, and
        are taken whole; with the factor dropped again after full steps, the quadratic
        convergence near the solution is kept. The converged state is the same.
    """
    if alpha < DAMPING_CUT:
        return max(4.0 * factor, DAMPING_START)
    if alpha >= 1.0:
        return factor / 4.0 if factor > DAMPING_START / 8.0 else 0.0
    return factor


def _newton_increment(
    assembler: Assembler,
    solver: LinearSolver,
    u_start: Any,
    prescribed_increment: Any,
    free: Any,
    constrained_wp: wp.array,
    *,
    tolerance: float,
    force_floor: float,
    max_iterations: int,
    nonlinear_elimination: bool,
    free_guess: Any = None,
    damping: bool = False,
    reuse_factorization: bool = False,
    reuse: _ReuseTracker | None = None,
    timer: PhaseTimer | None = None,
) -> _Step:
    """Newton iterations for one load increment, starting from a converged state.

    ``u_start``, ``prescribed_increment`` and ``free`` (N, 3): NumPy, or arrays of the
    solver's :class:`warptissue.fem.arrays.DeviceArrays` (CuPy on a CUDA device), which the
    iterations work in: on a GPU the state, residual, directions and trial states stay on
    the device, and each iteration reads only scalars (norms, slopes, energies) from it.
    The returned displacement and residual are arrays of that library.

    ``free_guess`` (N, 3), m: a predicted change of the free dofs over the increment. Where
    the state it gives (with the prescribed increment applied) has no inverted element, the
    iterations start there; otherwise, and without a guess, from the linearized predictor.

    ``damping``: adaptive Levenberg-Marquardt damping of the tangent's free diagonal (see
    :data:`DAMPING_START`); off, every iteration solves with the plain tangent.

    ``reuse_factorization``: solve with the last factorization by GMRES where that is
    cheaper (:meth:`LinearSolver.solve_newton`, to the relative residual of
    :func:`_forcing_term`), and where ``reuse`` (a :class:`_ReuseTracker` kept over the load
    path; None: a new one) finds the state close to the factorized one; off, every
    iteration factorizes.

    ``timer``: the :class:`warptissue.fem.timing.PhaseTimer` the phases are charged to
    (None: not timed).
    """
    arrays = solver.arrays
    if reuse is None:
        reuse = _ReuseTracker()
    if timer is None:
        timer = PhaseTimer(enabled=False)
    with arrays.context():
        u_start, prescribed_increment, free = (
            arrays.asarray(values) for values in (u_start, prescribed_increment, free)
        )
        if free_guess is not None:
            free_guess = arrays.asarray(free_guess)
        u = u_start.copy()
        fixed = 1.0 - free
        linear_total = 0
        local_total = 0
        increment_wp = arrays.warp(prescribed_increment)
        k_times_increment = wp.zeros_like(increment_wp)
        linearized = True
        if free_guess is not None:
            guess = u_start + prescribed_increment + free_guess * free
            with timer.phase("assembly"):
                assembly = assembler.assemble(guess)
            if assembly.min_jacobian > 0.0 and math.isfinite(assembly.energy_J):
                u, linearized = guess, False
        if linearized:
            with timer.phase("assembly"):
                assembly = assembler.assemble(u)
        residual = arrays.view(assembly.residual)
        limit = max(tolerance * arrays.norm(residual * fixed), force_floor)

        def outcome(converged: bool, iteration: int, reason: str) -> _Step:
            return _Step(
                converged,
                u,
                iteration,
                linear_total,
                reason,
                local_total,
                from_guess=not linearized,
                residual=residual if converged else None,
            )

        factor = 0.0
        for iteration in range(1, max_iterations + 1):
            first = iteration == 1 and linearized
            if first:
                wps.bsr_mv(assembly.matrix, increment_wp, k_times_increment, alpha=1.0, beta=0.0)
                k_du = arrays.view(k_times_increment)
                rhs = -(residual + k_du) * free + prescribed_increment
            else:
                rhs = -residual * free
            with timer.phase("assembly"):
                assembler.eliminate(constrained_wp, damping=factor)
            factorizations = solver.factorizations
            du, linear_iterations = solver.solve_newton(
                assembly.matrix,
                rhs,
                rtol=_forcing_term(limit, arrays.norm(rhs)),
                reuse=reuse_factorization and reuse.promising(u, factor, arrays),
            )
            if solver.factorizations > factorizations:
                reuse.factorized(u, factor)
            linear_total += linear_iterations
            free_du = du * free
            free_residual = residual * free
            du_squared, old_squared, slope, free_du_squared = arrays.floats(
                arrays.squared_norm(du),
                arrays.squared_norm(free_residual),
                arrays.dot(free_residual, du),
                arrays.squared_norm(free_du),
            )
            if not math.isfinite(du_squared):
                return outcome(False, iteration, "the linear solve gave non-finite values")
            if first:
                reuse.step_scale = math.sqrt(free_du_squared)
            old_norm = math.sqrt(old_squared)
            with timer.phase("line_search"):
                if first:
                    search = _first_iteration_step(
                        assembler, u + prescribed_increment, free_du, arrays=arrays
                    )
                else:
                    search = _line_search(
                        assembler,
                        u,
                        free_du,
                        free,
                        assembly.energy_J,
                        slope,
                        old_norm,
                        arrays=arrays,
                    )
            if search.assembly is None:
                return outcome(False, iteration, search.reason)
            u, alpha = search.state, search.alpha
            if damping and not first:
                factor = _next_damping(factor, alpha)
            if search.current:
                # The line search's residual at u; the tangent only where another iteration
                # (or the elimination) needs it, not at the converged state.
                assembly = search.assembly
            else:
                with timer.phase("assembly"):
                    assembly = assembler.assemble(u)
            residual = arrays.view(assembly.residual)
            free_norm, reaction_norm = _residual_norms(arrays, residual, free, fixed)
            limit = max(tolerance * reaction_norm, force_floor)
            if nonlinear_elimination and free_norm > limit:
                if assembly.matrix is None:
                    with timer.phase("assembly"):
                        assembly = assembler.assemble(u)
                    residual = arrays.view(assembly.residual)
                with timer.phase("elimination"):
                    u, assembly, local = _nonlinear_elimination(
                        assembler, assembly, u, free, limit, arrays=arrays
                    )
                local_total += local
                if local:
                    residual = arrays.view(assembly.residual)
                    free_norm, reaction_norm = _residual_norms(arrays, residual, free, fixed)
                    limit = max(tolerance * reaction_norm, force_floor)
            step_squared, increment_squared = arrays.floats(
                arrays.squared_norm(alpha * free_du), arrays.squared_norm(u - u_start)
            )
            # A correction at roundoff relative to the increment means the residual sits at its
            # roundoff floor (large bulk moduli raise it): accept if it is small anyway.
            at_roundoff = math.sqrt(step_squared) <= 1e-10 * math.sqrt(increment_squared)
            if free_norm <= limit or (at_roundoff and free_norm <= 1e-6 * reaction_norm):
                return outcome(True, iteration, "converged")
            if not math.isfinite(free_norm):
                return outcome(False, iteration, "the residual became non-finite")
            if assembly.matrix is None:  # the next iteration's tangent
                with timer.phase("assembly"):
                    assembly = assembler.assemble(u)
                residual = arrays.view(assembly.residual)
        return outcome(False, max_iterations, f"no convergence in {max_iterations} iterations")


def _residual_norms(
    arrays: DeviceArrays, residual: Any, free: Any, fixed: Any
) -> tuple[float, float]:
    """Norms of the free and of the prescribed part of a residual (one read), N."""
    free_squared, fixed_squared = arrays.floats(
        arrays.squared_norm(residual * free), arrays.squared_norm(residual * fixed)
    )
    return math.sqrt(free_squared), math.sqrt(fixed_squared)


CONTACT_PENALTY_RAMP = 0.1
"""Under rigid contact (a sphere, a wedge or a rounded punch; not a plate, whose contact
covers the whole surface) each load increment is first solved with the penalty stiffness
times this factor (to :data:`CONTACT_RAMP_TOLERANCE`), then with the full stiffness from there
(:func:`_penalty_ramped_increment`); 1 solves with the full stiffness at once."""
CONTACT_RAMP_TOLERANCE = 1.0e-3
"""Relative tolerance of the softened first stage of a contact increment."""


def _penalty_ramped_increment(
    assembler: Assembler,
    solver: LinearSolver,
    u_start: np.ndarray,
    prescribed_increment: np.ndarray,
    free: np.ndarray,
    constrained_wp: wp.array,
    *,
    tolerance: float,
    **options: Any,
) -> _Step:
    """One load increment under rigid contact: a softened penalty first, then the full one.

    The increment is solved by :func:`_newton_increment` with the contact's penalty stiffness
    k times :data:`CONTACT_PENALTY_RAMP` to the loose :data:`CONTACT_RAMP_TOLERANCE`, then
    with k from that state (no prescribed increment left) to ``tolerance``. The converged
    state is that of k alone; the iterations of both stages are counted.

    Notes:
        With ``k = beta mu0 h`` and beta = 1000, a node that a Newton step carries into the
        indenter meets a wall a thousand times stiffer than the tissue: the line search cuts
        the step where the first such node enters and the damping keeps the next steps
        short, so each ring of nodes that the contact edge passes costs iterations (a rounded
        punch on a 3 360-tet block: 10, 22, 61 at depths 0.02, 0.05, 0.1 a). With k / 10 the
        nodes enter gently; from the converged soft state the full penalty only moves the
        contact nodes by their penetration (a tenth of the soft one), which takes about three
        iterations. Measured in docs/design-notes/contact-newton.md. This is a continuation
        in the penalty parameter (Wriggers, Computational Contact Mechanics, 2006, ch. 6:
        a penalty increased during the solution).
    """
    contact = assembler.contact
    stiffness = contact.stiffness_N_per_m
    contact.stiffness_N_per_m = stiffness * CONTACT_PENALTY_RAMP
    try:
        soft = _newton_increment(
            assembler,
            solver,
            u_start,
            prescribed_increment,
            free,
            constrained_wp,
            tolerance=max(tolerance, CONTACT_RAMP_TOLERANCE),
            **options,
        )
    finally:
        contact.stiffness_N_per_m = stiffness
    if not soft.converged:
        return soft
    stiff = _newton_increment(
        assembler,
        solver,
        soft.displacement,
        0.0 * soft.displacement,
        free,
        constrained_wp,
        tolerance=tolerance,
        **(options | {"free_guess": None}),
    )
    stiff.iterations += soft.iterations
    stiff.linear_iterations += soft.linear_iterations
    stiff.local_iterations += soft.local_iterations
    stiff.from_guess = soft.from_guess
    return stiff


class SolveInterrupted(KeyboardInterrupt):
    """Ctrl-C during a solve, carrying the load steps that converged before it.

    A :class:`KeyboardInterrupt`, so that code that does not look for it stops as usual.

    Args:
        message: What was interrupted, and how many steps are kept.
        partial_result: The result of the converged steps (``completed=False``): a
            :class:`QuasistaticResult` from :func:`solve_quasistatic`, an
            :class:`warptissue.fem.IndentationResult` from
            :func:`warptissue.fem.simulate_indentation`.
    """

    def __init__(self, message: str, *, partial_result: Any) -> None:
        super().__init__(message)
        self.message = message
        self.partial_result = partial_result


def _checked_options(options: NewtonOptions | None) -> NewtonOptions:
    """The options, or the defaults for None; anything else is refused."""
    if options is None:
        return NewtonOptions()
    if not isinstance(options, NewtonOptions):
        raise InputError(
            "options must be a warptissue.fem.NewtonOptions", value=type(options).__name__
        )
    return options


def solve_quasistatic(
    assembler: Assembler,
    conditions: DirichletConditions,
    loads: np.ndarray,
    *,
    reaction_weights: np.ndarray | None = None,
    options: NewtonOptions | None = None,
    progress: bool = False,
    progress_label: str = "load steps",
    load_name: str = "load",
    initial_displacement_m: np.ndarray | None = None,
    sensitivity: Any = None,
    times_s: np.ndarray | None = None,
    profile: bool = False,
) -> QuasistaticResult:
    """Follow a displacement-controlled load path with Newton's method.

    Each requested load is reached from the previous converged one in one increment; when
    Newton fails (no convergence, no line-search decrease, or an inverted element) the
    increment is halved and retried, up to ``max_cutbacks`` halvings, and grows back after
    successes. When the halvings run out the path stops there, keeping what converged.

    Args:
        assembler: The discretized body. Its ``set_load(load)`` (where it has one) is called
            before each load increment and cutback with the load the increment goes to: a
            rigid contact's depth follows it (:meth:`warptissue.fem.Assembler.set_load`).
        conditions: Prescribed dofs, ``u = load * values_per_load``.
        loads: Increasing (or any) sequence of load factors, shape (S,).
        reaction_weights: Weights (N, 3) of the internal forces summed into ``reaction``
            (None: zeros).
        options: The Newton solver's settings (:class:`NewtonOptions`; None: the defaults).
            Converged when ``|f_int free| <= options.tolerance * |f_int prescribed|`` (or
            below a roundoff floor ``1e-13 mu0 L^2``). ``options.predictor``:
            ``"linearized"`` starts each increment from the converged state plus the
            tangent's response to the prescribed increment; ``"extrapolated"`` (after the
            first increment) from the free dofs extrapolated linearly in the load from the
            last two converged states, and where that state inverts an element, or Newton
            fails from it, the increment runs again from the linearized predictor before any
            cutback. ``options.nonlinear_elimination`` relaxes, after each global Newton step,
            the nodes that hold most of the residual with the others fixed
            (:func:`_nonlinear_elimination`). ``options.damping``: where the line search cuts
            a Newton step below a quarter of its length, the next iterations' tangent is
            damped (Levenberg-Marquardt, :func:`_next_damping`) until steps are taken whole
            again. These three change the path to the solution, not the convergence test.
        progress: Show a tqdm bar over the requested loads.
        progress_label: The bar's label.
        load_name: What the load is called in messages (e.g. ``"depth (m)"``).
        initial_displacement_m: Start state (N, 3); zero by default (load 0).
        sensitivity: A :class:`warptissue.fem.sensitivity.ForceSensitivity` of this
            assembler and these conditions: its ``at_converged_state`` runs at each converged
            requested load, after Newton (with Newton's linear solver), into
            ``reaction_sensitivity`` (with a viscous history: at every converged substep,
            which advances the history's derivatives).
        times_s: The time of each load, shape (S,), s, strictly increasing from t = 0 (the
            unloaded start): a timed path. Between two requested loads the load is linear in
            time, and cutbacks split both. Needed by a viscoelastic material
            (``assembler.viscous``), whose history is advanced after every converged
            (sub)step (:mod:`warptissue.fem.viscous`); an elastic one ignores time. None: a
            quasi-static path.
        profile: Time each phase of the Newton iterations (assembly, factorization, solve,
            line search, nonlinear elimination, sensitivities, host work) into the result's
            ``timings`` (:mod:`warptissue.fem.timing`). On a CUDA device this synchronizes
            the device at every phase boundary; off, nothing is timed.

    Returns:
        A :class:`QuasistaticResult`.

    Raises:
        InputError: Non-finite loads, mis-shaped weights, or options that are not a
            :class:`NewtonOptions`.
    """
    started = perf_counter()
    loads = np.atleast_1d(np.asarray(loads, dtype=np.float64))
    if loads.ndim != 1 or not np.all(np.isfinite(loads)):
        raise InputError("loads must be a finite 1-D sequence", value=loads)
    if times_s is not None:
        times = np.atleast_1d(np.asarray(times_s, dtype=np.float64))
        if times.shape != loads.shape or not np.all(np.isfinite(times)):
            raise InputError(
                f"times_s must be finite, one per load ({loads.size})", value=times.shape
            )
        steps = np.diff(np.concatenate([[0.0], times]))
        if np.any(steps <= 0.0):
            raise InputError(
                "times_s must be positive and strictly increasing (the path starts at t = 0)",
                key="times_s",
                value=times[: int(np.argmax(steps <= 0.0)) + 1].tolist()[-2:],
            )
    else:
        times = None
    options = _checked_options(options)
    n = assembler.node_count
    weights = np.zeros((n, 3)) if reaction_weights is None else np.asarray(reaction_weights)
    if weights.shape != (n, 3):
        raise InputError(f"reaction_weights must have shape ({n}, 3)", value=weights.shape)
    viscous = getattr(assembler, "viscous", None)
    if viscous is not None and times is None:
        raise InputError(
            "a viscoelastic material needs the time of each load (times_s)", key="times_s"
        )
    solver = LinearSolver(method=options.linear_solver, device=assembler.device)
    arrays = solver.arrays
    reuse = _ReuseTracker()
    timer = PhaseTimer(enabled=profile, device=assembler.device)
    solver.timer = timer
    mask = conditions.mask(n)
    free = 1.0 - mask
    constrained_wp = wp.array(mask, dtype=wp.vec3d, device=assembler.device)
    u = np.zeros((n, 3)) if initial_displacement_m is None else np.array(initial_displacement_m)
    # The state stays in the Newton loop's arrays (on a GPU: on the device) along the path;
    # the converged states come to the host once per requested load.
    with arrays.context():
        u, free_x, weights_x = arrays.asarray(u), arrays.asarray(free), arrays.asarray(weights)
    # Absolute floor of the residual norm: a roundoff-level force for this body and material.
    length = float(np.sum(assembler.tet_volumes)) ** (1.0 / 3.0)
    shear_modulus = min(material.initial_shear_modulus_Pa for material in assembler.materials)
    force_floor = 1e-13 * shear_modulus * length**2
    load, time = 0.0, 0.0
    # The converged state before the current one (path coordinate, state), for the
    # extrapolated predictor; the path coordinate is the time of a timed path, else the load.
    previous: tuple[float, Any] | None = None
    reached, states, reactions = [], [], []
    newton_counts, linear_counts, local_counts = [], [], []
    sensitivities: list[np.ndarray] = []
    sensitivity_count = 0 if sensitivity is None else len(sensitivity.names)
    message = f"converged at all {len(loads)} requested values of {load_name}"
    completed = True
    total_cutbacks = 0
    history: list[dict] = []
    bar = None

    def outcome(completed: bool, message: str, count: int) -> QuasistaticResult:
        return QuasistaticResult(
            loads=np.array(reached[:count]),
            displacement_m=np.array(states[:count]).reshape(count, n, 3),
            reaction=np.array(reactions[:count]),
            newton_iterations=np.array(newton_counts[:count], dtype=np.int64),
            linear_iterations=np.array(linear_counts[:count], dtype=np.int64),
            local_iterations=np.array(local_counts[:count], dtype=np.int64),
            completed=completed,
            message=message,
            cutbacks=total_cutbacks,
            linear_solver=solver.method,
            history=history,
            reaction_sensitivity=np.array(sensitivities[:count]).reshape(count, sensitivity_count),
            times_s=(np.arange(1.0, count + 1.0) if times is None else np.array(times[:count])),
            timings=(
                timer.timings(
                    total_s=perf_counter() - started, factorizations=solver.factorizations
                )
                if profile
                else None
            ),
            linear_solver_statistics=solver.statistics(),
        )

    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=len(loads), desc=progress_label, unit="step", leave=False)
    try:
        with arrays.context():
            for index, target in enumerate(loads):
                target_time = time if times is None else float(times[index])
                step_newton, step_linear, step_local, halvings = 0, 0, 0, 0
                start_load, start_time = load, time
                fraction, step_fraction = 0.0, 1.0
                retry_linearized = False
                while True:
                    next_fraction = fraction + step_fraction
                    if next_fraction >= 1.0 - 1e-12:
                        next_fraction = 1.0
                    next_load = (
                        target
                        if next_fraction == 1.0
                        else start_load + next_fraction * (target - start_load)
                    )
                    next_time = (
                        target_time
                        if next_fraction == 1.0
                        else start_time + next_fraction * (target_time - start_time)
                    )
                    prescribed = arrays.asarray(
                        conditions.values(next_load, n) - conditions.values(load, n)
                    )
                    if viscous is not None:
                        viscous.begin_step(next_time - time)
                    here, there = (load, next_load) if times is None else (time, next_time)
                    free_guess = None
                    if (
                        options.predictor == "extrapolated"
                        and previous is not None
                        and not retry_linearized
                        and here != previous[0]
                    ):
                        free_guess = (u - previous[1]) * ((there - here) / (here - previous[0]))
                    retry_linearized = False
                    set_load = getattr(assembler, "set_load", None)
                    if set_load is not None:  # a rigid contact's depth follows the load
                        set_load(next_load)
                    contact = getattr(assembler, "contact", None)
                    # A plate touches the whole surface: no contact edge crosses nodes, and the
                    # ramp would only repeat its iterations (4 -> 8-13 per step measured).
                    ramped = contact is not None and contact.indenter.kind != "plate"
                    increment = (
                        _penalty_ramped_increment
                        if ramped and CONTACT_PENALTY_RAMP < 1.0
                        else _newton_increment
                    )
                    step = increment(
                        assembler,
                        solver,
                        u,
                        prescribed,
                        free_x,
                        constrained_wp,
                        tolerance=options.tolerance,
                        force_floor=force_floor,
                        max_iterations=options.max_newton_iterations,
                        nonlinear_elimination=options.nonlinear_elimination,
                        free_guess=free_guess,
                        damping=options.damping,
                        reuse_factorization=options.reuse_factorization,
                        reuse=reuse,
                        timer=timer,
                    )
                    timer.count_iterations(step.iterations)
                    step_newton += step.iterations
                    step_linear += step.linear_iterations
                    step_local += step.local_iterations
                    history.append(
                        {
                            "load": next_load,
                            **({} if times is None else {"time_s": next_time}),
                            "converged": step.converged,
                            "iterations": step.iterations,
                            "local_iterations": step.local_iterations,
                            "reason": step.reason,
                        }
                    )
                    if step.converged:
                        if there != here:
                            previous = (here, u)
                        u, load, time, fraction = (
                            step.displacement,
                            next_load,
                            next_time,
                            next_fraction,
                        )
                        at_target = fraction == 1.0
                        if at_target:
                            # The internal force of the converged state (with the step's frozen
                            # history), as Newton's last assembly left it.
                            (reaction,) = arrays.floats(arrays.dot(weights_x, step.residual))
                        if sensitivity is not None and (at_target or viscous is not None):
                            # A viscous history needs its derivatives advanced at every substep.
                            with timer.phase("sensitivity"):
                                step_sensitivity = sensitivity.at_converged_state(
                                    solver, arrays.host(u)
                                )
                        if viscous is not None:
                            viscous.commit(assembler, assembler.device_displacement(u))
                        if at_target:
                            break
                        step_fraction = min(2.0 * step_fraction, 1.0 - fraction)
                        continue
                    if step.from_guess:
                        # Retry the increment from the linearized predictor before cutting back.
                        retry_linearized = True
                        continue
                    halvings += 1
                    total_cutbacks += 1
                    if halvings > options.max_cutbacks:
                        completed = False
                        message = (
                            f"stopped at {load_name} {load:.6g} on the way to {target:.6g}"
                            + ("" if times is None else f" (t = {time:.6g} s)")
                            + f": Newton failed ({step.reason}) after {options.max_cutbacks} "
                            f"cutbacks (last increment {step_fraction * (target - start_load):.3g}"
                            + (
                                ""
                                if times is None
                                else f" over {step_fraction * (target_time - start_time):.3g} s"
                            )
                            + f"); the {len(reached)} converged steps are kept"
                        )
                        break
                    step_fraction *= 0.5
                if not completed:
                    break
                reached.append(target)
                states.append(arrays.host(u).copy())
                reactions.append(reaction)
                if sensitivity is not None:
                    sensitivities.append(step_sensitivity)
                newton_counts.append(step_newton)
                linear_counts.append(step_linear)
                local_counts.append(step_local)
                if bar is not None:
                    bar.set_postfix(newton_iterations=step_newton, refresh=False)
                    bar.update(1)
    except KeyboardInterrupt as exc:
        # The lists grow in step; the last one appended bounds the consistent prefix.
        count = len(local_counts)
        raise SolveInterrupted(
            f"interrupted on the way to {load_name} {loads[min(count, len(loads) - 1)]:.6g}; "
            f"the {count} converged steps are kept",
            partial_result=outcome(False, "interrupted", count),
        ) from exc
    finally:
        if bar is not None:
            bar.close()
    return outcome(completed, message, len(reached))
