"""Quasi-linear viscoelasticity: a hyperelastic model with a Prony series."""

from __future__ import annotations

import difflib
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from warptissue.errors import InputError
from warptissue.kernels import materials as km
from warptissue.materials._base import (
    MAX_TERMS,
    HyperelasticMaterial,
    Material,
    check_finite,
    check_positive,
)
from warptissue.materials._rules import prony_term


@dataclass(frozen=True)
class Viscoelastic(Material):
    """Quasi-linear viscoelasticity: a hyperelastic model whose deviatoric stress relaxes.

    The deviatoric (isochoric) second Piola-Kirchhoff stress of the hyperelastic model,
    ``S0_dev(t)``, is convolved with the normalized Prony series; the volumetric stress is
    elastic::

        S(t) = S_vol(t) + int_0^t G(t - s) dS0_dev/ds ds,
        G(t) = 1 - sum_i g_i (1 - exp(-t / tau_i))

    (Ahn & Kim, Eq. 1-2, with the sign of Eq. 5 corrected; Abaqus's normalization: the
    instantaneous response is the hyperelastic model, the long-term one is scaled by
    ``g_inf = 1 - sum g_i``). This is FEBio's "uncoupled viscoelastic" material and, at small
    strain, Abaqus's time-domain Prony series on a hyperelastic model (Abaqus relaxes the
    Kirchhoff stress with a push-forward that differs at finite strain; docs/fe.md).

    Args:
        elastic: The instantaneous hyperelastic response, with a bulk modulus for the FE.
        g: Normalized Prony coefficients ``g_i >= 0`` with ``sum g_i < 1``.
        tau_s: Relaxation times ``tau_i > 0``, s.

    Notes:
        The FE keeps, per quadrature point, the deviatoric elastic stress of the last
        converged step and one history tensor per term, updated by the recursive convolution
        ``H_i(t_n) = exp(-dt/tau_i) H_i(t_n-1) + g_i tau_i/dt (1 - exp(-dt/tau_i))
        (S0(t_n) - S0(t_n-1))``, exact for stresses linear in time over a step
        (:mod:`warptissue.fem.viscous`). Parameters: the elastic model's, then ``g1..gN``,
        ``tau1_s..tauN_s``.
    """

    elastic: HyperelasticMaterial
    g: tuple[float, ...]
    tau_s: tuple[float, ...]

    def __post_init__(self) -> None:
        if not isinstance(self.elastic, HyperelasticMaterial):
            raise InputError(
                "the elastic response of a viscoelastic material must be one of the "
                "hyperelastic models (neo_hookean, mooney_rivlin, reduced_polynomial, ogden)",
                key="model",
                value=getattr(self.elastic, "model_name", type(self.elastic).__name__),
            )
        g = tuple(check_finite(f"g{i + 1}", v) for i, v in enumerate(self.g))
        tau = tuple(check_positive(f"tau{i + 1}_s", v) for i, v in enumerate(self.tau_s))
        if len(g) != len(tau) or not g:
            raise InputError(
                "a Prony series needs one tau<i>_s per g<i>, at least one term",
                key="g1" if not g else f"tau{len(tau) + 1}_s" if len(g) > len(tau) else "g1",
                value=(len(g), len(tau)),
            )
        if len(g) > MAX_TERMS:
            raise InputError(f"at most {MAX_TERMS} Prony terms", key="g1", value=len(g))
        for i, v in enumerate(g):
            if v < 0.0:
                raise InputError("must be >= 0", key=f"g{i + 1}", value=v)
        if not sum(g) < 1.0:
            raise InputError(
                "the Prony coefficients must sum to less than 1 (g_inf = 1 - sum g_i > 0)",
                key="g1",
                value=sum(g),
            )
        object.__setattr__(self, "g", g)
        object.__setattr__(self, "tau_s", tau)

    @property
    def model_name(self) -> str:  # type: ignore[override]
        """The elastic model's name (the Prony keys mark the material viscoelastic)."""
        return self.elastic.model_name

    @property
    def term_count(self) -> int:
        """Number of Prony terms."""
        return len(self.g)

    @property
    def long_term_factor(self) -> float:
        """``g_inf = 1 - sum g_i``: the long-term share of the deviatoric stress."""
        return 1.0 - sum(self.g)

    def reduced_relaxation(self, time_s: np.ndarray | float) -> np.ndarray:
        """``G(t) = 1 - sum g_i (1 - exp(-t / tau_i))``, shape of ``time_s``."""
        t = np.asarray(time_s, dtype=np.float64)
        out = np.ones_like(t)
        for g, tau in zip(self.g, self.tau_s, strict=True):
            out -= g * (1.0 - np.exp(-t / tau))
        return out

    @property
    def initial_shear_modulus_Pa(self) -> float:
        return self.elastic.initial_shear_modulus_Pa

    @property
    def bulk_modulus(self) -> float:
        return self.elastic.bulk_modulus

    @property
    def _fixed_keys(self) -> tuple[str, ...]:  # type: ignore[override]
        return self.elastic._fixed_keys

    def _prony_parameters(self) -> dict[str, float]:
        values = {f"g{i + 1}": v for i, v in enumerate(self.g)}
        values.update({f"tau{i + 1}_s": v for i, v in enumerate(self.tau_s)})
        return values

    def _flat_parameters(self) -> dict[str, float]:
        return {**self.elastic._flat_parameters(), **self._prony_parameters()}

    @property
    def parameter_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The elastic model's box, then ``0 <= g_i <= 1`` and ``1e-9 s <= tau_i``."""
        low, high = self.elastic.parameter_bounds
        n = self.term_count
        return (
            np.concatenate([low, np.zeros(n), np.full(n, 1e-9)]),
            np.concatenate([high, np.ones(n), np.full(n, np.inf)]),
        )

    def with_parameters(self, values: np.ndarray) -> Viscoelastic:
        """A copy with new fit parameters (:attr:`parameter_names` order); validated."""
        values = np.asarray(values, dtype=np.float64).ravel()
        names = self.parameter_names
        if values.shape != (len(names),):
            raise InputError(f"expected {len(names)} parameters {names}", value=values.tolist())
        k = len(self.elastic.parameter_names)
        n = self.term_count
        return Viscoelastic(
            self.elastic.with_parameters(values[:k]),
            tuple(values[k : k + n].tolist()),
            tuple(values[k + n :].tolist()),
        )

    def with_bulk_modulus(self, bulk_modulus_Pa: float | None) -> Viscoelastic:
        """A copy whose elastic response has bulk modulus K (Pa, > 0; None:
        incompressible); validated. The Prony series relaxes the deviatoric stress only, so
        K is the instantaneous and the long-term bulk modulus alike."""
        return Viscoelastic(self.elastic.with_bulk_modulus(bulk_modulus_Pa), self.g, self.tau_s)

    def with_prony(self, g: Sequence[float], tau_s: Sequence[float]) -> Viscoelastic:
        """A copy with another Prony series (same elastic response)."""
        return Viscoelastic(self.elastic, tuple(g), tuple(tau_s))

    def small_strain_equivalent(self) -> tuple[float, float]:
        """The instantaneous (elastic) Young's modulus and Poisson's ratio."""
        return self.elastic.small_strain_equivalent()

    def device_params(self) -> Any:
        """The elastic model's ``MaterialParams`` (the Prony series lives in the FE state)."""
        return self.elastic.device_params()

    def device_params_derivative(self, name: str) -> tuple[Any, int]:
        """As :meth:`Material.device_params_derivative`; for ``g<i>``/``tau<i>_s`` a zero
        struct (the elastic response does not depend on them; their derivative is the
        history's, :mod:`warptissue.fem.viscous`)."""
        if prony_term(name) is not None and name in self._prony_parameters():
            params, _ = self.elastic.device_params_derivative(self.elastic.sensitivity_names[0])
            return _zeroed(params), -1
        if name not in self.sensitivity_names:
            close = difflib.get_close_matches(name, self.sensitivity_names, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise InputError(
                f"viscoelastic {self.model_name} has no parameter {name!r}; it has "
                f"{', '.join(self.sensitivity_names)}{hint}",
                key="sensitivities",
                value=name,
            )
        return self.elastic.device_params_derivative(name)

    def prony_derivative(self, name: str) -> tuple[str, int] | None:
        """``("g" | "tau", term index)`` for a Prony parameter name, else None."""
        term = prony_term(name)
        if term is None or name not in self._prony_parameters():
            return None
        return term[0], term[1] - 1

    def moduli_derivative(self, name: str) -> tuple[float, float]:
        """The elastic model's (d mu0 / d name, d K / d name); (0, 0) for a Prony term."""
        if name in self._prony_parameters():
            return 0.0, 0.0
        return self.elastic.moduli_derivative(name)


def _zeroed(params: Any) -> Any:
    """A copy of a ``MaterialParams`` with every coefficient zero (model and counts kept)."""

    params.c_i0 = km.vec6d()
    params.c01 = 0.0
    params.ogden_mu = km.vec6d()
    params.bulk_modulus = 0.0
    params.shear_modulus = 0.0
    params.lame_lambda = 0.0
    return params
