"""Recorder lag at the rig's highest rate while a live fit runs beside it, in its own process.

A ramp-and-hold at 1 kHz in real time against a simulated rig, recorded with:

- ``none``: no live fit;
- ``live``: the live Prony fit (``prony:2``) every 500 samples (a Prony tissue; 4 mm at
  8 mm/s, 12 s hold: 13 s);
- ``busy``: the same, each refit first spinning 2 s in pure Python (a fit that cannot keep
  up; the spinning holds the fit process's interpreter lock, not the recorder's);
- ``study``: the inverse FE of ``scenes/live_punch_fit.toml`` at the end of each protocol
  segment and every 4000 samples, against the FE force of ``scenes/live_punch_specimen.toml``
  (0.4 mm at 0.1 mm/s, 8 s hold: 12.5 s);
- ``none-study``: no live fit, on the ``study`` kind's rig and protocol.

Prints, per run, the samples saved and sent, the lag of each saved chunk (the wall time it
reached the listener minus its last sample's rig time, less the smallest such difference)
and the refits. Results: docs/live-fitting.md.

Usage::

    python scripts/benchmarks/bench_live_fit.py none live busy none-study study
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from warptissue.acquisition import RampHold, Recorder, RigClient, RigConfig, RigServer, SimulatedRig
from warptissue.acquisition.live import LiveFit, LumpedFitter
from warptissue.device import quiet_warp
from warptissue.fit.live import StudyFitter
from warptissue.simulate import force_curve_tissue
from warptissue.study import load_study
from warptissue.viscoelastic import PronySeries, fit_relaxation_joint

SCENES = Path(__file__).resolve().parents[2] / "scenes"
KINDS = ("none", "live", "busy", "study", "none-study")


def busy_fit(records, **options):
    """The real fit after 2 s of pure-Python spinning."""
    started, count = time.perf_counter(), 0
    while time.perf_counter() - started < 2.0:
        count += 1
    return fit_relaxation_joint(records, **options)


class LagProbe:
    """A recorder listener that notes when each chunk arrives and passes it on."""

    def __init__(self, live: LiveFit | None) -> None:
        self.live = live
        self.arrivals: list[tuple[float, float]] = []

    def add_samples(self, time_s, displacement_m, force_N) -> None:
        self.arrivals.append((time.monotonic(), float(time_s[-1])))
        if self.live is not None:
            self.live.add_samples(time_s, displacement_m, force_N)

    @property
    def stop_requested(self) -> bool:
        return False


def setup(kind: str, folder: Path) -> tuple[SimulatedRig, RampHold, LiveFit | None]:
    """The rig, the test and the live fit (or None) of one kind of run."""
    if kind in ("study", "none-study"):
        tissue = force_curve_tissue(load_study(SCENES / "live_punch_specimen.toml"))
        config = RigConfig(
            time_scale=1.0, surface_position_m=1e-4, force_resolution_N=1e-7, force_noise_N=2e-6
        )
        test = RampHold(depth_m=4e-4, speed_m_per_s=1e-4, hold_s=8.0, dwell_s=0.5)
        fitter = StudyFitter.from_file(
            SCENES / "live_punch_fit.toml", record_path=folder / "live_record.csv"
        )
        live = None
        if kind == "study":
            live = LiveFit(fitter, every_samples=4000, segment_ends_s=test.segment_ends_s())
        return SimulatedRig(tissue, config), test, live
    tissue = PronySeries.from_normalized(40.0, (0.35, 0.35), (1.0, 8.0))
    config = RigConfig(time_scale=1.0, force_noise_N=3e-4)
    test = RampHold(depth_m=4e-3, speed_m_per_s=8e-3, hold_s=12.0, dwell_s=0.5)
    fit = busy_fit if kind == "busy" else fit_relaxation_joint
    live = None if kind == "none" else LiveFit(LumpedFitter(fit=fit), every_samples=500)
    return SimulatedRig(tissue, config), test, live


def run(kind: str, folder: Path) -> str:
    """One recording; its summary line."""
    rig, test, live = setup(kind, folder)
    probe = LagProbe(live)
    with RigServer(rig, transport="tcp") as server, RigClient(server.url) as client:
        recorder = Recorder(
            client,
            folder / f"{kind}.csv",
            rate_Hz=1000.0,
            overwrite=True,
            progress=False,
            listener=probe,
            flush_rows=100,
            flush_interval_s=0.1,
        )
        if live is not None:
            live.start()
        result = recorder.record(test)
        ended = time.monotonic()
        if live is not None:
            live.finish()
    waited_s = time.monotonic() - ended
    arrivals = np.array(probe.arrivals)
    lag_ms = 1e3 * (arrivals[:, 0] - arrivals[:, 1])
    lag_ms -= lag_ms.min()
    refits = 0 if live is None else len(live.estimates)
    fit_s = [e.fit_wall_s for e in live.estimates] if live is not None else []
    fits = f" fit s max {max(fit_s):.1f}, after the record {waited_s:.1f}" if fit_s else ""
    state = "" if live is None else f" {live.state}"
    return (
        f"{kind:10s} saved/sent {result.samples_received}/{result.samples_sent} missing "
        f"{result.samples_missing} chunks {len(arrivals)} lag ms: median "
        f"{np.median(lag_ms):.1f} p99 {np.percentile(lag_ms, 99):.1f} max {lag_ms.max():.1f} "
        f"refits {refits}{state}{fits}"
    )


if __name__ == "__main__":
    kinds = sys.argv[1:] or ["none", "live", "busy"]
    unknown = [kind for kind in kinds if kind not in KINDS]
    if unknown:
        sys.exit(f"bench_live_fit.py: choose from {', '.join(KINDS)}, not {', '.join(unknown)}")
    quiet_warp()  # the study rig's FE runs here: Warp's start-up notes off stdout
    with tempfile.TemporaryDirectory() as folder:
        for kind in kinds:
            print(run(kind, Path(folder)), flush=True)
