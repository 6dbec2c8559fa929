"""Flat-punch indentation: boundary conditions, Sneddon's stiffness with the computed
finite-layer factor of Hayes et al. (1972), insensitivity to the bulk modulus, locking of
displacement TET4, large bonded depths with a clean stop, and CPU/device agreement.

The heavier mesh-convergence study is ``scripts/examples/verify_flat_punch.py`` (docs/fe.md,
"Verification").
"""

from __future__ import annotations

import numpy as np
import pytest

from warptissue.errors import ConvergenceError, InputError
from warptissue.fem import IndentationProblem, NewtonOptions, simulate_indentation
from warptissue.fit.punch import hayes_kappa
from warptissue.indenter import Indenter
from warptissue.materials import NeoHookean
from warptissue.mesh import indentation_block

RADIUS_M = 1e-3
SHEAR_MODULUS_PA = 200.0


def _block(
    *,
    thickness_over_radius: float = 4.0,
    near: float = 0.5,
    element: str = "TET10",
    width_over_thickness: float = 4.0,
):
    thickness = thickness_over_radius * RADIUS_M
    return indentation_block(
        width_m=width_over_thickness * thickness,
        thickness_m=thickness,
        probe_radius_m=RADIUS_M,
        element=element,
        size_near_m=near * RADIUS_M,
        size_far_m=thickness / 3.0,
    )


def _punch(contact: str = "bonded") -> Indenter:
    return Indenter("flat_punch", radius_m=RADIUS_M, contact=contact)


def _material(bulk_over_shear: float) -> NeoHookean:
    return NeoHookean(SHEAR_MODULUS_PA / 2.0, bulk_over_shear * SHEAR_MODULUS_PA)


def _stiffness(mesh, material, *, contact="bonded", formulation="mixed", depth=2e-3 * RADIUS_M):
    problem = IndentationProblem(mesh, material, _punch(contact), formulation=formulation)
    result = simulate_indentation(problem, [depth], device="cpu", progress=False)
    assert result.completed, result.message
    return result.reaction_force_N[0] / depth


def layer_stiffness(thickness_m: float, material: NeoHookean) -> float:
    """Flat-punch stiffness of a layer bonded to a rigid base, N/m.

    Sneddon's half-space value 2 a E / (1 - nu^2) (8 mu a at nu = 1/2) times the finite-layer
    factor kappa(a/h, nu) of Hayes et al. (1972) for a frictionless punch on a layer of
    infinite extent, which ``warptissue.fit.punch.hayes_kappa`` computes from the integral
    equation (checked against its half-space, thin-layer and squeeze-flow limits in
    ``tests/test_punch.py``).
    """
    mu, bulk = material.initial_shear_modulus_Pa, material.bulk_modulus_Pa
    poissons_ratio = (3.0 * bulk - 2.0 * mu) / (6.0 * bulk + 2.0 * mu)
    return 8.0 * mu * RADIUS_M * hayes_kappa(RADIUS_M / thickness_m, poissons_ratio)


@pytest.mark.slow
def test_small_depth_stiffness_matches_sneddon_with_the_layer_factor():
    """A block 8 times wider than thick stands for the infinite layer (16 times changes the
    stiffness by 0.04 %); at this mesh the FE is 0.7 % below the computed factor and its
    Richardson extrapolation 0.36 % below (scripts/examples/verify_flat_punch.py). A bonded punch
    is stiffer than a frictionless one, slightly at nu = 1/2."""
    thickness = 4.0 * RADIUS_M
    mesh = _block(thickness_over_radius=4.0, near=0.25, width_over_thickness=8.0)
    material = _material(1000.0)
    expected = layer_stiffness(thickness, material)
    frictionless = _stiffness(mesh, material, contact="frictionless")
    bonded = _stiffness(mesh, material, contact="bonded")
    assert frictionless == pytest.approx(expected, rel=0.015)
    assert frictionless < bonded < 1.01 * frictionless


def test_force_is_insensitive_to_bulk_modulus_in_the_mixed_formulation():
    mesh = _block()
    soft = _stiffness(mesh, _material(100.0))
    stiff = _stiffness(mesh, _material(10000.0))
    assert abs(stiff / soft - 1.0) < 0.02


def test_displacement_tet4_locks_but_mixed_tet10_does_not():
    tet4 = _block(element="TET4")
    tet10 = _block(element="TET10")
    material = _material(1000.0)
    locked = _stiffness(tet4, material, formulation="displacement")
    mixed = _stiffness(tet10, material)
    reference = layer_stiffness(4.0 * RADIUS_M, material)
    assert locked > 1.5 * mixed
    assert abs(mixed / reference - 1.0) < 0.1


def test_bonded_punch_reaches_half_the_radius_and_stops_cleanly_beyond():
    """Half the radius in two steps; then a jump to 3 a that two halvings cannot rescue stops
    with a message and keeps the curve (scripts/examples/verify_flat_punch.py reaches 2 a in
    steps of 0.05 a)."""
    mesh = _block(near=1.0)
    problem = IndentationProblem(mesh, _material(1000.0), _punch())
    depths = RADIUS_M * np.array([0.25, 0.5, 3.0])
    options = NewtonOptions(max_cutbacks=2, max_newton_iterations=12)
    result = simulate_indentation(problem, depths, device="cpu", progress=False, options=options)
    assert not result.completed
    np.testing.assert_allclose(result.depths_m, depths[:2])
    assert result.displacement_m.shape == (2, mesh.node_count, 3)
    assert 0 < result.reaction_force_N[0] < result.reaction_force_N[1]
    assert "depth" in result.message and "2 cutbacks" in result.message
    assert result.cauchy_stress_Pa.shape == (mesh.tet_count, 6)
    assert result.von_mises_Pa.max() > 0
    # the punch nodes sit at the prescribed depth, bonded (no lateral slip)
    punch = problem.punch_nodes
    np.testing.assert_allclose(result.displacement_m[1, punch, 2], -0.5 * RADIUS_M)
    np.testing.assert_allclose(result.displacement_m[1, punch, :2], 0.0, atol=1e-15)
    options = NewtonOptions(max_cutbacks=0, max_newton_iterations=12)
    with pytest.raises(ConvergenceError) as error:
        simulate_indentation(
            problem, depths[2:], device="cpu", progress=False, options=options, strict=True
        )
    assert len(error.value.partial_result.depths_m) == 0


def _prescribed(conditions) -> dict:
    triples = zip(conditions.nodes, conditions.components, conditions.values_per_load, strict=True)
    return {(int(n), int(k)): v for n, k, v in triples}


def test_boundary_conditions():
    mesh = _block()
    material = _material(1000.0)
    bonded = IndentationProblem(mesh, material, _punch())
    frictionless = IndentationProblem(mesh, material, _punch("frictionless"), base="sliding")
    punch = bonded.punch_nodes
    assert np.array_equal(np.sort(punch), np.sort(mesh.node_sets["probe"]))
    assert bonded.symmetry_factor == 4
    c = bonded.dirichlet_conditions()
    prescribed = _prescribed(c)
    centre = punch[0]
    assert prescribed[(centre, 2)] == -1.0 and prescribed[(centre, 0)] == 0.0
    c = frictionless.dirichlet_conditions()
    prescribed = _prescribed(c)
    off_axis = [n for n in punch if mesh.points[n, 0] > 0 and mesh.points[n, 1] > 0]
    assert (off_axis[0], 0) not in prescribed and prescribed[(off_axis[0], 2)] == -1.0
    bottom_inner = [
        n
        for n in mesh.node_sets["bottom"]
        if mesh.points[n, 0] > 0.1 * RADIUS_M and mesh.points[n, 1] > 0.1 * RADIUS_M
    ]
    assert (bottom_inner[0], 2) in prescribed and (bottom_inner[0], 0) not in prescribed
    symmetry_node = mesh.node_sets["symmetry_x"][-1]
    assert prescribed[(symmetry_node, 0)] == 0.0


def test_full_model_with_sliding_base_matches_quarter_model():
    quarter = _block(near=1.0)
    full = indentation_block(
        width_m=16 * RADIUS_M,
        thickness_m=4 * RADIUS_M,
        probe_radius_m=RADIUS_M,
        quarter=False,
        size_near_m=RADIUS_M,
        size_far_m=4 * RADIUS_M / 3,
    )
    material = _material(1000.0)
    punch = _punch("frictionless")
    forces = []
    for mesh, planes in ((quarter, ("symmetry_x", "symmetry_y")), (full, ())):
        problem = IndentationProblem(mesh, material, punch, base="sliding", symmetry_planes=planes)
        result = simulate_indentation(problem, [0.05 * RADIUS_M], device="cpu", progress=False)
        assert result.completed, result.message
        forces.append(result.reaction_force_N[0])
    assert forces[1] == pytest.approx(forces[0], rel=0.03)


def test_bad_inputs_are_named():
    mesh = _block(near=1.0)
    material = _material(100.0)
    with pytest.raises(InputError, match="radius"):
        Indenter("flat_punch", radius_m=-1.0)
    with pytest.raises(InputError, match="contact"):
        _punch("glued")
    with pytest.raises(InputError, match="simulate only 'flat_punch'"):
        IndentationProblem(mesh, material, Indenter("platen", length_m=RADIUS_M))
    with pytest.raises(InputError, match="on the axis"):
        IndentationProblem(mesh, material, Indenter("flat_punch", radius_m=RADIUS_M, x_m=1e-4))
    with pytest.raises(InputError, match="off the indented surface"):
        IndentationProblem(mesh, material, Indenter("flat_punch", radius_m=RADIUS_M, z_m=0.0))
    with pytest.raises(InputError, match="node set 'symmetry_z'"):
        IndentationProblem(mesh, material, _punch(), symmetry_planes=("symmetry_z",))
    with pytest.raises(InputError, match="base"):
        IndentationProblem(mesh, material, _punch(), base="floating")
    with pytest.raises(InputError, match="TET10"):
        IndentationProblem(_block(near=1.0, element="TET4"), material, _punch())
    problem = IndentationProblem(mesh, material, _punch())
    with pytest.raises(InputError, match="increasing"):
        simulate_indentation(problem, [2e-4, 1e-4], device="cpu", progress=False)


def test_cpu_and_device_agree(device):
    mesh = _block(near=1.0)
    problem = IndentationProblem(mesh, _material(1000.0), _punch())
    depths = RADIUS_M * np.array([0.05, 0.1])
    options = NewtonOptions(tolerance=1e-11)
    cpu = simulate_indentation(problem, depths, device="cpu", progress=False, options=options)
    other = simulate_indentation(problem, depths, device=device, progress=False, options=options)
    np.testing.assert_allclose(other.reaction_force_N, cpu.reaction_force_N, rtol=1e-8)
    np.testing.assert_allclose(
        other.cauchy_stress_Pa,
        cpu.cauchy_stress_Pa,
        rtol=0,
        atol=1e-7 * np.abs(cpu.cauchy_stress_Pa).max(),
    )


def _warm_case(kind: str):
    """A coarse block under a bonded punch or a rigid sphere (the contact penalty's ramp),
    and the four depths a fit's evaluations share."""
    mesh = _block(near=1.0)
    if kind == "sphere":
        indenter = Indenter("sphere", radius_m=2.0 * RADIUS_M)
        depths = RADIUS_M * np.array([0.05, 0.1, 0.15, 0.2])
    else:
        indenter = _punch()
        depths = RADIUS_M * np.array([0.1, 0.2, 0.3, 0.4])
    return mesh, indenter, depths


@pytest.mark.parametrize("kind", ["punch", "sphere"])
def test_a_warm_start_gives_the_cold_run_s_forces_in_fewer_iterations(device, kind):
    """A fit's next evaluation started from the last one's states: at another C10 and
    another K / mu (so the displacements differ too), the forces and their C10
    sensitivities are those of a run from the predictor, to the Newton tolerance, in fewer
    Newton iterations."""
    mesh, indenter, depths = _warm_case(kind)
    first = IndentationProblem(mesh, _material(10.0), indenter)
    moved = IndentationProblem(mesh, NeoHookean(1.2 * SHEAR_MODULUS_PA / 2, 8.0 * 240.0), indenter)
    run = dict(device=device, progress=False, sensitivities=("C10_Pa",))
    earlier = simulate_indentation(first, depths, **run)
    cold = simulate_indentation(moved, depths, **run)
    warm = simulate_indentation(moved, depths, warm_states_m=earlier.displacement_m, **run)
    assert earlier.completed and cold.completed and warm.completed
    np.testing.assert_allclose(warm.reaction_force_N, cold.reaction_force_N, rtol=1e-7)
    np.testing.assert_allclose(
        warm.force_sensitivity_N_per_unit, cold.force_sensitivity_N_per_unit, rtol=1e-6
    )
    assert not np.allclose(earlier.displacement_m, cold.displacement_m, rtol=1e-3)
    assert warm.newton_iterations.sum() < cold.newton_iterations.sum()


def test_a_warm_start_that_inverts_elements_falls_back_to_the_predictor():
    """States that invert elements (the earlier run's turned inside out) are not taken: each
    depth starts from the predictor, with the cold run's forces and iterations."""
    mesh, indenter, depths = _warm_case("punch")
    problem = IndentationProblem(mesh, _material(10.0), indenter)
    cold = simulate_indentation(problem, depths, device="cpu", progress=False)
    bad = -40.0 * cold.displacement_m[:2]  # for the first two depths only
    warm = simulate_indentation(problem, depths, device="cpu", progress=False, warm_states_m=bad)
    assert warm.completed
    np.testing.assert_allclose(warm.reaction_force_N, cold.reaction_force_N, rtol=1e-9)
    np.testing.assert_array_equal(warm.newton_iterations, cold.newton_iterations)


def test_a_warm_start_of_another_shape_is_refused():
    mesh, indenter, depths = _warm_case("punch")
    problem = IndentationProblem(mesh, _material(10.0), indenter)
    wrong = np.zeros((5, mesh.node_count, 3))  # one state more than the four depths
    with pytest.raises(InputError, match=r"warm_states_m must have shape") as caught:
        simulate_indentation(problem, depths, device="cpu", progress=False, warm_states_m=wrong)
    assert caught.value.key == "warm_states_m" and caught.value.value == (5, mesh.node_count, 3)
    with pytest.raises(InputError, match="finite"):
        simulate_indentation(
            problem,
            depths,
            device="cpu",
            progress=False,
            warm_states_m=np.full((1, mesh.node_count, 3), np.nan),
        )
