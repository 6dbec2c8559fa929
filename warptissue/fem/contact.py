"""Frictionless penalty contact of a rigid indenter (sphere or plate) with surface nodes.

The indenter is an analytic rigid body positioned by the depth (the load of
:func:`warptissue.fem.solve_quasistatic`): a sphere of radius ``r`` whose lowest point is at
``top - depth`` on the axis ``(x_m, y_m)``, or the plane ``z = top - depth`` of a plate filling
the half-space above it. Each candidate node (every node of the indented surface, TET10
mid-edge nodes included) with signed distance ``g < 0`` to the indenter (penetration) gets the
contact force ``f_c = -k g n`` along the indenter's outward normal ``n``; the residual becomes
``R = f_int - f_c`` and the tangent gains ``k (n n^T + g/|x - c| (I - n n^T))`` on the node's
diagonal block (sphere; the second term is the turning of the normal), ``k n n^T`` (plate).
The energy gains ``k g^2 / 2``, so the line search sees one potential. The device code is
``sphere_contact_kernel`` and ``plate_contact_kernel`` in ``kernels/fem.py``.

Penalty stiffness per node: ``k = beta mu0 h``, ``mu0`` the material's initial shear modulus
and ``h`` the mean edge length of the elements of the candidate nodes under the indenter
(within its radius of the axis for a sphere, the whole surface for a plate); ``beta``
(:data:`DEFAULT_PENALTY_FACTOR`) was chosen by measurement (docs/fe.md "Contact").
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from warptissue.errors import InputError
from warptissue.indenter import CONTACT_KINDS, Indenter
from warptissue.mesh import TetMesh

__all__ = ["DEFAULT_PENALTY_FACTOR", "RigidContact", "mean_edge_length"]

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
        indenter: A sphere or a plate (:data:`warptissue.indenter.CONTACT_KINDS`).
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
        if self.indenter.kind not in CONTACT_KINDS:
            raise InputError(
                f"rigid contact needs one of {', '.join(map(repr, CONTACT_KINDS))}",
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
    def centre_m(self) -> np.ndarray:
        """The sphere's centre at the current depth, (3,), m."""
        radius = self.indenter.radius_m
        return np.array(
            [self.indenter.x_m, self.indenter.y_m, self.top_z_m - self.depth_m + radius]
        )

    @property
    def plane_z_m(self) -> float:
        """The plate's plane at the current depth, m."""
        return self.top_z_m - self.depth_m

    def gaps_m(self, points_m: np.ndarray) -> np.ndarray:
        """Signed distances of the candidate nodes at current positions ``points_m`` (N, 3)
        to the indenter (negative: penetration), (k,), m."""
        x = np.asarray(points_m)[self.nodes]
        if self.indenter.kind == "sphere":
            return np.linalg.norm(x - self.centre_m, axis=1) - self.indenter.radius_m
        return self.plane_z_m - x[:, 2]

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
        if indenter.kind == "sphere":
            xy = mesh.points[nodes, :2] - np.array([indenter.x_m, indenter.y_m])
            under = nodes[np.einsum("ij,ij->i", xy, xy) <= indenter.radius_m**2]
            if under.size == 0:
                raise InputError(
                    f"no node of {surface!r} lies under the sphere (within {indenter.radius_m} m "
                    f"of ({indenter.x_m}, {indenter.y_m}))",
                    key="radius_m",
                    value=indenter.radius_m,
                )
        h = mean_edge_length(mesh, under)
        return cls(indenter, nodes, top, float(penalty_factor) * shear_modulus_Pa * h)
