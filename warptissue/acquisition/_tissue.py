"""The specimen under the simulated rig: any object with ``force_N(time_s, displacement_m)``
(:class:`TissueModel`), a tabulated force curve (:class:`ForceCurveTissue`), and the
respiration and heartbeat that disturb the force (:class:`PhysiologicalDisturbance`, Kim et al.
Fig. 2d). The rig itself: :mod:`warptissue.acquisition.simulator`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np

from warptissue.errors import InputError
from warptissue.io import read_experiment_csv


class TissueModel(Protocol):
    """What the simulated rig indents: force for a displacement history."""

    def force_N(self, time_s: np.ndarray, displacement_m: np.ndarray) -> np.ndarray:
        """Force (N), shape (n,), for indentation depth ``displacement_m`` (m) at
        ``time_s`` (s), both shape (n,)."""
        ...


@dataclass(frozen=True)
class ForceCurveTissue:
    """A rate-independent specimen given by a precomputed force-depth curve (for example an
    FE reaction-force curve), interpolated linearly, zero force at zero depth.

    Attributes:
        displacement_m: Depths, shape (k,), strictly increasing.
        force_N: Forces at those depths, shape (k,).
    """

    displacement_m: np.ndarray
    force_N_values: np.ndarray

    @classmethod
    def from_csv(cls, path: str | Path) -> ForceCurveTissue:
        """Read any CSV with columns ``displacement_m`` (depth, increasing, zero or more) and
        ``force_N`` (compression positive), other columns ignored: ``warptissue simulate``'s
        ``force_curve.csv``, or a measured loading curve.

        Raises:
            InputError: Missing file or column, a bad number, a depth that does not increase
                or is negative, or forces that are all negative (file, line, column named).
        """

        record = read_experiment_csv(
            path, required=("displacement_m", "force_N"), monotonic="displacement_m"
        )
        depth, force = record["displacement_m"], record["force_N"]
        if depth[0] < 0:
            raise InputError(
                "the depth must be zero or more (zero at the surface)",
                path=path,
                line=2,
                column="displacement_m",
                value=float(depth[0]),
            )
        if force.max() <= 0 < -force.min():
            raise InputError(
                "every force is negative: give the compressive force as positive",
                path=path,
                column="force_N",
                value=float(force.min()),
            )
        return cls(depth, force)

    def force_N(self, time_s: np.ndarray, displacement_m: np.ndarray) -> np.ndarray:
        """Interpolated force at each depth; ``time_s`` is unused (rate-independent)."""
        depth = np.asarray(displacement_m, dtype=np.float64)
        curve_depth = np.concatenate(([0.0], self.displacement_m))
        curve_force = np.concatenate(([0.0], self.force_N_values))
        return np.where(depth > 0.0, np.interp(depth, curve_depth, curve_force), 0.0)


@dataclass(frozen=True)
class PhysiologicalDisturbance:
    """Respiration and heartbeat forces added to the transducer signal, as in Kim et al.
    Fig. 2(d) (large peaks from respiration, small ones from the heart beat).

    Kim et al. give the picture, not the numbers; the defaults are those of an anaesthetised,
    ventilated pig: 15 breaths/min (0.25 Hz) and 84 beats/min (1.4 Hz), with peaks of a few
    millinewtons, the respiration peak about four times the cardiac one. Each waveform is a
    zero-mean peaked pulse train, ``amplitude * (((1 - cos(2 pi f t)) / 2) ** 2 - 3/8)``, whose
    only harmonics are f and 2 f.

    Attributes:
        respiration_amplitude_N: Peak-to-peak respiration force (N).
        respiration_Hz: Breathing rate (Hz).
        heartbeat_amplitude_N: Peak-to-peak cardiac force (N).
        heartbeat_Hz: Heart rate (Hz).
    """

    respiration_amplitude_N: float = 8e-3
    respiration_Hz: float = 0.25
    heartbeat_amplitude_N: float = 2e-3
    heartbeat_Hz: float = 1.4

    def force_N(self, time_s: np.ndarray) -> np.ndarray:
        """Disturbance force (N) at rig time ``time_s`` (s), shape (n,)."""
        t = np.asarray(time_s, dtype=np.float64)
        total = np.zeros_like(t)
        for amplitude, rate, phase in (
            (self.respiration_amplitude_N, self.respiration_Hz, 0.3),
            (self.heartbeat_amplitude_N, self.heartbeat_Hz, 1.1),
        ):
            pulse = ((1.0 - np.cos(2.0 * np.pi * rate * t + phase)) / 2.0) ** 2 - 0.375
            total += amplitude * pulse
        return total
