"""Assembly: residual = gradient of the energy, tangent = derivative of the residual (finite
differences), symmetry, sparsity reuse, stress recovery, and CPU/device agreement."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from warptissue.errors import InputError
from warptissue.fem import Assembler, von_mises
from warptissue.materials import CompressibleNeoHookean, MooneyRivlin, NeoHookean, Ogden
from warptissue.mesh import block_mesh, to_tet10

CASES = [
    (4, "displacement", CompressibleNeoHookean(200.0, 2000.0)),
    (10, "displacement", MooneyRivlin(80.0, 20.0, 5000.0)),
    (10, "mixed", NeoHookean(100.0, 5000.0)),
    (10, "mixed", Ogden((200.0, -30.0), (5.0, -2.0), 5000.0)),
]


def _mesh(npe: int):
    grid = np.linspace(0.0, 1e-2, 3)
    mesh = block_mesh(grid, grid, np.linspace(0.0, 5e-3, 2))
    return to_tet10(mesh) if npe == 10 else mesh


def _dense(assembly, node_count: int) -> np.ndarray:
    matrix = assembly.matrix
    nnz = matrix.nnz_sync()
    return sp.bsr_matrix(
        (matrix.values.numpy()[:nnz], matrix.columns.numpy()[:nnz], matrix.offsets.numpy()),
        shape=(3 * node_count, 3 * node_count),
    ).toarray()


@pytest.mark.parametrize(("npe", "formulation", "material"), CASES)
def test_residual_and_tangent_match_finite_differences(npe, formulation, material, rng):
    mesh = _mesh(npe)
    assembler = Assembler(mesh, material, formulation=formulation, device="cpu")
    u = 2e-4 * rng.standard_normal((mesh.node_count, 3))
    assembly = assembler.assemble(u)
    assert assembly.min_jacobian > 0.3
    residual = assembly.residual.numpy().ravel().copy()
    tangent = _dense(assembly, mesh.node_count)
    dofs = rng.choice(3 * mesh.node_count, size=12, replace=False)
    assert_central_differences(assembler, u, residual, tangent, dofs, step=1e-8, tolerance=1e-6)


def assert_central_differences(assembler, u, residual, tangent, dofs, *, step, tolerance):
    """The residual at ``u`` is the energy's gradient and ``tangent`` the residual's along
    ``dofs`` (central differences of ``step``, to ``tolerance`` of the largest entry), and
    the tangent is symmetric."""
    for dof in dofs:
        plus, minus = u.copy(), u.copy()
        plus.flat[dof] += step
        minus.flat[dof] -= step
        a_plus = assembler.assemble(plus, with_tangent=False)
        e_plus, r_plus = a_plus.energy_J, a_plus.residual.numpy().ravel().copy()
        a_minus = assembler.assemble(minus, with_tangent=False)
        e_minus, r_minus = a_minus.energy_J, a_minus.residual.numpy().ravel().copy()
        assert (e_plus - e_minus) / (2 * step) == pytest.approx(
            residual[dof], abs=1e-6 * np.abs(residual).max()
        )
        np.testing.assert_allclose(
            (r_plus - r_minus) / (2 * step),
            tangent[:, dof],
            rtol=0,
            atol=tolerance * np.abs(tangent).max(),
        )
    np.testing.assert_allclose(tangent, tangent.T, rtol=0, atol=1e-12 * np.abs(tangent).max())


def test_rigid_motion_is_stress_free():
    mesh = _mesh(10)
    assembler = Assembler(mesh, NeoHookean(100.0, 1e5), device="cpu")
    angle = 0.7
    rotation = np.array(
        [[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]]
    )
    u = mesh.points @ rotation.T - mesh.points + 1e-3
    assembly = assembler.assemble(u)
    assert np.abs(assembly.residual.numpy()).max() < 1e-14
    assert abs(assembly.energy_J) < 1e-18
    assert np.abs(assembler.cauchy_stress(u)).max() < 1e-9


def test_cauchy_stress_of_uniaxial_stretch():
    """Homogeneous F = diag(l, t, t): sigma from the element equals the material's P F^T / J."""
    from warptissue.materials import evaluate_material

    material = NeoHookean(100.0, 2000.0)
    stretch, transverse = 1.2, 0.93
    f = np.diag([stretch, transverse, transverse])
    for npe, formulation in ((4, "displacement"), (10, "mixed")):
        mesh = _mesh(npe)
        u = mesh.points @ (f - np.eye(3)).T
        stress = Assembler(mesh, material, formulation=formulation, device="cpu").cauchy_stress(u)
        p = evaluate_material(material, f, device="cpu").first_piola_Pa[0]
        sigma = p @ f.T / np.linalg.det(f)
        expected = np.array([sigma[0, 0], sigma[1, 1], sigma[2, 2], 0.0, 0.0, 0.0])
        np.testing.assert_allclose(stress, np.broadcast_to(expected, stress.shape), atol=1e-9)
        vm = von_mises(stress)
        np.testing.assert_allclose(vm, abs(sigma[0, 0] - sigma[1, 1]), rtol=1e-10)


def test_pattern_is_reused_between_assemblies(rng):
    mesh = _mesh(10)
    assembler = Assembler(mesh, NeoHookean(100.0, 1e4), device="cpu")
    first = assembler.assemble(np.zeros((mesh.node_count, 3))).matrix
    columns = first.columns.numpy().copy()
    second = assembler.assemble(1e-4 * rng.standard_normal((mesh.node_count, 3))).matrix
    assert second is first
    np.testing.assert_array_equal(second.columns.numpy(), columns)


def test_mixed_formulation_requires_tet10():
    with pytest.raises(InputError, match="TET10"):
        Assembler(_mesh(4), NeoHookean(1.0, 10.0), formulation="mixed", device="cpu")
    with pytest.raises(InputError, match="formulation"):
        Assembler(_mesh(10), NeoHookean(1.0, 10.0), formulation="hybrid", device="cpu")


def test_cpu_and_device_agree(device, rng):
    mesh = _mesh(10)
    u = 3e-4 * rng.standard_normal((mesh.node_count, 3))
    material = Ogden((200.0, -30.0), (5.0, -2.0), 5000.0)
    results = []
    for dev in ("cpu", device):
        assembly = Assembler(mesh, material, device=dev).assemble(u)
        results.append(
            (assembly.residual.numpy().copy(), _dense(assembly, mesh.node_count), assembly.energy_J)
        )
    (r0, k0, e0), (r1, k1, e1) = results
    np.testing.assert_allclose(r1, r0, rtol=0, atol=1e-10 * np.abs(r0).max())
    np.testing.assert_allclose(k1, k0, rtol=0, atol=1e-10 * np.abs(k0).max())
    assert e1 == pytest.approx(e0, rel=1e-10)


def test_node_patch_and_tangent_submatrix(device, rng):
    """The patch is the nodes sharing a tet with the seeds (from the mesh's connectivity), and
    the gathered submatrix equals those rows and columns of the whole assembled tangent."""
    mesh = _mesh(10)
    assembler = Assembler(mesh, NeoHookean(100.0, 1e4), device=device)
    assembly = assembler.assemble(3e-4 * rng.standard_normal((mesh.node_count, 3)))
    dense = _dense(assembly, mesh.node_count)
    seeds = np.array([0, 7, mesh.node_count - 1])
    touching = np.any(np.isin(mesh.tets, seeds), axis=1)
    expected = np.unique(np.concatenate([seeds, mesh.tets[touching].ravel()]))
    patch = assembler.node_patch(seeds)
    np.testing.assert_array_equal(patch, expected)
    assert len(patch) < mesh.node_count
    dofs = (3 * patch[:, None] + np.arange(3)).ravel()
    np.testing.assert_array_equal(
        assembler.tangent_submatrix(patch).toarray(), dense[np.ix_(dofs, dofs)]
    )
    with pytest.raises(InputError, match="node indices"):
        assembler.node_patch([mesh.node_count])
    with pytest.raises(InputError, match="sorted and unique"):
        assembler.tangent_submatrix([3, 3])


@pytest.mark.parametrize("damping", [0.0, 0.5])
def test_eliminate_zeroes_prescribed_dofs_and_damps_the_free_diagonal(device, damping, rng):
    """Against the same operations on the dense tangent: rows and columns of prescribed dofs
    zeroed with 1 on the diagonal; each free diagonal entry K_ii -> K_ii + damping |K_ii|;
    every other entry untouched."""
    import warp as wp

    mesh = _mesh(10)
    assembler = Assembler(mesh, NeoHookean(100.0, 1e4), device=device)
    assembly = assembler.assemble(3e-4 * rng.standard_normal((mesh.node_count, 3)))
    tangent = _dense(assembly, mesh.node_count)
    mask = (rng.random((mesh.node_count, 3)) < 0.3).astype(np.float64)
    prescribed = mask.reshape(-1) > 0.5
    expected = tangent.copy()
    free_diagonal = np.flatnonzero(~prescribed)
    expected[free_diagonal, free_diagonal] += damping * np.abs(
        tangent[free_diagonal, free_diagonal]
    )
    expected[prescribed, :] = 0.0
    expected[:, prescribed] = 0.0
    expected[np.flatnonzero(prescribed), np.flatnonzero(prescribed)] = 1.0
    assembler.eliminate(wp.array(mask, dtype=wp.vec3d, device=assembler.device), damping=damping)
    np.testing.assert_array_equal(_dense(assembly, mesh.node_count), expected)


@pytest.mark.parametrize("damping", [-0.1, float("nan")])
def test_eliminate_refuses_a_negative_or_nan_damping(damping):
    import warp as wp

    mesh = _mesh(10)
    assembler = Assembler(mesh, NeoHookean(100.0, 1e4), device="cpu")
    assembler.assemble(np.zeros((mesh.node_count, 3)))
    with pytest.raises(InputError, match="damping"):
        assembler.eliminate(wp.zeros(mesh.node_count, dtype=wp.vec3d), damping=damping)
