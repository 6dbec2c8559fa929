"""Benchmark: write a 100k-tet simulation result with 20 time samples as USD.

    python scripts/benchmarks/bench_usd.py [--cells 26 26 25] [--steps 20]

Prints the tet count, the write time of write_simulation_usd (asset .usda + results .usdc +
root), the size of each layer, and the time to open the stage and read every time sample of
the points back. The result arrays are synthetic (a smooth indentation-like field), since the
point is the I/O cost, not the physics.
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

from warptissue.indenter import Indenter
from warptissue.mesh import TetMesh, block_mesh
from warptissue.usd import validate_stage, write_simulation_usd


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, nargs=3, default=(26, 26, 25))
    parser.add_argument("--steps", type=int, default=20)
    args = parser.parse_args()
    nx, ny, nz = args.cells
    blocks = block_mesh(
        np.linspace(-0.02, 0.02, nx + 1),
        np.linspace(-0.02, 0.02, ny + 1),
        np.linspace(0, 0.02, nz + 1),
    )
    # One material region (block_mesh numbers every hexahedron as its own region).
    mesh = TetMesh(
        points=blocks.points,
        tets=blocks.tets,
        node_sets=blocks.node_sets,
        face_sets=blocks.face_sets,
    )
    depth = np.linspace(1e-4, 2e-3, args.steps)
    r2 = mesh.points[:, 0] ** 2 + mesh.points[:, 1] ** 2
    shape = np.exp(-r2 / 1e-4) * (mesh.points[:, 2] / 0.02)
    displacement = np.zeros((args.steps, mesh.node_count, 3))
    displacement[:, :, 2] = -depth[:, None] * shape[None, :]
    rng = np.random.default_rng(0)
    result = {
        "depths_m": depth,
        "reaction_force_N": 50.0 * depth**1.5,
        "displacement_m": displacement,
        "cauchy_stress_Pa": rng.normal(size=(mesh.tet_count, 6)),
        "von_mises_Pa": rng.uniform(size=mesh.tet_count),
    }
    material = {"model": "neo_hookean", "C10_Pa": 287.5, "bulk_modulus_Pa": 2.9e4}
    with tempfile.TemporaryDirectory() as folder:
        started = time.perf_counter()
        paths = write_simulation_usd(
            Path(folder) / "bench.usda",
            mesh,
            material=material,
            result=result,
            indenter=Indenter("flat_punch", radius_m=1e-3),
        )
        written = time.perf_counter() - started
        from pxr import Usd, UsdGeom

        started = time.perf_counter()
        stage = Usd.Stage.Open(str(paths.root))
        points = UsdGeom.TetMesh(stage.GetPrimAtPath("/World/Specimen/Volume")).GetPointsAttr()
        for t in points.GetTimeSamples():
            points.Get(t)
        read = time.perf_counter() - started
        started = time.perf_counter()
        findings = validate_stage(paths.root)
        validated = time.perf_counter() - started
        sizes = {p.name: p.stat().st_size / 2**20 for p in (paths.root, paths.asset, paths.results)}
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores")
    print(f"tets {mesh.tet_count}, nodes {mesh.node_count}, time samples {args.steps} (+ rest)")
    print(f"write_simulation_usd: {written:.2f} s")
    for name, size in sizes.items():
        print(f"  {name}: {size:.2f} MiB")
    print(f"open + read all point samples: {read:.2f} s")
    print(f"validate_stage: {validated:.2f} s, {len(findings)} findings")


if __name__ == "__main__":
    main()
