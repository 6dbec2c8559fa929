"""The invariant models, linear in their parameters: neo-Hookean, Mooney-Rivlin and the
reduced polynomial (Yeoh is its order 3)."""

from __future__ import annotations

import abc
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from warptissue.errors import InputError
from warptissue.materials._base import (
    MAX_TERMS,
    HyperelasticMaterial,
    check_finite,
    check_positive,
    check_terms,
    optional_bulk_modulus,
    principal_stretches,
    with_bulk,
)


class _InvariantModel(HyperelasticMaterial):
    """Models W(I1, I2) that are linear in their parameters."""

    @abc.abstractmethod
    def _basis(self, i1: np.ndarray, i2: np.ndarray) -> tuple[np.ndarray, ...]:
        """Per parameter k: (dW1/dp_k, dW2/dp_k, d2W/dI1^2 / p_k, ...) as arrays (m, n).

        Returns (a, b, a11, a12, a22, w) with W1 = a @ p, W2 = b @ p, W11 = a11 @ p,
        W12 = a12 @ p, W22 = a22 @ p and W = w @ p; each of shape (..., n).
        """

    def energy_density_Pa(self, stretches: np.ndarray) -> np.ndarray:
        squares = np.asarray(stretches, dtype=np.float64) ** 2
        i1 = squares.sum(axis=-1)
        i2 = (1.0 / squares).sum(axis=-1)
        return self._basis(i1, i2)[5] @ self.parameter_vector

    def nominal_stress_gradient(self, stretch: np.ndarray, mode: str) -> np.ndarray:
        lam = np.atleast_1d(np.asarray(stretch, dtype=np.float64))
        squares = principal_stretches(lam, mode) ** 2
        i1 = squares.sum(axis=-1)
        i2 = (1.0 / squares).sum(axis=-1)
        a, b = self._basis(i1, i2)[:2]
        if mode == "uniaxial":
            factor_1, factor_2 = 2.0 * (lam - lam**-2), 2.0 * (1.0 - lam**-3)
        elif mode == "equibiaxial":
            factor_1 = 2.0 * (lam - lam**-5)
            factor_2 = factor_1 * lam**2
        else:
            factor_1 = factor_2 = 2.0 * (lam - lam**-3)
        return factor_1[:, None] * a + factor_2[:, None] * b

    def nominal_stress_Pa(self, stretch: np.ndarray, mode: str) -> np.ndarray:
        lam = np.atleast_1d(np.asarray(stretch, dtype=np.float64))
        return self.nominal_stress_gradient(lam, mode) @ self.parameter_vector

    def principal_log_strain_hessian(self, log_strains: np.ndarray) -> np.ndarray:
        strains = np.atleast_2d(np.asarray(log_strains, dtype=np.float64))
        squares = np.exp(2.0 * strains)
        inverse_squares = 1.0 / squares
        i1, i2 = squares.sum(axis=-1), inverse_squares.sum(axis=-1)
        grad_i1, grad_i2 = 2.0 * squares, -2.0 * inverse_squares
        a, b, a11, a12, a22, _ = self._basis(i1, i2)
        p = self.parameter_vector
        w1, w2, w11, w12, w22 = a @ p, b @ p, a11 @ p, a12 @ p, a22 @ p

        def outer(u: np.ndarray, v: np.ndarray) -> np.ndarray:
            return u[:, :, None] * v[:, None, :]

        diagonal = 4.0 * (w1[:, None] * squares + w2[:, None] * inverse_squares)
        return (
            w11[:, None, None] * outer(grad_i1, grad_i1)
            + w12[:, None, None] * (outer(grad_i1, grad_i2) + outer(grad_i2, grad_i1))
            + w22[:, None, None] * outer(grad_i2, grad_i2)
            + diagonal[:, :, None] * np.eye(3)
        )

    def start_parameters(
        self, design: Callable[[HyperelasticMaterial], np.ndarray], data: np.ndarray
    ) -> np.ndarray:
        """Linear least squares: the predictions are linear in the parameters."""
        start, *_ = np.linalg.lstsq(design(self), data, rcond=None)
        return start


@dataclass(frozen=True)
class ReducedPolynomial(_InvariantModel):
    """Reduced polynomial ``W = sum_i Ci0 (I1b - 3)^i + (J - 1)^2 / D1``.

    Args:
        C_Pa: ``(C10, C20, ..., CN0)``, Pa, 1 <= N <= 6. One term is neo-Hookean; three are
            Yeoh. With a bulk modulus, ``C10 > 0``.
        bulk_modulus_Pa: K = 2 / D1, Pa, > 0; None: incompressible.
    """

    C_Pa: tuple[float, ...]
    bulk_modulus_Pa: float | None = None

    model_name: ClassVar[str] = "reduced_polynomial"

    def __post_init__(self) -> None:
        object.__setattr__(self, "C_Pa", check_terms("C_Pa", self.C_Pa))
        if self.bulk_modulus_Pa is not None:
            check_positive("C10_Pa", self.C_Pa[0])
        object.__setattr__(self, "bulk_modulus_Pa", optional_bulk_modulus(self.bulk_modulus_Pa))

    @property
    def order(self) -> int:
        """N, the number of Ci0 terms."""
        return len(self.C_Pa)

    @property
    def initial_shear_modulus_Pa(self) -> float:
        return 2.0 * self.C_Pa[0]

    def _flat_parameters(self) -> dict[str, float]:
        out = {f"C{i + 1}0_Pa": c for i, c in enumerate(self.C_Pa)}
        return with_bulk(out, self.bulk_modulus_Pa)

    @classmethod
    def _from_flat(cls, values: Mapping[str, float]) -> ReducedPolynomial:
        order = sum(1 for key in values if key != "bulk_modulus_Pa")
        return cls(
            tuple(values[f"C{i + 1}0_Pa"] for i in range(order)), values.get("bulk_modulus_Pa")
        )

    def _basis(self, i1: np.ndarray, i2: np.ndarray) -> tuple[np.ndarray, ...]:
        x = np.asarray(i1) - 3.0
        powers = np.arange(1, self.order + 1)
        zero = np.zeros(x.shape + (self.order,))
        w = x[..., None] ** powers
        a = powers * x[..., None] ** (powers - 1)
        a11 = powers * (powers - 1) * x[..., None] ** np.maximum(powers - 2, 0)
        return a, zero, a11, zero, zero, w

    def _fill_device_params(self, params: Any, km: Any) -> None:
        params.polynomial_terms = self.order
        params.c_i0 = km.vec6d(*self.C_Pa, *([0.0] * (MAX_TERMS - self.order)))

    def _shear_modulus_of(self, flat: Mapping[str, float]) -> float:
        return 2.0 * flat["C10_Pa"]


@dataclass(frozen=True)
class NeoHookean(_InvariantModel):
    """Neo-Hookean ``W = C10 (I1b - 3) + (J - 1)^2 / D1``, initial shear modulus 2 C10.

    Args:
        C10_Pa: Pa; > 0 with a bulk modulus.
        bulk_modulus_Pa: K = 2 / D1, Pa, > 0; None: incompressible.
    """

    C10_Pa: float
    bulk_modulus_Pa: float | None = None

    model_name: ClassVar[str] = "neo_hookean"

    def __post_init__(self) -> None:
        check = check_finite if self.bulk_modulus_Pa is None else check_positive
        object.__setattr__(self, "C10_Pa", check("C10_Pa", self.C10_Pa))
        object.__setattr__(self, "bulk_modulus_Pa", optional_bulk_modulus(self.bulk_modulus_Pa))

    @property
    def initial_shear_modulus_Pa(self) -> float:
        return 2.0 * self.C10_Pa

    def _flat_parameters(self) -> dict[str, float]:
        return with_bulk({"C10_Pa": self.C10_Pa}, self.bulk_modulus_Pa)

    @classmethod
    def _from_flat(cls, values: Mapping[str, float]) -> NeoHookean:
        return cls(values["C10_Pa"], values.get("bulk_modulus_Pa"))

    def _basis(self, i1: np.ndarray, i2: np.ndarray) -> tuple[np.ndarray, ...]:
        return ReducedPolynomial((self.C10_Pa,))._basis(i1, i2)

    def _fill_device_params(self, params: Any, km: Any) -> None:
        params.polynomial_terms = 1
        params.c_i0 = km.vec6d(self.C10_Pa, 0.0, 0.0, 0.0, 0.0, 0.0)

    def _shear_modulus_of(self, flat: Mapping[str, float]) -> float:
        return 2.0 * flat["C10_Pa"]


@dataclass(frozen=True)
class MooneyRivlin(_InvariantModel):
    """Mooney-Rivlin ``W = C10 (I1b - 3) + C01 (I2b - 3) + (J - 1)^2 / D1``.

    Args:
        C10_Pa: Pa (may be negative, as fits sometimes give; the needle-indentation study,
            Table 1).
        C01_Pa: Pa. With a bulk modulus, ``C10 + C01`` must be positive.
        bulk_modulus_Pa: K = 2 / D1, Pa, > 0; None: incompressible.
    """

    C10_Pa: float
    C01_Pa: float
    bulk_modulus_Pa: float | None = None

    model_name: ClassVar[str] = "mooney_rivlin"

    def __post_init__(self) -> None:
        object.__setattr__(self, "C10_Pa", check_finite("C10_Pa", self.C10_Pa))
        object.__setattr__(self, "C01_Pa", check_finite("C01_Pa", self.C01_Pa))
        object.__setattr__(self, "bulk_modulus_Pa", optional_bulk_modulus(self.bulk_modulus_Pa))
        if self.bulk_modulus_Pa is not None and self.C10_Pa + self.C01_Pa <= 0.0:
            raise InputError(
                "C10_Pa + C01_Pa must be positive (initial shear modulus 2 (C10 + C01))",
                key="C01_Pa",
                value=self.C01_Pa,
            )

    @property
    def initial_shear_modulus_Pa(self) -> float:
        return 2.0 * (self.C10_Pa + self.C01_Pa)

    def _flat_parameters(self) -> dict[str, float]:
        return with_bulk({"C10_Pa": self.C10_Pa, "C01_Pa": self.C01_Pa}, self.bulk_modulus_Pa)

    @classmethod
    def _from_flat(cls, values: Mapping[str, float]) -> MooneyRivlin:
        return cls(values["C10_Pa"], values["C01_Pa"], values.get("bulk_modulus_Pa"))

    def _basis(self, i1: np.ndarray, i2: np.ndarray) -> tuple[np.ndarray, ...]:
        ones = np.ones(np.shape(i1))
        zeros = np.zeros(np.shape(i1) + (2,))
        a = np.stack([ones, 0.0 * ones], axis=-1)
        b = np.stack([0.0 * ones, ones], axis=-1)
        w = np.stack([np.asarray(i1) - 3.0, np.asarray(i2) - 3.0], axis=-1)
        return a, b, zeros, zeros, zeros, w

    def _fill_device_params(self, params: Any, km: Any) -> None:
        params.polynomial_terms = 1
        params.c_i0 = km.vec6d(self.C10_Pa, 0.0, 0.0, 0.0, 0.0, 0.0)
        params.c01 = self.C01_Pa

    def _shear_modulus_of(self, flat: Mapping[str, float]) -> float:
        return 2.0 * (flat["C10_Pa"] + flat["C01_Pa"])


def Yeoh(  # noqa: N802 (a constructor named like the model)
    C10_Pa: float, C20_Pa: float, C30_Pa: float, bulk_modulus_Pa: float | None = None
) -> ReducedPolynomial:
    """Yeoh: the reduced polynomial of order 3.

    Args:
        C10_Pa, C20_Pa, C30_Pa: Pa.
        bulk_modulus_Pa: Pa; None: incompressible.
    """
    return ReducedPolynomial((C10_Pa, C20_Pa, C30_Pa), bulk_modulus_Pa)
