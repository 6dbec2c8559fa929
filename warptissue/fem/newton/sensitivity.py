"""Exact derivatives of a reaction force by material parameters at converged load steps.

At a converged state the free dofs satisfy ``R_f(u, theta) = 0`` with the prescribed dofs set
by the load alone, so differentiating by a material parameter theta gives

    K_ff du_f/dtheta = -dR_f/dtheta,    du_p/dtheta = 0,

one linear solve with the tangent per parameter, and the reaction ``F = w . R(u, theta)``
(``w`` nonzero on prescribed dofs only) has the total derivative

    dF/dtheta = w . (dR/dtheta + K du/dtheta).

On a body held by support springs ``S`` (an elastic foundation, :mod:`warptissue.fem.support`)
``w`` also lies on the sprung free dofs and the reaction is ``F = w . (R - S u)``: the
derivative gains ``-(S w) . du/dtheta`` (``S`` does not depend on theta).

``dR/dtheta`` comes from the Warp element kernels
(:meth:`warptissue.fem.Assembler.parameter_residual`): the internal force is linear in every
material parameter but the Ogden exponents, and those have a hand-written kernel. Everything
is exact up to the Newton tolerance of the state and the accuracy of the linear solve; a
hyperelastic state depends on the load alone, not on the path, so each step is independent.

The linear solve: Newton's last factorization is of the iterate before the converged one (the
step that reached it was solved with it; the line search, nonlinear elimination and damping
may change the state and matrix after it), or of an earlier one where Newton solved the later
iterations with its factors (``NewtonOptions.reuse_factorization``).
``factorization="reuse"`` solves with those factors and refines iteratively against the
tangent at the converged state (``x += K_old^-1 (b - K x)``: no new factorization; it
converges fast because K_old is close to K), falling back to one factorization at the
converged state where the refinement does not converge;
``"refactorize"`` factorizes the converged tangent once per step. Both agree with central
differences of whole forward runs (tests/test_fem_sensitivity.py; docs/fe.md
"Sensitivities").
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import warp as wp
import warp.sparse as wps

from warptissue.errors import InputError
from warptissue.fem.arrays import DeviceArrays
from warptissue.fem.assembly import Assembler
from warptissue.fem.linear import LinearSolver
from warptissue.fem.newton.problems import DirichletConditions

__all__ = ["SENSITIVITY_FACTORIZATIONS", "ForceSensitivity", "check_sensitivity_names"]

SENSITIVITY_FACTORIZATIONS = ("reuse", "refactorize")


@dataclass
class ForceSensitivity:
    """Computes ``dF/dtheta`` of a reaction force at each converged state of a load path.

    Args:
        assembler: The discretized body (its material is the one differentiated).
        conditions: The prescribed dofs of the load path.
        names: Parameters to differentiate by, a subset of the material's
            :attr:`~warptissue.materials.Material.sensitivity_names`.
        reaction_weights: Weights (N, 3) of the internal forces summed into the reaction
            (nonzero on prescribed dofs only).
        factorization: ``"reuse"`` (Newton's last factors with iterative refinement) or
            ``"refactorize"`` (one factorization of the converged tangent per step).
        refinement_tolerance: Relative residual of the refined solves (``"reuse"``).
        max_refinements: Refinement steps before falling back to a factorization; 0 uses
            Newton's last factors as they are (no refinement, no fallback: for measuring).
        node_offsets: For K problems packed into the assembler's mesh
            (:func:`warptissue.fem.packing.pack_meshes`), the first node of each and the
            node count at the end, (K + 1,): each problem's reaction is differentiated by its
            own material's parameters, and :meth:`at_converged_state` gives one row per
            problem. None: one problem.

    Attributes:
        solves: Linear solves with existing factors so far.
        factorizations: Factorizations made for the sensitivities so far.
        refinement_steps: Refinement steps so far.
        seconds: Wall time spent in :meth:`at_converged_state` so far, s.

    Raises:
        InputError: An unknown parameter name or factorization, or mis-shaped weights.
    """

    assembler: Assembler
    conditions: DirichletConditions
    names: tuple[str, ...]
    reaction_weights: np.ndarray
    factorization: str = "reuse"
    refinement_tolerance: float = 1e-12
    max_refinements: int = 20
    node_offsets: np.ndarray | None = None
    solves: int = field(default=0, init=False)
    factorizations: int = field(default=0, init=False)
    refinement_steps: int = field(default=0, init=False)
    seconds: float = field(default=0.0, init=False)
    _arrays: Any = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        self.names = check_sensitivity_names(self.names)
        if len(set(self.names)) != len(self.names):
            raise InputError("sensitivities must be distinct parameter names", value=self.names)
        for k, material in enumerate(self.assembler.materials):
            for name in self.names:
                exponent = material.device_params_derivative(name)[1] >= 0  # names a bad one
                if exponent and self.assembler.problem_count > 1:
                    raise InputError(
                        f"problem {k}: packed problems are differentiated by moduli, not by "
                        "Ogden exponents",
                        key="sensitivities",
                        value=name,
                    )
        if self.node_offsets is None and self.assembler.problem_count > 1:
            raise InputError(
                "node_offsets are needed where the assembler packs several problems",
                key="node_offsets",
                value=self.assembler.problem_count,
            )
        if self.node_offsets is not None:
            self.node_offsets = np.asarray(self.node_offsets, dtype=np.int64)
        if self.factorization not in SENSITIVITY_FACTORIZATIONS:
            raise InputError(
                f"must be one of {', '.join(map(repr, SENSITIVITY_FACTORIZATIONS))}",
                key="sensitivity_factorization",
                value=self.factorization,
            )
        n = self.assembler.node_count
        self.reaction_weights = np.asarray(self.reaction_weights, dtype=np.float64)
        if self.reaction_weights.shape != (n, 3):
            raise InputError(
                f"reaction_weights must have shape ({n}, 3)", value=self.reaction_weights.shape
            )
        if self.assembler.viscous is not None:
            self.assembler.viscous.track_sensitivities(self.names)
        mask = self.conditions.mask(n)
        self._free = 1.0 - mask
        self._constrained = wp.array(mask, dtype=wp.vec3d, device=self.assembler.device)

    def at_converged_state(
        self,
        solver: LinearSolver,
        displacement_m: np.ndarray,
        *,
        reached: np.ndarray | None = None,
    ) -> np.ndarray:
        """``dF/dtheta`` for every name at a converged state.

        Assembles the tangent at the state (overwriting the assembler's matrix and residual).

        Args:
            solver: The linear solver that Newton used (its last factorization is reused).
            displacement_m: The converged nodal displacements, (N, 3), m.
            reached: Of packed problems, those at a converged state, (K,) (None: all); the
                others' rows are frozen and their derivatives 0.

        Returns:
            dF/dtheta, shape (len(names),) for one problem, (K, len(names)) for packed
            problems, in the reaction's unit per unit of each parameter.
        """
        start = time.perf_counter()
        try:
            return self._derivatives(solver, displacement_m, reached)
        finally:
            self.seconds += time.perf_counter() - start

    def _derivatives(
        self, solver: LinearSolver, displacement_m: np.ndarray, reached: np.ndarray | None
    ) -> np.ndarray:
        count = len(self.names)
        offsets = self.node_offsets
        if count == 0:
            return np.zeros(0) if offsets is None else np.zeros((len(offsets) - 1, 0))
        assembler = self.assembler
        free, constrained = self._free, self._constrained
        if offsets is not None and reached is not None and not np.all(reached):
            on = np.repeat(np.asarray(reached, dtype=np.float64), np.diff(offsets))[:, None]
            free = self._free * on
            constrained = wp.array(1.0 - free, dtype=wp.vec3d, device=assembler.device)
        matrix = assembler.assemble(displacement_m).matrix
        full_values = wp.clone(matrix.values)
        derivatives = [assembler.parameter_residual(displacement_m, name) for name in self.names]
        assembler.eliminate(constrained)
        refactorize = self.factorization == "refactorize"
        steps = []
        for d_residual in derivatives:
            rhs = -d_residual * free
            if refactorize:
                du, _ = solver.solve(matrix, rhs)
                self.factorizations += 1
                refactorize = False
            else:
                du, refactorize_now = self._refined_solve(solver, matrix, rhs)
                if refactorize_now:
                    du, _ = solver.solve(matrix, rhs)
                    self.factorizations += 1
            steps.append(du * free)
        viscous = assembler.viscous
        if viscous is not None:  # advance the history's derivatives with du/dtheta
            u_device = wp.array(displacement_m, dtype=wp.vec3d, device=assembler.device)
            for name, du in zip(self.names, steps, strict=True):
                viscous.commit_sensitivity(assembler, u_device, du, name, problems=reached)
        # K du on the prescribed rows needs the tangent before elimination.
        matrix.values.assign(full_values)
        product = wp.zeros(assembler.node_count, dtype=wp.vec3d, device=assembler.device)
        # Support springs: the reaction is w . (R - S u), so dF/dtheta gains -(S w) . du.
        springs = -assembler.spring_product(self.reaction_weights) if assembler.has_springs else 0
        out = np.empty(count) if offsets is None else np.zeros((len(offsets) - 1, count))
        for i, (d_residual, du) in enumerate(zip(derivatives, steps, strict=True)):
            du_wp = wp.array(du, dtype=wp.vec3d, device=assembler.device)
            wps.bsr_mv(matrix, du_wp, product, alpha=1.0, beta=0.0)
            contributions = self.reaction_weights * (d_residual + product.numpy()) + springs * du
            if offsets is None:
                out[i] = float(np.sum(contributions))
            else:
                per_node = contributions.sum(axis=1)
                out[:, i] = np.add.reduceat(per_node, offsets[:-1]) if len(per_node) else 0.0
                if reached is not None:
                    out[~np.asarray(reached), i] = 0.0
        return out

    def _refined_solve(
        self, solver: LinearSolver, matrix: wps.BsrMatrix, rhs: np.ndarray
    ) -> tuple[np.ndarray, bool]:
        """Solve ``matrix x = rhs`` with the existing factors plus iterative refinement.

        The refinement works in the arrays of the matrix's device (CuPy on a GPU, NumPy on
        the CPU): on a GPU the right-hand side goes to the device once and ``x`` comes back
        once, and each step reads one pair of norms.

        Returns:
            (x as NumPy, whether the refinement failed and a factorization is needed).
        """
        if self._arrays is None:
            self._arrays = DeviceArrays(matrix.device)
        arrays = self._arrays
        with arrays.context():
            x, failed = self._refine(arrays, solver, matrix, arrays.asarray(rhs))
            return arrays.host(x), failed

    def _refine(
        self, arrays: DeviceArrays, solver: LinearSolver, matrix: wps.BsrMatrix, rhs: Any
    ) -> tuple[Any, bool]:
        x, _ = solver.solve_factorized(matrix, rhs)
        self.solves += 1
        if self.max_refinements == 0:
            return x, False
        (scale_squared,) = arrays.floats(arrays.squared_norm(rhs))
        if scale_squared == 0.0:
            return arrays.xp.zeros_like(rhs), False
        scale = math.sqrt(scale_squared)
        product = wp.zeros(matrix.nrow, dtype=wp.vec3d, device=matrix.device)
        for _ in range(self.max_refinements):
            x_wp = arrays.warp(arrays.xp.ascontiguousarray(x))  # ``x`` stays alive meanwhile
            wps.bsr_mv(matrix, x_wp, product, alpha=1.0, beta=0.0)
            residual = rhs - arrays.view(product)
            residual_squared, x_squared = arrays.floats(
                arrays.squared_norm(residual), arrays.squared_norm(x)
            )
            if not math.isfinite(x_squared):  # (non-finite entries)
                return x, True
            if math.sqrt(residual_squared) <= self.refinement_tolerance * scale:
                return x, False
            correction, _ = solver.solve_factorized(matrix, residual)
            self.solves += 1
            self.refinement_steps += 1
            x = x + correction
        return x, True


def check_sensitivity_names(names: Sequence[str] | str) -> tuple[str, ...]:
    """The names as a tuple; a bare string is refused (a common slip for a 1-tuple)."""
    if isinstance(names, str):
        raise InputError(
            "sensitivities must be a sequence of parameter names, e.g. ('C10_Pa',)", value=names
        )
    return tuple(names)
