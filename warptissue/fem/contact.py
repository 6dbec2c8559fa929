"""Frictionless penalty contact of a rigid indenter with the specimen's surface nodes.

The indenter is an analytic rigid body positioned by the depth (the load of
:func:`warptissue.fem.solve_quasistatic`), its contact point at ``top - depth`` on the axis
``(x_m, y_m)``: a sphere of radius ``r``; a plate (the plane ``z = top - depth``, filling the
half-space above); a flat-ended cylinder of radius ``a`` whose edge is rounded with radius
``rho`` (``edge_radius_m``); a wedge along y of opening angle ``2 alpha`` whose tip is rounded
with radius ``rho``. Each candidate node (every node of the indented surface, TET10 mid-edge
nodes included) with signed distance ``g < 0`` to the indenter (penetration) gets the contact
force ``f_c = -k g n`` along the indenter's outward normal ``n``; the residual becomes
``R = f_int - f_c`` and the node's diagonal tangent block gains ``k (n n^T + g dn/dx)`` (the
second term is the turning of the normal over a curved surface). The energy gains
``k g^2 / 2``, so the line search sees one potential. Device code: ``rigid_contact_point``
and ``rigid_contact_kernel`` in ``kernels/fem.py``.

Penalty stiffness per node: ``k = beta mu0 h``, ``mu0`` the material's initial shear modulus
and ``h`` the mean edge length of the elements of the candidate nodes under the indenter
(within its radius of the axis for a sphere or a punch, within the tip radius or one row of
nodes of the line for a wedge, the whole surface for a plate); ``beta``
(:data:`DEFAULT_PENALTY_FACTOR`) was chosen by measurement (docs/fe.md "Contact").
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import warp as wp

from warptissue.errors import InputError
from warptissue.indenter import Indenter
from warptissue.mesh import TetMesh

__all__ = ["DEFAULT_PENALTY_FACTOR", "ContactState", "RigidContact", "mean_edge_length"]

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
    """

    indenter: Indenter
    nodes: np.ndarray
    top_z_m: float
    stiffness_N_per_m: float
    depth_m: float = 0.0

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

    @property
    def contact_z_m(self) -> float:
        """z of the indenter's lowest point at the current depth, m."""
        return self.top_z_m - self.depth_m

    def device_body(self) -> Any:
        """The indenter at the current depth as the kernels' ``RigidBody`` struct."""
        from warptissue.kernels import fem as kf

        probe = self.indenter
        body = kf.RigidBody()
        body.point = wp.vec3d(probe.x_m, probe.y_m, self.contact_z_m)
        body.radius = wp.float64(probe.radius_m)
        body.edge_radius = wp.float64(0.0)
        body.half_angle = wp.float64(0.0)
        if probe.kind == "sphere":
            body.kind = int(kf.RIGID_SPHERE)
            body.point = wp.vec3d(probe.x_m, probe.y_m, self.contact_z_m + probe.radius_m)
        elif probe.kind == "plate":
            body.kind = int(kf.RIGID_PLATE)
        elif probe.kind == "flat_punch":
            body.kind = int(kf.RIGID_PUNCH)
            body.edge_radius = wp.float64(probe.edge_radius_m)
        else:
            body.kind = int(kf.RIGID_WEDGE)
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
    ) -> RigidContact:
        """The contact of ``indenter`` with the nodes of ``surface``, its stiffness from the
        material and the mesh (``k = beta mu0 h``, module docstring).

        Raises:
            InputError: A non-positive ``penalty_factor``, or no node under the indenter.
        """
        if isinstance(penalty_factor, bool) or not (
            isinstance(penalty_factor, int | float)
            and math.isfinite(penalty_factor)
            and penalty_factor > 0
        ):
            raise InputError(
                "must be a positive number", key="penalty_factor", value=penalty_factor
            )
        nodes = mesh.node_set(surface).astype(np.int64)
        top = float(mesh.points[nodes, 2].max()) if indenter.z_m is None else indenter.z_m
        under = nodes
        if indenter.kind in ("sphere", "flat_punch"):
            xy = mesh.points[nodes, :2] - np.array([indenter.x_m, indenter.y_m])
            under = nodes[np.einsum("ij,ij->i", xy, xy) <= indenter.radius_m**2]
        elif indenter.kind == "wedge":
            dx = np.abs(mesh.points[nodes, 0] - indenter.x_m)
            under = nodes[dx <= max(indenter.radius_m, float(dx.min()))]
        if under.size == 0:
            raise InputError(
                f"no node of {surface!r} lies under the {indenter.kind} (within "
                f"{indenter.radius_m} m of ({indenter.x_m}, {indenter.y_m}))",
                key="radius_m",
                value=indenter.radius_m,
            )
        h = mean_edge_length(mesh, under)
        return cls(indenter, nodes, top, float(penalty_factor) * shear_modulus_Pa * h)


@dataclass(frozen=True)
class ContactState:
    """The contact at one displacement: per candidate node, its gap and the force on it.

    Attributes:
        nodes: Candidate nodes, (k,) int.
        gap_m: Signed distance of each node to the indenter (negative: penetration), (k,), m.
        force_N: Contact force on each node (zero where the gap is >= 0), (k, 3), N; of the
            modelled part of the specimen (not scaled by a symmetry factor).
    """

    nodes: np.ndarray
    gap_m: np.ndarray
    force_N: np.ndarray

    @property
    def total_force_N(self) -> np.ndarray:
        """The summed contact force on the modelled part, (3,), N."""
        return self.force_N.sum(axis=0)

    @property
    def max_penetration_m(self) -> float:
        """The largest penetration of a node into the indenter, m (0 out of contact)."""
        return max(0.0, -float(self.gap_m.min()))
