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
from pathlib import Path
from typing import TYPE_CHECKING, Any

from warptissue.cli._args import length_m, positive_int
from warptissue.errors import DeviceError, InputError

if TYPE_CHECKING:
    from warptissue.acquisition import CommandRefused
    from warptissue.acquisition.live import LiveCurve, LiveEstimate, LiveFit

__all__ = ["plot_live", "register", "tissue_from_args"]


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``acquire`` and ``rig-sim`` commands."""
    acquire = subparsers.add_parser(
        "acquire",
        help="run a test on the indentation rig and record it (CSV + JSON sidecar)",
        description="Run a ramp-and-hold or sine test on the rig and record every valid "
        "sample to CSV, flushed as it arrives. Quantities take unit suffixes: 4mm, 8mm/s, "
        "100s, 250ms, 1000Hz. Exit status: 0 complete; 2 bad input, or a test the rig refuses "
        "(nothing is written); 5 the rig cannot be reached, or the test did not run to its "
        "end (FAULT, STOP, link lost, rig silent: the data so far are kept); 130 Ctrl-C (the "
        "rig is stopped, the data so far are kept). With --fit, a final fit that fails or "
        "does not converge gives its own exit status (fit relaxation's, fit indentation's).",
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
    acquire.add_argument(
        "--start",
        help="move to this axis position first, e.g. 10mm (a sine swings about it; the axis "
        "starts at 0, the top of its travel)",
    )
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
    live = acquire.add_argument_group(
        "live fit (warptissue.acquisition.live; docs: Live fitting)",
        "Fit the record while the test runs, in a process apart from the recorder; at the "
        "end, 'warptissue fit relaxation' (a lumped model) or 'warptissue fit indentation' "
        "(a study) runs on the saved record.",
    )
    live.add_argument(
        "--fit",
        metavar="MODEL|STUDY.toml",
        help="a lumped model as 'fit relaxation --model' takes it (sls, prony:N, qlv:N, "
        "wiechert, wiechert-nonlinear), refitted every --fit-every samples; or a fit "
        "study with one [[data]] table, whose record the test replaces: its inverse FE "
        "refitted at the end of each ramp or hold (warm-started from the last estimate)",
    )
    live.add_argument(
        "--fit-every",
        type=positive_int,
        default=None,
        metavar="N",
        help="refit after N new samples (default 500 for a lumped model; a study: at the end "
        "of each protocol segment only; a slow fit skips cadences)",
    )
    live.add_argument(
        "--contact",
        default="auto",
        metavar="none|auto|POSITION",
        help="the lumped fit's contact point, as 'fit relaxation --contact' (default auto; the "
        "force offset before contact is removed; a study's [[data]] table says its own)",
    )
    live.add_argument(
        "--stop-when",
        metavar="se<LIMIT",
        help="stop the protocol once every parameter's relative standard error is below "
        "LIMIT (e.g. se<2%%), the fit is identified and its residuals are not systematic "
        "(Durbin-Watson in each window of the record); each progress line says what it "
        "still waits for; the record keeps every sample",
    )
    live.add_argument(
        "--fit-out",
        metavar="DIR",
        help="folder of the fit's outputs (default: STEM_relaxation_fit, or "
        "STEM_indentation_fit for a study, beside the CSV)",
    )
    live.add_argument(
        "--usd",
        action="store_true",
        help="a study fit: also write the specimen with the fitted material as a USD scene "
        "(as 'fit indentation --usd'; a lumped model has no continuum material: refused)",
    )
    acquire.set_defaults(handler=run_acquire)
    _register_rig_sim(subparsers)


def _register_rig_sim(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``rig-sim`` command."""
    sim = subparsers.add_parser(
        "rig-sim",
        help="serve a simulated indentation rig on a pty or a loopback TCP socket",
        description="A simulated rig speaking the rig protocol (docs/rig-protocol.md). "
        "Prints the port to pass to 'warptissue acquire --port', then serves until Ctrl-C "
        "or SIGTERM (exit 0). Exit status 2: a bad option, a bad force curve, or a TCP port "
        "that is busy or out of range.",
    )
    where = sim.add_mutually_exclusive_group()
    where.add_argument("--pty", action="store_true", help="serve on a pseudo-terminal (default)")
    where.add_argument("--tcp", type=int, metavar="PORT", help="serve on 127.0.0.1:PORT (0: any)")
    sim.add_argument(
        "--tissue",
        type=tissue_kind,
        default="sls",
        metavar="sls|prony|qlv|curve|study:FILE",
        help="sls: standard linear solid; prony: Prony series of --g and --tau on the "
        "linear spring --instantaneous-stiffness; qlv: Fung's quasi-linear viscoelasticity, "
        "--g and --tau on the exponential spring A (exp(B x) - 1) of --elastic-scale A and "
        "--elastic-rate B; curve: a static force-depth curve; study:FILE: the FE force of "
        "a study with an elastic material (run once on its [protocol] depths, then "
        "interpolated in depth)",
    )
    sim.add_argument("--instantaneous-stiffness", default="40N/m", help="sls and prony: G0")
    sim.add_argument("--equilibrium-stiffness", default="20N/m", help="sls")
    sim.add_argument("--relaxation-time", default="2s", help="sls")
    sim.add_argument(
        "--g", default="0.35,0.35", help="prony and qlv: normalized Prony coefficients g_i"
    )
    sim.add_argument("--tau", default="1s,20s", help="prony and qlv: relaxation times tau_i")
    sim.add_argument("--elastic-scale", default="10mN", help="qlv: A of A (exp(B x) - 1)")
    sim.add_argument("--elastic-rate", default="500", help="qlv: B of A (exp(B x) - 1), 1/m")
    sim.add_argument(
        "--force-curve",
        help="CSV with displacement_m,force_N columns, e.g. simulate's force_curve.csv "
        "(--tissue curve)",
    )
    sim.add_argument("--surface", default="0.3mm", help="specimen surface below the start")
    sim.add_argument("--noise", default="0.3mN", help="force noise (standard deviation)")
    sim.add_argument("--offset", default="0mN", help="force transducer offset")
    sim.add_argument(
        "--force-resolution",
        default="0.7mN",
        help="force transducer quantum (Ahn & Kim's rig: 0.7 mN); finer for a soft specimen "
        "under a small probe, e.g. 0.0001mN",
    )
    sim.add_argument("--respiration", help="respiration disturbance AMPLITUDE@RATE, 8mN@0.25Hz")
    sim.add_argument("--heartbeat", help="cardiac disturbance AMPLITUDE@RATE, 2mN@1.4Hz")
    sim.add_argument("--time-scale", default="1", help="rig seconds per wall second, or inf")
    sim.add_argument(
        "--faults",
        default="",
        metavar="NAME=N,...",
        help="link faults, counted on sample lines (each count 1 or more, each name once): "
        "garbage=N (a garbage burst after every N-th sample), split=N (every N-th line sent in "
        "two writes), corrupt=N (every N-th line with a wrong CRC), drop=N (every N-th sample "
        "never sent), disconnect=N (close the connection once after N samples; --tcp only), "
        "stall=N (freeze once after N samples) with stall_s=SECONDS (default 1; inf: for "
        "ever). At exit the counters go to stderr: delivered counts the sample lines put on "
        "the link whole, corrupted ones included",
    )
    sim.add_argument("--seed", type=int, default=0)
    sim.set_defaults(handler=run_rig_sim)


def _quantity(args: argparse.Namespace, name: str, kind: str, *, sign: str = "any") -> float:
    """The option ``--name`` (a quantity with a unit) in SI units.

    Args:
        args: The parsed options.
        name: The option's attribute name (``stall_timeout`` for ``--stall-timeout``).
        kind: The kind of quantity (see :func:`~warptissue.acquisition.parse_quantity`).
        sign: ``"positive"``, ``"nonnegative"`` or ``"any"``.

    Raises:
        InputError: Missing, without a valid unit, or of the wrong sign (the option named).
    """
    from warptissue.acquisition.protocol import parse_quantity

    option = f"--{name.replace('_', '-')}"
    text = getattr(args, name)
    if text is None:
        raise InputError(f"{option} is required for this protocol")
    value = parse_quantity(text, kind, name=option)
    if (sign == "positive" and not value > 0) or (sign == "nonnegative" and value < 0):
        raise InputError(
            f"{option} must be {'positive' if sign == 'positive' else 'zero or more'}", value=text
        )
    return value


PROTOCOL_OPTIONS: dict[str, tuple[str, ...]] = {
    "ramp-hold": ("depth", "speed", "hold"),
    "sine": ("amplitude", "frequency", "cycles"),
}
"""The options that describe each protocol's motion."""


def _test(args: argparse.Namespace):
    """The RampHold or Sine the options describe."""
    from warptissue.acquisition import RampHold, Sine

    for protocol, names in PROTOCOL_OPTIONS.items():
        given = [name for name in names if getattr(args, name) is not None]
        if protocol != args.protocol and given:
            raise InputError(
                f"--{given[0]} is an option of --protocol {protocol}, not {args.protocol}"
            )
    if args.protocol == "ramp-hold":
        return RampHold(
            depth_m=_quantity(args, "depth", "length", sign="positive"),
            speed_m_per_s=_quantity(args, "speed", "speed", sign="positive"),
            hold_s=_quantity(args, "hold", "time", sign="nonnegative"),
            dwell_s=_quantity(args, "dwell", "time", sign="nonnegative"),
        )
    if args.cycles is None or not (math.isfinite(args.cycles) and args.cycles > 0):
        raise InputError("--cycles must be a finite positive number", value=args.cycles)
    return Sine(
        amplitude_m=_quantity(args, "amplitude", "length", sign="positive"),
        frequency_Hz=_quantity(args, "frequency", "frequency", sign="positive"),
        cycles=args.cycles,
    )


def _refusal_as_input_error(refusal: CommandRefused) -> InputError:
    """A test the rig refuses as out of range or a bad argument: the user's input, said so
    with what to change."""
    hint = ""
    if refusal.reply.command == "SINE":
        hint = (
            "; a sine swings +-amplitude about the present position: start inside the "
            "travel with --start, e.g. --start 1mm"
        )
    elif refusal.reply.command in ("RAMP", "MOVE"):
        hint = "; check --start, --depth and --speed against the rig's travel and top speed"
    return InputError(f"{refusal}{hint}")


def run_acquire(args: argparse.Namespace) -> int:
    """Handler of ``warptissue acquire``."""
    from warptissue.acquisition import CommandRefused, ForceCalibration, Recorder, RigClient
    from warptissue.acquisition.protocol import ErrorCode
    from warptissue.acquisition.recorder import SIDECAR_KEYS

    test = _test(args)
    rate_Hz = _quantity(args, "rate", "frequency", sign="positive")
    if not 1.0 <= rate_Hz <= 1000.0:
        raise InputError("--rate must be between 1Hz and 1000Hz", value=args.rate)
    if args.reconnect_attempts < 0:
        raise InputError("--reconnect-attempts must be zero or more", value=args.reconnect_attempts)
    metadata: dict[str, Any] = {}
    for item in args.meta:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise InputError("--meta takes KEY=VALUE", value=item)
        if key in SIDECAR_KEYS:
            raise InputError(
                f"--meta: {key!r} is the recorder's own sidecar entry; choose another key",
                value=item,
            )
        metadata[key] = value
    calibration = None if args.calibration is None else ForceCalibration.load(args.calibration)
    if calibration is not None:
        metadata["calibration_file"] = args.calibration
    start_m = None if args.start is None else _quantity(args, "start", "length")
    stall_timeout_s = _quantity(args, "stall_timeout", "time", sign="positive")
    give_up_s = _quantity(args, "give_up", "time", sign="positive")
    if not give_up_s > stall_timeout_s:
        raise InputError(
            "--give-up must be longer than --stall-timeout (first ask the rig, then reopen)",
            value=f"{args.give_up} <= {args.stall_timeout}",
        )
    live = _live_fit(args, test)
    client = RigClient(args.port, reconnect_attempts=args.reconnect_attempts)
    with client:
        recorder = Recorder(  # checks the output before the rig moves
            client,
            args.out,
            rate_Hz=rate_Hz,
            calibration=calibration,
            metadata=metadata,
            overwrite=args.overwrite,
            progress=not args.no_progress,
            stall_timeout_s=stall_timeout_s,
            give_up_s=give_up_s,
            listener=live,
        )
        try:
            if start_m is not None:
                client.move_to(start_m)
                client.wait_until_done(timeout_s=60.0)  # Ctrl-C: the client sends STOP
            if args.zero:
                client.zero_force()
            if live is not None:
                live.start()
            result = recorder.record(test)
        except KeyboardInterrupt:
            if live is not None:
                live.abandon("interrupted (Ctrl-C)")
                summary = _write_live_summary(args, live, status="interrupted", saved_s=None)
                print(f"live fit: {live.state} ({live.stop_reason}); no final fit")
                print(f"wrote {summary}")
            raise
        except CommandRefused as refusal:
            if refusal.reply.code in (ErrorCode.BAD_ARGUMENT, ErrorCode.OUT_OF_RANGE):
                raise _refusal_as_input_error(refusal) from None
            raise
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
    final_status = 0 if live is None else _finish_live(args, live, result, test)
    if result.status in INCOMPLETE:
        print(
            f"warptissue: error: {INCOMPLETE[result.status]}; the data so far are kept",
            file=sys.stderr,
        )
        return DeviceError.exit_code
    return final_status


def _study_fit(args: argparse.Namespace) -> bool:
    """``--fit`` names a study file (``*.toml``) rather than a lumped model."""
    return args.fit is not None and args.fit.lower().endswith(".toml")


def _fit_out(args: argparse.Namespace) -> Path:
    """The folder of the live and the final fit's outputs."""
    if args.fit_out is not None:
        return Path(args.fit_out)
    out = Path(args.out)
    kind = "indentation" if _study_fit(args) else "relaxation"
    return out.parent / f"{out.stem}_{kind}_fit"


def plot_live(path: Path, label: str, estimate: LiveEstimate, curve: LiveCurve) -> None:
    """The live plot: the record so far and the latest fit (run in the fit process).

    Args:
        path: The PNG file (replaced atomically).
        label: What was fitted (``prony:2``, the study file).
        estimate: The refit.
        curve: What it fitted: time (s), measured and model force (N), shape (m,) each.
    """
    from warptissue.report import plot_fit

    plot_fit(
        path,
        curve.time_s,
        curve.measured_force_N,
        curve.model_force_N,
        xlabel="time (s)",
        ylabel="force (N)",
        title=f"live {label} fit at {estimate.rig_time_s:.4g} s ({estimate.samples} samples)",
    )


def _live_fit(args: argparse.Namespace, test) -> LiveFit | None:
    """The LiveFit that ``--fit``, ``--fit-every``, ``--contact`` and ``--stop-when``
    describe, printing its progress lines and refreshing its plot; None without ``--fit``."""
    from functools import partial

    from warptissue.acquisition.live import LiveFit, LumpedFitter, StopRule
    from warptissue.cli.fit_relaxation import parse_model
    from warptissue.fit.live import StudyFitter

    if args.fit is None:
        for option, given in (("--stop-when", args.stop_when), ("--usd", args.usd)):
            if given:
                raise InputError(f"{option} needs --fit MODEL or --fit STUDY.toml")
        return None
    stem = Path(args.out).stem
    if _study_fit(args):
        fitter = StudyFitter.from_file(
            args.fit, record_path=_fit_out(args) / f"{stem}_live_record.csv"
        )
        every, label = args.fit_every, Path(args.fit).name
    else:
        if args.usd:
            raise InputError(
                "--usd needs a study fit (--fit STUDY.toml): a lumped model has no continuum "
                "material to write",
                value=args.fit,
            )
        model, terms = parse_model(args.fit)
        contact: str | float = args.contact
        if contact not in ("none", "auto"):
            try:
                contact = length_m(args.contact)
            except argparse.ArgumentTypeError as exc:
                raise InputError(f"--contact: use none, auto or a position; {exc}") from None
        fitter = LumpedFitter(model=model, terms=terms, contact=contact)
        every, label = args.fit_every or 500, args.fit
    stop_rule = None if args.stop_when is None else StopRule.parse(args.stop_when)

    def show(estimate) -> None:
        print(estimate.progress_line(), flush=True)

    return LiveFit(
        fitter,
        every_samples=every,
        segment_ends_s=test.segment_ends_s(),
        stop_rule=stop_rule,
        on_estimate=show,
        plot=partial(plot_live, _fit_out(args) / f"{stem}_live.png", label),
    )


def _write_live_summary(
    args: argparse.Namespace, live: LiveFit, *, status: str, saved_s: float | None
) -> Path:
    """``STEM_live.json`` in the fit folder: the recording status, how the live fit ended,
    the time the stop rule saved, and every live estimate."""
    from warptissue.io import write_json

    return write_json(
        _fit_out(args) / f"{Path(args.out).stem}_live.json",
        {
            "data_file": str(args.out),
            "recording_status": status,
            "saved_time_s": saved_s,
            **live.summary(),
        },
    )


def _finish_live(args: argparse.Namespace, live: LiveFit, result, test) -> int:
    """Wait for the live fit, write its summary, and fit the saved record offline with
    ``warptissue fit relaxation`` or ``warptissue fit indentation`` (outputs in the fit
    folder); the exit status of that fit (0 when it could not run: a warning)."""
    from warptissue.io import read_experiment_csv

    live.finish()
    saved_s = None
    if result.status == "stopped_early":
        recorded_s = float(read_experiment_csv(result.csv_path)["time_s"][-1])
        saved_s = max(test.duration_s() - recorded_s, 0.0)
        print(
            f"live fit: stopped the test at {recorded_s:.4g} s by --stop-when "
            f"{live.stop_rule}; {saved_s:.4g} s of the protocol saved"
        )
    print(f"live fit: {live.state}" + (f" ({live.stop_reason})" if live.stop_reason else ""))
    waits = live.estimates[-1].stop_rule_waits_for if live.estimates else ()
    if live.stop_rule is not None and not live.stop_requested and waits:
        print(
            f"warptissue: warning: --stop-when {live.stop_rule} never held; the last estimate "
            f"waits for: {'; '.join(waits)}",
            file=sys.stderr,
        )
    print(f"wrote {_write_live_summary(args, live, status=result.status, saved_s=saved_s)}")
    final = _final_study_fit if _study_fit(args) else _final_lumped_fit
    try:
        return final(args, live, Path(result.csv_path))
    except InputError as exc:
        print(
            f"warptissue: warning: the final fit of the record did not run: {exc}", file=sys.stderr
        )
    return 0


def _command_args(argv: list[str]) -> argparse.Namespace:
    """``argv`` parsed by the CLI's own parser: the final fits get every option of the offline
    command, with its defaults (a hand-built Namespace missed each option added later)."""
    from warptissue.cli import build_parser

    return build_parser().parse_args(argv)


def _final_lumped_fit(args: argparse.Namespace, live: LiveFit, csv_path: Path) -> int:
    """``warptissue fit relaxation`` of the saved record, with the live fit's conditioning;
    its exit status."""
    contact = live.fitter.contact
    parsed = _command_args(
        ["fit", "relaxation", str(csv_path), "--model", args.fit, "--out", str(_fit_out(args))]
        + ["--contact", contact if isinstance(contact, str) else repr(float(contact))]
        + ["--offset", live.fitter.offset]
    )
    return parsed.handler(parsed)


def _final_study_fit(args: argparse.Namespace, live: LiveFit, csv_path: Path) -> int:
    """``warptissue fit indentation`` of the study with the saved record in its [[data]]
    (written as ``STEM_study.toml`` in the fit folder, which reproduces the fit offline);
    its exit status."""
    from warptissue.study import save_study

    folder = _fit_out(args)
    study_path = folder / f"{Path(args.out).stem}_study.toml"
    save_study(live.fitter.study_for(csv_path), study_path)
    print(f"wrote {study_path}")
    argv = ["fit", "indentation", str(study_path), "--out", str(folder)]
    argv += ["--usd"] if args.usd else []
    argv += ["--quiet"] if args.no_progress else []
    parsed = _command_args(argv)
    return parsed.handler(parsed)


INCOMPLETE: dict[str, str] = {
    "link_lost": "rig link lost",
    "stalled": "the rig stopped answering",
    "fault": "the rig ended the test with FAULT",
    "stopped": "the rig was stopped (STOP from elsewhere) before the test ended",
}
"""Recording statuses of a test that did not run to its end (exit 5), and what they mean."""


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
        if values[f"{name}_amplitude_N"] < 0 or not values[f"{name}_Hz"] > 0:
            raise InputError(
                f"--{name}: the amplitude must be zero or more and the rate positive", value=text
            )
    return PhysiologicalDisturbance(**values)


def _prony_terms(args: argparse.Namespace) -> tuple[list[float], list[float]]:
    """``--g`` and ``--tau`` as lists of equal length (g_i >= 0 summing to at most 1,
    tau_i > 0 in s)."""
    from warptissue.acquisition.protocol import parse_quantity

    try:
        g = [float(v) for v in args.g.split(",")]
    except ValueError:
        raise InputError(
            "--g takes comma-separated numbers, e.g. 0.35,0.35", value=args.g
        ) from None
    tau = [parse_quantity(v, "time", name="--tau") for v in args.tau.split(",")]
    if len(g) != len(tau):
        raise InputError("--g and --tau need as many values each", value=f"{args.g} / {args.tau}")
    if not all(math.isfinite(v) and v >= 0 for v in g) or sum(g) > 1.0:
        raise InputError("--g: each g_i zero or more, summing to at most 1", value=args.g)
    if not all(math.isfinite(v) and v > 0 for v in tau):
        raise InputError("--tau: each tau_i must be positive", value=args.tau)
    return g, tau


TISSUES = ("sls", "prony", "qlv", "curve")
"""rig-sim's built-in ``--tissue`` kinds (besides ``study:FILE``)."""


def tissue_kind(text: str) -> str:
    """``--tissue``: one of :data:`TISSUES` or ``study:FILE``."""
    if text in TISSUES or (text.startswith("study:") and len(text) > len("study:")):
        return text
    raise argparse.ArgumentTypeError(f"choose from {', '.join(TISSUES)} or study:FILE")


def tissue_from_args(args: argparse.Namespace):
    """The specimen that rig-sim's ``--tissue`` options describe (SI units).

    Raises:
        InputError: A bad option (named).
    """
    from functools import partial

    from warptissue.acquisition import ForceCurveTissue
    from warptissue.acquisition.protocol import parse_quantity
    from warptissue.viscoelastic import (
        PronySeries,
        QuasiLinearViscoelastic,
        StandardLinearSolid,
        exponential_elastic_force,
    )

    if args.tissue.startswith("study:"):
        from warptissue.device import quiet_warp
        from warptissue.simulate import force_curve_tissue
        from warptissue.study import load_study

        quiet_warp()
        return force_curve_tissue(load_study(args.tissue.removeprefix("study:")))
    if args.tissue == "curve":
        if args.force_curve is None:
            raise InputError("--tissue curve needs --force-curve CSV")
        return ForceCurveTissue.from_csv(args.force_curve)
    if args.tissue == "prony":
        g, tau = _prony_terms(args)
        stiffness = _quantity(args, "instantaneous_stiffness", "stiffness", sign="positive")
        return PronySeries.from_normalized(stiffness, g, tau)
    if args.tissue == "qlv":
        g, tau = _prony_terms(args)
        scale_N = parse_quantity(args.elastic_scale, "force", name="--elastic-scale")
        try:
            rate_per_m = float(args.elastic_rate)
        except ValueError:
            raise InputError("--elastic-rate: a number in 1/m", value=args.elastic_rate) from None
        if not (scale_N > 0 and math.isfinite(rate_per_m)):
            raise InputError(
                "--elastic-scale must be positive and --elastic-rate finite",
                value=f"{args.elastic_scale} / {args.elastic_rate}",
            )
        return QuasiLinearViscoelastic(
            g, tau, partial(exponential_elastic_force, scale_N=scale_N, rate_per_m=rate_per_m)
        )
    return StandardLinearSolid(
        _quantity(args, "instantaneous_stiffness", "stiffness", sign="positive"),
        _quantity(args, "equilibrium_stiffness", "stiffness", sign="nonnegative"),
        _quantity(args, "relaxation_time", "time", sign="positive"),
    )


def run_rig_sim(args: argparse.Namespace) -> int:
    """Handler of ``warptissue rig-sim``."""
    from warptissue.acquisition import FaultPlan, RigConfig, RigServer, SimulatedRig

    try:
        time_scale = math.inf if args.time_scale == "inf" else float(args.time_scale)
    except ValueError:
        raise InputError("--time-scale: not a number", value=args.time_scale) from None
    if not time_scale > 0:
        raise InputError("--time-scale must be positive", value=args.time_scale)
    if args.seed < 0:
        raise InputError("--seed must be zero or more", value=args.seed)
    surface_m = _quantity(args, "surface", "length", sign="nonnegative")
    travel_m = RigConfig.travel_m
    if surface_m >= travel_m:
        raise InputError(
            f"--surface is beyond the rig's travel ({travel_m * 1e3:g} mm): the probe would "
            "never touch the specimen",
            value=args.surface,
        )
    config = RigConfig(
        surface_position_m=surface_m,
        force_noise_N=_quantity(args, "noise", "force", sign="nonnegative"),
        force_offset_N=_quantity(args, "offset", "force"),
        force_resolution_N=_quantity(args, "force_resolution", "force", sign="positive"),
        disturbance=_disturbance(args),
        time_scale=time_scale,
        seed=args.seed,
    )
    tissue = tissue_from_args(args)
    faults = FaultPlan.parse(args.faults)
    server = RigServer(
        SimulatedRig(tissue, config),
        transport="tcp" if args.tcp is not None else "pty",
        port=args.tcp or 0,
        faults=faults,
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
