"""Several studies' load steps solved in one batched FE run (``warptissue batch --together``).

:func:`together_settings` says which prepared studies can share a run;
:func:`run_studies_together` solves them with :func:`warptissue.fem.simulate_indentation_batch`
and writes each study's files as :func:`warptissue.simulate.run_study` does.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

from warptissue.errors import InputError
from warptissue.fem import (
    simulate_indentation_batch,
)
from warptissue.simulate.build import StudySetup
from warptissue.simulate.outputs import SimulationOutputs, write_study_outputs


def together_settings(setup: StudySetup) -> dict[str, Any]:
    """What studies solved together must share (:func:`run_studies_together`).

    Args:
        setup: The study's :class:`StudySetup`.

    Returns:
        ``device`` (its name), ``solver.formulation`` and ``solver`` (the Newton options),
        to compare with ``==``.
    """
    return {
        "device": str(setup.device),
        "solver.formulation": setup.problem.formulation,
        "solver": setup.study.solver.options,
    }


def run_studies_together(setups: Sequence[StudySetup]) -> list[SimulationOutputs]:
    """Solve several simulation studies in the same launches and write each one's outputs.

    The load steps of all the studies run as one batched FE run
    (:func:`warptissue.fem.simulate_indentation_batch`: one assembly launch and one
    factorization of the block-diagonal tangent per Newton iteration, each study with its
    own increments, convergence and cutbacks); then each study's folder gets what
    :func:`run_study` writes, with ``solved_together`` = the number of studies in
    ``result.json``.

    Args:
        setups: The studies, from :func:`prepare_study`: any indenter, elastic or
            viscoelastic, quasi-static or timed protocols, on one device, with one
            formulation and equal ``[solver]`` settings.

    Returns:
        One :class:`SimulationOutputs` per study, in order.

    Raises:
        InputError: No study, or one whose device, formulation or solver settings differ
            from the first study's (quoting both).

    Notes:
        The forces equal those of :func:`run_study` to the Newton tolerance: every study
        runs the one Newton loop with its own decisions; only the shared factorization's
        reuse is decided for all at once, which changes the path to the solution, not the
        converged state (docs/design-notes/batched-fe.md).
    """

    setups = list(setups)
    if not setups:
        raise InputError("at least one study is needed", key="studies", value=0)
    first = setups[0]
    for setup in setups[1:]:
        for (key, mine), theirs in zip(
            together_settings(setup).items(), together_settings(first).values(), strict=True
        ):
            if mine != theirs:
                raise InputError(
                    f"studies solved together need one {key}; {first.study.path} has {theirs!r}",
                    path=setup.study.path,
                    key=key,
                    value=mine,
                )
    started = time.perf_counter()
    results = simulate_indentation_batch(
        [setup.problem for setup in setups],
        [setup.depths_m for setup in setups],
        device=str(first.device),
        options=first.study.solver.options,
        times_s=[setup.times_s for setup in setups],
    )
    solve_s = time.perf_counter() - started
    return [
        write_study_outputs(
            setup,
            result,
            status="completed" if result.completed else "stopped_early",
            message=str(result.message),
            solve_s=solve_s,
            solved_together=len(setups),
        )
        for setup, result in zip(setups, results, strict=True)
    ]
