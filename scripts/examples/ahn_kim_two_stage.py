"""Ahn & Kim's Table 1 -> Table 2 workflow, reproduced on FE-made ramp-and-hold records.

Ahn & Kim indented porcine liver with a flat probe (ramp at 8 mm/s, then a hold), fitted a
two-term Prony series to each experiment's normalized relaxation (their Table 1: tau1, tau2,
g1, g2) and then, with those terms fixed, the neo-Hookean C10 by inverse FE until R^2 > 0.99
(their Eq. 9; Table 2: C10 = 287.5 +- 53.7 Pa). Here each of the three experiments of Table 1
becomes a synthetic record with a known truth:

- the forward viscoelastic FE (:func:`warptissue.fem.simulate_indentation` with
  ``times_s``) of the liver slab of ``scenes/liver_fit.toml`` (a 40 x 40 x 20 mm quarter
  block on a fixed base, a 5 mm radius bonded flat punch; its mesh, size_near_m = 2 mm:
  the force at 3.6 mm lies 0.4 % from a 7157-node mesh's), neo-Hookean C10 = 287.5 Pa with
  K = 1000 x 2 C10 and the experiment's Table 1 Prony series (G(t) = 1 - sum g_i (1 -
  exp(-t/tau_i)), the sign of Ahn & Kim's Eq. 5 corrected);
- a ramp at 8 mm/s (Ahn & Kim's speed) to 3.6 mm, then a 120 s hold; the FE runs on a finer
  time grid (16 ramp + 64 hold steps) than the fit (``fit.time_steps``);
- sampled as a rig would (50 Hz, 800 Hz during the ramp), plus seeded Gaussian noise of 1 %
  of the peak force.

Each record is fitted with :func:`warptissue.fit.indentation.fit_indentation`:

- ``strategy="two_stage"`` (Ahn & Kim): stage (i) the Prony series from the record's
  relaxation (:func:`warptissue.viscoelastic.fitting.fit_qlv`: QLV with an exponential elastic
  force, the finite ramp included), compared with Table 1; stage (ii) C10 by inverse FE with
  those Prony terms fixed, compared with 287.5 Pa, and R^2 against Ahn & Kim's 0.99;
- ``strategy="joint"``: C10, g1, g2, tau1, tau2 at once, from generic start values
  (g = 0.3, 0.3; tau = 1, 30 s; C10 from the record's small-depth stiffness), for comparison
  (iterations, forward runs, recovered values).

Prints a table (experiment | Table 1 truth | stage (i) | C10 (stage ii) | R^2 | joint fit) and
writes it as JSON. The full run takes 5 to 10 minutes on a shared 2-core CPU;
``--quick`` (one experiment, a tiny mesh, few steps, a 60 s hold) takes well under a minute
once the Warp kernels are compiled.

Usage:
    python scripts/examples/ahn_kim_two_stage.py [--quick] [--out JSON] [--device cpu]
        [--experiments 1 2 3] [--size-near-mm 2.0] [--time-steps 32]
    python scripts/examples/ahn_kim_two_stage.py --markdown RESULTS.json

Exit status: 0 on success (every fit ran; a missed recovery is reported, not an error),
2 on bad arguments or input (one line on stderr), another warptissue error's own status
(1, or ConvergenceError's) when a fit cannot run.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

C10_PA = 287.5
"""Ahn & Kim, Table 2: the mean C10 of the three experiments (Pa)."""
BULK_RATIO = 1000.0
"""K = BULK_RATIO x 2 C10 (nearly incompressible)."""
TABLE_1 = {
    1: {"tau1_s": 1.376, "tau2_s": 49.369, "g1": 0.348, "g2": 0.358},
    2: {"tau1_s": 1.087, "tau2_s": 52.545, "g1": 0.353, "g2": 0.365},
    3: {"tau1_s": 0.944, "tau2_s": 51.698, "g1": 0.408, "g2": 0.288},
}
"""Ahn & Kim, Table 1: the Prony series of the three experiments."""
TABLE_2_C10_PA = {1: 246.1, 2: 320.7, 3: 295.7}
"""Ahn & Kim, Table 2: the C10 each experiment gave on real liver (for reference only)."""
SPEED_M_PER_S = 0.008
DEPTH_M = 0.0036
NOISE_SHARE = 0.01
"""Gaussian noise: this share of the peak force (one standard deviation)."""
JOINT_START = {"g1": 0.3, "g2": 0.3, "tau1_s": 1.0, "tau2_s": 30.0}
"""Start values of the Prony terms in the joint fit (as scenes/liver_fit.toml)."""
PRONY = ("g1", "g2", "tau1_s", "tau2_s")


def _settings(quick: bool, args: argparse.Namespace) -> dict:
    """The run's settings (mesh, time grids, sampling)."""
    if quick:
        return {
            "size_near_m": (args.size_near_mm or 5.0) * 1e-3,
            "size_far_m": 10e-3,
            "hold_s": 60.0,
            "data_ramp_steps": 8,
            "data_hold_steps": 24,
            "fit_time_steps": args.time_steps or 10,
            "ramp_rate_Hz": 200.0,
            "hold_rate_Hz": 10.0,
        }
    return {
        "size_near_m": (args.size_near_mm or 2.0) * 1e-3,
        "size_far_m": 8e-3,
        "hold_s": 120.0,
        "data_ramp_steps": 16,
        "data_hold_steps": 64,
        "fit_time_steps": args.time_steps or 32,
        "ramp_rate_Hz": 800.0,
        "hold_rate_Hz": 50.0,
    }


def _study_table(settings: dict, material: dict, device: str) -> dict:
    """The liver slab of scenes/liver_fit.toml at the run's mesh, with a ramp-and-hold."""
    return {
        "schema_version": 2,
        "name": "ahn_kim_two_stage",
        "specimen": {
            "shape": "block",
            "width_m": 0.040,
            "thickness_m": 0.020,
            "quarter": True,
            "element": "TET10",
            "size_near_m": settings["size_near_m"],
            "size_far_m": settings["size_far_m"],
            "growth": 1.5,
        },
        "indenter": {"kind": "flat_punch", "radius_m": 0.005, "contact": "bonded"},
        "protocol": {
            "kind": "ramp_hold",
            "max_depth_m": DEPTH_M,
            "speed_m_per_s": SPEED_M_PER_S,
            "hold_s": settings["hold_s"],
            "ramp_steps": settings["data_ramp_steps"],
            "hold_steps": settings["data_hold_steps"],
        },
        "material": material,
        "boundary": {"base": "fixed"},
        "solver": {"device": device, "formulation": "mixed"},
    }


def _truth(experiment: int) -> dict:
    return {"C10_Pa": C10_PA, **TABLE_1[experiment]}


def _material(values: dict) -> dict:
    return {
        "model": "neo_hookean",
        "C10_Pa": values["C10_Pa"],
        "bulk_modulus_Pa": 2 * BULK_RATIO * C10_PA,
        **{key: values[key] for key in PRONY},
    }


def make_record(experiment: int, settings: dict, device: str, seed: int) -> dict:
    """A synthetic ramp-and-hold record of one experiment: FE force at rig samples + noise.

    Returns:
        ``time_s``, ``displacement_m``, ``force_N`` (noisy), ``clean_force_N`` (the FE force
        at the samples), ``peak_force_N``, ``noise_N``, ``fe_steps``, ``seconds``.
    """
    from warptissue.fem import simulate_indentation
    from warptissue.simulate import build_mesh, build_problem
    from warptissue.study import study_from_dict

    started = time.perf_counter()
    study = study_from_dict(_study_table(settings, _material(_truth(experiment)), device))
    mesh = build_mesh(study)
    fe_times = np.asarray(study.protocol.times_s, dtype=np.float64)
    fe_depths = np.asarray(study.protocol.depths_m, dtype=np.float64)
    result = simulate_indentation(
        build_problem(study, mesh),
        fe_depths,
        times_s=fe_times,
        device=device,
        progress=False,
        strict=True,
    )
    ramp_s = DEPTH_M / SPEED_M_PER_S
    end_s = ramp_s + settings["hold_s"]
    t = np.concatenate(
        [
            np.arange(0.0, ramp_s, 1.0 / settings["ramp_rate_Hz"]),
            np.arange(ramp_s, end_s + 1e-9, 1.0 / settings["hold_rate_Hz"]),
        ]
    )
    clean = np.interp(
        t,
        np.concatenate([[0.0], fe_times]),
        np.concatenate([[0.0], np.asarray(result.reaction_force_N, dtype=np.float64)]),
    )
    peak = float(np.max(clean))
    noise = NOISE_SHARE * peak
    rng = np.random.default_rng(seed)
    return {
        "time_s": t,
        "displacement_m": DEPTH_M * np.minimum(t / ramp_s, 1.0),
        "force_N": clean + noise * rng.standard_normal(t.size),
        "clean_force_N": clean,
        "peak_force_N": peak,
        "noise_N": noise,
        "fe_steps": int(fe_times.size),
        "mesh_nodes": int(mesh.node_count),
        "mesh_tets": int(mesh.tet_count),
        "seconds": time.perf_counter() - started,
    }


def _sorted_prony(values: dict) -> dict:
    """The Prony terms ordered by relaxation time (tau1 < tau2), as Table 1 orders them."""
    pairs = sorted(
        ((values["tau1_s"], values["g1"]), (values["tau2_s"], values["g2"])),
        key=lambda pair: pair[0],
    )
    return {
        "tau1_s": float(pairs[0][0]),
        "tau2_s": float(pairs[1][0]),
        "g1": float(pairs[0][1]),
        "g2": float(pairs[1][1]),
    }


def _errors(found: dict, truth: dict) -> dict:
    return {key: float(found[key] / truth[key] - 1.0) for key in found if key in truth}


def _r_squared_at_start(fit, measured: np.ndarray) -> float | None:
    """R^2 at the start values, from the fit's start cost (absolute objective)."""
    start = getattr(fit, "start_cost", None)
    if start is None:
        return None
    return 1.0 - 2.0 * start / float(np.sum((measured - np.mean(measured)) ** 2))


def _ahn_kim_stop(fit, measured: np.ndarray) -> dict | None:
    """Where Ahn & Kim's stop (Eq. 9, R^2 > 0.99) would have ended stage (ii): the start
    (iteration 0) or the first accepted trial step with R^2 > 0.99, from the costs
    (absolute objective: R^2 = 1 - 2 cost / SS_tot), and its C10; None if never."""
    total = float(np.sum((measured - np.mean(measured)) ** 2))
    start = getattr(fit, "start_cost", None)
    if start is not None and 1.0 - 2.0 * start / total > 0.99:
        c10 = float(fit.start["C10_Pa"])
        return {
            "iteration": 0,
            "r_squared": 1.0 - 2.0 * start / total,
            "C10_Pa": c10,
            "error": c10 / C10_PA - 1.0,
        }
    for record in fit.result.history:
        r2 = 1.0 - 2.0 * record.cost / total
        if record.accepted and r2 > 0.99:
            c10 = float(record.x[0])
            return {
                "iteration": int(record.iteration),
                "r_squared": r2,
                "C10_Pa": c10,
                "error": c10 / C10_PA - 1.0,
            }
    return None


def fit_experiment(experiment: int, settings: dict, device: str, seed: int, folder: Path) -> dict:
    """Make one experiment's record and fit it two-stage (Ahn & Kim) and jointly."""
    import tomli_w

    from warptissue.fit.indentation import fit_indentation
    from warptissue.io import write_csv
    from warptissue.study import load_study
    from warptissue.viscoelastic.fitting import fit_qlv

    truth = _truth(experiment)
    record = make_record(experiment, settings, device, seed)
    print(
        f"experiment {experiment}: record made by the FE ({record['mesh_nodes']} nodes, "
        f"{record['fe_steps']} time steps, {record['seconds']:.1f} s); peak force "
        f"{record['peak_force_N'] * 1e3:.2f} mN, noise {record['noise_N'] * 1e3:.3f} mN",
        flush=True,
    )
    name = f"ahn_kim_exp{experiment}.csv"
    write_csv(
        folder / name,
        {
            "time_s": record["time_s"],
            "displacement_m": record["displacement_m"],
            "force_N": record["force_N"],
        },
    )
    start = {"C10_Pa": C10_PA, **JOINT_START}
    table = _study_table(settings, _material(start), device)
    table["data"] = [{"file": name}]
    table["fit"] = {
        "free": ["C10_Pa", *PRONY],
        "strategy": "two_stage",
        "method": "lm",
        "objective": "absolute",
        "time_steps": settings["fit_time_steps"],
        "max_iterations": 50,
        "bounds": {"C10_Pa": [1.0, 1e5], "tau1_s": [0.01, 1000.0], "tau2_s": [0.01, 1000.0]},
    }
    path = folder / f"ahn_kim_exp{experiment}.toml"
    path.write_text(tomli_w.dumps(table), encoding="utf-8")
    study = load_study(path)

    two = fit_indentation(study, strategy="two_stage", device=device, progress=False)
    # Stage (i) on the noise-free FE force: what is left is the model's own error (QLV with
    # an exponential elastic force against the FE's nonuniform field), not the noise's.
    clean = fit_qlv(record["time_s"], record["displacement_m"], record["clean_force_N"], terms=2)
    clean_values = _sorted_prony(clean.parameters)
    stage_one = two.stage_one_fits[0]
    stage_one_values = _sorted_prony(stage_one.parameters)
    c10 = two.parameters["C10_Pa"]
    c10_se = None if two.result.standard_errors is None else float(two.result.standard_errors[0])
    row = {
        "experiment": experiment,
        "truth": truth,
        "record": {
            key: record[key]
            for key in ("peak_force_N", "noise_N", "fe_steps", "mesh_nodes", "mesh_tets")
        }
        | {"samples": int(record["time_s"].size)},
        "stage_one": {
            "parameters": stage_one_values,
            "exponential_elastic_force": {
                "k0_N_per_m": float(stage_one.parameters["k0_N_per_m"]),
                "B_per_m": float(stage_one.parameters["B_per_m"]),
            },
            "errors": _errors(stage_one_values, truth),
            "standard_errors": None
            if stage_one.standard_errors is None
            else dict(
                zip(stage_one.parameter_names, map(float, stage_one.standard_errors), strict=True)
            ),
            "r_squared": stage_one.r_squared,
            "status": stage_one.status,
            "iterations": stage_one.iterations,
            "noise_free": {
                "parameters": clean_values,
                "errors": _errors(clean_values, truth),
                "r_squared": clean.r_squared,
            },
        },
        "stage_two": {
            "C10_Pa": c10,
            "standard_error_Pa": c10_se,
            "error": c10 / C10_PA - 1.0,
            "start_C10_Pa": two.start.get("C10_Pa"),
            "start_r_squared": _r_squared_at_start(two, record["force_N"]),
            "r_squared": two.result.r_squared,
            "rmse_N": two.result.rmse,
            "iterations": two.result.iterations,
            "forward_solves": two.forward_solves,
            "finite_difference_solves": two.finite_difference_solves,
            "ahn_kim_stop": _ahn_kim_stop(two, record["force_N"]),
            "status": two.status,
            "seconds": two.seconds,
            "warnings": list(two.warnings),
        },
    }
    print(
        "  two-stage: stage (i) "
        + ", ".join(f"{k} {v:.4g}" for k, v in stage_one_values.items())
        + f"; stage (ii) C10 {c10:.2f} Pa ({100 * row['stage_two']['error']:+.2f} %), "
        f"R^2 {two.result.r_squared:.5f}, {two.result.iterations} iterations, "
        f"{two.forward_solves} forward runs, {two.seconds:.1f} s",
        flush=True,
    )

    joint = fit_indentation(study, strategy="joint", device=device, progress=False)
    found = dict(joint.parameters)
    joint_values = {"C10_Pa": float(found["C10_Pa"]), **_sorted_prony(found)}
    errors = None if joint.result.standard_errors is None else joint.result.standard_errors
    row["joint"] = {
        "parameters": joint_values,
        "standard_errors": None
        if errors is None
        else dict(zip(joint.result.parameter_names, map(float, errors), strict=True)),
        "errors": _errors(joint_values, truth),
        "start": dict(joint.start),
        "r_squared": joint.result.r_squared,
        "rmse_N": joint.result.rmse,
        "iterations": joint.result.iterations,
        "forward_solves": joint.forward_solves,
        "finite_difference_solves": joint.finite_difference_solves,
        "status": joint.status,
        "seconds": joint.seconds,
        "warnings": list(joint.warnings),
    }
    print(
        "  joint: "
        + ", ".join(f"{k} {v:.4g}" for k, v in joint_values.items())
        + f"; R^2 {joint.result.r_squared:.5f}, {joint.result.iterations} iterations, "
        f"{joint.forward_solves} forward runs, {joint.seconds:.1f} s",
        flush=True,
    )
    return row


def _pct(value: float) -> str:
    return f"{100 * value:+.1f} %"


def markdown(results: dict) -> str:
    """The tables of docs/viscoelastic.md ("Ahn & Kim's two-stage characterization")."""
    lines = [
        f"Machine: {results['machine']}; device {results['device']}; {results['date']}; "
        f"`{results['command']}`.",
        "",
        "| exp. | Table 1 truth: tau1, tau2 (s), g1, g2 | stage (i): tau1, tau2, g1, g2 "
        "(error) | C10, stage (ii) (truth 287.5 Pa) | R² (ii) | joint fit: C10, tau1, tau2, "
        "g1, g2 (error) |",
        "|---|---|---|---|---|---|",
    ]
    for row in results["experiments"]:
        truth, one, two, joint = row["truth"], row["stage_one"], row["stage_two"], row["joint"]
        se = two["standard_error_Pa"]
        lines.append(
            f"| {row['experiment']} "
            f"| {truth['tau1_s']}, {truth['tau2_s']}, {truth['g1']}, {truth['g2']} "
            "| "
            + ", ".join(
                f"{one['parameters'][k]:.4g} ({_pct(one['errors'][k])})"
                for k in ("tau1_s", "tau2_s", "g1", "g2")
            )
            + f" | {two['C10_Pa']:.1f}"
            + ("" if se is None else f" ± {se:.1f}")
            + f" Pa ({_pct(two['error'])}) | {two['r_squared']:.4f} | "
            + ", ".join(
                f"{joint['parameters'][k]:.4g} ({_pct(joint['errors'][k])})"
                for k in ("C10_Pa", "tau1_s", "tau2_s", "g1", "g2")
            )
            + " |"
        )
    lines += [
        "",
        "| exp. | two-stage: stage (ii) iterations, forward runs, time | Ahn & Kim's stop: "
        "R² > 0.99 first at iteration | joint: iterations, forward runs (forward "
        "differences would need), time, R² |",
        "|---|---|---|---|",
    ]
    for row in results["experiments"]:
        two, joint = row["stage_two"], row["joint"]
        stop = two["ahn_kim_stop"]
        lines.append(
            f"| {row['experiment']} | {two['iterations']}, {two['forward_solves']}, "
            f"{two['seconds']:.0f} s | "
            + (
                "never"
                if stop is None
                else f"{stop['iteration']} (C10 {stop['C10_Pa']:.1f} Pa, {_pct(stop['error'])})"
            )
            + " | "
            f"{joint['iterations']}, {joint['forward_solves']} "
            f"({joint['finite_difference_solves']}), {joint['seconds']:.0f} s, "
            f"{joint['r_squared']:.4f} |"
        )
    clean = [row for row in results["experiments"] if "noise_free" in row["stage_one"]]
    if clean:
        lines += [
            "",
            "| exp. | stage (i) on the noise-free FE force: tau1, tau2, g1, g2 (error) | R² |",
            "|---|---|---|",
        ]
        for row in clean:
            free = row["stage_one"]["noise_free"]
            lines.append(
                f"| {row['experiment']} | "
                + ", ".join(
                    f"{free['parameters'][k]:.4g} ({_pct(free['errors'][k])})"
                    for k in ("tau1_s", "tau2_s", "g1", "g2")
                )
                + f" | {free['r_squared']:.6f} |"
            )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Run the workflow (see the module docstring); a WarpTissueError is one line on stderr."""
    from warptissue.errors import WarpTissueError

    try:
        return _main(argv)
    except (WarpTissueError, OSError, json.JSONDecodeError) as exc:
        print(f"ahn_kim_two_stage.py: error: {exc}", file=sys.stderr)
        return int(getattr(exc, "exit_code", 2))


def _main(argv: list[str] | None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="one experiment, a tiny mesh")
    parser.add_argument("--out", type=Path, default=None, help="write the results (JSON)")
    parser.add_argument("--device", default="cpu", help="Warp device (cpu, cuda, cuda:N)")
    parser.add_argument("--experiments", nargs="+", type=int, choices=sorted(TABLE_1))
    parser.add_argument("--size-near-mm", type=float, default=None, help="mesh size_near (2.0)")
    parser.add_argument("--time-steps", type=int, default=None, help="fit.time_steps (32)")
    parser.add_argument("--seed", type=int, default=20100, help="noise seed")
    parser.add_argument("--markdown", type=Path, default=None, help="print a JSON's tables")
    args = parser.parse_args(argv)
    if args.markdown is not None:
        print(markdown(json.loads(args.markdown.read_text(encoding="utf-8"))))
        return 0
    experiments = args.experiments or ([1] if args.quick else [1, 2, 3])
    settings = _settings(args.quick, args)
    results: dict = {
        "method": "Ahn & Kim two-stage (stage (i) QLV Prony series, stage (ii) C10 by "
        "inverse FE) against the joint fit of all five parameters",
        "machine": f"{platform.machine()} {os.cpu_count()}-core {platform.system()}",
        "device": args.device,
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "command": "python scripts/examples/ahn_kim_two_stage.py "
        + " ".join(sys.argv[1:] if argv is None else argv),
        "python": sys.version.split()[0],
        "quick": bool(args.quick),
        "settings": settings
        | {
            "C10_Pa": C10_PA,
            "bulk_modulus_Pa": 2 * BULK_RATIO * C10_PA,
            "speed_m_per_s": SPEED_M_PER_S,
            "depth_m": DEPTH_M,
            "noise_share_of_peak": NOISE_SHARE,
            "joint_start": JOINT_START,
            "seed": args.seed,
        },
        "experiments": [],
    }
    from warptissue.io import write_json

    started = time.perf_counter()
    with tempfile.TemporaryDirectory() as folder:
        for experiment in experiments:
            results["experiments"].append(
                fit_experiment(
                    experiment, settings, args.device, args.seed + experiment, Path(folder)
                )
            )
            results["seconds"] = time.perf_counter() - started
            results["complete"] = len(results["experiments"]) == len(experiments)
            if args.out is not None:  # after each experiment: a long run keeps what it did
                write_json(args.out, results)
    print(markdown(results))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
