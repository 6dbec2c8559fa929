"""Nonlinear elimination: the few nodes that hold most of a problem's residual after a global
Newton step are relaxed by a local Newton solve with all its other nodes fixed.

Of K problems solved together, each problem whose residual is above its limit is relaxed on
its own patch (the problems share no node, so their patches, tets and tangent blocks are
disjoint); the global convergence test is unchanged.
"""

from __future__ import annotations

import importlib.util
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse.linalg
import warp as wp

from warptissue.fem.arrays import DeviceArrays
from warptissue.fem.assembly import Assembler, Assembly
from warptissue.fem.gather import scatter_vectors

__all__ = ["nonlinear_elimination", "patch_solve"]


def _norm(values: np.ndarray) -> float:
    """Euclidean norm of all entries (NumPy's own loop, no BLAS thread start-up)."""
    return math.sqrt(float(np.einsum("ij,ij->", values, values)))


def nonlinear_elimination(
    assembler: Assembler,
    assembly: Assembly,
    u: Any,
    free: Any,
    limit: float,
    *,
    problem: int = 0,
    nodes: slice | None = None,
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
        problem: Of K problems packed into the mesh, the one relaxed (its energy, smallest
            J and residual norm are its own; the others' nodes are not touched).
        nodes: That problem's node range (None: the whole mesh, one problem).
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
            return nonlinear_elimination(
                assembler,
                assembly,
                u,
                free,
                limit,
                problem=problem,
                nodes=nodes,
                seed_count=seed_count,
                max_iterations=max_iterations,
                ratio=ratio,
                arrays=arrays,
            )
    u, free = arrays.asarray(u), arrays.asarray(free)
    residual = arrays.view(assembly.residual)
    if nodes is None:
        nodes = slice(0, assembler.node_count)
    free_residual = residual * free
    patch = _residual_patch(assembler, arrays, free_residual, nodes, seed_count)
    if patch is None:
        return u, assembly, 0
    local = _Patch.around(assembler, arrays, patch, free)
    trials, state = local.start(
        assembler, arrays, assembly, u, free_residual, nodes=nodes, problem=problem
    )
    state, iterations = local.newton(
        assembler, trials, state, limit=limit, max_iterations=max_iterations, ratio=ratio
    )
    if iterations == 0:
        # Nothing moved and the tangent is untouched (it is only reassembled after a step).
        return u, assembly, 0
    u, assembly = local.relaxed(assembler, arrays, assembly, u, residual, state, problem=problem)
    return u, assembly, iterations


@dataclass(frozen=True)
class _Patch:
    """The patch's nodes and its tets' (the part's) nodes, and where each sits: on the host
    (``at_patch``: the patch's positions among the part's nodes) and in the arrays of the
    whole mesh (``nodes_at``, ``patch_at``); its free dofs (``free_part``, ``free_patch``
    (P, 3), ``patch_free`` (3P,) bool)."""

    nodes: np.ndarray
    part: Any
    nodes_at: Any
    patch_at: Any
    at_patch: np.ndarray
    free_part: np.ndarray
    free_patch: np.ndarray
    patch_free: np.ndarray

    @classmethod
    def around(
        cls, assembler: Assembler, arrays: DeviceArrays, patch: np.ndarray, free: Any
    ) -> _Patch:
        # Only the tets holding a patch node change, and with them the residual at their
        # nodes: the whole residual and energy follow from the last ones and the change of
        # that part. The host works on the part's nodes alone (no array of the whole mesh
        # per trial).
        part = assembler.element_part(nodes=patch)
        xp = arrays.xp
        at_patch = np.searchsorted(part.nodes, patch)
        free_part = arrays.host(free[xp.asarray(part.nodes)])
        free_patch = free_part[at_patch]
        return cls(
            nodes=patch,
            part=part,
            nodes_at=xp.asarray(part.nodes),
            patch_at=xp.asarray(patch),
            at_patch=at_patch,
            free_part=free_part,
            free_patch=free_patch,
            patch_free=free_patch.reshape(-1) > 0.5,
        )

    def start(
        self,
        assembler: Assembler,
        arrays: DeviceArrays,
        assembly: Assembly,
        u: Any,
        free_residual: Any,
        *,
        nodes: slice,
        problem: int,
    ) -> tuple[_PatchTrials, _PatchState]:
        """The trials' buffers and the patch's state at ``u`` (its part assembled)."""
        outside = arrays.xp.zeros(len(u), dtype=bool)
        outside[nodes] = True
        outside[self.nodes_at] = False
        rest_squared, total_squared = arrays.floats(
            arrays.squared_norm(free_residual[outside]),
            arrays.squared_norm(free_residual[nodes]),
        )
        trials = _PatchTrials(
            assembler=assembler,
            part=self.part,
            patch=wp.array(self.nodes.astype(np.int32), dtype=wp.int32, device=assembler.device),
            values=wp.zeros(len(self.nodes), dtype=wp.vec3d, device=assembler.device),
            state=arrays.warp(u.copy()),  # the trials are scattered into it
            free_part=self.free_part,
            rest_squared=rest_squared,
        )
        forces, part_energy, _ = assembler.assemble_part(trials.state, self.part)
        state = _PatchState(
            u_patch=arrays.host(u[self.patch_at]),
            residual_part=arrays.host(arrays.view(assembly.residual)[self.nodes_at]),
            energy=float(assembly.problem_energies_J[problem]),
            total=math.sqrt(total_squared),
            forces=forces,
            part_energy=part_energy,
            min_jacobian=float(assembly.problem_min_jacobians[problem]),
        )
        return trials, state

    def newton(
        self,
        assembler: Assembler,
        trials: _PatchTrials,
        state: _PatchState,
        *,
        limit: float,
        max_iterations: int,
        ratio: float,
    ) -> tuple[_PatchState, int]:
        """Newton's method on the patch alone (as :func:`nonlinear_elimination` says).

        Returns:
            (the last accepted state, the local iterations taken).
        """
        at_patch, free_patch, patch_free = self.at_patch, self.free_patch, self.patch_free
        iterations = 0
        for _ in range(max_iterations):
            if iterations:  # the patch's tangent at the new state (the whole matrix is spoilt)
                state.forces, state.part_energy, _ = assembler.assemble_part(
                    trials.state, self.part, with_tangent=True
                )
            local_residual = (state.residual_part[at_patch] * free_patch).reshape(-1)[patch_free]
            step = patch_solve(assembler, self.nodes, patch_free, local_residual)
            if step is None:
                break
            slope = float(local_residual @ step)
            if not (np.all(np.isfinite(step)) and slope < 0.0):
                break
            patch_step = np.zeros(3 * len(self.nodes))
            patch_step[patch_free] = step
            accepted = trials.backtrack(state, patch_step.reshape(-1, 3), slope)
            if accepted is None:
                break
            iterations += 1
            state = accepted
            local = _norm(state.residual_part[at_patch] * free_patch)
            total = state.total
            if total <= limit or local <= ratio * math.sqrt(max(total**2 - local**2, 0.0)):
                break
        return state, iterations

    def relaxed(
        self,
        assembler: Assembler,
        arrays: DeviceArrays,
        assembly: Assembly,
        u: Any,
        residual: Any,
        state: _PatchState,
        *,
        problem: int,
    ) -> tuple[Any, Assembly]:
        """The whole state with the patch's relaxed, and its assembly (residual, energies and
        smallest J; no tangent)."""
        u = u.copy()
        u[self.patch_at] = arrays.asarray(state.u_patch)
        residual = residual.copy()
        residual[self.nodes_at] = arrays.asarray(state.residual_part)
        energies = np.array(assembly.problem_energies_J, dtype=np.float64)
        min_jacobians = np.array(assembly.problem_min_jacobians, dtype=np.float64)
        energies[problem], min_jacobians[problem] = state.energy, state.min_jacobian
        assembly = Assembly(
            residual=assembler.set_residual(residual),
            matrix=None,
            energy_J=float(energies.sum()),
            min_jacobian=float(min_jacobians.min()),
            problem_energies_J=energies,
            problem_min_jacobians=min_jacobians,
        )
        return u, assembly


def _residual_patch(
    assembler: Assembler,
    arrays: DeviceArrays,
    free_residual: Any,
    nodes: slice,
    seed_count: int,
) -> np.ndarray | None:
    """The patch to relax: the (up to) ``seed_count`` nodes of ``nodes`` with the largest
    free residual (at least 1e-3 of the largest) and their neighbours; None where the
    residual is zero or the patch would hold more than a quarter of the nodes."""
    xp = arrays.xp
    norms = arrays.row_norms(free_residual[nodes])
    count = min(seed_count, len(norms))
    seeds = xp.argpartition(norms, len(norms) - count)[len(norms) - count :]
    seeds, seed_norms = arrays.host(seeds), arrays.host(norms[seeds])
    seeds = seeds + nodes.start
    largest = float(seed_norms.max())
    if largest == 0.0:
        return None
    patch = assembler.node_patch(seeds[seed_norms >= 1e-3 * largest])
    if 4 * len(patch) > nodes.stop - nodes.start:
        return None
    return patch


@dataclass
class _PatchState:
    """A state of the patch on the host: its displacements (P, 3), m; the residual at the
    part's nodes (R, 3), N; the problem's energy, J; the whole free residual norm, N; the
    part's forces (R, 3), N, and energy, J; the smallest det F so far."""

    u_patch: np.ndarray
    residual_part: np.ndarray
    energy: float
    total: float
    forces: np.ndarray
    part_energy: float
    min_jacobian: float


@dataclass
class _PatchTrials:
    """Evaluates trial states of a patch: scatters them into the device state and assembles
    the part's tets alone."""

    assembler: Assembler
    part: Any
    patch: wp.array
    values: wp.array
    state: wp.array
    free_part: np.ndarray
    rest_squared: float

    def backtrack(
        self, state: _PatchState, direction: np.ndarray, slope: float
    ) -> _PatchState | None:
        """The first of ``state.u_patch + alpha direction``, alpha = 1, 1/2, ... (8 tries),
        where every J > 0, the energy decreases (Armijo, 1e-4) and the whole free residual
        norm decreases; None where none does."""
        alpha = 1.0
        for _ in range(8):
            trial = state.u_patch + alpha * direction
            self.values.assign(trial)
            scatter_vectors(self.values, self.patch, self.state)
            forces, part_energy, min_jacobian = self.assembler.assemble_part(self.state, self.part)
            residual_part = state.residual_part + (forces - state.forces)
            energy = state.energy + (part_energy - state.part_energy)
            trial_free = residual_part * self.free_part
            total = math.sqrt(self.rest_squared + np.einsum("ij,ij->", trial_free, trial_free))
            if (
                min_jacobian > 0.0
                and math.isfinite(energy)
                and energy <= state.energy + 1e-4 * alpha * slope
                and total < state.total
            ):
                return _PatchState(
                    u_patch=trial,
                    residual_part=residual_part,
                    energy=energy,
                    total=total,
                    forces=forces,
                    part_energy=part_energy,
                    min_jacobian=min(state.min_jacobian, min_jacobian),
                )
            alpha *= 0.5
        return None


def patch_solve(
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
