"""Constitutive models: one class per model for the FE, the homogeneous tests and the fits.

Each model is a small frozen dataclass in SI units with Abaqus conventions (C10, C01, Ci0,
mu_i, alpha_i, D1 = 2/K), in the manner of FElupe's ``ConstitutiveMaterial``: the same object

- runs in the FE: ``material.device_params()`` packs it into the
  ``warptissue.kernels.materials.MaterialParams`` struct that the FE kernels read, and
  :func:`evaluate_material` evaluates energy, stress and tangent for a batch of deformation
  gradients on any Warp device;
- gives the incompressible closed forms of the homogeneous tests of a materials lab (the four
  :class:`HyperelasticMaterial` models): nominal stress in uniaxial, equibiaxial and planar
  tension or compression, its gradient with respect to the parameters, the energy, and the
  log-strain Hessian of the Drucker stability check;
- is fitted: ``parameter_names`` (units in the names), ``parameter_units``,
  ``parameter_vector`` / ``with_parameters`` (vector <-> model), ``parameter_bounds`` and, for
  the hyperelastic models, ``start_parameters`` (least-squares start values). The fitting and
  the test records are in :mod:`warptissue.fit.hyperelastic`;
- is serialized: ``to_dict()`` / :func:`material_from_dict` with flat keys (``C10_Pa``,
  ``mu1_Pa``, ``alpha1``, ``bulk_modulus_Pa``, ...), as study files and USD layers store them.

The four Abaqus hyperelastic models (:class:`NeoHookean`, :class:`MooneyRivlin`,
:class:`ReducedPolynomial` with :func:`Yeoh`, :class:`Ogden`) take an optional bulk modulus:
without one (``bulk_modulus_Pa=None``, D1 = 0 as in Abaqus) the model is incompressible, which
is what the homogeneous closed forms and their fits use; the FE needs a bulk modulus
(``with_bulk_modulus``). The volumetric term is not a fit parameter of these models: their
``parameter_names`` are the isochoric parameters only, and ``with_parameters`` keeps the bulk
modulus. A model with a bulk modulus must have a positive initial shear modulus (the FE
tangent at rest is indefinite otherwise); an incompressible one may have any, as the trial
points of a fit do (the Drucker check in :mod:`warptissue.fit.hyperelastic` reports it).

Notes:
    Energies (the needle-indentation study, Eq. 2; Abaqus Theory Manual 4.6.1), with
    isochoric invariants ``I1b = J^(-2/3) tr C``, ``I2b = J^(-4/3) (tr^2 C - tr C^2) / 2`` and
    ``U(J) = (J - 1)^2 / D1``:

    - ``NeoHookean``: ``W = C10 (I1b - 3) + U``, ``mu0 = 2 C10``.
    - ``MooneyRivlin``: ``W = C10 (I1b - 3) + C01 (I2b - 3) + U``, ``mu0 = 2 (C10 + C01)``.
    - ``ReducedPolynomial``: ``W = sum_i Ci0 (I1b - 3)^i + U``, ``mu0 = 2 C10``; Yeoh is N = 3.
      The study prints higher-order volumetric terms ``K_i/2 (J - 1)^(2i)``; only ``D1`` is
      used here, as for nearly incompressible fits in Abaqus.
    - ``Ogden``: ``W = sum_i 2 mu_i / alpha_i^2 (l1b^alpha_i + l2b^alpha_i + l3b^alpha_i - 3)
      + U``, ``mu0 = sum_i mu_i``.
    - ``CompressibleNeoHookean``: ``W = mu/2 (I1 - 3) - mu ln J + lambda/2 (ln J)^2`` with
      ``lambda = K - 2 mu / 3``.
    - ``LinearElastic``: small strain, ``W = mu eps:eps + lambda/2 (tr eps)^2``.

    Homogeneous tests (incompressible, principal stretches l1, l2, l3 with l1 l2 l3 = 1):
    uniaxial (l, l^-1/2, l^-1/2), equibiaxial (l, l, l^-2), planar (l, 1, l^-1). Invariant
    models W(I1, I2), with W1 = dW/dI1 and W2 = dW/dI2, give the nominal stress (force per
    reference area) along the loading direction (free lateral faces)::

        uniaxial     S = 2 (l - l^-2) (W1 + W2 / l) = 2 (1 - l^-3) (l W1 + W2)
        equibiaxial  S = 2 (l - l^-5) (W1 + l^2 W2)
        planar       S = 2 (l - l^-3) (W1 + W2)

    The study's Eq. 3 (uniaxial) agrees for neo-Hookean, RP2 and Mooney-Rivlin. Ogden gives::

        S = sum 2 mu_i / alpha_i (l^(a_i - 1) - l^(-k a_i - 1)),  k = 1/2, 2, 1

    for uniaxial, equibiaxial and planar; k = 1/2 is the study's Eq. 3. Each formula is the
    derivative of the energy along the path: S = dW/dl / (number of loaded directions), which
    the tests check by numerical differentiation. Stresses are signed (tension positive).
"""

from __future__ import annotations

import abc
import dataclasses
import difflib
import itertools
import math
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, fields
from typing import Any, ClassVar

import numpy as np
import warp as wp

from warptissue.device import resolve_device
from warptissue.errors import InputError
from warptissue.kernels import assembly as ka
from warptissue.kernels import materials as km

__all__ = [
    "HOMOGENEOUS_MODES",
    "CompressibleNeoHookean",
    "HyperelasticMaterial",
    "LinearElastic",
    "Material",
    "MaterialEvaluation",
    "MooneyRivlin",
    "NeoHookean",
    "Ogden",
    "ReducedPolynomial",
    "Viscoelastic",
    "Yeoh",
    "evaluate_material",
    "material_from_dict",
    "principal_log_strains",
    "principal_stretches",
]

MAX_TERMS = 6
"""Most polynomial (Ci0) or Ogden terms a material may have."""

HOMOGENEOUS_MODES: tuple[str, ...] = ("uniaxial", "equibiaxial", "planar")
"""Deformation modes of the homogeneous closed forms."""


def _check_finite(name: str, value: float) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise InputError("must be a number", key=name, value=value)
    value = float(value)
    if not math.isfinite(value):
        raise InputError("must be finite", key=name, value=value)
    return value


def _check_positive(name: str, value: float) -> float:
    value = _check_finite(name, value)
    if value <= 0.0:
        raise InputError("must be positive", key=name, value=value)
    return value


def _check_terms(name: str, values: Any) -> tuple[float, ...]:
    try:
        items = tuple(values)
    except TypeError:
        raise InputError("must be a sequence of numbers", key=name, value=values) from None
    if not 1 <= len(items) <= MAX_TERMS:
        raise InputError(f"must have 1 to {MAX_TERMS} terms", key=name, value=values)
    return tuple(_check_finite(f"{name}[{i}]", v) for i, v in enumerate(items))


def _check_mode(mode: str) -> str:
    if mode not in HOMOGENEOUS_MODES:
        raise InputError("mode must be uniaxial, equibiaxial or planar", value=mode)
    return mode


def principal_log_strains(stretch: np.ndarray, mode: str) -> np.ndarray:
    """The three principal logarithmic strains of an incompressible homogeneous test.

    Args:
        stretch: Stretch of the loading direction, shape (m,), > 0.
        mode: "uniaxial", "equibiaxial" or "planar".

    Returns:
        Principal log strains, shape (m, 3), summing to zero.
    """
    e = np.log(np.asarray(stretch, dtype=np.float64))
    e2 = {"uniaxial": -0.5 * e, "equibiaxial": e, "planar": np.zeros_like(e)}[_check_mode(mode)]
    return np.stack([e, e2, -e - e2], axis=-1)


def principal_stretches(stretch: np.ndarray, mode: str) -> np.ndarray:
    """The three principal stretches of an incompressible homogeneous test.

    Args:
        stretch: Stretch of the loading direction, shape (m,), > 0.
        mode: "uniaxial", "equibiaxial" or "planar".

    Returns:
        Principal stretches, shape (m, 3), with product 1.
    """
    return np.exp(principal_log_strains(stretch, mode))


class Material:
    """Common behaviour of the material dataclasses.

    Subclasses define ``model_name``, ``initial_shear_modulus_Pa``, ``_flat_parameters`` and
    ``_from_flat``, and either a ``bulk_modulus_Pa`` field or their own ``bulk_modulus``.
    """

    model_name: ClassVar[str]
    _bounds: ClassVar[Mapping[str, tuple[float, float]]] = {}
    _fixed_keys: ClassVar[tuple[str, ...]] = ()

    @property
    def initial_shear_modulus_Pa(self) -> float:
        """Shear modulus at zero strain, Pa."""
        raise NotImplementedError

    @property
    def bulk_modulus(self) -> float:
        """Bulk modulus at zero strain, Pa; ``inf`` for an incompressible model.

        The ``bulk_modulus_Pa`` field of the models that take one; a model without that field
        (LinearElastic) overrides this property.
        """
        value = self.bulk_modulus_Pa
        return math.inf if value is None else value

    @property
    def D1_per_Pa(self) -> float:  # noqa: N802 (Abaqus name)
        """Abaqus volumetric compliance D1 = 2 / K, 1/Pa (0 when incompressible)."""
        return 2.0 / self.bulk_modulus

    def small_strain_equivalent(self) -> tuple[float, float]:
        """Young's modulus (Pa) and Poisson's ratio of the linearized material.

        An incompressible model gives ``(3 mu0, 0.5)``.
        """
        mu, k = self.initial_shear_modulus_Pa, self.bulk_modulus
        if math.isinf(k):
            return 3.0 * mu, 0.5
        return 9.0 * k * mu / (3.0 * k + mu), (3.0 * k - 2.0 * mu) / (2.0 * (3.0 * k + mu))

    def _flat_parameters(self) -> dict[str, float]:
        raise NotImplementedError

    @classmethod
    def _from_flat(cls, values: Mapping[str, float]) -> Material:
        raise NotImplementedError

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """Names of the fit parameters, with units (``C10_Pa``, ``alpha1``, ...).

        Every scalar parameter of ``to_dict`` except the bulk modulus of the hyperelastic
        models (held fixed by :meth:`with_parameters`).
        """
        return tuple(key for key in self._flat_parameters() if key not in self._fixed_keys)

    @property
    def parameter_units(self) -> tuple[str, ...]:
        """SI unit of each entry of :attr:`parameter_vector` ("Pa", "s" or "" for
        dimensionless)."""
        return tuple(
            "Pa" if name.endswith("_Pa") else "s" if name.endswith("_s") else ""
            for name in self.parameter_names
        )

    @property
    def parameter_vector(self) -> np.ndarray:
        """The fit parameters in :attr:`parameter_names` order, shape (n,)."""
        flat = self._flat_parameters()
        return np.array([flat[name] for name in self.parameter_names], dtype=np.float64)

    @property
    def parameter_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) bounds of the fit parameters, each shape (n,); +-inf where free.

        The box of admissible values; constraints that are not a box (alpha_i != 0,
        K > 2 mu / 3) are checked on construction.
        """
        box = [self._bounds.get(name, (-math.inf, math.inf)) for name in self.parameter_names]
        return (
            np.array([low for low, _ in box], dtype=np.float64),
            np.array([high for _, high in box], dtype=np.float64),
        )

    def with_parameters(self, values: np.ndarray) -> Material:
        """A copy with new fit parameters (:attr:`parameter_names` order); validated."""
        values = np.asarray(values, dtype=np.float64).ravel()
        names = self.parameter_names
        if values.shape != (len(names),):
            raise InputError(f"expected {len(names)} parameters {names}", value=values.tolist())
        return self._from_flat(
            {**self._flat_parameters(), **dict(zip(names, values.tolist(), strict=True))}
        )

    def to_dict(self) -> dict[str, Any]:
        """``{"model": name, <parameter>_<unit>: value, ...}``, as read by material_from_dict.

        An incompressible model has no ``bulk_modulus_Pa`` key.
        """
        return {"model": self.model_name, **self._flat_parameters()}

    def device_params(self) -> Any:
        """The ``MaterialParams`` Warp struct of this material.

        Raises:
            InputError: The model is incompressible (no bulk modulus).
        """

        if math.isinf(self.bulk_modulus):
            raise InputError(
                f"the FE needs a bulk modulus; this {self.model_name} model is incompressible "
                "(give bulk_modulus_Pa, or use with_bulk_modulus)",
                key="bulk_modulus_Pa",
            )
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

    @property
    def sensitivity_names(self) -> tuple[str, ...]:
        """Parameters the FE force can be differentiated by: :attr:`parameter_names` plus
        ``bulk_modulus_Pa`` where the model has one (the keys of :meth:`to_dict`)."""
        return tuple(self._flat_parameters())

    def device_params_derivative(self, name: str) -> tuple[Any, int]:
        """The derivative of :meth:`device_params` with respect to one parameter.

        The FE internal force is linear in every numeric field of ``MaterialParams`` except
        the Ogden exponents (``c_i0``, ``c01``, ``ogden_mu``, ``bulk_modulus``,
        ``shear_modulus``, ``lame_lambda``): the returned struct holds ``d field / d name`` in
        those fields and the material's own model, term counts and alphas, so that the
        internal force assembled with it is ``dR/d name`` of those fields (chain rule through
        ``mu0(theta)``, ``K(theta)`` and ``lambda = K - 2 mu0 / 3``). ``alpha_i`` enters
        nonlinearly: it is returned as the term index ``i - 1`` (else -1), and its derivative
        is a kernel of its own.

        Args:
            name: One of :attr:`sensitivity_names`.

        Returns:
            (struct, alpha_term).

        Raises:
            InputError: ``name`` is not a parameter of this model.
        """

        names = self.sensitivity_names
        if name not in names:
            close = difflib.get_close_matches(name, names, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise InputError(
                f"{self.model_name} has no parameter {name!r}; it has {', '.join(names)}{hint}",
                key="sensitivities",
                value=name,
            )
        params = self.device_params()
        c_i0, c01, ogden_mu = [0.0] * MAX_TERMS, 0.0, [0.0] * MAX_TERMS
        alpha_term = -1
        if name == "C01_Pa":
            c01 = 1.0
        elif name.startswith("C") and name.endswith("0_Pa"):
            c_i0[int(name[1:-4]) - 1] = 1.0
        elif name.startswith("mu") and name[2:-3].isdigit():
            ogden_mu[int(name[2:-3]) - 1] = 1.0
        elif name.startswith("alpha"):
            alpha_term = int(name[5:]) - 1
        d_shear, d_bulk = self.moduli_derivative(name)
        params.c_i0 = km.vec6d(*c_i0)
        params.c01 = c01
        params.ogden_mu = km.vec6d(*ogden_mu)
        params.bulk_modulus = d_bulk
        params.shear_modulus = d_shear
        params.lame_lambda = d_bulk - 2.0 * d_shear / 3.0
        return params, alpha_term

    def moduli_derivative(self, name: str) -> tuple[float, float]:
        """``(d mu0 / d name, d K / d name)`` of the initial shear and bulk moduli.

        The hyperelastic models' ``mu0`` is linear in their Pa parameters (2 C10,
        2 (C10 + C01), sum mu_i), so its derivative is its value at a unit parameter.

        Args:
            name: A parameter of the model (a ``to_dict`` key).

        Returns:
            (d mu0 / d name, d K / d name), in Pa per the parameter's unit.
        """
        if name == "bulk_modulus_Pa":
            return 0.0, 1.0
        if not name.endswith("_Pa"):
            return 0.0, 0.0
        unit = {key: 0.0 for key in self._flat_parameters()}
        unit[name] = 1.0
        return self._shear_modulus_of(unit), 0.0

    def _shear_modulus_of(self, flat: Mapping[str, float]) -> float:
        """mu0 of flat parameter values (linear in them); see :meth:`moduli_derivative`."""
        raise NotImplementedError

    def shear_modulus_weight(self, name: str) -> float:
        """d mu0 / d ``name`` for a modulus, 0 for any other parameter.

        mu0 is linear in the moduli (the Pa parameters: ``C10_Pa``, ``C01_Pa``, the Ogden
        ``mu<i>_Pa``, ``shear_modulus_Pa``, ``youngs_modulus_Pa`` at a fixed Poisson's ratio),
        so ``mu0 = sum_i weight_i p_i`` over them; the shape parameters (``C20_Pa`` and up have
        weight 0 as well), ``alpha<i>``, a Poisson's ratio and the Prony terms get 0.

        Args:
            name: A parameter of the model.

        Returns:
            The weight, Pa / Pa (dimensionless).
        """
        return self.moduli_derivative(name)[0] if name.endswith("_Pa") else 0.0


def _optional_bulk_modulus(value: float | None) -> float | None:
    return None if value is None else _check_positive("bulk_modulus_Pa", value)


class HyperelasticMaterial(Material, abc.ABC):
    """Base of the Abaqus hyperelastic models: FE material and incompressible closed forms.

    Subclasses are frozen dataclasses whose last field is ``bulk_modulus_Pa`` (None:
    incompressible). They provide the energy at J = 1, the signed nominal stress of each
    homogeneous mode and its gradient with respect to :attr:`parameter_vector`, the
    log-strain Hessian used by the Drucker check, and least-squares start values.
    """

    bulk_modulus_Pa: float | None
    _fixed_keys: ClassVar[tuple[str, ...]] = ("bulk_modulus_Pa",)

    @property
    def incompressible(self) -> bool:
        """True without a bulk modulus (D1 = 0)."""
        return self.bulk_modulus_Pa is None

    def with_bulk_modulus(self, bulk_modulus_Pa: float | None) -> HyperelasticMaterial:
        """A copy with bulk modulus K (Pa, > 0; None: incompressible); validated."""
        return dataclasses.replace(self, bulk_modulus_Pa=bulk_modulus_Pa)

    @abc.abstractmethod
    def energy_density_Pa(self, stretches: np.ndarray) -> np.ndarray:
        """Strain energy per reference volume at J = 1, from principal stretches (..., 3)."""

    @abc.abstractmethod
    def nominal_stress_Pa(self, stretch: np.ndarray, mode: str) -> np.ndarray:
        """Signed nominal stress along the loading direction, shape (m,), Pa.

        Args:
            stretch: Stretch of the loading direction, shape (m,) or scalar, > 0.
            mode: One of :data:`HOMOGENEOUS_MODES`.
        """

    @abc.abstractmethod
    def nominal_stress_gradient(self, stretch: np.ndarray, mode: str) -> np.ndarray:
        """d nominal stress / d :attr:`parameter_vector`, shape (m, n)."""

    @abc.abstractmethod
    def principal_log_strain_hessian(self, log_strains: np.ndarray) -> np.ndarray:
        """Hessian of W(exp e1, exp e2, exp e3) in the principal log strains, (m, 3, 3), Pa.

        Any extension of W off the incompressible plane e1 + e2 + e3 = 0 serves, since only
        its restriction to that plane is used (the plane is linear in e).

        Args:
            log_strains: Principal logarithmic strains, shape (m, 3), summing to zero.
        """

    @abc.abstractmethod
    def start_parameters(
        self, design: Callable[[HyperelasticMaterial], np.ndarray], data: np.ndarray
    ) -> np.ndarray:
        """Least-squares start values of :attr:`parameter_vector` for a fit.

        Args:
            design: Maps a model of this kind to the Jacobian of the (weighted) predictions
                with respect to its parameter vector, shape (m, n).
            data: The (weighted) data the predictions are fitted to, shape (m,).

        Returns:
            The start vector, shape (n,).

        Raises:
            InputError: No start point gives finite predictions.
        """

    def log_strain_hessian(self, e1: np.ndarray, e2: np.ndarray) -> np.ndarray:
        """Hessian of W~(e1, e2) = W(exp e1, exp e2, exp(-e1 - e2)), shape (m, 2, 2), Pa."""
        e1 = np.atleast_1d(np.asarray(e1, dtype=np.float64))
        e2 = np.atleast_1d(np.asarray(e2, dtype=np.float64))
        ambient = self.principal_log_strain_hessian(np.stack([e1, e2, -e1 - e2], axis=-1))
        basis = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, -1.0]])
        return basis.T @ ambient @ basis


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
        object.__setattr__(self, "C_Pa", _check_terms("C_Pa", self.C_Pa))
        if self.bulk_modulus_Pa is not None:
            _check_positive("C10_Pa", self.C_Pa[0])
        object.__setattr__(self, "bulk_modulus_Pa", _optional_bulk_modulus(self.bulk_modulus_Pa))

    @property
    def order(self) -> int:
        """N, the number of Ci0 terms."""
        return len(self.C_Pa)

    @property
    def initial_shear_modulus_Pa(self) -> float:
        return 2.0 * self.C_Pa[0]

    def _flat_parameters(self) -> dict[str, float]:
        out = {f"C{i + 1}0_Pa": c for i, c in enumerate(self.C_Pa)}
        return _with_bulk(out, self.bulk_modulus_Pa)

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


def _with_bulk(values: dict[str, float], bulk_modulus_Pa: float | None) -> dict[str, float]:
    """``values`` plus ``bulk_modulus_Pa`` when the model has one."""
    if bulk_modulus_Pa is not None:
        values["bulk_modulus_Pa"] = bulk_modulus_Pa
    return values


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
        check = _check_finite if self.bulk_modulus_Pa is None else _check_positive
        object.__setattr__(self, "C10_Pa", check("C10_Pa", self.C10_Pa))
        object.__setattr__(self, "bulk_modulus_Pa", _optional_bulk_modulus(self.bulk_modulus_Pa))

    @property
    def initial_shear_modulus_Pa(self) -> float:
        return 2.0 * self.C10_Pa

    def _flat_parameters(self) -> dict[str, float]:
        return _with_bulk({"C10_Pa": self.C10_Pa}, self.bulk_modulus_Pa)

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
        object.__setattr__(self, "C10_Pa", _check_finite("C10_Pa", self.C10_Pa))
        object.__setattr__(self, "C01_Pa", _check_finite("C01_Pa", self.C01_Pa))
        object.__setattr__(self, "bulk_modulus_Pa", _optional_bulk_modulus(self.bulk_modulus_Pa))
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
        return _with_bulk({"C10_Pa": self.C10_Pa, "C01_Pa": self.C01_Pa}, self.bulk_modulus_Pa)

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
        object.__setattr__(self, "mu_Pa", _check_terms("mu_Pa", self.mu_Pa))
        object.__setattr__(self, "alpha", _check_terms("alpha", self.alpha))
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
        object.__setattr__(self, "bulk_modulus_Pa", _optional_bulk_modulus(self.bulk_modulus_Pa))

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
        return _with_bulk(out, self.bulk_modulus_Pa)

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
        k = _OGDEN_K[_check_mode(mode)]
        return sum(
            2.0 * mu / a * (lam ** (a - 1.0) - lam ** (-k * a - 1.0))
            for mu, a in zip(self.mu_Pa, self.alpha, strict=True)
        )

    def nominal_stress_gradient(self, stretch: np.ndarray, mode: str) -> np.ndarray:
        lam = np.atleast_1d(np.asarray(stretch, dtype=np.float64))
        k = _OGDEN_K[_check_mode(mode)]
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
            object.__setattr__(self, f.name, _check_positive(f.name, getattr(self, f.name)))
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
            _check_positive("youngs_modulus_Pa", self.youngs_modulus_Pa),
        )
        nu = _check_finite("poissons_ratio", self.poissons_ratio)
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


PRONY_KEY = re.compile(r"^(g|tau)(\d+)(_s)?$")
"""What looks like a Prony key of a material table: ``g<i>`` (dimensionless) or ``tau<i>_s``
(s), and their near misses (``tau1``, ``g1_s``) that the table reader names in its error;
:func:`prony_term` tells the keys themselves."""


def prony_term(name: str) -> tuple[str, int] | None:
    """The Prony term that a parameter or material-table key names.

    Args:
        name: A key, e.g. ``g2`` (a dimensionless coefficient) or ``tau2_s`` (a time, s).

    Returns:
        ``("g" | "tau", i)`` with the term's number i (from 1), or None for any other name.
    """
    match = PRONY_KEY.match(name)
    if match is None or (match.group(1) == "tau") != (match.group(3) == "_s"):
        return None
    return match.group(1), int(match.group(2))


POSITIVE_MODULI: tuple[str, ...] = (
    "C10_Pa",
    "shear_modulus_Pa",
    "youngs_modulus_Pa",
    "bulk_modulus_Pa",
)
"""The moduli that a fit keeps at or above 0 (:func:`positive_bounds`), Pa."""


def positive_bounds(
    names: Sequence[str], lower: np.ndarray, upper: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Bounds tightened where a parameter must be positive, whatever the model's box says.

    The moduli of :data:`POSITIVE_MODULI` and the Prony times ``tau<i>_s`` get lower bound
    0; the Prony coefficients ``g<i>`` lie in [0, 1].

    Args:
        names: Parameter names, shape (n,).
        lower: Lower bounds in their units, shape (n,).
        upper: Upper bounds, shape (n,).

    Returns:
        (lower, upper), new arrays of shape (n,).
    """
    lower, upper = np.array(lower, dtype=np.float64), np.array(upper, dtype=np.float64)
    for j, name in enumerate(names):
        term = prony_term(name)
        if name in POSITIVE_MODULI or (term is not None and term[0] == "tau"):
            lower[j] = max(lower[j], 0.0)
        elif term is not None:
            lower[j] = max(lower[j], 0.0)
            upper[j] = min(upper[j], 1.0)
    return lower, upper


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
        g = tuple(_check_finite(f"g{i + 1}", v) for i, v in enumerate(self.g))
        tau = tuple(_check_positive(f"tau{i + 1}_s", v) for i, v in enumerate(self.tau_s))
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
    prony = _pop_prony(values)
    name = values.pop("model", None)
    if name == "yeoh":
        name = "reduced_polynomial"
        order = 3
    else:
        order = None
    if name not in _MODELS:
        names = sorted([*_MODELS, "yeoh"])
        close = difflib.get_close_matches(str(name).lower(), names, n=1, cutoff=0.6)
        hint = f"did you mean {close[0]!r}? " if close else ""
        raise InputError(
            f"unknown material model ({hint}choose from {', '.join(names)})",
            key="model",
            value=name,
        )
    cls = _MODELS[name]
    if "D1_per_Pa" in values:
        if "bulk_modulus_Pa" in values:
            raise InputError("give bulk_modulus_Pa or D1_per_Pa, not both", key="D1_per_Pa")
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
    unknown = [key for key in values if key not in expected]
    if missing:
        lowered = {key.lower(): key for key in unknown}
        close = difflib.get_close_matches(missing[0].lower(), list(lowered), n=1, cutoff=0.6)
        hint = f" (the unknown key {lowered[close[0]]!r} looks like a typo of it)" if close else ""
        raise InputError(f"missing parameter for model {name!r}{hint}", key=missing[0])
    if unknown:
        raise InputError(
            f"unknown parameter for model {name!r}; expected {', '.join(expected)}",
            key=unknown[0],
            value=values[unknown[0]],
        )
    for key in expected:
        _check_finite(key, values[key])
    material = cls._from_flat({key: float(values[key]) for key in expected})
    if prony is None:
        return material
    return Viscoelastic(material, *prony)


def _pop_prony(values: dict[str, Any]) -> tuple[tuple[float, ...], tuple[float, ...]] | None:
    """Take the Prony keys (``g<i>``, ``tau<i>_s``, numbered 1..N) out of a material table."""
    found: dict[str, dict[int, float]] = {"g": {}, "tau": {}}
    for key in [k for k in values if isinstance(k, str) and PRONY_KEY.match(k)]:
        match = PRONY_KEY.match(key)
        kind, index, unit = match.group(1), int(match.group(2)), match.group(3)
        if (kind == "tau") != (unit == "_s"):
            expected = f"tau{index}_s" if kind == "tau" else f"g{index}"
            raise InputError(f"unknown key; did you mean {expected!r}?", key=key)
        found[kind][index] = _check_finite(key, values.pop(key))
    if not found["g"] and not found["tau"]:
        return None
    count = max([*found["g"], *found["tau"]])
    for kind, suffix in (("g", ""), ("tau", "_s")):
        for i in range(1, count + 1):
            if i not in found[kind]:
                raise InputError(
                    f"a Prony series numbers its terms 1..{count}: this term is missing",
                    key=f"{kind}{i}{suffix}",
                )
    return (
        tuple(found["g"][i] for i in range(1, count + 1)),
        tuple(found["tau"][i] for i in range(1, count + 1)),
    )


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
        ka.evaluate_material_kernel,
        dim=n,
        inputs=[material.device_params(), f_wp],
        outputs=[energy, stress, tangent],
        device=dev,
    )
    return MaterialEvaluation(energy.numpy(), stress.numpy(), tangent.numpy())
