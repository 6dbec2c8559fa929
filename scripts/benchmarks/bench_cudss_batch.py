"""cuDSS on K problems' tangents: one block-diagonal matrix, a batch of matrices, or a loop.

Issue 23 asks which linear solve a batch of K independent problems should share on a GPU.
This benchmark takes K flat-punch problems on the benchmark's quarter block
(``bench_batch_fe.py``'s problems: one mesh, C10 from 0.8 to 1.2 times the benchmark's),
assembles their tangents at the undeformed state with the punch and symmetry conditions
eliminated, and times a factorization with a solve, three ways:

- ``block_diagonal``: the packed problems' one block-diagonal matrix, through
  :class:`warptissue.fem.linear.cudss.CudssSolver` (what :mod:`warptissue.fem.batched` does);
- ``batch``: the K diagonal blocks as a sequence of CSR matrices in one nvmath-python
  ``DirectSolver`` (cuDSS's batch API), with the same options;
- ``loop``: one :class:`~warptissue.fem.linear.cudss.CudssSolver` per problem, one after another
  (timed on the first ``--loop-limit`` problems and scaled to K);
- ``dense``: the K diagonal blocks as dense matrices, factorized and solved at once by
  cuSOLVER's batched dense LU (``cupy.linalg.solve`` on the ``(K, n, n)`` stack), where the
  stack fits in ``--dense-limit-gib`` of device memory; its "analysis" is the densification.

Each is timed over ``--repeat`` factorizations with solves after a warm-up, the device
synchronized; the analysis (reordering) is timed once. Every row also gives the largest
relative difference of the batch's and the loop's solutions from the block-diagonal one's.

Usage::

    python scripts/benchmarks/bench_cudss_batch.py --tets 9k --counts 1,8,32,128 \
        --out $OUT/bench_cudss_batch.json

It needs a CUDA device with nvmath-python and CuPy (the ``gpu`` extra); elsewhere it says so
and exits with status 5.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402
from bench_batch_fe import problems_for  # noqa: E402
from bench_flat_punch import machine_description, parse_count, warptissue_mesh  # noqa: E402

NO_DEVICE_STATUS = 5
"""Exit status without a CUDA device or the ``gpu`` extra (as the CLI's device errors)."""


def eliminated_tangent(problems: list[Any], device: str) -> tuple[Any, Any]:
    """The packed problems' assembler, its tangent at u = 0 with the Dirichlet rows and
    columns eliminated (identity there), and the packed meshes."""
    import warp as wp

    from warptissue.fem import batch_assembler
    from warptissue.fem.packing import pack_meshes

    packed = pack_meshes([problem.mesh for problem in problems])
    assembler = batch_assembler(problems, device=device)
    constrained = np.zeros((packed.mesh.node_count, 3))
    offsets = packed.node_offsets
    for k, problem in enumerate(problems):
        size = int(offsets[k + 1] - offsets[k])
        constrained[packed.nodes(k)] = problem.dirichlet_conditions().mask(size)
    assembler.assemble(np.zeros((packed.mesh.node_count, 3)))
    assembler.eliminate(wp.array(constrained, dtype=wp.vec3d, device=assembler.device))
    return assembler, packed


def timed(step: Any, repeat: int, synchronize: Any) -> float:
    """Mean seconds of ``step()`` over ``repeat`` calls after one warm-up call."""
    step()
    synchronize()
    start = time.perf_counter()
    for _ in range(repeat):
        step()
    synchronize()
    return (time.perf_counter() - start) / repeat


def block_diagonal(assembler: Any, rhs: Any, repeat: int, synchronize: Any) -> dict[str, Any]:
    from warptissue.fem.linear.cudss import CudssSolver

    start = time.perf_counter()
    solver = CudssSolver(assembler.matrix)
    synchronize()
    analysis = time.perf_counter() - start
    seconds = timed(lambda: solver.solve(rhs), repeat, synchronize)
    return {"analysis_s": analysis, "factor_solve_s": seconds, "x": solver.solve(rhs)}


def diagonal_blocks(
    offsets: Any,
    host_offsets: np.ndarray,
    columns: Any,
    values: Any,
    node_offsets: np.ndarray,
    csr_matrix: Any,
) -> list[Any]:
    """The K diagonal blocks of a block-diagonal scalar CSR matrix, as K CSR matrices.

    Args:
        offsets, columns, values: The matrix's CSR arrays (3 N + 1,), (nnz,), (nnz,), in one
            array library (NumPy or CuPy); the blocks' values are slices of ``values``.
        host_offsets: ``offsets`` as a NumPy array.
        node_offsets: First node of each problem, and the node count at the end, (K + 1,).
        csr_matrix: The library's CSR class (``scipy.sparse.csr_matrix`` or
            ``cupyx.scipy.sparse.csr_matrix``).

    Returns:
        Problem k's rows and columns ``3 node_offsets[k] : 3 node_offsets[k + 1]``, for each k.
    """
    blocks = []
    for first_node, last_node in zip(node_offsets[:-1], node_offsets[1:], strict=True):
        first, last = 3 * int(first_node), 3 * int(last_node)
        start, stop = int(host_offsets[first]), int(host_offsets[last])
        blocks.append(
            csr_matrix(
                (
                    values[start:stop],
                    columns[start:stop] - first,
                    offsets[first : last + 1] - start,
                ),
                shape=(last - first, last - first),
            )
        )
    return blocks


def batch(assembler: Any, packed: Any, rhs: Any, repeat: int, synchronize: Any) -> dict[str, Any]:
    """The K diagonal blocks of the union's CSR matrix as one batch of nvmath matrices."""
    import cupy
    import nvmath.sparse.advanced as nvs

    from warptissue.fem.linear.cudss import preload_cudss

    preload_cudss()
    matrix = assembler.matrix
    right = cupy.asarray(rhs).reshape(-1)
    matrices = _device_blocks(assembler, packed)
    sides = [
        cupy.ascontiguousarray(right[3 * int(first) : 3 * int(last)])
        for first, last in zip(packed.node_offsets[:-1], packed.node_offsets[1:], strict=True)
    ]
    options = nvs.DirectSolverOptions(
        sparse_system_type=nvs.DirectSolverMatrixType.SYMMETRIC,
        sparse_system_view=nvs.DirectSolverMatrixViewType.LOWER,
    )
    start = time.perf_counter()
    solver = nvs.DirectSolver(
        matrices,
        sides,
        options=options,
        execution=nvs.ExecutionCUDA(device_id=matrix.device.ordinal),
    )
    solver.plan()
    synchronize()
    analysis = time.perf_counter() - start

    def step() -> Any:
        solver.factorize()
        return solver.solve()

    seconds = timed(step, repeat, synchronize)
    solution = step()
    parts = solution if isinstance(solution, (list, tuple)) else [solution]
    x = cupy.concatenate([cupy.asarray(part).reshape(-1) for part in parts])
    solver.free()
    return {"analysis_s": analysis, "factor_solve_s": seconds, "x": x.reshape(-1, 3)}


def _device_blocks(assembler: Any, packed: Any) -> list[Any]:
    """The union's K diagonal blocks as K CuPy CSR matrices (values on the device)."""
    import cupy
    import cupyx.scipy.sparse
    import warp as wp

    from warptissue.fem.linear.cudss import bsr33_csr_pattern, bsr33_csr_values

    matrix = assembler.matrix
    offsets_wp, columns_wp, block_rows = bsr33_csr_pattern(matrix)
    values_wp = wp.zeros(columns_wp.shape[0], dtype=wp.float64, device=matrix.device)
    bsr33_csr_values(matrix, block_rows, values_wp)
    offsets, columns = cupy.asarray(offsets_wp), cupy.asarray(columns_wp)
    return diagonal_blocks(
        offsets,
        cupy.asnumpy(offsets),
        columns,
        cupy.asarray(values_wp),
        packed.node_offsets,
        cupyx.scipy.sparse.csr_matrix,
    )


def dense(
    assembler: Any, packed: Any, rhs: Any, repeat: int, synchronize: Any, limit_gib: float
) -> dict[str, Any]:
    """The K diagonal blocks densified into one ``(K, n, n)`` stack (the problems share a
    mesh, so n is one size) and solved by batched LU; refused above ``limit_gib``."""
    import cupy

    sizes = np.diff(packed.node_offsets) * 3
    n, count = int(sizes[0]), len(sizes)
    gib = count * n * n * 8 / 2**30
    if np.any(sizes != n) or gib > limit_gib:
        raise MemoryError(f"a dense stack of {count} x {n}^2 is {gib:.3g} GiB > {limit_gib} GiB")
    start = time.perf_counter()
    stack = cupy.stack([block.toarray() for block in _device_blocks(assembler, packed)])
    sides = cupy.asarray(rhs).reshape(count, n, 1)
    synchronize()
    densify = time.perf_counter() - start
    seconds = timed(lambda: cupy.linalg.solve(stack, sides), repeat, synchronize)
    x = cupy.linalg.solve(stack, sides)
    return {"analysis_s": densify, "factor_solve_s": seconds, "x": x.reshape(-1, 3)}


def loop(
    problems: list[Any], device: str, rhs: Any, packed: Any, repeat: int, synchronize: Any
) -> dict[str, Any]:
    """One solver per problem for the given (first) problems; times are for those alone."""
    import cupy

    from warptissue.fem.linear.cudss import CudssSolver

    solvers, sides = [], []
    start = time.perf_counter()
    for k, problem in enumerate(problems):
        assembler, _ = eliminated_tangent([problem], device)
        solvers.append(CudssSolver(assembler.matrix))
        sides.append(cupy.ascontiguousarray(rhs[packed.nodes(k)]))
    synchronize()
    analysis = time.perf_counter() - start
    seconds = timed(
        lambda: [s.solve(b) for s, b in zip(solvers, sides, strict=True)], repeat, synchronize
    )
    parts = [s.solve(b) for s, b in zip(solvers, sides, strict=True)]
    return {"analysis_s": analysis, "factor_solve_s": seconds, "x": cupy.concatenate(parts)}


def run(args: argparse.Namespace) -> dict[str, Any]:
    import cupy
    import warp as wp

    from warptissue.device import quiet_warp

    quiet_warp()
    wp.init()
    target = parse_count(args.tets)
    mesh, _ = warptissue_mesh(target, mesher="delaunay")
    rows = []
    synchronize = cupy.cuda.Device(wp.get_device(args.device).ordinal).synchronize
    for count in (parse_count(c) for c in args.counts.split(",")):
        problems = problems_for(mesh, count)
        assembler, packed = eliminated_tangent(problems, args.device)
        rng = np.random.default_rng(count)
        rhs = cupy.asarray(rng.standard_normal((packed.mesh.node_count, 3)))
        reference = block_diagonal(assembler, rhs, args.repeat, synchronize)
        row: dict[str, Any] = {
            "cells": mesh.tet_count,
            "problems": count,
            "dofs": 3 * packed.mesh.node_count,
        }
        scale = float(cupy.abs(reference["x"]).max())
        for name in ("block_diagonal", "batch", "loop", "dense"):
            try:
                if name == "block_diagonal":
                    result = reference
                elif name == "batch":
                    result = batch(assembler, packed, rhs, args.repeat, synchronize)
                elif name == "dense":
                    result = dense(
                        assembler, packed, rhs, args.repeat, synchronize, args.dense_limit_gib
                    )
                else:  # measured on the first --loop-limit problems, scaled to K
                    measured = min(count, args.loop_limit)
                    result = loop(
                        problems[:measured], args.device, rhs, packed, args.repeat, synchronize
                    )
                    result["analysis_s"] *= count / measured
                    result["factor_solve_s"] *= count / measured
            except Exception as exc:  # a way that fails is a row entry, not the end of the run
                row[f"{name}_error"] = f"{type(exc).__name__}: {exc}"
                continue
            row[f"{name}_analysis_s"] = result["analysis_s"]
            row[f"{name}_factor_solve_s"] = result["factor_solve_s"]
            x = cupy.asarray(result["x"])
            difference = cupy.abs(x - reference["x"][: x.shape[0]]).max()
            row[f"{name}_difference"] = float(difference) / scale
        print(json.dumps(row), flush=True)
        rows.append(row)
    return {"label": args.label, "machine": machine_description(), "runs": rows}


def markdown(all_results: list[dict[str, Any]]) -> str:
    """The rows of result sets (as :func:`run` returns them) as one Markdown table."""
    lines = [
        "| run | cells | problems | DOFs | block-diagonal ms | batch ms | loop ms | dense ms "
        "| analysis s: block-diagonal, batch, loop, dense | largest difference |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---|---:|",
    ]
    for results in all_results:
        for row in results["runs"]:

            def ms(name: str, row: dict[str, Any] = row) -> str:
                value = row.get(f"{name}_factor_solve_s")
                if value is None:  # failed in this run, or not a way of that run's version
                    return "failed" if f"{name}_error" in row else "-"
                return f"{1e3 * value:.3g}"

            def analysis(name: str, row: dict[str, Any] = row) -> str:
                value = row.get(f"{name}_analysis_s")
                return "-" if value is None else f"{value:.2g}"

            difference = max(
                (row.get(f"{name}_difference", 0.0) for name in ("batch", "loop", "dense")),
                default=0.0,
            )
            cells, dofs = (f"{row[key]:,}".replace(",", " ") for key in ("cells", "dofs"))
            lines.append(
                f"| {results['label']} | {cells} | {row['problems']} | {dofs} "
                f"| {ms('block_diagonal')} | {ms('batch')} | {ms('loop')} | {ms('dense')} "
                f"| {analysis('block_diagonal')}, {analysis('batch')}, {analysis('loop')}, "
                f"{analysis('dense')} "
                f"| {difference:.1e} |"
            )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--device", default="cuda:0", help="CUDA device")
    parser.add_argument("--tets", default="9k", help="target tet count of the mesh")
    parser.add_argument("--counts", default="1,8,32", help="problem counts K, comma separated")
    parser.add_argument("--repeat", type=int, default=5, help="timed factorizations per way")
    parser.add_argument(
        "--loop-limit",
        type=int,
        default=8,
        help="time the loop on at most this many problems and scale it to K",
    )
    parser.add_argument(
        "--dense-limit-gib",
        type=float,
        default=16.0,
        help="largest dense stack (K n^2 float64) the dense way may allocate, GiB",
    )
    parser.add_argument("--label", default="", help="name of this machine in the tables")
    parser.add_argument("--out", type=Path, help="write the results as JSON here")
    parser.add_argument("--markdown", nargs="+", type=Path, help="print result files as a table")
    args = parser.parse_args(argv)
    if args.markdown:
        print(markdown([json.loads(path.read_text()) for path in args.markdown]))
        return 0
    try:
        import cupy  # noqa: F401
        import nvmath  # noqa: F401
        import warp as wp
    except ImportError as exc:
        print(
            f"bench_cudss_batch: needs the gpu extra (nvmath-python, CuPy): {exc}", file=sys.stderr
        )
        return NO_DEVICE_STATUS
    if not wp.is_cuda_available():
        print("bench_cudss_batch: needs a CUDA device; none is available", file=sys.stderr)
        return NO_DEVICE_STATUS
    results = run(args)
    if args.out:
        from warptissue.io import write_json

        write_json(args.out, results)
    print(markdown([results]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
