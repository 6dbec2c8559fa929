"""Homogeneous hyperelastic tests: the closed-form stresses of warptissue.materials, and the
fits and Drucker stability of warptissue.fit.hyperelastic.

Independent references: numerical differentiation of each strain energy (stress = dW/dl per
loaded direction; Hessian of W in log strains), the needle-indentation study's printed Eq. 3,
and its RP2 parameters (C10 = 600.553 Pa, C20 = 4097.45 Pa) recovered from synthetic data of its
compression test (70 x 80 x 80 mm block, 80 mm tall, compressed by 12.7 mm at 0.4 mm/s).
"""

from __future__ import annotations

import numpy as np
import pytest

from warptissue.errors import InputError
from warptissue.fit.hyperelastic import (
    STABILITY_MODES,
    HomogeneousTest,
    drucker_stability,
    fit_hyperelastic,
    model_from_name,
)
from warptissue.materials import (
    MooneyRivlin,
    NeoHookean,
    Ogden,
    ReducedPolynomial,
    Yeoh,
    principal_stretches,
)

MODELS = {
    "neo_hookean": NeoHookean(350.0),
    "mooney_rivlin": MooneyRivlin(-400.0, 900.0),
    "yeoh": Yeoh(500.0, -120.0, 60.0),
    "ogden_2": Ogden((300.0, -40.0), (2.5, -3.0)),
}
STRETCHES = np.array([0.45, 0.7, 0.93, 1.08, 1.4, 2.2])

STUDY_C10_PA, STUDY_C20_PA = 600.553, 4097.45
STUDY_HEIGHT_M, STUDY_AREA_M2, STUDY_DEPTH_M = 0.080, 0.070 * 0.080, 0.0127


def numeric_log_strain_hessian(model, e1, e2, h=1e-4):
    def w(a, b):
        return model.energy_density_Pa(np.exp(np.array([[a, b, -a - b]])))[0]

    hessian = np.empty((2, 2))
    hessian[0, 0] = (w(e1 + h, e2) - 2.0 * w(e1, e2) + w(e1 - h, e2)) / h**2
    hessian[1, 1] = (w(e1, e2 + h) - 2.0 * w(e1, e2) + w(e1, e2 - h)) / h**2
    hessian[0, 1] = hessian[1, 0] = (
        w(e1 + h, e2 + h) - w(e1 + h, e2 - h) - w(e1 - h, e2 + h) + w(e1 - h, e2 - h)
    ) / (4.0 * h**2)
    return hessian


@pytest.mark.parametrize("name", sorted(MODELS))
def test_log_strain_hessian_matches_finite_differences(name):
    model = MODELS[name]
    for e1, e2 in ((0.3, -0.1), (-0.4, 0.25), (0.05, 0.05)):
        analytic = model.log_strain_hessian(np.array([e1]), np.array([e2]))[0]
        numeric = numeric_log_strain_hessian(model, e1, e2)
        np.testing.assert_allclose(analytic, numeric, rtol=1e-5, atol=1e-6 * np.abs(numeric).max())


@pytest.mark.parametrize("name", sorted(MODELS))
def test_hessian_along_the_uniaxial_path_is_the_true_stress_tangent(name):
    """d tau : d eps along the path is d(Cauchy stress)/d(log strain) (module Notes)."""
    model = MODELS[name]
    lam = STRETCHES
    h = 1e-6

    def true_stress(stretch):
        return stretch * model.nominal_stress_Pa(stretch, "uniaxial")

    tangent = (true_stress(lam * np.exp(h)) - true_stress(lam * np.exp(-h))) / (2.0 * h)
    e = np.log(lam)
    hessian = model.log_strain_hessian(e, -0.5 * e)
    direction = np.array([1.0, -0.5])
    np.testing.assert_allclose(hessian @ direction @ direction, tangent, rtol=1e-6)


def needle_study_compression_test(rng, noise_N=0.02):
    """The needle-indentation study's test: 0.4 mm/s to 12.7 mm, sampled at 50 Hz, force
    noise 0.02 N (the sensor's resolution)."""
    displacement_m = np.arange(0.0, STUDY_DEPTH_M + 1e-12, 0.4e-3 / 50.0)
    truth = ReducedPolynomial((STUDY_C10_PA, STUDY_C20_PA))
    clean = HomogeneousTest.from_force_displacement(
        displacement_m,
        np.zeros_like(displacement_m),
        area_m2=STUDY_AREA_M2,
        height_m=STUDY_HEIGHT_M,
        loading="compression",
    )
    force_N = clean.predicted_stress_Pa(truth) * STUDY_AREA_M2
    force_N = force_N + rng.normal(0.0, noise_N, force_N.size)
    return HomogeneousTest.from_force_displacement(
        displacement_m,
        force_N,
        area_m2=STUDY_AREA_M2,
        height_m=STUDY_HEIGHT_M,
        loading="compression",
    )


def test_needle_study_geometry():
    assert STUDY_DEPTH_M / STUDY_HEIGHT_M == pytest.approx(0.15875)
    stretch = 1.0 - STUDY_DEPTH_M / STUDY_HEIGHT_M
    stress = -ReducedPolynomial((STUDY_C10_PA, STUDY_C20_PA)).nominal_stress_Pa(stretch, "uniaxial")
    # about 1.5 kPa, 8.3 N on the 70 x 80 mm face: well above the 0.02 N resolution
    assert stress[0] * STUDY_AREA_M2 == pytest.approx(8.3, abs=0.1)


@pytest.mark.parametrize(
    ("objective", "method"), [("absolute", "lm"), ("relative", "lm"), ("absolute", "salm")]
)
def test_needle_study_rp2_parameters_are_recovered(rng, objective, method):
    test = needle_study_compression_test(rng)
    fit = fit_hyperelastic("reduced_polynomial:2", test, objective=objective, method=method)
    assert fit.result.success
    np.testing.assert_allclose(fit.model.C_Pa, (STUDY_C10_PA, STUDY_C20_PA), rtol=0.01)
    assert fit.result.r_squared > 0.999
    assert fit.stability.stable_everywhere
    # the reported standard errors cover the truth
    errors = np.abs(np.array(fit.model.C_Pa) - (STUDY_C10_PA, STUDY_C20_PA))
    assert np.all(errors < 5.0 * fit.result.standard_errors)
    if objective == "relative":
        assert fit.min_strain == 0.05 and fit.result.fitted.size < test.nominal_strain.size


def test_four_models_ranked_by_r_squared_and_mooney_rivlin_stability(rng):
    test = needle_study_compression_test(rng)
    fits = {name: fit_hyperelastic(name, test) for name in (
        "neo_hookean", "mooney_rivlin", "reduced_polynomial:2", "ogden:1")}  # fmt: skip
    ranking = sorted(fits, key=lambda n: fits[n].result.r_squared, reverse=True)
    assert ranking[0] == "reduced_polynomial:2"  # the model that generated the data
    assert ranking[-1] == "neo_hookean"  # cannot stiffen: the study's worst fit too
    assert all(0.0 < fits[n].result.r_squared < 1.0 for n in fits)
    mooney = fits["mooney_rivlin"]
    # The study: Mooney-Rivlin fits well with a negative C10 and is stable only for small
    # strains (< 0.05).
    assert mooney.model.C10_Pa < 0.0 < mooney.model.C01_Pa
    assert mooney.result.r_squared > 0.99
    compression = mooney.stability["uniaxial_compression"].unstable_from_strain
    assert compression is not None and 0.0 < compression < 0.05
    assert 0.0 < mooney.stability.stable_up_to_strain <= compression
    assert mooney.comparison_row()["unstable_from_strain_tested_modes"] == compression
    assert fits["neo_hookean"].stability.stable_everywhere
    assert fits["reduced_polynomial:2"].stability.stable_everywhere
    # unstable inside the tested range: said in the result's warnings
    warning, *others = mooney.result.warnings
    assert "not Drucker-stable in uniaxial compression" in warning
    # and in the loadings not tested (issue 36): a negative tensile stress, instabilities
    # (and its residuals are systematic: Durbin-Watson, as the inverse FE's rule)
    assert any("residuals of test" in m and "systematic" in m for m in others)
    assert [m.split(" (not tested)")[0] for m in others if m.startswith("in ")] == [
        "in tension",
        "in equibiaxial",
        "in planar",
    ]
    assert warning in mooney.to_dict()["fit"]["warnings"]
    assert fits["reduced_polynomial:2"].result.warnings == []


def test_reported_stability_limits_are_where_the_numeric_hessian_loses_definiteness():
    model = MooneyRivlin(-4440.0, 4796.0)
    report = drucker_stability(model)
    checked = 0
    for entry in report.ranges:
        if entry.stable:
            continue
        mode, _, direction = entry.mode.partition("_")
        sign = 1.0 if direction == "tension" else -1.0
        for factor, expect_stable in ((0.99, True), (1.01, False)):
            stretch = 1.0 + sign * factor * entry.unstable_from_strain
            e = np.log(stretch)
            e1, e2 = {"uniaxial": (e, -0.5 * e), "equibiaxial": (e, e), "planar": (e, 0.0)}[mode]
            eigenvalues = np.linalg.eigvalsh(numeric_log_strain_hessian(model, e1, e2, h=1e-3))
            assert (eigenvalues.min() > 0.0) == expect_stable, (entry.mode, factor)
        checked += 1
    assert checked >= 2


def test_known_stability_cases():
    assert drucker_stability(MooneyRivlin(300.0, 100.0)).stable_everywhere
    assert drucker_stability(Ogden((500.0, 20.0), (3.0, -2.0))).stable_everywhere  # mu_i > 0
    # mu > 0 is stable at any stretch; with alpha = -11 the Hessian's eigenvalues differ by
    # 1e15 at large strain, which a naive 2 x 2 determinant reports as unstable.
    assert drucker_stability(Ogden((1091.0,), (-11.0,))).stable_everywhere
    negative = drucker_stability(NeoHookean(-10.0))
    assert all(entry.unstable_from_strain == 0.0 for entry in negative.ranges)
    assert set(negative.to_dict()) == {*STABILITY_MODES, "stable_up_to_strain"}


def test_joint_fit_over_three_loadings_recovers_ogden_parameters():
    truth = Ogden((800.0,), (4.0,))
    strain = np.linspace(0.02, 0.6, 30)
    tests = [
        HomogeneousTest(loading, strain, np.zeros_like(strain), loading)
        for loading in ("tension", "equibiaxial", "planar")
    ]
    tests = [
        HomogeneousTest(t.loading, strain, t.predicted_stress_Pa(truth), t.name) for t in tests
    ]
    fit = fit_hyperelastic("ogden:1", tests)
    np.testing.assert_allclose(fit.model.parameter_vector, [800.0, 4.0], rtol=1e-7)
    assert fit.result.fitted.size == 3 * strain.size
    json_ready = fit.to_dict()
    assert json_ready["loadings"] == ["tension", "equibiaxial", "planar"]


def test_from_force_displacement_and_sign_convention():
    test = HomogeneousTest.from_force_displacement(
        [0.0, 0.008], [0.0, 5.6], area_m2=0.0056, height_m=0.08, loading="compression"
    )
    np.testing.assert_allclose(test.nominal_strain, [0.0, 0.1])
    np.testing.assert_allclose(test.nominal_stress_Pa, [0.0, 1000.0])
    np.testing.assert_allclose(test.stretch, [1.0, 0.9])
    model = NeoHookean(500.0)
    assert test.predicted_stress_Pa(model)[1] > 0.0  # compressive stress is positive here
    assert model.nominal_stress_Pa(0.9, "uniaxial")[0] < 0.0  # signed mechanics


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"area_m2": 0.0}, "area_m2"),
        ({"height_m": -1.0}, "height_m"),
        ({"displacement_m": [0.0, 0.09]}, "below 1"),
        ({"displacement_m": [0.0, -0.01, -0.02]}, "magnitudes"),
        ({"loading": "shear"}, "loading"),
    ],
)
def test_invalid_tests(kwargs, match):
    arguments = {
        "displacement_m": [0.0, 0.01],
        "force_N": [0.0, 1.0],
        "area_m2": 0.0056,
        "height_m": 0.08,
        "loading": "compression",
    }
    arguments.update(kwargs)
    arguments["force_N"] = np.zeros(len(arguments["displacement_m"]))
    with pytest.raises(InputError, match=match):
        HomogeneousTest.from_force_displacement(
            arguments.pop("displacement_m"), arguments.pop("force_N"), **arguments
        )


def test_relative_objective_without_a_window_rejects_zero_stress(rng):
    test = needle_study_compression_test(rng, noise_N=0.0)
    with pytest.raises(InputError, match="non-zero"):
        fit_hyperelastic("neo_hookean", test, objective="relative", min_strain=0.0)


@pytest.mark.parametrize("spec", ["ogden:0", "neo_hookean:2", "foam", "reduced_polynomial:x"])
def test_bad_model_names(spec):
    with pytest.raises(InputError):
        model_from_name(spec)


def test_model_names_and_orders():
    assert model_from_name("reduced_polynomial:2").parameter_names == ("C10_Pa", "C20_Pa")
    assert model_from_name("yeoh").parameter_names == ("C10_Pa", "C20_Pa", "C30_Pa")
    assert model_from_name("ogden:2").parameter_names == ("mu1_Pa", "alpha1", "mu2_Pa", "alpha2")
    assert model_from_name("ogden:2").parameter_units == ("Pa", "", "Pa", "")
    assert MooneyRivlin(100.0, 50.0).initial_shear_modulus_Pa == 300.0
    assert Ogden((100.0, 20.0), (2.0, -2.0)).initial_shear_modulus_Pa == 120.0


def test_mooney_rivlin_limits_match_the_closed_form_criterion():
    """For Mooney-Rivlin the log-strain Hessian is diagonal in 3-D, G = diag(4 c_j) with
    c_j = C10 l_j^2 + C01 l_j^-2, and on the trace-free plane it is positive definite iff
    e2(c) = c1 c2 + c2 c3 + c3 c1 > 0 (with c1 + c2 + c3 > 0): the first root of e2 along a
    mode is its stability limit."""
    import scipy.optimize

    model = MooneyRivlin(-4437.0, 4793.0)
    report = drucker_stability(model)

    def e2(strain, mode, sign):
        lam = principal_stretches(np.array([1.0 + sign * strain]), mode)[0]
        c = model.C10_Pa * lam**2 + model.C01_Pa / lam**2
        return c[0] * c[1] + c[1] * c[2] + c[2] * c[0]

    for entry in report.ranges:
        mode, _, direction = entry.mode.partition("_")
        sign = 1.0 if direction == "tension" else -1.0
        grid = np.linspace(1e-6, 0.5, 5001)
        values = np.array([e2(s, mode, sign) for s in grid])
        first = int(np.flatnonzero(values <= 0.0)[0])
        root = scipy.optimize.brentq(e2, grid[first - 1], grid[first], args=(mode, sign))
        assert entry.unstable_from_strain == pytest.approx(root, rel=1e-6), entry.mode


def test_records_name_the_file_and_column_of_a_sign_error():
    displacement_m = np.linspace(0.0, 0.01, 11)
    force_N = -np.linspace(0.0, 5.0, 11)
    with pytest.raises(InputError, match="flip the sign") as error:
        HomogeneousTest.from_force_displacement(
            displacement_m,
            force_N,
            area_m2=0.0056,
            height_m=0.08,
            loading="compression",
            path="run.csv",
        )
    assert error.value.column == "force_N" and str(error.value.path) == "run.csv"
    with pytest.raises(InputError, match="magnitudes") as error:
        HomogeneousTest("tension", displacement_m, force_N)
    assert error.value.column == "nominal_stress_Pa"


def test_an_all_zero_stress_is_not_fitted():
    test = HomogeneousTest("compression", np.linspace(0.0, 0.1, 11), np.zeros(11))
    with pytest.raises(InputError, match="nothing to fit"):
        fit_hyperelastic("neo_hookean", test)


def test_window_errors_show_plain_numbers():
    """Before: '(got np.float64(-1.0))' and a window error without the data's range."""
    test = HomogeneousTest("compression", np.linspace(0.0, 0.1, 5), np.linspace(0.0, 1.0, 5))
    with pytest.raises(InputError) as error:
        fit_hyperelastic("neo_hookean", test, min_strain=np.float64(-1.0))
    assert "np.float64" not in str(error.value) and "(got -1.0)" in str(error.value)
    with pytest.raises(InputError, match="largest nominal strain 0.1") as error:
        fit_hyperelastic("neo_hookean", test, min_strain=np.float64(0.5))
    assert "np.float64" not in str(error.value)


def test_a_negative_c01_is_named_as_the_cause_of_an_implausible_modulus():
    """Issue 36: a Mooney-Rivlin fit with a negative C01 got "the modulus is outside the
    plausible range ... check the units"; the cause, the negative parameter, is named."""
    truth = MooneyRivlin(1000.0, -999.0)  # mu0 = 2 (C10 + C01) = 2 Pa, E = 6 Pa
    stretch = np.linspace(1.0, 2.0, 21)
    test = HomogeneousTest("tension", stretch - 1.0, truth.nominal_stress_Pa(stretch, "uniaxial"))
    fit = fit_hyperelastic("mooney_rivlin", test)
    assert fit.model.C01_Pa == pytest.approx(-999.0, rel=1e-6)
    (message,) = [m for m in fit.result.warnings if "Young's modulus" in m]
    assert "because C01_Pa = -999 Pa is negative" in message and "units" not in message


def test_systematic_residuals_are_warned_as_in_the_inverse_fe():
    """Issue 36: a neo-Hookean fit with R^2 = 0.84 on data with a strong upturn got no
    warning; the inverse FE's Durbin-Watson rule (lsq.metrics) applies to each test. The
    statistic is checked by hand: sum(diff(r)^2) / sum(r^2)."""
    from warptissue.lsq.metrics import DURBIN_WATSON_LIMIT, durbin_watson

    stretch = np.linspace(1.0, 3.0, 30)
    upturn = ReducedPolynomial((1000.0, 0.0, 400.0)).nominal_stress_Pa(stretch, "uniaxial")
    fit = fit_hyperelastic("neo_hookean", HomogeneousTest("tension", stretch - 1.0, upturn))
    residuals = fit.tests[0].predicted_stress_Pa(fit.model) - upturn
    by_hand = np.sum(np.diff(residuals) ** 2) / np.sum(residuals**2)
    assert durbin_watson(residuals) == pytest.approx(by_hand)
    assert by_hand < DURBIN_WATSON_LIMIT
    (message,) = [m for m in fit.result.warnings if "systematic" in m]
    assert f"Durbin-Watson statistic {by_hand:.3g}" in message
    exact = ReducedPolynomial((1000.0,)).nominal_stress_Pa(stretch, "uniaxial")
    noisy = exact * (1 + 0.01 * np.random.default_rng(3).standard_normal(stretch.size))
    clean = fit_hyperelastic("neo_hookean", HomogeneousTest("tension", stretch - 1.0, noisy))
    assert not [m for m in clean.result.warnings if "systematic" in m]


def test_an_absurd_prediction_in_a_loading_not_tested_is_a_warning():
    """Issue 36: a 3-term Ogden fitted to uniaxial data alone predicted 2.8e10 MPa in
    equibiaxial tension with only "not identified" said. An Ogden with a hidden term
    (mu = -10 Pa, alpha = -8: 1e-3 of the uniaxial stress at stretch 3, but it sends the
    equibiaxial stress negative) fitted to its own uniaxial curve gets a warning naming the
    loading, the stress and the stretch."""
    truth = Ogden(mu_Pa=(3e5, -10.0), alpha=(2.0, -8.0))
    stretch = np.linspace(1.0, 3.0, 21)[1:]
    test = HomogeneousTest(
        "tension", stretch - 1.0, truth.nominal_stress_Pa(stretch, "uniaxial"), name="hidden"
    )
    fit = fit_hyperelastic(truth, test)
    assert fit.model.parameter_vector == pytest.approx(truth.parameter_vector, rel=1e-9)
    equibiaxial = truth.nominal_stress_Pa(stretch, "equibiaxial")
    assert np.min(equibiaxial) < 0.0  # by the closed form: the rule has something to catch
    (warning,) = [w for w in fit.result.warnings if "(not tested)" in w]
    assert warning.startswith("in equibiaxial (not tested) the fitted model predicts a nominal")
    assert "do not use it there" in warning
