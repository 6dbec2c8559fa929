"""``warptissue fit relaxation`` / ``punch-modulus`` end to end on synthetic CSV files."""

from __future__ import annotations

import json

import numpy as np
import pytest

from warptissue.cli import main
from warptissue.cli.fit_relaxation import parse_model
from warptissue.errors import InputError
from warptissue.io import write_csv
from warptissue.fit.punch import flat_punch_force_N
from warptissue.viscoelastic import PronySeries


@pytest.fixture
def relaxation_csv(tmp_path, rng):
    time = np.arange(0.0, 60.0, 0.05)
    x = 2e-3 * np.minimum(time / 0.5, 1.0)
    force = PronySeries(5.0, (6.0, 4.0), (0.8, 15.0)).force_N(time, x)
    force = force + rng.normal(0, 1e-4, time.size)
    path = tmp_path / "liver.csv"
    write_csv(path, {"time_s": time, "displacement_m": x, "force_N": force})
    return path


def test_relaxation_cli_writes_json_csv_png(relaxation_csv, tmp_path, capsys):
    out = tmp_path / "out"
    status = main(
        [
            "fit",
            "relaxation",
            str(relaxation_csv),
            "--model",
            "prony:2",
            "--out",
            str(out),
            "--json",
        ]
    )
    assert status == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed["model"]["g"] == pytest.approx([0.4, 4.0 / 15.0], rel=0.03)
    for suffix in ("json", "csv", "png"):
        assert (out / f"liver_prony2.{suffix}").stat().st_size > 0
    saved = json.loads((out / "liver_prony2.json").read_text())
    assert saved["parameters"]["tau2_s"]["unit"] == "s"
    assert saved["r_squared"] > 0.99


def test_relaxation_cli_sls_summary(relaxation_csv, tmp_path, capsys):
    assert (
        main(["fit", "relaxation", str(relaxation_csv), "--out", str(tmp_path), "--p0", "10,5,1"])
        == 0
    )
    text = capsys.readouterr().out
    assert "relaxation_time_s" in text
    saved = json.loads((tmp_path / "liver_sls.json").read_text())
    assert "seed001_eq4_printed_form" in saved["metadata"]


def test_relaxation_cli_errors_are_one_line(relaxation_csv, tmp_path, capsys):
    assert main(["fit", "relaxation", str(relaxation_csv), "--model", "maxwell"]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "maxwell" in error
    assert main(["fit", "relaxation", str(relaxation_csv), "--p0", "1,x"]) == 2
    assert "--p0" in capsys.readouterr().err
    bad = tmp_path / "bad.csv"
    bad.write_text("time_s,displacement_m,force_N\n0,0,0\n1,0.001,nan\n")
    assert main(["fit", "relaxation", str(bad), "--out", str(tmp_path)]) == 2
    error = capsys.readouterr().err
    assert "bad.csv" in error and error.count("\n") == 1


def test_punch_modulus_cli(tmp_path, capsys):
    depth = np.linspace(0.0, 1e-3, 21)
    force = np.concatenate(
        [
            [0.0],
            flat_punch_force_N(depth[1:], radius_m=1e-3, youngs_modulus_Pa=3e4, poissons_ratio=0.5),
        ]
    )
    path = tmp_path / "probe.csv"
    write_csv(path, {"displacement_m": depth, "force_N": force})
    status = main(
        [
            "fit",
            "punch-modulus",
            str(path),
            "--radius-m",
            "1e-3",
            "--out",
            str(tmp_path / "o"),
            "--json",
        ]
    )
    assert status == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed["fit"]["parameters"]["youngs_modulus_Pa"]["value"] == pytest.approx(3e4)


def test_parse_model():
    assert parse_model("prony:3") == ("prony", 3)
    assert parse_model("wiechert-nonlinear") == ("wiechert-nonlinear", 2)
    for bad in ("prony:0", "sls:2", "kelvin"):
        with pytest.raises(InputError):
            parse_model(bad)
