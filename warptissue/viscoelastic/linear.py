"""Linear lumped viscoelastic models: standard linear solid, Prony series, and QLV.

Every model here has a relaxation function of Prony form,

    G(t) = k_inf + sum_i k_i exp(-t / tau_i),

and computes force from an arbitrary sampled displacement history by Boltzmann
superposition, F(t) = integral_0^t G(t - s) dx(s), evaluated exactly for displacement that is
linear between samples (see :mod:`warptissue.viscoelastic._hereditary`). A real
ramp-and-hold record is therefore simulated as it was measured, with its finite ramp time,
not as an ideal step.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from warptissue.errors import InputError
from warptissue.viscoelastic._hereditary import exponential_hereditary_states, validate_history

__all__ = [
    "NotARelaxationWarning",
    "PronySeries",
    "QuasiLinearViscoelastic",
    "StandardLinearSolid",
    "exponential_elastic_force",
    "exponential_spring_force",
]


class NotARelaxationWarning(UserWarning):
    """Parameters give a relaxation function that increases with time (not a relaxation)."""


def _require_positive(**values: float) -> None:
    for name, value in values.items():
        if not (math.isfinite(value) and value > 0.0):
            raise InputError(f"{name} must be a finite positive number", value=float(value))


def _require_non_negative(**values: float) -> None:
    for name, value in values.items():
        if not (math.isfinite(value) and value >= 0.0):
            raise InputError(f"{name} must be a finite non-negative number", value=float(value))


@dataclass(frozen=True)
class PronySeries:
    """A Prony-series relaxation stiffness G(t) = k_inf + sum_i k_i exp(-t/tau_i).

    The lumped (force-displacement) form of Ahn & Kim Eq. 4, in N/m. The normalized form of
    Eq. 2 and 5, G(t) = G0 (1 - sum_i g_i (1 - exp(-t/tau_i))), follows with
    G0 = k_inf + sum_i k_i and g_i = k_i / G0 (Eq. 6).

    Attributes:
        equilibrium_stiffness_N_per_m: k_inf = G(infinity) >= 0.
        branch_stiffness_N_per_m: k_i >= 0, one per term.
        relaxation_times_s: tau_i > 0, one per term.

    Notes:
        Ahn & Kim prints Eq. 5 as G0 (1 - g1 (1 - e^-t/tau1) + g2 (1 - e^-t/tau2));
        the second sign is a misprint. Equating G(0) and G(infinity) of Eq. 4 and Eq. 5 gives
        G0 = k0 + k1 + k2 and G0 (1 - g1 - g2) = k0, which holds only with a minus sign on
        both terms. This class implements the corrected form.
    """

    equilibrium_stiffness_N_per_m: float
    branch_stiffness_N_per_m: tuple[float, ...]
    relaxation_times_s: tuple[float, ...]

    def __post_init__(self) -> None:
        object.__setattr__(
            self, "branch_stiffness_N_per_m", tuple(map(float, self.branch_stiffness_N_per_m))
        )
        object.__setattr__(self, "relaxation_times_s", tuple(map(float, self.relaxation_times_s)))
        if len(self.branch_stiffness_N_per_m) != len(self.relaxation_times_s):
            raise InputError(
                "branch_stiffness_N_per_m and relaxation_times_s differ in length",
                value=(len(self.branch_stiffness_N_per_m), len(self.relaxation_times_s)),
            )
        _require_non_negative(equilibrium_stiffness_N_per_m=self.equilibrium_stiffness_N_per_m)
        for i, (k, tau) in enumerate(
            zip(self.branch_stiffness_N_per_m, self.relaxation_times_s, strict=True)
        ):
            _require_non_negative(**{f"branch_stiffness_N_per_m[{i}]": k})
            _require_positive(**{f"relaxation_times_s[{i}]": tau})

    @classmethod
    def from_normalized(
        cls,
        instantaneous_stiffness_N_per_m: float,
        g: tuple[float, ...] | list[float],
        relaxation_times_s: tuple[float, ...] | list[float],
    ) -> PronySeries:
        """Build from Ahn & Kim Eq. 2: G0 and the normalized coefficients g_i (sum < 1)."""
        g_values = tuple(float(v) for v in g)
        if sum(g_values) > 1.0:
            raise InputError("the g_i must sum to at most 1", value=g_values)
        g0 = float(instantaneous_stiffness_N_per_m)
        return cls(
            equilibrium_stiffness_N_per_m=g0 * (1.0 - sum(g_values)),
            branch_stiffness_N_per_m=tuple(g0 * v for v in g_values),
            relaxation_times_s=tuple(relaxation_times_s),
        )

    @property
    def term_count(self) -> int:
        """Number of exponential terms N."""
        return len(self.relaxation_times_s)

    @property
    def instantaneous_stiffness_N_per_m(self) -> float:
        """G0 = G(0) = k_inf + sum_i k_i."""
        return self.equilibrium_stiffness_N_per_m + sum(self.branch_stiffness_N_per_m)

    @property
    def g(self) -> tuple[float, ...]:
        """Normalized Prony coefficients g_i = k_i / G0 (Ahn & Kim Eq. 6)."""
        g0 = self.instantaneous_stiffness_N_per_m
        return tuple(float(k / g0) for k in self.branch_stiffness_N_per_m)

    def relaxation_N_per_m(self, time_s: np.ndarray | float) -> np.ndarray:
        """G(t) in N/m at the given times (s); shape of ``time_s``."""
        t = np.asarray(time_s, dtype=np.float64)
        result = np.full(t.shape, self.equilibrium_stiffness_N_per_m)
        for k, tau in zip(self.branch_stiffness_N_per_m, self.relaxation_times_s, strict=True):
            result = result + k * np.exp(-t / tau)
        return result

    def force_N(self, time_s: np.ndarray, displacement_m: np.ndarray) -> np.ndarray:
        """Force for a displacement history, by exact Boltzmann superposition.

        Args:
            time_s: Strictly increasing sample times, shape (n,), in seconds.
            displacement_m: Displacement at the samples, shape (n,), linear in between; a
                non-zero first value is a step applied at the first sample.

        Returns:
            Force, shape (n,), in newtons.
        """
        time, displacement = validate_history(time_s, displacement_m, name="displacement_m")
        states = exponential_hereditary_states(time, displacement, self.relaxation_times_s)
        weights = np.asarray(self.branch_stiffness_N_per_m)
        return self.equilibrium_stiffness_N_per_m * displacement + weights @ states

    def to_dict(self) -> dict[str, object]:
        """Parameters with units in the keys, plus the normalized form."""
        return {
            "model": "prony",
            "equilibrium_stiffness_N_per_m": self.equilibrium_stiffness_N_per_m,
            "branch_stiffness_N_per_m": list(self.branch_stiffness_N_per_m),
            "relaxation_times_s": list(self.relaxation_times_s),
            "instantaneous_stiffness_N_per_m": self.instantaneous_stiffness_N_per_m,
            "g": list(self.g),
        }


@dataclass(frozen=True)
class StandardLinearSolid:
    """The standard linear solid (Kelvin model), parametrized physically.

    G(t) = k_e + (k_g - k_e) exp(-t / tau): a spring k_e in parallel with a Maxwell arm of
    stiffness k_g - k_e and time constant tau.

    Attributes:
        instantaneous_stiffness_N_per_m: k_g = G(0).
        equilibrium_stiffness_N_per_m: k_e = G(infinity).
        relaxation_time_s: tau.

    Notes:
        Kim et al. Eq. 4 prints G(t) = k1 [1 - (1 - k2/k1) exp(-(b/k1) t)] 1(t)
        with k1 = 0.008 N/mm, k2 = 0.007 N/mm, b = 0.130 s N/mm. It starts at k2 and ends at
        k1, so with the published values it rises with time: not a stress relaxation. Its
        exponent (b/k1) t is also not dimensionless (b/k1 is in seconds). Use
        :meth:`from_printed` to reproduce the printed expression; fits return this class.
        A model with k_g < k_e is accepted (the printed parameters need it) but
        :attr:`is_relaxation` is then False.
    """

    instantaneous_stiffness_N_per_m: float
    equilibrium_stiffness_N_per_m: float
    relaxation_time_s: float

    def __post_init__(self) -> None:
        _require_positive(
            instantaneous_stiffness_N_per_m=self.instantaneous_stiffness_N_per_m,
            relaxation_time_s=self.relaxation_time_s,
        )
        _require_non_negative(equilibrium_stiffness_N_per_m=self.equilibrium_stiffness_N_per_m)

    @classmethod
    def from_printed(
        cls, k1_N_per_m: float, k2_N_per_m: float, b_N_s_per_m: float
    ) -> StandardLinearSolid:
        """Reproduce Kim et al. Eq. 4 exactly as printed.

        G(t) = k1 [1 - (1 - k2/k1) exp(-(b/k1) t)], evaluated with the numbers in SI units
        (N/m, N s/m, s); the ratio b/k1 is the same in N/mm units. So
        G(0) = k2, G(infinity) = k1 and tau = k1 / b.

        Args:
            k1_N_per_m: Printed k1 (the paper's 0.008 N/mm is 8 N/m).
            k2_N_per_m: Printed k2 (0.007 N/mm is 7 N/m).
            b_N_s_per_m: Printed b (0.130 s N/mm is 130 N s/m).

        Returns:
            The equivalent physically parametrized model.

        Warns:
            NotARelaxationWarning: k2 < k1, so that the printed G(t) increases with time.
        """
        _require_positive(k1_N_per_m=k1_N_per_m, k2_N_per_m=k2_N_per_m, b_N_s_per_m=b_N_s_per_m)
        if k2_N_per_m < k1_N_per_m:
            warnings.warn(
                f"Kim et al. Eq. 4 with k1={k1_N_per_m} N/m > k2={k2_N_per_m} N/m gives a G(t) "
                "that rises from k2 to k1: this is not a stress relaxation",
                NotARelaxationWarning,
                stacklevel=2,
            )
        return cls(
            instantaneous_stiffness_N_per_m=float(k2_N_per_m),
            equilibrium_stiffness_N_per_m=float(k1_N_per_m),
            relaxation_time_s=float(k1_N_per_m) / float(b_N_s_per_m),
        )

    def to_printed(self) -> dict[str, float]:
        """Parameters of Kim et al. Eq. 4 as printed: k1, k2 (N/m) and b (N s/m)."""
        k1 = self.equilibrium_stiffness_N_per_m
        return {
            "k1_N_per_m": k1,
            "k2_N_per_m": self.instantaneous_stiffness_N_per_m,
            "b_N_s_per_m": k1 / self.relaxation_time_s,
        }

    @property
    def is_relaxation(self) -> bool:
        """True when G(t) does not increase with time (k_g >= k_e)."""
        return self.instantaneous_stiffness_N_per_m >= self.equilibrium_stiffness_N_per_m

    @property
    def maxwell_damping_N_s_per_m(self) -> float:
        """Dashpot coefficient of the Maxwell arm, (k_g - k_e) tau."""
        return (
            self.instantaneous_stiffness_N_per_m - self.equilibrium_stiffness_N_per_m
        ) * self.relaxation_time_s

    def to_prony(self) -> PronySeries:
        """The same model as a one-term Prony series (requires k_g >= k_e)."""
        if not self.is_relaxation:
            raise InputError(
                "a standard linear solid whose G(t) increases has no Prony form",
                value=self.to_dict(),
            )
        return PronySeries(
            equilibrium_stiffness_N_per_m=self.equilibrium_stiffness_N_per_m,
            branch_stiffness_N_per_m=(
                self.instantaneous_stiffness_N_per_m - self.equilibrium_stiffness_N_per_m,
            ),
            relaxation_times_s=(self.relaxation_time_s,),
        )

    def relaxation_N_per_m(self, time_s: np.ndarray | float) -> np.ndarray:
        """G(t) in N/m at the given times (s); shape of ``time_s``."""
        t = np.asarray(time_s, dtype=np.float64)
        k_e = self.equilibrium_stiffness_N_per_m
        return k_e + (self.instantaneous_stiffness_N_per_m - k_e) * np.exp(
            -t / self.relaxation_time_s
        )

    def force_N(self, time_s: np.ndarray, displacement_m: np.ndarray) -> np.ndarray:
        """Force for an arbitrary displacement history (exact for piecewise-linear input).

        Args:
            time_s: Strictly increasing sample times, shape (n,), in seconds.
            displacement_m: Displacement at the samples, shape (n,); a non-zero first value
                is a step applied at the first sample.

        Returns:
            Force, shape (n,), in newtons.
        """
        time, displacement = validate_history(time_s, displacement_m, name="displacement_m")
        (states,) = exponential_hereditary_states(time, displacement, [self.relaxation_time_s])
        k_e = self.equilibrium_stiffness_N_per_m
        return k_e * displacement + (self.instantaneous_stiffness_N_per_m - k_e) * states

    def to_dict(self) -> dict[str, object]:
        """Parameters with units in the keys."""
        return {
            "model": "sls",
            "instantaneous_stiffness_N_per_m": self.instantaneous_stiffness_N_per_m,
            "equilibrium_stiffness_N_per_m": self.equilibrium_stiffness_N_per_m,
            "relaxation_time_s": self.relaxation_time_s,
        }


def exponential_elastic_force(
    displacement_m: np.ndarray, *, scale_N: float, rate_per_m: float
) -> np.ndarray:
    """Fung's exponential elastic response F_e(x) = A (exp(B x) - 1); F_e(0) = 0, F_e'(0) = A B.

    Args:
        displacement_m: Displacement, any shape, in metres.
        scale_N: A, in newtons.
        rate_per_m: B, in 1/m; B -> 0 with A B fixed is the linear spring A B x.

    Returns:
        Elastic force, the shape of ``displacement_m``, in newtons.
    """
    x = np.asarray(displacement_m, dtype=np.float64)
    return scale_N * np.expm1(rate_per_m * x)


def exponential_spring_force(
    displacement_m: np.ndarray, *, stiffness_N_per_m: float, rate_per_m: float
) -> np.ndarray:
    """Fung's exponential elastic response by its stiffness at zero displacement,
    F_e(x) = (k0 / B) (exp(B x) - 1), k0 = A B of :func:`exponential_elastic_force`.

    Unlike (A, B), (k0, B) stays finite for a nearly linear response: B = 0 is the linear
    spring k0 x, and B < 0 a softening one.

    Args:
        displacement_m: Displacement, any shape, in metres.
        stiffness_N_per_m: k0 = F_e'(0), in N/m.
        rate_per_m: B, in 1/m.

    Returns:
        Elastic force, the shape of ``displacement_m``, in newtons.
    """
    x = np.asarray(displacement_m, dtype=np.float64)
    if rate_per_m == 0.0:
        return stiffness_N_per_m * x
    return stiffness_N_per_m * np.expm1(rate_per_m * x) / rate_per_m


@dataclass(frozen=True)
class QuasiLinearViscoelastic:
    """Fung's quasi-linear viscoelasticity for force-displacement records.

    F(t) = integral_0^t G(t - s) dF_e(x(s))/ds ds with the reduced (normalized, G(0) = 1)
    relaxation function G(t) = 1 - sum_i g_i (1 - exp(-t/tau_i)) of Ahn & Kim Eq. 2 and a
    nonlinear elastic response F_e (Ahn & Kim Eq. 1 reduced to one dimension).

    Attributes:
        g: Normalized Prony coefficients g_i (sum <= 1).
        relaxation_times_s: tau_i > 0.
        elastic_force: F_e(displacement_m) -> force_N, vectorized, F_e(0) = 0.

    Notes:
        The hereditary integral is evaluated with the exact recursive exponential update
        for an elastic-force history that is linear between evaluation points. Each sample
        interval is split into ``substeps`` equal parts (the displacement is linear in each
        interval, F_e is evaluated at the sub-points), so the error falls as
        1/substeps^2 for a smooth F_e; it is exact when F_e is linear.
    """

    g: tuple[float, ...]
    relaxation_times_s: tuple[float, ...]
    elastic_force: Callable[[np.ndarray], np.ndarray]

    def __post_init__(self) -> None:
        object.__setattr__(self, "g", tuple(map(float, self.g)))
        object.__setattr__(self, "relaxation_times_s", tuple(map(float, self.relaxation_times_s)))
        if len(self.g) != len(self.relaxation_times_s):
            raise InputError(
                "g and relaxation_times_s differ in length",
                value=(len(self.g), len(self.relaxation_times_s)),
            )
        if sum(self.g) > 1.0 or any(v < 0.0 for v in self.g):
            raise InputError(
                "the g_i must be >= 0 and sum to at most 1", value=tuple(float(v) for v in self.g)
            )
        for i, tau in enumerate(self.relaxation_times_s):
            _require_positive(**{f"relaxation_times_s[{i}]": tau})

    def reduced_relaxation(self, time_s: np.ndarray | float) -> np.ndarray:
        """The reduced relaxation function G(t), G(0) = 1; shape of ``time_s``."""
        return PronySeries.from_normalized(1.0, self.g, self.relaxation_times_s).relaxation_N_per_m(
            time_s
        )

    def force_N(
        self, time_s: np.ndarray, displacement_m: np.ndarray, *, substeps: int = 4
    ) -> np.ndarray:
        """Force for a sampled displacement history.

        Args:
            time_s: Strictly increasing sample times, shape (n,), in seconds.
            displacement_m: Displacement at the samples, shape (n,), linear in between.
            substeps: Sub-intervals per sample interval for the elastic-force history (>= 1).

        Returns:
            Force at the samples, shape (n,), in newtons.
        """
        time, displacement = validate_history(time_s, displacement_m, name="displacement_m")
        if int(substeps) < 1:
            raise InputError("substeps must be >= 1", value=substeps)
        m = int(substeps)
        if time.size > 1 and m > 1:
            fractions = np.arange(m) / m
            interior = time[:-1, None] + np.diff(time)[:, None] * fractions
            fine_time = np.append(interior.ravel(), time[-1])
            fine_x = np.interp(fine_time, time, displacement)
        else:
            fine_time, fine_x = time, displacement
        elastic = np.asarray(self.elastic_force(fine_x), dtype=np.float64)
        prony = PronySeries.from_normalized(1.0, self.g, self.relaxation_times_s)
        states = exponential_hereditary_states(fine_time, elastic, prony.relaxation_times_s)
        force = prony.equilibrium_stiffness_N_per_m * elastic + np.asarray(prony.g) @ states
        return force[::m] if (time.size > 1 and m > 1) else force
