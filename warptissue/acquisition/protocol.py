"""The indentation rig's ASCII line protocol: framing, checksums, messages and quantities.

Every line is framed like an NMEA sentence but carries a CRC-16 instead of an XOR byte::

    $<body>*<CRC>\\r\\n

``body`` is printable ASCII (0x20-0x7E) without ``$`` and ``*``; its comma-separated fields
start with a message type. ``CRC`` is CRC-16/CCITT-FALSE (polynomial 0x1021, initial value
0xFFFF, no reflection, no final XOR) of the body's bytes, written as four hexadecimal digits.
The check value of ``123456789`` is ``29B1``. The full specification, written for the firmware
side, is ``docs/rig-protocol.md``.

Rig to host: ``S`` (a streamed sample), ``OK`` (a command's reply), ``ERR`` (a refused
command, with a numeric code) and ``DONE`` (end of a motion, with the number of samples the
rig emitted during it). Host to rig: the commands of :data:`COMMANDS`.
"""

from __future__ import annotations

import binascii
import math
import re
from dataclasses import dataclass
from enum import IntEnum

from warptissue.errors import InputError, WarpTissueError

__all__ = [
    "COMMANDS",
    "FORCE_UNITS",
    "LENGTH_UNITS",
    "PROTOCOL_VERSION",
    "Done",
    "ErrorCode",
    "ErrorReply",
    "Message",
    "ProtocolError",
    "Reply",
    "Sample",
    "crc16",
    "format_command",
    "format_done",
    "format_error",
    "format_reply",
    "format_sample",
    "frame",
    "parse_line",
    "parse_quantity",
    "unframe",
]

PROTOCOL_VERSION = "1"
"""Version of the line protocol described in ``docs/rig-protocol.md``."""

LENGTH_UNITS: dict[str, float] = {"um": 1e-6, "mm": 1e-3, "m": 1.0}
"""Length units the rig accepts in ``UNITS``, with their size in metres."""

FORCE_UNITS: dict[str, float] = {"mN": 1e-3, "N": 1.0}
"""Force units the rig accepts in ``UNITS``, with their size in newtons."""

COMMANDS: dict[str, int] = {
    "IDN": 0,
    "STAT": 0,
    "HOME": 0,
    "ZERO": 0,
    "STOP": 0,
    "UNITS": 2,
    "RATE": 1,
    "SPEED": 1,
    "MOVE": 1,
    "RAMP": 3,
    "SINE": 3,
}
"""Host commands and their number of arguments (RAMP takes an optional fourth, the dwell)."""

OPTIONAL_ARGUMENTS: dict[str, int] = {"RAMP": 1}
"""Commands that take optional trailing arguments, and how many."""


class ErrorCode(IntEnum):
    """Codes of ``ERR`` replies."""

    UNKNOWN_COMMAND = 1
    BAD_CHECKSUM = 2
    BAD_ARGUMENT = 3
    OUT_OF_RANGE = 4
    BUSY = 5
    NOT_HOMED = 6
    FAULT = 7


class ProtocolError(WarpTissueError):
    """A line that cannot be accepted: garbage, a bad checksum or an unknown message.

    Attributes:
        kind: ``"garbage"`` (no frame, bad characters), ``"checksum"`` (frame intact, CRC
            wrong) or ``"message"`` (valid frame, unknown or malformed content).
        line: The offending raw line.
    """

    def __init__(self, message: str, *, kind: str, line: bytes) -> None:
        self.kind = kind
        self.line = line
        super().__init__(f"{message}: {line[:80]!r}")


def crc16(data: bytes) -> int:
    """CRC-16/CCITT-FALSE of ``data`` (poly 0x1021, init 0xFFFF); ``crc16(b"123456789")`` is
    0x29B1."""
    return binascii.crc_hqx(data, 0xFFFF)


_BODY_CHARACTERS = re.compile(rb"^[\x20-\x23\x25-\x29\x2b-\x7e]*$")


def frame(body: str) -> bytes:
    """Frame a message body as ``$body*CRC\\r\\n``.

    Raises:
        ValueError: The body holds a character outside printable ASCII, ``$`` or ``*``.
    """
    data = body.encode("ascii")
    if not _BODY_CHARACTERS.match(data):
        raise ValueError(f"message body holds a forbidden character: {body!r}")
    return b"$" + data + b"*" + f"{crc16(data):04X}".encode("ascii") + b"\r\n"


def unframe(line: bytes) -> str:
    """Check a framed line and return its body.

    Bytes before the last ``$`` are noise from a resynchronising link and are ignored, so a
    sample glued to a burst of garbage is still recovered. The CRC's hex digits may be upper
    or lower case. A trailing CR, LF or CRLF is allowed.

    Raises:
        ProtocolError: kind ``"garbage"`` when there is no well-formed frame, ``"checksum"``
            when the frame is intact and the CRC does not match.
    """
    stripped = line.rstrip(b"\r\n")
    start = stripped.rfind(b"$")
    if start < 0:
        raise ProtocolError("no '$' frame start", kind="garbage", line=line)
    framed = stripped[start + 1 :]
    star = framed.rfind(b"*")
    if star < 0 or len(framed) - star - 1 != 4:
        raise ProtocolError("no '*CRC' frame end", kind="garbage", line=line)
    body, digits = framed[:star], framed[star + 1 :]
    if not _BODY_CHARACTERS.match(body) or not re.fullmatch(rb"[0-9A-Fa-f]{4}", digits):
        raise ProtocolError("forbidden character in frame", kind="garbage", line=line)
    if int(digits, 16) != crc16(body):
        raise ProtocolError(
            f"CRC mismatch (line says {digits.decode()}, body gives {crc16(body):04X})",
            kind="checksum",
            line=line,
        )
    return body.decode("ascii")


@dataclass(frozen=True)
class Sample:
    """One streamed sample, in the units configured with ``UNITS`` (wire units).

    Attributes:
        sequence: Sample counter, 0 at the first sample of each motion command.
        time_us: Rig time since the motion command started, microseconds.
        position: Axis position (positive toward the specimen), configured length unit.
        force: Force on the probe (positive when pushing into the specimen), configured
            force unit.
        position_text: ``position`` exactly as transmitted.
        force_text: ``force`` exactly as transmitted.
    """

    sequence: int
    time_us: int
    position: float
    force: float
    position_text: str = ""
    force_text: str = ""


@dataclass(frozen=True)
class Reply:
    """An ``OK`` reply: the command it answers and its result fields."""

    command: str
    fields: tuple[str, ...] = ()


@dataclass(frozen=True)
class ErrorReply:
    """An ``ERR`` reply: the numeric code, the command it refuses and a human-readable text."""

    code: int
    command: str
    text: str


@dataclass(frozen=True)
class Done:
    """End of a motion: the command, the number of samples emitted and how it ended.

    ``status`` is ``OK`` (completed), ``STOPPED`` (a STOP ended it) or ``FAULT``.
    """

    command: str
    samples: int
    status: str


Message = Sample | Reply | ErrorReply | Done


def _number(text: str, line: bytes) -> float:
    try:
        value = float(text)
    except ValueError:
        raise ProtocolError(f"not a number: {text!r}", kind="message", line=line) from None
    if not math.isfinite(value):
        raise ProtocolError(f"not a finite number: {text!r}", kind="message", line=line)
    return value


def _integer(text: str, line: bytes) -> int:
    if not re.fullmatch(r"[0-9]{1,12}", text):
        raise ProtocolError(f"not a non-negative integer: {text!r}", kind="message", line=line)
    return int(text)


def parse_line(line: bytes) -> Message:
    """Parse one line from the rig.

    Args:
        line: The raw bytes of one line, with or without its line ending.

    Returns:
        The message.

    Raises:
        ProtocolError: Garbage, a CRC mismatch, or a well-framed line whose content is not a
            valid rig message (the error's ``kind`` says which).
    """
    fields = unframe(line).split(",")
    kind = fields[0]
    if kind == "S":
        if len(fields) != 5:
            raise ProtocolError("a sample has 5 fields", kind="message", line=line)
        return Sample(
            sequence=_integer(fields[1], line),
            time_us=_integer(fields[2], line),
            position=_number(fields[3], line),
            force=_number(fields[4], line),
            position_text=fields[3],
            force_text=fields[4],
        )
    if kind == "OK" and len(fields) >= 2:
        return Reply(command=fields[1], fields=tuple(fields[2:]))
    if kind == "ERR" and len(fields) >= 3:
        return ErrorReply(
            code=_integer(fields[1], line), command=fields[2], text=",".join(fields[3:])
        )
    if kind == "DONE" and len(fields) == 4:
        return Done(command=fields[1], samples=_integer(fields[2], line), status=fields[3])
    raise ProtocolError(f"unknown or malformed message {kind!r}", kind="message", line=line)


def format_sample(sample: Sample) -> bytes:
    """Frame a sample: ``$S,<sequence>,<time_us>,<position>,<force>*CRC``.

    Position and force are written with the text in ``position_text``/``force_text`` when
    given, else with 6 significant decimals (``%.6g`` is not used: a fixed number of decimals
    keeps the line length steady).
    """
    position = sample.position_text or f"{sample.position:.4f}"
    force = sample.force_text or f"{sample.force:.4f}"
    return frame(f"S,{sample.sequence},{sample.time_us},{position},{force}")


def format_reply(command: str, *fields: str) -> bytes:
    """Frame an ``OK`` reply to ``command``."""
    return frame(",".join(("OK", command, *fields)))


def _printable(text: str) -> str:
    """``text`` with every character a frame cannot carry replaced by ``?``."""
    return "".join(c if " " <= c <= "~" and c not in "$*" else "?" for c in text)


def format_error(code: ErrorCode, command: str, text: str) -> bytes:
    """Frame an ``ERR`` reply. Characters a frame cannot carry (in an echoed command or the
    text) become ``?``; commas are allowed in ``text`` only."""
    name = _printable(command).replace(",", "?") or "?"
    return frame(f"ERR,{int(code)},{name},{_printable(text)}")


def format_done(command: str, samples: int, status: str) -> bytes:
    """Frame a ``DONE`` line closing a motion."""
    return frame(f"DONE,{command},{samples},{status}")


def format_command(command: str, *arguments: float | str) -> bytes:
    """Frame a host command, for example ``format_command("RAMP", 4, 8, 10)``.

    Numbers are written with ``repr`` of the float (shortest exact decimal).
    """
    if command not in COMMANDS:
        raise ValueError(f"unknown rig command {command!r}")
    texts = [a if isinstance(a, str) else repr(float(a)) for a in arguments]
    return frame(",".join((command, *texts)))


_QUANTITY_UNITS: dict[str, dict[str, float]] = {
    "length": {"m": 1.0, "mm": 1e-3, "um": 1e-6, "µm": 1e-6},
    "speed": {"m/s": 1.0, "mm/s": 1e-3, "um/s": 1e-6, "µm/s": 1e-6, "mm/min": 1e-3 / 60.0},
    "time": {"s": 1.0, "ms": 1e-3, "min": 60.0},
    "frequency": {"Hz": 1.0, "kHz": 1e3},
    "stiffness": {"N/m": 1.0, "N/mm": 1e3, "mN/mm": 1.0},
    "force": {"N": 1.0, "mN": 1e-3},
}
_QUANTITY = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([^\s\d].*?)?\s*$")


def parse_quantity(text: str, kind: str, *, name: str = "value") -> float:
    """Parse a number with a unit suffix into SI units.

    Args:
        text: For example ``"4mm"``, ``"8 mm/s"``, ``"100s"``, ``"250ms"``, ``"1kHz"``.
        kind: ``"length"``, ``"speed"``, ``"time"``, ``"frequency"``, ``"stiffness"`` or
            ``"force"``; selects the accepted units.
        name: What the value is (an option name), used in error messages.

    Returns:
        The value in metres, metres per second, seconds, hertz, newtons per metre or newtons.

    Raises:
        InputError: No number, a missing or unknown unit, or a non-finite value. The message
            names ``name``, the text and the accepted units.
    """
    units = _QUANTITY_UNITS[kind]
    match = _QUANTITY.match(text)
    accepted = ", ".join(units)
    if match is None:
        raise InputError(f"{name}: not a {kind} with a unit ({accepted})", value=text)
    number, unit = match.group(1), match.group(2)
    if unit is None or unit not in units:
        raise InputError(
            f"{name}: {'missing' if unit is None else 'unknown'} unit; use one of {accepted}",
            value=text,
        )
    value = float(number) * units[unit]
    if not math.isfinite(value):
        raise InputError(f"{name}: not a finite number", value=text)
    return value
