"""CPU direct solver: the scalar pattern against SciPy's BSR -> CSR conversion, solves against
SciPy's spsolve on assembled and eliminated tangents, symmetry of the eliminated tangent, and
reuse of PARDISO's symbolic analysis along a Newton path."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
import warp as wp

from warptissue.fem import (
    Assembler,
    DirichletConditions,
    LinearSolver,
    NewtonOptions,
    solve_quasistatic,
)
from warptissue.fem.linear.direct import (
    CPU_DIRECT_METHODS,
    CpuDirectSolver,
    bsr33_scalar_pattern,
    pardiso_available,
)
from warptissue.materials import NeoHookean
from warptissue.mesh import block_mesh, to_tet10

SIDE_M = 1e-2
METHODS = [
    pytest.param(
        method,
        marks=pytest.mark.skipif(
            method == "pardiso" and not pardiso_available(), reason="pypardiso not installed"
        ),
    )
    for method in CPU_DIRECT_METHODS
]


def _mesh():
    grid = np.linspace(0.0, SIDE_M, 3)
    return to_tet10(block_mesh(grid, grid, np.linspace(0.0, SIDE_M, 2)))


def _conditions(mesh) -> DirichletConditions:
    """Fixed base, top pushed down (-z) and sheared (+x)."""
    bottom, top = mesh.node_sets["zmin"], mesh.node_sets["zmax"]
    return DirichletConditions.combine(
        DirichletConditions(
            np.repeat(bottom, 3), np.tile([0, 1, 2], len(bottom)), 0.0 * bottom.repeat(3)
        ),
        DirichletConditions(top, np.full(len(top), 2), np.full(len(top), -1.0)),
        DirichletConditions(top, np.full(len(top), 0), np.full(len(top), 0.3)),
    )


def _scipy_csr(matrix, node_count: int) -> sp.csr_matrix:
    nnz = matrix.nnz_sync()
    return sp.bsr_matrix(
        (
            matrix.values.numpy()[:nnz],
            matrix.columns.numpy()[:nnz],
            matrix.offsets.numpy()[: node_count + 1],
        ),
        shape=(3 * node_count, 3 * node_count),
    ).tocsr()


def _eliminated_tangent(assembler, conditions, u):
    assembly = assembler.assemble(u)
    mask = conditions.mask(assembler.node_count)
    assembler.eliminate(wp.array(mask, dtype=wp.vec3d, device=assembler.device))
    return assembly.matrix, mask


@pytest.mark.parametrize("upper", [False, True])
def test_scalar_pattern_matches_scipy(upper, rng):
    """Random block pattern (sorted columns per row, diagonal present) and random values."""
    node_count = 7
    dense_blocks = rng.random((node_count, node_count)) < 0.4
    dense_blocks |= dense_blocks.T
    np.fill_diagonal(dense_blocks, True)
    rows, cols = np.nonzero(dense_blocks)
    offsets = np.concatenate([[0], np.cumsum(np.bincount(rows, minlength=node_count))])
    values = rng.standard_normal((len(cols), 3, 3))
    indptr, indices, source = bsr33_scalar_pattern(offsets, cols, upper=upper)
    reference = sp.bsr_matrix((values, cols, offsets), shape=(3 * node_count,) * 2).tocsr()
    if upper:
        reference = sp.triu(reference, format="csr")
    reference.sort_indices()
    np.testing.assert_array_equal(indptr, reference.indptr)
    np.testing.assert_array_equal(indices, reference.indices)
    np.testing.assert_array_equal(values.reshape(-1)[source], reference.data)


def test_eliminated_tangent_is_symmetric(rng):
    mesh = _mesh()
    assembler = Assembler(mesh, NeoHookean(100.0, 1e5), device="cpu")
    conditions = _conditions(mesh)
    u = conditions.values(2e-4, mesh.node_count) + 1e-4 * rng.standard_normal((mesh.node_count, 3))
    matrix, mask = _eliminated_tangent(assembler, conditions, u)
    csr = _scipy_csr(matrix, mesh.node_count)
    scale = np.abs(csr.data).max()
    assert np.abs(csr - csr.T).max() <= 1e-13 * scale
    dense = csr.toarray()
    prescribed = np.flatnonzero(mask.reshape(-1))
    free = np.flatnonzero(mask.reshape(-1) == 0.0)
    assert prescribed.size and free.size
    np.testing.assert_array_equal(dense[np.ix_(prescribed, free)], 0.0)
    np.testing.assert_array_equal(dense[np.ix_(free, prescribed)], 0.0)
    np.testing.assert_array_equal(dense[np.ix_(prescribed, prescribed)], np.eye(prescribed.size))


@pytest.mark.parametrize("method", METHODS)
def test_solve_matches_scipy_and_reuses_analysis(method, rng):
    """New tangent values each solve: results match spsolve, the analysis is done once."""
    mesh = _mesh()
    assembler = Assembler(mesh, NeoHookean(100.0, 1e5), device="cpu")
    conditions = _conditions(mesh)
    solver = LinearSolver(method=method, device=assembler.device)
    for step in range(3):
        u = conditions.values(1e-4 * step, mesh.node_count)
        u += 5e-5 * rng.standard_normal((mesh.node_count, 3))
        matrix, _ = _eliminated_tangent(assembler, conditions, u)
        rhs = rng.standard_normal((mesh.node_count, 3))
        x, iterations = solver.solve(matrix, rhs)
        reference = sp.linalg.spsolve(_scipy_csr(matrix, mesh.node_count).tocsc(), rhs.ravel())
        np.testing.assert_allclose(
            x.ravel(), reference, rtol=0, atol=1e-10 * np.abs(reference).max(), err_msg=method
        )
        assert iterations == 1
    assert solver.direct.factorizations == 3
    assert solver.direct.analyses == (1 if method == "pardiso" else 3)


@pytest.mark.skipif(not pardiso_available(), reason="pypardiso not installed")
def test_newton_path_analyses_once(monkeypatch):
    """Along a whole load path PARDISO analyses once; without factorization reuse it
    factorizes once per Newton iteration, with it (the default) once per counted
    factorization."""
    phases: list[int] = []
    original = CpuDirectSolver._pardiso

    def recording(self, phase, rhs=None):
        phases.append(phase)
        return original(self, phase, rhs)

    monkeypatch.setattr(CpuDirectSolver, "_pardiso", recording)
    mesh = _mesh()
    for reuse in (False, True):
        phases.clear()
        assembler = Assembler(mesh, NeoHookean(100.0, 1e5), device="cpu")
        path = solve_quasistatic(
            assembler,
            _conditions(mesh),
            [1e-3, 2e-3],
            options=NewtonOptions(linear_solver="pardiso", reuse_factorization=reuse),
        )
        assert path.completed, path.message
        newton = int(path.newton_iterations.sum())
        assert newton >= 4
        assert phases.count(11) == 1
        factorizations = path.linear_solver_statistics["factorizations"]
        assert phases.count(22) == factorizations
        if not reuse:
            assert factorizations == phases.count(33) == newton


def test_pardiso_that_does_not_load_is_a_one_line_device_error(monkeypatch):
    """pypardiso imports but MKL's mkl_rt is missing: a DeviceError naming the reason and
    the fix, not an ImportError from inside pypardiso."""
    from warptissue.errors import DeviceError
    from warptissue.fem.linear import direct

    def missing_mkl():
        raise ImportError("Shared library mkl_rt not found.")

    monkeypatch.setattr(direct, "_pardiso_routine", missing_mkl)
    direct.pardiso_unavailable_reason.cache_clear()
    try:
        assert not direct.pardiso_available()
        assert "mkl_rt not found" in direct.pardiso_unavailable_reason()
        mesh = _mesh()
        assembler = Assembler(mesh, NeoHookean(100.0, 1e4), device="cpu")
        matrix = assembler.assemble(np.zeros((mesh.node_count, 3))).matrix
        with pytest.raises(DeviceError, match="MKL PARDISO could not be loaded .*superlu"):
            CpuDirectSolver(matrix, method="pardiso")
    finally:
        direct.pardiso_unavailable_reason.cache_clear()


@pytest.fixture
def base_prefix_mkl(monkeypatch, tmp_path):
    """A virtual environment whose base Python holds ``lib/libmkl_rt.so.2`` (an empty
    file): ``sys.prefix`` and ``sys.base_prefix`` pointed there, ``PYPARDISO_MKL_RT`` unset
    (and removed again at teardown, whatever the code under test set), the routine's cache
    cleared before and after. Yields the library's path."""
    from warptissue.fem.linear import direct

    library = tmp_path / "base" / "lib" / "libmkl_rt.so.2"
    library.parent.mkdir(parents=True)
    library.write_bytes(b"")
    # set first, so that the teardown removes what the code under test sets
    monkeypatch.setenv("PYPARDISO_MKL_RT", "")
    monkeypatch.delenv("PYPARDISO_MKL_RT")
    monkeypatch.setattr(direct.sys, "prefix", str(tmp_path / "venv"))
    monkeypatch.setattr(direct.sys, "base_prefix", str(tmp_path / "base"))
    direct._pardiso_routine.cache_clear()
    yield library
    direct._pardiso_routine.cache_clear()


def test_pardiso_takes_the_base_pythons_mkl_in_a_virtual_environment(monkeypatch, base_prefix_mkl):
    """A virtual environment made with --system-site-packages has MKL under the base Python's
    prefix, where pypardiso does not look: the routine is loaded from there (through
    PYPARDISO_MKL_RT) instead of falling back to SuperLU; where the base prefix has none, or
    the variable is set already, pypardiso's own ImportError stands."""
    import sys
    import types

    from warptissue.fem.linear import direct

    seen = []

    class FakeSolver:
        def __init__(self):
            path = direct.os.environ.get("PYPARDISO_MKL_RT")
            seen.append(path)
            if path is None:
                raise ImportError("Shared library mkl_rt not found.")
            self._mkl_pardiso = ("routine from", path)

    monkeypatch.setitem(sys.modules, "pypardiso", types.SimpleNamespace(PyPardisoSolver=FakeSolver))
    routine = direct._pardiso_routine()
    assert routine == ("routine from", str(base_prefix_mkl))
    assert seen == [None, str(base_prefix_mkl)]
    # No MKL under the base prefix either: pypardiso's error stands.
    base_prefix_mkl.unlink()
    monkeypatch.delenv("PYPARDISO_MKL_RT", raising=False)
    direct._pardiso_routine.cache_clear()
    with pytest.raises(ImportError, match="mkl_rt not found"):
        direct._pardiso_routine()


def test_pardiso_loads_where_pypardiso_s_import_itself_fails_without_mkl(
    tmp_path, monkeypatch, base_prefix_mkl
):
    """pypardiso makes a solver as it is imported: without ``mkl_rt`` under the environment's
    prefix its import raises (as in a ``--system-site-packages`` environment). The base
    prefix's ``mkl_rt`` is then tried with the import run again; a missing pypardiso stays
    a ModuleNotFoundError."""
    import sys

    from warptissue.fem.linear import direct

    package = tmp_path / "site" / "pypardiso"
    package.mkdir(parents=True)
    (package / "__init__.py").write_text(
        "import os\n"
        "class PyPardisoSolver:\n"
        "    def __init__(self):\n"
        "        path = os.environ.get('PYPARDISO_MKL_RT')\n"
        "        if path is None:\n"
        "            raise ImportError('Shared library mkl_rt not found.')\n"
        "        self._mkl_pardiso = ('routine from', path)\n"
        "solver = PyPardisoSolver()  # as pypardiso's scipy aliases do on import\n"
    )
    monkeypatch.delitem(sys.modules, "pypardiso", raising=False)
    monkeypatch.syspath_prepend(str(tmp_path / "site"))
    try:
        assert direct._pardiso_routine() == ("routine from", str(base_prefix_mkl))
        monkeypatch.setitem(sys.modules, "pypardiso", None)  # not installed
        monkeypatch.delenv("PYPARDISO_MKL_RT", raising=False)
        direct._pardiso_routine.cache_clear()
        with pytest.raises(ModuleNotFoundError):
            direct._pardiso_routine()
        assert "PYPARDISO_MKL_RT" not in direct.os.environ
    finally:
        sys.modules.pop("pypardiso", None)
