"""Flat-punch verification study for the FE core (README "Finite elements").

Runs, on the CPU:

1. mesh convergence of the small-depth punch stiffness (TET10 mean dilatation, frictionless and
   bonded punch, thickness h = 4a, block width 8h, K/mu = 1000), with the observed order and a
   Richardson extrapolation, against Sneddon's 8 mu a times the finite-layer factor of Hayes et
   al. (1972) that ``warptissue.fit.punch.hayes_kappa`` computes (layer of infinite extent bonded
   to a rigid base, frictionless punch), and against Shull's (2002) fitted factor;
2. the effect of the block's finite width (4h, 8h, 16h);
3. the stiffness for h/a = 2, 4, 8 against the same factors, and an extrapolation of the FE
   stiffness to the half-space (a/h -> 0);
4. the change of the stiffness as K/mu goes 100 -> 10,000;
5. the locking contrast: displacement-only TET4 vs TET10 mean dilatation;
6. how deep the bonded punch goes before the cutbacks run out;
7. timings of one ~20k-tet TET10 problem: assembly, and one linear solve with PARDISO and SuperLU.

Usage:
    python scripts/examples/verify_flat_punch.py --out runs/verify_flat_punch.json [--quick]

The full study takes tens of minutes on a 2-core CPU. ``--quick`` (under a minute) runs only
the two coarsest meshes of study 1, without the extrapolation, and the locking contrast (5)
on the coarser of them.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from warptissue.fem import (
    Assembler,
    IndentationProblem,
    LinearSolver,
    NewtonOptions,
    simulate_indentation,
)
from warptissue.fit.punch import hayes_kappa
from warptissue.indenter import Indenter
from warptissue.io import write_json
from warptissue.materials import NeoHookean
from warptissue.mesh import indentation_block

RADIUS_M = 1e-3
SHEAR_MODULUS_PA = 200.0
DEPTH_M = 2e-3 * RADIUS_M


def block(
    thickness_over_radius: float,
    near: float,
    element: str = "TET10",
    *,
    width_over_thickness: float = 4.0,
):
    thickness = thickness_over_radius * RADIUS_M
    return indentation_block(
        width_m=width_over_thickness * thickness,
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
        Indenter("flat_punch", radius_m=RADIUS_M, contact=contact),
        formulation=formulation,
    )
    result = simulate_indentation(problem, [DEPTH_M], device="cpu", progress=False)
    if not result.completed:
        raise RuntimeError(result.message)
    return float(result.reaction_force_N[0] / DEPTH_M / (8.0 * SHEAR_MODULUS_PA * RADIUS_M))


def hayes_factor(radius_over_thickness: float, bulk_over_shear: float = 1000.0) -> float:
    """Hayes et al. (1972) finite-layer factor at the material's Poisson's ratio (computed)."""
    poissons_ratio = (3.0 * bulk_over_shear - 2.0) / (6.0 * bulk_over_shear + 2.0)
    return hayes_kappa(radius_over_thickness, poissons_ratio)


def shull_factor(radius_over_thickness: float) -> float:
    """Shull's (2002) fit for an incompressible layer bonded to a rigid base, for comparison."""
    x = radius_over_thickness
    return 1.0 + 1.33 * x + 1.33 * x**3


def locking_contrast(near: float) -> dict:
    """Small-depth stiffness of displacement TET4, displacement TET10 and mixed TET10."""
    return {
        "size_near_over_a": near,
        "tet4_displacement": normalized_stiffness(
            block(4.0, near, "TET4"), formulation="displacement"
        ),
        "tet10_displacement": normalized_stiffness(block(4.0, near), formulation="displacement"),
        "tet10_mixed": normalized_stiffness(block(4.0, near)),
    }


def richardson(values: list[float]) -> tuple[float, float]:
    """Observed order and extrapolation from the three finest of levels halving the size."""
    k = np.asarray(values[-3:])
    order = float(np.log2(abs(k[1] - k[0]) / abs(k[2] - k[1])))
    return order, float(k[2] + (k[2] - k[1]) / (2.0**order - 1.0))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="runs/verify_flat_punch.json")
    parser.add_argument(
        "--quick", action="store_true", help="two coarse meshes and the locking contrast only"
    )
    args = parser.parse_args()
    report: dict = {
        "radius_m": RADIUS_M,
        "shear_modulus_Pa": SHEAR_MODULUS_PA,
        "depth_m": DEPTH_M,
        "machine": "2-core x86_64 CPU (shared)",
    }

    contacts = ("frictionless", "bonded")
    sizes = [1.0, 0.5] if args.quick else [1.0, 0.5, 0.25, 0.125]
    convergence = []
    for near in sizes:
        mesh = block(4.0, near, width_over_thickness=8.0)
        start = time.perf_counter()
        level = {"size_near_over_a": near, "tets": mesh.tet_count}
        for contact in contacts:
            level[contact] = normalized_stiffness(mesh, contact=contact)
        level["seconds"] = time.perf_counter() - start
        convergence.append(level)
        print(level, flush=True)
    report["mesh_convergence"] = {
        "width_over_thickness": 8.0,
        "levels": convergence,
        "hayes_k_over_8mua": hayes_factor(0.25),
        "shull_k_over_8mua": shull_factor(0.25),
    }
    if args.quick:
        report["locking_K_over_mu_1000"] = [locking_contrast(0.5)]
        print(report, flush=True)
        write_json(args.out, report)
        return
    for contact in contacts:
        order, extrapolated = richardson([level[contact] for level in convergence])
        report["mesh_convergence"][contact] = {
            "observed_order": order,
            "richardson_k_over_8mua": extrapolated,
            "relative_to_hayes": extrapolated / hayes_factor(0.25) - 1.0,
        }
    print(report["mesh_convergence"], flush=True)

    width_study = []
    for width in (4.0, 8.0, 16.0):
        mesh = block(4.0, 0.5, width_over_thickness=width)
        width_study.append(
            {"width_over_thickness": width, "tets": mesh.tet_count}
            | {contact: normalized_stiffness(mesh, contact=contact) for contact in contacts}
        )
        print(width_study[-1], flush=True)
    report["block_width"] = width_study

    thickness_study = []
    for h_over_a in (2.0, 4.0, 8.0):
        mesh = block(h_over_a, 0.25, width_over_thickness=8.0)
        thickness_study.append(
            {
                "h_over_a": h_over_a,
                "hayes": hayes_factor(1.0 / h_over_a),
                "shull": shull_factor(1.0 / h_over_a),
            }
            | {contact: normalized_stiffness(mesh, contact=contact) for contact in contacts}
        )
        print(thickness_study[-1], flush=True)
    x = np.array([1.0 / t["h_over_a"] for t in thickness_study])
    fit = np.linalg.solve(
        np.column_stack([np.ones(3), x, x**3]), [t["frictionless"] for t in thickness_study]
    )
    report["sneddon"] = {
        "width_over_thickness": 8.0,
        "thicknesses": thickness_study,
        "frictionless_half_space_extrapolation_k_over_8mua": float(fit[0]),
        "frictionless_fitted_linear_coefficient": float(fit[1]),
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
        locking.append(locking_contrast(near))
        print(locking[-1], flush=True)
    report["locking_K_over_mu_1000"] = locking

    reach = []
    for near in (0.5, 0.25):
        mesh = block(4.0, near)
        problem = IndentationProblem(
            mesh, material(1000.0), Indenter("flat_punch", radius_m=RADIUS_M)
        )
        depths = RADIUS_M * np.arange(0.05, 2.001, 0.05)
        start = time.perf_counter()
        result = simulate_indentation(
            problem, depths, device="cpu", progress=False, options=NewtonOptions(max_cutbacks=3)
        )
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

    # 7. timings of one ~20k-tet problem
    mesh = block(4.0, 0.125)
    assembler = Assembler(mesh, material(1000.0), device="cpu")
    u = np.zeros((mesh.node_count, 3))
    assembler.assemble(u)
    start = time.perf_counter()
    assembler.assemble(u)
    assemble_s = time.perf_counter() - start
    rhs = np.random.default_rng(0).standard_normal((mesh.node_count, 3))
    import warp as wp

    problem = IndentationProblem(mesh, material(1000.0), Indenter("flat_punch", radius_m=RADIUS_M))
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
