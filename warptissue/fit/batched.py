"""Inverse-FE fits of many flat-punch curves at once, their forward runs batched.

K fits (one per specimen, site or rate: its own mesh, material, depths and measured forces)
run the fit engine's Levenberg-Marquardt (:func:`warptissue.lsq.least_squares`), each with its
own damping, accepted and rejected steps and stopping test, exactly as K separate fits would.
What they share is the forward model: whenever every fit still running has asked for its
next trial point, the K trial curves are solved together in one batched FE run
(:func:`warptissue.fem.simulate_indentation_batch`, with the exact force sensitivities), so a
GPU does one batch of K curves where it did K curves one after another. A fit that has
stopped leaves the batch; the others go on.

The fits run in threads that meet at the forward model (only the batched FE does work; the
engine's steps are small dense solves); the batched FE itself runs in the caller's thread.
"""

from __future__ import annotations

import dataclasses
import threading
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from warptissue.errors import InputError
from warptissue.fem import (
    IndentationProblem,
    NewtonOptions,
    batch_assembler,
    simulate_indentation_batch,
)
from warptissue.lsq.engine import least_squares
from warptissue.lsq.result import FitResult, RejectStep

__all__ = ["fit_indentation_batch"]


@dataclass
class _Evaluation:
    """One fit's forward run at a trial point: residuals (m,) and Jacobian (m, n)."""

    x: np.ndarray
    residuals: np.ndarray | None
    jacobian: np.ndarray | None
    error: BaseException | None = None


class _BatchedForward:
    """Collects the fits' trial points; the caller's thread solves them in one batched FE run.

    A fit's thread calls :meth:`evaluate` and waits. :meth:`serve`, in the thread that called
    :func:`fit_indentation_batch`, runs a batch whenever every fit still running has a trial
    point waiting, and hands each its result. :meth:`leave` takes a stopped fit out of the
    set. The FE runs in one thread because the GPU's libraries keep per-thread state (nvmath's
    cuDSS handles fail in a thread other than the one that first used them).
    """

    def __init__(self, count: int, run: Any) -> None:
        self._condition = threading.Condition()
        self._run = run
        self._live = set(range(count))
        self._pending: dict[int, np.ndarray] = {}
        self._results: dict[int, _Evaluation] = {}
        self._stopped: BaseException | None = None

    def evaluate(self, k: int, x: np.ndarray) -> _Evaluation:
        with self._condition:
            if self._stopped is not None:
                return _Evaluation(x, None, None, self._stopped)
            self._pending[k] = x
            self._condition.notify_all()
            self._condition.wait_for(lambda: k in self._results)
            return self._results.pop(k)

    def leave(self, k: int) -> None:
        with self._condition:
            self._live.discard(k)
            self._condition.notify_all()

    def serve(self) -> None:
        """Run batches in this thread until every fit has left.

        An exception of a batch is handed to each fit of that batch. An interrupt (Ctrl-C)
        is handed to every waiting fit and to every later trial point, so that the fit
        threads end, and raised here.
        """
        batch: dict[int, np.ndarray] = {}
        try:
            while True:
                with self._condition:
                    self._condition.wait_for(
                        lambda: (
                            not self._live
                            or (bool(self._pending) and set(self._pending) >= self._live)
                        )
                    )
                    if not self._live:
                        return
                    batch, self._pending = self._pending, {}
                try:
                    results = self._run(batch)
                except Exception as exc:  # every fit of the batch gets the error
                    results = {k: _Evaluation(x, None, None, exc) for k, x in batch.items()}
                with self._condition:
                    self._results.update(results)
                    batch = {}
                    self._condition.notify_all()
        except BaseException as exc:  # Ctrl-C: every fit stops
            with self._condition:
                self._stopped = exc
                for k, x in {**batch, **self._pending}.items():
                    self._results[k] = _Evaluation(x, None, None, exc)
                self._pending = {}
                self._condition.notify_all()
            raise


def fit_indentation_batch(
    problems: Sequence[IndentationProblem],
    depths_m: Sequence[np.ndarray],
    forces_N: Sequence[np.ndarray],
    names: Sequence[str],
    *,
    device: str | None = None,
    options: NewtonOptions | None = None,
    method: str = "lm",
    max_iterations: int = 50,
    ftol: float = 1e-10,
    xtol: float = 1e-10,
    gtol: float = 1e-10,
) -> list[FitResult]:
    """Fit material parameters of K flat-punch problems to K measured curves, batched.

    Each fit minimizes ``0.5 * sum(((F(depth_i; theta) - F_i) / max|F|)**2)`` over its
    problem's parameters ``names`` (starting from its material's values, within the
    material's bounds, scaled by them), with the engine's ``method``; F and its exact
    derivatives come from the batched FE.

    Args:
        problems: Flat-punch problems with elastic materials
            (:func:`warptissue.fem.simulate_indentation_batch` says which); their materials
            hold the start values.
        depths_m: Each problem's depths, positive and increasing, m.
        forces_N: Each problem's measured forces at those depths, N.
        names: Parameters to fit, from each material's ``parameter_names`` (moduli, not
            Ogden exponents), e.g. ``("C10_Pa",)``.
        device: Warp device; None for Warp's default.
        options: The forward runs' Newton settings.
        method, max_iterations, ftol, xtol, gtol: As :func:`warptissue.lsq.least_squares`.

    Returns:
        One :class:`warptissue.lsq.FitResult` per problem, as
        :func:`warptissue.lsq.least_squares` gives it for that fit alone.

    Raises:
        InputError: Lists of different lengths, a name a material cannot fit, or forces that
            do not match the depths.
    """
    problems = list(problems)
    count = len(problems)
    if not (len(depths_m) == len(forces_N) == count) or count == 0:
        raise InputError(
            "one depth and one force sequence per problem",
            key="problems",
            value=(count, len(depths_m), len(forces_N)),
        )
    names = tuple(names)
    depths, forces, starts, bounds, columns = [], [], [], [], []
    for k, problem in enumerate(problems):
        material = problem.material
        unknown = [name for name in names if name not in material.parameter_names]
        if not names or unknown:
            raise InputError(
                f"problem {k}: fit parameters must be some of {material.parameter_names}",
                key="names",
                value=unknown or names,
            )
        path = np.atleast_1d(np.asarray(depths_m[k], dtype=np.float64))
        measured = np.atleast_1d(np.asarray(forces_N[k], dtype=np.float64))
        if measured.shape != path.shape or not np.all(np.isfinite(measured)):
            raise InputError(
                f"problem {k}: one finite force per depth ({path.size})",
                key="forces_N",
                value=measured.shape,
            )
        position = [material.parameter_names.index(name) for name in names]
        lower, upper = material.parameter_bounds
        depths.append(path)
        forces.append(measured)
        columns.append(position)
        starts.append(material.parameter_vector[position])
        bounds.append((lower[position], upper[position]))
    scales = [max(float(np.abs(f).max()), np.finfo(float).tiny) for f in forces]

    # The assembler of the running fits' meshes, built again only when a fit has stopped.
    assemblers: dict[tuple[int, ...], Any] = {}

    def run(batch: dict[int, np.ndarray]) -> dict[int, _Evaluation]:
        order = sorted(batch)
        key = tuple(order)
        if key not in assemblers:
            assemblers.clear()
            assemblers[key] = batch_assembler([problems[k] for k in order], device=device)
        trial = []
        for k in order:
            material = problems[k].material
            vector = material.parameter_vector
            vector[columns[k]] = batch[k]
            trial.append(
                dataclasses.replace(problems[k], material=material.with_parameters(vector))
            )
        results = simulate_indentation_batch(
            trial,
            [depths[k] for k in order],
            options=options,
            sensitivities=names,
            assembler=assemblers[key],
        )
        out = {}
        for k, result in zip(order, results, strict=True):
            if not result.completed:
                out[k] = _Evaluation(batch[k], None, None, RejectStep(result.message))
                continue
            out[k] = _Evaluation(
                batch[k],
                (result.reaction_force_N - forces[k]) / scales[k],
                result.force_sensitivity_N_per_unit / scales[k],
            )
        return out

    forward = _BatchedForward(count, run)
    outcomes: list[FitResult | BaseException | None] = [None] * count

    def fit(k: int) -> None:
        last: list[_Evaluation] = []

        def evaluate(x: np.ndarray) -> _Evaluation:
            if last and np.array_equal(last[0].x, x):
                return last[0]
            evaluation = forward.evaluate(k, np.array(x, dtype=np.float64))
            last[:] = [evaluation]
            if evaluation.error is not None:
                raise evaluation.error
            return evaluation

        try:
            outcomes[k] = least_squares(
                lambda x: evaluate(x).residuals,
                starts[k],
                jac=lambda x: evaluate(x).jacobian,
                bounds=bounds[k],
                method=method,
                x_scale=np.abs(starts[k]) + (starts[k] == 0.0),
                max_iterations=max_iterations,
                ftol=ftol,
                xtol=xtol,
                gtol=gtol,
                parameter_names=names,
                parameter_units=tuple(problems[k].material.parameter_units[i] for i in columns[k]),
            )
        except BaseException as exc:  # reported below, in the caller's thread
            outcomes[k] = exc
        finally:
            forward.leave(k)

    threads = [
        threading.Thread(target=fit, args=(k,), name=f"warptissue-fit-{k}", daemon=True)
        for k in range(count)
    ]
    for thread in threads:
        thread.start()
    forward.serve()
    for thread in threads:
        thread.join()
    for outcome in outcomes:
        if isinstance(outcome, BaseException):
            raise outcome
    return outcomes  # type: ignore[return-value]
