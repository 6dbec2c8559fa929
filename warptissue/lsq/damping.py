"""The damping rules of the least-squares engine's two methods
(:mod:`warptissue.lsq.engine`): Levenberg-Marquardt with Marquardt's scaling and Nielsen's
update (``"lm"``), and Tong et al.'s self-adapting LM (``"salm"``, Eq. 8-12, with the
misprints of Eq. 9 and 10 corrected as the engine's Notes explain).

Each rule gives the step's column scaling D, the gradient norm its stopping test uses, the
damping of the next step and its update from the ratio of actual to predicted reduction
(None: the model refused the trial point).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from warptissue.errors import InputError

__all__ = ["REFUSAL_FACTOR", "MarquardtDamping", "SelfAdaptingDamping"]

REFUSAL_FACTOR = 10.0
"""The further growth of the damping after a refused trial point."""


class MarquardtDamping:
    """Levenberg-Marquardt with Marquardt's diagonal scaling and Nielsen's damping update."""

    def __init__(self, options: Mapping[str, float], x_scale: np.ndarray | None) -> None:
        self.damping = float(options["initial_damping"])
        self.p0 = float(options["p0"])
        self.nu = 2.0
        self.fixed_scale = None if x_scale is None else 1.0 / x_scale

    def scale(self, jacobian: np.ndarray) -> np.ndarray:
        if self.fixed_scale is not None:
            return self.fixed_scale
        norms = np.linalg.norm(jacobian, axis=0)
        return np.where(norms > 0.0, norms, 1.0)

    def gradient_norm(
        self, jacobian: np.ndarray, residuals: np.ndarray, gradient: np.ndarray, free: np.ndarray
    ) -> float:
        residual_norm = float(np.linalg.norm(residuals))
        norms = np.linalg.norm(jacobian, axis=0)
        active = free & (norms > 0.0)
        if residual_norm == 0.0 or not np.any(active):
            return 0.0
        return float(np.max(np.abs(gradient[active]) / (norms[active] * residual_norm)))

    def value(self, residual_norm: float, scaled_gradient_norm: float) -> float:
        return self.damping

    def update(self, ratio: float | None) -> None:
        if ratio is None:
            self.damping *= REFUSAL_FACTOR * self.nu
            self.nu *= 2.0
        elif ratio > self.p0:
            self.damping *= max(1.0 / 3.0, 1.0 - (2.0 * ratio - 1.0) ** 3)
            self.damping = max(self.damping, 1e-300)
            self.nu = 2.0
        else:
            self.damping *= self.nu
            self.nu *= 2.0


class SelfAdaptingDamping:
    """Tong et al.'s self-adapting LM (Eq. 8-12), misprints corrected."""

    def __init__(self, options: Mapping[str, float], x_scale: np.ndarray | None) -> None:
        self.theta = float(options["theta"])
        self.c = float(options["c"])
        self.p0 = float(options["p0"])
        self.eta = float(options["eta0"])
        if not 0.0 <= self.theta <= 1.0:
            raise InputError("salm option theta must lie in [0, 1]", value=self.theta)
        if not (self.c > 0.0 and 0.0 < self.p0 < 1.0 and self.eta > self.c):
            raise InputError(
                "salm options need c > 0, 0 < p0 < 1 and eta0 > c (Tong et al., Algorithm 1)",
                value=dict(options),
            )
        self.fixed_scale = None if x_scale is None else 1.0 / x_scale
        self.damping = 0.0

    def scale(self, jacobian: np.ndarray) -> np.ndarray:
        if self.fixed_scale is not None:
            return self.fixed_scale
        return np.ones(jacobian.shape[1])

    def gradient_norm(
        self, jacobian: np.ndarray, residuals: np.ndarray, gradient: np.ndarray, free: np.ndarray
    ) -> float:
        scale = self.scale(jacobian)
        return float(np.linalg.norm(np.where(free, gradient / scale, 0.0)))

    def value(self, residual_norm: float, scaled_gradient_norm: float) -> float:
        smaller = min(residual_norm**2, scaled_gradient_norm**2)
        self.damping = self.eta * (
            self.theta * smaller / residual_norm
            + (1.0 - self.theta) * smaller / scaled_gradient_norm
        )
        return self.damping

    def update(self, ratio: float | None) -> None:
        if ratio is None:
            factor = REFUSAL_FACTOR * self._q(0.0)
        else:
            factor = self._q(ratio)
        self.eta = max(self.c, self.eta * factor)

    @staticmethod
    def _q(ratio: float) -> float:
        return max(0.5, 1.0 - 2.0 * (2.0 * ratio - 1.0) ** 3)
