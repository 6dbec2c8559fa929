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

This module runs the batch (the client, Dask, one study's task); ``_outcome`` holds a study's
summary row, its marker and ``summary.csv``, ``_work`` what a task does with one study on its
worker, and ``_group`` the task of several studies solved together.
"""

from __future__ import annotations

import logging
import os
import sys
import time
import uuid
import warnings
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import warp as wp

from warptissue import simulate
from warptissue.batch._group import run_group_task
from warptissue.batch._outcome import (  # noqa: F401 (every public name stays importable here)
    DONE_MARKER,
    FAILED_EXIT_CODE,
    GPU_PIN_ENV,
    STUDY_KINDS,
    SUMMARY_COLUMNS,
    SUMMARY_FILE,
    BatchResult,
    StudyOutcome,
    Task,
    completed_outcome,
    error_numbers,
    file_sha256,
    one_line,
    recorded,
    start_outcome,
    study_kind,
    write_marker,
    write_summary,
)
from warptissue.batch._work import (
    KILL_ONCE_ENV,
    fit_study,
    kill_once_hook,
    simulation_numbers,
    worker_device,
)
from warptissue.device import (
    quiet_warp,
    terminal_interrupts_ignored,
    thread_lock_for_progress_bars,
)
from warptissue.errors import DeviceError, InputError
from warptissue.study import collect_studies, folder_names, load_study

__all__ = [
    "DONE_MARKER",
    "FAILED_EXIT_CODE",
    "SUMMARY_COLUMNS",
    "BatchResult",
    "StudyOutcome",
    "run_batch",
]

_KILL_ONCE_ENV = KILL_ONCE_ENV  # the names tests/test_batch.py reaches for
_worker_device = worker_device

SCHEDULER_TIMEOUT_S = 20.0
"""How long ``--scheduler`` waits for the scheduler to connect and answer, s: a port that
accepts and never answers is an unreachable scheduler (exit 5) after this long."""


def _simulate(study: Any, out_dir: Path, device: str | None) -> dict[str, Any]:
    outputs = simulate.run_study(
        study, out_dir=out_dir, device=device, progress=False, announce=False
    )
    return simulation_numbers(outputs)


def run_study_task(task: Task) -> StudyOutcome:
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
    outcome = start_outcome(task)
    caught: list[str] = []
    try:
        with recorded(caught):
            quiet_warp()
            study = load_study(task.path)
            kind = study_kind(study)
            outcome = replace(outcome, kind=kind)
            device = worker_device(task.device, study) if task.on_dask else task.device
            run = fit_study if kind == "fit" else _simulate
            numbers = run(study, out_dir, device)
        numbers["warnings"] = numbers["warnings"] + caught
        outcome = replace(outcome, **numbers)
    except Exception as exc:  # noqa: BLE001 - a failed study is a row; the batch goes on
        outcome = replace(outcome, **error_numbers(exc))
    outcome = replace(outcome, seconds=time.perf_counter() - started)
    if task.on_dask:
        kill_once_hook()
    write_marker(task, outcome)
    return outcome


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
                f"cannot reach the Dask scheduler {scheduler!r}: {one_line(exc)}"
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
        raise DeviceError(f"cannot reach the Dask scheduler {address!r}: {one_line(exc)}") from None


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
    studies = _batch_studies(paths, out_dir, scheduler, workers, together)
    out_dir.mkdir(parents=True, exist_ok=True)
    summary_path = out_dir / SUMMARY_FILE
    names = folder_names(studies)
    use_dask = _uses_dask(scheduler, workers)
    outcomes, pending = _pending(
        studies, names, out_dir, force=force, device=device, on_dask=use_dask
    )

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
    try:
        worker_count = _run_pending(
            pending,
            finish,
            together=together,
            use_dask=use_dask,
            scheduler=scheduler,
            workers=workers,
            retries=retries,
            device=device,
        )
    finally:
        bar.close()
    return BatchResult(
        out_dir=out_dir,
        outcomes=tuple(o for o in outcomes if o is not None),
        summary_path=summary_path,
        seconds=time.perf_counter() - started,
        workers=worker_count,
    )


def _batch_studies(
    paths: Sequence[str | Path],
    out_dir: Path,
    scheduler: str | None,
    workers: int | None,
    together: int,
) -> list[Path]:
    """The batch's study files (:func:`collect_studies`), those inside ``out_dir`` left out,
    with :func:`run_batch`'s options checked."""
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
    return studies


def _pending(
    studies: Sequence[Path],
    names: Sequence[str],
    out_dir: Path,
    *,
    force: bool,
    device: str | None,
    on_dask: bool,
) -> tuple[list[StudyOutcome | None], list[tuple[int, Task]]]:
    """Each study's outcome where its folder holds a complete result of the same study file
    (skipped; None for the others unless ``force``), and the tasks of the others as
    (index, task)."""
    outcomes: list[StudyOutcome | None] = [None] * len(studies)
    pending: list[tuple[int, Task]] = []
    for index, (path, name) in enumerate(zip(studies, names, strict=True)):
        done = None if force else completed_outcome(out_dir / name, file_sha256(path))
        if done is not None:
            outcomes[index] = replace(done, study=str(path), folder=name, skipped=True)
            continue
        task = Task(
            path=os.path.abspath(path),
            study=str(path),
            out_dir=os.path.abspath(out_dir),
            folder=name,
            device=device,
            on_dask=on_dask,
        )
        pending.append((index, task))
    return outcomes, pending


def _uses_dask(scheduler: str | None, workers: int | None) -> bool:
    """Whether the batch runs on Dask: not with ``workers=0``, nor by default where Dask
    distributed is not installed (said in a warning)."""
    if scheduler is None and workers == 0:
        return False
    if scheduler is None and workers is None and not _have_dask():
        warnings.warn(
            "Dask distributed is not installed (pip install 'warptissue[batch]'): the studies "
            "run one after another in this process",
            stacklevel=3,
        )
        return False
    return True


def _run_pending(
    pending: Sequence[tuple[int, Task]],
    finish: Callable[[int | None, StudyOutcome | None], None],
    *,
    together: int,
    use_dask: bool,
    scheduler: str | None,
    workers: int | None,
    retries: int,
    device: str | None,
) -> int:
    """Run the pending studies' tasks, in this process or on Dask, each outcome to
    ``finish`` as it ends; returns the number of Dask workers (0 in this process)."""
    if not pending:
        finish(None, None)
        return 0
    if not use_dask:
        for group in _groups(pending, together):
            for (index, _), outcome in zip(group, _run_group(group), strict=True):
                finish(index, outcome)
        return 0
    groups = _groups(pending, together)
    gpus = [] if scheduler is not None else worker_gpus(device)
    if workers is None:
        workers = max(1, len(gpus))  # one worker per GPU, else one
    return _run_on_dask(groups, scheduler, workers, retries, finish, gpus)


def _groups(pending: Sequence[tuple[int, Task]], together: int) -> list[list[tuple[int, Task]]]:
    """The pending studies in groups of up to ``together``, in order: one task each."""
    return [list(pending[i : i + together]) for i in range(0, len(pending), together)]


def _run_group(group: Sequence[tuple[int, Task]]) -> list[StudyOutcome]:
    """Run one group's task: a single study alone, several as :func:`run_group_task`."""
    tasks = [task for _, task in group]
    if tasks[0].on_dask:
        thread_lock_for_progress_bars()
    return [run_study_task(tasks[0])] if len(tasks) == 1 else run_group_task(tasks)


def _run_on_dask(
    groups: Sequence[Sequence[tuple[int, Task]]],
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
    futures: dict[Any, Sequence[tuple[int, Task]]] = {}
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
                        error=f"the Dask task failed: {one_line(exc)}",
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
