"""Flat-punch verification study for the FE core (README "Finite elements").

Runs, on the CPU:

1. mesh convergence of the small-depth punch stiffness (TET10 mean dilatation, bonded punch,
   thickness h = 4a, K/mu = 1000), with the observed order and a Richardson extrapolation;
2. the stiffness against Sneddon's 8 mu a for h/a = 2, 4, 8, with Shull's (2002) finite-layer
   factor and an extrapolation of the FE stiffness to the half-space (a/h -> 0);
3. the change of the stiffness as K/mu goes 100 -> 10,000;
4. the locking contrast: displacement-only TET4 vs TET10 mean dilatation;
5. how deep the bonded punch goes before the cutbacks run out;
6. timings of one ~20k-tet TET10 problem: assembly, and one linear solve with PARDISO and SuperLU.

Usage:
    python scripts/verify_flat_punch.py --out runs/verify_flat_punch.json [--quick]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from warptissue.fem import (
    Assembler,
    FlatPunch,
    IndentationProblem,
    LinearSolver,
    simulate_indentation,
)
from warptissue.io import write_json
from warptissue.materials import NeoHookean
from warptissue.mesh import indentation_block

RADIUS_M = 1e-3
SHEAR_MODULUS_PA = 200.0
DEPTH_M = 2e-3 * RADIUS_M


def block(thickness_over_radius: float, near: float, element: str = "TET10"):
    thickness = thickness_over_radius * RADIUS_M
    return indentation_block(
        width_m=4.0 * thickness,
        thickness_m=thickness,
        probe_radius_m=RADIUS_M,
        element=element,
        size_near_m=near * RADIUS_M,
        size_far_m=thickness / 3.0,
    )


def material(bulk_over_shear: float) -> NeoHookean:
    return NeoHookean(SHEAR_MODULUS_PA / 2.0, bulk_over_shear * SHEAR_MODULUS_PA)


def normalized_stiffness(mesh, bulk_over_shear=1000.0, formulation="mixed", contact="bonded"):
    """Small-depth stiffness over Sneddon's half-space value 8 mu a."""
    problem = IndentationProblem(
        mesh,
        material(bulk_over_shear),
        FlatPunch(RADIUS_M, contact=contact),
        formulation=formulation,
    )
    result = simulate_indentation(problem, [DEPTH_M], device="cpu", progress=False)
    if not result.completed:
        raise RuntimeError(result.message)
    return result.reaction_force_N[0] / DEPTH_M / (8.0 * SHEAR_MODULUS_PA * RADIUS_M)


def shull_factor(radius_over_thickness: float) -> float:
    """Shull (2002) finite-layer factor for an incompressible layer bonded to a rigid base."""
    x = radius_over_thickness
    return 1.0 + 1.33 * x + 1.33 * x**3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="runs/verify_flat_punch.json")
    parser.add_argument("--quick", action="store_true", help="skip the finest mesh and timings")
    args = parser.parse_args()
    report: dict = {
        "radius_m": RADIUS_M,
        "shear_modulus_Pa": SHEAR_MODULUS_PA,
        "depth_m": DEPTH_M,
        "machine": "2-core x86_64 CPU (shared)",
    }

    sizes = [1.0, 0.5, 0.25] if args.quick else [1.0, 0.5, 0.25, 0.125]
    convergence = []
    for near in sizes:
        mesh = block(4.0, near)
        start = time.perf_counter()
        k = normalized_stiffness(mesh)
        convergence.append(
            {
                "size_near_over_a": near,
                "tets": mesh.tet_count,
                "k_over_8mua": k,
                "seconds": time.perf_counter() - start,
            }
        )
        print(convergence[-1], flush=True)
    k = np.array([c["k_over_8mua"] for c in convergence])
    order = float(np.log2(abs(k[-2] - k[-3]) / abs(k[-1] - k[-2])))
    extrapolated = float(k[-1] + (k[-1] - k[-2]) / (2.0**order - 1.0))
    report["mesh_convergence"] = {
        "levels": convergence,
        "observed_order": order,
        "richardson_k_over_8mua": extrapolated,
        "shull_k_over_8mua": shull_factor(0.25),
    }
    print(report["mesh_convergence"], flush=True)

    thickness_study = []
    for h_over_a in (2.0, 4.0, 8.0):
        k_fe = normalized_stiffness(block(h_over_a, 0.25))
        thickness_study.append(
            {"h_over_a": h_over_a, "k_over_8mua": k_fe, "shull": shull_factor(1.0 / h_over_a)}
        )
        print(thickness_study[-1], flush=True)
    x = np.array([1.0 / t["h_over_a"] for t in thickness_study])
    fit = np.linalg.solve(
        np.column_stack([np.ones(3), x, x**3]), [t["k_over_8mua"] for t in thickness_study]
    )
    report["sneddon"] = {
        "thicknesses": thickness_study,
        "half_space_extrapolation_k_over_8mua": float(fit[0]),
        "fitted_linear_coefficient": float(fit[1]),
    }
    print(report["sneddon"], flush=True)

    mesh = block(4.0, 0.25)
    bulk = {str(r): normalized_stiffness(mesh, r) for r in (100.0, 1000.0, 10000.0)}
    report["bulk_modulus_sensitivity"] = {
        "k_over_8mua": bulk,
        "change_100_to_10000": bulk["10000.0"] / bulk["100.0"] - 1.0,
    }
    print(report["bulk_modulus_sensitivity"], flush=True)

    locking = []
    for near in (0.5, 0.25):
        locking.append(
            {
                "size_near_over_a": near,
                "tet4_displacement": normalized_stiffness(
                    block(4.0, near, "TET4"), formulation="displacement"
                ),
                "tet10_displacement": normalized_stiffness(
                    block(4.0, near), formulation="displacement"
                ),
                "tet10_mixed": normalized_stiffness(block(4.0, near)),
            }
        )
        print(locking[-1], flush=True)
    report["locking_K_over_mu_1000"] = locking

    reach = []
    for near in (0.5, 0.25):
        mesh = block(4.0, near)
        problem = IndentationProblem(mesh, material(1000.0), FlatPunch(RADIUS_M))
        depths = RADIUS_M * np.arange(0.05, 2.001, 0.05)
        start = time.perf_counter()
        result = simulate_indentation(problem, depths, device="cpu", progress=False, max_cutbacks=3)
        reach.append(
            {
                "size_near_over_a": near,
                "tets": mesh.tet_count,
                "deepest_over_a": float(result.depths_m[-1] / RADIUS_M),
                "force_at_deepest_N": float(result.reaction_force_N[-1]),
                "completed": result.completed,
                "message": result.message,
                "seconds": time.perf_counter() - start,
            }
        )
        print(reach[-1], flush=True)
    report["bonded_depth_reach"] = reach

    if not args.quick:
        mesh = block(4.0, 0.125)
        assembler = Assembler(mesh, material(1000.0), device="cpu")
        u = np.zeros((mesh.node_count, 3))
        assembler.assemble(u)
        start = time.perf_counter()
        assembler.assemble(u)
        assemble_s = time.perf_counter() - start
        rhs = np.random.default_rng(0).standard_normal((mesh.node_count, 3))
        import warp as wp

        problem = IndentationProblem(mesh, material(1000.0), FlatPunch(RADIUS_M))
        mask = problem.dirichlet_conditions().mask(mesh.node_count)
        assembler.eliminate(wp.array(mask, dtype=wp.vec3d, device=assembler.device))
        solves = {}
        for method in ("pardiso", "superlu"):
            start = time.perf_counter()
            LinearSolver(method=method, device=assembler.device).solve(assembler.matrix, rhs)
            solves[method] = time.perf_counter() - start
            print(method, solves[method], flush=True)
        report["timing_20k_tet10"] = {
            "tets": mesh.tet_count,
            "nodes": mesh.node_count,
            "dofs": 3 * mesh.node_count,
            "assembly_with_tangent_s": assemble_s,
            "linear_solve_s": solves,
        }
        print(report["timing_20k_tet10"], flush=True)
    write_json(args.out, report)


if __name__ == "__main__":
    main()
