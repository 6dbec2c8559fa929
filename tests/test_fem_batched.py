"""K indentations solved together (the one Newton loop with K > 1): every problem's
curve equals the one :func:`warptissue.fem.simulate_indentation` gives it alone, with its own
cutbacks, and a failing problem stops without holding the others; rigid indenters in contact
(sphere, rounded punch, wedge, plate) mix with flat punches, each with its own contact
outputs."""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest
import warp as wp
import warp.sparse as wps
from test_fem_contact import WEDGE, _plate_cube, _wedge_strip

from warptissue.errors import InputError
from warptissue.fem import (
    Assembler,
    IndentationProblem,
    NewtonOptions,
    batch_assembler,
    simulate_indentation,
    simulate_indentation_batch,
)
from warptissue.fem.arrays import DeviceArrays
from warptissue.fem.contact import RigidContact
from warptissue.fem.newton.problems import Problems
from warptissue.fem.packing import pack_meshes
from warptissue.indenter import Indenter
from warptissue.materials import MooneyRivlin, NeoHookean, Ogden, Viscoelastic
from warptissue.mesh import indentation_block

RADIUS_M = 1e-3
TOLERANCE = 1e-10
"""Tight, so that batched and sequential runs (different paths to the solution) agree far
below the 1e-8 the tests ask."""


def _punch(size_near_m: float, material, *, contact: str = "bonded", width_m: float = 0.008):
    mesh = indentation_block(
        width_m=width_m,
        thickness_m=0.004,
        probe_radius_m=RADIUS_M,
        quarter=True,
        size_near_m=size_near_m,
        size_far_m=2.5e-3,
    )
    return IndentationProblem(
        mesh,
        material,
        Indenter("flat_punch", radius_m=RADIUS_M, contact=contact),
        symmetry_planes=("symmetry_x", "symmetry_y"),
    )


def _alone(problem, depths, device, options, **extra):
    """The problem's single run (the reference of its batched run)."""
    return simulate_indentation(
        problem, depths, device=device, progress=False, options=options, **extra
    )


def _problems():
    return [
        _punch(RADIUS_M / 2.0, NeoHookean(287.5, 575e3)),
        _punch(RADIUS_M / 3.0, MooneyRivlin(200.0, 60.0, 2e5), width_m=0.01),
        _punch(RADIUS_M / 2.0, NeoHookean(500.0, 5e5), contact="frictionless"),
    ]


def test_per_problem_sums_and_spreads_follow_the_node_ranges(device, rng):
    """Sums over each problem's node range (of different lengths, one of a single node)
    equal NumPy's sums of the slices, and a per-problem value spreads to its own nodes."""
    offsets = np.array([0, 5, 6, 13])
    vectors = rng.standard_normal((13, 3))
    arrays = DeviceArrays(wp.get_device(device))
    others = rng.standard_normal((13, 3))
    with arrays.context():
        problems = Problems(arrays, offsets)
        x, y = arrays.asarray(vectors), arrays.asarray(others)
        dots, squares = problems.read(problems.dot(x, y), problems.squared(x))
        spread = arrays.host(problems.per_node(np.array([1.0, 2.0, 3.0])))
        chosen = arrays.host(problems.where(np.array([True, False, True]), x, y))
        single = Problems(arrays, [0, 13])
        (whole,) = single.read(single.squared(x))
    for k in range(3):
        nodes = slice(offsets[k], offsets[k + 1])
        assert problems.nodes(k) == nodes
        expected = np.sum(vectors[nodes] * others[nodes])
        assert dots[k] == pytest.approx(expected, rel=1e-13, abs=1e-14)
        assert squares[k] == pytest.approx(np.sum(vectors[nodes] ** 2), rel=1e-13)
        np.testing.assert_array_equal(spread[nodes, 0], k + 1.0)
        np.testing.assert_array_equal(chosen[nodes], (vectors if k != 1 else others)[nodes])
    assert problems.count == 3 and spread.shape == (13, 1)
    assert whole[0] == pytest.approx(np.sum(vectors**2), rel=1e-14)


def test_reductions_and_scalars_come_back_in_one_read(device, rng):
    """``read(..., scalars=)`` gives the reductions of ``read`` and the scalars array
    (flattened, a copy), for one problem and for three, and the scalars alone."""
    vectors = rng.standard_normal((13, 3))
    values = rng.standard_normal(6)
    arrays = DeviceArrays(wp.get_device(device))
    with arrays.context():
        x, scalars = arrays.asarray(vectors), arrays.asarray(values)
        for offsets in ([0, 5, 6, 13], [0, 13]):
            problems = Problems(arrays, offsets)
            expected = problems.read(problems.squared(x), problems.dot(x, x))
            squares, dots, read = problems.read(
                problems.squared(x), problems.dot(x, x), scalars=scalars
            )
            np.testing.assert_array_equal(squares, expected[0])
            np.testing.assert_array_equal(dots, expected[1])
            np.testing.assert_array_equal(read, values)
            (alone,) = problems.read(scalars=scalars)
            np.testing.assert_array_equal(alone, values)
    read[0] = np.nan  # a copy, not a view of the device array
    assert np.isfinite(arrays.host(scalars)[0])


@pytest.mark.slow
def test_batched_curves_equal_sequential_ones(device):
    """Three problems (different meshes, materials, contact conditions and depths, one of
    them cut back) give each the curve and displacements of its own run, to 1e-8."""
    problems = _problems()
    depths = [
        RADIUS_M * np.array([0.05, 0.1]),
        RADIUS_M * np.array([0.02, 0.04, 0.3]),  # a large last increment: cut back
        RADIUS_M * np.array([0.08]),
    ]
    # Few iterations per increment, so that the large one is cut back.
    options = NewtonOptions(tolerance=TOLERANCE, max_newton_iterations=5)
    batched = simulate_indentation_batch(problems, depths, device=device, options=options)
    cut = 0
    for problem, path, result in zip(problems, depths, batched, strict=True):
        alone = _alone(problem, path, device, options)
        assert result.completed and alone.completed, (result.message, alone.message)
        np.testing.assert_allclose(result.depths_m, path)
        np.testing.assert_allclose(result.reaction_force_N, alone.reaction_force_N, rtol=1e-8)
        scale = np.abs(alone.displacement_m).max()
        np.testing.assert_allclose(
            result.displacement_m, alone.displacement_m, rtol=0, atol=1e-8 * scale
        )
        np.testing.assert_allclose(
            result.von_mises_Pa, alone.von_mises_Pa, rtol=0, atol=1e-6 * alone.von_mises_Pa.max()
        )
        assert result.newton_iterations.min() >= 1
        cut += result.cutbacks
    assert batched[1].cutbacks > 0 and cut == batched[1].cutbacks


@pytest.mark.slow
def test_batched_force_sensitivities_equal_sequential_ones(device):
    """dF/dC10 and dF/dK of each problem, by its own parameters, equal those of its own run
    (exact sensitivities, tests/test_fem_sensitivity.py), to 1e-7."""
    problems = _problems()
    depths = [
        RADIUS_M * np.array([0.05, 0.1]),
        RADIUS_M * np.array([0.04, 0.12]),
        RADIUS_M * np.array([0.08]),
    ]
    names = ("C10_Pa", "bulk_modulus_Pa")
    options = NewtonOptions(tolerance=TOLERANCE)
    batched = simulate_indentation_batch(
        problems, depths, device=device, options=options, sensitivities=names
    )
    for problem, path, result in zip(problems, depths, batched, strict=True):
        alone = _alone(problem, path, device, options, sensitivities=names)
        assert result.sensitivity_names == names
        assert result.force_sensitivity_N_per_unit.shape == (len(path), 2)
        np.testing.assert_allclose(
            result.force_sensitivity_N_per_unit, alone.force_sensitivity_N_per_unit, rtol=1e-7
        )


def test_a_failing_problem_stops_alone():
    """With no cutback allowed, the problem whose increment is too large for its Newton
    iterations stops with what converged; the others complete as alone."""
    problems = _problems()[:2]
    depths = [RADIUS_M * np.array([0.05, 0.1]), RADIUS_M * np.array([0.02, 0.4])]
    options = NewtonOptions(tolerance=TOLERANCE, max_cutbacks=0, max_newton_iterations=8)
    easy, hard = simulate_indentation_batch(problems, depths, device="cpu", options=options)
    assert easy.completed
    assert not hard.completed and len(hard.depths_m) == 1
    assert "Newton failed" in hard.message
    alone = simulate_indentation(
        problems[0],
        depths[0],
        device="cpu",
        progress=False,
        options=NewtonOptions(tolerance=TOLERANCE),
    )
    np.testing.assert_allclose(easy.reaction_force_N, alone.reaction_force_N, rtol=1e-8)


@pytest.mark.slow
def test_a_reused_assembler_takes_each_calls_materials():
    """An assembler from batch_assembler, reused with new materials (a fit's next trial
    points), gives the curves of a run that builds its own; one of other meshes is refused."""
    problems = _problems()[:2]
    depths = [RADIUS_M * np.array([0.05, 0.1]), RADIUS_M * np.array([0.08])]
    options = NewtonOptions(tolerance=TOLERANCE)
    stiffer = [
        IndentationProblem(
            p.mesh,
            p.material.with_parameters(p.material.parameter_vector * 1.5),
            p.indenter,
            symmetry_planes=p.symmetry_planes,
        )
        for p in problems
    ]
    assembler = batch_assembler(problems, device="cpu")
    first = simulate_indentation_batch(problems, depths, options=options, assembler=assembler)
    second = simulate_indentation_batch(stiffer, depths, options=options, assembler=assembler)
    fresh = simulate_indentation_batch(stiffer, depths, device="cpu", options=options)
    for reused, own, soft in zip(second, fresh, first, strict=True):
        np.testing.assert_allclose(reused.reaction_force_N, own.reaction_force_N, rtol=1e-12)
        assert np.all(np.abs(reused.reaction_force_N) > 1.4 * np.abs(soft.reaction_force_N))
    with pytest.raises(InputError, match="assembler was built for other meshes"):
        simulate_indentation_batch(problems[:1], depths[:1], assembler=assembler)


def test_the_batch_refuses_what_it_cannot_take():
    problem = _problems()[0]
    depths = [RADIUS_M * np.array([0.05])]
    with pytest.raises(InputError, match="at least one problem"):
        simulate_indentation_batch([], [])
    with pytest.raises(InputError, match="one depth sequence per problem"):
        simulate_indentation_batch([problem], depths * 2)
    with pytest.raises(InputError, match="strictly increasing"):
        simulate_indentation_batch([problem], [np.array([2e-4, 1e-4])])
    viscous = IndentationProblem(
        problem.mesh,
        Viscoelastic(problem.material, (0.3,), (1.0,)),
        problem.indenter,
        symmetry_planes=problem.symmetry_planes,
    )
    with pytest.raises(InputError, match="needs the time of each load"):
        simulate_indentation_batch([viscous], depths)
    ogden = IndentationProblem(
        problem.mesh,
        Ogden((120.0, -30.0), (5.0, -2.0), 1.8e5),
        problem.indenter,
        symmetry_planes=problem.symmetry_planes,
    )
    with pytest.raises(InputError, match="Ogden exponents"):
        simulate_indentation_batch([ogden, problem], depths * 2, sensitivities=("alpha1",))


@pytest.mark.slow
def test_viscoelastic_ramp_and_hold_batch_equals_single_runs(device):
    """A ramp-and-hold of two viscoelastic problems (different Prony series, time steps and
    meshes) and an elastic one, solved together with their exact sensitivities (a Prony
    parameter included), equals each problem's own run: forces to 1e-8, sensitivities to
    1e-7."""
    base = _problems()
    problems = [
        IndentationProblem(
            base[0].mesh,
            Viscoelastic(base[0].material, (0.35, 0.3), (1.0, 20.0)),
            base[0].indenter,
            symmetry_planes=base[0].symmetry_planes,
        ),
        IndentationProblem(
            base[1].mesh,
            Viscoelastic(base[1].material, (0.5,), (2.0,)),
            base[1].indenter,
            symmetry_planes=base[1].symmetry_planes,
        ),
        base[2],
    ]
    depths = [
        RADIUS_M * np.array([0.05, 0.1, 0.1, 0.1]),
        RADIUS_M * np.array([0.04, 0.08, 0.08]),
        RADIUS_M * np.array([0.05, 0.08]),
    ]
    times = [np.array([0.5, 1.0, 3.0, 9.0]), np.array([0.2, 0.4, 5.0]), None]
    names = ("C10_Pa", "g1")
    options = NewtonOptions(tolerance=TOLERANCE)
    batched = simulate_indentation_batch(
        problems,
        depths,
        device=device,
        options=options,
        sensitivities=names[:1],
        times_s=times,
    )
    viscous = simulate_indentation_batch(
        problems[:2],
        depths[:2],
        device=device,
        options=options,
        sensitivities=names,
        times_s=times[:2],
    )
    for k, (problem, path, time) in enumerate(zip(problems, depths, times, strict=True)):
        alone = _alone(
            problem, path, device, options, sensitivities=names[: 2 if k < 2 else 1], times_s=time
        )
        assert batched[k].completed and alone.completed
        np.testing.assert_allclose(batched[k].reaction_force_N, alone.reaction_force_N, rtol=1e-8)
        np.testing.assert_allclose(
            batched[k].force_sensitivity_N_per_unit,
            alone.force_sensitivity_N_per_unit[:, :1],
            rtol=1e-7,
        )
        if k < 2:
            np.testing.assert_allclose(
                viscous[k].force_sensitivity_N_per_unit,
                alone.force_sensitivity_N_per_unit,
                rtol=1e-7,
            )
    # The hold relaxes: the viscoelastic forces fall at constant depth.
    assert batched[0].reaction_force_N[-1] < 0.9 * batched[0].reaction_force_N[1]


# --- rigid contact in a batch ---------------------------------------------------------------

CONTACT_FIELDS = ("reaction_force_N", "contact_force_N", "contact_area_m2", "max_penetration_m")


def _contact_block():
    """A coarse quarter block 3 R x 1.5 R under indenters of radius about 0.2 R (1 463 TET10
    nodes)."""
    return indentation_block(
        width_m=3.0 * RADIUS_M,
        thickness_m=1.5 * RADIUS_M,
        probe_radius_m=0.2 * RADIUS_M,
        size_near_m=0.2 * RADIUS_M,
        size_far_m=0.75 * RADIUS_M,
    )


def _contact_problems():
    """A sphere, a rounded flat punch, a wedge, a plate and a bonded flat punch, with their
    own meshes, materials and depths."""
    block = _contact_block()
    problems = [
        IndentationProblem(block, NeoHookean(287.5, 575e3), Indenter("sphere", radius_m=RADIUS_M)),
        IndentationProblem(
            block,
            NeoHookean(400.0, 4e5),
            Indenter("flat_punch", radius_m=0.2 * RADIUS_M, edge_radius_m=0.05 * RADIUS_M),
        ),
        IndentationProblem(_wedge_strip(full=False), NeoHookean(287.5, 575e3), WEDGE),
        IndentationProblem(
            _plate_cube(), NeoHookean(100.0, 1e5), Indenter("plate"), base="sliding"
        ),
        IndentationProblem(
            block, MooneyRivlin(200.0, 60.0, 2e5), Indenter("flat_punch", radius_m=0.2 * RADIUS_M)
        ),
    ]
    depths = [
        RADIUS_M * np.array([0.01, 0.03]),
        RADIUS_M * np.array([0.02]),
        np.array([0.1e-3]),
        1e-2 * np.array([0.05, 0.1]),
        RADIUS_M * np.array([0.01, 0.02]),
    ]
    return problems, depths


@pytest.mark.slow
def test_batched_rigid_contacts_equal_their_single_runs(device):
    """A sphere, a rounded punch, a wedge, a plate and a bonded flat punch solved together
    (one contact launch over all their candidate nodes, each problem with its own body,
    depth and penalty) give each the force curve and contact outputs of its own run, to
    1e-8 (measured 1e-12 - 1e-10), and the sphere's exact sensitivities (the penalty's
    dependence on mu0 included) those of its own run, to 1e-7."""
    problems, depths = _contact_problems()
    names = ("C10_Pa", "bulk_modulus_Pa")
    options = NewtonOptions(tolerance=TOLERANCE)
    batched = simulate_indentation_batch(
        problems, depths, device=device, options=options, sensitivities=names
    )
    for k, (problem, path, result) in enumerate(zip(problems, depths, batched, strict=True)):
        alone = _alone(problem, path, device, options, sensitivities=names if k == 0 else ())
        assert result.completed and alone.completed, (result.message, alone.message)
        np.testing.assert_allclose(result.depths_m, path)
        for name in CONTACT_FIELDS:
            mine, theirs = getattr(result, name), getattr(alone, name)
            assert mine.shape == theirs.shape, name
            np.testing.assert_allclose(mine, theirs, rtol=1e-8, err_msg=name)
        assert result.contact_pressure_Pa.shape == alone.contact_pressure_Pa.shape
        if problem.is_contact:
            np.testing.assert_allclose(
                result.contact_pressure_Pa,
                alone.contact_pressure_Pa,
                rtol=0,
                atol=1e-8 * alone.contact_pressure_Pa.max(),
            )
            np.testing.assert_allclose(result.contact_force_N, result.reaction_force_N, rtol=1e-6)
        else:
            assert result.contact_force_N.size == 0
        scale = np.abs(alone.displacement_m).max()
        np.testing.assert_allclose(
            result.displacement_m, alone.displacement_m, rtol=0, atol=1e-8 * scale
        )
        assert result.force_sensitivity_N_per_unit.shape == (len(path), len(names))
        if k == 0:  # the sphere: through the contact's penalty
            assert np.all(result.force_sensitivity_N_per_unit[:, 0] > 0.0)
            np.testing.assert_allclose(
                result.force_sensitivity_N_per_unit, alone.force_sensitivity_N_per_unit, rtol=1e-7
            )


def test_packed_contacts_assemble_as_each_problem_alone(device, rng):
    """One packed assembler with each problem's contact (and none on the bonded punch), at
    each problem's depth, gives each problem's residual, energy, tangent, contact state and
    dR/dC10 (the penalty's share included) of its own assembler."""
    problems, _ = _contact_problems()
    depths = np.array([0.03 * RADIUS_M, 0.02 * RADIUS_M, 0.2e-3, 5e-4, 0.0])
    packed = pack_meshes([problem.mesh for problem in problems])
    assembler = batch_assembler(problems, device=device)
    assembler.set_contact([problem.rigid_contact() for problem in problems])
    assembler.set_load(depths)
    u = 1e-6 * rng.standard_normal((packed.mesh.node_count, 3))
    assembly = assembler.assemble(u)
    residual = assembly.residual.numpy().copy()  # the buffer is reused
    direction = rng.standard_normal((packed.mesh.node_count, 3))
    product = wp.zeros(packed.mesh.node_count, dtype=wp.vec3d, device=device)
    wps.bsr_mv(assembly.matrix, wp.array(direction, dtype=wp.vec3d, device=device), product)
    product = product.numpy()
    d_residual = assembler.parameter_residual(u, "C10_Pa")
    states = assembler.contact_states(u)
    assert states[-1] is None and assembler.contact is None
    for k, problem in enumerate(problems):
        nodes = packed.nodes(k)
        alone = Assembler(problem.mesh, problem.material, device=device)
        alone.set_contact(problem.rigid_contact())
        alone.set_load(depths[k])
        single = alone.assemble(u[nodes])
        expected = single.residual.numpy()
        scale = np.abs(expected).max()
        np.testing.assert_allclose(residual[nodes], expected, rtol=0, atol=1e-12 * scale)
        assert assembly.problem_energies_J[k] == pytest.approx(single.energy_J, rel=1e-12)
        mine = wp.zeros(problem.mesh.node_count, dtype=wp.vec3d, device=device)
        wps.bsr_mv(single.matrix, wp.array(direction[nodes], dtype=wp.vec3d, device=device), mine)
        mine = mine.numpy()
        np.testing.assert_allclose(product[nodes], mine, rtol=0, atol=1e-12 * np.abs(mine).max())
        theirs = alone.parameter_residual(u[nodes], "C10_Pa")
        np.testing.assert_allclose(
            d_residual[nodes], theirs, rtol=0, atol=1e-12 * np.abs(theirs).max()
        )
        if problem.is_contact:
            state = alone.contact_state(u[nodes])
            assert np.array_equal(states[k].nodes, state.nodes)
            assert np.any(state.gap_m < 0.0)
            np.testing.assert_allclose(states[k].gap_m, state.gap_m, rtol=1e-12)
            np.testing.assert_allclose(states[k].force_N, state.force_N, rtol=1e-12, atol=0)
            state = assembler.contact_state(u, problem=k)
            np.testing.assert_array_equal(state.force_N, states[k].force_N)


def test_packed_contacts_are_refused_where_they_do_not_fit():
    problems, _ = _contact_problems()
    problems = problems[:2]
    assembler = batch_assembler(problems, device="cpu")
    contacts = [problem.rigid_contact() for problem in problems]
    with pytest.raises(InputError, match="one contact"):
        assembler.set_contact(contacts[0])
    with pytest.raises(InputError, match="one contact"):
        assembler.set_contact(contacts[:1])
    beyond = RigidContact(
        contacts[1].indenter,
        np.array([problems[1].mesh.node_count]),
        contacts[1].top_z_m,
        contacts[1].stiffness_N_per_m,
    )
    with pytest.raises(InputError, match="of problem 1"):
        assembler.set_contact([contacts[0], beyond])
    with pytest.raises(InputError, match="one load per packed problem"):
        assembler.set_contact(contacts)
        assembler.set_load(np.zeros(3))
    with pytest.raises(InputError, match="name the problem"):
        assembler.contact_state(np.zeros((assembler.node_count, 3)))
    assembler.set_contact(None)
    assert assembler.contacts == (None, None) and not assembler.has_contact


def test_a_batch_of_one_contact_problem_is_its_single_run(device):
    """K = 1 through the batch (a packed assembler of one problem) is the single run: the
    same forces and contact outputs (to the Newton tolerance)."""
    problems, depths = _contact_problems()
    options = NewtonOptions(tolerance=TOLERANCE)
    depths = depths[0][:1]
    (batched,) = simulate_indentation_batch(problems[:1], [depths], device=device, options=options)
    alone = _alone(problems[0], depths, device, options)
    for name in CONTACT_FIELDS:
        np.testing.assert_allclose(getattr(batched, name), getattr(alone, name), rtol=1e-8)


def test_the_penalty_ramp_decides_per_problem(monkeypatch):
    """The soft stage scales every problem's penalty and restores it; the stiff stage takes
    the problems that converged in the soft one from their soft states; a problem that failed
    either stage keeps its start state, with the reason of the stage it failed."""
    from warptissue.fem.newton import increment

    contacts = [SimpleNamespace(stiffness_N_per_m=10.0), SimpleNamespace(stiffness_N_per_m=30.0)]
    assembler = SimpleNamespace(contacts=(contacts[0], None, contacts[1]))
    stages = []
    outcomes = [np.array([True, False, True]), np.array([True, True, False])]

    def stage(assembler, solver, problems, u_start, prescribed, free, constrained, **options):
        number = len(stages)
        stages.append(
            (
                options["active"].copy(),
                options["tolerance"],
                [each.stiffness_N_per_m for each in contacts],
                np.array(u_start),
            )
        )
        converged = options["active"] & outcomes[number]
        state = u_start + 1.0
        return increment.Increment(
            converged=converged,
            displacement=problems.where(converged, state, u_start),
            iterations=np.array([2, 3, 4]) * options["active"],
            linear_iterations=np.zeros(3, dtype=np.int64),
            local_iterations=np.zeros(3, dtype=np.int64),
            reasons=["converged" if done else f"stage {number} failed" for done in converged],
            from_guess=np.zeros(3, dtype=bool),
            last_iterate=state,
        )

    monkeypatch.setattr(increment, "newton_increment", stage)
    arrays = DeviceArrays(wp.get_device("cpu"))
    with arrays.context():
        problems = Problems(arrays, [0, 2, 3, 5])
        start = np.zeros((5, 3))
        step = increment.penalty_ramped_increment(
            assembler,
            None,
            problems,
            start,
            start,
            start,
            start,
            tolerance=1e-10,
            active=np.array([True, True, True]),
        )
    ramp = increment.CONTACT_PENALTY_RAMP
    assert stages[0][1] == increment.CONTACT_RAMP_TOLERANCE and stages[1][1] == 1e-10
    assert stages[0][2] == [10.0 * ramp, 30.0 * ramp] and stages[1][2] == [10.0, 30.0]
    np.testing.assert_array_equal(stages[1][0], [True, False, True])
    np.testing.assert_array_equal(stages[1][3], [[1.0] * 3] * 2 + [[0.0] * 3] + [[1.0] * 3] * 2)
    np.testing.assert_array_equal(step.converged, [True, False, False])
    np.testing.assert_array_equal(step.displacement, [[2.0] * 3] * 2 + [[0.0] * 3] * 3)
    np.testing.assert_array_equal(step.iterations, [4, 3, 8])
    assert step.reasons == ["converged", "stage 0 failed", "stage 1 failed"]


def test_a_batch_starts_each_problem_from_its_own_warm_states(device):
    """A fit's next batched evaluation: each problem started from the states of the last
    batch (the first two), or cold (the third), at new materials, gives the forces of a
    cold batch to the Newton tolerance, in fewer Newton iterations where it starts warm."""
    problems = _problems()
    depths = [RADIUS_M * np.array([0.05, 0.1])] * len(problems)
    options = NewtonOptions(tolerance=TOLERANCE)
    earlier = simulate_indentation_batch(problems, depths, device=device, options=options)
    moved = []  # the last parameter (K, or Mooney-Rivlin's C01) down 10 %, the others up 30 %
    for problem in problems:
        vector = problem.material.parameter_vector.copy()
        vector[:-1] *= 1.3
        vector[-1] *= 0.9
        moved.append(
            dataclasses.replace(problem, material=problem.material.with_parameters(vector))
        )
    cold = simulate_indentation_batch(moved, depths, device=device, options=options)
    warm_states = [earlier[0].displacement_m, earlier[1].displacement_m, None]
    warm = simulate_indentation_batch(
        moved, depths, device=device, options=options, warm_states_m=warm_states
    )
    for mine, theirs in zip(warm, cold, strict=True):
        assert mine.completed and theirs.completed
        np.testing.assert_allclose(mine.reaction_force_N, theirs.reaction_force_N, rtol=1e-8)
    for k in (0, 1):
        assert warm[k].newton_iterations.sum() < cold[k].newton_iterations.sum()
    with pytest.raises(InputError, match="one entry per packed problem"):
        simulate_indentation_batch(moved, depths, device=device, warm_states_m=warm_states[:2])
