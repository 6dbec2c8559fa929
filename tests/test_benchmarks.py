"""The benchmarks run, and the tables of docs/performance.md are what the flat-punch,
inverse-fit and batched-FE benchmarks print from the results files the page names (the
flat-punch ones against the reference force those files hold)."""

from __future__ import annotations

import json
import re
import shlex
from pathlib import Path

import numpy as np
import pytest
from _scripts import ROOT, run_script

PAGE = ROOT / "docs" / "performance.md"
BENCHMARK = "scripts/benchmarks/bench_flat_punch.py"


INVERSE_FIT = "scripts/benchmarks/bench_inverse_fit.py"
BATCH = "scripts/benchmarks/bench_batch_fe.py"


def generated_tables(benchmark: str = BENCHMARK) -> list[tuple[str, str]]:
    """(command, the tables printed under it) for every ``--markdown`` bash block of the page
    that runs ``benchmark``."""
    found = re.findall(
        r"```bash\n(python " + re.escape(benchmark) + r" --markdown [^\n]*)\n```\n\n"
        r"((?:\|[^\n]*\n)+(?:\n(?:\|[^\n]*\n)+)*)",
        PAGE.read_text(encoding="utf-8"),
    )
    return [(command, table.strip()) for command, table in found]


def test_the_page_has_generated_tables():
    assert len(generated_tables()) >= 4
    assert len(generated_tables(INVERSE_FIT)) >= 5
    assert len(generated_tables(BATCH)) >= 2


@pytest.mark.parametrize(
    "command, table",
    generated_tables() + generated_tables(INVERSE_FIT) + generated_tables(BATCH),
    ids=lambda x: str(x)[:40],
)
@pytest.mark.slow
def test_a_performance_table_is_the_benchmarks_output(command, table):
    script, *arguments = shlex.split(command)[1:]
    assert run_script(script, *arguments, cwd=ROOT).strip() == table


def test_the_reference_force_is_the_felupe_extrapolation():
    """The tables' "vs 2.460 mN" column: the Richardson extrapolation of FElupe's runs."""
    results = json.loads((ROOT / "scripts/results/bench_flat_punch_2core_cpu.json").read_text())
    assert results["references"]["felupe"]["force_N"] == pytest.approx(2.460e-3, abs=5e-7)
    source = (ROOT / BENCHMARK).read_text()
    assert "REFERENCE_FORCE_N = 2.460e-3" in source


def test_the_markdown_option_refuses_a_filter_that_keeps_nothing():
    results = "scripts/results/bench_flat_punch_2core_cpu.json"
    stderr = run_script(
        BENCHMARK, "--markdown", results, "--only", "damping=on", cwd=ROOT, expect_status=2
    )
    assert "no run in" in stderr and "Traceback" not in stderr


def run_benchmark(name: str, *args: str, cwd: Path) -> str:
    """Run ``scripts/benchmarks/NAME`` with ``args``; return its stdout."""
    return run_script(f"scripts/benchmarks/{name}", *args, cwd=cwd)


@pytest.mark.slow
def test_the_flat_punch_benchmark_runs_a_tiny_mesh(tmp_path):
    """Two of the 20 load steps on about a thousand tets: the force per depth lies 0-30 %
    above Sneddon's half-space 8 mu a (the finite block is stiffer, by 1.09 at convergence),
    the run is reported as not completed, and --markdown prints it."""
    run_benchmark("bench_flat_punch.py", "--sizes", "600", "--steps", "2", "--out", "b.json",
                  cwd=tmp_path)  # fmt: skip
    report = json.loads((tmp_path / "b.json").read_text())
    (run,) = report["runs"]
    assert run["steps_converged"] == 2 and not run["completed"]
    half_space = 8 * 575.0 * 1e-3 * 0.5e-3 / 20  # N per load step of depth
    for step, force in enumerate(run["force_N"], start=1):
        assert 1.0 < force / (step * half_space) < 1.3
    table = run_benchmark("bench_flat_punch.py", "--markdown", "b.json", cwd=tmp_path)
    assert "| 2 of 20 |" in table


@pytest.mark.slow
def test_the_flat_punch_benchmark_sweeps_the_near_size_and_tolerances(tmp_path):
    """--size-near-ratios meshes the block at a near size of R probe radii and the far size
    of a study's default (2.5 mm); with two tolerances the table gives each run's largest
    force change from the tighter one's curve."""
    run_benchmark("bench_flat_punch.py", "--sizes", "", "--size-near-ratios", "1",
                  "--tolerances", "1e-8,1e-4", "--out", "b.json", cwd=tmp_path)  # fmt: skip
    report = json.loads((tmp_path / "b.json").read_text())
    assert [run["size_far_m"] for run in report["runs"]] == [2.5e-3, 2.5e-3]
    assert [run["size_near_m"] for run in report["runs"]] == [1e-3, 1e-3]
    table = run_benchmark("bench_flat_punch.py", "--markdown", "b.json", cwd=tmp_path)
    assert "| near size / a | far size (um) |" in table and "| 1 | 2 500 |" in table
    first, second = table.splitlines()[2:]
    assert first.endswith("| 0 |") and re.search(r"\| \d\.\de-\d\d \|$", second)
    stderr = run_script(BENCHMARK, "--size-near-ratios", "2", cwd=tmp_path, expect_status=2)
    assert "--size-near-ratios must lie in (0, 1]" in stderr


@pytest.mark.slow
def test_the_newton_latency_benchmark_times_a_study_and_compares_runs(tmp_path):
    """The tutorial study's load path: one plain and one profiled run after the warm-up, the
    same iterations and forces (the CPU's reuse decisions follow measured times, so the
    forces agree to the Newton tolerance, not bitwise), and --compare reads the file."""
    study = ROOT / "scenes/tutorial_punch.toml"
    run_benchmark("bench_newton_latency.py", str(study), "--device", "cpu", "--repeats", "1",
                  "--out", "l.json", cwd=tmp_path)  # fmt: skip
    plain, profiled = json.loads((tmp_path / "l.json").read_text())["runs"]
    assert not plain["profile"] and profiled["profile"]
    assert plain["newton_iterations"] > 0 and plain["ms_per_iteration"] > 0.0
    assert profiled["newton_profile"]["newton_iterations"] == profiled["newton_iterations"]
    np.testing.assert_allclose(profiled["force_N"], plain["force_N"], rtol=1e-7)
    report = run_benchmark("bench_newton_latency.py", "--compare", "l.json", cwd=tmp_path)
    assert re.search(r"l\.json: [\d.]+ ms/iteration .* largest force difference", report)


@pytest.mark.parametrize(
    "name, args, expected",
    [
        ("bench_mesh.py", ("--factors", "0.5"), r"\n\s+0\.50\s+\d+"),
        ("bench_usd.py", ("--cells", "4", "4", "4", "--steps", "2"), r"validate_stage: .* 0 find"),
        ("bench_fit_engine.py", (), r"\ntotal \S+ s"),
        (
            "bench_sensitivity.py",
            ("--steps", "2", "--repeat", "1", "--near", "1.0"),
            r"4 parameter\(s\): exact",
        ),
        ("bench_inverse_fit.py", ("--quick", "--parts", "mesh"), r"\| 2.5 mm \| \d+ \|"),
        (
            "bench_batch_fe.py",
            ("--tets", "300", "--counts", "1,2", "--steps", "1", "--label", "tiny"),
            r"\| tiny \| cpu \| \d+ \| curves \| 2 \| .* \| \d\.\de-\d\d \(force\) \|",
        ),
        (
            "bench_batch_fe.py",
            ("--tets", "300", "--counts", "2", "--steps", "2", "--what", "fits", "--label", "t"),
            r"\| t \| cpu \| [\d ]+ \| fits \| 2 \| .* \| \d\.\de-\d\d \(C10\) \| - \| - \|",
        ),
        (
            "bench_batch_fe.py",
            (
                "--tets",
                "300",
                "--counts",
                "2",
                "--steps",
                "2",
                "--what",
                "fits",
                "--cluster-workers",
                "1",
                "--sequential-limit",
                "1",
                "--label",
                "c",
            ),
            r"\| c \| cpu \| [\d ]+ \| fits \| 2 \| .* \(C10\) \| [\d.]+ \(1\) \| [\d.]+ \|",
        ),
    ],
)
@pytest.mark.slow
def test_a_quick_benchmark_runs(name, args, expected, tmp_path):
    """The benchmarks without a test of their numbers still run on a small case."""
    assert re.search(expected, run_benchmark(name, *args, cwd=tmp_path))


def test_the_cudss_batch_benchmark_runs_on_a_gpu_and_says_why_not_elsewhere(tmp_path):
    """On a GPU with the ``gpu`` extra it times the three linear solves of a tiny batch and
    their solutions agree; elsewhere it says what it needs, in one line, with status 5."""
    import importlib.util

    import warp as wp

    usable = wp.is_cuda_available() and all(
        importlib.util.find_spec(name) for name in ("cupy", "nvmath")
    )
    args = ("--tets", "300", "--counts", "1,2", "--repeat", "1", "--label", "tiny")
    if not usable:
        stderr = run_script(
            "scripts/benchmarks/bench_cudss_batch.py", *args, cwd=tmp_path, expect_status=5
        )
        assert len(stderr.strip().splitlines()) == 1
        assert stderr.startswith("bench_cudss_batch: needs")
        return
    table = run_benchmark("bench_cudss_batch.py", *args, "--out", "r.json", cwd=tmp_path)
    rows = json.loads((tmp_path / "r.json").read_text())["runs"]
    assert [row["problems"] for row in rows] == [1, 2]
    for row in rows:
        assert row["block_diagonal_factor_solve_s"] > 0.0 and row["loop_difference"] < 1e-10
        assert row.get("batch_difference", 0.0) < 1e-10, row.get("batch_error")
    assert re.search(r"\| tiny \| [\d ]+ \| 2 \| [\d ]+ \| [\d.]+ \| ", table)


def test_the_cudss_batch_benchmark_tables_a_failed_solve(tmp_path):
    results = {
        "label": "h100",
        "runs": [
            {
                "cells": 7885,
                "problems": 8,
                "dofs": 319968,
                "block_diagonal_analysis_s": 0.52,
                "block_diagonal_factor_solve_s": 0.0412,
                "block_diagonal_difference": 0.0,
                "batch_error": "RuntimeError: not supported",
                "loop_analysis_s": 1.6,
                "loop_factor_solve_s": 0.136,
                "loop_difference": 2e-15,
                "dense_error": "MemoryError: a dense stack of 8 x 39996^2 is 95.4 GiB > 16 GiB",
            }
        ],
    }
    (tmp_path / "r.json").write_text(json.dumps(results))
    table = run_benchmark("bench_cudss_batch.py", "--markdown", "r.json", cwd=tmp_path)
    row = (
        "| h100 | 7 885 | 8 | 319 968 | 41.2 | failed | 136 | failed | 0.52, -, 1.6, - | 2.0e-15 |"
    )
    assert row in table
    del results["runs"][0]["dense_error"]  # a result file from before the dense way: "-"
    (tmp_path / "r.json").write_text(json.dumps(results))
    table = run_benchmark("bench_cudss_batch.py", "--markdown", "r.json", cwd=tmp_path)
    assert row.replace("| failed | 0.52", "| - | 0.52") in table


@pytest.mark.slow
def test_the_cudss_batch_benchmark_splits_the_union_into_each_problems_tangent():
    """The batch it hands cuDSS is each problem's own eliminated tangent: the diagonal blocks
    of the packed problems' CSR matrix (two meshes of different sizes), and nothing else."""
    import importlib.util

    import numpy as np
    import scipy.sparse
    import warp as wp

    from warptissue.fem import IndentationProblem
    from warptissue.fem.linear.cudss import bsr33_csr_pattern, bsr33_csr_values
    from warptissue.indenter import Indenter
    from warptissue.materials import NeoHookean
    from warptissue.mesh import indentation_block

    path = ROOT / "scripts/benchmarks/bench_cudss_batch.py"
    spec = importlib.util.spec_from_file_location("bench_cudss_batch", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)

    def csr(assembler):
        matrix = assembler.matrix
        offsets, columns, rows = bsr33_csr_pattern(matrix)
        values = wp.zeros(columns.shape[0], dtype=wp.float64, device="cpu")
        bsr33_csr_values(matrix, rows, values)
        return offsets.numpy(), columns.numpy(), values.numpy()

    problems = [
        IndentationProblem(
            indentation_block(
                width_m=0.008,
                thickness_m=0.004,
                probe_radius_m=1e-3,
                quarter=True,
                size_near_m=near,
                size_far_m=2.5e-3,
            ),
            NeoHookean(c10, 2000.0 * c10),
            Indenter("flat_punch", radius_m=1e-3),
            symmetry_planes=("symmetry_x", "symmetry_y"),
        )
        for near, c10 in ((5e-4, 250.0), (3.5e-4, 400.0))
    ]
    assembler, packed = module.eliminated_tangent(problems, "cpu")
    offsets, columns, values = csr(assembler)
    blocks = module.diagonal_blocks(
        offsets, offsets, columns, values, packed.node_offsets, scipy.sparse.csr_matrix
    )
    assert packed.mesh.node_count > 0 and len(blocks) == 2
    assert sum(block.nnz for block in blocks) == values.size  # nothing off the blocks
    for problem, block in zip(problems, blocks, strict=True):
        own_offsets, own_columns, own_values = csr(module.eliminated_tangent([problem], "cpu")[0])
        own = scipy.sparse.csr_matrix((own_values, own_columns, own_offsets), shape=block.shape)
        assert block.shape == (3 * problem.mesh.node_count,) * 2
        np.testing.assert_array_equal(block.toarray(), own.toarray())
