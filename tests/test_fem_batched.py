"""K indentations solved together (the one Newton loop with K > 1): every problem's
curve equals the one :func:`warptissue.fem.simulate_indentation` gives it alone, with its own
cutbacks, and a failing problem stops without holding the others."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from warptissue.errors import InputError
from warptissue.fem import (
    IndentationProblem,
    NewtonOptions,
    batch_assembler,
    simulate_indentation,
    simulate_indentation_batch,
)
from warptissue.fem.arrays import DeviceArrays
from warptissue.fem.newton.problems import Problems
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
        alone = simulate_indentation(problem, path, device=device, progress=False, options=options)
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
        alone = simulate_indentation(
            problem, path, device=device, progress=False, options=options, sensitivities=names
        )
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
    sphere = IndentationProblem(
        problem.mesh,
        problem.material,
        Indenter("sphere", radius_m=RADIUS_M),
        symmetry_planes=problem.symmetry_planes,
    )
    with pytest.raises(InputError, match="flat punches"):
        simulate_indentation_batch([sphere], depths)
    ogden = IndentationProblem(
        problem.mesh,
        Ogden((120.0, -30.0), (5.0, -2.0), 1.8e5),
        problem.indenter,
        symmetry_planes=problem.symmetry_planes,
    )
    with pytest.raises(InputError, match="Ogden exponents"):
        simulate_indentation_batch([ogden, problem], depths * 2, sensitivities=("alpha1",))


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
        alone = simulate_indentation(
            problem,
            path,
            device=device,
            progress=False,
            options=options,
            sensitivities=names if k < 2 else names[:1],
            times_s=time,
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
