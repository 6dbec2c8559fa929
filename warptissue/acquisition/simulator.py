"""A simulated indentation rig that speaks the line protocol over a pty or a loopback socket.

The rig follows Ahn & Kim's bench (a motor on a linear guide, a force transducer, 41.5 mm of
travel, at most 8 mm/s, 0.7 mN force resolution) and streams at up to 1 kHz like Kim et al.'s
probe. The specimen is any object with ``force_N(time_s, displacement_m) -> force_N`` (for
example ``warptissue.viscoelastic.StandardLinearSolid`` or :class:`ForceCurveTissue`); the
displacement it receives is the indentation depth below the specimen surface (zero in air).
Sensor effects: Gaussian noise, an offset, a linear drift, quantization to the transducer
resolution, and optional physiological disturbance (respiration and heartbeat, Kim et al.
Fig. 2d). Faults can be injected on the link to test the driver and recorder.

Time runs ``time_scale`` times faster than the wall clock (``math.inf``: as fast as the link
drains), so that a 100 s hold can be tested in a fraction of a second; the samples and their
time stamps are those of the rig's own clock either way.
"""

from __future__ import annotations

import contextlib
import errno
import math
import os
import select
import socket
import threading
import time
import tty
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np

from warptissue.acquisition import protocol as wire
from warptissue.errors import InputError
from warptissue.io import read_experiment_csv

__all__ = [
    "FAULT_OPTIONS",
    "FaultPlan",
    "ForceCurveTissue",
    "PhysiologicalDisturbance",
    "RigConfig",
    "RigCounters",
    "RigServer",
    "SimulatedRig",
    "TissueModel",
    "trapezoid_position",
]


class TissueModel(Protocol):
    """What the simulated rig indents: force for a displacement history."""

    def force_N(self, time_s: np.ndarray, displacement_m: np.ndarray) -> np.ndarray:
        """Force (N), shape (n,), for indentation depth ``displacement_m`` (m) at
        ``time_s`` (s), both shape (n,)."""
        ...


@dataclass(frozen=True)
class ForceCurveTissue:
    """A rate-independent specimen given by a precomputed force-depth curve (for example an
    FE reaction-force curve), interpolated linearly, zero force at zero depth.

    Attributes:
        displacement_m: Depths, shape (k,), strictly increasing.
        force_N: Forces at those depths, shape (k,).
    """

    displacement_m: np.ndarray
    force_N_values: np.ndarray

    @classmethod
    def from_csv(cls, path: str | Path) -> ForceCurveTissue:
        """Read any CSV with columns ``displacement_m`` (depth, increasing, zero or more) and
        ``force_N`` (compression positive), other columns ignored: ``warptissue simulate``'s
        ``force_curve.csv``, or a measured loading curve.

        Raises:
            InputError: Missing file or column, a bad number, a depth that does not increase
                or is negative, or forces that are all negative (file, line, column named).
        """

        record = read_experiment_csv(
            path, required=("displacement_m", "force_N"), monotonic="displacement_m"
        )
        depth, force = record["displacement_m"], record["force_N"]
        if depth[0] < 0:
            raise InputError(
                "the depth must be zero or more (zero at the surface)",
                path=path,
                line=2,
                column="displacement_m",
                value=float(depth[0]),
            )
        if force.max() <= 0 < -force.min():
            raise InputError(
                "every force is negative: give the compressive force as positive",
                path=path,
                column="force_N",
                value=float(force.min()),
            )
        return cls(depth, force)

    def force_N(self, time_s: np.ndarray, displacement_m: np.ndarray) -> np.ndarray:
        """Interpolated force at each depth; ``time_s`` is unused (rate-independent)."""
        depth = np.asarray(displacement_m, dtype=np.float64)
        curve_depth = np.concatenate(([0.0], self.displacement_m))
        curve_force = np.concatenate(([0.0], self.force_N_values))
        return np.where(depth > 0.0, np.interp(depth, curve_depth, curve_force), 0.0)


@dataclass(frozen=True)
class PhysiologicalDisturbance:
    """Respiration and heartbeat forces added to the transducer signal, as in Kim et al.
    Fig. 2(d) (large peaks from respiration, small ones from the heart beat).

    Kim et al. give the picture, not the numbers; the defaults are those of an anaesthetised,
    ventilated pig: 15 breaths/min (0.25 Hz) and 84 beats/min (1.4 Hz), with peaks of a few
    millinewtons, the respiration peak about four times the cardiac one. Each waveform is a
    zero-mean peaked pulse train, ``amplitude * (((1 - cos(2 pi f t)) / 2) ** 2 - 3/8)``, whose
    only harmonics are f and 2 f.

    Attributes:
        respiration_amplitude_N: Peak-to-peak respiration force (N).
        respiration_Hz: Breathing rate (Hz).
        heartbeat_amplitude_N: Peak-to-peak cardiac force (N).
        heartbeat_Hz: Heart rate (Hz).
    """

    respiration_amplitude_N: float = 8e-3
    respiration_Hz: float = 0.25
    heartbeat_amplitude_N: float = 2e-3
    heartbeat_Hz: float = 1.4

    def force_N(self, time_s: np.ndarray) -> np.ndarray:
        """Disturbance force (N) at rig time ``time_s`` (s), shape (n,)."""
        t = np.asarray(time_s, dtype=np.float64)
        total = np.zeros_like(t)
        for amplitude, rate, phase in (
            (self.respiration_amplitude_N, self.respiration_Hz, 0.3),
            (self.heartbeat_amplitude_N, self.heartbeat_Hz, 1.1),
        ):
            pulse = ((1.0 - np.cos(2.0 * np.pi * rate * t + phase)) / 2.0) ** 2 - 0.375
            total += amplitude * pulse
        return total


FAULT_OPTIONS = {"garbage": "garbage_every", "split": "split_every", "corrupt": "corrupt_every",
                 "drop": "drop_every", "disconnect": "disconnect_after", "stall": "stall_after",
                 "stall_s": "stall_s"}  # fmt: skip
"""``--faults NAME=VALUE`` names and the :class:`FaultPlan` fields they set."""


@dataclass(frozen=True)
class FaultPlan:
    """Link faults to inject, counted on sample lines (n-th sample of the session, 1-based).

    Attributes:
        garbage_every: After every n-th sample, send a burst of garbage bytes; bursts
            alternate between ending with a newline (a garbage line) and not (glued onto the
            next, valid line). 0 disables.
        split_every: Send every n-th sample line in two writes with a pause between them.
        corrupt_every: Flip the CRC of every n-th sample line.
        drop_every: Never transmit every n-th sample (it is still emitted and numbered).
        disconnect_after: Close the connection once, after this many samples (TCP only).
        stall_after: Freeze the rig once, after this many samples, for ``stall_s`` wall
            seconds (``math.inf``: for ever); nothing is lost, the rig's clock stops too.
        stall_s: Length of the stall (wall seconds).
        split_pause_s: Pause between the two halves of a split line (wall seconds).
        seed: Seed of the garbage bytes.
    """

    garbage_every: int = 0
    split_every: int = 0
    corrupt_every: int = 0
    drop_every: int = 0
    disconnect_after: int | None = None
    stall_after: int | None = None
    stall_s: float = 1.0
    split_pause_s: float = 0.02
    seed: int = 1

    @classmethod
    def parse(cls, text: str) -> FaultPlan:
        """Parse ``"garbage=200,split=500,corrupt=300,drop=400,disconnect=1000,stall=2000"``
        (plus ``stall_s=1.5``); the empty string is no faults."""
        names = FAULT_OPTIONS
        options: dict[str, float | int] = {}
        for item in filter(None, (part.strip() for part in text.split(","))):
            key, sep, value = item.partition("=")
            if key not in names:
                raise InputError(f"--faults: unknown fault; use {', '.join(names)}", value=item)
            if not sep:
                raise InputError("--faults takes NAME=VALUE pairs, e.g. drop=400", value=item)
            if names[key] in options:
                raise InputError(f"--faults: {key} is given twice", value=text)
            try:
                number = float(value) if key == "stall_s" else int(value)
            except ValueError:
                raise InputError("--faults: not a number", value=item) from None
            if not (math.isfinite(number) and number > 0):
                what = "a positive number of seconds" if key == "stall_s" else "1 or more"
                raise InputError(f"--faults: {key} must be {what}", value=item)
            options[names[key]] = number
        return cls(**options)


@dataclass
class RigCounters:
    """What the simulated rig did, for checking the recorder's accounting.

    Attributes:
        emitted: Samples numbered by the rig (across all motions of the session).
        delivered: Sample lines the rig put on the link whole, corrupted ones included
            (intact lines: ``delivered - corrupted``; split lines count once, when whole).
        corrupted: Sample lines sent with a wrong CRC.
        dropped: Samples emitted but never transmitted (``drop_every``).
        undelivered: Samples emitted while no host was connected, or lost in the rig's
            output queue at a disconnect.
        garbage_lines: Garbage bursts that end with a newline.
        garbage_glued: Garbage bursts glued onto the next line.
        split_lines: Lines sent in two pieces.
        disconnects: Connections the rig closed.
        stalls: Stalls that started.
        commands: Commands received (framed or plain).
    """

    emitted: int = 0
    delivered: int = 0
    corrupted: int = 0
    dropped: int = 0
    undelivered: int = 0
    garbage_lines: int = 0
    garbage_glued: int = 0
    split_lines: int = 0
    disconnects: int = 0
    stalls: int = 0
    commands: int = 0


@dataclass(frozen=True)
class RigConfig:
    """The simulated bench.

    Attributes:
        surface_position_m: Axis position of the specimen surface (m); the probe is in air
            above it. The axis starts at 0, positive toward the specimen.
        travel_m: Axis travel (m) (Ahn & Kim: 41.5 mm).
        max_speed_m_per_s: Highest speed (m/s) (Ahn & Kim: 8 mm/s).
        acceleration_m_per_s2: Acceleration and deceleration of moves (m/s^2); ramps are
            trapezoidal, which is why Takacs et al. trim their ends.
        force_resolution_N: Transducer quantum (N) (Ahn & Kim: 0.7 mN).
        force_noise_N: Standard deviation of the transducer noise (N).
        force_offset_N: Transducer offset before ``ZERO`` (N).
        force_drift_N_per_s: Linear transducer drift (N/s of rig time).
        position_resolution_m: Encoder quantum (m).
        disturbance: Respiration and heartbeat, or None (ex vivo).
        time_scale: Rig seconds per wall second (``math.inf``: as fast as the link drains).
        clock_start_s: Rig clock at power-on (s); sets the phase of the disturbance.
        seed: Seed of the noise.
        serial_number: Reported by ``IDN``.
    """

    surface_position_m: float = 0.3e-3
    travel_m: float = 41.5e-3
    max_speed_m_per_s: float = 8e-3
    acceleration_m_per_s2: float = 0.2
    force_resolution_N: float = 0.7e-3
    force_noise_N: float = 0.3e-3
    force_offset_N: float = 0.0
    force_drift_N_per_s: float = 0.0
    position_resolution_m: float = 0.1e-6
    disturbance: PhysiologicalDisturbance | None = None
    time_scale: float = 1.0
    clock_start_s: float = 0.0
    seed: int = 0
    serial_number: str = "SIM0001"


def trapezoid_position(
    time_s: np.ndarray, distance_m: float, speed_m_per_s: float, acceleration_m_per_s2: float
) -> np.ndarray:
    """Position (m) along a move of ``distance_m`` (signed) with a trapezoidal (or, for short
    moves, triangular) velocity profile, at ``time_s`` (s) from its start, shape (n,)."""
    t = np.clip(np.asarray(time_s, dtype=np.float64), 0.0, None)
    length = abs(distance_m)
    if length == 0.0:
        return np.zeros_like(t)
    accel = acceleration_m_per_s2
    peak = min(speed_m_per_s, math.sqrt(length * accel))
    t_accel = peak / accel
    t_total = 2.0 * t_accel + (length - peak * t_accel) / peak
    s = np.where(
        t < t_accel,
        0.5 * accel * t**2,
        np.where(
            t < t_total - t_accel,
            0.5 * accel * t_accel**2 + peak * (t - t_accel),
            length - 0.5 * accel * np.clip(t_total - t, 0.0, None) ** 2,
        ),
    )
    s = np.where(t >= t_total, length, np.clip(s, 0.0, length))
    return math.copysign(1.0, distance_m) * s


def move_duration_s(distance_m: float, speed_m_per_s: float, acceleration_m_per_s2: float) -> float:
    """Duration (s) of a trapezoidal move (see :func:`trapezoid_position`)."""
    length = abs(distance_m)
    if length == 0.0:
        return 0.0
    peak = min(speed_m_per_s, math.sqrt(length * acceleration_m_per_s2))
    return 2.0 * peak / acceleration_m_per_s2 + (length - peak**2 / acceleration_m_per_s2) / peak


class _CommandRefused(Exception):
    def __init__(self, code: wire.ErrorCode, text: str) -> None:
        self.code = code
        self.text = text
        super().__init__(text)


@dataclass
class _Motion:
    command: str
    time_s: np.ndarray
    position_m: np.ndarray
    force_N: np.ndarray
    next_index: int = 0


@dataclass
class _Line:
    data: bytes
    is_sample: bool
    corrupt: bool = False
    split: bool = False


class SimulatedRig:
    """The rig's firmware: command handling, motion, the transducer; no transport.

    The transport (:class:`RigServer`) feeds it command lines with :meth:`handle_line` and
    asks it for the sample lines that are due with :meth:`due_lines`.

    Args:
        tissue: The specimen (``force_N(time_s, displacement_m)``).
        config: The bench.
    """

    def __init__(self, tissue: TissueModel, config: RigConfig | None = None) -> None:
        self.tissue = tissue
        self.config = config or RigConfig()
        self.counters = RigCounters()
        self.length_unit = "mm"
        self.force_unit = "mN"
        self.rate_Hz = 1000.0
        self.speed_m_per_s = self.config.max_speed_m_per_s
        self.position_m = 0.0
        self.tare_N = 0.0
        self.motion: _Motion | None = None
        self.last_motion_samples = 0
        self.rig_time_s = self.config.clock_start_s
        self._wall_origin = time.monotonic()
        self._rng = np.random.default_rng(self.config.seed)
        self._history_time_s = np.array([self.config.clock_start_s])
        self._history_depth_m = np.zeros(1)

    # -- clock ------------------------------------------------------------------------------
    def rig_time_now(self) -> float:
        """Rig time (s) now, from the wall clock and ``time_scale``."""
        scale = self.config.time_scale
        if math.isinf(scale):
            return self.rig_time_s
        return self.config.clock_start_s + (time.monotonic() - self._wall_origin) * scale

    def freeze(self, wall_seconds: float) -> None:
        """Shift the clock so that ``wall_seconds`` of wall time do not count (a stall)."""
        self._wall_origin += wall_seconds

    # -- transducer -------------------------------------------------------------------------
    def _depth_m(self, position_m: np.ndarray) -> np.ndarray:
        return np.clip(position_m - self.config.surface_position_m, 0.0, None)

    def _measured_force_N(self, time_s: np.ndarray, position_m: np.ndarray) -> np.ndarray:
        """Transducer reading for a new stretch of the axis history (appended to it)."""
        depth = self._depth_m(position_m)
        history_t = np.concatenate((self._history_time_s, time_s))
        history_d = np.concatenate((self._history_depth_m, depth))
        tissue = np.asarray(self.tissue.force_N(history_t, history_d), dtype=np.float64)
        self._history_time_s, self._history_depth_m = history_t, history_d
        force = tissue[-len(time_s) :].copy()
        config = self.config
        force += config.force_offset_N + config.force_drift_N_per_s * time_s - self.tare_N
        if config.disturbance is not None:
            force += config.disturbance.force_N(time_s)
        force += self._rng.normal(0.0, config.force_noise_N, size=force.shape)
        return np.round(force / config.force_resolution_N) * config.force_resolution_N

    def _start(self, command: str, duration_s: float, path: Callable[[np.ndarray], np.ndarray]):
        start = max(self.rig_time_now(), float(self._history_time_s[-1]) + 1.0 / self.rate_Hz)
        count = int(math.floor(duration_s * self.rate_Hz + 1e-9)) + 1
        local = np.arange(count) / self.rate_Hz
        position = np.clip(path(local), 0.0, self.config.travel_m)
        force = self._measured_force_N(start + local, position)
        self.motion = _Motion(command, start + local, position, force)
        self.position_m = float(position[-1])

    # -- commands ---------------------------------------------------------------------------
    def _length(self, text: str) -> float:
        return self._number(text) * wire.LENGTH_UNITS[self.length_unit]

    @staticmethod
    def _number(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise _CommandRefused(wire.ErrorCode.BAD_ARGUMENT, f"not a number: {text}") from None
        if not math.isfinite(value):
            raise _CommandRefused(wire.ErrorCode.BAD_ARGUMENT, f"not finite: {text}")
        return value

    def _check_speed(self, speed: float) -> None:
        if not 0.0 < speed <= self.config.max_speed_m_per_s * (1 + 1e-9):
            raise _CommandRefused(wire.ErrorCode.OUT_OF_RANGE, "speed out of range")

    def _check_target(self, target: float) -> None:
        if not -1e-12 <= target <= self.config.travel_m + 1e-12:
            raise _CommandRefused(wire.ErrorCode.OUT_OF_RANGE, "position outside travel")

    def handle_line(self, line: bytes) -> list[bytes]:
        """Execute one command line; return the reply lines (framed)."""
        text = line.strip()
        if not text:
            return []
        self.counters.commands += 1
        if b"$" in text:
            try:
                body = wire.unframe(text)
            except wire.ProtocolError as exc:
                code = wire.ErrorCode.BAD_CHECKSUM if exc.kind == "checksum" else 3
                return [wire.format_error(wire.ErrorCode(code), "?", str(exc.args[0])[:60])]
            fields = body.split(",")
        else:
            fields = text.decode("ascii", "replace").replace(",", " ").split() or ["?"]
        command, arguments = fields[0].upper(), fields[1:]
        try:
            if command not in wire.COMMANDS:
                raise _CommandRefused(wire.ErrorCode.UNKNOWN_COMMAND, "unknown command")
            expected = wire.COMMANDS[command]
            optional = wire.OPTIONAL_ARGUMENTS.get(command, 0)
            if not expected <= len(arguments) <= expected + optional:
                raise _CommandRefused(wire.ErrorCode.BAD_ARGUMENT, "wrong number of arguments")
            if self.motion is not None and command not in ("STOP", "STAT", "IDN"):
                raise _CommandRefused(wire.ErrorCode.BUSY, "motion in progress")
            return self._execute(command, arguments)
        except _CommandRefused as refusal:
            return [wire.format_error(refusal.code, command, refusal.text)]

    def _execute(self, command: str, arguments: list[str]) -> list[bytes]:
        config = self.config
        if command == "IDN":
            return [
                wire.format_reply("IDN", "warptissue", "rig-sim", config.serial_number, "1.0", "P1")
            ]
        if command == "STAT":
            state = "MOVING" if self.motion is not None else "IDLE"
            samples = self.motion.next_index if self.motion else self.last_motion_samples
            position = self.position_m / wire.LENGTH_UNITS[self.length_unit]
            return [wire.format_reply("STAT", state, str(samples), f"{position:.6g}")]
        if command == "STOP":
            lines = [wire.format_reply("STOP")]
            if self.motion is not None:
                motion = self.motion
                self.position_m = float(motion.position_m[max(motion.next_index - 1, 0)])
                unexecuted = len(motion.time_s) - max(motion.next_index, 1)
                if unexecuted:  # the tissue only felt the part that ran
                    self._history_time_s = self._history_time_s[:-unexecuted]
                    self._history_depth_m = self._history_depth_m[:-unexecuted]
                lines.append(self._finish("STOPPED"))
            return lines
        if command == "UNITS":
            length, force = arguments
            if length not in wire.LENGTH_UNITS or force not in wire.FORCE_UNITS:
                raise _CommandRefused(wire.ErrorCode.BAD_ARGUMENT, "unknown unit")
            self.length_unit, self.force_unit = length, force
            return [wire.format_reply("UNITS", length, force)]
        if command == "RATE":
            rate = self._number(arguments[0])
            if not 1.0 <= rate <= 1000.0:
                raise _CommandRefused(wire.ErrorCode.OUT_OF_RANGE, "rate must be 1-1000 Hz")
            self.rate_Hz = rate
            return [wire.format_reply("RATE", f"{rate:g}")]
        if command == "SPEED":
            speed = self._length(arguments[0])
            self._check_speed(speed)
            self.speed_m_per_s = speed
            return [wire.format_reply("SPEED", arguments[0])]
        if command == "ZERO":
            time_now = np.array([max(self.rig_time_now(), float(self._history_time_s[-1]) + 1e-6)])
            reading = self._measured_force_N(time_now, np.array([self.position_m]))
            self.tare_N += float(reading[0])
            return [wire.format_reply("ZERO")]
        if command in ("HOME", "MOVE"):
            target = 0.0 if command == "HOME" else self._length(arguments[0])
            self._check_target(target)
            return self._move(command, target - self.position_m, self.speed_m_per_s, 0.0, 0.0)
        if command == "RAMP":
            depth, speed = self._length(arguments[0]), self._length(arguments[1])
            hold = self._number(arguments[2])
            dwell = self._number(arguments[3]) if len(arguments) > 3 else 0.0
            self._check_speed(speed)
            self._check_target(self.position_m + depth)
            if hold < 0 or dwell < 0:
                raise _CommandRefused(wire.ErrorCode.OUT_OF_RANGE, "negative time")
            return self._move("RAMP", depth, speed, hold, dwell)
        amplitude = self._length(arguments[0])
        frequency, cycles = self._number(arguments[1]), self._number(arguments[2])
        if amplitude <= 0 or frequency <= 0 or cycles <= 0:
            raise _CommandRefused(wire.ErrorCode.OUT_OF_RANGE, "non-positive sine argument")
        if 2 * math.pi * frequency * amplitude > config.max_speed_m_per_s * (1 + 1e-9):
            raise _CommandRefused(wire.ErrorCode.OUT_OF_RANGE, "peak speed above the maximum")
        self._check_target(self.position_m - amplitude)
        self._check_target(self.position_m + amplitude)
        origin = self.position_m
        self._start(
            "SINE",
            cycles / frequency,
            lambda t: origin + amplitude * np.sin(2 * math.pi * frequency * t),
        )
        return [wire.format_reply("SINE")]

    def _move(self, command: str, distance: float, speed: float, hold: float, dwell: float):
        origin = self.position_m
        accel = self.config.acceleration_m_per_s2
        duration = dwell + move_duration_s(distance, speed, accel) + hold
        self._start(
            command,
            duration,
            lambda t: origin + trapezoid_position(t - dwell, distance, speed, accel),
        )
        return [wire.format_reply(command)]

    def _finish(self, status: str) -> bytes:
        assert self.motion is not None
        motion, self.motion = self.motion, None
        self.last_motion_samples = motion.next_index
        return wire.format_done(motion.command, motion.next_index, status)

    # -- streaming --------------------------------------------------------------------------
    def due_lines(self, limit: int) -> list[tuple[bytes, bool]]:
        """Sample lines due now (at most ``limit``), then ``DONE`` when the motion ends.

        Returns:
            (framed line, is_sample) pairs.
        """
        motion = self.motion
        if motion is None:
            return []
        if math.isinf(self.config.time_scale):
            stop = min(len(motion.time_s), motion.next_index + limit)
        else:
            now = self.rig_time_now()
            due = int(np.searchsorted(motion.time_s, now, side="right"))
            stop = min(due, motion.next_index + limit)
        length_scale = wire.LENGTH_UNITS[self.length_unit]
        force_scale = wire.FORCE_UNITS[self.force_unit]
        length_decimals = {"um": 1, "mm": 4, "m": 7}[self.length_unit]
        force_decimals = {"mN": 4, "N": 7}[self.force_unit]
        lines = []
        start_time = motion.time_s[0]
        for index in range(motion.next_index, stop):
            position = round(motion.position_m[index] / self.config.position_resolution_m) * (
                self.config.position_resolution_m / length_scale
            )
            sample = wire.Sample(
                sequence=index,
                time_us=round((motion.time_s[index] - start_time) * 1e6),
                position=position,
                force=motion.force_N[index] / force_scale,
                position_text=f"{position:.{length_decimals}f}",
                force_text=f"{motion.force_N[index] / force_scale:.{force_decimals}f}",
            )
            lines.append((wire.format_sample(sample), True))
        self.counters.emitted += stop - motion.next_index
        motion.next_index = stop
        if stop:
            self.rig_time_s = max(self.rig_time_s, float(motion.time_s[stop - 1]))
        if motion.next_index == len(motion.time_s):
            lines.append((self._finish("OK"), False))
        return lines

    def next_due_wall_s(self) -> float | None:
        """Seconds of wall time until the next sample is due (None when idle)."""
        motion = self.motion
        if motion is None:
            return None
        if math.isinf(self.config.time_scale) or motion.next_index >= len(motion.time_s):
            return 0.0
        wait = (motion.time_s[motion.next_index] - self.rig_time_now()) / self.config.time_scale
        return max(wait, 0.0)


class _Garbage:
    def __init__(self, seed: int) -> None:
        self._rng = np.random.default_rng(seed)
        self.count = 0

    def burst(self) -> tuple[bytes, bool]:
        """Random bytes without ``$`` or line ends; every other burst ends with a newline."""
        values = self._rng.integers(0, 256, size=int(self._rng.integers(3, 24)))
        data = bytes(v for v in values.tolist() if v not in (0x24, 0x0A, 0x0D)) or b"#"
        self.count += 1
        with_newline = self.count % 2 == 1
        return (data + b"\n", True) if with_newline else (data, False)


class RigServer:
    """Serve a :class:`SimulatedRig` over a pseudo-terminal or a loopback TCP socket.

    One thread runs the rig: it reads commands, emits the samples that are due, injects the
    faults of ``faults``, and writes through a non-blocking output queue (nothing is lost to
    a slow reader). A TCP rig keeps running when the host disconnects and accepts the next
    connection; samples emitted meanwhile are counted as undelivered.

    Args:
        rig: The simulated rig.
        transport: ``"pty"`` or ``"tcp"``.
        port: TCP port on 127.0.0.1 (0: any free port).
        faults: Link faults to inject.

    Attributes:
        url: What to pass to ``serial.serial_for_url``: the pty's slave path, or
            ``socket://127.0.0.1:PORT``.
    """

    def __init__(
        self,
        rig: SimulatedRig,
        *,
        transport: str = "tcp",
        port: int = 0,
        faults: FaultPlan | None = None,
    ) -> None:
        if transport not in ("pty", "tcp"):
            raise InputError("transport must be 'pty' or 'tcp'", value=transport)
        self.rig = rig
        self.faults = faults or FaultPlan()
        if transport == "pty" and self.faults.disconnect_after is not None:
            raise InputError("the disconnect fault needs the TCP transport (a pty cannot reopen)")
        self.transport = transport
        self._garbage = _Garbage(self.faults.seed)
        self._queue: deque[_Line] = deque()
        self._partial = b""
        self._input = b""
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._connection: socket.socket | None = None
        self._disconnect_done = False
        self._stall_done = False
        self._partial_lines: list[_Line] = []
        if transport == "pty":
            self._master, self._slave = os.openpty()
            tty.setraw(self._slave)
            os.set_blocking(self._master, False)
            self.url = os.ttyname(self._slave)
        else:
            if not 0 <= port <= 65535:
                raise InputError("the TCP port must be 0 (any free one) to 65535", value=port)
            self._listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            self._listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                self._listener.bind(("127.0.0.1", port))
            except OSError as exc:
                self._listener.close()
                raise InputError(
                    f"cannot listen on 127.0.0.1:{port}: {exc.strerror}; choose another port "
                    "(0: any free one)"
                ) from None
            self._listener.listen(1)
            self._listener.setblocking(False)
            self.url = f"socket://127.0.0.1:{self._listener.getsockname()[1]}"

    @property
    def counters(self) -> RigCounters:
        """The rig's counters."""
        return self.rig.counters

    def start(self) -> RigServer:
        """Run the rig in a background (daemon) thread; returns self."""
        self._thread = threading.Thread(target=self.serve_forever, name="rig-sim", daemon=True)
        self._thread.start()
        return self

    def close(self) -> None:
        """Stop the rig thread and release the pty or socket."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        if self.transport == "pty":
            for fd in (self._master, self._slave):
                with contextlib.suppress(OSError):
                    os.close(fd)
        else:
            self._drop_connection(count=False)
            self._listener.close()

    def __enter__(self) -> RigServer:
        return self.start()

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # -- link -------------------------------------------------------------------------------
    def _connected(self) -> bool:
        return self.transport == "pty" or self._connection is not None

    def _reader(self):
        if self.transport == "pty":
            return self._master
        return self._connection if self._connection is not None else self._listener

    def _writer(self):
        return self._master if self.transport == "pty" else self._connection

    def _drop_connection(self, *, count: bool) -> None:
        if self._connection is None:
            return
        if self._partial:
            self._requeue_partial()
        lost = sum(1 for line in self._queue if line.is_sample)
        if count:
            self.rig.counters.undelivered += lost
        self._queue.clear()
        self._partial = b""
        with contextlib.suppress(OSError):
            self._connection.shutdown(socket.SHUT_RDWR)
        self._connection.close()
        self._connection = None

    def _inject(self, line: _Line, number: int) -> list[_Line]:
        faults = self.faults
        counters = self.rig.counters
        if faults.drop_every and number % faults.drop_every == 0:
            counters.dropped += 1
            return []
        out = []
        if faults.corrupt_every and number % faults.corrupt_every == 0:
            line = _Line(
                line.data[:-3] + (b"0" if line.data[-3:-2] != b"0" else b"1") + b"\r\n",
                True,
                corrupt=True,
            )
        if faults.split_every and number % faults.split_every == 0:
            line.split = True
        out.append(line)
        if faults.garbage_every and number % faults.garbage_every == 0:
            burst, newline = self._garbage.burst()
            out.append(_Line(burst, False))
            if newline:
                counters.garbage_lines += 1
            else:
                counters.garbage_glued += 1
        return out

    def _write_pending(self) -> None:
        writer = self._writer()
        if writer is None:
            return
        counters = self.rig.counters
        while self._queue or self._partial:
            if not self._partial:
                line = self._queue[0]
                if line.split:
                    half = len(line.data) // 2
                    if not self._send_all(line.data[:half]):
                        self._drop_connection(count=True)
                        return
                    time.sleep(self.faults.split_pause_s)
                    self.rig.freeze(self.faults.split_pause_s)
                    self._queue[0] = _Line(line.data[half:], line.is_sample, line.corrupt)
                    counters.split_lines += 1
                    continue
                chunk = []
                while self._queue and not self._queue[0].split and len(chunk) < 512:
                    chunk.append(self._queue.popleft())
                self._partial = b"".join(item.data for item in chunk)
                self._partial_lines = chunk
            try:
                sent = (
                    os.write(writer, self._partial)
                    if self.transport == "pty"
                    else writer.send(self._partial)
                )
            except BlockingIOError:
                return
            except OSError as exc:
                if exc.errno in (errno.EAGAIN, errno.EWOULDBLOCK):
                    return
                self._requeue_partial()
                self._drop_connection(count=True)
                return
            self._partial = self._partial[sent:]
            if self._partial:
                self._requeue_partial()
                return
            for item in self._partial_lines:
                if item.is_sample:
                    counters.delivered += 1
                    if item.corrupt:
                        counters.corrupted += 1
            self._partial_lines = []

    def _requeue_partial(self) -> None:
        """Put the unsent lines of a partly sent chunk back at the head of the queue."""
        remaining = len(self._partial)
        counters = self.rig.counters
        keep: list[_Line] = []
        for item in reversed(self._partial_lines):
            if remaining <= 0:
                if item.is_sample:
                    counters.delivered += 1
                    if item.corrupt:
                        counters.corrupted += 1
                continue
            if remaining >= len(item.data):
                keep.append(item)
                remaining -= len(item.data)
            else:
                tail = item.data[len(item.data) - remaining :]
                keep.append(_Line(tail, item.is_sample, item.corrupt))
                remaining = 0
        self._queue.extendleft(keep)
        self._partial = b""
        self._partial_lines = []

    def _send_all(self, data: bytes) -> bool:
        """Write all of ``data`` (blocking); False when the link failed."""
        writer = self._writer()
        while data:
            try:
                sent = os.write(writer, data) if self.transport == "pty" else writer.send(data)
                data = data[sent:]
            except BlockingIOError:
                select.select([], [writer], [], 0.05)
            except OSError:
                return False
        return True

    # -- main loop --------------------------------------------------------------------------
    def serve_forever(self) -> None:
        """Run the rig until :meth:`close` (or Ctrl-C in the foreground)."""
        rig = self.rig
        while not self._stop.is_set():
            self._emit()
            if self._stop.is_set():
                break
            writer = self._writer()
            wait = rig.next_due_wall_s()
            timeout = 0.05 if wait is None else min(wait, 0.05)
            if self._queue or self._partial:
                timeout = min(timeout, 0.01)
            writers = [writer] if writer is not None and (self._queue or self._partial) else []
            try:
                readable, writable, _ = select.select([self._reader()], writers, [], timeout)
            except (OSError, ValueError):
                readable, writable = [], []
            if readable:
                self._read()
            if writable or (self._queue and writer is not None):
                self._write_pending()

    def _emit(self) -> None:
        rig = self.rig
        if rig.motion is None:
            return
        backlog = len(self._queue)
        if backlog > 4096:
            return
        lines = rig.due_lines(2048)
        counters = rig.counters
        # Session number (1-based) of the first sample in this batch.
        number = counters.emitted - sum(1 for _, is_sample in lines if is_sample)
        for data, is_sample in lines:
            if not is_sample:
                if self._connected():
                    self._queue.append(_Line(data, False))
                continue
            number += 1
            if not self._connected():
                counters.undelivered += 1
                continue
            self._queue.extend(self._inject(_Line(data, True), number))
            self._after_sample(number)

    def _after_sample(self, number: int) -> None:
        faults = self.faults
        if (
            faults.disconnect_after is not None
            and not self._disconnect_done
            and number >= faults.disconnect_after
        ):
            self._disconnect_done = True
            self._write_pending()
            self.rig.counters.disconnects += 1
            self._drop_connection(count=True)
        if faults.stall_after is not None and not self._stall_done and number >= faults.stall_after:
            self._stall_done = True
            self._write_pending()
            self.rig.counters.stalls += 1
            if math.isinf(faults.stall_s):
                self._stop.wait()
                return
            self._stop.wait(faults.stall_s)
            self.rig.freeze(faults.stall_s)

    def _read(self) -> None:
        if self.transport == "tcp" and self._connection is None:
            try:
                connection, _ = self._listener.accept()
            except BlockingIOError:
                return
            connection.setblocking(False)
            connection.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._connection = connection
            self._input = b""
            return
        try:
            data = (
                os.read(self._master, 4096)
                if self.transport == "pty"
                else self._connection.recv(4096)
            )
        except BlockingIOError:
            return
        except OSError:
            data = b""
        if not data:
            if self.transport == "tcp":
                self._drop_connection(count=True)
            return
        self._input += data
        while b"\n" in self._input or b"\r" in self._input:
            cut = min(i for i in (self._input.find(b"\n"), self._input.find(b"\r")) if i >= 0)
            line, self._input = self._input[:cut], self._input[cut + 1 :]
            for reply in self.rig.handle_line(line):
                self._queue.append(_Line(reply, False))
        self._write_pending()
