"""Tetrahedral finite-element kernels: element residual and tangent, Dirichlet elimination,
stress recovery (float64), launched by :mod:`warptissue.fem.assembly`.

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

The quadrature-point response (:func:`quadrature_point_response`, with a viscoelastic step's
``ViscousStep``) and :func:`deformation_gradient` live here and are imported by
``viscous.py``; ``evaluate_material_kernel`` (launched by :mod:`warptissue.materials`) is the
same response at single points. Each module of ``kernels/`` is one Warp module, compiled on
its first launch (docs/design-notes/kernel-modules.md).
"""

import warp as wp
from warptissue.kernels.materials import (
    MaterialParams,
    add_pressure_terms,
    deviatoric_response,
    flat,
    mat99d,
    ogden_alpha_stress_derivative,
    vec6d,
    volumetric_energy,
)

wp.set_module_options({"enable_backward": False})


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
    material_params: wp.array(dtype=MaterialParams),
    element_problem: wp.array(dtype=wp.int32),
    element_material: wp.array(dtype=wp.int32),
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
    Tet e belongs to problem ``k = element_problem[e]`` and has the material
    ``material_params[element_material[e]]``: one per problem (packed problems,
    :mod:`warptissue.fem.packing`), more where a problem's body has several material regions
    (:mod:`warptissue.fem.regions`); problem k's own, or its default region's, is entry k.
    ``block_index[e, a * nodes_per_tet + b]`` is the BSR block of node pair (a, b) of tet e.
    ``energy[k]`` accumulates problem k's stored energy (J) and ``min_jacobian[k]`` its
    smallest J. Problem k's time step is ``viscous[k]``: a viscoelastic one reads the frozen
    history stress ``frozen[e, q]`` (unused otherwise).
    """
    e = elements[wp.tid()]
    problem = element_problem[e]
    params = material_params[element_material[e]]
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
    material_params: wp.array(dtype=MaterialParams),
    element_problem: wp.array(dtype=wp.int32),
    element_material: wp.array(dtype=wp.int32),
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
    ``material_params[element_material[e]]`` (as in ``assemble_elements_kernel``).
    """
    e = wp.tid()
    params = material_params[element_material[e]]
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
