"""A load set of the heterogeneous field estimation (:class:`FieldProblem`) and its data
residual with the exact Jacobian (:func:`data_objective`, Tong et al., Eq. 5-6), which
:func:`warptissue.field.estimation.estimate_field` fits."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from warptissue.errors import InputError
from warptissue.field.fe import (
    LinearSolution,
    LinearTetModel,
)


@dataclass(frozen=True)
class FieldProblem:
    """One load set of a field estimation.

    Attributes:
        model: The grouped linear TET4 model.
        fixed_nodes: Nodes held at zero displacement (the base), shape (f,).
        force_N: External nodal forces, shape (node_count, 3), newtons.
        marker_interpolation: Nodes to the (training) markers, shape (k, node_count).
        marker_displacement_m: Measured displacements of those markers, shape (k, 3), metres.
        nodal_displacement_m: Displacement of every node, measured or filled in from the
            markers (:func:`fill_nodal_displacements`), shape (node_count, 3); the force
            objective (Eq. 5-6) needs it.
    """

    model: LinearTetModel
    fixed_nodes: np.ndarray
    force_N: np.ndarray
    marker_interpolation: sp.csr_matrix
    marker_displacement_m: np.ndarray
    nodal_displacement_m: np.ndarray

    def __post_init__(self) -> None:
        nodes = self.model.mesh.node_count
        if self.force_N.shape != (nodes, 3) or self.nodal_displacement_m.shape != (nodes, 3):
            raise InputError(f"force and nodal displacement need shape ({nodes}, 3)")
        if self.marker_interpolation.shape != (len(self.marker_displacement_m), nodes):
            raise InputError("marker_interpolation must have shape (markers, nodes)")
        if not np.any(self.force_N):
            raise InputError("the load set has no applied force")

    @property
    def free_dofs(self) -> np.ndarray:
        """Degrees of freedom not held by ``fixed_nodes``."""
        fixed = np.zeros(self.model.dof_count, dtype=bool)
        fixed[(3 * self.fixed_nodes[:, None] + np.arange(3)).ravel()] = True
        return np.flatnonzero(~fixed)

    @property
    def force_scale_N(self) -> float:
        """The largest nodal force magnitude, N (scales force residuals)."""
        return float(np.linalg.norm(self.force_N, axis=1).max())

    @property
    def displacement_scale_m(self) -> float:
        """The largest measured marker displacement, m (scales displacement residuals)."""
        scale = float(np.linalg.norm(self.marker_displacement_m, axis=1).max())
        return scale if scale > 0 else 1.0


def data_objective(
    problem: FieldProblem, *, objective: str, alpha0_Pa: float, nu_scale: float = 0.1
) -> tuple[Callable[[np.ndarray], np.ndarray], Callable[[np.ndarray], np.ndarray]]:
    """The data residual of :func:`estimate_field` and its exact Jacobian.

    Args:
        problem: The load set.
        objective: "force" or "displacement".
        alpha0_Pa, nu_scale: Normalization: x = (alpha_g / alpha0, nu_g / nu_scale).

    Returns:
        ``(residual(x) -> (m,), jacobian(x) -> (m, 2 groups))``.
    """
    groups = problem.model.group_count
    alpha0 = alpha0_Pa

    def split(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return x[:groups] * alpha0, x[groups:] * nu_scale

    free = problem.free_dofs
    model = problem.model

    def sensitivity_columns(
        force_g: sp.csr_matrix, force_h: sp.csr_matrix, alpha: np.ndarray, nu: np.ndarray
    ) -> np.ndarray:
        """d(K u)/dx on the free dofs, dense (free, 2 groups)."""
        d_alpha = (force_g + force_h @ sp.diags(nu)) * alpha0
        d_nu = force_h @ sp.diags(alpha * nu_scale)
        return sp.hstack([d_alpha, d_nu]).tocsr()[free].toarray()

    if objective == "force":
        force_g, force_h = model.group_forces(problem.nodal_displacement_m)
        target = problem.force_N.ravel()[free]
        scale = problem.force_scale_N

        def data_residual(x: np.ndarray) -> np.ndarray:
            alpha, nu = split(x)
            return ((force_g @ alpha + force_h @ (alpha * nu))[free] - target) / scale

        def data_jacobian(x: np.ndarray) -> np.ndarray:
            alpha, nu = split(x)
            return sensitivity_columns(force_g, force_h, alpha, nu) / scale

    else:
        markers = problem.marker_interpolation
        expand = sp.kron(markers, sp.eye(3)).tocsr()[:, free]
        measured = problem.marker_displacement_m.ravel()
        scale = problem.displacement_scale_m
        cache: dict[bytes, LinearSolution] = {}

        def forward(x: np.ndarray) -> LinearSolution:
            key = x.tobytes()
            if key not in cache:
                cache.clear()
                alpha, nu = split(x)
                cache[key] = model.solve(alpha, nu, problem.force_N, problem.fixed_nodes)
            return cache[key]

        def data_residual(x: np.ndarray) -> np.ndarray:
            solution = forward(x)
            return (markers @ solution.displacement_m).ravel() / scale - measured / scale

        def data_jacobian(x: np.ndarray) -> np.ndarray:
            solution = forward(x)
            alpha, nu = split(x)
            force_g, force_h = model.group_forces(solution.displacement_m)
            columns = sensitivity_columns(force_g, force_h, alpha, nu)
            return -(expand @ solution.solve_free(columns)) / scale

    return data_residual, data_jacobian
