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
from dataclasses import dataclass

import numpy as np

from warptissue.acquisition._rig import (  # noqa: F401
    RigConfig,
    RigCounters,
    SimulatedRig,
    move_duration_s,
    trapezoid_position,
)
from warptissue.acquisition._tissue import (  # noqa: F401
    ForceCurveTissue,
    PhysiologicalDisturbance,
    TissueModel,
)
from warptissue.errors import InputError

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
class _Line:
    data: bytes
    is_sample: bool
    corrupt: bool = False
    split: bool = False


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
