"""The indenter's own dynamics: Kim et al.'s two-mass lumped model and its frequency response.

A motor (inertia ``J_m``) drives a link (inertia ``J_l``) through a transmission of ratio
``N`` whose stiffness ``k_l`` sits on the motor side; the link touches the specimen (or, in the
calibration of Kim et al. Fig. 2a, an external force transducer) through a contact stiffness
``k_c``. The force at the contact ``F_h`` follows the motor force referred to the link
``F_e = N tau`` through Kim et al. Eq. 1,

    G(s) = F_h / F_e = k_l k_c / (J_m J_l s^4 + (J_m k_c + J_l k_l + N^2 J_m k_l) s^2 + k_l k_c),

unity at DC. This module adds viscous damping ``c_l`` parallel to ``k_l`` and ``c_c`` parallel
to ``k_c`` (replace ``k -> k + c s``), without which a measured resonance cannot be fitted; with
``c = 0`` it is exactly Eq. 1. It gives the frequency response, the band in which the rig does
not distort a measurement, a time-domain simulation from the equations of motion (an
independent check of the transfer function), sine-by-sine measurement of a frequency
response, and a least-squares fit of the model to a measured response.

Definitions used for the numbers reported:

- **Distortion-free band** ``flat_band_Hz``: the highest frequency ``f`` such that at every
  frequency in ``(0, f]`` the magnitude is within ``+-3 %`` of the DC gain and the phase within
  ``+-5 deg``. A stimulus whose spectrum lies in that band is reproduced within 3 %.
- **Bandwidth** ``bandwidth_Hz``: the lowest frequency at which the magnitude falls below
  ``1/sqrt(2)`` (-3 dB), i.e. past the first resonance.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from warptissue.errors import InputError
from warptissue.io import atomic_path
from warptissue.lsq.engine import least_squares
from warptissue.lsq.result import RejectStep

__all__ = [
    "PARAMETER_UNITS",
    "KIM_RIG",
    "RigDynamics",
    "RigDynamicsFit",
    "fit_rig_dynamics",
    "measure_frequency_response",
    "plot_frequency_response",
]

PARAMETER_UNITS: dict[str, str] = {
    "motor_inertia_kg_m2": "kg m^2",
    "link_inertia_kg_m2": "kg m^2",
    "link_stiffness_N_m_per_rad": "N m/rad",
    "contact_stiffness_N_m_per_rad": "N m/rad",
    "transmission_ratio": "-",
    "link_damping_N_m_s_per_rad": "N m s/rad",
    "contact_damping_N_m_s_per_rad": "N m s/rad",
}


@dataclass(frozen=True)
class RigDynamics:
    """Two-mass lumped model of the indenter in contact (Kim et al. Fig. 2b, Eq. 1).

    Generalized coordinates are the motor angle ``theta_m`` and the link angle ``theta_l``;
    for a linear stage read the link "angle" as the probe position and its inertia as the
    moving mass (the units then become kg and N/m).

    Attributes:
        motor_inertia_kg_m2: J_m.
        link_inertia_kg_m2: J_l.
        link_stiffness_N_m_per_rad: k_l, transmission stiffness on the motor side.
        contact_stiffness_N_m_per_rad: k_c, contact (specimen or transducer) stiffness.
        transmission_ratio: N, motor angle per link angle.
        link_damping_N_m_s_per_rad: c_l, parallel to k_l.
        contact_damping_N_m_s_per_rad: c_c, parallel to k_c.

    Notes:
        Equations of motion (motor torque ``tau`` in)::

            J_m theta_m'' = tau - k_l (theta_m - N theta_l) - c_l (theta_m' - N theta_l')
            J_l theta_l'' = N [k_l (theta_m - N theta_l) + c_l (...)'] - k_c theta_l - c_c theta_l'

        Eliminating ``theta_m`` gives ``k_c theta_l / (N tau)`` = Kim et al. Eq. 1 (with
        ``k -> k + c s``). Eq. 1 is printed correctly; its ``N^2 J_m k_l`` term places the
        transmission stiffness on the motor side of the ratio.
    """

    motor_inertia_kg_m2: float
    link_inertia_kg_m2: float
    link_stiffness_N_m_per_rad: float
    contact_stiffness_N_m_per_rad: float
    transmission_ratio: float
    link_damping_N_m_s_per_rad: float = 0.0
    contact_damping_N_m_s_per_rad: float = 0.0

    def __post_init__(self) -> None:
        for name, value in asdict(self).items():
            if not math.isfinite(value) or value < 0 or (value == 0 and "damping" not in name):
                raise InputError(f"{name} must be positive and finite", value=value)

    def transfer_function(self) -> tuple[np.ndarray, np.ndarray]:
        """Numerator and denominator of G(s), highest power first (scipy.signal order)."""
        Jm, Jl = self.motor_inertia_kg_m2, self.link_inertia_kg_m2
        N = self.transmission_ratio
        KL = np.array([self.link_damping_N_m_s_per_rad, self.link_stiffness_N_m_per_rad])
        KC = np.array([self.contact_damping_N_m_s_per_rad, self.contact_stiffness_N_m_per_rad])
        numerator = np.polymul(KL, KC)
        middle = np.polyadd(np.polyadd(Jm * KC, Jl * KL), N**2 * Jm * KL)
        denominator = np.polyadd(
            np.polyadd([Jm * Jl, 0.0, 0.0, 0.0, 0.0], np.polymul(middle, [1.0, 0.0, 0.0])),
            numerator,
        )
        return numerator, denominator

    def frequency_response(self, frequency_Hz: np.ndarray | float) -> np.ndarray:
        """G(i 2 pi f), complex, shape of ``frequency_Hz``."""
        numerator, denominator = self.transfer_function()
        s = 2j * np.pi * np.asarray(frequency_Hz, dtype=np.float64)
        return np.polyval(numerator, s) / np.polyval(denominator, s)

    def matrices(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Mass, damping and stiffness matrices (2, 2) in (theta_m, theta_l)."""
        N = self.transmission_ratio
        kl, kc = self.link_stiffness_N_m_per_rad, self.contact_stiffness_N_m_per_rad
        cl, cc = self.link_damping_N_m_s_per_rad, self.contact_damping_N_m_s_per_rad
        mass = np.diag([self.motor_inertia_kg_m2, self.link_inertia_kg_m2])
        stiffness = np.array([[kl, -N * kl], [-N * kl, N * N * kl + kc]])
        damping = np.array([[cl, -N * cl], [-N * cl, N * N * cl + cc]])
        return mass, damping, stiffness

    def natural_frequencies_Hz(self) -> np.ndarray:
        """Undamped natural frequencies (Hz), shape (2,), ascending (from K v = w^2 M v)."""
        from scipy.linalg import eigh

        mass, _, stiffness = self.matrices()
        return np.sqrt(eigh(stiffness, mass, eigvals_only=True)) / (2 * np.pi)

    def simulate(self, time_s: np.ndarray, input_force: np.ndarray) -> np.ndarray:
        """Contact force for an input ``F_e(t) = N tau(t)``, integrating the equations of
        motion (state space from M, C, K; zero initial state), shape (n,)."""
        from scipy.signal import lsim

        mass, damping, stiffness = self.matrices()
        inverse_mass = np.linalg.inv(mass)
        a = np.block(
            [[np.zeros((2, 2)), np.eye(2)], [-inverse_mass @ stiffness, -inverse_mass @ damping]]
        )
        b = np.concatenate(
            [np.zeros(2), inverse_mass @ np.array([1.0 / self.transmission_ratio, 0.0])]
        )
        c = np.array(
            [[0.0, self.contact_stiffness_N_m_per_rad, 0.0, self.contact_damping_N_m_s_per_rad]]
        )
        _, output, _ = lsim((a, b[:, None], c, np.zeros((1, 1))), input_force, time_s)
        return np.asarray(output, dtype=np.float64)

    def flat_band_Hz(
        self,
        *,
        magnitude_tolerance: float = 0.03,
        phase_tolerance_deg: float = 5.0,
        max_frequency_Hz: float = 1e4,
    ) -> float:
        """Highest frequency up to which |G| stays within ``1 +- magnitude_tolerance`` and
        the phase within ``+- phase_tolerance_deg`` (see the module docstring)."""
        frequency = np.geomspace(1e-3, max_frequency_Hz, 20001)
        response = self.frequency_response(frequency)
        bad = (np.abs(np.abs(response) - 1.0) > magnitude_tolerance) | (
            np.abs(np.degrees(np.angle(response))) > phase_tolerance_deg
        )
        if not bad.any():
            return max_frequency_Hz
        first = int(np.argmax(bad))
        if first == 0:
            return 0.0
        return self._refine(
            frequency[first - 1], frequency[first], magnitude_tolerance, phase_tolerance_deg
        )

    def _refine(self, low: float, high: float, tolerance: float, phase_deg: float) -> float:
        from scipy.optimize import brentq

        def excess(f: float) -> float:
            g = complex(self.frequency_response(f))
            return max(
                abs(abs(g) - 1.0) - tolerance,
                abs(math.degrees(math.atan2(g.imag, g.real))) / phase_deg * tolerance - tolerance,
            )

        return float(brentq(excess, low, high, xtol=1e-9 * high))

    def bandwidth_Hz(self, *, max_frequency_Hz: float = 1e5) -> float:
        """Lowest frequency (Hz) where |G| < 1/sqrt(2) (-3 dB)."""
        from scipy.optimize import brentq

        frequency = np.geomspace(1e-3, max_frequency_Hz, 40001)
        below = np.abs(self.frequency_response(frequency)) < 1.0 / math.sqrt(2.0)
        if not below.any():
            return max_frequency_Hz
        first = int(np.argmax(below))
        return float(
            brentq(
                lambda f: abs(complex(self.frequency_response(f))) - 1.0 / math.sqrt(2.0),
                frequency[first - 1],
                frequency[first],
            )
        )

    def to_dict(self) -> dict[str, Any]:
        """Parameters (with units in the keys), natural frequencies, band and bandwidth."""
        return {
            "parameters": asdict(self),
            "natural_frequencies_Hz": self.natural_frequencies_Hz(),
            "flat_band_Hz": self.flat_band_Hz(),
            "bandwidth_Hz": self.bandwidth_Hz(),
            "flat_band_definition": "|G| within 1 +- 3 % and phase within +- 5 deg",
        }


KIM_RIG = RigDynamics(
    motor_inertia_kg_m2=1.0e-5,
    link_inertia_kg_m2=2.0e-3,
    link_stiffness_N_m_per_rad=80.0,
    contact_stiffness_N_m_per_rad=4000.0,
    transmission_ratio=6.0,
    link_damping_N_m_s_per_rad=0.004,
    contact_damping_N_m_s_per_rad=0.4,
)
"""Representative parameters of Kim et al.'s probe in its frequency-response test (Fig. 2a,
against an external force transducer). The seed does not print them (its ref. [11] does);
these are chosen to reproduce its conclusion: flat below about 30 Hz, first structural
resonance near 200 Hz, far above the 0-5 Hz stimuli."""


def measure_frequency_response(
    time_s: np.ndarray, input_signal: np.ndarray, output_signal: np.ndarray, frequency_Hz: float
) -> complex:
    """Complex gain output/input at ``frequency_Hz`` from one sine record.

    Fits ``a sin(w t) + b cos(w t) + c + d t`` to each signal by linear least squares (the
    constant and the trend absorb offsets and drift) and divides the phasors. Use whole
    periods after the start-up transient has decayed.

    Args:
        time_s: Sample times (s), shape (n,).
        input_signal: Input (for example the commanded force or position), shape (n,).
        output_signal: Output (the measured force), shape (n,).
        frequency_Hz: The stimulus frequency (Hz).
    """
    t = np.asarray(time_s, dtype=np.float64)
    if t.ndim != 1 or t.size < 8 or frequency_Hz <= 0:
        raise InputError("need at least 8 samples and a positive frequency", value=frequency_Hz)
    w = 2 * np.pi * frequency_Hz
    basis = np.column_stack([np.sin(w * t), np.cos(w * t), np.ones_like(t), t - t.mean()])
    phasors = []
    for signal in (input_signal, output_signal):
        (a, b, _, _), *_ = np.linalg.lstsq(basis, np.asarray(signal, dtype=np.float64), rcond=None)
        phasors.append(complex(a, b))
    return phasors[1] / phasors[0]


@dataclass(frozen=True)
class RigDynamicsFit:
    """Result of :func:`fit_rig_dynamics`.

    Attributes:
        model: The fitted model.
        free_parameters: Names of the fitted parameters.
        standard_errors: Their standard errors (same units), from the Jacobian.
        rms_log_error: RMS of the residuals (natural-log magnitude and phase in rad).
        success: Whether the optimizer converged.
        message: The optimizer's message.
        nfev: Model evaluations.
    """

    model: RigDynamics
    free_parameters: tuple[str, ...]
    standard_errors: dict[str, float]
    rms_log_error: float
    success: bool
    message: str
    nfev: int

    @property
    def identifiability(self) -> list[str]:
        """Free parameters the data do not determine: a standard error larger than the
        value, or none at all (a singular Jacobian: some combination of them leaves the
        response unchanged). Empty for an identified fit."""
        messages = []
        values = asdict(self.model)
        for name in self.free_parameters:
            error = self.standard_errors[name]
            unit = PARAMETER_UNITS[name]
            if not math.isfinite(error):
                messages.append(
                    f"{name} has no standard error (singular Jacobian: with the other free "
                    "parameters it is not identified by a force-to-force response)"
                )
            elif error > abs(values[name]):
                messages.append(
                    f"{name} = {values[name]:.6g} {unit} has a standard error of "
                    f"{error:.3g} {unit}, larger than its value: it is not identified"
                )
        return messages

    @property
    def identified(self) -> bool:
        """True when :attr:`identifiability` has nothing to report."""
        return not self.identifiability

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready result, with the flat band and bandwidth of the fitted model."""
        values = asdict(self.model)
        return {
            "parameters": {
                name: {
                    "value": values[name],
                    "unit": PARAMETER_UNITS[name],
                    "standard_error": (
                        self.standard_errors[name]
                        if math.isfinite(self.standard_errors.get(name, math.nan))
                        else None
                    ),
                    "fitted": name in self.free_parameters,
                }
                for name in values
            },
            "rms_log_error": self.rms_log_error,
            "identified": self.identified,
            "warnings": self.identifiability,
            "success": self.success,
            "message": self.message,
            "nfev": self.nfev,
            "natural_frequencies_Hz": self.model.natural_frequencies_Hz(),
            "flat_band_Hz": self.model.flat_band_Hz(),
            "bandwidth_Hz": self.model.bandwidth_Hz(),
        }


def fit_rig_dynamics(
    frequency_Hz: np.ndarray,
    response: np.ndarray,
    *,
    initial: RigDynamics,
    free: tuple[str, ...] = (
        "link_inertia_kg_m2",
        "link_stiffness_N_m_per_rad",
        "link_damping_N_m_s_per_rad",
        "contact_damping_N_m_s_per_rad",
    ),
) -> RigDynamicsFit:
    """Fit the model to a measured frequency response.

    The residuals are the log-ratios ``log(G_model / G_measured)`` split into real (log
    magnitude) and imaginary (phase, rad) parts, so that every frequency weighs the same
    whatever its gain. Parameters are fitted in log space (they stay positive).

    Only four combinations are identifiable from a force-to-force response (two natural
    frequencies and two damping time constants; a common scale of all inertias and
    stiffnesses cancels), so fix the others: by default ``J_m`` (from the motor's data
    sheet), ``N`` (from the drive) and ``k_c`` (a static test) are held. The undamped
    problem has two mirror solutions (the modes swap between the masses); start within a
    factor of about two of the truth.

    Args:
        frequency_Hz: Measured frequencies (Hz), shape (k,), k >= len(free).
        response: Measured complex gains, shape (k,).
        initial: Starting model (also supplies the held parameters).
        free: Names of the parameters to fit (keys of :data:`PARAMETER_UNITS`).

    Raises:
        InputError: Shapes, non-finite values, unknown parameter names.
    """

    f = np.asarray(frequency_Hz, dtype=np.float64)
    measured = np.asarray(response, dtype=np.complex128)
    if f.ndim != 1 or measured.shape != f.shape:
        raise InputError("frequency_Hz and response must be 1-D of equal length")
    if not (np.all(np.isfinite(f)) and np.all(np.isfinite(measured)) and np.all(f > 0)):
        raise InputError("frequencies must be positive and responses finite")
    if np.any(measured == 0):
        raise InputError("a measured gain is zero")
    unknown = [name for name in free if name not in PARAMETER_UNITS]
    if unknown:
        raise InputError(f"unknown parameter(s) {unknown}; use {list(PARAMETER_UNITS)}")
    if 2 * f.size < len(free):
        raise InputError("fewer measurements than free parameters", value=f.size)
    start = asdict(initial)
    x0 = np.log([start[name] for name in free])

    def model(x: np.ndarray) -> RigDynamics:
        with np.errstate(over="ignore", under="ignore"):
            values = np.exp(x)
        try:
            return replace(initial, **dict(zip(free, values.tolist(), strict=True)))
        except InputError:  # a trial step left the domain (a value 0 or infinite)
            raise RejectStep from None

    def residuals(x: np.ndarray) -> np.ndarray:
        with np.errstate(all="ignore"):
            ratio = np.log(model(x).frequency_response(f) / measured)
        return np.concatenate([ratio.real, ratio.imag])

    solution = least_squares(
        residuals, x0, method="lm", parameter_names=[f"log_{name}" for name in free]
    )
    fitted = model(solution.x)
    log_errors = solution.standard_errors  # None: too few residuals or a singular Jacobian
    if log_errors is None:
        log_errors = np.full(len(free), np.nan)
    values = asdict(fitted)
    # Fitted in log space: the standard error of log(p) is p's relative standard error.
    errors = {name: float(values[name] * e) for name, e in zip(free, log_errors, strict=True)}
    return RigDynamicsFit(
        model=fitted,
        free_parameters=tuple(free),
        standard_errors=errors,
        rms_log_error=float(solution.rmse),
        success=bool(solution.success),
        message=str(solution.message),
        nfev=int(solution.nfev),
    )


def plot_frequency_response(
    path: str | Path,
    model: RigDynamics,
    *,
    frequency_Hz: np.ndarray | None = None,
    measured: np.ndarray | None = None,
    title: str = "Rig frequency response (Kim et al. Eq. 1)",
) -> Path:
    """Bode plot (PNG, atomic) of the model, with measured points and the flat band shaded.

    Args:
        path: Output PNG.
        model: The rig model.
        frequency_Hz: Measured frequencies (Hz), shape (k,), or None.
        measured: Measured complex gains, shape (k,), or None.
        title: Figure title.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    top = 2.0 * model.natural_frequencies_Hz()[-1]
    curve_f = np.geomspace(0.1, top, 2000)
    curve = model.frequency_response(curve_f)
    flat = model.flat_band_Hz()
    figure, (magnitude_axes, phase_axes) = plt.subplots(2, 1, sharex=True, figsize=(7, 6))
    magnitude_axes.loglog(curve_f, np.abs(curve), label="model")
    phase_axes.semilogx(curve_f, np.degrees(np.unwrap(np.angle(curve))), label="model")
    if frequency_Hz is not None and measured is not None:
        points = np.asarray(measured)
        magnitude_axes.loglog(frequency_Hz, np.abs(points), "o", label="measured")
        phase_axes.semilogx(frequency_Hz, np.degrees(np.angle(points)), "o", label="measured")
    for axes in (magnitude_axes, phase_axes):
        axes.axvspan(curve_f[0], flat, color="0.9", label=f"flat band ({flat:.1f} Hz)")
        axes.grid(True, which="both", alpha=0.3)
    magnitude_axes.set_ylabel("|F_h / F_e|")
    phase_axes.set_ylabel("phase (deg)")
    phase_axes.set_xlabel("frequency (Hz)")
    magnitude_axes.legend(loc="lower left")
    magnitude_axes.set_title(title)
    figure.tight_layout()
    with atomic_path(path) as temporary:
        figure.savefig(temporary, dpi=120)
    plt.close(figure)
    return Path(path)
