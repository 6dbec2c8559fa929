"""An indentation problem: the specimen, its material, the probe and the supports, and the
boundary conditions and reaction weights they make.

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

The reaction force (:meth:`IndentationProblem.reaction_weights`): of a flat punch, the sum of
the probe-direction components of the internal force over the punch nodes; under a sphere or a
plate, the base's; times the symmetry factor (2 per symmetry plane) in both cases.
:mod:`warptissue.fem.indentation` solves the problem.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from warptissue.errors import InputError
from warptissue.fem.assembly import FORMULATIONS
from warptissue.fem.contact import DEFAULT_PENALTY_FACTOR, ContactSurface, RigidContact
from warptissue.fem.newton import DirichletConditions
from warptissue.fem.probe import DOWN, ProbeFrame, footprint_normal, probe_frame, snap_to_surface
from warptissue.fem.support import Foundation, SupportSprings, support_edge_m
from warptissue.indenter import SIMULATED_KINDS, Indenter
from warptissue.materials import Material
from warptissue.mesh import TetMesh

__all__ = ["BASES", "IndentationProblem", "plane_axis"]

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
