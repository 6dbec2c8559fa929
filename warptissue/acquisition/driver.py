"""The host side of the rig's line protocol, over any pyserial URL.

:class:`RigClient` opens its port with ``serial.serial_for_url``, so the same code reaches a
real serial port (``/dev/ttyUSB0``, ``COM3``), a pty, ``socket://host:port``,
``rfc2217://host:port`` and ``loop://``. It reads with a short timeout into its own line
buffer (a line split across reads is joined, never lost), validates every line (garbage and
CRC failures are counted in :class:`LinkCounters` and skipped), reopens the port after a
disconnect, and, used as a context manager, stops the rig on the way out, Ctrl-C included.
"""

from __future__ import annotations

import contextlib
import socket
import struct
import time
from collections import deque
from dataclasses import asdict, dataclass

import serial
from serial.urlhandler import protocol_socket

from warptissue.acquisition import protocol as wire

try:  # POSIX: exact byte counts for sockets (see RigClient._available)
    import fcntl
    import termios
except ImportError:  # pragma: no cover - Windows
    fcntl = termios = None
from warptissue.errors import DeviceError

__all__ = ["CommandRefused", "LinkCounters", "LinkLost", "RigClient", "parse_status"]


class LinkLost(DeviceError):
    """The port closed or failed (the device disconnected, or the cable was pulled)."""


class CommandRefused(DeviceError):
    """The rig answered ``ERR``.

    Attributes:
        reply: The error reply (code, command, text).
    """

    def __init__(self, reply: wire.ErrorReply) -> None:
        self.reply = reply
        name = (
            wire.ErrorCode(reply.code).name
            if reply.code in wire.ErrorCode._value2member_map_
            else "?"
        )
        super().__init__(f"rig refused {reply.command}: error {reply.code} ({name}) {reply.text}")


@dataclass
class LinkCounters:
    """What the client saw on the link.

    Attributes:
        lines: Lines read (complete, newline-terminated, or overlong).
        garbage_lines: Lines with no valid frame (skipped).
        resynchronised_lines: Valid lines that had noise before their ``$`` (kept).
        checksum_errors: Lines whose CRC did not match (skipped).
        malformed_lines: Valid frames with content that is not a rig message (skipped).
        error_replies: ``ERR`` replies received.
        reconnections: Successful reopenings of the port.
    """

    lines: int = 0
    garbage_lines: int = 0
    resynchronised_lines: int = 0
    checksum_errors: int = 0
    malformed_lines: int = 0
    error_replies: int = 0
    reconnections: int = 0

    def to_dict(self) -> dict[str, int]:
        """The counters as a plain mapping."""
        return asdict(self)


class RigClient:
    """A connection to an indentation rig (or its simulation).

    Args:
        url: A port name or pyserial URL (``/dev/ttyACM0``, ``socket://127.0.0.1:5025``,
            ``rfc2217://rig.local:4000``, ``loop://``).
        baudrate: Serial speed (ignored by sockets and ptys).
        read_timeout_s: Longest single blocking read (s); bounds the latency of
            :meth:`read_message`.
        reply_timeout_s: How long a command waits for its ``OK``/``ERR`` (s).
        reconnect_attempts: How many times :meth:`reconnect` tries to reopen the port.
        reconnect_delay_s: First pause between attempts (s); it doubles after each failure.
        max_line_bytes: A line longer than this without a newline is discarded as garbage.

    Attributes:
        counters: Link counters (garbage, CRC errors, reconnections...).
        pending: Messages read while waiting for a reply (samples, ``DONE``), in order; the
            next :meth:`read_message` calls return them first.
    """

    def __init__(
        self,
        url: str,
        *,
        baudrate: int = 115200,
        read_timeout_s: float = 0.05,
        reply_timeout_s: float = 2.0,
        reconnect_attempts: int = 5,
        reconnect_delay_s: float = 0.1,
        max_line_bytes: int = 512,
    ) -> None:
        self.url = url
        self.baudrate = baudrate
        self.read_timeout_s = read_timeout_s
        self.reply_timeout_s = reply_timeout_s
        self.reconnect_attempts = reconnect_attempts
        self.reconnect_delay_s = reconnect_delay_s
        self.max_line_bytes = max_line_bytes
        self.counters = LinkCounters()
        self.pending: deque[wire.Message] = deque()
        self.length_unit = "mm"
        self.force_unit = "mN"
        self._port: serial.SerialBase | None = None
        self._buffer = bytearray()

    # -- connection ------------------------------------------------------------------------
    def open(self) -> RigClient:
        """Open the port.

        Raises:
            LinkLost: The port cannot be opened.
        """
        options = {"baudrate": self.baudrate, "timeout": self.read_timeout_s}
        if not self.url.startswith("rfc2217://"):  # pyserial's RFC 2217 client has none
            options["write_timeout"] = 2.0
        try:
            if self.url.startswith("socket://"):
                self._port = _KeepingSocket(self.url, **options)
            else:
                self._port = serial.serial_for_url(self.url, **options)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise LinkLost(f"cannot open {self.url}: {exc}") from exc
        self._buffer.clear()
        return self

    @property
    def is_open(self) -> bool:
        """Whether the port is open."""
        return self._port is not None and self._port.is_open

    def close(self) -> None:
        """Close the port (idempotent)."""
        if self._port is not None:
            try:
                self._port.close()
            except (serial.SerialException, OSError):
                pass
        self._port = None

    def reconnect(self) -> bool:
        """Close and reopen the port, with exponential back-off.

        Returns:
            True when the port is open again (``counters.reconnections`` is incremented),
            False after ``reconnect_attempts`` failures.
        """
        self.close()
        delay = self.reconnect_delay_s
        for _ in range(self.reconnect_attempts):
            time.sleep(delay)
            try:
                self.open()
            except LinkLost:
                delay *= 2.0
                continue
            self.counters.reconnections += 1
            return True
        return False

    def __enter__(self) -> RigClient:
        return self if self.is_open else self.open()

    def __exit__(self, exc_type: type[BaseException] | None, *rest: object) -> None:
        """Stop any motion (also on Ctrl-C), flush and close."""
        if self.is_open:
            try:
                self.stop()
            except DeviceError:
                pass
        self.close()

    # -- lines -----------------------------------------------------------------------------
    def send(self, command: str, *arguments: float | str) -> None:
        """Send one framed command (no waiting for its reply).

        Raises:
            LinkLost: The write failed.
        """
        if self._port is None:
            raise LinkLost(f"{self.url} is not open")
        try:
            self._port.write(wire.format_command(command, *arguments))
            self._port.flush()
        except (serial.SerialException, OSError) as exc:
            self.close()
            raise LinkLost(f"write to {self.url} failed: {exc}") from exc

    def _read_line(self) -> bytes | None:
        """One raw line, or None when the read timed out first."""
        while True:
            newline = self._buffer.find(b"\n")
            if newline >= 0:
                line = bytes(self._buffer[: newline + 1])
                del self._buffer[: newline + 1]
                return line
            if len(self._buffer) > self.max_line_bytes:
                line = bytes(self._buffer)
                self._buffer.clear()
                return line
            if self._port is None:
                raise LinkLost(f"{self.url} is not open")
            try:
                data = self._port.read(self._available() or 1)
            except (serial.SerialException, OSError) as exc:
                self.close()
                raise LinkLost(f"read from {self.url} failed: {exc}") from exc
            if not data:
                return None
            self._buffer.extend(data)

    def _available(self) -> int:
        """Bytes waiting in the port's input buffer.

        pyserial's ``socket://`` handler reports only 0 or 1 in ``in_waiting``, and its
        ``read(n)`` discards the bytes it has gathered when the peer closes in the middle of
        the call; asking the kernel (FIONREAD) for the exact count and reading no more than
        that keeps every byte that arrived before a disconnect.
        """
        port = self._port
        assert port is not None
        if fcntl is not None and isinstance(port, protocol_socket.Serial):
            try:
                return struct.unpack("i", fcntl.ioctl(port.fileno(), termios.FIONREAD, b"\0" * 4))[
                    0
                ]
            except OSError:
                return 0
        return port.in_waiting

    def read_message(self) -> wire.Message | None:
        """The next valid message, or None when nothing valid arrived within one read timeout.

        Garbage, CRC failures and malformed frames are counted and skipped.

        Raises:
            LinkLost: The device disconnected.
        """
        if self.pending:
            return self.pending.popleft()
        while True:
            line = self._read_line()
            if line is None:
                return None
            self.counters.lines += 1
            try:
                message = wire.parse_line(line)
            except wire.ProtocolError as exc:
                if exc.kind == "checksum":
                    self.counters.checksum_errors += 1
                elif exc.kind == "garbage":
                    self.counters.garbage_lines += 1
                else:
                    self.counters.malformed_lines += 1
                continue
            if not line.startswith(b"$"):
                self.counters.resynchronised_lines += 1
            if isinstance(message, wire.ErrorReply):
                self.counters.error_replies += 1
            return message

    def command(self, command: str, *arguments: float | str) -> wire.Reply:
        """Send a command and wait for its reply; other messages go to :attr:`pending`.

        Returns:
            The ``OK`` reply.

        Raises:
            CommandRefused: The rig answered ``ERR``.
            DeviceError: No reply within ``reply_timeout_s``.
            LinkLost: The device disconnected.
        """
        self.send(command, *arguments)
        deadline = time.monotonic() + self.reply_timeout_s
        held: list[wire.Message] = []
        try:
            while time.monotonic() < deadline:
                line_message = self._read_message_raw()
                if line_message is None:
                    continue
                if isinstance(line_message, wire.Reply) and line_message.command == command:
                    return line_message
                if isinstance(line_message, wire.ErrorReply) and line_message.command in (
                    command,
                    "?",
                ):
                    raise CommandRefused(line_message)
                held.append(line_message)
        finally:
            self.pending.extend(held)
        raise DeviceError(f"no reply to {command} from {self.url} in {self.reply_timeout_s} s")

    def _read_message_raw(self) -> wire.Message | None:
        saved, self.pending = self.pending, deque()
        try:
            return self.read_message()
        finally:
            saved.extend(self.pending)
            self.pending = saved

    # -- commands in SI units --------------------------------------------------------------
    def _length(self, value_m: float) -> float:
        return value_m / wire.LENGTH_UNITS[self.length_unit]

    def identify(self) -> dict[str, str]:
        """``IDN``: maker, model, serial number, firmware and protocol version."""
        fields = list(self.command("IDN").fields) + [""] * 5
        keys = ("maker", "model", "serial_number", "firmware", "protocol")
        return dict(zip(keys, fields[:5], strict=True))

    def status(self) -> tuple[str, int]:
        """``STAT``: the state (``IDLE`` or ``MOVING``) and the samples of the current or
        last motion."""
        state = parse_status(self.command("STAT"))
        if state is None:
            raise DeviceError(f"malformed STAT reply from {self.url}")
        return state

    def configure(self, *, length_unit: str = "mm", force_unit: str = "mN", rate_Hz: float):
        """``UNITS`` and ``RATE``; sample values are then in these units."""
        self.command("UNITS", length_unit, force_unit)
        self.length_unit, self.force_unit = length_unit, force_unit
        self.command("RATE", rate_Hz)

    def home(self) -> None:
        """``HOME``: start the move to the axis origin (samples stream until ``DONE``)."""
        self.command("HOME")

    def zero_force(self) -> None:
        """``ZERO``: tare the force transducer."""
        self.command("ZERO")

    def move_to(self, position_m: float) -> None:
        """``MOVE``: start a move to ``position_m`` (m)."""
        self.command("MOVE", self._length(position_m))

    def ramp_hold(
        self, *, depth_m: float, speed_m_per_s: float, hold_s: float, dwell_s: float = 0.0
    ) -> None:
        """``RAMP``: after ``dwell_s`` (s) at rest, indent ``depth_m`` (m) further at
        ``speed_m_per_s`` (m/s) and hold ``hold_s`` (s)."""
        self.command("RAMP", self._length(depth_m), self._length(speed_m_per_s), hold_s, dwell_s)

    def sine(self, *, amplitude_m: float, frequency_Hz: float, cycles: float) -> None:
        """``SINE``: oscillate ``amplitude_m`` (m) about the present position."""
        self.command("SINE", self._length(amplitude_m), frequency_Hz, cycles)

    def wait_until_done(self, *, timeout_s: float) -> wire.Done:
        """Read until the running motion's ``DONE`` (its samples are discarded; use
        :class:`~warptissue.acquisition.Recorder` to keep them).

        Raises:
            DeviceError: No ``DONE`` within ``timeout_s``.
        """
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            message = self.read_message()
            if isinstance(message, wire.Done):
                return message
        raise DeviceError(f"motion on {self.url} did not finish within {timeout_s} s")

    def stop(self, *, drain_s: float = 1.0) -> list[wire.Message]:
        """``STOP``: end any motion, then read until its ``DONE`` (or ``drain_s``).

        Returns:
            Messages that arrived meanwhile (samples included), also left in
            :attr:`pending` so that a recorder can still save them.
        """
        self.send("STOP")
        deadline = time.monotonic() + drain_s
        seen: list[wire.Message] = []
        stopped = False
        while time.monotonic() < deadline:
            message = self._read_message_raw()
            if message is None:
                if stopped:
                    break
                continue
            seen.append(message)
            if isinstance(message, wire.Reply) and message.command == "STOP":
                stopped = True
            if isinstance(message, wire.Done):
                break
        self.pending.extend(seen)
        return seen


class _KeepingSocket(protocol_socket.Serial):
    """pyserial's ``socket://`` port, less two things a rig link cannot afford.

    Its ``open()`` ends with ``reset_input_buffer()``, which reads and discards whatever the
    peer sent between the connection and that call: a rig keeps streaming across a link
    reset (docs/rig-protocol.md), so its first samples after a reconnect would be lost. And
    its ``close()`` sleeps 0.3 s "to give the server some time"; :meth:`RigClient.reconnect`
    has its own back-off. This port keeps every byte that arrives once connected, and closes
    at once.
    """

    _opening = False

    def open(self) -> None:
        """Connect; nothing that arrives meanwhile is discarded."""
        self._opening = True
        try:
            super().open()
        finally:
            self._opening = False

    def reset_input_buffer(self) -> None:
        """Discard pending input, except while opening (see the class docstring)."""
        if not self._opening:
            super().reset_input_buffer()

    def close(self) -> None:
        """Close the socket (idempotent), without pyserial's 0.3 s pause."""
        if self.is_open:
            if self._socket is not None:
                with contextlib.suppress(OSError):
                    self._socket.shutdown(socket.SHUT_RDWR)
                with contextlib.suppress(OSError):
                    self._socket.close()
                self._socket = None
            self.is_open = False


def parse_status(reply: wire.Reply) -> tuple[str, int] | None:
    """State and sample count of a ``STAT`` reply, or None when it is malformed."""
    fields = reply.fields
    if len(fields) < 2 or fields[0] not in ("IDLE", "MOVING") or not fields[1].isdigit():
        return None
    return fields[0], int(fields[1])
