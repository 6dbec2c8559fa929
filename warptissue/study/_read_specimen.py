"""Reading a study's ``[specimen]`` (shape, or a mesh file and its refined zones) and
``[indenter]`` tables, and a record's own probe."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np

from warptissue.errors import InputError
from warptissue.indenter import CONTACT_KINDS, CONTACTS, SIMULATED_KINDS, Indenter
from warptissue.mesh.generators import MESHERS
from warptissue.mesh.quality import edge_lengths
from warptissue.mesh.size import size_near_for_force_accuracy
from warptissue.study._organ import (
    MESH_UNITS,
    extent_along,
    probe_placement,
    specimen_mesh,
)
from warptissue.study._schema import (
    ELEMENT_TYPES,
    SPECIMEN_SHAPES,
    Specimen,
    Study,
)
from warptissue.study._sizing import (
    mesh_probe_radius,
    near_size_too_coarse,
    probe_outside_specimen,
    specimen_half_size_m,
)
from warptissue.study._toml import Source, Table


def read_specimen(table: Table, indenter: Indenter, *, deepest_m: float) -> Specimen:
    """The ``[specimen]`` table; ``deepest_m``: the study's deepest depth (m), which sizes a
    sphere's refined zone (:func:`warptissue.study.mesh_probe_radius`)."""
    shape = table.string("shape", choices=SPECIMEN_SHAPES)
    thickness_m = table.number("thickness_m")
    other_size_key = "radius_m" if shape == "block" else "width_m"
    if table.has(other_size_key):
        raise table.error(
            other_size_key,
            f"is not used by shape {shape!r} (a block has width_m, a disc radius_m)",
            table.data[other_size_key],
        )
    width_m = table.number("width_m") if shape == "block" else None
    radius_m = table.number("radius_m") if shape == "disc" else None
    half_size_m = specimen_half_size_m(shape, width_m, radius_m)
    probe_radius_m = mesh_probe_radius(indenter, half_size_m, depth_m=deepest_m)
    too_small = probe_outside_specimen(indenter, shape, half_size_m, probe_radius_m)
    if too_small:
        size_key = "width_m" if shape == "block" else "radius_m"
        raise table.error(size_key, too_small, width_m if shape == "block" else radius_m)
    quarter = table.boolean("quarter", default=True)
    element = table.string("element", default="TET10", choices=ELEMENT_TYPES)
    force_accuracy = table.number("force_accuracy", default=None)
    if force_accuracy is not None and table.has("size_near_m"):
        raise table.error(
            "force_accuracy",
            f"give either force_accuracy or size_near_m, not both (size_near_m = "
            f"{table.raw('size_near_m')!r})",
            force_accuracy,
        )
    if force_accuracy is None:
        size_near_m = table.number("size_near_m", default=probe_radius_m / 4.0)
    else:
        size_near_m = _size_near_for_accuracy(
            table, force_accuracy, indenter=indenter, probe_radius_m=probe_radius_m
        )
    size_far_m = table.number("size_far_m", default=min(thickness_m, half_size_m) / 4.0)
    if size_near_m > size_far_m and force_accuracy is not None:
        raise table.error(
            "force_accuracy",
            f"chooses size_near_m = {size_near_m!r} m, coarser than size_far_m "
            f"({size_far_m!r} m): give a size_far_m of at least that, or size_near_m",
            force_accuracy,
        )
    if size_near_m > size_far_m:
        raise table.error(
            "size_near_m", f"must not exceed size_far_m ({size_far_m!r} m)", size_near_m
        )
    if size_near_m > probe_radius_m:
        message = near_size_too_coarse(indenter, probe_radius_m, depth_m=deepest_m)
        raise table.error("size_near_m", message, size_near_m)
    growth = table.number("growth", default=1.2)
    if growth < 1.0:
        raise table.error("growth", "must be at least 1", growth)
    mesher = table.string("mesher", default="extruded", choices=MESHERS)
    table.finish()
    return Specimen(
        shape=shape,
        thickness_m=thickness_m,
        width_m=width_m,
        radius_m=radius_m,
        quarter=quarter,
        element=element,
        size_near_m=size_near_m,
        size_far_m=size_far_m,
        growth=growth,
        mesher=mesher,
        force_accuracy=force_accuracy,
    )


def _size_near_for_accuracy(
    table: Table, accuracy: float, *, indenter: Indenter, probe_radius_m: float
) -> float:
    """``specimen.force_accuracy``'s near size (:func:`warptissue.mesh.size_near_for_force_
    accuracy`), its errors placed at the key that is out of what was measured."""

    sharp = indenter.kind == "flat_punch" and indenter.edge_radius_m == 0.0
    if not (sharp and indenter.contact == "bonded"):
        raise table.error(
            "force_accuracy",
            "was measured for the sharp bonded flat punch only (indenter.kind = "
            f"{indenter.kind!r}, edge_radius_m = {indenter.edge_radius_m!r}, contact = "
            f"{indenter.contact!r}): give size_near_m",
            accuracy,
        )
    # The element and mesher keys come after this one in the table; read them here.
    element = table.string("element", default="TET10", choices=ELEMENT_TYPES)
    mesher = table.string("mesher", default="extruded", choices=MESHERS)
    try:
        return size_near_for_force_accuracy(
            accuracy, probe_radius_m=probe_radius_m, mesher=mesher, element=element
        )
    except InputError as exc:
        key = exc.column if exc.column in ("element", "mesher") else "force_accuracy"
        raise table.error(key, exc.message, table.raw(key, None)) from exc


def read_indenter(table: Table) -> tuple[Indenter, tuple | None, tuple | None, tuple | None]:
    """The ``[indenter]`` table: the probe, and ``site_m``, ``direction`` and a wedge's
    ``edge`` (None where not given)."""
    placement = _placement(table)
    edge = None
    if table.has("edge"):
        edge = table.number_list("edge")
        if len(edge) != 3 or not np.any(edge):
            raise table.error("edge", "must be three numbers (x, y, z), not all zero", list(edge))
        if table.raw("kind", None) != "wedge":
            raise table.error("edge", 'is the edge of a wedge (kind = "wedge")', list(edge))
    return _read_probe(table), *placement, edge


def _placement(table: Table) -> tuple[tuple | None, tuple | None]:
    """A table's ``site_m`` and ``direction`` (None where not given)."""
    placement = []
    for key in ("site_m", "direction"):
        vector = table.number_list(key) if table.has(key) else None
        if vector is not None and len(vector) != 3:
            raise table.error(key, "must be three numbers (x, y, z)", list(vector))
        if key == "direction" and vector is not None and not np.any(vector):
            raise table.error(key, "must not be the zero vector", list(vector))
        placement.append(vector)
    return placement[0], placement[1]


def record_probe(table: Table) -> dict[str, Any]:
    """A ``[[data]]`` record's own probe: ``site_m``, ``direction`` and an ``indenter``
    table (the keys of ``[indenter]`` but the placement)."""
    site_m, direction = _placement(table)
    indenter = _read_probe(table.table("indenter")) if table.has("indenter") else None
    return {"site_m": site_m, "direction": direction, "indenter": indenter}


def _read_probe(table: Table) -> Indenter:
    """The probe of an ``[indenter]`` table (its placement read apart)."""
    kind = table.string("kind", choices=SIMULATED_KINDS)
    # A plate needs no radius; given, it is the radius of the mesh's refined zone.
    radius_m = (
        table.number("radius_m", default=0.0) if kind == "plate" else table.number("radius_m")
    )
    values: dict[str, Any] = {"kind": kind, "radius_m": radius_m}
    if kind == "flat_punch":
        values["edge_radius_m"] = table.number("edge_radius_m", default=0.0, positive=False)
    if kind == "wedge":
        values["angle_deg"] = table.number("angle_deg", positive=False)
        values["length_m"] = table.number("length_m", default=0.0)
    rigid = kind in CONTACT_KINDS or values.get("edge_radius_m", 0.0) > 0
    values["contact"] = table.string(
        "contact", default="frictionless" if rigid else "bonded", choices=CONTACTS
    )
    table.finish()
    return table.build(lambda values: Indenter(**values), values)


def read_mesh_specimen(
    table: Table, *, base: Path, site_m: tuple | None, direction: tuple | None, probe: Indenter
) -> tuple[Specimen, Any, np.ndarray, np.ndarray]:
    """A ``[specimen]`` table with ``mesh``: the specimen, its mesh, and the snapped site
    and the direction (:mod:`warptissue.study._organ`)."""
    name = table.string("mesh")
    unit = table.string("unit", default="m", choices=tuple(MESH_UNITS))
    element = table.string("element", default="TET10", choices=ELEMENT_TYPES)
    if table.has("force_accuracy") and table.has("size_near_m"):
        raise table.error(
            "size_near_m",
            "give force_accuracy (the size follows from it) or size_near_m, not both",
            table.raw("size_near_m"),
        )
    accuracy = size = None
    if table.has("force_accuracy"):
        accuracy = table.number("force_accuracy")
        try:
            size_near_for_force_accuracy(accuracy, probe_radius_m=1.0, mesher="delaunay")
        except InputError as exc:
            raise table.error("force_accuracy", exc.message, accuracy) from exc
    elif table.has("size_near_m"):
        size = table.number("size_near_m")
    table.finish()
    path = (base / name) if not Path(name).is_absolute() else Path(name)
    if site_m is None:
        raise table.error(
            "mesh", "a mesh specimen needs [indenter] site_m, the point the probe indents", name
        )
    try:
        mesh = specimen_mesh(path, unit=unit, element=element)
        site, along = probe_placement(mesh, site_m, direction, radius_m=probe.radius_m)
    except InputError as exc:
        where = f"{exc.path}: " if exc.path is not None else ""
        raise table.source.error(
            exc.column or "specimen.mesh", where + exc.message, exc.value
        ) from exc
    depth = extent_along(mesh, site, along)
    if not depth > 0.0:
        raise table.source.error(
            "indenter.direction", "points out of the body at the site", list(direction or ())
        )
    lengths = edge_lengths(mesh.points, mesh.tets[:, :4])
    specimen = Specimen(
        shape="mesh",
        thickness_m=depth,
        width_m=None,
        radius_m=None,
        quarter=False,
        element=element,
        size_near_m=float(lengths.min()) if size is None else size,
        size_far_m=float(lengths.max()),
        growth=1.0,
        # "refined": meshed again around the sites (refined_specimen, once the records are read)
        mesher="file" if accuracy is None and size is None else "refined",
        mesh_file=name,
        mesh_path=path,
        unit=unit,
        force_accuracy=accuracy,
    )
    return specimen, mesh, site, along


def refined_specimen(specimen: Specimen, study: Study, source: Source) -> Specimen:
    """A mesh specimen with ``force_accuracy`` or ``size_near_m``: the zone around every
    probe's site (the study's and its records') refined to the size rule of the block's
    (:func:`warptissue.study.mesh_probe_radius`, and
    :func:`warptissue.mesh.size_near_for_force_accuracy` for TetGen's tets at that radius)."""
    if specimen.mesher != "refined":
        return specimen
    mesh = specimen_mesh(specimen.mesh_path, unit=specimen.unit, element=specimen.element)
    probes = [(study.indenter, study.site_m, study.direction)]
    probes += [study.probe_of(record) for record in study.data if record.placed]
    zones = []
    for probe in dict.fromkeys(probes):
        indenter, site_m, direction = probe
        site, along = probe_placement(mesh, site_m, direction, radius_m=indenter.radius_m)
        records = [r for r in study.data if study.probe_of(r) == probe]
        depths = [float(np.max(record.displacement_m)) for record in records]
        if probe == probes[0]:
            depths.append(max(study.protocol.depths_m, default=0.0))
        deepest = max(depths, default=0.0)
        zone = mesh_probe_radius(indenter, extent_along(mesh, site, along), depth_m=deepest)
        if specimen.force_accuracy is None:
            size = specimen.size_near_m
        else:
            size = size_near_for_force_accuracy(
                specimen.force_accuracy,
                probe_radius_m=zone,
                mesher="delaunay",
                element=specimen.element,
            )
        zones.append((*map(float, site), float(zone), float(size)))
    try:
        specimen_mesh(
            specimen.mesh_path, unit=specimen.unit, element=specimen.element, zones=tuple(zones)
        )
    except InputError as exc:
        key = "specimen.force_accuracy" if specimen.force_accuracy else "specimen.size_near_m"
        raise source.error(key, exc.message, exc.value) from exc
    return dataclasses.replace(
        specimen, refine_zones=tuple(zones), size_near_m=min(zone[4] for zone in zones)
    )
