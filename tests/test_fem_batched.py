"""K indentations solved together (the one Newton loop with K > 1): every problem's
curve equals the one :func:`warptissue.fem.simulate_indentation` gives it alone, with its own
cutbacks, and a failing problem stops without holding the others; rigid indenters in contact
(sphere, rounded punch, wedge, plate) mix with flat punches, each with its own contact
outputs."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp
from test_fem_contact import WEDGE, _plate_cube, _wedge_strip

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
    with pytest.raises(InputError, match="elastic materials"):
        simulate_indentation_batch([viscous], depths)
    ogden = IndentationProblem(
        problem.mesh,
        Ogden((120.0, -30.0), (5.0, -2.0), 1.8e5),
        problem.indenter,
        symmetry_planes=problem.symmetry_planes,
    )
    with pytest.raises(InputError, match="Ogden exponents"):
        simulate_indentation_batch([ogden, problem], depths * 2, sensitivities=("alpha1",))


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
        np.array([0.1e-3, 0.2e-3]),
        1e-2 * np.array([0.05, 0.1]),
        RADIUS_M * np.array([0.01, 0.02]),
    ]
    return problems, depths


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
        alone = simulate_indentation(
            problem,
            path,
            device=device,
            progress=False,
            options=options,
            sensitivities=names if k == 0 else (),
        )
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
