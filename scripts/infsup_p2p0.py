"""The discrete inf-sup constant of warptissue's TET10 P2/P0 pair, measured on its meshes.

A mixed (or mean-dilatation) element is uniformly stable when

    beta_h^2 = min_p  (p^T B A^-1 B^T p) / (p^T M p)

stays bounded away from zero as the mesh is refined. Here A is the deviatoric stiffness of
the free displacement DOFs (the tangent at u = 0 without its volumetric part), B the element
divergences (B[e, 3 a + i] = integral over tet e of dN_a/dx_i) and M the P0 pressure mass
(the element volumes). beta_h^2 is reported in units of mu, so it is dimensionless. With the
deviatoric A (weaker than the usual H1 seminorm) this beta_h is an upper bound of the
textbook one: if it falls with h, so does the textbook one.

The script takes A and B from warptissue itself: two tangent assemblies at bulk moduli K1 and
K2 differ by (K2 - K1) B^T M^-1 B, which checks the B built here from the element geometry
(``volumetric_check``, relative, should be roundoff), and A = K(K1) - K1 B^T M^-1 B. The
pressure Schur complement M^-1/2 B A^-1 B^T M^-1/2 is formed densely (one sparse LU of A,
one solve per tet), so keep the meshes to a few thousand tets.

Meshes: cubes of n^3 hexahedra split into 6 or 5 tets (bottom fixed, two symmetry planes,
the rest free), and the flat-punch benchmark's graded quarter block (also the nodes under
the bonded punch fixed).

``--numpy-cubes`` repeats the cube study with an independent NumPy assembly of the same P2/P0
element (a cross-check of the numbers above), and with one enriched variant: P2 plus one face
bubble 27 lambda_i lambda_j lambda_k per face along the face's normal (Bernardi-Raugel style
enrichment), P0 pressure.

What a falling beta_h would cost in practice is locking: a force that grows with K/mu beyond
the physics. ``--kmu-sizes`` measures that on the benchmark's meshes: the bonded-punch force at
depth a/40 for K/mu = 100, 1000 and 10 000, against the change that the material itself
makes, (1 - nu(100)) / (1 - nu(K/mu)) - 1 from Sneddon's F = 4 mu a delta / (1 - nu).

Examples:
    python scripts/infsup_p2p0.py --cubes 4,6,8 --splits six,five --bench-sizes 500,1500 \\
        --out scripts/results/infsup_p2p0.json
    python scripts/infsup_p2p0.py --cubes "" --bench-sizes "" --kmu-sizes 1500,3000,10000
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

SHEAR_MODULUS_PA = 575.0
SMALL_BULK_RATIO = 10.0
LARGE_BULK_RATIO = 1000.0


def tangent_at_rest(mesh, bulk_modulus_Pa: float) -> sp.csr_matrix:
    """The mixed TET10 tangent of a neo-Hookean solid at u = 0, as SciPy CSR (3N x 3N)."""
    import warp as wp

    from warptissue.fem import Assembler
    from warptissue.materials import NeoHookean

    assembler = Assembler(
        mesh,
        NeoHookean(C10_Pa=0.5 * SHEAR_MODULUS_PA, bulk_modulus_Pa=bulk_modulus_Pa),
        formulation="mixed",
        device="cpu",
    )
    assembler.assemble(wp.zeros(mesh.node_count, dtype=wp.vec3d, device="cpu"))
    return assembler.tangent_submatrix(np.arange(mesh.node_count))


def element_divergence(mesh) -> tuple[sp.csr_matrix, np.ndarray]:
    """B (tet_count x 3N) with B[e, 3 a + i] = int_e dN_a/dx_i dV, and the tet volumes (m^3)."""
    from warptissue.fem.elements import element_geometry

    geometry = element_geometry(mesh)
    integrals = np.einsum("tqai,tq->tai", geometry.shape_gradients, geometry.quadrature_volumes)
    tets, per_tet = mesh.tet_count, 3 * mesh.nodes_per_tet
    rows = np.repeat(np.arange(tets), per_tet)
    columns = (3 * mesh.tets[:, :, None] + np.arange(3)).reshape(tets, per_tet).ravel()
    divergence = sp.csr_matrix(
        (integrals.reshape(tets, per_tet).ravel(), (rows, columns)),
        shape=(tets, 3 * mesh.node_count),
    )
    return divergence, geometry.tet_volumes


def constrained_dofs(mesh, *, punch_radius_m: float | None) -> np.ndarray:
    """Mask (3N,) of the fixed DOFs: base, symmetry planes, and the punch's nodes if any."""
    sets = mesh.node_sets
    fixed = np.zeros((mesh.node_count, 3), dtype=bool)
    fixed[sets.get("bottom", sets.get("zmin"))] = True
    fixed[sets.get("symmetry_x", sets.get("xmin")), 0] = True
    fixed[sets.get("symmetry_y", sets.get("ymin")), 1] = True
    if punch_radius_m is not None:
        top = sets["top"]
        radius = np.hypot(mesh.points[top, 0], mesh.points[top, 1])
        fixed[top[radius <= punch_radius_m * (1.0 + 1e-9)]] = True
    return fixed.ravel()


def schur_spectrum(
    deviatoric: sp.csr_matrix, divergence: sp.csr_matrix, mass: sp.spmatrix, free: np.ndarray
) -> np.ndarray:
    """Eigenvalues (ascending, units of mu) of B A^-1 B^T p = lambda M p over the free DOFs,
    for a sparse pressure mass M (diagonal for P0)."""
    import scipy.linalg

    factor = spla.splu(deviatoric[free][:, free].tocsc())
    transposed = divergence[:, free].T.toarray()
    pressures = divergence.shape[0]
    schur = np.zeros((pressures, pressures))
    for start in range(0, pressures, 2000):
        block = transposed[:, start : start + 2000]
        schur[:, start : start + 2000] = transposed.T @ factor.solve(block)
    eigenvalues = scipy.linalg.eigh(0.5 * (schur + schur.T), mass.toarray(), eigvals_only=True)
    return eigenvalues * SHEAR_MODULUS_PA


def spectrum_record(eigenvalues: np.ndarray, free: np.ndarray, started: float) -> dict:
    """The low end of a spectrum from :func:`schur_spectrum`, for the JSON."""
    return {
        "tets": len(eigenvalues),
        "free_dofs": int(free.sum()),
        "beta_squared_smallest": [float(v) for v in eigenvalues[:8]],
        "count_below_1e-8": int(np.sum(eigenvalues < 1e-8)),
        "beta_squared_smallest_above_1e-8": float(eigenvalues[eigenvalues >= 1e-8][0]),
        "count_below_1e-2": int(np.sum(eigenvalues < 1e-2)),
        "largest": float(eigenvalues[-1]),
        "seconds": time.perf_counter() - started,
    }


def pressure_schur_spectrum(mesh, *, punch_radius_m: float | None) -> dict:
    """The spectrum for warptissue's TET10 P2/P0 element, with the check of its B."""
    started = time.perf_counter()
    small = tangent_at_rest(mesh, SMALL_BULK_RATIO * SHEAR_MODULUS_PA)
    large = tangent_at_rest(mesh, LARGE_BULK_RATIO * SHEAR_MODULUS_PA)
    divergence, volumes = element_divergence(mesh)
    volumetric = divergence.T @ sp.diags(1.0 / volumes) @ divergence
    bulk_step = (LARGE_BULK_RATIO - SMALL_BULK_RATIO) * SHEAR_MODULUS_PA
    difference = large - small
    check = abs(difference - bulk_step * volumetric).max() / abs(difference).max()
    deviatoric = small - SMALL_BULK_RATIO * SHEAR_MODULUS_PA * volumetric
    free = ~constrained_dofs(mesh, punch_radius_m=punch_radius_m)
    record = {"volumetric_check": float(check)}
    eigenvalues = schur_spectrum(deviatoric, divergence, sp.diags(volumes), free)
    record.update(spectrum_record(eigenvalues, free, started))
    return record


TET_EDGES = ((0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3))
TET_FACES = ((1, 2, 3), (0, 2, 3), (0, 1, 3), (0, 1, 2))


def tet_quadrature(points_per_direction: int = 5) -> tuple[np.ndarray, np.ndarray]:
    """Collapsed (Duffy) Gauss-Legendre rule on the reference tet: barycentrics (Q, 4) and
    weights (Q,) summing to 1/6; exact well beyond the degree-4 integrands used here."""
    x, w = np.polynomial.legendre.leggauss(points_per_direction)
    x, w = 0.5 * (x + 1.0), 0.5 * w
    u, v, t = np.meshgrid(x, x, x, indexing="ij")
    wu, wv, wt = np.meshgrid(w, w, w, indexing="ij")
    local = np.stack([u, v * (1 - u), t * (1 - u) * (1 - v)], axis=-1).reshape(-1, 3)
    weights = (wu * wv * wt * (1 - u) ** 2 * (1 - v)).ravel()
    return np.hstack([1.0 - local.sum(1, keepdims=True), local]), weights


def p2_gradients_in_barycentrics(barycentrics: np.ndarray, face_bubbles: bool) -> np.ndarray:
    """d N_a / d lambda_k at each point, (Q, 10 or 14, 4): P2 vertex and edge functions, then
    (with ``face_bubbles``) the cubic face bubbles 27 lambda_i lambda_j lambda_k."""
    points = len(barycentrics)
    gradients = np.zeros((points, 14 if face_bubbles else 10, 4))
    lam = barycentrics
    for i in range(4):
        gradients[:, i, i] = 4.0 * lam[:, i] - 1.0
    for a, (i, j) in enumerate(TET_EDGES):
        gradients[:, 4 + a, i] = 4.0 * lam[:, j]
        gradients[:, 4 + a, j] = 4.0 * lam[:, i]
    if face_bubbles:
        for a, (i, j, k) in enumerate(TET_FACES):
            gradients[:, 10 + a, i] = 27.0 * lam[:, j] * lam[:, k]
            gradients[:, 10 + a, j] = 27.0 * lam[:, i] * lam[:, k]
            gradients[:, 10 + a, k] = 27.0 * lam[:, i] * lam[:, j]
    return gradients


def quarter_block_fixed(node_points: np.ndarray, *, punch_radius_m: float | None) -> np.ndarray:
    """Fixed components (N, 3) of the quarter blocks used here: the base z = z_min, the
    symmetry planes x = 0 and y = 0, and (with ``punch_radius_m``) the top nodes under the
    bonded punch at x = y = 0."""
    low, high = node_points.min(0), node_points.max(0)
    tolerance = 1e-9 * float(np.max(high - low))
    fixed = np.zeros(node_points.shape, dtype=bool)
    fixed[node_points[:, 2] < low[2] + tolerance] = True
    fixed[node_points[:, 0] < tolerance, 0] = True
    fixed[node_points[:, 1] < tolerance, 1] = True
    if punch_radius_m is not None:
        radius = np.hypot(node_points[:, 0], node_points[:, 1])
        fixed[
            (node_points[:, 2] > high[2] - tolerance) & (radius <= punch_radius_m * (1 + 1e-9))
        ] = True
    return fixed


def numpy_mixed_operators(
    points: np.ndarray,
    corner_tets: np.ndarray,
    *,
    face_bubbles: bool,
    pressure: str,
    punch_radius_m: float | None,
    chunk: int = 2000,
) -> dict:
    """An independent NumPy assembly of P2 (optionally + one normal face bubble per face)
    displacements with P0 or continuous P1 pressures, on any TET4 corner mesh.

    Args:
        points: Corner node coordinates (N, 3), m (every node used by ``corner_tets``).
        corner_tets: Corner connectivity (T, 4), positively oriented.
        face_bubbles: Add 27 lambda_i lambda_j lambda_k n_f per face (one DOF, its amplitude
            along the face's unit normal n_f; Bernardi-Raugel style enrichment).
        pressure: ``"p0"`` (one per tet) or ``"p1"`` (continuous, one per corner node).
        punch_radius_m: Bonded punch radius for :func:`quarter_block_fixed` (None: no punch).
        chunk: Tets per vectorized batch.

    Returns:
        ``deviatoric`` A (D x D, 2 mu int dev eps(u) : dev eps(v), mu = SHEAR_MODULUS_PA),
        ``divergence`` B (P x D, B[q, d] = int psi_q div phi_d), ``pressure_mass`` M (P x P,
        int psi_q psi_r), ``free`` (D,) mask, ``punch`` (D,) mask of the punch's vertical DOFs
        (all False without a punch), ``dof_points`` (D, 3) and ``dof_components`` (D,) (-1 for
        face bubbles), ``tet_volumes`` (T,), ``corner_count`` N and ``edges`` (E, 2) (the P2
        nodes are the N corners, then the edges' midpoints; DOF 3 k + i is node k's
        component i).
    """
    tets = np.asarray(corner_tets)
    node_count, tet_count = len(points), len(tets)
    edge_keys = np.sort(tets[:, TET_EDGES], axis=2).reshape(-1, 2)
    edges, edge_of = np.unique(edge_keys, axis=0, return_inverse=True)
    face_keys = np.sort(tets[:, TET_FACES], axis=2).reshape(-1, 3)
    faces, face_of = np.unique(face_keys, axis=0, return_inverse=True)
    edge_of, face_of = edge_of.reshape(-1, 6), face_of.reshape(-1, 4)
    normals = np.cross(
        points[faces[:, 1]] - points[faces[:, 0]], points[faces[:, 2]] - points[faces[:, 0]]
    )
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    p2_nodes = node_count + len(edges)
    dof_count = 3 * p2_nodes + (len(faces) if face_bubbles else 0)
    barycentrics, weights = tet_quadrature()
    reference = p2_gradients_in_barycentrics(barycentrics, face_bubbles)
    functions = reference.shape[1]
    element_dofs = 30 + (4 if face_bubbles else 0)
    pressures_per_tet = 1 if pressure == "p0" else 4
    eye = np.eye(3)
    rows, columns, values = [], [], []
    b_rows, b_columns, b_values = [], [], []
    volumes = np.zeros(tet_count)
    for start in range(0, tet_count, chunk):
        corner = tets[start : start + chunk]
        batch = len(corner)
        jacobian = (points[corner[:, 1:]] - points[corner[:, :1]]).transpose(0, 2, 1)
        inverse = np.linalg.inv(jacobian)
        grad_lambda = np.concatenate([-inverse.sum(1, keepdims=True), inverse], axis=1)
        gradients = np.einsum("qak,tki->tqai", reference, grad_lambda)
        w = weights[None, :] * np.abs(np.linalg.det(jacobian))[:, None]
        volumes[start : start + batch] = w.sum(1)
        dot = np.einsum("tq,tqak,tqbk->tab", w, gradients, gradients, optimize=True)
        cross = np.einsum("tq,tqaj,tqbi->tabij", w, gradients, gradients, optimize=True)
        stiffness = (
            2.0
            * SHEAR_MODULUS_PA
            * (0.5 * (dot[..., None, None] * eye + cross) - cross.transpose(0, 1, 2, 4, 3) / 3.0)
        )
        stiffness = stiffness.transpose(0, 1, 3, 2, 4).reshape(batch, 3 * functions, -1)
        if pressure == "p0":
            divergence = np.einsum("tq,tqai->tai", w, gradients)[:, None]
        else:
            divergence = np.einsum("tq,qv,tqai->tvai", w, barycentrics, gradients)
        divergence = divergence.reshape(batch, pressures_per_tet, 3 * functions)
        nodes = np.concatenate([corner, node_count + edge_of[start : start + batch]], axis=1)
        dofs = (3 * nodes[:, :, None] + np.arange(3)).reshape(batch, 30)
        if face_bubbles:
            to_dofs = np.zeros((batch, 3 * functions, element_dofs))
            to_dofs[:, :30, :30] = np.eye(30)
            for k in range(4):
                to_dofs[:, 30 + 3 * k : 33 + 3 * k, 30 + k] = normals[
                    face_of[start : start + batch, k]
                ]
            stiffness = np.einsum("tki,tkl,tlj->tij", to_dofs, stiffness, to_dofs, optimize=True)
            divergence = np.einsum("tpk,tkj->tpj", divergence, to_dofs)
            dofs = np.concatenate([dofs, 3 * p2_nodes + face_of[start : start + batch]], axis=1)
        rows.append(np.repeat(dofs, element_dofs, axis=1).ravel())
        columns.append(np.tile(dofs, (1, element_dofs)).ravel())
        values.append(stiffness.ravel())
        pressure_ids = np.arange(start, start + batch)[:, None] if pressure == "p0" else corner
        b_rows.append(np.repeat(pressure_ids, element_dofs, axis=1).ravel())
        b_columns.append(np.tile(dofs, (1, pressures_per_tet)).ravel())
        b_values.append(divergence.ravel())
    deviatoric = sp.csr_matrix(
        (np.concatenate(values), (np.concatenate(rows), np.concatenate(columns))),
        shape=(dof_count, dof_count),
    )
    pressure_count = tet_count if pressure == "p0" else node_count
    divergence = sp.csr_matrix(
        (np.concatenate(b_values), (np.concatenate(b_rows), np.concatenate(b_columns))),
        shape=(pressure_count, dof_count),
    )
    if pressure == "p0":
        mass = sp.diags(volumes).tocsr()
    else:
        local = (np.ones((4, 4)) + np.eye(4)) / 20.0
        mass = sp.csr_matrix(
            (
                (volumes[:, None, None] * local).ravel(),
                (np.repeat(tets, 4, axis=1).ravel(), np.tile(tets, (1, 4)).ravel()),
            ),
            shape=(node_count, node_count),
        )
    node_points = np.vstack([points, points[edges].mean(1)])
    fixed = quarter_block_fixed(node_points, punch_radius_m=punch_radius_m)
    punch = np.zeros_like(fixed)
    if punch_radius_m is not None:
        punch[:, 2] = fixed.all(axis=1) & (node_points[:, 2] > node_points[:, 2].min())
    dof_points = np.repeat(node_points, 3, axis=0)
    dof_components = np.tile(np.arange(3), p2_nodes)
    fixed, punch = fixed.ravel(), punch.ravel()
    if face_bubbles:
        # A face's normal bubble is fixed where every corner of the face has the components
        # along the face's normal fixed (a face on a symmetry plane, the base or the punch).
        corner_fixed = quarter_block_fixed(points, punch_radius_m=punch_radius_m)[faces]
        along_normal = np.abs(normals)[:, None, :] > 1e-9
        bubble_fixed = np.all(corner_fixed | ~along_normal, axis=(1, 2))
        fixed = np.concatenate([fixed, bubble_fixed])
        punch = np.concatenate([punch, np.zeros(len(faces), dtype=bool)])
        dof_points = np.vstack([dof_points, points[faces].mean(1)])
        dof_components = np.concatenate([dof_components, np.full(len(faces), -1)])
    return {
        "deviatoric": deviatoric,
        "divergence": divergence,
        "pressure_mass": mass,
        "free": ~fixed,
        "punch": punch,
        "dof_points": dof_points,
        "dof_components": dof_components,
        "tet_volumes": volumes,
        "corner_count": node_count,
        "edges": edges,
    }


def cube_corner_mesh(divisions: int) -> tuple[np.ndarray, np.ndarray]:
    """The unit cube of divisions^3 hexahedra split into 6 tets: corner points and tets."""
    from warptissue.mesh import block_mesh

    grid = np.linspace(0.0, 1.0, divisions + 1)
    corners = block_mesh(grid, grid, grid, split="six")
    return corners.points, corners.tets[:, :4]


def corner_mesh(mesh) -> tuple[np.ndarray, np.ndarray]:
    """The corner (TET4) points and tets of a TET10 mesh, renumbered to its corner nodes."""
    used, corner_tets = np.unique(mesh.tets[:, :4], return_inverse=True)
    return mesh.points[used], corner_tets.reshape(-1, 4)


def numpy_spectrum(divisions: int, *, face_bubbles: bool) -> dict:
    """The spectrum for the NumPy P2 (+ face bubbles) / P0 element of
    :func:`numpy_mixed_operators` on a cube."""
    started = time.perf_counter()
    points, tets = cube_corner_mesh(divisions)
    operators = numpy_mixed_operators(
        points, tets, face_bubbles=face_bubbles, pressure="p0", punch_radius_m=None
    )
    free = operators["free"]
    eigenvalues = schur_spectrum(
        operators["deviatoric"], operators["divergence"], operators["pressure_mass"], free
    )
    return spectrum_record(eigenvalues, free, started)


def poisson_ratio(bulk_over_shear: float) -> float:
    """nu = (3 K - 2 mu) / (2 (3 K + mu))."""
    return (3.0 * bulk_over_shear - 2.0) / (2.0 * (3.0 * bulk_over_shear + 1.0))


def bulk_sensitivity(mesh, *, punch_radius_m: float) -> dict:
    """Bonded-punch force at depth a/40 for K/mu = 100, 1000, 10 000, relative to K/mu = 100,
    next to the half-space's own change (Sneddon, 1 / (1 - nu))."""
    from warptissue.fem import FlatPunch, IndentationProblem, simulate_indentation
    from warptissue.materials import NeoHookean

    ratios = (100.0, 1000.0, 10000.0)
    forces = []
    for ratio in ratios:
        problem = IndentationProblem(
            mesh,
            NeoHookean(C10_Pa=0.5 * SHEAR_MODULUS_PA, bulk_modulus_Pa=ratio * SHEAR_MODULUS_PA),
            FlatPunch(punch_radius_m, contact="bonded"),
            base="fixed",
            symmetry_planes=("symmetry_x", "symmetry_y"),
            formulation="mixed",
        )
        result = simulate_indentation(
            problem, [punch_radius_m / 40.0], device="cpu", progress=False, tolerance=1e-10
        )
        forces.append(float(result.reaction_force_N[-1]))
    return {
        "tets": mesh.tet_count,
        "bulk_over_shear": list(ratios),
        "force_N": forces,
        "force_change_from_100": [f / forces[0] - 1.0 for f in forces],
        "half_space_change_from_100": [
            (1.0 - poisson_ratio(ratios[0])) / (1.0 - poisson_ratio(r)) - 1.0 for r in ratios
        ],
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cubes", default="4,6,8", help="hexahedra per cube edge, comma separated")
    parser.add_argument("--splits", default="six,five", help="hexahedron splits: six, five")
    parser.add_argument(
        "--bench-sizes", default="500,1500", help="benchmark mesh sizes in tets (empty: none)"
    )
    parser.add_argument(
        "--numpy-cubes",
        default="",
        help="cubes (hexahedra per edge, 6-tet split) for the independent NumPy P2/P0 element "
        "and its P2 + normal face bubbles / P0 variant (empty: none)",
    )
    parser.add_argument(
        "--kmu-sizes",
        default="",
        help="benchmark mesh sizes in tets for the K/mu sensitivity of the force (empty: none)",
    )
    parser.add_argument("--out", type=Path, default=None, help="write the JSON here")
    args = parser.parse_args(argv)
    import warp as wp
    from bench_flat_punch import PROBE_RADIUS_M, warptissue_mesh

    from warptissue.mesh import block_mesh, to_tet10

    wp.config.quiet = True
    records = []

    def report(label: str, result: dict) -> None:
        record = {"mesh": label, **result}
        records.append(record)
        print(json.dumps(record), flush=True)

    for split in [s.strip() for s in args.splits.split(",") if s.strip()]:
        for divisions in [int(s) for s in args.cubes.split(",") if s.strip()]:
            grid = np.linspace(0.0, 10e-3, divisions + 1)
            mesh = to_tet10(block_mesh(grid, grid, grid, split=split))
            report(
                f"cube {divisions}^3 hexahedra, split {split}",
                pressure_schur_spectrum(mesh, punch_radius_m=None),
            )
    for divisions in [int(s) for s in args.numpy_cubes.split(",") if s.strip()]:
        for face_bubbles in (False, True):
            element = "P2 + normal face bubbles / P0" if face_bubbles else "P2/P0"
            report(
                f"cube {divisions}^3 hexahedra, split six, NumPy {element}",
                numpy_spectrum(divisions, face_bubbles=face_bubbles),
            )
    for sizes, study in (
        (args.bench_sizes, pressure_schur_spectrum),
        (args.kmu_sizes, bulk_sensitivity),
    ):
        for size in [int(s) for s in sizes.split(",") if s.strip()]:
            mesh, _ = warptissue_mesh(size)
            report(
                f"flat-punch benchmark quarter block, about {size} tets",
                study(mesh, punch_radius_m=PROBE_RADIUS_M),
            )
    if args.out is not None:
        from warptissue.io import write_json

        write_json(args.out, {"shear_modulus_Pa": SHEAR_MODULUS_PA, "records": records})
    return 0


if __name__ == "__main__":
    sys.exit(main())
