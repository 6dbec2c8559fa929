"""Tetrahedral finite-element kernels: element residual and tangent, Dirichlet elimination,
stress recovery (float64).

Elements are TET4 (one quadrature point) or TET10 (four points), with reference shape-function
gradients precomputed per quadrature point on the host. Three formulations share one element
kernel, selected by ``formulation``:

- displacement (``FORMULATION_DISPLACEMENT``): ``Pi_e = int psi_dev(F) + U(J) dV``.
- mean dilatation (``FORMULATION_MEAN_DILATATION``, TET10/P0):
  ``Pi_e = int psi_dev(F) dV + V_e U(Jbar)`` with ``Jbar = (1/V_e) int J dV``. With
  ``g_a = (1/V_e) int J F^-T grad N_a dV`` (so that ``dJbar = sum_a g_a . du_a``) the residual
  is ``int P_dev grad N_a dV + V_e U'(Jbar) g_a`` and the exact tangent is
  ``int grad N_a . (A_dev + U'(Jbar) d2J/dF2) . grad N_b dV + V_e U''(Jbar) g_a (x) g_b``.
  The pressure ``U'(Jbar)`` is constant per element, i.e. the P2/P0 pair. In 3D its discrete
  inf-sup constant is not uniform on these meshes (it falls about like h;
  ``scripts/infsup_p2p0.py``), although the punch forces show no locking.
- nodally averaged dilatation (``FORMULATION_NODAL``, TET4): ``Pi = sum_e V_e psi_dev(F_e)
  + sum_n V_n U(Jbar_n)``, with nodal volumes ``V_n = sum_{e ∋ n} V_e / 4`` and
  ``v_n = sum_{e ∋ n} J_e V_e / 4`` and ``Jbar_n = v_n / V_n``. With the nodal pressure
  ``p_n = U'(Jbar_n)`` the residual is the TET4 one with the element pressure
  ``pbar_e = (1/4) sum_{n ∈ e} p_n``, and the tangent is the TET4 one with that pressure
  plus, per node, ``(U''(Jbar_n) / V_n) w_na (x) w_nb`` over the pairs (a, b) of the node's
  one-ring, where ``w_na = d v_n / d u_a = sum_{e ∋ n, a} (1/4) J_e V_e F_e^-T grad N_a``.
  That last term couples nodes two rings apart.
"""

import warp as wp
from warptissue.kernels.materials import (
    MaterialParams,
    add_pressure_terms,
    deviatoric_response,
    flat,
    mat99d,
    volumetric_energy,
)

wp.set_module_options({"enable_backward": False})

FORMULATION_DISPLACEMENT = wp.constant(0)
FORMULATION_MEAN_DILATATION = wp.constant(1)
FORMULATION_NODAL = wp.constant(2)

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
    formulation: int,
    element_pressure: wp.float64,
    with_tangent: int,
):
    """Energy density, P and A at one quadrature point of any formulation (Pa).

    Displacement formulation: the full pointwise response, U(J) included, with ``j = det F``.
    The others: ``psi_dev`` only, and P and A carry the element's constant pressure
    ``element_pressure`` (``U'(Jbar)``, or the mean of the corners' nodal pressures; the
    volumetric stiffness is added by the caller). The material code is called once, not per branch, so
    that it is inlined once into each kernel.
    """
    psi, p, a_mat = deviatoric_response(params, f, with_tangent)
    pressure = element_pressure
    stiffness = wp.float64(0.0)
    if formulation == FORMULATION_DISPLACEMENT:
        u, du, ddu = volumetric_energy(params, j)
        psi += u
        pressure = du
        stiffness = ddu
    p, a_mat = add_pressure_terms(p, a_mat, f, pressure, stiffness, with_tangent)
    return psi, p, a_mat


@wp.func
def corner_mean(values: wp.array(dtype=wp.float64), tets: wp.array2d(dtype=wp.int32), e: int):
    """Mean of a nodal value over the four corners of tet e."""
    total = wp.float64(0.0)
    for a in range(4):
        total += values[tets[e, a]]
    return wp.float64(0.25) * total


@wp.kernel
def assemble_elements_kernel(
    params: MaterialParams,
    tets: wp.array2d(dtype=wp.int32),
    shape_gradients: wp.array3d(dtype=wp.vec3d),
    quadrature_volumes: wp.array2d(dtype=wp.float64),
    displacement: wp.array(dtype=wp.vec3d),
    block_index: wp.array2d(dtype=wp.int32),
    formulation: int,
    nodal_pressure: wp.array(dtype=wp.float64),
    ring_slot: wp.array2d(dtype=wp.int32),
    with_tangent: int,
    residual: wp.array(dtype=wp.vec3d),
    matrix_values: wp.array(dtype=wp.mat33d),
    energy: wp.array(dtype=wp.float64),
    min_jacobian: wp.array(dtype=wp.float64),
    volume_gradients: wp.array(dtype=wp.vec3d),
):
    """Add element internal forces to ``residual`` and tangent blocks to ``matrix_values``.

    ``block_index[e, a * nodes_per_tet + b]`` is the BSR block of node pair (a, b) of tet e.
    ``energy[0]`` accumulates the stored energy (J) and ``min_jacobian[0]`` the smallest J.
    Nodal formulation only: ``nodal_pressure`` (N,) holds p_n (Pa), and with the tangent
    ``volume_gradients[ring_slot[e, 4 a + b]]`` accumulates the share ``J_e V_e F_e^-T grad N_b
    / 4`` of ``w_nb`` (m^2) for corner n = a of tet e (empty arrays otherwise).
    """
    e = wp.tid()
    npe = tets.shape[1]
    nq = quadrature_volumes.shape[1]

    # Pass 1: J, the element volume and g_a = int J F^-T grad N_a dV (not for displacement).
    volume = wp.float64(0.0)
    deformed_volume = wp.float64(0.0)
    g = mat10x3d()
    for q in range(nq):
        f = deformation_gradient(e, q, tets, shape_gradients, displacement)
        j = wp.determinant(f)
        wp.atomic_min(min_jacobian, 0, j)
        dv = quadrature_volumes[e, q]
        volume += dv
        deformed_volume += j * dv
        if formulation != FORMULATION_DISPLACEMENT and j > wp.float64(0.0):
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
    if formulation == FORMULATION_MEAN_DILATATION:
        element_energy = volume * u_bar
    if formulation == FORMULATION_NODAL:
        p_bar = corner_mean(nodal_pressure, tets, e)

    # Pass 2: quadrature of the deviatoric part (and U(J) for the displacement formulation).
    for q in range(nq):
        f = deformation_gradient(e, q, tets, shape_gradients, displacement)
        j = wp.determinant(f)
        if j <= wp.float64(0.0):
            continue
        dv = quadrature_volumes[e, q]
        psi, p, a_mat = quadrature_point_response(params, f, j, formulation, p_bar, with_tangent)
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

    if formulation == FORMULATION_MEAN_DILATATION and with_tangent != 0:
        # g holds V_e g_a = int J F^-T grad N_a dV; the pressure U'(Jbar) J F^-T already went
        # into P above, this adds the rank-one part V_e U''(Jbar) g_a (x) g_b.
        for a in range(npe):
            ga = wp.vec3d(g[a, 0], g[a, 1], g[a, 2])
            for b in range(npe):
                gb = wp.vec3d(g[b, 0], g[b, 1], g[b, 2])
                wp.atomic_add(
                    matrix_values, block_index[e, a * npe + b], (k_bar / volume) * wp.outer(ga, gb)
                )
    if formulation == FORMULATION_NODAL and with_tangent != 0:
        for a in range(4):
            for b in range(4):
                gb = wp.vec3d(g[b, 0], g[b, 1], g[b, 2])
                wp.atomic_add(volume_gradients, ring_slot[e, 4 * a + b], wp.float64(0.25) * gb)
    wp.atomic_add(energy, 0, element_energy)


@wp.kernel
def nodal_deformed_volume_kernel(
    tets: wp.array2d(dtype=wp.int32),
    shape_gradients: wp.array3d(dtype=wp.vec3d),
    quadrature_volumes: wp.array2d(dtype=wp.float64),
    displacement: wp.array(dtype=wp.vec3d),
    nodal_volume: wp.array(dtype=wp.float64),
):
    """TET4: add a quarter of each tet's deformed volume J_e V_e to each of its corners (m^3)."""
    e = wp.tid()
    f = deformation_gradient(e, 0, tets, shape_gradients, displacement)
    share = wp.float64(0.25) * wp.determinant(f) * quadrature_volumes[e, 0]
    for a in range(4):
        wp.atomic_add(nodal_volume, tets[e, a], share)


@wp.kernel
def nodal_pressure_kernel(
    params: MaterialParams,
    reference_volume: wp.array(dtype=wp.float64),
    deformed_volume: wp.array(dtype=wp.float64),
    nodal_pressure: wp.array(dtype=wp.float64),
    nodal_stiffness: wp.array(dtype=wp.float64),
    energy: wp.array(dtype=wp.float64),
    min_jacobian: wp.array(dtype=wp.float64),
):
    """Per node: Jbar_n = v_n / V_n, p_n = U'(Jbar_n) (Pa), U''(Jbar_n) / V_n (Pa/m^3), and
    V_n U(Jbar_n) into ``energy[0]`` (J); Jbar_n into ``min_jacobian[0]``. A node of no tet
    (V_n = 0) carries nothing."""
    n = wp.tid()
    volume = reference_volume[n]
    nodal_pressure[n] = wp.float64(0.0)
    nodal_stiffness[n] = wp.float64(0.0)
    if volume <= wp.float64(0.0):
        return
    j_bar = deformed_volume[n] / volume
    wp.atomic_min(min_jacobian, 0, j_bar)
    if j_bar <= wp.float64(0.0):
        return
    u, du, ddu = volumetric_energy(params, j_bar)
    nodal_pressure[n] = du
    nodal_stiffness[n] = ddu / volume
    wp.atomic_add(energy, 0, volume * u)


@wp.func
def bsr_block(
    offsets: wp.array(dtype=wp.int32), columns: wp.array(dtype=wp.int32), row: int, col: int
):
    """Index of block (row, col) of a BSR pattern with sorted columns (binary search; the
    block must exist)."""
    low = offsets[row]
    high = offsets[row + 1] - 1
    while low < high:
        middle = (low + high) // 2
        if columns[middle] < col:
            low = middle + 1
        else:
            high = middle
    return low


@wp.kernel
def nodal_dilatation_tangent_kernel(
    ring_offsets: wp.array(dtype=wp.int32),
    ring_columns: wp.array(dtype=wp.int32),
    ring_rows: wp.array(dtype=wp.int32),
    volume_gradients: wp.array(dtype=wp.vec3d),
    nodal_stiffness: wp.array(dtype=wp.float64),
    matrix_offsets: wp.array(dtype=wp.int32),
    matrix_columns: wp.array(dtype=wp.int32),
    matrix_values: wp.array(dtype=wp.mat33d),
):
    """One thread per one-ring slot s = (n, a): add ``(U''_n / V_n) w_na (x) w_nb`` to block
    (a, b) for every b of node n's ring (the two-ring pattern holds it)."""
    s = wp.tid()
    n = ring_rows[s]
    a = ring_columns[s]
    w_a = nodal_stiffness[n] * volume_gradients[s]
    for t in range(ring_offsets[n], ring_offsets[n + 1]):
        block = bsr_block(matrix_offsets, matrix_columns, a, ring_columns[t])
        wp.atomic_add(matrix_values, block, wp.outer(w_a, volume_gradients[t]))


@wp.kernel
def eliminate_dirichlet_kernel(
    offsets: wp.array(dtype=wp.int32),
    columns: wp.array(dtype=wp.int32),
    constrained: wp.array(dtype=wp.vec3d),
    damping: wp.float64,
    matrix_values: wp.array(dtype=wp.mat33d),
):
    """Zero the rows and columns of constrained dofs and put 1 on their diagonal; add
    ``damping |K_ii|`` to the diagonal of the free dofs (Levenberg-Marquardt, 0 for none).

    ``constrained[n][i]`` is 1 where component i of node n is prescribed, else 0.
    """
    row = wp.tid()
    row_mask = constrained[row]
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
    params: MaterialParams,
    tets: wp.array2d(dtype=wp.int32),
    shape_gradients: wp.array3d(dtype=wp.vec3d),
    quadrature_volumes: wp.array2d(dtype=wp.float64),
    displacement: wp.array(dtype=wp.vec3d),
    formulation: int,
    nodal_pressure: wp.array(dtype=wp.float64),
    stress: wp.array2d(dtype=wp.float64),
):
    """Volume-averaged Cauchy stress per tet, Voigt order xx, yy, zz, yz, xz, xy (Pa).

    sigma = P F^T / J at each quadrature point; in the mean-dilatation formulation the
    pressure part is U'(Jbar) I, in the nodal one the mean of the corners' p_n, constant over
    the element (``nodal_pressure`` (N,), Pa: nodal formulation only).
    """
    e = wp.tid()
    nq = quadrature_volumes.shape[1]
    volume = wp.float64(0.0)
    deformed_volume = wp.float64(0.0)
    for q in range(nq):
        f = deformation_gradient(e, q, tets, shape_gradients, displacement)
        dv = quadrature_volumes[e, q]
        volume += dv
        deformed_volume += wp.determinant(f) * dv
    u_bar, p_bar, k_bar = volumetric_energy(params, deformed_volume / volume)
    if formulation == FORMULATION_NODAL:
        p_bar = corner_mean(nodal_pressure, tets, e)
    sigma = wp.mat33d()
    for q in range(nq):
        f = deformation_gradient(e, q, tets, shape_gradients, displacement)
        j = wp.determinant(f)
        dv = quadrature_volumes[e, q]
        psi, p, a_mat = quadrature_point_response(params, f, j, formulation, p_bar, 0)
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
    psi, p, a = quadrature_point_response(
        params, f, wp.determinant(f), FORMULATION_DISPLACEMENT, wp.float64(0.0), 1
    )
    energy[i] = psi
    stress[i] = p
    tangent[i] = a
