"""Typed access to the tables of a study file, each error naming the file, line and key.

:class:`Source` knows the line of each key path of the TOML text; :class:`Table` reads one
table's keys with their types and ranges and rejects the keys nobody asked for, naming the
closest known one.
"""

from __future__ import annotations

import difflib
import math
import re
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from warptissue.errors import InputError

_MISSING = object()


class Source:
    """Where values come from: the file, and the line of each key in its text."""

    def __init__(self, path: Path | None, text: str | None) -> None:
        self.path = path
        self._lines: dict[str, int] = {}
        if text is not None:
            self._index_lines(text)

    def _index_lines(self, text: str) -> None:
        table = ""
        header = re.compile(r"^\s*\[([^\[\]]+)\]\s*(#.*)?$")
        array_header = re.compile(r"^\s*\[\[([^\[\]]+)\]\]\s*(#.*)?$")
        assignment = re.compile(r"^\s*([A-Za-z0-9_\-\"'.]+)\s*=")
        counts: dict[str, int] = {}
        for number, line in enumerate(text.splitlines(), start=1):
            match = array_header.match(line)
            if match:  # [[data]]: the key paths data[0], data[1], ...
                name = match.group(1).strip().replace(" ", "")
                counts[name] = counts.get(name, -1) + 1
                table = f"{name}[{counts[name]}]"
                self._lines.setdefault(name, number)
                self._lines.setdefault(table, number)
                continue
            match = header.match(line)
            if match:
                table = match.group(1).strip().replace(" ", "")
                self._lines.setdefault(table, number)
                continue
            match = assignment.match(line)
            if match:
                key = match.group(1).strip().strip("\"'")
                self._lines.setdefault(f"{table}.{key}" if table else key, number)

    def line(self, key_path: str) -> int | None:
        """The line where ``key_path`` (or failing that its table) is written, if known."""
        while key_path:
            if key_path in self._lines:
                return self._lines[key_path]
            key_path = key_path.rpartition(".")[0]
        return None

    def error(self, key_path: str, problem: str, value: Any = None) -> InputError:
        """An InputError naming the file, the line, the key path and the value."""
        return InputError(
            f"{key_path}: {problem}", path=self.path, line=self.line(key_path), value=value
        )


_UNIT_WORDS = {"_m": "metres", "_Pa": "pascals", "_s": "seconds", "_N": "newtons"}
"""Unit suffixes of key names, for the hint of a "must be a number" error."""


def plain(value: Any) -> Any:
    """NumPy scalars and arrays as Python numbers and lists (checks and messages alike)."""
    if type(value).__module__ == "numpy":
        return value.tolist()
    return value


def closest(word: str, candidates: Sequence[str]) -> str | None:
    """The candidate closest to ``word`` (case-insensitive), if one is close."""
    lowered = {candidate.lower(): candidate for candidate in candidates if candidate != word}
    match = difflib.get_close_matches(word.lower(), list(lowered), n=1, cutoff=0.6)
    return lowered[match[0]] if match else None


def _number_problem(key: str) -> str:
    """ "must be a number", with the unit its key names (SI units, no unit strings)."""
    for suffix, word in _UNIT_WORDS.items():
        if key.endswith(suffix):
            return f"must be a number in {word} (SI units, without a unit: 1 mm is 0.001)"
    return "must be a number"


class Table:
    """Typed, key-path-aware access to one TOML table; rejects keys nobody asked for."""

    def __init__(self, data: Any, prefix: str, source: Source) -> None:
        if not isinstance(data, Mapping):
            raise source.error(prefix, f"must be a table, not {type(data).__name__}", plain(data))
        self.data = data
        self.prefix = prefix
        self.source = source
        self.used: set[str] = set()

    def key_path(self, key: str) -> str:
        return f"{self.prefix}.{key}" if self.prefix else key

    def error(self, key: str, problem: str, value: Any = None) -> InputError:
        return self.source.error(self.key_path(key), problem, plain(value))

    def has(self, key: str) -> bool:
        return key in self.data

    def raw(self, key: str, default: Any = _MISSING) -> Any:
        self.used.add(key)
        if key not in self.data:
            if default is _MISSING:
                raise self.missing(key)
            return default
        return plain(self.data[key])

    def missing(self, key: str) -> InputError:
        """The error for a missing required key: a close unknown key is named as the typo."""
        typo = closest(key, [k for k in self.data if k not in self.used])
        if typo is not None:
            return self.error(
                typo, f"unknown key; did you mean {key!r}? ({key!r} is required)", None
            )
        return self.error(key, "required key is missing")

    def table(self, key: str) -> Table:
        return Table(self.raw(key), self.key_path(key), self.source)

    def number(self, key: str, *, default: Any = _MISSING, positive: bool = True) -> float | None:
        value = self.raw(key, default)
        if value is default and default is not _MISSING:
            return value
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.error(key, _number_problem(key), value)
        if not math.isfinite(value):
            raise self.error(key, "must be a finite number", value)
        if positive and value <= 0:
            raise self.error(key, "must be positive", value)
        return float(value)

    def integer(self, key: str, *, default: Any = _MISSING, minimum: int = 1) -> int:
        value = self.raw(key, default)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(key, "must be an integer", value)
        if value < minimum:
            raise self.error(key, f"must be at least {minimum}", value)
        return int(value)

    def boolean(self, key: str, *, default: Any = _MISSING) -> bool:
        value = self.raw(key, default)
        if not isinstance(value, bool):
            raise self.error(key, "must be true or false (without quotes)", value)
        return value

    def string(self, key: str, *, default: Any = _MISSING, choices: Sequence[str] = ()) -> str:
        value = self.raw(key, default)
        if not isinstance(value, str):
            raise self.error(key, "must be a string (in quotes)", value)
        if choices and value not in choices:
            close = closest(value, choices)
            hint = f" (did you mean {close!r}?)" if close else ""
            raise self.error(key, f"must be one of {', '.join(map(repr, choices))}{hint}", value)
        return value

    def number_list(self, key: str) -> tuple[float, ...]:
        values = self.raw(key)
        if not isinstance(values, list | tuple) or not values:
            raise self.error(key, "must be a non-empty list of numbers", values)
        values = [plain(value) for value in values]
        for value in values:
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise self.error(key, f"must contain only numbers ({_number_problem(key)})", value)
            if not math.isfinite(value):
                raise self.error(key, "must contain only finite numbers", value)
        return tuple(float(v) for v in values)

    def present(self, keys: Sequence[str]) -> dict[str, Any]:
        """The values of those of ``keys`` that are given (all of ``keys`` count as known)."""
        for key in keys:
            self.raw(key, None)
        return {key: plain(self.data[key]) for key in keys if key in self.data}

    def build(self, constructor: Callable[..., Any], values: Mapping[str, Any]) -> Any:
        """``constructor(values)``, its InputError placed at the file, line and key path.

        An error about a key the table lacks names a close key of the table as its typo.
        """
        try:
            return constructor(values)
        except InputError as exc:
            key = exc.column or ""
            if key and key not in self.data:
                typo = closest(key, list(self.data))
                if typo is not None:
                    raise self.error(
                        typo, f"unknown key; did you mean {key!r}? ({exc.message})", None
                    ) from exc
            raise (
                self.error(key, exc.message, exc.value)
                if key
                else self.source.error(self.prefix, exc.message, plain(exc.value))
            ) from exc

    def finish(self, *, also_known: Sequence[str] = ()) -> None:
        """Reject any key that was not read (``also_known`` are listed as valid too)."""
        unknown = [key for key in self.data if key not in self.used]
        if unknown:
            known = sorted(self.used | set(also_known))
            close = closest(unknown[0], known)
            hint = f"did you mean {close!r}? " if close else ""
            raise self.error(
                unknown[0], f"unknown key ({hint}known keys here: {', '.join(known)})", None
            )
