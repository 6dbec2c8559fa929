"""Tests of warptissue.study: loading, defaults, round trips and every class of bad input."""

from __future__ import annotations

import re
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import tomli_w

from warptissue.acquisition.conditioning import condition_for_fit
from warptissue.errors import InputError
from warptissue.fem.newton import NewtonOptions
from warptissue.fit.punch import hayes_kappa
from warptissue.fit.start import record_youngs_modulus_Pa, start_values_from_record
from warptissue.io import read_experiment_csv, write_csv
from warptissue.lsq import engine
from warptissue.mesh import size_near_for_force_accuracy
from warptissue.simulate import size_near_reason
from warptissue.study import (
    CONTACT_RADIUS_SAFETY,
    FIT_METHODS,
    SCHEMA_VERSION,
    load_study,
    save_study,
    study_from_dict,
)

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
    assert study.schema_version == 1  # a version-1 file loads as it is, and stays version 1
    assert study.data == () and study.fit is None
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
    assert study.solver.contact_integration == "nodes"
    options = study.solver.options
    assert options.linear_solver == "auto"
    assert options.tolerance == pytest.approx(1e-9)
    assert options.max_newton_iterations == 25
    assert options.max_cutbacks == 8
    assert options.nonlinear_elimination == "auto"
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
        'kind = "flat_punch"', 'kind = "cone"', "indenter.kind", "'cone'", id="bad-choice"
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
        "steps = 4",
        'steps = 4\nspacing = "square"',
        "protocol.spacing",
        "'square'",
        id="unknown-spacing",
    ),
    pytest.param(
        "max_depth_m = 0.0005\nsteps = 4",
        'depths_m = [1e-4, 2e-4]\nspacing = "contact_radius"',
        "protocol.spacing",
        None,
        id="spacing-of-a-depth-list",
    ),
    pytest.param(
        "thickness_m = 0.01",
        "thickness_m = 0.01\nsize_near_m = 0.002",
        "specimen.size_near_m",
        "0.002",
        id="near-coarser-than-probe",
    ),
    pytest.param(
        "thickness_m = 0.01",
        "thickness_m = 0.01\nsize_near_m = 0.0002\nforce_accuracy = 0.02",
        "specimen.force_accuracy",
        "0.02",
        id="accuracy-and-near-size",
    ),
    pytest.param(
        "thickness_m = 0.01",
        "thickness_m = 0.01\nforce_accuracy = 0.001",
        "specimen.force_accuracy",
        "0.001",
        id="accuracy-below-measured",
    ),
    pytest.param(
        "thickness_m = 0.01",
        "thickness_m = 0.01\nforce_accuracy = 0.02\nsize_far_m = 0.0005",
        "specimen.force_accuracy",
        "0.02",
        id="accuracy-coarser-than-far",
    ),
    pytest.param(
        "thickness_m = 0.01",
        'thickness_m = 0.01\nforce_accuracy = 0.02\nelement = "TET4"',
        "specimen.element",
        "'TET4'",
        id="accuracy-for-tet4",
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
    pytest.param(
        "[material]",
        '[solver]\ncontact_integration = "surfaces"\n[material]',
        "solver.contact_integration",
        "'surfaces'",
        id="unknown-contact-integration",
    ),
    pytest.param(
        "[material]",
        "[solver]\ncontact_integration = 1\n[material]",
        "solver.contact_integration",
        "1",
        id="contact-integration-not-a-string",
    ),
]


def assert_names_key_and_line(error: InputError, text: str, path: Path, key_path: str, value):
    """``error`` names the file, the key path, the value and the line of the key (or of a
    table of that name; a missing key: some line). Keys of ``[a.b]`` tables are looked up
    below their table's header."""
    message = str(error)
    assert str(path) in message and key_path in message, message
    if value is not None:
        assert value in message, message
    table, _, key = key_path.rpartition(".")
    header = f"[{table}]" if table.count(".") else None  # [fit.start], [fit.bounds]
    offset = line_of(text, header) if header and header in text else 0
    below = "\n".join(text.splitlines()[offset:])
    for fragment in (f"{key} =", f"[{key_path}]"):
        if fragment in below:
            assert error.line == offset + line_of(below, fragment)
            break
    else:
        assert error.line is not None  # the line of the table that lacks the key


@pytest.mark.parametrize(("old", "new", "key_path", "value"), BAD_INPUTS)
def test_bad_input_names_file_line_key_and_value(tmp_path, old, new, key_path, value):
    assert old in MINIMAL
    text = MINIMAL.replace(old, new, 1)
    path = write(tmp_path, text)
    with pytest.raises(InputError) as caught:
        load_study(path)
    assert_names_key_and_line(caught.value, text, path, key_path, value)


@pytest.mark.parametrize(
    ("old", "new", "key_path", "value"),
    [
        pytest.param(
            'kind = "flat_punch"',
            'kind = "flat_punch"\nedge_radius_m = 0.0001',
            "specimen.force_accuracy",
            "0.02",
            id="rounded-punch",
        ),
        pytest.param(
            'kind = "flat_punch"\nradius_m = 0.001',
            'kind = "sphere"\nradius_m = 0.001',
            "specimen.force_accuracy",
            "0.02",
            id="sphere",
        ),
        pytest.param(
            "[material]",
            '[solver]\nformulation = "displacement"\n[material]',
            "solver.formulation",
            "'displacement'",
            id="displacement-formulation",
        ),
    ],
)
def test_a_force_accuracy_outside_its_measurement_is_refused(tmp_path, old, new, key_path, value):
    """specimen.force_accuracy was measured for the sharp bonded punch on TET10 mixed meshes."""
    text = MINIMAL.replace("thickness_m = 0.01", "thickness_m = 0.01\nforce_accuracy = 0.02")
    text = text.replace(old, new, 1)
    path = write(tmp_path, text)
    with pytest.raises(InputError) as caught:
        load_study(path)
    assert_names_key_and_line(caught.value, text, path, key_path, value)
    assert "\n" not in str(caught.value)


@pytest.mark.parametrize("mesher", ["extruded", "delaunay"])
def test_a_force_accuracy_chooses_the_near_size(tmp_path, mesher):
    text = MINIMAL.replace(
        "thickness_m = 0.01", f'thickness_m = 0.01\nforce_accuracy = 0.02\nmesher = "{mesher}"'
    )
    study = load_study(write(tmp_path, text))
    expected = size_near_for_force_accuracy(0.02, probe_radius_m=0.001, mesher=mesher)
    assert study.specimen.size_near_m == pytest.approx(expected)
    assert study.specimen.force_accuracy == 0.02
    record = study.to_dict()
    assert record["specimen"]["force_accuracy"] == 0.02 and "size_near_m" not in record["specimen"]
    assert study_from_dict(record).to_dict() == record
    reason = size_near_reason(study)
    assert f"{expected:.4g}" in reason and "force_accuracy = 0.02" in reason
    assert size_near_reason(load_study(write(tmp_path, MINIMAL))) is None


def test_a_force_accuracy_beyond_its_measured_depths_is_a_warning(tmp_path):
    """Issue 36: the size rule was measured to half the probe radius; deeper it was measured
    +2.0 % off at depth / radius 0.8 for 0.01. A study deeper than the range gets one line
    naming specimen.force_accuracy, the depth and the range; one within it, none."""
    import warnings

    accurate = MINIMAL.replace("thickness_m = 0.01", "thickness_m = 0.01\nforce_accuracy = 0.01")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_study(write(tmp_path, accurate))  # 0.5 mm = 0.5 probe radii: within
    deep = accurate.replace("max_depth_m = 0.0005", "max_depth_m = 0.0008")
    with pytest.warns(UserWarning) as caught:
        load_study(write(tmp_path, deep))
    (message,) = [str(w.message) for w in caught]
    assert "\n" not in message and "study.toml" in message
    assert "specimen.force_accuracy = 0.01" in message
    assert "0.0008 m (0.8 probe radii)" in message and "up to 0.5 probe radii" in message
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_study(write(tmp_path, deep.replace("force_accuracy = 0.01", "size_near_m = 2e-4")))


def test_a_sphere_s_refined_zone_follows_the_contact_radius_of_the_deepest_depth(tmp_path):
    """Issue 36: a sphere's refined zone was its whole r <= R cap. It is now
    CONTACT_RADIUS_SAFETY times Hertz's contact radius a = sqrt(R d) at the study's deepest
    depth (the protocol's or the records'), at most R, and the default near size a quarter of
    it; a flat punch keeps its radius."""
    sphere = MINIMAL.replace(
        'kind = "flat_punch"\nradius_m = 0.001', 'kind = "sphere"\nradius_m = 0.002'
    )
    study = load_study(write(tmp_path, sphere))  # d = 0.5 mm: a = 1 mm
    assert CONTACT_RADIUS_SAFETY == 1.5 and study.deepest_depth_m == 5e-4
    assert study.mesh_probe_radius_m == pytest.approx(1.5 * np.sqrt(0.002 * 5e-4), rel=1e-12)
    assert study.specimen.size_near_m == pytest.approx(study.mesh_probe_radius_m / 4.0)
    shallow = load_study(
        write(tmp_path, sphere.replace("max_depth_m = 0.0005", "max_depth_m = 2e-5"))
    )
    assert shallow.mesh_probe_radius_m == pytest.approx(1.5 * np.sqrt(0.002 * 2e-5), rel=1e-12)
    deep = load_study(
        write(tmp_path, sphere.replace("max_depth_m = 0.0005", "max_depth_m = 0.002"))
    )
    assert deep.mesh_probe_radius_m == 0.002  # 1.5 a = 3 mm: the cap R
    punch = load_study(write(tmp_path, MINIMAL))
    assert punch.mesh_probe_radius_m == 0.001 and punch.specimen.size_near_m == 0.00025
    # A fit's records count: the study's deepest depth is its deepest record's.
    record = tmp_path / "deep.csv"
    write_csv(
        record,
        {
            "time_s": np.linspace(0.0, 1.0, 11),
            "displacement_m": np.linspace(0.0, 8e-4, 11),
            "force_N": np.linspace(0.0, 1e-3, 11),
        },
    )
    fitted = sphere.replace("schema_version = 1", "schema_version = 2") + (
        '\n[[data]]\nfile = "deep.csv"\n\n[fit]\nfree = ["C10_Pa"]\n'
    )
    study = load_study(write(tmp_path, fitted))
    assert study.deepest_depth_m == pytest.approx(8e-4)
    assert study.mesh_probe_radius_m == pytest.approx(1.5 * np.sqrt(0.002 * 8e-4), rel=1e-12)


def test_a_sphere_wider_than_the_specimen_is_refused(tmp_path):
    """Issue 44: a sphere's refined zone is its contact's (1.5 sqrt(R d)), so a sphere of
    15 mm on a block 20 mm wide passed the zone's check and loaded; its radius must be less
    than the half width (docs/study-files.md)."""
    text = MINIMAL.replace(
        'kind = "flat_punch"\nradius_m = 0.001', 'kind = "sphere"\nradius_m = 0.015'
    )
    path = write(tmp_path, text)
    with pytest.raises(InputError) as caught:
        load_study(path)
    assert_names_key_and_line(caught.value, text, path, "specimen.width_m", "0.02")
    assert "indenter.radius_m (0.015 m)" in str(caught.value)
    assert "half the width (0.01 m)" in str(caught.value)
    assert load_study(write(tmp_path, text.replace("0.015", "0.009"))).indenter.radius_m == 0.009


def test_a_near_size_beyond_a_sphere_s_zone_names_the_zone_and_its_values(tmp_path):
    """Issue 44: the message said "must not exceed the probe radius (0.000335 m)" for a
    probe of radius 1 mm; it names the zone 1.5 sqrt(R d) and R and d."""
    text = MINIMAL.replace('kind = "flat_punch"', 'kind = "sphere"').replace(
        "max_depth_m = 0.0005", "max_depth_m = 5e-5"
    )
    text = text.replace("thickness_m = 0.01", "thickness_m = 0.01\nsize_near_m = 0.0005")
    path = write(tmp_path, text)
    with pytest.raises(InputError) as caught:
        load_study(path)
    assert_names_key_and_line(caught.value, text, path, "specimen.size_near_m", "0.0005")
    message = str(caught.value)
    assert "1.5 sqrt(R d) = 0.00033541 m" in message, message
    assert "indenter.radius_m = 0.001 m" in message and "deepest depth = 5e-05 m" in message
    punch = MINIMAL.replace("thickness_m = 0.01", "thickness_m = 0.01\nsize_near_m = 0.002")
    with pytest.raises(InputError, match=r"must not exceed the probe radius \(0.001 m\)"):
        load_study(write(tmp_path, punch))


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


def test_reading_a_study_does_not_start_warp(tmp_path):
    """The [solver] table reads into the solver's own NewtonOptions; importing the solver's
    modules must not initialize Warp (which takes seconds and prints a banner). Run outside
    the checkout, whose warptissue/ has no kernels/ (the installed package has)."""
    code = (
        "import warp._src.context as context\n"
        "from warptissue.study import load_study\n"
        f"study = load_study({str(SCENE)!r})\n"
        "assert type(study.solver.options).__name__ == 'NewtonOptions'\n"
        "print(context.runtime is None)\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path
    )
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
        "reuse_factorization": False,
    }
    assert set(values) == set(NewtonOptions.keys())
    record = load_study(SCENE).to_dict()
    record["solver"].update(values)
    study = study_from_dict(record)
    assert study.solver.options == NewtonOptions(**values)
    assert study.to_dict()["solver"] == dict(
        values,
        device="auto",
        formulation="mixed",
        penalty_factor=1000.0,
        contact_integration="nodes",
    )
    path = write(tmp_path, tomli_w.dumps(study.to_dict()))
    assert load_study(path).solver == study.solver


def test_surface_contact_integration_is_read_written_and_reaches_the_problem(tmp_path):
    """``[solver] contact_integration = "surface"`` selects the contact integrated at the
    surface's quadrature points (warptissue.fem.surface_contact): read, echoed by to_dict,
    read back from the TOML it writes, and passed to the indentation problem, whose rigid
    contact then carries a quadrature (a coarse block under a sphere: meshing and the
    problem's set-up, no solve)."""
    from warptissue.simulate import build_mesh, build_problem

    text = MINIMAL.replace('kind = "flat_punch"', 'kind = "sphere"').replace(
        "[material]", '[solver]\ncontact_integration = "surface"\n[material]', 1
    )
    text = text.replace("thickness_m = 0.01", "thickness_m = 0.01\nsize_near_m = 0.001", 1)
    study = load_study(write(tmp_path, text))
    assert study.solver.contact_integration == "surface"
    assert study.to_dict()["solver"]["contact_integration"] == "surface"
    again = load_study(write(tmp_path, tomli_w.dumps(study.to_dict()), name="again.toml"))
    assert again.solver == study.solver
    problem = build_problem(study, build_mesh(study))
    assert problem.contact_integration == "surface"
    assert problem.rigid_contact().quadrature is not None
    nodal = load_study(write(tmp_path, text.replace('"surface"', '"nodes"'), name="n.toml"))
    assert build_problem(nodal, build_mesh(nodal)).rigid_contact().quadrature is None


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
    """It used to pass the study and fail after meshing, naming a 'column'. A TET4 study
    that names no formulation (as version-1 files did) takes 'displacement' and is told
    where that locks."""
    text = MINIMAL.replace("thickness_m = 0.01", 'thickness_m = 0.01\nelement = "TET4"')
    with pytest.warns(UserWarning, match="'displacement' formulation is used, which locks"):
        study = load_study(write(tmp_path, text))
    assert study.solver.formulation == "displacement"
    saved = save_study(study, tmp_path / "saved" / "study.toml")  # explicit from now on
    assert 'formulation = "displacement"' in saved.read_text(encoding="utf-8")
    compressible = text.replace("bulk_modulus_Pa = 575000.0", "bulk_modulus_Pa = 2000.0")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # K/mu = 3.5: nothing locks, nothing is said
        assert load_study(write(tmp_path, compressible)).solver.formulation == "displacement"
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
    # Version 2: every [[data]] and [fit] key, and the tables [[data]], [fit.start], [fit.bounds].
    fit_record = load_study(FIT_SCENE).to_dict()
    v2_keys = set(fit_record["data"][0]) | set(fit_record["fit"]) - {"start", "bounds"}
    v2_keys |= {"contact_position_m", "offset", "window_s", "relative_floor_N", "stop_r_squared"}
    v2_keys |= {"contact_point", "depth_offset_m"}
    assert v2_keys <= documented, sorted(v2_keys - documented)
    for header in ("[[data]]", "[fit]", "[fit.start]", "[fit.bounds]"):
        assert f"| **`{header}`** |" in page, header


# --- Version 2: [[data]] and [fit] -------------------------------------------------------

FIT_SCENE = REPOSITORY / "scenes" / "liver_fit.toml"
TRUE_YOUNGS_PA = 1725.0
"""E of the synthetic records: 3 mu with mu = 2 C10 = 575 Pa (Ahn & Kim's C10)."""

FIT_TABLES = """\
[[data]]
file = "record.csv"
contact = "auto"
keep_depth_m = 0.0004

[fit]
free = ["C10_Pa"]
method = "salm"
"""
V2 = MINIMAL.replace("schema_version = 1", "schema_version = 2") + "\n" + FIT_TABLES


def synthetic_record(
    path: Path, *, youngs_Pa: float = TRUE_YOUNGS_PA, nu: float = 0.4995, seed: int = 1
) -> Path:
    """A probe that rests 1 s above the surface, then moves 0.5 mm/s through a 0.2 mm air gap
    to 0.5 mm below the surface of MINIMAL's layer (a = 1 mm, h = 10 mm), 100 Hz; the force is
    Sneddon's with the Hayes factor, plus a 3 mN offset and 2 uN of noise."""
    rng = np.random.default_rng(seed)
    time = np.arange(0.0, 2.4, 0.01)
    position = np.clip(time - 1.0, 0.0, None) * 5e-4
    depth = np.clip(position - 2e-4, 0.0, None)
    stiffness = 2 * 1e-3 * youngs_Pa * hayes_kappa(0.1, nu) / (1 - nu**2)
    force = 3e-3 + stiffness * depth + rng.normal(0.0, 2e-6, time.size)
    write_csv(path, {"time_s": time, "displacement_m": position, "force_N": force})
    return path


def write_v2(tmp_path: Path, text: str = V2) -> Path:
    synthetic_record(tmp_path / "record.csv")
    return write(tmp_path, text)


def test_the_example_fit_study_loads_with_three_conditioned_records():
    study = load_study(FIT_SCENE)
    assert study.schema_version == SCHEMA_VERSION == 2
    assert [r.file for r in study.data] == [
        "data/liver_ramp_hold.csv",
        "data/liver_ramp_medium.csv",
        "data/liver_ramp_slow.csv",
    ]
    for record in study.data:
        assert record.path.is_file() and record.contact == "auto"
        # The probe starts 0.5 mm above the surface (the records' air gap): found to 0.05 mm.
        assert record.conditioning["contact"]["position_m"] == pytest.approx(5e-4, abs=5e-5)
        # The whole record is kept: the 4 mm ramp below the contact and the hold.
        assert 3.95e-3 < record.displacement_m.max() <= 4.05e-3
        assert np.all(np.diff(record.displacement_m) >= -1e-9)
        assert record.time_s.shape == record.force_N.shape == record.displacement_m.shape
    # Ahn & Kim's two stages: the Prony terms from the relaxation, then C10 by inverse FE.
    assert study.fit.free == ("C10_Pa", "g1", "g2", "tau1_s", "tau2_s")
    assert study.fit.strategy == "two_stage" and study.fit.time_steps == 32
    assert study.fit.bounds == {"C10_Pa": (1.0, 1e5)}
    assert study.fit.start == {} and study.fit.start_from == "record"
    assert study.fit.stop_r_squared is None
    # The records' stiffness is the relaxing liver's (E = 1725 Pa instantaneous, 507 Pa at
    # equilibrium), so the start lies between mu/2 of the two.
    start = start_values_from_record(study)
    assert 507 / 6 < start["C10_Pa"] < 1725 / 6


def test_a_record_is_conditioned_by_the_same_code_as_the_fit_command(tmp_path):
    study = load_study(write_v2(tmp_path))
    raw = np.genfromtxt(tmp_path / "record.csv", delimiter=",", names=True)
    same = condition_for_fit(
        {name: raw[name] for name in ("time_s", "displacement_m", "force_N")},
        contact="auto",
        keep_depth_m=4e-4,
    )
    record = study.data[0]
    np.testing.assert_array_equal(record.displacement_m, same.displacement_m)
    np.testing.assert_array_equal(record.force_N, same.force_N)
    assert record.conditioning == same.summary
    assert record.conditioning["force_offset_N"] == pytest.approx(3e-3, abs=1e-5)


def test_start_value_from_a_sneddon_hayes_record(tmp_path):
    """A record made from E = 1725 Pa by the same formula: C10 = mu / 2 = E / 6 / (1 + nu)
    * 3 back within 1 % (the error left is the contact detection's and the noise's)."""
    study = load_study(write_v2(tmp_path))
    nu = study.material.small_strain_equivalent()[1]
    assert record_youngs_modulus_Pa(study, study.data[0]) == pytest.approx(TRUE_YOUNGS_PA, rel=1e-2)
    expected_c10 = TRUE_YOUNGS_PA / (2 * (1 + nu)) / 2
    assert start_values_from_record(study) == {"C10_Pa": pytest.approx(expected_c10, rel=1e-2)}


def _fit_study(tmp_path: Path, material: str, free: str, extra: str = "") -> object:
    """V2 with another material and free list; ``extra`` keys go into [fit], tables last."""
    text = V2.replace('model = "neo_hookean"\nC10_Pa = 287.5\nbulk_modulus_Pa = 575000.0', material)
    if extra.startswith("["):
        text, extra = text + extra + "\n", ""
    return load_study(
        write_v2(tmp_path, text.replace('free = ["C10_Pa"]', f"free = {free}\n{extra}"))
    )


def test_start_rule_of_every_model(tmp_path):
    """One common factor on the free parameters that set mu0, so that mu0 is the record's."""
    nu = 0.4995
    mu = TRUE_YOUNGS_PA / (2 * (1 + nu))
    mr = 'model = "mooney_rivlin"\nC10_Pa = 300.0\nC01_Pa = 100.0\nbulk_modulus_Pa = 575000.0'
    both = start_values_from_record(_fit_study(tmp_path, mr, '["C10_Pa", "C01_Pa"]'))
    assert both["C10_Pa"] == pytest.approx(3 * both["C01_Pa"])  # the [material] ratio
    assert 2 * (both["C10_Pa"] + both["C01_Pa"]) == pytest.approx(mu, rel=2e-2)
    one = start_values_from_record(_fit_study(tmp_path, mr, '["C10_Pa"]'))
    assert one["C10_Pa"] == pytest.approx(mu / 2 - 100.0, rel=3e-2)
    ogden = 'model = "ogden"\nmu1_Pa = 400.0\nalpha1 = 5.0\nbulk_modulus_Pa = 575000.0'
    start = start_values_from_record(_fit_study(tmp_path, ogden, '["mu1_Pa", "alpha1"]'))
    assert start == {"mu1_Pa": pytest.approx(mu, rel=2e-2), "alpha1": 5.0}
    yeoh = 'model = "yeoh"\nC10_Pa = 300.0\nC20_Pa = 50.0\nC30_Pa = 5.0\nbulk_modulus_Pa = 575000.0'
    start = start_values_from_record(_fit_study(tmp_path, yeoh, '["C10_Pa", "C20_Pa"]'))
    assert start == {"C10_Pa": pytest.approx(mu / 2, rel=2e-2), "C20_Pa": 50.0}
    linear = 'model = "linear_elastic"\nyoungs_modulus_Pa = 900.0\npoissons_ratio = 0.4995'
    linear = linear.replace("0.4995", "0.49")  # below 0.5, as the linear model needs
    start = start_values_from_record(_fit_study(tmp_path, linear, '["youngs_modulus_Pa"]'))
    kappa_ratio = hayes_kappa(0.1, 0.4995) / hayes_kappa(0.1, 0.49)
    expected = TRUE_YOUNGS_PA * (1 - 0.49**2) / (1 - nu**2) * kappa_ratio
    assert start == {"youngs_modulus_Pa": pytest.approx(expected, rel=2e-2)}
    # A given start is kept; start_from = "material" takes [material]; bounds clip.
    given = _fit_study(tmp_path, mr, '["C10_Pa", "C01_Pa"]', "[fit.start]\nC01_Pa = 10.0")
    start = start_values_from_record(given)
    assert start["C01_Pa"] == 10.0 and 2 * (start["C10_Pa"] + 10.0) == pytest.approx(mu, rel=2e-2)
    kept = _fit_study(tmp_path, mr, '["C10_Pa"]', 'start_from = "material"')
    assert start_values_from_record(kept) == {"C10_Pa": 300.0}
    clipped = _fit_study(tmp_path, mr, '["C10_Pa"]', "[fit.bounds]\nC10_Pa = [150.0, 160.0]")
    assert start_values_from_record(clipped) == {"C10_Pa": 160.0}  # mu / 2 - 100 = 187 Pa


def test_a_start_that_scaling_cannot_reach_is_refused(tmp_path):
    mr = 'model = "mooney_rivlin"\nC10_Pa = 300.0\nC01_Pa = 1000.0\nbulk_modulus_Pa = 575000.0'
    study = _fit_study(tmp_path, mr, '["C10_Pa"]')
    with pytest.raises(InputError, match=r"fit.free: scaling C10_Pa cannot reach"):
        start_values_from_record(study)


def test_start_value_from_a_finite_element_record(tmp_path):
    """Independent check: a record made by the FE (the bundled slab, C10 = 287.5 Pa, to
    0.1 mm = a / 10 in two steps) gives C10 back within 5 %. What is left is the
    small-depth approximation's error: Sneddon and Hayes assume a linear, laterally infinite
    layer; the FE slab is 20 mm wide, meshed at a / 2 under the probe and nearly (K / mu =
    1000), not exactly, incompressible (measured: -3.9 %). It also runs a study written by
    save_study through `warptissue simulate` as it is."""
    from warptissue.cli import main

    record = load_study(SCENE).to_dict()
    record["schema_version"] = 2
    record["protocol"] = {"max_depth_m": 1e-4, "steps": 2}
    record["data"] = [{"file": str(write_v2(tmp_path).parent / "record.csv")}]
    record["fit"] = {"free": ["C10_Pa"]}
    study_path = save_study(study_from_dict(record), tmp_path / "sub" / "forward.toml")
    assert main(["simulate", str(study_path), "--out", str(tmp_path / "run"), "--quiet"]) == 0
    record["data"] = [{"file": str(tmp_path / "run" / "force_curve.csv")}]
    study = study_from_dict(record)
    start = start_values_from_record(study)
    assert start["C10_Pa"] == pytest.approx(287.5, rel=0.05)


def test_round_trip_of_a_fit_study_to_another_folder(tmp_path):
    study = load_study(FIT_SCENE)
    record = study.to_dict()
    assert study_from_dict(record, path=FIT_SCENE).to_dict() == record
    saved = save_study(study, tmp_path / "elsewhere" / "fitted.toml")
    again = load_study(saved)
    assert not Path(again.data[0].file).is_absolute()
    assert again.data[0].path.resolve() == study.data[0].path.resolve()
    assert again.fit == study.fit and again.material == study.material
    for old, new in zip(study.data, again.data, strict=True):
        np.testing.assert_array_equal(old.force_N, new.force_N)
    expected = dict(
        record, data=[dict(d, file=n.file) for d, n in zip(record["data"], again.data, strict=True)]
    )
    assert again.to_dict() == expected
    # A study with the fitted material is written the same way.
    import dataclasses

    values = [301.0, *study.material.parameter_vector[1:]]  # C10, then the Prony terms
    fitted = dataclasses.replace(study, material=study.material.with_parameters(values))
    assert load_study(save_study(fitted, tmp_path / "f.toml")).material.elastic.C10_Pa == 301.0


def test_custom_columns_and_a_single_data_table(tmp_path):
    path = synthetic_record(tmp_path / "raw.csv")
    text = path.read_text().replace("time_s,displacement_m,force_N", "t,z_m,load_N", 1)
    path.write_text(text)
    tables = (
        '[data]\nfile = "raw.csv"\ntime_column = "t"\ndisplacement_column = "z_m"\n'
        'force_column = "load_N"\ncontact_position_m = 0.0002\noffset = "none"\n'
        "window_s = [0.0, 2.0]\n"
    )
    study = load_study(write(tmp_path, V2.replace(FIT_TABLES, tables)))
    (record,) = study.data
    assert (record.time_column, record.displacement_column, record.force_column) == (
        "t",
        "z_m",
        "load_N",
    )
    assert record.contact == pytest.approx(2e-4) and record.time_s.max() <= 2.0
    assert record.force_N[0] == pytest.approx(3e-3, abs=1e-5)  # offset = "none" keeps it
    assert study.fit is None
    assert study_from_dict(study.to_dict(), path=study.path).to_dict() == study.to_dict()


def test_fit_methods_are_the_engines():
    assert FIT_METHODS == engine.METHODS


def test_relative_paths_of_study_from_dict_follow_its_path(tmp_path):
    write_v2(tmp_path)
    data = load_study(write_v2(tmp_path)).to_dict()
    assert study_from_dict(data, path=tmp_path / "x.toml").data[0].path == tmp_path / "record.csv"
    with pytest.raises(InputError, match="experiment file not found"):
        study_from_dict(data, path=tmp_path / "sub" / "x.toml")


# (replace this in V2, with this, key path named, value named)
BAD_V2 = [
    pytest.param(
        'file = "record.csv"', 'file = "nope.csv"', "data[0].file", "nope.csv", id="no-csv"
    ),
    pytest.param('file = "record.csv"', 'file = ""', "data[0].file", "''", id="empty-file"),
    pytest.param('file = "record.csv"', "file = 3", "data[0].file", "3", id="file-not-string"),
    pytest.param(
        'file = "record.csv"',
        'file = "record.csv"\ntime_column = "t"',
        "data[0].file",
        "missing required column(s) ['t']",
        id="missing-column",
    ),
    pytest.param(
        'file = "record.csv"',
        'file = "record.csv"\nforce_column = "time_s"',
        "data[0].force_column",
        "'time_s'",
        id="same-column-twice",
    ),
    pytest.param(
        'contact = "auto"', 'contact = "manual"', "data[0].contact", "'manual'", id="contact"
    ),
    pytest.param(
        'contact = "auto"',
        'contact = "auto"\ncontact_position_m = 0.001',
        "data[0].contact_position_m",
        "0.001",
        id="two-contacts",
    ),
    pytest.param(
        'contact = "auto"',
        "contact_position_m = 0.01",
        "data[0].contact_position_m",
        "0.01",
        id="contact-beyond-record",
    ),
    pytest.param(
        'contact = "auto"',
        'contact_position_m = "2 mm"',
        "data[0].contact_position_m",
        "'2 mm'",
        id="contact-with-unit",
    ),
    pytest.param(
        'contact = "auto"',
        'contact = "auto"\noffset = "yes"',
        "data[0].offset",
        "'yes'",
        id="offset",
    ),
    pytest.param(
        'contact = "auto"',
        'contact = "none"\noffset = "none"',
        "data[0].offset",
        "'none'",
        id="offset-without-contact",
    ),
    pytest.param(
        "keep_depth_m = 0.0004",
        "keep_depth_m = -0.0004",
        "data[0].keep_depth_m",
        "-0.0004",
        id="keep-negative",
    ),
    pytest.param(
        "keep_depth_m = 0.0004",
        "keep_depth_m = 0.4",
        "data[0].keep_depth_m",
        "0.4",
        id="keep-deeper-than-record",
    ),
    pytest.param(
        "keep_depth_m = 0.0004",
        "window_s = [2.0, 1.0]",
        "data[0].window_s",
        "[2.0, 1.0]",
        id="window-backwards",
    ),
    pytest.param(
        "keep_depth_m = 0.0004",
        "window_s = [0.0]",
        "data[0].window_s",
        "[0.0]",
        id="window-one-number",
    ),
    pytest.param(
        "keep_depth_m = 0.0004",
        "window_s = [50.0, 60.0]",
        "data[0].window_s",
        "[50.0, 60.0]",
        id="window-empty",
    ),
    pytest.param(
        "keep_depth_m = 0.0004", "keep_depth = 0.0004", "data[0].keep_depth", None, id="data-typo"
    ),
    pytest.param(
        'free = ["C10_Pa"]',
        'free = ["C10_pa"]',
        "fit.free",
        "did you mean 'C10_Pa'?",
        id="free-typo",
    ),
    pytest.param(
        'free = ["C10_Pa"]', 'free = ["bulk_modulus_Pa"]', "fit.free", "held fixed", id="free-bulk"
    ),
    pytest.param('free = ["C10_Pa"]', "free = []", "fit.free", "[]", id="free-empty"),
    pytest.param(
        'free = ["C10_Pa"]', 'free = ["C10_Pa", "C10_Pa"]', "fit.free", "twice", id="free-twice"
    ),
    pytest.param(
        'free = ["C10_Pa"]', 'free = "C10_Pa"', "fit.free", "'C10_Pa'", id="free-not-list"
    ),
    pytest.param(
        'free = ["C10_Pa"]', 'fre = ["C10_Pa"]', "fit.fre", "did you mean 'free'?", id="fit-typo"
    ),
    pytest.param('method = "salm"', 'method = "gauss"', "fit.method", "'gauss'", id="method"),
    pytest.param(
        'method = "salm"', 'objective = "squared"', "fit.objective", "'squared'", id="objective"
    ),
    pytest.param(
        'method = "salm"',
        "relative_floor_N = 0.001",
        "fit.relative_floor_N",
        "0.001",
        id="floor-absolute",
    ),
    pytest.param(
        'method = "salm"',
        'objective = "relative"\nrelative_floor_N = 0.0',
        "fit.relative_floor_N",
        "0.0",
        id="floor-zero",
    ),
    pytest.param(
        'method = "salm"', "max_iterations = 0", "fit.max_iterations", "0", id="iterations"
    ),
    pytest.param('method = "salm"', "ftol = -1e-8", "fit.ftol", "-1e-08", id="ftol"),
    pytest.param('method = "salm"', 'xtol = "small"', "fit.xtol", "'small'", id="xtol"),
    pytest.param('method = "salm"', "gtol = 0.0", "fit.gtol", "0.0", id="gtol"),
    pytest.param(
        'method = "salm"', "stop_r_squared = 1.5", "fit.stop_r_squared", "1.5", id="r2-above-1"
    ),
    pytest.param(
        'method = "salm"', 'start_from = "guess"', "fit.start_from", "'guess'", id="start-from"
    ),
    pytest.param(
        'method = "salm"',
        "[fit.start]\nC10_Pa = -5.0",
        "fit.start.C10_Pa",
        "-5.0",
        id="start-invalid",
    ),
    pytest.param(
        'method = "salm"',
        "[fit.start]\nC01_Pa = 5.0",
        "fit.start.C01_Pa",
        "did you mean 'C10_Pa'?",
        id="start-unknown",
    ),
    pytest.param(
        'method = "salm"',
        '[fit.start]\nC10_Pa = "300 Pa"',
        "fit.start.C10_Pa",
        "'300 Pa'",
        id="start-unit",
    ),
    pytest.param(
        'method = "salm"',
        "[fit.bounds]\nC10_Pa = [500.0, 100.0]",
        "fit.bounds.C10_Pa",
        "[500.0, 100.0]",
        id="bounds-backwards",
    ),
    pytest.param(
        'method = "salm"',
        "[fit.bounds]\nC10_Pa = 100.0",
        "fit.bounds.C10_Pa",
        "100.0",
        id="bounds-not-pair",
    ),
    pytest.param(
        'method = "salm"',
        "[fit.bounds]\nC10_Pa = [1.0, 10.0]\n[fit.start]\nC10_Pa = 300.0",
        "fit.start.C10_Pa",
        "300.0",
        id="start-outside-bounds",
    ),
    pytest.param(
        'method = "salm"',
        'start_from = "material"\n[fit.bounds]\nC10_Pa = [1.0, 10.0]',
        "fit.start_from",
        "287.5",
        id="material-outside-bounds",
    ),
    pytest.param(
        'method = "salm"', 'contact_point = "guess"', "fit.contact_point", "'guess'", id="contact"
    ),
    pytest.param(
        'method = "salm"',
        'bulk_modulus = "ratio"',
        "fit.bulk_modulus",
        "'ratio'",
        id="bulk-modulus-rule",
    ),
    pytest.param(
        'method = "salm"',
        "[fit.start]\ndepth_offset_m = 1e-4",
        "fit.start.depth_offset_m",
        "0.0001",
        id="offset-start-without-fit",
    ),
    pytest.param(
        'method = "salm"',
        'contact_point = "fit"\n[fit.start]\ndepth_offset_m = "0.1 mm"',
        "fit.start.depth_offset_m",
        "'0.1 mm'",
        id="offset-start-unit",
    ),
    pytest.param(
        'method = "salm"',
        'contact_point = "fit"\n[fit.bounds]\ndepth_offset_m = [2e-4, 1e-4]',
        "fit.bounds.depth_offset_m",
        "[0.0002, 0.0001]",
        id="offset-bounds-backwards",
    ),
    pytest.param(
        'method = "salm"',
        'contact_point = "fit"\n[fit.bounds]\ndepth_offset_m = [0.0, 1e-4]\n'
        "[fit.start]\ndepth_offset_m = 2e-4",
        "fit.start.depth_offset_m",
        "0.0002",
        id="offset-start-outside-bounds",
    ),
]


@pytest.mark.parametrize(("old", "new", "key_path", "value"), BAD_V2)
def test_bad_fit_input_names_file_line_key_and_value(tmp_path, old, new, key_path, value):
    assert old in V2
    text = V2.replace(old, new, 1)
    path = write_v2(tmp_path, text)
    with pytest.raises(InputError) as caught:
        load_study(path)
    assert_names_key_and_line(caught.value, text, path, key_path, value)


def test_a_version_1_file_with_fit_tables_asks_for_version_2(tmp_path):
    text = MINIMAL + "\n" + FIT_TABLES
    with pytest.raises(InputError, match="needs schema_version = 2") as caught:
        load_study(write_v2(tmp_path, text))
    assert caught.value.line == line_of(text, "[[data]]")


def test_a_fit_without_data_is_refused(tmp_path):
    text = V2.replace(FIT_TABLES, '[fit]\nfree = ["C10_Pa"]\n')
    with pytest.raises(InputError, match="a fit needs measured records") as caught:
        load_study(write(tmp_path, text))
    assert caught.value.line == line_of(text, "[fit]")


def test_second_record_errors_name_its_index(tmp_path):
    text = V2.replace("[fit]", '[[data]]\nfile = "record.csv"\nwindow_s = [3.0, 1.0]\n\n[fit]')
    with pytest.raises(InputError, match=r"data\[1\]\.window_s") as caught:
        load_study(write_v2(tmp_path, text))
    assert caught.value.line == line_of(text, "window_s = [3.0")


def test_a_record_whose_time_goes_back_names_the_csv_line(tmp_path):
    path = write_v2(tmp_path)
    csv = tmp_path / "record.csv"
    lines = csv.read_text().splitlines()
    lines[5] = lines[3]  # the time of line 6 repeats line 4's
    csv.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match=r"record\.csv:6.*time_s must strictly increase") as caught:
        load_study(path)
    assert "data[0].file" in str(caught.value)
    assert caught.value.line == line_of(V2, 'file = "record.csv"')


def test_a_layer_beyond_the_hayes_range_asks_for_start_values(tmp_path):
    """a / h = 1 mm / 0.05 mm = 20 > 16: no start from the record, said in one line."""
    text = V2.replace("thickness_m = 0.01", "thickness_m = 0.01\nsize_far_m = 0.005").replace(
        "max_depth_m = 0.0005", "max_depth_m = 0.00001"
    )
    study = load_study(write_v2(tmp_path, text))
    table = study.to_dict()
    table["specimen"]["thickness_m"] = 5e-5
    table["data"][0]["keep_depth_m"] = 4e-5  # a record shallower than the layer
    thin = study_from_dict(table, path=study.path)
    with pytest.raises(InputError, match=r"no start value from record\.csv: .*\[fit\.start\]"):
        start_values_from_record(thin)


# --- Timed protocols (version 2) and the [fit] strategy ---------------------------------

QUASI_STATIC = "[protocol]\nmax_depth_m = 0.0005\nsteps = 4\n"
RAMP_HOLD = (
    '[protocol]\nkind = "ramp_hold"\nmax_depth_m = 0.0005\nspeed_m_per_s = 0.001\n'
    "hold_s = 20.0\nramp_steps = 4\nhold_steps = 6\n"
)
SINE = (
    '[protocol]\nkind = "sine"\npreload_depth_m = 0.0004\namplitude_m = 0.0001\n'
    "frequency_Hz = 2.0\ncycles = 2\npreload_s = 1.0\n"
)
TIMED = "[protocol]\ndepths_m = [0.0002, 0.0004, 0.0004, 0.0001]\ntimes_s = [0.5, 1.0, 5.0, 6.0]\n"
V2_SIM = MINIMAL.replace("schema_version = 1", "schema_version = 2")


def with_protocol(protocol: str, text: str = V2_SIM) -> str:
    assert QUASI_STATIC in text
    return text.replace(QUASI_STATIC, protocol, 1)


def assert_round_trips(study, tmp_path: Path) -> None:
    record = study.to_dict()
    assert study_from_dict(record, path=study.path) == study
    assert study_from_dict(record, path=study.path).to_dict() == record
    again = load_study(save_study(study, tmp_path / "again" / "study.toml"))
    assert again.protocol.times_s == study.protocol.times_s
    assert again.protocol.depths_m == study.protocol.depths_m


def test_a_ramp_hold_protocol_has_the_steps_of_loading_ramp_hold(tmp_path):
    from warptissue.loading import ramp_hold

    study = load_study(write(tmp_path, with_protocol(RAMP_HOLD)))
    protocol = study.protocol
    assert protocol.kind == "ramp_hold" and protocol.timed
    times, depths = ramp_hold(
        max_depth_m=5e-4, speed_m_per_s=1e-3, hold_s=20.0, ramp_steps=4, hold_steps=6
    )
    np.testing.assert_array_equal(protocol.times_s, times)
    np.testing.assert_array_equal(protocol.depths_m, depths)
    assert protocol.times_s[3] == pytest.approx(0.5) and protocol.times_s[-1] == pytest.approx(20.5)
    assert protocol.max_depth_m == pytest.approx(5e-4) and protocol.step_count == 10
    assert protocol.to_dict() == {
        "kind": "ramp_hold",
        "max_depth_m": 5e-4,
        "speed_m_per_s": 1e-3,
        "hold_s": 20.0,
        "ramp_steps": 4,
        "hold_steps": 6,
    }
    assert_round_trips(study, tmp_path)
    # The defaults are filled in.
    text = with_protocol(RAMP_HOLD.replace("ramp_steps = 4\nhold_steps = 6\n", ""))
    defaults = load_study(write(tmp_path, text, "defaults.toml")).protocol
    assert (defaults.settings["ramp_steps"], defaults.settings["hold_steps"]) == (10, 20)


def test_a_sine_protocol_oscillates_about_its_preload(tmp_path):
    study = load_study(write(tmp_path, with_protocol(SINE)))
    protocol = study.protocol
    assert protocol.kind == "sine" and protocol.step_count == 5 + 2 * 16
    times, depths = np.array(protocol.times_s), np.array(protocol.depths_m)
    np.testing.assert_allclose(depths[:5], 4e-4 * times[:5] / 1.0)  # the ramp to the preload
    expected = 4e-4 + 1e-4 * np.sin(2 * np.pi * 2.0 * (times[5:] - 1.0))
    np.testing.assert_allclose(depths[5:], expected, atol=1e-15)
    assert depths.max() == pytest.approx(5e-4) and depths[5:].min() == pytest.approx(3e-4)
    assert protocol.to_dict()["steps_per_cycle"] == 16
    assert_round_trips(study, tmp_path)


def test_explicit_depths_and_times_are_a_timed_protocol(tmp_path):
    study = load_study(write(tmp_path, with_protocol(TIMED)))
    protocol = study.protocol
    assert protocol.kind == "timed"
    assert protocol.times_s == (0.5, 1.0, 5.0, 6.0)
    assert protocol.depths_m == (2e-4, 4e-4, 4e-4, 1e-4)  # down again: allowed when timed
    assert protocol.max_depth_m == 4e-4
    assert protocol.to_dict() == {
        "kind": "timed",
        "depths_m": [2e-4, 4e-4, 4e-4, 1e-4],
        "times_s": [0.5, 1.0, 5.0, 6.0],
    }
    assert_round_trips(study, tmp_path)


def test_a_quasi_static_protocol_is_untimed_and_echoed_without_a_kind(tmp_path):
    study = load_study(write(tmp_path, MINIMAL))
    assert study.protocol.kind == "quasi_static" and not study.protocol.timed
    assert study.protocol.times_s is None
    assert study.protocol.to_dict() == {"depths_m": [1.25e-4, 2.5e-4, 3.75e-4, 5e-4]}
    text = with_protocol('[protocol]\nkind = "quasi_static"\nmax_depth_m = 0.0005\nsteps = 4\n')
    assert load_study(write(tmp_path, text, "explicit.toml")).protocol == study.protocol
    # kind = "quasi_static" is read in a version-1 file too (a timed kind is not).
    assert load_study(write(tmp_path, text.replace("schema_version = 2", "schema_version = 1")))


def test_a_quasi_static_protocol_spaced_by_the_contact_radius(tmp_path):
    """spacing = "contact_radius": d_k = d_max (k / n)^2, so that a sphere's Hertz contact
    radius sqrt(R* d) grows by the same sqrt(R* d_max) / n at every step; echoed as the keys
    that made it and read back the same."""
    text = MINIMAL.replace("steps = 4", 'steps = 4\nspacing = "contact_radius"')
    study = load_study(write(tmp_path, text))
    depths = np.array(study.protocol.depths_m)
    np.testing.assert_allclose(depths, 5e-4 * np.array([1, 4, 9, 16]) / 16, rtol=1e-15)
    reduced_radius = 1e-3  # any R*: the steps of a = sqrt(R* d) are equal
    steps_of_a = np.diff(np.sqrt(reduced_radius * depths), prepend=0.0)
    np.testing.assert_allclose(steps_of_a, np.sqrt(reduced_radius * 5e-4) / 4, rtol=1e-12)
    assert study.protocol.to_dict() == {
        "max_depth_m": 5e-4,
        "steps": 4,
        "spacing": "contact_radius",
    }
    again = load_study(save_study(study, tmp_path / "again.toml"))
    assert again.protocol == study.protocol
    even = load_study(write(tmp_path, text.replace('"contact_radius"', '"even"'), "even.toml"))
    assert even.protocol == load_study(write(tmp_path, MINIMAL, "minimal.toml")).protocol


def record_protocol(**keys: str) -> str:
    lines = ['kind = "record"', 'file = "record.csv"', *(f"{k} = {v}" for k, v in keys.items())]
    return "[protocol]\n" + "\n".join(lines) + "\n"


def test_a_record_protocol_follows_the_records_depth_from_its_contact(tmp_path):
    """synthetic_record: the probe moves at 0.5 mm/s from t = 1 s and meets the surface
    0.2 mm lower, at t = 1.4 s; the FE history starts there: depth = 0.5 mm/s x time."""
    synthetic_record(tmp_path / "record.csv")
    text = with_protocol(record_protocol(contact='"auto"', steps="12"))
    study = load_study(write(tmp_path, text))
    protocol = study.protocol
    assert protocol.kind == "record" and protocol.record is not None
    assert protocol.record.contact_time_s == pytest.approx(1.4, abs=0.02)
    times, depths = np.array(protocol.times_s), np.array(protocol.depths_m)
    assert abs(times.size - 12) <= 1 and np.all(times > 0) and np.all(np.diff(times) > 0)
    assert times[-1] == pytest.approx(2.39 - 1.4, abs=0.02)
    np.testing.assert_allclose(depths, 5e-4 * times, atol=1e-5)  # 10 um: the contact estimate
    assert protocol.to_dict()["steps"] == 12 and protocol.to_dict()["contact"] == "auto"
    assert_round_trips(study, tmp_path)
    moved = load_study(save_study(study, tmp_path / "elsewhere" / "moved.toml"))
    assert moved.protocol.to_dict()["file"] == "../record.csv"
    assert moved.protocol.record.path.resolve() == study.protocol.record.path.resolve()
    assert (moved.protocol.times_s, moved.protocol.depths_m) == (
        tuple(times),
        tuple(depths),
    )


def test_a_record_protocol_needs_no_force_column_with_a_given_contact(tmp_path):
    path = synthetic_record(tmp_path / "full.csv")
    columns = np.genfromtxt(path, delimiter=",", names=True)
    write_csv(
        tmp_path / "record.csv",
        {"time_s": columns["time_s"], "displacement_m": columns["displacement_m"]},
    )
    text = with_protocol(record_protocol(contact_position_m="0.0002", steps="8"))
    protocol = load_study(write(tmp_path, text)).protocol
    assert protocol.record.contact_time_s == pytest.approx(1.4, abs=0.011)
    np.testing.assert_allclose(protocol.depths_m, 5e-4 * np.array(protocol.times_s), atol=3e-6)
    bad = with_protocol(record_protocol(contact='"auto"'))
    with pytest.raises(InputError, match="protocol.contact: 'auto' detects the contact") as caught:
        load_study(write(tmp_path, bad, "auto.toml"))
    assert caught.value.line == line_of(bad, 'contact = "auto"')


def test_load_history_is_resample_history_from_the_contact(tmp_path):
    from warptissue.loading import resample_history

    study = load_study(write_v2(tmp_path))
    (record,) = study.data
    times, depths = record.load_history(steps=study.fit.time_steps)
    expected = resample_history(
        record.time_s - record.contact_time_s, record.displacement_m, steps=24
    )
    np.testing.assert_array_equal(times, expected[0])
    np.testing.assert_array_equal(depths, expected[1])
    assert times[0] > 0 and times[-1] == pytest.approx(record.time_s[-1] - record.contact_time_s)
    with pytest.raises(InputError, match=r"record\.csv.*steps"):
        record.load_history(steps=1)


# (replace QUASI_STATIC with this, key path named, value named)
BAD_PROTOCOLS = [
    pytest.param('[protocol]\nkind = "ramp"\n', "protocol.kind", "'ramp'", id="unknown-kind"),
    pytest.param(
        RAMP_HOLD.replace("speed_m_per_s = 0.001\n", ""),
        "protocol.speed_m_per_s",
        None,
        id="ramp-hold-missing-speed",
    ),
    pytest.param(
        RAMP_HOLD.replace("hold_s = 20.0", "hold_s = -1.0"),
        "protocol.hold_s",
        "-1.0",
        id="negative-hold",
    ),
    pytest.param(
        RAMP_HOLD.replace("max_depth_m = 0.0005", "max_depth_m = 0.02"),
        "protocol.max_depth_m",
        "0.02",
        id="ramp-hold-through-the-specimen",
    ),
    pytest.param(
        RAMP_HOLD.replace("ramp_steps = 4", "ramp_steps = 0"),
        "protocol.ramp_steps",
        "0",
        id="no-ramp-steps",
    ),
    pytest.param(RAMP_HOLD + 'file = "x.csv"\n', "protocol.file", None, id="a-key-of-another-kind"),
    pytest.param(
        RAMP_HOLD + "hold_step = 4\n", "protocol.hold_step", None, id="typo-in-a-timed-kind"
    ),
    pytest.param(
        SINE.replace("amplitude_m = 0.0001", "amplitude_m = 0.0005"),
        "protocol.amplitude_m",
        "0.0005",
        id="amplitude-above-preload",
    ),
    pytest.param(
        SINE.replace("preload_depth_m = 0.0004", "preload_depth_m = 0.0099"),
        "protocol.amplitude_m",
        "0.01",
        id="sine-through-the-specimen",
    ),
    pytest.param(
        SINE.replace("cycles = 2", "cycles = 1.5"), "protocol.cycles", "1.5", id="cycles-int"
    ),
    pytest.param(
        TIMED.replace("[0.5, 1.0, 5.0, 6.0]", "[0.5, 1.0, 1.0, 6.0]"),
        "protocol.times_s",
        "[0.5, 1.0, 1.0, 6.0]",
        id="times-not-increasing",
    ),
    pytest.param(
        TIMED.replace("[0.5, 1.0, 5.0, 6.0]", "[0.0, 1.0, 5.0, 6.0]"),
        "protocol.times_s",
        None,
        id="time-zero",
    ),
    pytest.param(
        TIMED.replace("[0.5, 1.0, 5.0, 6.0]", "[0.5, 1.0, 5.0]"),
        "protocol.times_s",
        "3",
        id="times-shorter",
    ),
    pytest.param(
        TIMED.replace("0.0001]", "-0.0001]"), "protocol.depths_m", "-0.0001", id="negative-depth"
    ),
    pytest.param(record_protocol(), "protocol.file", "record.csv", id="record-not-found"),
    pytest.param(record_protocol(steps="1"), "protocol.steps", "1", id="record-one-step"),
]


@pytest.mark.parametrize(("new", "key_path", "value"), BAD_PROTOCOLS)
def test_bad_protocols_name_file_line_key_and_value(tmp_path, new, key_path, value):
    text = with_protocol(new)
    path = write(tmp_path, text)
    with pytest.raises(InputError) as caught:
        load_study(path)
    message = str(caught.value)
    assert str(path) in message and key_path in message, message
    if value is not None:
        assert value in message, message
    key = key_path.rpartition(".")[2]
    below = "\n".join(text.splitlines()[line_of(text, "[protocol]") :])
    line = line_of(text, "[protocol]")
    if f"\n{key} =" in "\n" + below:
        line += next(n for n, x in enumerate(below.splitlines(), 1) if x.startswith(f"{key} ="))
    assert caught.value.line == line


def test_a_key_of_another_kind_says_whose_it_is(tmp_path):
    with pytest.raises(InputError, match="not a key of kind 'ramp_hold'.*belongs to kind"):
        load_study(write(tmp_path, with_protocol(RAMP_HOLD + "cycles = 2\n")))


def test_a_timed_protocol_in_a_version_1_file_asks_for_version_2(tmp_path):
    for protocol, key in ((RAMP_HOLD, "kind"), (TIMED, "times_s")):
        text = MINIMAL.replace(QUASI_STATIC, protocol)
        with pytest.raises(InputError, match="needs schema_version = 2") as caught:
            load_study(write(tmp_path, text))
        assert f"protocol.{key}" in str(caught.value)
        assert caught.value.line == line_of(text, "[protocol]") + (1 if key == "kind" else 2)


def test_fit_strategy_and_time_steps_defaults_and_round_trip(tmp_path):
    study = load_study(write_v2(tmp_path))
    assert (study.fit.strategy, study.fit.time_steps) == ("joint", 24)
    table = study.fit.to_dict()
    assert (table["strategy"], table["time_steps"]) == ("joint", 24)
    text = V2.replace('method = "salm"', 'method = "salm"\ntime_steps = 12')
    study = load_study(write_v2(tmp_path, text))
    assert study.fit.time_steps == 12
    assert study_from_dict(study.to_dict(), path=study.path).fit == study.fit


VISCO_MATERIAL = "C10_Pa = 287.5\nbulk_modulus_Pa = 575000.0\ng1 = 0.3\ntau1_s = 1.0\n"


def test_the_bulk_modulus_rule_defaults_round_trips_and_needs_a_hyperelastic_model(tmp_path):
    """Issue 36: fit.bulk_modulus = "follows_shear" (K/mu0 held) is read, written back and
    refused in one line for a model with compressibility parameters of its own."""
    study = load_study(write_v2(tmp_path))
    assert study.fit.bulk_modulus == "fixed" and "bulk_modulus" not in study.fit.to_dict()
    text = V2.replace('method = "salm"', 'method = "salm"\nbulk_modulus = "follows_shear"')
    study = load_study(write_v2(tmp_path, text))
    assert study.fit.bulk_modulus == "follows_shear"
    assert study_from_dict(study.to_dict(), path=study.path).fit == study.fit
    linear = text.replace('model = "neo_hookean"', 'model = "linear_elastic"').replace(
        "C10_Pa = 287.5\nbulk_modulus_Pa = 575000.0",
        "youngs_modulus_Pa = 1725.0\npoissons_ratio = 0.499",
    )
    linear = linear.replace('free = ["C10_Pa"]', 'free = ["youngs_modulus_Pa"]')
    with pytest.raises(InputError) as caught:
        load_study(write_v2(tmp_path, linear))
    assert_names_key_and_line(
        caught.value, linear, caught.value.path, "fit.bulk_modulus", "'follows_shear'"
    )


def test_contact_point_defaults_and_round_trips(tmp_path):
    study = load_study(write_v2(tmp_path))
    assert study.fit.contact_point == "given" and "contact_point" not in study.fit.to_dict()
    text = V2.replace(
        'method = "salm"',
        'method = "salm"\ncontact_point = "fit"\n[fit.start]\ndepth_offset_m = -2e-5\n'
        "[fit.bounds]\ndepth_offset_m = [-1e-4, 1e-4]",
    )
    study = load_study(write_v2(tmp_path, text))
    assert study.fit.contact_point == "fit"
    assert study.fit.start == {"depth_offset_m": -2e-5}
    assert study.fit.bounds == {"depth_offset_m": (-1e-4, 1e-4)}
    assert study.fit.to_dict()["contact_point"] == "fit"
    assert study_from_dict(study.to_dict(), path=study.path).fit == study.fit
    # A viscoelastic material takes it too (each record's FE run starts at its touch).
    visco = text.replace("C10_Pa = 287.5\nbulk_modulus_Pa = 575000.0\n", VISCO_MATERIAL)
    assert load_study(write_v2(tmp_path, visco)).fit.contact_point == "fit"


def test_two_stage_needs_prony_terms_and_a_free_elastic_parameter(tmp_path):
    text = V2.replace('method = "salm"', 'method = "salm"\nstrategy = "two_stage"')
    with pytest.raises(InputError, match="fit.strategy: 'two_stage'.*has none") as caught:
        load_study(write_v2(tmp_path, text))
    assert caught.value.line == line_of(text, "strategy =")
    visco = text.replace("C10_Pa = 287.5\nbulk_modulus_Pa = 575000.0\n", VISCO_MATERIAL)
    only_prony = visco.replace('free = ["C10_Pa"]', 'free = ["g1", "tau1_s"]')
    with pytest.raises(InputError, match="fit.strategy: .*free an elastic parameter too"):
        load_study(write_v2(tmp_path, only_prony))
    for free in (["C10_Pa"], ["C10_Pa", "g1", "tau1_s"]):  # stage (i) fits every Prony term
        listed = visco.replace('free = ["C10_Pa"]', f"free = {free!r}".replace("'", '"'))
        study = load_study(write_v2(tmp_path, listed))
        assert study.fit.strategy == "two_stage" and study.fit.free == tuple(free)
        assert study_from_dict(study.to_dict(), path=study.path).fit == study.fit


BAD_FIT_KEYS = [
    pytest.param('strategy = "staged"', "fit.strategy", "'staged'", id="unknown-strategy"),
    pytest.param("time_steps = 1", "fit.time_steps", "1", id="one-time-step"),
    pytest.param("time_steps = 2.5", "fit.time_steps", "2.5", id="time-steps-not-integer"),
]


@pytest.mark.parametrize(("line", "key_path", "value"), BAD_FIT_KEYS)
def test_bad_strategy_and_time_steps(tmp_path, line, key_path, value):
    text = V2.replace('method = "salm"', f'method = "salm"\n{line}')
    path = write_v2(tmp_path, text)
    with pytest.raises(InputError) as caught:
        load_study(path)
    assert_names_key_and_line(caught.value, text, path, key_path, value)


def test_every_protocol_key_is_in_the_study_file_reference():
    from warptissue.study._reader import PROTOCOL_KEYS

    page = (REPOSITORY / "docs" / "study-files.md").read_text(encoding="utf-8")
    documented = set(re.findall(r"^\| `([A-Za-z0-9_]+)`[ ,|]", page, flags=re.MULTILINE))
    rows = re.findall(r"^\| (`[A-Za-z0-9_]+`(?:, `[A-Za-z0-9_]+`)*) \|", page, re.MULTILINE)
    for row in rows:
        documented |= set(re.findall(r"`([A-Za-z0-9_]+)`", row))
    keys = {"kind"} | {key for keys in PROTOCOL_KEYS.values() for key in keys}
    assert keys <= documented, sorted(keys - documented)
    for kind in ("quasi_static", "timed", "ramp_hold", "sine", "record"):
        assert f'`"{kind}"`' in page, kind


def test_a_protocol_from_a_data_record_is_written_and_read_back(tmp_path):
    import dataclasses

    from warptissue.study import Protocol

    study = load_study(write_v2(tmp_path))
    protocol = Protocol.from_record(study.data[0], steps=10)
    times, depths = study.data[0].load_history(steps=10)
    assert protocol.kind == "record" and protocol.times_s == tuple(times)
    assert protocol.depths_m == tuple(depths)
    replayed = dataclasses.replace(study, protocol=protocol)
    again = load_study(save_study(replayed, tmp_path / "elsewhere" / "replay.toml"))
    assert again.protocol.to_dict()["keep_depth_m"] == 0.0004  # the record's conditioning
    assert (again.protocol.times_s, again.protocol.depths_m) == (
        protocol.times_s,
        protocol.depths_m,
    )


@pytest.mark.parametrize(
    ("change", "message"),
    [
        pytest.param(
            lambda columns: {**columns, "displacement_m": columns["displacement_m"] * 1e3},
            "m deep and the specimen is 0.01 m thick: check the displacement's unit",
            id="millimetres-in-a-metre-column",
        ),
        pytest.param(
            lambda columns: {**columns, "force_N": np.zeros_like(columns["force_N"])},
            "the force is zero throughout",
            id="zero-force",
        ),
        pytest.param(
            lambda columns: {**columns, "force_N": -columns["force_N"]},
            "the force is mostly negative",
            id="negative-force",
        ),
    ],
)
def test_a_fit_record_that_cannot_be_an_indentation_is_refused_at_load(tmp_path, change, message):
    """Checked against the specimen before any FE run (they used to fail after it: exit 4,
    or a start-value error naming fit.free): one line at data[0].file, naming the file."""
    path = synthetic_record(tmp_path / "record.csv")
    columns = read_experiment_csv(path).columns
    write_csv(path, change(dict(columns)))
    # The whole record, used as recorded (with contact = "auto" a flat force is refused by
    # the contact detection already).
    text = V2.replace("keep_depth_m = 0.0004\n", "").replace('"auto"', '"none"')
    with pytest.raises(InputError, match=message) as caught:
        load_study(write(tmp_path, text))
    assert "data[0].file" in str(caught.value) and "record.csv" in str(caught.value)
    assert caught.value.line == line_of(text, 'file = "record.csv"')
