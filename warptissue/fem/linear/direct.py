"""Sparse direct solves on the CPU for a fixed 3x3-block BSR sparsity pattern.

The tangent of a mesh keeps its sparsity pattern for the whole load path, so
:class:`CpuDirectSolver` does all pattern work once:

- the scalar CSR index arrays of the matrix (the upper triangle for PARDISO, the full matrix in
  column-compressed order for SuperLU) and the positions of their values among the BSR block
  values, so that every solve only gathers values (one ``np.take``);
- for PARDISO, the fill-reducing ordering and symbolic factorization (phase 11). Each solve
  then runs only the numerical factorization (phase 22) and the triangular solves with
  iterative refinement (phase 33).

PARDISO is driven as a real symmetric indefinite matrix (``mtype = -2``, Bunch-Kaufman
pivoting, upper triangle): the consistent tangent of a hyperelastic energy is symmetric, and
Dirichlet elimination zeroes the rows AND columns of prescribed dofs (unit diagonal), so the
eliminated matrix stays symmetric. It is not declared positive definite: nothing guarantees
that along a load path (the geometric stiffness of compressed states, trial states near
instability; a flat-punch predictor state at 10k TET10 tets has 3 negative eigenvalues), and
the indefinite factorization costs only a few per cent more (README "Performance").
pypardiso's ``spsolve``/``solve`` repeat the analysis whenever the matrix values change, so
the MKL routine that pypardiso loads is called directly, with the phases above.
"""

from __future__ import annotations

import ctypes
import functools
import glob
import os
import sys

import numpy as np
import scipy.sparse as sp
import warp.sparse as wps

from warptissue.errors import DeviceError
from warptissue.fem.timing import PhaseTimer

__all__ = [
    "CPU_DIRECT_METHODS",
    "CpuDirectSolver",
    "bsr33_scalar_pattern",
    "pardiso_available",
    "pardiso_unavailable_reason",
]

CPU_DIRECT_METHODS = ("pardiso", "superlu")

_PARDISO_SYMMETRIC_INDEFINITE = -2


@functools.cache
def _pardiso_routine():
    """MKL's ``pardiso`` routine, loaded once per process (pypardiso searches for the library
    and declares the argument types).

    pypardiso looks for MKL's ``mkl_rt`` under ``sys.prefix`` only. In a virtual environment
    made with ``--system-site-packages`` MKL may lie under the base Python's prefix instead;
    there PARDISO would not load and every CPU solve would fall back to SuperLU, 5 to 10
    times slower (``scripts/examples/hertz_ball.py``: 258 CPU-seconds unfinished against 69).
    Where pypardiso finds no ``mkl_rt`` and no ``PYPARDISO_MKL_RT`` is set, the base
    prefix's is tried (:func:`_base_prefix_mkl_rt`).
    """
    try:
        return _loaded_pardiso()
    except ImportError as exc:
        if isinstance(exc, ModuleNotFoundError) and exc.name == "pypardiso":
            raise  # not installed
        fallback = _base_prefix_mkl_rt()
        if fallback is None or os.environ.get(_MKL_RT_VARIABLE):
            raise
    os.environ[_MKL_RT_VARIABLE] = fallback  # pypardiso reads it; subprocesses inherit it
    return _loaded_pardiso()


def _loaded_pardiso():
    """pypardiso's ``pardiso`` routine. pypardiso makes a solver as it is imported (its
    scipy aliases), so a missing ``mkl_rt`` fails the import itself; Python forgets a module
    whose import failed, and the next import runs it again."""
    from pypardiso import PyPardisoSolver

    return PyPardisoSolver()._mkl_pardiso


_MKL_RT_VARIABLE = "PYPARDISO_MKL_RT"
"""The environment variable in which pypardiso takes the path of MKL's ``mkl_rt``."""


def _base_prefix_mkl_rt() -> str | None:
    """The shortest path of an ``mkl_rt`` library under the base Python's prefix, where this
    is a virtual environment (``sys.prefix != sys.base_prefix``); else None."""
    if sys.prefix == sys.base_prefix:
        return None
    found = sorted(glob.glob(f"{sys.base_prefix}/[Ll]ib*/**/*mkl_rt*", recursive=True), key=len)
    return found[0] if found else None


@functools.cache
def pardiso_unavailable_reason() -> str | None:
    """Why MKL PARDISO cannot be used in this process, in one line, or None where it loads.

    pypardiso may import while Intel MKL's ``mkl_rt`` library is missing or does not load;
    this loads the routine itself.
    """
    try:
        _pardiso_routine()
    except (ImportError, OSError, AttributeError) as exc:
        return f"{type(exc).__name__}: {exc}"
    return None


def pardiso_available() -> bool:
    """Whether pypardiso imports and MKL's PARDISO routine loads."""
    return pardiso_unavailable_reason() is None


def bsr33_scalar_pattern(
    offsets: np.ndarray, columns: np.ndarray, *, upper: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The scalar CSR pattern of a square 3x3-block BSR pattern, with the value permutation.

    Args:
        offsets: Block-row offsets, shape (n + 1,).
        columns: Block columns (sorted within each block row), shape (b,).
        upper: Keep only the upper triangle (column >= row) of the scalar matrix.

    Returns:
        (indptr (3 n + 1,), indices (k,), source (k,)): int32 CSR row pointers and column
        indices (sorted within each row), and int64 positions of each entry in the flattened
        (b, 3, 3) block values, so that ``values.reshape(-1)[source]`` are the CSR values.
    """
    offsets = np.asarray(offsets, dtype=np.int64)
    columns = np.asarray(columns, dtype=np.int64)
    row_count = offsets.shape[0] - 1
    block_count = columns.shape[0]
    block_rows = np.repeat(np.arange(row_count), np.diff(offsets))
    start = offsets[block_rows]
    count = offsets[block_rows + 1] - start
    slot = np.arange(block_count) - start
    # Row 3 r + i holds row i of each block of block row r in block order, then column k:
    # entry (i, k) of block b lands at 9 start + 3 count i + 3 slot + k.
    i, k = np.divmod(np.arange(9), 3)
    position = (
        9 * start[:, None] + 3 * count[:, None] * i[None, :] + 3 * slot[:, None] + k[None, :]
    ).reshape(-1)
    scalar_rows = np.empty(9 * block_count, dtype=np.int64)
    scalar_cols = np.empty(9 * block_count, dtype=np.int64)
    source = np.empty(9 * block_count, dtype=np.int64)
    scalar_rows[position] = (3 * block_rows[:, None] + i[None, :]).reshape(-1)
    scalar_cols[position] = (3 * columns[:, None] + k[None, :]).reshape(-1)
    source[position] = np.arange(9 * block_count, dtype=np.int64)
    if upper:
        keep = scalar_cols >= scalar_rows
        scalar_rows, scalar_cols, source = scalar_rows[keep], scalar_cols[keep], source[keep]
    if scalar_cols.shape[0] >= 2**31:
        raise ValueError(
            f"{scalar_cols.shape[0]} matrix entries exceed the 32-bit indices of the CPU "
            "direct solvers; use a CUDA device for a mesh this large"
        )
    indptr = np.zeros(3 * row_count + 1, dtype=np.int64)
    np.cumsum(np.bincount(scalar_rows, minlength=3 * row_count), out=indptr[1:])
    return indptr.astype(np.int32), scalar_cols.astype(np.int32), source


class CpuDirectSolver:
    """Repeated direct solves of one BSR sparsity pattern on the CPU.

    Args:
        matrix: Square 3x3-block float64 BSR matrix (N x N blocks) on the CPU. Its pattern
            (offsets, columns) must stay fixed; its values may change between solves.
        method: ``"pardiso"`` (MKL PARDISO, symmetric indefinite, analysis reused) or
            ``"superlu"`` (SciPy's SuperLU, full matrix, a fresh factorization per solve).

    Raises:
        DeviceError: ``"pardiso"`` where MKL's PARDISO does not load (see
            :func:`pardiso_unavailable_reason`).

    Attributes:
        analyses: Symbolic analyses (orderings) done so far (PARDISO: 1 per pattern).
        factorizations: Numerical factorizations done so far.
        timer: The :class:`warptissue.fem.timing.PhaseTimer` that its factorizations and
            solves are charged to (a disabled one unless the Newton solver profiles).
    """

    def __init__(self, matrix: wps.BsrMatrix, *, method: str) -> None:
        if method not in CPU_DIRECT_METHODS:
            raise ValueError(f"method must be one of {CPU_DIRECT_METHODS}, got {method!r}")
        if matrix.device.is_cuda:
            raise ValueError(f"CpuDirectSolver needs a CPU matrix; this one is on {matrix.device}")
        self.matrix = matrix
        self.method = method
        self.timer = PhaseTimer(enabled=False)
        self.analyses = 0
        self.factorizations = 0
        self.row_count = 3 * matrix.nrow
        self.block_count = matrix.nnz_sync()
        offsets = matrix.offsets.numpy()[: matrix.nrow + 1]
        columns = matrix.columns.numpy()[: self.block_count]
        indptr, indices, source = bsr33_scalar_pattern(offsets, columns, upper=method == "pardiso")
        self._source = source
        self._data = np.empty(source.shape[0], dtype=np.float64)
        self._x = np.empty(self.row_count, dtype=np.float64)
        if method == "pardiso":
            self._indptr, self._indices = indptr, indices
            self._init_pardiso()
        else:
            # The tangent is symmetric, so the CSR arrays of A are also the CSC arrays of A^T;
            # SuperLU wants CSC, so build the CSC value order of A itself once.
            csc_order = (
                sp.csr_matrix(
                    (np.arange(1, indices.shape[0] + 1, dtype=np.float64), indices, indptr),
                    shape=(self.row_count, self.row_count),
                )
                .tocsc()
                .sorted_indices()
            )
            self._source = source[csc_order.data.astype(np.int64) - 1]
            self._data = np.empty(self._source.shape[0], dtype=np.float64)
            self._csc = sp.csc_matrix(
                (self._data, csc_order.indices, csc_order.indptr),
                shape=(self.row_count, self.row_count),
            )

    def _gather_values(self) -> None:
        values = self.matrix.values.numpy().reshape(-1)
        np.take(values, self._source, out=self._data)

    def _init_pardiso(self) -> None:
        reason = pardiso_unavailable_reason()
        if reason is not None:
            raise DeviceError(
                f"MKL PARDISO could not be loaded ({reason}); install it with "
                "'pip install pypardiso mkl', or use linear_solver = 'superlu'"
            )
        self._pardiso_routine = _pardiso_routine()
        self._handle = np.zeros(64, dtype=np.int64)  # PARDISO's internal pointers
        self._perm = np.zeros(0, dtype=np.int32)
        iparm = np.zeros(64, dtype=np.int32)
        iparm[0] = 1  # these settings, not MKL's defaults
        iparm[1] = 2  # nested-dissection ordering (METIS)
        iparm[7] = 2  # at most 2 iterative refinement steps
        iparm[9] = 8  # pivot perturbation 1e-8 (symmetric indefinite)
        iparm[10] = 0  # no scaling: the ordering is reused across value changes
        iparm[12] = 0  # no weighted matching, for the same reason
        iparm[20] = 1  # Bunch-Kaufman 1x1 and 2x2 pivoting
        iparm[23] = 0  # classic parallel factorization (2 cores)
        iparm[34] = 1  # zero-based indexing: the CSR arrays are passed as they are
        self._iparm = iparm
        self._pardiso(11)
        self.analyses += 1

    def _pardiso(self, phase: int, rhs: np.ndarray | None = None) -> int:
        """Call PARDISO for ``phase``; returns its error code (0 on success)."""
        c_int32_p = ctypes.POINTER(ctypes.c_int32)
        c_double_p = ctypes.POINTER(ctypes.c_double)
        b = self._x if rhs is None else rhs
        error = ctypes.c_int32(0)
        self._pardiso_routine(
            self._handle.ctypes.data_as(ctypes.POINTER(ctypes.c_int64)),
            ctypes.byref(ctypes.c_int32(1)),  # maxfct
            ctypes.byref(ctypes.c_int32(1)),  # mnum
            ctypes.byref(ctypes.c_int32(_PARDISO_SYMMETRIC_INDEFINITE)),
            ctypes.byref(ctypes.c_int32(phase)),
            ctypes.byref(ctypes.c_int32(self.row_count)),
            self._data.ctypes.data_as(c_double_p),
            self._indptr.ctypes.data_as(c_int32_p),
            self._indices.ctypes.data_as(c_int32_p),
            self._perm.ctypes.data_as(c_int32_p),
            ctypes.byref(ctypes.c_int32(1)),  # one right-hand side
            self._iparm.ctypes.data_as(c_int32_p),
            ctypes.byref(ctypes.c_int32(0)),  # no statistics output
            b.ctypes.data_as(c_double_p),
            self._x.ctypes.data_as(c_double_p),
            ctypes.byref(error),
        )
        return int(error.value)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """Factorize the matrix's current values and solve ``matrix x = rhs``.

        Args:
            rhs: Right-hand side, shape (N, 3).

        Returns:
            x, shape (N, 3); all NaN when the factorization or solve failed (e.g. a singular
            matrix), which the Newton solver treats as a failed step.
        """
        b = np.ascontiguousarray(rhs, dtype=np.float64).reshape(-1)
        if b.shape[0] != self.row_count:
            raise ValueError(f"rhs must have {self.row_count} entries, got {b.shape[0]}")
        self._gather_values()
        self.factorizations += 1
        if self.method == "superlu":
            self.analyses += 1
            with self.timer.phase("factorization"):
                try:
                    self._lu = sp.linalg.splu(self._csc)
                except RuntimeError:  # exactly singular
                    self._lu = None
            if self._lu is None:
                return np.full((self.row_count // 3, 3), np.nan)
            with self.timer.phase("solve"):
                return self._lu.solve(b).reshape(-1, 3)
        with self.timer.phase("factorization"):
            self._factorized = self._pardiso(22) == 0
        if not self._factorized:
            return np.full((self.row_count // 3, 3), np.nan)
        return self.solve_factorized(rhs)

    def solve_factorized(self, rhs: np.ndarray, *, refine: bool = True) -> np.ndarray:
        """Solve with the factors of the last :meth:`solve`, without a new factorization.

        The matrix's values may have changed since: this solves with the matrix as it was
        factorized (PARDISO's iterative refinement, too, uses those values).

        Args:
            rhs: Right-hand side, shape (N, 3).
            refine: Let PARDISO refine the solution iteratively (up to 2 steps, against the
                factorized values); False for a preconditioner's solve, where the factorized
                matrix is only an approximation anyway.

        Returns:
            x, shape (N, 3); all NaN when there is no factorization or the solve failed.
        """
        b = np.ascontiguousarray(rhs, dtype=np.float64).reshape(-1)
        if b.shape[0] != self.row_count:
            raise ValueError(f"rhs must have {self.row_count} entries, got {b.shape[0]}")
        failed = np.full((self.row_count // 3, 3), np.nan)
        if self.method == "superlu":
            lu = getattr(self, "_lu", None)
            if lu is None:
                return failed
            with self.timer.phase("solve"):
                return lu.solve(b).reshape(-1, 3)
        if not getattr(self, "_factorized", False):
            return failed
        with self.timer.phase("solve"):
            if refine:
                error = self._pardiso(33, b)
            else:
                self._iparm[7] = 0
                try:
                    error = self._pardiso(33, b)
                finally:
                    self._iparm[7] = 2
        if error != 0:
            return failed
        return self._x.reshape(-1, 3).copy()

    def __del__(self) -> None:
        if getattr(self, "method", None) == "pardiso" and hasattr(self, "_iparm"):
            try:
                self._pardiso(-1)  # release all of PARDISO's memory for this handle
            except ImportError:  # the interpreter is shutting down: the process frees it
                pass
