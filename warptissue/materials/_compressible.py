"""The compressible models of the FE only (no incompressible closed forms): the
compressible neo-Hookean and small-strain linear elasticity."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import ClassVar

from warptissue.errors import InputError
from warptissue.materials._base import Material, check_finite, check_positive


@dataclass(frozen=True)
class CompressibleNeoHookean(Material):
    """Compressible neo-Hookean ``W = mu/2 (I1 - 3) - mu ln J + lambda/2 (ln J)^2``.

    Args:
        shear_modulus_Pa: mu, Pa, > 0.
        bulk_modulus_Pa: K, Pa, > 2 mu / 3 (so that lambda = K - 2 mu / 3 > 0).
    """

    shear_modulus_Pa: float
    bulk_modulus_Pa: float

    model_name: ClassVar[str] = "compressible_neo_hookean"
    _device_model: ClassVar[int] = 2
    _bounds: ClassVar[Mapping[str, tuple[float, float]]] = {
        "shear_modulus_Pa": (0.0, math.inf),
        "bulk_modulus_Pa": (0.0, math.inf),
    }

    def __post_init__(self) -> None:
        for f in fields(self):
            object.__setattr__(self, f.name, check_positive(f.name, getattr(self, f.name)))
        if self.bulk_modulus_Pa <= 2.0 * self.shear_modulus_Pa / 3.0:
            raise InputError(
                "bulk_modulus_Pa must exceed 2/3 shear_modulus_Pa (Poisson's ratio > 0)",
                key="bulk_modulus_Pa",
                value=self.bulk_modulus_Pa,
            )

    @property
    def initial_shear_modulus_Pa(self) -> float:
        return self.shear_modulus_Pa

    def _flat_parameters(self) -> dict[str, float]:
        return {"shear_modulus_Pa": self.shear_modulus_Pa, "bulk_modulus_Pa": self.bulk_modulus_Pa}

    def _shear_modulus_of(self, flat: Mapping[str, float]) -> float:
        return flat["shear_modulus_Pa"]

    @classmethod
    def _from_flat(cls, values: Mapping[str, float]) -> CompressibleNeoHookean:
        return cls(values["shear_modulus_Pa"], values["bulk_modulus_Pa"])


@dataclass(frozen=True)
class LinearElastic(Material):
    """Small-strain isotropic linear elasticity (not frame invariant: small rotations only).

    Args:
        youngs_modulus_Pa: E, Pa, > 0.
        poissons_ratio: nu, -1 < nu < 0.5.
    """

    youngs_modulus_Pa: float
    poissons_ratio: float

    model_name: ClassVar[str] = "linear_elastic"
    _device_model: ClassVar[int] = 3
    _bounds: ClassVar[Mapping[str, tuple[float, float]]] = {
        "youngs_modulus_Pa": (0.0, math.inf),
        "poissons_ratio": (-1.0, 0.5),
    }

    def __post_init__(self) -> None:
        object.__setattr__(
            self,
            "youngs_modulus_Pa",
            check_positive("youngs_modulus_Pa", self.youngs_modulus_Pa),
        )
        nu = check_finite("poissons_ratio", self.poissons_ratio)
        if not -1.0 < nu < 0.5:
            raise InputError("must lie in (-1, 0.5)", key="poissons_ratio", value=nu)
        object.__setattr__(self, "poissons_ratio", nu)

    @property
    def initial_shear_modulus_Pa(self) -> float:
        return self.youngs_modulus_Pa / (2.0 * (1.0 + self.poissons_ratio))

    @property
    def bulk_modulus(self) -> float:
        return self.youngs_modulus_Pa / (3.0 * (1.0 - 2.0 * self.poissons_ratio))

    def small_strain_equivalent(self) -> tuple[float, float]:
        return self.youngs_modulus_Pa, self.poissons_ratio

    def _flat_parameters(self) -> dict[str, float]:
        return {"youngs_modulus_Pa": self.youngs_modulus_Pa, "poissons_ratio": self.poissons_ratio}

    def moduli_derivative(self, name: str) -> tuple[float, float]:
        """mu = E / (2 (1 + nu)) and K = E / (3 (1 - 2 nu)) differentiated by E or nu."""
        e, nu = self.youngs_modulus_Pa, self.poissons_ratio
        if name == "youngs_modulus_Pa":
            return 1.0 / (2.0 * (1.0 + nu)), 1.0 / (3.0 * (1.0 - 2.0 * nu))
        return -e / (2.0 * (1.0 + nu) ** 2), 2.0 * e / (3.0 * (1.0 - 2.0 * nu) ** 2)

    @classmethod
    def _from_flat(cls, values: Mapping[str, float]) -> LinearElastic:
        return cls(values["youngs_modulus_Pa"], values["poissons_ratio"])


@dataclass(frozen=True)
class StableNeoHookean(LinearElastic):
    """Stable neo-Hookean ``W = mu/2 (I1 - 3) + lambda_nh/2 (J - alpha)^2``: the tet energy of
    NVIDIA Newton's VBD solver, the model a trainer's linear tets run.

    Args:
        youngs_modulus_Pa: E, Pa, > 0 (what a simulator reads as ``physics:youngsModulus``).
        poissons_ratio: nu, -1 < nu < 0.5 (``physics:poissonsRatio``).

    Notes:
        Smith, de Goes and Kim (2018), with Newton's Lame matching (its Eq. 13):
        ``mu = E / (2 (1 + nu))``, ``lambda = E nu / ((1 + nu)(1 - 2 nu))``,
        ``lambda_nh = lambda + mu`` and ``alpha = 1 + mu / lambda_nh``, so that the rest
        state is stress free and the small-strain limit is linear elasticity with E and nu:
        ``P = mu F + lambda_nh (J - alpha) cof F``. Newton drops the log barrier of the
        paper, and so does this model. :mod:`warptissue.trainer` calibrates E and nu of this
        model on a trainer's mesh.
    """

    model_name: ClassVar[str] = "stable_neo_hookean"
    _device_model: ClassVar[int] = 4
