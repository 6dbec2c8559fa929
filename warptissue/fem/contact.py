"""Frictionless penalty contact of a rigid indenter with the specimen's surface nodes.

The indenter is an analytic rigid body positioned by the depth (the load of
:func:`warptissue.fem.solve_quasistatic`), its contact point at ``top - depth`` on the axis
``(x_m, y_m)``, or, in a probe frame (:mod:`warptissue.fem.probe`), at
``site + depth * direction`` with the shapes below turned so that -z is the direction and y
the wedge's edge: a sphere of radius ``r``; a plate (the plane ``z = top - depth``, filling the
half-space above); a flat-ended cylinder of radius ``a`` whose edge is rounded with radius
``rho`` (``edge_radius_m``); a wedge along y of opening angle ``2 alpha`` whose tip is rounded
with radius ``rho``. Each candidate node (every node of the indented surface, TET10 mid-edge
nodes included) with signed distance ``g < 0`` to the indenter (penetration) gets the contact
force ``f_c = -k g n`` along the indenter's outward normal ``n``; the residual becomes
``R = f_int - f_c`` and the node's diagonal tangent block gains ``k (n n^T + g dn/dx)`` (the
second term is the turning of the normal over a curved surface). The energy gains
``k g^2 / 2``, so the line search sees one potential. Device code: ``rigid_contact_point``
and ``rigid_contact_kernel`` in ``kernels/contact.py``.

Penalty stiffness per node: ``k = beta mu0 h``, ``mu0`` the material's initial shear modulus
and ``h`` the mean edge length of the elements of the candidate nodes under the indenter
(within its radius of the axis for a sphere or a punch, within the tip radius or one row of
nodes of the line for a wedge, the whole surface for a plate); ``beta``
(:data:`DEFAULT_PENALTY_FACTOR`) was chosen by measurement (docs/fe.md "Contact").

Outputs (:class:`ContactSurface`): the contact area and the contact pressure on the indented
surface's triangles (the boundary faces of the tets whose corners all lie in the surface's
node set; a TET10 face is a 6-node triangle), in the current configuration.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import warp as wp

from warptissue.errors import InputError
from warptissue.fem.packing import per_problem
from warptissue.fem.probe import ProbeFrame, probe_frame
from warptissue.fem.surface_contact import (
    CONTACT_INTEGRATIONS,
    SURFACE_PENALTY_SCALE,
    SurfaceContactArrays,
    SurfaceQuadrature,
    block_ids,
    surface_triangles,
)
from warptissue.indenter import Indenter
from warptissue.kernels import contact as kc
from warptissue.mesh import TetMesh

__all__ = [
    "DEFAULT_PENALTY_FACTOR",
    "ContactState",
    "ContactSurface",
    "RigidContact",
    "RigidContacts",
    "mean_edge_length",
]

DEFAULT_PENALTY_FACTOR = 1000.0
"""``beta`` of the penalty stiffness ``k = beta mu0 h`` (docs/fe.md "Contact": the force is
within 1 % of its stiff-penalty limit and the penetration a small fraction of the depth)."""

_CORNER_EDGES = ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))


def mean_edge_length(mesh: TetMesh, nodes: np.ndarray) -> float:
    """Mean corner-to-corner edge length of the tets holding any of ``nodes``, m."""
    holds = np.zeros(mesh.node_count, dtype=bool)
    holds[np.asarray(nodes, dtype=np.int64)] = True
    tets = mesh.tets[holds[mesh.tets].any(axis=1)]
    if len(tets) == 0:
        raise InputError("no element holds a contact candidate node", key="mesh")
    corners = mesh.points[tets[:, :4]]
    lengths = [np.linalg.norm(corners[:, a] - corners[:, b], axis=1) for a, b in _CORNER_EDGES]
    return float(np.mean(lengths))


@dataclass
class RigidContact:
    """A rigid indenter pressed into a set of nodes through a frictionless penalty.

    Args:
        indenter: A rigid-contact indenter (:attr:`warptissue.indenter.Indenter.is_rigid_contact`).
        nodes: Candidate nodes (the indented surface), (k,) int.
        top_z_m: z of the contact point at depth 0 (the specimen's top), m.
        stiffness_N_per_m: Penalty stiffness per node ``k``, N/m.
        depth_m: Current depth of the indenter below ``top_z_m``, m.
        frame: The probe's frame (:class:`warptissue.fem.probe.ProbeFrame`): its origin is
            the contact point at depth 0 and the indenter moves ``depth_m`` along its
            direction. None: along -z from ``(x_m, y_m, top_z_m)`` of the indenter.
        quadrature: None: the node-to-surface penalty on ``nodes``; else the contact is
            integrated at these points of the surface's triangles
            (:mod:`warptissue.fem.surface_contact`) and ``stiffness_N_per_m`` is the
            penalty per unit area ``eps``, Pa/m (``nodes`` still give the outputs' gaps).
    """

    indenter: Indenter
    nodes: np.ndarray
    top_z_m: float
    stiffness_N_per_m: float
    depth_m: float = 0.0
    frame: ProbeFrame | None = None
    quadrature: SurfaceQuadrature | None = None

    def __post_init__(self) -> None:
        if not self.indenter.is_rigid_contact:
            raise InputError(
                "rigid contact needs a sphere, a plate, a wedge or a flat punch with "
                "edge_radius_m > 0 (a sharp flat punch prescribes its nodes)",
                key="kind",
                value=self.indenter.kind,
            )
        self.nodes = np.asarray(self.nodes, dtype=np.int64).ravel()
        if self.nodes.size == 0:
            raise InputError("rigid contact needs candidate nodes", key="surface")
        k = self.stiffness_N_per_m
        if not (math.isfinite(k) and k > 0):
            raise InputError("the penalty stiffness must be positive", value=k)
        if self.frame is None:
            origin = (self.indenter.x_m, self.indenter.y_m, self.top_z_m)
            self.frame = probe_frame(origin_m=origin)

    @property
    def contact_z_m(self) -> float:
        """z of the indenter's contact point at the current depth, m (its lowest point
        along -z)."""
        return float(self.frame.point_at_depth(self.depth_m)[2])

    def device_body(self) -> Any:
        """The indenter at the current depth as the kernels' ``RigidBody`` struct."""

        probe = self.indenter
        frame = self.frame
        # The contact point in frame coordinates (the kernel's x' = A x, no translation).
        point = frame.axes @ frame.point_at_depth(self.depth_m)
        body = kc.RigidBody()
        body.axes = wp.mat33d(*frame.axes.ravel())
        body.point = wp.vec3d(*point)
        body.radius = wp.float64(probe.radius_m)
        body.edge_radius = wp.float64(0.0)
        body.half_angle = wp.float64(0.0)
        if probe.kind == "sphere":
            body.kind = int(kc.RIGID_SPHERE)
            body.point = wp.vec3d(point[0], point[1], point[2] + probe.radius_m)
        elif probe.kind == "plate":
            body.kind = int(kc.RIGID_PLATE)
        elif probe.kind == "flat_punch":
            body.kind = int(kc.RIGID_PUNCH)
            body.edge_radius = wp.float64(probe.edge_radius_m)
        else:
            body.kind = int(kc.RIGID_WEDGE)
            body.edge_radius = wp.float64(probe.radius_m)
            body.half_angle = wp.float64(math.radians(0.5 * probe.angle_deg))
        return body

    @classmethod
    def for_mesh(
        cls,
        mesh: TetMesh,
        indenter: Indenter,
        shear_modulus_Pa: float,
        *,
        surface: str = "top",
        penalty_factor: float = DEFAULT_PENALTY_FACTOR,
        frame: ProbeFrame | None = None,
        integration: str = "nodes",
    ) -> RigidContact:
        """The contact of ``indenter`` with the nodes of ``surface``, its stiffness from the
        material and the mesh (``k = beta mu0 h``, module docstring; ``integration =
        "surface"``: the penalty per unit area ``eps = 10 beta mu0 / h``
        (:data:`~warptissue.fem.surface_contact.SURFACE_PENALTY_SCALE`) at the quadrature
        points of the triangles whose corners are candidate nodes,
        :mod:`warptissue.fem.surface_contact`).

        ``frame`` (None: along -z from ``(x_m, y_m)`` and the top of ``surface``) places the
        indenter; the nodes "under" it are measured perpendicular to its direction, within
        its radius of the site along it (so that the far side of a body does not count).

        Raises:
            InputError: A non-positive ``penalty_factor``, no node under the indenter, or an
                unknown ``integration``.
        """
        if integration not in CONTACT_INTEGRATIONS:
            raise InputError(
                f"must be one of {CONTACT_INTEGRATIONS}", key="integration", value=integration
            )
        if isinstance(penalty_factor, bool) or not (
            isinstance(penalty_factor, int | float)
            and math.isfinite(penalty_factor)
            and penalty_factor > 0
        ):
            raise InputError(
                "must be a positive number", key="penalty_factor", value=penalty_factor
            )
        nodes = mesh.node_set(surface).astype(np.int64)
        placed = frame is not None
        if frame is None:
            top = float(mesh.points[nodes, 2].max()) if indenter.z_m is None else indenter.z_m
            frame = probe_frame(origin_m=(indenter.x_m, indenter.y_m, top))
        local = frame.to_local(mesh.points[nodes])
        if placed:  # not the far side of the body
            near = np.abs(local[:, 2]) <= max(indenter.radius_m, float(np.abs(local[:, 2]).min()))
            nodes, local = nodes[near], local[near]
        under = nodes
        if indenter.kind in ("sphere", "flat_punch"):
            xy = local[:, :2]
            under = nodes[np.einsum("ij,ij->i", xy, xy) <= indenter.radius_m**2]
        elif indenter.kind == "wedge":
            dx = np.abs(local[:, 0])
            under = nodes[dx <= max(indenter.radius_m, float(dx.min()))]
        if under.size == 0:
            raise InputError(
                f"no node of {surface!r} lies under the {indenter.kind} (within "
                f"{indenter.radius_m} m of the axis through {frame.origin_m.tolist()})",
                key="radius_m",
                value=indenter.radius_m,
            )
        h = mean_edge_length(mesh, under)
        stiffness = float(penalty_factor) * shear_modulus_Pa * h
        quadrature = None
        if integration == "surface":
            stiffness *= SURFACE_PENALTY_SCALE / (h * h)
            faces = surface_triangles(mesh, nodes)
            quadrature = SurfaceQuadrature.for_faces(mesh.points, faces)
        origin = float(frame.origin_m[2])
        return cls(indenter, nodes, origin, stiffness, frame=frame, quadrature=quadrature)


@dataclass(frozen=True)
class ContactState:
    """The contact at one displacement: per candidate node, its gap and the force on it.

    Attributes:
        nodes: Candidate nodes, (k,) int.
        gap_m: Signed distance of each node to the indenter (negative: penetration), (k,), m.
        force_N: Contact force on each node (zero where the gap is >= 0), (k, 3), N; of the
            modelled part of the specimen (not scaled by a symmetry factor).
        point_gap_m: Under a surface-integrated contact
            (:mod:`warptissue.fem.surface_contact`), the gap at each quadrature point, (Q,),
            m; None under the nodal one.
        point_area_m2: The current area each quadrature point stands for, (Q,), m^2; None
            under the nodal contact.
    """

    nodes: np.ndarray
    gap_m: np.ndarray
    force_N: np.ndarray
    point_gap_m: np.ndarray | None = None
    point_area_m2: np.ndarray | None = None

    @property
    def total_force_N(self) -> np.ndarray:
        """The summed contact force on the modelled part, (3,), N."""
        return self.force_N.sum(axis=0)

    @property
    def max_penetration_m(self) -> float:
        """The largest penetration into the indenter, m (0 out of contact): of a node, or
        under a surface-integrated contact of a node or a quadrature point."""
        deepest = -float(self.gap_m.min())
        if self.point_gap_m is not None and self.point_gap_m.size:
            deepest = max(deepest, -float(self.point_gap_m.min()))
        return max(0.0, deepest)

    @property
    def point_contact_area_m2(self) -> float | None:
        """Under a surface-integrated contact, the current area of the quadrature points
        that penetrate the indenter (gap < 0), m^2, of the modelled part; None under the
        nodal contact. The contact's edge is resolved to the points' spacing, a fraction
        ``1 / (2 s)`` of a triangle (:func:`warptissue.fem.surface_contact.triangle_rule`),
        not to a ring of nodes."""
        if self.point_gap_m is None or self.point_area_m2 is None:
            return None
        return float(self.point_area_m2[self.point_gap_m < 0.0].sum())


@dataclass(frozen=True)
class ContactSurface:
    """The indented surface as triangles, for the contact area and pressure.

    Tributary area of a node: ``w_i = integral of N_i dA`` over the surface triangles, with
    the triangles' own shape functions (the row sums of the surface's consistent matrix
    ``integral of N_i N_j dA``). A 3-node triangle (TET4 face) of area A gives each corner
    ``A / 3``. A 6-node triangle (TET10 face) gives each mid-edge node ``A / 3`` and each
    corner 0: ``integral of L (2 L - 1) dA = 0``. These are the weights of the nodal forces a
    uniform pressure p puts on the nodes (``f_i = p w_i``), and so the forces the penalty
    contact settles to at equilibrium (measured on the plate test: TET10 corner nodes carry
    1e-4 of a mid-edge node's force, at a gap ~1e-4 of the mid-edge nodes'). Dividing those
    forces by any positive lumping (the 4-sub-triangle one, corners ``A / 12``, mid-edge
    ``A / 4``, or Hinton-Rock-Zienkiewicz's) gives a checkerboard, measured under a sphere
    (docs/fe.md "Contact outputs"): corners 0-4 % of Hertz's pressure, mid-edge nodes
    121-131 %. Hence:

    - pressure ``p_i = |f_i| / w_i`` where ``w_i > 0``; the small force left on TET10 corner
      nodes (0.01-1.2 % of the total, measured under a sphere) is first handed to the
      mid-edge nodes of the triangles around them in proportion to their ``w``, so that the
      integral of the interpolated pressure, ``sum_i p_i w_i``, equals the summed normal
      contact force. A TET10 corner node, whose ``w`` is 0, shows the ``w``-weighted mean
      pressure of the mid-edge nodes of its triangles (for display; it does not enter the
      integral).
    - contact area ``sum of w_i`` over the nodes that penetrate the indenter (gap < 0); TET10
      corner nodes, without area and with a gap of no meaning, count nothing. The edge of
      contact is resolved by whole nodes: the area is uncertain by a ring of nodes (half an
      element) around the contact edge.

    A TET10 triangle's area is that of its four sub-triangles (corner and mid-edge nodes),
    which follows a curved face; a TET4 triangle's is the flat one.

    Attributes:
        triangles: Node indices, (F, 3) corners or (F, 6) corners then the mid-edge nodes of
            the edges (0, 1), (1, 2), (2, 0).
    """

    triangles: np.ndarray

    @classmethod
    def for_mesh(cls, mesh: TetMesh, *, surface: str = "top") -> ContactSurface:
        """The boundary triangles of ``mesh`` whose corners all lie in node set ``surface``.

        Raises:
            InputError: No boundary triangle lies on ``surface``.
        """
        triangles = surface_triangles(mesh, mesh.node_set(surface))
        if len(triangles) == 0:
            raise InputError(f"no boundary triangle lies on node set {surface!r}", key="surface")
        return cls(triangles)

    def triangle_areas_m2(self, points_m: np.ndarray) -> np.ndarray:
        """Area of each triangle at node positions ``points_m`` (N, 3), m^2, shape (F,)."""
        x = np.asarray(points_m, dtype=np.float64)
        tri = self.triangles
        if tri.shape[1] == 3:
            pieces = [(0, 1, 2)]
        else:  # the four sub-triangles: three at the corners, one of the mid-edge nodes
            pieces = [(0, 3, 5), (3, 1, 4), (5, 4, 2), (3, 4, 5)]
        area = np.zeros(len(tri))
        for a, b, c in pieces:
            cross = np.cross(x[tri[:, b]] - x[tri[:, a]], x[tri[:, c]] - x[tri[:, a]])
            area += 0.5 * np.linalg.norm(cross, axis=1)
        return area

    def tributary_areas_m2(self, points_m: np.ndarray) -> np.ndarray:
        """``w_i = integral of N_i dA`` of every node at positions ``points_m`` (N, 3), m^2,
        shape (N,) (zero off the surface and at TET10 corner nodes)."""
        weights = np.zeros(len(points_m))
        third = self.triangle_areas_m2(points_m) / 3.0
        holders = self.triangles[:, 3:] if self.triangles.shape[1] == 6 else self.triangles
        for column in holders.T:
            np.add.at(weights, column, third)
        return weights

    def contact_area_m2(self, state: ContactState, points_m: np.ndarray) -> float:
        """Area of the surface in contact, m^2, of the modelled part: the tributary areas
        of the nodes with gap < 0; under a surface-integrated contact the areas of the
        quadrature points with gap < 0 (:attr:`ContactState.point_contact_area_m2`).

        Args:
            state: The contact at ``points_m``.
            points_m: Current node positions (reference plus displacement), (N, 3), m.
        """
        if state.point_contact_area_m2 is not None:
            return state.point_contact_area_m2
        weights = self.tributary_areas_m2(points_m)
        return float(weights[state.nodes[state.gap_m < 0.0]].sum())

    def pressure_Pa(self, state: ContactState, points_m: np.ndarray) -> np.ndarray:
        """Contact pressure at every node, Pa, shape (N,) (zero off the contact).

        Args:
            state: The contact at ``points_m``.
            points_m: Current node positions (reference plus displacement), (N, 3), m.

        Returns:
            ``p_i = |f_i| / w_i`` (class docstring): its integral ``sum_i p_i w_i`` is the
            summed normal contact force of the modelled part.
        """
        count = len(points_m)
        weights = self.tributary_areas_m2(points_m)
        force = np.zeros(count)
        force[state.nodes] = np.linalg.norm(state.force_N, axis=1)
        tri = self.triangles
        if tri.shape[1] == 6:
            # Hand the corners' force to the mid-edge nodes of their triangles, by weight.
            share = np.zeros(count)
            for corner in tri[:, :3].T:
                for mid in tri[:, 3:].T:
                    np.add.at(share, corner, weights[mid])
            for corner in tri[:, :3].T:
                for mid in tri[:, 3:].T:
                    held = share[corner] > 0
                    moved = np.zeros(count)
                    np.add.at(
                        moved,
                        mid[held],
                        force[corner[held]] * weights[mid[held]] / share[corner[held]],
                    )
                    force += moved
            force[np.unique(tri[:, :3])] = 0.0
        pressure = np.zeros(count)
        loaded = weights > 0.0
        pressure[loaded] = force[loaded] / weights[loaded]
        if tri.shape[1] == 6:  # corners: the weighted mean of their mid-edge nodes
            total, weight = np.zeros(count), np.zeros(count)
            for corner in tri[:, :3].T:
                for mid in tri[:, 3:].T:
                    np.add.at(total, corner, (weights * pressure)[mid])
                    np.add.at(weight, corner, weights[mid])
            corners = np.unique(tri[:, :3])
            corners = corners[weight[corners] > 0]
            pressure[corners] = total[corners] / weight[corners]
        return pressure


class RigidContacts:
    """The rigid contacts of the K problems of one assembler's mesh and their launches of
    ``rigid_contact_kernel``: one launch over every problem's candidate nodes, each with its
    own problem's body and penalty stiffness. :class:`warptissue.fem.assembly.Assembler`
    holds one (``set_contact``, ``set_load``, ``contact_states``).

    Args:
        points: Reference node coordinates, vec3d (N,), m, on the assembler's device.
        pattern: The tangent's BSR row offsets and columns, (N + 1,) and (B,): each node's
            diagonal block, and a surface-integrated contact's blocks between the nodes of a
            triangle.
        node_offsets: First node of each packed problem and N at the end, (K + 1,); None
            where the problems are not packed in contiguous node ranges.
        node_problem: The problem of each node, (N,).
        problem_count: K.
        device: The assembler's Warp device.

    Attributes:
        contacts: Each problem's rigid contact or None, (K,).
        contact: The rigid contact of one problem (None without one, and always None where
            K > 1).
        force: The force on each problem's body of the last launch that wrote it, vec3d
            (K,), N.
    """

    def __init__(
        self,
        *,
        points: wp.array,
        pattern: tuple[np.ndarray, np.ndarray],
        node_offsets: np.ndarray | None,
        node_problem: np.ndarray,
        problem_count: int,
        device: Any,
    ) -> None:
        count = problem_count
        self._pattern = pattern
        diagonal = np.arange(len(pattern[0]) - 1)
        self._surface: SurfaceContactArrays | None = None
        self.problem_count = count
        self.device = device
        self._points = points
        self._diagonal_blocks = block_ids(*pattern, diagonal, diagonal)
        self._node_offsets = node_offsets
        self._node_problem = node_problem
        self.contact: RigidContact | None = None
        self.contacts: tuple[RigidContact | None, ...] = (None,) * count
        self.force = wp.zeros(count, dtype=wp.vec3d, device=device)
        self._ranges = np.zeros(count + 1, dtype=np.int64)
        self._bodies_key: Any = None
        self._stiffness_key: Any = None

    def set(self, contact: RigidContact | Sequence[RigidContact | None] | None) -> None:
        """The contacts from the next launch on (as
        :meth:`warptissue.fem.assembly.Assembler.set_contact`).

        Raises:
            InputError: Not one entry per problem, a contact node outside its problem, or
                contacts on problems that are not packed in contiguous node ranges.
        """
        count = self.problem_count
        offsets = self._node_offsets
        contacts, used = per_problem(
            contact,
            RigidContact,
            count=count,
            node_offsets=offsets,
            key="contact",
            one="contact",
            many="rigid contacts",
        )
        counts = np.zeros(count, dtype=np.int64)
        nodes, problems = [], []
        for k in used:
            own = contacts[k].nodes
            size = int(offsets[k + 1] - offsets[k])
            if own.min() < 0 or own.max() >= size:
                raise InputError(
                    "contact nodes must be nodes of the mesh"
                    + ("" if count == 1 else f" (of problem {k}, in its own numbering)"),
                    key="mesh",
                )
            nodes.append(own + offsets[k])
            problems.append(np.full(len(own), k, dtype=np.int32))
            counts[k] = len(own)
        if used:
            dev = self.device
            union = np.concatenate(nodes)
            self._nodes = wp.array(union, dtype=wp.int32, device=dev)
            self._blocks = wp.array(self._diagonal_blocks[union], dtype=wp.int32, device=dev)
            self._problem = wp.array(np.concatenate(problems), dtype=wp.int32, device=dev)
            self._node_force = wp.zeros(len(union), dtype=wp.vec3d, device=dev)
            self._gap = wp.zeros(len(union), dtype=wp.float64, device=dev)
        quadratures = [None if each is None else each.quadrature for each in contacts]
        self._surface = SurfaceContactArrays.for_problems(
            quadratures, used, node_offsets=offsets, pattern=self._pattern, device=self.device
        )
        self._ranges = np.concatenate([[0], np.cumsum(counts)])
        self._bodies_key = self._stiffness_key = None  # uploaded at the next launch
        self.contacts = contacts
        self.contact = contacts[0] if count == 1 else None

    @property
    def has_contact(self) -> bool:
        """Whether any problem has a rigid contact."""
        return any(each is not None for each in self.contacts)

    def set_load(self, load: Any) -> None:
        """Each indenter's depth, m (as :meth:`warptissue.fem.assembly.Assembler.set_load`).

        Raises:
            InputError: Not one depth per problem.
        """
        count = self.problem_count
        if count == 1:
            if self.contact is not None:
                value = np.asarray(load, dtype=np.float64)
                if value.size != 1:
                    raise InputError("one load for one problem", key="load", value=value.shape)
                self.contact.depth_m = float(load) if value.ndim == 0 else float(value.flat[0])
            return
        loads = np.asarray(load, dtype=np.float64)
        if loads.ndim == 0:
            loads = np.full(count, float(loads))
        if loads.shape != (count,):
            raise InputError(
                f"one load per packed problem ({count})", key="load", value=loads.shape
            )
        for each, depth in zip(self.contacts, loads, strict=True):
            if each is not None:
                each.depth_m = float(depth)

    def states(self, u: wp.array, values: wp.array) -> list[ContactState | None]:
        """Every problem's :class:`ContactState` at the displacement ``u`` (vec3d (N,), m)
        from one launch without the tangent, None where a problem has no rigid contact.

        Args:
            u: Nodal displacements on the device.
            values: The tangent's BSR values (not written without the tangent).
        """
        if not self.has_contact:
            return [None] * self.problem_count
        scratch = wp.zeros(len(self._node_problem), dtype=wp.vec3d, device=self.device)
        energy = wp.zeros(self.problem_count, dtype=wp.float64, device=self.device)
        force = wp.zeros(self.problem_count, dtype=wp.vec3d, device=self.device)
        self.launch(u, 0, scratch, values, energy, force)
        gaps, forces = self._gap.numpy(), self._node_force.numpy()
        points = [{} for _ in self.contacts]
        surface = self._surface
        if surface is not None:  # the nodes' gaps, and the forces the points put on them
            point_gaps = surface.gap.numpy()
            zeros = wp.zeros_like(scratch)
            self.launch(u, 0, zeros, values, energy, wp.zeros_like(force), nodes=True)
            gaps, forces = self._gap.numpy(), -scratch.numpy()[self._nodes.numpy()]
            current = self._points.numpy() + u.numpy()
            offsets = self._node_offsets
            for k, each in enumerate(self.contacts):
                if each is not None:
                    own = current[offsets[k] : offsets[k + 1]]
                    points[k] = {
                        "point_gap_m": point_gaps[surface.point_problem == k].copy(),
                        "point_area_m2": each.quadrature.areas_m2(own),
                    }
        ranges = self._ranges
        return [
            None
            if each is None
            else ContactState(
                nodes=each.nodes.copy(),
                gap_m=gaps[ranges[k] : ranges[k + 1]].copy(),
                force_N=forces[ranges[k] : ranges[k + 1]].copy(),
                **points[k],
            )
            for k, each in enumerate(self.contacts)
        ]

    def _inputs(self) -> list[Any]:
        """The per-problem inputs of ``rigid_contact_kernel``: ``[bodies, stiffness]``, each
        problem's body at its current depth and its penalty stiffness, copied to the device
        only when a contact's depth, body or stiffness has changed (the penalty ramp of
        :mod:`warptissue.fem.newton.increment` scales the stiffness)."""
        bodies_key = tuple(
            None
            if each is None
            else (each.indenter, each.depth_m, *each.frame.origin_m, *each.frame.axes.ravel())
            for each in self.contacts
        )
        if bodies_key != self._bodies_key:
            self._bodies = wp.array(
                [kc.RigidBody() if each is None else each.device_body() for each in self.contacts],
                dtype=kc.RigidBody,
                device=self.device,
            )
            self._bodies_key = bodies_key
        stiffness_key = tuple(
            0.0 if each is None else float(each.stiffness_N_per_m) for each in self.contacts
        )
        if stiffness_key != self._stiffness_key:
            self._stiffness = wp.array(
                np.array(stiffness_key, dtype=np.float64), dtype=wp.float64, device=self.device
            )
            self._stiffness_key = stiffness_key
        return [self._bodies, self._stiffness]

    def launch(
        self,
        u: wp.array,
        with_tangent: int,
        residual: wp.array,
        values: wp.array,
        energy: wp.array,
        force: wp.array,
        *,
        nodes: bool = False,
    ) -> None:
        """One launch of ``rigid_contact_kernel`` over every problem's candidate nodes at the
        contacts' current depths: subtracts the contact forces from ``residual`` (vec3d (N,)),
        adds to the diagonal blocks of ``values`` where ``with_tangent``, and to ``energy``
        (J) and ``force`` (N), one entry per problem; of ``rigid_surface_contact_kernel``
        over the quadrature points instead where the contacts are surface-integrated, unless
        ``nodes`` asks for the node kernel (its gaps and node forces, for the states)."""
        surface = self._surface
        if surface is not None and not nodes:
            wp.launch(
                kc.rigid_surface_contact_kernel,
                dim=surface.point_count,
                inputs=[self._points, u, *surface.inputs, *self._inputs(), with_tangent],
                outputs=[residual, values, energy, force, surface.gap],
                device=self.device,
            )
            return
        wp.launch(
            kc.rigid_contact_kernel,
            dim=int(self._ranges[-1]),
            inputs=[
                self._points,
                u,
                self._nodes,
                self._blocks,
                self._problem,
                *self._inputs(),
                with_tangent,
            ],
            outputs=[residual, values, energy, force, self._node_force, self._gap],
            device=self.device,
        )

    def parameter_residual(
        self, u: wp.array, values: wp.array, d_shears: np.ndarray, moduli: np.ndarray
    ) -> np.ndarray | float:
        """The rigid contacts' part of ``dR/dtheta``: each problem's penalty ``k = beta mu0 h``
        follows its initial shear modulus, so ``dR_c/dtheta = R_c (dmu0/dtheta) / mu0`` on its
        nodes (0 without contact or for a parameter mu0 does not depend on).

        Args:
            u: Nodal displacements on the device.
            values: The tangent's BSR values (not written).
            d_shears: Each problem's ``dmu0/dtheta``, (K,), the ``shear_modulus`` field of
                :meth:`warptissue.materials.Material.device_params_derivative`.
            moduli: Each problem's initial shear modulus ``mu0``, (K,), Pa.

        Returns:
            (N, 3), N per unit of the parameter; or 0.0.
        """
        shares = np.where(
            [each is not None for each in self.contacts], np.asarray(d_shears) / moduli, 0.0
        )
        if not np.any(shares != 0.0):
            return 0.0
        scratch = wp.zeros(len(self._node_problem), dtype=wp.vec3d, device=self.device)
        energy = wp.zeros(self.problem_count, dtype=wp.float64, device=self.device)
        force = wp.zeros(self.problem_count, dtype=wp.vec3d, device=self.device)
        self.launch(u, 0, scratch, values, energy, force)
        if self.problem_count == 1:
            return shares[0] * scratch.numpy()
        return scratch.numpy() * shares[self._node_problem][:, None]
