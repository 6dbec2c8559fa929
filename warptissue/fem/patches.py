"""Assembly on patches of nodes, for the nonlinear elimination's local solves: a node's
patch (it and its neighbours), the tets that hold some nodes and their forces and energy alone,
and the tangent among some nodes, as sparse or dense matrices.

:class:`PatchAssembly` is a part of :class:`warptissue.fem.assembly.Assembler` (its base
class): it uses the assembler's mesh arrays, sparsity pattern and element launch.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse
import warp as wp

from warptissue.errors import InputError
from warptissue.fem.gather import gather_bsr_blocks, gather_vectors
from warptissue.fem.sparsity import block_ranges
from warptissue.kernels import assembly as ka
from warptissue.kernels import sparse as ks

__all__ = ["ElementPart", "PatchAssembly"]


@dataclass(frozen=True)
class ElementPart:
    """Some tets of a mesh and their nodes, on the assembler's device
    (:meth:`Assembler.element_part`, :meth:`Assembler.assemble_part`).

    Attributes:
        elements: Tet indices, sorted, (T,) int32 Warp array.
        nodes: The nodes of those tets, sorted, (R,) int64 NumPy array.
        device_nodes: ``nodes`` as an int32 Warp array.
        forces: The part's nodal forces of the last :meth:`Assembler.assemble_part`, (R,)
            vec3d Warp array (its buffer).
        problems: The packed problems its tets belong to, sorted, (q,) int64 (``[0]`` for an
            assembler of one problem).
    """

    elements: wp.array
    nodes: np.ndarray
    device_nodes: wp.array
    forces: wp.array
    problems: np.ndarray


@dataclass(frozen=True)
class _SubmatrixBlocks:
    """The tangent's blocks among some nodes: for block i, its index ``blocks[i]`` in the
    BSR values, its local row ``rows[i]`` and column ``columns[i]`` (positions in ``nodes``),
    on the host and as int32 Warp arrays on the assembler's device."""

    nodes: np.ndarray
    rows: np.ndarray
    blocks: np.ndarray
    columns: np.ndarray
    device_rows: wp.array
    device_blocks: wp.array
    device_columns: wp.array


class PatchAssembly:
    """The patch methods of :class:`warptissue.fem.assembly.Assembler` (its base class)."""

    def _init_patches(self) -> None:
        """The patch buffers (after the assembler's mesh arrays and problems are set)."""
        count = self.problem_count
        self._node_elements: tuple[np.ndarray, np.ndarray] | None = None
        self._part_residual = wp.zeros(self.node_count, dtype=wp.vec3d, device=self.device)
        self._part_scalars = wp.zeros(2 * count, dtype=wp.float64, device=self.device)
        self._part_force = wp.zeros(count, dtype=wp.vec3d, device=self.device)
        self._tets_host: np.ndarray | None = None
        self._last_submatrix: _SubmatrixBlocks | None = None

    def node_patch(self, nodes: np.ndarray) -> np.ndarray:
        """The given nodes and every node sharing a tet with one of them.

        Args:
            nodes: Node indices, (k,).

        Returns:
            Sorted unique node indices, (P,) int64.

        Raises:
            InputError: A node index is out of range.
        """
        nodes = self._node_indices(nodes)
        neighbours = self._pattern_columns[block_ranges(self._pattern_offsets, nodes)]
        return np.union1d(nodes, neighbours)

    def element_part(
        self, *, nodes: np.ndarray | None = None, elements: np.ndarray | None = None
    ) -> ElementPart:
        """A part of the mesh for :meth:`assemble_part`: the tets that hold at least one of
        ``nodes``, or the tets ``elements``; with their nodes.

        Args:
            nodes: Node indices, (k,).
            elements: Tet indices, (T,) (instead of ``nodes``).

        Returns:
            An :class:`ElementPart`.

        Raises:
            InputError: Neither or both given, or an index out of range.
        """
        if (nodes is None) == (elements is None):
            raise InputError("give the part's nodes or its elements, not both")
        if elements is None:
            nodes = self._node_indices(nodes)
            if self._node_elements is None:  # node -> tets, built once
                tets = self._tets.numpy()
                owners = np.repeat(np.arange(self.tet_count, dtype=np.int32), tets.shape[1])
                order = np.argsort(tets.reshape(-1), kind="stable")
                offsets = np.zeros(self.node_count + 1, dtype=np.int64)
                np.cumsum(np.bincount(tets.reshape(-1), minlength=self.node_count), out=offsets[1:])
                self._node_elements = (offsets, owners[order])
            offsets, owners = self._node_elements
            elements = np.unique(owners[block_ranges(offsets, nodes)])
        else:
            elements = np.unique(np.asarray(elements, dtype=np.int64).reshape(-1))
            if elements.size and (elements[0] < 0 or elements[-1] >= self.tet_count):
                raise InputError(
                    f"element indices must lie in [0, {self.tet_count})", key="elements"
                )
        if self._tets_host is None:
            self._tets_host = self._tets.numpy()
        part_nodes = np.unique(self._tets_host[elements])
        return ElementPart(
            elements=wp.array(elements.astype(np.int32), dtype=wp.int32, device=self.device),
            nodes=part_nodes.astype(np.int64),
            device_nodes=wp.array(part_nodes.astype(np.int32), dtype=wp.int32, device=self.device),
            forces=wp.zeros(len(part_nodes), dtype=wp.vec3d, device=self.device),
            problems=np.unique(self._element_problem_host[elements]).astype(np.int64),
        )

    def assemble_part(
        self,
        displacement_m: np.ndarray | wp.array,
        part: ElementPart,
        *,
        with_tangent: bool = False,
    ) -> tuple[np.ndarray, float, float]:
        """The internal forces and energy of some tets alone (and of the rigid contact).

        For a local solve on a patch of nodes (the nonlinear elimination): where only the
        patch's nodes move, only the tets that hold them change their forces and energy, so
        the whole residual follows from the last one plus the change of this part, at the
        part's nodes. The rigid contacts, where there are any, are evaluated at every
        candidate node (its unchanged nodes cancel in that difference; the forces returned
        hold their share at the part's nodes).

        Args:
            displacement_m: Nodal displacements, (N, 3), m (NumPy or a vec3d Warp array).
            part: The tets and their nodes (:meth:`element_part`).
            with_tangent: Also assemble their tangent: every block that these tets add to is
                zeroed first, so a block of two nodes whose tets all lie in the part (two
                nodes of the patch the part was made for) is exact afterwards, and the
                others are not: the assembler's matrix must be assembled again
                (:meth:`assemble`) before it is used as a whole.

        Returns:
            (forces of these tets and of the contact at ``part.nodes``, (R, 3), N; their
            energy with the contact's at every candidate node of their problems
            (``part.problems``), J; the smallest det F over their quadrature points).
        """
        u = self.device_displacement(displacement_m)
        self._part_residual.zero_()
        scalars = self._part_scalars
        scalars.zero_()
        count = self.problem_count
        energy, min_jacobian = scalars[:count], scalars[count:]
        min_jacobian.fill_(np.inf)
        if with_tangent:
            wp.launch(
                ka.zero_element_blocks_kernel,
                dim=(part.elements.shape[0], self.nodes_per_tet**2),
                inputs=[part.elements, self._block_index],
                outputs=[self.matrix.values],
                device=self.device,
            )
        self._launch_elements(
            u,
            part.elements,
            with_tangent=with_tangent,
            residual=self._part_residual,
            energy=energy,
            min_jacobian=min_jacobian,
            contact_force=self._part_force,
        )
        gather_vectors(self._part_residual, part.device_nodes, part.forces)
        values = scalars.numpy()
        return (
            part.forces.numpy().copy(),
            float(values[:count][part.problems].sum()),
            float(values[count:].min()),
        )

    def set_residual(self, residual_N: Any) -> wp.array:
        """Overwrite the assembler's residual buffer (the one :meth:`assemble` returns), e.g.
        with a residual updated from a part (:meth:`assemble_part`).

        Args:
            residual_N: (N, 3), N: NumPy, or an array on the assembler's CUDA device (CuPy;
                copied on the device).

        Returns:
            The buffer, a vec3d Warp array (N,).
        """
        self._residual.assign(self._vec3_array(residual_N, "residual"))
        return self._residual

    def _submatrix_blocks(self, nodes: np.ndarray) -> _SubmatrixBlocks:
        """The tangent's blocks among ``nodes`` (sorted and unique, checked); the last
        patch's are kept, since the nonlinear elimination asks for the same patch at each
        of its local iterations."""
        nodes = self._node_indices(nodes)
        last = self._last_submatrix
        if last is not None and np.array_equal(last.nodes, nodes):
            return last
        if np.any(np.diff(nodes) <= 0):
            raise InputError("nodes must be sorted and unique", value=nodes.tolist()[:20])
        local = np.full(self.node_count, -1, dtype=np.int64)
        local[nodes] = np.arange(len(nodes))
        counts = self._pattern_offsets[nodes + 1] - self._pattern_offsets[nodes]
        rows = np.repeat(np.arange(len(nodes)), counts)
        blocks = block_ranges(self._pattern_offsets, nodes)
        columns = local[self._pattern_columns[blocks]]
        inside = columns >= 0
        rows, blocks, columns = rows[inside], blocks[inside], columns[inside]

        def device(values: np.ndarray) -> wp.array:
            return wp.array(values.astype(np.int32), dtype=wp.int32, device=self.device)

        self._last_submatrix = _SubmatrixBlocks(
            nodes=nodes.copy(),
            rows=rows,
            blocks=blocks,
            columns=columns,
            device_rows=device(rows),
            device_blocks=device(blocks),
            device_columns=device(columns),
        )
        return self._last_submatrix

    def tangent_submatrix_dense(self, nodes: np.ndarray) -> wp.array:
        """The last assembled tangent restricted to ``nodes``, as a dense matrix on the
        assembler's device (for a small patch's solve there, without a copy to the host).

        Args:
            nodes: Sorted unique node indices, (P,).

        Returns:
            float64 Warp array (3P, 3P), N/m; dof ``3 i + c`` is component c of ``nodes[i]``.

        Raises:
            InputError: A node index is out of range, or the indices are not sorted and unique.
        """
        part = self._submatrix_blocks(nodes)
        size = 3 * len(part.nodes)
        dense = wp.zeros((size, size), dtype=wp.float64, device=self.device)
        if len(part.blocks):
            wp.launch(
                ks.blocks_to_dense_kernel,
                dim=len(part.blocks),
                inputs=[
                    self.matrix.values,
                    part.device_blocks,
                    part.device_rows,
                    part.device_columns,
                ],
                outputs=[dense],
                device=self.device,
            )
        return dense

    def tangent_submatrix(self, nodes: np.ndarray) -> scipy.sparse.csr_matrix:
        """The last assembled tangent restricted to the rows and columns of ``nodes``.

        Only the needed blocks leave the device.

        Args:
            nodes: Sorted unique node indices, (P,).

        Returns:
            Scalar CSR matrix (3P, 3P), N/m; dof ``3 i + c`` is component c of ``nodes[i]``.

        Raises:
            InputError: A node index is out of range, or the indices are not sorted and unique.
        """
        part = self._submatrix_blocks(nodes)
        rows, columns, size = part.rows, part.columns, 3 * len(part.nodes)
        gathered = wp.empty(len(part.blocks), dtype=wp.mat33d, device=self.device)
        gather_bsr_blocks(self.matrix, part.device_blocks, gathered)
        component = np.arange(3)
        row_dofs = 3 * rows[:, None, None] + component[None, :, None]
        column_dofs = 3 * columns[:, None, None] + component[None, None, :]
        shape = (len(part.blocks), 3, 3)
        return scipy.sparse.csr_matrix(
            (
                gathered.numpy().reshape(-1),
                (
                    np.broadcast_to(row_dofs, shape).reshape(-1),
                    np.broadcast_to(column_dofs, shape).reshape(-1),
                ),
            ),
            shape=(size, size),
        )

    def _node_indices(self, nodes: np.ndarray) -> np.ndarray:
        nodes = np.asarray(nodes, dtype=np.int64).reshape(-1)
        outside = (nodes < 0) | (nodes >= self.node_count)
        if np.any(outside):
            raise InputError(
                f"node indices must lie in [0, {self.node_count})",
                value=nodes[outside][:20].tolist(),
            )
        return nodes
