"""Homogeneous hyperelastic tests: closed-form stresses, fits and Drucker stability.

Incompressible, isotropic hyperelastic models (Abaqus conventions) under the homogeneous
tests of a materials lab, in closed form: uniaxial tension and compression, equibiaxial
tension and planar tension (pure shear). Measured force and displacement become nominal
stress and strain; the models are fitted with :func:`warptissue.fit.fit_curve` with an
absolute (seed 003, Eq. 4) or relative (Eq. 5) objective; and every fitted model gets a
Drucker stability check over the six standard modes, as Abaqus's material evaluation
reports it.

Sign convention: a :class:`HomogeneousTest` holds MAGNITUDES, positive in the loading
direction: ``nominal_strain = d / H0`` and ``nominal_stress_Pa = F / A0`` are both positive
for a specimen compressed by d under a compressive force F. The mechanics underneath is
signed (tension positive): the stretch is 1 - strain in compression and 1 + strain otherwise,
and the model's signed nominal stress is compared with the measured magnitude times the
loading's sign.

Notes:
    Kinematics (incompressible, principal stretches l1, l2, l3 with l1 l2 l3 = 1):
    uniaxial (l, l^-1/2, l^-1/2), equibiaxial (l, l, l^-2), planar (l, 1, l^-1).

    Invariant models W(I1, I2), with W1 = dW/dI1 and W2 = dW/dI2, give the nominal stress
    (force per reference area) along the loading direction (free lateral faces):

        uniaxial     S = 2 (l - l^-2) (W1 + W2 / l) = 2 (1 - l^-3) (l W1 + W2)
        equibiaxial  S = 2 (l - l^-5) (W1 + l^2 W2)
        planar       S = 2 (l - l^-3) (W1 + W2)

    Seed 003's Eq. 3 (uniaxial) agrees for neo-Hookean, RP2 and Mooney-Rivlin. Ogden
    (Abaqus form W = sum 2 mu_i / alpha_i^2 (l1^a + l2^a + l3^a - 3)) gives

        S = sum 2 mu_i / alpha_i (l^(a_i - 1) - l^(-k a_i - 1)),  k = 1/2, 2, 1

    for uniaxial, equibiaxial and planar; k = 1/2 is seed 003's Eq. 3. Each formula is the
    derivative of the energy along the path: S = dW/dl / (number of loaded directions), which
    the tests check by numerical differentiation.

    Drucker stability (Abaqus Theory Manual, hyperelastic stability): an incompressible
    material is stable when d tau : d eps > 0 for every logarithmic strain increment with
    trace zero (tau = Kirchhoff stress = Cauchy stress at J = 1). With the principal log
    strains (e1, e2, -e1 - e2) and W~(e1, e2) = W(exp e1, exp e2, exp(-e1 - e2)), one has
    tau_i - tau_3 = dW~/de_i, so d tau : d eps = de^T H de with H the 2 x 2 Hessian of W~:
    stable iff H is positive definite, checked at each state of the six modes (uniaxial,
    equibiaxial, planar; tension and compression). Along a uniaxial path the criterion
    contains the familiar one, d(true stress)/d(log strain) > 0 (H in the path direction
    (1, -1/2)), but it is stronger: it also checks the lateral directions. Non-finite values
    (overflow of l^alpha) count as unstable.
"""

from __future__ import annotations

import abc
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from warptissue.errors import InputError
from warptissue.fit import FitResult, RejectStep, fit_curve

__all__ = [
    "LOADINGS",
    "MODEL_NAMES",
    "STABILITY_MODES",
    "HomogeneousTest",
    "HyperelasticFit",
    "HyperelasticModel",
    "MooneyRivlin",
    "NeoHookean",
    "Ogden",
    "ReducedPolynomial",
    "StabilityReport",
    "StableRange",
    "drucker_stability",
    "fit_hyperelastic",
    "model_from_name",
    "model_label",
    "principal_stretches",
    "yeoh",
]

LOADINGS: dict[str, tuple[str, float]] = {
    "tension": ("uniaxial", 1.0),
    "compression": ("uniaxial", -1.0),
    "equibiaxial": ("equibiaxial", 1.0),
    "planar": ("planar", 1.0),
}
"""Loading name -> (deformation mode, sign of the stretch change)."""

STABILITY_MODES: tuple[str, ...] = (
    "uniaxial_tension",
    "uniaxial_compression",
    "equibiaxial_tension",
    "equibiaxial_compression",
    "planar_tension",
    "planar_compression",
)
"""The six modes of the Drucker stability check."""

MODEL_NAMES: tuple[str, ...] = (
    "neo_hookean",
    "mooney_rivlin",
    "reduced_polynomial",
    "yeoh",
    "ogden",
)
"""Names accepted by :func:`model_from_name` (``reduced_polynomial:N``, ``ogden:N``)."""


def _principal_log_strains(mode: str, log_stretch: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(e1, e2) of a mode at log stretch e of the loading direction; e3 = -e1 - e2."""
    if mode == "uniaxial":
        return log_stretch, -0.5 * log_stretch
    if mode == "equibiaxial":
        return log_stretch, log_stretch
    if mode == "planar":
        return log_stretch, np.zeros_like(log_stretch)
    raise InputError("mode must be uniaxial, equibiaxial or planar", value=mode)


def principal_stretches(stretch: np.ndarray, mode: str) -> np.ndarray:
    """The three principal stretches of an incompressible homogeneous test.

    Args:
        stretch: Stretch of the loading direction, shape (m,), > 0.
        mode: "uniaxial", "equibiaxial" or "planar".

    Returns:
        Principal stretches, shape (m, 3), with product 1.
    """
    e1, e2 = _principal_log_strains(mode, np.log(np.asarray(stretch, dtype=np.float64)))
    return np.exp(np.stack([e1, e2, -e1 - e2], axis=-1))


class HyperelasticModel(abc.ABC):
    """Base of the incompressible closed-form models.

    Subclasses are frozen dataclasses whose fields are the material parameters (names and
    units as in :mod:`warptissue.materials`). They provide the energy, the nominal stress of
    each mode and its gradient with respect to the parameters, and the log-strain Hessian
    used by the Drucker check.
    """

    name: str = ""

    @property
    @abc.abstractmethod
    def parameter_names(self) -> tuple[str, ...]:
        """Names of the entries of :attr:`parameter_vector`."""

    @property
    def parameter_units(self) -> tuple[str, ...]:
        """SI unit of each entry of :attr:`parameter_vector`."""
        return tuple("" if n.startswith("alpha") else "Pa" for n in self.parameter_names)

    @property
    @abc.abstractmethod
    def parameter_vector(self) -> np.ndarray:
        """The parameters as a vector, shape (n,)."""

    @abc.abstractmethod
    def with_parameters(self, vector: np.ndarray) -> HyperelasticModel:
        """A model of the same kind with the given parameter vector."""

    @property
    @abc.abstractmethod
    def initial_shear_modulus_Pa(self) -> float:
        """Small-strain shear modulus mu0."""

    @abc.abstractmethod
    def energy_density_Pa(self, stretches: np.ndarray) -> np.ndarray:
        """Strain energy per reference volume, from principal stretches (..., 3), J = 1."""

    @abc.abstractmethod
    def nominal_stress_Pa(self, stretch: np.ndarray, mode: str) -> np.ndarray:
        """Signed nominal stress along the loading direction, shape (m,)."""

    @abc.abstractmethod
    def nominal_stress_gradient(self, stretch: np.ndarray, mode: str) -> np.ndarray:
        """d nominal stress / d parameter_vector, shape (m, n)."""

    @abc.abstractmethod
    def principal_log_strain_hessian(self, log_strains: np.ndarray) -> np.ndarray:
        """Hessian of W(exp e1, exp e2, exp e3) in the principal log strains, (m, 3, 3), Pa.

        Any extension of W off the incompressible plane e1 + e2 + e3 = 0 serves, since only
        its restriction to that plane is used (the plane is linear in e).

        Args:
            log_strains: Principal logarithmic strains, shape (m, 3), summing to zero.
        """

    def log_strain_hessian(self, e1: np.ndarray, e2: np.ndarray) -> np.ndarray:
        """Hessian of W~(e1, e2) = W(exp e1, exp e2, exp(-e1 - e2)), shape (m, 2, 2), Pa."""
        e1 = np.atleast_1d(np.asarray(e1, dtype=np.float64))
        e2 = np.atleast_1d(np.asarray(e2, dtype=np.float64))
        ambient = self.principal_log_strain_hessian(np.stack([e1, e2, -e1 - e2], axis=-1))
        basis = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, -1.0]])
        return basis.T @ ambient @ basis

    def to_dict(self) -> dict[str, Any]:
        """``{"model": name, parameter: value, ...}``, the flat keys of
        ``warptissue.materials`` (``C10_Pa``, ``C20_Pa``, ``mu1_Pa``, ``alpha1``, ...)."""
        values = self.parameter_vector
        return {"model": self.name} | {
            key: float(v) for key, v in zip(self.parameter_names, values, strict=True)
        }

    def to_material(self, bulk_modulus_Pa: float) -> Any:
        """The matching :mod:`warptissue.materials` dataclass (nearly incompressible).

        Raises:
            InputError: warptissue.materials is not available in this installation.
        """
        try:
            from warptissue import materials
        except ImportError as exc:
            raise InputError("warptissue.materials is not available") from exc
        return self._material(materials, bulk_modulus_Pa)

    @abc.abstractmethod
    def _material(self, materials: Any, bulk_modulus_Pa: float) -> Any:
        """Build the dataclass from the ``warptissue.materials`` module."""


class _InvariantModel(HyperelasticModel):
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


@dataclass(frozen=True)
class ReducedPolynomial(_InvariantModel):
    """Incompressible reduced polynomial, W = sum_i C_i0 (I1 - 3)^i (seed 003, Eq. 2).

    Attributes:
        C_Pa: (C10, C20, ..., CN0) in Pa. One term is neo-Hookean; three are Yeoh.
    """

    C_Pa: tuple[float, ...]
    name: str = field(default="reduced_polynomial", init=False)

    def __post_init__(self) -> None:
        values = tuple(float(c) for c in self.C_Pa)
        if not values or not all(math.isfinite(c) for c in values):
            raise InputError("C_Pa must be a non-empty tuple of finite numbers", value=self.C_Pa)
        object.__setattr__(self, "C_Pa", values)

    @property
    def order(self) -> int:
        """Number of terms N."""
        return len(self.C_Pa)

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return tuple(f"C{i}0_Pa" for i in range(1, self.order + 1))

    @property
    def parameter_vector(self) -> np.ndarray:
        return np.array(self.C_Pa)

    def with_parameters(self, vector: np.ndarray) -> ReducedPolynomial:
        return ReducedPolynomial(tuple(float(v) for v in vector))

    @property
    def initial_shear_modulus_Pa(self) -> float:
        return 2.0 * self.C_Pa[0]

    def _basis(self, i1: np.ndarray, i2: np.ndarray) -> tuple[np.ndarray, ...]:
        x = np.asarray(i1) - 3.0
        powers = np.arange(1, self.order + 1)
        zero = np.zeros(x.shape + (self.order,))
        w = x[..., None] ** powers
        a = powers * x[..., None] ** (powers - 1)
        a11 = powers * (powers - 1) * x[..., None] ** np.maximum(powers - 2, 0)
        return a, zero, a11, zero, zero, w

    def _material(self, materials: Any, bulk_modulus_Pa: float) -> Any:
        return materials.ReducedPolynomial(C_Pa=self.C_Pa, bulk_modulus_Pa=bulk_modulus_Pa)


@dataclass(frozen=True)
class NeoHookean(_InvariantModel):
    """Incompressible neo-Hookean, W = C10 (I1 - 3), mu0 = 2 C10.

    Attributes:
        C10_Pa: C10 in Pa.
    """

    C10_Pa: float
    name: str = field(default="neo_hookean", init=False)

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return ("C10_Pa",)

    @property
    def parameter_vector(self) -> np.ndarray:
        return np.array([self.C10_Pa], dtype=np.float64)

    def with_parameters(self, vector: np.ndarray) -> NeoHookean:
        return NeoHookean(float(vector[0]))

    @property
    def initial_shear_modulus_Pa(self) -> float:
        return 2.0 * self.C10_Pa

    def _basis(self, i1: np.ndarray, i2: np.ndarray) -> tuple[np.ndarray, ...]:
        return ReducedPolynomial((self.C10_Pa,))._basis(i1, i2)

    def _material(self, materials: Any, bulk_modulus_Pa: float) -> Any:
        return materials.NeoHookean(C10_Pa=self.C10_Pa, bulk_modulus_Pa=bulk_modulus_Pa)


@dataclass(frozen=True)
class MooneyRivlin(_InvariantModel):
    """Incompressible Mooney-Rivlin, W = C10 (I1 - 3) + C01 (I2 - 3), mu0 = 2 (C10 + C01).

    Attributes:
        C10_Pa: C10 in Pa.
        C01_Pa: C01 in Pa.
    """

    C10_Pa: float
    C01_Pa: float
    name: str = field(default="mooney_rivlin", init=False)

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return ("C10_Pa", "C01_Pa")

    @property
    def parameter_vector(self) -> np.ndarray:
        return np.array([self.C10_Pa, self.C01_Pa], dtype=np.float64)

    def with_parameters(self, vector: np.ndarray) -> MooneyRivlin:
        return MooneyRivlin(float(vector[0]), float(vector[1]))

    @property
    def initial_shear_modulus_Pa(self) -> float:
        return 2.0 * (self.C10_Pa + self.C01_Pa)

    def _basis(self, i1: np.ndarray, i2: np.ndarray) -> tuple[np.ndarray, ...]:
        ones = np.ones(np.shape(i1))
        zeros = np.zeros(np.shape(i1) + (2,))
        a = np.stack([ones, 0.0 * ones], axis=-1)
        b = np.stack([0.0 * ones, ones], axis=-1)
        w = np.stack([np.asarray(i1) - 3.0, np.asarray(i2) - 3.0], axis=-1)
        return a, b, zeros, zeros, zeros, w

    def _material(self, materials: Any, bulk_modulus_Pa: float) -> Any:
        return materials.MooneyRivlin(
            C10_Pa=self.C10_Pa, C01_Pa=self.C01_Pa, bulk_modulus_Pa=bulk_modulus_Pa
        )


def yeoh(C10_Pa: float, C20_Pa: float, C30_Pa: float) -> ReducedPolynomial:
    """The Yeoh model: a reduced polynomial of order 3."""
    return ReducedPolynomial((C10_Pa, C20_Pa, C30_Pa))


_OGDEN_K = {"uniaxial": 0.5, "equibiaxial": 2.0, "planar": 1.0}


@dataclass(frozen=True)
class Ogden(HyperelasticModel):
    """Incompressible Ogden, W = sum 2 mu_i / alpha_i^2 (l1^a_i + l2^a_i + l3^a_i - 3).

    Abaqus convention; mu0 = sum mu_i. The parameter vector is (mu1, alpha1, mu2, alpha2, ...).

    Attributes:
        mu_Pa: (mu_1, ..., mu_N) in Pa.
        alpha: (alpha_1, ..., alpha_N), dimensionless, non-zero.
    """

    mu_Pa: tuple[float, ...]
    alpha: tuple[float, ...]
    name: str = field(default="ogden", init=False)

    def __post_init__(self) -> None:
        mu = tuple(float(v) for v in self.mu_Pa)
        alpha = tuple(float(v) for v in self.alpha)
        if not mu or len(mu) != len(alpha):
            raise InputError("Ogden needs as many alpha as mu_Pa values", value=(mu, alpha))
        if not all(math.isfinite(v) for v in mu + alpha) or any(a == 0.0 for a in alpha):
            raise InputError("Ogden parameters must be finite, with alpha != 0", value=alpha)
        object.__setattr__(self, "mu_Pa", mu)
        object.__setattr__(self, "alpha", alpha)

    @property
    def order(self) -> int:
        """Number of terms N."""
        return len(self.mu_Pa)

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return tuple(name for i in range(1, self.order + 1) for name in (f"mu{i}_Pa", f"alpha{i}"))

    @property
    def parameter_vector(self) -> np.ndarray:
        return np.ravel(np.column_stack([self.mu_Pa, self.alpha]))

    def with_parameters(self, vector: np.ndarray) -> Ogden:
        pairs = np.asarray(vector, dtype=np.float64).reshape(-1, 2)
        return Ogden(tuple(pairs[:, 0]), tuple(pairs[:, 1]))

    @property
    def initial_shear_modulus_Pa(self) -> float:
        return float(sum(self.mu_Pa))

    def energy_density_Pa(self, stretches: np.ndarray) -> np.ndarray:
        lam = np.asarray(stretches, dtype=np.float64)
        return sum(
            2.0 * mu / a**2 * (np.sum(lam**a, axis=-1) - 3.0)
            for mu, a in zip(self.mu_Pa, self.alpha, strict=True)
        )

    def nominal_stress_Pa(self, stretch: np.ndarray, mode: str) -> np.ndarray:
        lam = np.atleast_1d(np.asarray(stretch, dtype=np.float64))
        k = _OGDEN_K[mode]
        return sum(
            2.0 * mu / a * (lam ** (a - 1.0) - lam ** (-k * a - 1.0))
            for mu, a in zip(self.mu_Pa, self.alpha, strict=True)
        )

    def nominal_stress_gradient(self, stretch: np.ndarray, mode: str) -> np.ndarray:
        lam = np.atleast_1d(np.asarray(stretch, dtype=np.float64))
        k = _OGDEN_K[mode]
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

    def _material(self, materials: Any, bulk_modulus_Pa: float) -> Any:
        return materials.Ogden(mu_Pa=self.mu_Pa, alpha=self.alpha, bulk_modulus_Pa=bulk_modulus_Pa)


def model_from_name(spec: str) -> HyperelasticModel:
    """A model with placeholder parameters from a name such as ``reduced_polynomial:2``.

    Accepted: ``neo_hookean``, ``mooney_rivlin``, ``reduced_polynomial:N`` (default N = 2),
    ``yeoh``, ``ogden:N`` (default N = 1).

    Raises:
        InputError: An unknown name or a bad order.
    """
    kind, _, order_text = spec.strip().lower().partition(":")
    if kind not in MODEL_NAMES:
        raise InputError(f"unknown model; choose from {MODEL_NAMES}", value=spec)
    if order_text and kind not in ("reduced_polynomial", "ogden"):
        raise InputError(f"model {kind!r} takes no order", value=spec)
    default_order = {"reduced_polynomial": 2, "ogden": 1}.get(kind, 1)
    try:
        order = int(order_text) if order_text else default_order
    except ValueError:
        raise InputError("the model order must be an integer", value=spec) from None
    if not 1 <= order <= 6:
        raise InputError("the model order must be between 1 and 6", value=spec)
    if kind == "neo_hookean":
        return NeoHookean(1.0)
    if kind == "mooney_rivlin":
        return MooneyRivlin(1.0, 1.0)
    if kind == "reduced_polynomial":
        return ReducedPolynomial((1.0,) * order)
    if kind == "yeoh":
        return yeoh(1.0, 1.0, 1.0)
    return Ogden((1.0,) * order, tuple(2.0 * (i + 1) for i in range(order)))


def model_label(model: HyperelasticModel) -> str:
    """Short label: ``neo_hookean``, ``reduced_polynomial:2``, ``ogden:3``, ..."""
    if isinstance(model, ReducedPolynomial | Ogden):
        return f"{model.name}:{model.order}"
    return model.name


@dataclass(frozen=True)
class HomogeneousTest:
    """A homogeneous test record as nominal strain and nominal stress magnitudes.

    Attributes:
        loading: "tension", "compression", "equibiaxial" (tension) or "planar" (tension).
        nominal_strain: d / H0, positive in the loading direction, shape (m,).
        nominal_stress_Pa: F / A0, positive in the loading direction, shape (m,).
        name: A label for reports.
    """

    loading: str
    nominal_strain: np.ndarray
    nominal_stress_Pa: np.ndarray
    name: str = ""

    def __post_init__(self) -> None:
        if self.loading not in LOADINGS:
            raise InputError(f"loading must be one of {tuple(LOADINGS)}", value=self.loading)
        strain = np.asarray(self.nominal_strain, dtype=np.float64).reshape(-1)
        stress = np.asarray(self.nominal_stress_Pa, dtype=np.float64).reshape(-1)
        if strain.size == 0 or strain.shape != stress.shape:
            raise InputError(
                "nominal strain and stress must be non-empty and of equal length",
                value=(strain.size, stress.size),
            )
        if not (np.all(np.isfinite(strain)) and np.all(np.isfinite(stress))):
            raise InputError("nominal strain and stress must be finite")
        if self.loading == "compression" and np.any(strain >= 1.0):
            index = int(np.flatnonzero(strain >= 1.0)[0])
            raise InputError(
                f"compressive strain must stay below 1 (index {index})", value=strain[index]
            )
        if np.any(strain <= -1.0) or np.median(strain) < 0.0:
            raise InputError(
                "strains are magnitudes, positive in the loading direction (see the sign "
                "convention of warptissue.uniaxial); got mostly negative or <= -1 values",
                value=float(np.median(strain)),
            )
        object.__setattr__(self, "nominal_strain", strain)
        object.__setattr__(self, "nominal_stress_Pa", stress)

    @classmethod
    def from_force_displacement(
        cls,
        displacement_m: np.ndarray,
        force_N: np.ndarray,
        *,
        area_m2: float,
        height_m: float,
        loading: str,
        name: str = "",
    ) -> HomogeneousTest:
        """Nominal stress F / A0 and nominal strain d / H0 from a force-displacement record.

        Args:
            displacement_m: Platen displacement, positive in the loading direction, (m,).
            force_N: Force, positive in the loading direction (compressive force positive for
                a compression test), shape (m,).
            area_m2: Undeformed loaded area A0 (> 0).
            height_m: Undeformed gauge length H0 (> 0).
            loading: See :data:`LOADINGS`.
            name: A label for reports.

        Raises:
            InputError: Non-positive geometry, or invalid data (see the class).
        """
        for label, value in (("area_m2", area_m2), ("height_m", height_m)):
            if not (math.isfinite(value) and value > 0.0):
                raise InputError(f"{label} must be positive", column=label, value=value)
        strain = np.asarray(displacement_m, dtype=np.float64) / height_m
        stress = np.asarray(force_N, dtype=np.float64) / area_m2
        return cls(loading, strain, stress, name)

    @property
    def mode(self) -> str:
        """The deformation mode: uniaxial, equibiaxial or planar."""
        return LOADINGS[self.loading][0]

    @property
    def sign(self) -> float:
        """-1 for compression, +1 otherwise."""
        return LOADINGS[self.loading][1]

    @property
    def stretch(self) -> np.ndarray:
        """Stretch of the loading direction, 1 + sign * strain, shape (m,)."""
        return 1.0 + self.sign * self.nominal_strain

    def window(self, min_strain: float) -> HomogeneousTest:
        """The points with nominal strain above ``min_strain`` (all points when it is 0)."""
        keep = (
            self.nominal_strain > min_strain
            if min_strain > 0.0
            else np.ones(self.nominal_strain.size, bool)
        )
        if not np.any(keep):
            raise InputError(
                f"no data above the strain window's lower end in test {self.name!r}",
                value=min_strain,
            )
        return HomogeneousTest(
            self.loading, self.nominal_strain[keep], self.nominal_stress_Pa[keep], self.name
        )

    def predicted_stress_Pa(self, model: HyperelasticModel) -> np.ndarray:
        """Model nominal stress magnitude in the loading direction, shape (m,)."""
        return self.sign * model.nominal_stress_Pa(self.stretch, self.mode)


@dataclass(frozen=True)
class StableRange:
    """Drucker stability along one mode.

    Attributes:
        mode: One of :data:`STABILITY_MODES`.
        unstable_from_strain: Nominal strain magnitude where the material first becomes
            unstable, or None when it is stable over the whole checked range.
        checked_up_to_strain: Upper end of the checked range of nominal strain magnitude.
    """

    mode: str
    unstable_from_strain: float | None
    checked_up_to_strain: float

    @property
    def stable(self) -> bool:
        """Stable over the whole checked range."""
        return self.unstable_from_strain is None


@dataclass(frozen=True)
class StabilityReport:
    """Drucker stability over the six modes."""

    ranges: tuple[StableRange, ...]

    def __getitem__(self, mode: str) -> StableRange:
        for entry in self.ranges:
            if entry.mode == mode:
                return entry
        raise KeyError(mode)

    @property
    def stable_everywhere(self) -> bool:
        """Stable in every mode over the checked ranges."""
        return all(entry.stable for entry in self.ranges)

    @property
    def stable_up_to_strain(self) -> float | None:
        """Smallest strain at which any mode becomes unstable, or None if none does."""
        limits = [e.unstable_from_strain for e in self.ranges if not e.stable]
        return min(limits) if limits else None

    def to_dict(self) -> dict[str, Any]:
        """{mode: {"unstable_from_strain", "checked_up_to_strain"}, "stable_up_to_strain"}."""
        summary: dict[str, Any] = {
            e.mode: {
                "unstable_from_strain": e.unstable_from_strain,
                "checked_up_to_strain": e.checked_up_to_strain,
            }
            for e in self.ranges
        }
        summary["stable_up_to_strain"] = self.stable_up_to_strain
        return summary


def _is_stable(model: HyperelasticModel, mode: str, stretch: np.ndarray) -> np.ndarray:
    """Positive definiteness of the Hessian on the plane of trace-free log strains.

    The plane is parametrized by eliminating, point by point, the principal direction k of
    SMALLEST ambient curvature G_kk (basis e_i - e_k, e_j - e_k). Eliminating a stiff
    direction instead would bury the soft one under rounding: for Ogden with
    G = diag(c), det = c_i c_j + c_k (c_i + c_j) is then formed as (c_i + c_k)(c_j + c_k)
    - c_k^2, which cancels when c_k >> c_i, c_j.
    """
    e1, e2 = _principal_log_strains(mode, np.log(stretch))
    strains = np.stack([e1, e2, -e1 - e2], axis=-1)
    with np.errstate(over="ignore", invalid="ignore"):
        ambient = model.principal_log_strain_hessian(strains)
        order = np.argsort(np.diagonal(ambient, axis1=1, axis2=2), axis=1)
        k, i, j = order[:, 0], order[:, 1], order[:, 2]
        rows = np.arange(strains.shape[0])

        def g(a: np.ndarray, b: np.ndarray) -> np.ndarray:
            return ambient[rows, a, b]

        h11 = g(i, i) - 2.0 * g(i, k) + g(k, k)
        h22 = g(j, j) - 2.0 * g(j, k) + g(k, k)
        h12 = g(i, j) - g(i, k) - g(j, k) + g(k, k)
        determinant = h11 * h22 - h12 * h12
        rounding = 16.0 * np.finfo(np.float64).eps * (np.abs(h11 * h22) + h12 * h12)
        stable = (h11 > 0.0) & (determinant > rounding)
    return stable & np.isfinite(determinant)


def drucker_stability(
    model: HyperelasticModel,
    *,
    max_tension_strain: float = 10.0,
    max_compression_strain: float = 0.95,
    samples: int = 2000,
) -> StabilityReport:
    """Drucker stability of an incompressible model over the six standard modes.

    Scans the nominal strain magnitude from 0 to the maximum of each mode (log-spaced
    samples plus 0) and refines the first unstable point by bisection to 1e-9 relative.

    Args:
        model: The fitted model.
        max_tension_strain: Largest nominal strain checked in tension (Abaqus checks to 10).
        max_compression_strain: Largest nominal strain magnitude checked in compression (< 1).
        samples: Samples per mode before bisection.

    Returns:
        The :class:`StabilityReport` (criterion in the module Notes).
    """
    if not 0.0 < max_compression_strain < 1.0 or not max_tension_strain > 0.0:
        raise InputError(
            "need max_tension_strain > 0 and 0 < max_compression_strain < 1",
            value=(max_tension_strain, max_compression_strain),
        )
    ranges = []
    for mode_name in STABILITY_MODES:
        mode, _, direction = mode_name.partition("_")
        sign = 1.0 if direction == "tension" else -1.0
        limit = max_tension_strain if sign > 0.0 else max_compression_strain
        strains = np.concatenate([[0.0], np.geomspace(1e-6 * limit, limit, samples)])
        stable = _is_stable(model, mode, 1.0 + sign * strains)
        if np.all(stable):
            ranges.append(StableRange(mode_name, None, limit))
            continue
        first = int(np.argmin(stable))
        if first == 0:
            ranges.append(StableRange(mode_name, 0.0, limit))
            continue
        low, high = strains[first - 1], strains[first]
        while high - low > 1e-9 * high:
            middle = 0.5 * (low + high)
            if _is_stable(model, mode, np.array([1.0 + sign * middle]))[0]:
                low = middle
            else:
                high = middle
        ranges.append(StableRange(mode_name, float(high), limit))
    return StabilityReport(tuple(ranges))


@dataclass
class HyperelasticFit:
    """A fitted homogeneous hyperelastic model.

    Attributes:
        model: The model with the fitted parameters.
        result: The engine's result (parameters, statistics, R² over the fitted window).
        tests: The tests that were fitted, full records (not windowed).
        objective: "absolute" or "relative".
        min_strain: Lower end of the strain window.
        stability: The Drucker check of the fitted model.
    """

    model: HyperelasticModel
    result: FitResult
    tests: tuple[HomogeneousTest, ...]
    objective: str
    min_strain: float
    stability: StabilityReport

    @property
    def label(self) -> str:
        """Model label, e.g. ``reduced_polynomial:2``."""
        return model_label(self.model)

    def to_dict(self) -> dict[str, Any]:
        """JSON-compatible: the model, the fit, the window and the stability check."""
        return {
            "model": self.model.to_dict(),
            "initial_shear_modulus_Pa": self.model.initial_shear_modulus_Pa,
            "objective": self.objective,
            "min_strain": self.min_strain,
            "loadings": [t.loading for t in self.tests],
            "fit": self.result.to_dict(),
            "stability": self.stability.to_dict(),
        }

    def comparison_row(self) -> dict[str, Any]:
        """One row of a model-comparison table (seed 003 Table 1 plus the stable range)."""
        mode_names = {f"{t.mode}_{'compression' if t.sign < 0 else 'tension'}" for t in self.tests}
        tested = [self.stability[m].unstable_from_strain for m in sorted(mode_names)]
        unstable = [value for value in tested if value is not None]
        return {
            "model": self.label,
            "objective": self.objective,
            "r_squared": self.result.r_squared,
            "rmse_Pa": self.result.rmse,
            "status": self.result.status,
            "unstable_from_strain_tested_modes": min(unstable) if unstable else None,
            "stable_up_to_strain_all_modes": self.stability.stable_up_to_strain,
        }


def _ogden_start(
    template: Ogden, tests: Sequence[HomogeneousTest], divisors: np.ndarray
) -> np.ndarray:
    """Best (mu, alpha) on a grid of alphas, with mu solved linearly for each (the model is
    linear in mu at fixed alpha)."""
    grid = (-12.0, -8.0, -5.0, -3.0, -2.0, -1.0, 1.0, 2.0, 3.0, 5.0, 8.0, 12.0, 20.0)
    data = np.concatenate([t.nominal_stress_Pa for t in tests]) / divisors
    best, best_cost = None, math.inf
    for alphas in itertools.combinations(grid, template.order):
        trial = Ogden((1.0,) * template.order, alphas)
        with np.errstate(over="ignore", invalid="ignore"):
            gradient = (
                np.concatenate(
                    [t.sign * trial.nominal_stress_gradient(t.stretch, t.mode) for t in tests]
                )[:, 0::2]
                / divisors[:, None]
            )
        if not np.all(np.isfinite(gradient)):
            continue
        mu, *_ = np.linalg.lstsq(gradient, data, rcond=None)
        cost = float(np.sum((gradient @ mu - data) ** 2))
        if cost < best_cost:
            best, best_cost = np.ravel(np.column_stack([mu, alphas])), cost
    if best is None:
        raise InputError("no Ogden starting point gives finite stresses for these data")
    return best


def fit_hyperelastic(
    model: str | HyperelasticModel,
    tests: HomogeneousTest | Sequence[HomogeneousTest],
    *,
    objective: str = "absolute",
    min_strain: float | None = None,
    method: str = "lm",
    bounds: tuple[Any, Any] = (-np.inf, np.inf),
    progress: bool = False,
) -> HyperelasticFit:
    """Fit an incompressible hyperelastic model to one or several homogeneous tests.

    Starting values: given a model instance, its parameters; given a name, the linear
    least-squares solution for the invariant models (they are linear in their
    parameters), and for Ogden the best of a grid of alphas with mu solved linearly. The
    engine then runs with analytic Jacobians.

    Args:
        model: A name (see :func:`model_from_name`) or a model instance (its parameters are
            the starting point).
        tests: One test or several (a joint fit; residuals are concatenated).
        objective: "absolute" (seed 003, Eq. 4) or "relative" (Eq. 5).
        min_strain: Fit only points with nominal strain above this; default 0.05 for the
            relative objective (as seed 003) and 0 (all points) for the absolute one.
        method: "lm" or "salm".
        bounds: Parameter bounds in the order of the model's parameter vector.
        progress: Show the engine's progress bar.

    Returns:
        The :class:`HyperelasticFit` with its Drucker stability check.

    Raises:
        InputError: Bad model name, objective or data (e.g. zero stress in the window of a
            relative fit).
    """
    template = model_from_name(model) if isinstance(model, str) else model
    if not isinstance(template, HyperelasticModel):
        raise InputError("model must be a name or a warptissue.uniaxial model", value=model)
    test_list = (tests,) if isinstance(tests, HomogeneousTest) else tuple(tests)
    if not test_list:
        raise InputError("at least one test is needed")
    if objective not in ("absolute", "relative"):
        raise InputError("objective must be 'absolute' or 'relative'", value=objective)
    window = (0.05 if objective == "relative" else 0.0) if min_strain is None else min_strain
    if not (math.isfinite(window) and window >= 0.0):
        raise InputError("min_strain must be >= 0", value=min_strain)
    fitted_tests = [t.window(window) for t in test_list]
    data = np.concatenate([t.nominal_stress_Pa for t in fitted_tests])
    divisors = data.copy() if objective == "relative" else np.ones_like(data)
    if objective == "relative" and np.any(data == 0.0):
        raise InputError("the relative objective needs non-zero stresses in the strain window")

    def model_at(p: np.ndarray) -> HyperelasticModel:
        try:
            return template.with_parameters(p)
        except InputError as exc:
            raise RejectStep(str(exc)) from exc

    def predictions(p: np.ndarray) -> np.ndarray:
        candidate = model_at(p)
        with np.errstate(over="ignore", invalid="ignore"):
            return np.concatenate([t.predicted_stress_Pa(candidate) for t in fitted_tests])

    def jacobian(p: np.ndarray) -> np.ndarray:
        candidate = model_at(p)
        return np.concatenate(
            [t.sign * candidate.nominal_stress_gradient(t.stretch, t.mode) for t in fitted_tests]
        )

    if not isinstance(model, str):
        start = template.parameter_vector
    elif isinstance(template, Ogden):
        start = _ogden_start(template, fitted_tests, divisors)
    else:
        design = jacobian(template.parameter_vector) / divisors[:, None]
        start, *_ = np.linalg.lstsq(design, data / divisors, rcond=None)
    lower = np.broadcast_to(np.asarray(bounds[0], dtype=np.float64), start.shape)
    upper = np.broadcast_to(np.asarray(bounds[1], dtype=np.float64), start.shape)
    start = np.clip(start, lower, upper)
    result = fit_curve(
        predictions,
        start,
        data,
        objective=objective,
        jac=jacobian,
        bounds=bounds,
        method=method,
        parameter_names=template.parameter_names,
        parameter_units=template.parameter_units,
        progress=progress,
        max_iterations=500,
        ftol=1e-12,
        xtol=1e-12,
        gtol=1e-10,
    )
    fitted = template.with_parameters(result.x)
    return HyperelasticFit(
        model=fitted,
        result=result,
        tests=test_list,
        objective=objective,
        min_strain=window,
        stability=drucker_stability(fitted),
    )
