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
    :data:`OFFSET_DIFFERENCE_SHARE` of the record's depth span.

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

from warptissue import fem
from warptissue.device import resolve_device
from warptissue.errors import INTERRUPTED_EXIT_CODE, ConvergenceError, InputError
from warptissue.fit._forward import FitMeeting, run_fits
from warptissue.fit.start import start_values_from_record
from warptissue.io import read_sidecar, software_versions
from warptissue.loading import resample_history
from warptissue.lsq.engine import RELATIVE_FLOOR_SHARE, covariance_from_jacobian, least_squares
from warptissue.lsq.metrics import r_squared, rmse
from warptissue.lsq.result import FitResult, IterationRecord, RejectStep
from warptissue.materials import Viscoelastic, positive_bounds, prony_term
from warptissue.simulate import build_mesh, build_problem, check_linear_solver, estimate_mesh
from warptissue.study import (
    CONTACT_POINTS,
    DEPTH_OFFSET,
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
OFFSET_BOUND_SHARES = (0.5, 0.1)
"""Default bounds of a record's depth offset: from its shallowest recorded depth less this
first share of its depth span, to its deepest less the second share (the probe touches
before its deepest point)."""
OFFSET_DIFFERENCE_SHARE = 1e-4
"""The step of the one-sided difference of a viscoelastic record's force by its depth offset,
as a share of the record's depth span."""
OFFSET_NOISE_SIGMA = 6.0
"""The start of a depth offset without a contact point: where the force first exceeds this
many noise standard deviations (and 1 % of the peak force)."""
_CACHE_SIZE = 8


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


@dataclass
class _Evaluation:
    """One forward evaluation: residuals, Jacobian and the curves behind them."""

    x: np.ndarray
    residuals: np.ndarray
    jacobian: np.ndarray
    predicted: list[np.ndarray]
    fe_curves: list[tuple[np.ndarray, np.ndarray, np.ndarray]]

    @property
    def cost(self) -> float:
        return 0.5 * float(self.residuals @ self.residuals)


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


class _ForwardModel:
    """The FE force of every record as a function of the free parameters, with a cache.

    One evaluation runs the FE (once for an elastic material, once per record for a
    viscoelastic one) with the sensitivities of the free parameters, and gives the
    residuals and the Jacobian together: ``fun`` and ``jac`` at one point share one run.

    With ``offset_start`` (one depth offset per record, m) the parameter
    vector is the free material parameters followed by the records' depth offsets, and the
    FE depths are a lattice of steps fixed by the start (module docstring, "Contact point").
    """

    def __init__(
        self,
        *,
        study: Study,
        problem: Any,
        assembler: Any,
        material: Any,
        names: tuple[str, ...],
        device: Any,
        progress: bool,
        offset_start: np.ndarray | None = None,
        batch_records: bool = False,
    ) -> None:
        settings = study.fit
        self.batch_records = batch_records
        self._packed_assembler: Any = None
        self.meeting: tuple[FitMeeting, int] | None = None
        self.study = study
        self.problem = problem
        self.assembler = assembler
        self.material = material
        self.names = names
        self.device = device
        self.progress = progress
        self.options = study.solver.options
        self.all_names = tuple(material.parameter_names)
        missing = [name for name in names if name not in self.all_names]
        if missing:
            raise InputError(
                f"fit.free names {missing[0]!r}, not a parameter of the material "
                f"({', '.join(self.all_names)})",
                path=study.path,
                key="fit.free",
                value=missing[0],
            )
        self.index = [self.all_names.index(name) for name in names]

        self.viscoelastic = isinstance(material, Viscoelastic)
        self.records = study.data
        steps = settings.time_steps
        self.measured = [np.asarray(r.force_N, dtype=np.float64) for r in self.records]
        everything = np.concatenate(self.measured)
        largest = float(np.max(np.abs(everything)))
        if settings.objective == "relative":
            floor = settings.relative_floor_N or RELATIVE_FLOOR_SHARE * largest
            self.divisors = [np.maximum(np.abs(f), floor) for f in self.measured]
        else:
            self.divisors = [np.ones_like(f) for f in self.measured]
        self.contact_s = [r.contact_time_s for r in self.records]
        self.offset_count = 0 if offset_start is None else len(self.records)
        self.depth_step_m = 0.0
        self.steps = steps
        self.offset_differences = [
            OFFSET_DIFFERENCE_SHARE * max(float(np.ptp(r.displacement_m)), 1e-12)
            for r in self.records
        ]
        if self.viscoelastic and self.offset_count:
            offsets = np.asarray(offset_start, dtype=np.float64)
            try:
                self.grids = [self._touch(k, offsets[k])[1] for k in range(len(self.records))]
            except RejectStep as exc:
                raise InputError(
                    f"the start of the depth offsets {offsets.tolist()} m: {exc}; give "
                    "fit.start.depth_offset_m below the deepest recorded depth",
                    path=study.path,
                    key=f"fit.start.{DEPTH_OFFSET}",
                ) from None
        elif self.viscoelastic:
            self.grids = [record.load_history(steps=steps) for record in self.records]
        elif self.offset_count:
            reach = self._reach(np.asarray(offset_start, dtype=np.float64))
            if not reach > 0.0:
                raise InputError(
                    f"the start of the depth offsets {np.asarray(offset_start).tolist()} m "
                    "leaves no record in contact: give fit.start.depth_offset_m below the "
                    "deepest recorded depth",
                    path=study.path,
                    key=f"fit.start.{DEPTH_OFFSET}",
                )
            self.depth_step_m = reach / steps
            self.grids = [(None, self._lattice(np.asarray(offset_start, dtype=np.float64)))]
        else:
            deepest = max(float(np.max(r.displacement_m)) for r in self.records)
            self.grids = [(None, deepest * np.arange(1, steps + 1) / steps)]
        self.forward_solves = 0
        self.solves_per_evaluation = len(self.grids)
        self.cache: dict[bytes, _Evaluation] = {}
        self.best: _Evaluation | None = None
        self.evaluations = 0

    def material_at(self, x: np.ndarray) -> Any:
        vector = self.material.parameter_vector.copy()
        vector[self.index] = np.asarray(x)[: len(self.names)]
        return self.material.with_parameters(vector)

    def offsets_at(self, x: np.ndarray) -> np.ndarray:
        """The records' depth offsets (m) in ``x``: zeros when the contact is given."""
        if not self.offset_count:
            return np.zeros(len(self.records))
        return np.asarray(x, dtype=np.float64)[len(self.names) :]

    def _touch(self, k: int, offset: float) -> tuple[float, tuple[np.ndarray, np.ndarray]]:
        """Record ``k``'s touch time at a depth offset and its FE time steps from it.

        The touch time t0 is where the record's recorded depth (its running maximum) first
        passes ``offset`` (linear between samples; the first sample's time for a record
        deeper than that from its start); the steps are
        :func:`warptissue.loading.resample_history` of ``(time - t0, depth - offset)``, as
        :meth:`DataRecord.load_history` does from a given contact.

        Returns:
            ``(t0, (times_s, depths_m))``: t0 on the record's clock (s); the FE times from
            t0 (s) and true depths (m).

        Raises:
            RejectStep: The record never reaches the offset, or fewer than two samples
                follow the touch.
        """
        record = self.records[k]
        t = np.asarray(record.time_s, dtype=np.float64)
        recorded = np.asarray(record.displacement_m, dtype=np.float64)
        reached = np.maximum.accumulate(recorded)
        # The first sample beyond the offset; the touch lies after the one before it (the
        # last at or above the offset's level: a conditioned record's clipped zeros end at
        # its contact).
        i = int(np.searchsorted(reached, offset, side="right"))
        if i >= reached.size:
            raise RejectStep(
                f"{record.file} never reaches the depth offset {offset:.6g} m (its deepest "
                f"recorded depth is {reached[-1]:.6g} m)"
            )
        if i == 0:
            touch = float(t[0])
        else:
            share = (offset - reached[i - 1]) / (reached[i] - reached[i - 1])
            touch = float(t[i - 1] + share * (t[i] - t[i - 1]))

        try:
            grid = resample_history(t - touch, recorded - offset, steps=self.steps)
        except InputError as exc:
            raise RejectStep(f"{record.file}: {exc.message}") from exc
        return touch, grid

    def _reach(self, offsets: np.ndarray) -> float:
        """The deepest true depth of the records at these offsets (m)."""
        return max(
            float(np.max(r.displacement_m)) - d0
            for r, d0 in zip(self.records, offsets, strict=True)
        )

    def _lattice(self, offsets: np.ndarray) -> np.ndarray:
        """FE depths: the fixed steps of ``depth_step_m`` to the deepest true depth."""
        count = max(1, math.ceil(self._reach(offsets) / self.depth_step_m - 1e-9))
        return self.depth_step_m * np.arange(1, count + 1)

    def _run(
        self,
        material: Any,
        times: np.ndarray | None,
        depths: np.ndarray,
        *,
        sensitivities: bool = True,
    ) -> Any:
        problem = dataclasses.replace(self.problem, material=material)
        extra = {} if times is None else {"times_s": times}
        self.forward_solves += 1
        try:
            result = _simulate()(
                problem,
                depths,
                device=self.device,
                progress=self.progress,
                options=self.options,
                assembler=self.assembler,
                sensitivities=self.names if sensitivities else (),
                **extra,
            )
        except ConvergenceError as exc:
            raise RejectStep(f"the FE failed: {exc}") from exc
        if not result.completed:
            raise RejectStep(f"the FE did not converge: {result.message}")
        return result

    def _runs(
        self,
        material: Any,
        grids: Sequence[tuple[np.ndarray | None, np.ndarray]],
        *,
        sensitivities: bool = True,
    ) -> list[Any]:
        """The FE runs of several load paths (``(times, depths)`` each) of one material: in
        one batched run (:func:`warptissue.fem.simulate_indentation_batch`) where
        ``batch_records`` and there are several, else one after another. A fit of several
        studies hands them to its :class:`~warptissue.fit._forward.FitMeeting`, which
        solves them with the other fits' runs."""
        if self.meeting is not None:
            meeting, fit = self.meeting
            self.forward_solves += len(grids)
            results = meeting.request(
                fit,
                _RunRequest(
                    problems=[dataclasses.replace(self.problem, material=material)] * len(grids),
                    grids=list(grids),
                    names=self.names if sensitivities else (),
                    options=self.options,
                    device=self.device,
                ),
            )
            for result in results:
                if not result.completed:
                    raise RejectStep(f"the FE did not converge: {result.message}")
            return results
        if not (self.batch_records and len(grids) > 1):
            return [
                self._run(material, times, depths, sensitivities=sensitivities)
                for times, depths in grids
            ]

        problems = [dataclasses.replace(self.problem, material=material)] * len(grids)
        if self._packed_assembler is None or self._packed_assembler.problem_count != len(grids):
            self._packed_assembler = fem.batch_assembler(problems, device=self.device)
        self.forward_solves += len(grids)
        results = fem.simulate_indentation_batch(
            problems,
            [depths for _, depths in grids],
            options=self.options,
            sensitivities=self.names if sensitivities else (),
            assembler=self._packed_assembler,
            times_s=[times for times, _ in grids],
        )
        for result in results:
            if not result.completed:
                raise RejectStep(f"the FE did not converge: {result.message}")
        return results

    def evaluate(self, x: np.ndarray) -> _Evaluation:
        key = np.asarray(x, dtype=np.float64).tobytes()
        if key in self.cache:  # least recently used out: the current point stays
            self.cache[key] = self.cache.pop(key)
            return self.cache[key]
        try:
            material = self.material_at(x)
        except InputError as exc:
            raise RejectStep(str(exc)) from exc
        if float(material.initial_shear_modulus_Pa) <= 0.0:
            raise RejectStep("the initial shear modulus is not positive")
        offsets = self.offsets_at(x)
        touches = list(self.contact_s)
        if self.viscoelastic and self.offset_count:
            timed = [self._touch(k, offsets[k]) for k in range(len(self.records))]
            touches = [touch for touch, _ in timed]
            grids = [grid for _, grid in timed]
        elif self.offset_count:
            grids = [(None, self._lattice(offsets))]
        else:
            grids = self.grids
        runs = self._runs(material, grids)
        earlier = None
        if self.viscoelastic and self.offset_count:
            earlier = self._earlier_touches(material, offsets)
        predicted, jacobians, curves = [], [], []
        for k, record in enumerate(self.records):
            if self.viscoelastic:
                run = runs[k]
                fe_time = np.asarray(grids[k][0], dtype=np.float64)
                fe_depth = np.asarray(run.depths_m, dtype=np.float64)
                where = np.concatenate([[0.0], fe_time])
                at = record.time_s - touches[k]
            else:
                run = runs[0]
                fe_depth = np.asarray(run.depths_m, dtype=np.float64)
                where = np.concatenate([[0.0], fe_depth])
                shifted = record.displacement_m - offsets[k]
                at = np.clip(shifted, 0.0, None)
                fe_time = _first_passage_times(record.time_s, shifted, self.contact_s[k], fe_depth)
            force = np.asarray(run.reaction_force_N, dtype=np.float64)
            sensitivity = np.asarray(run.force_sensitivity_N_per_unit, dtype=np.float64)
            curve = np.concatenate([[0.0], force])
            predicted.append(np.interp(at, where, curve))
            columns = [
                np.interp(at, where, np.concatenate([[0.0], sensitivity[:, j]]))
                for j in range(len(self.names))
            ]
            for i in range(self.offset_count):
                if i != k:
                    columns.append(np.zeros(at.size))
                elif self.viscoelastic:
                    columns.append((predicted[k] - earlier[k]) / self.offset_differences[k])
                else:
                    columns.append(_offset_column(shifted, where, curve))
            jacobians.append(np.column_stack(columns))
            if self.viscoelastic:
                curves.append((fe_time, fe_depth, force))
            else:
                # The FE steps up to the first one at or beyond the record's deepest point.
                covered = int(np.searchsorted(fe_depth, float(np.max(at))))
                keep = slice(0, covered + 1)
                curves.append((fe_time[keep], fe_depth[keep], force[keep]))
        residuals = np.concatenate(
            [(p - f) / w for p, f, w in zip(predicted, self.measured, self.divisors, strict=True)]
        )
        jacobian = np.vstack(
            [j / w[:, None] for j, w in zip(jacobians, self.divisors, strict=True)]
        )
        evaluation = _Evaluation(
            np.array(x, dtype=np.float64), residuals, jacobian, predicted, curves
        )
        self.evaluations += 1
        if len(self.cache) >= _CACHE_SIZE:
            self.cache.pop(next(iter(self.cache)))
        self.cache[key] = evaluation
        if self.best is None or evaluation.cost < self.best.cost:
            self.best = evaluation
        return evaluation

    def _earlier_touches(self, material: Any, offsets: np.ndarray) -> list[np.ndarray]:
        """Each record's force at its samples with the probe touching earlier, for dF/dd0 of
        a viscoelastic material by a one-sided difference.

        The touch time, the FE time steps and the depths all move with the offset, and the
        force is a hereditary integral of the depth history, not a function of the depth:
        one more FE run per record (without sensitivities, all records batched where the
        forward runs are) at ``offset - h`` (the probe touching earlier, so the record stays
        in contact), h = :data:`OFFSET_DIFFERENCE_SHARE` of the record's depth span, gives
        (F(d0) - F(d0 - h)) / h at the samples.
        """
        timed = [
            self._touch(k, offsets[k] - self.offset_differences[k])
            for k in range(len(self.records))
        ]
        runs = self._runs(material, [grid for _, grid in timed], sensitivities=False)
        forces = []
        for record, (touch, (times, _)), run in zip(self.records, timed, runs, strict=True):
            where = np.concatenate([[0.0], np.asarray(times, dtype=np.float64)])
            curve = np.concatenate([[0.0], np.asarray(run.reaction_force_N, dtype=np.float64)])
            forces.append(np.interp(record.time_s - touch, where, curve))
        return forces

    def fun(self, x: np.ndarray) -> np.ndarray:
        return self.evaluate(x).residuals

    def jac(self, x: np.ndarray) -> np.ndarray:
        return self.evaluate(x).jacobian

    def r_squared_at(self, evaluation: _Evaluation) -> float | None:
        try:
            return r_squared(np.concatenate(self.measured), np.concatenate(evaluation.predicted))
        except InputError:
            return None


def _offset_column(shifted: np.ndarray, where: np.ndarray, curve: np.ndarray) -> np.ndarray:
    """d F_model / d d0 at the samples: minus the slope of the interpolant's segment at the
    true depth ``shifted`` = d - d0 (m, shape (m,)); zero before the touch and beyond the
    last FE depth, where the interpolant is flat. ``where``, ``curve``: the FE depths and
    forces with (0, 0) first."""
    slopes = np.diff(curve) / np.diff(where)
    segment = np.clip(np.searchsorted(where, shifted, side="right") - 1, 0, slopes.size - 1)
    inside = (shifted > 0.0) & (shifted < where[-1])
    return np.where(inside, -slopes[segment], 0.0)


def _first_passage_times(
    time_s: np.ndarray, depth_m: np.ndarray, contact_s: float, depths: np.ndarray
) -> np.ndarray:
    """The times (from the contact) at which a record of depth ``depth_m`` (below the
    contact, m) first reaches each depth (its loading ramp); depths beyond its deepest point
    get its deepest point's time."""
    t = time_s - contact_s
    d = np.maximum.accumulate(np.clip(depth_m, 0.0, None))
    rising = np.concatenate([[True], np.diff(d) > 0.0])
    return np.interp(depths, d[rising], t[rising])


def _simulate() -> Callable[..., Any]:
    return fem.simulate_indentation


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


def _forward_model(
    study: Study,
    material: Any,
    free: tuple[str, ...],
    *,
    device: str | None,
    progress: bool,
    offset_start: np.ndarray | None = None,
    batch_records: bool | None = None,
) -> _ForwardModel:
    """The mesh, problem and assembler of a study (built once), as a :class:`_ForwardModel`
    of the free parameters (and of the records' depth offsets, with ``offset_start``);
    ``batch_records`` (None: :func:`batches_records`) solves the records' runs together."""

    chosen = device if device is not None else study.solver.device
    warp_device = resolve_device(None if chosen == "auto" else chosen)
    check_linear_solver(study, warp_device)
    estimate_mesh(study).require_fits(solve=warp_device.is_cpu, what="study's mesh")
    mesh = build_mesh(study)
    problem = build_problem(dataclasses.replace(study, material=material), mesh)
    assembler = fem.Assembler(mesh, material, formulation=problem.formulation, device=warp_device)
    return _ForwardModel(
        study=study,
        problem=problem,
        assembler=assembler,
        material=material,
        names=free,
        device=warp_device,
        progress=progress,
        offset_start=offset_start,
        batch_records=(batches_records(warp_device) if batch_records is None else batch_records),
    )


def batches_records(device: Any) -> bool:
    """Whether a fit solves its records' FE runs (one per record of a viscoelastic material)
    together in one batched run (:func:`warptissue.fem.simulate_indentation_batch`) rather
    than one after another.

    Args:
        device: The Warp device of the fit.

    Returns:
        True where that was measured to pay: see docs/design-notes/batched-fe.md.
    """
    return RECORD_BATCHING[device.is_cuda]


RECORD_BATCHING = {False: False, True: True}
"""Whether a fit batches its records' FE runs, by device (CPU: False, CUDA: True), as
measured (docs/design-notes/batched-fe.md, "A fit's records")."""


def depth_offset_names(records: Sequence[DataRecord]) -> tuple[str, ...]:
    """The parameter names of the records' depth offsets: ``depth_offset_m`` for one record,
    ``depth_offset1_m``, ``depth_offset2_m``, ... (in ``[[data]]`` order) for several."""
    if len(records) == 1:
        return (DEPTH_OFFSET,)
    return tuple(f"depth_offset{k}_m" for k in range(1, len(records) + 1))


def depth_offset_start_m(record: DataRecord) -> float:
    """A start value of a record's depth offset d0 (m), from the record.

    A record conditioned with a contact point (``contact = "auto"``, detected by
    :func:`warptissue.acquisition.conditioning.detect_contact`, or ``contact_position_m``)
    has its depths counted from it: 0. A record used as recorded (``contact = "none"``):
    where the force first exceeds :data:`OFFSET_NOISE_SIGMA` noise standard deviations and
    1 % of the peak force, refined by a straight line through the next samples (to 4 times
    that force) back to zero force, kept between the last sample below it and the first one
    above; a record above it from its first sample: that line's zero, at most that sample.

    Args:
        record: A conditioned ``[[data]]`` record.

    Returns:
        The recorded depth at first touch (m).

    Notes:
        The noise is estimated from second differences of the force (1.4826 times their
        median absolute value over sqrt(6)), which a smooth loading curve leaves to the
        noise. The force is taken as zero before the touch (the model's too).
    """
    if record.conditioning.get("contact", "none") != "none":
        return 0.0
    d = np.asarray(record.displacement_m, dtype=np.float64)
    f = np.asarray(record.force_N, dtype=np.float64)
    peak = float(np.max(f)) if f.size else 0.0
    if f.size < 3 or not peak > 0.0:
        return float(d[0]) if d.size else 0.0
    noise = 1.4826 * float(np.median(np.abs(np.diff(f, 2)))) / math.sqrt(6.0)
    threshold = max(OFFSET_NOISE_SIGMA * noise, 0.01 * peak)
    loading = int(np.argmax(d)) + 1  # up to the deepest point
    above = np.flatnonzero(f[:loading] > threshold)
    if not above.size:
        return float(d[int(np.argmax(f))])
    first = int(above[0])
    upto = np.flatnonzero(f[first:loading] > 4.0 * threshold)
    last = first + (int(upto[0]) if upto.size else loading - 1 - first)
    last = max(last, min(first + 1, loading - 1))
    pick = slice(first, last + 1)
    guess = float(d[first])
    if last > first and np.ptp(d[pick]) > 0.0:
        slope, intercept = np.polyfit(d[pick], f[pick], 1)
        if slope > 0.0:
            guess = float(-intercept / slope)
    if first > 0:
        return float(np.clip(guess, d[first - 1], d[first]))
    return min(guess, float(d[0]))


def _offset_box(study: Study) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(start, lower, upper) of each record's depth offset (m), each shape (records,):
    ``[fit.start]``/``[fit.bounds]`` ``depth_offset_m`` where given, else from the record
    (:func:`depth_offset_start_m`, :data:`OFFSET_BOUND_SHARES`); the start clipped into the
    bounds."""
    settings = study.fit
    starts, lowers, uppers = [], [], []
    below, above = OFFSET_BOUND_SHARES
    for record in study.data:
        d = np.asarray(record.displacement_m, dtype=np.float64)
        shallow, deep = float(np.min(d)), float(np.max(d))
        span = deep - shallow
        low, high = settings.bounds.get(DEPTH_OFFSET, (shallow - below * span, deep - above * span))
        start = settings.start.get(DEPTH_OFFSET)
        start = depth_offset_start_m(record) if start is None else float(start)
        start = min(max(start, low), high)
        if not start < deep:
            key = "start" if DEPTH_OFFSET in settings.start else "bounds"
            raise InputError(
                f"{record.file}: a depth offset of {start:g} m leaves the record out of "
                f"contact (its deepest recorded depth is {deep:g} m): give a start below it",
                path=study.path,
                key=f"fit.{key}.{DEPTH_OFFSET}",
                value=start,
            )
        starts.append(start)
        lowers.append(low)
        uppers.append(high)
    return np.array(starts), np.array(lowers), np.array(uppers)


def _shifted(record: DataRecord, offset_m: float) -> DataRecord:
    """The record with its depths counted from a depth offset (``d - d0``)."""
    if offset_m == 0.0:
        return record
    samples = dataclasses.replace(record.record, displacement_m=record.displacement_m - offset_m)
    return dataclasses.replace(record, record=samples)


@dataclass(frozen=True)
class _RunRequest:
    """FE runs one fit asks of a :class:`~warptissue.fit._forward.FitMeeting`: one problem
    per load path ``(times_s or None, depths_m)``, with the sensitivities ``names``."""

    problems: list[Any]
    grids: list[tuple[np.ndarray | None, np.ndarray]]
    names: tuple[str, ...]
    options: Any
    device: Any


class _SharedRuns:
    """Solves the requests of fits that meet (:class:`~warptissue.fit._forward.FitMeeting`):
    the requests that share their sensitivities, Newton settings, device and formulation
    are solved in one batched FE run; the packed assembler of the last few sets of meshes is
    kept (a fit's trial points change the materials, not the meshes)."""

    KEPT = 4

    def __init__(self) -> None:
        self._assemblers: dict[tuple, Any] = {}

    def __call__(self, batch: dict[int, _RunRequest]) -> dict[int, Any]:
        groups: dict[tuple, list[int]] = {}
        for fit, request in sorted(batch.items()):  # in fit order: one assembler per set
            key = (
                request.names,
                request.options,
                str(request.device),
                request.problems[0].formulation,
            )
            groups.setdefault(key, []).append(fit)
        answers: dict[int, Any] = {}
        for key, fits in groups.items():
            problems = [problem for fit in fits for problem in batch[fit].problems]
            grids = [grid for fit in fits for grid in batch[fit].grids]
            meshes = (key, tuple(id(problem.mesh) for problem in problems))
            try:
                if meshes not in self._assemblers:
                    if len(self._assemblers) >= self.KEPT:
                        self._assemblers.pop(next(iter(self._assemblers)))
                    self._assemblers[meshes] = fem.batch_assembler(
                        problems, device=batch[fits[0]].device
                    )
                assembler = self._assemblers[meshes]
                results = fem.simulate_indentation_batch(
                    problems,
                    [depths for _, depths in grids],
                    options=batch[fits[0]].options,
                    sensitivities=key[0],
                    assembler=assembler,
                    times_s=[times for times, _ in grids],
                )
            except Exception as exc:  # every fit of the group gets it
                answers.update(dict.fromkeys(fits, exc))
                continue
            start = 0
            for fit in fits:
                count = len(batch[fit].grids)
                answers[fit] = results[start : start + count]
                start += count
        return answers


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
        _SharedRuns(),
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
        offset_start, offset_lower, offset_upper = _offset_box(study)
        start = start_values_from_record(study, _shifted(study.data[0], float(offset_start[0])))
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

    model = _forward_model(
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
    best: _Evaluation,
    model: _ForwardModel,
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


def _record_curves(model: _ForwardModel, best: _Evaluation) -> tuple[RecordCurve, ...]:
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
