"""Dask distributed against Ray as the engine of ``warptissue batch`` (docs/design-notes/batch.md).

For each engine found installed, with 2 worker processes on this machine:

- ``start_s``: starting the local cluster (Dask ``LocalCluster``; Ray ``ray.init``) and
  connecting a client;
- ``noop_task_ms``: the round trip of one task that does nothing, the mean over
  ``--noop-tasks`` tasks submitted at once;
- ``studies_s``: ``--studies`` tiny simulations (scenes/tutorial_punch.toml on a coarse mesh,
  2 load steps) run by :func:`warptissue.batch.run_study_task`, one task each, the first
  task to reach the end killing its own worker process (SIGKILL) before it returns;
  ``studies_completed`` says how many came back complete (the engine must run the killed
  task again elsewhere);
- ``stop_s``: closing the client and the cluster.

Usage::

    python scripts/benchmarks/bench_batch_engines.py \
        --out scripts/results/bench_batch_engines_2core_cpu.json

Ray is optional (``pip install ray``); an engine that is not installed is reported as such.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _tiny_study(c10_Pa: float) -> str:
    text = (ROOT / "scenes" / "tutorial_punch.toml").read_text(encoding="utf-8")
    text = text.replace("steps = 5", "steps = 2").replace(
        "size_near_m = 0.0005", "size_near_m = 0.001"
    )
    return text.replace("C10_Pa = 287.5", f"C10_Pa = {c10_Pa!r}")


def _tasks(folder: Path, count: int, *, on_dask: bool) -> list:
    from warptissue.batch import Task

    studies = folder / "studies"
    studies.mkdir(parents=True, exist_ok=True)
    tasks = []
    for k in range(count):
        path = studies / f"punch{k}.toml"
        path.write_text(_tiny_study(250.0 + 25.0 * k), encoding="utf-8")
        tasks.append(
            Task(
                path=str(path),
                study=str(path),
                out_dir=str(folder / "out"),
                folder=path.stem,
                device="cpu",
                on_dask=on_dask,
            )
        )
    return tasks


def _noop(x: int) -> int:
    return x


def _ray_study(task):  # the Ray task: the same study function, the same kill hook
    from warptissue import batch

    outcome = batch.run_study_task(task)
    batch.kill_once_hook()
    return outcome


def bench_dask(folder: Path, studies: int, noop_tasks: int) -> dict:
    from distributed import Client, LocalCluster, __version__

    started = time.perf_counter()
    cluster = LocalCluster(
        n_workers=2,
        threads_per_worker=1,
        host="127.0.0.1",
        dashboard_address=None,
        silence_logs=logging.ERROR,
    )
    client = Client(cluster)
    start_s = time.perf_counter() - started
    client.gather(client.map(_noop, range(8)))  # warm
    started = time.perf_counter()
    client.gather(client.map(_noop, range(noop_tasks), pure=False))
    noop_ms = (time.perf_counter() - started) / noop_tasks * 1e3
    from warptissue.batch import run_study_task

    tasks = _tasks(folder, studies, on_dask=True)
    started = time.perf_counter()
    outcomes = client.gather([client.submit(run_study_task, t, pure=False) for t in tasks])
    studies_s = time.perf_counter() - started
    started = time.perf_counter()
    client.close()
    cluster.close()
    return {
        "version": __version__,
        "start_s": start_s,
        "noop_task_ms": noop_ms,
        "studies_s": studies_s,
        "studies_completed": sum(o.status == "completed" for o in outcomes),
        "stop_s": time.perf_counter() - started,
    }


def bench_ray(folder: Path, studies: int, noop_tasks: int) -> dict:
    import ray

    started = time.perf_counter()
    ray.init(num_cpus=2, include_dashboard=False, logging_level=logging.ERROR)
    start_s = time.perf_counter() - started
    noop = ray.remote(_noop)
    ray.get([noop.remote(i) for i in range(8)])  # warm
    started = time.perf_counter()
    ray.get([noop.remote(i) for i in range(noop_tasks)])
    noop_ms = (time.perf_counter() - started) / noop_tasks * 1e3
    study = ray.remote(max_retries=3)(_ray_study)
    tasks = _tasks(folder, studies, on_dask=False)
    started = time.perf_counter()
    outcomes = ray.get([study.remote(t) for t in tasks])
    studies_s = time.perf_counter() - started
    started = time.perf_counter()
    ray.shutdown()
    return {
        "version": ray.__version__,
        "start_s": start_s,
        "noop_task_ms": noop_ms,
        "studies_s": studies_s,
        "studies_completed": sum(o.status == "completed" for o in outcomes),
        "stop_s": time.perf_counter() - started,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--studies", type=int, default=4)
    parser.add_argument("--noop-tasks", type=int, default=500)
    parser.add_argument("--out", type=Path, default=None, help="results JSON")
    args = parser.parse_args()
    from warptissue.batch import _KILL_ONCE_ENV

    results: dict = {
        "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores",
        "python": platform.python_version(),
        "studies": args.studies,
        "noop_tasks": args.noop_tasks,
        "engines": {},
    }
    for name, bench in (("dask", bench_dask), ("ray", bench_ray)):
        with tempfile.TemporaryDirectory() as tmp:
            os.environ[_KILL_ONCE_ENV] = str(Path(tmp) / "killed.pid")
            try:
                results["engines"][name] = bench(Path(tmp), args.studies, args.noop_tasks)
            except ImportError as exc:
                results["engines"][name] = {"error": f"not installed: {exc}"}
            killed = Path(tmp) / "killed.pid"
            if killed.exists():
                results["engines"][name]["killed_worker_pid"] = int(killed.read_text())
        print(name, json.dumps(results["engines"][name]), file=sys.stderr, flush=True)
    text = json.dumps(results, indent=2) + "\n"
    if args.out is not None:
        args.out.write_text(text, encoding="utf-8")
    print(text, end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
