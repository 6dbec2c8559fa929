"""The rig line protocol: CRC, framing, messages, quantities; property tests of the parser."""

from __future__ import annotations

import math
import re

import pytest
from hypothesis import given
from hypothesis import strategies as st

from warptissue.acquisition import protocol as wire
from warptissue.errors import InputError


def crc16_bitwise(data: bytes) -> int:
    """CRC-16/CCITT-FALSE written out bit by bit (independent of binascii)."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) if crc & 0x8000 else (crc << 1)
            crc &= 0xFFFF
    return crc


def test_crc_check_value_and_bitwise_reference():
    assert wire.crc16(b"123456789") == 0x29B1
    for text in (b"", b"S,0,0,0.0000,1.4000", b"OK,IDN,warptissue,rig-sim,SIM0001,1.0,P1"):
        assert wire.crc16(text) == crc16_bitwise(text)


def test_documented_example_line():
    # The example in docs/rig-protocol.md.
    line = wire.format_sample(
        wire.Sample(12, 12000, 0.0960, 3.5000, position_text="0.0960", force_text="3.5000")
    )
    assert (
        line
        == b"$S,12,12000,0.0960,3.5000*"
        + b"%04X" % crc16_bitwise(b"S,12,12000,0.0960,3.5000")
        + b"\r\n"
    )
    assert line == b"$S,12,12000,0.0960,3.5000*E465\r\n"
    sample = wire.parse_line(line)
    assert sample == wire.Sample(12, 12000, 0.096, 3.5, "0.0960", "3.5000")


def test_message_kinds_round_trip():
    assert wire.parse_line(wire.format_reply("RATE", "1000")) == wire.Reply("RATE", ("1000",))
    assert wire.parse_line(wire.format_error(wire.ErrorCode.BUSY, "RAMP", "motion, busy")) == (
        wire.ErrorReply(5, "RAMP", "motion, busy")
    )
    assert wire.parse_line(wire.format_done("RAMP", 5501, "OK")) == wire.Done("RAMP", 5501, "OK")
    command = wire.format_command("RAMP", 4, 8, 100, 0.5)
    assert wire.unframe(command) == "RAMP,4.0,8.0,100.0,0.5"


@pytest.mark.parametrize(
    ("line", "kind"),
    [
        (b"no frame at all\r\n", "garbage"),
        (b"$S,1,2,3,4\r\n", "garbage"),
        (b"$S,1,2,3,4*12\r\n", "garbage"),
        (b"$S,1,2,3,4*0000\r\n", "checksum"),
        (wire.frame("S,1,2,3"), "message"),
        (wire.frame("S,-1,2,3,4"), "message"),
        (wire.frame("S,1,2,nan,4"), "message"),
        (wire.frame("HELLO,1"), "message"),
    ],
)
def test_bad_lines_are_classified(line, kind):
    with pytest.raises(wire.ProtocolError) as caught:
        wire.parse_line(line)
    assert caught.value.kind == kind


def test_noise_before_the_frame_is_skipped():
    line = b"\xff\x13garbage" + wire.format_done("HOME", 3, "OK")
    assert wire.parse_line(line) == wire.Done("HOME", 3, "OK")


body_text = st.text(
    alphabet=st.characters(min_codepoint=0x20, max_codepoint=0x7E, blacklist_characters="$*"),
    max_size=80,
)


@given(body_text)
def test_frame_unframe_round_trip(body):
    assert wire.unframe(wire.frame(body)) == body


@given(body_text, st.data())
def test_any_single_byte_change_is_detected(body, data):
    line = wire.frame(body)
    content_end = len(line) - 2  # keep CR LF
    position = data.draw(st.integers(0, content_end - 1))
    replacement = data.draw(st.integers(0, 255).filter(lambda b: b != line[position]))
    mutated = line[:position] + bytes([replacement]) + line[position + 1 :]
    try:
        result = wire.unframe(mutated)
    except wire.ProtocolError:
        return
    # Accepted only when the change is the case of a CRC hex digit, or a '$' turned the
    # head into noise before an identical frame (impossible here: no '$' in the body).
    assert result == body
    assert mutated[position : position + 1].upper() == line[position : position + 1].upper()


@given(st.binary(max_size=200))
def test_arbitrary_bytes_only_raise_protocol_errors(data):
    try:
        wire.parse_line(data)
    except wire.ProtocolError:
        pass


@given(
    st.integers(0, 10**9),
    st.integers(0, 10**11),
    st.floats(-1e6, 1e6, allow_nan=False),
    st.floats(-1e6, 1e6, allow_nan=False),
)
def test_sample_round_trip(sequence, time_us, position, force):
    sample = wire.Sample(sequence, time_us, position, force, f"{position:.4f}", f"{force:.4f}")
    parsed = wire.parse_line(wire.format_sample(sample))
    assert (parsed.sequence, parsed.time_us) == (sequence, time_us)
    assert math.isclose(parsed.position, float(f"{position:.4f}"))
    assert math.isclose(parsed.force, float(f"{force:.4f}"))


@pytest.mark.parametrize(
    ("text", "kind", "expected"),
    [
        ("4mm", "length", 4e-3),
        ("250 um", "length", 250e-6),
        ("0.5m", "length", 0.5),
        ("8mm/s", "speed", 8e-3),
        ("20mm/min", "speed", 20e-3 / 60),
        ("100s", "time", 100.0),
        ("250ms", "time", 0.25),
        ("1kHz", "frequency", 1000.0),
        ("1e3Hz", "frequency", 1000.0),
        ("0.008N/mm", "stiffness", 8.0),
        ("2mN", "force", 2e-3),
    ],
)
def test_parse_quantity(text, kind, expected):
    assert math.isclose(wire.parse_quantity(text, kind), expected, rel_tol=1e-12)


@pytest.mark.parametrize(("text", "fragment"), [("4", "missing unit"), ("4 furlongs", "unknown")])
def test_parse_quantity_errors_name_the_value(text, fragment):
    with pytest.raises(InputError, match=fragment) as caught:
        wire.parse_quantity(text, "length", name="--depth")
    assert "--depth" in str(caught.value) and repr(text) in str(caught.value)


def test_every_example_line_in_the_protocol_document_checks_out():
    from pathlib import Path

    document = Path(__file__).resolve().parents[1] / "docs" / "rig-protocol.md"
    examples = re.findall(r"^(\$[^*\n]*\*[0-9A-F]{4})", document.read_text(), re.MULTILINE)
    assert len(examples) >= 10
    for line in examples:
        wire.unframe(line.encode("ascii"))
