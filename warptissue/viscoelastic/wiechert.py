"""Wiechert bodies (Takacs et al.): linear, with exponential springs, distributed.

A Wiechert body is a spring k0 in parallel with two Maxwell arms (k1, b1) and (k2, b2). The
nonlinear variant replaces every spring by k_j(chi) = K_j exp(kappa_j chi) (Eq. 2), so that a
spring stretched by chi carries K_j chi exp(kappa_j chi). Forces are in newtons for the whole
sample the parameters were fitted on; :meth:`NonlinearWiechert.scaled` turns them into the
specific (per square metre) parameters of the distributed model (Eq. 5-8).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, fields

import numpy as np
from scipy.integrate import solve_ivp

from warptissue.errors import ConvergenceError, InputError
from warptissue.viscoelastic._hereditary import validate_history
from warptissue.viscoelastic.linear import PronySeries

__all__ = [
    "LinearWiechert",
    "NonlinearWiechert",
    "SurfaceProfile",
    "line_indenter_force_N",
    "quadratic_profile",
]

_IMPLICIT_METHODS = ("LSODA", "BDF", "Radau")

SurfaceProfile = Callable[[np.ndarray, float], np.ndarray]
"""profile(y_m (n,), depth_m) -> surface displacement (n,) in metres, at the distance y_m
from the indentation line when the indenter is at depth_m."""


def _check_positive(instance: object) -> None:
    for item in fields(instance):  # type: ignore[arg-type]
        value = getattr(instance, item.name)
        if item.name.startswith("kappa"):
            if not math.isfinite(value):
                raise InputError(f"{item.name} must be finite", value=float(value))
        elif not (math.isfinite(value) and value > 0.0):
            raise InputError(f"{item.name} must be a finite positive number", value=float(value))


@dataclass(frozen=True)
class LinearWiechert:
    """The 5-parameter linear Wiechert model (Takacs et al. Eq. 1).

    Attributes:
        k0_N_per_m: Parallel (equilibrium) spring.
        k1_N_per_m, b1_N_s_per_m: First Maxwell arm.
        k2_N_per_m, b2_N_s_per_m: Second Maxwell arm.

    Notes:
        W(s) = k0 + k1 b1 s / (b1 s + k1) + k2 b2 s / (b2 s + k2). Over the common
        denominator B2 s^2 + B1 s + B0 with B2 = b1 b2, B1 = b1 k2 + b2 k1, B0 = k1 k2 the
        numerator is A2 s^2 + A1 s + A0 with A2 = b1 b2 (k0 + k1 + k2),
        A1 = b1 k2 (k0 + k1) + b2 k1 (k0 + k2) and A0 = k0 k1 k2. Takacs et al. prints the
        constant term as a second A2 and defines A0 = k0 k1 k2 b2; both are misprints (the
        extra b2 breaks the units and the static limit W(0) = k0).
        Inverting W(s) U(s) gives G(t) = k0 + k1 exp(-t k1/b1) + k2 exp(-t k2/b2): a
        two-term Prony series with tau_j = b_j / k_j.
    """

    k0_N_per_m: float
    k1_N_per_m: float
    k2_N_per_m: float
    b1_N_s_per_m: float
    b2_N_s_per_m: float

    def __post_init__(self) -> None:
        _check_positive(self)

    @property
    def relaxation_times_s(self) -> tuple[float, float]:
        """tau_j = b_j / k_j of the two Maxwell arms."""
        return (self.b1_N_s_per_m / self.k1_N_per_m, self.b2_N_s_per_m / self.k2_N_per_m)

    def transfer_function(self) -> tuple[np.ndarray, np.ndarray]:
        """Eq. 1 coefficients (corrected): numerator (A2, A1, A0), denominator (B2, B1, B0)."""
        k0, k1, k2 = self.k0_N_per_m, self.k1_N_per_m, self.k2_N_per_m
        b1, b2 = self.b1_N_s_per_m, self.b2_N_s_per_m
        numerator = np.array(
            [b1 * b2 * (k0 + k1 + k2), b1 * k2 * (k0 + k1) + b2 * k1 * (k0 + k2), k0 * k1 * k2]
        )
        denominator = np.array([b1 * b2, b1 * k2 + b2 * k1, k1 * k2])
        return numerator, denominator

    def to_prony(self) -> PronySeries:
        """The equivalent two-term Prony series."""
        return PronySeries(
            self.k0_N_per_m, (self.k1_N_per_m, self.k2_N_per_m), self.relaxation_times_s
        )

    def step_response_N(self, time_s: np.ndarray, depth_m: float) -> np.ndarray:
        """Force after an ideal step to ``depth_m`` at t = 0: depth G(t); shape of time_s."""
        return depth_m * self.to_prony().relaxation_N_per_m(time_s)

    def ramp_response_N(
        self, time_s: np.ndarray, rate_m_per_s: float, *, hold_after_s: float = math.inf
    ) -> np.ndarray:
        """Force for x = v t from t = 0, held at v T after ``hold_after_s`` = T.

        F(t) = v [k0 t + sum_j b_j (1 - exp(-t k_j / b_j))] while ramping; after T, by
        superposition, F(t) = R(t) - R(t - T) with R the ramp response.
        """
        t = np.asarray(time_s, dtype=np.float64)
        ramp = self._unit_ramp_response(t)
        if math.isfinite(hold_after_s):
            ramp = ramp - np.where(
                t > hold_after_s, self._unit_ramp_response(np.maximum(t - hold_after_s, 0.0)), 0
            )
        return rate_m_per_s * ramp

    def _unit_ramp_response(self, t: np.ndarray) -> np.ndarray:
        response = self.k0_N_per_m * t
        for k, b in ((self.k1_N_per_m, self.b1_N_s_per_m), (self.k2_N_per_m, self.b2_N_s_per_m)):
            response = response - b * np.expm1(-t * k / b)
        return response

    def force_N(self, time_s: np.ndarray, displacement_m: np.ndarray) -> np.ndarray:
        """Force for a sampled displacement history (exact for piecewise-linear input)."""
        return self.to_prony().force_N(time_s, displacement_m)

    def to_dict(self) -> dict[str, object]:
        """Parameters with units in the keys."""
        return {"model": "wiechert"} | {f.name: getattr(self, f.name) for f in fields(self)}


@dataclass(frozen=True)
class NonlinearWiechert:
    """The 8-parameter Wiechert model with exponential springs (Takacs et al. Eq. 2-4).

    Attributes:
        K0_N_per_m, K1_N_per_m, K2_N_per_m: Spring coefficients K_j.
        b1_N_s_per_m, b2_N_s_per_m: Dashpots.
        kappa0_per_m, kappa1_per_m, kappa2_per_m: Spring exponents kappa_j (kappa = 0 is the
            linear Wiechert model).

    Notes:
        Eq. 3: x1' = K1 (x0 - x1) exp(kappa1 (x0 - x1)) / b1, likewise x2; Eq. 4:
        F = K0 x0 exp(kappa0 x0) + sum_j K_j (x0 - x_j) exp(kappa_j (x0 - x_j)). x0 is the
        imposed surface displacement, x_j the dashpot-spring junctions. Integrated with
        scipy's ``solve_ivp`` (LSODA by default, switching to a stiff method as needed) with
        the analytic (diagonal) Jacobian. Table I of Takacs et al. gives parameters for a
        20 x 20 mm sample; Table II lists them per square metre (divided by 4e-4 m^2), its
        b1 = 127e6 is ten times 5073 / 4e-4 = 12.7e6 (one of the tables is misprinted) and
        its kappa values, which do not scale with area, were lost in extraction.
    """

    K0_N_per_m: float
    K1_N_per_m: float
    K2_N_per_m: float
    b1_N_s_per_m: float
    b2_N_s_per_m: float
    kappa0_per_m: float
    kappa1_per_m: float
    kappa2_per_m: float

    def __post_init__(self) -> None:
        _check_positive(self)

    @classmethod
    def from_vector(cls, values: np.ndarray | list[float]) -> NonlinearWiechert:
        """Build from (K0, K1, K2, b1, b2, kappa0, kappa1, kappa2)."""
        return cls(*(float(v) for v in values))

    def to_vector(self) -> np.ndarray:
        """(K0, K1, K2, b1, b2, kappa0, kappa1, kappa2), shape (8,)."""
        return np.array([getattr(self, f.name) for f in fields(self)])

    def scaled(self, factor: float) -> NonlinearWiechert:
        """Multiply the K_j and b_j by ``factor`` (kappa_j unchanged).

        ``scaled(1 / area_m2)`` gives the specific parameters per square metre of Takacs et al.
        Table II; ``scaled(area_m2)`` turns specific parameters back into a body of that area.
        """
        values = self.to_vector()
        values[:5] *= factor
        return NonlinearWiechert.from_vector(values)

    def spring_forces_N(
        self, surface_m: np.ndarray, junction_1_m: np.ndarray, junction_2_m: np.ndarray
    ) -> np.ndarray:
        """Eq. 4: total spring force for the given states (arrays broadcast together)."""
        d1 = surface_m - junction_1_m
        d2 = surface_m - junction_2_m
        return (
            self.K0_N_per_m * surface_m * np.exp(self.kappa0_per_m * surface_m)
            + self.K1_N_per_m * d1 * np.exp(self.kappa1_per_m * d1)
            + self.K2_N_per_m * d2 * np.exp(self.kappa2_per_m * d2)
        )

    def force_N(
        self,
        time_s: np.ndarray,
        displacement_m: np.ndarray,
        *,
        method: str = "LSODA",
        rtol: float = 1e-8,
    ) -> np.ndarray:
        """Force for a displacement history, linear between samples.

        Args:
            time_s: Strictly increasing sample times, shape (n,), in seconds.
            displacement_m: Surface displacement x0 at the samples, shape (n,); a non-zero
                first value is a step at the first sample (the dashpots do not move in it).
            method: A ``scipy.integrate.solve_ivp`` method ("LSODA", "BDF", "Radau", ...).
            rtol: Relative tolerance of the integrator.

        Returns:
            Force at the samples, shape (n,), in newtons.

        Raises:
            ConvergenceError: The integrator failed (for example, runaway exponentials).
        """
        time, displacement = validate_history(time_s, displacement_m, name="displacement_m")
        junctions = _integrate_junctions(
            self, time, displacement[None, :], method=method, rtol=rtol
        )
        return self.spring_forces_N(displacement, junctions[0, 0], junctions[1, 0])

    def to_dict(self) -> dict[str, object]:
        """Parameters with units in the keys."""
        return {"model": "wiechert-nonlinear"} | {
            f.name: getattr(self, f.name) for f in fields(self)
        }


def _integrate_junctions(
    model: NonlinearWiechert,
    time: np.ndarray,
    surface: np.ndarray,
    *,
    method: str,
    rtol: float,
) -> np.ndarray:
    """Integrate Eq. 3 for ``p`` independent bodies; surface (p, n) -> junctions (2, p, n)."""
    body_count = surface.shape[0]
    junctions = np.zeros((2, body_count, time.size))
    if time.size == 1:
        return junctions
    gains = np.array([model.K1_N_per_m / model.b1_N_s_per_m, model.K2_N_per_m / model.b2_N_s_per_m])
    kappas = np.array([model.kappa1_per_m, model.kappa2_per_m])
    scale = max(float(np.max(np.abs(surface))), 1e-12)

    def surface_at(t: float) -> np.ndarray:
        index = int(np.clip(np.searchsorted(time, t) - 1, 0, time.size - 2))
        weight = (t - time[index]) / (time[index + 1] - time[index])
        return surface[:, index] + weight * (surface[:, index + 1] - surface[:, index])

    def rhs(t: float, state: np.ndarray) -> np.ndarray:
        stretch = surface_at(t)[None, :] - state.reshape(2, body_count)
        return (gains[:, None] * stretch * np.exp(kappas[:, None] * stretch)).ravel()

    def jacobian(t: float, state: np.ndarray) -> np.ndarray:
        stretch = surface_at(t)[None, :] - state.reshape(2, body_count)
        slope = gains[:, None] * np.exp(kappas[:, None] * stretch) * (1 + kappas[:, None] * stretch)
        return np.diag(-slope.ravel())

    with np.errstate(over="ignore", invalid="ignore"):
        solution = solve_ivp(
            rhs,
            (time[0], time[-1]),
            np.zeros(2 * body_count),
            method=method,
            t_eval=time,
            jac=jacobian if method in _IMPLICIT_METHODS else None,
            rtol=rtol,
            atol=1e-10 * scale,
        )
    if not solution.success or not np.all(np.isfinite(solution.y)):
        raise ConvergenceError(
            f"nonlinear Wiechert integration failed: {solution.message}",
            partial_result=model.to_dict(),
        )
    return solution.y.reshape(2, body_count, time.size)


def quadratic_profile(radius_m: float) -> SurfaceProfile:
    """Takacs et al. Eq. 6: x(y) = x_d (|y| - rho)^2 / rho^2 for |y| <= rho, zero beyond.

    Args:
        radius_m: rho, the distance from the indentation line beyond which the surface does
            not move (Eq. 7: the slope is zero there).

    Returns:
        A :data:`SurfaceProfile`.
    """
    if not (math.isfinite(radius_m) and radius_m > 0):
        raise InputError("radius_m must be a finite positive number", value=float(radius_m))

    def profile(y_m: np.ndarray, depth_m: float) -> np.ndarray:
        gap = np.maximum(radius_m - np.abs(np.asarray(y_m, dtype=np.float64)), 0.0)
        return depth_m * (gap / radius_m) ** 2

    return profile


def line_indenter_force_N(
    specific_model: NonlinearWiechert,
    time_s: np.ndarray,
    depth_m: np.ndarray,
    *,
    half_width_m: float,
    length_m: float,
    profile: SurfaceProfile,
    element_count: int = 64,
    method: str = "LSODA",
    rtol: float = 1e-7,
) -> np.ndarray:
    """Force under a line indenter from distributed Wiechert bodies (Takacs et al. Eq. 5-8).

    F(t) = integral f(y, z, t) dy dz over the surface, with one body per surface element
    driven by its own displacement history x(y, t) = profile(y, depth(t)) (Eq. 6 and 8 for
    the quadratic profile). The deformation is uniform along the line (z, length
    ``length_m``) and symmetric in y, so the strip 0 <= y <= ``half_width_m`` is split into
    ``element_count`` equal elements (midpoint rule) and its force doubled.

    Args:
        specific_model: Parameters per square metre (``model.scaled(1 / area_m2)``).
        time_s: Strictly increasing sample times, shape (n,), in seconds.
        depth_m: Indentation depth x_d at the samples, shape (n,), linear in between.
        half_width_m: Half width of the loaded strip across the line.
        length_m: Length of the strip along the line.
        profile: Surface displacement shape, for example :func:`quadratic_profile`.
        element_count: Elements across the half width.
        method: ``solve_ivp`` method.
        rtol: Relative tolerance of the integrator.

    Returns:
        Indenter force, shape (n,), in newtons.
    """
    time, depth = validate_history(time_s, depth_m, name="depth_m")
    for name, value in (("half_width_m", half_width_m), ("length_m", length_m)):
        if not (math.isfinite(value) and value > 0):
            raise InputError(f"{name} must be a finite positive number", value=float(value))
    if int(element_count) < 1:
        raise InputError("element_count must be >= 1", value=element_count)
    width = half_width_m / int(element_count)
    centres = (np.arange(int(element_count)) + 0.5) * width
    surface = np.stack([np.asarray(profile(centres, float(d)), dtype=np.float64) for d in depth], 1)
    if surface.shape != (centres.size, time.size) or not np.all(np.isfinite(surface)):
        raise InputError("profile(y_m, depth_m) must return finite values of the shape of y_m")
    moving = np.any(surface != 0.0, axis=1)
    force = np.zeros(time.size)
    if not np.any(moving):
        return force
    junctions = _integrate_junctions(
        specific_model, time, surface[moving], method=method, rtol=rtol
    )
    pressure = specific_model.spring_forces_N(surface[moving], junctions[0], junctions[1])
    return 2.0 * length_m * width * pressure.sum(axis=0)
