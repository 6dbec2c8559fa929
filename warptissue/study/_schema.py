"""The study schema: its versions, its choices and the dataclasses of a validated study.

Each table of a study file has its dataclass here (:class:`Specimen`, :class:`Protocol`,
:class:`Boundary`, :class:`Solver`, :class:`DataRecord`, :class:`FitSettings`, the whole
:class:`Study`), each with the ``to_dict`` that writes it back. The package's reader
validates a file into them, its writer writes them back as TOML.
"""

from __future__ import annotations

import os
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from warptissue.errors import InputError
from warptissue.fem.newton import NewtonOptions
from warptissue.fem.support import Foundation
from warptissue.indenter import Indenter
from warptissue.loading import resample_history
from warptissue.lsq.engine import METHODS
from warptissue.study._sizing import deepest_depth_m, mesh_probe_radius, specimen_half_size_m

if TYPE_CHECKING:
    from warptissue.acquisition.conditioning import FitRecord


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
BULK_MODULUS_RULES: tuple[str, ...] = ("fixed", "follows_shear")
"""``fit.bulk_modulus``: the bulk modulus K stays at its ``[material]`` value while the shear
moduli are fitted, or K follows the initial shear modulus mu0 at the ``[material]``'s ratio
K/mu0 (its small-strain Poisson's ratio held)."""
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
BASE_KINDS: tuple[str, ...] = ("fixed", "sliding", "foundation")
MAX_STEPS: int = 10_000
"""Most load steps a study may have: the run keeps every converged state in memory."""
DEVICE_PATTERN = re.compile(r"^(auto|cpu|cuda(:\d+)?)$")


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
            :func:`warptissue.mesh.indentation_block`. A mesh specimen: ``"file"`` (the
            file's mesh as it is) or ``"refined"`` (meshed again around its probes' sites,
            :attr:`refine_zones`).
        force_accuracy: The relative force accuracy that ``size_near_m`` was chosen for
            (:func:`warptissue.mesh.size_near_for_force_accuracy`), or None when the near
            size was given (or defaulted).
        mesh_file: ``shape == "mesh"``: the volume mesh file as the study names it (relative
            to the study's folder); its ``thickness_m`` is then how deep the body reaches
            below the probe's site along its direction, and its sizes are the file's
            shortest and longest edges.
        mesh_path: The mesh file, resolved.
        unit: The mesh file's length unit (``"m"``, ``"mm"``, ...).
        refine_zones: A mesh specimen refined around its probes' sites (``force_accuracy``
            or ``size_near_m`` given with ``mesh``): per site ``(x, y, z, zone radius,
            size)``, m (:func:`warptissue.mesh.refine_near_sites`); empty: the file's mesh.
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
    mesh_file: str | None = None
    mesh_path: Path | None = None
    unit: str = "m"
    refine_zones: tuple[tuple[float, float, float, float, float], ...] = ()

    @property
    def half_size_m(self) -> float:
        """The specimen's extent from the probe axis, m (:func:`specimen_half_size_m`; a mesh
        specimen's depth below the site)."""
        if self.shape == "mesh":
            return self.thickness_m
        return specimen_half_size_m(self.shape, self.width_m, self.radius_m)

    def to_dict(self) -> dict[str, Any]:
        """The ``[specimen]`` table, with every default filled in; a near size chosen for a
        force accuracy is given as ``force_accuracy`` (which loads as the same size)."""
        if self.shape == "mesh":
            table = {"mesh": self.mesh_file, "unit": self.unit, "element": self.element}
            if self.force_accuracy is not None:
                table["force_accuracy"] = self.force_accuracy
            elif self.mesher == "refined":
                table["size_near_m"] = self.size_near_m
            return table
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
            default filled in), ``{"steps": n}`` for a record, ``max_depth_m``, ``steps``
            and ``spacing`` for a quasi-static one spaced by the contact radius
            (:func:`warptissue.loading.quasi_static_depths`); empty otherwise.
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
        if self.kind == "quasi_static":  # spaced by the contact radius: the keys that did it
            return dict(self.settings) if self.settings else {"depths_m": list(self.depths_m)}
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
        base: ``"fixed"`` (all displacement of the base z = 0 is zero), ``"sliding"``
            (only z is held; the base slides freely in x and y; a mesh specimen's support
            has its normal held: exactly where it is flat on a plane x, y or z = const, by a
            frictionless bed where it is tilted or curved) or
            ``"foundation"`` (the base, or a mesh specimen's support, rests on the springs of
            ``foundation``); a mesh specimen's support.
        support: A mesh specimen's support: a node set of its file, ``"opposite"`` (the
            surface farther than half the body's depth below the site), or
            ``{"box": [[xmin, ymin, zmin], [xmax, ymax, zmax]]}`` (the nodes inside the box,
            m), or ``{"half_space": [[x, y, z], [nx, ny, nz]]}`` (the nodes on the side of
            the plane through the point, m, that the normal points to); None for a block or
            a disc (their base z = 0).
        foundation: The elastic foundation of ``base = "foundation"``
            (``foundation_Pa_per_m`` and ``foundation_tangential_Pa_per_m``); None otherwise.
    """

    base: str
    support: str | dict[str, Any] | None = None
    foundation: Foundation | None = None

    def to_dict(self) -> dict[str, Any]:
        """The ``[boundary]`` table."""
        table: dict[str, Any] = {"base": self.base}
        if self.support is not None:
            table["support"] = self.support
        if self.foundation is not None:
            table["foundation_Pa_per_m"] = float(self.foundation.normal_Pa_per_m)
            table["foundation_tangential_Pa_per_m"] = float(self.foundation.tangential_Pa_per_m)
        return table


@dataclass(frozen=True)
class Solver:
    """Solver settings: the ``[solver]`` table.

    The table is flat: ``device``, ``formulation``, ``penalty_factor``,
    ``contact_integration`` and the keys of
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
        contact_integration: How a rigid indenter's contact is discretized: ``"nodes"``
            (node-to-surface penalty, the default) or ``"surface"`` (integrated at
            quadrature points of the surface's triangles,
            :mod:`warptissue.fem.surface_contact`); unused by a sharp flat punch.
    """

    device: str
    formulation: str
    options: NewtonOptions
    penalty_factor: float
    contact_integration: str = "nodes"

    def to_dict(self) -> dict[str, Any]:
        """The ``[solver]`` table (flat: device, formulation, penalty factor, then the Newton
        options)."""
        return {
            "device": self.device,
            "formulation": self.formulation,
            "penalty_factor": self.penalty_factor,
            "contact_integration": self.contact_integration,
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
        site_m: ``[indenter] site_m``, where a mesh specimen is indented (snapped to its
            surface), (3,), m; None for a block or a disc (the top centre).
        direction: ``[indenter] direction``, the probe's direction into the body (3,); None:
            the inward normal over the probe's footprint (a mesh specimen) or -z.
        edge: ``[indenter] edge``, a wedge's edge direction on a mesh specimen (3,; its part
            perpendicular to the direction); None: the frame's default (y for a probe
            along -z).
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
    site_m: tuple[float, ...] | None = None
    direction: tuple[float, ...] | None = None
    edge: tuple[float, ...] | None = None

    def probe_of(
        self, record: DataRecord
    ) -> tuple[Indenter, tuple[float, ...] | None, tuple[float, ...] | None]:
        """A record's probe: ``(indenter, site_m, direction)``, the record's own where it
        gives them, else the study's (a record's own site comes with its own direction, or
        the inward normal there: not the study's)."""
        indenter = record.indenter if record.indenter is not None else self.indenter
        if record.site_m is not None:
            return indenter, record.site_m, record.direction
        direction = record.direction if record.direction is not None else self.direction
        return indenter, self.site_m, direction

    @property
    def deepest_depth_m(self) -> float:
        """The deepest depth the study asks for, m: its protocol's and its records'."""
        return deepest_depth_m(self.protocol, self.data)

    @property
    def mesh_probe_radius_m(self) -> float:
        """The radius of its mesh's refined zone under the probe, m
        (:func:`warptissue.study.mesh_probe_radius` at :attr:`deepest_depth_m`)."""
        return mesh_probe_radius(
            self.indenter, self.specimen.half_size_m, depth_m=self.deepest_depth_m
        )

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
            "indenter": {
                **self.indenter.to_dict(),
                **({} if self.site_m is None else {"site_m": list(self.site_m)}),
                **({} if self.direction is None else {"direction": list(self.direction)}),
                **({} if self.edge is None else {"edge": list(self.edge)}),
            },
            "protocol": self.protocol.to_dict(relative_to=relative_to),
            "material": dict(self.material.to_dict()),
            "boundary": self.boundary.to_dict(),
            "solver": self.solver.to_dict(),
        }
        if self.specimen.mesh_path is not None and relative_to is not None:
            record["specimen"]["mesh"] = os.path.relpath(self.specimen.mesh_path, relative_to)
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
        site_m: Where a mesh specimen was indented for this record (3,), m; None: the
            study's ``[indenter] site_m``. Records of several sites are fitted jointly.
        direction: The probe's direction into the body for this record (3,); None: the
            study's where the record has no site of its own, else the inward normal over
            the probe's footprint at the record's site.
        indenter: The probe of this record; None: the study's ``[indenter]``.
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
    site_m: tuple[float, ...] | None = None
    direction: tuple[float, ...] | None = None
    indenter: Indenter | None = None

    @property
    def placed(self) -> bool:
        """Whether the record has a probe of its own (a site, a direction or an indenter)."""
        return not (self.site_m is None and self.direction is None and self.indenter is None)

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
        for key in ("site_m", "direction"):
            if getattr(self, key) is not None:
                table[key] = list(getattr(self, key))
        if self.indenter is not None:
            table["indenter"] = self.indenter.to_dict()
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
        bulk_modulus: ``"fixed"``: the bulk modulus K (not a fit parameter of the
            hyperelastic models) stays at its ``[material]`` value, so K/mu0 changes as the
            shear moduli are fitted; ``"follows_shear"``: K = (K/mu0 of ``[material]``) mu0
            at every trial point, so a nearly incompressible material stays as nearly
            incompressible (:data:`BULK_MODULUS_RULES`).
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
    bulk_modulus: str = "fixed"

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
        if self.bulk_modulus != "fixed":
            table["bulk_modulus"] = self.bulk_modulus
        if self.relative_floor_N is not None:
            table["relative_floor_N"] = self.relative_floor_N
        if self.stop_r_squared is not None:
            table["stop_r_squared"] = self.stop_r_squared
        if self.start:
            table["start"] = dict(self.start)
        if self.bounds:
            table["bounds"] = {k: list(v) for k, v in self.bounds.items()}
        return table
