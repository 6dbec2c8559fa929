"""The project's exception hierarchy.

Every error warptissue raises on purpose derives from :class:`WarpTissueError`. The CLI turns
them into one-line messages and a non-zero exit code; the Python API lets them propagate.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

__all__ = [
    "INTERRUPTED_EXIT_CODE",
    "ConvergenceError",
    "DeviceError",
    "InputError",
    "MeshError",
    "WarpTissueError",
]

INTERRUPTED_EXIT_CODE = 130
"""Exit status of an interrupted run or fit (Ctrl-C), as the shell gives a process ended by
SIGINT."""


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

    A NumPy scalar value is shown as the plain number (``1.19``, not ``np.float64(1.19)``).

    Args:
        message: What is wrong, in one sentence.
        path: The file the value came from, if any.
        line: 1-based line number in ``path``, if known.
        column: Column name of a data file, if known.
        value: The offending value, if any.
        option: The command-line option the value came from (``"--growth"``), if any; it is
            named instead of ``column`` or ``key``.
        key: Name of a parameter, option or study key that is not a data column (shown as
            ``key 'tolerance'``); :attr:`column` then holds the same name, so callers that
            map a name to a study key or an option read one attribute.
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
        option: str | None = None,
        key: str | None = None,
    ) -> None:
        self.message = message
        self.path = None if path is None else Path(path)
        self.line = line
        self.column = column if column is not None else key
        self.key = key
        self.value = _plain(value)
        self.option = option
        where = []
        if path is not None:
            where.append(str(path) + (f":{line}" if line is not None else ""))
        elif line is not None:
            where.append(f"line {line}")
        if option is not None:
            where.append(f"option {option}")
        elif key is not None:
            where.append(f"key {key!r}")
        elif column is not None:
            where.append(f"column {column!r}")
        text = message if not where else f"{', '.join(where)}: {message}"
        if self.value is not None:
            text += f" (got {self.value!r})"
        super().__init__(text)

    def for_option(self, option: str) -> InputError:
        """The same error, naming the command-line option ``option`` instead of the column."""
        return InputError(
            self.message, path=self.path, line=self.line, column=self.column, value=self.value,
            option=option, key=self.key,
        )  # fmt: skip


def _plain(value: Any) -> Any:
    """A NumPy scalar as the Python number it holds; anything else unchanged."""
    if type(value).__module__ == "numpy" and getattr(value, "ndim", None) == 0:
        return value.item()
    return value


class MeshError(WarpTissueError, ValueError):
    """A mesh that cannot be used: bad connectivity, degenerate elements, too large for memory.

    Inverted or degenerate elements name the first one; a mesh too large for the memory
    available is refused before it is made.

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
