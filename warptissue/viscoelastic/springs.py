"""Kim et al.'s nonlinear models: the Blatz exponential law (Eq. 3) and parallel springs (Eq. 5).

Kim et al. fit both to in vivo indentation of pig liver and esophagus with a 2 mm flat
probe. The parallel-spring parameters of their table are in the paper's units
(displacement in mm, force in N, time in s); :class:`ParallelNonlinearSprings` converts at
its edges, so that it takes and returns SI values like every other model.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp

from warptissue.errors import ConvergenceError, InputError
from warptissue.lsq import FitResult, RejectStep, fit_curve
from warptissue.viscoelastic._hereditary import validate_history

__all__ = ["ParallelNonlinearSprings", "blatz_pressure_Pa", "fit_blatz"]


def blatz_pressure_Pa(stretch: np.ndarray | float, *, alpha: float, gamma_Pa: float) -> np.ndarray:
    """The Blatz exponential law, Kim et al. Eq. 3.

    P = gamma / (alpha + 1) (lambda exp(alpha (lambda^2 - 1)) - exp(alpha (1/lambda - 1)) /
    lambda^2).

    Args:
        stretch: Compression ratio lambda > 0 (deformed / undeformed length), any shape.
        alpha: Dimensionless exponent (alpha != -1).
        gamma_Pa: Stiffness parameter, in pascals.

    Returns:
        Pressure at the indenter tip (force / area), the shape of ``stretch``, in pascals;
        negative in compression (lambda < 1), as printed.

    Notes:
        At lambda = 1, P = 0 and dP/dlambda = 3 gamma, so gamma plays the part of a
        small-strain shear modulus (E = 3 gamma for an incompressible solid).
    """
    lam = np.asarray(stretch, dtype=np.float64)
    if np.any(~np.isfinite(lam)) or np.any(lam <= 0.0):
        raise InputError("stretch must be finite and positive")
    if alpha == -1.0:
        raise InputError("alpha = -1 makes Eq. 3 singular", value=float(alpha))
    return (
        gamma_Pa
        / (alpha + 1.0)
        * (lam * np.exp(alpha * (lam**2 - 1.0)) - np.exp(alpha * (1.0 / lam - 1.0)) / lam**2)
    )


def fit_blatz(
    stretch: np.ndarray,
    pressure_Pa: np.ndarray,
    *,
    p0: Sequence[float] = (1.0, 1e3),
    method: str = "lm",
) -> FitResult:
    """Least-squares fit of Eq. 3's (alpha, gamma_Pa) to pressure-stretch data.

    Args:
        stretch: Compression ratios, shape (m,).
        pressure_Pa: Measured pressures (force / probe area, negative in compression), (m,).
        p0: Initial (alpha, gamma_Pa); gamma's sign is taken from the data's initial slope.
        method: "lm" or "salm".

    Returns:
        FitResult with parameters alpha and gamma_Pa.
    """
    lam = np.asarray(stretch, dtype=np.float64)
    pressure = np.asarray(pressure_Pa, dtype=np.float64)
    if lam.shape != pressure.shape or lam.ndim != 1 or lam.size < 3:
        raise InputError("stretch and pressure_Pa need equal 1-D shapes, at least 3 points")
    start = np.asarray(p0, dtype=np.float64)
    nearest = int(np.argmin(np.abs(lam - 1.0)))
    if lam[nearest] != 1.0 and start[1] == 1e3:
        start[1] = pressure[nearest] / (3.0 * (lam[nearest] - 1.0))

    def predict(p: np.ndarray) -> np.ndarray:
        try:
            with np.errstate(over="raise", invalid="raise"):
                return blatz_pressure_Pa(lam, alpha=p[0], gamma_Pa=p[1])
        except (FloatingPointError, InputError) as exc:
            raise RejectStep(str(exc)) from exc

    return fit_curve(
        predict,
        start,
        pressure,
        method=method,
        parameter_names=("alpha", "gamma_Pa"),
        parameter_units=("", "Pa"),
        x_scale=np.maximum(np.abs(start), [0.1, 1e-6]),
    )


def _signed_power(value: np.ndarray, exponent: float) -> np.ndarray:
    return np.sign(value) * np.abs(value) ** exponent


@dataclass(frozen=True)
class ParallelNonlinearSprings:
    """Kim et al. Eq. 5: a nonlinear spring in parallel with relaxing nonlinear branches.

    F = F0 + sum_j F_j, F0 = k01 x^k02 and, for each branch j (state a_j, b_j):
    F_j = k_j3 (x - a_j)^k_j2, a_j' = b_j, b_j' = k_j1 (x - a_j)^k_j2 - b_j.

    Attributes:
        k01: F0 coefficient, in N / mm^k02.
        k02: F0 exponent.
        branches: One (k_j1, k_j2, k_j3) per branch: k_j1 in mm^(1 - k_j2) / s^2, k_j2
            dimensionless, k_j3 in N / mm^k_j2.

    Notes:
        Parameters use the paper's units (x in mm, F in N); :meth:`force_N` converts. Powers
        of negative stretches keep their sign (sign(d) |d|^k), so that unloading is
        defined. The printed second branch reads F2(t + tau), with a tau the paper never
        defines or tabulates; it is taken as 0. The branch states are integrated with
        ``solve_ivp`` (LSODA by default).
        Kim et al.'s table, liver: k01 = 0.0020, k02 = 1.6797, (k11, k12, k13) =
        (0.0250, 2.2355, 0.0070), (k21, k22, k23) = (0.080, 2.1838, 0.0005).
    """

    k01: float
    k02: float
    branches: tuple[tuple[float, float, float], ...]

    def __post_init__(self) -> None:
        object.__setattr__(
            self, "branches", tuple(tuple(float(v) for v in branch) for branch in self.branches)
        )
        values = [self.k01, self.k02] + [v for branch in self.branches for v in branch]
        if not all(math.isfinite(v) and v >= 0.0 for v in values):
            raise InputError(
                "parameters must be finite and non-negative", value=[float(v) for v in values]
            )
        if any(len(branch) != 3 for branch in self.branches):
            raise InputError("each branch needs (k_j1, k_j2, k_j3)", value=self.branches)

    def force_N(
        self, time_s: np.ndarray, displacement_m: np.ndarray, *, method: str = "LSODA"
    ) -> np.ndarray:
        """Force for a displacement history, linear between samples.

        Args:
            time_s: Strictly increasing sample times, shape (n,).
            displacement_m: Indentation depth, shape (n,), in metres (converted to mm).
            method: ``solve_ivp`` method.

        Returns:
            Force, shape (n,), in newtons.
        """
        time, displacement = validate_history(time_s, displacement_m, name="displacement_m")
        x_mm = 1e3 * displacement
        force = self.k01 * _signed_power(x_mm, self.k02)
        active = [b for b in self.branches if b[0] != 0.0 or b[2] != 0.0]
        if not active or time.size == 1:
            return force + sum(b[2] * _signed_power(x_mm, b[1]) for b in active)
        gains = np.array([b[0] for b in active])
        exponents = np.array([b[1] for b in active])

        def rhs(t: float, state: np.ndarray) -> np.ndarray:
            position, velocity = state.reshape(2, -1)
            stretch = np.interp(t, time, x_mm) - position
            return np.concatenate([velocity, gains * _signed_power(stretch, exponents) - velocity])

        solution = solve_ivp(
            rhs,
            (time[0], time[-1]),
            np.zeros(2 * len(active)),
            method=method,
            t_eval=time,
            rtol=1e-9,
            atol=1e-12 * max(float(np.max(np.abs(x_mm))), 1.0),
        )
        if not solution.success:
            raise ConvergenceError(f"parallel-spring integration failed: {solution.message}")
        positions = solution.y[: len(active)]
        for (_, exponent, coefficient), position in zip(active, positions, strict=True):
            force = force + coefficient * _signed_power(x_mm - position, exponent)
        return force
