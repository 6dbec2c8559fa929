"""Tetrahedral finite-element kernels: element residual and tangent, Dirichlet elimination,
stress recovery (float64).

Elements are TET4 (one quadrature point) or TET10 (four points), with reference shape-function
gradients precomputed per quadrature point on the host. Two formulations share one kernel:

- displacement (``mixed == 0``): ``Pi_e = int psi_dev(F) + U(J) dV``.
- mean dilatation (``mixed == 1``, TET10/P0): ``Pi_e = int psi_dev(F) dV + V_e U(Jbar)`` with
  ``Jbar = (1/V_e) int J dV``. With ``g_a = (1/V_e) int J F^-T grad N_a dV`` (so that
  ``dJbar = sum_a g_a . du_a``) the residual is ``int P_dev grad N_a dV + V_e U'(Jbar) g_a``
  and the exact tangent is ``int grad N_a . (A_dev + U'(Jbar) d2J/dF2) . grad N_b dV
  + V_e U''(Jbar) g_a (x) g_b``. The pressure ``U'(Jbar)`` is constant per element, i.e. the
  P2/P0 pair. In 3D its discrete inf-sup constant is not uniform on these meshes (it falls
  about like h; docs/design-notes/inf-sup.md), although the punch forces show no locking.
"""

import warp as wp
from warptissue.kernels.materials import (
    MaterialParams,
    add_pressure_terms,
    deviatoric_response,
    flat,
    mat99d,
    ogden_alpha_stress_derivative,
    volumetric_energy,
)

wp.set_module_options({"enable_backward": False})

MAX_PRONY_TERMS = wp.constant(6)
vec6d = wp.types.vector(length=6, dtype=wp.float64)


@wp.struct
class ViscousStep:
    """The Prony coefficients of one time step of a viscoelastic material.

    With ``x_i = dt / tau_i``: ``a_i = exp(-x_i)`` (the history's decay over the step),
    ``b_i = g_i (1 - a_i) / x_i`` (the weight of the step's elastic-stress increment, the
    exact convolution of a stress linear in time over the step) and
    ``gamma = 1 - sum g_i + sum b_i`` (the weight of the current elastic stress).
    ``active = 0`` for an elastic material (the rest unused).
    """

    active: wp.int32
    terms: wp.int32
    gamma: wp.float64
    a: vec6d
    b: vec6d


mat10x3d = wp.types.matrix(shape=(10, 3), dtype=wp.float64)
mat3x9d = wp.types.matrix(shape=(3, 9), dtype=wp.float64)


@wp.func
def deformation_gradient(
    e: int,
    q: int,
    tets: wp.array2d(dtype=wp.int32),
    shape_gradients: wp.array3d(dtype=wp.vec3d),
    displacement: wp.array(dtype=wp.vec3d),
) -> wp.mat33d:
    """F = I + sum_a u_a (x) grad_X N_a at quadrature point q of element e."""
    f = wp.identity(n=3, dtype=wp.float64)
    for a in range(tets.shape[1]):
        f += wp.outer(displacement[tets[e, a]], shape_gradients[e, q, a])
    return f


@wp.func
def quadrature_point_response(
    params: MaterialParams,
    f: wp.mat33d,
    j: wp.float64,
    mixed: int,
    element_pressure: wp.float64,
    with_tangent: int,
    viscous: ViscousStep,
    frozen: wp.mat33d,
):
    """Energy density, P and A at one quadrature point of either formulation (Pa).

    Displacement formulation (``mixed == 0``): the full pointwise response, U(J) included,
    with ``j = det F``. Mixed: ``psi_dev`` only, and P and A carry the element's constant
    pressure ``element_pressure = U'(Jbar)`` (its stiffness ``U''(Jbar)`` is the element's
    rank-one term, added by the caller). The material code is called once, not per branch, so
    that it is inlined once into each kernel.

    Viscoelastic step (``viscous.active != 0``): the deviatoric second Piola-Kirchhoff stress
    of the step is ``S = gamma S0(F) + Q`` with the step's ``gamma`` and the quadrature
    point's ``frozen`` history stress Q (fixed during the step), the stationarity condition of
    the incremental energy ``gamma psi_dev + Q : (C - I) / 2``, so P gains ``F Q`` and A gains
    ``delta_ik Q_LJ``.
    """
    psi, p, a_mat = deviatoric_response(params, f, with_tangent)
    if viscous.active != 0:
        gamma = viscous.gamma
        psi = gamma * psi + wp.float64(0.5) * wp.ddot(
            frozen, wp.transpose(f) @ f - wp.identity(n=3, dtype=wp.float64)
        )
        p = gamma * p + f @ frozen
        if with_tangent != 0:
            for r in range(9):
                for c in range(9):
                    a_mat[r, c] = gamma * a_mat[r, c]
            for i in range(3):
                for jj in range(3):
                    for ll in range(3):
                        a_mat[flat(i, jj), flat(i, ll)] = (
                            a_mat[flat(i, jj), flat(i, ll)] + frozen[ll, jj]
                        )
    pressure = element_pressure
    stiffness = wp.float64(0.0)
    if mixed == 0:
        u, du, ddu = volumetric_energy(params, j)
        psi += u
        pressure = du
        stiffness = ddu
    p, a_mat = add_pressure_terms(p, a_mat, f, pressure, stiffness, with_tangent)
    return psi, p, a_mat


@wp.kernel
def assemble_elements_kernel(
    problem_params: wp.array(dtype=MaterialParams),
    element_problem: wp.array(dtype=wp.int32),
    tets: wp.array2d(dtype=wp.int32),
    shape_gradients: wp.array3d(dtype=wp.vec3d),
    quadrature_volumes: wp.array2d(dtype=wp.float64),
    displacement: wp.array(dtype=wp.vec3d),
    block_index: wp.array2d(dtype=wp.int32),
    elements: wp.array(dtype=wp.int32),
    mixed: int,
    with_tangent: int,
    viscous: wp.array(dtype=ViscousStep),
    frozen: wp.array2d(dtype=wp.mat33d),
    residual: wp.array(dtype=wp.vec3d),
    matrix_values: wp.array(dtype=wp.mat33d),
    energy: wp.array(dtype=wp.float64),
    min_jacobian: wp.array(dtype=wp.float64),
):
    """Add element internal forces to ``residual`` and tangent blocks to ``matrix_values``.

    One thread per entry of ``elements``, the tets to assemble (all of them, or a patch's).
    Tet e belongs to problem ``k = element_problem[e]`` and has its material
    ``problem_params[k]`` (one problem: all zeros; packed problems: one per problem,
    :mod:`warptissue.fem.packing`).
    ``block_index[e, a * nodes_per_tet + b]`` is the BSR block of node pair (a, b) of tet e.
    ``energy[k]`` accumulates problem k's stored energy (J) and ``min_jacobian[k]`` its
    smallest J. Problem k's time step is ``viscous[k]``: a viscoelastic one reads the frozen
    history stress ``frozen[e, q]`` (unused otherwise).
    """
    e = elements[wp.tid()]
    problem = element_problem[e]
    params = problem_params[problem]
    step = viscous[problem]
    npe = tets.shape[1]
    nq = quadrature_volumes.shape[1]

    # Pass 1: mean dilatation Jbar and its gradient g_a (mixed formulation only).
    volume = wp.float64(0.0)
    deformed_volume = wp.float64(0.0)
    g = mat10x3d()
    for q in range(nq):
        f = deformation_gradient(e, q, tets, shape_gradients, displacement)
        j = wp.determinant(f)
        wp.atomic_min(min_jacobian, problem, j)
        dv = quadrature_volumes[e, q]
        volume += dv
        deformed_volume += j * dv
        if mixed != 0 and j > wp.float64(0.0):
            f_inv_t = wp.transpose(wp.inverse(f))
            for a in range(npe):
                ga = j * dv * (f_inv_t @ shape_gradients[e, q, a])
                for i in range(3):
                    g[a, i] = g[a, i] + ga[i]
    j_bar = deformed_volume / volume
    if j_bar <= wp.float64(0.0):
        return
    u_bar, p_bar, k_bar = volumetric_energy(params, j_bar)
    element_energy = wp.float64(0.0)
    if mixed != 0:
        element_energy = volume * u_bar

    # Pass 2: quadrature of the deviatoric part (and U(J) for the displacement formulation).
    for q in range(nq):
        f = deformation_gradient(e, q, tets, shape_gradients, displacement)
        j = wp.determinant(f)
        if j <= wp.float64(0.0):
            continue
        dv = quadrature_volumes[e, q]
        history = wp.mat33d()
        if step.active != 0:
            history = frozen[e, q]
        psi, p, a_mat = quadrature_point_response(
            params, f, j, mixed, p_bar, with_tangent, step, history
        )
        element_energy += psi * dv
        for a in range(npe):
            grad_a = shape_gradients[e, q, a]
            wp.atomic_add(residual, tets[e, a], dv * (p @ grad_a))
            if with_tangent != 0:
                # t[i, 3k + L] = sum_J grad_a[J] A[3i + J, 3k + L]
                t = mat3x9d()
                for i in range(3):
                    for col in range(9):
                        t[i, col] = dv * (
                            grad_a[0] * a_mat[flat(i, 0), col]
                            + grad_a[1] * a_mat[flat(i, 1), col]
                            + grad_a[2] * a_mat[flat(i, 2), col]
                        )
                for b in range(npe):
                    grad_b = shape_gradients[e, q, b]
                    block = wp.mat33d()
                    for i in range(3):
                        for k in range(3):
                            block[i, k] = (
                                t[i, flat(k, 0)] * grad_b[0]
                                + t[i, flat(k, 1)] * grad_b[1]
                                + t[i, flat(k, 2)] * grad_b[2]
                            )
                    wp.atomic_add(matrix_values, block_index[e, a * npe + b], block)

    if mixed != 0 and with_tangent != 0:
        # g holds V_e g_a = int J F^-T grad N_a dV; the pressure U'(Jbar) J F^-T already went
        # into P above, this adds the rank-one part V_e U''(Jbar) g_a (x) g_b.
        for a in range(npe):
            ga = wp.vec3d(g[a, 0], g[a, 1], g[a, 2])
            for b in range(npe):
                gb = wp.vec3d(g[b, 0], g[b, 1], g[b, 2])
                wp.atomic_add(
                    matrix_values, block_index[e, a * npe + b], (k_bar / volume) * wp.outer(ga, gb)
                )
    wp.atomic_add(energy, problem, element_energy)


@wp.kernel
def zero_element_blocks_kernel(
    elements: wp.array(dtype=wp.int32),
    block_index: wp.array2d(dtype=wp.int32),
    matrix_values: wp.array(dtype=wp.mat33d),
):
    """Zero every tangent block that the tets ``elements`` add to (thread (i, k): block k of
    tet ``elements[i]``)."""
    i, k = wp.tid()
    matrix_values[block_index[elements[i], k]] = wp.mat33d()


@wp.kernel
def ogden_alpha_residual_kernel(
    params: MaterialParams,
    tets: wp.array2d(dtype=wp.int32),
    shape_gradients: wp.array3d(dtype=wp.vec3d),
    quadrature_volumes: wp.array2d(dtype=wp.float64),
    displacement: wp.array(dtype=wp.vec3d),
    term: int,
    residual: wp.array(dtype=wp.vec3d),
):
    """Add ``dR/d alpha_term = int dP_dev/d alpha_term grad N_a dV`` of an Ogden material (N).

    The internal force is linear in every other material parameter (C_i0, C01, mu_i, K, mu,
    lambda), so their derivatives are residuals of ``assemble_elements_kernel`` with the
    parameters' derivative struct; alpha_i enters nonlinearly and only the deviatoric stress,
    in either formulation (the mean-dilatation pressure depends on K only).
    """
    e = wp.tid()
    for q in range(quadrature_volumes.shape[1]):
        f = deformation_gradient(e, q, tets, shape_gradients, displacement)
        if wp.determinant(f) <= wp.float64(0.0):
            continue
        dv = quadrature_volumes[e, q]
        dp = ogden_alpha_stress_derivative(params, f, term)
        for a in range(tets.shape[1]):
            wp.atomic_add(residual, tets[e, a], dv * (dp @ shape_gradients[e, q, a]))


@wp.kernel
def eliminate_dirichlet_kernel(
    offsets: wp.array(dtype=wp.int32),
    columns: wp.array(dtype=wp.int32),
    constrained: wp.array(dtype=wp.vec3d),
    node_problem: wp.array(dtype=wp.int32),
    problem_damping: wp.array(dtype=wp.float64),
    matrix_values: wp.array(dtype=wp.mat33d),
):
    """Zero the rows and columns of constrained dofs and put 1 on their diagonal; add
    ``damping |K_ii|`` to the diagonal of the free dofs (Levenberg-Marquardt, 0 for none),
    with the damping of the row's problem (``problem_damping[node_problem[row]]``).

    ``constrained[n][i]`` is 1 where component i of node n is prescribed, else 0.
    """
    row = wp.tid()
    row_mask = constrained[row]
    damping = problem_damping[node_problem[row]]
    for idx in range(offsets[row], offsets[row + 1]):
        col = columns[idx]
        col_mask = constrained[col]
        block = matrix_values[idx]
        for i in range(3):
            for k in range(3):
                if row_mask[i] != wp.float64(0.0) or col_mask[k] != wp.float64(0.0):
                    block[i, k] = wp.float64(0.0)
                    if row == col and i == k:
                        block[i, k] = wp.float64(1.0)
                elif row == col and i == k:
                    block[i, k] = block[i, k] + damping * wp.abs(block[i, k])
        matrix_values[idx] = block


@wp.kernel
def cauchy_stress_kernel(
    problem_params: wp.array(dtype=MaterialParams),
    element_problem: wp.array(dtype=wp.int32),
    tets: wp.array2d(dtype=wp.int32),
    shape_gradients: wp.array3d(dtype=wp.vec3d),
    quadrature_volumes: wp.array2d(dtype=wp.float64),
    displacement: wp.array(dtype=wp.vec3d),
    mixed: int,
    viscous: wp.array(dtype=ViscousStep),
    frozen: wp.array2d(dtype=wp.mat33d),
    stress: wp.array2d(dtype=wp.float64),
):
    """Volume-averaged Cauchy stress per tet, Voigt order xx, yy, zz, yz, xz, xy (Pa).

    sigma = P F^T / J at each quadrature point; in the mixed formulation the pressure part is
    U'(Jbar) I, constant over the element. A viscoelastic state passes ``gamma = g_inf`` and
    ``frozen = sum_i H_i`` (the committed stress). Tet e has the material
    ``problem_params[element_problem[e]]`` (as in ``assemble_elements_kernel``).
    """
    e = wp.tid()
    params = problem_params[element_problem[e]]
    step = viscous[element_problem[e]]
    nq = quadrature_volumes.shape[1]
    volume = wp.float64(0.0)
    deformed_volume = wp.float64(0.0)
    for q in range(nq):
        f = deformation_gradient(e, q, tets, shape_gradients, displacement)
        dv = quadrature_volumes[e, q]
        volume += dv
        deformed_volume += wp.determinant(f) * dv
    u_bar, p_bar, k_bar = volumetric_energy(params, deformed_volume / volume)
    sigma = wp.mat33d()
    for q in range(nq):
        f = deformation_gradient(e, q, tets, shape_gradients, displacement)
        j = wp.determinant(f)
        dv = quadrature_volumes[e, q]
        history = wp.mat33d()
        if step.active != 0:
            history = frozen[e, q]
        psi, p, a_mat = quadrature_point_response(params, f, j, mixed, p_bar, 0, step, history)
        sigma += (dv / (j * volume)) * (p @ wp.transpose(f))
    stress[e, 0] = sigma[0, 0]
    stress[e, 1] = sigma[1, 1]
    stress[e, 2] = sigma[2, 2]
    stress[e, 3] = wp.float64(0.5) * (sigma[1, 2] + sigma[2, 1])
    stress[e, 4] = wp.float64(0.5) * (sigma[0, 2] + sigma[2, 0])
    stress[e, 5] = wp.float64(0.5) * (sigma[0, 1] + sigma[1, 0])


@wp.kernel
def evaluate_material_kernel(
    params: MaterialParams,
    deformation_gradients: wp.array(dtype=wp.mat33d),
    energy: wp.array(dtype=wp.float64),
    stress: wp.array(dtype=wp.mat33d),
    tangent: wp.array(dtype=mat99d),
):
    """Energy density, first Piola-Kirchhoff stress and tangent for a batch of F.

    Each F is a point of the displacement formulation: the full response, U(J) included.
    """
    i = wp.tid()
    f = deformation_gradients[i]
    elastic = ViscousStep()
    elastic.active = 0
    psi, p, a = quadrature_point_response(
        params, f, wp.determinant(f), 0, wp.float64(0.0), 1, elastic, wp.mat33d()
    )
    energy[i] = psi
    stress[i] = p
    tangent[i] = a


@wp.func
def deviatoric_pk2(params: MaterialParams, f: wp.mat33d) -> wp.mat33d:
    """The hyperelastic deviatoric second Piola-Kirchhoff stress ``S0 = F^-1 P_dev`` (Pa)."""
    psi, p, a_mat = deviatoric_response(params, f, 0)
    return wp.inverse(f) @ p


@wp.kernel
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


@wp.kernel
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


@wp.kernel
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


@wp.kernel
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


RIGID_SPHERE = wp.constant(0)
RIGID_PLATE = wp.constant(1)
RIGID_PUNCH = wp.constant(2)
RIGID_WEDGE = wp.constant(3)


@wp.struct
class RigidBody:
    """A rigid indenter at its current position (SI units).

    ``kind``: ``RIGID_SPHERE`` (centre ``point``, radius ``radius``), ``RIGID_PLATE`` (the
    plane ``z = point[2]``, filling the half-space above), ``RIGID_PUNCH`` (a flat-ended
    cylinder along z of radius ``radius`` whose end face lies at ``z = point[2]`` on the axis
    through ``point``, its edge rounded with radius ``edge_radius``) or ``RIGID_WEDGE`` (a
    wedge along y whose rounded tip, radius ``edge_radius``, has its lowest line through
    ``point``, flanks at ``half_angle`` (rad) from the vertical).
    """

    kind: int
    point: wp.vec3d
    radius: wp.float64
    edge_radius: wp.float64
    half_angle: wp.float64


@wp.struct
class RigidContactPoint:
    """Signed distance ``gap`` (m, negative inside the body) of a point to a rigid body, the
    body's outward unit normal ``normal`` at the closest point, and ``normal_gradient`` =
    d normal / d x (1/m), symmetric, used by the consistent tangent."""

    gap: wp.float64
    normal: wp.vec3d
    normal_gradient: wp.mat33d


@wp.func
def distance_to_point(offset: wp.vec3d, plane_only: int) -> RigidContactPoint:
    """The distance to a point (``offset = x - p``) and its normal gradient ``(I - n n^T)/d``;
    ``plane_only`` restricts both to the x-z plane (the distance to a line along y)."""
    result = RigidContactPoint()
    d = wp.length(offset)
    result.gap = d
    eye = wp.identity(n=3, dtype=wp.float64)
    if plane_only != 0:
        eye = wp.mat33d(
            wp.float64(1.0), wp.float64(0.0), wp.float64(0.0),
            wp.float64(0.0), wp.float64(0.0), wp.float64(0.0),
            wp.float64(0.0), wp.float64(0.0), wp.float64(1.0),
        )  # fmt: skip
    if d > wp.float64(0.0):
        n = offset / d
        result.normal = n
        result.normal_gradient = (eye - wp.outer(n, n)) / d
    else:
        result.normal = wp.vec3d(wp.float64(0.0), wp.float64(0.0), wp.float64(-1.0))
    return result


@wp.func
def rigid_contact_point(body: RigidBody, x: wp.vec3d) -> RigidContactPoint:
    """Signed distance, normal and normal gradient of the point ``x`` to ``body``.

    The punch is the Minkowski sum of a sharp cylinder of radius ``radius - edge_radius``
    whose end lies ``edge_radius`` above the face, and a ball of radius ``edge_radius``; the
    wedge is that of a sharp wedge whose apex lies ``edge_radius`` above the tip line, and a
    cylinder of radius ``edge_radius``. So each distance is the distance to a sharp core (to
    its end face, its rim circle, its side, its apex line or a flank plane) less
    ``edge_radius``. For the rim circle of radius ``c`` at the distance ``d`` in the plane of
    the axis, ``dn/dx = t t^T / d + (n_r / r) e_phi e_phi^T`` (``t`` the in-plane tangent,
    ``r`` the distance from the axis).
    """
    zero = wp.float64(0.0)
    down = wp.vec3d(zero, zero, wp.float64(-1.0))
    result = RigidContactPoint()
    if body.kind == RIGID_SPHERE:
        result = distance_to_point(x - body.point, 0)
        result.gap = result.gap - body.radius
        return result
    if body.kind == RIGID_PLATE:
        result.gap = body.point[2] - x[2]
        result.normal = down
        return result
    if body.kind == RIGID_PUNCH:
        core = body.radius - body.edge_radius
        core_end = body.point[2] + body.edge_radius
        dx = x[0] - body.point[0]
        dy = x[1] - body.point[1]
        r = wp.sqrt(dx * dx + dy * dy)
        face_depth = x[2] - body.point[2]
        if r <= core and (r == zero or body.radius - r >= face_depth):
            result.gap = -face_depth
            result.normal = down
            return result
        radial = wp.vec3d(dx / r, dy / r, zero)
        hoop = wp.vec3d(-dy / r, dx / r, zero)
        if r <= core:  # deep inside, nearer the side than the end face
            result.gap = r - body.radius
            result.normal = radial
            result.normal_gradient = wp.outer(hoop, hoop) / r
            return result
        if x[2] >= core_end:
            result.gap = r - core - body.edge_radius
            result.normal = radial
            result.normal_gradient = wp.outer(hoop, hoop) / r
            return result
        in_plane = (r - core) * radial + (x[2] - core_end) * wp.vec3d(zero, zero, wp.float64(1.0))
        d = wp.length(in_plane)
        n = in_plane / d
        t = wp.cross(hoop, n)
        result.gap = d - body.edge_radius
        result.normal = n
        result.normal_gradient = wp.outer(t, t) / d + (wp.dot(n, radial) / r) * wp.outer(hoop, hoop)
        return result
    # RIGID_WEDGE: the sharp core's apex line runs along y through (point[0], point[2] + rho).
    apex = wp.vec3d(body.point[0], x[1], body.point[2] + body.edge_radius)
    offset = x - apex
    side = wp.float64(1.0)
    if offset[0] < zero:
        side = wp.float64(-1.0)
    s = wp.sin(body.half_angle)
    c = wp.cos(body.half_angle)
    flank = wp.vec3d(side * s, zero, c)
    if wp.dot(offset, flank) <= zero:
        result = distance_to_point(offset, 1)
    else:
        result.normal = wp.vec3d(side * c, zero, -s)
        result.gap = wp.dot(offset, result.normal)
    result.gap = result.gap - body.edge_radius
    return result


@wp.kernel
def rigid_contact_kernel(
    points: wp.array(dtype=wp.vec3d),
    displacement: wp.array(dtype=wp.vec3d),
    nodes: wp.array(dtype=wp.int32),
    diagonal_blocks: wp.array(dtype=wp.int32),
    node_problem: wp.array(dtype=wp.int32),
    bodies: wp.array(dtype=RigidBody),
    stiffness: wp.array(dtype=wp.float64),
    with_tangent: int,
    residual: wp.array(dtype=wp.vec3d),
    matrix_values: wp.array(dtype=wp.mat33d),
    energy: wp.array(dtype=wp.float64),
    contact_force: wp.array(dtype=wp.vec3d),
    node_force: wp.array(dtype=wp.vec3d),
    node_gap: wp.array(dtype=wp.float64),
):
    """Frictionless penalty contact of rigid bodies with the candidate nodes.

    Candidate ``i`` (node ``nodes[i]``) belongs to problem ``k = node_problem[i]`` and meets
    that problem's body ``bodies[k]`` with its penalty stiffness ``stiffness[k]`` (N/m); one
    problem: all zeros. A node that penetrates (signed distance ``g < 0``) gets the force
    ``f_c = -k g n`` along the body's outward normal ``n``: ``R -= f_c``, ``energy[k]`` gains
    ``k g^2 / 2`` (J) and the node's diagonal tangent block (``diagonal_blocks[i]``, BSR) gains
    ``d(-f_c)/dx = k (n n^T + g dn/dx)``. ``contact_force[k]`` sums the force on problem k's
    body (N); ``node_force[i]`` holds the force on ``nodes[i]`` (N; zero out of contact) and
    ``node_gap[i]`` its signed distance (m).
    """
    i = wp.tid()
    node = nodes[i]
    problem = node_problem[i]
    k = stiffness[problem]
    x = points[node] + displacement[node]
    hit = rigid_contact_point(bodies[problem], x)
    node_gap[i] = hit.gap
    if hit.gap >= wp.float64(0.0):
        node_force[i] = wp.vec3d()
        return
    force = -k * hit.gap * hit.normal
    node_force[i] = force
    wp.atomic_sub(residual, node, force)
    wp.atomic_add(contact_force, problem, force)
    wp.atomic_add(energy, problem, wp.float64(0.5) * k * hit.gap * hit.gap)
    if with_tangent != 0:
        block = k * (wp.outer(hit.normal, hit.normal) + hit.gap * hit.normal_gradient)
        wp.atomic_add(matrix_values, diagonal_blocks[i], block)
