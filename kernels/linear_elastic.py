"""Linear tetrahedral elasticity in substitution parameters (Tong et al.).

Device code only. The isotropic elasticity matrix is written as D = alpha (G + nu H) with
alpha = E / ((1 + nu)(1 - 2 nu)) (Tong et al., Eq. 2). In Voigt order (xx, yy, zz, xy, yz, zx)
with engineering shear strains, G = diag(1, 1, 1, 1/2, 1/2, 1/2) and H has the normal block
1 1^T - 2 I and -1 on the shear diagonal; G is the Lame pair (lambda = 0, mu = 1/2) and H the
pair (lambda = 1, mu = -1). For shape-function gradients a, b of nodes p, q the 3x3 blocks of
V B^T G B and V B^T H B are therefore

    KG_pq[i, j] = V / 2 * ((a . b) delta_ij + a_j b_i)
    KH_pq[i, j] = V * (a_i b_j - a_j b_i - (a . b) delta_ij)

and the element stiffness is K^e = alpha (KG + nu KH) (the consistent form of Tong et al.'s Eq. 4;
the printed equation lacks alpha on the second term).
"""

import warp as wp


@wp.struct
class GroupParameters:
    """Per-group substitution parameters: alpha (Pa) and Poisson's ratio nu, shape (groups,)."""

    alpha_Pa: wp.array(dtype=wp.float64)
    nu: wp.array(dtype=wp.float64)


@wp.func
def tet_gradients(x0: wp.vec3d, x1: wp.vec3d, x2: wp.vec3d, x3: wp.vec3d) -> wp.mat33d:
    """Rows 0-2: gradients of the linear shape functions of corners 1-3 (1/m)."""
    dm = wp.matrix_from_cols(x1 - x0, x2 - x0, x3 - x0)
    return wp.inverse(dm)


@wp.func
def corner_gradient(inv_dm: wp.mat33d, corner: int) -> wp.vec3d:
    """Gradient of the shape function of ``corner`` (0-3), from the inverse edge matrix."""
    g1 = wp.vec3d(inv_dm[0, 0], inv_dm[0, 1], inv_dm[0, 2])
    g2 = wp.vec3d(inv_dm[1, 0], inv_dm[1, 1], inv_dm[1, 2])
    g3 = wp.vec3d(inv_dm[2, 0], inv_dm[2, 1], inv_dm[2, 2])
    if corner == 1:
        return g1
    if corner == 2:
        return g2
    if corner == 3:
        return g3
    return -(g1 + g2 + g3)


@wp.kernel
def element_basis_matrices(
    points: wp.array(dtype=wp.vec3d),
    tets: wp.array2d(dtype=wp.int32),
    stiffness_g: wp.array3d(dtype=wp.float64),
    stiffness_h: wp.array3d(dtype=wp.float64),
    volume_m3: wp.array(dtype=wp.float64),
):
    """Per tet: V B^T G B and V B^T H B (12 x 12, units m) and the volume V (m^3)."""
    e = wp.tid()
    x0 = points[tets[e, 0]]
    x1 = points[tets[e, 1]]
    x2 = points[tets[e, 2]]
    x3 = points[tets[e, 3]]
    volume = wp.dot(wp.cross(x1 - x0, x2 - x0), x3 - x0) / wp.float64(6.0)
    volume_m3[e] = volume
    inv_dm = tet_gradients(x0, x1, x2, x3)
    half = wp.float64(0.5)
    for p in range(4):
        a = corner_gradient(inv_dm, p)
        for q in range(4):
            b = corner_gradient(inv_dm, q)
            ab = wp.dot(a, b)
            for i in range(3):
                for j in range(3):
                    delta = wp.float64(0.0)
                    if i == j:
                        delta = wp.float64(1.0)
                    stiffness_g[e, 3 * p + i, 3 * q + j] = (
                        volume * half * (ab * delta + a[j] * b[i])
                    )
                    stiffness_h[e, 3 * p + i, 3 * q + j] = volume * (
                        a[i] * b[j] - a[j] * b[i] - ab * delta
                    )


@wp.kernel
def combine_element_stiffness(
    stiffness_g: wp.array3d(dtype=wp.float64),
    stiffness_h: wp.array3d(dtype=wp.float64),
    tet_group: wp.array(dtype=wp.int32),
    parameters: GroupParameters,
    stiffness: wp.array3d(dtype=wp.float64),
):
    """K^e = alpha_g (V B^T G B + nu_g V B^T H B) for every tet (N/m), one thread per entry."""
    e, r, c = wp.tid()
    g = tet_group[e]
    alpha = parameters.alpha_Pa[g]
    stiffness[e, r, c] = alpha * (stiffness_g[e, r, c] + parameters.nu[g] * stiffness_h[e, r, c])


@wp.kernel
def element_basis_forces(
    stiffness_g: wp.array3d(dtype=wp.float64),
    stiffness_h: wp.array3d(dtype=wp.float64),
    tets: wp.array2d(dtype=wp.int32),
    displacement_m: wp.array(dtype=wp.vec3d),
    force_g: wp.array2d(dtype=wp.float64),
    force_h: wp.array2d(dtype=wp.float64),
):
    """Per tet: (V B^T G B) u^e and (V B^T H B) u^e, shape (12,) each (N/Pa)."""
    e, r = wp.tid()
    sum_g = wp.float64(0.0)
    sum_h = wp.float64(0.0)
    for q in range(4):
        u = displacement_m[tets[e, q]]
        for j in range(3):
            sum_g += stiffness_g[e, r, 3 * q + j] * u[j]
            sum_h += stiffness_h[e, r, 3 * q + j] * u[j]
    force_g[e, r] = sum_g
    force_h[e, r] = sum_h
