"""GMRES with an earlier factorization as preconditioner: against SciPy's direct solve, and
the Newton solve that reuses a factorization against a fresh factorization."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse
import scipy.sparse.linalg
import warp as wp
from fem_cases import compression_conditions

from warptissue.fem import Assembler, LinearSolver, NewtonOptions, solve_quasistatic
from warptissue.fem.linear import solver as linear_solver
from warptissue.fem.linear.krylov import gmres
from warptissue.materials import NeoHookean
from warptissue.mesh import block_mesh, to_tet10


def _system(rng, n=300, perturbation=0.05):
    """A sparse nonsymmetric matrix A and the LU factors of a perturbed copy of it."""
    base = scipy.sparse.random(n, n, density=0.02, random_state=np.random.RandomState(3))
    a = (base + base.T + 10.0 * scipy.sparse.eye(n)).tocsc()
    noise = scipy.sparse.random(n, n, density=0.01, random_state=np.random.RandomState(4))
    near = (a + perturbation * noise).tocsc()
    return a, scipy.sparse.linalg.splu(near)


@pytest.mark.parametrize("rtol", [1e-4, 1e-10])
def test_gmres_with_a_nearby_factorization_matches_the_direct_solve(rng, rtol):
    a, lu = _system(rng)
    b = rng.standard_normal(a.shape[0])
    outcome = gmres(lambda v: a @ v, lu.solve, b, rtol=rtol, max_iterations=40)
    reference = scipy.sparse.linalg.spsolve(a, b)
    assert outcome.converged
    assert 1 <= outcome.iterations <= 20
    assert outcome.relative_residual == pytest.approx(
        np.linalg.norm(b - a @ outcome.x) / np.linalg.norm(b)
    )
    assert outcome.relative_residual <= rtol
    # the error is bounded by the condition number times the residual
    condition = np.linalg.cond(a.toarray())
    error = np.linalg.norm(outcome.x - reference) / np.linalg.norm(reference)
    assert error <= condition * rtol


def test_gmres_keeps_block_shapes_and_stops_when_told(rng):
    a, lu = _system(rng, n=150, perturbation=2.0)  # a poor preconditioner: many iterations
    b = rng.standard_normal((50, 3))
    calls = []
    outcome = gmres(
        lambda v: (a @ v.reshape(-1)).reshape(v.shape),
        lambda v: lu.solve(v.reshape(-1)).reshape(v.shape),
        b,
        rtol=1e-14,
        max_iterations=40,
        keep_going=lambda k, relative: calls.append((k, relative)) or k < 2,
    )
    assert outcome.x.shape == (50, 3)
    assert [k for k, _ in calls] == [1, 2] and outcome.iterations == 2
    assert 0.0 < calls[1][1] <= calls[0][1] < 1.0  # GMRES residuals never grow
    assert not outcome.converged
    assert outcome.relative_residual == pytest.approx(
        np.linalg.norm(b.reshape(-1) - a @ outcome.x.reshape(-1)) / np.linalg.norm(b)
    )


def test_gmres_of_a_zero_right_hand_side_is_zero():
    outcome = gmres(lambda v: v, lambda v: v, np.zeros(4), rtol=1e-8, max_iterations=3)
    assert outcome.converged and outcome.iterations == 0
    np.testing.assert_array_equal(outcome.x, 0.0)


def test_gmres_refuses_bad_settings():
    with pytest.raises(ValueError, match="rtol"):
        gmres(lambda v: v, lambda v: v, np.ones(3), rtol=1.0, max_iterations=3)
    with pytest.raises(ValueError, match="max_iterations"):
        gmres(lambda v: v, lambda v: v, np.ones(3), rtol=1e-3, max_iterations=0)


def _cube_tangents(device, rng, scale):
    """The eliminated tangent of a compressed TET10 cube at two nearby states."""
    grid = np.linspace(0.0, 1e-2, 3)
    mesh = to_tet10(block_mesh(grid, grid, grid))
    assembler = Assembler(mesh, NeoHookean(100.0, 1e4), device=device)
    conditions = compression_conditions(mesh)
    constrained = wp.array(
        conditions.mask(mesh.node_count), dtype=wp.vec3d, device=assembler.device
    )
    u = 1e-4 * rng.standard_normal((mesh.node_count, 3))
    return assembler, constrained, u, u + scale * rng.standard_normal(u.shape)


def test_a_newton_solve_reuses_the_factorization_of_a_nearby_tangent(device, rng):
    assembler, constrained, u0, u1 = _cube_tangents(device, rng, 1e-6)
    solver = LinearSolver(device=assembler.device)
    rhs = rng.standard_normal((assembler.node_count, 3))
    matrix = assembler.assemble(u0).matrix
    assembler.eliminate(constrained)
    first, count = solver.solve_newton(matrix, rhs, rtol=1e-10)
    assert count == 1 and solver.factorizations == 1 and solver.reused_solves == 0
    assembler.assemble(u1)
    assembler.eliminate(constrained)
    solver._factorization_s = 1e9  # a generous budget: the decision is tested below
    x, iterations = solver.solve_newton(matrix, rhs, rtol=1e-10)
    assert solver.factorizations == 1 and solver.reused_solves == 1
    assert 1 <= iterations <= 10
    fresh = LinearSolver(device=assembler.device, method=solver.method)
    reference, _ = fresh.solve(matrix, rhs)
    np.testing.assert_allclose(x, reference, rtol=0, atol=1e-8 * np.abs(reference).max())
    assert not np.allclose(first, reference, rtol=0, atol=1e-8 * np.abs(reference).max())


def test_a_newton_solve_factorizes_when_gmres_would_cost_more(device, rng):
    assembler, constrained, u0, u1 = _cube_tangents(device, rng, 1e-6)
    solver = LinearSolver(device=assembler.device)
    rhs = rng.standard_normal((assembler.node_count, 3))
    matrix = assembler.assemble(u0).matrix
    assembler.eliminate(constrained)
    solver.solve_newton(matrix, rhs, rtol=1e-10)
    assembler.assemble(u1)
    assembler.eliminate(constrained)
    solver._factorization_s = 0.0  # no time for a single GMRES iteration
    x, _ = solver.solve_newton(matrix, rhs, rtol=1e-10)
    assert solver.factorizations == 2 and solver.failed_reuses == 1
    reference, _ = LinearSolver(device=assembler.device, method=solver.method).solve(matrix, rhs)
    np.testing.assert_allclose(x, reference, rtol=0, atol=1e-10 * np.abs(reference).max())
    # and without reuse every Newton solve factorizes
    solver.solve_newton(matrix, rhs, rtol=1e-10, reuse=False)
    assert solver.factorizations == 3


def test_reusing_factorizations_keeps_the_load_path(device, monkeypatch):
    """A compressed TET10 cube, with and without reuse (with a budget that always lets GMRES
    try): the same converged forces, and most Newton solves without a factorization."""
    monkeypatch.setattr(linear_solver, "REUSE_BUDGET", 1e6)
    grid = np.linspace(0.0, 1e-2, 3)
    mesh = to_tet10(block_mesh(grid, grid, grid))
    weights = np.zeros((mesh.node_count, 3))
    weights[mesh.node_sets["zmax"], 2] = 1.0
    paths = {}
    for reuse in (False, True):
        assembler = Assembler(mesh, NeoHookean(100.0, 2e5), device=device)
        paths[reuse] = solve_quasistatic(
            assembler,
            compression_conditions(mesh),
            1e-2 * np.linspace(0.02, 0.3, 8),
            reaction_weights=weights,
            options=NewtonOptions(tolerance=1e-9, reuse_factorization=reuse),
        )
        assert paths[reuse].completed, paths[reuse].message
    plain, reused = paths[False], paths[True]
    np.testing.assert_allclose(reused.reaction, plain.reaction, rtol=1e-7)
    assert plain.linear_solver_statistics["reused_solves"] == 0
    assert plain.linear_solver_statistics["factorizations"] == plain.newton_iterations.sum()
    statistics = reused.linear_solver_statistics
    assert statistics["reused_solves"] > statistics["factorizations"]
    assert statistics["factorizations"] + statistics["reused_solves"] == (
        reused.newton_iterations.sum()
    )
