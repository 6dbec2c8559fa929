"""Hyperelastic and linear elastic materials: parameters, validation, serialization.

Each model is a small frozen dataclass in SI units with Abaqus conventions (C10, C01, Ci0,
mu_i, alpha_i, D1 = 2/K). ``material.device_params()`` packs it into the
``warptissue.kernels.materials.MaterialParams`` struct that the FE kernels read, and
:func:`evaluate_material` evaluates energy, stress and tangent for a batch of deformation
gradients on any Warp device.

Notes:
    Energies (seed 003, Eq. 2; Abaqus Theory Manual 4.6.1), with isochoric invariants
    ``I1b = J^(-2/3) tr C``, ``I2b = J^(-4/3) (tr^2 C - tr C^2) / 2`` and
    ``U(J) = (J - 1)^2 / D1``:

    - ``NeoHookean``: ``W = C10 (I1b - 3) + U``, ``mu0 = 2 C10``.
    - ``MooneyRivlin``: ``W = C10 (I1b - 3) + C01 (I2b - 3) + U``, ``mu0 = 2 (C10 + C01)``.
    - ``ReducedPolynomial``: ``W = sum_i Ci0 (I1b - 3)^i + U``, ``mu0 = 2 C10``; Yeoh is N = 3.
      Seed 003 prints higher-order volumetric terms ``K_i/2 (J - 1)^(2i)``; only ``D1`` is used
      here, as for nearly incompressible fits in Abaqus.
    - ``Ogden``: ``W = sum_i 2 mu_i / alpha_i^2 (l1b^alpha_i + l2b^alpha_i + l3b^alpha_i - 3)
      + U``, ``mu0 = sum_i mu_i``.
    - ``CompressibleNeoHookean``: ``W = mu/2 (I1 - 3) - mu ln J + lambda/2 (ln J)^2`` with
      ``lambda = K - 2 mu / 3``.
    - ``LinearElastic``: small strain, ``W = mu eps:eps + lambda/2 (tr eps)^2``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any, ClassVar

import numpy as np
import warp as wp

from warptissue.device import resolve_device
from warptissue.errors import InputError

__all__ = [
    "CompressibleNeoHookean",
    "LinearElastic",
    "Material",
    "MaterialEvaluation",
    "MooneyRivlin",
    "NeoHookean",
    "Ogden",
    "ReducedPolynomial",
    "Yeoh",
    "evaluate_material",
    "material_from_dict",
]

MAX_TERMS = 6
"""Most polynomial (Ci0) or Ogden terms a material may have."""


def _check_finite(name: str, value: float) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise InputError("must be a number", column=name, value=value)
    value = float(value)
    if not math.isfinite(value):
        raise InputError("must be finite", column=name, value=value)
    return value


def _check_positive(name: str, value: float) -> float:
    value = _check_finite(name, value)
    if value <= 0.0:
        raise InputError("must be positive", column=name, value=value)
    return value


def _check_terms(name: str, values: Any) -> tuple[float, ...]:
    try:
        items = tuple(values)
    except TypeError:
        raise InputError("must be a sequence of numbers", column=name, value=values) from None
    if not 1 <= len(items) <= MAX_TERMS:
        raise InputError(f"must have 1 to {MAX_TERMS} terms", column=name, value=values)
    return tuple(_check_finite(f"{name}[{i}]", v) for i, v in enumerate(items))


class Material:
    """Common behaviour of the material dataclasses.

    Subclasses define ``model_name``, ``initial_shear_modulus_Pa``, ``_flat_parameters`` and
    ``_from_flat``, and either a ``bulk_modulus_Pa`` field or their own ``bulk_modulus``.
    """

    model_name: ClassVar[str]

    @property
    def initial_shear_modulus_Pa(self) -> float:
        """Shear modulus at zero strain, Pa."""
        raise NotImplementedError

    @property
    def bulk_modulus(self) -> float:
        """Bulk modulus at zero strain, Pa.

        The ``bulk_modulus_Pa`` field of the models that take one; a model without that field
        (LinearElastic) overrides this property.
        """
        return self.bulk_modulus_Pa

    @property
    def D1_per_Pa(self) -> float:  # noqa: N802 (Abaqus name)
        """Abaqus volumetric compliance D1 = 2 / K, 1/Pa."""
        return 2.0 / self.bulk_modulus

    def small_strain_equivalent(self) -> tuple[float, float]:
        """Young's modulus (Pa) and Poisson's ratio of the linearized material."""
        mu, k = self.initial_shear_modulus_Pa, self.bulk_modulus
        return 9.0 * k * mu / (3.0 * k + mu), (3.0 * k - 2.0 * mu) / (2.0 * (3.0 * k + mu))

    def _flat_parameters(self) -> dict[str, float]:
        raise NotImplementedError

    @classmethod
    def _from_flat(cls, values: Mapping[str, float]) -> Material:
        raise NotImplementedError

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """Names of the scalar parameters, with units (``C10_Pa``, ``alpha1``, ...)."""
        return tuple(self._flat_parameters())

    def parameter_vector(self) -> np.ndarray:
        """The scalar parameters in ``parameter_names`` order, shape (n,)."""
        return np.array(list(self._flat_parameters().values()), dtype=np.float64)

    def with_parameters(self, values: np.ndarray) -> Material:
        """A copy with new scalar parameters (``parameter_names`` order); validated."""
        values = np.asarray(values, dtype=np.float64).ravel()
        names = self.parameter_names
        if values.shape != (len(names),):
            raise InputError(f"expected {len(names)} parameters {names}", value=values.tolist())
        return self._from_flat(dict(zip(names, values.tolist(), strict=True)))

    def to_dict(self) -> dict[str, Any]:
        """``{"model": name, <parameter>_<unit>: value, ...}``, as read by material_from_dict."""
        return {"model": self.model_name, **self._flat_parameters()}

    def device_params(self) -> Any:
        """The ``MaterialParams`` Warp struct of this material."""
        from warptissue.kernels import materials as km

        params = km.MaterialParams()
        params.model = int(self._device_model)
        params.polynomial_terms = 0
        params.c_i0 = km.vec6d()
        params.c01 = 0.0
        params.ogden_terms = 0
        params.ogden_mu = km.vec6d()
        params.ogden_alpha = km.vec6d()
        mu, k = self.initial_shear_modulus_Pa, self.bulk_modulus
        params.bulk_modulus = k
        params.shear_modulus = mu
        params.lame_lambda = k - 2.0 * mu / 3.0
        self._fill_device_params(params, km)
        return params

    _device_model: ClassVar[int] = 0

    def _fill_device_params(self, params: Any, km: Any) -> None:
        """Set the model-specific struct fields."""


@dataclass(frozen=True)
class ReducedPolynomial(Material):
    """Reduced polynomial ``W = sum_i Ci0 (I1b - 3)^i + (J - 1)^2 / D1``.

    Args:
        C_Pa: ``(C10, C20, ..., CN0)``, Pa, 1 <= N <= 6; ``C10 > 0``.
        bulk_modulus_Pa: K = 2 / D1, Pa.
    """

    C_Pa: tuple[float, ...]
    bulk_modulus_Pa: float

    model_name: ClassVar[str] = "reduced_polynomial"

    def __post_init__(self) -> None:
        object.__setattr__(self, "C_Pa", _check_terms("C_Pa", self.C_Pa))
        _check_positive("C10_Pa", self.C_Pa[0])
        object.__setattr__(
            self, "bulk_modulus_Pa", _check_positive("bulk_modulus_Pa", self.bulk_modulus_Pa)
        )

    @property
    def order(self) -> int:
        """N, the number of Ci0 terms."""
        return len(self.C_Pa)

    @property
    def initial_shear_modulus_Pa(self) -> float:
        return 2.0 * self.C_Pa[0]

    def _flat_parameters(self) -> dict[str, float]:
        out = {f"C{i + 1}0_Pa": c for i, c in enumerate(self.C_Pa)}
        out["bulk_modulus_Pa"] = self.bulk_modulus_Pa
        return out

    @classmethod
    def _from_flat(cls, values: Mapping[str, float]) -> ReducedPolynomial:
        order = sum(1 for key in values if key != "bulk_modulus_Pa")
        return cls(tuple(values[f"C{i + 1}0_Pa"] for i in range(order)), values["bulk_modulus_Pa"])

    def _fill_device_params(self, params: Any, km: Any) -> None:
        params.polynomial_terms = self.order
        params.c_i0 = km.vec6d(*self.C_Pa, *([0.0] * (MAX_TERMS - self.order)))


@dataclass(frozen=True)
class NeoHookean(Material):
    """Nearly incompressible neo-Hookean ``W = C10 (I1b - 3) + (J - 1)^2 / D1``.

    Args:
        C10_Pa: Pa, > 0 (initial shear modulus 2 C10).
        bulk_modulus_Pa: K = 2 / D1, Pa, > 0.
    """

    C10_Pa: float
    bulk_modulus_Pa: float

    model_name: ClassVar[str] = "neo_hookean"

    def __post_init__(self) -> None:
        for f in fields(self):
            object.__setattr__(self, f.name, _check_positive(f.name, getattr(self, f.name)))

    @property
    def initial_shear_modulus_Pa(self) -> float:
        return 2.0 * self.C10_Pa

    def _flat_parameters(self) -> dict[str, float]:
        return {"C10_Pa": self.C10_Pa, "bulk_modulus_Pa": self.bulk_modulus_Pa}

    @classmethod
    def _from_flat(cls, values: Mapping[str, float]) -> NeoHookean:
        return cls(values["C10_Pa"], values["bulk_modulus_Pa"])

    def _fill_device_params(self, params: Any, km: Any) -> None:
        params.polynomial_terms = 1
        params.c_i0 = km.vec6d(self.C10_Pa, 0.0, 0.0, 0.0, 0.0, 0.0)


@dataclass(frozen=True)
class MooneyRivlin(Material):
    """Mooney-Rivlin ``W = C10 (I1b - 3) + C01 (I2b - 3) + (J - 1)^2 / D1``.

    Args:
        C10_Pa: Pa (may be negative, as fits sometimes give; seed 003 Table 1).
        C01_Pa: Pa.
        bulk_modulus_Pa: Pa, > 0. ``C10 + C01`` must be positive.
    """

    C10_Pa: float
    C01_Pa: float
    bulk_modulus_Pa: float

    model_name: ClassVar[str] = "mooney_rivlin"

    def __post_init__(self) -> None:
        object.__setattr__(self, "C10_Pa", _check_finite("C10_Pa", self.C10_Pa))
        object.__setattr__(self, "C01_Pa", _check_finite("C01_Pa", self.C01_Pa))
        object.__setattr__(
            self, "bulk_modulus_Pa", _check_positive("bulk_modulus_Pa", self.bulk_modulus_Pa)
        )
        if self.C10_Pa + self.C01_Pa <= 0.0:
            raise InputError(
                "C10_Pa + C01_Pa must be positive (initial shear modulus 2 (C10 + C01))",
                column="C01_Pa",
                value=self.C01_Pa,
            )

    @property
    def initial_shear_modulus_Pa(self) -> float:
        return 2.0 * (self.C10_Pa + self.C01_Pa)

    def _flat_parameters(self) -> dict[str, float]:
        return {
            "C10_Pa": self.C10_Pa,
            "C01_Pa": self.C01_Pa,
            "bulk_modulus_Pa": self.bulk_modulus_Pa,
        }

    @classmethod
    def _from_flat(cls, values: Mapping[str, float]) -> MooneyRivlin:
        return cls(values["C10_Pa"], values["C01_Pa"], values["bulk_modulus_Pa"])

    def _fill_device_params(self, params: Any, km: Any) -> None:
        params.polynomial_terms = 1
        params.c_i0 = km.vec6d(self.C10_Pa, 0.0, 0.0, 0.0, 0.0, 0.0)
        params.c01 = self.C01_Pa


def Yeoh(  # noqa: N802 (a constructor named like the model)
    C10_Pa: float, C20_Pa: float, C30_Pa: float, bulk_modulus_Pa: float
) -> ReducedPolynomial:
    """Yeoh: the reduced polynomial of order 3.

    Args:
        C10_Pa, C20_Pa, C30_Pa: Pa.
        bulk_modulus_Pa: Pa.
    """
    return ReducedPolynomial((C10_Pa, C20_Pa, C30_Pa), bulk_modulus_Pa)


@dataclass(frozen=True)
class Ogden(Material):
    """Ogden ``W = sum_i 2 mu_i / alpha_i^2 (l1b^alpha_i + l2b^alpha_i + l3b^alpha_i - 3)``.

    Plus ``(J - 1)^2 / D1``; ``lb`` are isochoric principal stretches (Abaqus convention).

    Args:
        mu_Pa: ``(mu_1, ..., mu_N)``, Pa, 1 <= N <= 6, with ``sum mu_i > 0``.
        alpha: ``(alpha_1, ..., alpha_N)``, nonzero.
        bulk_modulus_Pa: Pa, > 0.
    """

    mu_Pa: tuple[float, ...]
    alpha: tuple[float, ...]
    bulk_modulus_Pa: float

    model_name: ClassVar[str] = "ogden"
    _device_model: ClassVar[int] = 1

    def __post_init__(self) -> None:
        object.__setattr__(self, "mu_Pa", _check_terms("mu_Pa", self.mu_Pa))
        object.__setattr__(self, "alpha", _check_terms("alpha", self.alpha))
        if len(self.mu_Pa) != len(self.alpha):
            raise InputError(
                f"mu_Pa has {len(self.mu_Pa)} terms but alpha has {len(self.alpha)}",
                column="alpha",
                value=self.alpha,
            )
        for i, a in enumerate(self.alpha):
            if a == 0.0:
                raise InputError("must be nonzero", column=f"alpha{i + 1}", value=a)
        if sum(self.mu_Pa) <= 0.0:
            raise InputError(
                "sum of mu_i must be positive (initial shear modulus)",
                column="mu_Pa",
                value=self.mu_Pa,
            )
        object.__setattr__(
            self, "bulk_modulus_Pa", _check_positive("bulk_modulus_Pa", self.bulk_modulus_Pa)
        )

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
        out["bulk_modulus_Pa"] = self.bulk_modulus_Pa
        return out

    @classmethod
    def _from_flat(cls, values: Mapping[str, float]) -> Ogden:
        order = sum(1 for key in values if key.startswith("mu"))
        return cls(
            tuple(values[f"mu{i + 1}_Pa"] for i in range(order)),
            tuple(values[f"alpha{i + 1}"] for i in range(order)),
            values["bulk_modulus_Pa"],
        )

    def _fill_device_params(self, params: Any, km: Any) -> None:
        pad = [0.0] * (MAX_TERMS - self.order)
        params.ogden_terms = self.order
        params.ogden_mu = km.vec6d(*self.mu_Pa, *pad)
        params.ogden_alpha = km.vec6d(*self.alpha, *pad)


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

    def __post_init__(self) -> None:
        for f in fields(self):
            object.__setattr__(self, f.name, _check_positive(f.name, getattr(self, f.name)))
        if self.bulk_modulus_Pa <= 2.0 * self.shear_modulus_Pa / 3.0:
            raise InputError(
                "bulk_modulus_Pa must exceed 2/3 shear_modulus_Pa (Poisson's ratio > 0)",
                column="bulk_modulus_Pa",
                value=self.bulk_modulus_Pa,
            )

    @property
    def initial_shear_modulus_Pa(self) -> float:
        return self.shear_modulus_Pa

    def _flat_parameters(self) -> dict[str, float]:
        return {"shear_modulus_Pa": self.shear_modulus_Pa, "bulk_modulus_Pa": self.bulk_modulus_Pa}

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

    def __post_init__(self) -> None:
        object.__setattr__(
            self,
            "youngs_modulus_Pa",
            _check_positive("youngs_modulus_Pa", self.youngs_modulus_Pa),
        )
        nu = _check_finite("poissons_ratio", self.poissons_ratio)
        if not -1.0 < nu < 0.5:
            raise InputError("must lie in (-1, 0.5)", column="poissons_ratio", value=nu)
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

    @classmethod
    def _from_flat(cls, values: Mapping[str, float]) -> LinearElastic:
        return cls(values["youngs_modulus_Pa"], values["poissons_ratio"])


_MODELS: dict[str, type[Material]] = {
    cls.model_name: cls
    for cls in (
        NeoHookean,
        MooneyRivlin,
        ReducedPolynomial,
        Ogden,
        CompressibleNeoHookean,
        LinearElastic,
    )
}


def material_from_dict(data: Mapping[str, Any]) -> Material:
    """Build a material from ``{"model": name, parameters...}`` (the ``to_dict`` layout).

    ``model`` is one of ``neo_hookean``, ``mooney_rivlin``, ``reduced_polynomial``, ``yeoh``,
    ``ogden``, ``compressible_neo_hookean``, ``linear_elastic``. Parameters are the flat keys of
    ``to_dict`` (``C10_Pa``, ``C20_Pa``, ``mu1_Pa``, ``alpha1``, ``bulk_modulus_Pa``, ...);
    ``D1_per_Pa`` may replace ``bulk_modulus_Pa``; polynomial and Ogden coefficients may also be
    given as lists ``C_Pa``, ``mu_Pa`` and ``alpha``.

    Raises:
        InputError: Unknown model, missing or unknown key, or a bad value (named).
    """
    if not isinstance(data, Mapping):
        raise InputError("material must be a table of parameters", value=data)
    values = dict(data)
    name = values.pop("model", None)
    if name == "yeoh":
        name = "reduced_polynomial"
        order = 3
    else:
        order = None
    if name not in _MODELS:
        raise InputError(
            f"unknown material model; choose from {sorted(_MODELS) + ['yeoh']}",
            column="model",
            value=name,
        )
    cls = _MODELS[name]
    if "D1_per_Pa" in values:
        if "bulk_modulus_Pa" in values:
            raise InputError("give bulk_modulus_Pa or D1_per_Pa, not both", column="D1_per_Pa")
        d1 = _check_positive("D1_per_Pa", values.pop("D1_per_Pa"))
        values["bulk_modulus_Pa"] = 2.0 / d1
    for list_key, prefix, suffix in (
        ("C_Pa", "C", "0_Pa"),
        ("mu_Pa", "mu", "_Pa"),
        ("alpha", "alpha", ""),
    ):
        if list_key in values:
            items = _check_terms(list_key, values.pop(list_key))
            for i, v in enumerate(items):
                values[f"{prefix}{i + 1}{suffix}"] = v
    if cls is ReducedPolynomial:
        present = sorted(
            int(k[1])
            for k in values
            if k.startswith("C") and k.endswith("0_Pa") and len(k) == 6 and k[1].isdigit()
        )
        count = order if order is not None else (max(present) if present else 0)
        expected = [f"C{i + 1}0_Pa" for i in range(count)] + ["bulk_modulus_Pa"]
    elif cls is Ogden:
        count = sum(1 for k in values if k.startswith("mu") and k.endswith("_Pa"))
        expected = [
            f"{p}{i + 1}{s}" for i in range(count) for p, s in (("mu", "_Pa"), ("alpha", ""))
        ]
        expected.append("bulk_modulus_Pa")
    else:
        expected = [f.name for f in fields(cls)]
    missing = [key for key in expected if key not in values]
    if missing:
        raise InputError(f"missing parameter for model {name!r}", column=missing[0])
    unknown = [key for key in values if key not in expected]
    if unknown:
        raise InputError(
            f"unknown parameter for model {name!r}; expected {expected}",
            column=unknown[0],
            value=values[unknown[0]],
        )
    for key in expected:
        _check_finite(key, values[key])
    return cls._from_flat({key: float(values[key]) for key in expected})


@dataclass(frozen=True)
class MaterialEvaluation:
    """Energy, stress and tangent at a batch of deformation gradients.

    Attributes:
        energy_density_Pa: psi, shape (n,).
        first_piola_Pa: P = dpsi/dF, shape (n, 3, 3).
        tangent_Pa: A = dP/dF, shape (n, 9, 9), ``A[:, 3 i + J, 3 k + L] = dP_iJ/dF_kL``.
    """

    energy_density_Pa: np.ndarray
    first_piola_Pa: np.ndarray
    tangent_Pa: np.ndarray


def evaluate_material(
    material: Material,
    deformation_gradients: np.ndarray,
    *,
    device: str | None = None,
) -> MaterialEvaluation:
    """Evaluate energy, first Piola-Kirchhoff stress and tangent on a Warp device.

    Args:
        material: Any material of this module.
        deformation_gradients: F, shape (n, 3, 3) or (3, 3), with det F > 0.
        device: Warp device (``"cpu"``, ``"cuda:0"``); None for Warp's default.

    Returns:
        A :class:`MaterialEvaluation` with arrays of leading size n.
    """
    from warptissue.kernels import fem as kf
    from warptissue.kernels import materials as km

    f = np.asarray(deformation_gradients, dtype=np.float64)
    if f.shape == (3, 3):
        f = f[None]
    if f.ndim != 3 or f.shape[1:] != (3, 3):
        raise InputError("deformation gradients must have shape (n, 3, 3)", value=f.shape)
    if not np.all(np.isfinite(f)):
        raise InputError("deformation gradients must be finite")
    n = f.shape[0]
    if n == 0:
        return MaterialEvaluation(np.zeros(0), np.zeros((0, 3, 3)), np.zeros((0, 9, 9)))
    det = np.linalg.det(f)
    if np.any(det <= 0.0):
        bad = int(np.flatnonzero(det <= 0.0)[0])
        raise InputError(f"det F must be positive; F[{bad}] has det {det[bad]:.6g}")
    dev = resolve_device(device)
    f_wp = wp.array(f, dtype=wp.mat33d, device=dev)
    energy = wp.zeros(n, dtype=wp.float64, device=dev)
    stress = wp.zeros(n, dtype=wp.mat33d, device=dev)
    tangent = wp.zeros(n, dtype=km.mat99d, device=dev)
    wp.launch(
        kf.evaluate_material_kernel,
        dim=n,
        inputs=[material.device_params(), f_wp],
        outputs=[energy, stress, tangent],
        device=dev,
    )
    return MaterialEvaluation(energy.numpy(), stress.numpy(), tangent.numpy())
