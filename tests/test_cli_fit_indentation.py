"""Tests of ``warptissue fit indentation STUDY.toml`` (warptissue.cli.fit_indentation).

The record is made by the forward FE on the study's own mesh with a known C10 (plus seeded
noise), so the fit must give C10 back; the fitted study must run under ``warptissue
simulate`` and give the fitted force; the exit statuses are the documented ones.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from warptissue.cli import main
from warptissue.io import write_csv

TRUE_C10_PA = 400.0
"""C10 of the synthetic record (the study's [material] says 287.5 Pa)."""
NOISE_SHARE = 0.003
"""Gaussian noise of the record, as a share of its largest force."""

STUDY = """\
schema_version = 2
name = "tiny_fit"

[specimen]
shape = "block"
width_m = 0.008
thickness_m = 0.004
quarter = true
element = "TET10"
size_near_m = 0.0005
size_far_m = 0.002
growth = 1.5

[indenter]
kind = "flat_punch"
radius_m = 0.001

[protocol]
max_depth_m = 0.0003
steps = 3

[material]
model = "neo_hookean"
C10_Pa = 287.5
bulk_modulus_Pa = 575000.0

[solver]
device = "cpu"

[[data]]
file = "ramp.csv"

[fit]
free = ["C10_Pa"]
time_steps = 6
"""


@pytest.fixture(scope="module")
def record_columns() -> dict[str, np.ndarray]:
    """A loading ramp to 0.3 mm at 0.1 mm/s, 0.1 s apart, force from the forward FE."""
    import dataclasses
    import tomllib

    from warptissue.fem import simulate_indentation
    from warptissue.simulate import build_mesh, build_problem
    from warptissue.study import study_from_dict

    data = tomllib.loads(STUDY)
    data["schema_version"] = 1
    for key in ("data", "fit"):
        data.pop(key)
    study = study_from_dict(data)
    study = dataclasses.replace(
        study, material=dataclasses.replace(study.material, C10_Pa=TRUE_C10_PA)
    )
    depths = np.linspace(0.0, 3e-4, 13)
    fe = simulate_indentation(
        build_problem(study, build_mesh(study)), depths[1:], progress=False, device="cpu"
    )
    assert fe.completed
    force = np.concatenate([[0.0], fe.reaction_force_N])
    noise = np.random.default_rng(7).normal(0.0, NOISE_SHARE * force.max(), force.size)
    return {"time_s": depths / 1e-4, "displacement_m": depths, "force_N": force + noise}


@pytest.fixture
def study_file(tmp_path: Path, record_columns: dict[str, np.ndarray]) -> Path:
    write_csv(tmp_path / "ramp.csv", record_columns)
    path = tmp_path / "tiny.toml"
    path.write_text(STUDY, encoding="utf-8")
    return path


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as f:
        return list(csv.DictReader(f))


@pytest.mark.slow
def test_fit_writes_its_report_and_summary_and_the_fitted_study_runs(study_file, tmp_path, capsys):
    out = tmp_path / "out"
    status = main(["fit", "indentation", str(study_file), "-o", str(out), "--usd"])
    captured = capsys.readouterr()
    assert status == 0, captured.err
    # The summary: parameters, statistics, forward solves, status and the files written.
    printed = captured.out
    assert "C10_Pa" in printed and "R^2 =" in printed and "forward solves" in printed
    assert "status: converged" in printed or "status: stopped_at_r_squared" in printed
    assert "fit.json" in printed and "fitted_study.toml" in printed
    names = {p.name for p in out.iterdir()}
    assert {"fit.json", "fit_curves.csv", "fit.png", "fitted_study.toml", "specimen.usda"} <= names
    summary = json.loads((out / "fit.json").read_text())
    c10 = summary["parameters"]["C10_Pa"]
    # The record was made by the same FE with C10 = 400 Pa: the fit finds it within 2 %, and
    # its standard error covers the truth (the noise is 0.3 % of the peak force).
    assert c10["value"] == pytest.approx(TRUE_C10_PA, rel=0.02)
    assert abs(c10["value"] - TRUE_C10_PA) <= 3 * c10["standard_error"] + 1e-9
    assert summary["status"] in ("converged", "stopped_at_r_squared")
    assert summary["r_squared"] > 0.999
    assert summary["forward_solves"] >= 1 and "warp-lang" in summary["software"]
    rows = _rows(out / "fit_curves.csv")
    assert len(rows) == 13 and {r["record"] for r in rows} == {"ramp.csv"}
    measured = np.array([float(r["measured_force_N"]) for r in rows])
    assert measured == pytest.approx(
        np.loadtxt(tmp_path / "ramp.csv", delimiter=",", skiprows=1)[:, 2], abs=1e-12
    )
    # The fitted study runs as it is, with the fitted C10: its force at 0.3 mm is the fitted
    # curve's (the same FE; interpolation only between the fit's steps).
    assert (
        main(
            ["simulate", str(out / "fitted_study.toml"), "--out", str(tmp_path / "sim"), "--quiet"]
        )
        == 0
    )
    simulated = json.loads((tmp_path / "sim" / "result.json").read_text())
    final = simulated["force_curve"]["reaction_force_N"][-1]
    fitted = [float(r["fitted_force_N"]) for r in rows]
    assert final == pytest.approx(fitted[-1], rel=0.01)
    assert final == pytest.approx(measured[-1], rel=0.05)


def test_ctrl_c_keeps_the_best_parameters_and_exits_130(study_file, tmp_path, capsys, monkeypatch):
    import warptissue.fit.indentation as module

    real = module.fit_indentation
    seen = []

    def interrupt_after_the_first_step(progress):
        seen.append(progress)
        if len(seen) == 1:
            raise KeyboardInterrupt

    def fit_with_ctrl_c(study, **options):
        return real(study, callback=interrupt_after_the_first_step, **options)

    monkeypatch.setattr(module, "fit_indentation", fit_with_ctrl_c)
    out = tmp_path / "out"
    assert main(["fit", "indentation", str(study_file), "-o", str(out), "--quiet"]) == 130
    err = capsys.readouterr().err
    assert "interrupted" in err and "best parameters" in err and "Traceback" not in err
    summary = json.loads((out / "fit.json").read_text())
    assert summary["status"] == "interrupted"
    best = summary["parameters"]["C10_Pa"]["value"]
    # Stopped after one trial step: the outputs hold the best point evaluated (the start, or
    # the first trial where it was better), not a half-written state.
    rows = _rows(out / "fit_curves.csv")
    cost = 0.5 * sum(float(r["residual_N"]) ** 2 for r in rows)
    # Every file holds that one point: its curves' cost is the JSON's, no worse than at the
    # start values, and the fitted study carries its C10.
    assert cost == pytest.approx(summary["cost"], rel=1e-9)
    assert cost <= summary["start_cost"] * (1 + 1e-12)
    assert cost <= seen[0].cost * (1 + 1e-9)
    from warptissue.study import load_study

    fitted = load_study(out / "fitted_study.toml")
    assert fitted.material.C10_Pa == pytest.approx(best, rel=1e-12)
    assert (out / "fit.png").is_file()


def test_bad_input_is_one_line_with_status_2(study_file, tmp_path, capsys):
    text = study_file.read_text()
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace('free = ["C10_Pa"]', 'free = ["C11_Pa"]'), encoding="utf-8")
    assert main(["fit", "indentation", str(bad), "-o", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "bad.toml" in err and "C11_Pa" in err
    forward = tmp_path / "forward.toml"
    forward.write_text(
        text.split("[[data]]")[0].replace("schema_version = 2", "schema_version = 1")
    )
    assert main(["fit", "indentation", str(forward)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "forward.toml" in err and "[[data]]" in err
    assert main(["fit", "indentation", str(tmp_path / "missing.toml")]) == 2
    assert capsys.readouterr().err.count("\n") == 1
    # A record measured with another probe (its sidecar says so) is refused before fitting.
    (tmp_path / "ramp.json").write_text(json.dumps({"probe_radius_m": 0.002}))
    assert main(["fit", "indentation", str(study_file), "-o", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "ramp" in err and "probe_radius_m" in err
    assert not (tmp_path / "o").exists()


def test_help_states_the_exit_statuses(capsys):
    with pytest.raises(SystemExit):
        main(["fit", "indentation", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    for status in ("0 fitted", "2 bad input", "4 the fit failed", "130 interrupted"):
        assert status in text


@pytest.mark.slow
def test_the_shipped_liver_records_are_what_their_script_makes(tmp_path):
    """scenes/data/liver_ramp_*.csv come from scripts/tools/make_relaxation_example.py (the
    forward FE of scenes/liver_fit.toml with the truth of the sidecar): its quick form remakes
    the fast record (the same FE run and noise) and writes its first 10 s, which must be the
    shipped file's first 10 s, with the same sidecar."""
    from _scripts import ROOT, run_script

    run_script(
        "scripts/tools/make_relaxation_example.py",
        "--out-dir",
        str(tmp_path),
        "--quick",
        cwd=tmp_path,
    )
    shipped_csv = ROOT / "scenes" / "data" / "liver_ramp_hold.csv"
    made = np.loadtxt(tmp_path / "liver_ramp_hold.csv", delimiter=",", skiprows=1)
    shipped = np.loadtxt(shipped_csv, delimiter=",", skiprows=1)
    assert 400 < made.shape[0] < shipped.shape[0]
    shipped = shipped[: made.shape[0]]
    # Written with 6 decimals (1 uN against the 0.2 mN noise); the FE's own round-off
    # between machines may move a last digit.
    np.testing.assert_allclose(made, shipped, rtol=0.0, atol=2e-6)
    assert made[:, 2].max() > 0.1  # the 4 mm peak is in the first 10 s
    sidecar = json.loads((tmp_path / "liver_ramp_hold.json").read_text())
    assert sidecar == json.loads(shipped_csv.with_suffix(".json").read_text())
    assert sidecar["truth"] == {
        "model": "neo_hookean",
        "C10_Pa": 287.5,
        "bulk_modulus_Pa": 575000.0,
        "g1": 0.348,
        "g2": 0.358,
        "tau1_s": 1.376,
        "tau2_s": 49.369,
    }


def test_a_fit_out_of_iterations_exits_4_with_its_outputs(study_file, tmp_path, capsys):
    """max_iterations = 1 cannot converge from the record's start value: the documented
    convergence status (4), the reason on stderr, the files written from the best point;
    --json prints fit.json."""
    from warptissue.errors import ConvergenceError

    text = study_file.read_text().replace("time_steps = 6", "time_steps = 6\nmax_iterations = 1")
    study_file.write_text(text)
    out = tmp_path / "out"
    status = main(["fit", "indentation", str(study_file), "-o", str(out), "--json"])
    captured = capsys.readouterr()
    err = captured.err
    assert status == ConvergenceError.exit_code == 4
    assert json.loads(captured.out) == json.loads((out / "fit.json").read_text())
    assert "error: the fit did not converge (max_iterations)" in err and "Traceback" not in err
    summary = json.loads((out / "fit.json").read_text())
    assert summary["status"] == "max_iterations" and not summary["success"]
    assert (out / "fitted_study.toml").is_file() and (out / "fit_curves.csv").is_file()


def test_two_stage_refuses_a_record_without_a_hold(study_file, tmp_path, capsys):
    """Issue 36: a ramp-only record fed stage (i) of Ahn & Kim's two stages, which invented
    a Prony series for it (g1 = 0.119, tau1 = 0.958 s) and said so only deep in fit.json;
    now it is refused in one line naming the record, before any FE run."""
    text = study_file.read_text()
    text = text.replace("C10_Pa = 287.5", "C10_Pa = 287.5\ng1 = 0.5\ntau1_s = 1.0")
    text = text.replace("time_steps = 6", 'time_steps = 6\nstrategy = "two_stage"')
    study_file.write_text(text)
    status = main(["fit", "indentation", str(study_file), "-o", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert status == 2
    assert err.count("\n") == 1 and "ramp.csv" in err and "no hold" in err
    assert not (tmp_path / "out").exists()


def test_two_stage_says_when_stage_one_did_not_converge(
    study_file, record_columns, tmp_path, capsys, monkeypatch
):
    """Issue 36: stage (i) stopped at its iteration limit, and the command printed "status:
    converged", no warning and exit 0. Now each stage (i) finding is a warning line on stderr
    naming the stage and the record, and a stage (i) that did not converge is exit 4 (as a
    stage (ii) that did not), the outputs written."""
    import functools

    from warptissue.viscoelastic.fitting import fit_qlv

    # Stage (i) as the fit plan runs it, with one iteration.
    monkeypatch.setattr(
        "warptissue.fit._setup.fit_qlv", functools.partial(fit_qlv, max_iterations=1)
    )
    time = np.concatenate([record_columns["time_s"], 3.0 + np.arange(1, 13) * 0.25])
    depth = np.concatenate([record_columns["displacement_m"], np.full(12, 3e-4)])
    peak = record_columns["force_N"][-1]
    relaxing = peak * (0.7 + 0.3 * np.exp(-np.arange(1, 13) * 0.25))
    force = np.concatenate([record_columns["force_N"], relaxing])
    write_csv(
        study_file.parent / "ramp.csv", {"time_s": time, "displacement_m": depth, "force_N": force}
    )
    text = study_file.read_text()
    text = text.replace("C10_Pa = 287.5", "C10_Pa = 287.5\ng1 = 0.3\ntau1_s = 1.0")
    text = text.replace("time_steps = 6", 'time_steps = 6\nstrategy = "two_stage"')
    study_file.write_text(text)
    out = tmp_path / "out"
    status = main(["fit", "indentation", str(study_file), "-o", str(out), "--quiet"])
    err = capsys.readouterr().err
    assert status == 4, err
    assert "warptissue: warning: stage (i) (Ahn & Kim), ramp.csv: the fit did not converge" in err
    assert "error: stage (i) (Ahn & Kim) did not converge on ramp.csv" in err
    assert "Traceback" not in err
    # The API's result says it too: its status and top-level warnings (fit.json's).
    fit = json.loads((out / "fit.json").read_text())
    assert fit["status"] == "stage_one_not_converged" and fit["success"] is False
    assert any(
        w.startswith("stage (i) (Ahn & Kim), ramp.csv: the fit did not converge")
        for w in fit["warnings"]
    )
