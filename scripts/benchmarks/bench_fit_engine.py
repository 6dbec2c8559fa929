"""Benchmark the fit engine on the More-Garbow-Hillstrom problems against scipy (MINPACK).

Prints, per problem and method, the final sum of squares, the trial steps, the residual
evaluations (finite-difference Jacobians, as scipy's "lm" without jac) and the status, next
to scipy.optimize.least_squares(method="lm"), and the wall time of the whole table.

Usage: python scripts/benchmarks/bench_fit_engine.py
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
import scipy.optimize

from warptissue.lsq import least_squares

# The test problems are a test fixture: they live in the repository's tests/ folder.
sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))
from fit_problems import PROBLEMS  # noqa: E402

TOLERANCES = {"ftol": 1e-12, "xtol": 1e-12, "gtol": 1e-12}


def main() -> None:
    """Print the comparison table."""
    print(f"{'problem':<24} {'solver':<6} {'sum r^2':>12} {'steps':>6} {'nfev':>6} status")
    start = time.perf_counter()
    for name, problem in PROBLEMS.items():
        reference = scipy.optimize.least_squares(
            problem.residuals, problem.x0, method="lm", max_nfev=20000, **TOLERANCES
        )
        print(
            f"{name:<24} {'scipy':<6} {2 * reference.cost:>12.6g} {'':>6} "
            f"{reference.nfev:>6} {reference.status}"
        )
        for method in ("lm", "salm"):
            result = least_squares(
                problem.residuals, problem.x0, method=method, max_iterations=3000, **TOLERANCES
            )
            distance = np.max(np.abs(result.x - reference.x) / np.maximum(np.abs(reference.x), 1))
            print(
                f"{'':<24} {method:<6} {2 * result.cost:>12.6g} {result.iterations:>6} "
                f"{result.nfev:>6} {result.status}  (max rel. distance to scipy x: {distance:.1e})"
            )
    print(f"total {time.perf_counter() - start:.2f} s")


if __name__ == "__main__":
    main()
