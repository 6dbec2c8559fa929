"""Tests of ``warptissue fit uniaxial`` (warptissue.cli.fit_uniaxial)."""

from __future__ import annotations

import json

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
        (["--model", "foam"], "unknown model"),
        (["--area-m2", "-1"], "area_m2"),
    ],
)
def test_errors_are_one_line_with_exit_code_2(compression_csv, capsys, arguments, message):
    base = ["fit", "uniaxial", str(compression_csv), "--area-m2", str(AREA_M2)]
    status = main([*base, "--height-m", str(HEIGHT_M), *arguments])
    error = capsys.readouterr().err.strip()
    assert status == 2
    assert message in error and len(error.splitlines()) == 1


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
