"""Which FE formulation is accurate for compressible tissue: TET10 mixed or displacement?

The problem: the bundled scene (``scenes/liver_slab_flat_punch.toml``: a flat punch of radius
a = 1 mm, bonded, on a specimen 10 a thick and 10 a in half-width with a fixed base, neo-Hookean
C10 = 287.5 Pa) on its round counterpart, a quarter DISC of radius 10 a, so that an
axisymmetric model of the same problem converges far enough to serve as an independent
reference. Poisson's ratio nu = 0.3, 0.45 and 0.4995 (the scene's K/mu = 1000); one small
depth step (0.02 a), where the response is linear.

- warptissue: ``indentation_disc`` (curved side) at the scene's near size a/2 and at a/4,
  TET10, ``formulation="mixed"`` (element mean dilatation) and ``"displacement"``.
- Reference: FElupe, axisymmetric QUAD4 Q1/P0 (three-field, element-constant pressure) on
  graded 2-D meshes halved three times (near size a/8 to a/64), Richardson-extrapolated from
  its three finest levels. Displacement-only Q1 on the same meshes is extrapolated too, as a
  check where it does not lock (nu <= 0.45); their difference is reported.

Usage:
    python scripts/benchmarks/formulation_study.py \\
        --out scripts/results/formulation_study_2core_cpu.json
    python scripts/benchmarks/formulation_study.py --quick   # one nu, the coarse mesh only
"""

from __future__ import annotations

import argparse
import json
import math
import time

import numpy as np
from bench_flat_punch import geometric_levels  # this folder is on sys.path when run

PROBE_RADIUS_M = 1.0e-3
RADIUS_M = 10.0e-3
THICKNESS_M = 10.0e-3
C10_PA = 287.5
SHEAR_MODULUS_PA = 2.0 * C10_PA
DEPTH_M = 0.02 * PROBE_RADIUS_M
POISSON_RATIOS = (0.3, 0.45, 0.4995)
NEAR_SIZES_M = (0.5e-3, 0.25e-3)
"""The scene's near size and one finer (its far size 5 mm and growth 1.4 kept)."""
REFERENCE_NEAR_SIZES_M = tuple(PROBE_RADIUS_M / 2**k for k in (3, 4, 5, 6))


def bulk_modulus_pa(poisson_ratio: float) -> float:
    """K from mu and nu: K = 2 mu (1 + nu) / (3 (1 - 2 nu))."""
    return 2.0 * SHEAR_MODULUS_PA * (1.0 + poisson_ratio) / (3.0 * (1.0 - 2.0 * poisson_ratio))


def warptissue_force(poisson_ratio: float, size_near_m: float, formulation: str) -> dict:
    """Punch force at DEPTH_M of warptissue on the quarter disc."""
    from warptissue.fem import IndentationProblem, NewtonOptions, simulate_indentation
    from warptissue.indenter import Indenter
    from warptissue.materials import NeoHookean
    from warptissue.mesh import indentation_disc

    mesh = indentation_disc(
        radius_m=RADIUS_M,
        thickness_m=THICKNESS_M,
        probe_radius_m=PROBE_RADIUS_M,
        element="TET10",
        size_near_m=size_near_m,
        size_far_m=5.0e-3,
        growth=1.4,
        curved_side=True,
    )
    problem = IndentationProblem(
        mesh,
        NeoHookean(C10_Pa=C10_PA, bulk_modulus_Pa=bulk_modulus_pa(poisson_ratio)),
        Indenter("flat_punch", radius_m=PROBE_RADIUS_M, contact="bonded"),
        formulation=formulation,
    )
    started = time.perf_counter()
    result = simulate_indentation(
        problem, [DEPTH_M], device="cpu", progress=False, options=NewtonOptions(tolerance=1e-10)
    )
    if not result.completed:
        raise RuntimeError(result.message)
    return {
        "tets": mesh.tet_count,
        "force_N": float(result.reaction_force_N[0]),
        "seconds": time.perf_counter() - started,
    }


def felupe_force(poisson_ratio: float, size_near_m: float, *, mixed: bool) -> dict:
    """Punch force at DEPTH_M of an axisymmetric FElupe model of the disc (QUAD4)."""
    import felupe as fem
    from scipy.sparse.linalg import spsolve

    a = PROBE_RADIUS_M
    radial = np.concatenate(
        [
            np.linspace(0.0, a, math.ceil(a / size_near_m) + 1),
            a + geometric_levels(RADIUS_M - a, size_near_m, 1.08)[1:],
        ]
    )
    axial = THICKNESS_M - geometric_levels(THICKNESS_M, size_near_m, 1.08)[::-1]
    mesh = fem.Grid(axial, radial)  # x_1 = axial (z), x_2 = radial (r)
    field = fem.FieldContainer([fem.FieldAxisymmetric(fem.RegionQuad(mesh), dim=2)])
    bulk = bulk_modulus_pa(poisson_ratio)
    if mixed:
        solid = fem.SolidBodyNearlyIncompressible(
            fem.NeoHooke(mu=SHEAR_MODULUS_PA), field, bulk=bulk
        )
    else:
        solid = fem.SolidBody(fem.NeoHooke(mu=SHEAR_MODULUS_PA, bulk=bulk), field)
    z, r = mesh.points.T
    tolerance = 1e-9 * a
    probe = (np.abs(z - THICKNESS_M) < tolerance) & (r <= a + tolerance)
    boundaries = {
        "axis": fem.Boundary(field[0], mask=r < tolerance, skip=(1, 0)),
        "bottom": fem.Boundary(field[0], mask=np.abs(z) < tolerance),
        "probe_r": fem.Boundary(field[0], mask=probe, skip=(1, 0)),
        "probe_z": fem.Boundary(field[0], mask=probe, skip=(0, 1), value=-DEPTH_M),
    }
    dof0, dof1 = fem.dof.partition(field, boundaries)
    ext0 = fem.dof.apply(field, boundaries, dof0)
    result = fem.newtonraphson(
        items=[solid], dof1=dof1, dof0=dof0, ext0=ext0, solver=spsolve, tol=1e-10, verbose=0
    )
    force = -float(np.sum(result.fun[boundaries["probe_z"].dof]))
    return {"cells": mesh.ncells, "force_N": force}


def richardson(forces: list[float]) -> dict:
    """Extrapolate the last three forces of a refinement by 2: limit and observed order."""
    f1, f2, f3 = forces[-3:]
    order = math.log(abs((f1 - f2) / (f2 - f3))) / math.log(2.0)
    limit = f3 + (f3 - f2) / (2.0**order - 1.0)
    return {"limit_N": limit, "order": order}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", help="write the results as JSON here")
    parser.add_argument("--quick", action="store_true", help="nu = 0.3, the scene's mesh only")
    args = parser.parse_args()
    from warptissue.device import quiet_warp

    quiet_warp()
    ratios = POISSON_RATIOS[:1] if args.quick else POISSON_RATIOS
    sizes = NEAR_SIZES_M[:1] if args.quick else NEAR_SIZES_M
    rows = []
    for nu in ratios:
        reference = {}
        for mixed in (False, True):
            forces = [felupe_force(nu, h, mixed=mixed)["force_N"] for h in REFERENCE_NEAR_SIZES_M]
            reference["q1p0" if mixed else "q1"] = {"forces_N": forces, **richardson(forces)}
        reference_n = reference["q1p0"]["limit_N"]
        check = reference["q1"]["limit_N"] / reference_n - 1.0
        print(f"nu = {nu}: reference (Q1/P0) {reference_n * 1e6:.4f} uN, order "
              f"{reference['q1p0']['order']:.2f}; Q1 {100 * check:+.2f} %", flush=True)  # fmt: skip
        for size in sizes:
            for formulation in ("mixed", "displacement"):
                run = warptissue_force(nu, size, formulation)
                error = run["force_N"] / reference_n - 1.0
                rows.append(
                    {
                        "poisson_ratio": nu,
                        "size_near_m": size,
                        "formulation": formulation,
                        **run,
                        "reference_N": reference_n,
                        "q1_minus_reference": check,
                        "error": error,
                        "felupe": reference,
                    }
                )
                print(f"  near {size * 1e3:.2f} mm {formulation:>12}: {run['tets']} tets, "
                      f"{run['force_N'] * 1e6:.4f} uN, {100 * error:+.2f} % "
                      f"({run['seconds']:.1f} s)", flush=True)  # fmt: skip
    if args.out:
        with open(args.out, "w", encoding="utf-8") as out:
            json.dump({"depth_m": DEPTH_M, "rows": rows}, out, indent=1)


if __name__ == "__main__":
    main()
