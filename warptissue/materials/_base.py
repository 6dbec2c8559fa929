"""What every material shares: the :class:`Material` base (fit parameters, serialization,
the FE's ``MaterialParams`` struct and its derivatives), the :class:`HyperelasticMaterial`
base of the homogeneous closed forms, the kinematics of the homogeneous tests, and the checks
of parameter values."""

from __future__ import annotations

import abc
import dataclasses
import difflib
import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any, ClassVar

import numpy as np

from warptissue.errors import InputError
from warptissue.kernels import materials as km

MAX_TERMS = 6
"""Most polynomial (Ci0) or Ogden terms a material may have."""

HOMOGENEOUS_MODES: tuple[str, ...] = ("uniaxial", "equibiaxial", "planar")
"""Deformation modes of the homogeneous closed forms."""


def check_finite(name: str, value: float) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise InputError("must be a number", key=name, value=value)
    value = float(value)
    if not math.isfinite(value):
        raise InputError("must be finite", key=name, value=value)
    return value


def check_positive(name: str, value: float) -> float:
    value = check_finite(name, value)
    if value <= 0.0:
        raise InputError("must be positive", key=name, value=value)
    return value


def check_terms(name: str, values: Any) -> tuple[float, ...]:
    try:
        items = tuple(values)
    except TypeError:
        raise InputError("must be a sequence of numbers", key=name, value=values) from None
    if not 1 <= len(items) <= MAX_TERMS:
        raise InputError(f"must have 1 to {MAX_TERMS} terms", key=name, value=values)
    return tuple(check_finite(f"{name}[{i}]", v) for i, v in enumerate(items))


def check_mode(mode: str) -> str:
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
    e2 = {"uniaxial": -0.5 * e, "equibiaxial": e, "planar": np.zeros_like(e)}[check_mode(mode)]
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

    @property
    def parts(self) -> tuple[tuple[str, Material], ...]:
        """``(parameter-name prefix, material)`` of each material of the body: ``(("",
        self),)``; a body of several materials
        (:class:`~warptissue.materials.MaterialRegions`) has one per region."""
        return (("", self),)

    def part_of(self, name: str) -> tuple[int, str]:
        """The index in :attr:`parts` of the material that parameter ``name`` belongs to, and
        the name within it: ``(0, name)``."""
        return 0, name

    def with_parts(self, materials: Sequence[Material]) -> Material:
        """A copy with new materials, one per entry of :attr:`parts`: the one given."""
        if len(materials) != 1:
            raise InputError("one material per part: 1 expected", value=len(materials))
        return materials[0]

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


def optional_bulk_modulus(value: float | None) -> float | None:
    return None if value is None else check_positive("bulk_modulus_Pa", value)


def with_bulk(values: dict[str, float], bulk_modulus_Pa: float | None) -> dict[str, float]:
    """``values`` plus ``bulk_modulus_Pa`` when the model has one."""
    if bulk_modulus_Pa is not None:
        values["bulk_modulus_Pa"] = bulk_modulus_Pa
    return values


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
