"""Takacs et al.'s line indenter on a beef liver strip: finite elements against distributed
Wiechert bodies (issue 21, must-show d).

Takacs et al. (Section VII, Fig. 10) press a 3D-printed 30 degree wedge (edge 30 mm) across a
25 x 25 x 200 mm strip of beef liver at 10 mm/min to 6 mm and estimate the force with
distributed nonlinear Wiechert bodies (Eq. 5-8): every surface element is one body of Table
I's nonlinear parameters divided by the 20 x 20 mm area of the cube they were fitted on,
driven by the quadratic surface profile of Eq. 6 (rho = 16 mm). The measured curve leaves the
estimate at about 4 mm, where its slope rises; the paper blames lateral tension, which the
one-degree-of-freedom bodies lack. This script computes the same estimate
(:func:`warptissue.viscoelastic.line_indenter_force_N`) and the finite-element force of the
same indenter (a rigid wedge in frictionless penalty contact, :mod:`warptissue.fem.contact`),
and compares the FE's own surface profile with Eq. 6.

The FE material is fitted to the nonlinear Wiechert model itself, with the project's fits:

1. the Wiechert model (Table I, the paper's 20 mm cube) compressed uniformly at the strip
   test's 10 mm/min to 6 mm and held 120 s gives a force record;
2. :func:`warptissue.viscoelastic.fit_qlv` fits Fung's QLV to it (elastic force
   A (exp(B x) - 1) = (k0 / B) (exp(B x) - 1), two Prony terms);
3. the elastic force F_e(x) on the cube, as nominal stress F_e / (20 mm)^2 against nominal
   strain x / 20 mm in uniaxial compression, is fitted with
   :func:`warptissue.fit.hyperelastic.fit_hyperelastic` (reduced polynomial N = 3);
4. the FE material is that model with K = 1000 mu0 and the QLV's Prony terms
   (:class:`warptissue.materials.Viscoelastic`, the same normalized G(t) as QLV).

The mesh is a quarter of the strip (symmetry planes x = 0 across the line and y = 0 along
it; the strip's long axis is x, the wedge runs along y through x = 0 and spans the width),
graded toward the line and the top, TET10 with the mixed formulation, its base fixed. The
probe moves at 10 mm/min (the time of each depth is depth / rate).

Usage:
    python scripts/examples/takacs_line_indenter.py [--quick] [--out JSON]
        [--tip-radii-mm 0.5 1.0 0.25] [--steps 24] [--penalty-factor 1000] [--device cpu]

The full run (4320 tets, three tip radii, 24 load steps each) writes
scripts/results/takacs_line_indenter_2core_cpu.json; docs/viscoelastic.md ("Line indenter:
finite elements against distributed Wiechert bodies") has the table. ``--quick`` (a 600-tet
strip, one tip radius) takes about 20 s.
"""

from __future__ import annotations

import argparse
import platform
import time

import numpy as np

from warptissue.fem import IndentationProblem, simulate_indentation
from warptissue.fem.contact import DEFAULT_PENALTY_FACTOR
from warptissue.fit.hyperelastic import HomogeneousTest, fit_hyperelastic
from warptissue.indenter import Indenter
from warptissue.materials import Viscoelastic
from warptissue.mesh import TetMesh, block_mesh, graded_coordinates, to_tet10
from warptissue.viscoelastic import (
    NonlinearWiechert,
    QuasiLinearViscoelastic,
    exponential_spring_force,
    fit_qlv,
    line_indenter_force_N,
    quadratic_profile,
)

TABLE_I = NonlinearWiechert(2.03, 0.438, 0.102, 5073.0, 39.24, 909.9, 1522.0, 81.18)
"""Takacs et al. Table I, nonlinear model (the 20 x 20 x 20 mm cube; N, m, s)."""

CUBE_EDGE_M = 0.020
STRIP_LENGTH_M, STRIP_WIDTH_M, STRIP_HEIGHT_M = 0.200, 0.025, 0.025
RATE_M_PER_S = 10e-3 / 60.0  # 10 mm/min (Fig. 10)
MAX_DEPTH_M = 6e-3
PROFILE_RADIUS_M = 16e-3  # rho of Eq. 6 (Fig. 9)
WEDGE_ANGLE_DEG = 30.0
BULK_OVER_SHEAR = 1000.0
HYPERELASTIC_MODEL = "reduced_polynomial:3"


def cube_record(hold_s: float = 120.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The Wiechert cube compressed uniformly at 10 mm/min to 6 mm, then held.

    Returns:
        time_s, displacement_m, force_N, shape (n,) each.
    """
    ramp_s = MAX_DEPTH_M / RATE_M_PER_S
    time_s = np.concatenate([np.linspace(0.0, ramp_s, 145), ramp_s + np.geomspace(0.1, hold_s, 60)])
    displacement = np.minimum(RATE_M_PER_S * time_s, MAX_DEPTH_M)
    return time_s, displacement, TABLE_I.force_N(time_s, displacement)


def fit_material() -> tuple[Viscoelastic, dict]:
    """QLV fitted to the cube record, its elastic force fitted by a hyperelastic model."""
    time_s, displacement, force = cube_record()
    qlv = fit_qlv(time_s, displacement, force, terms=2)
    g, tau = tuple(qlv.x[2:4]), tuple(qlv.x[4:6])
    x = np.linspace(0.0, MAX_DEPTH_M, 61)[1:]
    elastic_force = exponential_spring_force(
        x, stiffness_N_per_m=qlv.parameters["k0_N_per_m"], rate_per_m=qlv.parameters["B_per_m"]
    )
    test = HomogeneousTest.from_force_displacement(
        x,
        elastic_force,
        area_m2=CUBE_EDGE_M**2,
        height_m=CUBE_EDGE_M,
        loading="compression",
        name="QLV elastic force of the Wiechert cube",
    )
    hyper = fit_hyperelastic(HYPERELASTIC_MODEL, test)
    mu0 = hyper.model.initial_shear_modulus_Pa
    material = Viscoelastic(hyper.model.with_bulk_modulus(BULK_OVER_SHEAR * mu0), g=g, tau_s=tau)
    # The FE material on the cube (homogeneous uniaxial compression, QLV with its own elastic
    # force), against the Wiechert cube on the same ramp: the material fit's own error.
    fe_cube = QuasiLinearViscoelastic(
        g,
        tau,
        lambda u: (
            -hyper.model.nominal_stress_Pa(1.0 - np.asarray(u) / CUBE_EDGE_M, "uniaxial")
            * CUBE_EDGE_M**2
        ),
    )
    ramp = time_s <= MAX_DEPTH_M / RATE_M_PER_S + 1e-9
    fe_force = fe_cube.force_N(time_s[ramp], displacement[ramp])
    check_m = np.arange(1, 7) * 1e-3
    fe_at = np.interp(check_m, displacement[ramp], fe_force)
    wiechert_at = np.interp(check_m, displacement[ramp], force[ramp])
    report = {
        "cube_check": {
            "depth_m": check_m.tolist(),
            "wiechert_N": wiechert_at.tolist(),
            "fe_material_N": fe_at.tolist(),
            "ratio": (fe_at / wiechert_at).tolist(),
        },
        "cube_record": {
            "edge_m": CUBE_EDGE_M,
            "rate_m_per_s": RATE_M_PER_S,
            "depth_m": MAX_DEPTH_M,
            "hold_s": float(time_s[-1] - MAX_DEPTH_M / RATE_M_PER_S),
            "force_at_depth_N": float(np.interp(MAX_DEPTH_M - 1e-12, displacement, force)),
            "force_end_of_hold_N": float(force[-1]),
        },
        "qlv_fit": {
            "parameters": dict(zip(qlv.parameter_names, map(float, qlv.x), strict=True)),
            "r_squared": float(qlv.r_squared),
            "rmse_N": float(qlv.rmse),
            "warnings": list(qlv.warnings),
        },
        "hyperelastic_fit": {
            "model": hyper.model.to_dict(),
            "r_squared": float(hyper.result.r_squared),
            "initial_shear_modulus_Pa": mu0,
            "stable_up_to_strain": hyper.stability.stable_up_to_strain,
            "warnings": list(hyper.result.warnings),
        },
        "fe_material": material.to_dict(),
    }
    return material, report


def _axis(core_m: float, core_cells: int, length_m: float, cells: int, ratio: float):
    """Uniform cells of core_m / core_cells from 0 to core_m, then graded to length_m."""
    core = np.linspace(0.0, core_m, core_cells + 1)
    return np.concatenate(
        [core, core_m + graded_coordinates(length_m - core_m, cells, ratio=ratio)[1:]]
    )


def strip_mesh(*, quick: bool) -> TetMesh:
    """A quarter of the strip: x in [0, 100 mm] (along the strip, the line at x = 0), y in
    [0, 12.5 mm] (across, the free side at 12.5 mm), z in [0, 25 mm] (base at 0)."""
    if quick:
        x = _axis(4e-3, 4, STRIP_LENGTH_M / 2, 6, 30.0)
        y = np.linspace(0.0, STRIP_WIDTH_M / 2, 3)
        z = graded_coordinates(STRIP_HEIGHT_M, 5, ratio=0.15)
    else:
        x = _axis(4e-3, 8, STRIP_LENGTH_M / 2, 10, 30.0)
        y = np.linspace(0.0, STRIP_WIDTH_M / 2, 5)
        z = graded_coordinates(STRIP_HEIGHT_M, 10, ratio=0.1)
    mesh = to_tet10(block_mesh(x, y, z))
    sets = dict(mesh.node_sets)
    sets.update(
        top=sets["zmax"], bottom=sets["zmin"], symmetry_x=sets["xmin"], symmetry_y=sets["ymin"]
    )
    return TetMesh(points=mesh.points, tets=mesh.tets, node_sets=sets, face_sets=mesh.face_sets)


def wiechert_estimate_N(depth_m: np.ndarray, radius_m: float = PROFILE_RADIUS_M) -> np.ndarray:
    """Takacs et al.'s estimate (Eq. 5-8) at the given depths of the 10 mm/min ramp: Table I
    per square metre (/ 4e-4 m^2), the Eq. 6 profile with rho = ``radius_m`` (16 mm, Fig. 9),
    over the strip's 25 mm width (the 30 mm wedge spans it)."""
    time_s = np.linspace(0.0, MAX_DEPTH_M / RATE_M_PER_S, 241)
    force = line_indenter_force_N(
        TABLE_I.scaled(1.0 / CUBE_EDGE_M**2),
        time_s,
        RATE_M_PER_S * time_s,
        half_width_m=radius_m,
        length_m=STRIP_WIDTH_M,
        profile=quadratic_profile(radius_m),
        element_count=128,
    )
    return np.interp(depth_m, RATE_M_PER_S * time_s, force)


def surface_profile(mesh: TetMesh, displacement_m: np.ndarray, depth_m: float) -> dict:
    """The top surface's settlement -u_z along the strip (x) on the centre plane y = 0 and on
    the free side y = 12.5 mm, beside Eq. 6 (rho = 16 mm)."""
    top = mesh.node_set("top")
    out = {}
    for label, y in (("centre", 0.0), ("side", STRIP_WIDTH_M / 2)):
        nodes = top[np.isclose(mesh.points[top, 1], y, atol=1e-9)]
        nodes = nodes[np.argsort(mesh.points[nodes, 0])]
        x = mesh.points[nodes, 0]
        settlement = -displacement_m[nodes, 2]
        # Where the surface first comes back to zero (linear between nodes): beyond it the
        # nearly incompressible strip rises (the doming Eq. 7 neglects).
        crossing = None
        below = np.flatnonzero(settlement <= 0.0)
        if below.size:
            j = int(below[0])
            crossing = float(
                x[j - 1]
                + (x[j] - x[j - 1]) * settlement[j - 1] / (settlement[j - 1] - settlement[j])
            )
        out[label] = {
            "x_m": x.tolist(),
            "settlement_m": settlement.tolist(),
            "takacs_eq6_m": quadratic_profile(PROFILE_RADIUS_M)(x, depth_m).tolist(),
            "zero_crossing_m": crossing,
            "one_percent_of_depth_m": float(x[np.flatnonzero(settlement < 0.01 * depth_m)[0]])
            if np.any(settlement < 0.01 * depth_m)
            else None,
            "eq6_best_radius_m": best_radius(x, settlement, depth_m),
            "largest_rise_m": float(max(0.0, -settlement.min())),
            "largest_rise_at_m": float(x[np.argmin(settlement)]),
        }
    return out


def best_radius(x_m: np.ndarray, settlement_m: np.ndarray, depth_m: float) -> float:
    """rho of Eq. 6 that fits a settlement profile best (least squares over the nodes)."""
    from scipy.optimize import minimize_scalar

    def cost(radius: float) -> float:
        return float(np.sum((quadratic_profile(radius)(x_m, depth_m) - settlement_m) ** 2))

    return float(minimize_scalar(cost, bounds=(1e-3, 0.1), method="bounded").x)


def run_fe(
    mesh, material, tip_radius_m: float, steps: int, device: str, penalty_factor: float
) -> dict:
    """The wedge pressed at 10 mm/min to 6 mm: the force (base reaction) at each step."""
    depths = np.linspace(MAX_DEPTH_M / steps, MAX_DEPTH_M, steps)
    wedge = Indenter("wedge", radius_m=tip_radius_m, angle_deg=WEDGE_ANGLE_DEG)
    problem = IndentationProblem(mesh, material, wedge, penalty_factor=penalty_factor)
    start = time.perf_counter()
    result = simulate_indentation(
        problem, depths, times_s=depths / RATE_M_PER_S, device=device, progress=False
    )
    seconds = time.perf_counter() - start
    count = len(result.depths_m)
    return {
        "tip_radius_m": tip_radius_m,
        "penalty_factor": penalty_factor,
        "completed": bool(result.completed),
        "message": result.message,
        "seconds": seconds,
        "depths_m": result.depths_m.tolist(),
        "force_N": result.reaction_force_N.tolist(),
        "contact_force_N": result.contact_force_N.tolist(),
        "max_penetration_m": result.max_penetration_m.tolist(),
        "newton_iterations": result.newton_iterations.tolist(),
        "cutbacks": int(result.cutbacks),
        "_displacement_m": result.displacement_m[count - 1] if count else None,
    }


def _slope(depth: np.ndarray, force: np.ndarray) -> np.ndarray:
    return np.gradient(force, depth)


def _write(args: argparse.Namespace, mesh: TetMesh, report: dict, runs: list) -> None:
    """The JSON of the runs so far (rewritten after each tip radius)."""
    from warptissue.io import write_json

    write_json(
        args.out,
        {
            "method": "Takacs et al. line indenter: FE (rigid wedge, frictionless penalty "
            "contact) against distributed nonlinear Wiechert bodies (Eq. 5-8)",
            "machine": f"{platform.machine()} {platform.system()}, device {args.device}",
            "strip_m": [STRIP_LENGTH_M, STRIP_WIDTH_M, STRIP_HEIGHT_M],
            "quarter_model": True,
            "nodes": mesh.node_count,
            "tets": mesh.tet_count,
            "wedge_angle_deg": WEDGE_ANGLE_DEG,
            "rate_m_per_s": RATE_M_PER_S,
            "profile_radius_m": PROFILE_RADIUS_M,
            "wiechert_specific": TABLE_I.scaled(1.0 / CUBE_EDGE_M**2).to_dict(),
            **report,
            "runs": runs,
        },
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="coarse strip, one tip radius")
    parser.add_argument("--out", default=None, help="write the results as JSON here")
    parser.add_argument("--tip-radii-mm", type=float, nargs="+", default=None)
    parser.add_argument("--steps", type=int, default=None)
    parser.add_argument("--device", default="cpu")
    parser.add_argument(
        "--penalty-factor", type=float, default=DEFAULT_PENALTY_FACTOR, help="contact beta"
    )
    args = parser.parse_args()
    radii = args.tip_radii_mm or ([0.5] if args.quick else [0.5, 1.0, 0.25])
    steps = args.steps or 24

    material, report = fit_material()
    hyper, qlv = report["hyperelastic_fit"], report["qlv_fit"]
    print(
        f"Wiechert cube ({CUBE_EDGE_M * 1e3:g} mm, Table I) at 10 mm/min to 6 mm + hold: "
        f"QLV R^2 = {qlv['r_squared']:.5f}, {HYPERELASTIC_MODEL} R^2 = {hyper['r_squared']:.6f}, "
        f"mu0 = {hyper['initial_shear_modulus_Pa']:.1f} Pa, g = "
        f"{qlv['parameters']['g1']:.3f}, {qlv['parameters']['g2']:.3f}, tau = "
        f"{qlv['parameters']['tau1_s']:.2f}, {qlv['parameters']['tau2_s']:.2f} s"
    )
    cube = report["cube_check"]
    print(
        "FE material / Wiechert on the cube at 10 mm/min, 1..6 mm: "
        + ", ".join(f"{r:.2f}" for r in cube["ratio"])
    )
    mesh = strip_mesh(quick=args.quick)
    print(f"quarter strip: {mesh.node_count} TET10 nodes, {mesh.tet_count} tets")
    runs = []
    for radius_mm in radii:
        run = run_fe(mesh, material, radius_mm * 1e-3, steps, args.device, args.penalty_factor)
        depth = np.asarray(run["depths_m"])
        force = np.asarray(run["force_N"])
        estimate = wiechert_estimate_N(depth)
        run["wiechert_estimate_N"] = estimate.tolist()
        run["fe_over_estimate"] = (force / estimate).tolist()
        if depth.size > 2:
            run["fe_slope_N_per_m"] = _slope(depth, force).tolist()
            run["estimate_slope_N_per_m"] = _slope(depth, estimate).tolist()
        displacement = run.pop("_displacement_m")
        if radius_mm == radii[0] and displacement is not None and run["completed"]:
            profile = surface_profile(mesh, displacement, float(depth[-1]))
            run["surface_profile"] = profile
            # The estimate again with the FE's own profile width (Eq. 6 fitted on y = 0).
            rho = profile["centre"]["eq6_best_radius_m"]
            run["wiechert_estimate_fe_radius_N"] = wiechert_estimate_N(depth, rho).tolist()
        runs.append(run)
        if args.out:
            _write(args, mesh, report, runs)
        print(
            f"tip radius {radius_mm:g} mm: {run['seconds']:.0f} s, {run['message']} "
            f"({run['cutbacks']} cutbacks)"
        )
        print("  depth(mm)  F_FE(N)    F_Wiechert(N)  FE/Wiechert  pen(mm)  Newton")
        for i in range(depth.size):
            print(
                f"  {depth[i] * 1e3:<9.2f}  {force[i]:<9.4f}  {estimate[i]:<13.4f}  "
                f"{force[i] / estimate[i]:<11.3f}  {run['max_penetration_m'][i] * 1e3:<7.3f}  "
                f"{run['newton_iterations'][i]}"
            )
        if "surface_profile" in run:
            for label, p in run["surface_profile"].items():
                print(
                    f"  surface ({label}): back to zero at x = "
                    f"{(p['zero_crossing_m'] or float('nan')) * 1e3:.1f} mm (Eq. 6: "
                    f"{PROFILE_RADIUS_M * 1e3:g} mm), largest rise {p['largest_rise_m'] * 1e3:.2f} "
                    f"mm at x = {p['largest_rise_at_m'] * 1e3:.1f} mm; Eq. 6 fits it best with "
                    f"rho = {p['eq6_best_radius_m'] * 1e3:.1f} mm"
                )
            print(
                "  Wiechert estimate with the FE's rho, 1..6 mm: "
                + ", ".join(
                    f"{f:.4f}"
                    for d, f in zip(depth, run["wiechert_estimate_fe_radius_N"], strict=True)
                    if abs(d * 1e3 - round(d * 1e3)) < 1e-9
                )
            )


if __name__ == "__main__":
    main()
