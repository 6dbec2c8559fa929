"""Hyperelastic constitutive models as Warp device functions (float64).

Every model returns the strain energy density ``psi`` (Pa), the first Piola-Kirchhoff stress
``P = dpsi/dF`` (Pa) and the consistent tangent ``A = dP/dF`` as a 9x9 matrix with
``A[3 i + J, 3 k + L] = dP_iJ / dF_kL`` (row-major flattening of the 3x3 tensors).

The energy is split as ``psi(F) = psi_dev(F) + U(J)``. ``deviatoric_response`` gives the first
part and ``volumetric_energy`` gives ``U`` and its first two derivatives, so that the mixed
(mean-dilatation) element can evaluate ``U`` at the element's mean dilatation instead of the
pointwise ``J``. ``quadrature_point_response`` in ``assembly.py`` combines them for either
formulation.

One ``MaterialParams`` struct with a ``model`` id is the single dispatch point, so that one
compiled kernel serves every model. This file holds functions only; the kernels that call them
live in ``assembly.py`` (including the pointwise ``evaluate_material_kernel``) and
``viscous.py``. Warp compiles a function into each module whose kernels call it, so the
constitutive code is compiled once per module that uses it
(docs/design-notes/kernel-modules.md).

Notes:
    Abaqus conventions (Abaqus Theory Manual 4.6.1; the needle-indentation study, Eq. 2):
    isochoric invariants ``I1b = J^(-2/3) I1``, ``I2b = J^(-4/3) I2``;
    ``U(J) = (J - 1)^2 / D1`` with ``D1 = 2 / K``.

    - Invariant models: ``psi_dev = sum_i C_i0 (I1b - 3)^i + C01 (I2b - 3)`` (neo-Hookean,
      Mooney-Rivlin, reduced polynomial and Yeoh are special cases).
    - Ogden: ``psi_dev = sum_i 2 mu_i / alpha_i^2 (l1b^a_i + l2b^a_i + l3b^a_i - 3)`` with the
      isochoric principal stretches ``lb = J^(-1/3) l``.
    - Compressible neo-Hookean: ``psi = mu/2 (I1 - 3) - mu ln J + lambda/2 (ln J)^2``; here
      ``psi_dev = mu/2 (I1 - 3)`` and ``U = -mu ln J + lambda/2 (ln J)^2``.
    - Linear elastic (small strain, not frame invariant): ``psi = mu eps:eps + lambda/2
      tr(eps)^2`` with ``eps = sym(F) - I``; ``U = 0``.
    - Stable neo-Hookean (Smith, de Goes and Kim 2018, with the Lame-matched parameters of
      NVIDIA Newton's VBD tets): ``psi = mu/2 (I1 - 3) + lambda_nh/2 (J - alpha)^2`` with
      ``lambda_nh = lambda + mu`` and ``alpha = 1 + mu / lambda_nh``; here
      ``psi_dev = mu/2 (I1 - 3)`` and, up to a constant,
      ``U = lambda_nh/2 (J - 1)^2 - mu (J - 1)``, so that ``U' = lambda_nh (J - alpha)``.

    Invariant models are evaluated through ``psi(I1, I2, I3)`` of ``C = F^T F`` with
    ``S = 2 dpsi/dC``; Ogden through the eigenvalues ``c_a`` of ``C`` with the spectral
    tangent (Simo and Taylor 1991; Holzapfel 2000, Sec. 6.10), using the limit
    ``(g_a - g_b)/(c_a - c_b) -> g_aa - g_ab`` when two eigenvalues coincide. Then
    ``P = F S`` and ``dP = dF S + F dS[dF^T F + F^T dF]`` column by column.
"""

import warp as wp

wp.set_module_options({"enable_backward": False})

vec6d = wp.types.vector(length=6, dtype=wp.float64)
mat99d = wp.types.matrix(shape=(9, 9), dtype=wp.float64)

MODEL_INVARIANT = wp.constant(0)
MODEL_OGDEN = wp.constant(1)
MODEL_COMPRESSIBLE_NEO_HOOKEAN = wp.constant(2)
MODEL_LINEAR_ELASTIC = wp.constant(3)
MODEL_STABLE_NEO_HOOKEAN = wp.constant(4)

EQUAL_EIGENVALUE_TOLERANCE = wp.constant(wp.float64(1.0e-8))


@wp.struct
class MaterialParams:
    """Parameters of one material, all in SI units (Pa or dimensionless).

    Attributes:
        model: Which energy: MODEL_INVARIANT, MODEL_OGDEN, MODEL_COMPRESSIBLE_NEO_HOOKEAN,
            MODEL_LINEAR_ELASTIC or MODEL_STABLE_NEO_HOOKEAN.
        polynomial_terms: Number N of used ``C_i0`` (invariant models).
        c_i0: ``C10, C20, ..., C60`` (Pa); entries past ``polynomial_terms`` are zero.
        c01: ``C01`` (Pa), Mooney-Rivlin.
        ogden_terms: Number N of Ogden terms.
        ogden_mu: ``mu_1..mu_N`` (Pa).
        ogden_alpha: ``alpha_1..alpha_N`` (dimensionless).
        bulk_modulus: ``K = 2 / D1`` (Pa).
        shear_modulus: ``mu`` (Pa), compressible and stable neo-Hookean, linear elastic.
        lame_lambda: Lame's first parameter (Pa), compressible and stable neo-Hookean, linear
            elastic.
    """

    model: wp.int32
    polynomial_terms: wp.int32
    c_i0: vec6d
    c01: wp.float64
    ogden_terms: wp.int32
    ogden_mu: vec6d
    ogden_alpha: vec6d
    bulk_modulus: wp.float64
    shear_modulus: wp.float64
    lame_lambda: wp.float64


@wp.func
def flat(i: int, j: int) -> int:
    """Row-major index of tensor component (i, j) in a 9-vector."""
    return 3 * i + j


@wp.func
def symmetric_eigen(a: wp.mat33d):
    """Eigenvalues and eigenvectors of a symmetric 3x3 matrix by cyclic Jacobi rotations.

    Returns:
        (d, V): eigenvalues as a vec3d, eigenvectors as the columns of V (a = V diag(d) V^T).
    """
    v = wp.identity(n=3, dtype=wp.float64)
    scale = wp.float64(0.0)
    for i in range(3):
        for j in range(3):
            scale = wp.max(scale, wp.abs(a[i, j]))
    for _sweep in range(12):
        off = wp.abs(a[0, 1]) + wp.abs(a[0, 2]) + wp.abs(a[1, 2])
        if off <= wp.float64(1.0e-300) + wp.float64(1.0e-17) * scale:
            break
        for pair in range(3):
            p = 0
            q = 1
            if pair == 1:
                q = 2
            if pair == 2:
                p = 1
                q = 2
            apq = a[p, q]
            if wp.abs(apq) > wp.float64(1.0e-300):
                theta = (a[q, q] - a[p, p]) / (wp.float64(2.0) * apq)
                t = wp.float64(1.0) / (wp.abs(theta) + wp.sqrt(theta * theta + wp.float64(1.0)))
                if theta < wp.float64(0.0):
                    t = -t
                c = wp.float64(1.0) / wp.sqrt(t * t + wp.float64(1.0))
                s = t * c
                r = wp.identity(n=3, dtype=wp.float64)
                r[p, p] = c
                r[q, q] = c
                r[p, q] = s
                r[q, p] = -s
                a = wp.transpose(r) @ a @ r
                v = v @ r
    return wp.vec3d(a[0, 0], a[1, 1], a[2, 2]), v


@wp.func
def unit_direction(k: int, l: int) -> wp.mat33d:
    """The basis tensor e_k (x) e_l."""
    d = wp.mat33d()
    d[k, l] = wp.float64(1.0)
    return d


@wp.func
def right_cauchy_green_variation(f: wp.mat33d, k: int, l: int) -> wp.mat33d:
    """dC = dF^T F + F^T dF of C = F^T F in the direction dF = e_k (x) e_l."""
    df = unit_direction(k, l)
    return wp.transpose(df) @ f + wp.transpose(f) @ df


@wp.func
def piola_variation(f: wp.mat33d, s: wp.mat33d, ds: wp.mat33d, k: int, l: int) -> wp.mat33d:
    """dP = dF S + F dS of P = F S in the direction dF = e_k (x) e_l: column (k, l) of A.

    ``ds`` is the model's variation of S along ``dC = right_cauchy_green_variation(f, k, l)``.
    """
    return unit_direction(k, l) @ s + f @ ds


@wp.func
def invariant_energy_derivatives(params: MaterialParams, i1b: wp.float64, i2b: wp.float64):
    """W(I1b, I2b) = sum C_i0 (I1b - 3)^i + C01 (I2b - 3) and its derivatives.

    Returns:
        (W, W1, W2, W11): W12 = W22 = 0 for this family.
    """
    x = i1b - wp.float64(3.0)
    w = params.c01 * (i2b - wp.float64(3.0))
    w1 = wp.float64(0.0)
    w11 = wp.float64(0.0)
    power = wp.float64(1.0)  # x^(i-1) for term i
    power_2 = wp.float64(0.0)  # x^(i-2) for term i
    for i in range(params.polynomial_terms):
        order = wp.float64(i + 1)
        c = params.c_i0[i]
        w += c * power * x
        w1 += order * c * power
        w11 += order * (order - wp.float64(1.0)) * c * power_2
        power_2 = power
        power = power * x
    return w, w1, params.c01, w11


@wp.func
def invariant_model(params: MaterialParams, f: wp.mat33d, with_tangent: int):
    """Deviatoric part of invariant-based models and the compressible and stable
    neo-Hookean."""
    c = wp.transpose(f) @ f
    eye = wp.identity(n=3, dtype=wp.float64)
    i1 = wp.trace(c)
    i2 = wp.float64(0.5) * (i1 * i1 - wp.trace(c @ c))
    i3 = wp.determinant(c)
    c_inv = wp.inverse(c)
    # psi(I1, I2, I3): first derivatives d[0..2] and Hessian h (3x3).
    d = wp.vec3d()
    h = wp.mat33d()
    psi = wp.float64(0.0)
    if params.model == MODEL_COMPRESSIBLE_NEO_HOOKEAN or params.model == MODEL_STABLE_NEO_HOOKEAN:
        psi = wp.float64(0.5) * params.shear_modulus * (i1 - wp.float64(3.0))
        d[0] = wp.float64(0.5) * params.shear_modulus
    else:
        a = wp.pow(i3, wp.float64(-1.0) / wp.float64(3.0))
        i1b = a * i1
        i2b = a * a * i2
        w, w1, w2, w11 = invariant_energy_derivatives(params, i1b, i2b)
        psi = w
        # dI1b/dI and dI2b/dI
        g1 = wp.vec3d(a, wp.float64(0.0), -i1 * a / (wp.float64(3.0) * i3))
        g2 = wp.vec3d(
            wp.float64(0.0), a * a, -wp.float64(2.0) * i2 * a * a / (wp.float64(3.0) * i3)
        )
        d = w1 * g1 + w2 * g2
        h = w11 * wp.outer(g1, g1)
        # second derivatives of I1b and I2b with respect to (I1, I2, I3)
        h13 = -a / (wp.float64(3.0) * i3)
        h33 = wp.float64(4.0) * i1 * a / (wp.float64(9.0) * i3 * i3)
        k23 = -wp.float64(2.0) * a * a / (wp.float64(3.0) * i3)
        k33 = wp.float64(10.0) * i2 * a * a / (wp.float64(9.0) * i3 * i3)
        h[0, 2] = h[0, 2] + w1 * h13
        h[2, 0] = h[2, 0] + w1 * h13
        h[1, 2] = h[1, 2] + w2 * k23
        h[2, 1] = h[2, 1] + w2 * k23
        h[2, 2] = h[2, 2] + w1 * h33 + w2 * k33
    dI2 = i1 * eye - c
    dI3 = i3 * c_inv
    s = wp.float64(2.0) * (d[0] * eye + d[1] * dI2 + d[2] * dI3)
    p = f @ s
    tangent = mat99d()
    if with_tangent != 0:
        for k in range(3):
            for l in range(3):
                dc = right_cauchy_green_variation(f, k, l)
                di = wp.vec3d(wp.trace(dc), wp.ddot(dI2, dc), wp.ddot(dI3, dc))
                hdi = h @ di
                ds = wp.float64(2.0) * (
                    hdi[0] * eye
                    + hdi[1] * dI2
                    + hdi[2] * dI3
                    + d[1] * (di[0] * eye - dc)
                    + d[2] * (di[2] * c_inv - i3 * (c_inv @ dc @ c_inv))
                )
                dp = piola_variation(f, s, ds, k, l)
                for i in range(3):
                    for j in range(3):
                        tangent[flat(i, j), flat(k, l)] = dp[i, j]
    return psi, p, tangent


@wp.func
def ogden_model(params: MaterialParams, f: wp.mat33d, with_tangent: int):
    """Deviatoric Ogden energy through the eigenvalues of C (spectral form)."""
    c = wp.transpose(f) @ f
    eig, vecs = symmetric_eigen(c)
    e = wp.vec3d(wp.log(eig[0]), wp.log(eig[1]), wp.log(eig[2]))
    e_mean = (e[0] + e[1] + e[2]) / wp.float64(3.0)
    psi = wp.float64(0.0)
    h1 = wp.vec3d()  # d psi / d e_a
    h2 = wp.mat33d()  # d2 psi / d e_a d e_b
    third = wp.float64(1.0) / wp.float64(3.0)
    for i in range(params.ogden_terms):
        alpha = params.ogden_alpha[i]
        coef = wp.float64(2.0) * params.ogden_mu[i] / (alpha * alpha)
        half = wp.float64(0.5) * alpha
        t = wp.vec3d(
            wp.exp(half * (e[0] - e_mean)),
            wp.exp(half * (e[1] - e_mean)),
            wp.exp(half * (e[2] - e_mean)),
        )
        total = t[0] + t[1] + t[2]
        psi += coef * (total - wp.float64(3.0))
        for a in range(3):
            h1[a] = h1[a] + coef * half * (t[a] - third * total)
            for b in range(3):
                delta = wp.float64(0.0)
                if a == b:
                    delta = t[a]
                h2[a, b] = h2[a, b] + coef * half * half * (
                    delta - third * (t[a] + t[b]) + total / wp.float64(9.0)
                )
    # derivatives with respect to the eigenvalues c_a of C
    g = wp.vec3d()
    gg = wp.mat33d()
    for a in range(3):
        g[a] = h1[a] / eig[a]
        for b in range(3):
            gg[a, b] = h2[a, b] / (eig[a] * eig[b])
        gg[a, a] = gg[a, a] - h1[a] / (eig[a] * eig[a])
    s = wp.mat33d()
    for a in range(3):
        n = wp.vec3d(vecs[0, a], vecs[1, a], vecs[2, a])
        s += wp.float64(2.0) * g[a] * wp.outer(n, n)
    p = f @ s
    tangent = mat99d()
    if with_tangent != 0:
        theta = wp.mat33d()
        scale = wp.max(eig[0], wp.max(eig[1], eig[2]))
        for a in range(3):
            for b in range(3):
                if a != b:
                    gap = eig[a] - eig[b]
                    if wp.abs(gap) > EQUAL_EIGENVALUE_TOLERANCE * scale:
                        theta[a, b] = (g[a] - g[b]) / gap
                    else:
                        theta[a, b] = gg[a, a] - gg[a, b]
        for k in range(3):
            for l in range(3):
                dc = right_cauchy_green_variation(f, k, l)
                ds = wp.mat33d()
                for a in range(3):
                    na = wp.vec3d(vecs[0, a], vecs[1, a], vecs[2, a])
                    for b in range(3):
                        nb = wp.vec3d(vecs[0, b], vecs[1, b], vecs[2, b])
                        dcb = wp.dot(nb, dc @ nb)
                        ds += wp.float64(2.0) * gg[a, b] * dcb * wp.outer(na, na)
                        if b > a:
                            dab = wp.dot(na, dc @ nb)
                            ds += (
                                wp.float64(2.0)
                                * theta[a, b]
                                * dab
                                * (wp.outer(na, nb) + wp.outer(nb, na))
                            )
                dp = piola_variation(f, s, ds, k, l)
                for i in range(3):
                    for j in range(3):
                        tangent[flat(i, j), flat(k, l)] = dp[i, j]
    return psi, p, tangent


@wp.func
def ogden_alpha_stress_derivative(params: MaterialParams, f: wp.mat33d, term: int) -> wp.mat33d:
    """``dP/d alpha_term`` of the deviatoric Ogden stress at fixed F (Pa per unit alpha).

    With ``t_a = exp(alpha/2 (e_a - e_mean))`` (``e_a = ln c_a``), ``h1_a = dpsi/de_a =
    mu/alpha (t_a - sum_b t_b / 3)`` and ``S = sum_a 2 h1_a / c_a n_a (x) n_a``, so
    ``dS/dalpha = sum_a 2 (dh1_a/dalpha) / c_a n_a (x) n_a`` with ``dh1_a/dalpha =
    -mu/alpha^2 (t_a - T/3) + mu/alpha (t'_a - T'/3)``, ``t'_a = (e_a - e_mean)/2 t_a``.
    The volumetric part does not depend on alpha. Equal eigenvalues need no limit here: S is
    a sum over the eigenvectors with equal weights inside an eigenspace.
    """
    c = wp.transpose(f) @ f
    eig, vecs = symmetric_eigen(c)
    e = wp.vec3d(wp.log(eig[0]), wp.log(eig[1]), wp.log(eig[2]))
    e_mean = (e[0] + e[1] + e[2]) / wp.float64(3.0)
    alpha = params.ogden_alpha[term]
    mu = params.ogden_mu[term]
    half = wp.float64(0.5) * alpha
    t = wp.vec3d()
    dt = wp.vec3d()
    for a in range(3):
        t[a] = wp.exp(half * (e[a] - e_mean))
        dt[a] = wp.float64(0.5) * (e[a] - e_mean) * t[a]
    total = t[0] + t[1] + t[2]
    d_total = dt[0] + dt[1] + dt[2]
    third = wp.float64(1.0) / wp.float64(3.0)
    ds = wp.mat33d()
    for a in range(3):
        dh1 = -mu / (alpha * alpha) * (t[a] - third * total) + mu / alpha * (
            dt[a] - third * d_total
        )
        n = wp.vec3d(vecs[0, a], vecs[1, a], vecs[2, a])
        ds += wp.float64(2.0) * dh1 / eig[a] * wp.outer(n, n)
    return f @ ds


@wp.func
def linear_elastic_model(params: MaterialParams, f: wp.mat33d, with_tangent: int):
    """Small-strain isotropic linear elasticity (not frame invariant)."""
    eye = wp.identity(n=3, dtype=wp.float64)
    eps = wp.float64(0.5) * (f + wp.transpose(f)) - eye
    mu = params.shear_modulus
    lam = params.lame_lambda
    tr = wp.trace(eps)
    psi = mu * wp.ddot(eps, eps) + wp.float64(0.5) * lam * tr * tr
    p = lam * tr * eye + wp.float64(2.0) * mu * eps
    tangent = mat99d()
    if with_tangent != 0:
        for i in range(3):
            for j in range(3):
                for k in range(3):
                    for l in range(3):
                        value = wp.float64(0.0)
                        if i == j and k == l:
                            value += lam
                        if i == k and j == l:
                            value += mu
                        if i == l and j == k:
                            value += mu
                        tangent[flat(i, j), flat(k, l)] = value
    return psi, p, tangent


@wp.func
def deviatoric_response(params: MaterialParams, f: wp.mat33d, with_tangent: int):
    """psi_dev, its first Piola-Kirchhoff stress and tangent (tangent zero unless asked).

    Returns:
        (psi, P, A): Pa, Pa (mat33d), Pa (mat99d).
    """
    if params.model == MODEL_OGDEN:
        return ogden_model(params, f, with_tangent)
    if params.model == MODEL_LINEAR_ELASTIC:
        return linear_elastic_model(params, f, with_tangent)
    return invariant_model(params, f, with_tangent)


@wp.func
def volumetric_energy(params: MaterialParams, j: wp.float64):
    """U(J), U'(J) and U''(J) of the volumetric part (Pa).

    Abaqus models: U = K/2 (J - 1)^2 = (J - 1)^2 / D1. Compressible neo-Hookean:
    U = -mu ln J + lambda/2 (ln J)^2. Linear elastic: U = 0. Stable neo-Hookean:
    U = (lambda + mu)/2 (J - 1)^2 - mu (J - 1), linear in mu and lambda as the sensitivities
    need.
    """
    if params.model == MODEL_LINEAR_ELASTIC:
        return wp.float64(0.0), wp.float64(0.0), wp.float64(0.0)
    if params.model == MODEL_STABLE_NEO_HOOKEAN:
        lam_nh = params.lame_lambda + params.shear_modulus
        dj = j - wp.float64(1.0)
        return (
            wp.float64(0.5) * lam_nh * dj * dj - params.shear_modulus * dj,
            lam_nh * dj - params.shear_modulus,
            lam_nh,
        )
    if params.model == MODEL_COMPRESSIBLE_NEO_HOOKEAN:
        log_j = wp.log(j)
        mu = params.shear_modulus
        lam = params.lame_lambda
        u = -mu * log_j + wp.float64(0.5) * lam * log_j * log_j
        return u, (lam * log_j - mu) / j, (mu + lam - lam * log_j) / (j * j)
    k = params.bulk_modulus
    return (
        wp.float64(0.5) * k * (j - wp.float64(1.0)) * (j - wp.float64(1.0)),
        k * (j - wp.float64(1.0)),
        k,
    )


@wp.func
def add_pressure_terms(
    p: wp.mat33d,
    tangent: mat99d,
    f: wp.mat33d,
    pressure: wp.float64,
    stiffness: wp.float64,
    with_tangent: int,
):
    """Add ``pressure * dJ/dF`` to P and ``stiffness dJ/dF (x) dJ/dF + pressure d2J/dF2`` to A.

    ``dJ/dF = J F^-T`` and ``d2J/dF_iJ dF_kL = J (Finv_Ji Finv_Lk - Finv_Jk Finv_Li)``.
    """
    j = wp.determinant(f)
    f_inv = wp.inverse(f)
    p_out = p + pressure * j * wp.transpose(f_inv)
    a_out = tangent
    if with_tangent != 0:
        for i in range(3):
            for jj in range(3):
                for k in range(3):
                    for l in range(3):
                        a_out[flat(i, jj), flat(k, l)] = a_out[flat(i, jj), flat(k, l)] + (
                            stiffness * j * j * f_inv[jj, i] * f_inv[l, k]
                            + pressure
                            * j
                            * (f_inv[jj, i] * f_inv[l, k] - f_inv[jj, k] * f_inv[l, i])
                        )
    return p_out, a_out
