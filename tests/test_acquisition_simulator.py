"""The simulated rig's firmware: motion profiles, commands and error codes, the transducer."""

from __future__ import annotations

import math

import numpy as np
import pytest
from _sls_reference import ReferenceSLS
from hypothesis import given, settings
from hypothesis import strategies as st

from warptissue.acquisition import protocol as wire
from warptissue.acquisition.simulator import (
    FaultPlan,
    ForceCurveTissue,
    RigConfig,
    SimulatedRig,
    move_duration_s,
    trapezoid_position,
)
from warptissue.errors import InputError
from warptissue.io import write_csv


def make_rig(**config) -> SimulatedRig:
    return SimulatedRig(ReferenceSLS(40.0, 20.0, 2.0), RigConfig(time_scale=math.inf, **config))


def reply(rig: SimulatedRig, line: bytes) -> list[wire.Message]:
    return [wire.parse_line(out) for out in rig.handle_line(line)]


def samples(rig: SimulatedRig) -> list[wire.Sample]:
    lines = rig.due_lines(10**7)
    return [wire.parse_line(line) for line, is_sample in lines if is_sample]


@pytest.mark.parametrize(("distance", "speed"), [(4e-3, 8e-3), (0.1e-3, 8e-3), (-2e-3, 5e-3)])
def test_trapezoid_profile(distance, speed):
    acceleration = 0.2
    duration = move_duration_s(distance, speed, acceleration)
    time = np.linspace(-0.1, duration + 0.1, 200001)
    position = trapezoid_position(time, distance, speed, acceleration)
    velocity = np.gradient(position, time)
    assert position[0] == 0.0 and position[-1] == pytest.approx(distance, abs=1e-15)
    assert np.max(np.abs(velocity)) <= speed * (1 + 1e-6)
    assert np.max(np.abs(np.gradient(velocity, time))) <= acceleration * 1.01
    reached = np.flatnonzero(np.abs(position - distance) < 1e-12)[0]
    assert time[reached] == pytest.approx(duration, abs=1e-5)


def test_commands_and_error_codes():
    rig = make_rig()
    assert reply(rig, b"IDN")[0].fields[:2] == ("warptissue", "rig-sim")
    assert reply(rig, b"$RATE,2000*0000")[0].code == wire.ErrorCode.BAD_CHECKSUM
    assert reply(rig, wire.format_command("RATE", 2000))[0].code == wire.ErrorCode.OUT_OF_RANGE
    assert reply(rig, b"JUMP 3")[0].code == wire.ErrorCode.UNKNOWN_COMMAND
    assert reply(rig, b"RAMP 4 8")[0].code == wire.ErrorCode.BAD_ARGUMENT
    assert reply(rig, b"RAMP 4 nine 1")[0].code == wire.ErrorCode.BAD_ARGUMENT
    assert reply(rig, b"RAMP 4 9 1")[0].code == wire.ErrorCode.OUT_OF_RANGE  # above 8 mm/s
    assert reply(rig, b"MOVE 42")[0].code == wire.ErrorCode.OUT_OF_RANGE  # travel 41.5 mm
    assert reply(rig, b"SINE 1 2 3")[0].code == wire.ErrorCode.OUT_OF_RANGE  # 12.6 mm/s peak
    assert reply(rig, b"RATE 500") == [wire.Reply("RATE", ("500",))]
    assert reply(rig, wire.format_command("RAMP", 1, 8, 1)) == [wire.Reply("RAMP")]
    assert reply(rig, b"RATE 100")[0].code == wire.ErrorCode.BUSY
    status = reply(rig, b"STAT")[0]
    assert status.fields[0] == "MOVING"
    stopped = reply(rig, b"STOP")
    assert stopped[0] == wire.Reply("STOP")
    assert stopped[1] == wire.Done("RAMP", 0, "STOPPED")
    assert reply(rig, b"STAT")[0].fields[:2] == ("IDLE", "0")


def test_ramp_stream_units_quantization_and_done():
    rig = make_rig(surface_position_m=0.0, force_noise_N=0.0)
    reply(rig, b"UNITS um mN")
    reply(rig, b"RATE 1000")
    reply(rig, b"RAMP 2000 8000 0.5 0.1")  # um and um/s
    lines = rig.due_lines(10**7)
    done = wire.parse_line(lines[-1][0])
    stream = [wire.parse_line(line) for line, is_sample in lines if is_sample]
    duration = 0.1 + move_duration_s(2e-3, 8e-3, 0.2) + 0.5
    assert len(stream) == done.samples == math.floor(duration * 1000 + 1e-9) + 1
    assert [s.sequence for s in stream] == list(range(len(stream)))
    assert np.all(np.diff([s.time_us for s in stream]) == 1000)
    assert stream[-1].position == pytest.approx(2000.0)  # micrometres
    forces = np.array([s.force for s in stream]) / 0.7  # in units of the 0.7 mN resolution
    np.testing.assert_allclose(forces, np.round(forces), atol=1e-3)
    expected = ReferenceSLS(40.0, 20.0, 2.0).force_N(
        np.array([s.time_us for s in stream]) * 1e-6,
        np.array([s.position for s in stream]) * 1e-6,
    )
    np.testing.assert_allclose(np.array([s.force for s in stream]) * 1e-3, expected, atol=0.36e-3)


def test_zero_tares_the_offset():
    rig = make_rig(force_offset_N=5e-3, force_noise_N=0.0)
    reply(rig, b"ZERO")
    reply(rig, b"RAMP 0.2 8 0.1")
    forces = [s.force for s in samples(rig)]
    assert max(abs(f) for f in forces) < 0.71  # in air: zero within one quantum


def test_noise_level(rng):
    rig = make_rig(force_noise_N=2e-3, surface_position_m=10e-3)
    reply(rig, b"RAMP 1 8 2")
    forces = np.array([s.force for s in samples(rig)]) * 1e-3
    assert np.std(forces) == pytest.approx(np.sqrt(2e-3**2 + 0.7e-3**2 / 12), rel=0.1)


def test_force_curve_tissue(tmp_path):
    path = write_csv(
        tmp_path / "curve.csv", {"displacement_m": [1e-3, 2e-3], "force_N": [0.01, 0.03]}
    )
    tissue = ForceCurveTissue.from_csv(path)
    force = tissue.force_N(np.zeros(4), np.array([-1e-3, 0.5e-3, 1.5e-3, 3e-3]))
    np.testing.assert_allclose(force, [0.0, 0.005, 0.02, 0.03])


def test_fault_plan_parse():
    plan = FaultPlan.parse("garbage=200, corrupt=300,disconnect=1000,stall=50,stall_s=1.5")
    assert (plan.garbage_every, plan.corrupt_every, plan.disconnect_after) == (200, 300, 1000)
    assert (plan.stall_after, plan.stall_s) == (50, 1.5)
    with pytest.raises(InputError, match="unknown fault"):
        FaultPlan.parse("meteor=1")
    with pytest.raises(InputError, match="not a number"):
        FaultPlan.parse("drop=often")


def test_stop_keeps_only_the_executed_motion_in_the_tissue_history():
    rig = make_rig(surface_position_m=0.0, force_noise_N=0.0, force_resolution_N=1e-9)
    reply(rig, b"RAMP 4 8 10")
    first = rig.due_lines(200)  # 200 samples, 0.199 s: 1.6 mm down at most
    assert len(first) == 200
    reply(rig, b"STOP")
    depth = rig.position_m
    assert 1e-3 < depth < 1.6e-3
    reply(rig, b"MOVE %f" % (depth * 1e3))  # a null move: rest at the stop depth
    rest = samples(rig)
    # Relaxation from the force reached at the stop, not from a 4 mm ramp that never ran.
    assert rest[0].force * 1e-3 < 40.0 * depth * 1.001
    assert rest[0].force * 1e-3 > 20.0 * depth


@given(st.binary(max_size=80))
@settings(max_examples=200, deadline=None)
def test_any_command_line_gets_a_valid_reply_and_never_crashes_the_rig(line):
    rig = make_rig()
    for out in rig.handle_line(line.replace(b"\n", b" ").replace(b"\r", b" ")):
        assert isinstance(wire.parse_line(out), wire.Reply | wire.ErrorReply | wire.Done)
