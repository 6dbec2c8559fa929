"""Heterogeneous linear elastic parameter estimation (Tong et al.).

Three steps, each a function:

1. :func:`homogeneous_estimate`: one (E, nu) for the whole body from the force balance
   (Tong et al., Eq. 13-14), the initial value and the Tikhonov anchor of step 2.
2. :func:`estimate_field` with ``objective="force"``: per-group (alpha, nu) minimizing the
   regularized force residual of Eq. 5-6, by the self-adapting LM of ``warptissue.lsq``.
3. :func:`estimate_field` with ``objective="displacement"``: the same parameters fitted to
   the measured marker displacements through forward FE solves, with exact sensitivities
   from the linear system (K du/dtheta = -dK/dtheta u).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.optimize
import scipy.sparse as sp

from warptissue.device import available_host_memory_bytes
from warptissue.errors import InputError
from warptissue.field.fe import (
    alpha_from_youngs,
    youngs_from_alpha,
)
from warptissue.field.markers import MarkerGrid
from warptissue.field.problem import (  # noqa: F401
    FieldProblem,
    data_objective,
)
from warptissue.lsq import FitResult, least_squares

__all__ = [
    "FieldEstimate",
    "FieldProblem",
    "HomogeneousEstimate",
    "data_objective",
    "displacement_errors",
    "estimate_field",
    "fill_nodal_displacements",
    "homogeneous_estimate",
]

NU_UPPER = 0.49
"""Upper bound of Poisson's ratio in the fits (D stays positive definite for nu < 0.5)."""

NU_SCALE = 0.1
"""Scale of Poisson's ratio in the normalized unknowns and the Tikhonov term."""

CONFIDENCE_SIGMAS = 2.0
"""Standard errors added to the regularization bias bound in the per-group error bounds."""

CONSTRAINED_RESOLUTION = 0.9
"""Smallest resolution (diagonal of R) of a parameter counted as constrained."""

CONSTRAINED_YOUNGS_ERROR = 0.10
"""Largest error bound of E, relative, of a cell whose E counts as constrained."""

CONSTRAINED_NU_ERROR = 0.02
"""Largest error bound of nu, absolute, of a cell whose nu counts as constrained."""


def fill_nodal_displacements(
    grid: MarkerGrid,
    marker_interpolation: sp.csr_matrix,
    marker_displacement_m: np.ndarray,
    *,
    smoothing: float = 1e-6,
) -> np.ndarray:
    """Nodal displacements of a marker-grid mesh from marker displacements.

    Top-face nodes: least squares fit of the markers, ||P u - d||^2 + smoothing * ||L u||^2
    with L the 5-point Laplacian of the top grid, so that nodes without a marker take the
    harmonic interpolation of their neighbours. Nodes below the top: linear in z between
    the top node above and the fixed base (exact for one layer, which has no inner nodes).

    Args:
        grid: The marker grid and its mesh.
        marker_interpolation: Nodes to markers, shape (k, node_count).
        marker_displacement_m: Marker displacements, shape (k, 3), metres.
        smoothing: Weight of the Laplacian term relative to the marker term.

    Returns:
        Displacements of every node, shape (node_count, 3), metres.
    """
    top = grid.top_nodes
    ny1, nx1 = top.shape
    count = top.size
    interpolation = marker_interpolation[:, top.ravel()]
    index = np.arange(count).reshape(ny1, nx1)
    pairs = np.concatenate(
        [
            np.column_stack([index[:, :-1].ravel(), index[:, 1:].ravel()]),
            np.column_stack([index[:-1, :].ravel(), index[1:, :].ravel()]),
        ]
    )
    difference = sp.csr_matrix(
        (
            np.tile([1.0, -1.0], len(pairs)),
            (np.repeat(np.arange(len(pairs)), 2), pairs.ravel()),
        ),
        shape=(len(pairs), count),
    )
    normal = (interpolation.T @ interpolation + smoothing * (difference.T @ difference)).tocsc()
    top_values = sp.linalg.spsolve(normal, interpolation.T @ marker_displacement_m)
    top_values = np.asarray(top_values).reshape(count, 3)
    nz = grid.hex_shape[2]
    result = np.zeros((grid.mesh.node_count, 3))
    for k in range(nz + 1):
        fraction = (grid.z_m[k] - grid.z_m[0]) / (grid.z_m[-1] - grid.z_m[0])
        layer = top.ravel() - (nz - k) * count
        result[layer] = fraction * top_values
    return result


@dataclass(frozen=True)
class HomogeneousEstimate:
    """The homogeneous linear estimate of Tong et al., Eq. 13-14.

    Attributes:
        youngs_modulus_Pa: E0, Pa.
        poissons_ratio: nu0.
        alpha_Pa: alpha0 = E0 / ((1 + nu0)(1 - 2 nu0)), Pa.
        force_rms_N: RMS of the force residual on the free dofs at the estimate, N.
    """

    youngs_modulus_Pa: float
    poissons_ratio: float
    alpha_Pa: float
    force_rms_N: float


def homogeneous_estimate(problem: FieldProblem) -> HomogeneousEstimate:
    """Solve Tong et al.'s Eq. 14: min_(E, nu) sum_i ||E N_i(nu) - f_i||^2 over the free dofs.

    With K = E (phi(nu) K_G + varphi(nu) K_H) (Eq. 13), phi = 1/((1+nu)(1-2nu)) and
    varphi = nu phi, the forces are a K_G u + b K_H u with a = E phi, b = E varphi: a linear
    least-squares problem in (a, b), whose solution gives nu = b / a and E = a / phi(nu)
    exactly. If nu falls outside [0, NU_UPPER], the one-dimensional problem in nu (with the
    optimal E for each nu in closed form) is minimized on that interval instead.

    Args:
        problem: The load set (uses ``nodal_displacement_m`` and ``force_N``).

    Returns:
        The estimate.

    Raises:
        InputError: The displacements produce no forces (all zero), so nothing is determined,
            or the best homogeneous E is not positive (the markers move against the force).
    """
    force_g, force_h = problem.model.group_forces(problem.nodal_displacement_m)
    free = problem.free_dofs
    basis = np.column_stack(
        [np.asarray(force_g.sum(axis=1)).ravel(), np.asarray(force_h.sum(axis=1)).ravel()]
    )[free]
    target = problem.force_N.ravel()[free]
    if not np.any(basis):
        raise InputError("the displacements are zero: no stiffness can be estimated")
    (a, b), *_ = np.linalg.lstsq(basis, target, rcond=None)
    nu = b / a if a > 0 else -1.0
    if a > 0 and 0.0 <= nu <= NU_UPPER:
        youngs = a * (1.0 + nu) * (1.0 - 2.0 * nu)
    else:

        def misfit(trial_nu: float) -> float:
            column = basis @ np.array([1.0, trial_nu])
            youngs_scaled = max(column @ target / (column @ column), 0.0)
            return float(np.sum((youngs_scaled * column - target) ** 2))

        nu = scipy.optimize.minimize_scalar(
            misfit, bounds=(0.0, NU_UPPER), method="bounded", options={"xatol": 1e-10}
        ).x
        column = basis @ np.array([1.0, nu])
        youngs = column @ target / (column @ column) * (1.0 + nu) * (1.0 - 2.0 * nu)
    if not youngs > 0:
        raise InputError(
            "the markers move against the applied force (the best homogeneous fit has "
            f"E = {float(youngs):.4g} Pa, not positive): check the signs of the forces and "
            "of the displacements"
        )
    alpha = float(alpha_from_youngs(youngs, nu))
    residual = alpha * (basis @ np.array([1.0, nu])) - target
    return HomogeneousEstimate(
        float(youngs), float(nu), alpha, float(np.sqrt(np.mean(residual**2)))
    )


@dataclass(frozen=True)
class FieldEstimate:
    """Per-group parameters from :func:`estimate_field`.

    Attributes:
        alpha_Pa: alpha per group, shape (group_count,), Pa.
        poissons_ratio: nu per group, shape (group_count,).
        youngs_modulus_Pa: E = alpha (1 + nu)(1 - 2 nu) per group, Pa.
        initial: The homogeneous estimate used as x_1 and Tikhonov anchor.
        objective: "force" or "displacement".
        gamma: Tikhonov weight of Eq. 6 (on parameters normalized by the initial values).
        fit: The least-squares result (parameters normalized: alpha/alpha0, nu/NU_SCALE).
        resolution_alpha: Diagonal of the model-resolution matrix for alpha per group, in
            [0, 1]: the share of each parameter set by the data rather than by the prior.
        resolution_nu: The same for nu.
        youngs_relative_error: Standard error of E relative to E per group (noise estimated
            from the data residual, propagated through the regularized estimator). Noise
            only: the regularization bias is in :attr:`youngs_bias_bound`.
        poissons_ratio_error: Standard error of nu per group (noise only).
        youngs_leakage: Regularization-bias weights of E per group, shape (group_count, 2):
            the l1 norms, over the alpha columns and over the nu columns, of the group's
            row of d(ln E)/dx (I - R), R the resolution matrix. With every group's true
            alpha within ``alpha_deviation`` (relative) of alpha0 and every true nu within
            ``nu_deviation`` of nu0, the linearized bias of ln E is at most
            ``youngs_leakage @ (alpha_deviation, nu_deviation / NU_SCALE)``.
        poissons_ratio_leakage: The same for nu (rows of NU_SCALE (I - R)), shape
            (group_count, 2), so that the bias of nu is at most
            ``poissons_ratio_leakage @ (alpha_deviation, nu_deviation / NU_SCALE)``.
        alpha_deviation: The assumed largest relative deviation of the true alpha from
            alpha0 in any group (given, or the fitted field's largest deviation).
        nu_deviation: The assumed largest deviation of the true nu from nu0 (given, or the
            fitted field's largest deviation).
        identifiability: The fit's identifiability warnings
            (:attr:`warptissue.lsq.FitResult.identifiability`: a parameter pinned at a bound,
            a standard error above its value) in physical units, one per parameter
            (``alpha[g]`` in Pa, ``nu[g]``); empty when every parameter is identified.
    """

    alpha_Pa: np.ndarray
    poissons_ratio: np.ndarray
    youngs_modulus_Pa: np.ndarray
    initial: HomogeneousEstimate
    objective: str
    gamma: float
    fit: FitResult
    resolution_alpha: np.ndarray
    resolution_nu: np.ndarray
    youngs_relative_error: np.ndarray
    poissons_ratio_error: np.ndarray
    youngs_leakage: np.ndarray
    poissons_ratio_leakage: np.ndarray
    alpha_deviation: float
    nu_deviation: float
    identifiability: list[str]

    @property
    def _deviation(self) -> np.ndarray:
        return np.array([self.alpha_deviation, self.nu_deviation / NU_SCALE])

    @property
    def youngs_bias_bound(self) -> np.ndarray:
        """Bound on the regularization bias of E relative to E per group (linearized, under
        the deviation assumption of ``alpha_deviation`` and ``nu_deviation``)."""
        return self.youngs_leakage @ self._deviation

    @property
    def poissons_ratio_bias_bound(self) -> np.ndarray:
        """Bound on the regularization bias of nu per group (as :attr:`youngs_bias_bound`)."""
        return self.poissons_ratio_leakage @ self._deviation

    @property
    def youngs_error_bound(self) -> np.ndarray:
        """Error bound of E relative to E per group: bias bound + CONFIDENCE_SIGMAS standard
        errors."""
        return self.youngs_bias_bound + CONFIDENCE_SIGMAS * self.youngs_relative_error

    @property
    def poissons_ratio_error_bound(self) -> np.ndarray:
        """Error bound of nu per group: bias bound + CONFIDENCE_SIGMAS standard errors."""
        return self.poissons_ratio_bias_bound + CONFIDENCE_SIGMAS * self.poissons_ratio_error

    def constrained_youngs(
        self,
        *,
        resolution: float = CONSTRAINED_RESOLUTION,
        relative_error: float = CONSTRAINED_YOUNGS_ERROR,
    ) -> np.ndarray:
        """Groups whose E the data constrain: alpha's resolution >= ``resolution`` and the
        error bound (regularization bias bound + 2 standard errors, :attr:`youngs_error_bound`)
        <= ``relative_error`` of E."""
        return (self.resolution_alpha >= resolution) & (self.youngs_error_bound <= relative_error)

    def constrained_poissons_ratio(
        self, *, resolution: float = CONSTRAINED_RESOLUTION, error: float = CONSTRAINED_NU_ERROR
    ) -> np.ndarray:
        """Groups whose nu the data constrain: nu's resolution >= ``resolution`` and
        :attr:`poissons_ratio_error_bound` <= ``error`` (absolute)."""
        return (self.resolution_nu >= resolution) & (self.poissons_ratio_error_bound <= error)

    def confidence_assumptions(self) -> dict:
        """What the error bounds and the constrained flags assume (JSON-ready)."""
        return {
            "alpha_deviation": self.alpha_deviation,
            "nu_deviation": self.nu_deviation,
            "standard_errors_in_bound": CONFIDENCE_SIGMAS,
            "constrained_youngs": {
                "resolution_alpha_min": CONSTRAINED_RESOLUTION,
                "youngs_error_bound_max": CONSTRAINED_YOUNGS_ERROR,
            },
            "constrained_poissons_ratio": {
                "resolution_nu_min": CONSTRAINED_RESOLUTION,
                "poissons_ratio_error_bound_max": CONSTRAINED_NU_ERROR,
            },
            "meaning": "bias bound: largest linearized regularization bias for a true field "
            "whose alpha lies within alpha_deviation (relative) of alpha0 and whose nu lies "
            "within nu_deviation of nu0 in every cell; error bound = bias bound + "
            f"{CONFIDENCE_SIGMAS:g} standard errors (noise)",
        }

    def to_dict(self) -> dict:
        """JSON-ready summary (per-group arrays included)."""
        return {
            "objective": self.objective,
            "gamma": self.gamma,
            "initial": {
                "youngs_modulus_Pa": self.initial.youngs_modulus_Pa,
                "poissons_ratio": self.initial.poissons_ratio,
                "alpha_Pa": self.initial.alpha_Pa,
                "force_rms_N": self.initial.force_rms_N,
            },
            "groups": {
                "youngs_modulus_Pa": self.youngs_modulus_Pa,
                "poissons_ratio": self.poissons_ratio,
                "alpha_Pa": self.alpha_Pa,
                "resolution_alpha": self.resolution_alpha,
                "resolution_nu": self.resolution_nu,
                "youngs_relative_error": self.youngs_relative_error,
                "youngs_bias_bound": self.youngs_bias_bound,
                "youngs_error_bound": self.youngs_error_bound,
                "poissons_ratio_error": self.poissons_ratio_error,
                "poissons_ratio_bias_bound": self.poissons_ratio_bias_bound,
                "poissons_ratio_error_bound": self.poissons_ratio_error_bound,
                "constrained_youngs": self.constrained_youngs(),
                "constrained_poissons_ratio": self.constrained_poissons_ratio(),
            },
            "confidence": self.confidence_assumptions(),
            "fit": {
                "method": self.fit.method,
                "status": self.fit.status,
                "message": self.fit.message,
                "iterations": self.fit.iterations,
                "cost": self.fit.cost,
                "identified": not self.identifiability,
                "identifiability": self.identifiability,
            },
        }


def _resolution_and_spread(
    data_jacobian: np.ndarray, data_residual: np.ndarray, gamma: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Model resolution, noise covariance and regularization-bias operator of the estimate.

    With A = J^T J + gamma I (J the data Jacobian in the normalized unknowns): the resolution
    matrix R = A^-1 J^T J (its diagonal in [0, 1]); for residual noise of variance s^2, the
    covariance s^2 A^-1 J^T J A^-1, where s^2 is estimated as ||r||^2 / (m - trace R) (the
    effective degrees of freedom); and the bias operator I - R = gamma A^-1: linearized, the
    regularized estimate x of a true x_t anchored at x0 has the bias -(I - R)(x_t - x0).

    Returns:
        (diag R, shape (n,); covariance, shape (n, n); I - R, shape (n, n)).
    """
    _, singular, vt = np.linalg.svd(data_jacobian, full_matrices=False)
    power = singular**2
    filters = power / (power + gamma)
    resolution = np.einsum("kj,k->j", vt**2, filters)
    dof = max(data_jacobian.shape[0] - float(filters.sum()), 1.0)
    variance = float(data_residual @ data_residual) / dof
    covariance = (vt.T * (variance * power / (power + gamma) ** 2)) @ vt
    # I - V F V^T holds the null space of J (filter 0) too, which the thin SVD leaves out.
    bias_operator = np.eye(vt.shape[1]) - (vt.T * filters) @ vt
    return resolution, covariance, bias_operator


def _leakage(rows: np.ndarray, groups: int) -> np.ndarray:
    """l1 norms of rows over the alpha and the nu columns, shape (rows, 2)."""
    magnitude = np.abs(rows)
    return np.column_stack([magnitude[:, :groups].sum(axis=1), magnitude[:, groups:].sum(axis=1)])


def estimate_field(
    problem: FieldProblem,
    *,
    objective: str = "force",
    initial: HomogeneousEstimate | None = None,
    start: tuple[np.ndarray, np.ndarray] | None = None,
    gamma: float = 1e-5,
    method: str = "salm",
    max_iterations: int = 100,
    ftol: float = 1e-10,
    xtol: float = 1e-10,
    gtol: float = 0.0,
    alpha_deviation: float | None = None,
    nu_deviation: float | None = None,
    progress: bool = False,
) -> FieldEstimate:
    """Estimate alpha and nu per group (Tong et al., Eq. 5-6, solved by the self-adapting LM).

    The unknowns are normalized, x = (alpha_g / alpha0, nu_g / NU_SCALE), and the residual is

        r(x) = [ data residual ; sqrt(gamma) (x - x0) ]

    with x0 = (1, nu0 / NU_SCALE) the homogeneous estimate (Eq. 6's Tikhonov term, made
    dimensionless; NU_SCALE = 0.1 rather than nu0, which can be near zero)
    where the data residual is, for ``objective="force"``, (K(alpha, nu) u - f) on the free
    dofs divided by the largest applied force (Eq. 5-6; u = ``nodal_displacement_m``), and
    for ``objective="displacement"``, (P u(alpha, nu) - d) over the training markers
    divided by the largest measured displacement, u solving K u = f with the base fixed.

    Args:
        problem: The load set.
        objective: "force" (Eq. 6) or "displacement".
        initial: The homogeneous estimate (computed when None): anchor and default start.
        start: Starting (alpha_Pa, nu) per group; default the homogeneous values.
        gamma: Tikhonov weight (dimensionless, on the normalized parameters).
        method: "salm" (Tong et al.'s self-adapting LM) or "lm".
        max_iterations: Iteration limit of the LM.
        ftol, xtol, gtol: Stopping tolerances of :func:`warptissue.lsq.least_squares`.
        alpha_deviation: Assumed largest deviation of the true alpha from alpha0 in any
            group, relative (0.5: within +-50%), for the regularization bias bounds. None:
            the fitted field's largest deviation.
        nu_deviation: Assumed largest deviation of the true nu from nu0 in any group
            (absolute). None: the fitted field's largest deviation.
        progress: Show a progress bar.

    Returns:
        The estimate.

    Raises:
        InputError: A bad objective, gamma or deviation, or a field whose dense matrices
            (:func:`dense_memory_bytes`) exceed the available host memory.

    Notes:
        The force residual K(alpha, nu) u = FG alpha + FH (alpha nu) is bilinear, and its
        Jacobian is analytic: d/d alpha_g = FG_g + nu_g FH_g, d/d nu_g = alpha_g FH_g, with
        FG_g, FH_g the group's nodal forces per unit parameter. For the displacement
        objective, du/dtheta = -K^-1 (dK/dtheta u) with the same columns evaluated at the
        current u: one factorization, one multi-right-hand-side solve per iteration.

        Confidence (docs/field.md, "Confidence"): the resolution R, the noise standard
        errors, and a bound on the Tikhonov bias -(I - R)(x_true - x0), linearized at the
        estimate, for a true field within ``alpha_deviation`` and ``nu_deviation`` of the
        homogeneous estimate; a cell is constrained when its resolution is >= 0.9 and the
        bias bound plus 2 standard errors is within the tolerance. The resolution alone
        bounds nothing: a cell with R >= 0.9 still averages its neighbours.
    """
    _check_options(objective, gamma, alpha_deviation, nu_deviation)
    initial = homogeneous_estimate(problem) if initial is None else initial
    groups = problem.model.group_count
    alpha0 = initial.alpha_Pa
    nu_scale = NU_SCALE
    scales, prior, x0, bounds = _normalized_unknowns(initial, start, groups)
    rows = problem.free_dofs.size if objective == "force" else problem.marker_displacement_m.size
    _check_memory(rows=rows + 2 * groups, unknowns=2 * groups)
    data_residual, data_jacobian = data_objective(
        problem, objective=objective, alpha0_Pa=alpha0, nu_scale=nu_scale
    )
    lm_options = {"method": method, "max_iterations": max_iterations, "progress": progress}
    lm_options.update(ftol=ftol, xtol=xtol, gtol=gtol)
    result = _tikhonov_fit(data_residual, data_jacobian, x0, prior, bounds, gamma, **lm_options)
    alpha, nu = result.x[:groups] * alpha0, result.x[groups:] * nu_scale
    if alpha_deviation is None:
        alpha_deviation = float(np.abs(alpha / alpha0 - 1.0).max())
    if nu_deviation is None:
        nu_deviation = float(np.abs(nu - initial.poissons_ratio).max())
    return FieldEstimate(
        alpha_Pa=alpha,
        poissons_ratio=nu,
        youngs_modulus_Pa=youngs_from_alpha(alpha, nu),
        initial=initial,
        objective=objective,
        gamma=gamma,
        fit=result,
        **_confidence(data_jacobian(result.x), data_residual(result.x), gamma, alpha, nu, alpha0),
        alpha_deviation=float(alpha_deviation),
        nu_deviation=float(nu_deviation),
        identifiability=_physical(result, scales, groups).identifiability,
    )


def _check_options(
    objective: str, gamma: float, alpha_deviation: float | None, nu_deviation: float | None
) -> None:
    """Refuse a bad objective, Tikhonov weight or assumed deviation of
    :func:`estimate_field`."""
    if objective not in ("force", "displacement"):
        raise InputError("objective must be 'force' or 'displacement'", value=objective)
    if not gamma >= 0:
        raise InputError("gamma must be >= 0", value=float(gamma))
    for name, deviation in (("alpha_deviation", alpha_deviation), ("nu_deviation", nu_deviation)):
        if deviation is not None and not (np.isfinite(deviation) and deviation >= 0):
            raise InputError(f"{name} must be a finite number >= 0", value=float(deviation))


def _normalized_unknowns(
    initial: HomogeneousEstimate, start: tuple[np.ndarray, np.ndarray] | None, groups: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """The normalized unknowns x = (alpha_g / alpha0, nu_g / NU_SCALE) of
    :func:`estimate_field`: (their scales, the prior x0 of the Tikhonov term, the start
    within the bounds, the bounds (lower, upper)), each of shape (2 groups,)."""
    alpha0, nu_scale = initial.alpha_Pa, NU_SCALE
    scales = np.concatenate([np.full(groups, alpha0), np.full(groups, nu_scale)])
    prior = np.concatenate([np.ones(groups), np.full(groups, initial.poissons_ratio / nu_scale)])
    if start is None:
        x0 = prior.copy()
    else:
        x0 = np.concatenate([np.asarray(start[0]), np.asarray(start[1])]) / scales
    lower = np.concatenate([np.full(groups, 1e-3), np.zeros(groups)])
    upper = np.concatenate([np.full(groups, np.inf), np.full(groups, NU_UPPER / nu_scale)])
    return scales, prior, np.clip(x0, lower, upper), (lower, upper)


def _tikhonov_fit(
    data_residual: Callable[[np.ndarray], np.ndarray],
    data_jacobian: Callable[[np.ndarray], np.ndarray],
    x0: np.ndarray,
    prior: np.ndarray,
    bounds: tuple[np.ndarray, np.ndarray],
    gamma: float,
    *,
    method: str,
    max_iterations: int,
    ftol: float,
    xtol: float,
    gtol: float,
    progress: bool,
) -> FitResult:
    """Least squares of r(x) = [data residual; sqrt(gamma) (x - prior)] in the normalized
    unknowns (Tong et al., Eq. 6), from ``x0`` within ``bounds``."""
    root_gamma = np.sqrt(gamma)
    groups = x0.size // 2

    def residual(x: np.ndarray) -> np.ndarray:
        return np.concatenate([data_residual(x), root_gamma * (x - prior)])

    def jacobian(x: np.ndarray) -> np.ndarray:
        return np.vstack([data_jacobian(x), root_gamma * np.eye(x.size)])

    names = [f"alpha[{g}]" for g in range(groups)] + [f"nu[{g}]" for g in range(groups)]
    return least_squares(
        residual,
        x0,
        jac=jacobian,
        bounds=bounds,
        method=method,
        max_iterations=max_iterations,
        ftol=ftol,
        xtol=xtol,
        gtol=gtol,
        progress=progress,
        parameter_names=names,
    )


def _confidence(
    data_jacobian: np.ndarray,
    data_residual: np.ndarray,
    gamma: float,
    alpha: np.ndarray,
    nu: np.ndarray,
    alpha0: float,
) -> dict[str, np.ndarray]:
    """The estimate's resolution, standard errors and regularization-bias leakage per group
    (docs/field.md, "Confidence"), from the data Jacobian (m, 2 groups) and residual (m,) at
    the estimate (alpha, nu per group; alpha0, Pa: the normalization): the
    :class:`FieldEstimate` fields of those names."""
    groups, nu_scale = alpha.size, NU_SCALE
    resolution, covariance, bias_operator = _resolution_and_spread(
        data_jacobian, data_residual, max(gamma, 1e-300)
    )
    # d(ln E)/dx: d alpha / alpha + (1 / (1 + nu) - 2 / (1 - 2 nu)) d nu, x normalized.
    cells = np.arange(groups)
    weights_alpha = alpha0 / alpha
    weights_nu = nu_scale * (1.0 / (1.0 + nu) - 2.0 / (1.0 - 2.0 * nu))
    variance_e = (
        weights_alpha**2 * covariance[cells, cells]
        + weights_nu**2 * covariance[cells + groups, cells + groups]
        + 2.0 * weights_alpha * weights_nu * covariance[cells, cells + groups]
    )
    youngs_rows = (
        weights_alpha[:, None] * bias_operator[:groups]
        + weights_nu[:, None] * bias_operator[groups:]
    )
    return {
        "resolution_alpha": resolution[:groups],
        "resolution_nu": resolution[groups:],
        "youngs_relative_error": np.sqrt(np.maximum(variance_e, 0.0)),
        "poissons_ratio_error": np.sqrt(np.maximum(np.diag(covariance)[groups:], 0.0)) * nu_scale,
        "youngs_leakage": _leakage(youngs_rows, groups),
        "poissons_ratio_leakage": _leakage(nu_scale * bias_operator[groups:], groups),
    }


def dense_memory_bytes(*, rows: int, unknowns: int) -> int:
    """Rough peak of the dense float64 matrices of :func:`estimate_field`, bytes: the
    Jacobian (rows x unknowns) and its copies in the fit and its SVD (4), and the n x n
    normal matrix, covariance, resolution and bias operators with their temporaries (8)."""
    return 8 * (4 * rows * unknowns + 8 * unknowns * unknowns)


def _check_memory(*, rows: int, unknowns: int) -> None:
    """Refuse a field whose dense matrices cannot fit in the available host memory."""
    needed = dense_memory_bytes(rows=rows, unknowns=unknowns)
    available = available_host_memory_bytes()
    if needed > available:
        raise InputError(
            f"{unknowns // 2} cells ({unknowns} unknowns, {rows} residuals) need about "
            f"{needed / 1e9:.3g} GB of dense matrices, more than the {available / 1e9:.3g} GB "
            "available: use fewer markers (a coarser grid) or fewer layers"
        )


def _physical(result: FitResult, scales: np.ndarray, groups: int) -> FitResult:
    """The fit in physical units (alpha in Pa, nu), for messages that name values."""
    errors = result.standard_errors
    return dataclasses.replace(
        result,
        x=result.x * scales,
        jacobian=result.jacobian / scales,
        covariance=None
        if result.covariance is None
        else result.covariance * np.outer(scales, scales),
        standard_errors=None if errors is None else errors * scales,
        lower_bounds=None if result.lower_bounds is None else result.lower_bounds * scales,
        upper_bounds=None if result.upper_bounds is None else result.upper_bounds * scales,
        parameter_units=("Pa",) * groups + ("",) * groups,
        history=[],
    )


def displacement_errors(predicted_m: np.ndarray, measured_m: np.ndarray) -> dict[str, float]:
    """Maximum and mean Euclidean marker displacement error (Tong et al., Table 3), metres."""
    error = np.linalg.norm(np.asarray(predicted_m) - np.asarray(measured_m), axis=1)
    return {"max_error_m": float(error.max()), "mean_error_m": float(error.mean())}
