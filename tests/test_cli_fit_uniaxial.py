"""Tests of ``warptissue fit uniaxial`` (warptissue.cli.fit_uniaxial)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from warptissue.cli import main
from warptissue.fit.hyperelastic import HomogeneousTest
from warptissue.materials import ReducedPolynomial

AREA_M2, HEIGHT_M = 0.070 * 0.080, 0.080


@pytest.fixture
def compression_csv(tmp_path, rng):
    displacement_m = np.linspace(0.0, 0.0127, 200)
    test = HomogeneousTest("compression", displacement_m / HEIGHT_M, np.zeros_like(displacement_m))
    force_N = test.predicted_stress_Pa(ReducedPolynomial((600.553, 4097.45))) * AREA_M2
    force_N = force_N + rng.normal(0.0, 0.02, force_N.size)
    path = tmp_path / "block.csv"
    lines = ["time_s,displacement_m,force_N"] + [
        f"{float(d) / 4e-4!r},{float(d)!r},{float(f)!r}"
        for d, f in zip(displacement_m, force_N, strict=True)
    ]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_fit_two_models_writes_outputs_and_ranks_them(compression_csv, tmp_path, capsys):
    out = tmp_path / "out"
    status = main(
        [
            "fit", "uniaxial", str(compression_csv), "--area-m2", str(AREA_M2),
            "--height-m", str(HEIGHT_M), "--model", "neo_hookean,reduced_polynomial:2",
            "--out", str(out), "--json",
        ]
    )  # fmt: skip
    assert status == 0
    report = json.loads(capsys.readouterr().out)
    assert [row["model"] for row in report["models"]] == ["reduced_polynomial:2", "neo_hookean"]
    fit = json.loads((out / "block_reduced_polynomial_2.json").read_text())
    assert fit["parameters"]["C10_Pa"]["value"] == pytest.approx(600.553, rel=0.02)
    assert fit["parameters"]["C20_Pa"]["value"] == pytest.approx(4097.45, rel=0.02)
    assert fit["metadata"]["stability"]["stable_up_to_strain"] is None
    for suffix in ("csv", "png"):
        assert (out / f"block_neo_hookean.{suffix}").stat().st_size > 0
    assert "reduced_polynomial:2" in (out / "block_comparison.txt").read_text()


def test_relative_objective_uses_the_default_window(compression_csv, tmp_path, capsys):
    out = tmp_path / "rel"
    status = main(
        [
            "fit", "uniaxial", str(compression_csv), "--area-m2", str(AREA_M2),
            "--height-m", str(HEIGHT_M), "--model", "mooney_rivlin", "--objective", "relative",
            "--out", str(out),
        ]
    )  # fmt: skip
    assert status == 0
    assert "mooney_rivlin" in capsys.readouterr().out
    fit = json.loads((out / "block_mooney_rivlin.json").read_text())
    assert fit["metadata"]["min_strain"] == 0.05 and fit["objective"] == "relative"


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (["--model", "foam"], "--model: unknown model"),
        (["--model", "neo_hookean,,yeoh"], "--model has an empty entry"),
        (["--min-strain", "-1"], "--min-strain must be"),
        (["--min-strain", "nan"], "--min-strain must be"),
    ],
)
def test_errors_are_one_line_with_exit_code_2(compression_csv, capsys, arguments, message):
    base = ["fit", "uniaxial", str(compression_csv), "--area-m2", str(AREA_M2)]
    status = main([*base, "--height-m", str(HEIGHT_M), *arguments])
    error = capsys.readouterr().err.strip()
    assert status == 2
    assert message in error and len(error.splitlines()) == 1
    assert "column 'min_strain'" not in error and "np.float64" not in error


@pytest.mark.parametrize(
    ("option", "value", "message"),
    [
        ("--area-m2", "-1", "argument --area-m2: must be positive"),
        ("--area-m2", "nan", "argument --area-m2: not a finite number"),
        ("--height-m", "0", "argument --height-m: must be positive"),
        ("--height-m", "tall", "argument --height-m: not a length"),
        ("--bulk-modulus-ratio", "-5", "argument --bulk-modulus-ratio: must be positive"),
    ],
)
def test_bad_options_are_usage_errors_naming_the_option(
    compression_csv, capsys, option, value, message
):
    """Before: '--area-m2 -1' was reported as "column 'area_m2'" after reading the file."""
    arguments = {"--area-m2": str(AREA_M2), "--height-m": str(HEIGHT_M), option: value}
    with pytest.raises(SystemExit) as exit_info:
        main(
            ["fit", "uniaxial", str(compression_csv), *(x for kv in arguments.items() for x in kv)]
        )
    assert exit_info.value.code == 2
    error = capsys.readouterr().err
    assert message in error and "Traceback" not in error and "column" not in error


def test_height_takes_a_unit(compression_csv, tmp_path, capsys):
    """``acquire`` takes lengths with units; so does --height-m (80mm = 0.08 m)."""
    out = tmp_path / "out"
    status = main(
        [
            "fit", "uniaxial", str(compression_csv), "--area-m2", str(AREA_M2),
            "--height-m", "80mm", "--model", "neo_hookean", "--out", str(out),
        ]
    )  # fmt: skip
    assert status == 0
    assert json.loads((out / "block_neo_hookean.json").read_text())["metadata"]["height_m"] == (
        pytest.approx(0.08, rel=1e-12)
    )


def test_missing_column_names_the_file(tmp_path, capsys):
    path = tmp_path / "bad.csv"
    path.write_text("time_s,force_N\n0,0\n1,1\n")
    status = main(["fit", "uniaxial", str(path), "--area-m2", "1", "--height-m", "1"])
    assert status == 2
    assert "bad.csv" in capsys.readouterr().err


def test_usd_writes_the_best_model_as_a_material_layer(compression_csv, tmp_path, capsys):
    from warptissue.usd import read_material_usd, validate_stage

    out, usd = tmp_path / "out", tmp_path / "tissue.usda"
    status = main(
        [
            "fit", "uniaxial", str(compression_csv), "--area-m2", str(AREA_M2),
            "--height-m", str(HEIGHT_M), "--model", "neo_hookean,reduced_polynomial:2",
            "--out", str(out), "--usd", str(usd), "--bulk-modulus-ratio", "500", "--json",
        ]
    )  # fmt: skip
    assert status == 0
    report = json.loads(capsys.readouterr().out)
    assert report["files"]["usd"]["material"] == str(usd)
    assert validate_stage(usd) == []
    fit = json.loads((out / "block_reduced_polynomial_2.json").read_text())
    c10 = fit["parameters"]["C10_Pa"]["value"]
    c20 = fit["parameters"]["C20_Pa"]["value"]
    back = read_material_usd(usd)
    # The best model (by R^2) with K = 500 mu0 = 500 * 2 C10, values exact to float64.
    assert ReducedPolynomial((c10, c20), 500.0 * 2.0 * c10).to_dict() == back["material"]
    assert back["material"]["C10_Pa"] == c10
    assert back["material"]["C20_Pa"] == c20


def test_usd_must_be_usda(compression_csv, tmp_path):
    status = main(
        [
            "fit", "uniaxial", str(compression_csv), "--area-m2", str(AREA_M2),
            "--height-m", str(HEIGHT_M), "--model", "neo_hookean",
            "--out", str(tmp_path / "o"), "--usd", str(tmp_path / "x.usdc"),
        ]
    )  # fmt: skip
    assert status == 2
    assert not (tmp_path / "o").exists()


def _write_record(path, displacement_m, force_N):
    lines = ["displacement_m,force_N"] + [
        f"{float(d)!r},{float(f)!r}" for d, f in zip(displacement_m, force_N, strict=True)
    ]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_a_flattened_specimen_names_the_file_the_column_and_the_row(
    compression_csv, capsys, tmp_path
):
    """Before: 'compressive strain must stay below 1 (index 32) (got np.float64(1.0))'."""
    status = main(
        ["fit", "uniaxial", str(compression_csv), "--area-m2", str(AREA_M2), "--height-m", "0.01"]
    )
    error = capsys.readouterr().err.strip()
    assert status == 2 and len(error.splitlines()) == 1
    assert "block.csv" in error and "'displacement_m'" in error and "data row 158" in error
    assert "np.float64" not in error and "height" in error


@pytest.mark.parametrize(
    ("sign_d", "sign_f", "column"), [(1.0, -1.0, "force_N"), (-1.0, -1.0, "displacement_m")]
)
def test_negative_records_are_refused(compression_csv, tmp_path, capsys, sign_d, sign_f, column):
    """Before: compressive forces written negative fitted negative parameters with R^2 =
    0.9999 and exit 0."""
    columns = np.loadtxt(compression_csv, delimiter=",", skiprows=1)
    path = _write_record(tmp_path / "negative.csv", sign_d * columns[:, 1], sign_f * columns[:, 2])
    status = main(["fit", "uniaxial", str(path), "--area-m2", str(AREA_M2), "--height-m", "0.08"])
    error = capsys.readouterr().err.strip()
    assert status == 2 and len(error.splitlines()) == 1
    assert "negative.csv" in error and f"'{column}'" in error and "flip the sign" in error


def test_an_all_zero_force_is_refused(tmp_path, capsys):
    path = _write_record(tmp_path / "zero.csv", np.linspace(0.0, 0.01, 20), np.zeros(20))
    status = main(["fit", "uniaxial", str(path), "--area-m2", "0.0056", "--height-m", "0.08"])
    assert status == 2
    assert "nothing to fit" in capsys.readouterr().err


def test_table_and_json_give_each_parameter_with_unit_and_standard_error(
    compression_csv, tmp_path, capsys
):
    base = ["fit", "uniaxial", str(compression_csv), "--area-m2", str(AREA_M2)]
    base += ["--height-m", str(HEIGHT_M), "--model", "reduced_polynomial:2,ogden:1"]
    assert main([*base, "--out", str(tmp_path / "a")]) == 0
    table = capsys.readouterr().out
    assert re.search(r"C10_Pa = 59\d\.\d+ \+- [\d.]+ Pa, C20_Pa = 41\d\d\.\d+ \+- [\d.]+ Pa", table)
    assert "alpha1 = " in table and "identified" in table
    assert main([*base, "--out", str(tmp_path / "b"), "--json"]) == 0
    rows = {row["model"]: row for row in json.loads(capsys.readouterr().out)["models"]}
    c10 = rows["reduced_polynomial:2"]["parameters"]["C10_Pa"]
    assert c10["unit"] == "Pa" and c10["value"] == pytest.approx(600.553, rel=0.02)
    assert 0.0 < c10["standard_error"] < 10.0
    assert rows["ogden:1"]["parameters"]["alpha1"]["unit"] == ""
    assert rows["reduced_polynomial:2"]["identified"] is True
    saved = json.loads((tmp_path / "b" / "block_comparison.json").read_text())["models"]
    assert saved == list(rows.values())


def test_parameters_that_are_not_identified_are_flagged(compression_csv, tmp_path, capsys):
    """ogden:2 collapses onto ogden:1 on these data (alpha1 = alpha2): singular covariance."""
    status = main(
        [
            "fit", "uniaxial", str(compression_csv), "--area-m2", str(AREA_M2),
            "--height-m", str(HEIGHT_M), "--model", "ogden:2", "--out", str(tmp_path / "o"),
            "--json",
        ]
    )  # fmt: skip
    captured = capsys.readouterr()
    assert status == 0
    (row,) = json.loads(captured.out)["models"]
    assert row["identified"] is False and any("not identified" in w for w in row["warnings"])
    assert "warptissue: warning: ogden:2:" in captured.err and "not identified" in captured.err


def test_model_names_are_normalized_and_fitted_once(compression_csv, tmp_path, capsys):
    status = main(
        [
            "fit", "uniaxial", str(compression_csv), "--area-m2", str(AREA_M2),
            "--height-m", str(HEIGHT_M), "--model", "NEO_HOOKEAN, neo_hookean,reduced_polynomial",
            "--out", str(tmp_path / "o"), "--json",
        ]
    )  # fmt: skip
    assert status == 0
    rows = json.loads(capsys.readouterr().out)["models"]
    assert sorted(row["model"] for row in rows) == ["neo_hookean", "reduced_polynomial:2"]
    assert (tmp_path / "o" / "block_reduced_polynomial_2.png").exists()


def test_plots_have_units_parameters_and_a_decimated_record(tmp_path, capsys, monkeypatch):
    """A 10 000-point record: fitted on all points, at most MAX_PLOT_POINTS drawn per curve,
    axes in words with units, the fitted parameters in the legend."""
    import matplotlib.axes

    from warptissue.report import MAX_PLOT_POINTS

    drawn, labels = [], {}
    real_plot, real_xlabel = matplotlib.axes.Axes.plot, matplotlib.axes.Axes.set_xlabel
    real_ylabel = matplotlib.axes.Axes.set_ylabel

    def plot(self, *args, **kwargs):
        drawn.append((np.size(args[0]), kwargs.get("label")))
        return real_plot(self, *args, **kwargs)

    def set_xlabel(self, text, *args, **kwargs):
        labels["x"] = text
        return real_xlabel(self, text, *args, **kwargs)

    def set_ylabel(self, text, *args, **kwargs):
        labels.setdefault("y", text)
        return real_ylabel(self, text, *args, **kwargs)

    monkeypatch.setattr(matplotlib.axes.Axes, "plot", plot)
    monkeypatch.setattr(matplotlib.axes.Axes, "set_xlabel", set_xlabel)
    monkeypatch.setattr(matplotlib.axes.Axes, "set_ylabel", set_ylabel)
    displacement_m = np.linspace(0.0, 0.0127, 10_000)
    test = HomogeneousTest("compression", displacement_m / HEIGHT_M, np.zeros(10_000))
    force_N = test.predicted_stress_Pa(ReducedPolynomial((600.553, 4097.45))) * AREA_M2
    path = _write_record(tmp_path / "long.csv", displacement_m, force_N)
    out = tmp_path / "o"
    status = main(
        [
            "fit", "uniaxial", str(path), "--area-m2", str(AREA_M2), "--height-m", str(HEIGHT_M),
            "--model", "reduced_polynomial:2", "--out", str(out),
        ]
    )  # fmt: skip
    assert status == 0
    assert labels == {"x": "nominal strain (-)", "y": "nominal stress (Pa)"}
    sizes = [size for size, _ in drawn if size > 1]
    assert sizes and max(sizes) <= MAX_PLOT_POINTS < 10_000
    legend = " ".join(str(label) for _, label in drawn)
    assert re.search(r"C10 = 600\.6 Pa\s+C20 = 4097 Pa", legend)
    csv = np.loadtxt(out / "long_reduced_polynomial_2.csv", delimiter=",", skiprows=1)
    assert csv.shape[0] == 10_000


def test_the_shipped_example_is_the_generated_one_and_fits_back(tmp_path, capsys):
    """scenes/data/phantom_uniaxial.csv is what scripts/tools/make_uniaxial_example.py makes,
    and the documented command recovers the study's RP2 parameters from it."""
    import runpy
    from pathlib import Path

    from warptissue.io import write_csv

    root = Path(__file__).resolve().parents[1]
    shipped = root / "scenes" / "data" / "phantom_uniaxial.csv"
    script = runpy.run_path(str(root / "scripts" / "tools" / "make_uniaxial_example.py"))
    generated = write_csv(tmp_path / "generated.csv", script["make_record"]())
    assert generated.read_text() == shipped.read_text()
    out = tmp_path / "out"
    status = main(
        [
            "fit", "uniaxial", str(shipped), "--area-m2", "0.0056", "--height-m", "0.08",
            "--model", "reduced_polynomial:2", "--out", str(out), "--json",
        ]
    )  # fmt: skip
    assert status == 0
    (row,) = json.loads(capsys.readouterr().out)["models"]
    parameters = row["parameters"]
    for name, truth in (("C10_Pa", 600.553), ("C20_Pa", 4097.45)):
        assert abs(parameters[name]["value"] - truth) < 3.0 * parameters[name]["standard_error"]
    assert row["identified"] is True


def test_out_must_be_a_folder_that_can_be_made(compression_csv, tmp_path, capsys):
    """Before: a FileExistsError traceback."""
    blocker = tmp_path / "taken"
    blocker.write_text("")
    base = ["fit", "uniaxial", str(compression_csv), "--area-m2", str(AREA_M2)]
    base += ["--height-m", str(HEIGHT_M), "--model", "neo_hookean"]
    assert main([*base, "--out", str(blocker)]) == 2
    assert "--out must name a folder" in capsys.readouterr().err
    assert main([*base, "--out", str(blocker / "inside")]) == 2
    error = capsys.readouterr().err
    assert "--out: cannot create the folder" in error and len(error.strip().splitlines()) == 1


def test_a_window_above_the_data_names_the_option(compression_csv, capsys):
    status = main(
        [
            "fit", "uniaxial", str(compression_csv), "--area-m2", str(AREA_M2),
            "--height-m", str(HEIGHT_M), "--min-strain", "0.5",
        ]
    )  # fmt: skip
    error = capsys.readouterr().err
    assert status == 2 and "--min-strain 0.5 leaves no data" in error and "0.1588" in error


def test_a_model_unstable_inside_the_tested_range_is_warned(compression_csv, tmp_path, capsys):
    """Mooney-Rivlin fits these data with C10 < 0 and is unstable from about 0.04 in
    compression, inside the record (to 0.159): a warning line, exit status 0."""
    status = main(
        [
            "fit", "uniaxial", str(compression_csv), "--area-m2", str(AREA_M2),
            "--height-m", str(HEIGHT_M), "--model", "mooney_rivlin,reduced_polynomial:2",
            "--out", str(tmp_path / "o"),
        ]
    )  # fmt: skip
    error = capsys.readouterr().err
    assert status == 0
    assert "mooney_rivlin: the fitted model is not Drucker-stable in uniaxial compression" in error
    assert "reduced_polynomial:2:" not in error


def test_millimetres_in_a_tension_record_are_refused(compression_csv, tmp_path, capsys):
    """Before: a tension record with the displacement in mm (strains up to 159) was fitted,
    exit 0."""
    columns = np.loadtxt(compression_csv, delimiter=",", skiprows=1)
    path = _write_record(tmp_path / "mm.csv", 1000.0 * columns[:, 1], columns[:, 2])
    status = main(
        [
            "fit", "uniaxial", str(path), "--area-m2", str(AREA_M2), "--height-m", "0.08",
            "--loading", "tension", "--model", "neo_hookean",
        ]
    )  # fmt: skip
    error = capsys.readouterr().err.strip()
    assert status == 2 and len(error.splitlines()) == 1
    assert "mm.csv" in error and "'displacement_m'" in error and "metres" in error


def test_an_implausible_modulus_is_warned(compression_csv, tmp_path, capsys):
    """The area in mm^2 given as m^2 (5600 for 70 x 80 mm): stresses a million times too small,
    E = 3 mu0 of a few mPa. Before: fitted without a word."""
    status = main(
        [
            "fit", "uniaxial", str(compression_csv), "--area-m2", "5600", "--height-m", "0.08",
            "--model", "reduced_polynomial:2", "--out", str(tmp_path / "o"), "--json",
        ]
    )  # fmt: skip
    captured = capsys.readouterr()
    assert status == 0
    assert "outside the plausible range of soft tissue" in captured.err
    (row,) = json.loads(captured.out)["models"]
    assert any("specimen's area and height" in warning for warning in row["warnings"])


ROOT = Path(__file__).resolve().parents[1]
TRELOAR = {
    loading: ROOT / "scenes" / "data" / f"treloar_{name}.csv"
    for loading, name in (
        ("tension", "uniaxial"),
        ("equibiaxial", "equibiaxial"),
        ("planar", "planar"),
    )
}


def _neo_hookean_stress_Pa(stretch: np.ndarray, loading: str, c10_Pa: float) -> np.ndarray:
    """Incompressible neo-Hookean nominal stress, by hand: P = 2 C10 (lam - lam^-k), k = 2
    (uniaxial), 5 (equibiaxial), 3 (planar)."""
    power = {"tension": 2.0, "equibiaxial": 5.0, "planar": 3.0}[loading]
    return 2.0 * c10_Pa * (stretch - stretch**-power)


def test_joint_fit_of_stretch_and_stress_files_recovers_a_neo_hookean(tmp_path, capsys):
    """Issue 36: tests given as stretch and nominal stress (kPa here), three loadings, one
    joint fit from the command line; each test's error and the stress in each loading are
    reported; C10 against the closed forms written by hand."""
    arguments = ["fit", "hyperelastic"]
    for loading in ("tension", "equibiaxial", "planar"):
        stretch = np.linspace(1.0, 3.0, 11)
        stress_kPa = _neo_hookean_stress_Pa(stretch, loading, 2500.0) / 1e3
        path = tmp_path / f"{loading}.csv"
        lines = ["stretch,nominal_stress_kPa"] + [
            f"{float(a)!r},{float(b)!r}" for a, b in zip(stretch, stress_kPa, strict=True)
        ]
        path.write_text("\n".join(lines) + "\n")
        arguments += ["--test", loading, str(path)]
    out = tmp_path / "out"
    status = main([*arguments, "--model", "neo_hookean", "--out", str(out), "--json"])
    assert status == 0
    (row,) = json.loads(capsys.readouterr().out)["models"]
    assert row["parameters"]["C10_Pa"]["value"] == pytest.approx(2500.0, rel=1e-9)
    assert [t["loading"] for t in row["tests"]] == ["tension", "equibiaxial", "planar"]
    assert all(t["r_squared"] == pytest.approx(1.0) for t in row["tests"])
    for entry in row["predictions"]:
        stretch = np.asarray(entry["stretch"])
        assert entry["tested"] and stretch[-1] == pytest.approx(3.0)
        expected = _neo_hookean_stress_Pa(stretch, entry["loading"], 2500.0)
        np.testing.assert_allclose(entry["nominal_stress_Pa"], expected, rtol=1e-9)
    saved = json.loads((out / "neo_hookean.json").read_text())
    assert saved["tests"] == row["tests"] and len(saved["data_files"]) == 3


def test_ogden_fits_treloar_s_three_tests_jointly_and_predicts_the_untested_loadings(
    tmp_path, capsys
):
    """Issue 36: a 3-term Ogden fitted jointly to Treloar's uniaxial, equibiaxial and planar
    tests describes each (R^2 > 0.99 each); fitted to the uniaxial test alone, its stress in
    the two loadings not tested is reported as a prediction."""
    arguments = ["fit", "hyperelastic", "--model", "ogden:3", "--out", str(tmp_path / "o")]
    for loading, path in TRELOAR.items():
        arguments += ["--test", loading, str(path)]
    assert main(arguments) == 0
    captured = capsys.readouterr()
    for name in ("treloar_uniaxial (tension)", "treloar_equibiaxial", "treloar_planar"):
        (line,) = [x for x in captured.out.splitlines() if x.strip().startswith(name)]
        assert float(re.search(r"R\^2 = ([0-9.]+)", line).group(1)) > 0.99
    assert "equibiaxial at stretch 4.44" in captured.out and "(tested)" in captured.out
    alone = ["fit", "hyperelastic", "--model", "ogden:3", "--out", str(tmp_path / "a")]
    assert main([*alone, "--test", "tension", str(TRELOAR["tension"])]) == 0
    out = capsys.readouterr().out
    assert re.search(r"equibiaxial at stretch 7.6: nominal stress \S+ Pa \(predicted\)", out)
    assert re.search(r"planar at stretch 7.6: nominal stress \S+ Pa \(predicted\)", out)


def test_usd_writes_only_an_identified_stable_model_unless_asked(tmp_path, capsys):
    """Issue 36: --usd wrote the best model by R^2 although it was not identified; now the
    best identified and stable one is written and named, none at all is one line (exit 2),
    and --usd-any-model writes the best by R^2."""
    base = ["fit", "hyperelastic", "--test", "tension", str(TRELOAR["tension"])]
    usd = tmp_path / "m.usda"
    status = main(
        [*base, "--model", "ogden:3,neo_hookean", "--out", str(tmp_path / "a"), "--usd", str(usd)]
    )
    err = capsys.readouterr().err
    assert status == 0 and usd.is_file()
    assert "writing the best one that is, neo_hookean" in err
    assert '"model": "neo_hookean"' in usd.read_text() or "neo_hookean" in usd.read_text()
    usd.unlink()
    status = main([*base, "--model", "ogden:3", "--out", str(tmp_path / "b"), "--usd", str(usd)])
    err = capsys.readouterr().err
    assert status == 2 and not usd.exists()
    assert (
        err.strip().splitlines()[-1].startswith("warptissue: error: option --usd: no fitted model")
    )
    status = main(
        [
            *base,
            "--model",
            "ogden:3",
            "--out",
            str(tmp_path / "c"),
            "--usd",
            str(usd),
            "--usd-any-model",
        ]
    )
    capsys.readouterr()
    assert status == 0 and usd.is_file()


def test_tensile_data_under_the_default_compression_name_loading_tension(tmp_path, capsys):
    """Issue 36: tensile data with the default --loading compression got "the compressive
    nominal strain must stay below 1 ... check the specimen height"."""
    path = tmp_path / "pull.csv"
    d = np.linspace(0.0, 0.16, 9)
    path.write_text(
        "displacement_m,force_N\n" + "".join(f"{float(x)!r},{50 * float(x)!r}\n" for x in d)
    )
    status = main(["fit", "uniaxial", str(path), "--area-m2", "1e-4", "--height-m", "0.08"])
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1
    assert "the data look tensile" in err and "--loading tension" in err


def test_bad_test_loading_and_missing_stress_column_are_one_line(tmp_path, capsys):
    path = tmp_path / "t.csv"
    path.write_text("stretch,force_N\n1,0\n2,1\n")
    assert main(["fit", "hyperelastic", "--test", "shear", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "loading must be one of" in err
    assert main(["fit", "hyperelastic", "--test", "tension", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no nominal stress column" in err and str(path) in err


def test_stretches_of_the_other_loading_or_not_positive_name_the_fix(tmp_path, capsys):
    """Hunting issue 36's kind: tensile stretches under --test compression got "strains are
    magnitudes ... flip the sign"; they now name the loading, and a stretch of 0 is named."""
    path = tmp_path / "pull.csv"
    path.write_text("stretch,nominal_stress_Pa\n1.0,0\n1.5,1000\n2.0,2000\n")
    assert main(["fit", "hyperelastic", "--test", "compression", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "give the test's loading as tension" in err
    path.write_text("stretch,nominal_stress_Pa\n1.0,0\n0.0,1000\n")
    assert main(["fit", "hyperelastic", "--test", "compression", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "a stretch (L / L0) must be positive" in err
