"""A study's mesh and indentation problem: what :func:`warptissue.simulate.prepare_study` builds.

:func:`build_mesh` meshes the specimen (or the organ) a :class:`~warptissue.study.Study` names,
after :func:`estimate_mesh` has said it fits in memory; :func:`build_problem` makes its
:class:`~warptissue.fem.IndentationProblem`; :func:`record_problems` does both for each record
of a fit. :class:`StudySetup` holds what a run needs before its load steps.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from warptissue.errors import InputError
from warptissue.fem import (
    IndentationProblem,
    LinearSolver,
)
from warptissue.mesh import (
    MeshSizeEstimate,
    estimate_indentation_mesh,
    indentation_block,
    indentation_disc,
    near_size_choice,
)
from warptissue.study import (
    Study,
    organ_mesh,
    probe_placement,
    specimen_mesh,
    support_nodes,
)


def build_mesh(study: Study) -> Any:
    """Generate the specimen mesh a study describes.

    Args:
        study: The study.

    Returns:
        A :class:`warptissue.mesh.TetMesh` with the standard indentation node sets.
    """

    specimen = study.specimen
    if specimen.shape == "mesh":
        return _organ_mesh(study)
    common = {
        "thickness_m": specimen.thickness_m,
        "probe_radius_m": study.mesh_probe_radius_m,
        "quarter": specimen.quarter,
        "element": specimen.element,
        "size_near_m": specimen.size_near_m,
        "size_far_m": specimen.size_far_m,
        "growth": specimen.growth,
        "mesher": specimen.mesher,
    }
    if specimen.shape == "block":
        return indentation_block(width_m=specimen.width_m, **common)
    return indentation_disc(radius_m=specimen.radius_m, **common)


def size_near_reason(study: Study) -> str | None:
    """Which near size ``specimen.force_accuracy`` chose, and why; None where the study gives
    ``size_near_m`` (or leaves it at its default) instead.

    Args:
        study: The study.

    Returns:
        One sentence (:meth:`warptissue.mesh.NearSizeChoice.reason`), or None.
    """

    specimen = study.specimen
    if specimen.force_accuracy is None:
        return None
    if specimen.shape == "mesh":  # refined around its sites, TetGen's tets: the study's site
        return near_size_choice(
            specimen.force_accuracy,
            probe_radius_m=specimen.refine_zones[0][3],
            mesher="delaunay",
            element=specimen.element,
        ).reason()
    return near_size_choice(
        specimen.force_accuracy,
        probe_radius_m=study.mesh_probe_radius_m,
        mesher=specimen.mesher,
        element=specimen.element,
    ).reason()


def estimate_mesh(study: Study) -> Any:
    """The size of the study's mesh and the memory it takes, before it is generated.

    Args:
        study: The study.

    Returns:
        A :class:`warptissue.mesh.MeshSizeEstimate` (tets, nodes, bytes to generate and to
        solve on the CPU).
    """

    specimen = study.specimen
    if specimen.shape == "mesh":
        mesh = specimen_mesh(
            specimen.mesh_path,
            unit=specimen.unit,
            element=specimen.element,
            zones=specimen.refine_zones,
        )
        return MeshSizeEstimate(  # the mesh is already made: its solve is not counted
            tet_count=mesh.tet_count,
            node_count=mesh.node_count,
            element=specimen.element,
            mesh_bytes=0,
            solve_bytes=0,
        )
    half_size_m = specimen.half_size_m
    return estimate_indentation_mesh(
        shape=specimen.shape,
        half_extent_m=half_size_m,
        thickness_m=specimen.thickness_m,
        probe_radius_m=study.mesh_probe_radius_m,
        quarter=specimen.quarter,
        element=specimen.element,
        size_near_m=specimen.size_near_m,
        size_far_m=specimen.size_far_m,
        growth=specimen.growth,
    )


def build_problem(study: Study, mesh: Any) -> Any:
    """Build the indentation problem (mesh, material, punch, boundary conditions).

    Args:
        study: The study.
        mesh: The specimen mesh from :func:`build_mesh`.

    Returns:
        A :class:`warptissue.fem.IndentationProblem`.
    """

    placement = {}
    if study.site_m is not None:
        placement = {"site_m": study.site_m, "direction": study.direction, "edge": study.edge}
    return IndentationProblem(
        mesh,
        study.material,
        study.indenter,
        base=study.boundary.base,
        foundation=study.boundary.foundation,
        symmetry_planes=("symmetry_x", "symmetry_y") if study.specimen.quarter else (),
        formulation=study.solver.formulation,
        penalty_factor=study.solver.penalty_factor,
        contact_integration=study.solver.contact_integration,
        **placement,
    )


def record_problems(study: Study, material: Any = None) -> tuple[list[Any], list[int]]:
    """The indentation problems of a study's ``[[data]]`` records: one per distinct probe
    (indenter, site and direction, :meth:`warptissue.study.Study.probe_of`).

    Args:
        study: A study with records.
        material: The problems' material; None: the study's.

    Returns:
        ``(problems, index)``: the distinct problems, in the order their first record
        comes, and for each record the index of its problem. Problems whose supports hold
        the same nodes share one mesh (and so one assembler).
    """
    material = study.material if material is None else material
    problems: list[Any] = []
    keys: list[tuple] = []
    index: list[int] = []
    for record in study.data:
        key = study.probe_of(record)
        if key not in keys:
            indenter, site_m, direction = key
            placed = replace(
                study, indenter=indenter, site_m=site_m, direction=direction, material=material
            )
            mesh = build_mesh(placed)
            held = mesh.node_sets["bottom"]
            for earlier in problems:  # one organ, one support: the earlier site's mesh
                other = earlier.mesh
                if other.points is mesh.points and np.array_equal(other.node_sets["bottom"], held):
                    mesh = other
                    break
            keys.append(key)
            problems.append(build_problem(placed, mesh))
        index.append(keys.index(key))
    return problems, index


def _organ_mesh(study: Study) -> Any:
    """A mesh specimen's mesh with its support as ``"bottom"`` and the rest of its surface
    as ``"top"`` (:mod:`warptissue.study`'s ``[specimen] mesh``)."""
    specimen = study.specimen
    mesh = specimen_mesh(
        specimen.mesh_path,
        unit=specimen.unit,
        element=specimen.element,
        zones=specimen.refine_zones,
    )
    site, along = probe_placement(
        mesh, study.site_m, study.direction, radius_m=study.indenter.radius_m
    )
    support = support_nodes(mesh, study.boundary.support, site_m=site, direction=along)
    return organ_mesh(mesh, support)


@dataclass(frozen=True)
class StudySetup:
    """A simulation study made ready to solve (:func:`prepare_study`).

    Attributes:
        study: The study.
        out_dir: Its output folder (created, writable).
        device: The Warp device it runs on.
        mesh: The specimen mesh (:func:`build_mesh`).
        mesh_statistics: ``result.json``'s ``mesh``.
        problem: The :class:`warptissue.fem.IndentationProblem` (:func:`build_problem`).
        depths_m: The protocol's depths, (S,), m.
        times_s: The protocol's times, (S,), s; None for a quasi-static one.
        setup_s: Wall time of meshing and setting up, s.
    """

    study: Study
    out_dir: Path
    device: Any
    mesh: Any
    mesh_statistics: dict[str, Any]
    problem: Any
    depths_m: np.ndarray
    times_s: np.ndarray | None
    setup_s: float


def check_linear_solver(study: Study, device: Any) -> None:
    """Refuse, before any work, a linear solver that does not run on the device.

    Args:
        study: The study (its ``solver.linear_solver``).
        device: The Warp device the study runs on.

    Raises:
        InputError: The linear solver is unknown or does not run on ``device``.
    """

    try:
        LinearSolver(method=study.solver.options.linear_solver, device=device)
    except InputError as exc:
        raise InputError(
            f"solver.{exc.column or 'linear_solver'}: {exc.message}",
            path=study.path,
            value=exc.value,
        ) from None
