"""Sparse direct solves on the GPU with NVIDIA cuDSS, through nvmath-python.

The tangent lives in a 3x3-block ``warp.sparse`` BSR matrix whose sparsity pattern is fixed
for a mesh. :class:`CudssSolver` builds a scalar CSR copy of it once on the device (a Warp
kernel, :mod:`warptissue.kernels.sparse`), hands CuPy views of those Warp arrays to
``nvmath.sparse.advanced.DirectSolver`` without copying (``__cuda_array_interface__``), and
runs cuDSS's analysis (fill-reducing reordering and symbolic factorization) once. Each solve
then refreshes the CSR values in place from the BSR blocks, factorizes numerically and
solves; all of it on Warp's stream of the device.

The matrix is declared symmetric, not positive definite (cuDSS's LDL^T with its default
pivoting; only the lower triangle is read): the eliminated consistent tangent of a
hyperelastic energy is symmetric, and a trial state far from equilibrium can make it
indefinite, where a Cholesky factorization would fail.

Where the factors would not fit in the free device memory, the solver switches to cuDSS's
hybrid memory mode (factors in host memory), and refuses with the numbers what fits neither
way, before the first factorization.

Install: ``pip install 'warptissue[gpu]'`` (nvmath-python with NVIDIA cuDSS for CUDA 13, and
CuPy for CUDA 13). The libraries of those wheels are found without ``LD_LIBRARY_PATH``: before
nvmath-python looks for cuDSS, :func:`preload_cudss` finds ``libcudss.so`` in every
``nvidia/*/lib`` folder of the installed wheels (:func:`nvidia_library_dirs`) and loads it,
with the cuBLAS it needs, into the process's global symbol scope (:func:`load_global`), where
nvmath-python looks first. Where cuDSS still does not load, :func:`cudss_available` says why,
once, on the first solve that would have used it (the ``"auto"`` linear solver then runs CG,
often 10-30 times slower).
"""

from __future__ import annotations

import ctypes
import functools
import importlib.util
import os
import re
import site
import sys
import warnings
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import warp as wp
import warp.sparse as wps

from warptissue.device import available_host_memory_bytes
from warptissue.errors import DeviceError
from warptissue.fem.timing import PhaseTimer

__all__ = [
    "CUDSS_INSTALL_HINT",
    "DEVICE_MEMORY_SHARE",
    "MEMORY_ESTIMATE_NAMES",
    "CudssSolver",
    "bsr33_csr_pattern",
    "bsr33_csr_values",
    "check_memory_estimates",
    "cudss_available",
    "cudss_threading_library",
    "cudss_unavailable_reason",
    "find_nvidia_library",
    "load_global",
    "nvidia_library_dirs",
    "preload_cudss",
]

DEVICE_MEMORY_SHARE = 0.9
"""Share of the free device memory that cuDSS may take by default; the rest stays for the
Newton loop's own arrays."""
MEMORY_ESTIMATE_NAMES = (
    "permanent_device_memory_bytes",
    "peak_device_memory_bytes",
    "permanent_host_memory_bytes",
    "peak_host_memory_bytes",
    "hybrid_min_device_memory_bytes",
    "hybrid_max_host_memory_bytes",
)
"""cuDSS's memory estimates after the analysis (``CUDSS_DATA_MEMORY_ESTIMATES``), in its
order. The last is the most host memory the hybrid memory mode may use (nvmath-python names
that field ``hybrid_max_device_memory``; cuDSS documents it as host memory)."""


CUDSS_INSTALL_HINT = "pip install 'warptissue[gpu]'"
"""How to install cuDSS with its Python bindings (nvmath-python, nvidia-cudss-cu13, CuPy)."""


def nvidia_library_dirs(roots: Iterable[str | Path] | None = None) -> list[Path]:
    """Folders of shared libraries that NVIDIA's pip wheels install.

    The wheels put their libraries in ``nvidia/<component>/lib`` under a site-packages folder:
    ``nvidia/cu13/lib`` for the CUDA 13 wheels (cuDSS, cuBLAS, the runtime),
    ``nvidia/cudss/lib`` or ``nvidia/cublas/lib`` for older ones. Every root is searched, not
    only the first ``nvidia`` package Python would import: in a virtual environment beside
    another environment's ``nvidia`` package, the wheels of the one Python imports from may
    sit in the other folder.

    Args:
        roots: Folders to search (site-packages folders). Default: every entry of
            ``sys.path``, the site-packages folders, and the parents of the ``nvidia``
            namespace package's folders.

    Returns:
        Existing ``nvidia/*/lib`` folders, each once, in the roots' order.
    """
    if roots is None:
        roots = [*sys.path, *site.getsitepackages(), site.getusersitepackages()]
        spec = importlib.util.find_spec("nvidia")
        if spec is not None and spec.submodule_search_locations is not None:
            roots += [Path(folder).parent for folder in spec.submodule_search_locations]
    found: dict[Path, None] = {}
    for root in roots:
        for folder in sorted(Path(root or ".").glob("nvidia/*/lib")):
            if folder.is_dir():
                found.setdefault(folder.resolve(), None)
    return list(found)


def find_nvidia_library(name: str, folders: Iterable[Path]) -> Path | None:
    """The shared library ``lib<name>.so`` or ``lib<name>.so.<version>`` in ``folders``.

    Args:
        name: The library's name without ``lib`` and the suffix (``"cudss"``, ``"cublasLt"``).
        folders: Where to look, in order (see :func:`nvidia_library_dirs`).

    Returns:
        The first match (of a folder, the shortest name: the soname rather than the full
        version), or None.
    """
    pattern = re.compile(rf"lib{re.escape(name)}\.so(\.\d+)*")
    for folder in folders:
        matches = [path for path in folder.iterdir() if pattern.fullmatch(path.name)]
        if matches:
            return min(matches, key=lambda path: (len(path.name), path.name))
    return None


_MISSING_LIBRARY = re.compile(r"([^\s:/]+\.so[.\d]*): cannot open shared object file")


def load_global(path: Path, folders: Sequence[Path]) -> list[Path]:
    """Load a shared library into the process's global symbol scope, with the dependencies
    that the dynamic linker cannot find on its own taken from ``folders``.

    A library loaded this way is found by name afterwards without ``LD_LIBRARY_PATH``: by the
    dynamic linker for the libraries that need it, and by nvmath-python, which looks a
    symbol up in the global scope before it searches for the library itself.

    Args:
        path: The library.
        folders: Where to find its dependencies (see :func:`nvidia_library_dirs`).

    Returns:
        The libraries loaded, dependencies first.

    Raises:
        OSError: The library or a dependency cannot be loaded; the dynamic linker's message.
    """
    loaded: list[Path] = []
    for _ in range(32):  # each round resolves one missing dependency
        try:
            ctypes.CDLL(str(path), mode=os.RTLD_GLOBAL)
        except OSError as exc:
            missing = _MISSING_LIBRARY.search(str(exc))
            dependency = None if missing is None else _find_file(missing.group(1), folders)
            if dependency is None or dependency == path or dependency in loaded:
                raise
            loaded += load_global(dependency, folders)
            continue
        return [*loaded, path]
    raise OSError(f"{path}: too many missing dependencies")


def _find_file(file_name: str, folders: Iterable[Path]) -> Path | None:
    for folder in folders:
        if (folder / file_name).is_file():
            return folder / file_name
    return None


@functools.cache
def preload_cudss() -> tuple[list[Path], str | None]:
    """Load cuDSS from the installed NVIDIA wheels, once per process.

    Finds ``libcudss.so`` under :func:`nvidia_library_dirs` and loads it (with cuBLAS and
    whatever else it needs from the same wheels) into the global symbol scope, so that
    nvmath-python uses it without ``LD_LIBRARY_PATH``.

    Returns:
        (the libraries loaded, the reason cuDSS could not be loaded from the wheels or None).
    """
    folders = nvidia_library_dirs()
    library = find_nvidia_library("cudss", folders)
    if library is None:
        searched = ", ".join(str(folder) for folder in folders) or "no nvidia/*/lib folder"
        return [], f"libcudss.so was not found in the NVIDIA wheels' folders ({searched})"
    try:
        return load_global(library, folders), None
    except OSError as exc:
        return [], f"{library} did not load: {exc}"


@functools.cache
def cudss_unavailable_reason() -> str | None:
    """Why cuDSS cannot be used in this process, in one line, or None where it loads.

    Checks that nvmath-python and CuPy are installed, loads cuDSS from the NVIDIA wheels
    (:func:`preload_cudss`), then asks nvmath-python for cuDSS's version.
    """
    missing = [name for name in ("nvmath", "cupy") if importlib.util.find_spec(name) is None]
    if missing:
        names = {"nvmath": "nvmath-python", "cupy": "CuPy"}
        return f"{' and '.join(names[name] for name in missing)} not installed"
    _, preload_problem = preload_cudss()
    try:
        from nvmath.bindings import cudss

        cudss.get_property(0)
    except Exception as exc:  # any failure to import or load the library: say which
        problem = f"{type(exc).__name__}: {exc}".strip().splitlines()[0]
        return problem if preload_problem is None else f"{preload_problem}; {problem}"
    return None


_warned_unavailable: list[str] = []
"""The reason already warned about (once per process)."""


def cudss_available(*, warn: bool = True) -> bool:
    """Whether nvmath-python and CuPy import and the cuDSS library loads.

    Where it does not and a CUDA device is present, warns once per process (a
    ``RuntimeWarning`` naming the reason and the fix): the FE's ``linear_solver = "auto"``
    then runs Warp's conjugate gradients on the GPU, often 10-30 times slower (a 8 828-tet
    force curve took 88 s instead of 3.2 s on an H100).

    Args:
        warn: Warn as above (False for a silent probe, e.g. a test's skip condition).
    """
    reason = cudss_unavailable_reason()
    if reason is None:
        return True
    if warn and not _warned_unavailable and wp.is_cuda_available():
        _warned_unavailable.append(reason)
        warnings.warn(
            f"cuDSS, the GPU's direct solver, is not available ({reason}); the FE runs Warp's "
            "conjugate gradients on the GPU instead, often 10-30x slower. "
            f"Fix: {CUDSS_INSTALL_HINT}",
            RuntimeWarning,
            stacklevel=2,
        )
    return False


@functools.cache
def cudss_threading_library() -> str | None:
    """Path of cuDSS's threading layer (GNU OpenMP) shipped in the nvidia-cudss wheel, or None.

    With it cuDSS runs its host-side analysis (reordering, symbolic factorization) on several
    threads; without it nvmath-python warns on every solver it creates.
    """
    library = find_nvidia_library("cudss_mtlayer_gomp", nvidia_library_dirs())
    return None if library is None else str(library)


def _cupy_view(array: wp.array, cupy_module):
    """A CuPy array on the same device memory as a contiguous Warp array (no copy).

    A vec3d array of n entries becomes a float64 CuPy array of shape (n, 3).
    """
    return cupy_module.asarray(array)


def bsr33_csr_pattern(matrix: wps.BsrMatrix) -> tuple[wp.array, wp.array, wp.array]:
    """The scalar CSR pattern of a 3x3-block BSR matrix, on the matrix's device.

    Args:
        matrix: Square or rectangular BSR matrix with 3x3 blocks (n block rows, b blocks).

    Returns:
        (csr_offsets (3 n + 1,), csr_columns (9 b,), block_rows (b,)), int32 Warp arrays;
        ``block_rows`` is each block's row, for :func:`bsr33_csr_values`.
    """
    from warptissue.kernels import sparse as ks

    device = matrix.device
    block_count = matrix.nnz_sync()
    csr_offsets = wp.zeros(3 * matrix.nrow + 1, dtype=wp.int32, device=device)
    csr_columns = wp.empty(9 * block_count, dtype=wp.int32, device=device)
    block_rows = wp.empty(block_count, dtype=wp.int32, device=device)
    if matrix.nrow == 0:
        return csr_offsets, csr_columns, block_rows
    wp.launch(
        ks.bsr33_csr_pattern_kernel,
        dim=matrix.nrow,
        inputs=[matrix.offsets[: matrix.nrow + 1], matrix.columns],
        outputs=[csr_offsets, csr_columns, block_rows],
        device=device,
    )
    return csr_offsets, csr_columns, block_rows


def bsr33_csr_values(matrix: wps.BsrMatrix, block_rows: wp.array, csr_values: wp.array) -> None:
    """Copy the block values of a 3x3-block BSR matrix into its scalar CSR values, in place.

    Args:
        matrix: The BSR matrix (b blocks).
        block_rows: Each block's row, (b,) int32, from :func:`bsr33_csr_pattern`.
        csr_values: Output, (9 b,) float64 Warp array on the matrix's device.
    """
    from warptissue.kernels import sparse as ks

    if block_rows.shape[0] == 0:
        return
    if csr_values.shape[0] != 9 * block_rows.shape[0]:
        raise ValueError("csr_values must hold 9 values per block")
    wp.launch(
        ks.bsr33_csr_values_kernel,
        dim=block_rows.shape[0],
        inputs=[matrix.offsets[: matrix.nrow + 1], block_rows, matrix.values],
        outputs=[csr_values],
        device=matrix.device,
    )


def _gib(value_bytes: int) -> str:
    return f"{value_bytes / 2**30:.1f} GiB"


def check_memory_estimates(
    estimates: dict[str, int],
    *,
    hybrid: bool,
    device_limit_bytes: int,
    host_available_bytes: int,
    rows: int,
    device: str,
) -> None:
    """Refuse a factorization that cuDSS's estimates say cannot fit, before it starts.

    Args:
        estimates: cuDSS's estimates, keyed by :data:`MEMORY_ESTIMATE_NAMES`.
        hybrid: Whether the analysis ran in hybrid memory mode (factors in host memory).
        device_limit_bytes: Device memory the factorization may use.
        host_available_bytes: Host memory available.
        rows: Rows of the matrix, for the message.
        device: The device's name, for the message.

    Raises:
        DeviceError: The device or the host memory is too small; the message quotes what
            cuDSS needs and what there is.
    """
    key = "hybrid_min_device_memory_bytes" if hybrid else "peak_device_memory_bytes"
    if estimates[key] > device_limit_bytes:
        where = " even with its factors in host memory" if hybrid else ""
        raise DeviceError(
            f"cuDSS needs {_gib(estimates[key])} of device memory to factorize this "
            f"{rows}-row matrix{where}; {_gib(device_limit_bytes)} is available on {device}"
        )
    if estimates["peak_host_memory_bytes"] > host_available_bytes:
        where = " for its factors (hybrid memory mode)" if hybrid else ""
        raise DeviceError(
            f"cuDSS needs {_gib(estimates['peak_host_memory_bytes'])} of host memory{where} to "
            f"factorize this {rows}-row matrix; {_gib(host_available_bytes)} is available"
        )


class CudssSolver:
    """Repeated direct solves of one BSR sparsity pattern with cuDSS on a CUDA device.

    Where cuDSS's analysis finds that the factors would not fit in the device memory that is
    free, the solver plans again in cuDSS's hybrid memory mode: the factors live in host
    memory and stream through the device (slower, but it runs). A factorization that fits
    neither way is refused with the numbers before it starts.

    Args:
        matrix: Square 3x3-block float64 BSR matrix (N x N blocks) on a CUDA device. Its
            pattern (offsets, columns) must stay fixed; its values may change between solves.
        device_memory_limit_bytes: Device memory the factorization may use, bytes (default:
            :data:`DEVICE_MEMORY_SHARE` of what is free when the solver is made).

    Attributes:
        factorizations: Numerical factorizations done so far.
        threading_library: The cuDSS threading layer in use (see
            :func:`cudss_threading_library`), or None.
        hybrid_memory: Whether the factors are kept in host memory (hybrid memory mode).
        memory_estimates: cuDSS's memory estimates after the analysis, bytes, keyed by
            :data:`MEMORY_ESTIMATE_NAMES`.
        timer: The :class:`warptissue.fem.timing.PhaseTimer` that its factorizations and
            solves are charged to (a disabled one unless the Newton solver profiles).

    Raises:
        DeviceError: The matrix is not on a CUDA device, cuDSS could not be loaded, or the
            factorization cannot fit in device and host memory.
        ValueError: ``device_memory_limit_bytes`` is not positive.
    """

    def __init__(
        self, matrix: wps.BsrMatrix, *, device_memory_limit_bytes: int | None = None
    ) -> None:
        device = matrix.device
        if not device.is_cuda:
            raise DeviceError(f"cuDSS needs a CUDA device; the matrix is on {device}")
        preload_cudss()  # before nvmath-python looks for the library itself
        try:
            import cupy
            import cupyx.scipy.sparse
            import nvmath.sparse.advanced as nvs
        except ImportError as exc:
            raise DeviceError(
                "the cuDSS solver needs nvmath-python, nvidia-cudss-cu13 and cupy-cuda13x "
                f"({CUDSS_INSTALL_HINT})"
            ) from exc
        if device_memory_limit_bytes is not None and device_memory_limit_bytes <= 0:
            raise ValueError(
                f"device_memory_limit_bytes must be positive, got {device_memory_limit_bytes}"
            )
        self.matrix = matrix
        self.device = device
        self.timer = PhaseTimer(enabled=False)
        self.factorizations = 0
        self.row_count = 3 * matrix.nrow
        self._nvs = nvs
        self._cupy = cupy
        self._csr_offsets, self._csr_columns, self._block_rows = bsr33_csr_pattern(matrix)
        self._csr_values = wp.zeros(self._csr_columns.shape[0], dtype=wp.float64, device=device)
        self._rhs = wp.zeros(matrix.nrow, dtype=wp.vec3d, device=device)
        self._rhs_view = _cupy_view(self._rhs, cupy)
        self._stream = cupy.cuda.Stream.from_external(device.stream)
        self._events = (cupy.cuda.Event(), cupy.cuda.Event())  # around the last solve
        with cupy.cuda.Device(device.ordinal), self._stream:
            self._csr = cupyx.scipy.sparse.csr_matrix(
                (
                    _cupy_view(self._csr_values, cupy),
                    _cupy_view(self._csr_columns, cupy),
                    _cupy_view(self._csr_offsets, cupy),
                ),
                shape=(self.row_count, self.row_count),
                copy=False,
            )
            bsr33_csr_values(self.matrix, self._block_rows, self._csr_values)
            limit = (
                int(DEVICE_MEMORY_SHARE * device.free_memory)
                if device_memory_limit_bytes is None
                else device_memory_limit_bytes
            )
            self.hybrid_memory = False
            self._plan(hybrid_limit_bytes=None)
            needed = self.memory_estimates["peak_device_memory_bytes"]
            if needed > limit:
                # The factors do not fit on the device: plan again, keeping them in host
                # memory (cuDSS's hybrid memory mode must be chosen before the analysis).
                self._solver.free()
                self.hybrid_memory = True
                self._plan(hybrid_limit_bytes=limit)
            check_memory_estimates(
                self.memory_estimates,
                hybrid=self.hybrid_memory,
                device_limit_bytes=limit,
                host_available_bytes=available_host_memory_bytes(),
                rows=self.row_count,
                device=str(device),
            )
            if self.hybrid_memory:
                warnings.warn(
                    f"cuDSS needs {_gib(needed)} of device memory for this {self.row_count}-row "
                    f"matrix and {_gib(limit)} is available on {device}: its factors go to host "
                    "memory (hybrid memory mode) and stream through the GPU at every "
                    "factorization, which is much slower",
                    RuntimeWarning,
                    stacklevel=2,
                )

    def _plan(self, *, hybrid_limit_bytes: int | None) -> None:
        """Create the nvmath solver and run cuDSS's analysis, in hybrid memory mode when
        ``hybrid_limit_bytes`` (the device memory it may use) is given; sets
        ``memory_estimates`` from cuDSS's estimates after the analysis."""
        nvs = self._nvs
        execution = nvs.ExecutionCUDA(
            device_id=self.device.ordinal,
            hybrid_memory_mode_options=nvs.HybridMemoryModeOptions(
                hybrid_memory_mode=hybrid_limit_bytes is not None,
                hybrid_device_memory_limit=hybrid_limit_bytes,
            ),
        )
        threading = cudss_threading_library()
        # The threading layer is an optimization: if it does not load, run without it.
        for library in [threading, None] if threading else [None]:
            options = nvs.DirectSolverOptions(
                sparse_system_type=nvs.DirectSolverMatrixType.SYMMETRIC,
                sparse_system_view=nvs.DirectSolverMatrixViewType.LOWER,
                multithreading_lib=library,
            )
            try:
                self._solver = nvs.DirectSolver(
                    self._csr,
                    _cupy_view(self._rhs, self._cupy).reshape(-1),
                    options=options,
                    execution=execution,
                )
                self._solver.plan()
            except (RuntimeError, OSError) as exc:
                if library is None:
                    raise DeviceError(f"cuDSS could not be set up on {self.device}: {exc}") from exc
                continue
            self.threading_library = library
            break
        estimates = np.asarray(self._solver.plan_info.memory_estimates).item()
        self.memory_estimates = {
            name: int(value) for name, value in zip(MEMORY_ESTIMATE_NAMES, estimates, strict=False)
        }

    def solve(self, rhs: Any) -> Any:
        """Factorize the matrix's current values and solve ``matrix x = rhs``.

        Args:
            rhs: Right-hand side, shape (N, 3): NumPy, or a CuPy array on the device.

        Returns:
            x, shape (N, 3): NumPy for a NumPy ``rhs`` (copied to the host, which waits for
            the device); a new CuPy array on the device for a CuPy one (nothing waits).
        """
        with self._cupy.cuda.Device(self.device.ordinal), self._stream:
            self._events[0].record(self._stream)
            bsr33_csr_values(self.matrix, self._block_rows, self._csr_values)
            on_host = self._set_rhs(rhs)
            with self.timer.phase("factorization"):
                self._solver.factorize()
            self.factorizations += 1
            with self.timer.phase("solve"):
                x = self._solution(on_host)
            self._events[1].record(self._stream)
            return x

    def last_solve_device_s(self) -> float:
        """The device time of the last :meth:`solve` (the values' copy, the factorization
        and the solve), s, from CUDA events; waits for that solve to end. :meth:`solve`
        itself returns before the device has done its work."""
        if self.factorizations == 0:
            raise RuntimeError("last_solve_device_s needs a factorization: call solve first")
        start, end = self._events
        end.synchronize()
        return self._cupy.cuda.get_elapsed_time(start, end) / 1e3

    def solve_factorized(self, rhs: Any) -> Any:
        """Solve with the factors of the last :meth:`solve`, without a new factorization.

        Args:
            rhs: Right-hand side, shape (N, 3): NumPy, or a CuPy array on the device.

        Returns:
            x, shape (N, 3), of ``rhs``'s library (as :meth:`solve`).
        """
        if self.factorizations == 0:
            raise RuntimeError("solve_factorized needs a factorization: call solve first")
        with self._cupy.cuda.Device(self.device.ordinal), self._stream, self.timer.phase("solve"):
            return self._solution(self._set_rhs(rhs))

    def apply_factors(self, rhs):
        """Solve with the factors of the last :meth:`solve`, on the device.

        For the GMRES of :meth:`warptissue.fem.LinearSolver.solve_newton`: the call runs on
        the solver's stream (the caller enters ``cupy.cuda.Device`` and the stream), and
        nothing is copied to the host.

        Args:
            rhs: Right-hand side, a CuPy float64 array of 3 N entries (any shape).

        Returns:
            x, a new CuPy array of ``rhs``'s shape.
        """
        if self.factorizations == 0:
            raise RuntimeError("apply_factors needs a factorization: call solve first")
        self._rhs_view[...] = rhs.reshape(self._rhs_view.shape)
        return self._solver.solve().reshape(rhs.shape).copy()

    def _set_rhs(self, rhs: Any) -> bool:
        """Copy ``rhs`` into the solver's right-hand side (on its stream, which the caller has
        entered); a ValueError for another size. Returns whether it came from the host."""
        on_host = isinstance(rhs, np.ndarray) or not hasattr(rhs, "__cuda_array_interface__")
        xp = np if on_host else self._cupy
        values = xp.asarray(rhs, dtype=xp.float64)
        if values.size != self.row_count:
            raise ValueError(
                f"rhs must have shape ({self.row_count // 3}, 3), got {tuple(values.shape)}"
            )
        if on_host:
            self._rhs_view.set(np.ascontiguousarray(values.reshape(-1, 3)), stream=self._stream)
        else:
            self._rhs_view[...] = values.reshape(-1, 3)
        return on_host

    def _solution(self, on_host: bool) -> Any:
        """The solve's result as (N, 3): NumPy (waits for the device) or a new CuPy array."""
        x = self._solver.solve().reshape(-1, 3)
        if on_host:
            return self._cupy.asnumpy(x, stream=self._stream)
        return x.copy()

    def free(self) -> None:
        """Release cuDSS's factors and workspace now (they are also freed with the object)."""
        self._solver.free()
