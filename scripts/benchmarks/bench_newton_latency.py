"""Milliseconds per Newton iteration of a study's forward run, without and with the profile.

A small problem's iteration on a GPU is bound by latency (launches, host reads, library calls),
which ``--profile`` itself changes (it synchronizes the device at every phase boundary), so
this times the study's load path (:func:`warptissue.simulate.solve_study`, mesh and set-up
excluded) ``--repeats`` times unprofiled and once profiled, after one warm-up run, and
records the force curve of each run for comparison with another device's.

Usage::

    python scripts/benchmarks/bench_newton_latency.py scenes/liver_fit.toml --device cuda \
        --repeats 3 --label H200 --out $OUT/latency.json
    python scripts/benchmarks/bench_newton_latency.py --compare A.json B.json
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np


def measure(study_path: Path, *, device: str, repeats: int) -> dict[str, Any]:
    """Warm-up, ``repeats`` unprofiled and one profiled run of the study's load path."""
    from warptissue.simulate import prepare_study, solve_study
    from warptissue.study import load_study

    study = load_study(study_path)
    runs = []
    with tempfile.TemporaryDirectory() as folder:
        setup = prepare_study(study, out_dir=folder, device=device, announce=False)
        solve_study(setup, progress=False)  # compiles, analyses, warms the libraries
        for profile in [False] * repeats + [True]:
            started = time.perf_counter()
            outputs = solve_study(setup, progress=False, profile=profile)
            seconds = time.perf_counter() - started
            result = outputs.result
            iterations = int(np.sum(result.newton_iterations))
            runs.append(
                {
                    "profile": profile,
                    "seconds": seconds,
                    "newton_iterations": iterations,
                    "ms_per_iteration": 1e3 * seconds / max(iterations, 1),
                    "force_N": np.asarray(result.reaction_force_N, dtype=float).tolist(),
                    "newton_profile": outputs.summary.get("newton_profile"),
                }
            )
    return {"study": str(study_path), "device": device, "runs": runs}


def compare(paths: list[Path]) -> None:
    """Print each file's median ms per iteration and the largest relative force difference
    of every run from the first file's first run."""
    data = [json.loads(path.read_text()) for path in paths]
    reference = np.asarray(data[0]["runs"][0]["force_N"])
    scale = float(np.max(np.abs(reference)))
    for path, each in zip(paths, data, strict=True):
        plain = [run for run in each["runs"] if not run["profile"]]
        ms = float(np.median([run["ms_per_iteration"] for run in plain]))
        worst = max(
            float(np.max(np.abs(np.asarray(run["force_N"]) - reference))) / scale
            for run in each["runs"]
        )
        print(
            f"{path.name}: {ms:.2f} ms/iteration (median of {len(plain)}), "
            f"{plain[0]['newton_iterations']} iterations, largest force difference {worst:.1e}"
        )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("study", type=Path, nargs="?")
    parser.add_argument("--device", default="cuda")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--label", default="")
    parser.add_argument("--out", type=Path)
    parser.add_argument("--compare", type=Path, nargs="+")
    args = parser.parse_args()
    if args.compare:
        compare(args.compare)
        return 0
    if args.study is None:
        parser.error("a study file is needed")
    record = measure(args.study, device=args.device, repeats=args.repeats)
    record["label"] = args.label
    text = json.dumps(record, indent=1)
    if args.out:
        args.out.write_text(text)
    for run in record["runs"]:
        print(
            f"profile={run['profile']}: {run['seconds']:.3f} s, {run['newton_iterations']} its, "
            f"{run['ms_per_iteration']:.2f} ms/it"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
