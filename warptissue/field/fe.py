"""Linear tetrahedral FE with per-group substitution parameters (Tong et al., Eq. 2-4).

The element matrices V B^T G B and V B^T H B do not depend on the parameters, so they are
computed once by a Warp kernel; the stiffness for any (alpha, nu) is then a cheap
combination, and the nodal forces K u are linear in alpha and in alpha nu.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
import warp as wp

from warptissue.device import resolve_device
from warptissue.errors import InputError, MeshError
from warptissue.kernels import linear_elastic as kernels
from warptissue.mesh import TetMesh

__all__ = [
    "ElementBasis",
    "LinearTetModel",
    "LinearSolution",
    "alpha_from_youngs",
    "combine_element_stiffness",
    "element_basis_forces",
    "element_basis_matrices",
    "youngs_from_alpha",
]


def alpha_from_youngs(youngs_modulus_Pa: np.ndarray, nu: np.ndarray) -> np.ndarray:
    """Substitution parameter alpha = E / ((1 + nu)(1 - 2 nu)) in Pa (Tong et al., Eq. 2)."""
    nu = np.asarray(nu, dtype=np.float64)
    return np.asarray(youngs_modulus_Pa, dtype=np.float64) / ((1.0 + nu) * (1.0 - 2.0 * nu))


def youngs_from_alpha(alpha_Pa: np.ndarray, nu: np.ndarray) -> np.ndarray:
    """Young's modulus E = alpha (1 + nu)(1 - 2 nu) in Pa, the inverse of alpha_from_youngs."""
    nu = np.asarray(nu, dtype=np.float64)
    return np.asarray(alpha_Pa, dtype=np.float64) * (1.0 + nu) * (1.0 - 2.0 * nu)


@dataclass(frozen=True)
class ElementBasis:
    """Parameter-free element matrices of a TET4 mesh, on a Warp device.

    Attributes:
        stiffness_g: V B^T G B per tet, shape (tet_count, 12, 12), metres.
        stiffness_h: V B^T H B per tet, shape (tet_count, 12, 12), metres.
        volume_m3: Tet volumes, shape (tet_count,), m^3.
    """

    stiffness_g: wp.array
    stiffness_h: wp.array
    volume_m3: wp.array


def element_basis_matrices(mesh: TetMesh, *, device: str | None = None) -> ElementBasis:
    """Compute V B^T G B and V B^T H B for every tet (kernel ``element_basis_matrices``).

    Args:
        mesh: A TET4 mesh with positively oriented tets.
        device: Warp device.

    Returns:
        The element matrices, on ``device``.

    Raises:
        MeshError: The mesh is not TET4, or a tet has non-positive volume.
    """
    if mesh.nodes_per_tet != 4:
        raise MeshError(f"linear field estimation needs TET4, got {mesh.element_type}")
    target = resolve_device(device)
    count = mesh.tet_count
    stiffness_g = wp.zeros((count, 12, 12), dtype=wp.float64, device=target)
    stiffness_h = wp.zeros((count, 12, 12), dtype=wp.float64, device=target)
    volume = wp.zeros(count, dtype=wp.float64, device=target)
    if count == 0:
        return ElementBasis(stiffness_g, stiffness_h, volume)
    wp.launch(
        kernels.element_basis_matrices,
        dim=count,
        inputs=[
            wp.array(mesh.points, dtype=wp.vec3d, device=target),
            wp.array(mesh.tets, dtype=wp.int32, device=target),
        ],
        outputs=[stiffness_g, stiffness_h, volume],
        device=target,
    )
    volumes = volume.numpy()
    if np.any(volumes <= 0.0):
        bad = int(np.flatnonzero(volumes <= 0.0)[0])
        raise MeshError(f"tet {bad} has non-positive volume {volumes[bad]:.3e} m^3", element=bad)
    return ElementBasis(stiffness_g, stiffness_h, volume)


def combine_element_stiffness(
    basis: ElementBasis,
    tet_group: wp.array,
    alpha_Pa: np.ndarray,
    nu: np.ndarray,
    *,
    device: str | None = None,
) -> np.ndarray:
    """Element stiffness alpha_g (V B^T G B + nu_g V B^T H B) (kernel
    ``combine_element_stiffness``).

    Args:
        basis: Element matrices from :func:`element_basis_matrices`.
        tet_group: Group index of each tet, shape (tet_count,), int32, on ``device``.
        alpha_Pa: alpha per group, shape (group_count,), Pa.
        nu: Poisson's ratio per group, shape (group_count,).
        device: Warp device (that of ``basis``).

    Returns:
        Element stiffness matrices, shape (tet_count, 12, 12), N/m.

    Notes:
        Tong et al.'s Eq. 4 as printed reads K^e = alpha V B^T G B + nu V B^T H B; from Eq. 2 the
        second term is alpha nu V B^T H B, which is what is assembled here.
    """
    target = resolve_device(device)
    count = basis.stiffness_g.shape[0]
    stiffness = wp.zeros((count, 12, 12), dtype=wp.float64, device=target)
    if count == 0:
        return stiffness.numpy()
    parameters = kernels.GroupParameters()
    parameters.alpha_Pa = wp.array(
        np.asarray(alpha_Pa, np.float64), dtype=wp.float64, device=target
    )
    parameters.nu = wp.array(np.asarray(nu, np.float64), dtype=wp.float64, device=target)
    wp.launch(
        kernels.combine_element_stiffness,
        dim=(count, 12, 12),
        inputs=[basis.stiffness_g, basis.stiffness_h, tet_group, parameters],
        outputs=[stiffness],
        device=target,
    )
    return stiffness.numpy()


def element_basis_forces(
    basis: ElementBasis,
    tets: wp.array,
    displacement_m: np.ndarray,
    *,
    device: str | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Element forces per unit alpha, (V B^T G B) u^e and (V B^T H B) u^e (kernel
    ``element_basis_forces``).

    Args:
        basis: Element matrices from :func:`element_basis_matrices`.
        tets: Connectivity, shape (tet_count, 4), int32, on ``device``.
        displacement_m: Nodal displacements, shape (node_count, 3), metres.
        device: Warp device (that of ``basis``).

    Returns:
        Two arrays of shape (tet_count, 12), N/Pa.
    """
    target = resolve_device(device)
    count = basis.stiffness_g.shape[0]
    force_g = wp.zeros((count, 12), dtype=wp.float64, device=target)
    force_h = wp.zeros((count, 12), dtype=wp.float64, device=target)
    if count == 0:
        return force_g.numpy(), force_h.numpy()
    wp.launch(
        kernels.element_basis_forces,
        dim=(count, 12),
        inputs=[
            basis.stiffness_g,
            basis.stiffness_h,
            tets,
            wp.array(np.asarray(displacement_m, np.float64), dtype=wp.vec3d, device=target),
        ],
        outputs=[force_g, force_h],
        device=target,
    )
    return force_g.numpy(), force_h.numpy()


@dataclass(frozen=True)
class LinearSolution:
    """A static linear solve K u = f with some degrees of freedom held at zero.

    Attributes:
        displacement_m: Nodal displacements, shape (node_count, 3), metres.
        free_dofs: Indices of the unconstrained degrees of freedom (node * 3 + axis).
        factor: Sparse LU factorization of the free-free stiffness block (for sensitivities).
    """

    displacement_m: np.ndarray
    free_dofs: np.ndarray
    factor: spla.SuperLU

    def solve_free(self, rhs: np.ndarray) -> np.ndarray:
        """Solve K_ff x = rhs for right-hand sides on the free dofs, shape (free,) or (free, k)."""
        return self.factor.solve(np.asarray(rhs, dtype=np.float64))


class LinearTetModel:
    """Linear elastic TET4 model whose tets are grouped, each group with its own (alpha, nu).

    Args:
        mesh: TET4 mesh, metres.
        tet_group: Group of each tet, shape (tet_count,), values 0..group_count-1. Defaults to
            ``mesh.tet_regions`` (the hexahedron index for ``block_mesh(..., split="five")``).
        device: Warp device for the element kernels.

    Notes:
        D = alpha (G + nu H), alpha = E / ((1 + nu)(1 - 2 nu)) (Tong et al., Eq. 2),
        K = sum_g alpha_g (sum_{e in g} V B^T G B + nu_g V B^T H B) (Eq. 3-4 with the ERRATA).
    """

    def __init__(
        self, mesh: TetMesh, *, tet_group: np.ndarray | None = None, device: str | None = None
    ) -> None:
        self.mesh = mesh
        self.device = resolve_device(device)
        group = mesh.tet_regions if tet_group is None else np.asarray(tet_group)
        if group.shape != (mesh.tet_count,) or (group.size and group.min() < 0):
            raise InputError(
                f"tet_group must hold one non-negative group per tet ({mesh.tet_count}), "
                f"got shape {group.shape}"
            )
        self.tet_group = group.astype(np.int32)
        self.group_count = int(group.max()) + 1 if group.size else 0
        self.basis = element_basis_matrices(mesh, device=self.device)
        self._group_wp = wp.array(self.tet_group, dtype=wp.int32, device=self.device)
        self._tets_wp = wp.array(mesh.tets, dtype=wp.int32, device=self.device)
        element_dofs = (3 * mesh.tets[:, :, None] + np.arange(3)).reshape(-1, 12)
        self.element_dofs = element_dofs
        self._rows = np.repeat(element_dofs, 12, axis=1).ravel()
        self._cols = np.tile(element_dofs, (1, 12)).ravel()
        self.dof_count = 3 * mesh.node_count

    @property
    def volume_m3(self) -> np.ndarray:
        """Tet volumes, shape (tet_count,), m^3."""
        return self.basis.volume_m3.numpy()

    def _check_parameters(self, alpha_Pa: np.ndarray, nu: np.ndarray) -> None:
        alpha_Pa, nu = np.asarray(alpha_Pa), np.asarray(nu)
        if alpha_Pa.shape != (self.group_count,) or nu.shape != (self.group_count,):
            raise InputError(
                f"alpha and nu need shape ({self.group_count},), got {alpha_Pa.shape}, {nu.shape}"
            )

    def stiffness(self, alpha_Pa: np.ndarray, nu: np.ndarray) -> sp.csr_matrix:
        """Global stiffness K(alpha, nu), shape (3 N, 3 N), N/m, as scipy CSR."""
        self._check_parameters(alpha_Pa, nu)
        values = combine_element_stiffness(
            self.basis, self._group_wp, alpha_Pa, nu, device=self.device
        )
        shape = (self.dof_count, self.dof_count)
        return sp.csr_matrix((values.ravel(), (self._rows, self._cols)), shape=shape)

    def group_forces(self, displacement_m: np.ndarray) -> tuple[sp.csr_matrix, sp.csr_matrix]:
        """Nodal forces per unit parameter of each group, for a displacement field.

        Returns ``(FG, FH)``, each of shape (3 N, group_count) in N/Pa, such that
        K(alpha, nu) u = FG @ alpha + FH @ (alpha * nu). Columns are sums over the tets of
        the group of (V B^T G B) u^e and (V B^T H B) u^e.
        """
        displacement_m = np.asarray(displacement_m, dtype=np.float64)
        if displacement_m.shape != (self.mesh.node_count, 3):
            raise InputError(
                f"displacement must have shape ({self.mesh.node_count}, 3), "
                f"got {displacement_m.shape}"
            )
        force_g, force_h = element_basis_forces(
            self.basis, self._tets_wp, displacement_m, device=self.device
        )
        rows = self.element_dofs.ravel()
        cols = np.repeat(self.tet_group, 12)
        shape = (self.dof_count, self.group_count)
        return (
            sp.csr_matrix((force_g.ravel(), (rows, cols)), shape=shape),
            sp.csr_matrix((force_h.ravel(), (rows, cols)), shape=shape),
        )

    def solve(
        self,
        alpha_Pa: np.ndarray,
        nu: np.ndarray,
        force_N: np.ndarray,
        fixed_nodes: np.ndarray,
    ) -> LinearSolution:
        """Solve K u = f with the displacements of ``fixed_nodes`` held at zero.

        Args:
            alpha_Pa: alpha per group, shape (group_count,), Pa.
            nu: Poisson's ratio per group, shape (group_count,).
            force_N: External nodal forces, shape (node_count, 3), newtons.
            fixed_nodes: Nodes with all three components fixed, shape (k,).

        Returns:
            The displacements and the factorized free-free stiffness.

        Raises:
            InputError: The stiffness is singular (too few supports, or nu >= 0.5).
        """
        force_N = np.asarray(force_N, dtype=np.float64)
        if force_N.shape != (self.mesh.node_count, 3):
            raise InputError(
                f"force must have shape ({self.mesh.node_count}, 3), got {force_N.shape}"
            )
        fixed = np.zeros(self.dof_count, dtype=bool)
        fixed[(3 * np.asarray(fixed_nodes)[:, None] + np.arange(3)).ravel()] = True
        free = np.flatnonzero(~fixed)
        stiffness = self.stiffness(alpha_Pa, nu)
        block = stiffness[free][:, free].tocsc()
        try:
            factor = spla.splu(block)
        except RuntimeError as exc:
            raise InputError(f"the stiffness matrix is singular: {exc}") from exc
        displacement = np.zeros(self.dof_count)
        displacement[free] = factor.solve(force_N.ravel()[free])
        return LinearSolution(displacement.reshape(-1, 3), free, factor)
