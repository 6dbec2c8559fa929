"""Plots and files that every fit writes: JSON result, CSV of measured vs fitted, PNG.

All writes are atomic (:func:`warptissue.io.atomic_path`); figures use matplotlib's Agg
canvas without touching pyplot's global state, so that reports can be written from worker
threads and on machines without a display.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from warptissue.errors import InputError
from warptissue.fit.result import FitResult
from warptissue.io import atomic_path, write_csv, write_json

__all__ = [
    "MAX_PLOT_POINTS",
    "axis_label",
    "comparison_table",
    "parameter_legend",
    "plot_fit",
    "write_comparison",
    "write_fit_outputs",
]


_UNIT_SUFFIXES: tuple[tuple[str, str], ...] = (
    ("_N_s_per_m", "N s/m"),
    ("_N_per_m", "N/m"),
    ("_per_m", "1/m"),
    ("_Pa", "Pa"),
    ("_Hz", "Hz"),
    ("_N", "N"),
    ("_m", "m"),
    ("_s", "s"),
)
"""Column-name unit suffixes (longest first) and the unit each stands for."""

MAX_PLOT_POINTS = 4000
"""Records with more samples are decimated (every k-th sample) for plotting only."""


def axis_label(column: str) -> str:
    """An axis label with its unit from a column name: ``"time_s"`` -> ``"time (s)"``.

    A ``measured_`` or ``fitted_`` prefix is dropped; a name without a unit suffix is taken as
    dimensionless (``"nominal_strain"`` -> ``"nominal strain (-)"``).
    """
    name = column.removeprefix("measured_").removeprefix("fitted_")
    for suffix, unit in _UNIT_SUFFIXES:
        if name.endswith(suffix) and len(name) > len(suffix):
            return f"{name.removesuffix(suffix).replace('_', ' ')} ({unit})"
    return f"{name.replace('_', ' ')} (-)"


def parameter_legend(result: FitResult) -> str:
    """The fitted parameters as legend text, one ``name = value unit`` per line."""
    lines = []
    for name, value, unit in zip(
        result.parameter_names, result.x, result.parameter_units, strict=True
    ):
        label = axis_label(name).rsplit(" (", 1)[0] if unit else name
        lines.append(f"{label} = {float(value):.4g} {unit}".rstrip())
    return "\n".join(lines)


def _decimation(size: int, max_points: int) -> slice:
    """Every k-th sample so that at most about ``max_points`` remain."""
    return slice(None, None, max(1, -(-size // max(int(max_points), 1))))


def plot_fit(
    path: str | Path,
    x: np.ndarray,
    measured: np.ndarray,
    fitted: np.ndarray,
    *,
    xlabel: str,
    ylabel: str,
    title: str = "",
    fitted_label: str = "fitted",
    log_x: bool = False,
    groups: np.ndarray | None = None,
    group_names: Sequence[str] | None = None,
    max_points: int = MAX_PLOT_POINTS,
) -> Path:
    """Plot measured data, the fitted curve and the residuals to a PNG, atomically.

    Args:
        path: Output PNG file.
        x: Abscissa, shape (m,).
        measured: Measured values, shape (m,).
        fitted: Fitted values, shape (m,).
        xlabel: Label of the abscissa, with its unit.
        ylabel: Label of the ordinate, with its unit.
        title: Figure title.
        fitted_label: Legend entry of the fitted curve (e.g. the fitted parameters).
        log_x: Logarithmic abscissa (relaxation records); samples with x <= 0 are left out
            of the plot.
        groups: Integer record index per sample, shape (m,), for several records on one
            plot (a joint fit): each record gets its own colour.
        group_names: Legend names of the groups (default "record 1", ...).
        max_points: Each group with more samples is decimated (every k-th sample) for the
            plot; the CSV keeps every sample.

    Returns:
        The path written.

    Raises:
        InputError: Arrays of different lengths or with no values.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    abscissa = np.asarray(x, dtype=np.float64).reshape(-1)
    data = np.asarray(measured, dtype=np.float64).reshape(-1)
    model = np.asarray(fitted, dtype=np.float64).reshape(-1)
    labels = np.zeros(abscissa.size, dtype=int) if groups is None else np.asarray(groups)
    if not (abscissa.size == data.size == model.size == labels.size) or abscissa.size == 0:
        raise InputError(
            "plot_fit needs non-empty x, measured and fitted of equal length",
            value=(abscissa.size, data.size, model.size),
        )
    figure = Figure(figsize=(6.4, 5.6), layout="constrained")
    FigureCanvasAgg(figure)
    curves, residuals = figure.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": (3, 1)})
    residuals.axhline(0.0, color="0.5", linewidth=1)
    unique = list(dict.fromkeys(labels.tolist()))
    for k, group in enumerate(unique):
        keep = np.flatnonzero((labels == group) & ((abscissa > 0.0) if log_x else True))
        keep = keep[np.argsort(abscissa[keep], kind="stable")][_decimation(keep.size, max_points)]
        colour = f"C{k % 10}"
        name = (
            ""
            if len(unique) == 1
            else (f"{group_names[k]}: " if group_names else f"record {k + 1}: ")
        )
        curves.plot(
            abscissa[keep],
            data[keep],
            "o",
            color=colour,
            markersize=3,
            alpha=0.5,
            label=f"{name}measured",
        )
        curves.plot(
            abscissa[keep],
            model[keep],
            "-",
            color="k" if len(unique) == 1 else colour,
            linewidth=1.5,
            label=f"{name}fitted" if len(unique) > 1 else fitted_label,
        )
        residuals.plot(abscissa[keep], model[keep] - data[keep], ".", color=colour, markersize=3)
    if len(unique) > 1 and fitted_label != "fitted":
        curves.plot([], [], " ", label=fitted_label)
    if log_x:
        curves.set_xscale("log")
    curves.set_ylabel(ylabel)
    curves.legend(fontsize="small")
    curves.grid(alpha=0.3)
    if title:
        curves.set_title(title)
    residuals.set_xlabel(xlabel)
    residuals.set_ylabel(
        f"fitted - measured{ylabel[ylabel.rfind(' (') :] if ' (' in ylabel else ''}"
    )
    residuals.grid(alpha=0.3)
    with atomic_path(path) as temporary:
        figure.savefig(temporary, format="png", dpi=120)
    return Path(path)


def _first_column(columns: Mapping[str, Any], prefix: str) -> str:
    for name in columns:
        if name.startswith(prefix):
            return name
    raise InputError(
        f"write_fit_outputs needs a CSV column whose name starts with {prefix!r}",
        value=list(columns),
    )


def write_fit_outputs(
    out_dir: str | Path,
    name: str,
    result: FitResult,
    columns: Mapping[str, Sequence[float] | np.ndarray],
    *,
    metadata: Mapping[str, Any] | None = None,
    title: str | None = None,
    log_x: bool = False,
    group_column: str | None = None,
    group_names: Sequence[str] | None = None,
) -> dict[str, Path]:
    """Write a fit's JSON result, its measured-vs-fitted CSV and its PNG plot.

    Args:
        out_dir: Output folder (created).
        name: Base name of the three files: ``NAME.json``, ``NAME.csv``, ``NAME.png``.
        result: The fit.
        columns: CSV columns, name (with unit) to values of equal length. The FIRST column is
            the plot's abscissa; the first column whose name starts with "measured" and the
            first one starting with "fitted" are plotted. Other columns go to the CSV only.
            Axis labels come from the names with their units (:func:`axis_label`).
        metadata: Extra JSON content (data file, specimen, model details), stored under
            "metadata".
        title: Plot title (default: ``name``); the legend lists the fitted parameters.
        log_x: Logarithmic abscissa (relaxation: time).
        group_column: A column of record indices (a joint fit of several records): each
            record is plotted in its own colour.
        group_names: Legend names of the records.

    Returns:
        {"json": path, "csv": path, "png": path}.

    Raises:
        InputError: No columns, no "measured"/"fitted" column, or columns of unequal length.
    """
    if not columns:
        raise InputError("write_fit_outputs needs at least one column")
    folder = Path(out_dir)
    x_name = next(iter(columns))
    measured_name = _first_column(columns, "measured")
    fitted_name = _first_column(columns, "fitted")
    csv_path = write_csv(folder / f"{name}.csv", columns)
    summary = result.to_dict()
    if metadata:
        summary["metadata"] = dict(metadata)
    json_path = write_json(folder / f"{name}.json", summary)
    png_path = plot_fit(
        folder / f"{name}.png",
        np.asarray(columns[x_name]),
        np.asarray(columns[measured_name]),
        np.asarray(columns[fitted_name]),
        xlabel=axis_label(x_name),
        ylabel=axis_label(measured_name),
        title=name if title is None else title,
        fitted_label="fitted:\n" + parameter_legend(result),
        log_x=log_x,
        groups=None if group_column is None else np.asarray(columns[group_column]),
        group_names=group_names,
    )
    return {"json": json_path, "csv": csv_path, "png": png_path}


def comparison_table(rows: Sequence[Mapping[str, Any]]) -> str:
    """Format rows of equal keys as a plain-text table.

    The layout follows Table 1 of the needle-indentation study (one row per model fit).

    Floats are printed with 6 significant digits, None as "-".

    Args:
        rows: One mapping per model fit, e.g. {"model", "objective", "r_squared",
            "stable_up_to_strain"}; the first row's keys are the columns.

    Returns:
        The table, one line per row after a header and a rule.
    """
    if not rows:
        return "(no fits)"
    headers = list(rows[0])

    def cell(value: Any) -> str:
        if value is None:
            return "-"
        if isinstance(value, float | np.floating):
            return f"{float(value):.6g}"
        return str(value)

    cells = [[cell(row.get(h)) for h in headers] for row in rows]
    widths = [max(len(h), *(len(r[i]) for r in cells)) for i, h in enumerate(headers)]
    lines = [headers, ["-" * w for w in widths], *cells]
    return "\n".join(
        "  ".join(c.ljust(w) for c, w in zip(line, widths, strict=True)).rstrip() for line in lines
    )


def write_comparison(
    out_dir: str | Path, name: str, rows: Sequence[Mapping[str, Any]]
) -> dict[str, Path]:
    """Write a model-comparison table as ``NAME.txt`` (text) and ``NAME.json``, atomically.

    Returns:
        {"txt": path, "json": path}.
    """
    folder = Path(out_dir)
    text_path = folder / f"{name}.txt"
    with atomic_path(text_path) as temporary:
        temporary.write_text(comparison_table(rows) + "\n", encoding="utf-8")
    json_path = write_json(folder / f"{name}.json", {"models": [dict(r) for r in rows]})
    return {"txt": text_path, "json": json_path}
