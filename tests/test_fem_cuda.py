"""The FE on CUDA: the BSR -> CSR hand-off to cuDSS, and CUDA results against the CPU's.

The CPU reference is a direct solve (PARDISO or SuperLU). The CUDA runs use each CUDA linear
solver present (cuDSS through nvmath-python where it loads, Warp's CG always); they must
reproduce the CPU force curve and displacements to 1e-8 relative. Tests that need a GPU are
skipped without one.
"""

from __future__ import annotations

import ctypes
import shutil
import subprocess
import sys
import warnings
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import scipy.sparse as sp
import warp as wp
import warp.sparse as wps

from warptissue.errors import DeviceError, InputError
from warptissue.fem import (
    IndentationProblem,
    LinearSolver,
    NewtonOptions,
    simulate_indentation,
)
from warptissue.fem.linear import cudss
from warptissue.fem.linear.cudss import (
    MEMORY_ESTIMATE_NAMES,
    CudssSolver,
    bsr33_csr_pattern,
    bsr33_csr_values,
    check_memory_estimates,
    cudss_available,
    cudss_threading_library,
)
from warptissue.indenter import Indenter
from warptissue.materials import NeoHookean
from warptissue.mesh import TetMesh, block_mesh, to_tet10

NEWTON_TOLERANCE = 1e-11
"""Tight, so that two converged solutions agree far below the 1e-8 the tests ask."""
RELATIVE_TOLERANCE = {"cudss": 1e-8, "cg": 1e-7}
"""CG stops at a relative linear residual of 1e-12: on the CPU its curve differs from the
direct solver's by 3e-8, so the CUDA CG run is held to 1e-7."""
needs_cuda = pytest.mark.skipif(not wp.is_cuda_available(), reason="needs a CUDA device")
CUDA_SOLVERS = (["cudss"] if cudss_available(warn=False) else []) + ["cg"]


def _random_bsr(rng: np.random.Generator, device: str, block_rows: int = 7):
    """A random 3x3-block BSR matrix with some empty rows, and its dense copy."""
    rows = rng.integers(0, block_rows - 2, size=40)  # the last two block rows stay empty
    cols = rng.integers(0, block_rows, size=40)
    keys = np.unique(rows * block_rows + cols)
    rows, cols = keys // block_rows, keys % block_rows
    blocks = rng.standard_normal((len(keys), 3, 3))
    matrix = wps.bsr_from_triplets(
        block_rows,
        block_rows,
        wp.array(rows.astype(np.int32), dtype=wp.int32, device=device),
        wp.array(cols.astype(np.int32), dtype=wp.int32, device=device),
        wp.array(blocks, dtype=wp.mat33d, device=device),
    )
    dense = np.zeros((3 * block_rows, 3 * block_rows))
    for r, c, block in zip(rows, cols, blocks, strict=True):
        dense[3 * r : 3 * r + 3, 3 * c : 3 * c + 3] = block
    return matrix, dense


def test_bsr33_to_csr_matches_the_dense_matrix(device, rng):
    matrix, dense = _random_bsr(rng, device)
    offsets, columns, block_rows = bsr33_csr_pattern(matrix)
    values = wp.full(columns.shape[0], np.nan, dtype=wp.float64, device=device)
    bsr33_csr_values(matrix, block_rows, values)
    csr = sp.csr_matrix((values.numpy(), columns.numpy(), offsets.numpy()), shape=dense.shape)
    assert not np.isnan(values.numpy()).any()
    np.testing.assert_array_equal(csr.toarray(), dense)
    assert csr.has_sorted_indices
    # The same pattern serves new values of the same blocks.
    matrix.values.assign(2.0 * matrix.values.numpy())
    bsr33_csr_values(matrix, block_rows, values)
    np.testing.assert_array_equal(
        sp.csr_matrix((values.numpy(), columns.numpy(), offsets.numpy())).toarray(), 2.0 * dense
    )


def _fake_site_packages(root: Path, files: dict[str, list[str]]) -> Path:
    """A site-packages folder with empty files at ``nvidia/<component>/lib/<name>``."""
    for component, names in files.items():
        folder = root / "nvidia" / component / "lib"
        folder.mkdir(parents=True)
        for name in names:
            (folder / name).write_bytes(b"")
    return root


def test_wheel_libraries_are_found_in_every_site_packages(tmp_path, monkeypatch):
    """The CUDA 13 wheels' ``nvidia/cu13/lib`` and older ``nvidia/<name>/lib`` folders, in
    every root: also where another environment's ``nvidia`` package comes first."""
    other = _fake_site_packages(tmp_path / "other", {"cuda_runtime": ["libcudart.so.12"]})
    (tmp_path / "empty" / "nvidia").mkdir(parents=True)
    wheels = ["libcublas.so.13", "libcublasLt.so.13", "libcudss.so.0", "libcudss.so.0.7.1"]
    mine = _fake_site_packages(
        tmp_path / "venv", {"cu13": [*wheels, "libcudss_mtlayer_gomp.so.0", "libcudss.txt"]}
    )
    folders = cudss.nvidia_library_dirs([other, tmp_path / "empty", mine, mine])
    assert folders == [other / "nvidia/cuda_runtime/lib", mine / "nvidia/cu13/lib"]
    lib = mine / "nvidia/cu13/lib"
    assert cudss.find_nvidia_library("cudss", folders) == lib / "libcudss.so.0"
    assert cudss.find_nvidia_library("cublas", folders) == lib / "libcublas.so.13"
    assert cudss.find_nvidia_library("cublasLt", folders) == lib / "libcublasLt.so.13"
    assert cudss.find_nvidia_library("cusparse", folders) is None
    monkeypatch.setattr(cudss, "nvidia_library_dirs", lambda: folders)
    cudss_threading_library.cache_clear()
    try:
        assert cudss_threading_library() == str(lib / "libcudss_mtlayer_gomp.so.0")
        monkeypatch.setattr(cudss, "nvidia_library_dirs", lambda: folders[:1])
        cudss_threading_library.cache_clear()
        assert cudss_threading_library() is None
    finally:
        cudss_threading_library.cache_clear()


def _compile_library(path: Path, source: str, *, needs: Path | None = None) -> None:
    command = [shutil.which("cc"), "-shared", "-fPIC", f"-Wl,-soname,{path.name}"]
    command += ["-x", "c", "-", "-o", str(path)]
    if needs is not None:  # linked by soname, with no run path: the loader must find it
        command += [f"-L{needs.parent}", f"-l:{needs.name}"]
    subprocess.run(command, input=source, text=True, check=True, capture_output=True)


@pytest.mark.skipif(shutil.which("cc") is None, reason="needs a C compiler to build libraries")
def test_load_global_finds_the_dependencies_in_the_wheels(tmp_path):
    """A library whose dependency sits in another wheel folder, not on LD_LIBRARY_PATH: the
    plain load fails; load_global loads the dependency first, then the library."""
    site = _fake_site_packages(tmp_path, {"cu13": [], "cudss": []})
    dependency = site / "nvidia/cu13/lib" / f"libwtdep{tmp_path.name[-8:]}.so.13"
    library = site / "nvidia/cudss/lib" / "libwtcudss.so.0"
    _compile_library(dependency, "int wt_dep(void) { return 41; }")
    _compile_library(
        library, "int wt_dep(void); int wt_main(void) { return wt_dep() + 1; }", needs=dependency
    )
    with pytest.raises(OSError, match=f"{dependency.name}: cannot open shared object file"):
        ctypes.CDLL(str(library))
    folders = cudss.nvidia_library_dirs([site])
    assert cudss.load_global(library, folders) == [dependency, library]
    assert ctypes.CDLL(str(library)).wt_main() == 42
    # A dependency found nowhere: the dynamic linker's message.
    nowhere = tmp_path / f"libwtnowhere{tmp_path.name[-8:]}.so.1"
    _compile_library(nowhere, "int wt_gone(void) { return 0; }")
    broken = site / "nvidia/cudss/lib" / "libwtbroken.so.0"
    _compile_library(
        broken, "int wt_gone(void); int wt_b(void) { return wt_gone(); }", needs=nowhere
    )
    nowhere.unlink()
    with pytest.raises(OSError, match=f"{nowhere.name}: cannot open shared object file"):
        cudss.load_global(broken, folders)


@pytest.fixture
def fresh_cudss_probe(monkeypatch):
    """cuDSS's probe and its once-per-process warning, reset for one test."""
    monkeypatch.setattr(cudss, "_warned_unavailable", [])
    cached = (cudss.cudss_unavailable_reason, cudss.preload_cudss)
    for function in cached:
        function.cache_clear()
    yield
    for function in cached:
        function.cache_clear()


def test_missing_cudss_is_said_once_with_the_fix(monkeypatch, fresh_cudss_probe):
    """On a CUDA machine without cuDSS, "auto" falls back to CG with one warning naming the
    reason and the install command, not silently."""
    monkeypatch.setattr(cudss, "cudss_unavailable_reason", lambda: "nvmath-python not installed")
    monkeypatch.setattr(cudss.wp, "is_cuda_available", lambda: True)
    cuda = SimpleNamespace(is_cuda=True, is_cpu=False)
    with pytest.warns(RuntimeWarning) as caught:
        assert LinearSolver(method="auto", device=cuda).method == "cg"
    assert len(caught) == 1
    message = str(caught[0].message)
    assert "nvmath-python not installed" in message
    assert "pip install 'warptissue[gpu]'" in message
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a second solver says nothing more
        assert LinearSolver(method="auto", device=cuda).method == "cg"
        assert not cudss_available()


def test_no_warning_without_a_gpu_or_when_asked_not_to(monkeypatch, fresh_cudss_probe):
    monkeypatch.setattr(cudss, "cudss_unavailable_reason", lambda: "CuPy not installed")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        monkeypatch.setattr(cudss.wp, "is_cuda_available", lambda: False)
        assert not cudss_available()
        monkeypatch.setattr(cudss.wp, "is_cuda_available", lambda: True)
        assert not cudss_available(warn=False)


def test_the_reason_names_what_failed(tmp_path, monkeypatch, fresh_cudss_probe):
    """nvmath-python installed but cuDSS not in the wheels: the reason says where it looked
    and what nvmath-python said."""
    folders = [_fake_site_packages(tmp_path, {"cu13": ["libcublas.so.13"]}) / "nvidia/cu13/lib"]
    monkeypatch.setattr(cudss, "nvidia_library_dirs", lambda: folders)
    monkeypatch.setattr(cudss.importlib.util, "find_spec", lambda name: object())

    def get_property(kind):
        raise RuntimeError("libcudss.so.0: cannot open shared object file")

    bindings = SimpleNamespace(cudss=SimpleNamespace(get_property=get_property))
    monkeypatch.setitem(sys.modules, "nvmath", SimpleNamespace(bindings=bindings))
    monkeypatch.setitem(sys.modules, "nvmath.bindings", bindings)
    monkeypatch.setitem(sys.modules, "nvmath.bindings.cudss", bindings.cudss)
    reason = cudss.cudss_unavailable_reason()
    assert f"libcudss.so was not found in the NVIDIA wheels' folders ({folders[0]})" in reason
    assert "RuntimeError: libcudss.so.0: cannot open shared object file" in reason
    cudss.cudss_unavailable_reason.cache_clear()
    monkeypatch.setattr(cudss.importlib.util, "find_spec", lambda name: None)
    assert cudss.cudss_unavailable_reason() == "nvmath-python and CuPy not installed"


@needs_cuda
@pytest.mark.skipif(not cudss_available(warn=False), reason="needs nvmath-python with cuDSS")
def test_cudss_solves_with_its_threading_layer(rng):
    """A symmetric positive definite system solved by cuDSS equals NumPy's solution; the
    solver runs with the wheel's threading layer where that is installed."""
    dense = rng.standard_normal((21, 21))
    spd = dense @ dense.T + 3.0 * np.eye(21)
    blocks = spd.reshape(7, 3, 7, 3).transpose(0, 2, 1, 3).reshape(49, 3, 3)
    rows, cols = np.divmod(np.arange(49), 7)
    matrix = wps.bsr_from_triplets(
        7,
        7,
        wp.array(rows.astype(np.int32), dtype=wp.int32, device="cuda:0"),
        wp.array(cols.astype(np.int32), dtype=wp.int32, device="cuda:0"),
        wp.array(blocks, dtype=wp.mat33d, device="cuda:0"),
    )
    rhs = rng.standard_normal((7, 3))
    solver = CudssSolver(matrix)
    assert solver.threading_library == cudss_threading_library()
    np.testing.assert_allclose(
        solver.solve(rhs).ravel(), np.linalg.solve(spd, rhs.ravel()), rtol=1e-10, atol=1e-12
    )


def _grid_stiffness_bsr(points_per_side: int, device: str):
    """The SPD 3x3-block matrix kron(L, I3) + kron(I, S) of a 7-point grid Laplacian L on
    points_per_side^3 nodes (S a fixed SPD 3x3 block), as BSR and as SciPy CSR."""
    line = sp.diags(
        [
            -np.ones(points_per_side - 1),
            2.0 * np.ones(points_per_side),
            -np.ones(points_per_side - 1),
        ],
        [-1, 0, 1],
    )
    eye = sp.identity(points_per_side)
    laplacian = (
        sp.kron(sp.kron(line, eye), eye)
        + sp.kron(sp.kron(eye, line), eye)
        + sp.kron(eye, sp.kron(eye, line))
    ).tocoo()
    coupling = np.array([[2.0, 0.5, 0.1], [0.5, 1.5, 0.2], [0.1, 0.2, 1.0]])
    blocks = (
        laplacian.data[:, None, None] * np.eye(3)
        + (laplacian.row == laplacian.col)[:, None, None] * coupling
    )
    node_count = points_per_side**3
    matrix = wps.bsr_from_triplets(
        node_count,
        node_count,
        wp.array(laplacian.row.astype(np.int32), dtype=wp.int32, device=device),
        wp.array(laplacian.col.astype(np.int32), dtype=wp.int32, device=device),
        wp.array(blocks, dtype=wp.mat33d, device=device),
    )
    csr = (sp.kron(laplacian, sp.identity(3)) + sp.kron(sp.identity(node_count), coupling)).tocsr()
    return matrix, csr


@needs_cuda
@pytest.mark.skipif(not cudss_available(warn=False), reason="needs nvmath-python with cuDSS")
def test_cudss_keeps_its_factors_in_host_memory_when_the_device_memory_is_short(rng):
    """Below cuDSS's estimate of the device memory it needs, the solver plans again in hybrid
    memory mode and still solves exactly; below the hybrid mode's least device memory it
    refuses before factorizing."""
    matrix, csr = _grid_stiffness_bsr(14, "cuda:0")
    rhs = rng.standard_normal((matrix.nrow, 3))
    expected = sp.linalg.spsolve(csr.tocsc(), rhs.ravel())
    on_device = CudssSolver(matrix)
    assert not on_device.hybrid_memory
    assert set(on_device.memory_estimates) == set(MEMORY_ESTIMATE_NAMES)
    np.testing.assert_allclose(on_device.solve(rhs).ravel(), expected, rtol=1e-10, atol=1e-12)
    peak = on_device.memory_estimates["peak_device_memory_bytes"]
    least = on_device.memory_estimates["hybrid_min_device_memory_bytes"]
    assert 0 < least < peak
    with pytest.warns(RuntimeWarning, match="factors go to host memory"):
        hybrid = CudssSolver(matrix, device_memory_limit_bytes=(least + peak) // 2)
    assert hybrid.hybrid_memory
    np.testing.assert_allclose(hybrid.solve(rhs).ravel(), expected, rtol=1e-10, atol=1e-12)
    with pytest.raises(DeviceError, match="device memory"):
        CudssSolver(matrix, device_memory_limit_bytes=least // 4)


def test_memory_estimates_that_do_not_fit_are_refused_with_the_numbers():
    estimates = dict.fromkeys(MEMORY_ESTIMATE_NAMES, 0)
    estimates.update(
        peak_device_memory_bytes=8 * 2**30,
        hybrid_min_device_memory_bytes=2 * 2**30,
        peak_host_memory_bytes=3 * 2**30,
    )
    fits = {"rows": 300, "device": "cuda:0", "host_available_bytes": 4 * 2**30}
    check_memory_estimates(estimates, hybrid=False, device_limit_bytes=8 * 2**30, **fits)
    check_memory_estimates(estimates, hybrid=True, device_limit_bytes=2 * 2**30, **fits)
    with pytest.raises(DeviceError, match=r"8\.0 GiB of device memory .* 300-row .* 7\.0 GiB"):
        check_memory_estimates(estimates, hybrid=False, device_limit_bytes=7 * 2**30, **fits)
    with pytest.raises(DeviceError, match=r"2\.0 GiB .* even with its factors in host memory"):
        check_memory_estimates(estimates, hybrid=True, device_limit_bytes=2**30, **fits)
    with pytest.raises(DeviceError, match=r"3\.0 GiB of host memory .* 2\.5 GiB is available"):
        check_memory_estimates(
            estimates,
            hybrid=True,
            device_limit_bytes=2 * 2**30,
            rows=300,
            device="cuda:0",
            host_available_bytes=int(2.5 * 2**30),
        )


def test_cudss_needs_a_cuda_device():
    with pytest.raises(InputError, match="cudss"):
        LinearSolver(method="cudss", device=wp.get_device("cpu"))


def _bonded_punch_problem() -> IndentationProblem:
    """A quarter 1 mm block of 108 TET10 under a bonded punch of radius 0.4 mm, K/mu = 1000."""
    grid = np.linspace(0.0, 1e-3, 4)
    block = to_tet10(block_mesh(grid, grid, np.linspace(0.0, 1e-3, 3), split="six"))
    names = {"top": "zmax", "bottom": "zmin", "symmetry_x": "xmin", "symmetry_y": "ymin"}
    mesh = TetMesh(
        block.points,
        block.tets,
        node_sets={name: block.node_set(source) for name, source in names.items()},
    )
    return IndentationProblem(
        mesh,
        NeoHookean(C10_Pa=287.5, bulk_modulus_Pa=1000.0 * 575.0),
        Indenter("flat_punch", radius_m=0.4e-3, contact="bonded"),
    )


@pytest.fixture(scope="module")
def cpu_reference():
    problem = _bonded_punch_problem()
    depths = np.array([2e-5, 5e-5, 1e-4])
    result = simulate_indentation(
        problem,
        depths,
        device="cpu",
        progress=False,
        options=NewtonOptions(tolerance=NEWTON_TOLERANCE),
    )
    assert result.completed
    return problem, depths, result


@needs_cuda
@pytest.mark.parametrize("linear_solver", CUDA_SOLVERS)
def test_cuda_equals_cpu(cpu_reference, linear_solver):
    problem, depths, reference = cpu_reference
    result = simulate_indentation(
        problem,
        depths,
        device="cuda:0",
        progress=False,
        options=NewtonOptions(linear_solver=linear_solver, tolerance=NEWTON_TOLERANCE),
    )
    assert result.completed, result.message
    assert result.linear_solver == linear_solver
    force_error = np.abs(result.reaction_force_N / reference.reaction_force_N - 1.0).max()
    displacement_error = np.linalg.norm(
        result.displacement_m - reference.displacement_m
    ) / np.linalg.norm(reference.displacement_m)
    stress_error = np.abs(result.von_mises_Pa - reference.von_mises_Pa).max() / (
        reference.von_mises_Pa.max()
    )
    print(
        f"{linear_solver}: force {force_error:.2e}, displacement {displacement_error:.2e}, "
        f"stress {stress_error:.2e}"
    )
    rtol = RELATIVE_TOLERANCE[linear_solver]
    assert force_error <= rtol
    assert displacement_error <= rtol
    assert stress_error <= rtol


@needs_cuda
def test_auto_prefers_cudss_on_cuda():
    solver = LinearSolver(method="auto", device=wp.get_device("cuda:0"))
    assert solver.method == ("cudss" if cudss_available() else "cg")
