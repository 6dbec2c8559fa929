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

__all__ = ["comparison_table", "plot_fit", "write_comparison", "write_fit_outputs"]


def plot_fit(
    path: str | Path,
    x: np.ndarray,
    measured: np.ndarray,
    fitted: np.ndarray,
    *,
    xlabel: str,
    ylabel: str,
    title: str = "",
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
    if not (abscissa.size == data.size == model.size) or abscissa.size == 0:
        raise InputError(
            "plot_fit needs non-empty x, measured and fitted of equal length",
            value=(abscissa.size, data.size, model.size),
        )
    figure = Figure(figsize=(6.4, 5.6), layout="constrained")
    FigureCanvasAgg(figure)
    curves, residuals = figure.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": (3, 1)})
    curves.plot(abscissa, data, "o", markersize=3, alpha=0.6, label="measured")
    order = np.argsort(abscissa, kind="stable")
    curves.plot(abscissa[order], model[order], "-", linewidth=2, label="fitted")
    curves.set_ylabel(ylabel)
    curves.legend()
    curves.grid(alpha=0.3)
    if title:
        curves.set_title(title)
    residuals.axhline(0.0, color="0.5", linewidth=1)
    residuals.plot(abscissa, model - data, ".", markersize=3)
    residuals.set_xlabel(xlabel)
    residuals.set_ylabel("fitted - measured")
    residuals.grid(alpha=0.3)
    with atomic_path(path) as temporary:
        figure.savefig(temporary, format="png", dpi=120)
    return Path(path)


def _first_column(columns: Mapping[str, Any], prefix: str) -> str:
    for name in columns:
        if name.startswith(prefix):
            return name
    raise InputError(f"columns need one whose name starts with {prefix!r}", value=list(columns))


def write_fit_outputs(
    out_dir: str | Path,
    name: str,
    result: FitResult,
    columns: Mapping[str, Sequence[float] | np.ndarray],
    *,
    metadata: Mapping[str, Any] | None = None,
    title: str | None = None,
) -> dict[str, Path]:
    """Write a fit's JSON result, its measured-vs-fitted CSV and its PNG plot.

    Args:
        out_dir: Output folder (created).
        name: Base name of the three files: ``NAME.json``, ``NAME.csv``, ``NAME.png``.
        result: The fit.
        columns: CSV columns, name (with unit) to values of equal length. The FIRST column is
            the plot's abscissa; the first column whose name starts with "measured" and the
            first one starting with "fitted" are plotted. Other columns go to the CSV only.
        metadata: Extra JSON content (data file, specimen, model details), stored under
            "metadata".
        title: Plot title (default: ``name``).

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
        xlabel=x_name,
        ylabel=measured_name.removeprefix("measured_"),
        title=name if title is None else title,
    )
    return {"json": json_path, "csv": csv_path, "png": png_path}


def comparison_table(rows: Sequence[Mapping[str, Any]]) -> str:
    """Format rows of equal keys as a plain-text table (like seed 003's Table 1).

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
