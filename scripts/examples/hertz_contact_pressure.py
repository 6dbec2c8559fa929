"""Contact area and pressure under a rigid sphere against Hertz (issue 21, outputs).

A frictionless rigid sphere (R = 1 mm) indents a quarter block (neo-Hookean C10 = 500 Pa,
K = 2000 C10, so E = 6 C10 and nu -> 0.5) 6 R wide and 3 R thick, refined to 0.075 R
within 0.25 R of the axis (the mesh of tests/test_fem_contact.py's ``hertz_run``, 5025
TET10 nodes). Per depth it prints the contact area (:class:`warptissue.fem.contact.
ContactSurface`) against Hertz's pi a^2 with a = sqrt(R d); the pressure against Hertz's
p(r) = p0 sqrt(1 - r^2/a^2), p0 = 3 F / (2 pi a^2) with F the FE force (the RMS error over
the surface nodes within 0.8 a, and the peak); the pressure's integral with the tributary
areas and by an isoparametric quadrature of the interpolated field over the curved deformed
6-node triangles, both against the summed normal contact force; and, for comparison, the
pressure a positive lumping gives (the 4-sub-triangle one: corners A/12, mid-edge nodes
A/4), at corner and at mid-edge nodes, over Hertz's.

Usage:
    python scripts/examples/hertz_contact_pressure.py [--quick] [--device cuda] [--out FILE.json]

Measured on the 2-core CPU (about 50 s): docs/fe.md "Contact outputs". ``--quick`` (about
15 s) runs the coarser 3 R x 1.5 R block of tests/test_fem_contact.py's ``sphere_mesh``
(refined to 0.1 R within 0.2 R) at 0.02 R and 0.04 R.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from warptissue.fem import Assembler, IndentationProblem, simulate_indentation
from warptissue.fem.contact import ContactSurface
from warptissue.indenter import Indenter
from warptissue.materials import NeoHookean
from warptissue.mesh import indentation_block

RADIUS_M = 1e-3
C10_PA = 500.0
DEPTHS_R = (0.01, 0.02, 0.03, 0.04)

# Strang and Fix's 6-point rule on the reference triangle (weights sum to 1).
_A, _B = 0.445948490915965, 0.091576213509771
_WEIGHTS = np.array([0.223381589678011] * 3 + [0.109951743655322] * 3)
_POINTS = np.array(
    [[_A, _A, 1 - 2 * _A], [_A, 1 - 2 * _A, _A], [1 - 2 * _A, _A, _A]]
    + [[_B, _B, 1 - 2 * _B], [_B, 1 - 2 * _B, _B], [1 - 2 * _B, _B, _B]]
)


def isoparametric_integral(points: np.ndarray, triangles: np.ndarray, values: np.ndarray) -> float:
    """Integral of a nodal field over curved 6-node triangles (their own shape functions)."""
    x = points[triangles]
    total = 0.0
    for weight, (l0, l1, l2) in zip(_WEIGHTS, _POINTS, strict=True):
        shape = np.array(
            [l0 * (2 * l0 - 1), l1 * (2 * l1 - 1), l2 * (2 * l2 - 1)]
            + [4 * l0 * l1, 4 * l1 * l2, 4 * l2 * l0]
        )
        d_xi = np.array([1 - 4 * l0, 4 * l1 - 1, 0, 4 * (l0 - l1), 4 * l2, -4 * l2])
        d_eta = np.array([1 - 4 * l0, 0, 4 * l2 - 1, -4 * l1, 4 * l1, 4 * (l0 - l2)])
        tangent_xi = np.einsum("fjk,j->fk", x, d_xi)
        tangent_eta = np.einsum("fjk,j->fk", x, d_eta)
        jacobian = np.linalg.norm(np.cross(tangent_xi, tangent_eta), axis=1)
        total += weight * 0.5 * float(np.sum(jacobian * (values[triangles] @ shape)))
    return total


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a coarse block, two depths")
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--out", default=None, help="write the rows as JSON here")
    args = parser.parse_args()
    width = 3.0 if args.quick else 6.0
    mesh = indentation_block(
        width_m=width * RADIUS_M,
        thickness_m=0.5 * width * RADIUS_M,
        probe_radius_m=(0.2 if args.quick else 0.25) * RADIUS_M,
        size_near_m=(0.1 if args.quick else 0.075) * RADIUS_M,
        size_far_m=(0.6 if args.quick else 1.5) * RADIUS_M,
        growth=1.2 if args.quick else 1.5,
    )
    material = NeoHookean(C10_PA, 2000.0 * C10_PA)
    problem = IndentationProblem(mesh, material, Indenter("sphere", radius_m=RADIUS_M))
    assembler = Assembler(mesh, material, device=args.device)
    depths = RADIUS_M * np.array((0.02, 0.04) if args.quick else DEPTHS_R)
    started = time.perf_counter()
    result = simulate_indentation(
        problem, depths, device=args.device, progress=False, assembler=assembler
    )
    elapsed = time.perf_counter() - started
    surface = ContactSurface.for_mesh(mesh)
    top = mesh.node_set("top")
    is_corner = np.zeros(mesh.node_count, dtype=bool)
    is_corner[np.unique(mesh.tets[:, :4])] = True
    print(
        f"sphere R = {RADIUS_M * 1e3:g} mm on a {width:g} R x {width / 2:g} R quarter block, "
        f"{mesh.node_count} "
        f"TET10 nodes, {elapsed:.1f} s on {args.device}"
    )
    header = (
        f"{'d/R':>5} {'area/pi a^2':>11} {'p RMS/p0':>9} {'peak/p0':>8} {'lumped int':>11} "
        f"{'iso int':>9} {'positive lumping: corner':>25} {'mid-edge':>9}"
    )
    print(header)
    rows = []
    for step, depth in enumerate(result.depths_m):
        assembler.set_load(depth)
        state = assembler.contact_state(result.displacement_m[step])
        current = mesh.points + result.displacement_m[step]
        normal = np.zeros(mesh.node_count)
        normal[state.nodes] = np.linalg.norm(state.force_N, axis=1)
        pressure = result.contact_pressure_Pa[step]
        weights = surface.tributary_areas_m2(current)
        a = np.sqrt(RADIUS_M * depth)
        p0 = 3.0 * result.reaction_force_N[step] / (2.0 * np.pi * a**2)
        r = np.hypot(current[:, 0], current[:, 1])
        hertz = p0 * np.sqrt(np.clip(1.0 - (r / a) ** 2, 0.0, None))
        inner = np.zeros(mesh.node_count, dtype=bool)
        inner[top] = True
        inner &= r < 0.8 * a
        # The positive 4-sub-triangle lumping, for comparison (not what is output).
        lumped = np.zeros(mesh.node_count)
        areas = surface.triangle_areas_m2(current)
        for column in range(6):
            np.add.at(
                lumped, surface.triangles[:, column], areas * (1 / 12 if column < 3 else 1 / 4)
            )
        naive = np.where(lumped > 0, normal / np.where(lumped > 0, lumped, 1.0), 0.0)
        row = {
            "depth_over_R": float(depth / RADIUS_M),
            "force_N": float(result.reaction_force_N[step]),
            "contact_area_m2": float(result.contact_area_m2[step]),
            "area_over_hertz": float(result.contact_area_m2[step] / (np.pi * a**2)),
            "pressure_rms_over_p0": float(np.sqrt(np.mean((pressure - hertz)[inner] ** 2)) / p0),
            "peak_over_p0": float(pressure[top].max() / p0),
            "lumped_integral_over_force": float(np.sum(weights * pressure) / normal.sum()),
            "isoparametric_integral_over_force": float(
                isoparametric_integral(current, surface.triangles, pressure) / normal.sum()
            ),
            "positive_lumping_corner_over_hertz": float(
                np.mean(naive[inner & is_corner] / hertz[inner & is_corner])
            ),
            "positive_lumping_mid_edge_over_hertz": float(
                np.mean(naive[inner & ~is_corner] / hertz[inner & ~is_corner])
            ),
            "max_penetration_over_depth": float(result.max_penetration_m[step] / depth),
        }
        rows.append(row)
        print(
            f"{row['depth_over_R']:>5.2f} {row['area_over_hertz']:>11.3f} "
            f"{row['pressure_rms_over_p0']:>9.3f} {row['peak_over_p0']:>8.3f} "
            f"{row['lumped_integral_over_force']:>11.6f} "
            f"{row['isoparametric_integral_over_force']:>9.5f} "
            f"{row['positive_lumping_corner_over_hertz']:>25.4f} "
            f"{row['positive_lumping_mid_edge_over_hertz']:>9.3f}"
        )
    if args.out:
        with open(args.out, "w", encoding="utf-8") as handle:
            json.dump(
                {
                    "machine": f"{args.device}",
                    "node_count": mesh.node_count,
                    "seconds": elapsed,
                    "rows": rows,
                },
                handle,
                indent=2,
            )


if __name__ == "__main__":
    main()
