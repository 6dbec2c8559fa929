"""Device gathers and scatters: selected 3x3 blocks of a BSR tangent, and nodal vectors by
index, launched on the arrays' own device (``kernels/sparse.py``). The assembler gathers the
blocks and forces of a patch of nodes with them; the nonlinear elimination scatters a
patch's solution back into the whole state.
"""

from __future__ import annotations

import warp as wp
import warp.sparse as wps

from warptissue.kernels import sparse as ks

__all__ = ["gather_bsr_blocks", "gather_vectors", "scatter_vectors"]


def gather_bsr_blocks(matrix: wps.BsrMatrix, block_ids: wp.array, gathered: wp.array) -> None:
    """Copy selected 3x3 blocks of a BSR matrix into ``gathered``, in place.

    Args:
        matrix: 3x3-block float64 BSR matrix.
        block_ids: Indices into the matrix's blocks, (k,) int32 on the matrix's device.
        gathered: Output, (k,) mat33d on the matrix's device.
    """
    if block_ids.shape[0] == 0:
        return
    if gathered.shape[0] != block_ids.shape[0]:
        raise ValueError(
            f"gathered holds {gathered.shape[0]} blocks, block_ids asks for {block_ids.shape[0]}"
        )
    wp.launch(
        ks.gather_blocks_kernel,
        dim=block_ids.shape[0],
        inputs=[matrix.values, block_ids],
        outputs=[gathered],
        device=matrix.device,
    )


def gather_vectors(values: wp.array, indices: wp.array, gathered: wp.array) -> None:
    """``gathered[i] = values[indices[i]]`` for vec3d arrays on one device, in place.

    Args:
        values: (N,) vec3d.
        indices: (k,) int32, each in [0, N).
        gathered: Output, (k,) vec3d.
    """
    if indices.shape[0] == 0:
        return
    wp.launch(
        ks.gather_vectors_kernel,
        dim=indices.shape[0],
        inputs=[values, indices],
        outputs=[gathered],
        device=values.device,
    )


def scatter_vectors(values: wp.array, indices: wp.array, target: wp.array) -> None:
    """``target[indices[i]] = values[i]`` for vec3d arrays on one device, in place.

    Args:
        values: (k,) vec3d.
        indices: (k,) int32, distinct, each in [0, N).
        target: (N,) vec3d, changed at ``indices`` only.
    """
    if indices.shape[0] == 0:
        return
    wp.launch(
        ks.scatter_vectors_kernel,
        dim=indices.shape[0],
        inputs=[values, indices],
        outputs=[target],
        device=target.device,
    )
