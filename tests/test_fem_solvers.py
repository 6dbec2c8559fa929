"""Newton load stepping and linear solvers: homogeneous uniaxial compression against the
incompressible analytic solutions (the needle-indentation study, Eq. 3), solver agreement,
cutback."""

from __future__ import annotations

import gc

import numpy as np
import pytest
import warp as wp
from fem_cases import compression_conditions

from warptissue.errors import InputError
from warptissue.fem import (
    Assembler,
    DirichletConditions,
    IndentationProblem,
    LinearSolver,
    NewtonOptions,
    simulate_indentation,
    solve_quasistatic,
)
from warptissue.fem.arrays import DeviceArrays
from warptissue.fem.linear import solver as linear_solver_module
from warptissue.fem.linear.direct import pardiso_available
from warptissue.fem.newton import increment as newton_increments
from warptissue.fem.newton.elimination import nonlinear_elimination, patch_solve
from warptissue.fem.newton.options import (
    ELIMINATION_MIN_TETS_CUDA,
    REUSE_MIN_TETS_CUDA,
    elimination_pays,
    reuse_pays,
)
from warptissue.fem.newton.problems import Problems
from warptissue.fem.newton.search import search_steps
from warptissue.fem.newton.steering import DAMPING_START, next_damping
from warptissue.indenter import Indenter
from warptissue.materials import MooneyRivlin, NeoHookean, Ogden, ReducedPolynomial
from warptissue.mesh import block_mesh, indentation_block, to_tet10

SIDE_M = 1e-2


def _cube():
    grid = np.linspace(0.0, SIDE_M, 3)
    return to_tet10(block_mesh(grid, grid, grid))


def _nominal_stress(material, stretches, *, linear_solver="auto"):
    mesh = _cube()
    weights = np.zeros((mesh.node_count, 3))
    weights[mesh.node_sets["zmax"], 2] = 1.0
    assembler = Assembler(mesh, material, formulation="mixed", device="cpu")
    path = solve_quasistatic(
        assembler,
        compression_conditions(mesh),
        SIDE_M * (1.0 - stretches),
        reaction_weights=weights,
        options=NewtonOptions(linear_solver=linear_solver),
    )
    assert path.completed, path.message
    return path.reaction / SIDE_M**2, path


# Incompressible uniaxial nominal stress S(l) = dW/dl with W(l, l^-1/2, l^-1/2), derived here:
# NH:  W = C10 (l^2 + 2/l - 3)                      -> S = 2 C10 (l - l^-2)
# MR:  + C01 (2 l + l^-2 - 3)                        -> S = 2 (1 - l^-3)(C10 l + C01)
# RP2: + C20 (I1 - 3)^2                              -> S = 2 (l - l^-2)(C10 + 2 C20 (I1 - 3))
# Ogden: W = sum 2 mu/a^2 (l^a + 2 l^(-a/2) - 3)     -> S = sum 2 mu/a (l^(a-1) - l^(-a/2-1))
ANALYTIC = {
    "neo_hookean": (
        NeoHookean(100.0, 2.0e5),
        lambda s: 2 * 100.0 * (s - s**-2),
    ),
    "mooney_rivlin": (
        MooneyRivlin(80.0, 20.0, 2.0e5),
        lambda s: 2 * (1 - s**-3) * (80.0 * s + 20.0),
    ),
    "reduced_polynomial_2": (
        ReducedPolynomial((600.553, 4097.45), 1.2e7),
        lambda s: 2 * (s - s**-2) * (600.553 + 2 * 4097.45 * (s**2 + 2 / s - 3)),
    ),
    "ogden": (
        Ogden((150.0, -20.0), (6.0, -3.0), 2.6e5),
        lambda s: 2 * 150.0 / 6.0 * (s**5 - s**-4) + 2 * -20.0 / -3.0 * (s**-4 - s**0.5),
    ),
}


@pytest.mark.parametrize("name", list(ANALYTIC))
def test_uniaxial_compression_matches_incompressible_analytic(name):
    material, analytic = ANALYTIC[name]
    assert material.bulk_modulus_Pa >= 1000 * material.initial_shear_modulus_Pa
    stretches = np.array([0.9, 0.8, 0.7])
    stress, path = _nominal_stress(material, stretches)
    np.testing.assert_allclose(stress, analytic(stretches), rtol=5e-3)
    assert np.all(path.newton_iterations <= 8)  # quadratic convergence, consistent tangent


@pytest.mark.slow
def test_linear_solvers_agree(rng):
    mesh = _cube()
    assembler = Assembler(mesh, NeoHookean(100.0, 1e4), device="cpu")
    conditions = compression_conditions(mesh)
    u = 1e-4 * rng.standard_normal((mesh.node_count, 3))
    assembly = assembler.assemble(u)
    assembler.eliminate(
        wp.array(conditions.mask(mesh.node_count), dtype=wp.vec3d, device=assembler.device)
    )
    rhs = rng.standard_normal((mesh.node_count, 3))
    methods = ["superlu", "cg"] + (["pardiso"] if pardiso_available() else [])
    solutions = {}
    for method in methods:
        solver = LinearSolver(method=method, device=assembler.device, tolerance=1e-13)
        solutions[method], iterations = solver.solve(assembly.matrix, rhs)
        assert iterations >= 1
    reference = solutions["superlu"]
    for method, x in solutions.items():
        np.testing.assert_allclose(
            x, reference, rtol=0, atol=1e-8 * np.abs(reference).max(), err_msg=method
        )


def test_cutback_recovers_and_reports(rng):
    """One huge increment (to stretch 0.3) needs cutbacks; with none allowed it stops cleanly."""
    material = NeoHookean(100.0, 2.0e5)
    mesh = _cube()
    assembler = Assembler(mesh, material, device="cpu")
    conditions = compression_conditions(mesh)
    target = [SIDE_M * 0.2, SIDE_M * 0.7]
    path = solve_quasistatic(
        assembler, conditions, target, options=NewtonOptions(max_newton_iterations=4)
    )
    assert path.completed and path.cutbacks > 0
    # The residual of homogeneous compression is spread over the whole cube: the nonlinear
    # elimination's patch would hold more than a quarter of the nodes, so it stays out.
    assert path.local_iterations.sum() == 0
    stopped = solve_quasistatic(
        assembler,
        conditions,
        target,
        options=NewtonOptions(max_newton_iterations=4, max_cutbacks=0),
    )
    assert not stopped.completed
    assert len(stopped.loads) == 1 and stopped.loads[0] == target[0]
    assert "cutbacks" in stopped.message and "kept" in stopped.message


def test_line_search_finds_the_energy_minimum_along_an_overshooting_direction(rng):
    """A Newton direction scaled so that the energy minimum along it lies at alpha = 0.3: the
    search must stop near it, where the energy's directional derivative g has fallen to half
    of g(0) (plain halving until the energy or the residual decreases stops at alpha = 0.5,
    where |g| is 2.8 |g(0)| here). Near a quadratic minimum it takes the full Newton step at
    once."""
    mesh = _cube()
    assembler = Assembler(mesh, NeoHookean(100.0, 1e4), formulation="mixed", device="cpu")
    conditions = compression_conditions(mesh)
    mask = conditions.mask(mesh.node_count)
    free = 1.0 - mask
    solver = LinearSolver(method="superlu", device=assembler.device)

    def state(scale):
        u = scale * rng.standard_normal((mesh.node_count, 3)) * free
        assembly = assembler.assemble(u)
        residual = assembly.residual.numpy()
        assembler.eliminate(wp.array(mask, dtype=wp.vec3d, device=assembler.device))
        newton, _ = solver.solve(assembly.matrix, -residual * free)
        return u, assembly.energy_J, np.linalg.norm(residual * free), newton

    def slope_at(u, direction, alpha):
        r = assembler.assemble(u + alpha * direction, with_tangent=False).residual.numpy()
        return float(np.sum(r * free * direction))

    u, energy_J, residual_norm, newton = state(2e-4)
    scan = np.linspace(0.0, 1.0, 401)
    energies = [assembler.assemble(u + t * newton, with_tangent=False).energy_J for t in scan]
    t_min = scan[int(np.argmin(energies))]
    assert 0.05 < t_min < 0.95  # far from equilibrium: the Newton step itself is too long
    direction = (t_min / 0.3) * newton
    g0 = slope_at(u, direction, 0.0)
    assert g0 < 0.0
    search = _line_search(assembler, u, direction, free, energy_J, g0, residual_norm)
    assert search.found[0] and search.assembly is not None
    alpha = float(search.alpha[0])
    assert abs(slope_at(u, direction, alpha)) <= 0.5 * abs(g0)
    assert abs(alpha - 0.3) < 0.1
    assert search.assembly.energy_J < energy_J
    np.testing.assert_allclose(search.state, u + alpha * direction)

    u, energy_J, residual_norm, newton = state(1e-8)
    exact = _line_search(
        assembler, u, newton, free, energy_J, slope_at(u, newton, 0.0), residual_norm
    )
    assert exact.alpha[0] == 1.0


def _line_search(assembler, u, direction, free, energy_J, slope, residual_norm):
    """The step search of one problem at a later (not first) Newton iteration."""
    problems = Problems(DeviceArrays(assembler.device), [0, assembler.node_count])
    return search_steps(
        assembler,
        problems,
        u,
        direction,
        free,
        searching=np.array([True]),
        first=np.array([False]),
        prescribed_increment=np.zeros_like(u),
        energies_J=np.array([energy_J]),
        slopes=np.array([slope]),
        residual_norms=np.array([residual_norm]),
    )


def _one_increment(assembler, u_start, prescribed, free, **options):
    """One load increment of one problem (:func:`newton_increment` with K = 1)."""
    arrays = DeviceArrays(assembler.device)
    return newton_increments.newton_increment(
        assembler,
        LinearSolver(method="superlu", device=assembler.device),
        Problems(arrays, [0, assembler.node_count]),
        u_start,
        prescribed,
        free,
        1.0 - free,
        active=np.array([True]),
        tolerance=1e-8,
        force_floors=np.zeros(1),
        **options,
    )


def test_conditions_validate():
    with pytest.raises(InputError, match="conflicting"):
        DirichletConditions([0, 0], [2, 2], [0.0, 1.0])
    with pytest.raises(InputError, match="components"):
        DirichletConditions([0], [3], [0.0])
    merged = DirichletConditions([3, 1, 3], [0, 2, 0], [0.5, 0.0, 0.5])
    np.testing.assert_array_equal(merged.nodes, [1, 3])
    with pytest.raises(InputError, match="linear solver"):
        LinearSolver(method="lu", device=wp.get_device("cpu"))


@pytest.mark.parametrize(
    "spec", ["neo_hookean", "mooney_rivlin", "reduced_polynomial:2", "ogden:1"]
)
def test_fe_agrees_with_the_closed_form_fitting_models(spec):
    """The incompressible closed forms that the analytic fits use (warptissue.materials) agree
    with a homogeneous nearly incompressible FE run of the same model with a bulk modulus."""
    from warptissue.fit.hyperelastic import model_from_name

    parameters = {
        "neo_hookean": [150.0],
        "mooney_rivlin": [120.0, 30.0],
        "reduced_polynomial:2": [600.553, 4097.45],
        "ogden:1": [300.0, 4.0],
    }[spec]
    model = model_from_name(spec).with_parameters(np.array(parameters))
    material = model.with_bulk_modulus(2000.0 * model.initial_shear_modulus_Pa)
    stretches = np.array([0.9, 0.8, 0.7])
    stress, _ = _nominal_stress(material, stretches)
    closed_form = model.nominal_stress_Pa(stretches, "uniaxial")
    np.testing.assert_allclose(stress, closed_form, rtol=5e-3)


PUNCH_RADIUS_M = 1e-3


def _bonded_punch() -> IndentationProblem:
    """Quarter block under a bonded flat punch, TET10/P0, K/mu = 1000, 1 728 tets."""
    mesh = indentation_block(
        width_m=0.012,
        thickness_m=0.006,
        probe_radius_m=PUNCH_RADIUS_M,
        quarter=True,
        size_near_m=PUNCH_RADIUS_M / 2.5,
        size_far_m=3e-3,
    )
    return IndentationProblem(
        mesh,
        NeoHookean(287.5, 575e3),
        Indenter("flat_punch", radius_m=PUNCH_RADIUS_M, contact="bonded"),
        symmetry_planes=("symmetry_x", "symmetry_y"),
    )


def _bonded_punch_runs(depths, option: str, values) -> dict:
    """The bonded punch pressed through ``depths`` once per value of one solver option."""
    problem = _bonded_punch()
    return {
        value: simulate_indentation(
            problem,
            depths,
            device="cpu",
            progress=False,
            options=NewtonOptions(tolerance=1e-8, **{option: value}),
        )
        for value in values
    }


@pytest.mark.slow
def test_nonlinear_elimination_saves_newton_iterations_and_keeps_the_curve():
    """Bonded flat punch (TET10/P0, K/mu = 1000, 1 728 tets): relaxing the residual peaks at
    the punch edge after each global step saves global Newton iterations (factorizations;
    measured 18 -> 12 here), and the converged forces equal those of plain Newton to the
    tolerance. The default ("auto") on the CPU is the elimination, iteration for iteration."""
    depths = PUNCH_RADIUS_M * np.array([0.05, 0.1, 0.15])
    results = _bonded_punch_runs(depths, "nonlinear_elimination", (False, True, "auto"))
    plain, relaxed = results[False], results[True]
    np.testing.assert_array_equal(results["auto"].newton_iterations, relaxed.newton_iterations)
    np.testing.assert_allclose(  # PARDISO's run-to-run roundoff
        results["auto"].reaction_force_N, relaxed.reaction_force_N, rtol=1e-10
    )
    assert plain.completed and relaxed.completed
    assert plain.local_iterations.sum() == 0
    assert relaxed.local_iterations.sum() > 0
    assert relaxed.newton_iterations.sum() < plain.newton_iterations.sum()
    np.testing.assert_allclose(relaxed.reaction_force_N, plain.reaction_force_N, rtol=1e-8)


def test_nonlinear_elimination_returns_the_assembly_of_the_state_it_returns():
    """Whether a local step is taken or every trial is refused (here: trials made to look
    inverted), the returned assembly's residual is that of the returned displacement (to
    roundoff: the elimination updates it from the patch's part), not of the last trial."""
    problem = _bonded_punch()
    mesh = problem.mesh
    conditions = problem.dirichlet_conditions()
    mask = conditions.mask(mesh.node_count)
    free = 1.0 - mask
    assembler = Assembler(mesh, problem.material, device="cpu")
    # The state after the first Newton iteration of a step (plain Newton stopped there):
    # prescribed depth, free dofs at the linear prediction, residual at the punch edge.
    first = _one_increment(
        assembler,
        np.zeros((mesh.node_count, 3)),
        conditions.values(0.1 * PUNCH_RADIUS_M, mesh.node_count),
        free,
        max_iterations=1,
        nonlinear_elimination_on=False,
    )
    assert not first.converged[0]
    u = first.last_iterate

    def inverted_trials(displacement, part, *, with_tangent=False):
        forces, energy, _ = Assembler.assemble_part(
            assembler, displacement, part, with_tangent=with_tangent
        )
        return forces, energy, -1.0

    for refuse in (False, True):
        start = assembler.assemble(u)
        if refuse:
            assembler.assemble_part = inverted_trials
        returned, assembly, iterations = nonlinear_elimination(assembler, start, u, free, limit=0.0)
        residual = assembly.residual.numpy().copy()
        energy = assembly.energy_J
        if refuse:
            del assembler.assemble_part
            assert iterations == 0
            np.testing.assert_array_equal(returned, u)
        else:
            assert iterations > 0
            assert assembly.matrix is None
        fresh = assembler.assemble(returned, with_tangent=False)
        scale = np.abs(fresh.residual.numpy()).max()
        np.testing.assert_allclose(residual, fresh.residual.numpy(), rtol=0, atol=1e-12 * scale)
        assert energy == pytest.approx(fresh.energy_J, rel=1e-12)


@pytest.mark.skipif(
    not (wp.is_cuda_available() and DeviceArrays(wp.get_device("cuda:0")).resident),
    reason="needs a CUDA device and CuPy",
)
def test_no_nodal_array_leaves_the_gpu_inside_a_load_increment(monkeypatch):
    """On a GPU the Newton iterations (line search, nonlinear elimination and linear solves
    included) read scalars and the elimination's patch from the device, never an array of
    the whole mesh; the converged curve is that of the CPU."""
    import cupy

    problem = _bonded_punch()
    node_count = problem.mesh.node_count
    depths = PUNCH_RADIUS_M * np.array([0.05, 0.1])
    reference = simulate_indentation(
        problem, depths, device="cpu", progress=False, options=NewtonOptions(tolerance=1e-10)
    )
    inside, copied = [False], []
    numpy_of_warp, asnumpy = wp.array.numpy, cupy.asnumpy
    increment = newton_increments.newton_increment

    def record(values):
        if inside[0] and values.shape and values.shape[0] == node_count:
            copied.append(values.shape)

    def warp_to_numpy(self):
        if self.device.is_cuda:
            record(self)
        return numpy_of_warp(self)

    def cupy_to_numpy(values, *args, **kwargs):
        record(values)
        return asnumpy(values, *args, **kwargs)

    def watched(*args, **kwargs):
        inside[0] = True
        try:
            return increment(*args, **kwargs)
        finally:
            inside[0] = False

    monkeypatch.setattr(wp.array, "numpy", warp_to_numpy)
    monkeypatch.setattr(cupy, "asnumpy", cupy_to_numpy)
    monkeypatch.setattr(newton_increments, "newton_increment", watched)
    # The elimination on (its rule turns it off on CUDA below 16 000 tets), so it is watched.
    options = NewtonOptions(tolerance=1e-10, nonlinear_elimination=True)
    result = simulate_indentation(problem, depths, device="cuda:0", progress=False, options=options)
    assert result.completed, result.message
    assert result.local_iterations.sum() > 0  # the elimination ran
    assert copied == []
    np.testing.assert_allclose(result.reaction_force_N, reference.reaction_force_N, rtol=1e-8)


def test_the_patch_step_is_the_solve_of_the_patch_tangent(device, rng):
    """The nonlinear elimination's patch step (dense LU on a GPU with CuPy, SuperLU on the
    CPU) solves the patch's free block of the tangent, which the dense copy on the device
    holds as the sparse one does."""
    problem = _bonded_punch()
    mesh = problem.mesh
    assembler = Assembler(mesh, problem.material, device=device)
    assembler.assemble(1e-5 * rng.standard_normal((mesh.node_count, 3)))
    patch = assembler.node_patch(np.array([5, 17, 40]))
    sparse = assembler.tangent_submatrix(patch).toarray()
    dense = assembler.tangent_submatrix_dense(patch).numpy()
    np.testing.assert_array_equal(dense, sparse)
    free = rng.random(3 * len(patch)) > 0.2
    residual = rng.standard_normal(int(free.sum()))
    step = patch_solve(assembler, patch, free, residual)
    reference = np.linalg.solve(sparse[free][:, free], -residual)
    np.testing.assert_allclose(step, reference, rtol=1e-9, atol=1e-12 * np.abs(reference).max())


def test_a_part_of_the_tets_adds_up_with_the_rest_to_the_whole_assembly(rng):
    """The forces, energy and patch tangent blocks of some tets, with those of the other
    tets, equal the whole mesh's."""
    problem = _bonded_punch()
    mesh = problem.mesh
    assembler = Assembler(mesh, problem.material, device="cpu")
    u = 1e-5 * rng.standard_normal((mesh.node_count, 3))
    whole = assembler.assemble(u)
    whole_residual = whole.residual.numpy().copy()
    nodes = assembler.node_patch(np.array([5, 17]))
    first = assembler.element_part(nodes=nodes)
    elements = first.elements.numpy()
    tets = mesh.tets
    assert np.all(np.isin(tets[elements], nodes).any(axis=1))
    np.testing.assert_array_equal(first.nodes, np.unique(tets[elements]))
    others = np.setdiff1d(np.arange(mesh.tet_count), elements)
    assert not np.isin(tets[others], nodes).any()
    rest = assembler.element_part(elements=others)
    patch_tangent = assembler.tangent_submatrix(nodes).toarray()
    first_forces, first_energy, first_jacobian = assembler.assemble_part(
        u, first, with_tangent=True
    )
    rest_forces, rest_energy, rest_jacobian = assembler.assemble_part(u, rest)
    summed = np.zeros_like(whole_residual)
    summed[first.nodes] += first_forces
    summed[rest.nodes] += rest_forces
    scale = np.abs(whole_residual).max()
    np.testing.assert_allclose(summed, whole_residual, rtol=0, atol=1e-12 * scale)
    assert first_energy + rest_energy == pytest.approx(whole.energy_J, rel=1e-12)
    assert min(first_jacobian, rest_jacobian) == pytest.approx(whole.min_jacobian, rel=1e-14)
    # the patch's own blocks hold only its tets' contributions: all of them
    np.testing.assert_allclose(
        assembler.tangent_submatrix(nodes).toarray(),
        patch_tangent,
        rtol=0,
        atol=1e-12 * np.abs(patch_tangent).max(),
    )
    with pytest.raises(InputError, match="not both"):
        assembler.element_part(nodes=nodes, elements=others)


def _six_step_compression() -> tuple[Assembler, DirichletConditions, np.ndarray]:
    """The cube compressed between frictionless plates in six equal steps to stretch 0.7:
    its assembler (neo-Hookean, mu = 200 Pa, K/mu = 500), plate conditions and loads (m)."""
    mesh = _cube()
    assembler = Assembler(mesh, NeoHookean(100.0, 1e5), device="cpu")
    return assembler, compression_conditions(mesh), SIDE_M * np.linspace(0.05, 0.3, 6)


def test_extrapolated_predictor_saves_newton_iterations_on_a_smooth_path():
    """Homogeneous compression of a cube in six equal steps to stretch 0.7: starting each step
    after the first from the last two converged states extrapolated linearly saves Newton
    iterations against the linearized predictor (measured 24 -> 19), and the converged states
    agree to the tolerance."""
    assembler, conditions, loads = _six_step_compression()
    paths = {
        predictor: solve_quasistatic(
            assembler, conditions, loads, options=NewtonOptions(predictor=predictor)
        )
        for predictor in ("linearized", "extrapolated")
    }
    linearized, extrapolated = paths["linearized"], paths["extrapolated"]
    assert linearized.completed and extrapolated.completed
    # The first step has nothing to extrapolate from: the same start, the same iterations.
    assert extrapolated.newton_iterations[0] == linearized.newton_iterations[0]
    assert extrapolated.newton_iterations[1:].sum() < linearized.newton_iterations[1:].sum()
    scale = np.abs(linearized.displacement_m).max()
    np.testing.assert_allclose(
        extrapolated.displacement_m, linearized.displacement_m, rtol=0, atol=1e-8 * scale
    )


@pytest.mark.slow
def test_extrapolated_predictor_keeps_the_punch_curve():
    """Bonded flat punch (TET10/P0, K/mu = 1000, 1 728 tets): the same converged forces from
    either predictor. (At a finely meshed punch edge the extrapolation costs iterations:
    README "Performance".)"""
    depths = PUNCH_RADIUS_M * np.array([0.05, 0.1, 0.15, 0.2])
    runs = _bonded_punch_runs(depths, "predictor", ("linearized", "extrapolated"))
    forces = [run.reaction_force_N for run in runs.values()]
    assert len(forces[0]) == len(forces[1]) == len(depths)
    np.testing.assert_allclose(forces[1], forces[0], rtol=1e-7)


@pytest.mark.slow
def test_an_extrapolation_that_inverts_an_element_falls_back_to_the_linearized_predictor():
    """A guess that folds the mesh is refused before any Newton iteration: the increment then
    runs exactly as without a guess."""
    problem = _bonded_punch()
    mesh = problem.mesh
    conditions = problem.dirichlet_conditions()
    mask = conditions.mask(mesh.node_count)
    assembler = Assembler(mesh, problem.material, device="cpu")
    folding = np.zeros((mesh.node_count, 3))
    folding[:, 2] = -2.0 * mesh.points[:, 2]  # mirrors the block through its base
    runs = []
    for guess in (None, folding):
        step = _one_increment(
            assembler,
            np.zeros((mesh.node_count, 3)),
            conditions.values(0.05 * PUNCH_RADIUS_M, mesh.node_count),
            1.0 - mask,
            max_iterations=25,
            nonlinear_elimination_on=True,
            free_guess=guess,
        )
        assert step.converged[0], step.reasons
        runs.append(step)
    assert runs[0].iterations[0] == runs[1].iterations[0]
    np.testing.assert_array_equal(runs[0].displacement, runs[1].displacement)


def test_newton_failing_from_the_extrapolated_state_retries_from_the_linearized_one(
    monkeypatch,
):
    """Where Newton fails from the extrapolated state (forced here: one iteration allowed from
    a guess), the increment runs again from the linearized predictor, with no cutback. From
    the same converged state that retry is the linearized run's own step, so the path equals
    the linearized predictor's to the last bit, at one extra iteration per retried step."""
    newton_increment = newton_increments.newton_increment

    def one_iteration_from_a_guess(*args, free_guess=None, max_iterations, **kwargs):
        if free_guess is not None:
            max_iterations = 1
        return newton_increment(
            *args, free_guess=free_guess, max_iterations=max_iterations, **kwargs
        )

    assembler, conditions, loads = _six_step_compression()
    linearized = solve_quasistatic(
        assembler,
        conditions,
        loads,
        # every Newton solve factorized, so that both paths are bitwise equal
        options=NewtonOptions(predictor="linearized", reuse_factorization=False),
    )
    monkeypatch.setattr(newton_increments, "newton_increment", one_iteration_from_a_guess)
    retried = solve_quasistatic(
        assembler,
        conditions,
        loads,
        options=NewtonOptions(predictor="extrapolated", reuse_factorization=False),
    )
    assert linearized.completed and retried.completed
    assert retried.cutbacks == linearized.cutbacks == 0
    attempts = [(entry["load"], entry["converged"]) for entry in retried.history]
    expected = [(loads[0], True)]
    for load in loads[1:]:
        expected += [(load, False), (load, True)]
    assert [load for load, _ in attempts] == pytest.approx([load for load, _ in expected])
    assert [converged for _, converged in attempts] == [c for _, c in expected]
    np.testing.assert_array_equal(retried.displacement_m, linearized.displacement_m)
    np.testing.assert_array_equal(
        retried.newton_iterations, linearized.newton_iterations + [0, 1, 1, 1, 1, 1]
    )


def test_newton_options_refuse_bad_values_by_name():
    for key, value in (
        ("predictor", "quadratic"),
        ("linear_solver", "lu"),
        ("tolerance", 0.0),
        ("tolerance", 2.0),
        ("tolerance", "1e-9"),
        ("max_newton_iterations", 0),
        ("max_newton_iterations", 2.5),
        ("max_cutbacks", -1),
        ("damping", "yes"),
        ("nonlinear_elimination", 1),
        ("nonlinear_elimination", "yes"),
        ("reuse_factorization", 1),
        ("reuse_factorization", "always"),
    ):
        with pytest.raises(InputError) as error:
            NewtonOptions(**{key: value})
        assert error.value.column == key and repr(value) in str(error.value)


def test_nonlinear_elimination_auto_follows_the_measured_rule():
    """ "auto": on the CPU always; on CUDA for one problem of 16 000 tets or more, never for a
    batch (docs/performance.md); true and false are kept as given."""
    assert elimination_pays(is_cuda=False, tets_per_problem=500, problem_count=32)
    assert not elimination_pays(is_cuda=True, tets_per_problem=8_828, problem_count=1)
    assert elimination_pays(
        is_cuda=True, tets_per_problem=ELIMINATION_MIN_TETS_CUDA, problem_count=1
    )
    assert not elimination_pays(is_cuda=True, tets_per_problem=78_171, problem_count=2)
    auto = NewtonOptions()
    assert auto.nonlinear_elimination == "auto"
    for is_cuda, tets, count in ((False, 10, 1), (True, 10, 1), (True, 10**5, 4)):
        expected = elimination_pays(is_cuda=is_cuda, tets_per_problem=tets, problem_count=count)
        assert auto.eliminates(is_cuda=is_cuda, tets_per_problem=tets, problem_count=count) is (
            expected
        )
        for value in (True, False):
            given = NewtonOptions(nonlinear_elimination=value)
            assert (
                given.eliminates(is_cuda=is_cuda, tets_per_problem=tets, problem_count=count)
                is value
            )


def test_reuse_factorization_auto_follows_the_measured_rule():
    """ "auto": on the CPU always; on CUDA from 5 000 tets of the whole system on (the main
    job's 576 tets, three records batched, factorize at every iteration; docs/performance.md);
    true and false are kept as given."""
    assert reuse_pays(is_cuda=False, tet_count=100)
    assert not reuse_pays(is_cuda=True, tet_count=3 * 576)
    assert not reuse_pays(is_cuda=True, tet_count=2_471)
    assert reuse_pays(is_cuda=True, tet_count=REUSE_MIN_TETS_CUDA)
    assert reuse_pays(is_cuda=True, tet_count=8_828)
    auto = NewtonOptions()
    assert auto.reuse_factorization == "auto"
    for is_cuda, tets in ((False, 10), (True, 10), (True, 10**5)):
        assert auto.reuses(is_cuda=is_cuda, tet_count=tets) is reuse_pays(
            is_cuda=is_cuda, tet_count=tets
        )
        for value in (True, False):
            given = NewtonOptions(reuse_factorization=value)
            assert given.reuses(is_cuda=is_cuda, tet_count=tets) is value


def test_the_loop_takes_the_reuse_rule_of_its_system(monkeypatch):
    """The Newton loop solves with earlier factors where the rule says so for its whole
    system: with the CPU taken for a CUDA device of the rule, a small mesh factorizes at every
    iteration under "auto" and reuses factors under true."""
    mesh = _cube()
    conditions = compression_conditions(mesh)
    monkeypatch.setattr(
        "warptissue.fem.newton.options.reuse_pays",
        lambda *, is_cuda, tet_count: tet_count >= 10**6,
    )
    counts = {}
    for value in ("auto", True):
        assembler = Assembler(mesh, NeoHookean(100.0, 1e5), device="cpu")
        result = solve_quasistatic(
            assembler,
            conditions,
            [1e-4, 2e-4, 3e-4],
            options=NewtonOptions(reuse_factorization=value),
        )
        counts[value] = result.linear_solver_statistics
    assert counts["auto"]["reused_solves"] == 0
    assert counts["auto"]["failed_reuses"] == 0
    assert counts[True]["reused_solves"] + counts[True]["failed_reuses"] > 0


@pytest.mark.parametrize("method", ["superlu", "pardiso"])
def test_an_assemblers_later_runs_reuse_its_symbolic_analysis(method, monkeypatch):
    """A second run on the same assembler (a fit's next forward run) analyses nothing again
    and gives the run of a fresh assembler; a matrix of another pattern gets its own."""
    if method == "pardiso" and not pardiso_available():
        pytest.skip("pypardiso is not installed")
    built = []
    original = linear_solver_module.CpuDirectSolver

    def counting(matrix, *, method):
        built.append(matrix)
        return original(matrix, method=method)

    monkeypatch.setattr(linear_solver_module, "CpuDirectSolver", counting)
    mesh = _cube()
    options = NewtonOptions(linear_solver=method, reuse_factorization=False)
    conditions = compression_conditions(mesh)
    assembler = Assembler(mesh, NeoHookean(100.0, 1e5), device="cpu")
    first = solve_quasistatic(assembler, conditions, [1e-4, 2e-4], options=options)
    assembler.set_material(NeoHookean(150.0, 1e5))
    second = solve_quasistatic(assembler, conditions, [1e-4, 2e-4], options=options)
    assert built == [assembler.matrix]
    fresh = Assembler(mesh, NeoHookean(150.0, 1e5), device="cpu")
    alone = solve_quasistatic(fresh, conditions, [1e-4, 2e-4], options=options)
    assert built == [assembler.matrix, fresh.matrix]
    np.testing.assert_array_equal(second.newton_iterations, alone.newton_iterations)
    np.testing.assert_allclose(second.displacement_m, alone.displacement_m, rtol=1e-12, atol=1e-18)
    assert not np.allclose(first.displacement_m, second.displacement_m, rtol=1e-6, atol=0.0)
    owned = linear_solver_module.analysed_solver(assembler.matrix, method, owner=assembler)
    assert owned is linear_solver_module.analysed_solver(assembler.matrix, method, owner=assembler)
    assert linear_solver_module.analysed_solver(assembler.matrix, method) is not owned
    del assembler, fresh, owned  # the analyses go with their assemblers
    gc.collect()
    assert len(linear_solver_module._ANALYSED) == 0


def test_solvers_take_one_options_object():
    """The defaults equal an explicit NewtonOptions(); loose keyword options are gone."""
    mesh = _cube()
    assembler = Assembler(mesh, NeoHookean(100.0, 1e5), device="cpu")
    conditions = compression_conditions(mesh)
    default = solve_quasistatic(assembler, conditions, [1e-4])
    explicit = solve_quasistatic(assembler, conditions, [1e-4], options=NewtonOptions())
    np.testing.assert_array_equal(default.displacement_m, explicit.displacement_m)
    with pytest.raises(TypeError):
        solve_quasistatic(assembler, conditions, [1e-4], predictor="linearized")
    with pytest.raises(InputError, match="NewtonOptions"):
        solve_quasistatic(assembler, conditions, [1e-4], options={"predictor": "linearized"})
    assert NewtonOptions(max_cutbacks=2).to_dict() == dict(
        NewtonOptions().to_dict(), max_cutbacks=2
    )


def test_ctrl_c_keeps_the_converged_steps(ctrl_c_at_newton_increment):
    """KeyboardInterrupt in the third load step: SolveInterrupted (a KeyboardInterrupt)
    carries the two converged steps, equal to those of an uninterrupted run."""
    from warptissue.fem import SolveInterrupted

    assembler, conditions, loads = _six_step_compression()
    # every Newton solve factorized (reuse depends on measured times): bitwise reproducible
    options = NewtonOptions(reuse_factorization=False)
    full = solve_quasistatic(assembler, conditions, loads, options=options)
    ctrl_c_at_newton_increment(3)
    with pytest.raises(KeyboardInterrupt) as error:
        solve_quasistatic(assembler, conditions, loads, options=options)
    assert isinstance(error.value, SolveInterrupted)
    partial = error.value.partial_result
    assert not partial.completed and partial.message == "interrupted"
    np.testing.assert_array_equal(partial.loads, loads[:2])
    np.testing.assert_array_equal(partial.displacement_m, full.displacement_m[:2])
    np.testing.assert_array_equal(partial.reaction, full.reaction[:2])
    assert "2 converged steps are kept" in str(error.value)


@pytest.mark.slow
def test_damping_saves_newton_iterations_on_a_large_depth_increment():
    """Bonded flat punch (TET10/P0, K/mu = 1000, 1 728 tets) pressed to 0.3 a in one step: with
    the adaptive Levenberg-Marquardt damping the line search no longer cuts step after step
    (measured 16 -> 9 Newton iterations), and the converged force is the same."""
    depths = [0.3 * PUNCH_RADIUS_M]
    results = _bonded_punch_runs(depths, "damping", (False, True))
    plain, damped = results[False], results[True]
    assert plain.completed and damped.completed
    assert damped.newton_iterations.sum() < plain.newton_iterations.sum()
    np.testing.assert_allclose(damped.reaction_force_N, plain.reaction_force_N, rtol=1e-8)


def test_damping_rises_on_cut_steps_and_falls_back_to_zero_after_full_ones():
    factor = 0.0
    factor = next_damping(factor, 1.0)
    assert factor == 0.0  # full steps: no damping
    factor = next_damping(factor, 0.5)
    assert factor == 0.0  # a mild cut: unchanged
    factor = next_damping(factor, 0.01)
    assert factor == DAMPING_START
    factor = next_damping(factor, 0.1)
    assert factor == 4.0 * DAMPING_START
    factor = next_damping(factor, 0.5)
    assert factor == 4.0 * DAMPING_START
    history = []
    while factor > 0.0:
        factor = next_damping(factor, 1.0)
        history.append(factor)
    assert history == [DAMPING_START, DAMPING_START / 4.0, DAMPING_START / 16.0, 0.0]
