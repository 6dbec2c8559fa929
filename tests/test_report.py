"""Tests of warptissue.report: fit outputs, plots and comparison tables."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from matplotlib.image import imread

from warptissue.errors import InputError
from warptissue.lsq import fit_curve
from warptissue.report import comparison_table, plot_fit, write_comparison, write_fit_outputs


def linear_fit():
    x = np.linspace(0.0, 1.0, 25)
    y = 2.0 * x + 1.0 + 0.01 * np.sin(11.0 * x)
    result = fit_curve(
        lambda p: p[0] * x + p[1], [1.0, 0.0], y, parameter_names=["slope_Pa", "offset_Pa"]
    )
    return x, y, result


def test_write_fit_outputs_writes_consistent_json_csv_png(tmp_path):
    x, y, result = linear_fit()
    paths = write_fit_outputs(
        tmp_path / "out",
        "line",
        result,
        {"strain": x, "measured_stress_Pa": y, "fitted_stress_Pa": result.fitted},
        metadata={"data": "synthetic"},
    )
    assert set(paths) == {"json", "csv", "png"}
    summary = json.loads(paths["json"].read_text())
    assert summary["parameters"]["slope_Pa"]["value"] == pytest.approx(result.x[0])
    assert summary["metadata"] == {"data": "synthetic"}
    with paths["csv"].open() as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == x.size
    assert float(rows[3]["fitted_stress_Pa"]) == pytest.approx(result.fitted[3], rel=1e-15)
    image = imread(paths["png"])
    assert image.ndim == 3 and image.shape[0] > 100
    assert not list((tmp_path / "out").glob(".*tmp*"))


def test_write_fit_outputs_needs_measured_and_fitted_columns(tmp_path):
    x, y, result = linear_fit()
    with pytest.raises(InputError, match="fitted"):
        write_fit_outputs(tmp_path, "bad", result, {"strain": x, "measured_stress_Pa": y})


def test_plot_fit_rejects_mismatched_arrays_and_leaves_no_file(tmp_path):
    with pytest.raises(InputError):
        plot_fit(tmp_path / "p.png", np.zeros(3), np.zeros(2), np.zeros(3), xlabel="x", ylabel="y")
    assert not list(tmp_path.iterdir())


def test_comparison_table_text_and_json(tmp_path):
    rows = [
        {"model": "mooney_rivlin", "r_squared": 0.99691234, "stable_up_to_strain": 0.05},
        {"model": "neo_hookean", "r_squared": 0.9386, "stable_up_to_strain": None},
    ]
    text = comparison_table(rows)
    lines = text.splitlines()
    assert lines[0].split() == ["model", "r_squared", "stable_up_to_strain"]
    assert "0.996912" in lines[2] and lines[3].split()[-1] == "-"
    paths = write_comparison(tmp_path, "comparison", rows)
    assert json.loads(paths["json"].read_text())["models"][1]["stable_up_to_strain"] is None
    assert paths["txt"].read_text().strip() == text


def test_axis_labels_carry_units_not_column_names():
    from warptissue.report import axis_label

    assert axis_label("time_s") == "time (s)"
    assert axis_label("measured_force_N") == "force (N)"
    assert axis_label("displacement_m") == "displacement (m)"
    assert axis_label("fitted_nominal_stress_Pa") == "nominal stress (Pa)"
    assert axis_label("k1_N_per_m") == "k1 (N/m)"
    assert axis_label("nominal_strain") == "nominal strain (-)"


def _captured_figures(monkeypatch):
    from matplotlib.figure import Figure

    figures = []
    original = Figure.savefig

    def capture(self, *args, **kwargs):
        figures.append(self)
        return original(self, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", capture)
    return figures


def test_plot_shows_units_parameters_log_time_and_decimates(tmp_path, monkeypatch):
    figures = _captured_figures(monkeypatch)
    time = np.linspace(0.0, 100.0, 50_001)
    force = 1.0 + np.exp(-time / 3.0)
    result = fit_curve(
        lambda p: p[0] + p[1] * np.exp(-time / 3.0),
        [0.5, 0.5],
        force,
        parameter_names=("equilibrium_force_N", "relaxing_force_N"),
        parameter_units=("N", "N"),
    )
    write_fit_outputs(
        tmp_path,
        "relax",
        result,
        {"time_s": time, "measured_force_N": force, "fitted_force_N": result.fitted},
        log_x=True,
    )
    curves, residuals = figures[0].axes
    assert residuals.get_xlabel() == "time (s)"
    assert curves.get_ylabel() == "force (N)"
    assert curves.get_xscale() == "log"
    legend = "\n".join(t.get_text() for t in curves.get_legend().get_texts())
    assert "equilibrium force = 1 N" in legend and "relaxing force = 1 N" in legend
    for line in curves.get_lines():
        assert 0 < len(line.get_xdata()) <= 4001
        assert np.all(np.asarray(line.get_xdata()) > 0.0)


def test_plot_of_several_records_has_one_colour_per_record(tmp_path, monkeypatch):
    figures = _captured_figures(monkeypatch)
    x, y, result = linear_fit()
    plot_fit(
        tmp_path / "joint.png",
        np.concatenate([x, x]),
        np.concatenate([y, y]),
        np.concatenate([result.fitted, result.fitted]),
        xlabel="time (s)",
        ylabel="force (N)",
        groups=np.repeat([0, 1], x.size),
        group_names=("ramp.csv", "step.csv"),
    )
    texts = [t.get_text() for t in figures[0].axes[0].get_legend().get_texts()]
    assert texts == [
        "ramp.csv: measured",
        "ramp.csv: fitted",
        "step.csv: measured",
        "step.csv: fitted",
    ]


# --- The inverse-FE fit's report (warptissue fit indentation) ------------------------------


def _indentation_fit(study):
    """An IndentationFit-like object of two records: C10 of a line F = k C10 d fitted to
    noisy samples (the report only reads the fit's attributes)."""
    import dataclasses
    from types import SimpleNamespace

    rng = np.random.default_rng(3)
    records, depths, measured = [], [], []
    for k, name in enumerate(("data/fast.csv", "data/slow.csv")):
        time = np.linspace(0.0, 2.0 + 3.0 * k, 40 + 60 * k)
        depth = np.minimum(time, 1.0) * 1e-3
        depths.append(depth)
        measured.append(0.02 * depth / 1e-3 + rng.normal(0.0, 1e-4, time.size))
        records.append(SimpleNamespace(file=name, time_s=time, depth_m=depth))
    all_depth, all_measured = np.concatenate(depths), np.concatenate(measured)
    result = fit_curve(
        lambda p: p[0] * 7e-2 * all_depth,
        [250.0],
        all_measured,
        parameter_names=["C10_Pa"],
        parameter_units=["Pa"],
    )
    start = 0
    for record, force in zip(records, measured, strict=True):
        stop = start + force.size
        record.measured_force_N = force
        record.fitted_force_N = result.fitted[start:stop]
        record.r_squared, record.rmse_N, start = 0.99, 1e-4, stop
    material = dataclasses.replace(study.material, C10_Pa=float(result.x[0]))
    fit = SimpleNamespace(
        study=study,
        fitted_study=dataclasses.replace(study, material=material),
        result=result,
        records=tuple(records),
        strategy="joint",
        stage_one=None,
        forward_solves=4,
        finite_difference_solves=8,
        status="converged",
        message="test",
        seconds=1.0,
        warnings=[],
        start_cost=0.5 * float(np.sum((250.0 * 7e-2 * all_depth - all_measured) ** 2)),
    )
    fit.to_dict = lambda: {"parameters": result.to_dict()["parameters"], "status": fit.status}
    return fit


def test_indentation_fit_outputs_csv_json_study_and_four_panels(tmp_path, monkeypatch):
    from warptissue.report import indentation_fit_columns, write_indentation_fit_outputs
    from warptissue.study import load_study

    root = Path(__file__).resolve().parents[1]
    fit = _indentation_fit(load_study(root / "scenes" / "tutorial_punch.toml"))
    figures = _captured_figures(monkeypatch)
    files = write_indentation_fit_outputs(tmp_path / "out", fit)
    assert {k: p.name for k, p in files.items()} == {
        "study": "fitted_study.toml",
        "json": "fit.json",
        "csv": "fit_curves.csv",
        "png": "fit.png",
    }
    with files["csv"].open() as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == [
        "record",
        "time_s",
        "depth_m",
        "measured_force_N",
        "fitted_force_N",
        "residual_N",
    ]
    assert len(rows) == 40 + 100 and rows[0]["record"] == "data/fast.csv"
    assert rows[-1]["record"] == "data/slow.csv"
    for row in rows[::17]:
        residual = float(row["fitted_force_N"]) - float(row["measured_force_N"])
        assert float(row["residual_N"]) == pytest.approx(residual, abs=1e-15)
    columns = indentation_fit_columns(fit)
    assert columns["measured_force_N"] == pytest.approx(
        np.concatenate([r.measured_force_N for r in fit.records])
    )
    summary = json.loads(files["json"].read_text())
    assert summary["parameters"]["C10_Pa"]["value"] == pytest.approx(fit.result.x[0])
    assert summary["fitted_study_file"] == "fitted_study.toml" and "numpy" in summary["software"]
    fitted = load_study(files["study"])
    assert fitted.material.C10_Pa == pytest.approx(fit.result.x[0], rel=1e-12)
    assert fitted.material.C10_Pa != pytest.approx(287.5, rel=1e-3)
    by_depth, by_time, residuals, history = figures[0].axes
    assert by_depth.get_xlabel() == "depth (mm)" and by_time.get_ylabel() == "force (N)"
    assert residuals.get_ylabel() == "fitted - measured (N)"
    legend = [t.get_text() for t in by_depth.get_legend().get_texts()]
    assert legend[0] == "fast.csv: measured" and legend[3].startswith("slow.csv: fitted")
    # The start's cost, then one cost per trial step of the engine.
    costs = history.get_lines()[0].get_ydata()
    assert len(costs) == len(fit.result.history) + 1 > 1 and costs[0] == fit.start_cost
    assert "C10_Pa" in figures[0].get_suptitle()
    assert imread(files["png"]).shape[1] > 1000
