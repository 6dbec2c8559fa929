"""A rigid sphere on an elastic ball against Hertz (issue 44): node-to-surface against
surface-integrated contact, at the pole and at a site turned off it, over radius ratios and
near sizes; F / Hertz, the contact area over Hertz's pi R* d, and Newton iterations per
load step and per increment.

The ball (radius R2, neo-Hookean C10 = 500 Pa, K = 1000 mu) is meshed by
:func:`warptissue.mesh.ball_mesh` finer around its pole (pole size ``c sqrt(R* d_min)``),
turned so that the pole lies ``--site-deg`` degrees from +z about y, and held on its lower
half (z < 0; at 45 degrees the support's edge lies 45 degrees of arc from the site). The
sphere (R1) comes in along the inward normal at the site. Hertz with R* = R1 R2 / (R1 + R2),
E* = E / (1 - nu^2).

Usage:
    python scripts/benchmarks/bench_sphere_on_ball.py --ratios 0.05 0.0741 0.5 \
        --site-deg 0 45 --pole 0.3 --integration nodes surface --device cuda --out table.json

``--steps N --spacing contact_radius`` takes N load steps to the deepest of ``--depths``
with the contact radius growing evenly (:func:`warptissue.loading.quasi_static_depths`).
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from warptissue.fem import IndentationProblem, NewtonOptions, simulate_indentation
from warptissue.indenter import Indenter
from warptissue.loading import DEPTH_SPACINGS, quasi_static_depths
from warptissue.materials import NeoHookean
from warptissue.mesh import TetMesh, ball_mesh

BALL_RADIUS_M = 10e-3
C10_PA = 500.0
BULK_OVER_SHEAR = 1000.0
DEPTHS_OVER_RSTAR = np.array([0.005, 0.01, 0.02, 0.03, 0.04])


def hertz_N(depth_m: np.ndarray, reduced_radius_m: float) -> np.ndarray:
    mu = 2.0 * C10_PA
    nu = (3.0 * BULK_OVER_SHEAR - 2.0) / (2.0 * (3.0 * BULK_OVER_SHEAR + 1.0))
    reduced = 2.0 * mu * (1.0 + nu) / (1.0 - nu**2)
    return 4.0 / 3.0 * reduced * np.sqrt(reduced_radius_m) * depth_m**1.5


def turned_ball(
    pole_m: float, site_deg: float, *, far: float = 0.15, growth: float = 0.25
) -> tuple[TetMesh, np.ndarray]:
    mesh = ball_mesh(
        BALL_RADIUS_M, pole_size_m=pole_m, far_size_m=far * BALL_RADIUS_M, growth=growth
    )
    angle = np.radians(site_deg)
    c, s = np.cos(angle), np.sin(angle)
    rotation = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    points = mesh.points @ rotation.T
    # The support stays the world's lower half (z < 0), not the turned one: turned with the
    # mesh it would make every site the pole again.
    surface = mesh.node_sets["surface"]
    lower = points[surface, 2] < 0.0
    sets = dict(mesh.node_sets, top=surface[~lower], bottom=surface[lower])
    turned = TetMesh(points=points, tets=mesh.tets, node_sets=sets)
    return turned, rotation @ [0.0, 0.0, 1.0]


def run_case(
    ratio: float,
    site_deg: float,
    pole: float,
    integration: str,
    device: str,
    *,
    far: float = 0.15,
    growth: float = 0.25,
    depths_over_rstar: np.ndarray = DEPTHS_OVER_RSTAR,
    options: NewtonOptions | None = None,
) -> dict:
    probe_radius = ratio * BALL_RADIUS_M
    reduced_radius = probe_radius * BALL_RADIUS_M / (probe_radius + BALL_RADIUS_M)
    contact = np.sqrt(reduced_radius * DEPTHS_OVER_RSTAR.min() * reduced_radius)
    mesh, normal = turned_ball(pole * contact, site_deg, far=far, growth=growth)
    problem = IndentationProblem(
        mesh,
        NeoHookean(C10_PA, BULK_OVER_SHEAR * 2.0 * C10_PA),
        Indenter("sphere", radius_m=probe_radius),
        site_m=BALL_RADIUS_M * normal,
        direction=-normal,
        symmetry_planes=(),
        contact_integration=integration,
    )
    depths = np.asarray(depths_over_rstar) * reduced_radius
    start = time.perf_counter()
    result = simulate_indentation(problem, depths, device=device, progress=False, options=options)
    seconds = time.perf_counter() - start
    count = len(result.reaction_force_N)
    ratio_to_hertz = result.reaction_force_N / hertz_N(depths[:count], reduced_radius)
    hertz_area = np.pi * reduced_radius * depths[:count]  # a^2 = R* d
    per_increment = [each["iterations"] for each in result.increments]
    return {
        "R1_over_R2": ratio,
        "site_deg": site_deg,
        "pole_over_contact": pole,
        "integration": integration,
        "nodes": mesh.node_count,
        "seconds": seconds,
        "completed": bool(result.completed),
        "message": result.message,
        "far_over_R2": far,
        "growth": growth,
        "d_over_Rstar": np.asarray(depths_over_rstar)[:count].tolist(),
        "F_over_hertz": ratio_to_hertz.tolist(),
        "newton_iterations": np.asarray(result.newton_iterations).tolist(),
        "area_over_hertz": (result.contact_area_m2 / hertz_area).tolist(),
        "increment_iterations": per_increment,
        "increment_converged": [bool(each["converged"]) for each in result.increments],
        "max_increment_iterations": max(per_increment) if per_increment else 0,
        "cutbacks": int(result.cutbacks),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ratios", type=float, nargs="+", default=[1 / 13.5])
    parser.add_argument("--site-deg", type=float, nargs="+", default=[0.0])
    parser.add_argument("--pole", type=float, nargs="+", default=[0.3])
    parser.add_argument("--integration", nargs="+", default=["nodes", "surface"])
    parser.add_argument("--far", type=float, default=0.15, help="far size over R2")
    parser.add_argument("--growth", type=float, default=0.25, help="ball_mesh's growth")
    parser.add_argument("--depths", type=float, nargs="+", default=DEPTHS_OVER_RSTAR.tolist())
    parser.add_argument(
        "--steps",
        type=int,
        default=None,
        help="load steps to the deepest of --depths, spaced by --spacing (replaces --depths)",
    )
    parser.add_argument("--spacing", choices=DEPTH_SPACINGS, default="even")
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--out", default=None)
    args = parser.parse_args()
    depths = np.array(args.depths)
    if args.steps is not None:
        depths = quasi_static_depths(
            max_depth_m=float(depths.max()), steps=args.steps, spacing=args.spacing
        )
    rows = []
    for ratio in args.ratios:
        for site in args.site_deg:
            for pole in args.pole:
                for integration in args.integration:
                    row = run_case(
                        ratio,
                        site,
                        pole,
                        integration,
                        args.device,
                        far=args.far,
                        growth=args.growth,
                        depths_over_rstar=depths,
                    )
                    row["spacing"] = args.spacing if args.steps is not None else "listed"
                    rows.append(row)
                    print(
                        f"R1/R2 {ratio:.4g} site {site:g} pole {pole:g} {integration:8s} "
                        f"nodes {row['nodes']} {row['seconds']:.0f} s "
                        f"F/H {np.round(row['F_over_hertz'], 4).tolist()} "
                        f"its {row['newton_iterations']} "
                        f"A/H {np.round(row['area_over_hertz'], 3).tolist()} "
                        f"increments {row['increment_iterations']} "
                        + ("" if row["completed"] else row["message"]),
                        flush=True,
                    )
                    if args.out:  # after every case: a long sweep keeps what it has
                        with open(args.out, "w", encoding="utf-8") as handle:
                            json.dump(rows, handle, indent=1)


if __name__ == "__main__":
    main()
