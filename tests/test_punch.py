"""Contact formulas against independent derivations (Boussinesq, Sneddon's general punch)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad

from warptissue.errors import InputError
from warptissue.fit.punch import (
    flat_punch_force_N,
    flat_punch_modulus_Pa,
    flat_punch_modulus_printed_Pa,
    hayes_kappa,
    hertz_contact_radius_m,
    hertz_force_N,
    hertz_modulus_Pa,
)


@pytest.mark.parametrize("nu", [0.0, 0.3, 0.5])
def test_flat_punch_against_boussinesq_superposition(nu):
    # The flat-punch pressure p(r) = F / (2 pi a sqrt(a^2 - r^2)) displaces the centre by
    # w(0) = (1 - nu^2)/(pi E) int p(r)/r dA (Boussinesq point loads); integrate numerically.
    force, radius, modulus = 0.02, 1e-3, 3e4
    # int_0^a dr / sqrt(a^2 - r^2), with the (a - r)^-1/2 singularity taken by the weight.
    integral, _ = quad(
        lambda r: 1.0 / math.sqrt(radius + r), 0.0, radius, weight="alg", wvar=(0.0, -0.5)
    )
    pressure_over_r = 2 * math.pi * force / (2 * math.pi * radius) * integral  # int p/r dA
    depth = (1 - nu**2) / (math.pi * modulus) * pressure_over_r
    assert flat_punch_modulus_Pa(force, depth, radius_m=radius, poissons_ratio=nu) == (
        pytest.approx(modulus, rel=1e-10)
    )
    assert flat_punch_force_N(
        depth, radius_m=radius, youngs_modulus_Pa=modulus, poissons_ratio=nu
    ) == pytest.approx(force, rel=1e-10)


def test_printed_eq2_differs_by_one_plus_nu():
    kwargs = {"radius_m": 1e-3, "poissons_ratio": 0.5}
    correct = flat_punch_modulus_Pa(0.01, 2e-4, **kwargs)
    printed = flat_punch_modulus_printed_Pa(0.01, 2e-4, **kwargs)
    assert correct / printed == pytest.approx(1.5)


def test_hertz_against_sneddon_general_punch_quadrature():
    # Sneddon (1965) for a punch of profile f(r), rho = r / a: delta = int_0^1 f'(x)/sqrt(1-x^2)
    # and F = 2 a E* int_0^1 x^2 f'(x)/sqrt(1-x^2) dx. Paraboloid f = r^2 / (2R).
    radius, modulus, nu, contact = 2e-3, 5e3, 0.45, 0.3e-3
    slope = lambda x: contact**2 * x / radius  # noqa: E731  d f(a x)/dx
    # 1/sqrt(1 - x^2) = (1 - x)^-1/2 (weight) * (1 + x)^-1/2.
    depth, _ = quad(lambda x: slope(x) / math.sqrt(1 + x), 0, 1, weight="alg", wvar=(0, -0.5))
    moment, _ = quad(
        lambda x: x**2 * slope(x) / math.sqrt(1 + x), 0, 1, weight="alg", wvar=(0, -0.5)
    )
    force = 2 * contact * modulus / (1 - nu**2) * moment
    assert hertz_force_N(
        depth, radius_m=radius, youngs_modulus_Pa=modulus, poissons_ratio=nu
    ) == pytest.approx(force, rel=1e-9)
    assert hertz_contact_radius_m(depth, radius_m=radius) == pytest.approx(contact, rel=1e-9)
    assert hertz_modulus_Pa(force, depth, radius_m=radius, poissons_ratio=nu) == pytest.approx(
        modulus, rel=1e-9
    )


def test_hayes_kappa_limits():
    assert hayes_kappa(0.0, 0.5) == 1.0
    assert hayes_kappa(1e-3, 0.3) == pytest.approx(1.0, abs=2e-3)  # half-space limit
    # Increasing, and converged in the quadrature.
    values = [hayes_kappa(r, 0.45) for r in (0.2, 0.5, 1.0)]
    assert values[0] > 1.0 and np.all(np.diff(values) > 0)
    assert hayes_kappa(1.0, 0.45, node_count=96) == pytest.approx(values[2], rel=1e-8)


def test_hayes_kappa_thin_layer_is_oedometric():
    # a >> h: F -> pi a^2 delta M / h, M = E (1 - nu)/((1 + nu)(1 - 2 nu)), so
    # d kappa / d(a/h) -> pi (1 - nu)^2 / (2 (1 - 2 nu)); edge terms cancel in the difference.
    nu = 0.3
    slope = (hayes_kappa(8.0, nu) - hayes_kappa(4.0, nu)) / 4.0
    assert slope == pytest.approx(math.pi * (1 - nu) ** 2 / (2 * (1 - 2 * nu)), rel=2e-3)


def test_hayes_kappa_thin_incompressible_layer_is_lubrication_limit():
    # nu = 0.5, a >> h: squeeze flow of a layer bonded below, shear-free on top gives
    # p = 3 mu delta (a^2 - r^2) / (4 h^3), F = 3 pi mu a^4 delta / (8 h^3), so
    # kappa / (a/h)^3 -> 3 pi / 64. The approach is slow (edge terms in h/a and (h/a)^2):
    # extrapolate A + B/r + C/r^2 through r = a/h = 4, 8, 16.
    ratios = np.array([4.0, 8.0, 16.0])
    scaled = [hayes_kappa(r, 0.5) / r**3 for r in ratios]
    basis = np.column_stack([np.ones(3), 1 / ratios, 1 / ratios**2])
    limit = np.linalg.solve(basis, scaled)[0]
    assert limit == pytest.approx(3 * math.pi / 64, rel=0.02)


def test_thickness_correction_applies_kappa():
    kwargs = {"radius_m": 1e-3, "poissons_ratio": 0.45}
    thick = flat_punch_modulus_Pa(0.01, 2e-4, **kwargs)
    thin = flat_punch_modulus_Pa(0.01, 2e-4, thickness_m=2e-3, **kwargs)
    assert thick / thin == pytest.approx(hayes_kappa(0.5, 0.45))


@pytest.mark.parametrize(
    "kwargs",
    [
        {"radius_m": 0.0, "poissons_ratio": 0.3},
        {"radius_m": 1e-3, "poissons_ratio": 0.6},
        {"radius_m": 1e-3, "poissons_ratio": 0.3, "thickness_m": -1.0},
    ],
)
def test_bad_contact_input(kwargs):
    with pytest.raises(InputError):
        flat_punch_modulus_Pa(0.01, 1e-4, **kwargs)
    with pytest.raises(InputError, match="depth"):
        flat_punch_modulus_Pa(0.01, -1e-4, radius_m=1e-3, poissons_ratio=0.3)


def test_fit_punch_modulus_sphere_and_layer(rng):
    from warptissue.fit.punch import fit_punch_modulus

    depth = np.linspace(1e-5, 1e-3, 30)
    force = hertz_force_N(depth, radius_m=2e-3, youngs_modulus_Pa=8e3, poissons_ratio=0.49)
    noisy = force * (1 + rng.normal(0, 1e-3, depth.size))
    sphere = fit_punch_modulus(depth, noisy, radius_m=2e-3, poissons_ratio=0.49, geometry="sphere")
    assert sphere.parameters["youngs_modulus_Pa"] == pytest.approx(8e3, rel=5e-3)
    layer_force = flat_punch_force_N(
        depth, radius_m=1e-3, youngs_modulus_Pa=8e3, poissons_ratio=0.3
    ) * hayes_kappa(0.5, 0.3)
    layer = fit_punch_modulus(
        depth, layer_force, radius_m=1e-3, poissons_ratio=0.3, thickness_m=2e-3
    )
    assert layer.parameters["youngs_modulus_Pa"] == pytest.approx(8e3, rel=1e-9)
    with pytest.raises(InputError, match="geometry"):
        fit_punch_modulus(depth, force, radius_m=1e-3, poissons_ratio=0.3, geometry="cone")


def test_a_layer_much_thinner_than_the_punch_is_refused_not_fitted_negative():
    from warptissue.fit.punch import HAYES_MAX_RADIUS_OVER_THICKNESS, fit_punch_modulus

    # a/h = 50: the discretized Hayes factor used to come out negative (E < 0, R^2 = 1).
    depth = np.linspace(1e-6, 1e-5, 10)
    force = flat_punch_force_N(depth, radius_m=5e-3, youngs_modulus_Pa=3e4, poissons_ratio=0.5)
    with pytest.raises(InputError, match="beyond the range of the finite-thickness"):
        fit_punch_modulus(depth, force, radius_m=5e-3, poissons_ratio=0.5, thickness_m=1e-4)
    with pytest.raises(InputError, match="a/h = 30"):
        hayes_kappa(30.0, 0.5)
    assert hayes_kappa(HAYES_MAX_RADIUS_OVER_THICKNESS, 0.5) > 1.0


def test_fit_punch_modulus_never_returns_a_negative_modulus():
    from warptissue.fit.punch import fit_punch_modulus

    depth = np.linspace(1e-5, 1e-4, 10)
    pulling = -flat_punch_force_N(depth, radius_m=1e-3, youngs_modulus_Pa=3e4, poissons_ratio=0.5)
    result = fit_punch_modulus(depth, pulling, radius_m=1e-3, poissons_ratio=0.5)
    assert result.parameters["youngs_modulus_Pa"] >= 0.0
    assert not result.identified
    assert "pinned at its lower bound" in result.identifiability[0]


def test_fit_punch_modulus_warns_beyond_small_strain_and_implausible_moduli():
    from warptissue.fit.punch import fit_punch_modulus

    depth = np.linspace(1e-5, 1e-3, 20)
    kwargs = {"radius_m": 1e-3, "poissons_ratio": 0.3}
    force = flat_punch_force_N(depth, youngs_modulus_Pa=8e3, **kwargs) * hayes_kappa(0.5, 0.3)
    layer = fit_punch_modulus(depth, force, thickness_m=2e-3, **kwargs)
    assert any("0.5 of the layer thickness" in w for w in layer.warnings)
    shallow = fit_punch_modulus(depth[:4], force[:4], thickness_m=2e-3, **kwargs)
    assert shallow.warnings == []
    huge = fit_punch_modulus(depth, 1e6 * force, **kwargs)  # kN written as N, say
    assert any("outside the plausible range of soft tissue" in w for w in huge.warnings)
