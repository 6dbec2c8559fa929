"""``warptissue acquire`` (record a test from the rig) and ``warptissue rig-sim`` (a simulated
rig on a pty or a loopback socket).

Examples::

    warptissue rig-sim --tissue sls --instantaneous-stiffness 40N/m \\
        --equilibrium-stiffness 20N/m --relaxation-time 2s
    warptissue acquire --port /dev/pts/5 --protocol ramp-hold --depth 4mm --speed 8mm/s \\
        --hold 100s --out run.csv
"""

from __future__ import annotations

import argparse
import contextlib
import math
import signal
import sys
import threading
from collections.abc import Iterator
from typing import Any

from warptissue.errors import DeviceError, InputError

__all__ = ["register"]


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``acquire`` and ``rig-sim`` commands."""
    acquire = subparsers.add_parser(
        "acquire",
        help="run a test on the indentation rig and record it (CSV + JSON sidecar)",
        description="Run a ramp-and-hold or sine test on the rig and record every valid "
        "sample to CSV, flushed as it arrives. Quantities take unit suffixes: 4mm, 8mm/s, "
        "100s, 250ms, 1000Hz.",
    )
    acquire.add_argument("--port", required=True, help="port or pyserial URL of the rig")
    acquire.add_argument("--protocol", choices=("ramp-hold", "sine"), default="ramp-hold")
    acquire.add_argument("--depth", help="ramp depth, e.g. 4mm")
    acquire.add_argument("--speed", help="ramp speed, e.g. 8mm/s")
    acquire.add_argument("--hold", help="hold time, e.g. 100s")
    acquire.add_argument("--dwell", default="0.5s", help="rest before the ramp (baseline)")
    acquire.add_argument("--amplitude", help="sine amplitude, e.g. 0.5mm")
    acquire.add_argument("--frequency", help="sine frequency, e.g. 1Hz")
    acquire.add_argument("--cycles", type=float, help="number of sine cycles")
    acquire.add_argument("--rate", default="1000Hz", help="sample rate, at most 1000Hz")
    acquire.add_argument("--out", required=True, help="output CSV (the sidecar is .json)")
    acquire.add_argument("--start", help="move to this axis position first, e.g. 10mm")
    acquire.add_argument("--zero", action="store_true", help="tare the force before the test")
    acquire.add_argument("--calibration", help="force calibration JSON (raw column kept)")
    acquire.add_argument("--overwrite", action="store_true", help="replace an existing CSV")
    acquire.add_argument("--stall-timeout", default="2s", help="silence before asking STAT")
    acquire.add_argument("--give-up", default="10s", help="silence before reopening the port")
    acquire.add_argument("--reconnect-attempts", type=int, default=5)
    acquire.add_argument(
        "--meta", action="append", default=[], metavar="KEY=VALUE", help="sidecar metadata"
    )
    acquire.add_argument("--no-progress", action="store_true", help="no progress bar")
    acquire.set_defaults(handler=run_acquire)

    sim = subparsers.add_parser(
        "rig-sim",
        help="serve a simulated indentation rig on a pty or a loopback TCP socket",
        description="A simulated rig speaking the rig protocol (docs/rig-protocol.md). "
        "Prints the port to pass to 'warptissue acquire --port', then serves until Ctrl-C.",
    )
    where = sim.add_mutually_exclusive_group()
    where.add_argument("--pty", action="store_true", help="serve on a pseudo-terminal (default)")
    where.add_argument("--tcp", type=int, metavar="PORT", help="serve on 127.0.0.1:PORT (0: any)")
    sim.add_argument("--tissue", choices=("sls", "curve"), default="sls")
    sim.add_argument("--instantaneous-stiffness", default="40N/m")
    sim.add_argument("--equilibrium-stiffness", default="20N/m")
    sim.add_argument("--relaxation-time", default="2s")
    sim.add_argument("--force-curve", help="CSV with displacement_m,force_N (--tissue curve)")
    sim.add_argument("--surface", default="0.3mm", help="specimen surface below the start")
    sim.add_argument("--noise", default="0.3mN", help="force noise (standard deviation)")
    sim.add_argument("--offset", default="0mN", help="force transducer offset")
    sim.add_argument("--respiration", help="respiration disturbance AMPLITUDE@RATE, 8mN@0.25Hz")
    sim.add_argument("--heartbeat", help="cardiac disturbance AMPLITUDE@RATE, 2mN@1.4Hz")
    sim.add_argument("--time-scale", default="1", help="rig seconds per wall second, or inf")
    sim.add_argument("--faults", default="", help="e.g. garbage=200,corrupt=300,drop=400")
    sim.add_argument("--seed", type=int, default=0)
    sim.set_defaults(handler=run_rig_sim)


def _quantity(args: argparse.Namespace, name: str, kind: str) -> float:
    from warptissue.acquisition.protocol import parse_quantity

    text = getattr(args, name)
    if text is None:
        raise InputError(f"--{name.replace('_', '-')} is required for this protocol")
    return parse_quantity(text, kind, name=f"--{name.replace('_', '-')}")


def _positive(value: float, name: str) -> float:
    if not value > 0:
        raise InputError(f"{name} must be positive", value=value)
    return value


def run_acquire(args: argparse.Namespace) -> int:
    """Handler of ``warptissue acquire``."""
    from warptissue.acquisition import ForceCalibration, RampHold, Recorder, RigClient, Sine

    if args.protocol == "ramp-hold":
        test: RampHold | Sine = RampHold(
            depth_m=_positive(_quantity(args, "depth", "length"), "--depth"),
            speed_m_per_s=_positive(_quantity(args, "speed", "speed"), "--speed"),
            hold_s=_quantity(args, "hold", "time"),
            dwell_s=_quantity(args, "dwell", "time"),
        )
    else:
        if args.cycles is None or not args.cycles > 0:
            raise InputError("--cycles must be a positive number", value=args.cycles)
        test = Sine(
            amplitude_m=_positive(_quantity(args, "amplitude", "length"), "--amplitude"),
            frequency_Hz=_positive(_quantity(args, "frequency", "frequency"), "--frequency"),
            cycles=args.cycles,
        )
    metadata: dict[str, Any] = {}
    for item in args.meta:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise InputError("--meta takes KEY=VALUE", value=item)
        metadata[key] = value
    calibration = None if args.calibration is None else ForceCalibration.load(args.calibration)
    if calibration is not None:
        metadata["calibration_file"] = args.calibration
    start_m = None if args.start is None else _quantity(args, "start", "length")
    client = RigClient(args.port, reconnect_attempts=args.reconnect_attempts)
    with client:
        if start_m is not None:
            client.move_to(start_m)
            client.wait_until_done(timeout_s=60.0)
        if args.zero:
            client.zero_force()
        recorder = Recorder(
            client,
            args.out,
            rate_Hz=_quantity(args, "rate", "frequency"),
            calibration=calibration,
            metadata=metadata,
            overwrite=args.overwrite,
            progress=not args.no_progress,
            stall_timeout_s=_quantity(args, "stall_timeout", "time"),
            give_up_s=_quantity(args, "give_up", "time"),
        )
        result = recorder.record(test)
    counts = {
        "status": result.status,
        "samples sent": result.samples_sent,
        "samples received/saved": result.samples_received,
        "samples missing": result.samples_missing,
        "sequence gaps": result.sequence_gaps,
        "checksum errors": result.link["checksum_errors"],
        "garbage lines": result.link["garbage_lines"],
        "reconnections": result.link["reconnections"],
    }
    width = max(len(k) for k in counts)
    for key, value in counts.items():
        print(f"{key:<{width}}  {value}")
    print(f"wrote {result.csv_path} and {result.sidecar_path}")
    if result.status in ("link_lost", "stalled"):
        print(
            f"warptissue: error: rig {result.status.replace('_', ' ')}; data so far kept",
            file=sys.stderr,
        )
        return DeviceError.exit_code
    return 0


def _disturbance(args: argparse.Namespace):
    from warptissue.acquisition import PhysiologicalDisturbance
    from warptissue.acquisition.protocol import parse_quantity

    if args.respiration is None and args.heartbeat is None:
        return None
    values: dict[str, float] = {
        "respiration_amplitude_N": 0.0,
        "respiration_Hz": 0.25,
        "heartbeat_amplitude_N": 0.0,
        "heartbeat_Hz": 1.4,
    }
    for name in ("respiration", "heartbeat"):
        text = getattr(args, name)
        if text is None:
            continue
        amplitude, sep, rate = text.partition("@")
        if not sep:
            raise InputError(f"--{name} takes AMPLITUDE@RATE, e.g. 8mN@0.25Hz", value=text)
        values[f"{name}_amplitude_N"] = parse_quantity(amplitude, "force", name=f"--{name}")
        values[f"{name}_Hz"] = parse_quantity(rate, "frequency", name=f"--{name}")
    return PhysiologicalDisturbance(**values)


def _tissue(args: argparse.Namespace):
    from warptissue.acquisition import ForceCurveTissue
    from warptissue.acquisition.protocol import parse_quantity

    if args.tissue == "curve":
        if args.force_curve is None:
            raise InputError("--tissue curve needs --force-curve CSV")
        return ForceCurveTissue.from_csv(args.force_curve)
    from warptissue.viscoelastic import StandardLinearSolid

    return StandardLinearSolid(
        parse_quantity(args.instantaneous_stiffness, "stiffness", name="--instantaneous-stiffness"),
        parse_quantity(args.equilibrium_stiffness, "stiffness", name="--equilibrium-stiffness"),
        parse_quantity(args.relaxation_time, "time", name="--relaxation-time"),
    )


def run_rig_sim(args: argparse.Namespace) -> int:
    """Handler of ``warptissue rig-sim``."""
    from warptissue.acquisition import FaultPlan, RigConfig, RigServer, SimulatedRig
    from warptissue.acquisition.protocol import parse_quantity

    try:
        time_scale = math.inf if args.time_scale == "inf" else float(args.time_scale)
    except ValueError:
        raise InputError("--time-scale: not a number", value=args.time_scale) from None
    if not time_scale > 0:
        raise InputError("--time-scale must be positive", value=args.time_scale)
    config = RigConfig(
        surface_position_m=parse_quantity(args.surface, "length", name="--surface"),
        force_noise_N=parse_quantity(args.noise, "force", name="--noise"),
        force_offset_N=parse_quantity(args.offset, "force", name="--offset"),
        disturbance=_disturbance(args),
        time_scale=time_scale,
        seed=args.seed,
    )
    server = RigServer(
        SimulatedRig(_tissue(args), config),
        transport="tcp" if args.tcp is not None else "pty",
        port=args.tcp or 0,
        faults=FaultPlan.parse(args.faults),
    )
    print(server.url, flush=True)
    try:
        with _interrupted_by(signal.SIGINT, signal.SIGTERM):
            server.serve_forever()
    except KeyboardInterrupt:
        pass
    finally:
        server.close()
        print(f"rig-sim: {server.counters}", file=sys.stderr)
    return 0


@contextlib.contextmanager
def _interrupted_by(*signals: signal.Signals) -> Iterator[None]:
    """Turn the given signals into KeyboardInterrupt while inside (main thread only).

    A process started in the background by a non-interactive shell inherits SIGINT ignored,
    and a pipeline stops its helpers with SIGTERM: the simulated rig should shut down cleanly
    on either.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def interrupt(signum: int, frame: object) -> None:
        raise KeyboardInterrupt

    previous = {number: signal.signal(number, interrupt) for number in signals}
    try:
        yield
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)
