"""Time the parts of one Newton iteration of the flat-punch benchmark on a CUDA device.

For each mesh size: tangent assembly, residual-only assembly, Dirichlet elimination, the BSR
-> CSR copy, cuDSS numerical factorization and solve (after one analysis), and one BSR
matrix-vector product, each synchronized and repeated;
plus the bytes each part must move at least, so that its time can be set against the
memory-bandwidth floor (``--bandwidth-GBps``, measured device-to-device copy rate).
Where the factors do not fit in the free device memory, cuDSS runs in its hybrid memory mode
(factors in host memory; ``hybrid_memory`` in the record); where they fit in neither, the
record carries cuDSS's refusal instead of factorization timings.

Example:
    python scripts/profile_newton_cuda.py --sizes 10k,100k --out $OUT/profile.json
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_flat_punch import (  # noqa: E402
    BULK_MODULUS_PA,
    SHEAR_MODULUS_PA,
    SIZE_TARGETS,
    parse_count,
    warptissue_mesh,
)


def timed(function, device, repeats: int) -> float:
    """Median seconds of ``function()`` over ``repeats`` synchronized runs (after one warm-up)."""
    import warp as wp

    function()
    wp.synchronize_device(device)
    samples = []
    for _ in range(repeats):
        started = time.perf_counter()
        function()
        wp.synchronize_device(device)
        samples.append(time.perf_counter() - started)
    return statistics.median(samples)


def profile(target_tets: int, device_name: str, repeats: int, bandwidth: float) -> dict:
    import warp as wp
    import warp.sparse as wps

    from warptissue.errors import DeviceError
    from warptissue.fem import Assembler
    from warptissue.fem.cudss import CudssSolver, bsr33_csr_values
    from warptissue.materials import NeoHookean

    started = time.perf_counter()
    mesh, _ = warptissue_mesh(target_tets)
    mesh_s = time.perf_counter() - started
    device = wp.get_device(device_name)
    started = time.perf_counter()
    assembler = Assembler(
        mesh,
        NeoHookean(C10_Pa=0.5 * SHEAR_MODULUS_PA, bulk_modulus_Pa=BULK_MODULUS_PA),
        formulation="mixed",
        device=device,
    )
    assembler_s = time.perf_counter() - started
    rng = np.random.default_rng(1)
    u = wp.array(1e-6 * rng.standard_normal((mesh.node_count, 3)), dtype=wp.vec3d, device=device)
    constrained = np.zeros((mesh.node_count, 3))
    constrained[mesh.node_set("bottom")] = 1.0
    constrained_wp = wp.array(constrained, dtype=wp.vec3d, device=device)
    rhs = rng.standard_normal((mesh.node_count, 3)) * (1.0 - constrained)
    blocks = assembler.block_count
    k = assembler.matrix
    assembly_parts = {
        "assemble_tangent_s": timed(lambda: assembler.assemble(u), device, repeats),
        "assemble_residual_s": timed(
            lambda: assembler.assemble(u, with_tangent=False), device, repeats
        ),
    }
    assembler.assemble(u)
    eliminate_s = timed(lambda: assembler.eliminate(constrained_wp), device, repeats)
    vector = wp.array(rhs, dtype=wp.vec3d, device=device)
    applied = wp.zeros_like(vector)
    bsr_mv_s = timed(lambda: wps.bsr_mv(k, vector, applied), device, repeats)
    started = time.perf_counter()
    try:
        solver = CudssSolver(assembler.matrix)
    except DeviceError as exc:
        # Too large for this device and host even in cuDSS's hybrid memory mode.
        solver, refusal = None, str(exc)
    wp.synchronize_device(device)
    analysis_s = time.perf_counter() - started
    tets = mesh.tet_count
    # Fewest bytes per part: the tangent assembly reads the element data (tets, shape
    # gradients, quadrature volumes, displacements) and read-modify-writes every BSR block it
    # touches (100 blocks x 4 points per TET10, 9 float64 each, read and written).
    bytes_tangent = tets * (10 * 4 + 4 * 10 * 3 * 8 + 4 * 8 + 10 * 24) + 2 * blocks * 72
    bytes_csr = blocks * (72 + 72 + 4)
    record = {
        "tets": tets,
        "nodes": mesh.node_count,
        "dofs": 3 * mesh.node_count,
        "bsr_blocks": blocks,
        "csr_nnz": 9 * blocks,
        "mesh_s": mesh_s,
        "assembler_setup_s": assembler_s,
        "analysis_s": analysis_s,
        **assembly_parts,
        "eliminate_s": eliminate_s,
        "bsr_mv_s": bsr_mv_s,
        "assemble_tangent_floor_s": bytes_tangent / (bandwidth * 1e9),
        "bsr_to_csr_floor_s": bytes_csr / (bandwidth * 1e9),
    }
    if solver is None:
        record["cudss_refused"] = refusal
        return record
    record["memory_estimates_bytes"] = solver.memory_estimates
    record["hybrid_memory"] = solver.hybrid_memory
    record["bsr_to_csr_s"] = timed(
        lambda: bsr33_csr_values(k, solver._block_rows, solver._csr_values), device, repeats
    )
    record["factorize_and_solve_s"] = timed(lambda: solver.solve(rhs), device, repeats)
    x = solver.solve(rhs)
    values = k.values.numpy()[:blocks]
    product = np.zeros_like(rhs)
    rows = np.repeat(np.arange(mesh.node_count), np.diff(k.offsets.numpy()[: mesh.node_count + 1]))
    np.add.at(product, rows, np.einsum("bij,bj->bi", values, x[k.columns.numpy()[:blocks]]))
    record["relative_residual_of_solve"] = float(
        np.linalg.norm(product - rhs) / np.linalg.norm(rhs)
    )
    record["factor_nnz"] = int(getattr(solver._solver.factorization_info, "lu_nnz", -1))
    solver.free()
    return record


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--device", default="cuda:0")
    parser.add_argument("--sizes", default="10k,100k")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--bandwidth-GBps", type=float, default=3000.0, dest="bandwidth")
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args(argv)
    import warp as wp

    wp.config.quiet = True
    records = []
    for size in [s.strip().lower() for s in args.sizes.split(",") if s.strip()]:
        target = SIZE_TARGETS.get(size) or parse_count(size)
        record = profile(target, args.device, args.repeats, args.bandwidth)
        records.append(record)
        print(json.dumps(record))
        sys.stdout.flush()
    if args.out is not None:
        from warptissue.io import write_json

        write_json(args.out, {"device": args.device, "records": records})
    return 0


if __name__ == "__main__":
    sys.exit(main())
