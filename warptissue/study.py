"""Study files: the TOML record of one indentation simulation.

A study names the specimen and its mesh, the indenter, the loading protocol, the material,
the boundary conditions and the solver settings. It is the reproducible record of a run and
the unit of batch work: ``warptissue simulate STUDY.toml`` runs one, and the result JSON
echoes it back with every default filled in.

The schema is versioned (``schema_version = 1``). Every key carries its unit in its name
(``thickness_m``, ``C10_Pa``). Loading validates the whole file: an unknown key, a missing
key, a value of the wrong type or out of range raises :class:`~warptissue.errors.InputError`
naming the file, the line, the key path (for example ``material.C10_Pa``) and the value.
Later schema additions (measured data, fit settings) come as new tables; a version-1 reader
rejects tables it does not know, so that a typo never passes silently.

Example:
    >>> from warptissue.study import load_study
    >>> study = load_study("scenes/liver_slab_flat_punch.toml")  # doctest: +SKIP
    >>> study.protocol.depths_m[-1]  # doctest: +SKIP
    0.0005
"""

from __future__ import annotations

import math
import re
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from warptissue.errors import InputError
from warptissue.mesh.generators import MESHERS

__all__ = [
    "SCHEMA_VERSION",
    "Boundary",
    "Indenter",
    "Protocol",
    "Solver",
    "Specimen",
    "Study",
    "load_study",
    "study_from_dict",
]

SCHEMA_VERSION: int = 1
"""The study schema version this module reads and writes."""

SPECIMEN_SHAPES: tuple[str, ...] = ("block", "disc")
ELEMENT_TYPES: tuple[str, ...] = ("TET10", "TET4")
INDENTER_KINDS: tuple[str, ...] = ("flat_punch",)
CONTACT_KINDS: tuple[str, ...] = ("bonded", "frictionless")
BASE_KINDS: tuple[str, ...] = ("fixed", "sliding")
FORMULATIONS: tuple[str, ...] = ("mixed", "displacement")
LINEAR_SOLVERS: tuple[str, ...] = ("auto", "pardiso", "superlu", "cudss", "cg")
PREDICTORS: tuple[str, ...] = ("linearized", "extrapolated")
DEVICE_PATTERN = re.compile(r"^(auto|cpu|cuda(:\d+)?)$")

_MISSING = object()


@dataclass(frozen=True)
class Specimen:
    """The specimen and its mesh.

    Attributes:
        shape: ``"block"`` (square in plan) or ``"disc"`` (round in plan).
        thickness_m: Height from the base (z = 0) to the indented top face, m.
        width_m: Full edge length of the square block, m (block only, else None).
        radius_m: Radius of the disc, m (disc only, else None).
        quarter: Model one quarter (x >= 0, y >= 0) with two symmetry planes.
        element: ``"TET10"`` (quadratic) or ``"TET4"`` (linear) tetrahedra.
        size_near_m: Target element edge length under the probe, m.
        size_far_m: Target element edge length far from the probe, m.
        growth: Size ratio of neighbouring cells along the grading, outward and downward.
        mesher: ``"extruded"`` (layers of split prisms) or ``"delaunay"`` (TetGen's quality
            tets inside the same graded surface); see
            :func:`warptissue.mesh.indentation_block`.
    """

    shape: str
    thickness_m: float
    width_m: float | None
    radius_m: float | None
    quarter: bool
    element: str
    size_near_m: float
    size_far_m: float
    growth: float
    mesher: str = "extruded"

    def to_dict(self) -> dict[str, Any]:
        """The ``[specimen]`` table, with every default filled in."""
        table: dict[str, Any] = {"shape": self.shape}
        if self.width_m is not None:
            table["width_m"] = self.width_m
        if self.radius_m is not None:
            table["radius_m"] = self.radius_m
        table.update(
            thickness_m=self.thickness_m,
            quarter=self.quarter,
            element=self.element,
            size_near_m=self.size_near_m,
            size_far_m=self.size_far_m,
            growth=self.growth,
            mesher=self.mesher,
        )
        return table


@dataclass(frozen=True)
class Indenter:
    """The indenter.

    Attributes:
        kind: ``"flat_punch"`` (a rigid flat-ended cylinder).
        radius_m: Probe radius, m.
        contact: ``"bonded"`` (nodes under the probe move with it in x, y and z) or
            ``"frictionless"`` (only z is prescribed under the probe).
    """

    kind: str
    radius_m: float
    contact: str

    def to_dict(self) -> dict[str, Any]:
        """The ``[indenter]`` table."""
        return {"kind": self.kind, "radius_m": self.radius_m, "contact": self.contact}


@dataclass(frozen=True)
class Protocol:
    """The loading protocol: the probe depths of the load steps.

    Attributes:
        depths_m: Probe depth at the end of each load step, shape (steps,), strictly
            increasing and positive, m.
    """

    depths_m: tuple[float, ...]

    @property
    def max_depth_m(self) -> float:
        """The final depth, m."""
        return self.depths_m[-1]

    @property
    def step_count(self) -> int:
        """Number of load steps."""
        return len(self.depths_m)

    def to_dict(self) -> dict[str, Any]:
        """The ``[protocol]`` table (always as an explicit depth list)."""
        return {"depths_m": list(self.depths_m)}


@dataclass(frozen=True)
class Boundary:
    """Boundary conditions besides the probe and the symmetry planes.

    Attributes:
        base: ``"fixed"`` (all displacement of the base z = 0 is zero) or ``"sliding"``
            (only z is held; the base slides freely in x and y).
    """

    base: str

    def to_dict(self) -> dict[str, Any]:
        """The ``[boundary]`` table."""
        return {"base": self.base}


@dataclass(frozen=True)
class Solver:
    """Solver settings.

    Attributes:
        device: ``"auto"`` (a GPU where present, else the CPU), ``"cpu"``, ``"cuda"`` or
            ``"cuda:N"``.
        formulation: ``"mixed"`` (locking-free for nearly incompressible material) or
            ``"displacement"`` (pure displacement; locks when nearly incompressible).
        linear_solver: ``"auto"`` (PARDISO where pypardiso is installed, else SuperLU, on the
            CPU; cuDSS on CUDA where installed, else conjugate gradients), ``"pardiso"``,
            ``"superlu"``, ``"cudss"`` or ``"cg"``.
        tolerance: Newton convergence tolerance on the residual force norm relative to the
            reaction force norm (dimensionless).
        max_newton_iterations: Newton iterations allowed per load step before a cutback.
        max_cutbacks: Number of times a failed load step may be halved before the run
            stops early.
        nonlinear_elimination: Relax the nodes that hold most of the residual after each
            global Newton step (fewer factorizations at a punch edge; same converged curve).
        predictor: Start of each load step's Newton iterations: ``"linearized"`` or
            ``"extrapolated"`` (see :func:`warptissue.fem.solve_quasistatic`; same converged
            curve).
        damping: Damp the tangent (Levenberg-Marquardt) after a Newton step that the line
            search cut short (same converged curve).
    """

    device: str
    formulation: str
    linear_solver: str
    tolerance: float
    max_newton_iterations: int
    max_cutbacks: int
    nonlinear_elimination: bool = True
    predictor: str = "linearized"
    damping: bool = True

    def to_dict(self) -> dict[str, Any]:
        """The ``[solver]`` table."""
        return {
            "device": self.device,
            "formulation": self.formulation,
            "linear_solver": self.linear_solver,
            "tolerance": self.tolerance,
            "max_newton_iterations": self.max_newton_iterations,
            "max_cutbacks": self.max_cutbacks,
            "nonlinear_elimination": self.nonlinear_elimination,
            "predictor": self.predictor,
            "damping": self.damping,
        }


@dataclass(frozen=True)
class Study:
    """A validated study.

    Attributes:
        name: A short name for the study (defaults to the file's stem).
        description: Free text.
        specimen: Specimen geometry and mesh settings.
        indenter: The probe.
        protocol: The load steps.
        material: The constitutive model, a :mod:`warptissue.materials` object.
        boundary: Base boundary condition.
        solver: Solver settings.
        path: The file it was loaded from, or None when built from a mapping.
        schema_version: The schema version of the record (always :data:`SCHEMA_VERSION`).
    """

    name: str
    description: str
    specimen: Specimen
    indenter: Indenter
    protocol: Protocol
    material: Any
    boundary: Boundary
    solver: Solver
    path: Path | None = None
    schema_version: int = SCHEMA_VERSION

    def to_dict(self) -> dict[str, Any]:
        """The study as a TOML-ready mapping, with every default filled in.

        ``study_from_dict(study.to_dict())`` reproduces the study.
        """
        return {
            "schema_version": self.schema_version,
            "name": self.name,
            "description": self.description,
            "specimen": self.specimen.to_dict(),
            "indenter": self.indenter.to_dict(),
            "protocol": self.protocol.to_dict(),
            "material": dict(self.material.to_dict()),
            "boundary": self.boundary.to_dict(),
            "solver": self.solver.to_dict(),
        }


class _Source:
    """Where values come from: the file, and the line of each key in its text."""

    def __init__(self, path: Path | None, text: str | None) -> None:
        self.path = path
        self._lines: dict[str, int] = {}
        if text is not None:
            self._index_lines(text)

    def _index_lines(self, text: str) -> None:
        table = ""
        header = re.compile(r"^\s*\[([^\[\]]+)\]\s*(#.*)?$")
        assignment = re.compile(r"^\s*([A-Za-z0-9_\-\"'.]+)\s*=")
        for number, line in enumerate(text.splitlines(), start=1):
            match = header.match(line)
            if match:
                table = match.group(1).strip().replace(" ", "")
                self._lines.setdefault(table, number)
                continue
            match = assignment.match(line)
            if match:
                key = match.group(1).strip().strip("\"'")
                self._lines.setdefault(f"{table}.{key}" if table else key, number)

    def line(self, key_path: str) -> int | None:
        """The line where ``key_path`` (or failing that its table) is written, if known."""
        while key_path:
            if key_path in self._lines:
                return self._lines[key_path]
            key_path = key_path.rpartition(".")[0]
        return None

    def error(self, key_path: str, problem: str, value: Any = None) -> InputError:
        """An InputError naming the file, the line, the key path and the value."""
        return InputError(
            f"{key_path}: {problem}", path=self.path, line=self.line(key_path), value=value
        )


class _Table:
    """Typed, key-path-aware access to one TOML table; rejects keys nobody asked for."""

    def __init__(self, data: Any, prefix: str, source: _Source) -> None:
        if not isinstance(data, Mapping):
            raise source.error(prefix, f"must be a table, not {type(data).__name__}", data)
        self.data = data
        self.prefix = prefix
        self.source = source
        self.used: set[str] = set()

    def key_path(self, key: str) -> str:
        return f"{self.prefix}.{key}" if self.prefix else key

    def error(self, key: str, problem: str, value: Any = None) -> InputError:
        return self.source.error(self.key_path(key), problem, value)

    def has(self, key: str) -> bool:
        return key in self.data

    def raw(self, key: str, default: Any = _MISSING) -> Any:
        self.used.add(key)
        if key not in self.data:
            if default is _MISSING:
                raise self.error(key, "required key is missing")
            return default
        return self.data[key]

    def table(self, key: str) -> _Table:
        return _Table(self.raw(key), self.key_path(key), self.source)

    def number(self, key: str, *, default: Any = _MISSING, positive: bool = True) -> float | None:
        value = self.raw(key, default)
        if value is default and default is not _MISSING:
            return value
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.error(key, "must be a number", value)
        if not math.isfinite(value):
            raise self.error(key, "must be a finite number", value)
        if positive and value <= 0:
            raise self.error(key, "must be positive", value)
        return float(value)

    def integer(self, key: str, *, default: Any = _MISSING, minimum: int = 1) -> int:
        value = self.raw(key, default)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(key, "must be an integer", value)
        if value < minimum:
            raise self.error(key, f"must be at least {minimum}", value)
        return int(value)

    def boolean(self, key: str, *, default: Any = _MISSING) -> bool:
        value = self.raw(key, default)
        if not isinstance(value, bool):
            raise self.error(key, "must be true or false", value)
        return value

    def string(self, key: str, *, default: Any = _MISSING, choices: Sequence[str] = ()) -> str:
        value = self.raw(key, default)
        if not isinstance(value, str):
            raise self.error(key, "must be a string", value)
        if choices and value not in choices:
            raise self.error(key, f"must be one of {', '.join(map(repr, choices))}", value)
        return value

    def number_list(self, key: str) -> tuple[float, ...]:
        values = self.raw(key)
        if not isinstance(values, list) or not values:
            raise self.error(key, "must be a non-empty list of numbers", values)
        for value in values:
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise self.error(key, "must contain only numbers", value)
            if not math.isfinite(value):
                raise self.error(key, "must contain only finite numbers", value)
        return tuple(float(v) for v in values)

    def finish(self, *, also_known: Sequence[str] = ()) -> None:
        """Reject any key that was not read (``also_known`` are listed as valid too)."""
        unknown = [key for key in self.data if key not in self.used]
        if unknown:
            known = ", ".join(sorted(self.used | set(also_known)))
            raise self.error(unknown[0], f"unknown key (known keys here: {known})", None)


def _read_specimen(table: _Table, probe_radius_m: float) -> Specimen:
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
    half_size_m = width_m / 2.0 if shape == "block" else radius_m
    size_key = "width_m" if shape == "block" else "radius_m"
    if half_size_m <= probe_radius_m:
        raise table.error(
            size_key,
            f"the specimen must extend beyond the probe radius {probe_radius_m!r} m"
            + (" (half the width is compared)" if shape == "block" else ""),
            width_m if shape == "block" else radius_m,
        )
    quarter = table.boolean("quarter", default=True)
    element = table.string("element", default="TET10", choices=ELEMENT_TYPES)
    size_near_m = table.number("size_near_m", default=probe_radius_m / 4.0)
    size_far_m = table.number("size_far_m", default=min(thickness_m, half_size_m) / 4.0)
    if size_near_m > size_far_m:
        raise table.error(
            "size_near_m", f"must not exceed size_far_m ({size_far_m!r} m)", size_near_m
        )
    if size_near_m > probe_radius_m:
        raise table.error(
            "size_near_m",
            f"must not exceed the probe radius ({probe_radius_m!r} m), or the probe is not "
            "resolved",
            size_near_m,
        )
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
    )


def _read_indenter(table: _Table) -> Indenter:
    kind = table.string("kind", choices=INDENTER_KINDS)
    radius_m = table.number("radius_m")
    contact = table.string("contact", default="bonded", choices=CONTACT_KINDS)
    table.finish()
    return Indenter(kind=kind, radius_m=radius_m, contact=contact)


def _read_protocol(table: _Table, thickness_m: float) -> Protocol:
    has_list = table.has("depths_m")
    has_ramp = table.has("max_depth_m") or table.has("steps")
    if has_list == has_ramp:
        raise table.source.error(
            table.prefix,
            "give either depths_m, or max_depth_m and steps (exactly one of the two forms)",
        )
    if has_list:
        depths = table.number_list("depths_m")
        for previous, depth in zip((0.0, *depths[:-1]), depths, strict=True):
            if depth <= previous:
                raise table.error(
                    "depths_m", "must be positive and strictly increasing", list(depths)
                )
        last_key = "depths_m"
    else:
        max_depth_m = table.number("max_depth_m")
        steps = table.integer("steps")
        depths = tuple(max_depth_m * (k + 1) / steps for k in range(steps))
        last_key = "max_depth_m"
    if depths[-1] >= thickness_m:
        raise table.error(
            last_key,
            f"the final depth must be less than the thickness ({thickness_m!r} m)",
            depths[-1],
        )
    table.finish(also_known=("depths_m", "max_depth_m", "steps"))
    return Protocol(depths_m=depths)


def _read_material(table: _Table) -> Any:
    from warptissue.materials import material_from_dict

    for key in table.data:
        table.raw(key)
    try:
        return material_from_dict(dict(table.data))
    except InputError as exc:
        key = exc.column or ""
        key_path = table.key_path(key) if key else table.prefix
        raise InputError(
            f"{key_path}: {exc.message}",
            path=table.source.path,
            line=table.source.line(key_path),
            value=exc.value,
        ) from exc


def _read_boundary(table: _Table) -> Boundary:
    base = table.string("base", default="fixed", choices=BASE_KINDS)
    table.finish()
    return Boundary(base=base)


def _read_solver(table: _Table) -> Solver:
    device = table.string("device", default="auto")
    if not DEVICE_PATTERN.match(device):
        raise table.error("device", "must be 'auto', 'cpu', 'cuda' or 'cuda:N'", device)
    formulation = table.string("formulation", default="mixed", choices=FORMULATIONS)
    linear_solver = table.string("linear_solver", default="auto", choices=LINEAR_SOLVERS)
    tolerance = table.number("tolerance", default=1.0e-9)
    if tolerance >= 1.0:
        raise table.error("tolerance", "must be less than 1", tolerance)
    max_newton_iterations = table.integer("max_newton_iterations", default=25)
    max_cutbacks = table.integer("max_cutbacks", default=8, minimum=0)
    nonlinear_elimination = table.boolean("nonlinear_elimination", default=True)
    predictor = table.string("predictor", default="linearized", choices=PREDICTORS)
    damping = table.boolean("damping", default=True)
    table.finish()
    return Solver(
        device=device,
        formulation=formulation,
        linear_solver=linear_solver,
        tolerance=tolerance,
        max_newton_iterations=max_newton_iterations,
        max_cutbacks=max_cutbacks,
        nonlinear_elimination=nonlinear_elimination,
        predictor=predictor,
        damping=damping,
    )


def _build(data: Mapping[str, Any], source: _Source, default_name: str) -> Study:
    root = _Table(data, "", source)
    version = root.raw("schema_version")
    if isinstance(version, bool) or not isinstance(version, int):
        raise root.error("schema_version", "must be an integer", version)
    if version != SCHEMA_VERSION:
        raise root.error(
            "schema_version",
            f"unsupported schema version; this reader knows {SCHEMA_VERSION}",
            version,
        )
    name = root.string("name", default=default_name)
    description = root.string("description", default="")
    indenter = _read_indenter(root.table("indenter"))
    specimen = _read_specimen(root.table("specimen"), indenter.radius_m)
    protocol = _read_protocol(root.table("protocol"), specimen.thickness_m)
    material = _read_material(root.table("material"))
    boundary = _read_boundary(_optional_table(root, "boundary"))
    solver = _read_solver(_optional_table(root, "solver"))
    root.finish()
    return Study(
        name=name,
        description=description,
        specimen=specimen,
        indenter=indenter,
        protocol=protocol,
        material=material,
        boundary=boundary,
        solver=solver,
        path=source.path,
    )


def _optional_table(root: _Table, key: str) -> _Table:
    """A table whose keys all have defaults, so that the table itself may be left out."""
    return _Table(root.raw(key, {}), root.key_path(key), root.source)


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
    source = _Source(None if path is None else Path(path), None)
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
    if not study_path.is_file():
        raise InputError("study file not found", path=study_path)
    text = study_path.read_text(encoding="utf-8")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        line = getattr(exc, "lineno", None)
        if line is None:
            match = re.search(r"at line (\d+)", str(exc))
            line = int(match.group(1)) if match else None
        raise InputError(f"not valid TOML: {exc}", path=study_path, line=line) from exc
    return _build(data, _Source(study_path, text), default_name=study_path.stem)
