"""A batch's record of its studies: each study's outcome (its summary row), the marker a
succeeded study leaves in its folder, and ``summary.csv``.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import socket
import warnings
from collections.abc import Iterator, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from warptissue.errors import WarpTissueError
from warptissue.io import write_csv, write_json

DONE_MARKER = "batch_done.json"
"""The file a study's task writes last (atomically) into its folder when the study succeeded:
its :class:`StudyOutcome` and the SHA-256 of its study file. Its presence makes a rerun skip
the study."""


SUMMARY_FILE = "summary.csv"
"""The summary table the client writes into the batch's output folder."""


SUMMARY_COLUMNS: tuple[str, ...] = (
    "study",
    "folder",
    "kind",
    "status",
    "exit_status",
    "seconds",
    "solved_together",
    "gpu",
    "peak_force_N",
    "r_squared",
    "parameters",
    "warnings",
    "skipped",
    "error",
)
"""Columns of ``summary.csv``: the study file as given; its result folder under OUT; its kind
(``simulation``, ``fit`` or empty when the file could not be read); its status (a
simulation's ``completed``/``stopped_early``, a fit's ``converged``/
``stopped_at_r_squared``/``max_iterations``/``failed``/``stage_one_not_converged``, or
``error``); the exit status its
single-study command would have given (0 success); the task's wall time (s); how many
studies its load steps were solved with in one batched FE run (1: alone); the GPU its
worker was pinned to (``CUDA_VISIBLE_DEVICES``; empty where not pinned); the peak
reaction force of a simulation (N); a fit's R^2 over all its records; the fitted parameters
(``name=value`` separated by ``;``); the number of warnings; ``True`` for a study skipped
because its folder holds a complete result of an earlier run (its numbers are that run's);
the one-line error of a failed study."""


FAILED_EXIT_CODE = 6
"""Exit status of ``warptissue batch`` when one or more studies failed (the others ran)."""


STUDY_KINDS: tuple[str, ...] = ("simulation", "fit")
"""What a study is: a forward simulation, or an inverse-FE fit of its ``[[data]]`` records."""


GPU_PIN_ENV = "CUDA_VISIBLE_DEVICES"
"""The environment variable that pins a LocalCluster worker to one GPU."""


@dataclass(frozen=True)
class StudyOutcome:
    """One study's row of the batch summary.

    Attributes:
        study: The study file, as given (or found in a folder or by a pattern).
        folder: Its result folder's name under the batch's output folder.
        kind: ``"simulation"``, ``"fit"``, or ``""`` when the file could not be read.
        status: The simulation's or the fit's status, or ``"error"`` (an exception).
        exit_status: The exit status the single-study command would give (0: success;
            2 input or a path the system refuses, 3 mesh, 4 convergence, 5 device, 1 anything else).
        seconds: Wall time of the study's task, s (for studies solved together, its own
            setup plus the whole batched run, load steps and outputs).
        solved_together: How many studies its load steps were solved with in one batched
            FE run, itself included (1: alone).
        gpu: The GPU its worker process was pinned to (its ``CUDA_VISIBLE_DEVICES``), or
            ``""`` where it was not.
        peak_force_N: Largest reaction force of a simulation, N (None for a fit).
        r_squared: R^2 of a fit over all its records (None for a simulation).
        parameters: A fit's fitted parameters, name -> value in SI units (empty otherwise).
        warnings: The study's warnings (implausible results, unidentified parameters,
            Python warnings raised while it ran).
        error: The one-line error of a failed study (empty otherwise).
        skipped: True when the study was not run because its folder held a complete result
            of the same study file (the numbers are that run's).
        study_sha256: SHA-256 of the study file's bytes when it ran.
        host: The machine the task ran on.
        pid: The process the task ran in.
    """

    study: str
    folder: str
    kind: str = ""
    status: str = "error"
    exit_status: int = 1
    seconds: float = 0.0
    solved_together: int = 1
    gpu: str = ""
    peak_force_N: float | None = None
    r_squared: float | None = None
    parameters: dict[str, float] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    error: str = ""
    skipped: bool = False
    study_sha256: str = ""
    host: str = ""
    pid: int = 0

    @property
    def failed(self) -> bool:
        """True when the study did not succeed (its exit status is not 0)."""
        return self.exit_status != 0

    def to_dict(self) -> dict[str, Any]:
        """The outcome as a JSON-ready mapping (the content of :data:`DONE_MARKER`)."""
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> StudyOutcome:
        """The outcome :meth:`to_dict` gave (unknown keys are ignored)."""
        known = {f for f in cls.__dataclass_fields__}
        return cls(**{key: value for key, value in data.items() if key in known})

    def summary_row(self) -> dict[str, Any]:
        """The row of ``summary.csv`` (:data:`SUMMARY_COLUMNS`)."""
        return {
            "study": self.study,
            "folder": self.folder,
            "kind": self.kind,
            "status": self.status,
            "exit_status": int(self.exit_status),
            "seconds": float(self.seconds),
            "solved_together": int(self.solved_together),
            "gpu": self.gpu,
            "peak_force_N": self.peak_force_N,
            "r_squared": self.r_squared,
            "parameters": ";".join(f"{k}={float(v)!r}" for k, v in self.parameters.items()),
            "warnings": len(self.warnings),
            "skipped": bool(self.skipped),
            "error": self.error,
        }


@dataclass(frozen=True)
class BatchResult:
    """What :func:`run_batch` did.

    Attributes:
        out_dir: The batch's output folder.
        outcomes: One :class:`StudyOutcome` per study, in the order of the studies.
        summary_path: ``OUT/summary.csv``.
        seconds: Wall time of the batch, s.
        workers: The Dask workers the batch ran on (0: in this process, without Dask).
    """

    out_dir: Path
    outcomes: tuple[StudyOutcome, ...]
    summary_path: Path
    seconds: float
    workers: int = 0

    @property
    def failed(self) -> tuple[StudyOutcome, ...]:
        """The studies that failed."""
        return tuple(o for o in self.outcomes if o.failed)

    @property
    def skipped(self) -> tuple[StudyOutcome, ...]:
        """The studies skipped because their folder held a complete result."""
        return tuple(o for o in self.outcomes if o.skipped)

    @property
    def exit_code(self) -> int:
        """0 when every study succeeded, else :data:`FAILED_EXIT_CODE`."""
        return FAILED_EXIT_CODE if self.failed else 0


@dataclass(frozen=True)
class Task:
    """What a worker needs to run one study (sent to it by Dask)."""

    path: str
    study: str
    out_dir: str
    folder: str
    device: str | None
    on_dask: bool


def file_sha256(path: str | Path) -> str:
    try:
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()
    except OSError:
        return ""


def one_line(error: BaseException) -> str:
    """An exception as one line (its message; the class name for an unexpected one)."""
    text = " ".join(str(error).split())
    if isinstance(error, WarpTissueError):
        return text
    if isinstance(error, OSError) and error.strerror:
        path = error.filename2 if error.filename2 is not None else error.filename
        return error.strerror if path is None else f"cannot use {str(path)!r}: {error.strerror}"
    return f"{type(error).__name__}: {text}" if text else type(error).__name__


def completed_outcome(folder: Path, sha256: str) -> StudyOutcome | None:
    """The outcome in a folder's marker when it is of a successful run of the same file."""
    marker = folder / DONE_MARKER
    try:
        data = json.loads(marker.read_text(encoding="utf-8"))
        outcome = StudyOutcome.from_dict(data)
    except (OSError, ValueError, TypeError):
        return None
    if outcome.failed or not sha256 or outcome.study_sha256 != sha256:
        return None
    return outcome


def study_kind(study: Any) -> str:
    """What a study is: a fit when it has ``[[data]]`` records and a ``[fit]`` table."""
    return "fit" if study.data and study.fit is not None else "simulation"


def start_outcome(task: Task) -> StudyOutcome:
    """A study's outcome before it runs; removes its folder's marker (the folder is about
    to change: it holds no complete result)."""

    marker = Path(task.out_dir) / task.folder / DONE_MARKER
    if marker.is_file():
        marker.unlink()
    return StudyOutcome(
        study=task.study,
        folder=task.folder,
        study_sha256=file_sha256(task.path),
        gpu=os.environ.get(GPU_PIN_ENV, ""),
        host=socket.gethostname(),
        pid=os.getpid(),
    )


def write_marker(task: Task, outcome: StudyOutcome) -> None:
    """Write a successful study's marker, last and atomically."""
    if not outcome.failed:
        write_json(Path(task.out_dir) / task.folder / DONE_MARKER, outcome.to_dict())


def error_numbers(exc: Exception) -> dict[str, Any]:
    """A failed study's numbers. As the command line: a project error's own status, 2 for a
    path the system refuses (a folder where a file goes, no permission, a full disk), else 1."""
    if isinstance(exc, WarpTissueError):
        exit_status = exc.exit_code
    else:
        exit_status = 2 if isinstance(exc, OSError) else 1
    return {"status": "error", "exit_status": exit_status, "error": one_line(exc)}


@contextlib.contextmanager
def recorded(into: list[str]) -> Iterator[None]:
    """Record the Python warnings raised inside, one line each, into ``into``."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("default")
        try:
            yield
        finally:
            into.extend(" ".join(str(w.message).split()) for w in caught)


def write_summary(path: str | Path, outcomes: Sequence[StudyOutcome]) -> Path:
    """Write the batch summary table (:data:`SUMMARY_COLUMNS`), atomically.

    Args:
        path: The CSV file.
        outcomes: One row each; None cells (a simulation's R^2) are empty.

    Returns:
        The path written.
    """
    rows = [outcome.summary_row() for outcome in outcomes]
    columns = {
        name: np.array([row[name] for row in rows] or [], dtype=object) for name in SUMMARY_COLUMNS
    }
    return write_csv(path, columns)
