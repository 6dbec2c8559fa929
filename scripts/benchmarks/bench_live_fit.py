"""Recorder lag at the rig's highest rate while a live fit runs beside it.

A 13 s ramp-and-hold at 1 kHz in real time against a simulated Prony tissue, recorded with no
fit (``none``), the live Prony fit every 500 samples (``live``), or a fit that spins in pure
Python for 2 s per refit, holding the interpreter lock (``busy``). Prints, per run, the
samples saved and sent and the lag of each saved chunk (the wall time it reached the
listener minus its last sample's rig time, less the smallest such difference). Results:
docs/live-fitting.md.

Usage::

    python scripts/benchmarks/bench_live_fit.py none live busy
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from warptissue.acquisition import RampHold, Recorder, RigClient, RigConfig, RigServer, SimulatedRig
from warptissue.acquisition.live import LiveFit, LumpedFitter
from warptissue.viscoelastic import PronySeries, fit_relaxation_joint


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


def run(kind: str, folder: Path) -> str:
    """One recording; its summary line."""
    tissue = PronySeries.from_normalized(40.0, (0.35, 0.35), (1.0, 8.0))
    rig = SimulatedRig(tissue, RigConfig(time_scale=1.0, force_noise_N=3e-4))
    fit = busy_fit if kind == "busy" else fit_relaxation_joint
    live = None if kind == "none" else LiveFit(LumpedFitter(fit=fit), every_samples=500)
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
        result = recorder.record(
            RampHold(depth_m=4e-3, speed_m_per_s=8e-3, hold_s=12.0, dwell_s=0.5)
        )
        if live is not None:
            live.finish()
    arrivals = np.array(probe.arrivals)
    lag_ms = 1e3 * (arrivals[:, 0] - arrivals[:, 1])
    lag_ms -= lag_ms.min()
    refits = 0 if live is None else len(live.estimates)
    return (
        f"{kind:5s} saved/sent {result.samples_received}/{result.samples_sent} missing "
        f"{result.samples_missing} chunks {len(arrivals)} lag ms: median "
        f"{np.median(lag_ms):.1f} p99 {np.percentile(lag_ms, 99):.1f} max {lag_ms.max():.1f} "
        f"refits {refits}"
    )


if __name__ == "__main__":
    with tempfile.TemporaryDirectory() as folder:
        for kind in sys.argv[1:] or ["none", "live", "busy"]:
            print(run(kind, Path(folder)), flush=True)
