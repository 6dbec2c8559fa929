"""Exact force sensitivities of the flat-punch FE against central differences of whole runs.

``simulate_indentation(..., sensitivities=names)`` solves ``K du/dtheta = -dR/dtheta`` at each
converged depth; the reference is ``(F(theta + h) - F(theta - h)) / 2h`` of two forward runs
with a tight Newton tolerance (1e-12) and a relative step h = 1e-6 theta. Measured agreement
on this mesh (max over depths, relative to the largest FD value): 1e-10 to 2e-7 for every
parameter of every model, bonded and frictionless; the tests assert 1e-5 (the FD's own error,
about tolerance / h = 1e-6, bounds what can be asserted).
"""

from __future__ import annotations

import numpy as np
import pytest

from warptissue.errors import InputError
from warptissue.fem import (
    Assembler,
    ForceSensitivity,
    IndentationProblem,
    NewtonOptions,
    simulate_indentation,
    solve_quasistatic,
)
from warptissue.fem.linear.direct import pardiso_available
from warptissue.indenter import Indenter
from warptissue.materials import (
    CompressibleNeoHookean,
    LinearElastic,
    MooneyRivlin,
    NeoHookean,
    Ogden,
    Yeoh,
    material_from_dict,
)
from warptissue.mesh import indentation_block

RADIUS_M = 1e-3
DEPTHS_M = RADIUS_M * np.array([0.1, 0.2, 0.3])
TIGHT = NewtonOptions(tolerance=1e-12)
MATERIALS = {
    "neo_hookean": NeoHookean(100.0, 2000.0),
    "mooney_rivlin": MooneyRivlin(80.0, 20.0, 2000.0),
    "yeoh": Yeoh(100.0, 30.0, 10.0, 2000.0),
    "ogden": Ogden((200.0, -50.0), (4.0, -2.0), 2000.0),
    "compressible_neo_hookean": CompressibleNeoHookean(200.0, 2000.0),
    "linear_elastic": LinearElastic(600.0, 0.4),
}


@pytest.fixture(scope="module")
def mesh():
    """A quarter block of 2 radii thickness, a few hundred TET10."""
    return indentation_block(
        width_m=8.0 * RADIUS_M,
        thickness_m=2.0 * RADIUS_M,
        probe_radius_m=RADIUS_M,
        element="TET10",
        size_near_m=RADIUS_M,
        size_far_m=1.5 * RADIUS_M,
    )


def _problem(mesh, material, contact: str = "bonded") -> IndentationProblem:
    return IndentationProblem(
        mesh, material, Indenter("flat_punch", radius_m=RADIUS_M, contact=contact)
    )


def _force(mesh, material, contact: str, device: str = "cpu") -> np.ndarray:
    result = simulate_indentation(
        _problem(mesh, material, contact), DEPTHS_M, device=device, progress=False, options=TIGHT
    )
    assert result.completed, result.message
    return result.reaction_force_N


def _central_differences(mesh, material, name: str, contact: str) -> np.ndarray:
    flat = material.to_dict()
    value = flat[name]
    step = 1e-6 * abs(value)
    forces = []
    for sign in (1.0, -1.0):
        moved = material_from_dict({**flat, name: value + sign * step})
        forces.append(_force(mesh, moved, contact))
    return (forces[0] - forces[1]) / (2.0 * step)


def _relative_error(exact: np.ndarray, reference: np.ndarray) -> float:
    return float(np.max(np.abs(exact - reference)) / np.max(np.abs(reference)))


@pytest.mark.parametrize("formulation", ["mixed", "displacement"])
def test_residual_derivative_matches_central_differences_of_the_residual(mesh, formulation, rng):
    """dR/dtheta at a random state (all models, every parameter): the kernels' derivative
    against central differences of assembled residuals (measured 1e-10 to 1e-8)."""
    u = 2e-5 * rng.standard_normal((mesh.node_count, 3))
    for material in MATERIALS.values():
        assembler = Assembler(mesh, material, formulation=formulation)
        for name in material.sensitivity_names:
            exact = assembler.parameter_residual(u, name)
            flat = material.to_dict()
            step = 1e-6 * abs(flat[name])
            residuals = []
            for sign in (1.0, -1.0):
                assembler.set_material(material_from_dict({**flat, name: flat[name] + sign * step}))
                residuals.append(assembler.assemble(u, with_tangent=False).residual.numpy().copy())
            assembler.set_material(material)
            reference = (residuals[0] - residuals[1]) / (2.0 * step)
            error = _relative_error(exact, reference)
            assert error < 1e-6, f"{material.model_name} {name}: {error:.1e}"


@pytest.mark.parametrize("contact", ["bonded", "frictionless"])
@pytest.mark.parametrize("model", list(MATERIALS))
@pytest.mark.slow
def test_sensitivities_match_central_differences_of_whole_runs(mesh, model, contact):
    material = MATERIALS[model]
    names = material.sensitivity_names
    assert "bulk_modulus_Pa" in names or model == "linear_elastic"
    result = simulate_indentation(
        _problem(mesh, material, contact),
        DEPTHS_M,
        device="cpu",
        progress=False,
        options=TIGHT,
        sensitivities=names,
    )
    assert result.completed, result.message
    assert result.sensitivity_names == names
    assert result.force_sensitivity_N_per_unit.shape == (len(DEPTHS_M), len(names))
    for column, name in enumerate(names):
        reference = _central_differences(mesh, material, name, contact)
        error = _relative_error(result.force_sensitivity_N_per_unit[:, column], reference)
        assert error < 1e-5, f"{model} {contact} {name}: relative error {error:.2e}"


def test_reused_and_fresh_factorizations_agree_and_the_stale_one_alone_does_not(mesh):
    """Newton's last factorization is of the iterate before the converged state (where
    every Newton solve factorizes: ``reuse_factorization=False``): solving with it alone is
    off by about the size of the last Newton step (measured 2.5e-9 here, at tolerance 1e-9:
    Newton converges quadratically); refined against the converged tangent it agrees with a
    fresh factorization of the converged tangent to roundoff."""
    material = MATERIALS["ogden"]
    problem = _problem(mesh, material)
    weights = np.zeros((mesh.node_count, 3))
    weights[problem.punch_nodes, 2] = -float(problem.symmetry_factor)
    names = material.sensitivity_names
    outcomes = {}
    for label, factorization, refinements in (
        ("stale", "reuse", 0),
        ("refined", "reuse", 20),
        ("fresh", "refactorize", 20),
    ):
        assembler = Assembler(mesh, material)
        sensitivity = ForceSensitivity(
            assembler,
            problem.dirichlet_conditions(),
            names,
            weights,
            factorization=factorization,
            max_refinements=refinements,
        )
        path = solve_quasistatic(
            assembler,
            problem.dirichlet_conditions(),
            DEPTHS_M,
            reaction_weights=weights,
            options=NewtonOptions(tolerance=1e-9, reuse_factorization=False),
            sensitivity=sensitivity,
        )
        assert path.completed
        outcomes[label] = (path.reaction_sensitivity, sensitivity)
    refined, fresh, stale = outcomes["refined"][0], outcomes["fresh"][0], outcomes["stale"][0]
    assert _relative_error(refined, fresh) < 1e-11
    assert 1e-14 < _relative_error(stale, fresh) < 1e-6
    refined_counts = outcomes["refined"][1]
    assert refined_counts.factorizations == 0
    assert refined_counts.refinement_steps > 0
    assert outcomes["fresh"][1].factorizations == len(DEPTHS_M)


def test_sensitivities_on_each_device(mesh, device):
    material = MATERIALS["ogden"]
    names = ("mu1_Pa", "alpha1", "bulk_modulus_Pa")
    result = simulate_indentation(
        _problem(mesh, material),
        DEPTHS_M,
        device=device,
        progress=False,
        options=TIGHT,
        sensitivities=names,
    )
    cpu = simulate_indentation(
        _problem(mesh, material),
        DEPTHS_M,
        device="cpu",
        progress=False,
        options=TIGHT,
        sensitivities=names,
        sensitivity_factorization="refactorize",
    )
    np.testing.assert_allclose(
        result.force_sensitivity_N_per_unit, cpu.force_sensitivity_N_per_unit, rtol=1e-7
    )
    assert result.to_dict()["sensitivity_names"] == list(names)


def test_linear_elastic_force_is_homogeneous_in_youngs_modulus(mesh):
    """An independent check: F is proportional to E (small strain, fixed nu), so dF/dE = F/E."""
    material = MATERIALS["linear_elastic"]
    result = simulate_indentation(
        _problem(mesh, material),
        DEPTHS_M,
        device="cpu",
        progress=False,
        sensitivities=("youngs_modulus_Pa",),
    )
    np.testing.assert_allclose(
        result.force_sensitivity_N_per_unit[:, 0],
        result.reaction_force_N / material.youngs_modulus_Pa,
        rtol=1e-8,
    )


def test_bad_sensitivity_requests_are_refused(mesh):
    problem = _problem(mesh, MATERIALS["neo_hookean"])
    with pytest.raises(InputError, match="C01_Pa"):
        simulate_indentation(problem, DEPTHS_M[:1], progress=False, sensitivities=("C01_Pa",))
    with pytest.raises(InputError, match="sequence"):
        simulate_indentation(problem, DEPTHS_M[:1], progress=False, sensitivities="C10_Pa")
    with pytest.raises(InputError, match="distinct"):
        simulate_indentation(
            problem, DEPTHS_M[:1], progress=False, sensitivities=("C10_Pa", "C10_Pa")
        )
    with pytest.raises(InputError, match="refactorize"):
        simulate_indentation(
            problem,
            DEPTHS_M[:1],
            progress=False,
            sensitivities=("C10_Pa",),
            sensitivity_factorization="new",
        )


def test_superlu_reuses_its_factors(mesh):
    """SuperLU keeps its factorization for the sensitivity solves, as PARDISO does: no
    factorization for the sensitivities, and the result of a fresh PARDISO one (a fresh
    SuperLU one where pypardiso is not installed)."""
    material = MATERIALS["mooney_rivlin"]
    problem = _problem(mesh, material)
    weights = np.zeros((mesh.node_count, 3))
    weights[problem.punch_nodes, 2] = -float(problem.symmetry_factor)
    jacobians = []
    reference = "pardiso" if pardiso_available() else "superlu"
    for solver, factorization in (("superlu", "reuse"), (reference, "refactorize")):
        assembler = Assembler(mesh, material, device="cpu")  # both solvers run on the CPU
        sensitivity = ForceSensitivity(
            assembler,
            problem.dirichlet_conditions(),
            material.sensitivity_names,
            weights,
            factorization=factorization,
        )
        path = solve_quasistatic(
            assembler,
            problem.dirichlet_conditions(),
            DEPTHS_M[:2],
            reaction_weights=weights,
            options=NewtonOptions(linear_solver=solver),
            sensitivity=sensitivity,
        )
        assert path.completed and path.linear_solver == solver
        assert sensitivity.factorizations == (0 if factorization == "reuse" else 2)
        jacobians.append(path.reaction_sensitivity)
    np.testing.assert_allclose(jacobians[0], jacobians[1], rtol=1e-9)
