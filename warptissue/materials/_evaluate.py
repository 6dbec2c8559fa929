"""Energy, stress and tangent of a material at deformation gradients, on a Warp device."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from warptissue.device import resolve_device
from warptissue.errors import InputError
from warptissue.kernels import assembly as ka
from warptissue.kernels import materials as km
from warptissue.materials._base import Material


@dataclass(frozen=True)
class MaterialEvaluation:
    """Energy, stress and tangent at a batch of deformation gradients.

    Attributes:
        energy_density_Pa: psi, shape (n,).
        first_piola_Pa: P = dpsi/dF, shape (n, 3, 3).
        tangent_Pa: A = dP/dF, shape (n, 9, 9), ``A[:, 3 i + J, 3 k + L] = dP_iJ/dF_kL``.
    """

    energy_density_Pa: np.ndarray
    first_piola_Pa: np.ndarray
    tangent_Pa: np.ndarray


def evaluate_material(
    material: Material,
    deformation_gradients: np.ndarray,
    *,
    device: str | None = None,
) -> MaterialEvaluation:
    """Evaluate energy, first Piola-Kirchhoff stress and tangent on a Warp device.

    Args:
        material: Any material of this module.
        deformation_gradients: F, shape (n, 3, 3) or (3, 3), with det F > 0.
        device: Warp device (``"cpu"``, ``"cuda:0"``); None for Warp's default.

    Returns:
        A :class:`MaterialEvaluation` with arrays of leading size n.
    """

    f = np.asarray(deformation_gradients, dtype=np.float64)
    if f.shape == (3, 3):
        f = f[None]
    if f.ndim != 3 or f.shape[1:] != (3, 3):
        raise InputError("deformation gradients must have shape (n, 3, 3)", value=f.shape)
    if not np.all(np.isfinite(f)):
        raise InputError("deformation gradients must be finite")
    n = f.shape[0]
    if n == 0:
        return MaterialEvaluation(np.zeros(0), np.zeros((0, 3, 3)), np.zeros((0, 9, 9)))
    det = np.linalg.det(f)
    if np.any(det <= 0.0):
        bad = int(np.flatnonzero(det <= 0.0)[0])
        raise InputError(f"det F must be positive; F[{bad}] has det {det[bad]:.6g}")
    dev = resolve_device(device)
    f_wp = wp.array(f, dtype=wp.mat33d, device=dev)
    energy = wp.zeros(n, dtype=wp.float64, device=dev)
    stress = wp.zeros(n, dtype=wp.mat33d, device=dev)
    tangent = wp.zeros(n, dtype=km.mat99d, device=dev)
    wp.launch(
        ka.evaluate_material_kernel,
        dim=n,
        inputs=[material.device_params(), f_wp],
        outputs=[energy, stress, tangent],
        device=dev,
    )
    return MaterialEvaluation(energy.numpy(), stress.numpy(), tangent.numpy())
