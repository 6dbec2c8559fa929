"""Benchmark: a fit's next evaluation started warm against cold (docs/design-notes/warm-start.md).

The bundled slab study (``scenes/liver_slab_flat_punch.toml``) coarsened to a near size of
0.5 mm, under its bonded flat punch or a rigid sphere of radius 2 mm, is run at its C10 (K at
the same ratio), then at each other C10 twice: from the predictor (cold) and from the first
run's states (``warm_states_m``). Prints and writes the Newton iterations, the seconds and the
largest relative differences of the forces and of their C10 sensitivities.

Usage:
    python scripts/benchmarks/bench_warm_start.py [--probe punch|sphere] [--factors 1.05,0.8]
        [--device cpu] [--out warm.json]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import numpy as np

from warptissue.fem import simulate_indentation
from warptissue.simulate import build_mesh, build_problem
from warptissue.study import load_study, study_from_dict

ROOT = Path(__file__).resolve().parents[2]
SCENE = ROOT / "scenes" / "liver_slab_flat_punch.toml"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--probe", choices=("punch", "sphere"), default="sphere")
    parser.add_argument("--factors", default="1.05,0.8", help="C10 factors, comma separated")
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    record = load_study(SCENE).to_dict()
    record["specimen"].update(size_near_m=5.0e-4, size_far_m=5.0e-3, growth=1.4)
    record["solver"]["device"] = args.device
    if args.probe == "sphere":
        record["indenter"] = {"kind": "sphere", "radius_m": 0.002}
        depths = np.array([1e-4, 2e-4, 3e-4, 4e-4])
    else:
        depths = np.array([2e-4, 4e-4, 6e-4, 8e-4])
    study = study_from_dict(record)
    mesh = build_mesh(study)
    problem = build_problem(study, mesh)

    def run(material, warm=None):
        started = time.perf_counter()
        result = simulate_indentation(
            dataclasses.replace(problem, material=material),
            depths,
            device=args.device,
            progress=False,
            sensitivities=("C10_Pa",),
            warm_states_m=warm,
        )
        assert result.completed, result.message
        return result, time.perf_counter() - started

    first, seconds = run(problem.material)
    rows = [{"C10_factor": 1.0, "iterations": first.newton_iterations.tolist(), "s": seconds}]
    print(f"{mesh.tet_count} tets; at C10: {first.newton_iterations.tolist()} its, {seconds:.2f} s")
    for factor in (float(f) for f in args.factors.split(",")):
        material = problem.material.with_parameters(problem.material.parameter_vector * factor)
        cold, cold_s = run(material)
        warm, warm_s = run(material, first.displacement_m)
        force = np.max(np.abs(warm.reaction_force_N / cold.reaction_force_N - 1.0))
        slopes = np.max(
            np.abs(warm.force_sensitivity_N_per_unit / cold.force_sensitivity_N_per_unit - 1.0)
        )
        row = {
            "C10_factor": factor,
            "cold_iterations": cold.newton_iterations.tolist(),
            "cold_s": cold_s,
            "warm_iterations": warm.newton_iterations.tolist(),
            "warm_s": warm_s,
            "force_difference": float(force),
            "sensitivity_difference": float(slopes),
        }
        rows.append(row)
        print(json.dumps(row))
    if args.out is not None:
        args.out.write_text(json.dumps({"probe": args.probe, "runs": rows}, indent=2) + "\n")


if __name__ == "__main__":
    main()
