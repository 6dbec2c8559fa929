"""Reading a study: each table validated into the schema's dataclasses, errors placed at
the file, line and key path (:func:`load_study`, :func:`study_from_dict`)."""

from __future__ import annotations

import dataclasses
import math
import re
import tomllib
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from warptissue.errors import InputError
from warptissue.fem.assembly import FORMULATIONS
from warptissue.fem.contact import DEFAULT_PENALTY_FACTOR
from warptissue.fem.newton import NewtonOptions
from warptissue.fem.probe import probe_frame
from warptissue.fem.support import Foundation
from warptissue.indenter import CONTACT_KINDS, CONTACTS, SIMULATED_KINDS, Indenter
from warptissue.loading import ramp_hold, sine
from warptissue.materials import material_from_dict, prony_term
from warptissue.mesh.generators import MESHERS
from warptissue.mesh.quality import edge_lengths
from warptissue.mesh.size import force_accuracy_depth_warning, size_near_for_force_accuracy
from warptissue.study._organ import (
    MESH_UNITS,
    OPPOSITE,
    extent_along,
    probe_placement,
    specimen_mesh,
    support_nodes,
)
from warptissue.study._records import condition_record, read_data, record_options
from warptissue.study._schema import (
    BASE_KINDS,
    BULK_MODULUS_RULES,
    CONTACT_POINTS,
    DEPTH_OFFSET,
    DEVICE_PATTERN,
    ELEMENT_TYPES,
    FIT_METHODS,
    FIT_OBJECTIVES,
    FIT_STRATEGIES,
    MAX_STEPS,
    PROTOCOL_KINDS,
    SCHEMA_VERSIONS,
    SPECIMEN_SHAPES,
    START_FROM,
    Boundary,
    DataRecord,
    FitSettings,
    Protocol,
    Solver,
    Specimen,
    Study,
)
from warptissue.study._sizing import (
    deepest_depth_m,
    mesh_probe_radius,
    near_size_too_coarse,
    probe_outside_specimen,
    specimen_half_size_m,
)
from warptissue.study._toml import Source, Table, closest, plain


def _read_specimen(table: Table, indenter: Indenter, *, deepest_m: float) -> Specimen:
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


def _read_indenter(table: Table) -> tuple[Indenter, tuple | None, tuple | None, tuple | None]:
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


def _record_probe(table: Table) -> dict[str, Any]:
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


def _read_mesh_specimen(
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
        # "refined": meshed again around the sites (_refined, once the records are read)
        mesher="file" if accuracy is None and size is None else "refined",
        mesh_file=name,
        mesh_path=path,
        unit=unit,
        force_accuracy=accuracy,
    )
    return specimen, mesh, site, along


def _refined(specimen: Specimen, study: Study, source: Source) -> Specimen:
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


PROTOCOL_KEYS: dict[str, tuple[str, ...]] = {
    "quasi_static": ("depths_m", "max_depth_m", "steps"),
    "timed": ("depths_m", "times_s"),
    "ramp_hold": ("max_depth_m", "speed_m_per_s", "hold_s", "ramp_steps", "hold_steps"),
    "sine": (
        "preload_depth_m",
        "amplitude_m",
        "frequency_Hz",
        "cycles",
        "preload_s",
        "preload_steps",
        "steps_per_cycle",
    ),
    "record": (
        "file",
        "time_column",
        "displacement_column",
        "force_column",
        "contact",
        "contact_position_m",
        "offset",
        "keep_depth_m",
        "window_s",
        "steps",
    ),
}
"""The keys of ``[protocol]`` for each kind (besides ``kind``)."""
RECORD_PROTOCOL_STEPS: int = 40
"""Default ``protocol.steps`` of a ``"record"`` protocol."""


def _read_protocol(table: Table, thickness_m: float, *, version: int, base: Path) -> Protocol:
    timed_list = table.has("times_s")
    kind = table.string(
        "kind", default="timed" if timed_list else "quasi_static", choices=PROTOCOL_KINDS
    )
    if version < 2 and (kind != "quasi_static" or timed_list):
        key = "kind" if table.has("kind") else "times_s"
        raise table.error(
            key, "a timed protocol needs schema_version = 2 (this file says 1)", table.data[key]
        )
    for key in table.data:  # a key of another kind (a typo is named by finish())
        owners = [k for k, keys in PROTOCOL_KEYS.items() if key in keys]
        if key != "kind" and owners and key not in PROTOCOL_KEYS[kind]:
            raise table.error(
                key,
                f"is not a key of kind {kind!r} (its keys: {', '.join(PROTOCOL_KEYS[kind])}); "
                f"it belongs to kind {owners[0]!r}",
                None,
            )
    if kind == "quasi_static":
        return _read_quasi_static(table, thickness_m)
    settings: dict[str, Any] = {}
    record = None
    if kind == "timed":
        depths = table.number_list("depths_m")
        times = table.number_list("times_s")
        if len(times) != len(depths):
            raise table.error(
                "times_s",
                f"must hold one time per depth ({len(depths)} depths, {len(times)} times)",
                len(times),
            )
        for previous, time in zip((0.0, *times[:-1]), times, strict=True):
            if time <= previous:
                raise table.error(
                    "times_s", "must be positive and strictly increasing", list(times)
                )
        depth_key = "depths_m"
    elif kind == "ramp_hold":
        settings = {
            "max_depth_m": table.number("max_depth_m"),
            "speed_m_per_s": table.number("speed_m_per_s"),
            "hold_s": table.number("hold_s", positive=False),
            "ramp_steps": table.integer("ramp_steps", default=10),
            "hold_steps": table.integer("hold_steps", default=20),
        }
        times, depths = table.build(lambda values: ramp_hold(**values), settings)
        depth_key = "max_depth_m"
    elif kind == "sine":
        settings = {
            "preload_depth_m": table.number("preload_depth_m"),
            "amplitude_m": table.number("amplitude_m"),
            "frequency_Hz": table.number("frequency_Hz"),
            "cycles": table.integer("cycles"),
            "preload_s": table.number("preload_s"),
            "preload_steps": table.integer("preload_steps", default=5),
            "steps_per_cycle": table.integer("steps_per_cycle", default=16, minimum=4),
        }
        times, depths = table.build(lambda values: sine(**values), settings)
        depth_key = "amplitude_m"
    else:  # record
        options = record_options(table, base)
        steps = table.integer("steps", default=RECORD_PROTOCOL_STEPS, minimum=2)
        if steps > MAX_STEPS:
            raise table.error("steps", f"must be at most {MAX_STEPS}", steps)
        record = condition_record(table, options, force_required=False)
        try:
            times, depths = record.load_history(steps=steps)
        except InputError as exc:
            raise table.error("file", exc.message, options["file"]) from None
        settings = {"steps": steps}
        depth_key = "file"
    times, depths = tuple(map(float, times)), tuple(map(float, depths))
    if len(depths) > MAX_STEPS:
        raise table.error(depth_key, f"gives more than {MAX_STEPS} steps", len(depths))
    if min(depths) < 0.0:
        raise table.error(depth_key, "depths must be >= 0 (into the specimen)", min(depths))
    if max(depths) >= thickness_m:
        raise table.error(
            depth_key,
            f"the deepest depth must be less than the thickness ({thickness_m!r} m)",
            max(depths),
        )
    table.finish(also_known=PROTOCOL_KEYS[kind])
    return Protocol(depths_m=depths, times_s=times, kind=kind, settings=settings, record=record)


def _read_quasi_static(table: Table, thickness_m: float) -> Protocol:
    has_list = table.has("depths_m")
    has_ramp = table.has("max_depth_m") or table.has("steps")
    if has_list == has_ramp:
        raise table.source.error(
            table.prefix,
            "give either depths_m, or max_depth_m and steps (exactly one of the two forms)",
        )
    if has_list:
        depths = table.number_list("depths_m")
        if len(depths) > MAX_STEPS:
            raise table.error("depths_m", f"must hold at most {MAX_STEPS} depths", len(depths))
        for previous, depth in zip((0.0, *depths[:-1]), depths, strict=True):
            if depth <= previous:
                raise table.error(
                    "depths_m", "must be positive and strictly increasing", list(depths)
                )
        last_key = "depths_m"
    else:
        max_depth_m = table.number("max_depth_m")
        steps = table.integer("steps")
        if steps > MAX_STEPS:
            raise table.error("steps", f"must be at most {MAX_STEPS}", steps)
        depths = tuple(max_depth_m * (k + 1) / steps for k in range(steps))
        last_key = "max_depth_m"
    if depths[-1] >= thickness_m:
        raise table.error(
            last_key,
            f"the final depth must be less than the thickness ({thickness_m!r} m)",
            depths[-1],
        )
    table.finish(also_known=("kind", *PROTOCOL_KEYS["quasi_static"]))
    return Protocol(depths_m=depths)


def _read_material(table: Table) -> Any:
    values = table.present(list(table.data))
    return table.build(material_from_dict, values)


def _support(table: Table) -> str | dict[str, Any]:
    """``[boundary] support``: a node set's name, ``"opposite"``, ``{ box = [[xmin, ymin,
    zmin], [xmax, ymax, zmax]] }`` (m, each min below its max) or ``{ half_space = [[x, y, z],
    [nx, ny, nz]] }`` (a point of the plane, m, and the normal pointing into the held side)."""
    support = table.raw("support", default=OPPOSITE)
    if isinstance(support, str):
        return support
    shape = next(iter(support)) if isinstance(support, Mapping) and len(support) == 1 else None
    pair = support.get(shape) if shape in ("box", "half_space") else None
    vectors_ok = (
        isinstance(pair, list)
        and len(pair) == 2
        and all(isinstance(corner, list) and len(corner) == 3 for corner in pair)
        and all(
            isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
            for corner in pair
            for v in corner
        )
    )
    if vectors_ok and shape == "box":
        vectors_ok = all(a < b for a, b in zip(*pair, strict=True))
    if vectors_ok and shape == "half_space":
        vectors_ok = any(v != 0 for v in pair[1])
    if not vectors_ok:
        raise table.error(
            "support",
            'must be a node set\'s name, "opposite", { box = [[xmin, ymin, zmin], '
            "[xmax, ymax, zmax]] } (m, each min below its max) or { half_space = [[x, y, z], "
            "[nx, ny, nz]] } (a point of the plane, m, and a nonzero normal into the held side)",
            support,
        )
    return {shape: [[float(v) for v in corner] for corner in pair]}


def _read_boundary(table: Table, organ: tuple | None = None) -> Boundary:
    """The ``[boundary]`` table; ``organ``: a mesh specimen's (mesh, site, direction), whose
    ``support`` is checked against it."""
    base = table.string("base", default="fixed", choices=BASE_KINDS)
    foundation = None
    if base == "foundation":
        if not table.has("foundation_Pa_per_m"):
            raise table.error(
                "foundation_Pa_per_m",
                'is needed with base = "foundation": the bed\'s stiffness per unit area, Pa/m',
            )
        normal = table.number("foundation_Pa_per_m")
        tangential = table.number("foundation_tangential_Pa_per_m", default=normal)
        foundation = Foundation(normal, tangential)
    else:
        for key in ("foundation_Pa_per_m", "foundation_tangential_Pa_per_m"):
            if table.has(key):
                raise table.error(
                    key, f'needs base = "foundation" (base is {base!r})', table.raw(key)
                )
    support = None
    if organ is not None:
        support = _support(table)
        mesh, site, along = organ
        try:
            support_nodes(mesh, support, site_m=site, direction=along)
        except InputError as exc:
            raise table.error("support", exc.message, exc.value) from exc
    table.finish()
    return Boundary(base=base, support=support, foundation=foundation)


LOCKING_BULK_TO_SHEAR = 10.0
"""K / mu (Poisson's ratio about 0.45) from which a TET4 study without a formulation is told
that the displacement formulation it gets locks."""


def _read_solver(table: Table, element: str, material: Any) -> Solver:
    # The solver's own modules: importing them does not start Warp (test_study checks).

    device = table.string("device", default="auto")
    if not DEVICE_PATTERN.match(device):
        raise table.error("device", "must be 'auto', 'cpu', 'cuda' or 'cuda:N'", device)
    if table.has("formulation") or element == "TET10":
        formulation = table.string("formulation", default="mixed", choices=FORMULATIONS)
    else:
        # A TET4 study that names no formulation (version-1 files ran so): the one TET4
        # takes, said out loud where it locks.
        formulation = "displacement"
        ratio = material.bulk_modulus / material.initial_shear_modulus_Pa
        if ratio >= LOCKING_BULK_TO_SHEAR:
            where = table.source.path if table.source.path is not None else "the study"
            warnings.warn(
                f"{where}: specimen.element = 'TET4' and no solver.formulation: the "
                f"'displacement' formulation is used, which locks at K/mu = {ratio:.4g} "
                "(forces too high); element = \"TET10\" takes the locking-free 'mixed' one",
                UserWarning,
                stacklevel=2,
            )
    penalty_factor = table.number("penalty_factor", default=DEFAULT_PENALTY_FACTOR)
    options = table.build(
        lambda values: NewtonOptions(**values), table.present(NewtonOptions.keys())
    )
    table.finish()
    return Solver(
        device=device, formulation=formulation, options=options, penalty_factor=penalty_factor
    )


def _free_name_problem(name: str, material: Any) -> str:
    """Why ``name`` is not a free parameter of ``material``."""
    names = material.parameter_names
    if name in material.to_dict():
        return (
            f"is held fixed: the volumetric term is not a fit parameter of model "
            f"{material.model_name!r} (its fit parameters: {', '.join(names)})"
        )
    close = closest(name, names)
    hint = f"did you mean {close!r}? " if close else ""
    return f"is not a parameter of model {material.model_name!r} ({hint}its fit parameters: " + (
        f"{', '.join(names)})"
    )


def _parameter_table(
    table: Table, free: Sequence[str], material: Any, *, contact_point: str = "given"
) -> dict[str, Any]:
    """The keys of ``[fit.start]`` or ``[fit.bounds]``: each must be a free parameter (or
    the depth offset, with ``contact_point = "fit"``)."""
    for key in table.data:
        if key in free:
            continue
        if key == DEPTH_OFFSET:
            if contact_point == "fit":
                continue
            raise table.error(
                key,
                "applies only with fit.contact_point = 'fit' (the depth offset fitted with "
                "the material)",
                table.data[key],
            )
        if key in material.parameter_names:
            raise table.error(
                key,
                "is not free: list it in fit.free, or set its value in [material]",
                table.data[key],
            )
        raise table.error(key, _free_name_problem(key, material), None)
    return dict(table.data)


def _read_fit(table: Table, material: Any) -> FitSettings:
    free_raw = table.raw("free")
    if (
        not isinstance(free_raw, list)
        or not free_raw
        or not all(isinstance(name, str) for name in free_raw)
    ):
        raise table.error("free", "must be a non-empty list of parameter names", free_raw)
    for name in free_raw:
        if name not in material.parameter_names:
            raise table.error("free", f"{name!r} {_free_name_problem(name, material)}", name)
        if free_raw.count(name) > 1:
            raise table.error("free", f"names {name!r} twice", free_raw)
    free = tuple(free_raw)
    contact_point = table.string("contact_point", default="given", choices=CONTACT_POINTS)
    bounds_table = _optional_table(table, "bounds")
    bounds: dict[str, tuple[float, float]] = {}
    for key in _parameter_table(bounds_table, free, material, contact_point=contact_point):
        pair = bounds_table.raw(key)
        if not isinstance(pair, list) or len(pair) != 2:
            raise bounds_table.error(key, "must be [lower, upper]", pair)
        low, high = (plain(v) for v in pair)
        if any(isinstance(v, bool) or not isinstance(v, int | float) for v in (low, high)):
            raise bounds_table.error(key, "must be [lower, upper], two numbers", pair)
        if math.isnan(low) or math.isnan(high) or not low < high:
            raise bounds_table.error(key, "the lower bound must be below the upper", pair)
        bounds[key] = (float(low), float(high))
    start_table = _optional_table(table, "start")
    start = {
        key: start_table.number(key, positive=False)
        for key in _parameter_table(start_table, free, material, contact_point=contact_point)
    }
    if DEPTH_OFFSET in start and DEPTH_OFFSET in bounds:
        low, high = bounds[DEPTH_OFFSET]
        if not low <= start[DEPTH_OFFSET] <= high:
            raise start_table.error(
                DEPTH_OFFSET, f"lies outside fit.bounds [{low:g}, {high:g}]", start[DEPTH_OFFSET]
            )
    start_from = table.string("start_from", default="record", choices=START_FROM)
    method = table.string("method", default="lm", choices=FIT_METHODS)
    objective = table.string("objective", default="absolute", choices=FIT_OBJECTIVES)
    relative_floor_N = table.number("relative_floor_N", default=None)
    if relative_floor_N is not None and objective != "relative":
        raise table.error(
            "relative_floor_N", "applies only with objective = 'relative'", relative_floor_N
        )
    max_iterations = table.integer("max_iterations", default=50)
    tolerances = {key: table.number(key, default=1e-8) for key in ("ftol", "xtol", "gtol")}
    stop_r_squared = table.number("stop_r_squared", default=None)
    if stop_r_squared is not None and not stop_r_squared < 1.0:
        raise table.error("stop_r_squared", "must lie between 0 and 1", stop_r_squared)
    strategy = table.string("strategy", default="joint", choices=FIT_STRATEGIES)
    if strategy == "two_stage":
        prony = [name for name in material.parameter_names if prony_term(name) is not None]
        if not prony:
            raise table.error(
                "strategy",
                "'two_stage' (Ahn & Kim) fits Prony terms first, and [material] has none "
                f"(model {material.model_name!r}): add g1, tau1_s, ... to [material], or use "
                "'joint'",
                strategy,
            )
        if all(prony_term(name) is not None for name in free):
            raise table.error(
                "strategy",
                "'two_stage' fits the Prony terms in stage (i) and the other free parameters "
                "by inverse FE in stage (ii), and fit.free names no other: free an elastic "
                "parameter too (C10_Pa, ...), or use 'joint'",
                strategy,
            )
    bulk_modulus = table.string("bulk_modulus", default="fixed", choices=BULK_MODULUS_RULES)
    if bulk_modulus == "follows_shear" and not hasattr(material, "with_bulk_modulus"):
        raise table.error(
            "bulk_modulus",
            "'follows_shear' holds K/mu0 of a hyperelastic model's bulk modulus (not a fit "
            f"parameter); model {material.model_name!r} has its own compressibility "
            "parameters: leave them out of fit.free to hold them",
            bulk_modulus,
        )
    time_steps = table.integer("time_steps", default=24, minimum=2)
    if time_steps > MAX_STEPS:
        raise table.error("time_steps", f"must be at most {MAX_STEPS}", time_steps)
    table.finish()
    settings = FitSettings(
        free=free,
        start=start,
        bounds=bounds,
        start_from=start_from,
        method=method,
        objective=objective,
        relative_floor_N=relative_floor_N,
        max_iterations=max_iterations,
        stop_r_squared=stop_r_squared,
        strategy=strategy,
        time_steps=time_steps,
        contact_point=contact_point,
        bulk_modulus=bulk_modulus,
        **tolerances,
    )
    lower, upper = settings.parameter_bounds(material)
    current = dict(zip(material.parameter_names, material.parameter_vector.tolist(), strict=True))
    for j, name in enumerate(free):
        if name in start:
            where, value = start_table, start[name]
        elif start_from == "material":
            where, value = table, current[name]
        else:
            continue
        if not lower[j] <= value <= upper[j]:
            key, problem = (
                (name, "lies outside fit.bounds")
                if where is start_table
                else ("start_from", f"the [material] value of {name} lies outside its bounds")
            )
            raise where.error(key, f"{problem} [{lower[j]:g}, {upper[j]:g}]", value)
    given = {name: value for name, value in start.items() if name != DEPTH_OFFSET}
    if given:
        vector = np.array([given.get(name, current[name]) for name in material.parameter_names])
        try:
            material.with_parameters(vector)
        except InputError as exc:
            key = exc.column if exc.column in given else next(iter(given))
            raise start_table.error(key, exc.message, given[key]) from None
    return settings


def _build(data: Mapping[str, Any], source: Source, default_name: str) -> Study:
    root = Table(data, "", source)
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
    description = root.string("description", default="")
    indenter, site_m, direction, edge = _read_indenter(root.table("indenter"))
    # The depths come before the rest of the specimen: they size a sphere's refined zone.
    specimen_table = root.table("specimen")
    base = source.path.parent if source.path is not None else Path.cwd()
    organ = None
    if specimen_table.has("mesh"):
        specimen, *organ = _read_mesh_specimen(
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
    protocol = _read_protocol(root.table("protocol"), thickness_m, version=version, base=base)
    records: tuple[DataRecord, ...] = ()
    if version >= 2 and root.has("data"):
        records = read_data(root, base, thickness_m, probe_reader=_record_probe)
    deepest_m = deepest_depth_m(protocol, records)
    if organ is None:
        specimen = _read_specimen(specimen_table, indenter, deepest_m=deepest_m)
    material = _read_material(root.table("material"))
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
    boundary = _read_boundary(_optional_table(root, "boundary"), organ)
    _check_placed_records(records, root.source, organ, boundary, indenter)
    solver = _read_solver(_optional_table(root, "solver"), specimen.element, material)
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
    fit = None
    if version >= 2:
        if root.has("fit"):
            if not records:
                raise root.error("fit", "a fit needs measured records: add [[data]] tables")
            fit = _read_fit(root.table("fit"), material)
    else:
        for key in ("data", "fit"):
            if root.has(key):
                raise root.error(key, "needs schema_version = 2 (this file says 1)", None)
    root.finish()
    if specimen.force_accuracy is not None:
        message = force_accuracy_depth_warning(
            specimen.force_accuracy,
            depth_m=deepest_m,
            probe_radius_m=mesh_probe_radius(indenter, specimen.half_size_m, depth_m=deepest_m),
        )
        if message is not None:
            where = source.path if source.path is not None else "the study"
            warnings.warn(f"{where}: {message}", UserWarning, stacklevel=2)
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
        study = dataclasses.replace(study, specimen=_refined(specimen, study, source))
    return study


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


def _optional_table(root: Table, key: str) -> Table:
    """A table whose keys all have defaults, so that the table itself may be left out."""
    return Table(root.raw(key, {}), root.key_path(key), root.source)


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
