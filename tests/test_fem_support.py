"""An elastic foundation under the specimen (warptissue.fem.support) and the sliding base on
any axis plane: the bed in series with the body (analytic), the spring blocks' integral over
the support, the probe force equal to the contact force with exact sensitivities (central
differences), the stiff-bed limit, batches, and the refusals."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from warptissue.errors import InputError
from warptissue.fem import (
    Foundation,
    IndentationProblem,
    simulate_indentation,
    simulate_indentation_batch,
)
from warptissue.fem.support import SupportSprings
from warptissue.indenter import Indenter
from warptissue.materials import NeoHookean
from warptissue.mesh import TetMesh, block_mesh, to_tet10

WIDTH_M, HEIGHT_M = 4e-3, 2e-3
SHEAR_PA = 200.0
BED_PA_PER_M = 2e5


def _column(cells: int = 3, layers: int = 2, *, element: str = "TET10") -> TetMesh:
    """A block centred on the z axis, base z = 0: "top" and "bottom" its z faces."""
    half = WIDTH_M / 2
    mesh = block_mesh(
        np.linspace(-half, half, cells + 1),
        np.linspace(-half, half, cells + 1),
        np.linspace(0.0, HEIGHT_M, layers + 1),
    )
    if element == "TET10":
        mesh = to_tet10(mesh)
    mesh.node_sets["top"] = mesh.node_sets["zmax"]
    mesh.node_sets["bottom"] = mesh.node_sets["zmin"]
    return mesh


def _on_bed(mesh, material, indenter, foundation=None, **options) -> IndentationProblem:
    return IndentationProblem(
        mesh,
        material,
        indenter,
        base="foundation",
        foundation=foundation or Foundation(BED_PA_PER_M),
        symmetry_planes=(),
        **options,
    )


def test_a_column_on_a_bed_is_the_body_and_the_bed_in_series(device):
    """Poisson's ratio 0 (K = 2 mu / 3): a bonded plate over the whole top compresses the
    column uniaxially and the bed uniformly, F = d A / (H / E + 1 / k), E = 2 mu."""
    material = NeoHookean(SHEAR_PA / 2.0, 2.0 * SHEAR_PA / 3.0)
    plate = Indenter("flat_punch", radius_m=WIDTH_M, contact="bonded")
    depth = 1e-7
    result = simulate_indentation(
        _on_bed(_column(), material, plate), [depth], device=device, progress=False
    )
    expected = depth * WIDTH_M**2 / (HEIGHT_M / (2.0 * SHEAR_PA) + 1.0 / BED_PA_PER_M)
    assert result.completed, result.message
    assert result.reaction_force_N[0] == pytest.approx(expected, rel=1e-4)


@pytest.mark.parametrize("element", ["TET4", "TET10"])
def test_the_spring_blocks_integrate_the_bed_over_the_support(element):
    """Sum of S_i over a flat base = A diag(k_t, k_t, k_n); only nodes of the base carry one."""
    mesh = _column(element=element)
    springs = SupportSprings.foundation(mesh, Foundation(3.0, 1.0), surface="bottom")
    area = WIDTH_M**2
    np.testing.assert_allclose(
        springs.blocks.sum(axis=0), area * np.diag([1.0, 1.0, 3.0]), rtol=1e-12, atol=1e-20
    )
    assert set(springs.nodes) <= set(mesh.node_sets["bottom"])
    u = np.random.default_rng(1).normal(size=(mesh.node_count, 3))
    energy = 0.5 * np.sum(u * springs.product(u))
    assert energy > 0.0  # S is positive definite on its nodes


def test_the_blocks_follow_a_turned_support():
    """A support turned by a rotation Q has the blocks Q S Q^T."""
    mesh = _column()
    angle = 0.7
    q = np.array(
        [[np.cos(angle), 0.0, np.sin(angle)], [0.0, 1.0, 0.0], [-np.sin(angle), 0.0, np.cos(angle)]]
    )
    turned = TetMesh(points=mesh.points @ q.T, tets=mesh.tets, node_sets=dict(mesh.node_sets))
    bed = Foundation(5.0, 2.0)
    flat = SupportSprings.foundation(mesh, bed, surface="bottom")
    tilted = SupportSprings.foundation(turned, bed, surface="bottom")
    np.testing.assert_array_equal(flat.nodes, tilted.nodes)
    np.testing.assert_allclose(tilted.blocks, q @ flat.blocks @ q.T, rtol=0, atol=1e-18)


@pytest.fixture(scope="module")
def sphere_on_bed():
    mesh = _column(cells=5, layers=3)
    material = NeoHookean(SHEAR_PA / 2.0, 20.0 * SHEAR_PA)
    sphere = Indenter("sphere", radius_m=2e-3)
    bed = Foundation(BED_PA_PER_M, BED_PA_PER_M / 2.0)
    return mesh, material, sphere, bed


def test_on_a_bed_the_probe_force_is_the_contact_force_with_exact_sensitivities(sphere_on_bed):
    mesh, material, sphere, bed = sphere_on_bed
    depths = [1e-4, 2e-4]
    result = simulate_indentation(
        _on_bed(mesh, material, sphere, bed),
        depths,
        device="cpu",
        progress=False,
        sensitivities=("C10_Pa",),
    )
    assert result.completed, result.message
    np.testing.assert_allclose(result.reaction_force_N, result.contact_force_N, rtol=1e-9)
    step = 1e-3 * material.C10_Pa
    forces = [
        simulate_indentation(
            _on_bed(mesh, NeoHookean(material.C10_Pa + sign * step, 20.0 * SHEAR_PA), sphere, bed),
            depths,
            device="cpu",
            progress=False,
        ).reaction_force_N
        for sign in (1.0, -1.0)
    ]
    central = (forces[0] - forces[1]) / (2.0 * step)
    np.testing.assert_allclose(result.force_sensitivity_N_per_unit[:, 0], central, rtol=1e-5)


def test_a_stiff_bed_holds_like_the_fixed_base():
    mesh = _column()
    material = NeoHookean(SHEAR_PA / 2.0, 20.0 * SHEAR_PA)
    punch = Indenter("flat_punch", radius_m=1e-3, contact="bonded")
    depth = [1e-5]
    fixed = IndentationProblem(mesh, material, punch, symmetry_planes=())
    forces = [simulate_indentation(fixed, depth, device="cpu", progress=False).reaction_force_N]
    for stiffness in (1e6, 1e12):
        bed = Foundation(stiffness)
        run = simulate_indentation(
            _on_bed(mesh, material, punch, bed), depth, device="cpu", progress=False
        )
        forces.append(run.reaction_force_N)
    soft, stiff = forces[1][0] / forces[0][0] - 1.0, forces[2][0] / forces[0][0] - 1.0
    assert soft < -1e-3  # a bed of 1e6 Pa/m gives way
    assert abs(stiff) < 1e-6


def test_batched_problems_on_beds_equal_sequential_ones(sphere_on_bed, device):
    mesh, material, sphere, bed = sphere_on_bed
    punch = Indenter("flat_punch", radius_m=1e-3, contact="bonded")
    problems = [
        _on_bed(mesh, material, sphere, bed),
        _on_bed(mesh, material, punch, Foundation(4.0 * BED_PA_PER_M)),
        IndentationProblem(mesh, material, punch, symmetry_planes=()),
    ]
    depths = [np.array([1e-4, 2e-4])] * 3
    batched = simulate_indentation_batch(problems, depths, device=device, sensitivities=("C10_Pa",))
    for problem, together in zip(problems, batched, strict=True):
        alone = simulate_indentation(
            problem, depths[0], device=device, progress=False, sensitivities=("C10_Pa",)
        )
        np.testing.assert_allclose(together.reaction_force_N, alone.reaction_force_N, rtol=1e-7)
        np.testing.assert_allclose(
            together.force_sensitivity_N_per_unit, alone.force_sensitivity_N_per_unit, rtol=1e-6
        )


def test_a_sliding_base_holds_the_normal_of_any_axis_plane():
    """The column with its axes turned cyclically (base on x = 0, probe along -x) gives the
    same force as on z = 0: the base's normal component is held, its plane free."""
    mesh = _column()
    material = NeoHookean(SHEAR_PA / 2.0, 20.0 * SHEAR_PA)
    sphere = Indenter("sphere", radius_m=2e-3)
    depths = [1e-4]
    flat = IndentationProblem(mesh, material, sphere, base="sliding", symmetry_planes=())
    cyclic = mesh.points[:, [2, 0, 1]]
    turned_mesh = TetMesh(points=cyclic, tets=mesh.tets, node_sets=dict(mesh.node_sets))
    top = float(cyclic[:, 0].max())
    turned = IndentationProblem(
        turned_mesh,
        material,
        sphere,
        base="sliding",
        symmetry_planes=(),
        site_m=(top, 0.0, 0.0),
        direction=(-1.0, 0.0, 0.0),
    )
    held = turned.dirichlet_conditions()
    bottom = set(mesh.node_sets["bottom"])
    on_base = np.isin(held.nodes, list(bottom))
    assert set(held.components[on_base]) == {0, 1, 2}  # x on all; y, z on the pins only
    assert np.sum(held.components[on_base] == 0) == len(bottom)
    forces = [
        simulate_indentation(problem, depths, device="cpu", progress=False).reaction_force_N
        for problem in (flat, turned)
    ]
    np.testing.assert_allclose(forces[1], forces[0], rtol=1e-8)


def test_a_tilted_sliding_support_rests_on_a_frictionless_bed():
    """The column turned by an arbitrary rotation (its base on a tilted plane, the bonded
    plate along the turned axis) rests on the sliding bed: its force is the exact sliding
    base's to within the bed's penalty (1/beta: 9e-4 at beta = 1000, 6e-5 at 10 times the
    stiffness), and the base barely moves along its normal."""
    from scipy.spatial.transform import Rotation

    mesh = _column(cells=4, layers=3)
    material = NeoHookean(SHEAR_PA / 2.0, 20.0 * SHEAR_PA)
    punch = Indenter("flat_punch", radius_m=1e-3, contact="bonded")
    depths = [5e-5, 1e-4]
    top = np.array([0.0, 0.0, HEIGHT_M])
    turn = Rotation.from_euler("xyz", [23.0, -41.0, 67.0], degrees=True).as_matrix()
    turned_mesh = TetMesh(mesh.points @ turn.T, mesh.tets, node_sets=dict(mesh.node_sets))
    flat = IndentationProblem(
        mesh, material, punch, base="sliding", symmetry_planes=(), site_m=top,
        direction=(0.0, 0.0, -1.0),
    )  # fmt: skip
    exact = simulate_indentation(flat, depths, device="cpu", progress=False).reaction_force_N
    turned = IndentationProblem(
        turned_mesh, material, punch, base="sliding", symmetry_planes=(), site_m=turn @ top,
        direction=turn @ [0.0, 0.0, -1.0],
    )  # fmt: skip
    assert turned.on_sliding_bed and not flat.on_sliding_bed
    held = turned.dirichlet_conditions().nodes
    assert not np.isin(held, mesh.node_sets["bottom"]).any()  # the bed holds the base
    run = simulate_indentation(turned, depths, device="cpu", progress=False)
    error = run.reaction_force_N / exact - 1.0
    assert np.all(np.abs(error) < 2e-3), error
    normal = turn @ [0.0, 0.0, 1.0]
    base = mesh.node_sets["bottom"]
    assert np.abs(run.displacement_m[-1][base] @ normal).max() < 2e-3 * depths[-1]
    stiffer = dataclasses.replace(
        turned, sliding_bed_Pa_per_m=10.0 * turned.sliding_bed_stiffness()
    )
    closer = simulate_indentation(stiffer, depths, device="cpu", progress=False)
    assert np.all(np.abs(closer.reaction_force_N / exact - 1.0) < 0.15 * np.abs(error))


def test_bad_supports_are_refused_naming_the_key():
    mesh = _column()
    material = NeoHookean(SHEAR_PA / 2.0, 20.0 * SHEAR_PA)
    punch = Indenter("flat_punch", radius_m=1e-3, contact="bonded")
    tilted = TetMesh(
        points=mesh.points + np.outer(mesh.points[:, 0], [0.0, 0.0, 0.1]),
        tets=mesh.tets,
        node_sets=dict(mesh.node_sets),
    )
    with pytest.raises(InputError, match="positive number of Pa/m") as caught:
        IndentationProblem(
            tilted, material, punch, base="sliding", symmetry_planes=(), sliding_bed_Pa_per_m=0.0
        )
    assert caught.value.key == "sliding_bed_Pa_per_m"
    with pytest.raises(InputError, match="positive number of Pa/m"):
        IndentationProblem(
            tilted, material, punch, base="sliding", symmetry_planes=(), sliding_bed_Pa_per_m=True
        )
    with pytest.raises(InputError) as caught:
        IndentationProblem(mesh, material, punch, base="foundation", symmetry_planes=())
    assert caught.value.key == "foundation"
    with pytest.raises(InputError) as caught:
        IndentationProblem(mesh, material, punch, foundation=Foundation(1.0), symmetry_planes=())
    assert caught.value.key == "foundation"
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(InputError) as caught:
            Foundation(bad)
        assert caught.value.key == "normal_Pa_per_m"
    with pytest.raises(InputError) as caught:
        Foundation(1.0, 0.0)
    assert caught.value.key == "tangential_Pa_per_m"
    assert Foundation(2.0).tangential_Pa_per_m == 2.0
