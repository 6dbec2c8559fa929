"""Benchmark the indentation mesh generator, the quality check and VTU output.

One refinement factor f scales both element sizes (size_near = 0.5 mm / f, size_far =
4 mm / f) of a quarter 40 x 40 x 20 mm block under a 2.5 mm radius probe; f = 1 gives about
10k tets and f = 6.5 about 1M.

    python scripts/benchmarks/bench_mesh.py --factors 1 2 4 6.5 --out runs/bench_mesh.json
    python scripts/benchmarks/bench_mesh.py --mesher delaunay --factors 1 2 4 8
"""

from __future__ import annotations

import argparse
import platform
import tempfile
import time
from pathlib import Path

from warptissue.io import software_versions, write_json
from warptissue.mesh import check_mesh, indentation_block, write_mesh


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--factors", type=float, nargs="+", default=[1.0, 2.0, 4.0, 6.5])
    parser.add_argument("--element", choices=("TET4", "TET10"), default="TET10")
    parser.add_argument("--mesher", choices=("extruded", "delaunay"), default="extruded")
    parser.add_argument("--out", type=Path, help="JSON file for the results")
    args = parser.parse_args()

    rows = []
    print(f"{'factor':>7} {'tets':>9} {'nodes':>9} {'generate_s':>11} {'check_s':>8} "
          f"{'write_vtu_s':>11} {'min_ratio':>9} {'min_dihedral':>12}")  # fmt: skip
    for factor in args.factors:
        start = time.perf_counter()
        mesh = indentation_block(
            width_m=0.04,
            thickness_m=0.02,
            probe_radius_m=0.0025,
            element=args.element,
            size_near_m=0.0005 / factor,
            size_far_m=0.004 / factor,
            mesher=args.mesher,
        )
        generated = time.perf_counter()
        quality = check_mesh(mesh)
        checked = time.perf_counter()
        with tempfile.TemporaryDirectory() as folder:
            write_mesh(Path(folder) / "mesh.vtu", mesh)
        written = time.perf_counter()
        row = {
            "refinement_factor": factor,
            "element": args.element,
            "mesher": args.mesher,
            "tet_count": mesh.tet_count,
            "node_count": mesh.node_count,
            "generate_s": generated - start,
            "check_mesh_s": checked - generated,
            "write_vtu_s": written - checked,
            "quality": quality.to_dict(),
        }
        rows.append(row)
        print(f"{factor:7.2f} {mesh.tet_count:9d} {mesh.node_count:9d} {row['generate_s']:11.2f} "
              f"{row['check_mesh_s']:8.2f} {row['write_vtu_s']:11.2f} "
              f"{quality.min_radius_ratio:9.3f} {quality.min_dihedral_deg:12.1f}")  # fmt: skip
    if args.out:
        write_json(
            args.out,
            {"machine": platform.machine(), "results": rows, "software": software_versions()},
        )


if __name__ == "__main__":
    main()
