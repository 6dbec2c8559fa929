"""Record a rig test to the experiment CSV and its JSON sidecar, losing no valid sample.

How nothing is lost (and why this is the one writer that does not rename atomically):
the project writes every other file to a temporary file and renames it over the target at the
end, so that a failed run leaves nothing half-written. For a recording that is the wrong
trade: a power cut, a crash or a killed process an hour into a test would leave only a
temporary file that the cleanup deletes, and the hour of data would be gone. So the recorder
appends to the final CSV as samples arrive. The file is opened line-buffered, so each row
reaches the operating system when it is written (a crash of the process loses nothing
written); after every chunk (``flush_rows`` rows or ``flush_interval_s`` seconds) it is also
``os.fsync``-ed, so a power cut loses at most the last chunk. The sidecar is rewritten
atomically after each chunk, with ``"status": "recording"`` and the rows saved so far
(``counts.samples_saved``); the final sidecar says how the run ended (see
:class:`RecordingResult`). After a crash the CSV holds every row written before it (at worst
a torn last line after a power cut, which ``counts.samples_saved`` lets a reader drop).
An existing output is never overwritten unless asked (``overwrite=True``).

Accounting: the rig numbers its samples from 0 in each motion and reports how many it emitted
in ``DONE`` (or ``STAT`` after a reconnection). The recorder keeps every valid sample,
counts sequence gaps, and ends with ``sent = received + missing`` and ``saved = received``.
"""

from __future__ import annotations

import csv
import datetime
import math
import os
import signal
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any, Protocol

import numpy as np

from warptissue.acquisition import protocol as wire
from warptissue.acquisition.driver import LinkLost, RigClient, parse_status
from warptissue.errors import DeviceError, InputError
from warptissue.io import software_versions, write_json

__all__ = [
    "ForceCorrection",
    "RampHold",
    "RecordingResult",
    "Recorder",
    "SampleListener",
    "Sine",
]


class SampleListener(Protocol):
    """What the recorder feeds as it records, for example a
    :class:`warptissue.acquisition.live.LiveFit`: each saved chunk of samples, and a request
    to end the protocol early.

    The recorder calls :meth:`add_samples` from its own thread after each chunk is on disk;
    the call must return at once (a listener that works on the samples does so elsewhere:
    ``LiveFit`` in a process of its own), so that it never delays the next chunk.
    """

    def add_samples(
        self, time_s: np.ndarray, displacement_m: np.ndarray, force_N: np.ndarray
    ) -> None:
        """Take the chunk's samples (s, m, N; shape (k,) each, as saved to the CSV)."""
        ...

    @property
    def stop_requested(self) -> bool:
        """True once the listener asks the rig to stop the protocol (checked between
        messages)."""
        ...


class ForceCorrection(Protocol):
    """What the recorder needs from a force calibration: a
    :class:`warptissue.acquisition.calibration.ForceCalibration`, or any object with this
    ``correct``."""

    def correct(self, raw_signal: np.ndarray) -> np.ndarray:
        """Corrected force (N) for raw transducer force (N), shape (n,)."""
        ...


def _check_finite(test: Any, *, positive: tuple[str, ...], nonnegative: tuple[str, ...]) -> None:
    """InputError naming the first field of ``test`` that is not finite with its sign."""
    for name in positive + nonnegative:
        value = getattr(test, name)
        if not (math.isfinite(value) and (value > 0 if name in positive else value >= 0)):
            sign = "positive" if name in positive else "zero or more"
            raise InputError(
                f"{type(test).__name__}: {name} must be finite and {sign}", value=float(value)
            )


@dataclass(frozen=True)
class RampHold:
    """Ramp-and-hold: dwell at rest, indent ``depth_m`` at ``speed_m_per_s``, hold."""

    depth_m: float
    speed_m_per_s: float
    hold_s: float
    dwell_s: float = 0.0

    name = "ramp-hold"

    def __post_init__(self) -> None:
        _check_finite(
            self, positive=("depth_m", "speed_m_per_s"), nonnegative=("hold_s", "dwell_s")
        )

    def duration_s(self) -> float:
        """Nominal duration (s), ignoring acceleration."""
        return self.dwell_s + self.depth_m / self.speed_m_per_s + self.hold_s

    def segment_ends_s(self) -> tuple[float, ...]:
        """Rig times at which the dwell, the ramp and the hold end (s; nominal)."""
        ramp_end_s = self.dwell_s + self.depth_m / self.speed_m_per_s
        return (self.dwell_s, ramp_end_s, ramp_end_s + self.hold_s)

    def start(self, client: RigClient) -> None:
        """Send the command."""
        client.ramp_hold(
            depth_m=self.depth_m,
            speed_m_per_s=self.speed_m_per_s,
            hold_s=self.hold_s,
            dwell_s=self.dwell_s,
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON form for the sidecar."""
        return {
            "kind": self.name,
            "depth_m": self.depth_m,
            "speed_m_per_s": self.speed_m_per_s,
            "hold_s": self.hold_s,
            "dwell_s": self.dwell_s,
        }


@dataclass(frozen=True)
class Sine:
    """Sinusoidal displacement about the present position."""

    amplitude_m: float
    frequency_Hz: float
    cycles: float

    name = "sine"

    def __post_init__(self) -> None:
        _check_finite(self, positive=("amplitude_m", "frequency_Hz", "cycles"), nonnegative=())

    def duration_s(self) -> float:
        """Duration (s)."""
        return self.cycles / self.frequency_Hz

    def segment_ends_s(self) -> tuple[float, ...]:
        """Rig times at which each full cycle ends, and the last part cycle (s)."""
        period_s = 1.0 / self.frequency_Hz
        ends = [period_s * k for k in range(1, int(math.floor(self.cycles)) + 1)]
        if not ends or ends[-1] < self.duration_s():
            ends.append(self.duration_s())
        return tuple(ends)

    def start(self, client: RigClient) -> None:
        """Send the command."""
        client.sine(
            amplitude_m=self.amplitude_m, frequency_Hz=self.frequency_Hz, cycles=self.cycles
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON form for the sidecar."""
        return {
            "kind": self.name,
            "amplitude_m": self.amplitude_m,
            "frequency_Hz": self.frequency_Hz,
            "cycles": self.cycles,
        }


@dataclass
class RecordingResult:
    """How a recording went.

    Attributes:
        csv_path: The experiment CSV.
        sidecar_path: Its JSON sidecar.
        status: ``complete``, ``stopped_early`` (the recorder's listener asked for the stop,
            e.g. a live fit whose parameters are known), ``stopped`` (a STOP from
            elsewhere), ``fault`` (the rig ended the motion with FAULT), ``interrupted``
            (Ctrl-C), ``link_lost`` (the port could not be reopened) or ``stalled`` (the
            rig stopped answering). A test the rig refuses raises instead, and writes
            nothing.
        samples_sent: Samples the rig reports it emitted (None if it never said).
        samples_received: Valid samples received (saved, one row each).
        samples_missing: Sequence numbers never received (gaps and a lost tail).
        sequence_gaps: Number of gaps.
        out_of_order: Samples with a sequence number already passed (skipped).
        stalls: Silences longer than the stall timeout.
        link: The client's link counters (garbage, CRC errors, reconnections...).
    """

    csv_path: Path
    sidecar_path: Path
    status: str
    samples_sent: int | None
    samples_received: int
    samples_missing: int
    sequence_gaps: int
    out_of_order: int
    stalls: int
    link: dict[str, int] = field(default_factory=dict)

    @property
    def samples_saved(self) -> int:
        """Rows written to the CSV (every valid sample received)."""
        return self.samples_received


SIDECAR_KEYS: frozenset[str] = frozenset(
    {
        "schema",
        "status",
        "data_file",
        "port",
        "sample_rate_Hz",
        "units_as_recorded",
        "columns",
        "counts",
        "software",
        "rig",
        "protocol",
        "started_utc",
        "finished_utc",
        "calibration",
    }
)
"""Keys the recorder writes to the sidecar itself; metadata may not replace them."""


def _utc_now() -> str:
    return datetime.datetime.now(datetime.UTC).isoformat(timespec="milliseconds")


class Recorder:
    """Run one protocol on the rig and record it.

    Args:
        client: An open :class:`RigClient`.
        csv_path: The experiment CSV to write (``time_s,displacement_m,force_N,sequence,
            time_us,position_<unit>,force_<unit>`` and, with a calibration,
            ``force_uncorrected_N``).
        rate_Hz: Sample rate to configure (1 to 1000 Hz).
        calibration: Force correction applied to the raw force, or None.
        metadata: Extra sidecar entries (specimen, probe, temperature...).
        overwrite: Replace an existing CSV; otherwise an existing file is an error.
        progress: Show a tqdm progress bar.
        stall_timeout_s: Silence (wall s) after which the rig is asked for its ``STAT``.
        give_up_s: Silence (wall s) after which the port is reopened; when that fails or the
            rig still does not answer, the run ends as ``stalled`` with its data kept.
        flush_rows: Rows per fsync-ed chunk.
        flush_interval_s: Longest time between chunks (wall s).
        listener: Fed every saved chunk (:class:`SampleListener`); when it asks for a
            stop, the rig is sent ``STOP`` and the run ends as ``stopped_early`` once the
            rig's ``DONE`` is in (every sample before it is kept).
    """

    def __init__(
        self,
        client: RigClient,
        csv_path: str | Path,
        *,
        rate_Hz: float = 1000.0,
        calibration: ForceCorrection | None = None,
        metadata: dict[str, Any] | None = None,
        overwrite: bool = False,
        progress: bool = True,
        stall_timeout_s: float = 2.0,
        give_up_s: float = 10.0,
        flush_rows: int = 1000,
        flush_interval_s: float = 0.5,
        listener: SampleListener | None = None,
    ) -> None:
        if not 1.0 <= rate_Hz <= 1000.0:
            raise InputError("rate must be between 1 Hz and 1000 Hz", value=rate_Hz)
        self.client = client
        self.csv_path = Path(csv_path)
        self.sidecar_path = self.csv_path.with_suffix(".json")
        if self.csv_path.suffix != ".csv":
            raise InputError("the output must be a .csv file", path=self.csv_path)
        if self.csv_path.is_dir():
            raise InputError("the output is a folder; give a .csv file", path=self.csv_path)
        for existing in (self.csv_path, self.sidecar_path):
            if not overwrite and existing.exists():
                raise InputError(
                    "output exists; choose another name or pass --overwrite", path=existing
                )
        folder = self.csv_path.absolute().parent
        while not folder.exists():
            folder = folder.parent
        if not folder.is_dir() or not os.access(folder, os.W_OK | os.X_OK):
            reason = "not a folder" if not folder.is_dir() else "permission denied"
            raise InputError(f"cannot write the output: {folder}: {reason}", path=self.csv_path)
        reserved = sorted(SIDECAR_KEYS.intersection(metadata or {}))
        if reserved:
            raise InputError(
                f"metadata key {reserved[0]!r} is the recorder's own sidecar entry; choose "
                "another name",
                value=reserved,
            )
        self.rate_Hz = rate_Hz
        self.calibration = calibration
        self.metadata = dict(metadata or {})
        self.progress = progress
        self.stall_timeout_s = stall_timeout_s
        self.give_up_s = give_up_s
        self.flush_rows = flush_rows
        self.flush_interval_s = flush_interval_s
        self.overwrite = overwrite
        self.listener = listener
        self._software = software_versions()

    # -- output ----------------------------------------------------------------------------
    def _columns(self) -> list[str]:
        client = self.client
        columns = ["time_s", "displacement_m", "force_N", "sequence", "time_us"]
        columns += [f"position_{client.length_unit}", f"force_{client.force_unit}"]
        if self.calibration is not None:
            columns.append("force_uncorrected_N")
        return columns

    def _sidecar(self, status: str, result_counts: dict[str, Any], extra: dict[str, Any]):
        client = self.client
        write_json(
            self.sidecar_path,
            {
                "schema": "warptissue.acquisition/1",
                "status": status,
                "data_file": self.csv_path.name,
                "port": client.url,
                "sample_rate_Hz": self.rate_Hz,
                "units_as_recorded": {
                    "time": "us",
                    "position": client.length_unit,
                    "force": client.force_unit,
                },
                "columns": {
                    "time_s": "rig time since the command started (s)",
                    "displacement_m": "axis position minus its value at the first sample (m)",
                    "force_N": "force, calibrated when a calibration is given (N)",
                    "sequence": "rig sample number (gaps are missing samples)",
                    "time_us": "raw rig time (us)",
                    f"position_{client.length_unit}": "raw axis position as transmitted",
                    f"force_{client.force_unit}": "raw force as transmitted",
                    "force_uncorrected_N": "raw force in N before calibration",
                },
                "counts": result_counts,
                "software": self._software,
                **extra,
                **self.metadata,
            },
        )

    # -- the run ---------------------------------------------------------------------------
    def record(self, test: RampHold | Sine) -> RecordingResult:
        """Configure the rig, run ``test`` and record every valid sample.

        Returns:
            The result; its status says how the run ended. Only a Ctrl-C propagates (after
            the rig is stopped and everything received is saved).

        Raises:
            KeyboardInterrupt: Re-raised after a clean stop.
            DeviceError: The rig could not be configured, or refused the test
                (:class:`~warptissue.acquisition.CommandRefused`); nothing is written then.
            InputError: The output could not be opened once the rig had started (the rig
                is stopped first).
        """
        client = self.client
        client.configure(length_unit="mm", force_unit="mN", rate_Hz=self.rate_Hz)
        identity = client.identify()
        extra = {
            "rig": identity,
            "protocol": test.to_dict(),
            "started_utc": _utc_now(),
            "calibration": None
            if self.calibration is None
            else {"model": getattr(self.calibration, "model", type(self.calibration).__name__)},
        }
        self._interrupt_requested = False
        previous_handler = self._catch_ctrl_c()
        try:
            test.start(client)  # a refusal raises here, before any file is written
            handle = self._open_output()
            return self._record(test, handle, extra)
        finally:
            if previous_handler is not None:
                signal.signal(signal.SIGINT, previous_handler)

    def _open_output(self) -> IO[str]:
        """Open the CSV for appending rows; the rig is moving: stop it if that fails."""
        try:
            self.csv_path.parent.mkdir(parents=True, exist_ok=True)
            mode = "w" if self.overwrite else "x"
            return open(self.csv_path, mode, newline="", encoding="utf-8", buffering=1)
        except OSError as exc:
            try:
                self.client.stop()
            except DeviceError:
                pass
            raise InputError(
                f"cannot write the output: {exc.strerror}; the rig was stopped",
                path=self.csv_path,
            ) from None

    def _record(self, test: RampHold | Sine, handle: IO[str], extra: dict[str, Any]):
        """Save the started test's samples to ``handle`` until the rig says it is done."""
        from tqdm import tqdm

        client = self.client
        length_scale = wire.LENGTH_UNITS[client.length_unit]
        force_scale = wire.FORCE_UNITS[client.force_unit]
        state = _RunState()
        writer = csv.writer(handle)
        writer.writerow(self._columns())
        self._sync(handle)
        self._sidecar("recording", state.counts(client), extra)
        bar = tqdm(
            total=max(1, round(test.duration_s() * self.rate_Hz)),
            unit="sample",
            disable=not self.progress,
            desc=f"{test.name} {self.csv_path.name}",
        )
        rows: list[list[Any]] = []  # rows written since the last fsync
        values: list[tuple[float, float, float]] = []  # their (time_s, displacement_m, force_N)
        origin: list[float] = []

        def save() -> None:
            if rows:
                latest = rows[-1]
                bar.set_postfix(
                    depth_mm=f"{float(latest[1]) * 1e3:.3f}",
                    force_mN=f"{float(latest[2]) * 1e3:.2f}",
                    missing=state.missing,
                    refresh=False,
                )
                rows.clear()
            self._sync(handle)
            self._sidecar("recording", state.counts(client), extra)
            if values and self.listener is not None:
                chunk = np.array(values, dtype=np.float64)
                self.listener.add_samples(chunk[:, 0], chunk[:, 1], chunk[:, 2])
            values.clear()

        def keep(sample: wire.Sample) -> None:
            if not state.accept(sample.sequence):
                return
            position_m = sample.position * length_scale
            if not origin:
                origin.append(position_m)
            raw_force_N = sample.force * force_scale
            force = (
                raw_force_N
                if self.calibration is None
                else float(self.calibration.correct(np.array([raw_force_N]))[0])
            )
            time_s, displacement_m = sample.time_us / 1e6, position_m - origin[0]
            row = [
                repr(time_s),
                repr(displacement_m),
                repr(force),
                sample.sequence,
                sample.time_us,
                sample.position_text,
                sample.force_text,
            ]
            if self.calibration is not None:
                row.append(repr(raw_force_N))
            writer.writerow(row)  # line-buffered: in the OS at once
            rows.append(row)
            values.append((time_s, displacement_m, force))
            bar.update(1)

        status = "link_lost"
        try:
            status = self._stream(keep, save, rows, state)
        except KeyboardInterrupt:
            status = "interrupted"
            try:
                for message in client.stop():
                    if isinstance(message, wire.Sample):
                        keep(message)
                    elif isinstance(message, wire.Done):
                        state.finish(message.samples)
                client.pending.clear()
            except DeviceError:
                pass
            raise
        finally:
            bar.close()
            save()
            handle.close()
            extra["finished_utc"] = _utc_now()
            self._sidecar(status, state.counts(client), extra)
            self.result = state.result(self, status)
        return self.result

    def _catch_ctrl_c(self):
        """Turn Ctrl-C into a request checked between messages, so that it never cuts a
        sample in half; returns the previous handler (None off the main thread)."""
        if threading.current_thread() is not threading.main_thread():
            return None

        def request_stop(signum: int, frame: object) -> None:
            self._interrupt_requested = True

        return signal.signal(signal.SIGINT, request_stop)

    @staticmethod
    def _sync(handle: IO[str]) -> None:
        handle.flush()
        os.fsync(handle.fileno())

    def _stream(
        self,
        keep: Callable[[wire.Sample], None],
        save: Callable[[], None],
        rows: list,
        state: _RunState,
    ) -> str:
        client = self.client
        last_message = last_save = time.monotonic()
        asked = False
        recovered_without_reply = False
        stop_sent = False
        while True:
            if self._interrupt_requested:
                raise KeyboardInterrupt
            if not stop_sent and self.listener is not None and self.listener.stop_requested:
                stop_sent = True
                try:
                    client.send("STOP")  # the rig answers OK STOP, then DONE STOPPED
                except LinkLost:
                    pass  # the next read reconnects, as for any lost link
            try:
                message = client.read_message()
            except LinkLost:
                save()
                outcome = self._recover(state)
                if outcome is not None:
                    return outcome
                last_message = time.monotonic()
                continue
            now = time.monotonic()
            if message is None:
                silence = now - last_message
                if silence > self.stall_timeout_s and not asked:
                    state.stalls += 1
                    asked = True
                    save()
                    self._ask_status(client)
                if silence > self.give_up_s:
                    save()
                    if recovered_without_reply:
                        return "stalled"
                    recovered_without_reply = True
                    outcome = self._recover(state, stalled=True)
                    if outcome is not None:
                        return outcome
                    last_message = time.monotonic()
                    asked = False
                continue
            last_message = now
            asked = False
            recovered_without_reply = False
            if isinstance(message, wire.Sample):
                keep(message)
            elif isinstance(message, wire.Done):
                state.finish(message.samples)
                if message.status == "STOPPED" and stop_sent:
                    return "stopped_early"
                return "complete" if message.status == "OK" else message.status.lower()
            elif isinstance(message, wire.Reply) and message.command == "STAT":
                status = parse_status(message)
                if status is not None and status[0] == "IDLE":
                    state.finish(status[1])
                    return "stopped_early" if stop_sent else "complete"
            if len(rows) >= self.flush_rows or now - last_save > self.flush_interval_s:
                save()
                last_save = now

    @staticmethod
    def _ask_status(client: RigClient) -> None:
        try:
            client.send("STAT")
        except LinkLost:
            pass

    def _recover(self, state: _RunState, *, stalled: bool = False) -> str | None:
        """Reopen the port and ask the rig where it is.

        Returns:
            None to keep recording, or the final status.
        """
        client = self.client
        if not client.reconnect():
            return "stalled" if stalled else "link_lost"
        try:
            client.send("STAT")
        except LinkLost:
            return "stalled" if stalled else "link_lost"
        return None


@dataclass
class _RunState:
    expected: int = 0
    received: int = 0
    missing: int = 0
    gaps: int = 0
    out_of_order: int = 0
    stalls: int = 0
    sent: int | None = None

    def accept(self, sequence: int) -> bool:
        if sequence < self.expected:
            self.out_of_order += 1
            return False
        if sequence > self.expected:
            self.missing += sequence - self.expected
            self.gaps += 1
        self.expected = sequence + 1
        self.received += 1
        return True

    def finish(self, emitted: int) -> None:
        self.sent = emitted
        if emitted > self.expected:
            self.missing += emitted - self.expected
            self.gaps += 1
            self.expected = emitted

    def counts(self, client: RigClient) -> dict[str, Any]:
        return {
            "samples_sent": self.sent,
            "samples_received": self.received,
            "samples_saved": self.received,
            "samples_missing": self.missing,
            "sequence_gaps": self.gaps,
            "out_of_order": self.out_of_order,
            "stalls": self.stalls,
            **client.counters.to_dict(),
        }

    def result(self, recorder: Recorder, status: str) -> RecordingResult:
        return RecordingResult(
            csv_path=recorder.csv_path,
            sidecar_path=recorder.sidecar_path,
            status=status,
            samples_sent=self.sent,
            samples_received=self.received,
            samples_missing=self.missing,
            sequence_gaps=self.gaps,
            out_of_order=self.out_of_order,
            stalls=self.stalls,
            link=recorder.client.counters.to_dict(),
        )
