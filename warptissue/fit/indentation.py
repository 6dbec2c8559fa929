"""Inverse-FE characterization: material parameters from indentation records.

:func:`fit_indentation` fits the free material parameters of a study (``[fit] free``) so that
the flat-punch force of the Warp FE (:func:`warptissue.fem.simulate_indentation`) matches the
measured force of every ``[[data]]`` record, jointly. It is the Python API behind
``warptissue fit indentation STUDY.toml``.

Every forward run also gives the exact force sensitivities dF/dtheta (``K du/dtheta =
-dR/dtheta`` at each converged step, docs/fe.md "Sensitivities"), so the least-squares engine
(:func:`warptissue.lsq.least_squares`, Levenberg-Marquardt or Tong et al.'s self-adapting LM)
gets its Jacobian from the same run as its residuals: one forward run per trial point, where
forward differences need 1 + n (FEBio's optimizer).

Notes:
    Model force at a record's samples. The record is conditioned (depth from the contact).
    With an elastic material the force depends on the depth only (hyperelasticity is path
    independent), so one FE run to the deepest point of all records, on ``time_steps``
    equal depth steps, serves every record: the model force of a sample is the FE force
    interpolated linearly in depth (with F = 0 at depth 0). With a viscoelastic material
    (a Prony series) each record is its own time-stepped run on the FE grid of
    :func:`warptissue.loading.resample_history` (time 0 at the contact), and the model force
    is the FE force interpolated linearly in time (with F = 0 at t = 0). The Jacobian is
    interpolated the same way from ``force_sensitivity_N_per_unit``.

    Contact point (``fit.contact_point = "fit"``). Each record's depth offset d0 (its
    recorded depth at first touch) is a parameter beside the material's:
    F_model(d) = F_FE(max(d - d0, 0)). Elastic: the FE runs on a lattice of equal depth
    steps fixed in true depth for the whole fit (``time_steps`` steps to the deepest true
    depth at the start values; a trial that needs deeper adds steps of the same size), so
    the FE force at a lattice depth does not depend on d0 and the model is the linear
    interpolant of the FE curve at ``d - d0``. Its offset column of the Jacobian is exact
    and costs no FE run: dF/dd0 = -(the slope of the interpolant's segment at ``d - d0``),
    zero before the touch. Viscoelastic: the touch time t0 is where the recorded depth
    first reaches d0, and each record's FE run starts there at depth 0 (no steps before the
    touch, where the force is zero; the time steps are
    :func:`warptissue.loading.resample_history` of ``(t - t0, d - d0)``, as from a given
    contact), so t0, the steps and the depths all move with d0; the force is a hereditary
    integral of the depth history, and its offset column is a one-sided difference: one
    more run per record (without sensitivities) at ``d0 - h``, h =
    :data:`warptissue.fit._model.OFFSET_DIFFERENCE_SHARE` of the record's depth span.

    Residuals, stacked over the records: ``F_model - F_measured`` (N, "absolute") or that
    divided by ``max(|F_measured|, floor)`` ("relative", Ahn & Kim Eq. 7), with ``floor`` =
    ``relative_floor_N`` or 1 % of the largest |force| of the records.

    The engine's scaling: "lm" uses Marquardt's diagonal of J^T J (invariant to the units
    of each parameter; a fixed ``x_scale`` would make its initial damping 1e-3 absolute,
    which against forces of millinewtons shrank the first steps a hundredfold), "salm" uses
    ``x_scale`` = |start| (its damping is built from the residual norms).

    Strategies. "joint": every free parameter at once. "two_stage" (Ahn & Kim): stage (i)
    fits the Prony series of each record from its relaxation, the finite ramp accounted for
    (:func:`warptissue.viscoelastic.fitting.fit_qlv`, QLV with an exponential elastic force;
    Ahn & Kim's Table 1), and takes the mean g_i, tau_i over the records; stage (ii) fits the
    remaining free parameters by inverse FE with those Prony terms fixed (their Table 2).

    Plausibility: a record measured with another probe radius than the study's (its sidecar
    ``probe_radius_m``) is refused before fitting; systematic residuals (Durbin-Watson
    statistic below :data:`warptissue.lsq.metrics.DURBIN_WATSON_LIMIT`), a force that rises
    during a hold or does
    not return to zero after unloading, a drift removed by the conditioning, non-identified
    parameters (:attr:`warptissue.lsq.FitResult.identifiability`) and a fit that did not
    converge are warnings of the result.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from warptissue.errors import INTERRUPTED_EXIT_CODE, ConvergenceError, InputError
from warptissue.fit._forward import FitMeeting, run_fits
from warptissue.fit._model import (
    Evaluation,
    ForwardModel,
    SharedRuns,
    depth_offset_names,
    depth_offset_start_m,
    forward_model,
)
from warptissue.fit._report import fitted_study, record_drift_warnings, result_from
from warptissue.fit._setup import FitPlan, ParameterSpace, fit_plan, parameter_space
from warptissue.io import software_versions
from warptissue.lsq.engine import least_squares
from warptissue.lsq.metrics import DURBIN_WATSON_LIMIT, durbin_watson, r_squared, rmse
from warptissue.lsq.result import FitResult, IterationRecord, RejectStep
from warptissue.study import Study

__all__ = [
    "CORRELATION_LIMIT",
    "OFFSET_IDENTIFIED_SHARE",
    "STAGE_ONE",
    "STATUSES",
    "IndentationFit",
    "IndentationFitProgress",
    "RecordCurve",
    "depth_offset_names",
    "depth_offset_start_m",
    "fit_indentation",
]

STATUSES: tuple[str, ...] = (
    "converged",
    "stopped_at_r_squared",
    "max_iterations",
    "interrupted",
    "failed",
    "stage_one_not_converged",
)
"""``IndentationFit.status``: the first two are successes. ``stage_one_not_converged``: the
inverse FE converged but Ahn & Kim's stage (i) did not on a record (the two-stage strategy)."""
STAGE_ONE = "stage (i) (Ahn & Kim)"
"""How messages name the two-stage strategy's first stage (each record's Prony series by
:func:`warptissue.viscoelastic.fitting.fit_qlv`)."""
CORRELATION_LIMIT = 0.995
"""Two parameters whose correlation exceeds this in magnitude are reported: the data
determine a combination of them rather than each."""
OFFSET_IDENTIFIED_SHARE = 0.1
"""A fitted depth offset whose standard error exceeds this share of its record's depth span
is reported as not identified (an offset may well be zero, so not judged by its value)."""


@dataclass(frozen=True)
class IndentationFitProgress:
    """What the fit reports after each trial step of the engine (to ``callback``).

    Attributes:
        stage: ``"joint"`` or ``"stage two"`` (the inverse FE of the two-stage strategy).
        iteration: 1-based trial step of the engine.
        parameters: The current free parameters (name -> value, SI units).
        cost: 0.5 * sum of the squared residuals at the current parameters.
        r_squared: R^2 of all records together at the current parameters, or None.
        forward_solves: FE forward runs so far.
        accepted: Whether this trial step was accepted.
    """

    stage: str
    iteration: int
    parameters: dict[str, float]
    cost: float
    r_squared: float | None
    forward_solves: int
    accepted: bool


@dataclass
class RecordCurve:
    """One ``[[data]]`` record and its fitted force, at its own (conditioned) samples.

    Attributes:
        file: The record's file, as the study names it.
        time_s: Sample times (s), shape (m,).
        depth_m: Depth below the contact (m), shape (m,).
        measured_force_N: Measured force (N), shape (m,).
        fitted_force_N: FE force at the samples with the fitted parameters (N), shape (m,).
        fe_time_s: Times of the FE steps behind this record (s, from the contact; for an
            elastic material, where one FE run in depth serves every record, the times at
            which the record first reaches each FE depth), shape (S,).
        fe_depth_m: Depths of the FE steps (m), shape (S,).
        fe_force_N: FE force at those steps (N), shape (S,).
        r_squared: R^2 of this record's fit (None for constant data).
        rmse_N: Root mean square error of this record's fit (N).
        durbin_watson: Durbin-Watson statistic of this record's residuals (about 2 for
            independent noise, near 0 for a systematic misfit; None for a perfect fit).
        depth_offset_m: The fitted depth offset d0 (m; the recorded depth at first touch,
            so the FE depth is ``depth_m - d0``), or None when the contact was given.
        depth_offset_standard_error_m: Its standard error (m), or None.
    """

    file: str
    time_s: np.ndarray
    depth_m: np.ndarray
    measured_force_N: np.ndarray
    fitted_force_N: np.ndarray
    fe_time_s: np.ndarray
    fe_depth_m: np.ndarray
    fe_force_N: np.ndarray
    r_squared: float | None
    rmse_N: float
    durbin_watson: float | None = None
    depth_offset_m: float | None = None
    depth_offset_standard_error_m: float | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (no sample arrays): file, samples, R^2, RMSE, Durbin-Watson
        (and the fitted depth offset with its standard error, when fitted)."""
        summary = {
            "file": self.file,
            "samples": int(self.time_s.size),
            "r_squared": self.r_squared,
            "rmse_N": self.rmse_N,
            "durbin_watson": self.durbin_watson,
            "peak_force_N": float(np.max(np.abs(self.measured_force_N))),
        }
        if self.depth_offset_m is not None:
            summary["depth_offset_m"] = self.depth_offset_m
            summary["depth_offset_standard_error_m"] = self.depth_offset_standard_error_m
        return summary


@dataclass
class IndentationFit:
    """The outcome of :func:`fit_indentation`.

    Attributes:
        study: The study fitted.
        fitted_study: The study with the fitted material (``dataclasses.replace(study,
            material=...)``); ``warptissue simulate`` runs it as it is once saved
            (:func:`warptissue.study.save_study`).
        result: The engine's :class:`FitResult` of the (last-stage) inverse FE: parameter
            names, units, values, standard errors, correlation, R^2 and RMSE (N) over all
            records, history, iterations, status, identifiability.
        records: One :class:`RecordCurve` per record, in ``[[data]]`` order.
        strategy: ``"joint"`` or ``"two_stage"``.
        stage_one: Ahn & Kim's stage (i) fit of the first record (None for "joint").
        stage_one_fits: Stage (i) fits of every record (Ahn & Kim's Table 1); empty for
            "joint".
        stage_one_prony: The Prony terms stage (ii) used: the mean of ``stage_one_fits``
            (``g1``, ``tau1_s``, ...); empty for "joint".
        forward_solves: FE forward runs made (each with its sensitivities).
        finite_difference_solves: The forward runs the same iterations would have needed
            with forward differences: (Jacobian evaluations * n + residual evaluations) per
            FE run of one evaluation.
        status: One of :data:`STATUSES`.
        message: One line on how the fit ended.
        seconds: Wall time of the fit (s).
        warnings: Identifiability and plausibility warnings (no "warning:" prefix); with the
            two-stage strategy also every stage (i) finding of each record (not converged,
            Prony terms not identified), as ``"stage (i) (Ahn & Kim), FILE: ..."``.
        start: The start values of the free parameters (name -> value).
        start_cost: The cost at the start values (before the first trial step of the
            engine; the history lists the cost after each), or None.
        contact_point: ``"given"`` or ``"fit"`` (each record's depth offset fitted: its
            value in ``parameters`` and in its :class:`RecordCurve`).
    """

    study: Study
    fitted_study: Study
    result: FitResult
    records: tuple[RecordCurve, ...]
    strategy: str
    stage_one: FitResult | None
    forward_solves: int
    finite_difference_solves: int
    status: str
    message: str
    seconds: float
    warnings: list[str] = field(default_factory=list)
    stage_one_fits: tuple[FitResult, ...] = ()
    stage_one_prony: dict[str, float] = field(default_factory=dict)
    start: dict[str, float] = field(default_factory=dict)
    start_cost: float | None = None
    contact_point: str = "given"

    @property
    def success(self) -> bool:
        """True when the fit converged or stopped at the asked R^2."""
        return self.status in ("converged", "stopped_at_r_squared")

    @property
    def exit_code(self) -> int:
        """0 when successful, 130 when interrupted, else ConvergenceError's exit status."""
        if self.success:
            return 0
        if self.status == "interrupted":
            return INTERRUPTED_EXIT_CODE
        return ConvergenceError.exit_code

    @property
    def parameters(self) -> dict[str, float]:
        """The fitted free parameters (name -> value)."""
        return self.result.parameters

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready summary of the fit.

        Returns:
            ``study`` (name and path), ``strategy``, ``contact_point``, ``status``,
            ``success``, ``message``, ``parameters`` (name -> value, unit, standard error,
            start; the depth offsets too, when fitted), ``correlation`` (``names`` and
            ``matrix``, or None), ``r_squared``, ``rmse_N``, ``iterations``,
            ``forward_solves``, ``finite_difference_solves``, ``method``, ``objective``,
            ``warnings``, ``identified``, ``records`` (per record: file, samples, R^2, RMSE,
            Durbin-Watson, and ``depth_offset_m`` with its standard error when fitted),
            ``stage_one`` (None, or per record the Prony fit and the mean
            used), ``fitted_material``, ``history`` (per trial step: x, cost, accepted...),
            ``seconds`` and ``software``.
        """

        result = self.result
        errors = result.standard_errors
        parameters = {
            name: {
                "value": float(result.x[i]),
                "unit": result.parameter_units[i],
                "standard_error": None if errors is None else float(errors[i]),
                "start": self.start.get(name),
            }
            for i, name in enumerate(result.parameter_names)
        }
        stage_one = None
        if self.strategy == "two_stage":
            stage_one = {
                "method": "Ahn & Kim stage (i): QLV Prony series of each record's relaxation, "
                "finite ramp included (warptissue.viscoelastic.fitting.fit_qlv)",
                "records": [
                    {
                        "file": record.file,
                        "parameters": fit.parameters,
                        "standard_errors": None
                        if fit.standard_errors is None
                        else dict(
                            zip(fit.parameter_names, fit.standard_errors.tolist(), strict=True)
                        ),
                        "r_squared": fit.r_squared,
                        "status": fit.status,
                        "warnings": fit.all_warnings,
                    }
                    for record, fit in zip(self.records, self.stage_one_fits, strict=True)
                ],
                "mean": dict(self.stage_one_prony),
            }
        return {
            "study": {
                "name": self.study.name,
                "path": None if self.study.path is None else str(self.study.path),
            },
            "strategy": self.strategy,
            "contact_point": self.contact_point,
            "status": self.status,
            "success": self.success,
            "message": self.message,
            "parameters": parameters,
            "correlation": None
            if result.correlation is None
            else {"names": list(result.parameter_names), "matrix": result.correlation.tolist()},
            "r_squared": result.r_squared,
            "rmse_N": result.rmse,
            "cost": result.cost,
            "start_cost": self.start_cost,
            "iterations": result.iterations,
            "forward_solves": self.forward_solves,
            "finite_difference_solves": self.finite_difference_solves,
            "method": result.method,
            "objective": result.objective,
            "engine_status": result.status,
            "engine_message": result.message,
            "identified": result.identified,
            "warnings": list(self.warnings),
            "records": [record.to_dict() for record in self.records],
            "stage_one": stage_one,
            "fitted_material": dict(self.fitted_study.material.to_dict()),
            "history": [record.to_dict() for record in result.history],
            "seconds": self.seconds,
            "software": software_versions(),
        }


def fit_indentation(
    study: Study | Sequence[Study],
    *,
    device: str | None = None,
    progress: bool = True,
    strategy: str | None = None,
    callback: Callable[[IndentationFitProgress], None] | None = None,
    contact_point: str | None = None,
) -> IndentationFit | list[IndentationFit]:
    """Fit the study's free material parameters to its records by inverse FE.

    Several studies (specimens, sites, rates) are fitted together: each fit runs the
    engine's own Levenberg-Marquardt in a thread, exactly as it would alone, and whenever
    every fit still running has asked for its forward runs, all of them are solved in one
    batched FE run (:func:`warptissue.fem.simulate_indentation_batch`, each run with its own
    Newton decisions), so a GPU does one batch of every fit's runs where it did them one
    after another. Fits whose runs differ in their free parameters, Newton settings, device
    or formulation are solved in separate batches.

    Args:
        study: A study with ``[[data]]`` records and a ``[fit]`` table
            (:func:`warptissue.study.load_study`), or a sequence of them (fitted together,
            without progress bars; ``callback`` is not called).
        device: Warp device (``"cpu"``, ``"cuda"``, ``"cuda:N"``); None: the study's
            ``solver.device`` (``"auto"``: a GPU where present, else the CPU).
        progress: Show a progress bar over the engine's trial steps (cost, R^2) and the FE's
            bars over the load steps inside them.
        strategy: ``"joint"`` or ``"two_stage"`` (Ahn & Kim); None: the study's
            ``fit.strategy`` ("joint" by default).
        callback: Called after each trial step of the engine with an
            :class:`IndentationFitProgress`. It may raise ``KeyboardInterrupt`` to stop.
        contact_point: ``"given"`` (depths as conditioned) or ``"fit"`` (each record's depth
            offset fitted with the material: parameters :func:`depth_offset_names`, in m,
            after the material's; with a viscoelastic material each record's FE run starts
            at its touch, and the two-stage strategy's stage (i) takes the records as
            conditioned); None: the study's ``fit.contact_point``.

    Returns:
        The :class:`IndentationFit` (a list of them, in order, for a sequence of studies).
        Ctrl-C (``KeyboardInterrupt``, also inside an FE run)
        ends the fit with status ``"interrupted"`` and the best parameters evaluated so far
        (their curves, residuals and standard errors). A fit that reaches the iteration
        limit has status ``"max_iterations"``; one whose engine found no acceptable step or
        could not evaluate the Jacobian, ``"failed"`` (both with the best point).

    Raises:
        InputError: The study has no fit or no records, a record was measured with another
            probe radius (its sidecar), an unknown strategy, contact point or free
            parameter. Of several studies, the first study's error is raised after every
            fit has ended.
        ConvergenceError: The FE does not converge at the start values (nothing to fit from).
        KeyboardInterrupt: Ctrl-C before the first forward run finished (nothing to keep).
        DeviceError: The device does not exist.

    Notes:
        Ahn & Kim (2010), the two-stage method and the relative objective (Eq. 7); the
        engine: Levenberg-Marquardt with Marquardt's scaling or Tong et al.'s self-adapting
        LM (:mod:`warptissue.lsq.engine`). See the module docstring for the model force,
        the residuals and the warnings.
    """
    options = {"strategy": strategy, "contact_point": contact_point}
    if isinstance(study, Study):
        return _fit_one(study, device=device, progress=progress, callback=callback, **options)
    studies = list(study)
    if not studies or not all(isinstance(each, Study) for each in studies):
        raise InputError("give a study or a non-empty sequence of studies", key="study")
    outcomes = run_fits(
        len(studies),
        SharedRuns(),
        lambda k, meeting: _fit_one(
            studies[k], device=device, progress=False, meeting=(meeting, k), **options
        ),
    )
    for outcome in outcomes:
        if isinstance(outcome, BaseException):
            raise outcome
    return outcomes


@dataclass
class _EngineRun:
    """How the engine's iteration ended: its result (None when interrupted), the cost at the
    start, the trial steps, and whether Ctrl-C or ``fit.stop_r_squared`` ended it."""

    engine_result: FitResult | None
    start_cost: float | None
    history: list[IterationRecord]
    interrupted: bool
    stopped_at_r_squared: bool


def _fit_one(
    study: Study,
    *,
    device: str | None,
    progress: bool,
    strategy: str | None,
    callback: Callable[[IndentationFitProgress], None] | None = None,
    contact_point: str | None,
    meeting: tuple[FitMeeting, int] | None = None,
) -> IndentationFit:
    """:func:`fit_indentation` of one study (its runs handed to ``meeting``, where given)."""
    started = time.perf_counter()
    plan = fit_plan(study, strategy=strategy, contact_point=contact_point)
    model = forward_model(
        study,
        plan.material,
        plan.free,
        device=device,
        progress=progress,
        offset_start=plan.offset_start,
    )
    model.meeting = meeting
    space = parameter_space(study, plan)
    run = _run_engine(
        model,
        space,
        stage="stage two" if plan.strategy == "two_stage" else "joint",
        progress=progress,
        callback=callback,
    )
    return _outcome(study, plan, space, model, run, started=started)


def _run_engine(
    model: ForwardModel,
    space: ParameterSpace,
    *,
    stage: str,
    progress: bool,
    callback: Callable[[IndentationFitProgress], None] | None,
) -> _EngineRun:
    """The least-squares engine on ``model`` from ``space.x0``, with its progress bar and
    ``callback``; Ctrl-C after the first forward run keeps the best point evaluated."""
    settings = model.study.fit
    names, x0 = space.names, space.x0
    history: list[IterationRecord] = []
    stopped_at_r_squared = False

    from tqdm.auto import tqdm

    bar = tqdm(
        total=settings.max_iterations,
        desc=f"inverse FE ({settings.method})",
        unit="step",
        disable=not progress,
    )

    def on_step(record: IterationRecord) -> bool:
        nonlocal stopped_at_r_squared
        history.append(record)
        current = model.cache.get(np.asarray(record.x, dtype=np.float64).tobytes())
        r2 = None if current is None else model.r_squared_at(current)
        bar.update(1)
        bar.set_postfix(
            cost=f"{record.cost:.4g}",
            R2="n/a" if r2 is None else f"{r2:.5f}",
            solves=model.forward_solves,
            refresh=False,
        )
        if callback is not None:
            callback(
                IndentationFitProgress(
                    stage=stage,
                    iteration=record.iteration,
                    parameters=dict(zip(names, record.x.tolist(), strict=True)),
                    cost=record.cost,
                    r_squared=r2,
                    forward_solves=model.forward_solves,
                    accepted=record.accepted,
                )
            )
        if (
            settings.stop_r_squared is not None
            and record.accepted
            and r2 is not None
            and r2 > settings.stop_r_squared
        ):
            stopped_at_r_squared = True
            return True
        return False

    engine_result = None
    interrupted = False
    start_cost = None
    try:
        try:
            start_cost = model.evaluate(x0).cost
        except RejectStep as exc:
            raise ConvergenceError(
                f"the FE does not converge at the start values "
                f"{dict(zip(names, x0.tolist(), strict=True))}: {exc}; give other start "
                "values in [fit.start]"
            ) from None
        engine_result = least_squares(
            model.fun,
            x0,
            jac=model.jac,
            bounds=(space.lower, space.upper),
            method=settings.method,
            x_scale=None if settings.method == "lm" else space.x_scale,
            max_iterations=settings.max_iterations,
            ftol=settings.ftol,
            xtol=settings.xtol,
            gtol=settings.gtol,
            callback=on_step,
            progress=False,
            parameter_names=names,
            parameter_units=space.units,
        )
    except KeyboardInterrupt:
        interrupted = True
        if model.best is None:
            raise
    finally:
        bar.close()
    return _EngineRun(engine_result, start_cost, history, interrupted, stopped_at_r_squared)


def _outcome(
    study: Study,
    plan: FitPlan,
    space: ParameterSpace,
    model: ForwardModel,
    run: _EngineRun,
    *,
    started: float,
) -> IndentationFit:
    """The :class:`IndentationFit` of a finished engine run: its result at the best point,
    status and message, record curves and warnings; ``started``: its perf_counter start."""
    settings = study.fit
    engine_result, history, names = run.engine_result, run.history, space.names
    free = plan.free
    best = model.best if run.interrupted else model.evaluate(engine_result.x)
    result = result_from(
        engine_result,
        best,
        model,
        names,
        space.units,
        settings.method,
        space.lower,
        space.upper,
        history,
    )
    if space.offset_names:
        scales = np.full(len(names), np.nan)
        scales[len(free) :] = OFFSET_IDENTIFIED_SHARE * space.spans
        result.standard_error_scales = scales
    n = len(names)
    if engine_result is not None:
        finite_difference = (engine_result.njev * n + engine_result.nfev) * (
            model.solves_per_evaluation
        )
    else:
        jacobians = 1 + sum(1 for record in history if record.accepted)
        finite_difference = (jacobians * n + 1 + len(history)) * model.solves_per_evaluation
    if run.interrupted:
        status = "interrupted"
        message = (
            f"interrupted (Ctrl-C) after {len(history)} trial steps: the best parameters "
            f"evaluated so far are kept (cost {best.cost:.6g})"
        )
    elif run.stopped_at_r_squared:
        status = "stopped_at_r_squared"
        message = (
            f"stopped at R^2 = {result.r_squared:.6g} > fit.stop_r_squared = "
            f"{settings.stop_r_squared:g}"
        )
    elif engine_result.status > 0:
        status, message = "converged", engine_result.message
    elif engine_result.status == 0:
        status, message = "max_iterations", engine_result.message
    else:
        status, message = "failed", engine_result.message
    records = _record_curves(model, best)
    if space.offset_names:
        errors = result.standard_errors
        for k, curve in enumerate(records):
            j = len(free) + k
            curve.depth_offset_m = float(result.x[j])
            curve.depth_offset_standard_error_m = None if errors is None else float(errors[j])
    warnings = _warnings(study, result, records, status, message)
    unconverged = []
    for record, stage in zip(study.data, plan.stage_one_fits, strict=False):
        warnings.extend(f"{STAGE_ONE}, {record.file}: {text}" for text in stage.all_warnings)
        if not stage.success:
            unconverged.append(record.file)
    if unconverged and status in ("converged", "stopped_at_r_squared"):
        status = "stage_one_not_converged"
        message = (
            f"{STAGE_ONE} did not converge on {', '.join(unconverged)}: stage (ii) used the "
            "Prony terms it reached"
        )
    result.warnings.extend(warnings)
    fitted_material = model.material_at(best.x)
    return IndentationFit(
        study=study,
        fitted_study=fitted_study(study, fitted_material),
        result=result,
        records=records,
        strategy=plan.strategy,
        stage_one=plan.stage_one_fits[0] if plan.stage_one_fits else None,
        forward_solves=model.forward_solves,
        finite_difference_solves=int(finite_difference),
        status=status,
        message=message,
        seconds=time.perf_counter() - started,
        warnings=result.all_warnings,
        stage_one_fits=plan.stage_one_fits,
        stage_one_prony=plan.prony,
        start=dict(zip(names, space.x0.tolist(), strict=True)),
        start_cost=run.start_cost,
        contact_point=plan.contact_point,
    )


def _record_curves(model: ForwardModel, best: Evaluation) -> tuple[RecordCurve, ...]:
    curves = []
    for k, record in enumerate(model.records):
        measured = model.measured[k]
        fitted = best.predicted[k]
        try:
            r2 = r_squared(measured, fitted)
        except InputError:
            r2 = None
        fe_time, fe_depth, fe_force = best.fe_curves[k]
        curves.append(
            RecordCurve(
                file=record.file,
                time_s=np.asarray(record.time_s, dtype=np.float64),
                depth_m=np.asarray(record.displacement_m, dtype=np.float64),
                measured_force_N=measured,
                fitted_force_N=fitted,
                fe_time_s=fe_time,
                fe_depth_m=fe_depth,
                fe_force_N=fe_force,
                r_squared=r2,
                rmse_N=rmse(measured, fitted),
                durbin_watson=durbin_watson(fitted - measured),
            )
        )
    return tuple(curves)


def _warnings(
    study: Study,
    result: FitResult,
    records: tuple[RecordCurve, ...],
    status: str,
    message: str,
) -> list[str]:
    """Plausibility warnings of a fit (the identifiability ones are the result's own)."""
    messages: list[str] = []
    fitted = any(record.depth_offset_m is not None for record in records)
    hint = "" if fitted else " (fit.contact_point = 'fit' fits it)"
    if status not in ("converged", "stopped_at_r_squared"):
        messages.append(f"the fit did not converge ({status}): {message}")
    correlation = result.correlation
    if correlation is not None:
        names = result.parameter_names
        for i in range(len(names)):
            for j in range(i + 1, len(names)):
                if abs(correlation[i, j]) > CORRELATION_LIMIT:
                    messages.append(
                        f"{names[i]} and {names[j]} are correlated (r = "
                        f"{correlation[i, j]:.4f}): the records determine a combination of "
                        "them, not each; fix one, or add records that separate them (other "
                        "depths, speeds or hold times)"
                    )
    for record, curve in zip(study.data, records, strict=True):
        messages.extend(record_drift_warnings(record))
        if curve.durbin_watson is not None and curve.durbin_watson < DURBIN_WATSON_LIMIT:
            messages.append(
                f"{curve.file}: the residuals are systematic (Durbin-Watson statistic "
                f"{curve.durbin_watson:.3g}, about 2 for noise; R^2 = "
                f"{'n/a' if curve.r_squared is None else f'{curve.r_squared:.4g}'}): check "
                f"the probe radius, the contact point{hint}, a drifting force offset, or "
                "the material model"
            )
    return messages
