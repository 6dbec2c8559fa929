"""``[[data]]`` records and a ``"record"`` protocol: their keys, CSV file and conditioning."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from warptissue.acquisition.conditioning import CONTACT_MODES, OFFSET_MODES, condition_for_fit
from warptissue.errors import InputError
from warptissue.io import read_experiment_csv
from warptissue.study._schema import DEFAULT_COLUMNS, DataRecord
from warptissue.study._toml import Table

_RECORD_KEYS = (
    "file",
    *DEFAULT_COLUMNS,
    "contact",
    "contact_position_m",
    "offset",
    "keep_depth_m",
    "window_s",
    "site_m",
    "direction",
    "indenter",
)
"""The keys of a ``[[data]]`` record."""


def record_options(table: Table, base: Path) -> dict[str, Any]:
    """The keys of a record (``[[data]]``, or a ``"record"`` protocol), validated."""

    file = table.string("file")
    if not file.strip():
        raise table.error("file", "must name a CSV file (relative to the study file)", file)
    path = Path(file) if Path(file).is_absolute() else base / file
    columns = {key: table.string(key, default=name) for key, name in DEFAULT_COLUMNS.items()}
    for index, (key, name) in enumerate(columns.items()):
        if not name.strip():
            raise table.error(key, "must name a column of the CSV file", name)
        if name in list(columns.values())[:index]:
            raise table.error(key, "names the same column as another column key", name)
    if table.has("contact") and table.has("contact_position_m"):
        raise table.error(
            "contact_position_m",
            "give contact ('none' or 'auto') or contact_position_m (a position), not both",
            table.data["contact_position_m"],
        )
    contact: str | float
    if table.has("contact_position_m"):
        contact = table.number("contact_position_m", positive=False)
    else:
        contact = table.string("contact", default="none", choices=CONTACT_MODES)
    offset = table.string("offset", default="auto", choices=OFFSET_MODES)
    if contact == "none" and table.has("offset"):
        raise table.error(
            "offset",
            "applies only with a contact point (contact = 'auto' or contact_position_m): "
            "without one the force is used as recorded",
            offset,
        )
    keep_depth_m = table.number("keep_depth_m", default=None)
    window_s = None
    if table.has("window_s"):
        window = table.number_list("window_s")
        if len(window) != 2 or window[0] < 0 or not window[1] > window[0]:
            raise table.error(
                "window_s", "must be [start, stop] in seconds, 0 <= start < stop", list(window)
            )
        window_s = (window[0], window[1])
    return {
        "file": file,
        "path": path,
        **columns,
        "contact": contact,
        "offset": offset,
        "keep_depth_m": keep_depth_m,
        "window_s": window_s,
    }


def condition_record(
    table: Table, options: Mapping[str, Any], *, force_required: bool = True
) -> DataRecord:
    """Read a record's CSV and condition it; errors placed at the table's keys.

    Without ``force_required`` a CSV without the force column is read with zero force (a
    depth-time history needs none); the contact must then be given (``"none"`` or a
    position): detecting it needs the force.
    """

    path, file, contact = options["path"], options["file"], options["contact"]
    names = {key: options[key] for key in DEFAULT_COLUMNS}
    required = tuple(names.values()) if force_required else tuple(names.values())[:2]
    try:
        data = read_experiment_csv(path, required=required, monotonic=names["time_column"])
    except InputError as exc:
        raise table.error("file", str(exc), file) from None
    columns = data.columns
    values = {
        "time_s": columns[names["time_column"]],
        "displacement_m": columns[names["displacement_column"]],
    }
    if names["force_column"] in columns:
        values["force_N"] = columns[names["force_column"]]
    elif contact == "auto":
        raise table.error(
            "contact",
            f"'auto' detects the contact from the force, and {file} has no column "
            f"{names['force_column']!r}: give contact_position_m, or contact = 'none'",
            contact,
        )
    else:
        values["force_N"] = np.zeros_like(values["time_s"])
    option_key = "contact" if isinstance(contact, str) else "contact_position_m"
    try:
        record = condition_for_fit(
            values,
            contact=contact,
            offset=options["offset"],
            keep_depth_m=options["keep_depth_m"],
            window_s=options["window_s"],
            option_names={"contact": option_key},
        )
    except InputError as exc:
        named = ("contact_position_m", "keep_depth_m", "window_s", "contact")
        key = next((k for k in named if table.has(k) and k in exc.message), None)
        if key is None and "no sample left" in exc.message:
            key = next((k for k in ("window_s", "keep_depth_m") if table.has(k)), None)
        key = key or "file"
        raise table.error(key, f"{path}: {exc.message}", table.data[key]) from None
    return DataRecord(**options, record=record)


def _read_record(
    table: Table, base: Path, thickness_m: float, probe_reader: ProbeReader
) -> DataRecord:
    """One ``[[data]]`` record: validate its keys, read its CSV, condition it, and check it
    against the specimen (:func:`check_record`); its own probe (``site_m``, ``direction``,
    an ``indenter`` table) read by ``probe_reader``."""
    options = record_options(table, base)
    options.update(probe_reader(table))
    table.finish(also_known=_RECORD_KEYS)
    record = condition_record(table, options)
    if not record.placed:  # a record at a site of its own is checked against the mesh there
        check_record(table, record, thickness_m)
    return record


ProbeReader = Callable[[Table], dict[str, Any]]
"""Reads a ``[[data]]`` table's own probe: ``{"site_m", "direction", "indenter"}``."""


def check_record(table: Table, record: DataRecord, thickness_m: float) -> None:
    """Refuse, before any FE run, a fit record that cannot be an indentation of the
    specimen: one deeper than the specimen is thick (often millimetres in a ``_m``
    column), or one whose force never pushes (all zero, or more negative than positive:
    compression is positive).

    Raises:
        InputError: At the record's ``file`` key, naming the file and the value.
    """
    path = record.path
    depth = float(np.max(record.displacement_m))
    if depth >= thickness_m:
        raise table.error(
            "file",
            f"{path}: the record goes {depth:.6g} m deep and the specimen is {thickness_m:.6g}"
            " m thick: check the displacement's unit (a '_m' column holds metres) or "
            "specimen.thickness_m",
            depth,
        )
    force = record.force_N
    peak, trough = float(np.max(force)), float(np.min(force))
    if peak <= 0.0 or -trough > peak:
        what = "is zero throughout" if peak == trough == 0.0 else "is mostly negative"
        raise table.error(
            "file",
            f"{path}: the force {what} (from {trough:.6g} to {peak:.6g} N): an indentation "
            "pushes, with compression positive: check the force column and its sign",
            peak,
        )


def read_data(
    root: Table, base: Path, thickness_m: float, *, probe_reader: ProbeReader
) -> tuple[DataRecord, ...]:
    """``[[data]]`` (one or more records) or a single ``[data]`` table, each checked against
    the specimen's thickness (m); ``probe_reader`` reads a record's own probe."""
    value = root.raw("data")
    if isinstance(value, Mapping):
        return (_read_record(root.table("data"), base, thickness_m, probe_reader),)
    if not isinstance(value, list) or not value:
        raise root.error("data", "must be one or more [[data]] tables", value)
    return tuple(
        _read_record(Table(item, f"data[{i}]", root.source), base, thickness_m, probe_reader)
        for i, item in enumerate(value)
    )
