"""Inverse-FE fits through the Warp FE: forward solves, time, and what forward differences
would need (issue 20's benchmark).

Three parts, each on the liver slab of ``scenes/liver_fit.toml`` (a 40 x 40 x 20 mm quarter
block, fixed base, a 5 mm bonded flat punch to 3.6 mm):

1. ``mesh``: the punch force at 3.6 mm (elastic neo-Hookean C10 = 287.5 Pa) for a series of
   ``size_near_m``, against the finest; the coarsest mesh within 1 % is the one the fits use.
2. ``c10``: a C10 fit to three synthetic ramp-and-hold records (8, 2 and 0.4 mm/s to 3.6 mm,
   a 60 s hold) made by the viscoelastic forward FE with Ahn & Kim's Table 1 (experiment 1)
   Prony series and C10 = 287.5 Pa, plus 1 % Gaussian noise (of the peak force), on a finer
   time grid than the fit's; the Prony terms are held at their true values (stage (ii) of
   Ahn & Kim). The fit starts from the records' small-depth stiffness.
3. ``four``: a four-parameter fit (reduced polynomial C10, C20 and the Prony g1, g2; the tau_i
   fixed) to the same kind of records made with C20 = 1000 Pa.

For each fit: iterations, FE forward runs (each with its exact sensitivities), the forward
runs forward differences would have needed for the same iterations (1 + n per Jacobian),
wall time, the recovered parameters and R^2. Writes a JSON file; ``--markdown`` prints the
tables of docs/performance.md from one.

Usage: python scripts/benchmarks/bench_inverse_fit.py [--device cpu] [--parts mesh c10 four]
    [--out scripts/results/bench_inverse_fit_2core_cpu.json] [--quick]
       python scripts/benchmarks/bench_inverse_fit.py --markdown RESULTS.json
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
TRUTH = {"C10_Pa": 287.5, "g1": 0.348, "g2": 0.358, "tau1_s": 1.376, "tau2_s": 49.369}
SPEEDS_M_PER_S = (0.008, 0.002, 0.0004)
DEPTH_M = 0.0036
HOLD_S = 60.0
NOISE_SHARE = 0.01
BULK_RATIO = 1000.0
SOLVER: dict = {}
"""Extra ``[solver]`` settings of the fits' study (``--solver``)."""


def _study_table(size_near_m: float, material: dict, *, time_steps: int, free: list[str]) -> dict:
    return {
        "schema_version": 2,
        "name": "bench_inverse_fit",
        "specimen": {
            "shape": "block",
            "width_m": 0.040,
            "thickness_m": 0.020,
            "quarter": True,
            "element": "TET10",
            "size_near_m": size_near_m,
            "size_far_m": 0.005,
            "growth": 1.4,
        },
        "indenter": {"kind": "flat_punch", "radius_m": 0.005, "contact": "bonded"},
        "protocol": {"max_depth_m": DEPTH_M, "steps": 6},
        "material": material,
        "boundary": {"base": "fixed"},
        "solver": {"device": "cpu", "formulation": "mixed"},
        "fit": {"free": free, "method": "lm", "objective": "absolute", "time_steps": time_steps},
    }


def _mesh_part(device: str, sizes: list[float]) -> dict:
    from warptissue.fem import simulate_indentation
    from warptissue.simulate import build_mesh, build_problem
    from warptissue.study import study_from_dict

    rows = []
    for size in sizes:
        table = _study_table(
            size,
            {"model": "neo_hookean", "C10_Pa": 287.5, "bulk_modulus_Pa": 575e3},
            time_steps=2,
            free=["C10_Pa"],
        )
        table.pop("fit")
        study = study_from_dict(table)
        mesh = build_mesh(study)
        start = time.perf_counter()
        result = simulate_indentation(
            build_problem(study, mesh),
            np.linspace(DEPTH_M / 6, DEPTH_M, 6),
            device=device,
            progress=False,
            strict=True,
        )
        rows.append(
            {
                "size_near_m": size,
                "tets": mesh.tet_count,
                "nodes": mesh.node_count,
                "force_N": float(result.reaction_force_N[-1]),
                "seconds": time.perf_counter() - start,
            }
        )
        print(
            f"mesh size_near {size * 1e3:.3f} mm: {mesh.tet_count} tets, "
            f"F = {rows[-1]['force_N']:.6g} N ({rows[-1]['seconds']:.1f} s)",
            flush=True,
        )
    reference = rows[-1]["force_N"]
    for row in rows:
        row["error_vs_finest"] = row["force_N"] / reference - 1.0
    within = [row for row in rows[:-1] if abs(row["error_vs_finest"]) <= 0.01]
    chosen = max(within, key=lambda r: r["size_near_m"]) if within else rows[-1]
    return {"rows": rows, "chosen_size_near_m": chosen["size_near_m"]}


def _records(folder: Path, material: dict, size_near_m: float, device: str, seed: int) -> list:
    """Write three synthetic ramp-and-hold records made by the forward FE (fine time grid)."""
    from warptissue.fem import simulate_indentation
    from warptissue.io import write_csv
    from warptissue.simulate import build_mesh, build_problem
    from warptissue.study import study_from_dict

    rng = np.random.default_rng(seed)
    table = _study_table(size_near_m, material, time_steps=2, free=["C10_Pa"])
    table.pop("fit")
    study = study_from_dict(table)
    mesh = build_mesh(study)
    problem = build_problem(study, mesh)
    files = []
    for speed in SPEEDS_M_PER_S:
        ramp_s = DEPTH_M / speed
        fe_times = np.concatenate(
            [np.linspace(ramp_s / 24, ramp_s, 24), ramp_s + np.geomspace(ramp_s / 24, HOLD_S, 48)]
        )
        fe_depths = DEPTH_M * np.minimum(fe_times / ramp_s, 1.0)
        result = simulate_indentation(
            problem, fe_depths, times_s=fe_times, device=device, progress=False, strict=True
        )
        rate_Hz = max(50.0, 400.0 / ramp_s)
        t = np.arange(0.0, ramp_s + HOLD_S, 1.0 / rate_Hz)
        t = np.unique(np.concatenate([t, np.geomspace(ramp_s, ramp_s + HOLD_S, 200)]))
        force = np.interp(
            t, np.concatenate([[0.0], fe_times]), np.concatenate([[0.0], result.reaction_force_N])
        )
        peak = float(np.max(force))
        noisy = force + NOISE_SHARE * peak * rng.standard_normal(t.size)
        path = folder / f"ramp_{speed * 1e3:g}mm_per_s.csv"
        write_csv(
            path,
            {
                "time_s": t,
                "displacement_m": DEPTH_M * np.minimum(t / ramp_s, 1.0),
                "force_N": noisy,
            },
        )
        files.append(path.name)
    return files


def _fit_part(
    name: str,
    material: dict,
    free: list[str],
    truth: dict,
    *,
    size_near_m: float,
    device: str,
    time_steps: int,
    seed: int,
) -> dict:
    import tomli_w

    from warptissue.fit.indentation import fit_indentation
    from warptissue.study import load_study

    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        start = time.perf_counter()
        files = _records(folder, material, size_near_m, device, seed)
        made_s = time.perf_counter() - start
        table = _study_table(size_near_m, material, time_steps=time_steps, free=free)
        table["solver"]["device"] = device
        table["solver"].update(SOLVER)
        table["data"] = [{"file": f} for f in files]
        (folder / "study.toml").write_text(tomli_w.dumps(table))
        study = load_study(folder / "study.toml")
        # The moduli start from the records' small-depth stiffness; g_i 30 % below the truth.
        if any(key.startswith("g") for key in free):
            names = study.material.parameter_names
            vector = np.array(
                [
                    0.7 * material[k] if k in free and k.startswith("g") else material[k]
                    for k in names
                ]
            )
            study = dataclasses.replace(study, material=study.material.with_parameters(vector))
        fit = fit_indentation(study, device=device, progress=False)
    n = len(free)
    found = fit.parameters
    errors = fit.result.standard_errors
    row = {
        "name": name,
        "free": free,
        "records_made_s": made_s,
        "status": fit.status,
        "iterations": fit.result.iterations,
        "forward_solves": fit.forward_solves,
        "finite_difference_solves": fit.finite_difference_solves,
        "solve_ratio": fit.finite_difference_solves / max(fit.forward_solves, 1),
        "seconds": fit.seconds,
        "r_squared": fit.result.r_squared,
        "parameters": {
            key: {
                "fitted": found[key],
                "true": truth[key],
                "error": found[key] / truth[key] - 1.0,
                "standard_error": None if errors is None else float(errors[i]),
            }
            for i, key in enumerate(free)
        },
        "start": fit.start,
        "warnings": fit.warnings,
        "n": n,
    }
    print(
        f"{name}: {fit.status}, {row['iterations']} iterations, {row['forward_solves']} "
        f"forward runs (forward differences: {row['finite_difference_solves']}), "
        f"{row['seconds']:.1f} s, R^2 {row['r_squared']:.5f}",
        flush=True,
    )
    for key, value in row["parameters"].items():
        print(
            f"  {key}: {value['fitted']:.6g} (true {value['true']:.6g}, "
            f"{100 * value['error']:+.2f} %)",
            flush=True,
        )
    return row


def _markdown(results: dict) -> str:
    """The tables of docs/performance.md (the machine and date are in the page's text)."""
    lines: list[str] = []
    if "mesh" in results:
        lines += [
            "| size_near_m | tets | force at 3.6 mm (N) | vs the finest |",
            "|---|---|---|---|",
        ]
        for row in results["mesh"]["rows"]:
            lines.append(
                f"| {row['size_near_m'] * 1e3:.3g} mm | {row['tets']} | {row['force_N']:.5g} "
                f"| {100 * row['error_vs_finest']:+.2f} % |"
            )
    fits = [results[k] for k in ("c10", "four") if k in results]
    if fits:
        if lines:
            lines.append("")
        lines += [
            "| free | iterations | forward runs | forward differences would need | time | R² "
            "| recovered |",
            "|---|---|---|---|---|---|---|",
        ]
        for row in fits:
            recovered = ", ".join(
                f"{k} {v['fitted']:.4g} ({100 * v['error']:+.1f} %)"
                for k, v in row["parameters"].items()
            )
            lines.append(
                f"| {', '.join(row['free'])} | {row['iterations']} | {row['forward_solves']} | "
                f"{row['finite_difference_solves']} ({row['solve_ratio']:.1f}x) | "
                f"{row['seconds']:.1f} s | {row['r_squared']:.4f} | {recovered} |"
            )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default="cpu")
    parser.add_argument(
        "--parts", nargs="+", default=["mesh", "c10", "four"], choices=["mesh", "c10", "four"]
    )
    parser.add_argument("--sizes-mm", nargs="+", type=float, default=[2.5, 1.67, 1.25, 0.83, 0.625])
    parser.add_argument(
        "--size-near-mm",
        type=float,
        default=None,
        help="mesh of the fits (default: the mesh part's choice, else 1.67 mm)",
    )
    parser.add_argument("--time-steps", type=int, default=24)
    parser.add_argument(
        "--solver",
        nargs="*",
        default=[],
        metavar="KEY=VALUE",
        help="[solver] settings of the fits' study, e.g. nonlinear_elimination=false",
    )
    parser.add_argument("--quick", action="store_true", help="a tiny run (tests)")
    parser.add_argument("--out", type=Path, default=None)
    parser.add_argument("--markdown", type=Path, default=None)
    args = parser.parse_args(argv)
    if args.markdown is not None:
        print(_markdown(json.loads(args.markdown.read_text())))
        return 0
    if args.quick:
        args.sizes_mm, args.time_steps = [5.0, 2.5], 6
        args.size_near_mm = args.size_near_mm or 5.0
    results: dict = {
        "machine": f"{platform.machine()} {os.cpu_count()}-core {platform.system()}",
        "device": args.device,
        "date": time.strftime("%Y-%m-%d"),
        "python": sys.version.split()[0],
        "time_steps": args.time_steps,
    }
    for item in args.solver:
        key, _, value = item.partition("=")
        SOLVER[key] = {"true": True, "false": False}.get(value.lower(), value)
    results["solver"] = dict(SOLVER)
    size = None if args.size_near_mm is None else args.size_near_mm * 1e-3
    if "mesh" in args.parts:
        results["mesh"] = _mesh_part(args.device, [s * 1e-3 for s in args.sizes_mm])
        size = size or results["mesh"]["chosen_size_near_m"]
    size = size or 1.67e-3
    results["fit_size_near_m"] = size
    prony = {k: TRUTH[k] for k in ("g1", "g2", "tau1_s", "tau2_s")}
    if "c10" in args.parts:
        material = {
            "model": "neo_hookean",
            "C10_Pa": TRUTH["C10_Pa"],
            "bulk_modulus_Pa": 2 * BULK_RATIO * TRUTH["C10_Pa"],
            **prony,
        }
        results["c10"] = _fit_part(
            "c10",
            material,
            ["C10_Pa"],
            TRUTH,
            size_near_m=size,
            device=args.device,
            time_steps=args.time_steps,
            seed=1,
        )
    if "four" in args.parts:
        truth = {**TRUTH, "C20_Pa": 1000.0}
        material = {
            "model": "reduced_polynomial",
            "C10_Pa": TRUTH["C10_Pa"],
            "C20_Pa": 1000.0,
            "bulk_modulus_Pa": 2 * BULK_RATIO * TRUTH["C10_Pa"],
            **prony,
        }
        results["four"] = _fit_part(
            "four",
            material,
            ["C10_Pa", "C20_Pa", "g1", "g2"],
            truth,
            size_near_m=size,
            device=args.device,
            time_steps=args.time_steps,
            seed=2,
        )
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(results, indent=2) + "\n")
    print(_markdown(results))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
