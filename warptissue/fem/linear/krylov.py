"""GMRES preconditioned by an earlier factorization: Newton's solve without a new one.

A Newton iteration's tangent differs little from the one factorized an iteration or a load
step earlier, and a solve with existing factors costs a small part of a factorization
(0.22 s against 1.9 s at 20k TET10 tets with PARDISO on two cores; 4 ms against 162 ms at
78k tets with cuDSS on an H100). :func:`gmres` solves the current tangent with the old
factors as a right preconditioner, so a few solves with them replace a factorization when the
tangent has changed little; :class:`warptissue.fem.LinearSolver` decides per iteration
whether that pays, from the times it measures (see
:meth:`warptissue.fem.LinearSolver.solve_newton`).

The vectors are NumPy arrays on the CPU and CuPy arrays on a CUDA device (the same code,
through ``xp``): on the GPU the Krylov basis stays in device memory, and the host reads two
small arrays of inner products per iteration.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from types import ModuleType
from typing import Any

import numpy as np

__all__ = ["KrylovOutcome", "gmres"]


@dataclass(frozen=True)
class KrylovOutcome:
    """The end of a :func:`gmres` run.

    Attributes:
        x: The last iterate, shape of ``b`` (an ``xp`` array).
        iterations: Preconditioned matrix-vector products taken.
        converged: Whether ``|b - A x| <= rtol |b|`` (the true residual, checked at the end).
        relative_residual: ``|b - A x| / |b|``.
    """

    x: Any
    iterations: int
    converged: bool
    relative_residual: float


def gmres(
    matvec: Callable[[Any], Any],
    precondition: Callable[[Any], Any],
    b: Any,
    *,
    rtol: float,
    max_iterations: int,
    xp: ModuleType = np,
    keep_going: Callable[[int, float], bool] | None = None,
) -> KrylovOutcome:
    """Solve ``A x = b`` by GMRES with right preconditioning, from ``x = 0``.

    Args:
        matvec: ``v -> A v``, on arrays of ``b``'s shape.
        precondition: ``v -> M^-1 v`` (here: a solve with earlier factors), same shapes.
        b: Right-hand side (any shape; treated as one flat vector), NumPy or CuPy.
        rtol: Relative tolerance on the residual norm, in (0, 1).
        max_iterations: Most iterations (no restart), >= 1.
        xp: The array module of ``b`` (``numpy`` or ``cupy``).
        keep_going: Called after each unconverged iteration with the iteration count and
            the relative residual ``|b - A x_k| / |b|`` (from the recurrence); False stops the
            run as unconverged (the caller's budget).

    Returns:
        A :class:`KrylovOutcome`; ``x`` is the minimal-residual iterate reached.

    Notes:
        Saad and Schultz (1986), SIAM J. Sci. Stat. Comput. 7: Arnoldi on ``A M^-1`` with
        classical Gram-Schmidt applied twice (two reductions per iteration, each one
        matrix-vector product on the basis, instead of ``k`` dot products), Givens rotations
        on the Hessenberg matrix for the residual norm, and ``x = M^-1 V y`` at the end.
        Right preconditioning keeps the monitored residual the true one, ``|b - A x|``,
        which is what Newton's convergence needs.
    """
    if not 0.0 < rtol < 1.0:
        raise ValueError(f"rtol must lie in (0, 1), got {rtol}")
    if max_iterations < 1:
        raise ValueError(f"max_iterations must be at least 1, got {max_iterations}")
    shape = b.shape
    flat_b = b.reshape(-1)
    beta = float(xp.linalg.norm(flat_b))
    if beta == 0.0 or not math.isfinite(beta):
        return KrylovOutcome(xp.zeros_like(b), 0, beta == 0.0, 0.0 if beta == 0.0 else math.nan)
    n = flat_b.shape[0]
    m = int(max_iterations)
    basis = xp.empty((m + 1, n), dtype=flat_b.dtype)
    basis[0] = flat_b / beta
    hessenberg = np.zeros((m + 1, m))
    cosines, sines = np.zeros(m), np.zeros(m)
    g = np.zeros(m + 1)
    g[0] = beta
    k = 0
    residual = beta
    while k < m:
        z = precondition(basis[k].reshape(shape)).reshape(-1)
        w = matvec(z.reshape(shape)).reshape(-1)
        # classical Gram-Schmidt, twice; its coefficients and the norm in one read (a
        # non-finite w makes them non-finite)
        h = basis[: k + 1] @ w
        w = w - basis[: k + 1].T @ h
        h2 = basis[: k + 1] @ w
        w = w - basis[: k + 1].T @ h2
        read = _host(xp.concatenate([h, h2, xp.linalg.norm(w).reshape(1)]), xp)
        column, norm = read[: k + 1] + read[k + 1 : -1], float(read[-1])
        if not (np.all(np.isfinite(column)) and math.isfinite(norm)):
            break
        hessenberg[: k + 1, k] = column
        hessenberg[k + 1, k] = norm
        for i in range(k):  # earlier rotations
            a, c = hessenberg[i, k], hessenberg[i + 1, k]
            hessenberg[i, k] = cosines[i] * a + sines[i] * c
            hessenberg[i + 1, k] = -sines[i] * a + cosines[i] * c
        a, c = hessenberg[k, k], hessenberg[k + 1, k]
        radius = math.hypot(a, c)
        if radius == 0.0:
            break
        cosines[k], sines[k] = a / radius, c / radius
        hessenberg[k, k], hessenberg[k + 1, k] = radius, 0.0
        g[k + 1] = -sines[k] * g[k]
        g[k] = cosines[k] * g[k]
        k += 1
        residual = abs(g[k])
        if residual <= rtol * beta or norm == 0.0:
            break
        if keep_going is not None and not keep_going(k, residual / beta):
            break
        basis[k] = w / norm
    if k == 0:
        return KrylovOutcome(xp.zeros_like(b), 0, False, 1.0)
    y = _solve_upper(hessenberg[:k, :k], g[:k])
    combination = basis[:k].T @ xp.asarray(y)
    x = precondition(combination.reshape(shape))
    # The true residual (the recurrence drifts when the preconditioner is far from A^-1).
    true_residual = float(xp.linalg.norm((b - matvec(x)).reshape(-1))) / beta
    return KrylovOutcome(x, k, true_residual <= rtol, true_residual)


def _host(values: Any, xp: ModuleType) -> np.ndarray:
    return values if xp is np else xp.asnumpy(values)


def _solve_upper(matrix: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Back substitution with an upper triangular matrix (k is at most a few dozen)."""
    k = rhs.shape[0]
    y = np.zeros(k)
    for i in range(k - 1, -1, -1):
        y[i] = (rhs[i] - matrix[i, i + 1 :] @ y[i + 1 :]) / matrix[i, i]
    return y
