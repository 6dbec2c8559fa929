"""The result of an indentation: the force-depth curve, the fields at its last depth and
how it was solved (:func:`warptissue.fem.simulate_indentation` makes it)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from warptissue.fem.timing import NewtonTimings

__all__ = ["IndentationResult"]


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
