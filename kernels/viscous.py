"""Quasi-linear viscoelastic history kernels (float64), launched by
:mod:`warptissue.fem.viscous`: the frozen history stress of a step, the commit of a converged
step, and the history's parts of the parameter sensitivities.

A step's Prony coefficients are a ``ViscousStep`` (``assembly.py``, whose element kernel
reads them).
"""

import warp as wp
from warptissue.kernels.assembly import ViscousStep, deformation_gradient
from warptissue.kernels.materials import (
    MaterialParams,
    deviatoric_response,
    flat,
    ogden_alpha_stress_derivative,
)

wp.set_module_options({"enable_backward": False})

# The kernels below are compiled in the Warp module of assembly.py: the FE's kernels are one
# Warp module, so that a cold start compiles the constitutive code once
# (docs/design-notes/kernel-modules.md; __init__.py imports every file of that module).
FE_MODULE = wp.get_module("warptissue.kernels.assembly")


@wp.func
def deviatoric_pk2(params: MaterialParams, f: wp.mat33d) -> wp.mat33d:
    """The hyperelastic deviatoric second Piola-Kirchhoff stress ``S0 = F^-1 P_dev`` (Pa)."""
    psi, p, a_mat = deviatoric_response(params, f, 0)
    return wp.inverse(f) @ p


@wp.kernel(module=FE_MODULE)
def viscous_frozen_kernel(
    element_problem: wp.array(dtype=wp.int32),
    viscous: wp.array(dtype=ViscousStep),
    history: wp.array3d(dtype=wp.mat33d),
    elastic_stress: wp.array2d(dtype=wp.mat33d),
    frozen: wp.array2d(dtype=wp.mat33d),
):
    """The history stress held fixed over a step: ``Q = sum_i (a_i H_i - b_i S0_prev)`` (Pa).

    ``history[e, q, i]`` is H_i and ``elastic_stress[e, q]`` the deviatoric elastic stress S0
    of the last converged step; tet e's step is ``viscous[element_problem[e]]``. Launched
    over (elements, quadrature points).
    """
    e, q = wp.tid()
    step = viscous[element_problem[e]]
    total = wp.mat33d()
    for i in range(step.terms):
        total += step.a[i] * history[e, q, i] - step.b[i] * elastic_stress[e, q]
    frozen[e, q] = total


@wp.kernel(module=FE_MODULE)
def viscous_commit_kernel(
    problem_params: wp.array(dtype=MaterialParams),
    element_problem: wp.array(dtype=wp.int32),
    committed: wp.array(dtype=wp.int32),
    tets: wp.array2d(dtype=wp.int32),
    shape_gradients: wp.array3d(dtype=wp.vec3d),
    displacement: wp.array(dtype=wp.vec3d),
    viscous: wp.array(dtype=ViscousStep),
    history: wp.array3d(dtype=wp.mat33d),
    elastic_stress: wp.array2d(dtype=wp.mat33d),
):
    """Advance the history to a converged step: ``H_i <- a_i H_i + b_i (S0_n - S0_prev)``,
    ``S0_prev <- S0_n``, with ``S0_n`` the deviatoric elastic stress at ``displacement``, in
    the tets of the problems k with ``committed[k] != 0`` (the others keep theirs).

    Launched over (elements, quadrature points).
    """
    e, q = wp.tid()
    problem = element_problem[e]
    step = viscous[problem]
    if committed[problem] == 0 or step.active == 0:
        return
    f = deformation_gradient(e, q, tets, shape_gradients, displacement)
    current = deviatoric_pk2(problem_params[problem], f)
    change = current - elastic_stress[e, q]
    for i in range(step.terms):
        history[e, q, i] = step.a[i] * history[e, q, i] + step.b[i] * change
    elastic_stress[e, q] = current


@wp.kernel(module=FE_MODULE)
def viscous_history_residual_kernel(
    problem_params: wp.array(dtype=MaterialParams),
    element_problem: wp.array(dtype=wp.int32),
    tets: wp.array2d(dtype=wp.int32),
    shape_gradients: wp.array3d(dtype=wp.vec3d),
    quadrature_volumes: wp.array2d(dtype=wp.float64),
    displacement: wp.array(dtype=wp.vec3d),
    viscous: wp.array(dtype=ViscousStep),
    d_viscous: wp.array(dtype=ViscousStep),
    history: wp.array3d(dtype=wp.mat33d),
    elastic_stress: wp.array2d(dtype=wp.mat33d),
    d_history: wp.array4d(dtype=wp.mat33d),
    d_elastic_stress: wp.array3d(dtype=wp.mat33d),
    parameter: int,
    residual: wp.array(dtype=wp.vec3d),
):
    """Add the history's part of ``dR/d theta`` at fixed u (N): ``int F dS/dtheta grad N_a dV``
    with ``dS/dtheta = dgamma S0(F) + sum_i (da_i H_i + a_i dH_i - db_i S0_prev - b_i dS0_prev)``.

    ``d_viscous`` holds ``dgamma, da_i, db_i`` by the parameter; ``d_history[parameter]`` and
    ``d_elastic_stress[parameter]`` the derivatives of H_i and S0_prev carried from the earlier
    steps. The elastic part ``gamma dP0/dtheta`` is the assembly kernel's (with derivative
    parameters). Tet e belongs to problem ``k = element_problem[e]``, with the material
    ``problem_params[k]`` and the steps ``viscous[k]``, ``d_viscous[k]``.
    """
    e = wp.tid()
    problem = element_problem[e]
    step = viscous[problem]
    d_step = d_viscous[problem]
    if step.active == 0:
        return
    params = problem_params[problem]
    for q in range(quadrature_volumes.shape[1]):
        f = deformation_gradient(e, q, tets, shape_gradients, displacement)
        if wp.determinant(f) <= wp.float64(0.0):
            continue
        d_stress = d_step.gamma * deviatoric_pk2(params, f)
        for i in range(step.terms):
            d_stress += (
                d_step.a[i] * history[e, q, i]
                + step.a[i] * d_history[parameter, e, q, i]
                - d_step.b[i] * elastic_stress[e, q]
                - step.b[i] * d_elastic_stress[parameter, e, q]
            )
        dp = f @ d_stress
        dv = quadrature_volumes[e, q]
        for a in range(tets.shape[1]):
            wp.atomic_add(residual, tets[e, a], dv * (dp @ shape_gradients[e, q, a]))


@wp.kernel(module=FE_MODULE)
def viscous_sensitivity_commit_kernel(
    problem_params: wp.array(dtype=MaterialParams),
    d_params: wp.array(dtype=MaterialParams),
    with_explicit: wp.array(dtype=wp.int32),
    alpha_term: int,
    element_problem: wp.array(dtype=wp.int32),
    committed: wp.array(dtype=wp.int32),
    tets: wp.array2d(dtype=wp.int32),
    shape_gradients: wp.array3d(dtype=wp.vec3d),
    displacement: wp.array(dtype=wp.vec3d),
    d_displacement: wp.array(dtype=wp.vec3d),
    viscous: wp.array(dtype=ViscousStep),
    d_viscous: wp.array(dtype=ViscousStep),
    history: wp.array3d(dtype=wp.mat33d),
    elastic_stress: wp.array2d(dtype=wp.mat33d),
    d_history: wp.array4d(dtype=wp.mat33d),
    d_elastic_stress: wp.array3d(dtype=wp.mat33d),
    parameter: int,
):
    """Advance the history's derivatives by one parameter to a converged step.

    With ``dF = sum_a du_a/dtheta (x) grad N_a`` and ``dP0 = A0 : dF (+ dP0/dtheta at fixed F
    when ``with_explicit``: ``d_params``' stress, or the Ogden ``alpha_term``'s)``:
    ``dS0_n = F^-1 (dP0 - dF S0_n)``, then
    ``dH_i <- da_i H_i + a_i dH_i + db_i (S0_n - S0_prev) + b_i (dS0_n - dS0_prev)`` and
    ``dS0_prev <- dS0_n``. Must run before :func:`viscous_commit_kernel` (it reads the
    previous H_i and S0_prev). Per problem k of tet e (``element_problem[e]``): its material
    ``problem_params[k]``, derivative ``d_params[k]``, ``with_explicit[k]`` and steps
    ``viscous[k]``, ``d_viscous[k]``; only problems with ``committed[k] != 0`` advance.
    Launched over (elements, quadrature points).
    """
    e, q = wp.tid()
    problem = element_problem[e]
    step = viscous[problem]
    d_step = d_viscous[problem]
    if committed[problem] == 0 or step.active == 0:
        return
    params = problem_params[problem]
    f = deformation_gradient(e, q, tets, shape_gradients, displacement)
    df = wp.mat33d()
    for a in range(tets.shape[1]):
        df += wp.outer(d_displacement[tets[e, a]], shape_gradients[e, q, a])
    psi, p, a_mat = deviatoric_response(params, f, 1)
    f_inv = wp.inverse(f)
    current = f_inv @ p
    dp = wp.mat33d()
    for i in range(3):
        for jj in range(3):
            value = wp.float64(0.0)
            for k in range(3):
                for ll in range(3):
                    value += a_mat[flat(i, jj), flat(k, ll)] * df[k, ll]
            dp[i, jj] = value
    if with_explicit[problem] != 0:
        if alpha_term >= 0:
            dp += ogden_alpha_stress_derivative(params, f, alpha_term)
        else:
            psi_d, p_d, a_d = deviatoric_response(d_params[problem], f, 0)
            dp += p_d
    d_current = f_inv @ (dp - df @ current)
    change = current - elastic_stress[e, q]
    d_change = d_current - d_elastic_stress[parameter, e, q]
    for i in range(step.terms):
        d_history[parameter, e, q, i] = (
            d_step.a[i] * history[e, q, i]
            + step.a[i] * d_history[parameter, e, q, i]
            + d_step.b[i] * change
            + step.b[i] * d_change
        )
    d_elastic_stress[parameter, e, q] = d_current
