"""Takacs et al., Table I reproduction: simulate, refit jointly, validate on a held-out rate.

Simulates the nonlinear Wiechert model with Table I's parameters (20 x 20 mm beef liver
sample, 4 mm) at 62.5 Hz: a near-step (750 mm/min) relaxation held 60 s, and constant-rate
ramps at 20 and 100 mm/min of which the first 3.6 mm are kept (as the paper does). Adds
Gaussian noise, refits the 8 parameters jointly to the near-step and 20 mm/min curves from a
perturbed start (LM through warptissue.fit, then Nelder-Mead on the paper's cost, the sum of
the RMS errors), and predicts the 100 mm/min curve.

Run: python scripts/examples/wiechert_table1_refit.py [--noise-N 0.005] [--seed 0] [--quick]

``--quick`` stops after the LM stage (a few seconds; Nelder-Mead takes about two minutes on a
2-core CPU).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from warptissue.viscoelastic import NonlinearWiechert, RelaxationRecord, fit_wiechert_joint

TABLE_I = NonlinearWiechert(2.03, 0.438, 0.102, 5073.0, 39.24, 909.9, 1522.0, 81.18)


def record(rate_mm_per_min: float, hold_s: float, keep_to_m: float, noise_N: float, rng):
    rate = rate_mm_per_min / 60e3
    t = np.arange(0.0, 4e-3 / rate + hold_s, 1 / 62.5)
    x = np.minimum(rate * t, 4e-3)
    keep = x <= keep_to_m + 1e-12
    t, x = t[keep], x[keep]
    force = TABLE_I.force_N(t, x)
    return RelaxationRecord(t, x, force + rng.normal(0.0, noise_N, t.size)), force


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--noise-N", type=float, default=0.005)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--quick", action="store_true", help="LM only, no Nelder-Mead stage")
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    near_step, _ = record(750, 60.0, 4e-3, args.noise_N, rng)
    slow, _ = record(20, 0.0, 3.6e-3, args.noise_N, rng)
    fast, fast_clean = record(100, 0.0, 3.6e-3, args.noise_N, rng)
    start = TABLE_I.to_vector() * [1.3, 0.7, 1.5, 0.7, 1.4, 0.8, 1.15, 0.5]
    stages = (("lm", start),) if args.quick else (("lm", start), ("nelder-mead", None))
    for optimizer, p0 in stages:
        began = time.perf_counter()
        result = fit_wiechert_joint(
            [near_step, slow],
            start if p0 is None else p0,
            optimizer=optimizer,
            max_iterations=200 if optimizer == "lm" else 4000,
        )
        elapsed = time.perf_counter() - began
        if optimizer == "lm":
            start = result.x
        predicted = result.fitted_model.force_N(fast.time_s, fast.displacement_m)
        rmse_data = float(np.sqrt(np.mean((predicted - fast.force_N) ** 2)))
        rmse_truth = float(np.sqrt(np.mean((predicted - fast_clean) ** 2)))
        print(
            f"== {optimizer}: {result.iterations} iterations, {result.nfev} evaluations, "
            f"{elapsed:.1f} s; {result.message}"
        )
        for name, value, true in zip(
            result.parameter_names, result.x, TABLE_I.to_vector(), strict=True
        ):
            print(f"  {name:<14} {value:12.5g}   (Table I {true:g})")
        print(
            f"  fit RMSE near-step {result.record_rmse_N[0]:.5f} N, 20 mm/min "
            f"{result.record_rmse_N[1]:.5f} N; the paper's cost (sum of RMSEs) "
            f"{result.sum_of_record_rmse_N:.5f} N"
        )
        print(
            f"  100 mm/min prediction RMSE: {rmse_data:.5f} N against the noisy data, "
            f"{rmse_truth:.5f} N against the noise-free curve"
        )


if __name__ == "__main__":
    main()
