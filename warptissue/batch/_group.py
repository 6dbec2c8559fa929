"""A batch task of several studies: the simulations that can share launches solved in one
batched FE run (:func:`warptissue.simulate.run_studies_together`), the fits refitted
together, the others one by one.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

from warptissue import simulate
from warptissue.batch._outcome import (
    StudyOutcome,
    Task,
    error_numbers,
    one_line,
    recorded,
    start_outcome,
    study_kind,
    write_marker,
)
from warptissue.batch._work import (
    check_out_dir,
    fit_numbers,
    fit_study,
    kill_once_hook,
    simulation_numbers,
    worker_device,
)
from warptissue.device import (
    quiet_warp,
)
from warptissue.fit.indentation import fit_indentation
from warptissue.study import load_study


def fit_together(
    members: list[tuple[int, Any, Path]], device: str | None
) -> dict[int, dict[str, Any]]:
    """A group's fits on one device fitted together (their forward runs batched,
    :func:`warptissue.fit.fit_indentation` over their studies): each one's numbers."""

    for _, _, out_dir in members:
        check_out_dir(out_dir)
    fits = fit_indentation([study for _, study, _ in members], device=device, progress=False)
    return {
        index: fit_numbers(fit, out_dir, solved_together=len(members))
        for (index, _, out_dir), fit in zip(members, fits, strict=True)
    }


def run_group_task(tasks: Sequence[Task]) -> list[StudyOutcome]:
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

    outcomes = [start_outcome(task) for task in tasks]
    notes: list[list[str]] = [[] for _ in tasks]
    seconds = [0.0] * len(tasks)
    alone: dict[int, Callable[[], dict[str, Any]]] = {}  # index -> what runs it alone
    parts: list[list[tuple[int, Any]]] = []  # simulations that share their settings
    fit_groups: dict[str | None, list[tuple[int, Any, Path]]] = {}  # fits by device
    for index, task in enumerate(tasks):
        started = time.perf_counter()
        try:
            with recorded(notes[index]):
                quiet_warp()
                study = load_study(task.path)
                outcomes[index] = replace(outcomes[index], kind=study_kind(study))
                device = worker_device(task.device, study) if task.on_dask else task.device
                out_dir = Path(task.out_dir) / task.folder
                if outcomes[index].kind == "fit":
                    alone[index] = functools.partial(fit_study, study, out_dir, device)
                    fit_groups.setdefault(device, []).append((index, study, out_dir))
                else:
                    setup = simulate.prepare_study(
                        study, out_dir=out_dir, device=device, announce=False
                    )
                    alone[index] = functools.partial(solve_alone, setup)
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
            outcomes[index] = replace(outcomes[index], **error_numbers(exc))
        seconds[index] = time.perf_counter() - started

    for part in (part for part in parts if len(part) > 1):
        started = time.perf_counter()
        shared: list[str] = []
        try:
            with recorded(shared):
                solved = simulate.run_studies_together([setup for _, setup in part])
        except Exception as exc:  # noqa: BLE001 - they run alone instead
            for index, _setup in part:
                notes[index].append(f"solved alone: the batched run failed: {one_line(exc)}")
            continue
        spent = time.perf_counter() - started
        for (index, _), outputs in zip(part, solved, strict=True):
            numbers = simulation_numbers(outputs)
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
            with recorded(shared):
                fitted = fit_together(members, device)
        except KeyboardInterrupt:
            raise
        except Exception as exc:  # noqa: BLE001 - they are fitted alone instead
            for index, _, _ in members:
                notes[index].append(f"fitted alone: the joint run failed: {one_line(exc)}")
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
            with recorded(caught):
                numbers = alone[index]()
            numbers["warnings"] = numbers["warnings"] + notes[index] + caught
            outcomes[index] = replace(outcomes[index], **numbers)
        except Exception as exc:  # noqa: BLE001 - a failed study is a row; the batch goes on
            outcomes[index] = replace(
                outcomes[index], **error_numbers(exc), warnings=notes[index] + caught
            )
        seconds[index] += time.perf_counter() - started
    outcomes = [replace(o, seconds=t) for o, t in zip(outcomes, seconds, strict=True)]
    if tasks and tasks[0].on_dask:
        kill_once_hook()
    for task, outcome in zip(tasks, outcomes, strict=True):
        write_marker(task, outcome)
    return outcomes


def solve_alone(setup: Any) -> dict[str, Any]:
    """A prepared simulation of a group solved alone: its outcome's numbers."""

    return simulation_numbers(simulate.solve_study(setup, progress=False))
