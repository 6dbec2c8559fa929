"""Sparse-format kernels: a 3x3-block BSR matrix as a scalar CSR matrix (float64).

Row ``3 r + i`` of the CSR matrix holds row ``i`` of every block of block row ``r``, in the
blocks' column order, so column indices stay sorted within each row when the block columns
are. With ``start = offsets[r]`` and ``count = offsets[r + 1] - start``, entry ``(i, k)`` of
block ``start + s`` lands at CSR position ``9 start + 3 count i + 3 s + k``; row ``3 r + i``
starts at ``9 start + 3 count i``.

Also: copying selected blocks of a BSR matrix out (a submatrix's values), and selected
entries of a vec3d array out or in (a patch of nodes).
"""

import warp as wp

wp.set_module_options({"enable_backward": False})


@wp.kernel
def bsr33_csr_pattern_kernel(
    block_offsets: wp.array(dtype=wp.int32),
    block_columns: wp.array(dtype=wp.int32),
    csr_offsets: wp.array(dtype=wp.int32),
    csr_columns: wp.array(dtype=wp.int32),
    block_rows: wp.array(dtype=wp.int32),
):
    """One thread per block row: CSR row offsets (3 rows), column indices, each block's row.

    ``csr_offsets`` has 3 n + 1 entries; the last one is written by the thread of row n - 1.
    """
    r = wp.tid()
    start = block_offsets[r]
    count = block_offsets[r + 1] - start
    for i in range(3):
        csr_offsets[3 * r + i] = 9 * start + 3 * count * i
    if r == block_offsets.shape[0] - 2:
        csr_offsets[3 * r + 3] = 9 * block_offsets[r + 1]
    for s in range(count):
        col = block_columns[start + s]
        block_rows[start + s] = r
        for i in range(3):
            for k in range(3):
                csr_columns[9 * start + 3 * count * i + 3 * s + k] = 3 * col + k


@wp.kernel
def bsr33_csr_values_kernel(
    block_offsets: wp.array(dtype=wp.int32),
    block_rows: wp.array(dtype=wp.int32),
    block_values: wp.array(dtype=wp.mat33d),
    csr_values: wp.array(dtype=wp.float64),
):
    """One thread per block: copy its nine values to their CSR positions."""
    b = wp.tid()
    r = block_rows[b]
    start = block_offsets[r]
    count = block_offsets[r + 1] - start
    s = b - start
    block = block_values[b]
    for i in range(3):
        for k in range(3):
            csr_values[9 * start + 3 * count * i + 3 * s + k] = block[i, k]


@wp.kernel
def gather_blocks_kernel(
    block_values: wp.array(dtype=wp.mat33d),
    block_ids: wp.array(dtype=wp.int32),
    gathered: wp.array(dtype=wp.mat33d),
):
    """One thread per requested block: ``gathered[i] = block_values[block_ids[i]]``."""
    i = wp.tid()
    gathered[i] = block_values[block_ids[i]]


@wp.kernel
def gather_vectors_kernel(
    values: wp.array(dtype=wp.vec3d),
    indices: wp.array(dtype=wp.int32),
    gathered: wp.array(dtype=wp.vec3d),
):
    """One thread per requested entry: ``gathered[i] = values[indices[i]]``."""
    i = wp.tid()
    gathered[i] = values[indices[i]]


@wp.kernel
def scatter_vectors_kernel(
    values: wp.array(dtype=wp.vec3d),
    indices: wp.array(dtype=wp.int32),
    target: wp.array(dtype=wp.vec3d),
):
    """One thread per entry: ``target[indices[i]] = values[i]`` (indices distinct)."""
    i = wp.tid()
    target[indices[i]] = values[i]


@wp.kernel
def blocks_to_dense_kernel(
    block_values: wp.array(dtype=wp.mat33d),
    block_ids: wp.array(dtype=wp.int32),
    rows: wp.array(dtype=wp.int32),
    columns: wp.array(dtype=wp.int32),
    dense: wp.array2d(dtype=wp.float64),
):
    """One thread per block: write block ``block_ids[i]`` at block row ``rows[i]`` and block
    column ``columns[i]`` of the dense matrix."""
    i = wp.tid()
    block = block_values[block_ids[i]]
    for a in range(3):
        for b in range(3):
            dense[3 * rows[i] + a, 3 * columns[i] + b] = block[a, b]
