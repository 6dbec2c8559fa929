"""Independent problems packed into one mesh (:mod:`warptissue.fem.packing`) and assembled in
the same launches: each problem's residual, tangent, energy, smallest J, stress and
derivative by a material parameter equal those of its own assembler, on every Warp
device."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from warptissue.errors import InputError
from warptissue.fem import Assembler
from warptissue.fem.contact import RigidContact
from warptissue.fem.packing import pack_meshes
from warptissue.indenter import Indenter
from warptissue.materials import MooneyRivlin, NeoHookean, Ogden, Viscoelastic
from warptissue.mesh import block_mesh, to_tet10


def _meshes():
    """Three TET10 blocks of different sizes and places."""
    meshes = []
    for count, side, shift in ((2, 0.01, 0.0), (3, 0.02, 0.05), (2, 0.005, -0.03)):
        grid = np.linspace(0.0, side, count + 1)
        mesh = to_tet10(block_mesh(grid, grid, 0.5 * grid))
        mesh.points[:, 0] += shift
        meshes.append(mesh)
    return meshes


MATERIALS = (
    NeoHookean(100.0, 1e4),
    MooneyRivlin(80.0, 30.0, 5e4),
    Ogden((120.0, -30.0), (5.0, -2.0), 1.8e5),
)


def test_packing_offsets_sets_and_split():
    meshes = _meshes()
    packed = pack_meshes(meshes)
    assert packed.problem_count == 3
    np.testing.assert_array_equal(
        packed.node_offsets, np.cumsum([0] + [m.node_count for m in meshes])
    )
    assert packed.mesh.tet_count == sum(m.tet_count for m in meshes)
    assert np.bincount(packed.element_problem).tolist() == [m.tet_count for m in meshes]
    assert np.bincount(packed.node_problem).tolist() == [m.node_count for m in meshes]
    for k, mesh in enumerate(meshes):
        np.testing.assert_array_equal(packed.mesh.points[packed.nodes(k)], mesh.points)
        name = sorted(mesh.node_sets)[0]
        np.testing.assert_array_equal(
            packed.mesh.node_set(f"{k}/{name}"), mesh.node_set(name) + packed.node_offsets[k]
        )
    parts = packed.split(packed.mesh.points)
    assert [len(p) for p in parts] == [m.node_count for m in meshes]
    with pytest.raises(InputError, match="rows"):
        packed.split(np.zeros((3, 3)))


def test_packing_refuses_nothing_and_mixed_elements():
    with pytest.raises(InputError, match="at least one"):
        pack_meshes([])
    grid = np.linspace(0.0, 0.01, 3)
    with pytest.raises(InputError, match="one element type"):
        pack_meshes([block_mesh(grid, grid, grid), to_tet10(block_mesh(grid, grid, grid))])


def _tangent(assembler: Assembler, nodes: np.ndarray) -> sp.csr_matrix:
    return assembler.tangent_submatrix(nodes)


def test_packed_problems_assemble_as_each_alone(device, rng):
    """One launch over three packed problems (different meshes and materials) gives each
    problem's residual, tangent, energy and smallest J; no block couples two problems."""
    meshes = _meshes()
    packed = pack_meshes(meshes)
    together = Assembler(
        packed.mesh, MATERIALS, device=device, element_problem=packed.element_problem
    )
    assert together.material is None and together.materials == MATERIALS
    displacements = [1e-4 * rng.standard_normal((m.node_count, 3)) for m in meshes]
    union = np.concatenate(displacements)
    derivative = together.parameter_residual(union, "bulk_modulus_Pa")
    assembly = together.assemble(union)
    residual = assembly.residual.numpy().copy()
    blocks = 0
    for k, (mesh, material, u) in enumerate(zip(meshes, MATERIALS, displacements, strict=True)):
        alone = Assembler(mesh, material, device=device)
        own = alone.assemble(u)
        scale = np.abs(own.residual.numpy()).max()
        np.testing.assert_allclose(
            residual[packed.nodes(k)], own.residual.numpy(), rtol=0, atol=1e-12 * scale
        )
        own_derivative = alone.parameter_residual(u, "bulk_modulus_Pa")
        np.testing.assert_allclose(
            derivative[packed.nodes(k)],
            own_derivative,
            rtol=0,
            atol=1e-12 * np.abs(own_derivative).max(),
        )
        own = alone.assemble(u)
        assert assembly.problem_energies_J[k] == pytest.approx(own.energy_J, rel=1e-12)
        assert assembly.problem_min_jacobians[k] == pytest.approx(own.min_jacobian, rel=1e-14)
        nodes = np.arange(packed.node_offsets[k], packed.node_offsets[k + 1])
        mine = _tangent(together, nodes).toarray()
        reference = _tangent(alone, np.arange(mesh.node_count)).toarray()
        np.testing.assert_allclose(mine, reference, rtol=0, atol=1e-12 * np.abs(reference).max())
        blocks += alone.matrix.nnz
        stress = together.cauchy_stress(np.concatenate(displacements))
        tets = slice(int(packed.tet_offsets[k]), int(packed.tet_offsets[k + 1]))
        np.testing.assert_allclose(
            stress[tets],
            alone.cauchy_stress(u),
            rtol=1e-12,
            atol=1e-12 * material.initial_shear_modulus_Pa,
        )
    assert together.matrix.nnz == blocks  # block diagonal: no pair of nodes across problems
    assert assembly.energy_J == pytest.approx(assembly.problem_energies_J.sum(), rel=1e-15)
    assert assembly.min_jacobian == assembly.problem_min_jacobians.min()


def test_one_problem_reports_its_energy_as_the_only_entry(device, rng):
    mesh = _meshes()[0]
    assembly = Assembler(mesh, MATERIALS[0], device=device).assemble(
        1e-4 * rng.standard_normal((mesh.node_count, 3))
    )
    assert assembly.problem_energies_J.tolist() == [assembly.energy_J]
    assert assembly.problem_min_jacobians.tolist() == [assembly.min_jacobian]


def test_packed_assemblers_refuse_what_they_cannot_do():
    meshes = _meshes()
    packed = pack_meshes(meshes)
    problems = packed.element_problem
    with pytest.raises(InputError, match="need element_problem"):
        Assembler(packed.mesh, MATERIALS, device="cpu")
    with pytest.raises(InputError, match=r"\[0, 3\)"):
        Assembler(packed.mesh, MATERIALS, device="cpu", element_problem=problems + 1)
    with pytest.raises(InputError, match="one integer per tet"):
        Assembler(packed.mesh, MATERIALS, device="cpu", element_problem=problems[:-1])
    with pytest.raises(InputError, match=r"\[0, 2\)"):  # two materials for three problems
        Assembler(packed.mesh, MATERIALS[:2], device="cpu", element_problem=problems)
    # A viscoelastic material among elastic ones: one history, its terms per problem.
    viscous = Viscoelastic(MATERIALS[0], (0.3,), (1.0,))
    mixed = Assembler(
        packed.mesh, (viscous, *MATERIALS[1:]), device="cpu", element_problem=problems
    )
    assert mixed.viscous is not None and mixed.viscous.term_counts() == (1, 0, 0)
    together = Assembler(packed.mesh, MATERIALS, device="cpu", element_problem=problems)
    with pytest.raises(InputError, match="one material per packed problem"):
        together.set_material(MATERIALS[:2])
    ogden = Assembler(packed.mesh, (MATERIALS[2],) * 3, device="cpu", element_problem=problems)
    with pytest.raises(InputError, match="Ogden exponent"):
        ogden.parameter_residual(np.zeros((packed.mesh.node_count, 3)), "alpha1")
    contact = RigidContact(
        Indenter("sphere", radius_m=1e-3), nodes=np.arange(3), top_z_m=0.0, stiffness_N_per_m=1.0
    )
    with pytest.raises(InputError, match=r"one contact \(or None\) per packed problem: 3"):
        together.set_contact(contact)
