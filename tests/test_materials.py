"""Materials: derivatives by finite differences, stress-free reference, small-strain limit,
frame invariance, serialization, fit parameters, and the homogeneous closed forms (against
numerical derivatives of the energy and the needle-indentation study's printed Eq. 3)."""

from __future__ import annotations

import numpy as np
import pytest

from warptissue.errors import InputError
from warptissue.materials import (
    HOMOGENEOUS_MODES,
    CompressibleNeoHookean,
    HyperelasticMaterial,
    LinearElastic,
    MooneyRivlin,
    NeoHookean,
    Ogden,
    ReducedPolynomial,
    StableNeoHookean,
    Yeoh,
    evaluate_material,
    material_from_dict,
    principal_stretches,
)

# Bulk moduli of about 10 shear moduli, so that the deviatoric parts are not masked by U(J).
MATERIALS = {
    "neo_hookean": NeoHookean(150.0, 3000.0),
    "mooney_rivlin": MooneyRivlin(-40.0, 160.0, 2500.0),
    "reduced_polynomial_2": ReducedPolynomial((600.553, 4097.45), 12000.0),
    "yeoh": Yeoh(300.0, -20.0, 15.0, 6000.0),
    "reduced_polynomial_6": ReducedPolynomial((300.0, 40.0, -5.0, 3.0, 1.0, 0.5), 6000.0),
    "ogden_1": Ogden((200.0,), (6.5,), 4000.0),
    "ogden_3": Ogden((250.0, -30.0, 5.0), (3.0, -2.0, 8.0), 4000.0),
    "compressible_neo_hookean": CompressibleNeoHookean(200.0, 1500.0),
    "linear_elastic": LinearElastic(600.0, 0.3),
    "stable_neo_hookean": StableNeoHookean(600.0, 0.45),
}
FINITE_STRAIN = [name for name in MATERIALS if name != "linear_elastic"]


def _deformation_gradients(rng: np.random.Generator) -> np.ndarray:
    """General F, plus states with two and three equal principal stretches."""
    general = np.eye(3) + 0.25 * rng.standard_normal((4, 3, 3))
    q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    q *= np.sign(np.linalg.det(q))
    uniaxial = q @ np.diag([0.7, 1.0 / np.sqrt(0.7), 1.0 / np.sqrt(0.7)]) @ q.T
    dilatation = 1.05 * q
    return np.concatenate([general, uniaxial[None], dilatation[None]])


def _finite_differences(material, f: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Central differences of energy (-> P) and of P (-> A) over the nine entries of F."""
    plus, minus = [], []
    for k in range(3):
        for col in range(3):
            e = np.zeros((3, 3))
            e[k, col] = step
            plus.append(f + e)
            minus.append(f - e)
    up = evaluate_material(material, np.array(plus), device="cpu")
    down = evaluate_material(material, np.array(minus), device="cpu")
    p_fd = ((up.energy_density_Pa - down.energy_density_Pa) / (2 * step)).reshape(3, 3)
    a_fd = ((up.first_piola_Pa - down.first_piola_Pa) / (2 * step)).reshape(9, 9).T
    return p_fd, a_fd


@pytest.mark.parametrize("name", list(MATERIALS))
def test_stress_and_tangent_match_finite_differences(name, rng):
    material = MATERIALS[name]
    fs = _deformation_gradients(rng)
    exact = evaluate_material(material, fs, device="cpu")
    for i, f in enumerate(fs):
        p_fd, a_fd = _finite_differences(material, f, step=1e-6)
        p, a = exact.first_piola_Pa[i], exact.tangent_Pa[i]
        assert np.abs(p - p_fd).max() <= 1e-6 * np.abs(p).max(), (name, i)
        assert np.abs(a - a_fd).max() <= 1e-6 * np.abs(a).max(), (name, i)
        assert np.abs(a - a.T).max() <= 1e-10 * np.abs(a).max()  # hyperelastic: symmetric


@pytest.mark.parametrize("name", list(MATERIALS))
def test_reference_state_is_stress_free_with_the_small_strain_tangent(name):
    """At F = I: P = 0, psi = 0, and A is the isotropic elasticity tensor of (mu0, K)."""
    material = MATERIALS[name]
    result = evaluate_material(material, np.eye(3), device="cpu")
    mu = material.initial_shear_modulus_Pa
    lam = material.bulk_modulus - 2.0 * mu / 3.0
    d = np.eye(3)
    expected = (
        lam * np.einsum("ij,kl->ijkl", d, d)
        + mu * np.einsum("ik,jl->ijkl", d, d)
        + mu * np.einsum("il,jk->ijkl", d, d)
    ).reshape(9, 9)
    assert abs(result.energy_density_Pa[0]) < 1e-12 * mu
    assert np.abs(result.first_piola_Pa[0]).max() < 1e-12 * mu
    np.testing.assert_allclose(result.tangent_Pa[0], expected, rtol=0, atol=1e-9 * lam)


@pytest.mark.parametrize("name", FINITE_STRAIN)
def test_frame_invariance(name, rng):
    material = MATERIALS[name]
    fs = _deformation_gradients(rng)
    q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    q *= np.sign(np.linalg.det(q))
    base = evaluate_material(material, fs, device="cpu")
    rotated = evaluate_material(material, q[None] @ fs, device="cpu")
    scale = np.abs(base.first_piola_Pa).max()
    np.testing.assert_allclose(rotated.energy_density_Pa, base.energy_density_Pa, rtol=1e-11)
    np.testing.assert_allclose(
        rotated.first_piola_Pa, q[None] @ base.first_piola_Pa, rtol=0, atol=1e-11 * scale
    )


def test_isochoric_energy_does_not_depend_on_volume():
    """Pure dilatation stores only U(J) = K/2 (J - 1)^2 in the Abaqus models."""
    j = 1.1
    f = np.cbrt(j) * np.eye(3)
    for name in ("neo_hookean", "mooney_rivlin", "reduced_polynomial_2", "ogden_3"):
        material = MATERIALS[name]
        energy = evaluate_material(material, f, device="cpu").energy_density_Pa[0]
        assert energy == pytest.approx(0.5 * material.bulk_modulus_Pa * (j - 1.0) ** 2, rel=1e-12)


def test_ogden_with_alpha_two_is_neo_hookean(rng):
    """Ogden N=1, alpha=2 is neo-Hookean with C10 = mu/2 (Abaqus convention)."""
    fs = _deformation_gradients(rng)
    ogden = evaluate_material(Ogden((300.0,), (2.0,), 5000.0), fs, device="cpu")
    neo = evaluate_material(NeoHookean(150.0, 5000.0), fs, device="cpu")
    np.testing.assert_allclose(ogden.energy_density_Pa, neo.energy_density_Pa, rtol=1e-11)
    np.testing.assert_allclose(ogden.tangent_Pa, neo.tangent_Pa, rtol=0, atol=1e-9 * 5000.0)


def test_cpu_and_device_agree(device, rng):
    fs = _deformation_gradients(rng)
    for material in MATERIALS.values():
        cpu = evaluate_material(material, fs, device="cpu")
        other = evaluate_material(material, fs, device=device)
        scale = np.abs(cpu.tangent_Pa).max()
        np.testing.assert_allclose(
            other.first_piola_Pa, cpu.first_piola_Pa, rtol=0, atol=1e-10 * scale
        )
        np.testing.assert_allclose(other.tangent_Pa, cpu.tangent_Pa, rtol=0, atol=1e-10 * scale)


@pytest.mark.parametrize("name", list(MATERIALS))
def test_dictionary_round_trip_and_parameter_vector(name):
    material = MATERIALS[name]
    data = material.to_dict()
    assert data["model"] == material.model_name
    assert material_from_dict(data) == material
    vector = material.parameter_vector
    assert len(vector) == len(material.parameter_names)
    assert material.with_parameters(vector) == material


def test_stable_neo_hookean_is_newtons_vbd_tet_energy(rng):
    """P = mu F + lambda_nh (J - alpha) cof F with Newton's Lame matching (Smith et al. 2018,
    Eq. 13 as NVIDIA Newton 1.8's VBD tets evaluate it), written out independently here."""
    e, nu = 1725.0, 0.42
    mu = e / (2 * (1 + nu))
    lam = e * nu / ((1 + nu) * (1 - 2 * nu))
    lam_nh = lam + mu
    alpha = 1 + mu / lam_nh
    f = np.eye(3) + 0.2 * rng.standard_normal((6, 3, 3))
    got = evaluate_material(StableNeoHookean(e, nu), f, device="cpu")
    for k in range(len(f)):
        cof = np.linalg.det(f[k]) * np.linalg.inv(f[k]).T
        expected = mu * f[k] + lam_nh * (np.linalg.det(f[k]) - alpha) * cof
        np.testing.assert_allclose(got.first_piola_Pa[k], expected, rtol=1e-12, atol=1e-9)


def test_small_strain_equivalent_and_d1():
    material = NeoHookean(100.0, 2.0e5)
    youngs, nu = material.small_strain_equivalent()
    assert material.D1_per_Pa == pytest.approx(1e-5)
    assert youngs == pytest.approx(9 * 2e5 * 200 / (3 * 2e5 + 200))
    assert nu == pytest.approx((3 * 2e5 - 400) / (2 * (3 * 2e5 + 200)))
    assert LinearElastic(600.0, 0.3).small_strain_equivalent() == (600.0, 0.3)


def test_from_dict_variants():
    yeoh = material_from_dict(
        {"model": "yeoh", "C10_Pa": 1.0, "C20_Pa": 2.0, "C30_Pa": 3.0, "D1_per_Pa": 0.01}
    )
    assert yeoh == ReducedPolynomial((1.0, 2.0, 3.0), 200.0)
    ogden = material_from_dict(
        {"model": "ogden", "mu_Pa": [1.0, 2.0], "alpha": [3.0, -1.0], "bulk_modulus_Pa": 10.0}
    )
    assert ogden == Ogden((1.0, 2.0), (3.0, -1.0), 10.0)


@pytest.mark.parametrize(
    ("data", "key"),
    [
        ({"model": "neo_hookean", "C10_Pa": 1.0}, "bulk_modulus_Pa"),
        ({"model": "neo_hookean", "C10_Pa": -1.0, "bulk_modulus_Pa": 1.0}, "C10_Pa"),
        ({"model": "neo_hookean", "C10_Pa": 1.0, "bulk_modulus_Pa": 1.0, "C01_Pa": 1}, "C01_Pa"),
        ({"model": "neo_hookean", "C10_Pa": "soft", "bulk_modulus_Pa": 1.0}, "C10_Pa"),
        ({"model": "rubber"}, "model"),
        (
            {"model": "linear_elastic", "youngs_modulus_Pa": 1.0, "poissons_ratio": 0.5},
            "poissons_ratio",
        ),
        ({"model": "ogden", "mu1_Pa": 1.0, "alpha1": 0.0, "bulk_modulus_Pa": 1.0}, "alpha1"),
        (
            {"model": "mooney_rivlin", "C10_Pa": -2.0, "C01_Pa": 1.0, "bulk_modulus_Pa": 1.0},
            "C01_Pa",
        ),
    ],
)
def test_bad_parameters_name_the_key(data, key):
    with pytest.raises(InputError) as error:
        material_from_dict(data)
    assert error.value.column == key


def test_ogden_term_counts_must_match():
    with pytest.raises(InputError, match="alpha"):
        Ogden((1.0, 2.0), (3.0,), 10.0)
    with pytest.raises(InputError):
        ReducedPolynomial(tuple(range(1, 8)), 10.0)


def test_evaluate_rejects_inverted_gradients():
    with pytest.raises(InputError, match="det F"):
        evaluate_material(NeoHookean(1.0, 10.0), -np.eye(3), device="cpu")


# Homogeneous closed forms (incompressible) of the hyperelastic models.
CLOSED_FORMS = {
    name: material.with_bulk_modulus(None)
    for name, material in MATERIALS.items()
    if isinstance(material, HyperelasticMaterial)
}
LOADED_DIRECTIONS = {"uniaxial": 1.0, "equibiaxial": 2.0, "planar": 1.0}
STRETCHES = np.array([0.45, 0.7, 0.93, 1.08, 1.4, 2.2])


def energy_along_path(model, stretch, mode):
    return model.energy_density_Pa(principal_stretches(np.atleast_1d(stretch), mode))


@pytest.mark.parametrize("mode", HOMOGENEOUS_MODES)
@pytest.mark.parametrize("name", sorted(CLOSED_FORMS))
def test_nominal_stress_is_the_derivative_of_the_energy(name, mode):
    model = CLOSED_FORMS[name]
    h = 1e-5 * STRETCHES
    numeric = (
        energy_along_path(model, STRETCHES + h, mode)
        - energy_along_path(model, STRETCHES - h, mode)
    ) / (2.0 * h * LOADED_DIRECTIONS[mode])
    analytic = model.nominal_stress_Pa(STRETCHES, mode)
    np.testing.assert_allclose(analytic, numeric, rtol=1e-6)


def test_uniaxial_stress_matches_the_printed_equation_3():
    lam = STRETCHES
    i1 = lam**2 + 2.0 / lam
    c10, c20, c01, mu, alpha = 600.553, 4097.45, -250.0, 800.0, -4.5
    printed = {
        "nh": 2.0 * c10 * (lam - lam**-2),
        "rp2": 2.0 * (lam - lam**-2) * (c10 + 2.0 * c20 * (i1 - 3.0)),
        "mr": 2.0 * (1.0 - lam**-3) * (c10 * lam + c01),
        "ogden": 2.0 * mu / alpha * (lam ** (alpha - 1.0) - lam ** (-0.5 * alpha - 1.0)),
    }
    ours = {
        "nh": NeoHookean(c10),
        "rp2": ReducedPolynomial((c10, c20)),
        "mr": MooneyRivlin(c10, c01),
        "ogden": Ogden((mu,), (alpha,)),
    }
    for key, model in ours.items():
        np.testing.assert_allclose(
            model.nominal_stress_Pa(lam, "uniaxial"), printed[key], rtol=1e-12
        )


@pytest.mark.parametrize("mode", HOMOGENEOUS_MODES)
@pytest.mark.parametrize("name", sorted(CLOSED_FORMS))
def test_parameter_gradient_matches_finite_differences(name, mode):
    model = CLOSED_FORMS[name]
    p = model.parameter_vector
    analytic = model.nominal_stress_gradient(STRETCHES, mode)
    scale = np.abs(model.nominal_stress_Pa(STRETCHES, mode)).max()
    for k in range(p.size):
        h = 1e-6 * max(abs(p[k]), 1.0)
        up, down = p.copy(), p.copy()
        up[k] += h
        down[k] -= h
        numeric = (
            model.with_parameters(up).nominal_stress_Pa(STRETCHES, mode)
            - model.with_parameters(down).nominal_stress_Pa(STRETCHES, mode)
        ) / (2.0 * h)
        # rounding of the difference quotient: a few eps * |S| / h
        rounding = 10.0 * np.finfo(np.float64).eps * scale / h
        np.testing.assert_allclose(analytic[:, k], numeric, rtol=1e-6, atol=max(1e-9, rounding))


def test_with_bulk_modulus_makes_the_fe_material():
    material = MooneyRivlin(100.0, 50.0).with_bulk_modulus(1e5)
    assert material == MooneyRivlin(100.0, 50.0, 1e5)
    assert material.C10_Pa == 100.0 and material.bulk_modulus_Pa == 1e5


def test_to_dict_uses_the_flat_material_keys():
    assert ReducedPolynomial((600.553, 4097.45)).to_dict() == {
        "model": "reduced_polynomial",
        "C10_Pa": 600.553,
        "C20_Pa": 4097.45,
    }
    assert Ogden((10.0,), (-2.0,)).to_dict() == {"model": "ogden", "mu1_Pa": 10.0, "alpha1": -2.0}
    assert MooneyRivlin(1.0, 2.0).to_dict() == {
        "model": "mooney_rivlin",
        "C10_Pa": 1.0,
        "C01_Pa": 2.0,
    }


@pytest.mark.parametrize("mode", HOMOGENEOUS_MODES)
@pytest.mark.parametrize("name", sorted(CLOSED_FORMS))
def test_closed_forms_match_the_fe_kernel_at_isochoric_states(name, mode):
    """The same object in the Warp kernel: at J = 1 the volumetric term is stress free, and the
    nominal stress of the incompressible test is P_11 - P_33 l_3 / l_1 (the pressure that
    frees face 3; face 2 is free or held as the mode says)."""
    material = MATERIALS[name]
    stretches = principal_stretches(STRETCHES, mode)
    result = evaluate_material(
        material, np.stack([np.diag(s) for s in stretches]), device="cpu"
    ).first_piola_Pa
    kernel = result[:, 0, 0] - result[:, 2, 2] * stretches[:, 2] / stretches[:, 0]
    closed_form = CLOSED_FORMS[name].nominal_stress_Pa(STRETCHES, mode)
    np.testing.assert_allclose(kernel, closed_form, rtol=1e-9, atol=1e-9 * np.abs(kernel).max())


def test_incompressible_models_have_no_bulk_modulus_and_the_fe_refuses_them():
    model = NeoHookean(150.0)
    assert model.incompressible and model.D1_per_Pa == 0.0
    assert model.to_dict() == {"model": "neo_hookean", "C10_Pa": 150.0}
    assert model.small_strain_equivalent() == (900.0, 0.5)
    with pytest.raises(InputError, match="bulk modulus") as error:
        evaluate_material(model, np.eye(3), device="cpu")
    assert error.value.column == "bulk_modulus_Pa"
    assert model.with_bulk_modulus(3000.0) == MATERIALS["neo_hookean"]


def test_a_model_with_a_bulk_modulus_needs_a_positive_initial_shear_modulus():
    """Fits explore unstable trial points (incompressible); the FE material must be stable at
    rest."""
    assert NeoHookean(-10.0).initial_shear_modulus_Pa == -20.0
    assert MooneyRivlin(-200.0, 100.0).C10_Pa == -200.0
    with pytest.raises(InputError) as error:
        NeoHookean(-10.0).with_bulk_modulus(1e4)
    assert error.value.column == "C10_Pa"
    with pytest.raises(InputError, match="C10_Pa \\+ C01_Pa"):
        MooneyRivlin(-200.0, 100.0, 1e4)
    with pytest.raises(InputError, match="sum of mu_i"):
        Ogden((-5.0,), (2.0,), 1e4)


def test_fit_parameters_exclude_the_bulk_modulus_and_keep_it():
    material = MATERIALS["ogden_3"]
    assert material.parameter_names == (
        "mu1_Pa", "alpha1", "mu2_Pa", "alpha2", "mu3_Pa", "alpha3"
    )  # fmt: skip
    assert material.parameter_units == ("Pa", "", "Pa", "", "Pa", "")
    changed = material.with_parameters(2.0 * material.parameter_vector)
    assert changed.bulk_modulus_Pa == material.bulk_modulus_Pa
    assert changed.mu_Pa == (500.0, -60.0, 10.0) and changed.alpha == (6.0, -4.0, 16.0)
    lower, upper = material.parameter_bounds
    assert np.all(lower == -np.inf) and np.all(upper == np.inf)
    lower, upper = MATERIALS["linear_elastic"].parameter_bounds
    np.testing.assert_array_equal(lower, [0.0, -1.0])
    np.testing.assert_array_equal(upper, [np.inf, 0.5])
    assert MATERIALS["compressible_neo_hookean"].parameter_names == (
        "shear_modulus_Pa", "bulk_modulus_Pa"
    )  # fmt: skip
    with pytest.raises(InputError, match="expected 6 parameters"):
        material.with_parameters([1.0, 2.0])


def test_start_parameters_solve_the_linear_models_exactly():
    truth = ReducedPolynomial((600.553, 4097.45))
    stretch = np.linspace(0.85, 1.0, 20)

    def design(model):
        return model.nominal_stress_gradient(stretch, "uniaxial")

    data = truth.nominal_stress_Pa(stretch, "uniaxial")
    start = ReducedPolynomial((1.0, 1.0)).start_parameters(design, data)
    np.testing.assert_allclose(start, truth.parameter_vector, rtol=1e-9)
    ogden = Ogden((300.0,), (5.0,))
    start = Ogden((1.0,), (2.0,)).start_parameters(
        design, ogden.nominal_stress_Pa(stretch, "uniaxial")
    )
    np.testing.assert_allclose(start, [300.0, 5.0], rtol=1e-9)  # alpha = 5 is on the grid


def test_a_typo_of_a_required_key_is_named():
    """Before: {"C10_pa": ...} was reported as a missing C10_Pa without naming the typo."""
    with pytest.raises(InputError, match="'C10_pa' looks like a typo") as error:
        material_from_dict({"model": "neo_hookean", "C10_pa": 1.0, "bulk_modulus_Pa": 1e4})
    assert error.value.column == "C10_Pa"
    with pytest.raises(InputError, match="expected C10_Pa, bulk_modulus_Pa") as error:
        material_from_dict({"model": "neo_hookean", "C10_Pa": 1.0, "bulk_modulus_Pa": 1e4, "x": 1})
    assert error.value.column == "x"


def test_an_unknown_model_names_the_close_one():
    with pytest.raises(InputError, match="did you mean 'neo_hookean'") as error:
        material_from_dict({"model": "neo_hooken", "C10_Pa": 1.0, "bulk_modulus_Pa": 1e4})
    assert error.value.column == "model" and "[" not in error.value.message


def test_a_viscoelastic_material_takes_another_bulk_modulus_and_keeps_its_prony_series():
    """Viscoelastic.with_bulk_modulus (fit.bulk_modulus = "follows_shear" sets K on the
    viscoelastic materials of a fit too): the elastic response's K changes, nothing else."""
    material = material_from_dict(
        {
            "model": "neo_hookean",
            "C10_Pa": 150.0,
            "bulk_modulus_Pa": 3000.0,
            "g1": 0.3,
            "tau1_s": 2.0,
        }
    )
    changed = material.with_bulk_modulus(6000.0)
    assert changed.bulk_modulus == 6000.0 and changed.elastic == NeoHookean(150.0, 6000.0)
    assert (changed.g, changed.tau_s) == (material.g, material.tau_s)
    with pytest.raises(InputError):
        material.with_bulk_modulus(-1.0)
