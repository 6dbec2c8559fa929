"""Reading a study: each table validated into the schema's dataclasses, errors placed at
the file, line and key path (:func:`load_study`, :func:`study_from_dict`).

This module reads the file and puts the study together; one reader per table lives in its own
module: ``_read_specimen`` (``[specimen]``, ``[indenter]``, a record's probe),
``_read_protocol`` (``[protocol]``), ``_read_solver`` (``[material]``, ``[boundary]``,
``[solver]``) and ``_read_fit`` (``[fit]``)."""

from __future__ import annotations

import dataclasses
import re
import tomllib
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from warptissue.errors import InputError
from warptissue.fem.probe import probe_frame
from warptissue.indenter import Indenter
from warptissue.mesh.size import force_accuracy_depth_warning
from warptissue.study._organ import (
    extent_along,
    probe_placement,
    support_nodes,
)
from warptissue.study._read_fit import optional_table, read_fit
from warptissue.study._read_protocol import (  # noqa: F401 (tests read PROTOCOL_KEYS here)
    PROTOCOL_KEYS,
    read_protocol,
)
from warptissue.study._read_solver import (
    read_boundary,
    read_material,
    read_solver,
)
from warptissue.study._read_specimen import (
    read_indenter,
    read_mesh_specimen,
    read_specimen,
    record_probe,
    refined_specimen,
)
from warptissue.study._records import read_data
from warptissue.study._schema import (
    SCHEMA_VERSIONS,
    Boundary,
    DataRecord,
    Study,
)
from warptissue.study._sizing import deepest_depth_m, mesh_probe_radius
from warptissue.study._toml import Source, Table


def _build(data: Mapping[str, Any], source: Source, default_name: str) -> Study:
    root = Table(data, "", source)
    version, name = _version_and_name(root, default_name)
    description = root.string("description", default="")
    indenter, site_m, direction, edge = read_indenter(root.table("indenter"))
    # The depths come before the rest of the specimen: they size a sphere's refined zone.
    specimen_table = root.table("specimen")
    base = source.path.parent if source.path is not None else Path.cwd()
    organ = None
    if specimen_table.has("mesh"):
        specimen, *organ = read_mesh_specimen(
            specimen_table, base=base, site_m=site_m, direction=direction, probe=indenter
        )
        thickness_m = specimen.thickness_m
    else:
        for key, value in (("site_m", site_m), ("direction", direction), ("edge", edge)):
            if value is not None:
                raise source.error(
                    f"indenter.{key}",
                    "needs [specimen] mesh (a block or a disc is indented at its top centre)",
                    list(value),
                )
        thickness_m = specimen_table.number("thickness_m")
    protocol = read_protocol(root.table("protocol"), thickness_m, version=version, base=base)
    records: tuple[DataRecord, ...] = ()
    if version >= 2 and root.has("data"):
        records = read_data(root, base, thickness_m, probe_reader=record_probe)
    deepest_m = deepest_depth_m(protocol, records)
    if organ is None:
        specimen = read_specimen(specimen_table, indenter, deepest_m=deepest_m)
    material = read_material(root.table("material"))
    _check_regions(material, organ, source)
    boundary = read_boundary(optional_table(root, "boundary"), organ)
    _check_placed_records(records, root.source, organ, boundary, indenter)
    solver = read_solver(optional_table(root, "solver"), specimen.element, material)
    _check_formulation(specimen, solver, source)
    fit = _fit_table(root, version, records, material)
    root.finish()
    _warn_force_accuracy(specimen, indenter, deepest_m, source)
    study = Study(
        name=name,
        description=description,
        specimen=specimen,
        indenter=indenter,
        protocol=protocol,
        material=material,
        boundary=boundary,
        solver=solver,
        path=source.path,
        schema_version=version,
        data=records,
        fit=fit,
        site_m=site_m,
        direction=direction,
        edge=edge,
    )
    if organ is not None and edge is not None:
        _, site, along = organ
        try:
            probe_frame(origin_m=site, direction=along, edge=edge)
        except InputError as exc:
            raise source.error("indenter.edge", exc.message, list(edge)) from None
    if organ is not None:
        study = dataclasses.replace(study, specimen=refined_specimen(specimen, study, source))
    return study


def _version_and_name(root: Table, default_name: str) -> tuple[int, str]:
    """The study's ``schema_version`` (one this reader knows) and its ``name`` (a plain
    name: it names the default output folder)."""
    version = root.raw("schema_version")
    if isinstance(version, bool) or not isinstance(version, int):
        raise root.error("schema_version", "must be an integer", version)
    if version not in SCHEMA_VERSIONS:
        raise root.error(
            "schema_version",
            f"unsupported schema version; this reader knows {', '.join(map(str, SCHEMA_VERSIONS))}",
            version,
        )
    name = root.string("name", default=default_name)
    if not name.strip() or name in (".", "..") or any(c in name for c in "/\\\0"):
        raise root.error(
            "name", "must be a plain name (it names the default output folder runs/<name>)", name
        )
    return version, name


def _check_regions(material: Any, organ: Sequence[Any] | None, source: Source) -> None:
    """Refuse material regions without a mesh file, or naming a tet region it lacks."""
    if len(material.parts) > 1:
        if organ is None:
            raise source.error(
                "material.regions",
                "material regions are the tet regions of a mesh file: give [specimen] mesh (a "
                "generated block or disc is one material)",
            )
        present = np.unique(organ[0].tet_regions)
        for region, ids in material.tet_regions.items():
            missing = sorted(set(ids) - set(present.tolist()))
            if missing:
                raise source.error(
                    f"material.regions.{region}.tet_regions",
                    f"tet region {missing[0]} is not in the mesh (its tet regions: "
                    f"{present.tolist()[:20]})",
                    list(ids),
                )


def _check_formulation(specimen: Any, solver: Any, source: Source) -> None:
    """Refuse a formulation the specimen's element cannot take, and a force accuracy (of
    the mixed formulation) with another formulation."""
    if solver.formulation == "mixed" and specimen.element != "TET10":
        key = "solver.formulation" if source.line("solver.formulation") else "specimen.element"
        raise source.error(
            key,
            f"formulation 'mixed' needs element 'TET10' (specimen.element is "
            f"{specimen.element!r}); TET4 takes formulation 'displacement', which locks when "
            "nearly incompressible",
        )
    if specimen.force_accuracy is not None and solver.formulation != "mixed":
        raise source.error(
            "solver.formulation",
            "specimen.force_accuracy was measured with the 'mixed' formulation only: give "
            "specimen.size_near_m",
            solver.formulation,
        )


def _fit_table(root: Table, version: int, records: Sequence[DataRecord], material: Any) -> Any:
    """The ``[fit]`` table read (None without one); refused without records, and ``[fit]``
    or ``[[data]]`` in a version-1 file."""
    fit = None
    if version >= 2:
        if root.has("fit"):
            if not records:
                raise root.error("fit", "a fit needs measured records: add [[data]] tables")
            fit = read_fit(root.table("fit"), material)
    else:
        for key in ("data", "fit"):
            if root.has(key):
                raise root.error(key, "needs schema_version = 2 (this file says 1)", None)
    return fit


def _warn_force_accuracy(
    specimen: Any, indenter: Indenter, deepest_m: float, source: Source
) -> None:
    """Warn where the depth lies outside the force accuracy's measured range."""
    if specimen.force_accuracy is not None:
        message = force_accuracy_depth_warning(
            specimen.force_accuracy,
            depth_m=deepest_m,
            probe_radius_m=mesh_probe_radius(indenter, specimen.half_size_m, depth_m=deepest_m),
        )
        if message is not None:
            where = source.path if source.path is not None else "the study"
            warnings.warn(f"{where}: {message}", UserWarning, stacklevel=3)


def _check_placed_records(
    records: Sequence[DataRecord],
    source: Source,
    organ: Sequence[Any] | None,
    boundary: Boundary,
    indenter: Indenter,
) -> None:
    """Refuse, before any FE run, a ``[[data]]`` record's own probe that the specimen
    cannot take: one on a block or a disc, a site off the mesh's surface, a direction out
    of the body, a support that holds nothing seen from the site, a record deeper than the
    body below its site."""
    for k, record in enumerate(records):
        if not record.placed:
            continue
        given = next(
            key for key in ("site_m", "direction", "indenter") if getattr(record, key) is not None
        )
        if organ is None:
            raise source.error(
                f"data[{k}].{given}",
                "a record's own probe needs [specimen] mesh (a block or a disc is indented "
                "at its top centre by the [indenter])",
                None if given == "indenter" else list(getattr(record, given)),
            )
        mesh, study_site, study_along = organ
        site_m = record.site_m if record.site_m is not None else tuple(study_site)
        direction = record.direction
        if direction is None and record.site_m is None:
            direction = tuple(study_along)
        probe = record.indenter if record.indenter is not None else indenter
        try:
            site, along = probe_placement(mesh, site_m, direction, radius_m=probe.radius_m)
        except InputError as exc:
            raise source.error(f"data[{k}].site_m", exc.message, exc.value) from None
        depth = extent_along(mesh, site, along)
        if not depth > 0.0:
            raise source.error(
                f"data[{k}].direction", "points out of the body at the site", list(direction)
            )
        try:
            support_nodes(mesh, boundary.support, site_m=site, direction=along)
        except InputError as exc:
            raise source.error(
                "boundary.support", f"seen from data[{k}]'s site: {exc.message}", exc.value
            ) from None
        deepest = float(np.max(record.displacement_m))
        if deepest >= depth:
            raise source.error(
                f"data[{k}].file",
                f"{record.path}: the record goes {deepest:.6g} m deep and the body is "
                f"{depth:.6g} m deep below its site: check the displacement's unit",
                deepest,
            )


def study_from_dict(data: Mapping[str, Any], *, path: str | Path | None = None) -> Study:
    """Validate a study given as a mapping (for example built by a script).

    Args:
        data: The study, shaped like the TOML file.
        path: The file it came from, used in error messages only.

    Returns:
        The validated study.

    Raises:
        InputError: A key is unknown or missing, or a value has the wrong type or range.
    """
    source = Source(None if path is None else Path(path), None)
    return _build(data, source, default_name="study" if path is None else Path(path).stem)


def load_study(path: str | Path) -> Study:
    """Load and validate a study TOML file.

    Args:
        path: The study file.

    Returns:
        The validated study, with defaults filled in and ``path`` set.

    Raises:
        InputError: The file is missing or not valid TOML (with the line), or a key is
            unknown or missing, or a value has the wrong type or range (naming the file, the
            line, the key path and the value).
    """
    study_path = Path(path)
    if study_path.is_dir():
        raise InputError("this is a folder, not a study file", path=study_path)
    if not study_path.is_file():
        raise InputError("study file not found", path=study_path)
    try:
        text = study_path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        line = study_path.read_bytes()[: exc.start].count(b"\n") + 1
        raise InputError("not a text (UTF-8) TOML file", path=study_path, line=line) from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        line = getattr(exc, "lineno", None)
        if line is None:
            match = re.search(r"at line (\d+)", str(exc))
            line = int(match.group(1)) if match else None
        raise InputError(f"not valid TOML: {exc}", path=study_path, line=line) from exc
    return _build(data, Source(study_path, text), default_name=study_path.stem)
