"""Tests of warptissue.usd.schema: material records and small-strain equivalents."""

from __future__ import annotations

import numpy as np
import pytest

from warptissue.errors import InputError
from warptissue.usd.schema import material_record, record_from_attributes, small_strain_from_record


def _moduli(youngs, nu):
    """Shear and bulk moduli from E and nu (the inverse relations, an independent check)."""
    return youngs / (2 * (1 + nu)), youngs / (3 * (1 - 2 * nu))


@pytest.mark.parametrize(
    ("record", "shear"),
    [
        ({"model": "neo_hookean", "C10_Pa": 287.5, "bulk_modulus_Pa": 5e4}, 575.0),
        (
            {"model": "mooney_rivlin", "C10_Pa": 100.0, "C01_Pa": 50.0, "bulk_modulus_Pa": 5e4},
            300.0,
        ),
        (
            {
                "model": "reduced_polynomial",
                "C10_Pa": 600.553,
                "C20_Pa": 4097.45,
                "bulk_modulus_Pa": 5e4,
            },
            1201.106,
        ),
        (
            {"model": "ReducedPolynomial", "C_Pa": [600.553, 4097.45], "bulk_modulus_Pa": 5e4},
            1201.106,
        ),
        (
            {
                "model": "ogden",
                "mu1_Pa": 400.0,
                "alpha1": 2.0,
                "mu2_Pa": -50.0,
                "alpha2": -2.0,
                "bulk_modulus_Pa": 5e4,
            },
            350.0,
        ),
        (
            {
                "model": "Ogden",
                "mu_Pa": [400.0, -50.0],
                "alpha": [2.0, -2.0],
                "bulk_modulus_Pa": 5e4,
            },
            350.0,
        ),
        (
            {
                "model": "compressible_neo_hookean",
                "shear_modulus_Pa": 900.0,
                "bulk_modulus_Pa": 5e4,
            },
            900.0,
        ),
    ],
)
def test_small_strain_equivalent(record, shear):
    youngs, nu = small_strain_from_record(record)
    mu, bulk = _moduli(youngs, nu)
    assert mu == pytest.approx(shear, rel=1e-12)
    assert bulk == pytest.approx(record["bulk_modulus_Pa"], rel=1e-10)


def test_incompressible_linear_and_d1():
    assert small_strain_from_record({"model": "neo_hookean", "C10_Pa": 100.0}) == (600.0, 0.5)
    record = {"model": "linear_elastic", "youngs_modulus_Pa": 2e4, "poissons_ratio": 0.3}
    assert small_strain_from_record(record) == (2e4, 0.3)
    with_d1 = small_strain_from_record({"model": "neo_hookean", "C10_Pa": 100.0, "D1_per_Pa": 2e-4})
    assert _moduli(*with_d1)[1] == pytest.approx(1e4, rel=1e-12)


def test_unknown_model_and_bad_values():
    with pytest.raises(InputError, match="cannot derive"):
        small_strain_from_record({"model": "Fung", "c_Pa": 1.0})
    with pytest.raises(InputError, match="model"):
        small_strain_from_record({"C10_Pa": 1.0})
    with pytest.raises(InputError, match="finite"):
        material_record({"model": "NeoHookean", "C10_Pa": float("nan")})
    with pytest.raises(InputError, match="sum g_i < 1"):
        material_record(
            {"model": "NeoHookean", "C10_Pa": 1.0, "prony_g": [0.6, 0.5], "prony_tau_s": [1, 2]}
        )
    with pytest.raises(InputError, match="to_dict"):
        material_record(42)


def test_record_maps_keys_and_inverts():
    record = {
        "model": "ogden",
        "mu1_Pa": 400.0,
        "alpha1": 2.0,
        "mu2_Pa": -50.0,
        "alpha2": -2.0,
        "bulk_modulus_Pa": 9.0,
        "prony_g": [0.2],
        "prony_tau_s": [3.0],
        "custom_thing_Pa": 5.0,
    }
    mapped = material_record(record)
    assert mapped.hyperelastic.keys() == {"mu", "alpha", "bulkModulus", "custom_thing_Pa"}
    np.testing.assert_array_equal(mapped.hyperelastic["mu"], [400.0, -50.0])
    np.testing.assert_array_equal(mapped.hyperelastic["alpha"], [2.0, -2.0])
    np.testing.assert_array_equal(mapped.prony_g, [0.2])
    values = dict(mapped.hyperelastic)
    values.update(pronyG=list(mapped.prony_g), pronyTau=list(mapped.prony_tau_s))
    assert record_from_attributes("ogden", values) == record
    tuple_form = material_record({"model": "reduced_polynomial", "C_Pa": [1.0, 2.0, 3.0]})
    assert tuple_form.hyperelastic == {"C10": 1.0, "C20": 2.0, "C30": 3.0}
    with pytest.raises(InputError, match="consecutive"):
        material_record(
            {"model": "ogden", "mu1_Pa": 1.0, "alpha1": 2.0, "mu3_Pa": 1.0, "alpha3": 2.0}
        )


def test_records_and_material_objects_give_the_same_small_strain_equivalent():
    """One owner: a material dictionary goes through the warptissue.materials model."""
    from warptissue import materials

    for material in (
        materials.NeoHookean(287.5, 3e4),
        materials.MooneyRivlin(-40.0, 160.0, 2500.0),
        materials.Yeoh(300.0, -20.0, 15.0, 6000.0),
        materials.Ogden((250.0, -30.0, 5.0), (3.0, -2.0, 8.0), 4000.0),
        materials.CompressibleNeoHookean(200.0, 1500.0),
    ):
        record = material.to_dict()
        assert small_strain_from_record(record) == material.small_strain_equivalent()
    with pytest.raises(InputError, match="cannot derive"):
        small_strain_from_record({"model": "compressible_neo_hookean", "shear_modulus_Pa": 1.0})
