"""A rigid sphere on a large nearly incompressible neo-Hookean block against Hertz (issue 21).

A frictionless rigid sphere (radius R = 1 mm, penalty contact, :mod:`warptissue.fem.contact`)
indents the centre of a quarter block (neo-Hookean, C10 = 500 Pa, K = 1000 mu, so E = 6 C10
and nu -> 0.5) bonded to a rigid base. The mesh is refined within the contact radius
a = sqrt(R d) of the deepest Hertz depth. Printed per depth: the FE force (the base reaction,
with the contact force sum beside it), Hertz's F = (16/9) E sqrt(R) d^(3/2), their ratio, the
ratio to Hertz times Dimitriadis et al.'s (2002) factor for a bonded layer of the block's
thickness (what remains is discretization error), the largest penetration over the depth and
Newton's iterations. Depths 0.1-0.3 R show the large-depth departure from Hertz.

Usage:
    python scripts/examples/hertz_sphere.py [--quick] [--out hertz_sphere.json]

Measured on the 2-core CPU (full run: block 16 R wide and 8 R thick, 21 053 TET10 nodes,
844 s): F / Hertz = 0.983, 0.990, 0.999, 0.995, 1.001, 1.001 at d/R = 0.005, 0.01, 0.02,
0.03, 0.04, 0.045 (within 1.7 %), 0.998, 0.998, 0.990 at 0.1, 0.2, 0.3; against Hertz times
the layer factor 0.97-0.98 at small depth (docs/fe.md "Contact" has the table). ``--quick``
(under a minute) runs a 3 R x 1.5 R block at two depths.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from warptissue.fem import IndentationProblem, simulate_indentation
from warptissue.indenter import Indenter
from warptissue.materials import NeoHookean
from warptissue.mesh import indentation_block

RADIUS_M = 1e-3
C10_PA = 500.0


def hertz_N(depth_m: np.ndarray) -> np.ndarray:
    """Hertz's rigid sphere on an incompressible half-space: (16/9) E sqrt(R) d^(3/2)."""
    return 16.0 / 9.0 * 6.0 * C10_PA * np.sqrt(RADIUS_M) * depth_m**1.5


def dimitriadis_factor(depth_m: np.ndarray, thickness_m: float) -> np.ndarray:
    """Dimitriadis et al. (2002, Biophys. J. 82): bonded layer, nu = 0.5, chi = sqrt(R d)/h."""
    chi = np.sqrt(RADIUS_M * depth_m) / thickness_m
    return 1 + 1.133 * chi + 1.283 * chi**2 + 0.769 * chi**3 + 0.0975 * chi**4


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a small block, two depths")
    parser.add_argument("--out", default=None, help="write the table as JSON here")
    args = parser.parse_args()
    if args.quick:
        thickness, width, near, far = 1.5, 3.0, 0.5, 0.6
        ratios = np.array([0.02, 0.04])
    else:
        thickness, width, near, far = 8.0, 16.0, 0.3, 1.0
        ratios = np.array([0.005, 0.01, 0.02, 0.03, 0.04, 0.045, 0.1, 0.2, 0.3])
    hertz_depths = ratios[ratios < 0.05] * RADIUS_M
    contact_radius = float(np.sqrt(RADIUS_M * hertz_depths.max()))
    mesh = indentation_block(
        width_m=width * RADIUS_M,
        thickness_m=thickness * RADIUS_M,
        probe_radius_m=contact_radius,
        size_near_m=near * contact_radius,
        size_far_m=far * RADIUS_M,
    )
    material = NeoHookean(C10_PA, 1000.0 * 2.0 * C10_PA)
    problem = IndentationProblem(mesh, material, Indenter("sphere", radius_m=RADIUS_M))
    depths = ratios * RADIUS_M
    start = time.perf_counter()
    result = simulate_indentation(problem, depths, device="cpu", progress=False)
    seconds = time.perf_counter() - start
    count = len(result.depths_m)
    hertz = hertz_N(depths[:count])
    corrected = hertz * dimitriadis_factor(depths[:count], thickness * RADIUS_M)
    print(
        f"sphere R = {RADIUS_M * 1e3:g} mm on a {width:g} R x {thickness:g} R quarter block, "
        f"{mesh.node_count} TET10 nodes, {mesh.tet_count} tets, {seconds:.0f} s on the CPU; "
        f"{result.message}"
    )
    print("d/R     F_FE (N)     F_contact (N)  F/Hertz  F/(Hertz*Dimitriadis)  pen/d    Newton")
    rows = []
    for i in range(count):
        row = {
            "depth_over_radius": float(ratios[i]),
            "force_N": float(result.reaction_force_N[i]),
            "contact_force_N": float(result.contact_force_N[i]),
            "hertz_N": float(hertz[i]),
            "force_over_hertz": float(result.reaction_force_N[i] / hertz[i]),
            "force_over_corrected_hertz": float(result.reaction_force_N[i] / corrected[i]),
            "penetration_over_depth": float(result.max_penetration_m[i] / depths[i]),
            "newton_iterations": int(result.newton_iterations[i]),
        }
        rows.append(row)
        print(
            f"{ratios[i]:<7.3f} {row['force_N']:<12.5e} {row['contact_force_N']:<14.5e} "
            f"{row['force_over_hertz']:<8.4f} {row['force_over_corrected_hertz']:<22.4f} "
            f"{row['penetration_over_depth']:<8.1e} {row['newton_iterations']}"
        )
    if args.out:
        from warptissue.io import write_json

        write_json(
            args.out,
            {
                "nodes": mesh.node_count,
                "tets": mesh.tet_count,
                "seconds": seconds,
                "thickness_over_radius": thickness,
                "width_over_radius": width,
                "rows": rows,
            },
        )


if __name__ == "__main__":
    main()
