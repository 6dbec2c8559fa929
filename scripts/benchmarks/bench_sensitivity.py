"""Cost of the exact force Jacobian per parameter against finite differences of whole runs.

A flat-punch curve on a small quarter block (TET10, mean dilatation) of a two-term Ogden
material; for 1, 2 and 4 parameters (mu1; mu1, alpha1; mu1, alpha1, mu2, alpha2). With
``--viscoelastic`` the material relaxes (a two-term Prony series on the Ogden model) and the
curve is a ramp and a hold, time-stepped, whose sensitivities are carried forward in time
(mu1; mu1, g1; mu1, alpha1, g1, tau1_s):

- the curve with exact sensitivities (``"reuse"``: Newton's last factors with iterative
  refinement; ``"refactorize"``: one fresh factorization per depth): the time spent in the
  sensitivities (``ForceSensitivity.seconds``) per parameter, as a fraction of the rest of
  the same run (the forward curve);
- forward differences (p more forward runs) and central differences (2p), timed against a
  forward run made just before them;
- the agreement of the exact Jacobian with central differences of runs at Newton tolerance
  1e-12 and relative step 1e-6 (not timed).

Each ratio is the median of ``--repeat`` interleaved repetitions (the machine is shared).
Writes a JSON file.

Usage: python scripts/benchmarks/bench_sensitivity.py [--near 0.5] [--steps 5]
    [--repeat 3] [--viscoelastic] [--out scripts/results/bench_sensitivity_2core_cpu.json]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numpy as np

from warptissue.fem import (
    Assembler,
    ForceSensitivity,
    IndentationProblem,
    NewtonOptions,
    simulate_indentation,
    solve_quasistatic,
)
from warptissue.indenter import Indenter
from warptissue.materials import Ogden, Viscoelastic, material_from_dict
from warptissue.mesh import indentation_block

RADIUS_M = 1e-3
MATERIAL = Ogden((150.0, 30.0), (4.0, -2.0), 5000.0)
PARAMETER_SETS = {
    1: ("mu1_Pa",),
    2: ("mu1_Pa", "alpha1"),
    4: ("mu1_Pa", "alpha1", "mu2_Pa", "alpha2"),
}
VISCOELASTIC = Viscoelastic(MATERIAL, (0.3, 0.3), (0.5, 10.0))
VISCOELASTIC_SETS = {
    1: ("mu1_Pa",),
    2: ("mu1_Pa", "g1"),
    4: ("mu1_Pa", "alpha1", "g1", "tau1_s"),
}
TIMES_S: np.ndarray | None = None
"""The step times of the viscoelastic curve (None: quasi-static)."""
RELATIVE_STEP = 1e-6
REFERENCE_STEPS = (1e-4, 1e-6)
"""Relative steps of the reference central differences (Newton tolerance 1e-12): at 1e-6 the
runs' own convergence noise, divided by the step, limits the agreement to about 1e-6-1e-5; at
1e-4 the truncation error (h^2) is still below it."""


def _problem(mesh, material) -> IndentationProblem:
    return IndentationProblem(mesh, material, Indenter("flat_punch", radius_m=RADIUS_M))


def _moved(name: str, sign: float, relative_step: float = RELATIVE_STEP) -> Ogden:
    flat = _material().to_dict()
    return material_from_dict({**flat, name: flat[name] + sign * relative_step * abs(flat[name])})


def _central_difference(mesh, depths: np.ndarray, name: str, relative_step: float) -> np.ndarray:
    """(F(theta + h) - F(theta - h)) / 2h of runs at Newton tolerance 1e-12, shape (S,)."""
    forces = [
        simulate_indentation(
            _problem(mesh, _moved(name, sign, relative_step)),
            depths,
            device="cpu",
            progress=False,
            options=NewtonOptions(tolerance=1e-12 if TIMES_S is None else 1e-10),
            times_s=TIMES_S,
        ).reaction_force_N
        for sign in (1.0, -1.0)
    ]
    step = relative_step * abs(_material().to_dict()[name])
    return (forces[0] - forces[1]) / (2.0 * step)


def _material():
    return MATERIAL if TIMES_S is None else VISCOELASTIC


def _timed(function, repeat: int):
    best, value = float("inf"), None
    for _ in range(repeat):
        start = time.perf_counter()
        value = function()
        best = min(best, time.perf_counter() - start)
    return best, value


def main() -> None:
    """Run the comparison and write the JSON."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--near", type=float, default=0.5, help="element size at the punch / a")
    parser.add_argument("--steps", type=int, default=5, help="depths up to a quarter radius")
    parser.add_argument("--repeat", type=int, default=3, help="timed repetitions (median kept)")
    parser.add_argument("--out", type=Path, default=None, help="JSON file to write")
    parser.add_argument(
        "--viscoelastic", action="store_true", help="a Prony series, a ramp and a hold"
    )
    args = parser.parse_args()
    global TIMES_S
    parameter_sets = PARAMETER_SETS
    material = MATERIAL
    thickness = 3.0 * RADIUS_M
    mesh = indentation_block(
        width_m=3.0 * thickness,
        thickness_m=thickness,
        probe_radius_m=RADIUS_M,
        element="TET10",
        size_near_m=args.near * RADIUS_M,
        size_far_m=thickness / 2.0,
    )
    depths = 0.25 * RADIUS_M * np.arange(1, args.steps + 1) / args.steps
    if args.viscoelastic:  # a 0.25 s ramp to the same depths, then as many hold steps
        ramp = 0.25 * np.arange(1, args.steps + 1) / args.steps
        TIMES_S = np.concatenate([ramp, 0.25 + np.geomspace(0.05, 20.0, args.steps)])
        depths = 0.25 * RADIUS_M * np.minimum(TIMES_S / 0.25, 1.0)
        parameter_sets, material = VISCOELASTIC_SETS, VISCOELASTIC
    options = NewtonOptions()

    def forward(material=material, **kwargs):
        result = simulate_indentation(
            _problem(mesh, material), depths, device="cpu", progress=False, options=options,
            times_s=TIMES_S, **kwargs,
        )  # fmt: skip
        if not result.completed:
            raise SystemExit(f"the forward run did not converge: {result.message}")
        return result

    forward()  # compile and warm up
    t_forward, base = _timed(forward, args.repeat)
    print(f"mesh: {mesh.tet_count} TET10, {3 * mesh.node_count} dofs; {args.steps} depths")
    iterations = int(base.newton_iterations.sum())
    print(f"forward curve: {t_forward:.3f} s, {iterations} Newton iterations")
    problem = _problem(mesh, material)
    weights = np.zeros((mesh.node_count, 3))
    weights[problem.punch_nodes, 2] = -float(problem.symmetry_factor)

    def exact_curve(names, mode):
        """One curve with sensitivities: (wall s, s inside the sensitivities, Jacobian)."""
        assembler = Assembler(mesh, material)
        sensitivity = ForceSensitivity(
            assembler, problem.dirichlet_conditions(), names, weights, factorization=mode
        )
        start = time.perf_counter()
        path = solve_quasistatic(
            assembler,
            problem.dirichlet_conditions(),
            depths,
            reaction_weights=weights,
            options=options,
            sensitivity=sensitivity,
            times_s=TIMES_S,
        )
        total = time.perf_counter() - start
        return total, sensitivity, path.reaction_sensitivity

    rows = []
    for count, names in parameter_sets.items():
        row = {"parameters": list(names), "count": count}
        samples: dict[str, list[float]] = {}
        for _ in range(args.repeat):
            # Interleaved, so that each ratio compares runs made under the same load.
            for mode in ("reuse", "refactorize"):
                total, sensitivity, jacobian = exact_curve(names, mode)
                samples.setdefault(f"exact_{mode}_fraction_per_parameter", []).append(
                    sensitivity.seconds / (count * (total - sensitivity.seconds))
                )
                row[f"jacobian_{mode}"] = jacobian.tolist()
                row[f"exact_{mode}_factorizations"] = sensitivity.factorizations
                row[f"exact_{mode}_refinement_steps"] = sensitivity.refinement_steps
            t_base, _ = _timed(forward, 1)
            t_fd, _ = _timed(lambda names=names: [forward(_moved(n, 1.0)) for n in names], 1)
            t_cd, _ = _timed(
                lambda names=names: [forward(_moved(n, s)) for n in names for s in (1.0, -1.0)],
                1,
            )
            samples.setdefault("forward_differences_fraction_per_parameter", []).append(
                t_fd / (count * t_base)
            )
            samples.setdefault("central_differences_fraction_per_parameter", []).append(
                t_cd / (count * t_base)
            )
        for key, values in samples.items():
            row[key] = float(np.median(values))
        for relative_step in REFERENCE_STEPS:
            reference = np.column_stack(
                [_central_difference(mesh, depths, name, relative_step) for name in names]
            )
            for mode in ("reuse", "refactorize"):
                exact = np.asarray(row[f"jacobian_{mode}"])
                row[f"max_relative_difference_{mode}_vs_central_step_{relative_step:g}"] = float(
                    np.max(np.abs(exact - reference) / np.max(np.abs(reference), axis=0))
                )
        rows.append(row)
        print(
            f"{count} parameter(s): exact (reuse) {row['exact_reuse_fraction_per_parameter']:.3f}, "
            f"exact (refactorize) {row['exact_refactorize_fraction_per_parameter']:.3f}, "
            f"forward differences {row['forward_differences_fraction_per_parameter']:.2f}, "
            f"central {row['central_differences_fraction_per_parameter']:.2f} forward curves "
            "per parameter; exact (reuse) vs central differences of runs at tolerance "
            f"{1e-12 if TIMES_S is None else 1e-10:g}: "
            + ", ".join(
                f"{row[f'max_relative_difference_reuse_vs_central_step_{h:g}']:.1e} (step {h:g})"
                for h in REFERENCE_STEPS
            )
        )
    report = {
        "benchmark": "bench_sensitivity",
        "machine": {
            "processor": platform.processor() or platform.machine(),
            "cpus": os.cpu_count(),
        },  # fmt: skip
        "mesh": {"tets": mesh.tet_count, "dofs": 3 * mesh.node_count, "element": "TET10"},
        "material": material.to_dict(),
        "depths_m": depths.tolist(),
        "times_s": None if TIMES_S is None else TIMES_S.tolist(),
        "newton_tolerance": options.tolerance,
        "forward_s": t_forward,
        "forward_newton_iterations": iterations,
        "repeat": args.repeat,
        "rows": rows,
    }
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        temporary = args.out.with_suffix(args.out.suffix + ".tmp")
        temporary.write_text(json.dumps(report, indent=1) + "\n")
        temporary.replace(args.out)
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
