"""The project's exception hierarchy.

Every error warptissue raises on purpose derives from :class:`WarpTissueError`. The CLI turns
them into one-line messages and a non-zero exit code; the Python API lets them propagate.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

__all__ = [
    "ConvergenceError",
    "DeviceError",
    "InputError",
    "MeshError",
    "WarpTissueError",
]


class WarpTissueError(Exception):
    """Root of every error raised by warptissue on purpose.

    Attributes:
        exit_code: Process exit status the CLI uses for this kind of error.
    """

    exit_code: int = 1


class InputError(WarpTissueError, ValueError):
    """Bad user input: a file, a column, a key or a value.

    The message names where the problem is (file, line, column or key) and the offending
    value, so that a user can fix it without a traceback.

    Args:
        message: What is wrong, in one sentence.
        path: The file the value came from, if any.
        line: 1-based line number in ``path``, if known.
        column: Column or key name, if known.
        value: The offending value, if any.
    """

    exit_code = 2

    def __init__(
        self,
        message: str,
        *,
        path: str | Path | None = None,
        line: int | None = None,
        column: str | None = None,
        value: Any = None,
    ) -> None:
        self.message = message
        self.path = None if path is None else Path(path)
        self.line = line
        self.column = column
        self.value = value
        where = []
        if path is not None:
            where.append(str(path) + (f":{line}" if line is not None else ""))
        elif line is not None:
            where.append(f"line {line}")
        if column is not None:
            where.append(f"column {column!r}")
        text = message if not where else f"{', '.join(where)}: {message}"
        if value is not None:
            text += f" (got {value!r})"
        super().__init__(text)


class MeshError(WarpTissueError, ValueError):
    """A mesh that cannot be used: bad connectivity, inverted or degenerate elements.

    Args:
        message: What is wrong.
        element: Index of the first offending element, if one is to blame.
    """

    exit_code = 3

    def __init__(self, message: str, *, element: int | None = None) -> None:
        self.element = element
        super().__init__(message if element is None else f"element {element}: {message}")


class ConvergenceError(WarpTissueError, RuntimeError):
    """A solver that did not converge, with whatever partial result it reached.

    Args:
        message: What failed and where (load step, iteration, residual norm).
        partial_result: The result computed before the failure (for example the force curve
            up to the last converged load step), or None.
    """

    exit_code = 4

    def __init__(self, message: str, *, partial_result: Any = None) -> None:
        self.partial_result = partial_result
        super().__init__(message)


class DeviceError(WarpTissueError, RuntimeError):
    """A compute device that is missing or unusable (for example ``cuda`` with no GPU)."""

    exit_code = 5
