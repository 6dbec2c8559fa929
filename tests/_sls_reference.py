"""An independent standard linear solid for the acquisition tests.

Relaxation function G(t) = k_inf + (k_0 - k_inf) exp(-t / tau). For a displacement that is
linear between samples, the hereditary integral F = int G(t - s) dx(s) is exact with the
recursion q_n = exp(-h/tau) q_(n-1) + (k_0 - k_inf) tau (1 - exp(-h/tau)) dx/h,
F_n = k_inf x_n + q_n (written here from the definition, not taken from warptissue).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import lfilter


class ReferenceSLS:
    """Standard linear solid: instantaneous k0 (N/m), equilibrium k_inf (N/m), tau (s)."""

    def __init__(self, k0: float, k_inf: float, tau: float) -> None:
        self.k0, self.k_inf, self.tau = k0, k_inf, tau

    def force_N(self, time_s: np.ndarray, displacement_m: np.ndarray) -> np.ndarray:
        t = np.asarray(time_s, dtype=np.float64)
        x = np.asarray(displacement_m, dtype=np.float64)
        h = np.diff(t)
        decay = np.exp(-h / self.tau)
        gain = (self.k0 - self.k_inf) * self.tau * (1.0 - decay) * np.diff(x) / h
        q = np.zeros_like(x)
        if h.size and np.ptp(h) < 1e-9 * h[0]:
            q[1:] = lfilter([1.0], [1.0, -decay[0]], gain)
        else:
            for i in range(1, len(x)):
                q[i] = decay[i - 1] * q[i - 1] + gain[i - 1]
        return self.k_inf * x + q


def fit_reference_sls(time_s, displacement_m, force_N, x0=(30.0, 10.0, 1.0)) -> np.ndarray:
    """Least-squares fit of (k0, k_inf, tau) with scipy, from a deliberately poor start."""
    solution = least_squares(
        lambda p: ReferenceSLS(*p).force_N(time_s, displacement_m) - force_N,
        x0,
        x_scale="jac",
        bounds=([0.0, 0.0, 1e-3], [np.inf, np.inf, np.inf]),
    )
    return solution.x
