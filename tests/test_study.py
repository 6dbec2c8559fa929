"""Tests of warptissue.study: loading, defaults, round trips and every class of bad input."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import tomli_w

from warptissue.errors import InputError
from warptissue.fem.solvers import NewtonOptions
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


def test_bundled_scene_loads_with_the_papers_values():
    study = load_study(SCENE)
    assert study.schema_version == SCHEMA_VERSION
    # Kim et al.: a 2 mm DIAMETER probe, so the radius is 1 mm.
    assert study.indenter.radius_m == pytest.approx(1.0e-3)
    assert study.indenter.kind == "flat_punch"
    assert study.indenter.contact == "bonded"
    # Ahn & Kim, Table 2: C10 = 287.5 Pa; nearly incompressible with K / mu = 1000.
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
    assert study.solver.options == NewtonOptions()
    options = study.solver.options
    assert options.linear_solver == "auto"
    assert options.tolerance == pytest.approx(1e-9)
    assert options.max_newton_iterations == 25
    assert options.max_cutbacks == 8
    assert options.nonlinear_elimination is True
    assert options.predictor == "linearized"
    assert options.damping is True


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
    with pytest.raises(InputError, match="a folder, not a study file"):
        load_study(tmp_path)


def test_a_binary_file_is_refused_with_its_line(tmp_path):
    path = tmp_path / "study.toml"
    path.write_bytes(b"schema_version = 1\n\xff\xfe\n")
    with pytest.raises(InputError, match="not a text") as caught:
        load_study(path)
    assert caught.value.line == 2 and caught.value.path == path


@pytest.mark.parametrize("name", ["../../elsewhere", "a/b", "..", " "])
def test_a_name_that_is_not_a_plain_folder_name_is_refused(tmp_path, name):
    """The name makes the default output folder runs/<name>: no path may escape runs/."""
    text = MINIMAL.replace("schema_version = 1", f"schema_version = 1\nname = {name!r}")
    with pytest.raises(InputError, match="must be a plain name") as caught:
        load_study(write(tmp_path, text))
    assert caught.value.line == line_of(text, "name =")


def test_too_many_load_steps_are_refused(tmp_path):
    """Every converged state is kept in memory: a billion steps is refused at once."""
    text = MINIMAL.replace("steps = 4", "steps = 1000000000")
    with pytest.raises(InputError, match="at most 10000"):
        load_study(write(tmp_path, text))


def test_study_from_dict_rejects_non_table():
    record = load_study(SCENE).to_dict()
    record["specimen"] = 3
    with pytest.raises(InputError, match="specimen: must be a table"):
        study_from_dict(record)


def test_reading_a_study_does_not_start_warp():
    """The [solver] table reads into the solver's own NewtonOptions; importing the solver's
    modules must not initialize Warp (which takes seconds and prints a banner)."""
    code = (
        "import warp._src.context as context\n"
        "from warptissue.study import load_study\n"
        f"study = load_study({str(SCENE)!r})\n"
        "assert type(study.solver.options).__name__ == 'NewtonOptions'\n"
        "print(context.runtime is None)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "True"


def test_solver_table_keys_are_the_options_names(tmp_path):
    """Every NewtonOptions field is a [solver] key of the same name, read and echoed."""
    values = {
        "linear_solver": "superlu",
        "tolerance": 1e-8,
        "max_newton_iterations": 12,
        "max_cutbacks": 3,
        "nonlinear_elimination": False,
        "predictor": "extrapolated",
        "damping": False,
    }
    assert set(values) == set(NewtonOptions.keys())
    record = load_study(SCENE).to_dict()
    record["solver"].update(values)
    study = study_from_dict(record)
    assert study.solver.options == NewtonOptions(**values)
    assert study.to_dict()["solver"] == dict(values, device="auto", formulation="mixed")
    path = write(tmp_path, tomli_w.dumps(study.to_dict()))
    assert load_study(path).solver == study.solver


def test_extrapolated_predictor_is_read_and_written(tmp_path):
    path = write(
        tmp_path,
        MINIMAL.replace("[material]", '[solver]\npredictor = "extrapolated"\n[material]', 1),
    )
    study = load_study(path)
    assert study.solver.options.predictor == "extrapolated"
    assert study.to_dict()["solver"]["predictor"] == "extrapolated"


def test_a_typo_in_a_required_material_key_is_named_with_the_close_match(tmp_path):
    """``C10_pa`` was reported as a missing ``C10_Pa``, without naming the key written."""
    text = MINIMAL.replace("C10_Pa = 287.5", "C10_pa = 287.5")
    with pytest.raises(InputError) as caught:
        load_study(write(tmp_path, text))
    message = str(caught.value)
    assert "material.C10_pa" in message and "did you mean 'C10_Pa'?" in message
    assert caught.value.line == line_of(text, "C10_pa")


TYPOS = [
    pytest.param("radius_m = 0.001", "radius_mm = 0.001", "indenter.radius_mm", "radius_m"),
    pytest.param("steps = 4", "steps = 4\nstep = 2", "protocol.step", "steps"),
    pytest.param("[material]", "[solvr]\ndamping = false\n[material]", "solvr", "solver"),
    pytest.param(
        "[material]",
        "[solver]\nmax_newton_iteration = 5\n[material]",
        "solver.max_newton_iteration",
        "max_newton_iterations",
    ),
    pytest.param("width_m = 0.02", "width_m = 0.02\nGrowth = 1.3", "specimen.Growth", "growth"),
]


@pytest.mark.parametrize(("old", "new", "key_path", "meant"), TYPOS)
def test_unknown_keys_are_named_with_a_suggestion(tmp_path, old, new, key_path, meant):
    text = MINIMAL.replace(old, new, 1)
    with pytest.raises(InputError) as caught:
        load_study(write(tmp_path, text))
    message = str(caught.value)
    assert key_path in message and f"did you mean {meant!r}?" in message
    key = key_path.rpartition(".")[2]
    fragment = f"[{key}]" if "." not in key_path else f"{key} ="
    assert caught.value.line == line_of(text, fragment)


def test_a_close_choice_is_suggested(tmp_path):
    text = MINIMAL.replace("[material]", '[solver]\nformulation = "mixd"\n[material]', 1)
    with pytest.raises(InputError, match="did you mean 'mixed'"):
        load_study(write(tmp_path, text))


def test_a_length_with_a_unit_asks_for_si_metres(tmp_path):
    text = MINIMAL.replace("radius_m = 0.001", 'radius_m = "1 mm"')
    with pytest.raises(InputError, match="number in metres") as caught:
        load_study(write(tmp_path, text))
    assert caught.value.line == line_of(text, "radius_m =")


def test_numpy_values_are_read_and_printed_as_plain_numbers():
    """A study built by a script from NumPy values: read as numbers, and errors print the
    value as a number, never as ``np.float64(...)``."""
    record = load_study(SCENE).to_dict()
    record["protocol"] = {"max_depth_m": np.float64(4e-4), "steps": np.int64(4)}
    record["specimen"]["growth"] = np.float32(1.25)
    study = study_from_dict(record)
    assert study.protocol.depths_m == pytest.approx([1e-4, 2e-4, 3e-4, 4e-4])
    assert type(study.to_dict()["protocol"]["depths_m"][0]) is float
    for table, key, value in (
        ("material", "C10_Pa", np.float64(-1.19)),
        ("indenter", "radius_m", np.float64(-1.19)),
        ("solver", "max_cutbacks", np.int64(-1)),
        ("specimen", "thickness_m", np.array([1.19])),
    ):
        bad = load_study(SCENE).to_dict()
        bad[table][key] = value
        with pytest.raises(InputError) as caught:
            study_from_dict(bad)
        message = str(caught.value)
        assert f"{table}.{key}" in message and "np." not in message and "array(" not in message
        assert str(value.tolist()) in message


def test_tet4_with_the_mixed_formulation_is_refused_at_load(tmp_path):
    """It used to pass the study and fail after meshing, naming a 'column'."""
    text = MINIMAL.replace("thickness_m = 0.01", 'thickness_m = 0.01\nelement = "TET4"')
    with pytest.raises(InputError, match="formulation 'mixed' needs element 'TET10'") as caught:
        load_study(write(tmp_path, text))
    assert caught.value.line == line_of(text, "element =")
    text += '[solver]\nformulation = "mixed"\n'
    with pytest.raises(InputError, match="solver.formulation") as caught:
        load_study(write(tmp_path, text))
    assert caught.value.line == line_of(text, "formulation =")
    study = load_study(write(tmp_path, text.replace('"mixed"', '"displacement"')))
    assert study.specimen.element == "TET4"


def test_every_key_is_in_the_study_file_reference():
    """docs/study-files.md's table lists every key a study has, under the same names."""
    page = (REPOSITORY / "docs" / "study-files.md").read_text(encoding="utf-8")
    documented = set(re.findall(r"^\| `([A-Za-z0-9_]+)` \|", page, flags=re.MULTILINE))
    tables = set(re.findall(r"^\| \*\*`\[([a-z]+)\]`\*\* \|", page, flags=re.MULTILINE))
    record = load_study(SCENE).to_dict()
    keys = {key for key, value in record.items() if not isinstance(value, dict)}
    for table, values in record.items():
        if isinstance(values, dict) and table != "material":
            keys |= set(values)
    keys |= {"radius_m", "depths_m", "max_depth_m", "steps", "model"}
    assert keys <= documented, sorted(keys - documented)
    assert {k for k, v in record.items() if isinstance(v, dict)} <= tables
    assert set(NewtonOptions.keys()) <= documented
