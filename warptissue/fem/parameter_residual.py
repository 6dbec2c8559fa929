"""The residual's derivatives by the material parameters at fixed displacement
(``dR/d theta``), which the exact force sensitivities solve with
(:mod:`warptissue.fem.newton.sensitivity`).

:class:`ParameterResidual` is a part of :class:`warptissue.fem.assembly.Assembler` (its base
class): it launches the assembler's element kernels with the derivative parameters.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from warptissue.errors import InputError
from warptissue.fem.regions import zero_derivative
from warptissue.kernels import assembly as ka
from warptissue.kernels.materials import MaterialParams

__all__ = ["ParameterResidual"]


class ParameterResidual:
    """The parameter residual of :class:`warptissue.fem.assembly.Assembler` (its base
    class)."""

    def parameter_residual(self, displacement_m: np.ndarray | wp.array, name: str) -> np.ndarray:
        """``dR/d theta``: the internal forces' derivative by one material parameter at fixed u.

        The internal force is linear in every material parameter but the Ogden exponents, so
        for those it is the residual assembled with the parameters' derivative struct
        (:meth:`warptissue.materials.Material.device_params_derivative`, the chain rule from
        the parameter to the device fields included); for ``alpha_i`` it is
        ``ogden_alpha_residual_kernel``.

        Packed problems (K > 1) are differentiated each by its own parameter of that name in
        one launch: the rows of problem k hold ``dR_k / d theta_k`` (the Ogden exponents,
        which need their own kernel, are refused there). A body of several material regions
        is differentiated by one region's parameter (``tumour.C10_Pa``; the default's
        unqualified): the other regions' tets contribute nothing.

        Args:
            displacement_m: Nodal displacements, (N, 3) or a vec3d Warp array, metres.
            name: A parameter of :attr:`material` (``C10_Pa``, ``alpha1``, ``bulk_modulus_Pa``,
                ...; :attr:`warptissue.materials.Material.sensitivity_names`); of every
                problem's material where K > 1.

        Returns:
            dR/d theta, shape (N, 3), N per unit of the parameter (a copy: the assembler's
            residual buffer is reused).
        """
        derivatives, alpha_term = [], -1
        for k, material in enumerate(self.materials):
            alpha_term = material.device_params_derivative(name)[1]  # names a bad one
            if alpha_term >= 0 and (self.problem_count > 1 or len(self._slots.materials) > 1):
                raise InputError(
                    f"problem {k}: the derivative by an Ogden exponent is available for one "
                    "problem of one material per assembler",
                    key="sensitivities",
                    value=name,
                )
        for slot, part in enumerate(self._slots.materials):
            local = self._slots.owner(slot, name)
            derivatives.append(
                zero_derivative(part) if local is None else part.device_params_derivative(local)[0]
            )
        u = self.device_displacement(displacement_m)
        self._residual.zero_()
        viscous = self.viscous
        if alpha_term >= 0:
            wp.launch(
                ka.ogden_alpha_residual_kernel,
                dim=self.tet_count,
                inputs=[*self._element_inputs(u), alpha_term],
                outputs=[self._residual],
                device=self.device,
            )
            explicit = self._residual.numpy().copy()
            if viscous is not None:  # the deviatoric stress of a step is gamma P0 + F Q
                explicit *= viscous.gamma(0)
        else:
            # Linear in the parameters: the residual of the derivative parameters (zero for
            # a Prony parameter), its deviatoric part scaled by each step's gamma.
            self._energy.zero_()
            self._min_jacobian.fill_(np.inf)
            derivative_params = wp.array(derivatives, dtype=MaterialParams, device=self.device)
            wp.launch(
                ka.assemble_elements_kernel,
                dim=self.tet_count,
                inputs=[
                    *self._assembly_inputs(u, problem_params=derivative_params),
                    self._block_index,
                    self._all_elements,
                    int(self.formulation == "mixed"),
                    0,
                    *self._viscous_inputs(zero_history=True),
                ],
                outputs=[self._residual, self.matrix.values, self._energy, self._min_jacobian],
                device=self.device,
            )
            explicit = self._residual.numpy().copy()
        count = self.problem_count  # a problem's contact scales with entry k's modulus
        d_shears = np.array([float(derivative.shear_modulus) for derivative in derivatives[:count]])
        moduli = np.array([material.initial_shear_modulus_Pa for material in self.materials])
        explicit = explicit + self._rigid.parameter_residual(
            u, self.matrix.values, d_shears, moduli
        )
        if viscous is None or name not in viscous.names:
            return explicit
        self._residual.zero_()
        viscous.history_residual(self, u, name, self._residual)
        return explicit + self._residual.numpy()
