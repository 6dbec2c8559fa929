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

import difflib
import math
import re
import tomllib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from warptissue.errors import InputError
from warptissue.indenter import CONTACTS, SIMULATED_KINDS, Indenter
from warptissue.mesh.generators import MESHERS

if TYPE_CHECKING:
    from warptissue.fem.solvers import NewtonOptions

__all__ = [
    "SCHEMA_VERSION",
    "Boundary",
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
BASE_KINDS: tuple[str, ...] = ("fixed", "sliding")
MAX_STEPS: int = 10_000
"""Most load steps a study may have: the run keeps every converged state in memory."""
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
    """Solver settings: the ``[solver]`` table.

    The table is flat: ``device``, ``formulation`` and the keys of
    :class:`warptissue.fem.NewtonOptions` under the same names (``linear_solver``,
    ``tolerance``, ``max_newton_iterations``, ``max_cutbacks``, ``nonlinear_elimination``,
    ``predictor``, ``damping``), each with its default there.

    Attributes:
        device: ``"auto"`` (a GPU where present, else the CPU), ``"cpu"``, ``"cuda"`` or
            ``"cuda:N"``.
        formulation: ``"mixed"`` (locking-free for nearly incompressible material) or
            ``"displacement"`` (pure displacement; locks when nearly incompressible).
        options: The Newton solver's settings, passed as they are to
            :func:`warptissue.fem.simulate_indentation`.
    """

    device: str
    formulation: str
    options: NewtonOptions

    def to_dict(self) -> dict[str, Any]:
        """The ``[solver]`` table (flat: device, formulation, then the Newton options)."""
        return {"device": self.device, "formulation": self.formulation, **self.options.to_dict()}


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


_UNIT_WORDS = {"_m": "metres", "_Pa": "pascals", "_s": "seconds", "_N": "newtons"}
"""Unit suffixes of key names, for the hint of a "must be a number" error."""


def _plain(value: Any) -> Any:
    """NumPy scalars and arrays as Python numbers and lists (checks and messages alike)."""
    if type(value).__module__ == "numpy":
        return value.tolist()
    return value


def _closest(word: str, candidates: Sequence[str]) -> str | None:
    """The candidate closest to ``word`` (case-insensitive), if one is close."""
    lowered = {candidate.lower(): candidate for candidate in candidates if candidate != word}
    match = difflib.get_close_matches(word.lower(), list(lowered), n=1, cutoff=0.6)
    return lowered[match[0]] if match else None


def _number_problem(key: str) -> str:
    """ "must be a number", with the unit its key names (SI units, no unit strings)."""
    for suffix, word in _UNIT_WORDS.items():
        if key.endswith(suffix):
            return f"must be a number in {word} (SI units, without a unit: 1 mm is 0.001)"
    return "must be a number"


class _Table:
    """Typed, key-path-aware access to one TOML table; rejects keys nobody asked for."""

    def __init__(self, data: Any, prefix: str, source: _Source) -> None:
        if not isinstance(data, Mapping):
            raise source.error(prefix, f"must be a table, not {type(data).__name__}", _plain(data))
        self.data = data
        self.prefix = prefix
        self.source = source
        self.used: set[str] = set()

    def key_path(self, key: str) -> str:
        return f"{self.prefix}.{key}" if self.prefix else key

    def error(self, key: str, problem: str, value: Any = None) -> InputError:
        return self.source.error(self.key_path(key), problem, _plain(value))

    def has(self, key: str) -> bool:
        return key in self.data

    def raw(self, key: str, default: Any = _MISSING) -> Any:
        self.used.add(key)
        if key not in self.data:
            if default is _MISSING:
                raise self.missing(key)
            return default
        return _plain(self.data[key])

    def missing(self, key: str) -> InputError:
        """The error for a missing required key: a close unknown key is named as the typo."""
        typo = _closest(key, [k for k in self.data if k not in self.used])
        if typo is not None:
            return self.error(
                typo, f"unknown key; did you mean {key!r}? ({key!r} is required)", None
            )
        return self.error(key, "required key is missing")

    def table(self, key: str) -> _Table:
        return _Table(self.raw(key), self.key_path(key), self.source)

    def number(self, key: str, *, default: Any = _MISSING, positive: bool = True) -> float | None:
        value = self.raw(key, default)
        if value is default and default is not _MISSING:
            return value
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.error(key, _number_problem(key), value)
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
            raise self.error(key, "must be true or false (without quotes)", value)
        return value

    def string(self, key: str, *, default: Any = _MISSING, choices: Sequence[str] = ()) -> str:
        value = self.raw(key, default)
        if not isinstance(value, str):
            raise self.error(key, "must be a string (in quotes)", value)
        if choices and value not in choices:
            close = _closest(value, choices)
            hint = f" (did you mean {close!r}?)" if close else ""
            raise self.error(key, f"must be one of {', '.join(map(repr, choices))}{hint}", value)
        return value

    def number_list(self, key: str) -> tuple[float, ...]:
        values = self.raw(key)
        if not isinstance(values, list | tuple) or not values:
            raise self.error(key, "must be a non-empty list of numbers", values)
        values = [_plain(value) for value in values]
        for value in values:
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise self.error(key, f"must contain only numbers ({_number_problem(key)})", value)
            if not math.isfinite(value):
                raise self.error(key, "must contain only finite numbers", value)
        return tuple(float(v) for v in values)

    def present(self, keys: Sequence[str]) -> dict[str, Any]:
        """The values of those of ``keys`` that are given (all of ``keys`` count as known)."""
        for key in keys:
            self.raw(key, None)
        return {key: _plain(self.data[key]) for key in keys if key in self.data}

    def build(self, constructor: Callable[..., Any], values: Mapping[str, Any]) -> Any:
        """``constructor(values)``, its InputError placed at the file, line and key path.

        An error about a key the table lacks names a close key of the table as its typo.
        """
        try:
            return constructor(values)
        except InputError as exc:
            key = exc.column or ""
            if key and key not in self.data:
                typo = _closest(key, list(self.data))
                if typo is not None:
                    raise self.error(
                        typo, f"unknown key; did you mean {key!r}? ({exc.message})", None
                    ) from exc
            raise (
                self.error(key, exc.message, exc.value)
                if key
                else self.source.error(self.prefix, exc.message, _plain(exc.value))
            ) from exc

    def finish(self, *, also_known: Sequence[str] = ()) -> None:
        """Reject any key that was not read (``also_known`` are listed as valid too)."""
        unknown = [key for key in self.data if key not in self.used]
        if unknown:
            known = sorted(self.used | set(also_known))
            close = _closest(unknown[0], known)
            hint = f"did you mean {close!r}? " if close else ""
            raise self.error(
                unknown[0], f"unknown key ({hint}known keys here: {', '.join(known)})", None
            )


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
    kind = table.string("kind", choices=SIMULATED_KINDS)
    radius_m = table.number("radius_m")
    contact = table.string("contact", default="bonded", choices=CONTACTS)
    table.finish()
    return table.build(
        lambda values: Indenter(**values), {"kind": kind, "radius_m": radius_m, "contact": contact}
    )


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
    table.finish(also_known=("depths_m", "max_depth_m", "steps"))
    return Protocol(depths_m=depths)


def _read_material(table: _Table) -> Any:
    from warptissue.materials import material_from_dict

    values = table.present(list(table.data))
    return table.build(material_from_dict, values)


def _read_boundary(table: _Table) -> Boundary:
    base = table.string("base", default="fixed", choices=BASE_KINDS)
    table.finish()
    return Boundary(base=base)


def _read_solver(table: _Table) -> Solver:
    # The solver's own modules: importing them does not start Warp (test_study checks).
    from warptissue.fem.assembly import FORMULATIONS
    from warptissue.fem.solvers import NewtonOptions

    device = table.string("device", default="auto")
    if not DEVICE_PATTERN.match(device):
        raise table.error("device", "must be 'auto', 'cpu', 'cuda' or 'cuda:N'", device)
    formulation = table.string("formulation", default="mixed", choices=FORMULATIONS)
    options = table.build(
        lambda values: NewtonOptions(**values), table.present(NewtonOptions.keys())
    )
    table.finish()
    return Solver(device=device, formulation=formulation, options=options)


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
    if not name.strip() or name in (".", "..") or any(c in name for c in "/\\\0"):
        raise root.error(
            "name", "must be a plain name (it names the default output folder runs/<name>)", name
        )
    description = root.string("description", default="")
    indenter = _read_indenter(root.table("indenter"))
    specimen = _read_specimen(root.table("specimen"), indenter.radius_m)
    protocol = _read_protocol(root.table("protocol"), specimen.thickness_m)
    material = _read_material(root.table("material"))
    boundary = _read_boundary(_optional_table(root, "boundary"))
    solver = _read_solver(_optional_table(root, "solver"))
    if solver.formulation == "mixed" and specimen.element != "TET10":
        key = "solver.formulation" if source.line("solver.formulation") else "specimen.element"
        raise source.error(
            key,
            f"formulation 'mixed' needs element 'TET10' (specimen.element is "
            f"{specimen.element!r}); TET4 takes formulation 'displacement', which locks when "
            "nearly incompressible",
        )
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
    return _build(data, _Source(study_path, text), default_name=study_path.stem)
