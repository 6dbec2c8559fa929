"""The Ogden model: principal stretches, nonlinear in its exponents alpha_i."""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from warptissue.errors import InputError
from warptissue.materials._base import (
    MAX_TERMS,
    HyperelasticMaterial,
    check_mode,
    check_terms,
    optional_bulk_modulus,
    with_bulk,
)

_OGDEN_K = {"uniaxial": 0.5, "equibiaxial": 2.0, "planar": 1.0}
"""Ogden nominal stress exponent k of each mode (module Notes)."""

_OGDEN_START_ALPHAS = (-12.0, -8.0, -5.0, -3.0, -2.0, -1.0, 1.0, 2.0, 3.0, 5.0, 8.0, 12.0, 20.0)
"""The grid of alpha values that :meth:`Ogden.start_parameters` tries."""


@dataclass(frozen=True)
class Ogden(HyperelasticMaterial):
    """Ogden ``W = sum_i 2 mu_i / alpha_i^2 (l1b^alpha_i + l2b^alpha_i + l3b^alpha_i - 3)``.

    Plus ``(J - 1)^2 / D1``; ``lb`` are isochoric principal stretches (Abaqus convention);
    mu0 = sum mu_i. The parameter vector is (mu1, alpha1, mu2, alpha2, ...).

    Args:
        mu_Pa: ``(mu_1, ..., mu_N)``, Pa, 1 <= N <= 6; with a bulk modulus ``sum mu_i > 0``.
        alpha: ``(alpha_1, ..., alpha_N)``, nonzero.
        bulk_modulus_Pa: K = 2 / D1, Pa, > 0; None: incompressible.
    """

    mu_Pa: tuple[float, ...]
    alpha: tuple[float, ...]
    bulk_modulus_Pa: float | None = None

    model_name: ClassVar[str] = "ogden"
    _device_model: ClassVar[int] = 1

    def __post_init__(self) -> None:
        object.__setattr__(self, "mu_Pa", check_terms("mu_Pa", self.mu_Pa))
        object.__setattr__(self, "alpha", check_terms("alpha", self.alpha))
        if len(self.mu_Pa) != len(self.alpha):
            raise InputError(
                f"mu_Pa has {len(self.mu_Pa)} terms but alpha has {len(self.alpha)}",
                key="alpha",
                value=self.alpha,
            )
        for i, a in enumerate(self.alpha):
            if a == 0.0:
                raise InputError("must be nonzero", key=f"alpha{i + 1}", value=a)
        if self.bulk_modulus_Pa is not None and sum(self.mu_Pa) <= 0.0:
            raise InputError(
                "sum of mu_i must be positive (initial shear modulus)",
                key="mu_Pa",
                value=self.mu_Pa,
            )
        object.__setattr__(self, "bulk_modulus_Pa", optional_bulk_modulus(self.bulk_modulus_Pa))

    @property
    def order(self) -> int:
        """N, the number of Ogden terms."""
        return len(self.mu_Pa)

    @property
    def initial_shear_modulus_Pa(self) -> float:
        return float(sum(self.mu_Pa))

    def _flat_parameters(self) -> dict[str, float]:
        out: dict[str, float] = {}
        for i, (mu, a) in enumerate(zip(self.mu_Pa, self.alpha, strict=True)):
            out[f"mu{i + 1}_Pa"] = mu
            out[f"alpha{i + 1}"] = a
        return with_bulk(out, self.bulk_modulus_Pa)

    @classmethod
    def _from_flat(cls, values: Mapping[str, float]) -> Ogden:
        order = sum(1 for key in values if key.startswith("mu"))
        return cls(
            tuple(values[f"mu{i + 1}_Pa"] for i in range(order)),
            tuple(values[f"alpha{i + 1}"] for i in range(order)),
            values.get("bulk_modulus_Pa"),
        )

    def energy_density_Pa(self, stretches: np.ndarray) -> np.ndarray:
        lam = np.asarray(stretches, dtype=np.float64)
        return sum(
            2.0 * mu / a**2 * (np.sum(lam**a, axis=-1) - 3.0)
            for mu, a in zip(self.mu_Pa, self.alpha, strict=True)
        )

    def nominal_stress_Pa(self, stretch: np.ndarray, mode: str) -> np.ndarray:
        lam = np.atleast_1d(np.asarray(stretch, dtype=np.float64))
        k = _OGDEN_K[check_mode(mode)]
        return sum(
            2.0 * mu / a * (lam ** (a - 1.0) - lam ** (-k * a - 1.0))
            for mu, a in zip(self.mu_Pa, self.alpha, strict=True)
        )

    def nominal_stress_gradient(self, stretch: np.ndarray, mode: str) -> np.ndarray:
        lam = np.atleast_1d(np.asarray(stretch, dtype=np.float64))
        k = _OGDEN_K[check_mode(mode)]
        log_lam = np.log(lam)
        columns = []
        for mu, a in zip(self.mu_Pa, self.alpha, strict=True):
            up, down = lam ** (a - 1.0), lam ** (-k * a - 1.0)
            columns.append(2.0 / a * (up - down))
            columns.append(
                -2.0 * mu / a**2 * (up - down) + 2.0 * mu / a * log_lam * (up + k * down)
            )
        return np.column_stack(columns)

    def principal_log_strain_hessian(self, log_strains: np.ndarray) -> np.ndarray:
        strains = np.atleast_2d(np.asarray(log_strains, dtype=np.float64))
        curvature = sum(
            2.0 * mu * np.exp(a * strains) for mu, a in zip(self.mu_Pa, self.alpha, strict=True)
        )
        return curvature[:, :, None] * np.eye(3)

    def start_parameters(
        self, design: Callable[[HyperelasticMaterial], np.ndarray], data: np.ndarray
    ) -> np.ndarray:
        """The best (mu, alpha) on a grid of alphas, with mu solved linearly for each (the
        model is linear in mu at fixed alpha)."""
        best, best_cost = None, math.inf
        for alphas in itertools.combinations(_OGDEN_START_ALPHAS, self.order):
            trial = Ogden((1.0,) * self.order, alphas)
            with np.errstate(over="ignore", invalid="ignore"):
                gradient = design(trial)[:, 0::2]
            if not np.all(np.isfinite(gradient)):
                continue
            mu, *_ = np.linalg.lstsq(gradient, data, rcond=None)
            cost = float(np.sum((gradient @ mu - data) ** 2))
            if cost < best_cost:
                best, best_cost = np.ravel(np.column_stack([mu, alphas])), cost
        if best is None:
            raise InputError("no Ogden starting point gives finite stresses for these data")
        return best

    def _fill_device_params(self, params: Any, km: Any) -> None:
        pad = [0.0] * (MAX_TERMS - self.order)
        params.ogden_terms = self.order
        params.ogden_mu = km.vec6d(*self.mu_Pa, *pad)
        params.ogden_alpha = km.vec6d(*self.alpha, *pad)

    def _shear_modulus_of(self, flat: Mapping[str, float]) -> float:
        return sum(flat[f"mu{i + 1}_Pa"] for i in range(self.order))
