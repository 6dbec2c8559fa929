"""What one assembly gives: the residual, the tangent and the energies at a displacement
(:class:`Assembly`, made by :meth:`warptissue.fem.assembly.Assembler.assemble`), and the von
Mises stress of a Cauchy stress."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import warp as wp
import warp.sparse as wps

__all__ = ["Assembly", "von_mises"]


@dataclass
class Assembly:
    """One evaluation of the discrete system at a displacement.

    Attributes:
        residual: Internal nodal forces f_int (no external loads) less the rigid contact's
            forces on the body where the assembler has one, Warp array (N,) vec3d, N.
        matrix: Tangent stiffness d f_int / d u as a 3x3-block BSR matrix (N/m), or None when
            only the residual was assembled. Shared with the assembler: the next assembly
            overwrites it.
        energy_J: Stored strain energy, J (of every packed problem together).
        min_jacobian: Smallest det F over all quadrature points (<= 0 means inverted).
        problem_energies_J: The energy of each packed problem, (K,), J; None where not
            assembled (one entry for an assembler of one problem).
        problem_min_jacobians: The smallest det F of each packed problem, (K,); None where
            not assembled.
        scalars: Where the four above are not read yet (``assemble(read_scalars=False)``),
            the assembler's device array (2K,) of the energies and then the smallest det F,
            to read with other values in one copy and pass to :meth:`with_scalars`.
    """

    residual: wp.array
    matrix: wps.BsrMatrix | None
    energy_J: float
    min_jacobian: float
    problem_energies_J: np.ndarray | None = None
    problem_min_jacobians: np.ndarray | None = None
    scalars: wp.array | None = None

    def with_scalars(self, values: np.ndarray) -> Assembly:
        """This assembly with its energies and smallest det F from ``values`` (2K,), the
        :attr:`scalars` as read."""
        energies, min_jacobians = np.array(values, dtype=np.float64).reshape(2, -1)
        return replace(
            self,
            energy_J=float(energies.sum()),
            min_jacobian=float(min_jacobians.min()),
            problem_energies_J=energies,
            problem_min_jacobians=min_jacobians,
            scalars=None,
        )


def von_mises(cauchy_stress_Pa: np.ndarray) -> np.ndarray:
    """Von Mises stress from Voigt Cauchy stress (xx, yy, zz, yz, xz, xy), shape (M, 6) -> (M,)."""
    s = np.asarray(cauchy_stress_Pa, dtype=np.float64)
    return np.sqrt(
        0.5 * ((s[:, 0] - s[:, 1]) ** 2 + (s[:, 1] - s[:, 2]) ** 2 + (s[:, 2] - s[:, 0]) ** 2)
        + 3.0 * (s[:, 3] ** 2 + s[:, 4] ** 2 + s[:, 5] ** 2)
    )
