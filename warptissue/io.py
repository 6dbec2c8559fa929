"""File input and output shared by every part of warptissue.

Writes are atomic: data goes to a temporary file in the target folder, which is renamed over
the target only once it is complete, so a failed run leaves no half-written file behind.
Experiment CSV files are validated on load, and every problem is reported with the file, the
line and the column it was found in.
"""

from __future__ import annotations

import contextlib
import csv
import json
import math
import os
import platform
import tempfile
import tomllib
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

from warptissue.errors import InputError

__all__ = [
    "INDENTATION_COLUMNS",
    "MAX_MAGNITUDE",
    "ExperimentData",
    "atomic_path",
    "read_experiment_csv",
    "read_sidecar",
    "software_versions",
    "to_jsonable",
    "write_csv",
    "write_json",
]

INDENTATION_COLUMNS: tuple[str, ...] = ("time_s", "displacement_m", "force_N")
"""Required columns of an indentation record, in SI units."""

MAX_MAGNITUDE = 1e100
"""The largest magnitude an experiment CSV's value may have: no measurement in SI units comes
near, and the fits' squares and products of larger values overflow float64."""


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside ``path`` that replaces ``path`` on success.

    The caller writes the complete file to the yielded path. When the block exits normally,
    the temporary file is renamed over ``path`` (an atomic operation on POSIX and Windows);
    when it raises, the temporary file is removed and ``path`` is left untouched.

    Args:
        path: The final file path. Its parent folders are created.

    Yields:
        The temporary path to write to. It keeps ``path``'s suffix, so that libraries which
        choose a format by suffix (meshio, USD) still work.
    """
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    umask = os.umask(0)
    os.umask(umask)
    temporary_path: Path | None = None
    try:
        # Inside the try: an interrupt (Ctrl-C) right after the file is made removes it too.
        try:
            handle, temporary = tempfile.mkstemp(
                prefix=f".{target.stem}.", suffix=f".tmp{target.suffix}", dir=target.parent
            )
        except OSError as error:  # name the file asked for, not the temporary one
            raise OSError(error.errno, error.strerror, str(target)) from None
        temporary_path = Path(temporary)
        os.close(handle)
        yield temporary_path
        # mkstemp creates owner-only files; give the result the usual mode of a new file.
        os.chmod(temporary_path, 0o666 & ~umask)
        os.replace(temporary_path, target)
    finally:
        if temporary_path is not None:
            with contextlib.suppress(FileNotFoundError):
                temporary_path.unlink()


def to_jsonable(value: Any) -> Any:
    """Convert NumPy scalars and arrays, paths and dataclass-like mappings to JSON types.

    Non-finite floats become None, since JSON has no NaN or infinity.
    """
    if isinstance(value, Mapping):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, np.ndarray):
        return to_jsonable(value.tolist())
    if isinstance(value, (list, tuple)):
        return [to_jsonable(v) for v in value]
    if isinstance(value, np.generic):
        return to_jsonable(value.item())
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, Path):
        return str(value)
    return value


def write_json(path: str | Path, data: Mapping[str, Any]) -> Path:
    """Write ``data`` as indented JSON, atomically.

    Args:
        path: Output file.
        data: A mapping of JSON-compatible values, NumPy values included.

    Returns:
        The path written.
    """
    with atomic_path(path) as temporary:
        temporary.write_text(json.dumps(to_jsonable(data), indent=2) + "\n", encoding="utf-8")
    return Path(path)


def write_csv(path: str | Path, columns: Mapping[str, Sequence[float] | np.ndarray]) -> Path:
    """Write equal-length columns to a CSV with a header row, atomically.

    Args:
        path: Output file.
        columns: Column name (with its unit, for example ``force_N``) to values, shape (n,).

    Returns:
        The path written.

    Raises:
        InputError: The columns differ in length.
    """
    names = list(columns)
    arrays = [np.asarray(columns[name]).reshape(-1) for name in names]
    lengths = {name: len(a) for name, a in zip(names, arrays, strict=True)}
    if len(set(lengths.values())) > 1:
        raise InputError("CSV columns differ in length", path=path, value=lengths)
    with atomic_path(path) as temporary, temporary.open("w", newline="", encoding="utf-8") as f:
        writer = csv.writer(f)
        writer.writerow(names)
        for row in zip(*arrays, strict=True):
            writer.writerow(
                [repr(float(v)) if isinstance(v, float | np.floating) else v for v in row]
            )
    return Path(path)


@dataclass(frozen=True)
class ExperimentData:
    """A validated experiment record.

    Attributes:
        columns: Column name to values, each shape (n,) float64, in file order.
        metadata: The sidecar's content (empty when there is none).
        path: The CSV file it was read from.
    """

    columns: dict[str, np.ndarray]
    metadata: dict[str, Any] = field(default_factory=dict)
    path: Path | None = None

    def __getitem__(self, name: str) -> np.ndarray:
        return self.columns[name]

    @property
    def sample_count(self) -> int:
        """Number of rows."""
        return len(next(iter(self.columns.values()))) if self.columns else 0


def read_sidecar(csv_path: str | Path) -> dict[str, Any]:
    """Read the metadata sidecar of an experiment CSV, if one exists.

    The sidecar has the CSV's name with ``.json`` or ``.toml`` in place of ``.csv``
    (``run.csv`` → ``run.json`` or ``run.toml``).

    Returns:
        The sidecar's content, or an empty dict when there is none.

    Raises:
        InputError: The sidecar exists but cannot be parsed.
    """
    base = Path(csv_path)
    for suffix, loader in ((".json", json.loads), (".toml", tomllib.loads)):
        sidecar = base.with_suffix(suffix)
        if sidecar.exists():
            try:
                return dict(loader(sidecar.read_text(encoding="utf-8")))
            except (json.JSONDecodeError, tomllib.TOMLDecodeError) as exc:
                line = getattr(exc, "lineno", None)
                raise InputError(
                    f"cannot parse metadata sidecar: {exc}", path=sidecar, line=line
                ) from exc
    return {}


def _text_lines(path: Path) -> list[str]:
    """The lines of a UTF-8 text file (a byte-order mark, as spreadsheets write, is dropped).

    Raises:
        InputError: The file is not UTF-8 text (naming the line of the first bad byte).
        OSError: The file cannot be read.
    """
    data = path.read_bytes()
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise InputError(
            f"not UTF-8 text (byte 0x{data[exc.start]:02x}); save the file as UTF-8",
            path=path,
            line=line,
        ) from None
    return text.splitlines(keepends=True)


def _parsed_rows(path: Path, reader: Iterator[Any]) -> list[Any]:
    """The rows of a CSV reader, its errors (a field larger than the csv module's limit, an
    unclosed quote) as one-line :class:`InputError` naming the file and line."""
    rows = []
    try:
        for row in reader:
            rows.append(row)
    except csv.Error as exc:
        # A DictReader's own line_num lags its row reader's by the row that failed.
        line = getattr(getattr(reader, "reader", reader), "line_num", None)
        raise InputError(f"cannot parse as CSV: {exc}", path=path, line=line) from None
    return rows


def read_experiment_csv(
    path: str | Path,
    *,
    required: Sequence[str] = INDENTATION_COLUMNS,
    monotonic: str | None = "time_s",
) -> ExperimentData:
    """Load and validate an experiment CSV with a header row.

    Args:
        path: The CSV file.
        required: Column names that must be present. Extra columns are kept.
        monotonic: A column that must strictly increase (time), or None.

    Returns:
        The validated record, with its sidecar metadata.

    Raises:
        InputError: Missing file or column, an empty file, a value that is not a finite number,
            or a non-increasing ``monotonic`` column. The message names the file, the line
            and the column.
    """
    csv_path = Path(path)
    if csv_path.is_dir():
        raise InputError("this is a folder, not an experiment file", path=csv_path)
    if not csv_path.is_file():
        raise InputError("experiment file not found", path=csv_path)
    try:
        rows = _parsed_rows(csv_path, csv.reader(_text_lines(csv_path)))
    except OSError as exc:
        raise InputError(f"cannot read file: {exc.strerror}", path=csv_path) from exc
    rows = [
        (number, row)
        for number, row in enumerate(rows, start=1)
        if row and any(c.strip() for c in row)
    ]
    if not rows:
        raise InputError("experiment file is empty", path=csv_path)
    header_line, header = rows[0]
    names = [name.strip() for name in header]
    missing = [name for name in required if name not in names]
    if missing:
        separator = next((c for c in ";\t|" if len(names) == 1 and c in names[0]), None)
        hint = f" (fields separated by {separator!r}: use commas)" if separator else ""
        raise InputError(
            f"missing required column(s) {missing}; header has {names}{hint}",
            path=csv_path,
            line=header_line,
        )
    if len(set(names)) != len(names):
        raise InputError(
            "duplicate column names in header", path=csv_path, line=header_line, value=names
        )
    if len(rows) == 1:
        raise InputError("experiment file has a header but no data rows", path=csv_path)
    values = np.empty((len(rows) - 1, len(names)), dtype=np.float64)
    for index, (number, row) in enumerate(rows[1:]):
        if len(row) != len(names):
            raise InputError(
                f"expected {len(names)} fields, found {len(row)}",
                path=csv_path,
                line=number,
                value=row,
            )
        for j, text in enumerate(row):
            try:
                number_value = float(text)
            except ValueError:
                raise InputError(
                    "not a number", path=csv_path, line=number, column=names[j], value=text
                ) from None
            if not math.isfinite(number_value):
                raise InputError(
                    "not a finite number", path=csv_path, line=number, column=names[j], value=text
                )
            if abs(number_value) > MAX_MAGNITUDE:
                raise InputError(
                    f"too large for a measurement in SI units (magnitude above "
                    f"{MAX_MAGNITUDE:g}); check the column's unit",
                    path=csv_path,
                    line=number,
                    column=names[j],
                    value=text,
                )
            values[index, j] = number_value
    columns = {name: values[:, j].copy() for j, name in enumerate(names)}
    if monotonic is not None and monotonic in columns:
        steps = np.diff(columns[monotonic])
        bad = np.flatnonzero(steps <= 0)
        if bad.size:
            line = rows[bad[0] + 2][0]
            raise InputError(
                f"{monotonic} must strictly increase",
                path=csv_path,
                line=line,
                column=monotonic,
                value=float(columns[monotonic][bad[0] + 1]),
            )
    return ExperimentData(columns=columns, metadata=read_sidecar(csv_path), path=csv_path)


def read_csv_rows(path: str | Path, *, required: Sequence[str]) -> list[tuple[int, dict[str, str]]]:
    """Read a CSV with a header row into text rows, checking that columns are present.

    For files with text columns (labels) beside numbers; parse numbers with
    :func:`csv_number`. All-numeric files should use :func:`read_experiment_csv`.

    Args:
        path: The CSV file.
        required: Column names that must be present (header names are stripped).

    Returns:
        ``(line, row)`` pairs, the 1-based file line (header is line 1) and the row by column.

    Raises:
        InputError: The file cannot be read, or a required column is missing.
    """
    csv_path = Path(path)
    try:
        lines = _text_lines(csv_path)
    except OSError as exc:
        raise InputError(f"cannot read file: {exc.strerror}", path=csv_path) from exc
    reader = csv.DictReader(lines)
    header = [name.strip() for name in (reader.fieldnames or [])]
    missing = [name for name in required if name not in header]
    if missing:
        raise InputError(f"missing column(s) {missing}; header is {header}", path=csv_path, line=1)
    reader.fieldnames = header
    return [(index + 2, row) for index, row in enumerate(_parsed_rows(csv_path, reader))]


def csv_number(path: str | Path, line: int, row: Mapping[str, str | None], column: str) -> float:
    """One finite float from a row of :func:`read_csv_rows`.

    Raises:
        InputError: The value is not a finite number (names the file, line, column and value).
    """
    text = (row.get(column) or "").strip()
    try:
        value = float(text)
    except ValueError:
        raise InputError("not a number", path=path, line=line, column=column, value=text) from None
    if not math.isfinite(value):
        raise InputError("not a finite number", path=path, line=line, column=column, value=text)
    return value


def software_versions() -> dict[str, str]:
    """Versions of warptissue, Python and the numerical libraries, for provenance records."""
    versions = {"python": platform.python_version()}
    for package in ("warptissue", "warp-lang", "numpy", "scipy", "usd-core", "meshio"):
        try:
            versions[package] = metadata.version(package)
        except metadata.PackageNotFoundError:
            versions[package] = "not installed"
    return versions
