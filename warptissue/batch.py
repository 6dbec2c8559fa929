"""Batches of studies: many simulations and fits, one result folder each, on Dask.

:func:`run_batch` is the Python API behind ``warptissue batch``. It takes study files (or
folders of them, or glob patterns), decides for each what it is the way the single-study
commands do (a study with ``[[data]]`` records and a ``[fit]`` table is an indentation fit,
:func:`warptissue.fit.indentation.fit_indentation`; any other a simulation,
:func:`warptissue.simulate.run_study`), and runs one task per study, or per group of up
to ``together`` studies whose simulations that can share launches are solved in one
batched FE run (:func:`run_group_task`, :func:`warptissue.simulate.run_studies_together`):

- each study writes the files of its single-study command into ``OUT/<folder>``, the folder
  named from the study file's stem (:func:`warptissue.study.folder_names`), then, last and
  atomically, the marker :data:`DONE_MARKER` (``batch_done.json``: the study's summary row
  and the SHA-256 of its study file) when it succeeded;
- a study that fails (bad input, a mesh that cannot be used, no convergence, a device
  missing, any exception) is one row of the summary with its one-line error, and the others
  go on;
- the client writes ``OUT/summary.csv`` (:data:`SUMMARY_COLUMNS`), one row per study in the
  order given, after every study that ends (atomically), so that it is current at any time;
- on a rerun, a study whose folder holds the marker of a run of the same study file is
  skipped (its row comes from the marker) unless ``force``.

The tasks run on Dask distributed: by default a ``LocalCluster`` of worker processes on this
machine, or a running cluster (``scheduler="tcp://HOST:PORT"``). A worker that dies (killed,
out of memory, a crash in a native library) takes its task with it, and the scheduler runs
the task again on another worker (up to Dask's ``distributed.scheduler.allowed-failures``,
3 by default; ``retries`` re-runs a task that raised, which the study task does not: it
turns its exceptions into a failed row). Each task writes its files itself, so the workers,
the study files, their data and ``OUT`` must be on one file system at the same paths (this
machine, or a shared disk). ``workers=0`` runs the studies one after another in this
process, without Dask. Why Dask: docs/design-notes/batch.md.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import json
import logging
import os
import signal
import socket
import sys
import time
import uuid
import warnings
from collections.abc import Callable, Iterator, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import warp as wp

from warptissue import simulate
from warptissue.device import (
    quiet_warp,
    terminal_interrupts_ignored,
    thread_lock_for_progress_bars,
)
from warptissue.errors import DeviceError, InputError, WarpTissueError
from warptissue.fit.indentation import fit_indentation
from warptissue.io import write_csv, write_json
from warptissue.report import write_indentation_fit_outputs
from warptissue.study import collect_studies, folder_names, load_study

__all__ = [
    "DONE_MARKER",
    "FAILED_EXIT_CODE",
    "SUMMARY_COLUMNS",
    "BatchResult",
    "StudyOutcome",
    "run_batch",
]

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
_KILL_ONCE_ENV = "WARPTISSUE_BATCH_TEST_KILL_ONCE"
"""Test hook (tests/test_batch.py): names a file; the first Dask task to create it kills its
own worker process (SIGKILL) after writing its results and before its marker."""
SCHEDULER_TIMEOUT_S = 20.0
"""How long ``--scheduler`` waits for the scheduler to connect and answer, s: a port that
accepts and never answers is an unreachable scheduler (exit 5) after this long."""

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
class _Task:
    """What a worker needs to run one study (sent to it by Dask)."""

    path: str
    study: str
    out_dir: str
    folder: str
    device: str | None
    on_dask: bool


def _sha256(path: str | Path) -> str:
    try:
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()
    except OSError:
        return ""


def _one_line(error: BaseException) -> str:
    """An exception as one line (its message; the class name for an unexpected one)."""
    text = " ".join(str(error).split())
    if isinstance(error, WarpTissueError):
        return text
    if isinstance(error, OSError) and error.strerror:
        path = error.filename2 if error.filename2 is not None else error.filename
        return error.strerror if path is None else f"cannot use {str(path)!r}: {error.strerror}"
    return f"{type(error).__name__}: {text}" if text else type(error).__name__


def _completed_outcome(folder: Path, sha256: str) -> StudyOutcome | None:
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


def _worker_device(device: str | None, study: Any) -> str | None:
    """The device of a study on a Dask worker: LocalCluster names its workers 0, 1, ...;
    on a machine with several GPUs, worker k takes GPU k mod (number of GPUs) when the device
    is ``cuda`` or ``auto`` (given or the study's). Elsewhere ``device`` as it is."""
    chosen = device if device is not None else study.solver.device
    if chosen not in ("cuda", "auto"):
        return device
    try:
        from distributed import get_worker

        name = get_worker().name
    except (ImportError, ValueError):
        return device
    if not isinstance(name, int):
        return device

    wp.init()
    count = wp.get_cuda_device_count()
    return f"cuda:{name % count}" if count > 1 else device


def _kill_once_hook() -> None:
    """Test hook: the first task to create the file named by :data:`_KILL_ONCE_ENV` kills
    its worker process."""
    flag = os.environ.get(_KILL_ONCE_ENV)
    if not flag:
        return
    try:
        handle = os.open(flag, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
    except FileExistsError:
        return
    os.write(handle, str(os.getpid()).encode())
    os.close(handle)
    os.kill(os.getpid(), getattr(signal, "SIGKILL", signal.SIGTERM))


def _simulation_numbers(outputs: Any) -> dict[str, Any]:
    """A simulation's numbers of its outcome, from its :class:`SimulationOutputs`."""
    forces = np.asarray(outputs.summary["force_curve"]["reaction_force_N"], dtype=np.float64)
    return {
        "status": outputs.status,
        "exit_status": outputs.exit_code,
        "solved_together": int(outputs.summary["solved_together"]),
        "peak_force_N": float(forces.max()) if forces.size else None,
        "warnings": list(outputs.summary["warnings"]),
        "error": "" if outputs.completed else f"stopped early: {outputs.message}",
    }


def _simulate(study: Any, out_dir: Path, device: str | None) -> dict[str, Any]:
    outputs = simulate.run_study(
        study, out_dir=out_dir, device=device, progress=False, announce=False
    )
    return _simulation_numbers(outputs)


def _fit(study: Any, out_dir: Path, device: str | None) -> dict[str, Any]:
    _check_out_dir(out_dir)
    return _fit_numbers(fit_indentation(study, device=device, progress=False), out_dir)


def _check_out_dir(out_dir: Path) -> None:
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError("the output folder is a file", path=out_dir)


def _fit_numbers(fit: Any, out_dir: Path, solved_together: int = 1) -> dict[str, Any]:
    """Write a fit's outputs into its folder; its outcome's numbers."""

    write_indentation_fit_outputs(out_dir, fit)
    if fit.status == "interrupted":  # Ctrl-C in this process: stop the batch
        raise KeyboardInterrupt
    error = ""
    if fit.status == "stage_one_not_converged":
        error = fit.message
    elif not fit.success:
        what = "failed" if fit.status == "failed" else f"did not converge ({fit.status})"
        error = f"the fit {what}: {fit.message}"
    return {
        "status": fit.status,
        "exit_status": fit.exit_code,
        "r_squared": fit.result.r_squared,
        "parameters": {name: float(value) for name, value in fit.parameters.items()},
        "warnings": list(fit.warnings),
        "error": error,
        "solved_together": solved_together,
    }


def _fit_together(
    members: list[tuple[int, Any, Path]], device: str | None
) -> dict[int, dict[str, Any]]:
    """A group's fits on one device fitted together (their forward runs batched,
    :func:`warptissue.fit.fit_indentation` over their studies): each one's numbers."""

    for _, _, out_dir in members:
        _check_out_dir(out_dir)
    fits = fit_indentation([study for _, study, _ in members], device=device, progress=False)
    return {
        index: _fit_numbers(fit, out_dir, solved_together=len(members))
        for (index, _, out_dir), fit in zip(members, fits, strict=True)
    }


def run_study_task(task: _Task) -> StudyOutcome:
    """Run one study of a batch and write its folder (the function each Dask task runs).

    Loads the study, runs it as a simulation or a fit, writes the files of its single-study
    command into the folder, and last, when it succeeded, the marker :data:`DONE_MARKER`
    (atomically). An exception becomes a failed outcome with its one-line message; only
    Ctrl-C (``KeyboardInterrupt``) passes.

    Args:
        task: The study file, its folder and the device.

    Returns:
        The study's :class:`StudyOutcome`.
    """

    started = time.perf_counter()
    out_dir = Path(task.out_dir) / task.folder
    outcome = _start_outcome(task)
    caught: list[str] = []
    try:
        with _recorded(caught):
            quiet_warp()
            study = load_study(task.path)
            kind = _kind(study)
            outcome = replace(outcome, kind=kind)
            device = _worker_device(task.device, study) if task.on_dask else task.device
            run = _fit if kind == "fit" else _simulate
            numbers = run(study, out_dir, device)
        numbers["warnings"] = numbers["warnings"] + caught
        outcome = replace(outcome, **numbers)
    except Exception as exc:  # noqa: BLE001 - a failed study is a row; the batch goes on
        outcome = replace(outcome, **_error_numbers(exc))
    outcome = replace(outcome, seconds=time.perf_counter() - started)
    if task.on_dask:
        _kill_once_hook()
    _write_marker(task, outcome)
    return outcome


def run_group_task(tasks: Sequence[_Task]) -> list[StudyOutcome]:
    """Run a group of studies of a batch, the simulations that can be solved together in
    one batched FE run (the function each Dask task runs when ``together`` > 1).

    Each study is loaded and set up (:func:`warptissue.simulate.prepare_study`) on its own.
    The simulations with equal device, formulation and ``[solver]`` settings are solved
    together (:func:`warptissue.simulate.run_studies_together`); the others (a setting
    shared with no other study of the group) run alone, as :func:`run_study_task`
    runs them; the group's fits on one device are fitted together, their forward runs
    batched (:func:`warptissue.fit.fit_indentation` over their studies), and where that
    raises, alone. A batched run that raises is said in its studies' warnings and they run
    alone instead. Each study's folder, marker and outcome are those :func:`run_study_task`
    would give, with ``solved_together``.

    Args:
        tasks: The studies of the group.

    Returns:
        One :class:`StudyOutcome` per task, in order.
    """

    outcomes = [_start_outcome(task) for task in tasks]
    notes: list[list[str]] = [[] for _ in tasks]
    seconds = [0.0] * len(tasks)
    alone: dict[int, Callable[[], dict[str, Any]]] = {}  # index -> what runs it alone
    parts: list[list[tuple[int, Any]]] = []  # simulations that share their settings
    fit_groups: dict[str | None, list[tuple[int, Any, Path]]] = {}  # fits by device
    for index, task in enumerate(tasks):
        started = time.perf_counter()
        try:
            with _recorded(notes[index]):
                quiet_warp()
                study = load_study(task.path)
                outcomes[index] = replace(outcomes[index], kind=_kind(study))
                device = _worker_device(task.device, study) if task.on_dask else task.device
                out_dir = Path(task.out_dir) / task.folder
                if outcomes[index].kind == "fit":
                    alone[index] = functools.partial(_fit, study, out_dir, device)
                    fit_groups.setdefault(device, []).append((index, study, out_dir))
                else:
                    setup = simulate.prepare_study(
                        study, out_dir=out_dir, device=device, announce=False
                    )
                    alone[index] = functools.partial(_solve_alone, setup)
                    settings = simulate.together_settings(setup)
                    part = next(
                        (p for p in parts if simulate.together_settings(p[0][1]) == settings),
                        None,
                    )
                    if part is None:
                        parts.append([(index, setup)])
                    else:
                        part.append((index, setup))
        except Exception as exc:  # noqa: BLE001 - a failed study is a row; the batch goes on
            outcomes[index] = replace(outcomes[index], **_error_numbers(exc))
        seconds[index] = time.perf_counter() - started

    for part in (part for part in parts if len(part) > 1):
        started = time.perf_counter()
        shared: list[str] = []
        try:
            with _recorded(shared):
                solved = simulate.run_studies_together([setup for _, setup in part])
        except Exception as exc:  # noqa: BLE001 - they run alone instead
            for index, _setup in part:
                notes[index].append(f"solved alone: the batched run failed: {_one_line(exc)}")
            continue
        spent = time.perf_counter() - started
        for (index, _), outputs in zip(part, solved, strict=True):
            numbers = _simulation_numbers(outputs)
            numbers["warnings"] = numbers["warnings"] + notes[index] + shared
            outcomes[index] = replace(outcomes[index], **numbers)
            seconds[index] += spent
            del alone[index]
    for device, members in fit_groups.items():
        if len(members) < 2:
            continue
        started = time.perf_counter()
        shared = []
        try:
            with _recorded(shared):
                fitted = _fit_together(members, device)
        except KeyboardInterrupt:
            raise
        except Exception as exc:  # noqa: BLE001 - they are fitted alone instead
            for index, _, _ in members:
                notes[index].append(f"fitted alone: the joint run failed: {_one_line(exc)}")
            continue
        spent = time.perf_counter() - started
        for index, numbers in fitted.items():
            numbers["warnings"] = numbers["warnings"] + notes[index] + shared
            outcomes[index] = replace(outcomes[index], **numbers)
            seconds[index] += spent
            del alone[index]
    for index in sorted(alone):
        started = time.perf_counter()
        caught: list[str] = []
        try:
            with _recorded(caught):
                numbers = alone[index]()
            numbers["warnings"] = numbers["warnings"] + notes[index] + caught
            outcomes[index] = replace(outcomes[index], **numbers)
        except Exception as exc:  # noqa: BLE001 - a failed study is a row; the batch goes on
            outcomes[index] = replace(
                outcomes[index], **_error_numbers(exc), warnings=notes[index] + caught
            )
        seconds[index] += time.perf_counter() - started
    outcomes = [replace(o, seconds=t) for o, t in zip(outcomes, seconds, strict=True)]
    if tasks and tasks[0].on_dask:
        _kill_once_hook()
    for task, outcome in zip(tasks, outcomes, strict=True):
        _write_marker(task, outcome)
    return outcomes


def _solve_alone(setup: Any) -> dict[str, Any]:
    """A prepared simulation of a group solved alone: its outcome's numbers."""

    return _simulation_numbers(simulate.solve_study(setup, progress=False))


def _kind(study: Any) -> str:
    """What a study is: a fit when it has ``[[data]]`` records and a ``[fit]`` table."""
    return "fit" if study.data and study.fit is not None else "simulation"


def _start_outcome(task: _Task) -> StudyOutcome:
    """A study's outcome before it runs; removes its folder's marker (the folder is about
    to change: it holds no complete result)."""

    marker = Path(task.out_dir) / task.folder / DONE_MARKER
    if marker.is_file():
        marker.unlink()
    return StudyOutcome(
        study=task.study,
        folder=task.folder,
        study_sha256=_sha256(task.path),
        gpu=os.environ.get(GPU_PIN_ENV, ""),
        host=socket.gethostname(),
        pid=os.getpid(),
    )


def _write_marker(task: _Task, outcome: StudyOutcome) -> None:
    """Write a successful study's marker, last and atomically."""
    if not outcome.failed:
        write_json(Path(task.out_dir) / task.folder / DONE_MARKER, outcome.to_dict())


def _error_numbers(exc: Exception) -> dict[str, Any]:
    """A failed study's numbers. As the command line: a project error's own status, 2 for a
    path the system refuses (a folder where a file goes, no permission, a full disk), else 1."""
    if isinstance(exc, WarpTissueError):
        exit_status = exc.exit_code
    else:
        exit_status = 2 if isinstance(exc, OSError) else 1
    return {"status": "error", "exit_status": exit_status, "error": _one_line(exc)}


@contextlib.contextmanager
def _recorded(into: list[str]) -> Iterator[None]:
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


def worker_gpus(device: str | None) -> list[str]:
    """The GPUs a LocalCluster's workers are pinned to, in turn, or [] where they are not.

    For ``device`` ``"cuda"``, ``"auto"`` or None (each study's own ``solver.device``) on a
    machine with GPUs: the GPUs this process may use (its own ``CUDA_VISIBLE_DEVICES``
    where that is set, else every GPU Warp finds). ``"cpu"`` and ``"cuda:N"`` (a GPU chosen
    by index) pin nothing.
    """
    if device not in (None, "cuda", "auto"):
        return []
    visible = os.environ.get(GPU_PIN_ENV)
    if visible is not None:
        return [gpu.strip() for gpu in visible.split(",") if gpu.strip()]
    quiet_warp()  # counting GPUs prints nothing where there are none
    return [str(index) for index in range(wp.get_cuda_device_count())]


def _dask_client(scheduler: str | None, workers: int, gpus: Sequence[str] = ()) -> tuple[Any, Any]:
    """A Dask client of a running scheduler, or of a new local cluster (returned to close):
    ``workers`` single-threaded worker processes, worker k pinned to ``gpus[k mod len]`` by
    :data:`GPU_PIN_ENV` where ``gpus`` are given (so that its ``cuda`` is that GPU)."""
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise InputError(
            "Dask distributed is not installed: pip install 'warptissue[batch]' (or "
            "--workers 0 runs the studies one after another in this process)",
            option="--scheduler" if scheduler else "--workers",
        ) from None
    if scheduler is not None:
        _check_scheduler(scheduler, SCHEDULER_TIMEOUT_S)
        try:
            return Client(scheduler, timeout=f"{SCHEDULER_TIMEOUT_S}s"), None
        except (OSError, TimeoutError, ValueError) as exc:
            raise DeviceError(
                f"cannot reach the Dask scheduler {scheduler!r}: {_one_line(exc)}"
            ) from None
    if gpus:
        from distributed import Nanny, Scheduler, SpecCluster

        with terminal_interrupts_ignored():
            cluster = SpecCluster(
                workers={
                    k: {
                        "cls": Nanny,
                        "options": {
                            "nthreads": 1,
                            "env": {GPU_PIN_ENV: gpus[k % len(gpus)]},
                            "silence_logs": logging.CRITICAL,
                        },
                    }
                    for k in range(workers)
                },
                scheduler={
                    "cls": Scheduler,
                    "options": {"host": "127.0.0.1", "dashboard_address": None},
                },
                silence_logs=logging.CRITICAL,
            )
        return Client(cluster), cluster
    with terminal_interrupts_ignored():
        cluster = LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address=None,
            silence_logs=logging.CRITICAL,
        )
    return Client(cluster), cluster


def _check_scheduler(address: str, timeout_s: float) -> None:
    """Ask the Dask scheduler at ``address`` who it is, waiting at most ``timeout_s`` for the
    connection and the answer together (a Dask client waits for ever on a port that accepts
    and never answers).

    Raises:
        DeviceError: No scheduler answers there in time, or ``address`` is not an address.
    """
    import asyncio

    from distributed.comm import connect

    async def identity() -> Any:
        comm = await connect(address, timeout=timeout_s)
        try:
            await comm.write({"op": "identity", "reply": True})
            return await comm.read()
        finally:
            comm.abort()

    try:
        asyncio.run(asyncio.wait_for(identity(), timeout_s))
    except TimeoutError:
        raise DeviceError(
            f"cannot reach the Dask scheduler {address!r}: it did not answer within {timeout_s:g} s"
        ) from None
    except (OSError, ValueError) as exc:
        raise DeviceError(
            f"cannot reach the Dask scheduler {address!r}: {_one_line(exc)}"
        ) from None


def _have_dask() -> bool:
    try:
        import distributed  # noqa: F401
    except ImportError:
        return False
    return True


def run_batch(
    paths: Sequence[str | Path],
    *,
    out: str | Path,
    device: str | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    force: bool = False,
    progress: bool = True,
    retries: int = 1,
    together: int = 1,
    on_outcome: Callable[[StudyOutcome], None] | None = None,
) -> BatchResult:
    """Run every study of a batch, one result folder each, and write the summary table.

    Args:
        paths: Study files, folders of them and glob patterns (:func:`collect_studies`);
            files inside ``out`` (the batch's own outputs) are left out.
        out: The batch's output folder: one folder per study
            (:func:`warptissue.study.folder_names`) and ``summary.csv``.
        device: Warp device of every study (``"cpu"``, ``"cuda"``, ``"cuda:N"``); None:
            each study's ``solver.device``. For ``cuda``, ``auto`` and None on a machine
            with GPUs, the local cluster's workers are pinned to them in turn by
            ``CUDA_VISIBLE_DEVICES`` (:func:`worker_gpus`): worker k's ``cuda`` is GPU
            k mod (number of GPUs).
        workers: Worker processes of the local cluster (default: one per GPU where the
            workers are pinned to GPUs, else 1; 0 runs the studies in this process, one
            after another, without Dask). Not with ``scheduler``.
        scheduler: Address of a running Dask scheduler (``"tcp://HOST:PORT"``) to run the
            studies on its workers instead of a LocalCluster.
        force: Run the studies whose folder holds a complete result too.
        progress: Show a progress bar over the studies (on standard error).
        retries: Dask ``retries`` of a task that raised (a worker that dies is handled by
            the scheduler: the task runs again elsewhere).
        together: Studies per task (default 1). Above 1, the studies are taken in groups of
            up to ``together``, in the order given, one task each, and the simulations of a
            group that can share launches are solved in one batched FE run
            (:func:`run_group_task`); the others of the group run alone in the same task.
        on_outcome: Called with each study's outcome as it ends (skipped ones first).

    Returns:
        The :class:`BatchResult`; its ``exit_code`` is :data:`FAILED_EXIT_CODE` when a study
        failed.

    Raises:
        InputError: No study file, a missing one, an output folder that is a file, ``workers``
            with ``scheduler``, or Dask not installed where it is asked for.
        DeviceError: The scheduler cannot be reached.
        KeyboardInterrupt: Ctrl-C; the summary then holds the studies that had ended.
    """
    started = time.perf_counter()
    out_dir = Path(out)
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError("the output folder is a file", path=out_dir)
    # The batch's own outputs (a fit's fitted_study.toml) are not studies of the batch, even
    # where a pattern such as '**/*.toml' reaches into OUT.
    inside = os.path.realpath(out_dir) + os.sep
    studies = [p for p in collect_studies(paths) if not os.path.realpath(p).startswith(inside)]
    if not studies:
        raise InputError("every study file given lies inside the output folder", path=out_dir)
    if scheduler is not None and workers is not None:
        raise InputError(
            "--workers sets the size of a LocalCluster; a running scheduler has its own "
            "workers: give one of them",
            option="--workers",
            value=workers,
        )
    if workers is not None and workers < 0:
        raise InputError("must be 0 or more", option="--workers", value=workers)
    if together < 1:
        raise InputError("must be 1 or more", option="--together", value=together)
    out_dir.mkdir(parents=True, exist_ok=True)
    summary_path = out_dir / SUMMARY_FILE
    names = folder_names(studies)
    outcomes: list[StudyOutcome | None] = [None] * len(studies)
    pending: list[tuple[int, _Task]] = []
    use_dask = scheduler is not None or workers != 0
    if use_dask and scheduler is None and workers is None and not _have_dask():
        warnings.warn(
            "Dask distributed is not installed (pip install 'warptissue[batch]'): the studies "
            "run one after another in this process",
            stacklevel=2,
        )
        use_dask = False
    for index, (path, name) in enumerate(zip(studies, names, strict=True)):
        done = None if force else _completed_outcome(out_dir / name, _sha256(path))
        if done is not None:
            outcomes[index] = replace(done, study=str(path), folder=name, skipped=True)
            continue
        task = _Task(
            path=os.path.abspath(path),
            study=str(path),
            out_dir=os.path.abspath(out_dir),
            folder=name,
            device=device,
            on_dask=use_dask,
        )
        pending.append((index, task))

    from tqdm.auto import tqdm

    bar = tqdm(
        total=len(studies),
        desc="batch",
        unit="study",
        disable=not progress,
        file=sys.stderr,
    )

    def finish(index: int | None, outcome: StudyOutcome | None) -> None:
        if index is not None:
            outcomes[index] = outcome
        write_summary(summary_path, [o for o in outcomes if o is not None])
        if outcome is not None:
            bar.update(1)
            if on_outcome is not None:
                on_outcome(outcome)

    for outcome in outcomes:
        if outcome is not None:
            finish(None, outcome)
    worker_count = 0
    try:
        if not pending:
            finish(None, None)
        elif not use_dask:
            for group in _groups(pending, together):
                for (index, _), outcome in zip(group, _run_group(group), strict=True):
                    finish(index, outcome)
        else:
            groups = _groups(pending, together)
            gpus = [] if scheduler is not None else worker_gpus(device)
            if workers is None:
                workers = max(1, len(gpus))  # one worker per GPU, else one
            worker_count = _run_on_dask(groups, scheduler, workers, retries, finish, gpus)
    finally:
        bar.close()
    return BatchResult(
        out_dir=out_dir,
        outcomes=tuple(o for o in outcomes if o is not None),
        summary_path=summary_path,
        seconds=time.perf_counter() - started,
        workers=worker_count,
    )


def _groups(pending: Sequence[tuple[int, _Task]], together: int) -> list[list[tuple[int, _Task]]]:
    """The pending studies in groups of up to ``together``, in order: one task each."""
    return [list(pending[i : i + together]) for i in range(0, len(pending), together)]


def _run_group(group: Sequence[tuple[int, _Task]]) -> list[StudyOutcome]:
    """Run one group's task: a single study alone, several as :func:`run_group_task`."""
    tasks = [task for _, task in group]
    if tasks[0].on_dask:
        thread_lock_for_progress_bars()
    return [run_study_task(tasks[0])] if len(tasks) == 1 else run_group_task(tasks)


def _run_on_dask(
    groups: Sequence[Sequence[tuple[int, _Task]]],
    scheduler: str | None,
    workers: int | None,
    retries: int,
    finish: Callable[[int | None, StudyOutcome | None], None],
    gpus: Sequence[str] = (),
) -> int:
    """Submit one task per group of studies, record each study as its task ends; returns
    the number of workers."""

    from distributed import as_completed

    client, cluster = _dask_client(scheduler, 1 if workers is None else workers, gpus)
    futures: dict[Any, Sequence[tuple[int, _Task]]] = {}
    try:
        worker_count = len(client.scheduler_info().get("workers", {}))
        token = uuid.uuid4().hex[:8]
        for group in groups:
            future = client.submit(
                _run_group,
                list(group),
                key=f"warptissue-batch-{group[0][1].folder}-{token}",
                retries=retries,
                pure=False,
            )
            futures[future] = group
        for future in as_completed(list(futures)):
            group = futures[future]
            try:
                outcomes = future.result()
            except Exception as exc:  # noqa: BLE001 - e.g. KilledWorker: its worker kept dying
                outcomes = [
                    StudyOutcome(
                        study=task.study,
                        folder=task.folder,
                        error=f"the Dask task failed: {_one_line(exc)}",
                    )
                    for _, task in group
                ]
            for (index, _), outcome in zip(group, outcomes, strict=True):
                finish(index, outcome)
    except KeyboardInterrupt:
        client.cancel(list(futures))
        raise
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    return worker_count
