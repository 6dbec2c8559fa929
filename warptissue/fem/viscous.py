"""The history of a viscoelastic material in the FE: internal variables per quadrature point.

A :class:`warptissue.materials.Viscoelastic` material relaxes its deviatoric second
Piola-Kirchhoff stress with a normalized Prony series (Ahn & Kim, Eq. 1-2):

    S_dev(t) = int_0^t G(t - s) dS0/ds ds,   G(t) = g_inf + sum_i g_i exp(-t / tau_i),

with ``S0 = F^-1 P_dev(F)`` the hyperelastic deviatoric stress and ``g_inf = 1 - sum g_i``.
Split into ``S_dev = g_inf S0 + sum_i H_i`` with ``H_i(t) = int g_i exp(-(t - s)/tau_i) dS0``,
a step from t_n-1 to t_n = t_n-1 + dt over which S0 changes linearly in time gives exactly

    H_i(t_n) = a_i H_i(t_n-1) + b_i (S0(t_n) - S0(t_n-1)),
    a_i = exp(-dt / tau_i),   b_i = g_i tau_i / dt (1 - a_i),

(the recursive convolution of Simo 1987 and Taylor, Pister & Goudreau 1970; the midpoint
rules of some codes are exact only in the limit dt -> 0). Hence within the step

    S_dev = gamma S0(F) + Q,   gamma = g_inf + sum_i b_i,   Q = sum_i (a_i H_i - b_i S0_prev),

where Q is fixed during the step's Newton iterations: the step is the minimum of the
incremental energy ``gamma psi_dev(F) + Q : (C - I)/2 + U``, so Newton's tangent stays
symmetric. :class:`ViscousHistory` holds H_i and S0_prev per quadrature point on the Warp
device, computes Q for a step, and commits a converged step.

Sensitivities carried forward in time (direct differentiation): for a parameter theta,
``dR/dtheta`` at fixed u gains ``int F dS/dtheta grad N dV`` with

    dS/dtheta = dgamma/dtheta S0 + sum_i (da_i H_i + a_i dH_i - db_i S0_prev - b_i dS0_prev)

from the history, whose derivatives ``dH_i`` and ``dS0_prev`` are advanced after each step
with the step's ``du/dtheta`` (:meth:`ViscousHistory.commit_sensitivity`). With
``x_i = dt / tau_i``: ``da_i/dtau_i = a_i x_i / tau_i``, ``db_i/dg_i = (1 - a_i) / x_i``,
``db_i/dtau_i = g_i ((1 - a_i) / dt - a_i / tau_i)``, ``dgamma/dg_i = db_i/dg_i - 1`` and
``dgamma/dtau_i = db_i/dtau_i``. tests/test_fem_viscoelastic.py checks all of it against
Fung's QLV integral and central differences of whole runs.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import warp as wp

from warptissue.errors import InputError
from warptissue.kernels import viscous as kv
from warptissue.kernels.assembly import ViscousStep
from warptissue.kernels.materials import MaterialParams, vec6d
from warptissue.materials import Material, Viscoelastic

__all__ = ["ViscousHistory", "elastic_step"]


def elastic_step() -> object:
    """The ``ViscousStep`` struct of an elastic material (``active = 0``)."""
    step = ViscousStep()
    step.active = 0
    step.terms = 0
    step.gamma = 1.0
    step.a = vec6d()
    step.b = vec6d()
    return step


def _step_struct(gamma: float, a: Sequence[float], b: Sequence[float]) -> object:
    step = ViscousStep()
    step.active = 1
    step.terms = len(a)
    step.gamma = float(gamma)
    step.a = vec6d(*a, *([0.0] * (6 - len(a))))
    step.b = vec6d(*b, *([0.0] * (6 - len(b))))
    return step


def _coefficients(material: Viscoelastic, dt: float) -> tuple[float, np.ndarray, np.ndarray]:
    """``(gamma, a, b)`` of a step of length ``dt`` (s)."""
    g = np.asarray(material.g)
    tau = np.asarray(material.tau_s)
    x = dt / tau
    a = np.exp(-x)
    # (1 - exp(-x)) / x without cancellation for small x.
    share = np.where(x > 1e-8, -np.expm1(-x) / np.where(x > 0, x, 1.0), 1.0 - 0.5 * x)
    b = g * share
    return 1.0 - float(g.sum()) + float(b.sum()), a, b


class ViscousHistory:
    """Internal variables of viscoelastic materials on a tet mesh, on a Warp device.

    One problem, or K problems packed into one mesh (:mod:`warptissue.fem.packing`), each
    with its own material (a viscoelastic one, or an elastic one whose step is inactive) and
    its own time step.

    Args:
        materials: One material per problem, (K,); at least one viscoelastic.
        element_problem: The problem of each tet, (M,) (None: one problem).
        tet_count: Elements M.
        quadrature_points: Quadrature points per element Q.
        device: The Warp device of the assembler.

    Attributes:
        materials: The materials, (K,).
        history: H_i per quadrature point, Warp array (M, Q, terms) of mat33d, Pa (terms: the
            most of any problem).
        elastic_stress: S0 of the last converged step, Warp array (M, Q) of mat33d, Pa.
        frozen: The step's fixed history stress Q, Warp array (M, Q) of mat33d, Pa.
        steps: Each problem's current ``ViscousStep`` (``gamma``, ``a_i``, ``b_i``), a Warp
            array (K,).
        dt_s: Each problem's current step length, (K,), s.
        names: The parameters whose history derivatives are carried
            (:meth:`track_sensitivities`).
    """

    def __init__(
        self,
        materials: Material | Sequence[Material],
        *,
        element_problem: np.ndarray | None = None,
        tet_count: int,
        quadrature_points: int,
        device: object,
    ) -> None:
        materials = (materials,) if isinstance(materials, Material) else tuple(materials)
        if not any(isinstance(material, Viscoelastic) for material in materials):
            raise InputError("a viscous history needs a viscoelastic material", value=materials)
        self.materials = materials
        self.device = device
        self._shape = (tet_count, quadrature_points)
        problems = (
            np.zeros(tet_count, dtype=np.int32) if element_problem is None else element_problem
        )
        self._element_problem = wp.array(np.asarray(problems, dtype=np.int32), device=device)
        self._terms = max(_term_count(material) for material in materials)
        self.history = wp.zeros((*self._shape, self._terms), dtype=wp.mat33d, device=device)
        self.elastic_stress = wp.zeros(self._shape, dtype=wp.mat33d, device=device)
        self.frozen = wp.zeros(self._shape, dtype=wp.mat33d, device=device)
        self.names: tuple[str, ...] = ()
        self._d_history = wp.zeros((1, 1, 1, 1), dtype=wp.mat33d, device=device)
        self._d_elastic_stress = wp.zeros((1, 1, 1), dtype=wp.mat33d, device=device)
        self.reset()

    @property
    def material(self) -> Material:
        """The material of a history of one problem."""
        if len(self.materials) != 1:
            raise InputError(
                f"this history holds {len(self.materials)} problems' materials",
                key="materials",
                value=len(self.materials),
            )
        return self.materials[0]

    def term_counts(self) -> tuple[int, ...]:
        """Each problem's number of Prony terms (0 for an elastic material)."""
        return tuple(_term_count(material) for material in self.materials)

    def reset(self, materials: Material | Sequence[Material] | None = None) -> None:
        """Back to the undeformed, unloaded state at t = 0 (optionally with new materials of
        the same numbers of terms)."""
        if materials is not None:
            materials = (materials,) if isinstance(materials, Material) else tuple(materials)
            counts = tuple(_term_count(material) for material in materials)
            if counts != self.term_counts():
                raise InputError(
                    "the new materials have other numbers of Prony terms",
                    value=(counts, self.term_counts()),
                )
            self.materials = materials
        self.history.zero_()
        self.elastic_stress.zero_()
        self.frozen.zero_()
        self._d_history.zero_()
        self._d_elastic_stress.zero_()
        self.dt_s = np.full(len(self.materials), math.nan)
        self._set_steps(
            [
                _step_struct(1.0, [1.0] * terms, [0.0] * terms) if terms else elastic_step()
                for terms in self.term_counts()
            ]
        )

    def _set_steps(self, steps: list[object]) -> None:
        self._step_list = steps
        self.steps = wp.array(steps, dtype=ViscousStep, device=self.device)

    def gamma(self, problem: int = 0) -> float:
        """The weight ``gamma`` of the current elastic stress in problem ``problem``'s step."""
        return float(self._step_list[problem].gamma)

    def track_sensitivities(self, names: Sequence[str]) -> None:
        """Carry the history's derivatives by these parameters from now on (zero now)."""
        self.names = tuple(names)
        count = max(len(self.names), 1)
        dev = self.device
        self._d_history = wp.zeros((count, *self._shape, self._terms), dtype=wp.mat33d, device=dev)
        self._d_elastic_stress = wp.zeros((count, *self._shape), dtype=wp.mat33d, device=dev)

    def begin_step(self, dt_s: float | np.ndarray) -> None:
        """Set the coefficients of a step of length ``dt_s`` (one per problem, (K,), or one
        for all) and its frozen history stress."""
        steps = np.broadcast_to(np.asarray(dt_s, dtype=np.float64), (len(self.materials),))
        if not (np.all(np.isfinite(steps)) and np.all(steps > 0.0)):
            raise InputError("a time step must be positive and finite", key="times_s", value=dt_s)
        structs = []
        for material, dt in zip(self.materials, steps, strict=True):
            if isinstance(material, Viscoelastic):
                structs.append(_step_struct(*_coefficients(material, float(dt))))
            else:
                structs.append(elastic_step())
        self.dt_s = steps.copy()
        self._set_steps(structs)
        wp.launch(
            kv.viscous_frozen_kernel,
            dim=self._shape,
            inputs=[self._element_problem, self.steps, self.history, self.elastic_stress],
            outputs=[self.frozen],
            device=self.device,
        )

    def stress_state(self) -> tuple[wp.array, wp.array]:
        """``(steps, frozen)`` giving the committed stress ``g_inf S0 + sum_i H_i`` (for the
        stress output after a step: the assembly kernels read it as ``gamma S0 + Q``)."""
        structs = [
            _step_struct(material.long_term_factor, [1.0] * terms, [0.0] * terms)
            if isinstance(material, Viscoelastic)
            else elastic_step()
            for material, terms in zip(self.materials, self.term_counts(), strict=True)
        ]
        steps = wp.array(structs, dtype=ViscousStep, device=self.device)
        total = wp.zeros(self._shape, dtype=wp.mat33d, device=self.device)
        wp.launch(
            kv.viscous_frozen_kernel,
            dim=self._shape,
            inputs=[self._element_problem, steps, self.history, self.elastic_stress],
            outputs=[total],
            device=self.device,
        )
        return steps, total

    def _committed(self, problems: np.ndarray | None) -> wp.array:
        """The problems to advance as a Warp int32 mask (None: all)."""
        mask = np.ones(len(self.materials), dtype=np.int32)
        if problems is not None:
            mask = np.asarray(problems, dtype=bool).astype(np.int32)
        return wp.array(mask, dtype=wp.int32, device=self.device)

    def commit(
        self, assembler: object, displacement: wp.array, problems: np.ndarray | None = None
    ) -> None:
        """Advance H_i and S0_prev to a converged step (after its sensitivities), in the
        problems ``problems`` ((K,) booleans; None: all)."""
        wp.launch(
            kv.viscous_commit_kernel,
            dim=self._shape,
            inputs=[
                assembler._problem_params,
                self._element_problem,
                self._committed(problems),
                assembler._tets,
                assembler._shape_gradients,
                displacement,
                self.steps,
                self.history,
                self.elastic_stress,
            ],
            device=self.device,
        )

    def step_derivatives(self, name: str) -> wp.array:
        """Each problem's ``ViscousStep`` holding ``dgamma, da_i, db_i`` by one parameter for
        this step, a Warp array (K,) (zero where ``name`` is not a Prony parameter)."""
        structs = []
        for material, terms, dt in zip(self.materials, self.term_counts(), self.dt_s, strict=True):
            d_gamma, d_a, d_b = 0.0, np.zeros(terms), np.zeros(terms)
            which = material.prony_derivative(name) if isinstance(material, Viscoelastic) else None
            if which is not None:
                kind, i = which
                g, tau = material.g[i], material.tau_s[i]
                x = dt / tau
                a = math.exp(-x)
                if kind == "g":
                    d_b[i] = -math.expm1(-x) / x if x > 1e-8 else 1.0 - 0.5 * x
                    d_gamma = d_b[i] - 1.0
                else:
                    d_a[i] = a * x / tau
                    d_b[i] = g * (-math.expm1(-x) / dt - a / tau)
                    d_gamma = d_b[i]
            structs.append(_step_struct(d_gamma, d_a, d_b) if terms else elastic_step())
        return wp.array(structs, dtype=ViscousStep, device=self.device)

    def history_residual(
        self, assembler: object, displacement: wp.array, name: str, residual: wp.array
    ) -> None:
        """Add the history's part of ``dR/d name`` at fixed u into ``residual`` (N)."""
        wp.launch(
            kv.viscous_history_residual_kernel,
            dim=self._shape[0],
            inputs=[
                assembler._problem_params,
                self._element_problem,
                assembler._tets,
                assembler._shape_gradients,
                assembler._quadrature_volumes,
                displacement,
                self.steps,
                self.step_derivatives(name),
                self.history,
                self.elastic_stress,
                self._d_history,
                self._d_elastic_stress,
                self.names.index(name),
            ],
            outputs=[residual],
            device=self.device,
        )

    def commit_sensitivity(
        self,
        assembler: object,
        displacement: wp.array,
        d_displacement: np.ndarray,
        name: str,
        problems: np.ndarray | None = None,
    ) -> None:
        """Advance the history's derivatives by ``name`` with the step's ``du/d name``
        (before :meth:`commit`), in the problems ``problems`` ((K,); None: all)."""
        derivatives, explicit, alpha_term = [], [], -1
        for material in self.materials:
            d_params, alpha_term = material.device_params_derivative(name)
            derivatives.append(d_params)
            prony = isinstance(material, Viscoelastic) and material.prony_derivative(name)
            explicit.append(int(not prony))
        wp.launch(
            kv.viscous_sensitivity_commit_kernel,
            dim=self._shape,
            inputs=[
                assembler._problem_params,
                wp.array(derivatives, dtype=MaterialParams, device=self.device),
                wp.array(explicit, dtype=wp.int32, device=self.device),
                alpha_term,
                self._element_problem,
                self._committed(problems),
                assembler._tets,
                assembler._shape_gradients,
                displacement,
                wp.array(d_displacement, dtype=wp.vec3d, device=self.device),
                self.steps,
                self.step_derivatives(name),
                self.history,
                self.elastic_stress,
                self._d_history,
                self._d_elastic_stress,
                self.names.index(name),
            ],
            device=self.device,
        )


def _term_count(material: Material) -> int:
    """Prony terms of a material (0 for an elastic one)."""
    return material.term_count if isinstance(material, Viscoelastic) else 0
