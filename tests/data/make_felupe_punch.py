"""Make ``felupe_punch.csv``: a flat-punch force curve from FElupe, an independent FE code.

The problem: a disc of radius R = 15 mm and thickness h = 10 mm, its base fixed, indented at
the centre of its top face by a bonded rigid flat punch of radius a = 5 mm to depths of
0.0625 ... 0.5 mm (8 equal steps, to a / 10). The tissue is nearly incompressible
neo-Hookean, ``W = C10 (I1b - 3) + K / 2 (J - 1)^2`` with C10 = 300 Pa (mu = 600 Pa) and
K = 1000 mu = 600 kPa: warptissue's ``NeoHookean(C10_Pa=300, bulk_modulus_Pa=6e5)``
(``(J - 1)^2 / D1`` with K = 2 / D1), and FElupe's isochoric ``NeoHooke(mu=600)``
(``mu / 2 (I1b - 3)``) inside ``SolidBodyNearlyIncompressible(..., bulk=6e5)``
(``U(Jbar) = K (Jbar - 1)^2 / 2``): the same strain energy.

FElupe solves it axisymmetric with Q1/P0 three-field quadrilaterals (Hu-Washizu with a
cell-constant pressure and dilatation) on a grid with a line of nodes at r = a: uniform
radial spacing ``s`` under the punch, and spacing growing geometrically (ratio 1.08) from
``s`` away from the punch edge in r and from the top face in z. Each depth step is taken in
2 Newton sub-steps; Newton stops when the free-dof residual norm is below 1e-9 of the
reaction norm. The force is the reaction at the punch's prescribed dofs (the full punch,
positive pushing in). Level L of the mesh has ``s = a / (8 * 2^L)``.

Mesh convergence, measured with ``--levels 3,4,5,6`` (force in mN at 0.0625, 0.25, 0.3125
and 0.5 mm):

=====  =======  =======  ========  ========  ========
level  s        cells    0.0625    0.25      0.5
=====  =======  =======  ========  ========  ========
3      a/64     3 072    2.74277   11.06006  22.40707
4      a/128    6 720    2.73717   11.03613  22.33922
5      a/256    14 945   2.73415   11.02249  22.29447
6      a/512    33 060   2.73266   11.01397  22.27822
=====  =======  =======  ========  ========  ========

The observed order is about 1 (0.5 to 1.5 over the depths: the singular punch edge); against
the Richardson extrapolation of levels 4, 5 and 6, level 5 is 0.11 to 0.32 % high at every
depth (level 6: 0.04 to 0.22 %). The CSV is level 5 (about 1 minute on a free core): the
curve is converged to about 0.3 %, from above. ``--quadratic`` runs the same meshes with
8-node (serendipity) quadrilaterals and P0 pressure, which converge from below
(``--quadratic --levels 2,3,4``; level 4: 2.72312, 10.97900, 22.21422 mN, order about 1 at
small depth). The two extrapolations differ by 0.21 % (0.0625 mm) to 0.25 % (0.5 mm), and
the CSV is 0.32 to 0.36 % above the Q2/P0 one: converged to better than 0.5 % either way.

Why a / 10: deeper (to 1.0 and 1.5 mm, a / 5 and 0.3 a) the forces beyond about 0.15 a did
not converge under refinement down to a / 512 (differences between successive levels of 0.2
to 0.5 % that did not shrink), as the free surface next to the bonded edge steepens towards
a crease along the punch's side, which no mesh here resolves (and neither code models
contact with the punch's side).

Run ``python tests/data/make_felupe_punch.py`` to rewrite the CSV; ``--levels 3,4,5,6``
prints the convergence study instead of writing.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
CSV_PATH = HERE / "felupe_punch.csv"

DISC_RADIUS_M = 15.0e-3
THICKNESS_M = 10.0e-3
PROBE_RADIUS_M = 5.0e-3
C10_PA = 300.0
SHEAR_MODULUS_PA = 2.0 * C10_PA
BULK_MODULUS_PA = 1000.0 * SHEAR_MODULUS_PA
MAX_DEPTH_M = 0.5e-3
STEP_COUNT = 8
SUBSTEPS = 2
GROWTH = 1.08
NEWTON_TOLERANCE = 1.0e-9
CSV_LEVEL = 5
"""The level written to the CSV: near size a / (8 * 2^5) = a / 256."""


def depths_m() -> np.ndarray:
    """The recorded depths, shape (STEP_COUNT,), m."""
    return MAX_DEPTH_M * np.arange(1, STEP_COUNT + 1) / STEP_COUNT


def geometric_levels(length_m: float, first_m: float, growth: float) -> np.ndarray:
    """Node positions 0..length with spacing first_m, first_m * growth, ... (last one fitted)."""
    sizes = [first_m]
    while sum(sizes) < length_m:
        sizes.append(sizes[-1] * growth)
    positions = np.concatenate([[0.0], np.cumsum(sizes)])
    return positions * (length_m / positions[-1])


def near_size_m(level: int) -> float:
    """The element size under the punch at a mesh level, m."""
    return PROBE_RADIUS_M / (8.0 * 2**level)


def force_curve(level: int, *, quadratic: bool = False) -> tuple[np.ndarray, int]:
    """FElupe's punch force at :func:`depths_m` on the mesh of one level.

    Args:
        level: The mesh level (near size a / (8 * 2^level)).
        quadratic: 8-node quadrilaterals (Q2 serendipity/P0) instead of Q1/P0.

    Returns:
        The force per depth (N, full punch, positive pushing in), shape (STEP_COUNT,), and
        the number of cells.
    """
    import felupe as fem
    from scipy.sparse.linalg import spsolve

    try:
        from pypardiso import spsolve
    except ImportError:
        pass

    a, size = PROBE_RADIUS_M, near_size_m(level)
    radial = np.concatenate(
        [
            np.linspace(0.0, a, round(a / size) + 1),
            a + geometric_levels(DISC_RADIUS_M - a, size, GROWTH)[1:],
        ]
    )
    axial = THICKNESS_M - geometric_levels(THICKNESS_M, size, GROWTH)[::-1]
    mesh = fem.Grid(axial, radial)  # x_1 = axial (z), x_2 = radial (r)
    if quadratic:
        mesh = fem.mesh.convert(mesh, order=2)
        region = fem.RegionQuadraticQuad(mesh)
    else:
        region = fem.RegionQuad(mesh)
    displacement = fem.FieldContainer([fem.FieldAxisymmetric(region, dim=2)])
    solid = fem.SolidBodyNearlyIncompressible(
        fem.NeoHooke(mu=SHEAR_MODULUS_PA), displacement, bulk=BULK_MODULUS_PA
    )
    z, r = mesh.points.T
    tolerance = 1e-9 * a
    probe = (np.abs(z - THICKNESS_M) < tolerance) & (r <= a + tolerance)
    boundaries = {
        "axis": fem.Boundary(displacement[0], mask=r < tolerance, skip=(1, 0)),
        "bottom": fem.Boundary(displacement[0], mask=np.abs(z) < tolerance),
        "probe_r": fem.Boundary(displacement[0], mask=probe, skip=(1, 0)),
        "probe_z": fem.Boundary(displacement[0], mask=probe, skip=(0, 1)),
    }
    dof0, dof1 = fem.dof.partition(displacement, boundaries)
    forces = []
    previous = 0.0
    for depth in depths_m():
        for fraction in np.arange(1, SUBSTEPS + 1) / SUBSTEPS:
            boundaries["probe_z"].update(-(previous + fraction * (depth - previous)))
            ext0 = fem.dof.apply(displacement, boundaries, dof0)
            result = fem.newtonraphson(
                items=[solid],
                dof1=dof1,
                dof0=dof0,
                ext0=ext0,
                solver=spsolve,
                tol=NEWTON_TOLERANCE,
                check=_relative_check,
                verbose=0,
                maxiter=25,
            )
            if not result.success:
                raise RuntimeError(f"FElupe did not converge at depth {depth:g} m")
        previous = depth
        # The residual at the prescribed probe dofs is the force the probe applies, along -z.
        forces.append(-float(np.sum(result.fun[boundaries["probe_z"].dof])))
    return np.array(forces), mesh.ncells


def _relative_check(dx, x, f, xtol, ftol, dof1=None, dof0=None, items=None):
    """Newton test: free-dof residual norm relative to the reaction norm."""
    residual = np.linalg.norm(f[dof1])
    reaction = np.linalg.norm(f[dof0])
    fnorm = residual / reaction if reaction > 0 else residual
    return np.linalg.norm(dx), fnorm, bool(fnorm < ftol)


def write_curve(forces_N: np.ndarray, path: Path = CSV_PATH) -> None:
    """Write ``time_s`` (the step number), ``displacement_m`` (depth) and ``force_N``."""
    from warptissue.io import write_csv

    steps = np.arange(1, STEP_COUNT + 1, dtype=np.float64)
    write_csv(path, {"time_s": steps, "displacement_m": depths_m(), "force_N": forces_N})


def convergence(levels: list[int], *, quadratic: bool = False) -> None:
    """Print each level's curve and, from three or more levels, the Richardson estimate."""
    curves = {}
    for level in levels:
        forces, cells = force_curve(level, quadratic=quadratic)
        curves[level] = forces
        print(
            f"level {level}: near size a/{PROBE_RADIUS_M / near_size_m(level):.0f}, "
            f"{cells} cells, force (mN) " + " ".join(f"{1e3 * f:.5f}" for f in forces),
            flush=True,
        )
    if len(levels) >= 3:
        f1, f2, f3 = (curves[k] for k in levels[-3:])  # coarse, medium, fine (ratio 2)
        order = np.log(np.abs((f1 - f2) / (f2 - f3))) / math.log(2.0)
        extrapolated = f3 + (f3 - f2) / (2.0**order - 1.0)
        print("observed order per depth:", " ".join(f"{p:.2f}" for p in order))
        for level in levels:
            error = curves[level] / extrapolated - 1.0
            print(
                f"level {level}: vs extrapolation, per depth (%) "
                + " ".join(f"{100 * e:+.3f}" for e in error)
            )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--levels",
        default="",
        help="comma-separated mesh levels: print the convergence study instead of writing",
    )
    parser.add_argument(
        "--quadratic",
        action="store_true",
        help="with --levels: 8-node quadrilaterals (Q2 serendipity/P0) instead of Q1/P0",
    )
    args = parser.parse_args(argv)
    if args.levels:
        levels = [int(item) for item in args.levels.split(",") if item.strip()]
        convergence(levels, quadratic=args.quadratic)
        return 0
    forces, cells = force_curve(CSV_LEVEL)
    write_curve(forces)
    print(
        f"wrote {CSV_PATH} ({cells} cells): force (mN) "
        + " ".join(f"{1e3 * f:.5f}" for f in forces)
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
