"""A body of several materials in the FE (warptissue.fem.regions): two layers in series
(analytic), one material in two regions equal to the plain body, exact sensitivities by each
region's parameters (central differences), packed problems, stresses per region and the
refusals."""

from __future__ import annotations

import numpy as np
import pytest

from warptissue.errors import InputError
from warptissue.fem import (
    Assembler,
    IndentationProblem,
    simulate_indentation,
    simulate_indentation_batch,
)
from warptissue.fem.regions import material_slots
from warptissue.indenter import Indenter
from warptissue.materials import MaterialRegions, NeoHookean, Viscoelastic, material_from_dict
from warptissue.mesh import TetMesh, block_mesh, to_tet10

WIDTH_M, HEIGHT_M = 4e-3, 2e-3
SHEAR_PA = 200.0


def _layers(cells: int = 2, layers: int = 2) -> TetMesh:
    """A column on z = 0 whose upper half is tet region 1, the lower tet region 0."""
    half = WIDTH_M / 2
    mesh = to_tet10(
        block_mesh(
            np.linspace(-half, half, cells + 1),
            np.linspace(-half, half, cells + 1),
            np.linspace(0.0, HEIGHT_M, layers + 1),
        )
    )
    centroids = mesh.points[mesh.tets[:, :4]].mean(axis=1)
    mesh.tet_regions = (centroids[:, 2] > HEIGHT_M / 2).astype(np.int32)
    mesh.node_sets["top"] = mesh.node_sets["zmax"]
    mesh.node_sets["bottom"] = mesh.node_sets["zmin"]
    return mesh


def _no_lateral(shear_Pa: float) -> NeoHookean:
    """Poisson's ratio 0: K = 2 mu / 3, E = 2 mu."""
    return NeoHookean(shear_Pa / 2.0, 2.0 * shear_Pa / 3.0)


def _body(lower: float, upper: float) -> MaterialRegions:
    return MaterialRegions(_no_lateral(lower), {"top": _no_lateral(upper)}, {"top": (1,)})


def _problem(mesh, material, indenter) -> IndentationProblem:
    return IndentationProblem(mesh, material, indenter, symmetry_planes=())


def test_two_layers_under_a_plate_are_two_springs_in_series(device):
    """Poisson's ratio 0 and a bonded plate over the whole top: each layer is compressed
    uniaxially, F = d A / (h1 / E1 + h2 / E2)."""
    plate = Indenter("flat_punch", radius_m=WIDTH_M, contact="bonded")
    depth = 1e-9  # the strain (5e-7) is the finite-strain error's order
    lower, upper = SHEAR_PA, 5.0 * SHEAR_PA
    result = simulate_indentation(
        _problem(_layers(), _body(lower, upper), plate), [depth], device=device, progress=False
    )
    half = HEIGHT_M / 2
    expected = depth * WIDTH_M**2 / (half / (2.0 * lower) + half / (2.0 * upper))
    assert result.completed, result.message
    assert result.reaction_force_N[0] == pytest.approx(expected, rel=1e-6)
    uniform = simulate_indentation(
        _problem(_layers(), _no_lateral(lower), plate), [depth], device=device, progress=False
    )
    assert result.reaction_force_N[0] > 1.5 * uniform.reaction_force_N[0]


def test_one_material_in_two_regions_is_the_plain_body(device):
    sphere = Indenter("sphere", radius_m=1.5e-3)
    material = NeoHookean(100.0, 10_000.0)
    body = MaterialRegions(material, {"top": material}, {"top": (1,)})
    depths = [1e-4, 2e-4]
    plain, split = (
        simulate_indentation(
            _problem(_layers(), each, sphere), depths, device=device, progress=False
        )
        for each in (material, body)
    )
    np.testing.assert_allclose(split.reaction_force_N, plain.reaction_force_N, rtol=1e-12)


def test_each_regions_sensitivity_is_exact(device):
    """dF/dC10 of the default and of the region "top" (and of their bulk moduli) from the
    FE equal central differences of whole runs, and sum to the plain body's dF/dC10."""
    sphere = Indenter("sphere", radius_m=1.5e-3)
    body = MaterialRegions(
        NeoHookean(100.0, 10_000.0), {"top": NeoHookean(300.0, 30_000.0)}, {"top": (1,)}
    )
    names = ("C10_Pa", "top.C10_Pa", "bulk_modulus_Pa", "top.bulk_modulus_Pa")
    depths = [2e-4]
    mesh = _layers()
    result = simulate_indentation(
        _problem(mesh, body, sphere), depths, device=device, progress=False, sensitivities=names
    )
    exact = result.force_sensitivity_N_per_unit[-1]
    for j, name in enumerate(names):
        flat = body._flat_parameters()
        step = 1e-4 * flat[name]
        forces = []
        for sign in (1.0, -1.0):
            moved = body.to_dict()
            index, local = body.part_of(name)
            table = moved if index == 0 else moved["regions"]["top"]
            table[local] = flat[name] + sign * step
            run = simulate_indentation(
                _problem(mesh, material_from_dict(moved), sphere),
                depths,
                device=device,
                progress=False,
            )
            forces.append(run.reaction_force_N[-1])
        difference = (forces[0] - forces[1]) / (2.0 * step)
        assert exact[j] == pytest.approx(difference, rel=1e-5), name
    plain_material = NeoHookean(100.0, 10_000.0)
    same = MaterialRegions(plain_material, {"top": plain_material}, {"top": (1,)})
    split = simulate_indentation(
        _problem(mesh, same, sphere), depths, device=device, progress=False, sensitivities=names
    ).force_sensitivity_N_per_unit[-1]
    plain = simulate_indentation(
        _problem(mesh, NeoHookean(100.0, 10_000.0), sphere),
        depths,
        device=device,
        progress=False,
        sensitivities=("C10_Pa",),
    ).force_sensitivity_N_per_unit[-1]
    assert split[0] + split[1] == pytest.approx(plain[0], rel=1e-9)


def test_packed_problems_with_regions_equal_sequential_ones(device):
    sphere = Indenter("sphere", radius_m=1.5e-3)
    bodies = [
        _body(SHEAR_PA, 4.0 * SHEAR_PA),
        NeoHookean(SHEAR_PA / 2.0, 50.0 * SHEAR_PA),
        _body(3.0 * SHEAR_PA, SHEAR_PA),
    ]
    problems = [_problem(_layers(), body, sphere) for body in bodies]
    depths = [[1e-4, 2e-4]] * 3
    names = ("C10_Pa",)
    batched = simulate_indentation_batch(problems, depths, sensitivities=names, device=device)
    for problem, depth, together in zip(problems, depths, batched, strict=True):
        alone = simulate_indentation(
            problem, depth, device=device, progress=False, sensitivities=names
        )
        np.testing.assert_allclose(together.reaction_force_N, alone.reaction_force_N, rtol=1e-7)
        np.testing.assert_allclose(
            together.force_sensitivity_N_per_unit,
            alone.force_sensitivity_N_per_unit,
            rtol=1e-6,
        )


def test_each_tet_has_its_regions_stress(device):
    """Under a uniform stretch each tet's stress is its own region's material's."""
    mesh = _layers()
    body = _body(SHEAR_PA, 3.0 * SHEAR_PA)
    assembler = Assembler(mesh, body, device=device)
    u = np.zeros((mesh.node_count, 3))
    u[:, 0] = 1e-4 * mesh.points[:, 0]
    stress = assembler.cauchy_stress(u)
    top = mesh.tet_regions == 1
    ratio = stress[top, 0].mean() / stress[~top, 0].mean()
    assert ratio == pytest.approx(3.0, rel=1e-6)


def test_the_material_table_puts_each_problem_first():
    material = NeoHookean(100.0, 10_000.0)
    body = MaterialRegions(material, {"a": material, "b": material}, {"a": (1,), "b": (2, 3)})
    problems = np.array([0, 0, 0, 0, 1, 1, 1, 1])
    regions = np.array([0, 1, 2, 3, 1, 0, 3, 2])
    slots = material_slots([body, body], problems, regions)
    assert slots.element_material.tolist() == [0, 2, 3, 3, 4, 1, 5, 5]
    assert slots.prefixes == ("", "", "a.", "b.", "a.", "b.")
    assert slots.problems.tolist() == [0, 1, 0, 0, 1, 1]
    assert slots.owner(2, "a.C10_Pa") == "C10_Pa"
    assert slots.owner(0, "a.C10_Pa") is None
    assert slots.owner(0, "C10_Pa") == "C10_Pa"


def test_bad_regions_are_refused_naming_the_key():
    material = NeoHookean(100.0, 10_000.0)
    with pytest.raises(InputError, match="tet region 7, which the mesh does not have") as info:
        Assembler(_layers(), MaterialRegions(material, {"top": material}, {"top": (7,)}))
    assert info.value.key == "material.regions.top.tet_regions"
    with pytest.raises(InputError, match="held by region 'a' already"):
        MaterialRegions(material, {"a": material, "b": material}, {"a": (1,), "b": (1,)})
    with pytest.raises(InputError, match="Prony series per region"):
        MaterialRegions(material, {"a": Viscoelastic(material, (0.3,), (1.0,))}, {"a": (1,)})
    with pytest.raises(InputError, match="a letter"):
        MaterialRegions(material, {"a.b": material}, {"a.b": (1,)})
    with pytest.raises(InputError, match="one set of device parameters per region"):
        MaterialRegions(material, {"a": material}, {"a": (1,)}).device_params()
