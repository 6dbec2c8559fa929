"""Block-preconditioned MINRES for three tetrahedral mixed pairs: is it robust in h and K/mu?

A Krylov solver whose iteration count does not grow with the mesh or with K/mu is what the
flat-punch targets need (README, Performance). For a saddle-point system

    [ A   B^T ] [u]   [f]
    [ B   -C  ] [p] = [g],     C = M / K,

the block-diagonal preconditioner diag(A_hat^-1, S_hat^-1) with S_hat = (1/mu + 1/K) M_lumped
and A_hat = A + B^T S_hat^-1 B (the natural norm of Zulehner, SIAM J. Matrix Anal. Appl. 32,
2011, for saddle problems whose A is coercive only on the kernel of B, as the deviatoric A is)
gives MINRES an iteration count bounded independently of h and K when the pair is uniformly
inf-sup stable (beta_h bounded below) and A_hat^-1 is applied by a uniform preconditioner.
For P0, A_hat is the condensed mean-dilatation tangent at a bulk modulus mu K / (mu + K): an
ordinary compressible elasticity operator. This script measures iteration counts on the
small-strain (first Newton iteration) systems of:

- P2/P0: warptissue's TET10 mixed element (its pressure, condensed in warptissue, kept here);
- P2 + one normal face bubble per face / P0 (Bernardi-Raugel style enrichment);
- P2/P1: Taylor-Hood, continuous linear pressure on the corner nodes.

All three come from the independent NumPy assembly of ``infsup_p2p0.py``
(:func:`numpy_mixed_operators`), which reproduces warptissue's P2/P0 operators. A is the
deviatoric stiffness 2 mu int dev eps : dev eps, B the pressure-weighted divergence, M the
pressure mass. The right-hand side is the bonded punch pushed down by a small depth (lifting of
its Dirichlet values), on the unit cube (n^3 hexahedra, 6-tet split, quarter punch of radius
0.25 at a corner of the top) and on the flat-punch benchmark's graded quarter blocks.

A_hat^-1 is one of:
- ``exact``: a sparse LU solve of A_hat (isolates the pressure side);
- ``amg``: one V-cycle of smoothed-aggregation AMG (pyamg, rigid-body near-null space,
  3x3 node blocks, two symmetric Gauss-Seidel sweeps; face bubbles get their diagonal);
- ``pmg-lu`` / ``pmg-amg``: one symmetric two-level p-multigrid cycle, the form a GPU version
  would take: Chebyshev-Jacobi smoothing (degree 3 unless ``--chebyshev-degree``) on the
  whole P2 (+ bubble) space, and the Galerkin P1 operator on the same tets (7-8x fewer DOFs)
  solved by sparse LU or one AMG V-cycle.
MINRES stops at a relative preconditioned residual of 1e-8; the record holds the iterations,
the true relative residual, and the relative error of u against a sparse direct solve of the
whole system.

Needs pyamg for the ``amg`` and ``pmg-amg`` rows (``pip install pyamg``).

Examples:
    python scripts/block_preconditioner_study.py --cubes 4,6,8 --bench-sizes 800,2000,5000 \\
        --out scripts/results/block_preconditioner_2core_cpu.json
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

sys.path.insert(0, str(Path(__file__).resolve().parent))

from infsup_p2p0 import (  # noqa: E402
    SHEAR_MODULUS_PA,
    corner_mesh,
    cube_corner_mesh,
    numpy_mixed_operators,
    schur_spectrum,
)

PAIRS = {
    "P2/P0": {"face_bubbles": False, "pressure": "p0"},
    "P2+bubbles/P0": {"face_bubbles": True, "pressure": "p0"},
    "P2/P1": {"face_bubbles": False, "pressure": "p1"},
}
RELATIVE_TOLERANCE = 1e-8
MAX_ITERATIONS = 3000


def mesh_shape(points: np.ndarray, tets: np.ndarray) -> dict:
    """How stretched the tets are: percentiles of each tet's longest / shortest edge and of its
    radius ratio 3 r_in / r_circ (1 regular). Point smoothers lose their mesh-independence on
    stretched elements."""
    from warptissue.mesh.quality import edge_lengths, radius_ratios

    lengths = edge_lengths(points, tets)
    stretch = lengths.max(axis=1) / lengths.min(axis=1)
    quality = radius_ratios(points, tets)
    return {
        "edge_ratio_median": float(np.median(stretch)),
        "edge_ratio_p90": float(np.percentile(stretch, 90)),
        "edge_ratio_max": float(stretch.max()),
        "radius_ratio_p01": float(np.percentile(quality, 1)),
        "radius_ratio_median": float(np.median(quality)),
    }


def saddle_system(operators: dict, bulk_over_shear: float, depth_m: float) -> tuple:
    """The free-DOF saddle-point matrix (symmetric, indefinite) and its right-hand side for
    the punch pushed down by ``depth_m``."""
    free, punch = operators["free"], operators["punch"]
    deviatoric, divergence = operators["deviatoric"], operators["divergence"]
    prescribed = -depth_m * np.ones(int(punch.sum()))
    block = deviatoric[free][:, free]
    coupling = divergence[:, free]
    compliance = operators["pressure_mass"] / (bulk_over_shear * SHEAR_MODULUS_PA)
    matrix = sp.bmat([[block, coupling.T], [coupling, -compliance]], format="csr")
    rhs = np.concatenate(
        [
            -deviatoric[free][:, punch] @ prescribed,
            -divergence[:, punch] @ prescribed,
        ]
    )
    return matrix, rhs


def augmented_block(operators: dict, bulk_over_shear: float) -> sp.csr_matrix:
    """A_hat = A + B^T S_hat^-1 B over all displacement DOFs, S_hat = (1/mu + 1/K) M_lumped:
    the displacement part of the saddle system's natural norm (Zulehner 2011), SPD and
    elliptic even where A (deviatoric) is coercive only on the kernel of B. For P0 it is the
    condensed mean-dilatation tangent at a bulk modulus mu K / (mu + K)."""
    return (
        operators["deviatoric"]
        + operators["divergence"].T
        @ sp.diags(1.0 / schur_diagonal(operators, bulk_over_shear))
        @ operators["divergence"]
    )


def schur_diagonal(operators: dict, bulk_over_shear: float) -> np.ndarray:
    """S_hat = (1/mu + 1/K) M_lumped, as its diagonal."""
    lumped = np.asarray(operators["pressure_mass"].sum(axis=1)).ravel()
    return (1.0 + 1.0 / bulk_over_shear) / SHEAR_MODULUS_PA * lumped


def displacement_preconditioner(
    operators: dict, bulk_over_shear: float, kind: str, *, smoothing: tuple[int, float]
) -> tuple[spla.LinearOperator, dict]:
    """A_hat^-1 over the free displacement DOFs: an exact LU solve, one AMG V-cycle, or one
    two-level p-multigrid cycle (``pmg-lu``, ``pmg-amg``) whose Chebyshev smoother has the
    degree and lower-bound divisor in ``smoothing``."""
    free = operators["free"]
    deviatoric = augmented_block(operators, bulk_over_shear).tocsr()
    block = deviatoric[free][:, free].tocsc()
    size = block.shape[0]
    if kind == "exact":
        factor = spla.splu(block)
        return spla.LinearOperator((size, size), matvec=factor.solve, dtype=float), {}
    if kind.startswith("pmg"):
        degree, lower_divisor = smoothing
        return p_multigrid(
            operators,
            block,
            coarse=kind.removeprefix("pmg-") or "lu",
            degree=degree,
            lower_divisor=lower_divisor,
        )
    import pyamg

    nodal = operators["dof_components"] >= 0
    node_dofs = int(nodal.sum())
    # Dirichlet rows and columns of the nodal block become identity, so its 3x3 blocks stay
    # whole for aggregation; the preconditioner then acts on the free entries only.
    nodal_matrix = deviatoric[:node_dofs][:, :node_dofs].tolil()
    fixed_nodal = np.flatnonzero(~free[:node_dofs])
    scale = float(deviatoric.diagonal()[:node_dofs].mean())
    keep = sp.diags(free[:node_dofs].astype(float))
    nodal_matrix = (keep @ nodal_matrix @ keep).tolil()
    nodal_matrix[fixed_nodal, fixed_nodal] = scale
    nodal_matrix = sp.bsr_matrix(nodal_matrix.tocsr(), blocksize=(3, 3))
    points = operators["dof_points"][:node_dofs:3]
    rigid = np.zeros((node_dofs, 6))
    for axis in range(3):
        rigid[axis::3, axis] = 1.0
    rotations = ((1, 2), (2, 0), (0, 1))
    for mode, (i, j) in enumerate(rotations):
        rigid[i::3, 3 + mode] = -points[:, j]
        rigid[j::3, 3 + mode] = points[:, i]
    sweeps = ("gauss_seidel", {"sweep": "symmetric", "iterations": 2})
    hierarchy = pyamg.smoothed_aggregation_solver(
        nodal_matrix, B=rigid, max_coarse=300, presmoother=sweeps, postsmoother=sweeps
    )
    cycle = hierarchy.aspreconditioner(cycle="V")
    free_nodal = free[:node_dofs]
    bubble_diagonal = deviatoric.diagonal()[node_dofs:][free[node_dofs:]]
    nodal_free_count = int(free_nodal.sum())

    def apply(vector: np.ndarray) -> np.ndarray:
        full = np.zeros(node_dofs)
        full[free_nodal] = vector[:nodal_free_count]
        result = np.empty_like(vector)
        result[:nodal_free_count] = (cycle @ full)[free_nodal]
        result[nodal_free_count:] = vector[nodal_free_count:] / bubble_diagonal
        return result

    info = {
        "amg_levels": len(hierarchy.levels),
        "amg_operator_complexity": float(hierarchy.operator_complexity()),
    }
    return spla.LinearOperator((size, size), matvec=apply, dtype=float), info


def linear_prolongation(operators: dict) -> sp.csr_matrix:
    """P1 -> P2 (+ bubbles) prolongation over all DOFs (D x 3 N): corners copied, edge
    midpoints averaged, face bubbles zero (a linear field has no bubble part)."""
    corners, edges = operators["corner_count"], operators["edges"]
    dof_count = len(operators["free"])
    rows = [np.arange(3 * corners)]
    columns = [np.arange(3 * corners)]
    values = [np.ones(3 * corners)]
    for end in range(2):
        rows.append((3 * (corners + np.arange(len(edges)))[:, None] + np.arange(3)).ravel())
        columns.append((3 * edges[:, end][:, None] + np.arange(3)).ravel())
        values.append(np.full(3 * len(edges), 0.5))
    return sp.csr_matrix(
        (np.concatenate(values), (np.concatenate(rows), np.concatenate(columns))),
        shape=(dof_count, 3 * corners),
    )


def chebyshev(
    matrix: sp.spmatrix,
    inverse_diagonal: np.ndarray,
    rhs: np.ndarray,
    start: np.ndarray | None,
    bounds: tuple[float, float],
    degree: int,
) -> np.ndarray:
    """``degree`` steps of Jacobi-preconditioned Chebyshev iteration on the eigenvalue interval
    ``bounds`` of D^-1 A (Saad, Iterative Methods for Sparse Linear Systems, Alg. 12.1), from
    ``start`` (None: zero, whose residual is ``rhs`` without a product)."""
    low, high = bounds
    theta, delta = 0.5 * (high + low), 0.5 * (high - low)
    sigma = theta / delta
    rho = 1.0 / sigma
    if start is None:
        x, residual = np.zeros_like(rhs), rhs.copy()
    else:
        x = start.astype(float)
        residual = rhs - matrix @ x
    step = inverse_diagonal * residual / theta
    for k in range(degree):
        x += step
        if k == degree - 1:
            break
        residual -= matrix @ step
        rho_next = 1.0 / (2.0 * sigma - rho)
        step = rho_next * rho * step + 2.0 * rho_next / delta * inverse_diagonal * residual
        rho = rho_next
    return x


def p_multigrid(
    operators: dict, block: sp.spmatrix, *, coarse: str, degree: int, lower_divisor: float
) -> tuple[spla.LinearOperator, dict]:
    """One symmetric two-level p-multigrid cycle for A_hat: Chebyshev-Jacobi smoothing of
    ``degree`` on [lambda_max / lower_divisor, 1.1 lambda_max] of D^-1 A_hat over P2
    (+ bubbles), the Galerkin P1 operator P^T A_hat P on the same tets solved by sparse LU
    (``coarse="lu"``, standing in for a GPU direct solve of the 7-8x smaller system) or by one
    smoothed-aggregation V-cycle (``coarse="amg"``). A GPU version would spend 2 ``degree``
    products with A_hat per cycle (the first residual is the right-hand side)."""
    free = operators["free"]
    coarse_free = free[: 3 * operators["corner_count"]]
    prolongation = linear_prolongation(operators)[free][:, coarse_free].tocsr()
    block = block.tocsr()
    coarse_matrix = (prolongation.T @ block @ prolongation).tocsc()
    if coarse == "lu":
        coarse_solve = spla.splu(coarse_matrix).solve
    else:
        import pyamg

        coarse_solve = (
            pyamg.smoothed_aggregation_solver(coarse_matrix.tocsr(), max_coarse=300)
            .aspreconditioner(cycle="V")
            .matvec
        )
    inverse_diagonal = 1.0 / block.diagonal()
    scaled = sp.diags(np.sqrt(inverse_diagonal)) @ block @ sp.diags(np.sqrt(inverse_diagonal))
    largest = float(spla.eigsh(scaled, k=1, which="LA", tol=1e-3, return_eigenvectors=False)[0])
    bounds = (largest / lower_divisor, 1.1 * largest)

    def apply(rhs: np.ndarray) -> np.ndarray:
        x = chebyshev(block, inverse_diagonal, rhs, None, bounds, degree)
        x += prolongation @ coarse_solve(prolongation.T @ (rhs - block @ x))
        return chebyshev(block, inverse_diagonal, rhs, x, bounds, degree)

    size = block.shape[0]
    info = {
        "coarse_dofs": int(coarse_free.sum()),
        "chebyshev_degree": degree,
        "chebyshev_lower_divisor": lower_divisor,
    }
    return spla.LinearOperator((size, size), matvec=apply, dtype=float), info


def preconditioned_minres(
    matrix: sp.spmatrix, rhs: np.ndarray, preconditioner, *, rtol: float, maxiter: int
) -> tuple[np.ndarray, list[float]]:
    """MINRES with a symmetric positive definite preconditioner P (Elman, Silvester and
    Wathen, Finite Elements and Fast Iterative Solvers, 2nd ed., Algorithm 4.1), stopped when
    the P^-1-norm of the residual falls below ``rtol`` times that of ``rhs`` (SciPy's minres
    stops on a backward error that mixes the blocks' units).

    Returns the solution and the relative P^-1-norm residual after each iteration."""
    x = np.zeros_like(rhs)
    v_old, v = np.zeros_like(rhs), rhs.copy()
    z = preconditioner(v)
    gamma_old, gamma = 1.0, float(np.sqrt(z @ v))
    w_old, w = np.zeros_like(rhs), np.zeros_like(rhs)
    eta, start = gamma, gamma
    s_old, s, c_old, c = 0.0, 0.0, 1.0, 1.0
    history = []
    for _ in range(maxiter):
        z = z / gamma
        product = matrix @ z
        delta = float(product @ z)
        v_new = product - (delta / gamma) * v - (gamma / gamma_old) * v_old
        z_new = preconditioner(v_new)
        gamma_new = float(np.sqrt(z_new @ v_new))
        alpha0 = c * delta - c_old * s * gamma
        alpha1 = float(np.hypot(alpha0, gamma_new))
        alpha2 = s * delta + c_old * c * gamma
        alpha3 = s_old * gamma
        c_new, s_new = alpha0 / alpha1, gamma_new / alpha1
        w_new = (z - alpha3 * w_old - alpha2 * w) / alpha1
        x += c_new * eta * w_new
        eta = -s_new * eta
        history.append(abs(eta) / start)
        if history[-1] < rtol:
            break
        v_old, v, z = v, v_new, z_new
        gamma_old, gamma = gamma, gamma_new
        w_old, w = w, w_new
        s_old, s, c_old, c = s, s_new, c, c_new
    return x, history


def block_minres(
    operators: dict,
    bulk_over_shear: float,
    kinds: list[str],
    depth_m: float,
    *,
    smoothing: tuple[int, float],
) -> list:
    """MINRES on the saddle system with diag(A_hat^-1, S_hat^-1), once per kind of A_hat,
    each checked against one sparse direct solve of the whole system."""
    matrix, rhs = saddle_system(operators, bulk_over_shear, depth_m)
    direct = spla.spsolve(matrix.tocsc(), rhs)
    pressure_diagonal = schur_diagonal(operators, bulk_over_shear)
    records = []
    for kind in kinds:
        started = time.perf_counter()
        displacement, info = displacement_preconditioner(
            operators, bulk_over_shear, kind, smoothing=smoothing
        )
        size_u = displacement.shape[0]

        def apply(vector: np.ndarray, displacement=displacement, size_u=size_u) -> np.ndarray:
            return np.concatenate(
                [displacement @ vector[:size_u], vector[size_u:] / pressure_diagonal]
            )

        setup_s = time.perf_counter() - started
        solution, history = preconditioned_minres(
            matrix, rhs, apply, rtol=RELATIVE_TOLERANCE, maxiter=MAX_ITERATIONS
        )
        records.append(
            {
                "bulk_over_shear": bulk_over_shear,
                "displacement_preconditioner": kind,
                "converged": bool(history[-1] < RELATIVE_TOLERANCE),
                "iterations": len(history),
                "true_relative_residual": float(
                    np.linalg.norm(matrix @ solution - rhs) / np.linalg.norm(rhs)
                ),
                "displacement_relative_error": float(
                    np.linalg.norm(solution[:size_u] - direct[:size_u])
                    / np.linalg.norm(direct[:size_u])
                ),
                "setup_s": setup_s,
                "solve_s": time.perf_counter() - started - setup_s,
                **info,
            }
        )
    return records


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cubes", default="4,6,8", help="hexahedra per cube edge (empty: none)")
    parser.add_argument(
        "--cube-stretch",
        type=float,
        default=1.0,
        help="squash the cubes' height by this factor (uniformly stretched tets, no grading)",
    )
    parser.add_argument(
        "--bench-sizes", default="800,2000", help="benchmark mesh sizes in tets (empty: none)"
    )
    parser.add_argument(
        "--bench-mesher",
        default="extruded",
        choices=("extruded", "delaunay"),
        help="benchmark meshes: layered prisms, or TetGen's quality tets in the same surface",
    )
    parser.add_argument("--pairs", default=",".join(PAIRS), help="pairs, comma separated")
    parser.add_argument("--ratios", default="10,1000,100000", help="K/mu values, comma separated")
    parser.add_argument(
        "--preconditioners",
        default="exact,amg,pmg-lu",
        help="A_hat: exact, amg, pmg-lu, pmg-amg (comma separated)",
    )
    parser.add_argument(
        "--chebyshev-degree", type=int, default=3, help="pmg: Chebyshev smoothing steps"
    )
    parser.add_argument(
        "--chebyshev-lower-divisor",
        type=float,
        default=8.0,
        help="pmg: smooth the eigenvalues of D^-1 A_hat above lambda_max / this",
    )
    parser.add_argument(
        "--spectrum-max-tets",
        type=int,
        default=6000,
        help="also compute beta_h^2 (dense Schur complement) on meshes up to this many tets",
    )
    parser.add_argument("--out", type=Path, default=None, help="write the JSON here")
    args = parser.parse_args(argv)

    def values(text: str) -> list[str]:
        return [s.strip() for s in text.split(",") if s.strip()]

    meshes = []
    for divisions in values(args.cubes):
        points, tets = cube_corner_mesh(int(divisions))
        points[:, 2] /= args.cube_stretch
        label = f"cube {divisions}^3 hexahedra, split six"
        if args.cube_stretch != 1.0:
            label += f", height / {args.cube_stretch:g}"
        meshes.append((label, points, tets, 0.25, 1e-3))
    if values(args.bench_sizes):
        from bench_flat_punch import PROBE_RADIUS_M, warptissue_mesh

        for size in values(args.bench_sizes):
            mesh, _ = warptissue_mesh(int(size), mesher=args.bench_mesher)
            meshes.append(
                (
                    f"flat-punch benchmark quarter block, {args.bench_mesher}, "
                    f"{mesh.tet_count} tets",
                    *corner_mesh(mesh),
                    PROBE_RADIUS_M,
                    PROBE_RADIUS_M / 40.0,
                )
            )
    records = []
    for label, points, tets, punch_radius_m, depth_m in meshes:
        for pair in values(args.pairs):
            operators = numpy_mixed_operators(
                points, tets, punch_radius_m=punch_radius_m, **PAIRS[pair]
            )
            common = {
                "mesh": label,
                "pair": pair,
                "tets": len(tets),
                "free_displacement_dofs": int(operators["free"].sum()),
                "pressure_dofs": operators["divergence"].shape[0],
                **mesh_shape(points, tets),
            }
            if len(tets) <= args.spectrum_max_tets:
                eigenvalues = schur_spectrum(
                    operators["deviatoric"],
                    operators["divergence"],
                    operators["pressure_mass"],
                    operators["free"],
                )
                common["beta_squared_smallest"] = float(eigenvalues[0])
                common["schur_largest"] = float(eigenvalues[-1])
            for ratio in values(args.ratios):
                for result in block_minres(
                    operators,
                    float(ratio),
                    values(args.preconditioners),
                    depth_m,
                    smoothing=(args.chebyshev_degree, args.chebyshev_lower_divisor),
                ):
                    records.append({**common, **result})
                    print(json.dumps(records[-1]), flush=True)
    if args.out is not None:
        from warptissue.io import write_json

        write_json(
            args.out,
            {
                "shear_modulus_Pa": SHEAR_MODULUS_PA,
                "relative_tolerance": RELATIVE_TOLERANCE,
                "records": records,
            },
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
