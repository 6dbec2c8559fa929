"""The pyserial driver: line assembly, validation counters, replies, reconnection, stop."""

from __future__ import annotations

import time

import pytest
import serial
from _sls_reference import ReferenceSLS
from hypothesis import given, settings
from hypothesis import strategies as st

from warptissue.acquisition import LinkLost, RigClient, RigConfig, RigServer, SimulatedRig
from warptissue.acquisition import protocol as wire
from warptissue.errors import DeviceError


def test_loop_url_split_lines_garbage_and_crc_errors():
    client = RigClient("loop://", read_timeout_s=0.01).open()
    port = client._port
    first = wire.format_sample(wire.Sample(0, 0, 0.0, 1.4, "0.0000", "1.4000"))
    second = wire.format_sample(wire.Sample(1, 1000, 0.01, 2.1, "0.0100", "2.1000"))
    port.write(first[:9])
    assert client.read_message() is None  # half a line: nothing yet, nothing lost
    port.write(first[9:] + b"\x00\xffnoise\n" + b"junk" + second)
    port.write(second[:-6] + b"0000\r\n")  # CRC broken
    port.write(wire.format_done("RAMP", 2, "OK"))
    messages = []
    while (message := client.read_message()) is not None:
        messages.append(message)
    assert [type(m).__name__ for m in messages] == ["Sample", "Sample", "Done"]
    assert messages[1].sequence == 1
    counters = client.counters
    assert (counters.garbage_lines, counters.resynchronised_lines) == (1, 1)
    assert counters.checksum_errors == 1
    client.close()


def test_command_without_reply_times_out():
    client = RigClient("loop://", read_timeout_s=0.01, reply_timeout_s=0.2).open()
    with pytest.raises(DeviceError, match="no reply to IDN"):
        client.identify()  # loop:// echoes the command, which is not a reply
    client.close()


def test_open_failure_and_reconnect_give_up():
    with pytest.raises(LinkLost, match="cannot open"):
        RigClient("/dev/does-not-exist-rig").open()
    client = RigClient("socket://127.0.0.1:9", reconnect_attempts=2, reconnect_delay_s=0.01)
    assert client.reconnect() is False
    assert client.counters.reconnections == 0


def test_units_and_exit_stops_a_running_rig():
    rig = SimulatedRig(ReferenceSLS(40.0, 20.0, 2.0), RigConfig(time_scale=1.0))
    with RigServer(rig, transport="tcp") as server:
        with RigClient(server.url) as client:
            client.configure(length_unit="um", force_unit="N", rate_Hz=100)
            assert (rig.length_unit, rig.force_unit, rig.rate_Hz) == ("um", "N", 100.0)
            client.ramp_hold(depth_m=4e-3, speed_m_per_s=8e-3, hold_s=100.0)
            assert client.status()[0] == "MOVING"
            time.sleep(0.1)
        # Leaving the block sent STOP and closed the port.
        assert rig.motion is None
        assert not client.is_open


def test_peer_close_raises_link_lost():
    rig = SimulatedRig(ReferenceSLS(40.0, 20.0, 2.0), RigConfig())
    server = RigServer(rig, transport="tcp").start()
    client = RigClient(server.url).open()
    assert client.identify()["model"] == "rig-sim"
    server.close()
    with pytest.raises((LinkLost, serial.SerialException)):
        for _ in range(50):
            client.read_message()
    client.close()


@given(st.lists(st.integers(1, 60), min_size=1, max_size=40), st.binary(max_size=30))
@settings(max_examples=50, deadline=None)
def test_any_chunking_of_the_stream_gives_the_same_messages(cuts, noise):
    """However the link splits the byte stream, the client assembles the same messages."""
    lines = [
        wire.format_sample(wire.Sample(i, 1000 * i, 0.01 * i, 0.7 * i, f"{0.01 * i:.4f}", "0"))
        for i in range(5)
    ]
    clean_noise = noise.replace(b"$", b"").replace(b"\n", b"") + b"\n"
    stream = lines[0] + lines[1] + clean_noise + b"".join(lines[2:])
    client = RigClient("loop://", read_timeout_s=0.001).open()
    messages = []

    def drain():
        while (message := client.read_message()) is not None:
            messages.append(message)

    position = 0
    for cut in [*cuts, len(stream)]:
        client._port.write(stream[position : position + cut])  # one read per piece
        position += cut
        drain()
    client.close()
    assert [m.sequence for m in messages] == [0, 1, 2, 3, 4]
    assert client.counters.garbage_lines == 1


class _Rfc2217Bridge:
    """An RFC 2217 server (pyserial's PortManager) in front of the simulated rig's pty,
    on 127.0.0.1: what a networked serial server in a lab would be."""

    def __init__(self, pty_path: str) -> None:
        import socket
        import threading

        from serial.rfc2217 import PortManager

        class PtyPort(serial.Serial):  # a pty has no modem control lines
            cts = dsr = ri = cd = property(lambda self: False)

            def _update_dtr_state(self) -> None:
                pass

            def _update_rts_state(self) -> None:
                pass

            def _update_break_state(self) -> None:
                pass

        self._serial = PtyPort(pty_path, timeout=0.02)
        self._listener = socket.create_server(("127.0.0.1", 0))
        self.url = f"rfc2217://127.0.0.1:{self._listener.getsockname()[1]}"
        self._stop = threading.Event()
        self._manager_class = PortManager
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        import threading

        connection, _ = self._listener.accept()
        connection.settimeout(0.02)
        lock = threading.Lock()

        class Writer:
            def write(self, data: bytes) -> None:
                with lock:
                    connection.sendall(data)

        manager = self._manager_class(self._serial, Writer())
        while not self._stop.is_set():
            data = self._serial.read(4096)
            if data:
                Writer().write(b"".join(manager.escape(data)))
            try:
                received = connection.recv(4096)
            except TimeoutError:
                continue
            if not received:
                break
            self._serial.write(b"".join(manager.filter(received)))
        connection.close()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        self._listener.close()
        self._serial.close()


@pytest.mark.filterwarnings("ignore::DeprecationWarning")  # inside pyserial's rfc2217
def test_rfc2217_url_through_a_network_serial_server(tmp_path):
    from warptissue.acquisition import RampHold, Recorder
    from warptissue.io import read_experiment_csv

    rig = SimulatedRig(ReferenceSLS(40.0, 20.0, 2.0), RigConfig(time_scale=20.0))
    with RigServer(rig, transport="pty") as server:
        bridge = _Rfc2217Bridge(server.url)
        try:
            with RigClient(bridge.url, reply_timeout_s=5.0) as client:
                test = RampHold(depth_m=1e-3, speed_m_per_s=8e-3, hold_s=0.5)
                result = Recorder(client, tmp_path / "rfc.csv", progress=False).record(test)
        finally:
            bridge.close()
    assert result.status == "complete"
    assert result.samples_received == result.samples_sent == rig.counters.emitted
    assert read_experiment_csv(tmp_path / "rfc.csv").sample_count == result.samples_received


class _StreamingServer:
    """A loopback server (127.0.0.1 only) that streams numbered, CRC-framed sample lines from
    the instant it accepts a connection, ``lines`` per connection, then closes it; it drops
    every ``drop_every``-th line and corrupts the CRC of every ``corrupt_every``-th, and
    counts what it put on the link."""

    def __init__(self, *, connections: int, lines: int, drop_every: int, corrupt_every: int):
        import socket
        import threading

        self.connections, self.lines = connections, lines
        self.drop_every, self.corrupt_every = drop_every, corrupt_every
        self.intact: list[int] = []
        self.dropped = self.corrupted = self.served = 0
        self._listener = socket.create_server(("127.0.0.1", 0))
        self._listener.settimeout(10.0)
        self.url = f"socket://127.0.0.1:{self._listener.getsockname()[1]}"
        self.done = threading.Event()
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        import socket

        number = 0
        try:
            for _ in range(self.connections):
                connection, _ = self._listener.accept()
                connection.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                for _ in range(self.lines):  # from the instant of accept, no pause
                    number += 1
                    if number % self.drop_every == 0:
                        self.dropped += 1
                        continue
                    line = wire.format_sample(wire.Sample(number, 1000 * number, 1.0, 2.0))
                    if number % self.corrupt_every == 0:
                        line = line[:-3] + (b"0" if line[-3:-2] != b"0" else b"1") + b"\r\n"
                        self.corrupted += 1
                    else:
                        self.intact.append(number)
                    connection.sendall(line)
                connection.shutdown(socket.SHUT_WR)
                connection.close()
                self.served += 1
        finally:
            self._listener.close()
            self.done.set()


def test_reconnects_to_a_rig_that_streams_at_once_lose_nothing():
    """100 reconnects to a server that streams from the instant of accept: every intact line
    it sent is received exactly once; missing = dropped + corrupted (pyserial's socket://
    open() empties the input that arrived while connecting; RigClient keeps it)."""
    server = _StreamingServer(connections=101, lines=60, drop_every=37, corrupt_every=23)
    client = RigClient(server.url, read_timeout_s=0.05, reconnect_delay_s=0.001).open()
    received: list[int] = []
    deadline = time.monotonic() + 60.0
    try:
        while time.monotonic() < deadline:
            try:
                message = client.read_message()
            except LinkLost:
                if server.done.is_set() and server.served == server.connections:
                    break
                assert client.reconnect()
                continue
            if isinstance(message, wire.Sample):
                received.append(message.sequence)
    finally:
        client.close()
    assert server.served == server.connections
    assert client.counters.reconnections == 100
    sent = server.connections * server.lines
    assert len(received) == len(set(received))
    assert received == server.intact
    assert sent - len(received) == server.dropped + server.corrupted
    assert client.counters.checksum_errors == server.corrupted
