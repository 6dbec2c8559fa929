"""Tests of warptissue.report: fit outputs, plots and comparison tables."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
from matplotlib.image import imread

from warptissue.errors import InputError
from warptissue.fit import fit_curve
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
