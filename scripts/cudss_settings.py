"""cuDSS settings on the flat-punch benchmark's tangent: factorization time and accuracy.

Runs the benchmark (``bench_flat_punch.py``: quarter block, bonded punch a = 1 mm, neo-Hookean,
K / mu = 1000, TET10 mixed) on CUDA for the first ``--steps`` load steps, assembles the
eliminated tangent at that state, and factorizes it with fresh cuDSS solvers under several
settings: the default (symmetric indefinite LDL^T, the one warptissue uses), no pivoting,
superpanels off, the nested-dissection reordering and the two other factorization
algorithms, Cholesky (SPD), and float32 factors with float64 iterative refinement. For each it
records the analysis time, three numerical factorizations (wall and host CPU seconds), the
solve, and the float64 residual ``|A x - b| / |b|`` for a random right-hand side.

Needs a CUDA device with ``pip install '.[gpu]'``::

    python scripts/cudss_settings.py --tets 100000 --steps 6 --out $OUT/cudss_settings.json
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_flat_punch as bench  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tets", type=int, default=100_000, help="about this many tets")
    parser.add_argument("--steps", type=int, default=6, help="load steps before the tangent")
    parser.add_argument("--out", type=Path, default=None, help="write the JSON here")
    args = parser.parse_args(argv)

    import cupy
    import cupyx.scipy.sparse
    import nvmath.sparse.advanced as nvs
    import warp as wp
    from nvmath.bindings import cudss

    from warptissue.fem import Assembler, FlatPunch, IndentationProblem, simulate_indentation
    from warptissue.fem.cudss import bsr33_csr_pattern, bsr33_csr_values
    from warptissue.materials import NeoHookean

    mesh, _ = bench.warptissue_mesh(args.tets)
    material = NeoHookean(
        C10_Pa=0.5 * bench.SHEAR_MODULUS_PA, bulk_modulus_Pa=bench.BULK_MODULUS_PA
    )
    problem = IndentationProblem(
        mesh,
        material,
        FlatPunch(bench.PROBE_RADIUS_M, contact="bonded"),
        base="fixed",
        symmetry_planes=("symmetry_x", "symmetry_y"),
        formulation="mixed",
    )
    path = simulate_indentation(
        problem,
        bench.depths_m()[: args.steps],
        device="cuda:0",
        progress=False,
        tolerance=bench.NEWTON_TOLERANCE,
    )
    assembler = Assembler(mesh, material, device="cuda:0")
    assembly = assembler.assemble(path.displacement_m[-1])
    mask = problem.dirichlet_conditions().mask(mesh.node_count)
    assembler.eliminate(wp.array(mask, dtype=wp.vec3d, device="cuda:0"))
    offsets, columns, block_rows = bsr33_csr_pattern(assembly.matrix)
    values = wp.zeros(columns.shape[0], dtype=wp.float64, device="cuda:0")
    bsr33_csr_values(assembly.matrix, block_rows, values)
    wp.synchronize()
    dof_count = 3 * mesh.node_count
    matrix = cupyx.scipy.sparse.csr_matrix(
        (cupy.asarray(values), cupy.asarray(columns), cupy.asarray(offsets)),
        shape=(dof_count, dof_count),
    )
    rhs = cupy.asarray(np.random.default_rng(1).standard_normal(dof_count))
    synchronize = cupy.cuda.Device().synchronize
    reference: Any = None
    results: list[dict[str, Any]] = []

    def write_report() -> None:
        """Write what has been measured so far (a setting may run past a time limit)."""
        if args.out is None:
            return
        report = {
            "tets": mesh.tet_count,
            "dofs": dof_count,
            "load_steps_before": args.steps,
            "newton_iterations": path.newton_iterations.tolist(),
            "machine": bench.machine_description(),
            "results": results,
        }
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(report, indent=1))

    def measure(
        label: str,
        *,
        dtype=np.float64,
        system="SYMMETRIC",
        plan=None,
        factor=None,
        refinements: int = 0,
    ) -> None:
        nonlocal reference
        record: dict[str, Any] = {"label": label}
        try:
            a = matrix if dtype == np.float64 else matrix.astype(dtype)
            b = rhs.astype(dtype)
            options = nvs.DirectSolverOptions(
                sparse_system_type=getattr(nvs.DirectSolverMatrixType, system),
                sparse_system_view=nvs.DirectSolverMatrixViewType.LOWER,
            )
            solver = nvs.DirectSolver(a, b, options=options, execution="cuda")
            for key, value in (plan or {}).items():
                setattr(solver.plan_config, key, value)
            for key, value in (factor or {}).items():
                setattr(solver.factorization_config, key, value)
            synchronize()
            started = time.perf_counter()
            solver.plan()
            synchronize()
            record["analysis_s"] = time.perf_counter() - started
            record["factorize_s"], record["factorize_cpu_s"] = [], []
            for _ in range(3):
                cpu, started = time.process_time(), time.perf_counter()
                solver.factorize()
                synchronize()
                record["factorize_s"].append(time.perf_counter() - started)
                record["factorize_cpu_s"].append(time.process_time() - cpu)
            started = time.perf_counter()
            x = solver.solve().astype(np.float64)
            residuals = [float(cupy.linalg.norm(matrix @ x - rhs) / cupy.linalg.norm(rhs))]
            for _ in range(refinements):
                b[...] = (rhs - matrix @ x).astype(dtype)
                x = x + solver.solve().astype(np.float64)
                residuals.append(float(cupy.linalg.norm(matrix @ x - rhs) / cupy.linalg.norm(rhs)))
            synchronize()
            record["solve_s"] = time.perf_counter() - started
            record["residuals"] = residuals
            if reference is None:
                reference = x.copy()
            record["difference_to_default"] = float(
                cupy.linalg.norm(x - reference) / cupy.linalg.norm(reference)
            )
            solver.free()
        except Exception as exc:  # a setting this cuDSS does not support is reported, not fatal
            record["error"] = f"{type(exc).__name__}: {exc}"[:300]
        results.append(record)
        print(json.dumps(record), flush=True)
        write_report()

    measure("default (LDL^T, pivoting)")
    # Only the fill-reducing orderings meant for symmetric matrices: BTF_COLAMD did not finish
    # one analysis of the 367k-dof tangent in 8 minutes on an H100.
    measure(
        "reordering NESTED_DISSECTION",
        plan={"reordering_algorithm": cudss.ReorderingAlg.NESTED_DISSECTION},
    )
    for algorithm in ("MULTIBLOCK", "GENERAL"):
        measure(
            f"factorization {algorithm}",
            factor={"factorization_algorithm": getattr(cudss.FactorizationAlg, algorithm)},
        )
    measure("no pivoting", plan={"pivot_type": cudss.PivotType.PIVOT_NONE})
    measure("superpanels off", plan={"use_superpanels": False})
    measure("Cholesky (SPD)", system="SPD")
    measure("float32 LDL^T + 4 refinements", dtype=np.float32, refinements=4)
    measure("float32 Cholesky + 4 refinements", dtype=np.float32, system="SPD", refinements=4)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
