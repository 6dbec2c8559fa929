"""Fit the record while the rig records it, in a process apart from the recorder.

:class:`LiveFit` is a :class:`~warptissue.acquisition.recorder.SampleListener`: the
:class:`~warptissue.acquisition.Recorder` hands it each chunk of samples once the chunk is on
disk (:meth:`LiveFit.add_samples` only appends to a list under a lock and wakes a hand-over
thread, so the recorder never waits for a fit). The fit itself runs in a process of its own
(``multiprocessing`` with the ``spawn`` start method): the hand-over thread sends it the rows
recorded since the last refit through a pipe and sleeps in the pipe's read until the estimate
comes back, so the fit never holds the recorder's interpreter lock. A fit that takes longer
than the record grows simply skips cadences: it always takes the latest record, and never
queues work.

What is fitted is a *fitter* (:class:`LiveFitter`): :class:`LumpedFitter` (a lumped
viscoelastic model, any of ``warptissue fit relaxation``'s, :func:`fit_lumped`, conditioned as
``warptissue fit relaxation`` does) or the inverse FE of a study
(:class:`warptissue.fit.live.StudyFitter`). It lives in the fit process, so it keeps its
own warm start from one refit to the next. The cadence is every ``every_samples`` new
samples, or each time the record passes the end of a protocol segment (``segment_ends_s``:
the end of the ramp, of the hold), or both; the end of the record is always fitted.

With a :class:`StopRule` (``se<2%``), the fit asks the recorder to stop the protocol once
every free parameter's relative standard error is below the limit and the fit is identified
by the rules of :attr:`warptissue.lsq.FitResult.identifiability` (no parameter pinned at a
bound, a non-singular covariance) and the model fits: no systematic residuals in any window
of the record (:mod:`warptissue.acquisition.stop_rule`); the recorder sends ``STOP`` and
keeps every sample up to the rig's ``DONE``. Each estimate says what the rule still waits for.

The live estimates are progress, not the result: the final fit of the finished record is the
offline fit (``warptissue acquire --fit`` runs ``warptissue fit relaxation`` or ``warptissue
fit indentation`` on the saved CSV), so that the reported parameters are those anyone gets
from the file.
"""

from __future__ import annotations

import math
import multiprocessing
import signal
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from multiprocessing.connection import Connection
from typing import Any, Protocol

import numpy as np

from warptissue.acquisition.conditioning import condition_for_fit
from warptissue.acquisition.stop_rule import StopRule
from warptissue.device import terminal_interrupts_ignored, thread_lock_for_progress_bars
from warptissue.errors import ConvergenceError, InputError
from warptissue.lsq import FitResult
from warptissue.viscoelastic import RelaxationRecord, fit_relaxation_joint
from warptissue.viscoelastic.fitting import RELAXATION_MODELS, fit_qlv

__all__ = [
    "LUMPED_MODELS",
    "LiveCurve",
    "LiveEstimate",
    "LiveFit",
    "LiveFitter",
    "LumpedFitter",
    "StopRule",
    "fit_lumped",
]

LUMPED_MODELS = (*RELAXATION_MODELS, "qlv")
"""The lumped models of a live fit: every model of ``warptissue fit relaxation``."""


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
        stop_rule_waits_for: With a stop rule, the conditions it still waits for
            (:meth:`StopRule.unmet`), else empty.
    """

    samples: int
    rig_time_s: float
    result: FitResult | None
    message: str
    stop_rule_met: bool
    fit_wall_s: float
    stop_rule_waits_for: tuple[str, ...] = ()

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
        if self.stop_rule_waits_for:
            tail = f"; stop rule waits for: {'; '.join(self.stop_rule_waits_for)}"
        return f"{head} {', '.join(parts)}{tail}"

    def to_dict(self) -> dict[str, Any]:
        """JSON form: the parameters with their standard errors, or the message."""
        entry: dict[str, Any] = {
            "samples": self.samples,
            "rig_time_s": self.rig_time_s,
            "message": self.message,
            "stop_rule_met": self.stop_rule_met,
            "stop_rule_waits_for": list(self.stop_rule_waits_for),
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


@dataclass(frozen=True)
class LiveCurve:
    """What a refit fitted and its model force, for the live plot.

    Attributes:
        time_s: Times of the fitted samples (s), shape (m,).
        measured_force_N: Their force (N), shape (m,).
        model_force_N: The fitted model's force there (N), shape (m,).
    """

    time_s: np.ndarray
    measured_force_N: np.ndarray
    model_force_N: np.ndarray


class LiveFitter(Protocol):
    """What a live fit refits: an object that can be pickled into the fit process."""

    def refit(self, samples: np.ndarray, *, final: bool = False) -> tuple[FitResult, LiveCurve]:
        """Fit the record so far.

        Args:
            samples: Every sample so far, shape (n, 3): time_s (s), displacement_m (m),
                force_N (N), as the recorder saved them.
            final: The recording has ended: this is the last refit, of the whole record.

        Returns:
            The fit and the curve it fitted.

        Raises:
            InputError: Not enough of a record yet (no contact, too few samples).
            ConvergenceError: The fit did not converge on the record so far.
        """
        ...


def fit_lumped(
    records: Sequence[RelaxationRecord],
    *,
    model: str,
    terms: int,
    p0: Sequence[float] | None,
    method: str,
) -> FitResult:
    """The fit ``warptissue fit relaxation --model MODEL`` makes of one record: ``qlv`` by
    :func:`warptissue.viscoelastic.fitting.fit_qlv` (Ahn & Kim's stage (i)), every other
    model by :func:`warptissue.viscoelastic.fit_relaxation_joint`.

    Args:
        records: One :class:`~warptissue.viscoelastic.RelaxationRecord` (qlv takes one).
        model: One of :data:`LUMPED_MODELS`.
        terms: Prony terms (prony, qlv).
        p0: Start values in the model's order, or None (from the data).
        method: ``"lm"`` or ``"salm"``.
    """
    if model != "qlv":
        return fit_relaxation_joint(records, model=model, terms=terms, p0=p0, method=method)
    (record,) = records
    return fit_qlv(
        record.time_s, record.displacement_m, record.force_N, terms=terms, p0=p0,
        method=method, max_displacement_m=record.max_displacement_m,
    )  # fmt: skip


@dataclass
class LumpedFitter:
    """A lumped viscoelastic model refitted to the record as it grows.

    Each refit conditions the whole record so far (contact point and force offset,
    :func:`~warptissue.acquisition.conditioning.condition_for_fit`, as ``warptissue fit
    relaxation``), then fits it warm-started from the last identified estimate; from the
    data's own start (as ``fit relaxation``) when there is none, or when the warm start ends
    unidentified (an early estimate can sit in another basin: a short hold does not separate
    the time constants).

    Args:
        model: One of :data:`LUMPED_MODELS` (:func:`fit_lumped`): every model of
            ``warptissue fit relaxation``.
        terms: Prony terms (prony, qlv).
        contact: ``"none"``, ``"auto"`` or the axis position at contact (m).
        offset: ``"auto"`` or ``"none"`` (the force offset).
        method: ``"lm"`` or ``"salm"``.
        fit: The fitting function, a module-level function (it is pickled into the fit
            process), called with a list of one :class:`~warptissue.viscoelastic.
            RelaxationRecord` and the keyword options ``model``, ``terms``, ``p0``,
            ``method``.
    """

    model: str = "prony"
    terms: int = 2
    contact: str | float = "auto"
    offset: str = "auto"
    method: str = "lm"
    fit: Callable[..., FitResult] = fit_lumped
    _previous: FitResult | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        if self.model not in LUMPED_MODELS:
            raise InputError(
                f"a live fit takes the models {', '.join(LUMPED_MODELS)} (prony:N, qlv:N)",
                value=self.model,
            )

    @property
    def label(self) -> str:
        """The model as ``--fit`` names it: ``sls``, ``prony:N``, ``qlv:N``, ``wiechert``."""
        return f"{self.model}:{self.terms}" if self.model in ("prony", "qlv") else self.model

    def refit(self, samples: np.ndarray, *, final: bool = False) -> tuple[FitResult, LiveCurve]:
        """Condition and fit the record so far (see :class:`LiveFitter`); the final refit
        starts from the data's own start, as the offline fit does, so that it ends at the
        offline fit's optimum (a warm start ends elsewhere within the engine's tolerance: up
        to 9e-6 relative on a QLV tissue whose parameters correlate at -0.99)."""
        conditioned = condition_for_fit(
            {"time_s": samples[:, 0], "displacement_m": samples[:, 1], "force_N": samples[:, 2]},
            contact=self.contact,
            offset=self.offset,
        )
        record = RelaxationRecord(
            conditioned.time_s,
            conditioned.displacement_m,
            conditioned.force_N,
            source="live record",
            conditioned=conditioned.conditioned,
        )
        options = {"model": self.model, "terms": self.terms, "method": self.method}
        result = None
        if self._previous is not None and not final:
            result = self.fit([record], p0=self._previous.x, **options)
        if result is None or not (result.success and result.identified):
            result = self.fit([record], p0=None, **options)
        if result.identified:
            self._previous = result
        return result, LiveCurve(record.time_s, record.force_N, np.asarray(result.fitted))


class LiveFit:
    """Refit the record as it grows, in a process of its own.

    Args:
        fitter: What to fit (:class:`LumpedFitter`, :class:`warptissue.fit.live.StudyFitter`).
        every_samples: Refit after this many new samples; None: only at ``segment_ends_s``
            and at the end (a slower fit skips cadences).
        segment_ends_s: Rig times (s) at which a protocol segment ends: the record is refitted
            once it has passed each of them.
        stop_rule: Ask the recorder to stop once this holds, or None.
        on_estimate: Called in this process's hand-over thread with each
            :class:`LiveEstimate` (the progress line). An exception there stops the live fit
            cleanly (the recording goes on).
        plot: Called in the fit process with each :class:`LiveEstimate` and the
            :class:`LiveCurve` it fitted (when the fit ran): the live plot. A module-level
            function or a ``functools.partial`` of one (it is pickled); an exception there
            stops the live fit cleanly.

    Attributes:
        estimates: Every estimate so far, in order.
        state: ``"waiting"`` (not started), ``"running"``, ``"finished"`` (ran to the end of
            the record) or ``"stopped"`` (an error ended it; :attr:`stop_reason` says which).
        stop_reason: Why the live fit stopped before the record ended, or "".
    """

    def __init__(
        self,
        fitter: LiveFitter,
        *,
        every_samples: int | None = 500,
        segment_ends_s: Sequence[float] = (),
        stop_rule: StopRule | None = None,
        on_estimate: Callable[[LiveEstimate], None] | None = None,
        plot: Callable[[LiveEstimate, LiveCurve], None] | None = None,
    ) -> None:
        if every_samples is not None and int(every_samples) < 1:
            raise InputError("every_samples must be at least 1", value=every_samples)
        if every_samples is None and not segment_ends_s:
            raise InputError("a live fit needs every_samples or segment_ends_s")
        self.fitter = fitter
        self.every_samples = None if every_samples is None else int(every_samples)
        self.segment_ends_s = tuple(sorted(float(t) for t in segment_ends_s))
        self.stop_rule = stop_rule
        self.on_estimate = on_estimate
        self.plot = plot
        self.estimates: list[LiveEstimate] = []
        self.state = "waiting"
        self.stop_reason = ""
        self._chunks: list[np.ndarray] = []
        self._count = 0
        self._last_time_s = -math.inf
        self._ended = False
        self._wake = threading.Condition()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._process: Any = None
        self._connection: Connection | None = None

    # -- the recorder's side ----------------------------------------------------------------
    def add_samples(
        self, time_s: np.ndarray, displacement_m: np.ndarray, force_N: np.ndarray
    ) -> None:
        """Take a chunk (s, m, N; shape (k,) each); returns at once."""
        chunk = np.column_stack([time_s, displacement_m, force_N])
        with self._wake:
            self._chunks.append(chunk)
            self._count += chunk.shape[0]
            if chunk.shape[0]:
                self._last_time_s = float(chunk[-1, 0])
            self._wake.notify()

    @property
    def stop_requested(self) -> bool:
        """True once the stop rule held."""
        return self._stop.is_set()

    # -- the process and the hand-over thread -----------------------------------------------
    def start(self) -> LiveFit:
        """Start the fit process and the hand-over thread (daemons: neither keeps this
        process alive). The fit process starts in the background (its imports take a
        second or two); the first refit waits for it, the recorder does not."""
        context = multiprocessing.get_context("spawn")
        ours, theirs = context.Pipe()
        self._process = context.Process(
            target=_serve,
            args=(theirs, self.fitter, self.plot, self.stop_rule),
            name="live-fit",
            daemon=True,
        )
        with terminal_interrupts_ignored():  # no traceback while it imports
            self._process.start()
        theirs.close()
        self._connection = ours
        self.state = "running"
        self._thread = threading.Thread(target=self._run, name="live-fit", daemon=True)
        self._thread.start()
        return self

    def finish(self, *, timeout_s: float | None = None) -> None:
        """Tell the fit the record is complete, wait for its last refit, end the process.

        Args:
            timeout_s: Longest wait (s); None waits for the fit in progress to end. A fit
                still running then is ended (state ``"stopped"``).
        """
        with self._wake:
            self._ended = True
            self._wake.notify()
        if self._thread is not None:
            self._thread.join(timeout_s)
            if self._thread.is_alive():
                self.abandon(f"the last refit did not end within {timeout_s:g} s")
                self._thread.join()
        self._close()

    def abandon(self, reason: str) -> None:
        """End the live fit without waiting for the fit in progress (Ctrl-C): the fit
        process is terminated."""
        with self._wake:
            self._ended = True
            if self.state == "running":
                self.state, self.stop_reason = "stopped", reason
            self._wake.notify()
        if self._process is not None and self._process.is_alive():
            self._process.terminate()

    def record(self) -> np.ndarray:
        """The samples so far, shape (n, 3): time_s, displacement_m, force_N."""
        with self._wake:
            if len(self._chunks) > 1:
                self._chunks = [np.concatenate(self._chunks)]
            return self._chunks[0].copy() if self._chunks else np.empty((0, 3))

    def _due(self, fitted: int, fitted_time_s: float) -> bool:
        """(Under the lock.) Enough new samples, or a segment end passed since the last fit."""
        if self._count <= fitted:
            return False
        if self.every_samples is not None and self._count - fitted >= self.every_samples:
            return True
        return any(fitted_time_s < end <= self._last_time_s for end in self.segment_ends_s)

    def _run(self) -> None:
        fitted, fitted_time_s = 0, -math.inf
        while True:
            with self._wake:
                while not self._ended and not self._due(fitted, fitted_time_s):
                    self._wake.wait()
                ended, count = self._ended, self._count
                rig_time_s = self._last_time_s
            if self.state != "running":
                return
            if count > fitted or (ended and count > 0):  # the end: one final refit
                rows = self.record()[fitted:count]
                fitted, fitted_time_s = count, rig_time_s
                if not self._refit(rows, final=ended):
                    return
            if ended:
                self.state = "finished"
                return

    def _refit(self, rows: np.ndarray, *, final: bool) -> bool:
        """Send the new rows (and whether the record has ended) to the fit process and take
        its estimate; False when the live fit stopped."""
        assert self._connection is not None
        try:
            self._connection.send((rows, final))
            reply = self._connection.recv()
        except (EOFError, OSError) as exc:
            self._stopped(f"the fit process ended ({type(exc).__name__})")
            return False
        if isinstance(reply, str):
            self._stopped(reply)
            return False
        self.estimates.append(reply)
        if reply.stop_rule_met:
            self._stop.set()  # before the plot: the rig is stopped as soon as it is known
        if self.on_estimate is not None:
            try:
                self.on_estimate(reply)
            except Exception as exc:  # noqa: BLE001 - the recording must go on
                self._stopped(f"{type(exc).__name__}: {exc}")
                return False
        try:
            plotted = self._connection.recv()  # None, or why the plot failed
        except (EOFError, OSError) as exc:
            self._stopped(f"the fit process ended ({type(exc).__name__})")
            return False
        if plotted is not None:
            self._stopped(plotted)
            return False
        return True

    def _stopped(self, reason: str) -> None:
        with self._wake:
            if self.state == "running":
                self.state, self.stop_reason = "stopped", reason

    def _close(self) -> None:
        if self._connection is not None:
            try:
                self._connection.send(None)
            except (OSError, ValueError):
                pass
            self._connection.close()
            self._connection = None
        if self._process is not None:
            self._process.join(10.0)
            if self._process.is_alive():
                self._process.terminate()
                self._process.join()

    def latest_result(self, *, identified: bool = False) -> FitResult | None:
        """The last estimate's fit (the last identified one if asked), or None."""
        for estimate in reversed(self.estimates):
            result = estimate.result
            if result is not None and (not identified or result.identified):
                return result
        return None

    def summary(self) -> dict[str, Any]:
        """JSON form: what was fitted, state, why it stopped, the stop rule, every estimate."""
        return {
            "model": getattr(self.fitter, "label", type(self.fitter).__name__),
            "every_samples": self.every_samples,
            "segment_ends_s": list(self.segment_ends_s),
            "state": self.state,
            "stop_reason": self.stop_reason,
            "stop_rule": None if self.stop_rule is None else str(self.stop_rule),
            "stop_rule_met": self.stop_requested,
            "estimates": [e.to_dict() for e in self.estimates],
        }


def _serve(
    connection: Connection,
    fitter: LiveFitter,
    plot: Callable[[LiveEstimate, LiveCurve], None] | None,
    stop_rule: StopRule | None,
) -> None:
    """The fit process: take (rows, final), refit the record so far, send back the estimate
    (or one line saying why the live fit must stop), then plot it and send None (or why the
    plot failed): the estimate, and with it the stop rule, never waits for the plot. None
    ends it.
    Ctrl-C is the parent's to handle (it terminates this process); this process starts with
    SIGINT ignored (:func:`warptissue.device.terminal_interrupts_ignored`) and keeps it so."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    thread_lock_for_progress_bars()  # terminated (Ctrl-C): no semaphore left behind
    chunks: list[np.ndarray] = []
    while True:
        try:
            message = connection.recv()
        except EOFError:
            return
        if message is None:
            return
        rows, final = message
        chunks.append(rows)
        samples = np.concatenate(chunks)
        chunks = [samples]
        started = time.perf_counter()
        try:
            estimate, curve = _estimate(fitter, samples, stop_rule, started, final=final)
        except Exception as exc:  # noqa: BLE001 - said to the parent, which stops cleanly
            connection.send(f"{type(exc).__name__}: {exc}")
            continue
        connection.send(estimate)
        failure = None
        if plot is not None and curve is not None:
            try:
                plot(estimate, curve)
            except Exception as exc:  # noqa: BLE001 - said to the parent, which stops cleanly
                failure = f"the live plot failed: {type(exc).__name__}: {exc}"
        connection.send(failure)


def _estimate(
    fitter: LiveFitter,
    samples: np.ndarray,
    stop_rule: StopRule | None,
    started: float,
    *,
    final: bool = False,
) -> tuple[LiveEstimate, LiveCurve | None]:
    """One refit of the record so far (``final``: the whole record, the recording ended):
    the :class:`LiveEstimate` and the curve it fitted (None when the fit could not run
    yet)."""
    count = samples.shape[0]
    rig_time_s = float(samples[-1, 0]) if count else 0.0
    result, curve, message = None, None, ""
    try:
        result, curve = fitter.refit(samples, final=final)
    except (InputError, ConvergenceError) as exc:
        message = f"not yet: {exc}"
    waits: tuple[str, ...] = ()
    if result is not None and stop_rule is not None:
        waits = tuple(stop_rule.unmet(result, curve))
    met = result is not None and stop_rule is not None and not waits
    wall_s = time.perf_counter() - started
    return LiveEstimate(count, rig_time_s, result, message, met, wall_s, waits), curve
