"""The simulated rig's mechanics and sensor, apart from its link: :class:`SimulatedRig` moves
the probe along trapezoid profiles (:func:`trapezoid_position`) and samples the force with
the sensor effects of its :class:`RigConfig`. :class:`warptissue.acquisition.simulator.RigServer`
serves it over a pty or a socket.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from warptissue.acquisition import protocol as wire
from warptissue.acquisition._tissue import PhysiologicalDisturbance, TissueModel


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
