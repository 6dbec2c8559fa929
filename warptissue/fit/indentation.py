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
    statistic below :data:`DURBIN_WATSON_LIMIT`), a force that rises during a hold or does
    not return to zero after unloading, a drift removed by the conditioning, non-identified
    parameters (:attr:`warptissue.lsq.FitResult.identifiability`) and a fit that did not
    converge are warnings of the result.
"""

from __future__ import annotations

import dataclasses
import math
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
    offset_box,
    shifted_record,
)
from warptissue.fit.start import start_values_from_record
from warptissue.io import read_sidecar, software_versions
from warptissue.lsq.engine import covariance_from_jacobian, least_squares
from warptissue.lsq.metrics import r_squared, rmse
from warptissue.lsq.result import FitResult, IterationRecord, RejectStep
from warptissue.materials import Viscoelastic, positive_bounds, prony_term
from warptissue.study import (
    CONTACT_POINTS,
    FIT_STRATEGIES,
    DataRecord,
    Protocol,
    Study,
)
from warptissue.viscoelastic.fitting import fit_qlv

__all__ = [
    "CORRELATION_LIMIT",
    "DURBIN_WATSON_LIMIT",
    "OFFSET_IDENTIFIED_SHARE",
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
)
"""``IndentationFit.status``: the first two are successes."""
DURBIN_WATSON_LIMIT = 0.5
"""A record whose residuals have a Durbin-Watson statistic below this is fitted
systematically badly (independent noise gives about 2)."""
DRIFT_SHARE = 0.02
"""A force change of more than this share of the record's peak force where none is expected
(rising in a hold, left after unloading, a baseline drift) is reported."""
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
        warnings: Identifiability and plausibility warnings (no "warning:" prefix).
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


def _durbin_watson(residuals: np.ndarray) -> float | None:
    """sum(diff(r)^2) / sum(r^2): about 2 for independent residuals, near 0 for a trend."""
    total = float(residuals @ residuals)
    if residuals.size < 3 or total == 0.0:
        return None
    return float(np.sum(np.diff(residuals) ** 2) / total)


def _record_drift_warnings(record: DataRecord) -> list[str]:
    """A force that rises in a hold, stays after unloading, or a baseline drift removed."""
    t, d, f = record.time_s, record.displacement_m, record.force_N
    peak = float(np.max(np.abs(f))) if f.size else 0.0
    if peak == 0.0 or f.size < 10:
        return []
    messages = []
    name = record.file
    drift = record.conditioning.get("force_drift_N_per_s")
    if drift:
        change = abs(float(drift)) * float(t[-1] - t[0])
        if change > DRIFT_SHARE * peak:
            messages.append(
                f"{name}: the conditioning removed a force baseline drift of {float(drift):.4g} "
                f"N/s ({100 * change / peak:.0f} % of the peak force over the record): a "
                "drifting transducer offset; check the record's zero"
            )
    deepest = int(np.argmax(d))
    span = float(d[deepest])
    if span > 0.0:
        hold = np.flatnonzero(np.abs(d - span) <= 0.005 * span)
        hold = hold[hold >= deepest]
        breaks = np.flatnonzero(np.diff(hold) > 1)
        contiguous = hold[: int(breaks[0]) + 1] if breaks.size else hold  # the first hold
        if contiguous.size >= 10:
            # Running means over a tenth of the hold: the last one against the lowest, beyond
            # both DRIFT_SHARE of the peak and 4 noise levels of such a mean.
            forces = f[contiguous]
            window = max(3, contiguous.size // 10)
            means = np.convolve(forces, np.full(window, 1.0 / window), mode="valid")
            rise = float(means[-1] - np.min(means))
            noise = 1.4826 * float(np.median(np.abs(np.diff(forces)))) / math.sqrt(2.0)
            if rise > max(DRIFT_SHARE * peak, 4.0 * noise / math.sqrt(window)):
                messages.append(
                    f"{name}: the force rises by {rise:.4g} N ({100 * rise / peak:.0f} % of "
                    "its peak) during the hold at the deepest point, where a tissue relaxes: "
                    "a drifting offset or a moving specimen"
                )
        after = np.flatnonzero((np.arange(d.size) > deepest) & (d <= 0.005 * span))
        if after.size >= 5:
            left = float(np.mean(f[after]))
            if abs(left) > DRIFT_SHARE * peak:
                messages.append(
                    f"{name}: the force is {left:.4g} N ({100 * abs(left) / peak:.0f} % of its "
                    "peak) after unloading, where it should return to zero: a drifting "
                    "offset or a probe that lost contact late"
                )
    return messages


def _check_probe_radius(study: Study) -> None:
    """Refuse a record whose sidecar names another probe radius than the study's."""

    radius = study.indenter.radius_m
    for record in study.data:
        sidecar = read_sidecar(record.path)
        value = sidecar.get("probe_radius_m")
        if value is None:
            continue
        try:
            measured = float(value)
        except (TypeError, ValueError):
            raise InputError(
                f"{record.file}: the sidecar's probe_radius_m is not a number",
                path=record.path,
                key="probe_radius_m",
                value=value,
            ) from None
        if not math.isclose(measured, radius, rel_tol=1e-3):
            raise InputError(
                f"{record.file} was measured with probe_radius_m = {measured:g} m (its "
                f"sidecar), the study's indenter has radius_m = {radius:g} m: fit it with a "
                "study of that probe",
                path=record.path,
                key="probe_radius_m",
                value=measured,
            )


def _x_scale(start: np.ndarray, units: Sequence[str]) -> np.ndarray:
    """|start|, or for a zero start the mean |start| of the parameters of its unit (else 1)."""
    scale = np.abs(start).astype(np.float64)
    for j in np.flatnonzero(scale == 0.0):
        same = [abs(start[k]) for k in range(start.size) if units[k] == units[j] and start[k]]
        scale[j] = float(np.mean(same)) if same else 1.0
    return scale


def _stage_one(study: Study, material: Any, strategy: str) -> tuple[tuple[FitResult, ...], dict]:
    """Ahn & Kim's stage (i): fit_qlv on every record; the mean Prony terms."""

    kinds = [term[0] for term in map(prony_term, material.parameter_names) if term is not None]
    terms = kinds.count("g")
    if terms == 0:
        raise InputError(
            "strategy two_stage fits a Prony series first: the material has none (add g1, "
            "tau1_s, ... to [material])",
            path=study.path,
            key="fit.strategy",
            value=strategy,
        )
    fits = []
    for record in study.data:
        try:
            fits.append(fit_qlv(record.time_s, record.displacement_m, record.force_N, terms=terms))
        except InputError as exc:
            raise InputError(
                f"{record.file}: stage (i) (Ahn & Kim): {exc.message}",
                path=record.path,
                value=exc.value,
            ) from None
    mean = {}
    for i in range(1, terms + 1):
        for name in (f"g{i}", f"tau{i}_s"):
            mean[name] = float(np.mean([fit.parameters[name] for fit in fits]))
    return tuple(fits), mean


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
    if study.fit is None or not study.data:
        raise InputError(
            "the study holds no fit: add [[data]] records and a [fit] table (schema_version 2)",
            path=study.path,
        )
    settings = study.fit
    chosen_strategy = strategy if strategy is not None else settings.strategy
    if chosen_strategy not in FIT_STRATEGIES:
        raise InputError(
            f"strategy must be one of {', '.join(FIT_STRATEGIES)}",
            path=study.path,
            key="fit.strategy",
            value=chosen_strategy,
        )
    chosen_contact = contact_point if contact_point is not None else settings.contact_point
    if chosen_contact not in CONTACT_POINTS:
        raise InputError(
            f"contact_point must be one of {', '.join(CONTACT_POINTS)}",
            path=study.path,
            key="fit.contact_point",
            value=chosen_contact,
        )
    fit_offsets = chosen_contact == "fit"
    _check_probe_radius(study)
    offset_start: np.ndarray | None = None
    offset_lower = offset_upper = np.zeros(0)
    if fit_offsets:
        offset_start, offset_lower, offset_upper = offset_box(study)
        start = start_values_from_record(
            study, shifted_record(study.data[0], float(offset_start[0]))
        )
    else:
        start = start_values_from_record(study)
    material = study.material
    free = tuple(settings.free)
    all_lower, all_upper = settings.parameter_bounds(material)
    stage_one_fits: tuple[FitResult, ...] = ()
    prony: dict[str, float] = {}
    if chosen_strategy == "two_stage":
        stage_one_fits, prony = _stage_one(study, material, chosen_strategy)
        vector = material.parameter_vector.copy()
        names = list(material.parameter_names)
        for name, value in prony.items():
            vector[names.index(name)] = value
        try:
            material = material.with_parameters(vector)
        except InputError as exc:
            raise InputError(
                f"stage (i) (Ahn & Kim) gave an invalid Prony series: {exc.message}",
                path=study.path,
                value=prony,
            ) from None
        keep = [j for j, name in enumerate(free) if prony_term(name) is None]
        if not keep:
            raise InputError(
                "strategy two_stage fits the Prony terms in stage (i) and the other free "
                "parameters by inverse FE in stage (ii): free an elastic parameter too",
                path=study.path,
                key="fit.free",
                value=list(free),
            )
        free = tuple(free[j] for j in keep)
        all_lower, all_upper = all_lower[keep], all_upper[keep]

    model = forward_model(
        study, material, free, device=device, progress=progress, offset_start=offset_start
    )
    model.meeting = meeting
    offset_names = depth_offset_names(study.data) if fit_offsets else ()
    names = free + offset_names
    units = tuple(material.parameter_units[material.parameter_names.index(n)] for n in free)
    units += ("m",) * len(offset_names)
    x0 = np.array([start[name] for name in free], dtype=np.float64)
    lower, upper = positive_bounds(free, all_lower, all_upper)
    x0 = np.clip(x0, lower, upper)
    spans = np.array([float(np.ptp(record.displacement_m)) for record in study.data])
    if offset_start is not None:
        x0 = np.concatenate([x0, offset_start])
        lower = np.concatenate([lower, offset_lower])
        upper = np.concatenate([upper, offset_upper])
    x_scale = _x_scale(x0, units)
    if offset_names:
        x_scale[len(free) :] = spans  # an offset may start at 0: its record's depth span
    stage = "stage two" if chosen_strategy == "two_stage" else "joint"
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
            bounds=(lower, upper),
            method=settings.method,
            x_scale=None if settings.method == "lm" else x_scale,
            max_iterations=settings.max_iterations,
            ftol=settings.ftol,
            xtol=settings.xtol,
            gtol=settings.gtol,
            callback=on_step,
            progress=False,
            parameter_names=names,
            parameter_units=units,
        )
    except KeyboardInterrupt:
        interrupted = True
        if model.best is None:
            raise
    finally:
        bar.close()

    best = model.best if interrupted else model.evaluate(engine_result.x)
    result = _result_from(
        engine_result, best, model, names, units, settings.method, lower, upper, history
    )
    if offset_names:
        scales = np.full(len(names), np.nan)
        scales[len(free) :] = OFFSET_IDENTIFIED_SHARE * spans
        result.standard_error_scales = scales
    n = len(names)
    if engine_result is not None:
        finite_difference = (engine_result.njev * n + engine_result.nfev) * (
            model.solves_per_evaluation
        )
    else:
        jacobians = 1 + sum(1 for record in history if record.accepted)
        finite_difference = (jacobians * n + 1 + len(history)) * model.solves_per_evaluation
    if interrupted:
        status = "interrupted"
        message = (
            f"interrupted (Ctrl-C) after {len(history)} trial steps: the best parameters "
            f"evaluated so far are kept (cost {best.cost:.6g})"
        )
    elif stopped_at_r_squared:
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
    if offset_names:
        errors = result.standard_errors
        for k, curve in enumerate(records):
            j = len(free) + k
            curve.depth_offset_m = float(result.x[j])
            curve.depth_offset_standard_error_m = None if errors is None else float(errors[j])
    warnings = _warnings(study, result, records, status, message)
    result.warnings.extend(warnings)
    fitted_material = model.material_at(best.x)
    return IndentationFit(
        study=study,
        fitted_study=_fitted_study(study, fitted_material),
        result=result,
        records=records,
        strategy=chosen_strategy,
        stage_one=stage_one_fits[0] if stage_one_fits else None,
        forward_solves=model.forward_solves,
        finite_difference_solves=int(finite_difference),
        status=status,
        message=message,
        seconds=time.perf_counter() - started,
        warnings=result.all_warnings,
        stage_one_fits=stage_one_fits,
        stage_one_prony=prony,
        start=dict(zip(names, x0.tolist(), strict=True)),
        start_cost=start_cost,
        contact_point=chosen_contact,
    )


def _result_from(
    engine_result: FitResult | None,
    best: Evaluation,
    model: ForwardModel,
    names: tuple[str, ...],
    units: tuple[str, ...],
    method: str,
    lower: np.ndarray,
    upper: np.ndarray,
    history: list[IterationRecord],
) -> FitResult:
    """The engine's result with the data statistics (R^2, RMSE in N, fitted force); for an
    interrupted fit, a result built from the best evaluation."""
    measured = np.concatenate(model.measured)
    fitted = np.concatenate(best.predicted)
    if engine_result is None:
        covariance, errors, correlation = covariance_from_jacobian(best.jacobian, best.cost)
        result = FitResult(
            x=best.x.copy(),
            parameter_names=names,
            parameter_units=units,
            cost=best.cost,
            residuals=best.residuals,
            jacobian=best.jacobian,
            success=False,
            status=-1,
            message="Interrupted (Ctrl-C): the best point evaluated so far.",
            iterations=len(history),
            nfev=model.evaluations,
            njev=1 + sum(1 for record in history if record.accepted),
            covariance=covariance,
            standard_errors=errors,
            correlation=correlation,
            r_squared=None,
            rmse=0.0,
            history=list(history),
            method=method,
            lower_bounds=lower,
            upper_bounds=upper,
        )
    else:
        result = engine_result
    result.fitted = fitted
    result.objective = model.study.fit.objective
    result.rmse = rmse(measured, fitted)
    try:
        result.r_squared = r_squared(measured, fitted)
    except InputError:
        result.r_squared = None
    return result


def _fitted_study(study: Study, material: Any) -> Study:
    """The study with the fitted material; a viscoelastic one whose study has a quasi-static
    protocol replays the first record's history instead (``warptissue simulate`` needs time
    steps for it)."""

    fitted = dataclasses.replace(study, material=material)
    if isinstance(material, Viscoelastic) and not study.protocol.timed:
        steps = study.fit.time_steps if study.fit is not None else 40
        protocol = Protocol.from_record(study.data[0], steps=steps)
        fitted = dataclasses.replace(fitted, protocol=protocol)
    return fitted


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
                durbin_watson=_durbin_watson(fitted - measured),
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
        messages.extend(_record_drift_warnings(record))
        if curve.durbin_watson is not None and curve.durbin_watson < DURBIN_WATSON_LIMIT:
            messages.append(
                f"{curve.file}: the residuals are systematic (Durbin-Watson statistic "
                f"{curve.durbin_watson:.3g}, about 2 for noise; R^2 = "
                f"{'n/a' if curve.r_squared is None else f'{curve.r_squared:.4g}'}): check "
                f"the probe radius, the contact point{hint}, a drifting force offset, or "
                "the material model"
            )
    return messages
