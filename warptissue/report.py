"""Plots and files that every fit writes: JSON result, CSV of measured vs fitted, PNG.

All writes are atomic (:func:`warptissue.io.atomic_path`); figures use matplotlib's Agg
canvas without touching pyplot's global state, so that reports can be written from worker
threads and on machines without a display.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from warptissue.errors import InputError
from warptissue.io import atomic_path, software_versions, write_csv, write_json
from warptissue.lsq.result import FitResult
from warptissue.study import save_study

if TYPE_CHECKING:
    from warptissue.fit.indentation import IndentationFit

__all__ = [
    "INDENTATION_FIT_FILES",
    "MAX_PLOT_POINTS",
    "axis_label",
    "comparison_table",
    "indentation_fit_columns",
    "parameter_legend",
    "plot_fit",
    "plot_indentation_fit",
    "write_comparison",
    "write_fit_outputs",
    "write_indentation_fit_outputs",
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


INDENTATION_FIT_FILES: dict[str, str] = {
    "json": "fit.json",
    "csv": "fit_curves.csv",
    "png": "fit.png",
    "study": "fitted_study.toml",
    "usd": "specimen.usda",
}
"""The files :func:`write_indentation_fit_outputs` writes, by key (``usd`` only when asked)."""


def indentation_fit_columns(fit: IndentationFit) -> dict[str, np.ndarray]:
    """The measured and fitted force of every record of an inverse-FE fit, as CSV columns.

    Args:
        fit: A :class:`warptissue.fit.indentation.IndentationFit`.

    Returns:
        ``record`` (the record's file as the study names it), ``time_s``, ``depth_m``,
        ``measured_force_N``, ``fitted_force_N`` and ``residual_N`` (fitted - measured), each
        shape (m,) with m the samples of all records (conditioned: time and depth from the
        contact); with a fitted contact point (``contact_point = "fit"``) also
        ``depth_below_fitted_contact_m``: ``max(depth_m - d0, 0)``, the FE's depth.
    """
    records = fit.records
    measured = np.concatenate([np.asarray(r.measured_force_N, float) for r in records])
    fitted = np.concatenate([np.asarray(r.fitted_force_N, float) for r in records])
    columns = {
        "record": np.concatenate(
            [np.full(len(r.time_s), str(r.file), dtype=object) for r in records]
        ),
        "time_s": np.concatenate([np.asarray(r.time_s, float) for r in records]),
        "depth_m": np.concatenate([np.asarray(r.depth_m, float) for r in records]),
        "measured_force_N": measured,
        "fitted_force_N": fitted,
        "residual_N": fitted - measured,
    }
    if getattr(fit, "contact_point", "given") == "fit":
        columns["depth_below_fitted_contact_m"] = np.concatenate(
            [np.clip(np.asarray(r.depth_m, float) - r.depth_offset_m, 0.0, None) for r in records]
        )
    return columns


def plot_indentation_fit(
    path: str | Path, fit: IndentationFit, *, max_points: int = MAX_PLOT_POINTS
) -> Path:
    """Plot an inverse-FE fit to a PNG, atomically: four panels.

    Force against depth and force against time (each record's measured samples as dots, the
    fitted FE force as a line, one colour per record; a fitted contact point as a dashed
    line), the residuals (fitted - measured)
    against time, and the convergence history of the least-squares engine (the cost after
    each trial step from the start values' at step 0, with the cost of each refused or
    rejected trial marked).

    Args:
        path: Output PNG file.
        fit: A :class:`warptissue.fit.indentation.IndentationFit`.
        max_points: Each record with more samples is decimated (every k-th sample) for the
            plot; the CSV keeps every sample.

    Returns:
        The path written.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    figure = Figure(figsize=(11.0, 8.0), layout="constrained")
    FigureCanvasAgg(figure)
    (by_depth, by_time), (residuals, history) = figure.subplots(2, 2)
    residuals.axhline(0.0, color="0.5", linewidth=1)
    for k, record in enumerate(fit.records):
        colour = f"C{k % 10}"
        name = Path(str(record.file)).name
        time = np.asarray(record.time_s, float)
        depth = np.asarray(record.depth_m, float)
        measured = np.asarray(record.measured_force_N, float)
        fitted = np.asarray(record.fitted_force_N, float)
        keep = _decimation(time.size, max_points)
        r2 = "n/a" if record.r_squared is None else f"{record.r_squared:.4f}"
        by_depth.plot(
            depth[keep] * 1e3,
            measured[keep],
            "o",
            color=colour,
            markersize=2.5,
            alpha=0.4,
            label=f"{name}: measured",
        )
        by_depth.plot(
            depth * 1e3,
            fitted,
            "-",
            color=colour,
            linewidth=1.5,
            label=f"{name}: fitted (R^2 = {r2})",
        )
        offset = getattr(record, "depth_offset_m", None)
        if offset is not None:
            by_depth.axvline(
                offset * 1e3,
                color=colour,
                linestyle="--",
                linewidth=1,
                label=f"{name}: fitted contact ({offset * 1e3:.4g} mm)",
            )
        by_time.plot(time[keep], measured[keep], "o", color=colour, markersize=2.5, alpha=0.4)
        by_time.plot(time, fitted, "-", color=colour, linewidth=1.5)
        residuals.plot(
            time[keep], (fitted - measured)[keep], ".", color=colour, markersize=3, label=name
        )
    by_depth.set_xlabel("depth (mm)")
    by_depth.set_ylabel("force (N)")
    by_depth.legend(fontsize="x-small")
    by_time.set_xlabel("time (s)")
    by_time.set_ylabel("force (N)")
    residuals.set_xlabel("time (s)")
    residuals.set_ylabel("fitted - measured (N)")
    for axes in (by_depth, by_time, residuals):
        axes.grid(alpha=0.3)
    _plot_history(history, fit)
    result = fit.result
    r2 = "n/a" if result.r_squared is None else f"{result.r_squared:.4f}"
    figure.suptitle(
        f"{fit.study.name}: inverse-FE fit ({fit.strategy.replace('_', '-')}), "
        f"R^2 = {r2}, {fit.forward_solves} forward solves, {fit.status}\n"
        + ", ".join(
            f"{name} = {float(value):.4g} {unit}".rstrip()
            for name, value, unit in zip(
                result.parameter_names, result.x, result.parameter_units, strict=True
            )
        ),
        fontsize="medium",
    )
    with atomic_path(path) as temporary:
        figure.savefig(temporary, format="png", dpi=110)
    return Path(path)


def _plot_history(axes: Any, fit: IndentationFit) -> None:
    """The engine's cost per trial step (accepted: line; refused or rejected: crosses)."""
    history = list(fit.result.history)
    axes.set_xlabel("trial step of the least-squares engine")
    axes.set_ylabel("cost 0.5 sum r^2")
    axes.grid(alpha=0.3)
    if not history:
        axes.text(0.5, 0.5, "no trial steps", ha="center", va="center", transform=axes.transAxes)
        return
    steps = np.array([h.iteration for h in history], dtype=float)
    cost = np.array([h.cost for h in history], dtype=float)
    start_cost = getattr(fit, "start_cost", None)
    if start_cost is not None and np.isfinite(start_cost):  # the start values, step 0
        steps, cost = np.concatenate([[0.0], steps]), np.concatenate([[start_cost], cost])
    axes.plot(steps, cost, "-o", color="k", markersize=3, label="cost after the trial")
    refused = [(h.iteration, h.trial_cost) for h in history if not h.accepted]
    if refused:
        axes.plot(
            [i for i, _ in refused],
            [c if c is not None and np.isfinite(c) else np.nan for _, c in refused],
            "x",
            color="C3",
            label="refused trial (cost)",
        )
    if np.all(cost > 0):
        axes.set_yscale("log")
    axes.xaxis.get_major_locator().set_params(integer=True)
    axes.legend(fontsize="x-small")


def write_indentation_fit_outputs(
    out_dir: str | Path, fit: IndentationFit, *, usd: bool = False
) -> dict[str, Path]:
    """Write an inverse-FE fit's report files into a folder (atomically, each).

    - ``fit.json``: :meth:`IndentationFit.to_dict` (every parameter's value, unit, standard
      error and correlation; R^2, RMSE, iterations, forward solves, status, warnings, each
      record's R^2 and RMSE, stage one) with the software versions;
    - ``fit_curves.csv``: :func:`indentation_fit_columns`;
    - ``fit.png``: :func:`plot_indentation_fit`;
    - ``fitted_study.toml``: the study with the fitted material
      (:func:`warptissue.study.save_study`; ``warptissue simulate`` runs it as it is);
    - with ``usd``: ``specimen.usda`` (over ``specimen.asset.usda``), the specimen mesh with
      the fitted material and the probe (:func:`warptissue.usd.export.export_study`).

    Args:
        out_dir: Output folder (created).
        fit: A :class:`warptissue.fit.indentation.IndentationFit` (an interrupted one
            included: its best parameters).
        usd: Also write the USD scene.

    Returns:
        The paths written, by the keys of :data:`INDENTATION_FIT_FILES`.
    """

    folder = Path(out_dir)
    names = INDENTATION_FIT_FILES
    files: dict[str, Path] = {}
    files["study"] = save_study(fit.fitted_study, folder / names["study"])
    summary = dict(fit.to_dict())
    summary["study_file"] = None if fit.study.path is None else str(fit.study.path)
    summary["fitted_study_file"] = names["study"]
    summary["software"] = software_versions()
    files["json"] = write_json(folder / names["json"], summary)
    files["csv"] = write_csv(folder / names["csv"], indentation_fit_columns(fit))
    files["png"] = plot_indentation_fit(folder / names["png"], fit)
    if usd:
        from warptissue.usd.export import export_study

        files["usd"] = export_study(files["study"], folder / names["usd"]).root
    return files
