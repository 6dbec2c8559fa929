"""Contact formulas for indentation moduli: Sneddon's flat punch and Hertz's sphere.

All functions take SI units and work elementwise on arrays. The half-space is linear
elastic, isotropic and homogeneous, the indenter rigid and the contact frictionless.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from scipy.interpolate import CubicSpline

from warptissue.errors import ConvergenceError, InputError
from warptissue.lsq import fit_curve
from warptissue.lsq.plausibility import modulus_warnings

if TYPE_CHECKING:
    from warptissue.lsq import FitResult

__all__ = [
    "HAYES_MAX_RADIUS_OVER_THICKNESS",
    "SMALL_STRAIN_DEPTH_OVER_THICKNESS",
    "flat_punch_force_N",
    "flat_punch_modulus_Pa",
    "flat_punch_modulus_printed_Pa",
    "fit_punch_modulus",
    "hayes_kappa",
    "hertz_contact_radius_m",
    "hertz_force_N",
    "hertz_modulus_Pa",
    "plane_strain_modulus_Pa",
]


HAYES_MAX_RADIUS_OVER_THICKNESS = 16.0
"""Largest a/h for which :func:`hayes_kappa` is computed (and verified: the thin-layer limits
of the tests reach a/h = 16). Beyond it the Nystrom discretization no longer resolves the
kernel (at a/h = 30-50 it returns wrong, even negative, values) and the layer is so thin that
the linear theory needs depths far below the layer thickness."""

SMALL_STRAIN_DEPTH_OVER_THICKNESS = 0.1
"""Depth over layer thickness above which :func:`fit_punch_modulus` warns: Hayes et al.'s
factor is a small-strain (linear elastic) result."""


def _check(radius_m: float, poissons_ratio: float) -> None:
    if not (math.isfinite(radius_m) and radius_m > 0.0):
        raise InputError("radius_m must be a finite positive number", value=float(radius_m))
    if not (math.isfinite(poissons_ratio) and -1.0 < poissons_ratio <= 0.5):
        raise InputError("poissons_ratio must lie in (-1, 0.5]", value=float(poissons_ratio))


def _depth(depth_m: np.ndarray | float) -> np.ndarray:
    depth = np.asarray(depth_m, dtype=np.float64)
    if np.any(~np.isfinite(depth)) or np.any(depth <= 0.0):
        raise InputError("depths must be finite and positive", column="depth_m")
    return depth


def plane_strain_modulus_Pa(youngs_modulus_Pa: float, poissons_ratio: float) -> float:
    """E* = E / (1 - nu^2), the contact modulus against a rigid indenter."""
    return youngs_modulus_Pa / (1.0 - poissons_ratio**2)


def flat_punch_force_N(
    depth_m: np.ndarray | float,
    *,
    radius_m: float,
    youngs_modulus_Pa: float,
    poissons_ratio: float,
) -> np.ndarray:
    """Sneddon's flat cylindrical punch: F = 2 a E* delta, E* = E / (1 - nu^2).

    Args:
        depth_m: Indentation depth delta > 0, any shape.
        radius_m: Punch radius a.
        youngs_modulus_Pa: E of the half-space.
        poissons_ratio: nu in (-1, 0.5].

    Returns:
        Force, the shape of ``depth_m``, in newtons.
    """
    _check(radius_m, poissons_ratio)
    stiffness = 2.0 * radius_m * plane_strain_modulus_Pa(youngs_modulus_Pa, poissons_ratio)
    return stiffness * _depth(depth_m)


def flat_punch_modulus_Pa(
    force_N: np.ndarray | float,
    depth_m: np.ndarray | float,
    *,
    radius_m: float,
    poissons_ratio: float,
    thickness_m: float | None = None,
) -> np.ndarray:
    """Young's modulus from a flat-punch force and depth: E = (1 - nu^2) F / (2 a delta kappa).

    Args:
        force_N: Measured force F, broadcastable with ``depth_m``.
        depth_m: Indentation depth delta > 0.
        radius_m: Punch radius a.
        poissons_ratio: nu in (-1, 0.5]; 0.5 for incompressible tissue.
        thickness_m: Thickness h of a layer bonded to a rigid base; None (default) for a
            half-space (kappa = 1). Otherwise kappa = :func:`hayes_kappa` (a / h, nu).

    Returns:
        E in pascals, the broadcast shape.

    Notes:
        Sneddon (1965), Int. J. Eng. Sci. 3:47, the flat-ended cylinder: F = 2 a E* delta.
        Kim et al. Eq. 2 prints (1 - nu) instead of (1 - nu^2); the printed form
        is smaller by the factor 1 / (1 + nu), 2/3 at nu = 0.5. It is available, for
        reproducing the paper's numbers only, as :func:`flat_punch_modulus_printed_Pa`.
    """
    _check(radius_m, poissons_ratio)
    force = np.asarray(force_N, dtype=np.float64)
    correction = _layer_kappa(radius_m, poissons_ratio, thickness_m)
    return (1.0 - poissons_ratio**2) * force / (2.0 * radius_m * _depth(depth_m) * correction)


def _layer_kappa(radius_m: float, poissons_ratio: float, thickness_m: float | None) -> float:
    """kappa of a flat punch on a layer of ``thickness_m`` bonded to a rigid base.

    1.0 for a half-space (``thickness_m`` None), else :func:`hayes_kappa` (a / h, nu).

    Raises:
        InputError: ``thickness_m`` is given but not a finite positive number.
    """
    if thickness_m is None:
        return 1.0
    if not (math.isfinite(thickness_m) and thickness_m > 0.0):
        raise InputError("thickness_m must be a finite positive number", value=float(thickness_m))
    return hayes_kappa(radius_m / thickness_m, poissons_ratio)


def hayes_kappa(
    radius_over_thickness: float, poissons_ratio: float, *, node_count: int = 48
) -> float:
    """Finite-thickness factor kappa(a/h, nu) of a flat punch on a layer bonded to a rigid base.

    F = 2 a E delta kappa / (1 - nu^2) for a frictionless rigid flat punch of radius a on an
    elastic layer of thickness h bonded to a rigid half-space (Hayes, Keer, Herrmann and
    Mockros 1972, J. Biomech. 5:541). kappa -> 1 as a/h -> 0 (Sneddon's half-space).

    Args:
        radius_over_thickness: a / h >= 0.
        poissons_ratio: nu in (-1, 0.5].
        node_count: Gauss-Legendre nodes of the Nystrom discretization.

    Returns:
        kappa >= 1.

    Raises:
        InputError: a/h negative, not finite, or above :data:`HAYES_MAX_RADIUS_OVER_THICKNESS`
            (a layer much thinner than the punch radius: the factor is not computed there).
        ConvergenceError: The discretization returned kappa < 1 (never within the range).

    Notes:
        Computed, not tabulated: with the contact pressure written as an Abel transform of
        phi(t), the mixed boundary-value problem reduces to the Fredholm equation
        phi(x) - (lambda/pi) int_0^1 [F(lambda(x-y)) + F(lambda(x+y))] phi(y) dy = 1,
        lambda = a/h, F(z) = int_0^inf (1 - k(s)) cos(s z) ds, kappa = int_0^1 phi dx, with
        the bonded-layer surface compliance
        k(s) = (2 eta sinh 2s - 4 s) / (2 eta cosh 2s + 1 + eta^2 + 4 s^2), eta = 3 - 4 nu.
        Solved by Nystrom quadrature; F is integrated by Gauss-Legendre on s in [0, 25]
        (composite, 1 - k decays as exp(-2 s)) and splined in z. Checked in the tests against the
        half-space limit, the compressible thin-layer (oedometric) limit
        d kappa / d(a/h) -> pi (1 - nu)^2 / (2 (1 - 2 nu)) and, for nu = 0.5, the
        squeeze-flow limit kappa / (a/h)^3 -> 3 pi / 64.
    """
    _check(1.0, poissons_ratio)
    ratio = float(radius_over_thickness)
    if not (math.isfinite(ratio) and ratio >= 0.0):
        raise InputError("radius_over_thickness must be finite and non-negative", value=ratio)
    if ratio > HAYES_MAX_RADIUS_OVER_THICKNESS:
        raise InputError(
            f"radius/thickness a/h = {ratio:.4g} is beyond the range of the finite-thickness "
            f"(Hayes) correction, a/h <= {HAYES_MAX_RADIUS_OVER_THICKNESS:g}: the layer is much "
            "thinner than the punch radius; use a smaller punch or a thicker layer",
        )
    if ratio == 0.0:
        return 1.0
    x, w = np.polynomial.legendre.leggauss(int(node_count))
    x, w = 0.5 * (x + 1.0), 0.5 * w
    z_max = 2.0 * ratio
    s_max = 25.0
    panel_count = int(16 + 3 * z_max * s_max / (2 * math.pi))  # >= 3 panels per cosine period
    gauss_s, gauss_w = np.polynomial.legendre.leggauss(16)
    panel_width = s_max / panel_count
    s = ((np.arange(panel_count)[:, None] + 0.5 * (gauss_s + 1.0)) * panel_width).ravel()
    ws = np.tile(0.5 * panel_width * gauss_w, panel_count)
    eta = 3.0 - 4.0 * poissons_ratio
    ch, sh = np.cosh(2 * s), np.sinh(2 * s)
    one_minus_k = (2 * eta * (ch - sh) + 1 + eta**2 + 4 * s**2 + 4 * s) / (
        2 * eta * ch + 1 + eta**2 + 4 * s**2
    )
    z_grid = np.linspace(0.0, z_max, int(64 + 16 * z_max))
    f_grid = (np.cos(np.multiply.outer(z_grid, s)) * one_minus_k) @ ws
    f = CubicSpline(z_grid, f_grid, bc_type=((1, 0.0), (2, 0.0)))
    kernel = f(ratio * np.abs(x[:, None] - x[None, :])) + f(ratio * (x[:, None] + x[None, :]))
    phi = np.linalg.solve(np.eye(x.size) - ratio / math.pi * kernel * w[None, :], np.ones(x.size))
    kappa = float(phi @ w)
    if not kappa >= 1.0:
        raise ConvergenceError(
            f"the Hayes factor at a/h = {ratio:.4g}, nu = {poissons_ratio:.4g} came out "
            f"{kappa:.4g} < 1 (not resolved by {int(node_count)} nodes)"
        )
    return kappa


def flat_punch_modulus_printed_Pa(
    force_N: np.ndarray | float,
    depth_m: np.ndarray | float,
    *,
    radius_m: float,
    poissons_ratio: float,
) -> np.ndarray:
    """Kim et al. Eq. 2 AS PRINTED, E = (1 - nu) F / (2 a delta). Not Sneddon's result.

    Use only to reproduce the paper's moduli; :func:`flat_punch_modulus_Pa` is correct.
    ``flat_punch_modulus_Pa = (1 + nu) * flat_punch_modulus_printed_Pa``.
    """
    _check(radius_m, poissons_ratio)
    force = np.asarray(force_N, dtype=np.float64)
    return (1.0 - poissons_ratio) * force / (2.0 * radius_m * _depth(depth_m))


def hertz_force_N(
    depth_m: np.ndarray | float,
    *,
    radius_m: float,
    youngs_modulus_Pa: float,
    poissons_ratio: float,
) -> np.ndarray:
    """Hertz's rigid sphere on a half-space: F = (4/3) E* sqrt(R) delta^(3/2).

    Args:
        depth_m: Indentation depth delta > 0, any shape.
        radius_m: Sphere radius R.
        youngs_modulus_Pa: E of the half-space.
        poissons_ratio: nu in (-1, 0.5].

    Returns:
        Force, the shape of ``depth_m``, in newtons.

    Notes:
        Valid for small depths (contact radius sqrt(R delta) much smaller than R).
    """
    _check(radius_m, poissons_ratio)
    contact_modulus = plane_strain_modulus_Pa(youngs_modulus_Pa, poissons_ratio)
    return 4.0 / 3.0 * contact_modulus * math.sqrt(radius_m) * _depth(depth_m) ** 1.5


def hertz_modulus_Pa(
    force_N: np.ndarray | float,
    depth_m: np.ndarray | float,
    *,
    radius_m: float,
    poissons_ratio: float,
) -> np.ndarray:
    """Young's modulus from a spherical indentation: E = 3 (1 - nu^2) F / (4 sqrt(R) delta^1.5)."""
    _check(radius_m, poissons_ratio)
    force = np.asarray(force_N, dtype=np.float64)
    denominator = 4.0 * math.sqrt(radius_m) * _depth(depth_m) ** 1.5
    return 3.0 * (1.0 - poissons_ratio**2) * force / denominator


def hertz_contact_radius_m(depth_m: np.ndarray | float, *, radius_m: float) -> np.ndarray:
    """Hertz contact radius a = sqrt(R delta)."""
    _check(radius_m, 0.0)
    return np.sqrt(radius_m * _depth(depth_m))


def fit_punch_modulus(
    depth_m: np.ndarray,
    force_N: np.ndarray,
    *,
    radius_m: float,
    poissons_ratio: float,
    geometry: str = "flat",
    thickness_m: float | None = None,
    method: str = "lm",
) -> FitResult:
    """Least-squares Young's modulus from a whole force-depth curve.

    Fits F = 2 a E delta kappa / (1 - nu^2) ("flat", Sneddon with the Hayes factor kappa
    when ``thickness_m`` is given) or F = 4/3 E/(1 - nu^2) sqrt(R) delta^1.5 ("sphere",
    Hertz) through :func:`warptissue.lsq.fit_curve`.

    Args:
        depth_m: Depths, shape (m,), all > 0.
        force_N: Forces, shape (m,).
        radius_m: Punch radius a or sphere radius R.
        poissons_ratio: nu in (-1, 0.5].
        geometry: "flat" or "sphere".
        thickness_m: Layer thickness for the flat-punch Hayes correction (None: half-space).
        method: "lm" or "salm".

    Returns:
        A :class:`warptissue.lsq.FitResult` with the one parameter ``youngs_modulus_Pa``,
        bounded below by 0 (a curve that falls with depth pins it there, which the result's
        identifiability check reports). Its ``warnings`` say when the deepest point exceeds
        :data:`SMALL_STRAIN_DEPTH_OVER_THICKNESS` of the layer thickness and when the modulus
        is implausible for soft tissue (:func:`warptissue.lsq.plausibility.modulus_warnings`).

    Raises:
        InputError: Bad data or options, or a layer outside the range of the Hayes
            correction (:data:`HAYES_MAX_RADIUS_OVER_THICKNESS`).
    """

    depth = _depth(depth_m)
    force = np.asarray(force_N, dtype=np.float64)
    if depth.ndim != 1 or force.shape != depth.shape or depth.size < 2:
        raise InputError("depth_m and force_N need equal 1-D shapes with 2 or more points")
    if geometry == "flat":
        unit_force = flat_punch_force_N(
            depth, radius_m=radius_m, youngs_modulus_Pa=1.0, poissons_ratio=poissons_ratio
        ) * _layer_kappa(radius_m, poissons_ratio, thickness_m)
    elif geometry == "sphere":
        unit_force = hertz_force_N(
            depth, radius_m=radius_m, youngs_modulus_Pa=1.0, poissons_ratio=poissons_ratio
        )
    else:
        raise InputError("geometry must be 'flat' or 'sphere'", value=geometry)
    start = float(unit_force @ force / (unit_force @ unit_force))
    result = fit_curve(
        lambda p: p[0] * unit_force,
        [start if start > 0 else 1.0],
        force,
        jac=lambda p: unit_force[:, None],
        bounds=(0.0, np.inf),
        method=method,
        parameter_names=("youngs_modulus_Pa",),
        parameter_units=("Pa",),
    )
    if thickness_m is not None and geometry == "flat":
        strain = float(np.max(depth)) / thickness_m
        if strain > SMALL_STRAIN_DEPTH_OVER_THICKNESS:
            result.warnings.append(
                f"the deepest point is {strain:.3g} of the layer thickness (above "
                f"{SMALL_STRAIN_DEPTH_OVER_THICKNESS:g}): the finite-thickness correction is a "
                "small-strain result; fit a shallower part of the curve"
            )
    result.warnings.extend(modulus_warnings(result.parameters["youngs_modulus_Pa"]))
    return result
