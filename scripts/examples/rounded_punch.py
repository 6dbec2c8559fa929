"""A flat punch whose edge radius shrinks converges to the sharp punch (issue 21, must-show b).

A rigid flat-ended cylinder of radius a = 1 mm whose edge is rounded with radius rho
(``Indenter("flat_punch", radius_m=a, edge_radius_m=rho)``, frictionless penalty contact)
indents a quarter block of nearly incompressible neo-Hookean tissue (the flat-punch
benchmark's material: C10 = 287.5 Pa, K = 1000 mu) bonded to a rigid base. On the same mesh
the sharp frictionless punch with prescribed nodes (``Indenter("flat_punch", radius_m=a,
contact="frictionless")``) is the reference. Printed and written per edge radius and depth:
the force over the sharp punch's, the radius of the sharp punch that would give the same
force (on this layer, through Hayes et al.'s finite-thickness factor) and the same radius
from Sneddon's (1965) half-space solution for the rounded profile, the largest penetration
and Newton's iterations.

The expectation: a rounded punch touches the tissue over a radius b between its flat face's
a - rho and a, growing with depth; for the half-space Sneddon's integrals for an
axisymmetric profile f(r) give (E* = 4 mu, incompressible)

    delta = int_c^b b f'(r) / sqrt(b^2 - r^2) dr,
    F     = 2 E* int_c^b r^2 f'(r) / sqrt(b^2 - r^2) dr,

with c = a - rho and f(r) = rho - sqrt(rho^2 - (r - c)^2) on the rim, and F = 2 E* a_eff
delta defines the punch's effective radius a_eff (the sharp punch has a_eff = a).

Usage:
    python scripts/examples/rounded_punch.py [--quick] [--out results.json]

``--quick`` runs a coarse mesh (near size a/3) and two edge radii (under a minute of CPU);
the full run writes ``scripts/results/rounded_punch_2core_cpu.json`` when given that path
as ``--out``.
"""

from __future__ import annotations

import argparse
import math
import time
import warnings

import numpy as np
from scipy.integrate import IntegrationWarning, quad
from scipy.optimize import brentq

from warptissue.fem import IndentationProblem, simulate_indentation
from warptissue.fit.punch import hayes_kappa
from warptissue.indenter import Indenter
from warptissue.materials import NeoHookean
from warptissue.mesh import indentation_block

RADIUS_M = 1.0e-3
SHEAR_MODULUS_PA = 575.0
DEPTHS_OVER_RADIUS = (0.02, 0.05, 0.1)


def sneddon_rounded_punch(depth_m: float, radius_m: float, edge_radius_m: float) -> dict:
    """Sneddon's (1965) frictionless rounded punch on an incompressible half-space.

    Args:
        depth_m: Depth of the flat face below the undeformed surface, m.
        radius_m: Punch radius a, m.
        edge_radius_m: Edge radius rho, 0 < rho <= a, m.

    Returns:
        ``contact_radius_m`` b (a - rho < b < a) and ``effective_radius_m`` a_eff = F /
        (8 mu delta), the radius of the sharp punch of the same force.
    """
    core = radius_m - edge_radius_m

    def slope(r: float) -> float:
        run = r - core
        return run / math.sqrt(max(edge_radius_m**2 - run**2, 1e-300))

    def integrals(b: float) -> tuple[float, float]:
        # r = b sin(t) removes the inverse square root at r = b.
        start = math.asin(min(core / b, 1.0))
        depth = quad(lambda t: b * slope(b * math.sin(t)), start, 0.5 * math.pi, limit=200)[0]
        force = quad(
            lambda t: (b * math.sin(t)) ** 2 * slope(b * math.sin(t)),
            start,
            0.5 * math.pi,
            limit=200,
        )[0]
        return depth, force  # force over 2 E*

    with warnings.catch_warnings():
        # Near b = a the rim's slope grows without bound; quad warns of roundoff there.
        warnings.simplefilter("ignore", IntegrationWarning)
        b = brentq(
            lambda b: integrals(b)[0] - depth_m,
            core * (1.0 + 1e-12) if core > 0 else 1e-12 * radius_m,
            radius_m * (1.0 - 1e-12),
            xtol=1e-14 * radius_m,
        )
        depth, force = integrals(b)
    return {"contact_radius_m": b, "effective_radius_m": force / depth}


def layer_effective_radius(force_ratio: float, radius_m: float, thickness_m: float) -> float:
    """The radius a_eff of the sharp punch whose force on the bonded layer is ``force_ratio``
    times that of radius ``radius_m``: a_eff kappa(a_eff/h) = ratio a kappa(a/h) (Hayes et
    al. 1972, :func:`warptissue.fit.punch.hayes_kappa`, nu = 0.5)."""
    target = force_ratio * radius_m * hayes_kappa(radius_m / thickness_m, 0.5)

    def mismatch(r: float) -> float:
        return r * hayes_kappa(r / thickness_m, 0.5) - target

    if mismatch(radius_m) <= 0.0:
        return radius_m * force_ratio  # at or above the sharp punch (penalty error)
    return brentq(mismatch, 1e-3 * radius_m, radius_m, xtol=1e-9 * radius_m)


def run(args: argparse.Namespace) -> dict:
    """Every edge radius and the sharp punch on one mesh, at the depths."""
    a = RADIUS_M
    thickness = args.thickness_over_radius * a
    mesh = indentation_block(
        width_m=args.width_over_radius * a,
        thickness_m=thickness,
        probe_radius_m=a,
        size_near_m=a * args.size_near_over_radius,
        size_far_m=0.25 * thickness,
    )
    material = NeoHookean(0.5 * SHEAR_MODULUS_PA, 1000.0 * SHEAR_MODULUS_PA)
    depths = a * np.array(DEPTHS_OVER_RADIUS)
    sharp_force = 8.0 * SHEAR_MODULUS_PA * a * depths
    print(
        f"quarter block {args.width_over_radius:g} a x {args.thickness_over_radius:g} a, near "
        f"size {args.size_near_over_radius:g} a: {mesh.tet_count} TET10, {mesh.node_count} nodes"
    )
    runs = []
    for rho in [0.0, *args.edge_radii]:
        indenter = (
            Indenter("flat_punch", radius_m=a, contact="frictionless")
            if rho == 0.0
            else Indenter("flat_punch", radius_m=a, edge_radius_m=rho * a)
        )
        started = time.perf_counter()
        result = simulate_indentation(
            IndentationProblem(mesh, material, indenter), depths, device="cpu", progress=False
        )
        seconds = time.perf_counter() - started
        if not result.completed:
            print(f"rho/a = {rho:g}: {result.message}")
        runs.append(
            {
                "edge_radius_over_radius": rho,
                "probe": "prescribed frictionless" if rho == 0.0 else "rounded, contact",
                "completed": bool(result.completed),
                "seconds": seconds,
                "force_N": result.reaction_force_N.tolist(),
                "force_over_sneddon": (
                    result.reaction_force_N / sharp_force[: len(result.depths_m)]
                ).tolist(),
                "newton_iterations": result.newton_iterations.tolist(),
                "max_penetration_over_depth": (
                    (result.max_penetration_m / depths[: len(result.depths_m)]).tolist()
                    if result.max_penetration_m.size
                    else []
                ),
            }
        )
    sharp = np.array(runs[0]["force_N"])
    rows = []
    print(
        "rho/a  d/a    F/F_sharp  a_eff/a (FE, layer)  a_eff/a (Sneddon)  b/a (Sneddon)  "
        "pen/d     Newton  s"
    )
    for entry in runs[1:]:
        rho = entry["edge_radius_over_radius"]
        for i, force in enumerate(entry["force_N"]):
            ratio = force / sharp[i]
            analytic = sneddon_rounded_punch(depths[i], a, rho * a)
            row = {
                "edge_radius_over_radius": rho,
                "depth_over_radius": DEPTHS_OVER_RADIUS[i],
                "force_N": force,
                "sharp_force_N": float(sharp[i]),
                "force_over_sharp": ratio,
                "effective_radius_over_radius_fe": layer_effective_radius(ratio, a, thickness) / a,
                "effective_radius_over_radius_sneddon": analytic["effective_radius_m"] / a,
                "contact_radius_over_radius_sneddon": analytic["contact_radius_m"] / a,
                "max_penetration_over_depth": entry["max_penetration_over_depth"][i],
                "newton_iterations": entry["newton_iterations"][i],
            }
            rows.append(row)
            print(
                f"{rho:<6.3g} {row['depth_over_radius']:<6.3g} {ratio:<10.4f} "
                f"{row['effective_radius_over_radius_fe']:<20.4f} "
                f"{row['effective_radius_over_radius_sneddon']:<18.4f} "
                f"{row['contact_radius_over_radius_sneddon']:<14.4f} "
                f"{row['max_penetration_over_depth']:<9.1e} {row['newton_iterations']:<7d} "
                f"{entry['seconds']:.0f}"
            )
    return {
        "radius_m": a,
        "width_over_radius": args.width_over_radius,
        "thickness_over_radius": args.thickness_over_radius,
        "size_near_over_radius": args.size_near_over_radius,
        "tets": mesh.tet_count,
        "nodes": mesh.node_count,
        "shear_modulus_Pa": SHEAR_MODULUS_PA,
        "bulk_over_shear": 1000.0,
        "depths_over_radius": list(DEPTHS_OVER_RADIUS),
        "penalty_ramp": not args.no_penalty_ramp,
        "runs": runs,
        "rows": rows,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a coarse mesh, two edge radii")
    parser.add_argument("--out", default=None, help="write the results as JSON here")
    parser.add_argument("--width-over-radius", type=float, default=6.0)
    parser.add_argument("--thickness-over-radius", type=float, default=3.0)
    parser.add_argument(
        "--size-near-over-radius",
        type=float,
        nargs="+",
        default=None,
        help="near element size(s) over a, one mesh each (default 1/4 and 1/6; quick 1/3)",
    )
    parser.add_argument("--edge-radii", type=float, nargs="+", default=None, help="rho / a")
    parser.add_argument(
        "--no-penalty-ramp",
        action="store_true",
        help="solve each contact increment with the full penalty at once (the solver before "
        "the penalty ramp, docs/design-notes/contact-newton.md)",
    )
    args = parser.parse_args()
    if args.no_penalty_ramp:
        from warptissue.fem.newton import increment

        increment.CONTACT_PENALTY_RAMP = 1.0
    sizes = args.size_near_over_radius or ([1.0 / 3.0] if args.quick else [0.25, 1.0 / 6.0])
    if args.edge_radii is None:
        args.edge_radii = [0.4, 0.1] if args.quick else [0.4, 0.2, 0.1, 0.05, 0.025]
    meshes = []
    for size in sizes:
        args.size_near_over_radius = size
        meshes.append(run(args))
    if args.out:
        import platform

        from warptissue.io import write_json

        write_json(
            args.out,
            {
                "machine": f"{platform.machine()} {platform.processor()}, 2 cores shared",
                "meshes": meshes,
            },
        )


if __name__ == "__main__":
    main()
