"""Fit a lumped viscoelastic model while the rig records, in a thread apart from the recorder.

:class:`LiveFit` is a :class:`~warptissue.acquisition.recorder.SampleListener`: the
:class:`~warptissue.acquisition.Recorder` hands it each chunk of samples once the chunk is on
disk (:meth:`LiveFit.add_samples` only appends to a list under a lock and wakes the fit
thread, so the recorder never waits for a fit). The fit thread conditions the record as it
grows (contact point and force offset, :func:`~warptissue.acquisition.conditioning.
condition_for_fit`, the same choices as ``warptissue fit relaxation``) and refits it with
:func:`warptissue.viscoelastic.fit_relaxation_joint` every ``every_samples`` new samples,
warm-started from the last identified estimate (from the data when there is none, or when
the warm start does not end identified). A fit that takes longer than the record grows simply
skips cadences: it always takes the latest record, and never queues work.

With a :class:`StopRule` (``se<2%``), the fit asks the recorder to stop the protocol once
every free parameter's relative standard error is below the limit and the fit is identified
by the rules of :attr:`warptissue.lsq.FitResult.identifiability` (no parameter pinned at a
bound, a non-singular covariance); the recorder sends ``STOP`` and keeps every sample up to
the rig's ``DONE``.

The live estimates are progress, not the result: the final fit of the finished record is the
offline fit (``warptissue acquire --fit`` runs ``warptissue fit relaxation`` on the saved
CSV), so that the reported parameters are those anyone gets from the file.
"""

from __future__ import annotations

import math
import re
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from warptissue.acquisition.conditioning import condition_for_fit
from warptissue.errors import ConvergenceError, InputError
from warptissue.lsq import FitResult
from warptissue.viscoelastic import RelaxationRecord, fit_relaxation_joint

__all__ = ["LiveEstimate", "LiveFit", "StopRule"]

_STOP_RULE = re.compile(r"^\s*se\s*<\s*([0-9.eE+-]+)\s*(%?)\s*$")


@dataclass(frozen=True)
class StopRule:
    """When a live fit has learnt enough: every free parameter's relative standard error
    below ``relative_standard_error`` and the fit identified.

    Attributes:
        relative_standard_error: The largest standard error / |value| allowed (0.02 for
            ``se<2%``).
    """

    relative_standard_error: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.relative_standard_error) and self.relative_standard_error > 0):
            raise InputError(
                "the stop rule's relative standard error must be positive",
                value=self.relative_standard_error,
            )

    @classmethod
    def parse(cls, text: str) -> StopRule:
        """``se<2%`` or ``se<0.02``.

        Raises:
            InputError: Any other text (the value named).
        """
        match = _STOP_RULE.match(text)
        if match is None:
            raise InputError("--stop-when takes se<LIMIT, e.g. se<2%", value=text)
        try:
            value = float(match.group(1))
        except ValueError:
            raise InputError("--stop-when takes se<LIMIT, e.g. se<2%", value=text) from None
        return cls(value / 100.0 if match.group(2) else value)

    def relative_errors(self, result: FitResult) -> np.ndarray | None:
        """Standard error / |value| per parameter, shape (n,), or None without a covariance."""
        if result.standard_errors is None:
            return None
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.abs(result.standard_errors) / np.abs(result.x)

    def met(self, result: FitResult) -> bool:
        """Converged, identified, and every relative standard error below the limit."""
        relative = self.relative_errors(result)
        return bool(
            result.success
            and result.identified
            and relative is not None
            and np.all(relative < self.relative_standard_error)
        )

    def __str__(self) -> str:
        return f"se<{self.relative_standard_error * 100:g}%"


@dataclass(frozen=True)
class LiveEstimate:
    """One refit of the growing record.

    Attributes:
        samples: Samples recorded when the fit started.
        rig_time_s: Rig time of the last of them (s).
        result: The fit, or None when it could not run on the record so far.
        message: Why not (too few samples, no contact yet, no convergence), or "".
        stop_rule_met: The stop rule held for this fit.
        fit_wall_s: Wall time the conditioning and the fit took (s).
    """

    samples: int
    rig_time_s: float
    result: FitResult | None
    message: str
    stop_rule_met: bool
    fit_wall_s: float

    def progress_line(self) -> str:
        """``live fit @ 12.3 s (12301 samples): k_inf = 20.1 +- 0.3 N/m, ...``."""
        head = f"live fit @ {self.rig_time_s:.3g} s ({self.samples} samples):"
        if self.result is None:
            return f"{head} {self.message}"
        errors = self.result.standard_errors
        parts = []
        for i, name in enumerate(self.result.parameter_names):
            unit = self.result.parameter_units[i]
            error = "n/a" if errors is None else f"{errors[i]:.3g}"
            parts.append(f"{name} = {self.result.x[i]:.5g} +- {error} {unit}".rstrip())
        tail = "; stop rule met" if self.stop_rule_met else ""
        return f"{head} {', '.join(parts)}{tail}"

    def to_dict(self) -> dict[str, Any]:
        """JSON form: the parameters with their standard errors, or the message."""
        entry: dict[str, Any] = {
            "samples": self.samples,
            "rig_time_s": self.rig_time_s,
            "message": self.message,
            "stop_rule_met": self.stop_rule_met,
            "fit_wall_s": self.fit_wall_s,
        }
        if self.result is not None:
            errors = self.result.standard_errors
            entry["parameters"] = {
                name: {
                    "value": float(self.result.x[i]),
                    "standard_error": None if errors is None else float(errors[i]),
                    "unit": self.result.parameter_units[i],
                }
                for i, name in enumerate(self.result.parameter_names)
            }
            entry["identified"] = self.result.identified
        return entry


class LiveFit:
    """Refit a lumped viscoelastic model to the record as it grows, in its own thread.

    Args:
        model: ``"sls"`` or ``"prony"`` (:func:`warptissue.viscoelastic.fit_relaxation_joint`).
        terms: Prony terms.
        every_samples: Refit after this many new samples (a slower fit skips cadences).
        contact: Conditioning: ``"none"``, ``"auto"`` or the axis position at contact (m).
        offset: Conditioning: ``"auto"`` or ``"none"`` (the force offset).
        method: ``"lm"`` or ``"salm"``.
        stop_rule: Ask the recorder to stop once this holds, or None.
        on_estimate: Called in the fit thread with each :class:`LiveEstimate` and the
            conditioned record it fitted (None when the fit could not run): progress line,
            live plot. An exception there stops the live fit cleanly (the recording goes on).
        fit: The fitting function (default :func:`~warptissue.viscoelastic.
            fit_relaxation_joint`), called with a list of one
            :class:`~warptissue.viscoelastic.RelaxationRecord` and the keyword options
            ``model``, ``terms``, ``p0``, ``method``.

    Attributes:
        estimates: Every estimate so far, in order.
        state: ``"waiting"`` (not started), ``"running"``, ``"finished"`` (ran to the end of
            the record) or ``"stopped"`` (an error ended it; :attr:`stop_reason` says which).
        stop_reason: Why the live fit stopped before the record ended, or "".
    """

    def __init__(
        self,
        *,
        model: str = "prony",
        terms: int = 2,
        every_samples: int = 500,
        contact: str | float = "auto",
        offset: str = "auto",
        method: str = "lm",
        stop_rule: StopRule | None = None,
        on_estimate: Callable[[LiveEstimate, RelaxationRecord | None], None] | None = None,
        fit: Callable[..., FitResult] = fit_relaxation_joint,
    ) -> None:
        if model not in ("sls", "prony"):
            raise InputError("a live fit takes the model sls or prony:N", value=model)
        if int(every_samples) < 1:
            raise InputError("every_samples must be at least 1", value=every_samples)
        self.model, self.terms, self.method = model, int(terms), method
        self.every_samples = int(every_samples)
        self.contact, self.offset = contact, offset
        self.stop_rule = stop_rule
        self.on_estimate = on_estimate
        self._fit = fit
        self.estimates: list[LiveEstimate] = []
        self.state = "waiting"
        self.stop_reason = ""
        self._chunks: list[np.ndarray] = []
        self._count = 0
        self._ended = False
        self._wake = threading.Condition()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    # -- the recorder's side ----------------------------------------------------------------
    def add_samples(
        self, time_s: np.ndarray, displacement_m: np.ndarray, force_N: np.ndarray
    ) -> None:
        """Take a chunk (s, m, N; shape (k,) each); returns at once."""
        chunk = np.column_stack([time_s, displacement_m, force_N])
        with self._wake:
            self._chunks.append(chunk)
            self._count += chunk.shape[0]
            self._wake.notify()

    @property
    def stop_requested(self) -> bool:
        """True once the stop rule held."""
        return self._stop.is_set()

    # -- the thread -------------------------------------------------------------------------
    def start(self) -> LiveFit:
        """Start the fit thread (a daemon: it never keeps the process alive)."""
        self.state = "running"
        self._thread = threading.Thread(target=self._run, name="live-fit", daemon=True)
        self._thread.start()
        return self

    def finish(self, *, timeout_s: float | None = None) -> None:
        """Tell the thread the record is complete and wait for its last fit.

        Args:
            timeout_s: Longest wait (s); None waits for the fit in progress to end.
        """
        with self._wake:
            self._ended = True
            self._wake.notify()
        if self._thread is not None:
            self._thread.join(timeout_s)

    def abandon(self, reason: str) -> None:
        """End the live fit without waiting for the fit in progress (Ctrl-C)."""
        with self._wake:
            self._ended = True
            if self.state == "running":
                self.state, self.stop_reason = "stopped", reason
            self._wake.notify()

    def record(self) -> np.ndarray:
        """The samples so far, shape (n, 3): time_s, displacement_m, force_N."""
        with self._wake:
            if len(self._chunks) > 1:
                self._chunks = [np.concatenate(self._chunks)]
            return self._chunks[0].copy() if self._chunks else np.empty((0, 3))

    def _run(self) -> None:
        fitted = 0
        while True:
            with self._wake:
                while not self._ended and self._count - fitted < self.every_samples:
                    self._wake.wait()
                ended, count = self._ended, self._count
            if self.state != "running":
                return
            if count > fitted:
                fitted = count
                try:
                    self._refit()
                except Exception as exc:  # noqa: BLE001 - the recording must go on
                    self.state = "stopped"
                    self.stop_reason = f"{type(exc).__name__}: {exc}"
                    return
            if ended:
                self.state = "finished"
                return

    def _refit(self) -> None:
        started = time.perf_counter()
        samples = self.record()
        count = samples.shape[0]
        rig_time_s = float(samples[-1, 0]) if count else 0.0
        result, message, fitted = None, "", None
        try:
            record = condition_for_fit(
                {
                    "time_s": samples[:, 0],
                    "displacement_m": samples[:, 1],
                    "force_N": samples[:, 2],
                },
                contact=self.contact,
                offset=self.offset,
            )
            fitted = RelaxationRecord(
                record.time_s,
                record.displacement_m,
                record.force_N,
                source="live record",
                conditioned=record.conditioned,
            )
            result = self._warm_or_cold_fit(fitted)
        except (InputError, ConvergenceError) as exc:
            result, fitted, message = None, None, f"not yet: {exc}"
        met = result is not None and self.stop_rule is not None and self.stop_rule.met(result)
        estimate = LiveEstimate(
            count, rig_time_s, result, message, met, time.perf_counter() - started
        )
        self.estimates.append(estimate)
        if met:
            self._stop.set()
        if self.on_estimate is not None:
            self.on_estimate(estimate, fitted)

    def _warm_or_cold_fit(self, record: RelaxationRecord) -> FitResult:
        """Warm-started from the last identified estimate; from the data's own start (as
        ``fit relaxation``) when there is none, or when the warm start ends unidentified
        (an early estimate can sit in another basin: a short hold does not separate the
        time constants)."""
        options = {"model": self.model, "terms": self.terms, "method": self.method}
        previous = self.latest_result(identified=True)
        if previous is not None:
            result = self._fit([record], p0=previous.x, **options)
            if result.success and result.identified:
                return result
        return self._fit([record], p0=None, **options)

    def latest_result(self, *, identified: bool = False) -> FitResult | None:
        """The last estimate's fit (the last identified one if asked), or None."""
        for estimate in reversed(self.estimates):
            result = estimate.result
            if result is not None and (not identified or result.identified):
                return result
        return None

    def summary(self) -> dict[str, Any]:
        """JSON form: state, why it stopped, the stop rule, every estimate."""
        return {
            "model": self.model if self.model == "sls" else f"prony:{self.terms}",
            "every_samples": self.every_samples,
            "contact": self.contact,
            "offset": self.offset,
            "state": self.state,
            "stop_reason": self.stop_reason,
            "stop_rule": None if self.stop_rule is None else str(self.stop_rule),
            "stop_rule_met": self.stop_requested,
            "estimates": [e.to_dict() for e in self.estimates],
        }
