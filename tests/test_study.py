"""Tests of warptissue.study: loading, defaults, round trips and every class of bad input."""

from __future__ import annotations

from pathlib import Path

import pytest
import tomli_w

from warptissue.errors import InputError
from warptissue.study import SCHEMA_VERSION, load_study, study_from_dict

REPOSITORY = Path(__file__).resolve().parents[1]
SCENE = REPOSITORY / "scenes" / "liver_slab_flat_punch.toml"

MINIMAL = """\
schema_version = 1

[specimen]
shape = "block"
width_m = 0.02
thickness_m = 0.01

[indenter]
kind = "flat_punch"
radius_m = 0.001

[protocol]
max_depth_m = 0.0005
steps = 4

[material]
model = "neo_hookean"
C10_Pa = 287.5
bulk_modulus_Pa = 575000.0
"""


def write(tmp_path: Path, text: str, name: str = "study.toml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def line_of(text: str, fragment: str) -> int:
    """1-based line of the first line containing ``fragment``."""
    for number, line in enumerate(text.splitlines(), start=1):
        if fragment in line:
            return number
    raise AssertionError(f"{fragment!r} not in the text")


def test_bundled_scene_loads_with_seed_values():
    study = load_study(SCENE)
    assert study.schema_version == SCHEMA_VERSION
    # Seed 001: a 2 mm DIAMETER probe, so the radius is 1 mm.
    assert study.indenter.radius_m == pytest.approx(1.0e-3)
    assert study.indenter.kind == "flat_punch"
    assert study.indenter.contact == "bonded"
    # Seed 000, Table 2: C10 = 287.5 Pa; nearly incompressible with K / mu = 1000.
    assert study.material.C10_Pa == pytest.approx(287.5)
    assert study.material.bulk_modulus_Pa / (2 * study.material.C10_Pa) == pytest.approx(1000)
    assert study.specimen.quarter and study.specimen.element == "TET10"
    assert study.solver.formulation == "mixed"
    # Indented to half the probe radius.
    assert study.protocol.max_depth_m == pytest.approx(0.5 * study.indenter.radius_m)
    assert 10 <= study.protocol.step_count <= 20


def test_minimal_study_gets_documented_defaults(tmp_path):
    study = load_study(write(tmp_path, MINIMAL, "slab.toml"))
    assert study.name == "slab"
    assert study.description == ""
    assert study.protocol.depths_m == pytest.approx([1.25e-4, 2.5e-4, 3.75e-4, 5e-4])
    assert study.specimen.quarter is True
    assert study.specimen.element == "TET10"
    assert study.specimen.size_near_m == pytest.approx(0.001 / 4)
    assert study.specimen.size_far_m == pytest.approx(0.01 / 4)
    assert study.specimen.growth == pytest.approx(1.2)
    assert study.specimen.mesher == "extruded"
    assert study.indenter.contact == "bonded"
    assert study.boundary.base == "fixed"
    assert study.solver.device == "auto"
    assert study.solver.formulation == "mixed"
    assert study.solver.linear_solver == "auto"
    assert study.solver.tolerance == pytest.approx(1e-9)
    assert study.solver.max_newton_iterations == 25
    assert study.solver.max_cutbacks == 8
    assert study.solver.nonlinear_elimination is True
    assert study.solver.predictor == "linearized"
    assert study.solver.damping is True


def test_explicit_depth_list_and_disc(tmp_path):
    text = MINIMAL.replace(
        'shape = "block"\nwidth_m = 0.02', 'shape = "disc"\nradius_m = 0.015'
    ).replace("max_depth_m = 0.0005\nsteps = 4", "depths_m = [1e-4, 3e-4, 4e-4]")
    study = load_study(write(tmp_path, text))
    assert study.specimen.shape == "disc"
    assert study.specimen.radius_m == pytest.approx(0.015)
    assert study.specimen.width_m is None
    assert study.protocol.depths_m == pytest.approx([1e-4, 3e-4, 4e-4])


def test_round_trip_through_dict_and_toml(tmp_path):
    study = load_study(SCENE)
    record = study.to_dict()
    assert study_from_dict(record).to_dict() == record
    rewritten = write(tmp_path, tomli_w.dumps(record))
    assert load_study(rewritten).to_dict() == record


# (replace this, with this, key path named, value named)
BAD_INPUTS = [
    pytest.param("C10_Pa = 287.5", "C10_Pa = -287.5", "material.C10_Pa", "-287.5", id="material"),
    pytest.param(
        "thickness_m = 0.01",
        'thickness_m = "1 cm"',
        "specimen.thickness_m",
        "'1 cm'",
        id="wrong-type",
    ),
    pytest.param(
        "thickness_m = 0.01", "thickness_m = 0.0", "specimen.thickness_m", "0.0", id="zero-size"
    ),
    pytest.param(
        "radius_m = 0.001", "radius_m = -0.001", "indenter.radius_m", "-0.001", id="negative-radius"
    ),
    pytest.param(
        "steps = 4", "steps = 4\nstep_size_m = 1e-4", "protocol.step_size_m", None, id="unknown-key"
    ),
    pytest.param(
        "[material]", "[materials]\nx = 1\n[material]", "materials", None, id="unknown-table"
    ),
    pytest.param("width_m = 0.02\n", "", "specimen.width_m", None, id="missing-key"),
    pytest.param(
        'kind = "flat_punch"', 'kind = "sphere"', "indenter.kind", "'sphere'", id="bad-choice"
    ),
    pytest.param("steps = 4", "steps = 4.5", "protocol.steps", "4.5", id="float-for-int"),
    pytest.param("steps = 4", "steps = true", "protocol.steps", "True", id="bool-for-int"),
    pytest.param(
        "schema_version = 1", "schema_version = 7", "schema_version", "7", id="schema-version"
    ),
    pytest.param(
        "max_depth_m = 0.0005",
        "max_depth_m = 0.02",
        "protocol.max_depth_m",
        "0.02",
        id="deeper-than-thick",
    ),
    pytest.param(
        "width_m = 0.02",
        "width_m = 0.0015",
        "specimen.width_m",
        "0.0015",
        id="probe-wider-than-block",
    ),
    pytest.param(
        "max_depth_m = 0.0005\nsteps = 4",
        "depths_m = [2e-4, 1e-4]",
        "protocol.depths_m",
        "[0.0002, 0.0001]",
        id="depths-not-increasing",
    ),
    pytest.param(
        "steps = 4", "steps = 4\ndepths_m = [1e-4]", "protocol", None, id="two-protocol-forms"
    ),
    pytest.param(
        "thickness_m = 0.01",
        "thickness_m = 0.01\nsize_near_m = 0.002",
        "specimen.size_near_m",
        "0.002",
        id="near-coarser-than-probe",
    ),
    pytest.param(
        "width_m = 0.02",
        "width_m = 0.02\ngrowth = 0.8",
        "specimen.growth",
        "0.8",
        id="shrinking-growth",
    ),
    pytest.param(
        "width_m = 0.02",
        'width_m = 0.02\nmesher = "octree"',
        "specimen.mesher",
        "'octree'",
        id="unknown-mesher",
    ),
    pytest.param(
        "width_m = 0.02",
        "width_m = 0.02\nradius_m = 0.01",
        "specimen.radius_m",
        "0.01",
        id="disc-key-on-block",
    ),
    pytest.param(
        "[material]",
        '[solver]\ndevice = "gpu"\n[material]',
        "solver.device",
        "'gpu'",
        id="bad-device",
    ),
    pytest.param(
        "[material]",
        '[solver]\nnonlinear_elimination = "yes"\n[material]',
        "solver.nonlinear_elimination",
        "'yes'",
        id="elimination-not-boolean",
    ),
    pytest.param(
        "[material]",
        '[solver]\npredictor = "parabolic"\n[material]',
        "solver.predictor",
        "'parabolic'",
        id="unknown-predictor",
    ),
    pytest.param(
        "[material]",
        "[solver]\ndamping = 1\n[material]",
        "solver.damping",
        "1",
        id="damping-not-boolean",
    ),
]


@pytest.mark.parametrize(("old", "new", "key_path", "value"), BAD_INPUTS)
def test_bad_input_names_file_line_key_and_value(tmp_path, old, new, key_path, value):
    assert old in MINIMAL
    text = MINIMAL.replace(old, new, 1)
    path = write(tmp_path, text)
    with pytest.raises(InputError) as caught:
        load_study(path)
    message = str(caught.value)
    assert str(path) in message
    assert key_path in message
    if value is not None:
        assert value in message
    key = key_path.rpartition(".")[2]
    for fragment in (f"{key} =", f"[{key}]"):
        if fragment in text:
            assert caught.value.line == line_of(text, fragment)
            break
    else:
        assert caught.value.line is not None  # the line of the table that lacks the key


def test_toml_syntax_error_names_the_line(tmp_path):
    text = MINIMAL.replace("radius_m = 0.001", "radius_m = 0.001 m")
    with pytest.raises(InputError) as caught:
        load_study(write(tmp_path, text))
    assert caught.value.line == line_of(text, "radius_m = 0.001 m")
    assert "study.toml" in str(caught.value)


def test_missing_file(tmp_path):
    with pytest.raises(InputError, match="not found"):
        load_study(tmp_path / "nope.toml")


def test_study_from_dict_rejects_non_table():
    record = load_study(SCENE).to_dict()
    record["specimen"] = 3
    with pytest.raises(InputError, match="specimen: must be a table"):
        study_from_dict(record)


def test_solver_choices_are_the_solvers_own():
    """The study module keeps its own copies of the solver's choices (so that reading a study
    does not start Warp): they must not drift apart."""
    from warptissue import study
    from warptissue.fem import assembly, solvers

    assert study.LINEAR_SOLVERS == solvers.LINEAR_SOLVERS
    assert study.PREDICTORS == solvers.PREDICTORS
    assert study.FORMULATIONS == assembly.FORMULATIONS


def test_extrapolated_predictor_is_read_and_written(tmp_path):
    path = write(
        tmp_path,
        MINIMAL.replace("[material]", '[solver]\npredictor = "extrapolated"\n[material]', 1),
    )
    study = load_study(path)
    assert study.solver.predictor == "extrapolated"
    assert study.to_dict()["solver"]["predictor"] == "extrapolated"
