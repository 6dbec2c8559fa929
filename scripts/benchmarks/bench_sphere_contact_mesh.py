"""Mesh convergence of a rigid sphere's force: node-to-surface against surface-integrated
contact (issue 44) on a quarter block under a sphere, at three near sizes.

R = 1 mm, neo-Hookean C10 = 500 Pa, K = 1000 mu, a quarter block 3 R wide and 1.5 R thick
bonded to a rigid base, refined within 1.5 sqrt(R d_max); F / Hertz at each depth (no layer
correction: the mesh's dependence is the point, the same block throughout) and Newton
iterations per depth.

Usage:
    python scripts/benchmarks/bench_sphere_contact_mesh.py --near 0.15 0.1 0.075 \
        --integration nodes surface [--penalty 1000]
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
DEPTHS_OVER_R = np.array([0.005, 0.01, 0.02, 0.04])


def hertz_N(depth_m: np.ndarray) -> np.ndarray:
    """Hertz, nu -> 0.5 (K = 1000 mu: nu = 0.4995), E = 2 mu (1 + nu)."""
    nu = (3.0 * 1000.0 - 2.0) / (2.0 * (3.0 * 1000.0 + 1.0))
    reduced = 2.0 * 2.0 * C10_PA * (1.0 + nu) / (1.0 - nu**2)
    return 4.0 / 3.0 * reduced * np.sqrt(RADIUS_M) * depth_m**1.5


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--near", type=float, nargs="+", default=[0.15, 0.1, 0.075])
    parser.add_argument("--integration", nargs="+", default=["nodes", "surface"])
    parser.add_argument("--penalty", type=float, default=1000.0)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--progress", action="store_true", help="print each Newton step")
    args = parser.parse_args()
    zone = 1.5 * np.sqrt(RADIUS_M * DEPTHS_OVER_R.max() * RADIUS_M)
    for near in args.near:
        mesh = indentation_block(
            width_m=3.0 * RADIUS_M,
            thickness_m=1.5 * RADIUS_M,
            probe_radius_m=zone,
            size_near_m=near * RADIUS_M,
            size_far_m=0.6 * RADIUS_M,
        )
        for integration in args.integration:
            problem = IndentationProblem(
                mesh,
                NeoHookean(C10_PA, 2000.0 * C10_PA),
                Indenter("sphere", radius_m=RADIUS_M),
                contact_integration=integration,
                penalty_factor=args.penalty,
            )
            start = time.perf_counter()
            result = simulate_indentation(
                problem, DEPTHS_OVER_R * RADIUS_M, device=args.device, progress=args.progress
            )
            seconds = time.perf_counter() - start
            count = len(result.reaction_force_N)
            depths = DEPTHS_OVER_R[:count] * RADIUS_M
            ratio = result.reaction_force_N / hertz_N(depths)
            print(
                f"near {near:g} R  {integration:8s} nodes {mesh.node_count} {seconds:.0f} s "
                f"F/Hertz {np.round(ratio, 4).tolist()} "
                f"pen/d {np.round(result.max_penetration_m / depths, 5).tolist()} "
                f"its {np.asarray(result.newton_iterations).tolist()} "
                + ("" if result.completed else result.message),
                flush=True,
            )


if __name__ == "__main__":
    main()
