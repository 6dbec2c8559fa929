"""Throughput of batched FE: K flat-punch curves (or fits) solved together against one after
another.

K problems share the flat-punch benchmark's quarter block (``bench_flat_punch.py``, the same
20 depths to half the punch radius) and differ in their material: C10 spread over
0.8-1.2 times the benchmark's, as the trials of a fit or a tissue bank's specimens would.

- ``batched``: :func:`warptissue.fem.simulate_indentation_batch`, all K at once.
- ``sequential``: :func:`warptissue.fem.simulate_indentation`, one after another, with one
  assembler (the defaults of a single run). Its rate is measured on the first
  ``--sequential-limit`` problems (a rate does not need all K).

Both times include building the assembler (and packing the meshes); a one-step run of one
problem warms up the kernels and libraries first.

Each row records curves per minute of both, their ratio, and the largest relative difference
of a batched force from the sequential one of the same problem. With ``--what fits``, K
inverse fits of C10 (studies whose records are synthetic curves made at each problem's C10,
fitted from 0.8 times it): :func:`warptissue.fit.fit_indentation` over the K studies
(forward runs batched) against ``fit_indentation`` of each, in fits per minute, and the
largest relative difference of a fitted C10. With ``--cluster-workers N`` as well, the same K
fits also run on a Dask ``LocalCluster`` of N single-threaded CPU worker processes
(:func:`warptissue.batch.run_batch` over the K study files with ``device="cpu"``), warmed
first (the CPU kernels compiled once into Warp's kernel cache, every worker's first forward
run done) and timed from the fits' submission, the way a lab without a GPU runs a long batch
on every core; the cluster's start and warm-up are reported apart.

Usage::

    python scripts/benchmarks/bench_batch_fe.py --device cuda --counts 1,8,32,128 \
        --out $OUT/bench_batch_fe.json
    python scripts/benchmarks/bench_batch_fe.py --device cuda --tets 600 --counts 32 \
        --what fits --cluster-workers 16 --out $OUT/bench_batch_fits.json
    python scripts/benchmarks/bench_batch_fe.py --markdown scripts/results/bench_batch_fe_*.json
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402
from bench_flat_punch import (  # noqa: E402
    BULK_MODULUS_PA,
    HALF_WIDTH_M,
    NEWTON_TOLERANCE,
    PROBE_RADIUS_M,
    SHEAR_MODULUS_PA,
    THICKNESS_M,
    depths_m,
    machine_description,
    parse_count,
    warptissue_mesh,
)


def problems_for(mesh: Any, count: int) -> list[Any]:
    """``count`` flat-punch problems on ``mesh``, C10 from 0.8 to 1.2 times the benchmark's."""
    from warptissue.fem import IndentationProblem
    from warptissue.indenter import Indenter
    from warptissue.materials import NeoHookean

    factors = np.linspace(0.8, 1.2, count) if count > 1 else np.ones(1)
    return [
        IndentationProblem(
            mesh,
            NeoHookean(C10_Pa=0.5 * SHEAR_MODULUS_PA * factor, bulk_modulus_Pa=BULK_MODULUS_PA),
            Indenter("flat_punch", radius_m=PROBE_RADIUS_M, contact="bonded"),
            base="fixed",
            symmetry_planes=("symmetry_x", "symmetry_y"),
            formulation="mixed",
        )
        for factor in factors
    ]


def _common(
    device: Any,
    mesh: Any,
    kind: str,
    count: int,
    steps: int,
    batched_s: float,
    sequential_count: int,
    sequential_s: float,
) -> dict:
    """The fields every row has: the case, both times and both rates (per minute)."""
    batched_rate = 60.0 * count / batched_s
    sequential_rate = 60.0 * sequential_count / sequential_s
    return {
        "device": str(device),
        "cells": mesh.tet_count,
        "dofs": 3 * mesh.node_count,
        "problems": count,
        "steps": steps,
        "kind": kind,
        "batched_s": batched_s,
        "sequential_problems": sequential_count,
        "sequential_s": sequential_s,
        "batched_per_minute": batched_rate,
        "sequential_per_minute": sequential_rate,
        "speedup": batched_rate / sequential_rate,
    }


def run(
    mesh: Any,
    count: int,
    device: str,
    *,
    steps: int,
    sequential_limit: int,
    elimination: bool | str = "auto",
    reuse: bool | str = "auto",
) -> dict:
    """One row: K problems batched, and the first ``sequential_limit`` of them alone."""
    import warp as wp

    from warptissue.device import resolve_device
    from warptissue.fem import (
        Assembler,
        NewtonOptions,
        simulate_indentation,
        simulate_indentation_batch,
    )

    warp_device = resolve_device(device)
    options = NewtonOptions(
        tolerance=NEWTON_TOLERANCE, nonlinear_elimination=elimination, reuse_factorization=reuse
    )
    problems = problems_for(mesh, count)
    depths = depths_m()[:steps]
    started = time.perf_counter()
    batched = simulate_indentation_batch(
        problems, [depths] * count, device=warp_device, options=options
    )
    wp.synchronize_device(warp_device)
    batched_s = time.perf_counter() - started
    alone_count = min(count, sequential_limit)
    started = time.perf_counter()
    assembler = Assembler(mesh, problems[0].material, device=warp_device)
    alone = [
        simulate_indentation(
            problem,
            depths,
            device=warp_device,
            progress=False,
            options=options,
            assembler=assembler,
        )
        for problem in problems[:alone_count]
    ]
    wp.synchronize_device(warp_device)
    sequential_s = time.perf_counter() - started
    difference = max(
        float(np.max(np.abs(b.reaction_force_N / a.reaction_force_N - 1.0)))
        for a, b in zip(alone, batched, strict=False)
    )
    return {
        **_common(warp_device, mesh, "curves", count, steps, batched_s, alone_count, sequential_s),
        "batched_completed": sum(result.completed for result in batched),
        "batched_newton_iterations": int(sum(r.newton_iterations.sum() for r in batched)),
        "nonlinear_elimination": elimination,
        "reuse_factorization": reuse,
        "max_force_difference": difference,
    }


FIT_STUDY = """\
schema_version = 2
name = "bench_fit_{k}"

[specimen]
shape = "block"
width_m = {width_m!r}
thickness_m = {thickness_m!r}
quarter = true
element = "TET10"
size_near_m = {size_near_m!r}
size_far_m = {size_far_m!r}
mesher = "{mesher}"

[indenter]
kind = "flat_punch"
radius_m = {radius_m!r}

[protocol]
max_depth_m = {max_depth_m!r}
steps = {steps}

[material]
model = "neo_hookean"
C10_Pa = {start!r}
bulk_modulus_Pa = {bulk_modulus_Pa!r}

[solver]
device = "{device}"
tolerance = {tolerance!r}
nonlinear_elimination = {elimination}
reuse_factorization = {reuse}

[[data]]
file = "record.csv"

[fit]
free = ["C10_Pa"]
time_steps = {steps}
"""


def fit_studies(
    folder: Path,
    truths: list[Any],
    depths: np.ndarray,
    forces: list[np.ndarray],
    *,
    size_near_m: float,
    mesher: str,
    device: str,
    elimination: bool | str,
    reuse: bool | str,
) -> list[Any]:
    """One study per synthetic curve in ``folder``: the benchmark's block (its sizes; the
    near size at most the probe radius, as a study needs) and punch, its curve as the
    record, C10 free from 0.8 times the truth."""
    from warptissue.io import write_csv
    from warptissue.study import load_study

    studies = []
    for k, (truth, force) in enumerate(zip(truths, forces, strict=True)):
        here = folder / f"specimen_{k}"
        here.mkdir(parents=True, exist_ok=True)
        write_csv(
            here / "record.csv",
            {
                "time_s": np.arange(len(depths) + 1, dtype=np.float64),
                "displacement_m": np.concatenate([[0.0], depths]),
                "force_N": np.concatenate([[0.0], force]),
            },
        )
        text = FIT_STUDY.format(
            k=k,
            width_m=2.0 * HALF_WIDTH_M,
            thickness_m=THICKNESS_M,
            size_near_m=min(size_near_m, PROBE_RADIUS_M),
            size_far_m=max(size_near_m, min(10.0 * size_near_m, 0.25 * THICKNESS_M)),
            mesher=mesher,
            radius_m=PROBE_RADIUS_M,
            max_depth_m=float(depths[-1]),
            steps=len(depths),
            start=0.8 * float(truth.material.parameter_vector[0]),
            bulk_modulus_Pa=BULK_MODULUS_PA,
            device=device,
            tolerance=NEWTON_TOLERANCE,
            elimination=json.dumps(elimination),
            reuse=json.dumps(reuse),
        )
        (here / "study.toml").write_text(text, encoding="utf-8")
        studies.append(load_study(here / "study.toml"))
    return studies


def run_fits(
    mesh: Any,
    count: int,
    device: str,
    *,
    steps: int,
    sequential_limit: int,
    size_near_m: float,
    mesher: str,
    elimination: bool | str = "auto",
    reuse: bool | str = "auto",
    cluster_workers: int = 0,
) -> dict:
    """One row of fits: K studies whose records are synthetic curves (made by the FE at each
    problem's C10 on the benchmark's mesh) fitted for C10 from 0.8 times it, together
    (:func:`warptissue.fit.fit_indentation` over the K studies: forward runs batched), and
    the first ``sequential_limit`` fitted alone (``fit_indentation`` of each)."""
    import tempfile

    import warp as wp

    from warptissue.device import resolve_device
    from warptissue.fem import NewtonOptions, simulate_indentation_batch
    from warptissue.fit import fit_indentation
    from warptissue.simulate import build_mesh

    warp_device = resolve_device(device)
    truths = problems_for(mesh, count)
    depths = depths_m()[:steps]
    curves = simulate_indentation_batch(
        truths,
        [depths] * count,
        device=warp_device,
        options=NewtonOptions(
            tolerance=NEWTON_TOLERANCE,
            nonlinear_elimination=elimination,
            reuse_factorization=reuse,
        ),
    )
    with tempfile.TemporaryDirectory(prefix="bench_batch_fits_") as folder:
        studies = fit_studies(
            Path(folder),
            truths,
            depths,
            [curve.reaction_force_N for curve in curves],
            size_near_m=size_near_m,
            mesher=mesher,
            device=str(warp_device),
            elimination=elimination,
            reuse=reuse,
        )
        started = time.perf_counter()
        fits = fit_indentation(studies, device=str(warp_device), progress=False)
        wp.synchronize_device(warp_device)
        batched_s = time.perf_counter() - started
        alone_count = min(count, sequential_limit)
        started = time.perf_counter()
        alone = [
            fit_indentation(study, device=str(warp_device), progress=False)
            for study in studies[:alone_count]
        ]
        wp.synchronize_device(warp_device)
        sequential_s = time.perf_counter() - started
        fitted_mesh = build_mesh(studies[0])
        cluster = cpu_cluster_fits(Path(folder), count, cluster_workers) if cluster_workers else {}
    c10 = [fit.parameters["C10_Pa"] for fit in fits]
    difference = max(abs(c10[k] / a.parameters["C10_Pa"] - 1.0) for k, a in enumerate(alone))
    return {
        **_common(
            warp_device, fitted_mesh, "fits", count, steps, batched_s, alone_count, sequential_s
        ),
        "batched_completed": sum(fit.success for fit in fits),
        "batched_lm_iterations": int(sum(fit.result.nfev for fit in fits)),
        "nonlinear_elimination": elimination,
        "reuse_factorization": reuse,
        "max_parameter_difference": difference,
        "max_truth_error": max(
            abs(value / float(truth.material.parameter_vector[0]) - 1.0)
            for value, truth in zip(c10, truths, strict=True)
        ),
        **{key: value for key, value in cluster.items() if key != "C10_Pa"},
        **(
            {
                "cluster_over_batched_C10_difference": max(
                    abs(a / b - 1.0) for a, b in zip(cluster["C10_Pa"], c10, strict=True)
                ),
                "batched_over_cluster": 60.0 * count / batched_s / cluster["cluster_per_minute"],
            }
            if cluster
            else {}
        ),
    }


def _warm_process(study_path: str) -> float:
    """One forward run of a study on the CPU in this process (its kernels compiled or loaded
    from Warp's kernel cache, the linear solver's library loaded); returns its seconds."""
    import tempfile

    from warptissue.simulate import prepare_study, solve_study
    from warptissue.study import load_study

    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="bench_batch_warm_") as folder:
        setup = prepare_study(load_study(study_path), out_dir=folder, device="cpu", announce=False)
        solve_study(setup, progress=False)
    return time.perf_counter() - started


def cpu_cluster_fits(folder: Path, count: int, workers: int) -> dict[str, Any]:
    """The K study files in ``folder`` fitted by :func:`warptissue.batch.run_batch` on a Dask
    LocalCluster of ``workers`` CPU processes (one thread each; BLAS and OpenMP held to one
    thread per process), warmed before it is timed.

    The warm-up: one forward run of the first study in this process (Warp compiles the CPU
    kernels once, into its kernel cache), then one on every worker at once (each loads them
    from the cache); the K fits are then timed from their submission to the summary, so the
    cluster's throughput is that of warm workers, as a lab's long batch sees it. The
    cluster's start and its warm-up are reported apart."""
    import os
    import tempfile

    from distributed import Client, LocalCluster

    from warptissue.batch import run_batch
    from warptissue.fem.linear.direct import pardiso_available

    paths = [folder / f"specimen_{k}" / "study.toml" for k in range(count)]
    saved = {name: os.environ.get(name) for name in ("OMP_NUM_THREADS", "MKL_NUM_THREADS")}
    os.environ.update(OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    try:
        main_warm_s = _warm_process(str(paths[0]))
        started = time.perf_counter()
        cluster = LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address=None,
        )
        client = Client(cluster)
        try:
            client.wait_for_workers(workers)
            start_s = time.perf_counter() - started
            started = time.perf_counter()
            worker_warm = client.run(_warm_process, str(paths[0]))
            warm_s = time.perf_counter() - started
            with tempfile.TemporaryDirectory(prefix="bench_batch_cluster_") as out:
                started = time.perf_counter()
                result = run_batch(
                    paths,
                    out=out,
                    device="cpu",
                    scheduler=cluster.scheduler_address,
                    progress=False,
                )
                seconds = time.perf_counter() - started
                fitted = [
                    json.loads(next(Path(out, outcome.folder).glob("**/fit.json")).read_text())
                    for outcome in result.outcomes
                ]
        finally:
            client.close()
            cluster.close()
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value
    return {
        "cluster_workers": workers,
        "cluster_host_cores": os.cpu_count(),
        "cluster_linear_solver": "pardiso" if pardiso_available() else "superlu",
        "cluster_start_s": start_s,
        "cluster_warm_s": warm_s,
        "cluster_main_warm_s": main_warm_s,
        "cluster_worker_warm_s": sorted(worker_warm.values()),
        "cluster_s": seconds,
        "cluster_per_minute": 60.0 * count / seconds,
        "cluster_completed": sum(outcome.exit_status == 0 for outcome in result.outcomes),
        "C10_Pa": [row["parameters"]["C10_Pa"]["value"] for row in fitted],
    }


def markdown(paths: list[Path]) -> str:
    """The rows of earlier ``--out`` files as a Markdown table."""
    return markdown_table([json.loads(path.read_text(encoding="utf-8")) for path in paths])


def markdown_table(all_results: list[dict]) -> str:
    """The rows of results (as ``--out`` writes them) as a Markdown table."""
    lines = [
        "| run | device | cells | what | problems | batched s | batched per min "
        "| sequential per min (measured on) | batched / sequential "
        "| largest difference from sequential | CPU cluster per min (workers) "
        "| batched / CPU cluster |",
        "|---|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for results in all_results:
        for row in results["runs"]:
            if row["kind"] == "fits":
                difference, what = row["max_parameter_difference"], "C10"
            else:
                difference, what = row["max_force_difference"], "force"
            cells = f"{row['cells']:,}".replace(",", " ")
            lines.append(
                f"| {results['label']} | {row['device']} | {cells} | {row['kind']} "
                f"| {row['problems']} | {row['batched_s']:.3g} | {row['batched_per_minute']:.3g} "
                f"| {row['sequential_per_minute']:.3g} ({row['sequential_problems']}) "
                f"| {row['speedup']:.2f} | {difference:.1e} ({what}) "
                + (
                    f"| {row['cluster_per_minute']:.3g} ({row['cluster_workers']}) "
                    f"| {row['batched_over_cluster']:.2f} |"
                    if "cluster_per_minute" in row
                    else "| - | - |"
                )
            )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default="cpu", help="Warp device: cpu, cuda, cuda:N")
    parser.add_argument("--counts", default="1,8", help="problem counts K, comma separated")
    parser.add_argument(
        "--tets", default="9k", help="tets of the shared mesh (about; e.g. 9k, 2000)"
    )
    parser.add_argument("--mesher", choices=("extruded", "delaunay"), default="delaunay")
    parser.add_argument("--steps", type=int, default=20, help="the first STEPS of the 20 depths")
    parser.add_argument(
        "--what",
        default="curves",
        help="curves, fits, or curves,fits: forward curves, and inverse fits of C10 to "
        "synthetic curves from 0.8 times it",
    )
    parser.add_argument(
        "--sequential-limit", type=int, default=8, help="problems run alone to measure the rate"
    )
    parser.add_argument(
        "--elimination",
        choices=("auto", "on", "off"),
        default="auto",
        help="the Newton solver's nonlinear elimination (NewtonOptions.nonlinear_elimination; "
        "auto: its measured rule)",
    )
    parser.add_argument(
        "--reuse",
        choices=("auto", "on", "off"),
        default="auto",
        help="Newton's solves with earlier factors (NewtonOptions.reuse_factorization; auto: "
        "its measured rule)",
    )
    parser.add_argument(
        "--cluster-workers",
        type=int,
        default=0,
        help="with --what fits: also run the K fits on a Dask LocalCluster of this many CPU "
        "worker processes (0: not)",
    )
    parser.add_argument("--label", default="", help="name of this machine in the tables")
    parser.add_argument("--out", type=Path, help="write the results as JSON here")
    parser.add_argument(
        "--markdown", type=Path, nargs="+", help="print earlier --out files as a table"
    )
    args = parser.parse_args(argv)
    if args.markdown:
        print(markdown(args.markdown))
        return 0
    try:
        counts = [int(text) for text in args.counts.split(",") if text]
        target = parse_count(args.tets)
    except ValueError as exc:
        print(f"bench_batch_fe.py: {exc}", file=sys.stderr)
        return 2
    if not counts or min(counts) < 1 or not 1 <= args.steps <= 20:
        print("bench_batch_fe.py: counts must be >= 1 and steps in [1, 20]", file=sys.stderr)
        return 2
    mesh, size_near_m = warptissue_mesh(target, mesher=args.mesher)
    run(mesh, 1, args.device, steps=1, sequential_limit=1)  # warm-up: kernels, libraries
    kinds = [text for text in args.what.split(",") if text]
    if not kinds or set(kinds) - {"curves", "fits"}:
        print("bench_batch_fe.py: --what takes curves, fits or both", file=sys.stderr)
        return 2
    rows = []
    for kind in kinds:
        for count in counts:
            options = {
                "steps": args.steps,
                "sequential_limit": args.sequential_limit,
                "elimination": {"auto": "auto", "on": True, "off": False}[args.elimination],
                "reuse": {"auto": "auto", "on": True, "off": False}[args.reuse],
            }
            if kind == "fits":
                options.update(
                    size_near_m=size_near_m,
                    mesher=args.mesher,
                    cluster_workers=args.cluster_workers,
                )
            row = (run if kind == "curves" else run_fits)(mesh, count, args.device, **options)
            rows.append(row)
            print(json.dumps(row))
    results = {"label": args.label or args.device, "machine": machine_description(), "runs": rows}
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(results, indent=1), encoding="utf-8")
    print(markdown_table([results]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
