"""Flat-punch indentation: boundary conditions, the load path and the reaction force.

Coordinates (CONVENTIONS.md): the punch is centred on x = y = 0 on the top surface and moves
in -z; the base is z = 0. Quarter models keep x >= 0, y >= 0 with symmetry planes
"symmetry_x" (x = 0) and "symmetry_y" (y = 0).

- Bonded punch (as in the needle-indentation study): every node of the punch surface with
  r <= a gets ``(ux, uy, uz) = (0, 0, -depth)``.
- Frictionless punch: only ``uz = -depth`` on those nodes.
- Symmetry planes: the normal displacement component is zero on each named node set.
- Base ``"fixed"``: all components zero on "bottom"; ``"sliding"``: the normal component zero
  on "bottom" (``uz`` on a block's base) where it lies flat on a plane x, y or z = const, plus
  pins that remove the in-plane rigid motions the other conditions leave free; a sliding
  support that is not flat on an axis plane (tilted, curved) rests on a frictionless bed of
  stiff normal springs with pin springs (:meth:`warptissue.fem.support.SupportSprings.
  sliding_bed`); ``"foundation"``: "bottom" rests on an elastic foundation (springs per unit area,
  :mod:`warptissue.fem.support`), no node held.

- Sphere and plate (rigid indenters, :mod:`warptissue.fem.contact`): no node is prescribed
  under them; a frictionless penalty pushes the surface nodes out of the indenter, whose depth
  is the load.

The reaction force of a flat punch is the sum of the z-components of the internal force over
the punch nodes, times the symmetry factor (2 per symmetry plane), positive when the punch
pushes in. Under a sphere or a plate it is the base's: the sum of the z internal forces of the
"bottom" nodes times the symmetry factor, which equals the contact force at equilibrium (the
result reports both); as it is a reaction of prescribed dofs, the exact sensitivities
(:mod:`warptissue.fem.newton.sensitivity`) hold unchanged: the penalty's tangent enters through
``K``, and its one dependence on the material (``k`` follows ``mu0``) through ``dR/dtheta``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from warptissue.errors import ConvergenceError, InputError
from warptissue.fem.assembly import FORMULATIONS, Assembler, von_mises
from warptissue.fem.contact import (
    DEFAULT_PENALTY_FACTOR,
    ContactState,
    ContactSurface,
    RigidContact,
)
from warptissue.fem.newton import (
    DirichletConditions,
    ForceSensitivity,
    NewtonOptions,
    QuasistaticResult,
    SolveInterrupted,
    solve_quasistatic,
    solve_quasistatic_batch,
)
from warptissue.fem.newton.path import check_packed_assembler
from warptissue.fem.newton.sensitivity import check_sensitivity_names
from warptissue.fem.packing import PackedMeshes, pack_meshes
from warptissue.fem.probe import DOWN, ProbeFrame, footprint_normal, probe_frame, snap_to_surface
from warptissue.fem.support import Foundation, SupportSprings, support_edge_m
from warptissue.fem.timing import NewtonTimings
from warptissue.indenter import SIMULATED_KINDS, Indenter
from warptissue.materials import Material, Viscoelastic
from warptissue.mesh import TetMesh

__all__ = [
    "IndentationProblem",
    "IndentationResult",
    "batch_assembler",
    "simulate_indentation",
    "simulate_indentation_batch",
]

BASES = ("fixed", "sliding", "foundation")


def plane_axis(mesh: TetMesh, name: str, *, key: str = "symmetry_planes") -> int:
    """The axis normal to a planar node set (the coordinate that does not vary on it)."""
    nodes = mesh.node_set(name)
    what = "symmetry node set" if key == "symmetry_planes" else "the sliding support"
    if nodes.size == 0:
        raise InputError(f"{what} {name!r} is empty", key=key)
    points = mesh.points[nodes]
    spread = np.ptp(points, axis=0)
    size = float(np.ptp(mesh.points, axis=0).max())
    axis = int(np.argmin(spread))
    if spread[axis] > 1e-9 * size:
        if key == "symmetry_planes":
            raise InputError(f"{what} {name!r} is not an axis-aligned plane", key=key)
        raise InputError(
            f"{what} is not flat on a plane x, y or z = const (it spans "
            f"{spread[axis]:.3g} m along {'xyz'[axis]}, its thinnest extent): a sliding base "
            'holds the normal of one plane; hold it "fixed" or set it on a "foundation"',
            key=key,
            value="sliding",
        )
    return axis


@dataclass(frozen=True)
class IndentationProblem:
    """A specimen mesh, its material, a flat punch and the supports.

    Args:
        mesh: TET10 (``formulation="mixed"``) or TET4/TET10 (``"displacement"``), metres, with
            node sets for the punch surface, "bottom" and the symmetry planes.
        material: A :mod:`warptissue.materials` material.
        indenter: The probe, a :class:`warptissue.indenter.Indenter` of kind ``"flat_punch"``
            on the axis (``x_m = y_m = 0``); its ``contact`` sets the conditions under it.
        base: ``"fixed"``, ``"sliding"`` (the normal of "bottom" held: exactly where it is
            flat on an axis plane, else by a frictionless bed) or ``"foundation"``
            ("bottom" on the springs of ``foundation``).
        symmetry_planes: Node sets with zero normal displacement; each doubles the force.
        formulation: ``"mixed"`` (locking free, TET10) or ``"displacement"``.
        surface: Node set of the indented surface; under a rigid indenter its boundary
            triangles carry the contact area and pressure
            (:class:`warptissue.fem.contact.ContactSurface`: a set holding none is refused).
        penalty_factor: ``beta`` of the contact penalty ``k = beta mu0 h`` of a sphere or a
            plate (:mod:`warptissue.fem.contact`; unused by a flat punch).
        contact_integration: ``"nodes"`` (node-to-surface penalty) or ``"surface"`` (at
            quadrature points of the triangles, :mod:`warptissue.fem.surface_contact`).
        site_m: Where the probe meets the specimen, (3,), m: snapped to the nearest point of
            ``surface``'s boundary triangles (:func:`warptissue.fem.probe.snap_to_surface`).
            None: ``(x_m, y_m)`` of the indenter on the top of ``surface`` (today's probe on
            the axis) where ``direction`` is given; with neither, the probe is along -z.
        direction: The probe's direction of motion into the body, (3,) (normalised). None:
            -z without a site; with a site, the inward normal averaged over the probe's
            footprint (:func:`warptissue.fem.probe.footprint_normal`). A probe at a site or
            along a direction needs the full specimen (no symmetry planes); a sharp
            frictionless punch only goes along -z (its one prescribed component), and a
            direction that points out of the body is refused.
        edge: A wedge's edge direction, (3,) (its part perpendicular to ``direction``);
            None: y (:func:`warptissue.fem.probe.probe_frame`).
        site_tolerance_m: How far ``site_m`` may lie from the surface, m; None: 1 % of the
            mesh's largest extent.
        foundation: The elastic foundation of ``base="foundation"``
            (:class:`warptissue.fem.support.Foundation`); None otherwise.
        sliding_bed_Pa_per_m: The normal stiffness per unit area of the frictionless bed
            of a sliding support that is not flat on an axis plane, Pa/m; None: set on
            construction to ``penalty_factor mu0 / h`` (the rigid contact's penalty, ``h`` the
            support's mean edge) of this problem's material, which a copy with another
            material (``dataclasses.replace``, as a fit makes its trial problems) keeps: the
            bed stays one as the parameters move, and the sensitivities exact.
    """

    mesh: TetMesh
    material: Material
    indenter: Indenter
    base: str = field(default="fixed", kw_only=True)
    symmetry_planes: tuple[str, ...] = field(default=("symmetry_x", "symmetry_y"), kw_only=True)
    formulation: str = field(default="mixed", kw_only=True)
    surface: str = field(default="top", kw_only=True)
    penalty_factor: float = field(default=DEFAULT_PENALTY_FACTOR, kw_only=True)
    contact_integration: str = field(default="nodes", kw_only=True)
    site_m: Sequence[float] | None = field(default=None, kw_only=True)
    direction: Sequence[float] | None = field(default=None, kw_only=True)
    edge: Sequence[float] | None = field(default=None, kw_only=True)
    site_tolerance_m: float | None = field(default=None, kw_only=True)
    foundation: Foundation | None = field(default=None, kw_only=True)
    sliding_bed_Pa_per_m: float | None = field(default=None, kw_only=True)

    def __post_init__(self) -> None:
        if not isinstance(self.indenter, Indenter):
            raise InputError(
                "the indenter must be a warptissue.indenter.Indenter",
                key="indenter",
                value=type(self.indenter).__name__,
            )
        if self.indenter.kind not in SIMULATED_KINDS:
            raise InputError(
                f"the finite elements simulate only {', '.join(map(repr, SIMULATED_KINDS))} "
                "indenters",
                key="kind",
                value=self.indenter.kind,
            )
        off_axis = self.indenter.x_m != 0.0 or self.indenter.y_m != 0.0
        if off_axis and (self.indenter.kind == "flat_punch" or self.symmetry_planes):
            raise InputError(
                "the finite elements need the punch on the axis x = y = 0"
                + (" (a symmetry model)" if self.indenter.kind != "flat_punch" else ""),
                key="x_m" if self.indenter.x_m != 0.0 else "y_m",
                value=self.indenter.x_m if self.indenter.x_m != 0.0 else self.indenter.y_m,
            )
        if self.base not in BASES:
            raise InputError(f"base must be one of {BASES}", key="base", value=self.base)
        if (self.base == "foundation") != (self.foundation is not None):
            raise InputError(
                'base "foundation" takes a foundation (warptissue.fem.support.Foundation), '
                "and only it",
                key="foundation",
                value=self.base,
            )
        bed = self.sliding_bed_Pa_per_m
        number = isinstance(bed, int | float) and not isinstance(bed, bool)
        if bed is not None and not (number and math.isfinite(bed) and bed > 0):
            raise InputError(
                "the sliding bed's stiffness must be a positive number of Pa/m",
                key="sliding_bed_Pa_per_m",
                value=bed,
            )
        if self.foundation is not None and not isinstance(self.foundation, Foundation):
            raise InputError(
                "the foundation must be a warptissue.fem.support.Foundation",
                key="foundation",
                value=type(self.foundation).__name__,
            )
        if self.formulation not in FORMULATIONS:
            raise InputError(
                f"formulation must be one of {FORMULATIONS}",
                key="formulation",
                value=self.formulation,
            )
        if self.formulation == "mixed" and self.mesh.nodes_per_tet != 10:
            raise InputError(
                "formulation 'mixed' needs a TET10 mesh (use warptissue.mesh.to_tet10 or "
                "element='TET10'); 'displacement' accepts TET4 but locks when nearly "
                "incompressible",
                key="formulation",
                value=self.formulation,
            )
        object.__setattr__(self, "symmetry_planes", tuple(self.symmetry_planes))
        for name in (self.surface, "bottom", *self.symmetry_planes):
            if name not in self.mesh.node_sets:
                raise InputError(
                    f"the mesh has no node set {name!r} (it has {sorted(self.mesh.node_sets)})",
                    key="mesh",
                )
        for key in ("site_m", "direction", "edge"):
            if getattr(self, key) is not None:
                object.__setattr__(self, key, tuple(float(v) for v in np.ravel(getattr(self, key))))
        object.__setattr__(self, "_frame", self._placed_frame())
        if self.on_sliding_bed and self.sliding_bed_Pa_per_m is None:
            # Fixed from this material: a copy with another one (a fit's) keeps the bed.
            object.__setattr__(self, "sliding_bed_Pa_per_m", self.sliding_bed_stiffness())
        if self.base == "foundation" or self.on_sliding_bed:
            self.support_springs()  # refuses a "bottom" that holds no boundary triangle
        if self.is_contact:
            self.rigid_contact()  # refuses a bad penalty factor or a sphere over no node
            # The contact outputs need the surface's triangles: refused here, not after a run.
            ContactSurface.for_mesh(self.mesh, surface=self.surface)
            return
        if self.punch_nodes.size == 0:
            axis = "the axis x = y = 0" if self.frame is None else "the probe's axis through "
            axis += "" if self.frame is None else f"the site {self.frame.origin_m.tolist()}"
            raise InputError(
                f"no node of {self.surface!r} lies within the punch radius "
                f"{self.indenter.radius_m} m of {axis}",
                key="radius_m",
            )
        if self.indenter.z_m is not None and self.frame is None:
            top = float(self.mesh.points[self.punch_nodes, 2].max())
            if abs(self.indenter.z_m - top) > 1e-9 * float(np.ptp(self.mesh.points[:, 2])):
                raise InputError(
                    f"the punch's contact point z_m is off the indented surface (z = {top:g} m)",
                    key="z_m",
                    value=self.indenter.z_m,
                )

    def _placed_frame(self) -> ProbeFrame | None:
        """The probe's frame where ``site_m`` or ``direction`` is given (else None)."""
        if self.site_m is None and self.direction is None and self.edge is None:
            return None
        probe = self.indenter
        if self.symmetry_planes:
            raise InputError(
                "a probe at a site or along a direction needs the full specimen "
                "(symmetry_planes=())",
                key="site_m" if self.site_m is not None else "direction",
            )
        if self.site_m is not None and (probe.x_m or probe.y_m or probe.z_m is not None):
            raise InputError(
                "give the probe's position as site_m, not also the indenter's x_m, y_m, z_m",
                key="site_m",
                value=list(self.site_m),
            )
        mesh = self.mesh
        site = self.site_m
        if site is None:
            top = float(mesh.points[mesh.node_set(self.surface), 2].max())
            site = (probe.x_m, probe.y_m, top if probe.z_m is None else probe.z_m)
        tolerance = self.site_tolerance_m
        if tolerance is None:
            tolerance = 0.01 * float(np.ptp(mesh.points, axis=0).max())
        site = snap_to_surface(mesh, site, tolerance_m=tolerance, surface=self.surface)
        inward = footprint_normal(mesh, site, radius_m=probe.radius_m, surface=self.surface)
        direction = inward if self.direction is None else self.direction
        frame = probe_frame(origin_m=site, direction=direction, edge=self.edge)
        cosine = float(np.dot(frame.direction, inward))
        if cosine <= 0.0:
            angle = np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))
            raise InputError(
                f"the direction points out of the body ({angle:.1f} degrees from the inward "
                f"normal {np.round(inward, 6).tolist()} at the site)",
                key="direction",
                value=list(self.direction),
            )
        if not self.is_contact and probe.contact == "frictionless" and not frame.is_default:
            raise InputError(
                "a sharp frictionless punch prescribes z only: it goes along -z (a bonded "
                "punch or a rounded edge goes along any direction)",
                key="contact",
                value=probe.contact,
            )
        return frame

    @property
    def frame(self) -> ProbeFrame | None:
        """The probe's frame at its site (None: along -z through ``(x_m, y_m)``, as before
        sites and directions)."""
        return self._frame  # type: ignore[attr-defined]

    @property
    def probe_direction(self) -> np.ndarray:
        """The unit direction the probe moves in, (3,)."""
        return np.array(DOWN) if self.frame is None else self.frame.direction

    @property
    def symmetry_factor(self) -> int:
        """2 per symmetry plane: 4 for a quarter model."""
        return 2 ** len(self.symmetry_planes)

    @property
    def is_contact(self) -> bool:
        """Whether the indenter touches through contact (sphere, plate, wedge, rounded punch),
        not prescribed nodes."""
        return self.indenter.is_rigid_contact

    def rigid_contact(self) -> RigidContact | None:
        """The frictionless penalty contact of a sphere or a plate (None for a flat punch)."""
        if not self.is_contact:
            return None
        return RigidContact.for_mesh(
            self.mesh,
            self.indenter,
            self.material.initial_shear_modulus_Pa,
            surface=self.surface,
            penalty_factor=self.penalty_factor,
            frame=self.frame,
            integration=self.contact_integration,
        )

    @property
    def on_sliding_bed(self) -> bool:
        """Whether a sliding "bottom" that is not flat on an axis plane rests on a bed."""
        if self.base != "sliding":
            return False
        try:
            plane_axis(self.mesh, "bottom", key="base")
        except InputError:
            return True
        return False

    def sliding_bed_stiffness(self) -> float:
        """The normal stiffness of the sliding bed, Pa/m: ``sliding_bed_Pa_per_m``, or
        ``penalty_factor mu0 / h`` of this problem's material and support."""
        if self.sliding_bed_Pa_per_m is not None:
            return float(self.sliding_bed_Pa_per_m)
        edge = support_edge_m(self.mesh, "bottom")
        return self.penalty_factor * self.material.initial_shear_modulus_Pa / edge

    def support_springs(self) -> SupportSprings | None:
        """The springs of the elastic foundation, or of the frictionless bed of a sliding
        support that is not flat on an axis plane, under "bottom" (None on another base)."""
        if self.foundation is None and not self.on_sliding_bed:
            return None
        try:
            if self.foundation is None:
                return SupportSprings.sliding_bed(
                    self.mesh, surface="bottom", normal_Pa_per_m=self.sliding_bed_stiffness()
                )
            return SupportSprings.foundation(self.mesh, self.foundation, surface="bottom")
        except InputError as exc:
            raise InputError(
                "a foundation or a sliding bed needs the support's boundary triangles: "
                + exc.message,
                key="base",
                value=self.base,
            ) from None

    def reaction_weights(self) -> np.ndarray:
        """Weights (N, 3) of the internal forces summed into the probe force: -factor on the
        punch nodes' z (flat punch), +factor on the "bottom" nodes' z (sphere, plate)."""
        weights = np.zeros((self.mesh.node_count, 3))
        factor = float(self.symmetry_factor)
        if self.frame is not None:  # along the direction
            if self.is_contact:
                weights[self.mesh.node_set("bottom")] = -factor * self.frame.direction
            else:
                weights[self.punch_nodes] = factor * self.frame.direction
            return weights
        if self.is_contact:
            weights[self.mesh.node_set("bottom"), 2] = factor
        else:
            weights[self.punch_nodes, 2] = -factor
        return weights

    @property
    def punch_nodes(self) -> np.ndarray:
        """Nodes of the punch surface with r <= radius (1e-9 relative tolerance); none under a
        sphere or a plate (no node is prescribed there). In a probe frame r is measured
        perpendicular to the direction, and only nodes within the radius of the site along
        it count (not the far side of a body)."""
        if self.is_contact:
            return np.zeros(0, dtype=np.int64)
        nodes = self.mesh.node_set(self.surface)
        xy = self.mesh.points[nodes, :2]
        radius = self.indenter.radius_m
        if self.frame is not None:
            local = self.frame.to_local(self.mesh.points[nodes])
            nodes = nodes[np.abs(local[:, 2]) <= radius]
            xy = local[np.abs(local[:, 2]) <= radius, :2]
        inside = np.einsum("ij,ij->i", xy, xy) <= (radius * (1.0 + 1e-9)) ** 2
        return nodes[inside].astype(np.int64)

    def dirichlet_conditions(self) -> DirichletConditions:
        """Prescribed dofs with ``u = depth * values_per_load`` (load = depth in metres)."""
        parts = []
        punch = self.punch_nodes
        punch_components = (2,) if self.indenter.contact == "frictionless" else (0, 1, 2)
        along = self.probe_direction
        for comp in punch_components:
            parts.append(_fixed(punch, comp, float(along[comp])))
        planes = {}
        for name in self.symmetry_planes:
            axis = plane_axis(self.mesh, name)
            planes[axis] = name
            parts.append(_fixed(self.mesh.node_set(name), axis, 0.0))
        bottom = self.mesh.node_set("bottom").astype(np.int64)
        if self.base == "foundation" or self.on_sliding_bed:
            return DirichletConditions.combine(*parts)  # the springs hold "bottom"
        normal = 2 if self.base == "fixed" else plane_axis(self.mesh, "bottom", key="base")
        base_components = (0, 1, 2) if self.base == "fixed" else (normal,)
        for comp in base_components:
            parts.append(_fixed(bottom, comp, 0.0))
        if self.base == "sliding" and (self.indenter.contact == "frictionless" or self.is_contact):
            parts.extend(self._rigid_body_pins(bottom, planes, normal))
        return DirichletConditions.combine(*parts)

    def _rigid_body_pins(self, bottom: np.ndarray, planes: dict[int, str], normal: int) -> list:
        """Pins on the base for the in-plane translations and the rotation about its normal
        (axis ``normal``; z for a block's base)."""
        a, b = (axis for axis in range(3) if axis != normal)
        points = self.mesh.points[bottom][:, [a, b]]
        centre = bottom[int(np.argmin(np.einsum("ij,ij->i", points, points)))]
        pins = [_fixed(np.array([centre]), axis, 0.0) for axis in (a, b) if axis not in planes]
        if not planes:
            far = bottom[int(np.argmax(points[:, 0]))]
            pins.append(_fixed(np.array([far]), b, 0.0))
        return pins


def _fixed(nodes: np.ndarray, component: int, value: float) -> DirichletConditions:
    nodes = np.asarray(nodes, dtype=np.int64)
    return DirichletConditions(nodes, np.full(len(nodes), component), np.full(len(nodes), value))


@dataclass
class IndentationResult:
    """Force-depth curve and fields of a flat-punch indentation.

    Attributes:
        depths_m: Depths reached, shape (S,), m (a prefix of the requested ones).
        reaction_force_N: Full punch force (symmetry factor applied, positive pushing in), (S,).
        newton_iterations: Newton iterations per depth (all substeps), (S,).
        linear_iterations: Linear-solver iterations per depth (1 per direct solve), (S,).
        local_iterations: Local Newton iterations of the nonlinear elimination per depth, (S,).
        displacement_m: Nodal displacements per depth, (S, N, 3).
        cauchy_stress_Pa: Per-tet Cauchy stress at the last depth (xx, yy, zz, yz, xz, xy),
            (M, 6).
        von_mises_Pa: Per-tet von Mises stress at the last depth, (M,).
        completed: Whether every requested depth converged.
        message: What happened.
        cutbacks: Number of increment halvings used.
        formulation, element_type, symmetry_factor, linear_solver: How it was solved.
        sensitivity_names: The parameters of ``force_sensitivity_N_per_unit``'s columns.
        force_sensitivity_N_per_unit: Exact ``dF/dtheta`` of the punch force at each depth,
            (S, n), N per unit of each parameter (N/Pa for ``C10_Pa``, N for ``alpha1``);
            n = 0 unless ``sensitivities`` were asked for (docs/fe.md "Sensitivities").
        times_s: The time of each depth of a timed run, s; else the step number 1..S, (S,).
        contact_force_N: Under a rigid indenter: the contact force on the body along the
            probe's direction summed over the nodes, times the symmetry factor, positive
            pushing in, (S,) (equal to ``reaction_force_N`` at equilibrium); empty for a
            sharp flat punch.
        tangential_force_N: Under a rigid indenter: the magnitude of the contact force's
            part perpendicular to the direction, (S,), N (a probe off the surface normal, or
            on a surface that is not symmetric about it; 0 in a symmetry model, whose
            symmetry cancels it); empty for a sharp flat punch.
        max_penetration_m: Under a sphere or a plate: the largest penetration of a node into
            the indenter at each depth, (S,), m; empty for a flat punch.
        contact_area_m2: Under a rigid indenter: the area of the surface in contact at each
            depth, of the whole specimen (the modelled part's times the symmetry factor),
            current configuration, (S,), m^2; empty for a sharp flat punch
            (:class:`warptissue.fem.contact.ContactSurface`: the sum of the tributary areas of
            the penetrating nodes, uncertain by a ring of nodes at the contact edge; under
            ``contact_integration="surface"`` the areas of the penetrating quadrature
            points, :attr:`warptissue.fem.contact.ContactState.point_contact_area_m2`).
        mean_contact_pressure_Pa: Under a rigid indenter: ``contact_force_N`` over
            ``contact_area_m2`` at each depth, (S,), Pa (0 where the area is 0; Hertz's is
            ``2 p0 / 3``); empty for a sharp flat punch.
        contact_pressure_Pa: Under a rigid indenter: the contact pressure at every node at
            each depth, (S, N), Pa (zero off the contact; the normal contact force over the
            node's tributary area, :class:`warptissue.fem.contact.ContactSurface`); shape
            (0, N) for a sharp flat punch.
        increments: One record per attempted load increment (``load``, ``converged``,
            ``iterations``, ``local_iterations``, ``reason``; cutbacks and substeps
            included), :attr:`warptissue.fem.QuasistaticResult.history`.
        timings: Where the load path's wall time went, per phase of the Newton iterations
            (:class:`warptissue.fem.NewtonTimings`), when run with ``profile=True``; else
            None.
        linear_solver_statistics: The linear solver's counts over the load path:
            ``factorizations``, ``reused_solves`` (Newton solves by GMRES with earlier
            factors), ``krylov_iterations``, ``failed_reuses``
            (:class:`warptissue.fem.QuasistaticResult`).
    """

    depths_m: np.ndarray
    reaction_force_N: np.ndarray
    newton_iterations: np.ndarray
    linear_iterations: np.ndarray
    local_iterations: np.ndarray
    displacement_m: np.ndarray
    cauchy_stress_Pa: np.ndarray
    von_mises_Pa: np.ndarray
    completed: bool
    message: str
    cutbacks: int = 0
    formulation: str = "mixed"
    element_type: str = "TET10"
    symmetry_factor: int = 4
    linear_solver: str = "auto"
    sensitivity_names: tuple[str, ...] = ()
    force_sensitivity_N_per_unit: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    times_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    contact_force_N: np.ndarray = field(default_factory=lambda: np.zeros(0))
    max_penetration_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    contact_area_m2: np.ndarray = field(default_factory=lambda: np.zeros(0))
    contact_pressure_Pa: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    tangential_force_N: np.ndarray = field(default_factory=lambda: np.zeros(0))
    mean_contact_pressure_Pa: np.ndarray = field(default_factory=lambda: np.zeros(0))
    increments: list[dict] = field(default_factory=list)
    timings: NewtonTimings | None = None
    linear_solver_statistics: dict[str, int] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary: the curve, iteration counts and status (fields omitted)."""
        return {
            "depths_m": self.depths_m.tolist(),
            "times_s": self.times_s.tolist(),
            "reaction_force_N": self.reaction_force_N.tolist(),
            "newton_iterations": self.newton_iterations.tolist(),
            "linear_iterations": self.linear_iterations.tolist(),
            "local_iterations": self.local_iterations.tolist(),
            "completed": bool(self.completed),
            "message": self.message,
            "cutbacks": int(self.cutbacks),
            "formulation": self.formulation,
            "element_type": self.element_type,
            "symmetry_factor": int(self.symmetry_factor),
            "linear_solver": self.linear_solver,
            "max_von_mises_Pa": float(self.von_mises_Pa.max()) if self.von_mises_Pa.size else None,
            **(
                {
                    "sensitivity_names": list(self.sensitivity_names),
                    "force_sensitivity_N_per_unit": self.force_sensitivity_N_per_unit.tolist(),
                }
                if self.sensitivity_names
                else {}
            ),
            **(
                {
                    "contact_force_N": self.contact_force_N.tolist(),
                    "max_penetration_m": self.max_penetration_m.tolist(),
                    "contact_area_m2": self.contact_area_m2.tolist(),
                    "mean_contact_pressure_Pa": self.mean_contact_pressure_Pa.tolist(),
                    "max_contact_pressure_Pa": (
                        self.contact_pressure_Pa.max(axis=1).tolist()
                        if self.contact_pressure_Pa.size
                        else []
                    ),
                }
                if self.contact_force_N.size
                else {}
            ),
            **({} if self.timings is None else {"newton_profile": self.timings.to_dict()}),
            "linear_solver_statistics": dict(self.linear_solver_statistics),
        }


def simulate_indentation(
    problem: IndentationProblem,
    depths_m: np.ndarray,
    *,
    device: str | None = None,
    progress: bool = True,
    options: NewtonOptions | None = None,
    strict: bool = False,
    assembler: Assembler | None = None,
    sensitivities: Sequence[str] = (),
    sensitivity_factorization: str = "reuse",
    times_s: np.ndarray | None = None,
    profile: bool = False,
) -> IndentationResult:
    """Push the punch to each depth in turn and record the reaction force.

    Args:
        problem: The :class:`IndentationProblem`.
        depths_m: Depths, shape (S,), m: increasing and positive for a quasi-static run; with
            ``times_s``, any depths >= 0 (a loading history may hold and unload).
        device: Warp device (``"cpu"``, ``"cuda:0"``); None for Warp's default.
        progress: Show a tqdm progress bar over the depths.
        options: The Newton solver's settings (linear solver, tolerance, iterations,
            cutbacks, predictor, nonlinear elimination, damping), a
            :class:`warptissue.fem.NewtonOptions`; None: the defaults. See
            :func:`warptissue.fem.solve_quasistatic`.
        strict: Raise :class:`ConvergenceError` (carrying the partial result) instead of
            returning an incomplete one.
        assembler: Reuse an :class:`Assembler` built for this mesh, material and formulation
            (for repeated solves in a fit); built when None.
        sensitivities: Material parameters (keys of ``problem.material.to_dict()``:
            ``C10_Pa``, ``mu1_Pa``, ``alpha1``, ``bulk_modulus_Pa``, ...) to differentiate the
            force by, exactly, at each depth: ``result.force_sensitivity_N_per_unit``.
        sensitivity_factorization: ``"reuse"`` (Newton's last factors with iterative
            refinement; no new factorization) or ``"refactorize"`` (one factorization of the
            converged tangent per depth); see :mod:`warptissue.fem.newton.sensitivity`.
        times_s: The time of each depth, shape (S,), s, strictly increasing; the probe
            starts at depth 0 at t = 0 and its depth is linear in time between steps. Needed
            by a :class:`warptissue.materials.Viscoelastic` material (its history is carried
            forward in time, :mod:`warptissue.fem.viscous`; so are the sensitivities, Prony
            parameters included); an elastic material gives the same forces as without.
        profile: Time each phase of the Newton iterations into ``result.timings`` (see
            :func:`warptissue.fem.solve_quasistatic` and :mod:`warptissue.fem.timing`).

    Returns:
        An :class:`IndentationResult` (``completed=False`` with a message when the cutbacks ran
        out; the curve up to there is kept).

    Raises:
        SolveInterrupted: Ctrl-C; its ``partial_result`` is the :class:`IndentationResult` of
            the depths that converged before it.
    """
    depths = np.atleast_1d(np.asarray(depths_m, dtype=np.float64))
    if depths.ndim != 1 or depths.size == 0 or not np.all(np.isfinite(depths)):
        raise InputError("depths_m must be a non-empty 1-D sequence of numbers", value=depths_m)
    if times_s is None:
        if np.any(depths <= 0) or np.any(np.diff(depths) <= 0):
            raise InputError(
                "depths_m must be positive and strictly increasing (give times_s for a "
                "loading history that holds or unloads)",
                value=depths.tolist(),
            )
        if isinstance(problem.material, Viscoelastic):
            raise InputError(
                "a viscoelastic material needs the time of each depth (times_s)",
                key="times_s",
            )
    elif np.any(depths < 0):
        raise InputError(
            "depths_m must be >= 0 (the probe stays in contact)", value=depths.tolist()
        )
    mesh = problem.mesh
    if assembler is None:
        assembler = Assembler(
            mesh, problem.material, formulation=problem.formulation, device=device
        )
    elif assembler.node_count != mesh.node_count or assembler.formulation != problem.formulation:
        raise InputError("the assembler was built for another mesh or formulation")
    else:
        assembler.set_material(problem.material)  # also resets a viscous history
    assembler.set_contact(problem.rigid_contact())
    assembler.set_springs(problem.support_springs())
    weights = problem.reaction_weights()
    conditions = problem.dirichlet_conditions()
    names = check_sensitivity_names(sensitivities)
    sensitivity = None
    if names:
        sensitivity = ForceSensitivity(
            assembler, conditions, names, weights, factorization=sensitivity_factorization
        )
    try:
        path = solve_quasistatic(
            assembler,
            conditions,
            depths,
            reaction_weights=weights,
            options=options,
            progress=progress,
            progress_label="indentation depths",
            load_name="depth (m)",
            sensitivity=sensitivity,
            times_s=times_s,
            profile=profile,
        )
    except SolveInterrupted as interrupted:
        partial = _finished(problem, assembler, interrupted.partial_result, names)
        raise SolveInterrupted(interrupted.message, partial_result=partial) from interrupted
    result = _finished(problem, assembler, path, names)
    if strict and not result.completed:
        raise ConvergenceError(result.message, partial_result=result)
    return result


def _last_stress(assembler: Assembler, path: QuasistaticResult) -> np.ndarray:
    """The Cauchy stress (M, 6) at a single run's last converged state ((0, 6) without one)."""
    if not len(path.loads):
        return np.zeros((0, 6))
    return assembler.cauchy_stress(path.displacement_m[-1])


def _contact_states(assembler: Assembler, path: QuasistaticResult) -> list[ContactState] | None:
    """A single run's rigid contact at each converged depth (None without a contact).

    Leaves the contact at the last depth of ``path``.
    """
    if assembler.contact is None:
        return None
    states = []
    for depth, u in zip(path.loads, path.displacement_m, strict=True):
        assembler.set_load(depth)
        states.append(assembler.contact_state(u))
    return states


def _finished(
    problem: IndentationProblem,
    assembler: Assembler,
    path: QuasistaticResult,
    sensitivity_names: tuple[str, ...],
) -> IndentationResult:
    """The indentation result of a single run's load path (complete or interrupted), with
    the stress and contact states of its last state read from ``assembler``."""
    return _indentation_result(
        problem,
        path,
        sensitivity_names,
        stress_Pa=_last_stress(assembler, path),
        contact_states=_contact_states(assembler, path),
    )


def _indentation_result(
    problem: IndentationProblem,
    path: QuasistaticResult,
    sensitivity_names: tuple[str, ...] = (),
    *,
    stress_Pa: np.ndarray,
    contact_states: Sequence[ContactState] | None = None,
) -> IndentationResult:
    """The indentation result of a load path: the curve, the fields at its last state.

    Args:
        problem: The problem solved.
        path: Its load path, in the problem's own node numbering.
        sensitivity_names: The parameters of ``path.reaction_sensitivity``'s columns.
        stress_Pa: The Cauchy stress (M, 6) at the last converged state ((0, 6) without one).
        contact_states: Under a rigid indenter, the contact at each converged depth, in the
            problem's own node numbering (:meth:`warptissue.fem.Assembler.contact_state`);
            None for a sharp flat punch.
    """
    stress = stress_Pa
    contact_force, penetration, area = np.zeros(0), np.zeros(0), np.zeros(0)
    tangential = np.zeros(0)
    along = problem.probe_direction
    pressure = np.zeros((0, problem.mesh.node_count))
    if contact_states is not None:
        steps = len(path.loads)
        surface = ContactSurface.for_mesh(problem.mesh, surface=problem.surface)
        contact_force, penetration, area = np.empty(steps), np.empty(steps), np.empty(steps)
        tangential = np.zeros(steps)
        pressure = np.empty((steps, problem.mesh.node_count))
        for i, (state, u) in enumerate(zip(contact_states, path.displacement_m, strict=True)):
            total = state.total_force_N
            if problem.frame is None:
                contact_force[i] = -problem.symmetry_factor * total[2]
            else:
                contact_force[i] = problem.symmetry_factor * float(np.dot(total, along))
            if not problem.symmetry_planes:
                tangential[i] = np.linalg.norm(total - np.dot(total, along) * along)
            penetration[i] = state.max_penetration_m
            current = problem.mesh.points + u
            area[i] = problem.symmetry_factor * surface.contact_area_m2(state, current)
            pressure[i] = surface.pressure_Pa(state, current)
    return IndentationResult(
        depths_m=path.loads,
        reaction_force_N=path.reaction,
        newton_iterations=path.newton_iterations,
        linear_iterations=path.linear_iterations,
        local_iterations=path.local_iterations,
        displacement_m=path.displacement_m,
        cauchy_stress_Pa=stress,
        von_mises_Pa=von_mises(stress) if len(stress) else np.zeros(0),
        completed=path.completed,
        message=path.message,
        cutbacks=path.cutbacks,
        formulation=problem.formulation,
        element_type=problem.mesh.element_type,
        symmetry_factor=problem.symmetry_factor,
        linear_solver=path.linear_solver,
        sensitivity_names=sensitivity_names,
        force_sensitivity_N_per_unit=path.reaction_sensitivity,
        times_s=path.times_s,
        contact_force_N=contact_force,
        max_penetration_m=penetration,
        contact_area_m2=area,
        contact_pressure_Pa=pressure,
        tangential_force_N=tangential,
        mean_contact_pressure_Pa=np.divide(
            contact_force, area, out=np.zeros_like(area), where=area > 0.0
        ),
        increments=list(path.history),
        timings=path.timings,
        linear_solver_statistics=path.linear_solver_statistics,
    )


def simulate_indentation_batch(
    problems: Sequence[IndentationProblem],
    depths_m: Sequence[np.ndarray],
    *,
    device: str | None = None,
    options: NewtonOptions | None = None,
    sensitivities: Sequence[str] = (),
    assembler: Assembler | None = None,
    times_s: Sequence[np.ndarray | None] | None = None,
) -> list[IndentationResult]:
    """K indentations solved together on one device, in one Newton loop.

    Args:
        problems: Problems all of one element type and formulation (meshes, materials,
            viscoelastic histories, indenters and their contact conditions may differ:
            bonded or frictionless flat punches, and rigid indenters in contact, each with
            its own penalty stiffness; :mod:`warptissue.fem.contact`).
        depths_m: Each problem's depths, m: positive and strictly increasing, or with its
            times any depths >= 0 (as :func:`simulate_indentation`).
        device: Warp device; None for Warp's default.
        options: The Newton settings (every one applies per problem,
            :func:`warptissue.fem.solve_quasistatic_batch`).
        sensitivities: Material parameters (``C10_Pa``, ``bulk_modulus_Pa``, ...; moduli,
            not Ogden exponents) to differentiate each problem's force by, exactly, at each
            depth: ``result.force_sensitivity_N_per_unit``.
        assembler: An assembler of these problems' meshes, in this order, from
            :func:`batch_assembler`, to reuse across calls that change only the materials
            (a batched fit's trial points); it takes the problems' materials, and the run
            uses its device. None builds one on ``device``.
        times_s: Each problem's times, s (None entries, or None: quasi-static paths); a
            viscoelastic material needs them.

    Returns:
        One :class:`warptissue.fem.IndentationResult` per problem, as
        :func:`warptissue.fem.simulate_indentation` gives it (equal forces to the Newton
        tolerance), with the contact outputs (contact force, penetration, area, pressure)
        of a rigid indenter. Where any problem has a rigid indenter other than a plate,
        every problem's increments take the penalty ramp
        (:func:`warptissue.fem.newton.increment.penalty_ramped_increment`): the path to the
        solution changes, not the converged state.

    Raises:
        InputError: No problem, a problem this batch cannot take (another element type or
            formulation), bad depths or times, or an assembler of other meshes or another
            formulation.
    """
    problems = list(problems)
    if not problems:
        raise InputError("at least one problem is needed", key="problems", value=0)
    if len(depths_m) != len(problems):
        raise InputError(
            f"one depth sequence per problem ({len(problems)})", key="depths_m", value=len(depths_m)
        )
    formulation = problems[0].formulation
    for k, problem in enumerate(problems):
        if problem.formulation != formulation:
            raise InputError(
                f"problem {k}: every problem of a batch has one formulation ({formulation!r})",
                key="formulation",
                value=problem.formulation,
            )
    times_list = [None] * len(problems) if times_s is None else list(times_s)
    if len(times_list) != len(problems):
        raise InputError(
            f"one time sequence per problem ({len(problems)})", key="times_s", value=len(times_list)
        )
    depths = []
    for k, values in enumerate(depths_m):
        path = np.atleast_1d(np.asarray(values, dtype=np.float64))
        timed = times_list[k] is not None
        if (
            path.ndim != 1
            or path.size == 0
            or not np.all(np.isfinite(path))
            or (not timed and (np.any(path <= 0) or np.any(np.diff(path) <= 0)))
            or (timed and np.any(path < 0))
        ):
            raise InputError(
                f"problem {k}: depths_m must be positive and strictly increasing (or >= 0 "
                "with times_s)",
                key="depths_m",
                value=path.tolist(),
            )
        depths.append(path)
    packed = pack_meshes([problem.mesh for problem in problems])
    if assembler is None:
        assembler = _packed_assembler(problems, packed, device)
    else:
        check_packed_assembler(assembler, packed, formulation)
        assembler.set_material([problem.material for problem in problems])
    # Each contact's stiffness follows its problem's material: set on every call.
    assembler.set_contact([problem.rigid_contact() for problem in problems])
    assembler.set_springs([problem.support_springs() for problem in problems])
    paths = solve_quasistatic_batch(
        assembler,
        packed,
        [problem.dirichlet_conditions() for problem in problems],
        depths,
        reaction_weights=[problem.reaction_weights() for problem in problems],
        options=options,
        load_name="depth (m)",
        sensitivities=sensitivities,
        times_s=times_list,
    )
    # Every problem's stress at its last converged state, in one launch over the union.
    last = np.zeros((packed.mesh.node_count, 3))
    for k, path in enumerate(paths):
        if len(path.loads):
            last[packed.nodes(k)] = path.displacement_m[-1]
    stress = assembler.cauchy_stress(last)
    states = _packed_contact_states(assembler, packed, paths)
    results = []
    for k, (problem, path) in enumerate(zip(problems, paths, strict=True)):
        tets = slice(int(packed.tet_offsets[k]), int(packed.tet_offsets[k + 1]))
        results.append(
            _indentation_result(
                problem,
                path,
                tuple(sensitivities),
                stress_Pa=stress[tets] if len(path.loads) else np.zeros((0, 6)),
                contact_states=states[k],
            )
        )
    return results


def _packed_contact_states(
    assembler: Assembler, packed: PackedMeshes, paths: Sequence[QuasistaticResult]
) -> list[list[ContactState] | None]:
    """Each packed problem's rigid contact at each of its converged depths (None for a
    problem without one), in its own node numbering: step i of every problem that reached
    it in one launch (:meth:`warptissue.fem.Assembler.contact_states`)."""
    states: list[list[ContactState] | None] = [
        None if contact is None else [] for contact in assembler.contacts
    ]
    if not assembler.has_contact:
        return states
    for i in range(max(len(path.loads) for path in paths)):
        u = np.zeros((packed.mesh.node_count, 3))
        depths = np.zeros(len(paths))
        for k, path in enumerate(paths):
            if i < len(path.loads):
                u[packed.nodes(k)] = path.displacement_m[i]
                depths[k] = path.loads[i]
        assembler.set_load(depths)
        for k, state in enumerate(assembler.contact_states(u)):
            if state is not None and i < len(paths[k].loads):
                states[k].append(state)
    return states


def batch_assembler(
    problems: Sequence[IndentationProblem], *, device: str | None = None
) -> Assembler:
    """The assembler of K problems' packed meshes, for :func:`simulate_indentation_batch`.

    Building it (element geometry and the sparsity pattern of the union) costs about as much
    as a few Newton iterations; a caller that solves the same meshes with other materials
    (the trial points of batched fits) builds it once and passes it to every call.

    Args:
        problems: The problems, in the order of the calls that will use it.
        device: Warp device; None for Warp's default.

    Returns:
        An :class:`warptissue.fem.Assembler` of the packed meshes, one material per problem.
    """
    problems = list(problems)
    if not problems:
        raise InputError("at least one problem is needed", key="problems", value=0)
    return _packed_assembler(problems, pack_meshes([p.mesh for p in problems]), device)


def _packed_assembler(
    problems: list[IndentationProblem], packed: PackedMeshes, device: str | None
) -> Assembler:
    return Assembler(
        packed.mesh,
        [problem.material for problem in problems],
        formulation=problems[0].formulation,
        device=device,
        element_problem=packed.element_problem,
    )
