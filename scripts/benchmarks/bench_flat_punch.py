"""Benchmark: the flat-punch indentation curve, warptissue against FElupe at equal accuracy.

The problem (issue 2): a quarter of a 20 mm x 20 mm x 10 mm block (symmetry planes x = 0 and
y = 0, fixed base), a bonded rigid flat punch of radius a = 1 mm pressed to a / 2 in 20 load
steps, nearly incompressible neo-Hookean tissue with mu = 575 Pa (C10 = 287.5 Pa, porcine
liver, Ahn & Kim) and K / mu = 1000.

- warptissue: TET10 mixed formulation on meshes from about 10k to about 1M tets
  (``--sizes``), on the CPU or CUDA (``--device``).
- FElupe (``--felupe-levels``): Q1/P0 three-field hexahedra
  (``felupe.SolidBodyNearlyIncompressible``, Hu-Washizu with element-constant pressure and
  dilatation) on an O-grid hexahedral mesh of the same quarter block with a ring of nodes at
  r = a, the same boundary conditions and load steps, on the CPU, with PyPardiso when
  installed (else SciPy's SuperLU).
- Reference: Richardson extrapolation of the final force over the finest three meshes of one
  code (refinement ratio constant), so that both codes can be compared at EQUAL force
  accuracy: for an error target, the time each code needs is interpolated (log-log) between
  its runs.

``--probe rounded --edge-radius-m RHO`` replaces warptissue's bonded punch by a rigid flat
punch of the same radius whose edge is rounded with radius RHO, pressed in through
frictionless penalty contact (issue 21, must-show f); the probe force is then the base
reaction. FElupe always presses the bonded punch.

``--size-near-ratios R1,R2,...`` runs warptissue meshes whose near size is R times the punch
radius and whose far size is fixed (``--size-far-m``, by default the study's default for this
block, min(thickness, half width) / 4 = 2.5 mm): the force error against the near-edge size
alone, which :func:`warptissue.mesh.size_near_for_force_accuracy` is read from (issue 22).

``--markdown RESULTS...`` runs nothing and prints the runs of earlier ``--out`` files as the
Markdown tables of docs/performance.md.

Examples:
    python scripts/benchmarks/bench_flat_punch.py --sizes 10k,20k --felupe-levels 1,2,3 \\
        --out bench.json
    python scripts/benchmarks/bench_flat_punch.py --device cuda --sizes 10k,100k,1m \\
        --out $OUT/bench.json
    python scripts/benchmarks/bench_flat_punch.py --sizes 10k --probe rounded \\
        --edge-radius-m 1e-4 --out rounded.json
    python scripts/benchmarks/bench_flat_punch.py --mesher delaunay --sizes "" \\
        --size-near-ratios 1,0.5,0.25 --out size.json
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import os
import platform
import resource
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

PROBE_RADIUS_M = 1.0e-3
HALF_WIDTH_M = 10.0e-3
THICKNESS_M = 10.0e-3
SHEAR_MODULUS_PA = 575.0
BULK_MODULUS_PA = 1000.0 * SHEAR_MODULUS_PA
FINAL_DEPTH_M = 0.5 * PROBE_RADIUS_M
STEP_COUNT = 20
DEFAULT_SIZE_FAR_M = min(THICKNESS_M, HALF_WIDTH_M) / 4.0
"""The far size of ``--size-near-ratios`` meshes by default: a study's default ``size_far_m``
for this block (:mod:`warptissue.study`)."""
NEWTON_TOLERANCE = 1.0e-8
REFERENCE_FORCE_N = 2.460e-3
"""The converged force at a / 2: Richardson extrapolation of the three finest FElupe block runs
(``scripts/results/bench_flat_punch_2core_cpu.json``, ``references.felupe``), rounded."""
SIZE_TARGETS = {
    "10k": 10_000,
    "20k": 20_000,
    "50k": 50_000,
    "100k": 100_000,
    "300k": 300_000,
    "1m": 1_000_000,
}


@dataclass
class RunRecord:
    """One run of one code on one mesh."""

    code: str
    device: str
    element: str
    cells: int
    nodes: int
    dofs: int
    size_near_m: float
    steps_converged: int
    completed: bool
    newton_iterations: int
    linear_iterations: int | None
    setup_s: float
    solve_s: float
    solve_cpu_s: float
    seconds_per_step: float
    seconds_per_newton_iteration: float
    peak_host_rss_MiB: float
    peak_gpu_MiB: float | None
    final_depth_m: float
    final_force_N: float
    force_N: list[float] = field(default_factory=list)
    newton_iterations_per_step: list[int] = field(default_factory=list)
    local_iterations: int | None = None
    linear_solver: str = ""
    predictor: str = ""
    damping: bool | None = None
    nonlinear_elimination: bool | None = None
    reuse_factorization: bool | None = None
    reused_solves: int | None = None
    krylov_iterations: int | None = None
    factorizations: int | None = None
    newton_tolerance: float | None = None
    relative_error: float | None = None
    newton_profile: dict[str, Any] | None = None
    assemblies: dict[str, int] | None = None
    probe: str = "bonded"
    edge_radius_m: float = 0.0
    size_far_m: float | None = None


def comma_separated(text: str) -> list[str]:
    """The non-empty, stripped items of a comma-separated option."""
    return [item.strip() for item in text.split(",") if item.strip()]


def parse_count(text: str) -> int:
    """``"1.2k"`` -> 1200, ``"1m"`` -> 1000000, ``"5000"`` -> 5000."""
    scale = {"k": 1_000, "m": 1_000_000}.get(text[-1:].lower(), 1)
    return int(float(text[:-1] if scale > 1 else text) * scale)


def peak_rss_mib() -> float:
    """Peak resident set size of this process so far, MiB (Linux reports KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def sneddon_force_N(depth_m: float) -> float:
    """Half-space, incompressible, flat punch: F = 8 mu a delta (Sneddon 1965)."""
    return 8.0 * SHEAR_MODULUS_PA * PROBE_RADIUS_M * depth_m


def depths_m() -> np.ndarray:
    return FINAL_DEPTH_M * np.arange(1, STEP_COUNT + 1) / STEP_COUNT


# --------------------------------------------------------------------------- FElupe


def graded_levels(length_m: float, first_m: float, last_m: float) -> np.ndarray:
    """Node positions 0..length with geometrically growing spacing from first_m to ~last_m."""
    if first_m >= length_m:
        return np.array([0.0, length_m])
    last_m = max(min(last_m, length_m), first_m)
    if math.isclose(first_m, last_m):
        count = max(1, round(length_m / first_m))
        return np.linspace(0.0, length_m, count + 1)
    ratio = (length_m - first_m) / (length_m - last_m) if last_m < length_m else 2.0
    ratio = max(ratio, 1.0 + 1e-9)
    count = max(1, math.ceil(math.log(last_m / first_m) / math.log(ratio)) + 1)
    sizes = first_m * ratio ** np.arange(count)
    sizes *= length_m / sizes.sum()
    return np.concatenate([[0.0], np.cumsum(sizes)])


def geometric_levels(length_m: float, first_m: float, growth: float) -> np.ndarray:
    """Node positions 0..length with spacing first_m, first_m * growth, ... (last one fitted)."""
    sizes = [first_m]
    while sum(sizes) < length_m:
        sizes.append(sizes[-1] * growth)
    positions = np.concatenate([[0.0], np.cumsum(sizes)])
    positions *= length_m / positions[-1]
    return positions


def quarter_block_hex_mesh(size_near_m: float, size_far_m: float) -> tuple[np.ndarray, np.ndarray]:
    """O-grid hexahedral mesh of the quarter block with a ring of nodes at r = a.

    In plan: a square core [0, a/2]^2, a ring from the core's edge to the circle r = a, and
    an outer ring from the circle to the block's sides, all on rays through the core's edge
    nodes; the radial spacing grows from ``size_near_m`` at r = a to ``size_far_m``. Through
    the thickness the spacing grows from ``size_near_m`` at the top to ``size_far_m``.

    Returns:
        points (N, 3) m, hexahedra (M, 8) in VTK order with positive volume.
    """
    a = PROBE_RADIUS_M
    core = 0.5 * a
    n_core = max(2, math.ceil(0.5 * math.pi * a / (2.0 * size_near_m)))
    grid = np.linspace(0.0, core, n_core + 1)
    core_x, core_y = np.meshgrid(grid, grid, indexing="ij")
    core_points = np.column_stack([core_x.ravel(), core_y.ravel()])
    index = np.arange((n_core + 1) ** 2).reshape(n_core + 1, n_core + 1)
    core_quads = np.column_stack(
        [
            index[:-1, :-1].ravel(),
            index[1:, :-1].ravel(),
            index[1:, 1:].ravel(),
            index[:-1, 1:].ravel(),
        ]
    )
    # Rays through the core's outer edge, counter-clockwise from the x axis to the y axis.
    edge = np.concatenate(
        [
            np.column_stack([np.full(n_core + 1, core), grid]),
            np.column_stack([grid[::-1][1:], np.full(n_core, core)]),
        ]
    )
    unit = edge / np.linalg.norm(edge, axis=1, keepdims=True)
    inner_count = max(2, math.ceil((a - core) / size_near_m))
    inner_t = np.linspace(0.0, 1.0, inner_count + 1)
    outer_levels = graded_levels(HALF_WIDTH_M - a, size_near_m, size_far_m) / (HALF_WIDTH_M - a)
    on_circle = a * unit
    on_side = edge * (HALF_WIDTH_M / core)
    ring = np.concatenate(
        [
            edge[:, None] + inner_t[None, :, None] * (on_circle - edge)[:, None],
            on_circle[:, None] + outer_levels[None, 1:, None] * (on_side - on_circle)[:, None],
        ],
        axis=1,
    )
    rays, levels = ring.shape[:2]
    ring_index = len(core_points) + np.arange(rays * levels).reshape(rays, levels)
    ring_quads = np.column_stack(
        [
            ring_index[:-1, :-1].ravel(),
            ring_index[:-1, 1:].ravel(),
            ring_index[1:, 1:].ravel(),
            ring_index[1:, :-1].ravel(),
        ]
    )
    plan = np.concatenate([core_points, ring.reshape(-1, 2)])
    quads = np.concatenate([core_quads, ring_quads])
    # Merge the ring's first level with the core's edge nodes.
    keys = np.round(plan / (1e-9 * a)).astype(np.int64)
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    plan = plan[first]
    quads = inverse.reshape(-1)[quads]
    z = THICKNESS_M - graded_levels(THICKNESS_M, size_near_m, size_far_m)[::-1]
    layer = len(plan)
    points = np.column_stack([np.tile(plan, (len(z), 1)), np.repeat(z, layer)])
    bottom = quads[None] + layer * np.arange(len(z) - 1)[:, None, None]
    hexahedra = np.concatenate([bottom, bottom + layer], axis=2).reshape(-1, 8)
    corners = points[hexahedra]
    volume_sign = np.einsum(
        "ij,ij->i",
        corners[:, 1] - corners[:, 0],
        np.cross(corners[:, 3] - corners[:, 0], corners[:, 4] - corners[:, 0]),
    )
    if np.any(volume_sign <= 0):
        raise RuntimeError("the O-grid generator made an inverted hexahedron")
    return points, hexahedra.astype(np.int64)


def felupe_linear_solver() -> tuple[Any, str]:
    try:
        from pypardiso import spsolve

        return spsolve, "pypardiso (MKL PARDISO)"
    except ImportError:
        from scipy.sparse.linalg import spsolve

        return spsolve, "scipy.sparse.linalg.spsolve (SuperLU)"


def run_felupe(size_near_m: float, size_far_m: float) -> RunRecord:
    """Q1/P0 three-field FElupe run of the benchmark on one mesh."""
    import felupe as fem

    solver, solver_name = felupe_linear_solver()
    started = time.perf_counter()
    points, hexahedra = quarter_block_hex_mesh(size_near_m, size_far_m)
    mesh = fem.Mesh(points, hexahedra, "hexahedron")
    region = fem.RegionHexahedron(mesh)
    displacement = fem.FieldContainer([fem.Field(region, dim=3)])
    solid = fem.SolidBodyNearlyIncompressible(
        fem.NeoHooke(mu=SHEAR_MODULUS_PA), displacement, bulk=BULK_MODULUS_PA
    )
    x, y, z = points.T
    tolerance = 1e-9 * PROBE_RADIUS_M
    probe = (np.abs(z - THICKNESS_M) < tolerance) & (np.hypot(x, y) <= PROBE_RADIUS_M + tolerance)
    boundaries = {
        "symmetry_x": fem.Boundary(displacement[0], mask=np.abs(x) < tolerance, skip=(0, 1, 1)),
        "symmetry_y": fem.Boundary(displacement[0], mask=np.abs(y) < tolerance, skip=(1, 0, 1)),
        "bottom": fem.Boundary(displacement[0], mask=np.abs(z) < tolerance),
        "probe_xy": fem.Boundary(displacement[0], mask=probe, skip=(0, 0, 1)),
        "probe_z": fem.Boundary(displacement[0], mask=probe, skip=(1, 1, 0)),
    }
    dof0, dof1 = fem.dof.partition(displacement, boundaries)
    setup_s = time.perf_counter() - started
    # Four quarters make the full probe.
    return _felupe_depth_sweep(
        fem,
        solid,
        displacement,
        boundaries,
        dof0,
        dof1,
        (solver, solver_name),
        force_scale=4.0,
        record={
            "code": "felupe",
            "element": "HEX8 Q1/P0",
            "cells": len(hexahedra),
            "nodes": len(points),
            "dofs": 3 * len(points),
            "size_near_m": size_near_m,
            "setup_s": setup_s,
        },
    )


def run_felupe_axisymmetric_disc(size_near_m: float) -> RunRecord:
    """Axisymmetric Q1/P0 FElupe run on a DISC of radius HALF_WIDTH_M (verification only).

    The disc of radius 10 a and thickness 10 a is the round counterpart of the benchmark
    block; in 2-D a very fine mesh is cheap, so this converges far enough to check
    warptissue's ``indentation_disc`` against an independent code.
    """
    import felupe as fem

    solver, solver_name = felupe_linear_solver()
    started = time.perf_counter()
    a = PROBE_RADIUS_M
    radial = np.concatenate(
        [
            np.linspace(0.0, a, max(2, math.ceil(a / size_near_m)) + 1),
            a + geometric_levels(HALF_WIDTH_M - a, size_near_m, 1.08)[1:],
        ]
    )
    axial = THICKNESS_M - geometric_levels(THICKNESS_M, size_near_m, 1.08)[::-1]
    mesh = fem.Grid(axial, radial)  # x_1 = axial (z), x_2 = radial (r)
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
    setup_s = time.perf_counter() - started
    return _felupe_depth_sweep(
        fem,
        solid,
        displacement,
        boundaries,
        dof0,
        dof1,
        (solver, solver_name),
        force_scale=1.0,
        record={
            "code": "felupe-axisymmetric-disc",
            "element": "QUAD4 Q1/P0 axisymmetric",
            "cells": mesh.ncells,
            "nodes": mesh.npoints,
            "dofs": 2 * mesh.npoints,
            "size_near_m": size_near_m,
            "setup_s": setup_s,
        },
    )


def _felupe_depth_sweep(
    fem: Any,
    solid: Any,
    displacement: Any,
    boundaries: dict[str, Any],
    dof0: np.ndarray,
    dof1: np.ndarray,
    solver: tuple[Any, str],
    *,
    force_scale: float,
    record: dict[str, Any],
) -> RunRecord:
    """Step the ``probe_z`` boundary through :func:`depths_m` with FElupe's Newton solver.

    Args:
        solver: FElupe's linear solver and its name.
        force_scale: Probe force per step is ``force_scale`` times the -z residual at the
            probe dofs (4 for a quarter model).
        record: The run's own fields of the RunRecord (code, element, cells, nodes, dofs,
            size_near_m, setup_s).

    Returns:
        The run's record, with the force per step (N), Newton iterations and timings.
    """
    solver, solver_name = solver
    forces: list[float] = []
    newton = 0
    started, cpu_started = time.perf_counter(), time.process_time()
    for depth in depths_m():
        boundaries["probe_z"].update(-depth)
        ext0 = fem.dof.apply(displacement, boundaries, dof0)
        result = fem.newtonraphson(
            items=[solid],
            dof1=dof1,
            dof0=dof0,
            ext0=ext0,
            solver=solver,
            tol=NEWTON_TOLERANCE,
            check=_relative_check,
            verbose=0,
            maxiter=25,
        )
        newton += result.iterations
        # The residual at the prescribed probe dofs is the force the probe applies, along -z.
        forces.append(-force_scale * float(np.sum(result.fun[boundaries["probe_z"].dof])))
    solve_s, solve_cpu_s = time.perf_counter() - started, time.process_time() - cpu_started
    return RunRecord(
        device="cpu",
        steps_converged=len(forces),
        completed=True,
        newton_iterations=newton,
        linear_iterations=None,
        solve_s=solve_s,
        solve_cpu_s=solve_cpu_s,
        seconds_per_step=solve_s / STEP_COUNT,
        seconds_per_newton_iteration=solve_s / newton,
        peak_host_rss_MiB=peak_rss_mib(),
        peak_gpu_MiB=None,
        final_depth_m=FINAL_DEPTH_M,
        final_force_N=forces[-1],
        force_N=forces,
        linear_solver=solver_name,
        **record,
    )


def _relative_check(dx, x, f, xtol, ftol, dof1=None, dof0=None, items=None):
    """Newton test: free-dof residual norm relative to the reaction norm (as warptissue)."""
    residual = np.linalg.norm(f[dof1])
    reaction = np.linalg.norm(f[dof0])
    fnorm = residual / reaction if reaction > 0 else residual
    return np.linalg.norm(dx), fnorm, bool(fnorm < ftol)


# --------------------------------------------------------------------------- warptissue


def warptissue_mesh(
    target_tets: int, element: str = "TET10", *, mesher: str = "extruded"
) -> tuple[Any, float]:
    """An indentation-block mesh with about ``target_tets`` tets, and its near size
    (``mesher``: see :func:`warptissue.mesh.indentation_block`)."""
    from warptissue.mesh import indentation_block

    size_near_m = PROBE_RADIUS_M / 4.0
    for _ in range(4):
        mesh = indentation_block(
            width_m=2.0 * HALF_WIDTH_M,
            thickness_m=THICKNESS_M,
            probe_radius_m=PROBE_RADIUS_M,
            quarter=True,
            element=element,
            size_near_m=size_near_m,
            size_far_m=min(10.0 * size_near_m, 0.25 * THICKNESS_M),
            mesher=mesher,
        )
        ratio = mesh.tet_count / target_tets
        if abs(ratio - 1.0) < 0.15:
            break
        size_near_m *= ratio ** (1.0 / 3.0)
    return mesh, size_near_m


def warptissue_mesh_at(size_near_m: float, size_far_m: float, *, mesher: str = "extruded") -> Any:
    """The benchmark's TET10 indentation block at the given near and far sizes (m)."""
    from warptissue.mesh import indentation_block

    return indentation_block(
        width_m=2.0 * HALF_WIDTH_M,
        thickness_m=THICKNESS_M,
        probe_radius_m=PROBE_RADIUS_M,
        quarter=True,
        element="TET10",
        size_near_m=size_near_m,
        size_far_m=size_far_m,
        mesher=mesher,
    )


def run_warptissue(
    mesh: Any,
    size_near_m: float,
    device: str,
    *,
    steps: int = STEP_COUNT,
    progress: bool = False,
    predictor: str = "linearized",
    damping: bool = True,
    nonlinear_elimination: bool = True,
    reuse_factorization: bool = True,
    tolerance: float = NEWTON_TOLERANCE,
    profile: bool = False,
    edge_radius_m: float = 0.0,
    size_far_m: float | None = None,
) -> RunRecord:
    """warptissue TET10 mixed run of the benchmark on one mesh: its first ``steps`` load
    steps (all 20 by default; fewer make a partial run, ``completed`` False), each started
    from ``predictor``, with or without ``damping``, converged to the Newton ``tolerance``
    (free-dof residual over reaction; see :func:`warptissue.fem.solve_quasistatic`); with
    ``profile``, the time of each phase of the Newton iterations is recorded too
    (``newton_profile``, :class:`warptissue.fem.NewtonTimings`), and the assemblies of the
    run are counted (``assemblies``: ``with_tangent``, ``residual_only``). With
    ``edge_radius_m`` > 0 the punch is rigid, its edge rounded with that radius, and pressed
    in through frictionless penalty contact instead of bonded prescribed nodes. ``size_far_m``
    is the mesh's far size, recorded only."""
    import warp as wp

    from warptissue.device import resolve_device
    from warptissue.fem import Assembler, IndentationProblem, NewtonOptions, simulate_indentation
    from warptissue.indenter import Indenter
    from warptissue.materials import NeoHookean

    warp_device = resolve_device(device)
    started = time.perf_counter()
    problem = IndentationProblem(
        mesh,
        NeoHookean(C10_Pa=0.5 * SHEAR_MODULUS_PA, bulk_modulus_Pa=BULK_MODULUS_PA),
        (
            Indenter("flat_punch", radius_m=PROBE_RADIUS_M, edge_radius_m=edge_radius_m)
            if edge_radius_m > 0.0
            else Indenter("flat_punch", radius_m=PROBE_RADIUS_M, contact="bonded")
        ),
        base="fixed",
        symmetry_planes=("symmetry_x", "symmetry_y"),
        formulation="mixed",
    )
    setup_s = time.perf_counter() - started
    assembler = Assembler(problem.mesh, problem.material, device=warp_device)
    assemblies = {"with_tangent": 0, "residual_only": 0}
    if profile:  # count this run's assemblies (an instance attribute hides the method)
        assemble = assembler.assemble

        def counted(displacement: Any, *, with_tangent: bool = True, **options: Any) -> Any:
            assemblies["with_tangent" if with_tangent else "residual_only"] += 1
            return assemble(displacement, with_tangent=with_tangent, **options)

        assembler.assemble = counted
    started = time.perf_counter()
    cpu_started = time.process_time()
    result = simulate_indentation(
        problem,
        depths_m()[:steps],
        device=warp_device,
        progress=progress,
        options=NewtonOptions(
            tolerance=tolerance,
            predictor=predictor,
            damping=damping,
            nonlinear_elimination=nonlinear_elimination,
            reuse_factorization=reuse_factorization,
        ),
        assembler=assembler,
        profile=profile,
    )
    wp.synchronize_device(warp_device)
    solve_s = time.perf_counter() - started
    solve_cpu_s = time.process_time() - cpu_started
    newton = int(np.sum(result.newton_iterations))
    peak_gpu = None
    if warp_device.is_cuda:
        peak_gpu = wp.get_mempool_used_mem_high(warp_device) / 2**20
    forces = [float(f) for f in result.reaction_force_N]
    return RunRecord(
        code="warptissue",
        device=str(warp_device),
        element=f"{mesh.element_type} mixed",
        cells=mesh.tet_count,
        nodes=mesh.node_count,
        dofs=3 * mesh.node_count,
        size_near_m=size_near_m,
        steps_converged=len(forces),
        completed=bool(result.completed) and steps == STEP_COUNT,
        newton_iterations=newton,
        linear_iterations=int(np.sum(result.linear_iterations)),
        setup_s=setup_s,
        solve_s=solve_s,
        solve_cpu_s=solve_cpu_s,
        seconds_per_step=solve_s / max(1, len(forces)),
        seconds_per_newton_iteration=solve_s / max(1, newton),
        peak_host_rss_MiB=peak_rss_mib(),
        peak_gpu_MiB=peak_gpu,
        final_depth_m=float(result.depths_m[-1]) if forces else 0.0,
        final_force_N=forces[-1] if forces else float("nan"),
        force_N=forces,
        newton_iterations_per_step=[int(n) for n in result.newton_iterations],
        local_iterations=int(np.sum(result.local_iterations)),
        linear_solver=str(getattr(result, "linear_solver", "")),
        predictor=predictor,
        damping=damping,
        nonlinear_elimination=nonlinear_elimination,
        reuse_factorization=reuse_factorization,
        reused_solves=result.linear_solver_statistics.get("reused_solves"),
        krylov_iterations=result.linear_solver_statistics.get("krylov_iterations"),
        factorizations=result.linear_solver_statistics.get("factorizations"),
        newton_tolerance=tolerance,
        newton_profile=None if result.timings is None else result.timings.to_dict(),
        assemblies=assemblies if profile else None,
        probe="rounded" if edge_radius_m > 0.0 else "bonded",
        edge_radius_m=edge_radius_m,
        size_far_m=size_far_m,
    )


# --------------------------------------------------------------------------- accuracy


def richardson(
    cells: list[int], forces: list[float], *, dimension: int = 3
) -> dict[str, float] | None:
    """Extrapolate F(h) = F* + C h^p from the three finest runs (h = cells^(-1/dimension)).

    Returns:
        ``{"force_N", "order"}``, or None when the three forces do not converge monotonically.
    """
    if len(cells) < 3:
        return None
    order_by_size = np.argsort(cells)[-3:]
    h = np.asarray(cells, dtype=float)[order_by_size] ** (-1.0 / dimension)
    f = np.asarray(forces, dtype=float)[order_by_size]
    d12, d23 = f[0] - f[1], f[1] - f[2]
    if d12 * d23 <= 0 or abs(d23) >= abs(d12):
        return None

    def mismatch(p: float) -> float:
        return (h[0] ** p - h[1] ** p) / (h[1] ** p - h[2] ** p) - d12 / d23

    low, high = 0.2, 8.0
    if mismatch(low) * mismatch(high) > 0:
        return None
    for _ in range(200):
        middle = 0.5 * (low + high)
        if mismatch(low) * mismatch(middle) <= 0:
            high = middle
        else:
            low = middle
    p = 0.5 * (low + high)
    c = d12 / (h[0] ** p - h[1] ** p)
    return {"force_N": float(f[2] - c * h[2] ** p), "order": float(p)}


def cheapest_run_within(records: list[RunRecord], target: float) -> dict[str, Any] | None:
    """The cheapest measured run (by CPU seconds) whose relative force error is <= target.

    No interpolation: the error of a mesh family need not fall monotonically with its cost.
    """
    within = [r for r in records if r.relative_error is not None and r.relative_error <= target]
    if not within:
        return None
    best = min(within, key=lambda r: r.solve_cpu_s)
    return {
        "cells": best.cells,
        "relative_error": best.relative_error,
        "solve_s": best.solve_s,
        "solve_cpu_s": best.solve_cpu_s,
    }


# --------------------------------------------------------------------------- main


def machine_description() -> dict[str, Any]:
    model = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {
        "cpu": model,
        "cpu_count": os.cpu_count(),
        "python": platform.python_version(),
        "platform": platform.platform(),
    }


def print_table(records: list[RunRecord]) -> None:
    header = (
        f"{'code':<10} {'predictor':<12} {'damp':<4} {'tol':>7} {'device':<7} {'cells':>8} "
        f"{'dofs':>9} {'newton':>6} {'linear':>7} "
        f"{'s/step':>8} {'total_s':>8} {'cpu_s':>8} {'s/newton':>8} {'RSS_MiB':>8} {'GPU_MiB':>8} "
        f"{'F_final_N':>11} {'error':>7}"
    )
    print(header)
    for r in records:
        gpu = f"{r.peak_gpu_MiB:8.0f}" if r.peak_gpu_MiB is not None else f"{'-':>8}"
        linear = f"{r.linear_iterations:7d}" if r.linear_iterations is not None else f"{'-':>7}"
        error = f"{100 * r.relative_error:6.2f}%" if r.relative_error is not None else f"{'-':>7}"
        damp = {None: "-", True: "on", False: "off"}[r.damping]
        tol = f"{r.newton_tolerance:7.0e}" if r.newton_tolerance is not None else f"{'-':>7}"
        print(
            f"{r.code[:10]:<10} {r.predictor or '-':<12} {damp:<4} {tol} {r.device:<7} "
            f"{r.cells:8d} {r.dofs:9d} {r.newton_iterations:6d} "
            f"{linear} {r.seconds_per_step:8.3f} {r.solve_s:8.2f} {r.solve_cpu_s:8.2f} "
            f"{r.seconds_per_newton_iteration:8.3f} {r.peak_host_rss_MiB:8.0f} {gpu} "
            f"{r.final_force_N:11.5e} {error}"
        )


def _grouped(value: float) -> str:
    """An integer with thin groups of three digits, as the docs print counts (``8 828``)."""
    return f"{int(round(value)):,}".replace(",", " ")


def _seconds(value: float) -> str:
    return f"{value:.3g}" if value < 10 else f"{value:.1f}"


def _force_change_column(runs: list[dict[str, Any]]) -> Any:
    """The cell function of the "force change vs tightest" column: the largest relative change
    of a run's force over its load steps from the run of the smallest Newton tolerance on the
    same mesh and settings ("0" for that run itself, "-" where no such run completed)."""

    def same_case(run: dict[str, Any]) -> tuple[Any, ...]:
        keys = ("code", "mesher", "cells", "probe", "predictor", "damping")
        return (
            *(run[k] for k in keys),
            run.get("nonlinear_elimination"),
            run.get("reuse_factorization"),
        )

    tightest: dict[tuple[Any, ...], dict[str, Any]] = {}
    for run in runs:
        if run["completed"] and run.get("newton_tolerance") is not None:
            best = tightest.get(same_case(run))
            if best is None or run["newton_tolerance"] < best["newton_tolerance"]:
                tightest[same_case(run)] = run

    def cell(run: dict[str, Any]) -> str:
        base = tightest.get(same_case(run))
        if base is None or not run["completed"] or run.get("newton_tolerance") is None:
            return "-"
        if base is run:
            return "0"
        change = np.abs(np.asarray(run["force_N"]) / np.asarray(base["force_N"]) - 1.0).max()
        return f"{change:.1e}"

    return cell


def markdown_table(paths: list[Path], *, only: list[str] = ()) -> str:
    """A Markdown table of the runs recorded in results files written by ``--out``.

    One row per run, in file order. Runs recorded before an option existed get the value
    that the code had then (predictor "linearized", damping "off", the problem's
    tolerance). ``only`` keeps the runs whose column has the given value (``"damping=on"``).
    The predictor, damping and tolerance columns appear only where the runs differ in them
    (with the tolerance, the factorizations where the runs counted them, and the largest
    relative force change over the load steps from the run of the smallest tolerance on the
    same mesh),
    the steps column only where a run stopped early, the GPU memory column only where a run
    recorded it. The force error is taken against :data:`REFERENCE_FORCE_N`.
    """
    runs = []
    for path in paths:
        report = json.loads(Path(path).read_text())
        problem = report.get("problem", {})
        defaults = {
            "mesher": problem.get("warptissue_mesher", "extruded"),
            "predictor": "linearized",
            "damping": "off",
            "tolerance": f"{problem.get('newton_tolerance', NEWTON_TOLERANCE):g}",
            "probe": "bonded",
        }
        for run in report["runs"]:
            row = defaults | {k: v for k, v in run.items() if v is not None}
            if isinstance(row["damping"], bool):
                row["damping"] = "on" if row["damping"] else "off"
            if "newton_tolerance" in run and run["newton_tolerance"] is not None:
                row["tolerance"] = f"{run['newton_tolerance']:g}"
            if row["probe"] == "rounded":
                row["probe"] = f"rounded, edge {1e6 * row['edge_radius_m']:g} um"
            if row["code"] != "warptissue":
                row.update(mesher="O-grid", predictor="-", damping="-", tolerance="-")
            runs.append(row)
    for condition in only:
        key, _, value = condition.partition("=")
        runs = [r for r in runs if str(r.get(key)) == value]
    if not runs:
        raise ValueError(f"no run in {[str(p) for p in paths]} matches {list(only)}")
    digits = 2 if all(r.get("size_far_m") for r in runs) else 1  # the size-near runs: 0.01 %
    names = {"warptissue": "warptissue TET10 mixed", "felupe": "FElupe Q1/P0 hex"}
    columns: list[tuple[str, Any]] = []
    if len({r["code"] for r in runs}) > 1:
        columns.append(("code", lambda r: names.get(r["code"], r["code"])))
    columns.append(("mesh", lambda r: r["mesher"]))
    for key in ("probe", "predictor", "damping", "tolerance"):
        if len({r[key] for r in runs if r["code"] == "warptissue"}) > 1:
            columns.append((key, lambda r, key=key: r[key]))
    columns += [
        ("cells", lambda r: _grouped(r["cells"])),
        ("DOFs", lambda r: _grouped(r["dofs"])),
        ("near size (um)", lambda r: _grouped(1e6 * r["size_near_m"])),
    ]
    if all(r.get("size_far_m") for r in runs):
        columns += [
            ("near size / a", lambda r: f"{r['size_near_m'] / PROBE_RADIUS_M:.3g}"),
            ("far size (um)", lambda r: _grouped(1e6 * r["size_far_m"])),
        ]
    if not all(r["completed"] for r in runs):
        columns.append(("load steps", lambda r: f"{r['steps_converged']} of {STEP_COUNT}"))
    columns += [
        ("Newton its", lambda r: str(r["newton_iterations"])),
    ]
    if any(r["probe"] != "bonded" for r in runs):
        columns.append(
            (
                "its / step: mean, max",
                lambda r: (
                    f"{np.mean(r['newton_iterations_per_step']):.1f}, "
                    f"{max(r['newton_iterations_per_step'])}"
                    if r.get("newton_iterations_per_step")
                    else "-"
                ),
            )
        )
    columns += [
        ("total s (wall)", lambda r: _seconds(r["solve_s"])),
        ("CPU s", lambda r: _seconds(r["solve_cpu_s"])),
        ("s / Newton it", lambda r: f"{r['seconds_per_newton_iteration']:.3g}"),
    ]
    if any(r.get("peak_gpu_MiB") for r in runs):
        columns.append(("peak GPU MiB", lambda r: _grouped(r.get("peak_gpu_MiB", 0)) or "-"))
    columns += [
        (
            "final force (mN)",
            lambda r: f"{1e3 * r['final_force_N']:.4f}" if r["completed"] else "-",
        ),
        (
            "vs 2.460 mN",
            lambda r: (
                f"{100 * (r['final_force_N'] / REFERENCE_FORCE_N - 1):+.{digits}f} %"
                if r["completed"] and r["probe"] == "bonded"
                else "-"
            ),
        ),
    ]
    if any(title == "tolerance" for title, _ in columns):
        if all(r.get("factorizations") is not None for r in runs):
            columns.append(("factorizations", lambda r: str(r["factorizations"])))
        columns.append(("force change vs tightest", _force_change_column(runs)))
    text_columns = {"code", "mesh", "probe", "predictor", "damping", "tolerance"}
    lines = [
        "| " + " | ".join(title for title, _ in columns) + " |",
        "|" + "|".join("---" if t in text_columns else "---:" for t, _ in columns) + "|",
    ]
    lines += ["| " + " | ".join(cell(r) for _, cell in columns) + " |" for r in runs]
    return "\n".join(lines)


PROFILE_COLUMNS = (
    ("assembly", "assembly"),
    ("line search", "line_search"),
    ("elimination", "elimination"),
    ("host", "host"),
    ("analysis", "analysis"),
    ("factorization", "factorization"),
    ("solve", "solve"),
)
"""The per-phase columns of :func:`markdown_profile_table` (title, phase): the Newton loop's
own first, then the linear solver's (the sensitivity phase, zero in this benchmark, is left
out)."""


def markdown_profile_table(paths: list[Path], *, only: list[str] = ()) -> str:
    """A Markdown table of where the Newton iterations' time went, one row per profiled run.

    Milliseconds per Newton iteration per phase (:mod:`warptissue.fem.timing`), and the share
    of the run's wall time outside the linear solver (the Newton loop's own cost). A results
    file written with ``--label`` names its runs in a first column.
    """
    runs = []
    for path in paths:
        report = json.loads(Path(path).read_text())
        mesher = report.get("problem", {}).get("warptissue_mesher", "extruded")
        load = report.get("notes", {}).get("load_average_at_end")
        for run in report["runs"]:
            if run.get("newton_profile"):
                runs.append(
                    {"label": report.get("label", ""), "mesher": mesher, "load": load, **run}
                )
    for condition in only:
        key, _, value = condition.partition("=")
        runs = [r for r in runs if str(r.get(key)) == value]
    if not runs:
        raise ValueError(f"no profiled run in {[str(p) for p in paths]} matches {list(only)}")
    columns: list[tuple[str, Any]] = []
    if any(r["label"] for r in runs):
        columns.append(("run", lambda r: r["label"]))
    columns += [
        ("mesh", lambda r: r["mesher"]),
        ("cells", lambda r: _grouped(r["cells"])),
        ("DOFs", lambda r: _grouped(r["dofs"])),
        ("Newton its", lambda r: str(r["newton_profile"]["newton_iterations"])),
        ("total s", lambda r: _seconds(r["newton_profile"]["total_s"])),
    ]
    if any(r["load"] for r in runs):
        columns.append(("load", lambda r: f"{r['load'][0]:.1f}" if r["load"] else "-"))
    if any(r.get("assemblies") for r in runs):
        columns.append(
            (
                "assemblies (tangent + residual)",
                lambda r: (
                    f"{r['assemblies']['with_tangent']} + {r['assemblies']['residual_only']}"
                    if r.get("assemblies")
                    else "-"
                ),
            )
        )

    def per_iteration_ms(run: dict[str, Any], phase: str) -> str:
        return f"{1e3 * run['newton_profile']['seconds_per_newton_iteration'][phase]:.0f}"

    for title, phase in (*PROFILE_COLUMNS, ("total", "total")):
        columns.append((f"{title} (ms/it)", lambda r, phase=phase: per_iteration_ms(r, phase)))
    columns += [
        ("outside the solver", lambda r: f"{100 * r['newton_profile']['own_share']:.1f} %"),
    ]
    text_columns = {"run", "mesh"}
    lines = [
        "| " + " | ".join(title for title, _ in columns) + " |",
        "|" + "|".join("---" if t in text_columns else "---:" for t, _ in columns) + "|",
    ]
    lines += ["| " + " | ".join(cell(r) for _, cell in columns) + " |" for r in runs]
    return "\n".join(lines)


def markdown_solver_table(paths: list[Path], *, only: list[str] = ()) -> str:
    """A Markdown table of the linear solves of profiled runs: factorizations against solves
    with earlier factors (``--reuse``) and the nonlinear elimination (``--elimination``).

    One row per profiled run: Newton iterations, factorizations, Newton solves by GMRES with
    earlier factors and their GMRES iterations, the seconds of the whole curve, of the
    factorizations, of the solves and of the elimination, the share inside the linear solver
    (analysis, factorization, solve), and the final force.
    """
    runs = []
    for path in paths:
        report = json.loads(Path(path).read_text())
        for run in report["runs"]:
            if run.get("newton_profile") and run.get("factorizations") is not None:
                runs.append({"label": report.get("label", ""), **run})
    for condition in only:
        key, _, value = condition.partition("=")
        runs = [r for r in runs if str(r.get(key)) == value]
    if not runs:
        raise ValueError(f"no profiled run with solver counts in {[str(p) for p in paths]}")
    on_off = {True: "on", False: "off"}

    def seconds(run: dict[str, Any], phase: str) -> str:
        return _seconds(run["newton_profile"]["seconds"][phase])

    columns: list[tuple[str, Any]] = [
        ("run", lambda r: r["label"]),
        ("cells", lambda r: _grouped(r["cells"])),
        ("elimination", lambda r: on_off[bool(r["nonlinear_elimination"])]),
        ("reuse", lambda r: on_off[bool(r["reuse_factorization"])]),
        ("Newton its", lambda r: str(r["newton_iterations"])),
        ("factorizations", lambda r: str(r["factorizations"])),
        ("solves with old factors", lambda r: str(r["reused_solves"])),
        ("GMRES its", lambda r: str(r["krylov_iterations"])),
        ("total s", lambda r: _seconds(r["newton_profile"]["total_s"])),
        ("factorization s", lambda r: seconds(r, "factorization")),
        ("solve s", lambda r: seconds(r, "solve")),
        ("elimination s", lambda r: seconds(r, "elimination")),
        (
            "inside the linear solver",
            lambda r: f"{100 * (1 - r['newton_profile']['own_share']):.0f} %",
        ),
        ("final force (mN)", lambda r: f"{1e3 * r['final_force_N']:.6f}"),
    ]
    text_columns = {"run", "elimination", "reuse"}
    lines = [
        "| " + " | ".join(title for title, _ in columns) + " |",
        "|" + "|".join("---" if t in text_columns else "---:" for t, _ in columns) + "|",
    ]
    lines += ["| " + " | ".join(cell(r) for _, cell in columns) + " |" for r in runs]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--device", default="cpu", help="warptissue device: cpu, cuda, cuda:N")
    parser.add_argument(
        "--sizes",
        default="10k,20k",
        help=f"warptissue mesh sizes, comma separated, from {list(SIZE_TARGETS)} or a tet "
        "count (empty: skip warptissue)",
    )
    parser.add_argument(
        "--size-near-ratios",
        default="",
        help="warptissue meshes whose near size is each of these multiples of the punch "
        "radius (comma separated, in (0, 1]), with the far size --size-far-m: the force error "
        "against the near-edge size alone (empty: none)",
    )
    parser.add_argument(
        "--size-far-m",
        type=float,
        default=DEFAULT_SIZE_FAR_M,
        help="far size of the --size-near-ratios meshes, m (default: a study's default for "
        f"this block, {DEFAULT_SIZE_FAR_M:g})",
    )
    parser.add_argument(
        "--felupe-levels",
        default="",
        help="FElupe mesh levels, comma separated integers; level L has size_near = "
        "a / (2 * 1.5^L) (empty: skip FElupe)",
    )
    parser.add_argument(
        "--felupe-axisymmetric-levels",
        default="",
        help="verification: axisymmetric FElupe runs on the round counterpart of the block "
        "(a disc of radius 10 a), comma separated integers; level L has size_near = "
        "a / (4 * 2^L) (empty: skip)",
    )
    parser.add_argument(
        "--steps",
        type=int,
        default=STEP_COUNT,
        help=f"run only the first STEPS of the {STEP_COUNT} load steps on each warptissue mesh "
        "(a partial curve, reported as not completed)",
    )
    parser.add_argument(
        "--progress", action="store_true", help="show a progress bar over each run's load steps"
    )
    parser.add_argument(
        "--mesher",
        default="extruded",
        choices=("extruded", "delaunay"),
        help="warptissue meshes: layered prisms, or TetGen's quality tets inside the same "
        "graded surface",
    )
    parser.add_argument(
        "--predictors",
        default="linearized",
        help="start of each load step's Newton iterations, comma separated, from "
        "linearized, extrapolated: each mesh runs once per predictor",
    )
    parser.add_argument(
        "--reuse",
        default="on",
        help="GMRES with the last factorization where it is cheaper than a new one: on, off, "
        "or on,off (each mesh runs once per setting; recorded as reuse_factorization)",
    )
    parser.add_argument(
        "--elimination",
        default="on",
        help="nonlinear elimination after each global Newton step: on, off, or on,off (each "
        "mesh runs once per setting; recorded as nonlinear_elimination)",
    )
    parser.add_argument(
        "--damping",
        default="on",
        help="Levenberg-Marquardt damping after cut Newton steps: on, off, or on,off (each "
        "mesh runs once per setting)",
    )
    parser.add_argument(
        "--tolerances",
        default=f"{NEWTON_TOLERANCE:g}",
        help="warptissue Newton tolerances (free-dof residual over reaction), comma separated: "
        "each mesh runs once per tolerance; the first is the one the reference and the "
        f"equal-accuracy comparison use (FElupe always runs at {NEWTON_TOLERANCE:g})",
    )
    parser.add_argument(
        "--profile",
        action="store_true",
        help="time each phase of warptissue's Newton iterations (assembly, factorization, "
        "solve, line search, elimination, host; on CUDA the device is synchronized at each "
        "phase boundary) and print and record the table (newton_profile); with --markdown: "
        "print the profiled runs' milliseconds per Newton iteration per phase instead",
    )
    parser.add_argument(
        "--label",
        default="",
        help="a name for this results file's runs (e.g. the code version), recorded in the "
        "JSON and shown by --markdown --profile",
    )
    parser.add_argument(
        "--probe",
        default="bonded",
        choices=("bonded", "rounded"),
        help="warptissue's punch: bonded prescribed nodes, or a rigid punch with a rounded "
        "edge (--edge-radius-m) in frictionless penalty contact",
    )
    parser.add_argument(
        "--edge-radius-m",
        type=float,
        default=0.0,
        help="edge radius of the rounded punch, m (0 < RHO <= the punch radius "
        f"{PROBE_RADIUS_M:g})",
    )
    parser.add_argument("--out", type=Path, default=None, help="write the JSON here")
    parser.add_argument(
        "--markdown",
        type=Path,
        nargs="+",
        metavar="RESULTS",
        help="run nothing: print the runs of these --out files as a Markdown table (the "
        "tables of docs/performance.md)",
    )
    parser.add_argument(
        "--only",
        action="append",
        default=[],
        metavar="COLUMN=VALUE",
        help="with --markdown: only the runs with this value (damping=on, tolerance=1e-08, "
        "mesher=delaunay, ...); may be repeated",
    )
    parser.add_argument(
        "--solver",
        action="store_true",
        help="with --markdown: print the linear solves of the profiled runs (factorizations, "
        "solves with earlier factors, elimination) instead",
    )
    args = parser.parse_args(argv)
    if args.markdown:
        table = (
            markdown_solver_table
            if args.solver
            else markdown_profile_table
            if args.profile
            else markdown_table
        )
        try:
            print(table(args.markdown, only=args.only))
        except (OSError, ValueError, KeyError) as exc:
            parser.error(f"--markdown: {exc}")
        return 0
    if not 1 <= args.steps <= STEP_COUNT:
        parser.error(f"--steps must be between 1 and {STEP_COUNT}, got {args.steps}")
    from warptissue.fem.newton import PREDICTORS

    predictors = comma_separated(args.predictors)
    if not predictors or not set(predictors) <= set(PREDICTORS):
        parser.error(f"--predictors takes {' and/or '.join(PREDICTORS)}, got {args.predictors!r}")
    try:
        tolerances = [float(t) for t in comma_separated(args.tolerances)]
    except ValueError:
        parser.error(f"--tolerances takes numbers, got {args.tolerances!r}")
    if not tolerances or any(not 0.0 < t < 1.0 for t in tolerances):
        parser.error(f"--tolerances must lie in (0, 1), got {args.tolerances!r}")
    edge_radius_m = args.edge_radius_m if args.probe == "rounded" else 0.0
    if args.probe == "rounded" and not 0.0 < edge_radius_m <= PROBE_RADIUS_M:
        parser.error(
            f"--probe rounded needs 0 < --edge-radius-m <= {PROBE_RADIUS_M:g}, got "
            f"{args.edge_radius_m!r}"
        )
    settings = {"on": True, "off": False}
    dampings = comma_separated(args.damping)
    if not dampings or any(d not in settings for d in dampings):
        parser.error(f"--damping takes on and/or off, got {args.damping!r}")
    eliminations = comma_separated(args.elimination)
    if not eliminations or any(e not in settings for e in eliminations):
        parser.error(f"--elimination takes on and/or off, got {args.elimination!r}")
    reuses = comma_separated(args.reuse)
    if not reuses or any(r not in settings for r in reuses):
        parser.error(f"--reuse takes on and/or off, got {args.reuse!r}")

    try:
        ratios = [float(r) for r in comma_separated(args.size_near_ratios)]
    except ValueError:
        parser.error(f"--size-near-ratios takes numbers, got {args.size_near_ratios!r}")
    if any(not 0.0 < r <= 1.0 for r in ratios):
        parser.error(f"--size-near-ratios must lie in (0, 1], got {args.size_near_ratios!r}")
    if not 0.0 < args.size_far_m <= THICKNESS_M:
        parser.error(f"--size-far-m must lie in (0, {THICKNESS_M:g}], got {args.size_far_m!r}")

    records: list[RunRecord] = []
    notes: dict[str, Any] = {}
    sizes = [size.lower() for size in comma_separated(args.sizes)]
    meshes: list[tuple[Any, float, float]] = []  # mesh, near size, far size
    for size in sizes:
        target = SIZE_TARGETS.get(size) or parse_count(size)
        mesh, size_near_m = warptissue_mesh(target, mesher=args.mesher)
        meshes.append((mesh, size_near_m, min(10.0 * size_near_m, 0.25 * THICKNESS_M)))
    for ratio in ratios:
        size_near_m = ratio * PROBE_RADIUS_M
        size_far_m = max(args.size_far_m, size_near_m)
        meshes.append(
            (
                warptissue_mesh_at(size_near_m, size_far_m, mesher=args.mesher),
                size_near_m,
                size_far_m,
            )
        )
    if meshes:
        import warp as wp

        wp.config.quiet = True
        started = time.perf_counter()
        warm_mesh, warm_size = warptissue_mesh(500)
        run_warptissue(
            warm_mesh, warm_size, args.device, profile=args.profile, edge_radius_m=edge_radius_m
        )
        notes["warptissue_warmup_s"] = time.perf_counter() - started
        for mesh, size_near_m, size_far_m in meshes:
            for predictor, damping, tolerance, elimination, reuse in itertools.product(
                predictors, dampings, tolerances, eliminations, reuses
            ):
                record = run_warptissue(
                    mesh,
                    size_near_m,
                    args.device,
                    steps=args.steps,
                    progress=args.progress,
                    predictor=predictor,
                    damping=settings[damping],
                    nonlinear_elimination=settings[elimination],
                    reuse_factorization=settings[reuse],
                    tolerance=tolerance,
                    profile=args.profile,
                    edge_radius_m=edge_radius_m,
                    size_far_m=size_far_m,
                )
                records.append(record)
                print_table([record])
                if record.newton_profile is not None:
                    from warptissue.fem import NewtonTimings

                    print(NewtonTimings.from_dict(record.newton_profile).table())
                sys.stdout.flush()
    for level in [int(s) for s in comma_separated(args.felupe_levels)]:
        size_near_m = 0.5 * PROBE_RADIUS_M / 1.5**level
        record = run_felupe(size_near_m, 10.0 * size_near_m)
        records.append(record)
        print_table([record])
        sys.stdout.flush()

    for level in [int(s) for s in comma_separated(args.felupe_axisymmetric_levels)]:
        record = run_felupe_axisymmetric_disc(0.25 * PROBE_RADIUS_M / 2**level)
        records.append(record)
        print_table([record])
        sys.stdout.flush()

    references = {}
    for code in ("warptissue", "felupe", "felupe-axisymmetric-disc"):
        runs = [
            r
            for r in records
            if r.code == code
            and r.completed
            and r.predictor in ("", predictors[0])
            and r.damping in (None, settings[dampings[0]])
            and r.newton_tolerance in (None, tolerances[0])
        ]
        extrapolated = richardson(
            [r.cells for r in runs],
            [r.final_force_N for r in runs],
            dimension=2 if code == "felupe-axisymmetric-disc" else 3,
        )
        if extrapolated is not None:
            references[code] = extrapolated
    reference = references.get("warptissue") or references.get("felupe")
    if reference is not None:
        for r in (r for r in records if r.code in ("warptissue", "felupe")):
            r.relative_error = abs(r.final_force_N - reference["force_N"]) / reference["force_N"]
    equal_accuracy = {}
    for target in (0.05, 0.02, 0.01, 0.005):
        times = {
            code: cheapest_run_within([r for r in records if r.code == code], target)
            for code in ("warptissue", "felupe")
        }
        equal_accuracy[f"{target:g}"] = times
    print()
    print_table(records)
    print(f"references (Richardson): {json.dumps(references)}")
    print(f"Sneddon half-space force at the final depth: {sneddon_force_N(FINAL_DEPTH_M):.5e} N")
    print("cheapest run within each relative force error:")
    for target, runs in equal_accuracy.items():
        print(f"  {target}: {json.dumps(runs)}")
    notes["load_average_at_end"] = list(os.getloadavg())  # 1, 5 and 15 minutes
    report = {
        **({"label": args.label} if args.label else {}),
        "problem": {
            "probe_radius_m": PROBE_RADIUS_M,
            "half_width_m": HALF_WIDTH_M,
            "thickness_m": THICKNESS_M,
            "shear_modulus_Pa": SHEAR_MODULUS_PA,
            "bulk_modulus_Pa": BULK_MODULUS_PA,
            "final_depth_m": FINAL_DEPTH_M,
            "steps": STEP_COUNT,
            "newton_tolerance": NEWTON_TOLERANCE,
            "warptissue_newton_tolerances": tolerances,
            "warptissue_mesher": args.mesher,
            "warptissue_probe": args.probe,
            "warptissue_edge_radius_m": edge_radius_m,
            "sneddon_force_N": sneddon_force_N(FINAL_DEPTH_M),
        },
        "machine": machine_description(),
        "runs": [asdict(r) for r in records],
        "references": references,
        "reference_used": reference,
        "cheapest_run_within_error": equal_accuracy,
        "notes": notes,
    }
    if args.out is not None:
        from warptissue.io import write_json

        write_json(args.out, report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
