"""Run ``bench_flat_punch.py`` with each cuDSS analysis and factorization timed as it happens.

For meshes where one load step takes minutes (1M tets), the benchmark's own record only comes
at the end of a run. This wrapper prints, as they finish, every cuDSS analysis (seconds,
memory mode, cuDSS's memory estimates in GiB) and every factorization with its solve
(seconds), so that a run cut short by a time limit still reports what it measured. It takes
the benchmark's arguments unchanged.

Example:
    python scripts/bench_cudss_timeline.py --device cuda --sizes 1m --steps 1 --progress
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))


def main(argv: list[str] | None = None) -> int:
    import bench_flat_punch
    import warp as wp

    from warptissue.fem import cudss

    started = time.perf_counter()
    plan, solve = cudss.CudssSolver.__init__, cudss.CudssSolver.solve

    def stamp() -> str:
        return f"[{time.perf_counter() - started:8.1f} s]"

    def timed_plan(self, matrix, **options) -> None:
        began = time.perf_counter()
        plan(self, matrix, **options)
        wp.synchronize_device(matrix.device)
        estimates = {name: round(value / 2**30, 2) for name, value in self.memory_estimates.items()}
        print(
            f"{stamp()} cuDSS analysis of {self.row_count} rows: "
            f"{time.perf_counter() - began:.1f} s, hybrid memory {self.hybrid_memory}, "
            f"estimates GiB {estimates}",
            flush=True,
        )

    def timed_solve(self, rhs):
        began = time.perf_counter()
        x = solve(self, rhs)
        print(
            f"{stamp()} factorization + solve {self.factorizations} of {self.row_count} rows: "
            f"{time.perf_counter() - began:.2f} s",
            flush=True,
        )
        return x

    cudss.CudssSolver.__init__, cudss.CudssSolver.solve = timed_plan, timed_solve
    return bench_flat_punch.main(argv)


if __name__ == "__main__":
    sys.exit(main())
