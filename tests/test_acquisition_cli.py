"""``warptissue acquire`` and ``warptissue rig-sim`` as a user runs them: the documented
examples, a refused test, bad ports, simulate's force curve, and bad input of every option
(one line on stderr, exit 2, nothing written, no traceback)."""

from __future__ import annotations

import signal
import socket
import subprocess
import sys
from contextlib import contextmanager

import numpy as np
import pytest
from _sls_reference import ReferenceSLS

from warptissue.acquisition import ForceCurveTissue, RigConfig, RigServer, SimulatedRig
from warptissue.cli import main
from warptissue.errors import InputError
from warptissue.io import read_experiment_csv, write_csv

SINE_EXAMPLE = "--protocol sine --amplitude 0.5mm --frequency 1Hz --cycles 10".split()
"""The sine test of docs/rig.md."""


@pytest.fixture
def rig_url():
    """A simulated rig (SLS specimen) on a loopback socket, as fast as the link drains."""
    rig = SimulatedRig(ReferenceSLS(40.0, 20.0, 2.0), RigConfig(time_scale=np.inf))
    with RigServer(rig, transport="tcp") as server:
        yield server.url


def one_error_line(capsys) -> str:
    """The single line on stderr (and no traceback, no NumPy repr, no 'column' for an
    option)."""
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert err.startswith("warptissue: error: ")
    assert "Traceback" not in err and "np.float64" not in err
    return err


def test_documented_sine_example_runs_and_a_refused_sine_leaves_no_file(tmp_path, capsys, rig_url):
    """Refused as out of travel, the sine leaves nothing behind (no header-only CSV, no
    sidecar), says how to fix it, and the rerun needs no --overwrite; with --start as
    documented, it records."""
    out = tmp_path / "sine.csv"
    command = ["acquire", "--port", rig_url, *SINE_EXAMPLE, "--out", str(out), "--no-progress"]
    for _ in range(2):  # the rerun gets the same answer, not "output exists"
        assert main(command) == 2
        assert "--start" in one_error_line(capsys)
        assert not out.exists() and not out.with_suffix(".json").exists()
    assert main([*command, "--start", "1mm"]) == 0
    data = read_experiment_csv(out)
    assert data.metadata["status"] == "complete"
    assert data.sample_count == 10 * 1000 + 1
    np.testing.assert_allclose(np.ptp(data["displacement_m"]), 1e-3, rtol=1e-3)


def test_a_refused_ramp_writes_nothing(tmp_path, capsys, rig_url):
    out = tmp_path / "fast.csv"
    command = ["acquire", "--port", rig_url, "--depth", "4mm", "--speed", "80mm/s"]
    assert main([*command, "--hold", "1s", "--out", str(out), "--no-progress"]) == 2
    assert "speed" in one_error_line(capsys)
    assert list(tmp_path.iterdir()) == []


def test_the_output_is_checked_before_the_rig_moves(tmp_path, capsys):
    """An existing output refuses the run before --start moves the axis."""
    rig = SimulatedRig(ReferenceSLS(40.0, 20.0, 2.0), RigConfig(time_scale=np.inf))
    out = tmp_path / "run.csv"
    out.write_text("precious\n")
    with RigServer(rig, transport="tcp") as server:
        command = ["acquire", "--port", server.url, "--depth", "1mm", "--speed", "8mm/s"]
        assert main([*command, "--hold", "0s", "--start", "5mm", "--out", str(out)]) == 2
        assert "output exists" in one_error_line(capsys)
    assert rig.position_m == 0.0 and out.read_text() == "precious\n"


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def run_cli(*args: str, timeout: float = 60) -> subprocess.CompletedProcess:
    """``warptissue ARGS`` in its own process."""
    return subprocess.run(
        [sys.executable, "-m", "warptissue.cli", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
    )


@pytest.mark.parametrize("port", ["busy", "99999", "-5"])
def test_rig_sim_on_a_bad_or_busy_port_says_so_in_one_line(port):
    """In its own process (a working rig-sim would serve until the timeout)."""
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen(1)
        number = str(busy.getsockname()[1]) if port == "busy" else port
        finished = run_cli("rig-sim", "--tcp", number)
    err = finished.stderr.strip()
    assert finished.returncode == 2 and len(err.splitlines()) == 1, err
    assert ("in use" in err) if port == "busy" else ("65535" in err)


@contextmanager
def rig_sim_process(*options: str):
    """``warptissue rig-sim --tcp 0 --time-scale inf OPTIONS`` in its own process; yields
    its URL, stops it with SIGTERM."""
    process = subprocess.Popen(
        [sys.executable, "-m", "warptissue.cli", "rig-sim", "--tcp", "0"]
        + ["--time-scale", "inf", *options],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        url = process.stdout.readline().strip()
        assert url.startswith("socket://"), process.stderr.read()
        yield url
    finally:
        process.send_signal(signal.SIGTERM)
        assert process.wait(timeout=10) == 0


def simulate_force_curve(path, depth_m, force_N):
    """A force curve in ``warptissue simulate``'s layout (its columns, in its order, with the
    undeformed row first)."""
    from warptissue.simulate import FORCE_CURVE_COLUMNS

    steps = np.arange(len(depth_m) + 1)
    values = {
        "time_s": steps / len(depth_m),
        "displacement_m": np.r_[0.0, depth_m],
        "force_N": np.r_[0.0, force_N],
        "step": steps,
        "newton_iterations": np.r_[0, np.full(len(depth_m), 3)],
    }
    return write_csv(path, {name: values[name] for name in FORCE_CURVE_COLUMNS})


def test_rig_sim_plays_simulates_force_curve(tmp_path, capsys):
    """simulate's force_curve.csv (extra columns, a zero row) drives rig-sim --tissue curve:
    the recorded force at each depth is the curve's, interpolated linearly, to the
    --force-resolution quantum given (1 uN)."""
    depth = np.linspace(0.2e-3, 4e-3, 20)
    curve = simulate_force_curve(tmp_path / "force_curve.csv", depth, 3000.0 * depth**1.5)
    out = tmp_path / "run.csv"
    with rig_sim_process(
        "--tissue", "curve", "--force-curve", str(curve), "--surface", "0mm", "--noise", "0mN",
        "--force-resolution", "0.001mN",
    ) as url:  # fmt: skip
        command = ["acquire", "--port", url, "--depth", "4mm", "--speed", "8mm/s"]
        assert main([*command, "--hold", "0s", "--out", str(out), "--no-progress"]) == 0
    data = read_experiment_csv(out)
    expected = np.interp(data["displacement_m"], np.r_[0.0, depth], np.r_[0.0, 3000.0 * depth**1.5])
    np.testing.assert_allclose(data["force_N"], expected, atol=1e-6)  # the 1 uN quantum
    assert data["force_N"].max() > 0.7


@pytest.mark.parametrize(
    ("columns", "message"),
    [
        ({"displacement_m": [0.001, 0.002], "force_N": [-0.1, -0.2]}, "compressive force"),
        ({"displacement_m": [-0.001, 0.002], "force_N": [0.1, 0.2]}, "zero or more"),
        ({"displacement_m": [0.002, 0.001], "force_N": [0.1, 0.2]}, "strictly increase"),
        ({"depth_m": [0.001, 0.002], "reaction_force_N": [0.1, 0.2]}, "displacement_m"),
    ],
)
def test_force_curve_errors_name_file_and_column(tmp_path, columns, message):
    path = write_csv(tmp_path / "curve.csv", {k: np.array(v) for k, v in columns.items()})
    with pytest.raises(InputError, match=message) as info:
        ForceCurveTissue.from_csv(path)
    assert "curve.csv" in str(info.value)


ACQUIRE_ERRORS = [
    (["--depth", "4mm", "--speed", "8mm/s", "--hold=-1s"], "--hold must be zero or more"),
    (["--depth=-4mm", "--speed", "8mm/s", "--hold", "1s"], "--depth must be positive"),
    (["--depth", "4", "--speed", "8mm/s", "--hold", "1s"], "--depth: missing unit"),
    (["--depth", "4mm", "--speed", "8mm/s", "--hold", "1s", "--rate", "5kHz"], "--rate must"),
    (["--depth", "4mm", "--speed", "8mm/s", "--hold", "1s", "--rate=-5Hz"], "--rate must"),
    (["--depth", "4mm", "--speed", "8mm/s", "--hold", "1s", "--stall-timeout", "0s"], "stall"),
    (["--depth", "4mm", "--speed", "8mm/s", "--hold", "1s", "--reconnect-attempts", "-1"], "rec"),
    (["--depth", "4mm", "--speed", "8mm/s", "--hold", "1s", "--give-up", "1s"], "--give-up must"),
    ([*SINE_EXAMPLE[:-1], "inf"], "--cycles must be a finite positive number"),
    ([*SINE_EXAMPLE, "--depth", "4mm"], "--depth is an option of --protocol ramp-hold, not sine"),
    (["--depth", "4mm", "--speed", "8mm/s", "--hold", "1s", "--cycles", "3"], "of --protocol sine"),
    ([*SINE_EXAMPLE[:-1], "nan"], "--cycles must be a finite positive number"),
    (["--depth", "4mm", "--speed", "8mm/s", "--hold", "1s", "--meta", "x"], "--meta takes"),
    (["--depth", "4mm", "--speed", "8mm/s", "--hold", "1s", "--meta", "status=ok"], "own sidecar"),
]


@pytest.mark.parametrize(("options", "message"), ACQUIRE_ERRORS)
def test_acquire_bad_options_one_line_no_file(tmp_path, capsys, rig_url, options, message):
    out = tmp_path / "run.csv"
    assert main(["acquire", "--port", rig_url, *options, "--out", str(out)]) == 2
    assert message in one_error_line(capsys)
    assert not out.exists()


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (None, "cannot read calibration"),
        ("{", "not JSON"),
        ('{"model": "polynomial", "coefficients": "1.0"}', "coefficients"),
        ('{"format": "warptissue.force_calibration", "version": 1}', "'model' missing"),
    ],
)
def test_acquire_bad_calibration_file(tmp_path, capsys, rig_url, content, message):
    calibration = tmp_path / "cal.json"
    if content is not None:
        calibration.write_text(content)
    options = ["--depth", "4mm", "--speed", "8mm/s", "--hold", "1s"]
    out = tmp_path / "run.csv"
    command = ["acquire", "--port", rig_url, *options, "--calibration", str(calibration)]
    assert main([*command, "--out", str(out)]) == 2
    assert message in one_error_line(capsys)
    assert not out.exists()


def test_acquire_unwritable_output(tmp_path, capsys, rig_url):
    """A file where the output's folder should be: refused before the rig moves."""
    (tmp_path / "file").write_text("")
    options = ["--depth", "4mm", "--speed", "8mm/s", "--hold", "1s", "--no-progress"]
    assert main(["acquire", "--port", rig_url, *options, "--out", str(tmp_path / "file/r.csv")])
    assert "cannot write the output" in one_error_line(capsys)


RIG_SIM_ERRORS = [
    (["--relaxation-time", "0s"], "--relaxation-time must be positive"),
    (["--instantaneous-stiffness=-40N/m"], "--instantaneous-stiffness must be positive"),
    (["--surface", "50mm"], "--surface is beyond the rig's travel"),
    (["--noise=-1mN"], "--noise must be zero or more"),
    (["--force-resolution", "0mN"], "--force-resolution must be positive"),
    (["--respiration", "8mN@-1Hz"], "--respiration"),
    (["--time-scale", "0"], "--time-scale must be positive"),
    (["--seed=-1"], "--seed must be zero or more"),
    (["--tissue", "curve"], "--force-curve"),
    (["--faults", "garbage=0"], "--faults: garbage must be 1 or more"),
    (["--faults", "drop=-5"], "--faults: drop must be 1 or more"),
    (["--faults", "stall=100,stall_s=-1"], "stall_s must be a positive number of seconds"),
    (["--faults", "drop=100,drop=200"], "drop is given twice"),
    (["--faults", "split"], "NAME=VALUE"),
    (["--tissue", "curve", "--force-curve", "missing.csv"], "not found"),
]


@pytest.mark.parametrize(("options", "message"), RIG_SIM_ERRORS)
@pytest.mark.slow
def test_rig_sim_bad_options_one_line(options, message):
    """Refused before serving; in its own process (a working rig-sim would serve until the
    timeout)."""
    finished = run_cli("rig-sim", "--tcp", "0", *options)
    err = finished.stderr.strip()
    assert finished.returncode == 2 and len(err.splitlines()) == 1, err
    assert message in err and "column" not in err and "Traceback" not in err


def test_ctrl_c_during_the_start_move_stops_the_axis(tmp_path, capsys, monkeypatch):
    """Ctrl-C while the axis moves to --start: the client sends STOP on its way out (exit
    130), so the axis does not run on to its target."""
    from warptissue.acquisition import RigClient

    def interrupted(self, *, timeout_s):
        raise KeyboardInterrupt

    monkeypatch.setattr(RigClient, "wait_until_done", interrupted)
    rig = SimulatedRig(ReferenceSLS(40.0, 20.0, 2.0), RigConfig(time_scale=1.0))
    with RigServer(rig, transport="tcp") as server:
        command = ["acquire", "--port", server.url, "--depth", "1mm", "--speed", "8mm/s"]
        assert (
            main([*command, "--hold", "0s", "--start", "20mm", "--out", str(tmp_path / "x.csv")])
            == 130
        )
        assert rig.motion is None and rig.position_m < 20e-3  # stopped short of 20 mm
    assert not (tmp_path / "x.csv").exists()


@pytest.mark.parametrize("status", ["fault", "stopped", "link_lost", "stalled"])
def test_a_test_that_did_not_run_to_its_end_exits_5(tmp_path, capsys, monkeypatch, status):
    """The rig ended the motion early (FAULT, a STOP from its panel) or the link failed: the
    data are kept, and the exit status says the test is incomplete."""
    from warptissue.acquisition import Recorder

    record = Recorder.record

    def ends_early(self, test):
        result = record(self, test)
        result.status = status
        return result

    monkeypatch.setattr(Recorder, "record", ends_early)
    rig = SimulatedRig(ReferenceSLS(40.0, 20.0, 2.0), RigConfig(time_scale=np.inf))
    out = tmp_path / "run.csv"
    with RigServer(rig, transport="tcp") as server:
        command = ["acquire", "--port", server.url, "--depth", "1mm", "--speed", "8mm/s"]
        assert main([*command, "--hold", "0s", "--out", str(out), "--no-progress"]) == 5
    assert "data so far are kept" in one_error_line(capsys)
    assert read_experiment_csv(out).sample_count > 0


def test_rig_sim_help_names_every_documented_fault_and_what_delivered_counts(capsys):
    """Issue 45: --help named three of the seven fault options docs/rig.md lists, and
    neither said whether 'delivered' counts corrupted lines (it does)."""
    import re
    from pathlib import Path

    from warptissue.acquisition.simulator import FAULT_OPTIONS

    rig_md = (Path(__file__).resolve().parents[1] / "docs" / "rig.md").read_text()
    (listed,) = re.findall(r"`--faults ([a-z_=0-9.,]+)`", rig_md)
    documented = [item.split("=")[0] for item in listed.split(",")]
    assert sorted(documented) == sorted(FAULT_OPTIONS)
    with pytest.raises(SystemExit):
        main(["rig-sim", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    for name in FAULT_OPTIONS:
        assert f"{name}=" in text, name
    assert (
        "delivered counts the sample lines put on the link whole, corrupted ones included" in text
    )
    assert "**corrupted\nones included**" in rig_md and "`delivered - corrupted`" in rig_md
