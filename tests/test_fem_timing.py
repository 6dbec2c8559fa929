"""The per-phase timing report of the Newton solver (warptissue.fem.timing, ``--profile``).

Timings are never asserted; what is checked is their consistency: every phase present, the
phases adding up to the run's wall time measured outside (a clock independent of the
timer's), the iteration and factorization counts equal to the solver's own, the profile
changing no result, and the CLI and result.json carrying it.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pytest
import tomli_w
import warp as wp

from warptissue.cli import main
from warptissue.fem import (
    Assembler,
    IndentationProblem,
    NewtonOptions,
    NewtonTimings,
    simulate_indentation,
    solve_quasistatic,
)
from warptissue.fem.linear.cudss import cudss_available
from warptissue.fem.timing import LINEAR_SOLVER_PHASES, PHASES, PhaseTimer
from warptissue.indenter import Indenter
from warptissue.materials import NeoHookean
from warptissue.mesh import indentation_block
from warptissue.study import load_study

SCENE = Path(__file__).resolve().parents[1] / "scenes" / "liver_slab_flat_punch.toml"
DEPTHS_M = 1e-4 * np.arange(1, 4)


@pytest.fixture(scope="module")
def problem() -> IndentationProblem:
    mesh = indentation_block(
        width_m=20e-3,
        thickness_m=10e-3,
        probe_radius_m=1e-3,
        quarter=True,
        element="TET10",
        size_near_m=0.5e-3,
        size_far_m=2.5e-3,
    )
    return IndentationProblem(
        mesh,
        NeoHookean(C10_Pa=287.5, bulk_modulus_Pa=575e3),
        Indenter("flat_punch", radius_m=1e-3, contact="bonded"),
    )


@pytest.fixture(scope="module")
def runs(problem):
    """The same curve without and with the profile, each timed from outside."""
    out = {}
    for profile in (False, True):
        started = time.perf_counter()
        result = simulate_indentation(
            problem,
            DEPTHS_M,
            device="cpu",
            progress=False,
            # every Newton solve factorized: which ones reuse factors follows measured
            # times, and this compares the two curves to roundoff
            options=NewtonOptions(tolerance=1e-8, reuse_factorization=False),
            sensitivities=("C10_Pa",),
            profile=profile,
        )
        out[profile] = (result, time.perf_counter() - started)
    return out


@pytest.mark.slow
def test_an_unprofiled_run_has_no_timings_and_the_same_curve(runs):
    plain, _ = runs[False]
    profiled, _ = runs[True]
    assert plain.timings is None and "newton_profile" not in plain.to_dict()
    np.testing.assert_array_equal(plain.newton_iterations, profiled.newton_iterations)
    np.testing.assert_allclose(profiled.reaction_force_N, plain.reaction_force_N, rtol=1e-12)


def test_every_phase_is_present_and_they_add_up_to_the_wall_time(runs):
    result, wall_s = runs[True]
    timings = result.timings
    assert isinstance(timings, NewtonTimings)
    assert set(timings.seconds) == set(PHASES)
    assert all(value >= 0.0 for value in timings.seconds.values())
    # The phases add up to the timer's total by construction ("host" is the remainder) ...
    assert sum(timings.seconds.values()) == pytest.approx(timings.total_s, rel=1e-9)
    # ... and the total is the run's wall time measured outside, less the stress field and
    # set-up after and before the load path (a few per cent of this small run).
    assert 0.85 * wall_s < timings.total_s <= wall_s
    # The phases that this run goes through were timed; "host" is no more than a share.
    for name in ("assembly", "analysis", "factorization", "solve", "line_search"):
        assert timings.seconds[name] > 0.0 and timings.calls[name] > 0, name
    assert timings.seconds["sensitivity"] > 0.0  # C10's dR/dtheta assemblies
    assert timings.seconds["host"] < 0.5 * timings.total_s
    assert timings.linear_solver_s == pytest.approx(
        sum(timings.seconds[name] for name in LINEAR_SOLVER_PHASES)
    )
    assert 0.0 < timings.own_share < 1.0


def test_the_counts_are_the_solvers_own(runs):
    result, _ = runs[True]
    timings = result.timings
    assert timings.newton_iterations == int(np.sum(result.newton_iterations))
    assert timings.increments == len(DEPTHS_M) + result.cutbacks
    # One linear solve per Newton iteration, a factorization or GMRES with earlier factors;
    # the sensitivities reuse Newton's last factors (one more factorization per depth where
    # their iterative refinement fails).
    statistics = result.linear_solver_statistics
    assert timings.factorizations == statistics["factorizations"]
    solves = statistics["factorizations"] + statistics["reused_solves"]
    assert timings.newton_iterations <= solves <= timings.newton_iterations + 3
    assert timings.calls["analysis"] == 1  # PARDISO's ordering, once per mesh
    means = timings.per_iteration_s
    assert means["total"] == pytest.approx(timings.total_s / timings.newton_iterations)
    assert means["assembly"] == pytest.approx(
        timings.seconds["assembly"] / timings.newton_iterations
    )


def test_the_profile_reads_back_from_json_and_prints_a_table(runs):
    result, _ = runs[True]
    data = json.loads(json.dumps(result.to_dict()["newton_profile"]))
    again = NewtonTimings.from_dict(data)
    assert again.seconds == pytest.approx(result.timings.seconds)
    assert again.newton_iterations == result.timings.newton_iterations
    table = again.table()
    for name in (*PHASES, "total"):
        assert f"\n{name} " in f"\n{table}"
    assert f"{again.newton_iterations} Newton iterations" in table


def test_phases_are_exclusive_when_nested():
    """A phase entered inside another stops the outer one's clock."""
    timer = PhaseTimer(enabled=True)
    with timer.phase("sensitivity"):
        time.sleep(0.02)
        with timer.phase("solve"):
            time.sleep(0.03)
        time.sleep(0.02)
    assert timer.seconds["solve"] == pytest.approx(0.03, abs=0.02)
    assert timer.seconds["sensitivity"] == pytest.approx(0.04, abs=0.02)
    assert timer.calls == {**dict.fromkeys(timer.calls, 0), "sensitivity": 1, "solve": 1}


def test_a_disabled_timer_reads_no_clock():
    timer = PhaseTimer(enabled=False)
    with timer.phase("assembly"), timer.phase("solve"):
        time.sleep(0.01)
    assert set(timer.seconds.values()) == {0.0} and set(timer.calls.values()) == {0}
    assert timer.phase("assembly") is timer.phase("line_search")  # one shared null context


@pytest.mark.slow
def test_solve_quasistatic_profiles_a_cutback(problem):
    """A depth jump with no room for it: cut back, every attempted increment counted."""
    assembler = Assembler(problem.mesh, problem.material, device="cpu")
    path = solve_quasistatic(
        assembler,
        problem.dirichlet_conditions(),
        np.array([1e-4, 2.5e-3]),
        reaction_weights=problem.reaction_weights(),
        options=NewtonOptions(max_newton_iterations=3),
        profile=True,
    )
    timings = path.timings
    assert path.cutbacks > 0
    assert timings.increments == len(path.history)
    assert timings.newton_iterations == sum(record["iterations"] for record in path.history)


def test_cli_profile_prints_the_table_and_writes_it_to_result_json(tmp_path, capsys):
    record = load_study(SCENE).to_dict()
    record["name"] = "tiny"
    record["specimen"].update(size_near_m=5.0e-4, size_far_m=5.0e-3, growth=1.4)
    record["protocol"] = {"depths_m": [2.0e-5, 5.0e-5]}
    record["solver"]["device"] = "cpu"
    study_path = tmp_path / "tiny.toml"
    study_path.write_text(tomli_w.dumps(record))
    status = main(["simulate", str(study_path), "--out", str(tmp_path / "a"), "--profile"])
    assert status == 0
    printed = capsys.readouterr().out
    assert "where the solve's time went" in printed
    assert "factorization" in printed and "Newton iterations" in printed
    summary = json.loads((tmp_path / "a" / "result.json").read_text())
    profile = summary["newton_profile"]
    assert set(profile["seconds"]) == set(PHASES)
    assert profile["newton_iterations"] == sum(summary["force_curve"]["newton_iterations"])
    # Without the option the field is there, null, and no table is printed.
    status = main(["simulate", str(study_path), "--out", str(tmp_path / "b"), "--quiet"])
    assert status == 0
    assert "where the solve's time went" not in capsys.readouterr().out
    assert json.loads((tmp_path / "b" / "result.json").read_text())["newton_profile"] is None


@pytest.mark.skipif(not wp.is_cuda_available(), reason="needs a CUDA device")
@pytest.mark.parametrize(
    "linear_solver", (["cudss"] if cudss_available(warn=False) else []) + ["cg"]
)
def test_the_profile_on_cuda_adds_up_and_changes_no_result(problem, linear_solver):
    """On a GPU the timer synchronizes the device at each phase boundary: the phases still
    add up to the wall time, and the curve is the unprofiled one."""
    runs = {}
    for profile in (False, True):
        started = time.perf_counter()
        result = simulate_indentation(
            problem,
            DEPTHS_M[:2],
            device="cuda:0",
            progress=False,
            options=NewtonOptions(tolerance=1e-8, linear_solver=linear_solver),
            profile=profile,
        )
        runs[profile] = (result, time.perf_counter() - started)
    (plain, _), (profiled, wall_s) = runs[False], runs[True]
    # The GPU assembly adds with atomics in a varying order: equal to CG's tolerance.
    np.testing.assert_allclose(profiled.reaction_force_N, plain.reaction_force_N, rtol=1e-7)
    timings = profiled.timings
    assert timings.device.startswith("cuda")
    assert sum(timings.seconds.values()) == pytest.approx(timings.total_s, rel=1e-9)
    assert 0.5 * wall_s < timings.total_s <= wall_s
    assert timings.newton_iterations == int(np.sum(profiled.newton_iterations))
    assert timings.seconds["solve"] > 0.0 and timings.seconds["assembly"] > 0.0
    if linear_solver == "cudss":
        assert timings.seconds["factorization"] > 0.0
        # Each Newton solve factorizes, or solves with earlier factors by GMRES.
        statistics = profiled.linear_solver_statistics
        assert timings.factorizations == statistics["factorizations"]
        assert (
            statistics["factorizations"] + statistics["reused_solves"] == timings.newton_iterations
        )
