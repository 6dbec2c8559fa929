"""Study files: the TOML record of one indentation simulation.

A study names the specimen and its mesh, the indenter, the loading protocol, the material,
the boundary conditions and the solver settings. It is the reproducible record of a run and
the unit of batch work: ``warptissue simulate STUDY.toml`` runs one, and the result JSON
echoes it back with every default filled in.

The schema is versioned. Version 1 describes a simulation; version 2 (:data:`SCHEMA_VERSION`)
adds the tables of a fit: ``[[data]]``, the measured records (CSV files relative to the study
file, their columns and their conditioning, read and conditioned on loading), and ``[fit]``,
which material parameters are free, their bounds and start values, the least-squares method
and its tolerances. Version-1 files load unchanged. Every key carries its unit in its name
(``thickness_m``, ``C10_Pa``). Loading validates the whole file: an unknown key, a missing
key, a value of the wrong type or out of range raises :class:`~warptissue.errors.InputError`
naming the file, the line, the key path (for example ``material.C10_Pa`` or
``data[0].keep_depth_m``) and the value, with the closest known name where one is close.

:func:`warptissue.fit.start.start_values_from_record` gives the start of every free parameter
from the small-depth stiffness of a record (Sneddon's flat punch with the Hayes layer factor);
:func:`save_study` writes a study (a fitted one, say) back as TOML, its data paths relative to
the new file.

Example:
    >>> from warptissue.study import load_study
    >>> study = load_study("scenes/liver_slab_flat_punch.toml")  # doctest: +SKIP
    >>> study.protocol.depths_m[-1]  # doctest: +SKIP
    0.0005
"""

from __future__ import annotations

import difflib
import math
import os
import re
import tomllib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import tomli_w

from warptissue.acquisition.conditioning import CONTACT_MODES, OFFSET_MODES, condition_for_fit
from warptissue.errors import InputError
from warptissue.fem.assembly import FORMULATIONS
from warptissue.fem.contact import DEFAULT_PENALTY_FACTOR
from warptissue.fem.newton import NewtonOptions
from warptissue.indenter import CONTACT_KINDS, CONTACTS, SIMULATED_KINDS, Indenter
from warptissue.io import atomic_path, read_experiment_csv
from warptissue.loading import ramp_hold, resample_history, sine
from warptissue.lsq.engine import METHODS
from warptissue.materials import material_from_dict, prony_term
from warptissue.mesh.generators import MESHERS
from warptissue.mesh.size import size_near_for_force_accuracy

if TYPE_CHECKING:
    import numpy as np

    from warptissue.acquisition.conditioning import FitRecord
    from warptissue.fem.newton import NewtonOptions

__all__ = [
    "FIT_METHODS",
    "FIT_OBJECTIVES",
    "CONTACT_POINTS",
    "DEPTH_OFFSET",
    "FIT_STRATEGIES",
    "PROTOCOL_KINDS",
    "SCHEMA_VERSION",
    "SCHEMA_VERSIONS",
    "START_FROM",
    "Boundary",
    "DataRecord",
    "FitSettings",
    "Protocol",
    "Solver",
    "Specimen",
    "Study",
    "load_study",
    "save_study",
    "study_from_dict",
]

SCHEMA_VERSION: int = 2
"""The newest study schema version: the one with ``[[data]]`` and ``[fit]``."""
SCHEMA_VERSIONS: tuple[int, ...] = (1, 2)
"""The versions this module reads (1: a simulation; 2: a simulation that may hold a fit)."""
FIT_METHODS: tuple[str, ...] = METHODS
"""``fit.method``: the methods of :func:`warptissue.lsq.least_squares` (its ``METHODS``)."""
FIT_OBJECTIVES: tuple[str, ...] = ("absolute", "relative")
"""``fit.objective``: force residuals (N), or residuals divided by the measured force."""
FIT_STRATEGIES: tuple[str, ...] = ("joint", "two_stage")
"""``fit.strategy``: all free parameters at once, or Ahn & Kim's Prony-first two stages."""
PROTOCOL_KINDS: tuple[str, ...] = ("quasi_static", "timed", "ramp_hold", "sine", "record")
"""``protocol.kind``: depths only, explicit depths and times, or a generated history."""
START_FROM: tuple[str, ...] = ("record", "material")
"""``fit.start_from``: where a free parameter without a ``[fit.start]`` value starts."""
CONTACT_POINTS: tuple[str, ...] = ("given", "fit")
"""``fit.contact_point``: the records' depths as conditioned (``"given"``), or a depth offset
of each record fitted with the material (``"fit"``, :mod:`warptissue.fit.indentation`)."""
DEPTH_OFFSET: str = "depth_offset_m"
"""The key of the depth offset in ``[fit.start]`` and ``[fit.bounds]`` (with
``contact_point = "fit"``), and its parameter name in a fit of one record."""
DEFAULT_COLUMNS: dict[str, str] = {
    "time_column": "time_s",
    "displacement_column": "displacement_m",
    "force_column": "force_N",
}
"""The ``[[data]]`` column keys and the column each names by default."""

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
        force_accuracy: The relative force accuracy that ``size_near_m`` was chosen for
            (:func:`warptissue.mesh.size_near_for_force_accuracy`), or None when the near
            size was given (or defaulted).
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
    force_accuracy: float | None = None

    @property
    def half_size_m(self) -> float:
        """The specimen's extent from the probe axis, m (:func:`specimen_half_size_m`)."""
        return specimen_half_size_m(self.shape, self.width_m, self.radius_m)

    def to_dict(self) -> dict[str, Any]:
        """The ``[specimen]`` table, with every default filled in; a near size chosen for a
        force accuracy is given as ``force_accuracy`` (which loads as the same size)."""
        table: dict[str, Any] = {"shape": self.shape}
        if self.width_m is not None:
            table["width_m"] = self.width_m
        if self.radius_m is not None:
            table["radius_m"] = self.radius_m
        table.update(thickness_m=self.thickness_m, quarter=self.quarter, element=self.element)
        if self.force_accuracy is None:
            table["size_near_m"] = self.size_near_m
        else:
            table["force_accuracy"] = self.force_accuracy
        table.update(size_far_m=self.size_far_m, growth=self.growth, mesher=self.mesher)
        return table


@dataclass(frozen=True)
class Protocol:
    """The loading protocol: the probe depth at the end of each load (or time) step.

    A quasi-static protocol (``kind = "quasi_static"``, the default) is a list of depths,
    rate-independent. A timed one (``"ramp_hold"``, ``"sine"``, ``"record"`` or an explicit
    ``"timed"`` list) also gives the time of each step: the FE starts from depth 0 at time 0
    and moves the probe linearly in time between steps, and a viscoelastic material relaxes
    (:func:`warptissue.fem.simulate_indentation` with ``times_s``). The depth-time histories
    are :mod:`warptissue.loading`'s.

    Attributes:
        depths_m: Probe depth at the end of each step, shape (steps,), m. Quasi-static:
            positive and strictly increasing; timed: >= 0 (the probe may go up and down).
        times_s: Time at the end of each step, shape (steps,), s, strictly increasing and
            > 0; None for a quasi-static protocol.
        kind: ``"quasi_static"``, ``"timed"`` (explicit ``depths_m`` and ``times_s``),
            ``"ramp_hold"``, ``"sine"`` or ``"record"``.
        settings: The keys that generated a ``ramp_hold`` or ``sine`` protocol (every
            default filled in), or ``{"steps": n}`` for a record; empty otherwise.
        record: The record whose depth-time history a ``"record"`` protocol follows (its
            force, where the CSV has one, is not used), else None.
    """

    depths_m: tuple[float, ...]
    times_s: tuple[float, ...] | None = None
    kind: str = "quasi_static"
    settings: dict[str, Any] = field(default_factory=dict)
    record: DataRecord | None = None

    @classmethod
    def from_record(cls, record: DataRecord, *, steps: int = 40) -> Protocol:
        """A ``"record"`` protocol along a record's own depth-time history.

        For example a fitted viscoelastic study's protocol, so that ``warptissue simulate``
        replays the first ``[[data]]`` record: ``dataclasses.replace(study,
        protocol=Protocol.from_record(study.data[0], steps=study.fit.time_steps))``.
        Written back (:func:`save_study`) it reads as the same protocol.

        Args:
            record: A conditioned record (of ``study.data``).
            steps: About how many time steps (:meth:`DataRecord.load_history`).

        Returns:
            The protocol, its steps those of ``record.load_history(steps=steps)``.
        """
        times, depths = record.load_history(steps=steps)
        return cls(
            depths_m=tuple(float(d) for d in depths),
            times_s=tuple(float(t) for t in times),
            kind="record",
            settings={"steps": int(steps)},
            record=record,
        )

    @property
    def max_depth_m(self) -> float:
        """The deepest depth, m (the final one of a quasi-static protocol)."""
        return max(self.depths_m)

    @property
    def step_count(self) -> int:
        """Number of load (time) steps."""
        return len(self.depths_m)

    @property
    def timed(self) -> bool:
        """True when the steps have times (a time-stepped run)."""
        return self.times_s is not None

    def to_dict(self, *, relative_to: str | Path | None = None) -> dict[str, Any]:
        """The ``[protocol]`` table.

        Quasi-static: an explicit depth list (no ``kind``, so that a version-1 study is
        echoed as version 1). Timed: the kind and the keys that generated it, every default
        filled in (``"timed"``: the two lists; ``"record"``: the record's keys, its file
        relative to ``relative_to`` where given, as :meth:`Study.to_dict`).
        """
        if self.kind == "quasi_static":
            return {"depths_m": list(self.depths_m)}
        table: dict[str, Any] = {"kind": self.kind}
        if self.kind == "timed":
            table.update(depths_m=list(self.depths_m), times_s=list(self.times_s or ()))
        elif self.kind == "record" and self.record is not None:
            table.update(self.record.to_dict(relative_to=relative_to))
            table.update(self.settings)
        else:
            table.update(self.settings)
        return table


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

    The table is flat: ``device``, ``formulation``, ``penalty_factor`` and the keys of
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
        penalty_factor: ``beta`` of the rigid contact's penalty stiffness ``k = beta mu0 h``
            (:class:`warptissue.fem.IndentationProblem`; default
            :data:`warptissue.fem.contact.DEFAULT_PENALTY_FACTOR`); unused by a sharp flat
            punch, whose nodes are prescribed.
    """

    device: str
    formulation: str
    options: NewtonOptions
    penalty_factor: float

    def to_dict(self) -> dict[str, Any]:
        """The ``[solver]`` table (flat: device, formulation, penalty factor, then the Newton
        options)."""
        return {
            "device": self.device,
            "formulation": self.formulation,
            "penalty_factor": self.penalty_factor,
            **self.options.to_dict(),
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
        schema_version: The schema version of the record (1 or 2, as read).
        data: The measured records of ``[[data]]`` (version 2), conditioned; empty when none.
        fit: The ``[fit]`` settings (version 2), or None.
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
    data: tuple[DataRecord, ...] = ()
    fit: FitSettings | None = None

    def to_dict(self, *, relative_to: str | Path | None = None) -> dict[str, Any]:
        """The study as a TOML-ready mapping, with every default filled in.

        ``study_from_dict(study.to_dict())`` reproduces the study.

        Args:
            relative_to: A folder: the data files are written relative to it (where the
                study is written to a new place). None: as the study file gave them.
        """
        record = {
            "schema_version": self.schema_version,
            "name": self.name,
            "description": self.description,
            "specimen": self.specimen.to_dict(),
            "indenter": self.indenter.to_dict(),
            "protocol": self.protocol.to_dict(relative_to=relative_to),
            "material": dict(self.material.to_dict()),
            "boundary": self.boundary.to_dict(),
            "solver": self.solver.to_dict(),
        }
        if self.data:
            record["data"] = [item.to_dict(relative_to=relative_to) for item in self.data]
        if self.fit is not None:
            record["fit"] = self.fit.to_dict()
        return record


@dataclass(frozen=True)
class DataRecord:
    """One measured record of ``[[data]]``: its file, its columns and its conditioning.

    The record is read (:func:`warptissue.io.read_experiment_csv`) and conditioned
    (:func:`warptissue.acquisition.conditioning.condition_for_fit`, the code behind
    ``warptissue fit relaxation --contact/--offset/--keep-depth/--window``) when the study is
    loaded; ``time_s``, ``displacement_m`` and ``force_N`` are the conditioned samples.

    Attributes:
        file: The CSV file as the study gives it (relative to the study file's folder, or
            absolute).
        path: The file, resolved.
        time_column: The CSV column of the time (s).
        displacement_column: The CSV column of the displacement (m).
        force_column: The CSV column of the force (N).
        contact: ``"none"`` (the displacement is already the depth), ``"auto"`` (detect the
            contact) or the axis position at contact (m).
        offset: ``"auto"`` (with a contact, subtract the force measured off the specimen)
            or ``"none"``.
        keep_depth_m: Keep only the loading ramp down to this depth below contact (m).
        window_s: Keep only ``start <= time_s <= stop`` (s).
        record: The conditioned samples and a summary of the conditioning.
    """

    file: str
    path: Path
    time_column: str = "time_s"
    displacement_column: str = "displacement_m"
    force_column: str = "force_N"
    contact: str | float = "none"
    offset: str = "auto"
    keep_depth_m: float | None = None
    window_s: tuple[float, float] | None = None
    record: FitRecord | None = field(default=None, compare=False, repr=False)

    @property
    def time_s(self) -> np.ndarray:
        """Time of the kept samples (s), shape (m,)."""
        return self._loaded().time_s

    @property
    def displacement_m(self) -> np.ndarray:
        """Depth of the kept samples (m), shape (m,)."""
        return self._loaded().displacement_m

    @property
    def force_N(self) -> np.ndarray:
        """Force of the kept samples (N), shape (m,)."""
        return self._loaded().force_N

    @property
    def conditioning(self) -> dict[str, Any]:
        """What the conditioning did (contact point, offset removed, samples kept), JSON-ready."""
        return self._loaded().summary

    @property
    def contact_time_s(self) -> float:
        """The time of the contact on the record's clock (s).

        With a contact point (given or detected) the time the probe reached it; with
        ``contact = "none"`` 0: the record's own time axis counts from the contact.
        """
        contact = self.conditioning.get("contact")
        return float(contact["time_s"]) if isinstance(contact, Mapping) else 0.0

    def load_history(self, *, steps: int) -> tuple[np.ndarray, np.ndarray]:
        """FE time steps that follow the record's own depth-time history.

        :func:`warptissue.loading.resample_history` of the kept samples, their time counted
        from the contact (``time_s - contact_time_s``, so that the FE starts from depth 0 at
        time 0 as the probe did): the ramps and sines resolved, a hold in log time, the
        deepest point and the last sample included. A ``window_s`` that starts after the
        contact leaves out the history before it (the FE then ramps straight from the
        contact to the window's first depth).

        Args:
            steps: About how many time steps (>= 2), e.g. ``fit.time_steps``.

        Returns:
            ``(times_s, depths_m)``, each shape (about ``steps``,): times > 0 since the
            contact (s), strictly increasing, and the record's depth there (m).

        Raises:
            InputError: Fewer than two samples after the contact, or ``steps`` below 2
                (naming the record's file).
        """

        try:
            return resample_history(
                self.time_s - self.contact_time_s, self.displacement_m, steps=steps
            )
        except InputError as exc:
            raise InputError(
                f"{exc.key}: {exc.message}" if exc.key else exc.message,
                path=self.path,
                value=exc.value,
            ) from None

    def _loaded(self) -> FitRecord:
        if self.record is None:
            raise InputError("the record was not read (build studies with load_study)")
        return self.record

    def to_dict(self, *, relative_to: str | Path | None = None) -> dict[str, Any]:
        """The record's ``[[data]]`` table (see :meth:`Study.to_dict` for ``relative_to``)."""
        file = self.file
        if relative_to is not None:  # absolute paths without resolving links, as given
            try:
                file = os.path.relpath(os.path.abspath(self.path), os.path.abspath(relative_to))
            except ValueError:  # another drive (Windows): keep the absolute path
                file = os.path.abspath(self.path)
            file = Path(file).as_posix()
        table: dict[str, Any] = {
            "file": file,
            "time_column": self.time_column,
            "displacement_column": self.displacement_column,
            "force_column": self.force_column,
        }
        if isinstance(self.contact, str):
            table["contact"] = self.contact
        else:
            table["contact_position_m"] = self.contact
        if self.contact != "none":
            table["offset"] = self.offset
        if self.keep_depth_m is not None:
            table["keep_depth_m"] = self.keep_depth_m
        if self.window_s is not None:
            table["window_s"] = list(self.window_s)
        return table


@dataclass(frozen=True)
class FitSettings:
    """The ``[fit]`` table: which material parameters a fit frees, and how it runs.

    Material parameters not in ``free`` stay at their ``[material]`` values.

    Attributes:
        free: The free parameters, named as in ``[material]`` (``C10_Pa``, ``mu1_Pa``,
            ``alpha1``, ...), in the order of the fit's parameter vector.
        start: Given start values (name -> value); the other free parameters start as
            ``start_from`` says.
        bounds: Given bounds (name -> (lower, upper)); the other free parameters have the
            material model's own box (:attr:`warptissue.materials.Material.parameter_bounds`).
        start_from: ``"record"``: free parameters without a start value that set the
            initial shear modulus start from the first record's small-depth stiffness
            (:func:`warptissue.fit.start.start_values_from_record`), the others from ``[material]``;
            ``"material"``: from ``[material]``.
        method: ``"lm"`` or ``"salm"`` (:func:`warptissue.lsq.least_squares`).
        objective: ``"absolute"`` (force residuals, N) or ``"relative"`` (divided by the
            measured force).
        relative_floor_N: With the relative objective, the smallest |force| used as a
            divisor (N); None: 1 % of the largest |force| of the records.
        max_iterations: Most trial steps of the least-squares engine.
        ftol: Relative cost-reduction tolerance of the engine.
        xtol: Relative step tolerance of the engine.
        gtol: Gradient tolerance of the engine.
        stop_r_squared: Stop as soon as R^2 of the fit exceeds this (None: run to the
            tolerances).
        strategy: ``"joint"``: every free parameter by inverse FE at once; ``"two_stage"``
            (Ahn & Kim): stage (i) the Prony terms of ``[material]`` from the normalized
            relaxation of the records, stage (ii) the free parameters other than Prony
            terms by inverse FE with the Prony terms fixed (needs Prony terms in
            ``[material]`` and a free parameter that is not one).
        time_steps: FE time steps per record: the grid of
            :meth:`DataRecord.load_history` (:func:`warptissue.loading.resample_history`).
        contact_point: ``"given"``: the records' depths count from the contact as
            conditioned; ``"fit"``: each record's depth offset d0 (the recorded depth at
            first touch, m) is fitted with the material, F(d) = F_FE(max(d - d0, 0))
            (docs/fitting.md "Contact point"). Its start and bounds
            are ``start["depth_offset_m"]`` and ``bounds["depth_offset_m"]`` (each record's),
            else from each record.
    """

    free: tuple[str, ...]
    start: dict[str, float] = field(default_factory=dict)
    bounds: dict[str, tuple[float, float]] = field(default_factory=dict)
    start_from: str = "record"
    method: str = "lm"
    objective: str = "absolute"
    relative_floor_N: float | None = None
    max_iterations: int = 50
    ftol: float = 1e-8
    xtol: float = 1e-8
    gtol: float = 1e-8
    stop_r_squared: float | None = None
    strategy: str = "joint"
    time_steps: int = 24
    contact_point: str = "given"

    def parameter_bounds(self, material: Any) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) of the free parameters, each shape (n,), in ``free`` order.

        Given bounds, else the material model's own box (+-inf where it has none).
        """

        names = list(material.parameter_names)
        lower, upper = material.parameter_bounds
        box = [
            self.bounds.get(k, (lower[names.index(k)], upper[names.index(k)])) for k in self.free
        ]
        return (
            np.array([low for low, _ in box], dtype=np.float64),
            np.array([high for _, high in box], dtype=np.float64),
        )

    def to_dict(self) -> dict[str, Any]:
        """The ``[fit]`` table, with every default filled in."""
        table: dict[str, Any] = {
            "free": list(self.free),
            "start_from": self.start_from,
            "method": self.method,
            "objective": self.objective,
            "max_iterations": self.max_iterations,
            "ftol": self.ftol,
            "xtol": self.xtol,
            "gtol": self.gtol,
            "strategy": self.strategy,
            "time_steps": self.time_steps,
        }
        if self.contact_point != "given":
            table["contact_point"] = self.contact_point
        if self.relative_floor_N is not None:
            table["relative_floor_N"] = self.relative_floor_N
        if self.stop_r_squared is not None:
            table["stop_r_squared"] = self.stop_r_squared
        if self.start:
            table["start"] = dict(self.start)
        if self.bounds:
            table["bounds"] = {k: list(v) for k, v in self.bounds.items()}
        return table


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
        array_header = re.compile(r"^\s*\[\[([^\[\]]+)\]\]\s*(#.*)?$")
        assignment = re.compile(r"^\s*([A-Za-z0-9_\-\"'.]+)\s*=")
        counts: dict[str, int] = {}
        for number, line in enumerate(text.splitlines(), start=1):
            match = array_header.match(line)
            if match:  # [[data]]: the key paths data[0], data[1], ...
                name = match.group(1).strip().replace(" ", "")
                counts[name] = counts.get(name, -1) + 1
                table = f"{name}[{counts[name]}]"
                self._lines.setdefault(name, number)
                self._lines.setdefault(table, number)
                continue
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


def specimen_half_size_m(shape: str, width_m: float | None, radius_m: float | None) -> float:
    """The specimen's extent from the probe axis: half a block's width, or a disc's radius.

    Args:
        shape: ``"block"`` or ``"disc"``.
        width_m: The block's full edge length, m (block only).
        radius_m: The disc's radius, m (disc only).

    Returns:
        The half size, m.
    """
    return width_m / 2.0 if shape == "block" else radius_m


def _read_specimen(table: _Table, indenter: Indenter) -> Specimen:
    probe_radius_m = indenter.radius_m
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
    probe_radius_m = mesh_probe_radius(indenter, half_size_m)
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
        force_accuracy=force_accuracy,
    )


def _size_near_for_accuracy(
    table: _Table, accuracy: float, *, indenter: Indenter, probe_radius_m: float
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


def _read_indenter(table: _Table) -> Indenter:
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


def mesh_probe_radius(indenter: Indenter, half_size_m: float) -> float:
    """The radius of the specimen mesh's refined zone under the probe, m: the probe's radius,
    or half the specimen's half-size for a plate without one or a wedge (whose contact
    widens with depth along its flanks)."""
    if indenter.kind == "wedge" or indenter.radius_m <= 0:
        return 0.5 * half_size_m
    return indenter.radius_m


_PROTOCOL_KEYS: dict[str, tuple[str, ...]] = {
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


def _read_protocol(table: _Table, thickness_m: float, *, version: int, base: Path) -> Protocol:
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
        owners = [k for k, keys in _PROTOCOL_KEYS.items() if key in keys]
        if key != "kind" and owners and key not in _PROTOCOL_KEYS[kind]:
            raise table.error(
                key,
                f"is not a key of kind {kind!r} (its keys: {', '.join(_PROTOCOL_KEYS[kind])}); "
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
        options = _record_options(table, base)
        steps = table.integer("steps", default=RECORD_PROTOCOL_STEPS, minimum=2)
        if steps > MAX_STEPS:
            raise table.error("steps", f"must be at most {MAX_STEPS}", steps)
        record = _condition_record(table, options, force_required=False)
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
    table.finish(also_known=_PROTOCOL_KEYS[kind])
    return Protocol(depths_m=depths, times_s=times, kind=kind, settings=settings, record=record)


def _read_quasi_static(table: _Table, thickness_m: float) -> Protocol:
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
    table.finish(also_known=("kind", *_PROTOCOL_KEYS["quasi_static"]))
    return Protocol(depths_m=depths)


def _read_material(table: _Table) -> Any:
    values = table.present(list(table.data))
    return table.build(material_from_dict, values)


def _read_boundary(table: _Table) -> Boundary:
    base = table.string("base", default="fixed", choices=BASE_KINDS)
    table.finish()
    return Boundary(base=base)


def _read_solver(table: _Table) -> Solver:
    # The solver's own modules: importing them does not start Warp (test_study checks).

    device = table.string("device", default="auto")
    if not DEVICE_PATTERN.match(device):
        raise table.error("device", "must be 'auto', 'cpu', 'cuda' or 'cuda:N'", device)
    formulation = table.string("formulation", default="mixed", choices=FORMULATIONS)
    penalty_factor = table.number("penalty_factor", default=DEFAULT_PENALTY_FACTOR)
    options = table.build(
        lambda values: NewtonOptions(**values), table.present(NewtonOptions.keys())
    )
    table.finish()
    return Solver(
        device=device, formulation=formulation, options=options, penalty_factor=penalty_factor
    )


_RECORD_KEYS = (
    "file",
    *DEFAULT_COLUMNS,
    "contact",
    "contact_position_m",
    "offset",
    "keep_depth_m",
    "window_s",
)
"""The keys of a ``[[data]]`` record."""


def _record_options(table: _Table, base: Path) -> dict[str, Any]:
    """The keys of a record (``[[data]]``, or a ``"record"`` protocol), validated."""

    file = table.string("file")
    if not file.strip():
        raise table.error("file", "must name a CSV file (relative to the study file)", file)
    path = Path(file) if Path(file).is_absolute() else base / file
    columns = {key: table.string(key, default=name) for key, name in DEFAULT_COLUMNS.items()}
    for index, (key, name) in enumerate(columns.items()):
        if not name.strip():
            raise table.error(key, "must name a column of the CSV file", name)
        if name in list(columns.values())[:index]:
            raise table.error(key, "names the same column as another column key", name)
    if table.has("contact") and table.has("contact_position_m"):
        raise table.error(
            "contact_position_m",
            "give contact ('none' or 'auto') or contact_position_m (a position), not both",
            table.data["contact_position_m"],
        )
    contact: str | float
    if table.has("contact_position_m"):
        contact = table.number("contact_position_m", positive=False)
    else:
        contact = table.string("contact", default="none", choices=CONTACT_MODES)
    offset = table.string("offset", default="auto", choices=OFFSET_MODES)
    if contact == "none" and table.has("offset"):
        raise table.error(
            "offset",
            "applies only with a contact point (contact = 'auto' or contact_position_m): "
            "without one the force is used as recorded",
            offset,
        )
    keep_depth_m = table.number("keep_depth_m", default=None)
    window_s = None
    if table.has("window_s"):
        window = table.number_list("window_s")
        if len(window) != 2 or window[0] < 0 or not window[1] > window[0]:
            raise table.error(
                "window_s", "must be [start, stop] in seconds, 0 <= start < stop", list(window)
            )
        window_s = (window[0], window[1])
    return {
        "file": file,
        "path": path,
        **columns,
        "contact": contact,
        "offset": offset,
        "keep_depth_m": keep_depth_m,
        "window_s": window_s,
    }


def _condition_record(
    table: _Table, options: Mapping[str, Any], *, force_required: bool = True
) -> DataRecord:
    """Read a record's CSV and condition it; errors placed at the table's keys.

    Without ``force_required`` a CSV without the force column is read with zero force (a
    depth-time history needs none); the contact must then be given (``"none"`` or a
    position): detecting it needs the force.
    """

    path, file, contact = options["path"], options["file"], options["contact"]
    names = {key: options[key] for key in DEFAULT_COLUMNS}
    required = tuple(names.values()) if force_required else tuple(names.values())[:2]
    try:
        data = read_experiment_csv(path, required=required, monotonic=names["time_column"])
    except InputError as exc:
        raise table.error("file", str(exc), file) from None
    columns = data.columns
    values = {
        "time_s": columns[names["time_column"]],
        "displacement_m": columns[names["displacement_column"]],
    }
    if names["force_column"] in columns:
        values["force_N"] = columns[names["force_column"]]
    elif contact == "auto":
        raise table.error(
            "contact",
            f"'auto' detects the contact from the force, and {file} has no column "
            f"{names['force_column']!r}: give contact_position_m, or contact = 'none'",
            contact,
        )
    else:
        values["force_N"] = np.zeros_like(values["time_s"])
    option_key = "contact" if isinstance(contact, str) else "contact_position_m"
    try:
        record = condition_for_fit(
            values,
            contact=contact,
            offset=options["offset"],
            keep_depth_m=options["keep_depth_m"],
            window_s=options["window_s"],
            option_names={"contact": option_key},
        )
    except InputError as exc:
        named = ("contact_position_m", "keep_depth_m", "window_s", "contact")
        key = next((k for k in named if table.has(k) and k in exc.message), None)
        if key is None and "no sample left" in exc.message:
            key = next((k for k in ("window_s", "keep_depth_m") if table.has(k)), None)
        key = key or "file"
        raise table.error(key, f"{path}: {exc.message}", table.data[key]) from None
    return DataRecord(**options, record=record)


def _read_record(table: _Table, base: Path) -> DataRecord:
    """One ``[[data]]`` record: validate its keys, read its CSV, condition it."""
    options = _record_options(table, base)
    table.finish(also_known=_RECORD_KEYS)
    return _condition_record(table, options)


def _read_data(root: _Table, base: Path) -> tuple[DataRecord, ...]:
    """``[[data]]`` (one or more records) or a single ``[data]`` table."""
    value = root.raw("data")
    if isinstance(value, Mapping):
        return (_read_record(root.table("data"), base),)
    if not isinstance(value, list) or not value:
        raise root.error("data", "must be one or more [[data]] tables", value)
    return tuple(
        _read_record(_Table(item, f"data[{i}]", root.source), base) for i, item in enumerate(value)
    )


def _free_name_problem(name: str, material: Any) -> str:
    """Why ``name`` is not a free parameter of ``material``."""
    names = material.parameter_names
    if name in material.to_dict():
        return (
            f"is held fixed: the volumetric term is not a fit parameter of model "
            f"{material.model_name!r} (its fit parameters: {', '.join(names)})"
        )
    close = _closest(name, names)
    hint = f"did you mean {close!r}? " if close else ""
    return f"is not a parameter of model {material.model_name!r} ({hint}its fit parameters: " + (
        f"{', '.join(names)})"
    )


def _parameter_table(
    table: _Table, free: Sequence[str], material: Any, *, contact_point: str = "given"
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


def _read_fit(table: _Table, material: Any) -> FitSettings:
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
        low, high = (_plain(v) for v in pair)
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


def _build(data: Mapping[str, Any], source: _Source, default_name: str) -> Study:
    root = _Table(data, "", source)
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
    indenter = _read_indenter(root.table("indenter"))
    specimen = _read_specimen(root.table("specimen"), indenter)
    base = source.path.parent if source.path is not None else Path.cwd()
    protocol = _read_protocol(
        root.table("protocol"), specimen.thickness_m, version=version, base=base
    )
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
    if specimen.force_accuracy is not None and solver.formulation != "mixed":
        raise source.error(
            "solver.formulation",
            "specimen.force_accuracy was measured with the 'mixed' formulation only: give "
            "specimen.size_near_m",
            solver.formulation,
        )
    records: tuple[DataRecord, ...] = ()
    fit = None
    if version >= 2:
        if root.has("data"):
            records = _read_data(root, base)
        if root.has("fit"):
            if not records:
                raise root.error("fit", "a fit needs measured records: add [[data]] tables")
            fit = _read_fit(root.table("fit"), material)
    else:
        for key in ("data", "fit"):
            if root.has(key):
                raise root.error(key, "needs schema_version = 2 (this file says 1)", None)
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
        schema_version=version,
        data=records,
        fit=fit,
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


def save_study(study: Study, path: str | Path) -> Path:
    """Write a study as TOML (atomically), its data files relative to the new file's folder.

    ``load_study(save_study(study, path))`` gives the study back, and ``warptissue simulate``
    runs the file as it is (a fitted study: ``dataclasses.replace(study, material=fitted)``).

    Args:
        study: The study.
        path: The ``.toml`` file to write.

    Returns:
        The path written.
    """

    target = Path(path)
    text = tomli_w.dumps(study.to_dict(relative_to=os.path.abspath(target.parent)))
    with atomic_path(target) as temporary:
        temporary.write_text(text, encoding="utf-8")
    return target
