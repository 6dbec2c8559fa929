"""Inverse-FE fits (warptissue.fit.indentation) against known truths.

Every record here is made by the forward FE with known parameters (the same mesh as the
fit's, on a finer time or depth grid than the fit's FE steps) plus 1 % Gaussian noise of the
peak force (seeded), written as a CSV next to a study file, loaded with ``load_study`` and
fitted. The fits must recover the truth (2 % for elastic parameters, 5 % for the Prony
terms, and within 3 standard errors); the Jacobian of the residuals must equal central
differences of whole forward runs; the exact sensitivities must save forward runs against
forward differences; Ctrl-C keeps the best point; bad input and non-identified parameters
are said out loud. The contact point: records whose recorded depth is offset from the true
depth (the probe touches at 0.15 mm) give the offset and C10 back when the offset is fitted
(from a start 50 % off), and a C10 half the truth when it is not.

The specimen is a quarter block 8 x 8 x 2 mm under a 1 mm flat punch (805 TET10 nodes).
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

import warptissue.fem
from warptissue.errors import InputError
from warptissue.fem import simulate_indentation
from warptissue.fit import IndentationFit, fit_indentation
from warptissue.fit._model import ForwardModel, forward_model
from warptissue.fit.indentation import depth_offset_start_m
from warptissue.fit.start import start_values_from_record
from warptissue.io import write_csv
from warptissue.lsq.result import RejectStep
from warptissue.materials import material_from_dict
from warptissue.mesh import indentation_block, write_mesh
from warptissue.simulate import build_mesh, build_problem, record_problems, run_study
from warptissue.study import load_study, save_study

RADIUS_M = 1e-3
BULK_PA = 575_000.0
GEOMETRY = """\
schema_version = 2
name = "synthetic"

[specimen]
shape = "block"
width_m = 0.008
thickness_m = 0.002
quarter = true
element = "TET10"
size_near_m = 0.0005
size_far_m = 0.002

[indenter]
kind = "flat_punch"
radius_m = 0.001

[protocol]
max_depth_m = 0.0003
steps = 4

[solver]
device = "cpu"
{solver}
[material]
{material}
"""
NEO_HOOKEAN = {"model": "neo_hookean", "C10_Pa": 287.5, "bulk_modulus_Pa": BULK_PA}
REDUCED_POLYNOMIAL = {
    "model": "reduced_polynomial",
    "C10_Pa": 287.5,
    "C20_Pa": 400.0,
    "bulk_modulus_Pa": BULK_PA,
}
VISCOELASTIC = {**NEO_HOOKEAN, "g1": 0.5, "tau1_s": 1.0}


def _toml_table(values: dict) -> str:
    """A ``[material]`` table's lines."""
    return "".join(f"{key} = {json.dumps(value)}\n" for key, value in values.items())


def ramp(depth_m: float, samples: int = 30) -> tuple[np.ndarray, np.ndarray]:
    """A loading ramp to ``depth_m`` in ``samples`` samples 0.1 s apart: (time_s, depth_m)."""
    fraction = np.arange(1, samples + 1) / samples
    return 0.1 * np.arange(1, samples + 1), depth_m * fraction


def ramp_and_hold(depth_m: float = 0.3 * RADIUS_M) -> tuple[np.ndarray, np.ndarray]:
    """A 0.5 s ramp, then a 5 s hold sampled in log time: (time_s, depth_m)."""
    time = np.concatenate([np.linspace(0.02, 0.5, 12), 0.5 + np.geomspace(0.05, 5.0, 30)])
    return time, np.where(time <= 0.5, depth_m * time / 0.5, depth_m)


def make_study(
    folder: Path,
    *,
    truth: dict,
    start: dict,
    fit: str,
    history: tuple[np.ndarray, np.ndarray] | list[tuple[np.ndarray, np.ndarray]],
    noise: float = 0.01,
    seed: int = 1,
    drift_per_s: float = 0.0,
    solver: str = "",
    recorded_depth: list[np.ndarray] | None = None,
):
    """Write record.csv (the FE force of ``truth`` along ``history`` plus Gaussian noise of
    ``noise`` times the peak force and a drift of ``drift_per_s`` times the peak force per
    second; a list of histories: record.csv, record2.csv, ...) and study.toml (material
    ``start``, the ``[fit]`` text), and load the study. ``recorded_depth`` (one per history):
    the displacement column written instead of the history's depth (a depth offset)."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "study.toml"
    path.write_text(GEOMETRY.format(material=_toml_table(truth), solver=solver))
    geometry = load_study(path)
    truth_study = dataclasses.replace(geometry, material=material_from_dict(truth))
    problem = build_problem(truth_study, build_mesh(truth_study))
    tables = ""
    histories = history if isinstance(history, list) else [history]
    rng = np.random.default_rng(seed)
    for k, (time, depth) in enumerate(histories):
        result = simulate_indentation(problem, depth, times_s=time, device="cpu", progress=False)
        assert result.completed, result.message
        force = result.reaction_force_N
        peak = float(np.max(force))
        noisy = force + rng.normal(0.0, noise * peak, force.size) + drift_per_s * peak * time
        name = "record.csv" if k == 0 else f"record{k + 1}.csv"
        written = depth if recorded_depth is None else recorded_depth[k]
        write_csv(
            folder / name,
            {
                "time_s": np.concatenate([[0.0], time]),
                "displacement_m": np.concatenate([[0.0], written]),
                "force_N": np.concatenate([[0.0], noisy]),
            },
        )
        tables += f'\n[[data]]\nfile = "{name}"\n'
    path.write_text(
        GEOMETRY.format(material=_toml_table(start), solver=solver) + tables + "\n[fit]\n" + fit
    )
    return load_study(path)


def assert_recovered(fit: IndentationFit, truth: dict, rtol: float) -> None:
    errors = fit.result.standard_errors
    assert errors is not None
    for name, value, error in zip(fit.result.parameter_names, fit.result.x, errors, strict=True):
        assert value == pytest.approx(truth[name], rel=rtol), name
        assert abs(value - truth[name]) <= 3.0 * error, (name, value, error)


def assert_jacobian_is_central_differences(
    model: ForwardModel, x: np.ndarray, jacobian: np.ndarray, steps, names=None
) -> None:
    """Each column j of ``jacobian`` at ``x`` equals the central difference of the model's
    residuals with step ``steps[j]``, to 1e-5 of the column's largest entry."""
    for j, step in enumerate(steps):
        up, down = x.copy(), x.copy()
        up[j] += step
        down[j] -= step
        central = (model.fun(up) - model.fun(down)) / (2.0 * step)
        scale = float(np.max(np.abs(central)))
        assert scale > 0.0
        name = None if names is None else names[j]
        np.testing.assert_allclose(jacobian[:, j], central, rtol=0, atol=1e-5 * scale, err_msg=name)


@pytest.fixture(scope="module")
def neo_hookean_fit(tmp_path_factory) -> IndentationFit:
    study = make_study(
        tmp_path_factory.mktemp("neo_hookean"),
        truth=NEO_HOOKEAN,
        start=NEO_HOOKEAN,
        fit='free = ["C10_Pa"]\ntime_steps = 10\n',
        history=ramp(0.3 * RADIUS_M),
    )
    return fit_indentation(study, progress=False)


@pytest.mark.slow
def test_neo_hookean_c10_is_recovered_from_a_noisy_fe_record(neo_hookean_fit):
    fit = neo_hookean_fit
    assert fit.status == "converged" and fit.exit_code == 0 and fit.success
    assert fit.strategy == "joint" and fit.stage_one is None
    # C10 starts from the record's small-depth stiffness (Sneddon + Hayes), not the truth.
    assert fit.start["C10_Pa"] != pytest.approx(287.5, rel=1e-3)
    assert_recovered(fit, NEO_HOOKEAN, 0.02)
    assert fit.result.r_squared > 0.998
    assert fit.warnings == []
    # One record, its curves at its own samples, the fitted study runs the fitted material.
    (record,) = fit.records
    assert record.file == "record.csv"
    assert record.fitted_force_N.shape == record.measured_force_N.shape == (31,)
    assert record.fe_depth_m[-1] == pytest.approx(0.3 * RADIUS_M)
    assert 1.0 < record.durbin_watson < 3.0  # independent noise: about 2
    assert fit.fitted_study.material.C10_Pa == pytest.approx(fit.result.x[0])
    assert fit.fitted_study.data == fit.study.data
    summary = json.loads(json.dumps(fit.to_dict()))
    assert summary["parameters"]["C10_Pa"]["unit"] == "Pa"
    assert summary["parameters"]["C10_Pa"]["standard_error"] > 0.0
    assert summary["forward_solves"] == fit.forward_solves
    assert summary["records"][0]["r_squared"] == pytest.approx(record.r_squared)
    assert summary["fitted_material"]["C10_Pa"] == pytest.approx(fit.result.x[0])
    assert summary["status"] == "converged"


@pytest.mark.slow
def test_elastic_records_of_different_depths_share_one_fe_run_per_evaluation(tmp_path):
    # Elastic: the force depends on the depth only, so one FE run to the deepest point of
    # both records serves both.
    study = make_study(
        tmp_path,
        truth=NEO_HOOKEAN,
        start=NEO_HOOKEAN,
        fit='free = ["C10_Pa"]\ntime_steps = 10\n',
        history=[ramp(0.3 * RADIUS_M), ramp(0.15 * RADIUS_M, 20)],
    )
    fit = fit_indentation(study, progress=False)
    assert fit.status == "converged"
    assert_recovered(fit, NEO_HOOKEAN, 0.02)
    assert [record.file for record in fit.records] == ["record.csv", "record2.csv"]
    assert fit.result.residuals.shape == (31 + 21,)
    assert fit.forward_solves == fit.result.nfev  # one run per evaluation, not per record
    shallow = fit.records[1]
    assert shallow.fe_depth_m[-1] >= 0.15 * RADIUS_M > shallow.fe_depth_m[-2]
    # The FE curve passes through the fitted force at the record's deepest point.
    assert shallow.fitted_force_N[-1] == pytest.approx(
        np.interp(0.15 * RADIUS_M, shallow.fe_depth_m, shallow.fe_force_N)
    )
    for record in fit.records:
        assert record.r_squared > 0.99 and record.rmse_N > 0.0


@pytest.mark.slow
def test_two_parameters_are_recovered_with_fewer_forward_runs_than_differences(tmp_path):
    study = make_study(
        tmp_path,
        truth=REDUCED_POLYNOMIAL,
        start={**REDUCED_POLYNOMIAL, "C10_Pa": 250.0, "C20_Pa": 100.0},
        fit='free = ["C10_Pa", "C20_Pa"]\nstart_from = "material"\ntime_steps = 10\n',
        history=ramp(0.5 * RADIUS_M),
    )
    fit = fit_indentation(study, progress=False)
    assert fit.status == "converged"
    assert_recovered(fit, REDUCED_POLYNOMIAL, 0.02)
    # Forward differences: 1 + n runs per Jacobian; the sensitivities come with each run.
    assert fit.forward_solves < fit.finite_difference_solves / 2
    assert fit.result.correlation is not None and abs(fit.result.correlation[0, 1]) < 0.999


@pytest.mark.parametrize(
    ("truth", "start"),
    [
        (
            {"model": "mooney_rivlin", "C10_Pa": 200.0, "C01_Pa": 80.0, "bulk_modulus_Pa": BULK_PA},
            {"C10_Pa": 150.0, "C01_Pa": 150.0},
        ),
        (
            {"model": "ogden", "mu1_Pa": 575.0, "alpha1": 6.0, "bulk_modulus_Pa": BULK_PA},
            {"mu1_Pa": 450.0, "alpha1": 3.0},
        ),
    ],
    ids=["mooney_rivlin", "ogden"],
)
@pytest.mark.slow
def test_mooney_rivlin_and_ogden_parameters_are_recovered(tmp_path, truth, start):
    free = list(start)
    study = make_study(
        tmp_path,
        truth=truth,
        start={**truth, **start},
        fit=f'free = {json.dumps(free)}\nstart_from = "material"\ntime_steps = 10\n',
        history=ramp(0.6 * RADIUS_M, 120),
    )
    fit = fit_indentation(study, progress=False)
    assert fit.success, fit.message
    if truth["model"] == "ogden":
        assert_recovered(fit, truth, 0.02)
        return
    # Mooney-Rivlin under a flat punch: C10 and C01 differ only through the large-strain
    # response, so one record pins their sum (the initial shear modulus 2 (C10 + C01)) and
    # barely their split: measured correlation -0.998, standard errors about 4 % at 1 %
    # noise (0.6 a deep; 2.6 % at 0.9 a). Each is within 3 standard errors, the sum within
    # 1 %, and the fit says that the two are not separately identified.
    assert_recovered(fit, truth, 0.1)
    fitted = fit.parameters
    assert fitted["C10_Pa"] + fitted["C01_Pa"] == pytest.approx(280.0, rel=0.01)
    assert fit.result.correlation[0, 1] < -0.99
    assert any("C10_Pa" in w and "C01_Pa" in w for w in fit.warnings), fit.warnings


@pytest.mark.parametrize(
    ("truth", "free", "history", "steps"),
    [
        (REDUCED_POLYNOMIAL, ("C10_Pa", "C20_Pa"), ramp(0.4 * RADIUS_M, 12), 6),
        (VISCOELASTIC, ("C10_Pa", "g1", "tau1_s"), ramp_and_hold(), 10),
    ],
    ids=["reduced_polynomial", "viscoelastic"],
)
@pytest.mark.slow
def test_the_jacobian_equals_central_differences_of_the_residuals(
    tmp_path, truth, free, history, steps
):
    study = make_study(
        tmp_path,
        truth=truth,
        start=truth,
        fit=f'free = {json.dumps(list(free))}\nobjective = "relative"\ntime_steps = {steps}\n',
        history=history,
        solver="tolerance = 1e-12",
    )
    model = forward_model(study, study.material, free, device="cpu", progress=False)
    x = np.array([truth[name] for name in free]) * 0.9
    jacobian = model.jac(x)
    assert model.forward_solves == model.solves_per_evaluation  # fun and jac: one run
    model.fun(x)
    assert model.forward_solves == model.solves_per_evaluation
    assert_jacobian_is_central_differences(model, x, jacobian, 1e-6 * x, free)


def test_ctrl_c_keeps_the_best_parameters_evaluated(tmp_path):
    study = make_study(
        tmp_path,
        truth=NEO_HOOKEAN,
        start=NEO_HOOKEAN,
        fit='free = ["C10_Pa"]\ntime_steps = 8\n[fit.start]\nC10_Pa = 2000.0\n',
        history=ramp(0.3 * RADIUS_M),
    )
    steps = []

    def interrupt(progress):
        steps.append(progress)
        if progress.iteration == 2:
            raise KeyboardInterrupt

    fit = fit_indentation(study, progress=False, callback=interrupt)
    assert fit.status == "interrupted" and fit.exit_code == 130 and not fit.success
    assert [p.iteration for p in steps] == [1, 2]
    start_cost = forward_model(
        study, study.material, ("C10_Pa",), device="cpu", progress=False
    ).evaluate(np.array([2000.0]))
    assert fit.result.cost <= start_cost.cost
    assert fit.start_cost == pytest.approx(start_cost.cost)
    best = min(steps, key=lambda p: p.cost)
    assert fit.result.x[0] == pytest.approx(best.parameters["C10_Pa"])
    assert fit.result.cost == pytest.approx(best.cost)
    assert fit.fitted_study.material.C10_Pa == pytest.approx(fit.result.x[0])
    assert fit.records[0].fitted_force_N.shape == (31,)
    assert fit.result.standard_errors is not None
    assert any("did not converge (interrupted)" in message for message in fit.warnings)
    summary = json.loads(json.dumps(fit.to_dict()))
    assert summary["status"] == "interrupted" and not summary["success"]
    assert summary["parameters"]["C10_Pa"]["value"] == pytest.approx(fit.result.x[0])
    assert len(summary["history"]) == 2


def test_ctrl_c_inside_a_forward_run_keeps_the_best_parameters(
    tmp_path, ctrl_c_at_newton_increment
):
    study = make_study(
        tmp_path,
        truth=NEO_HOOKEAN,
        start=NEO_HOOKEAN,
        fit='free = ["C10_Pa"]\ntime_steps = 8\n[fit.start]\nC10_Pa = 2000.0\n',
        history=ramp(0.3 * RADIUS_M),
    )
    costs = []
    # One Newton increment per load step: the start run's 8 steps, the first trial's 8, then
    # Ctrl-C in the third step of the second trial.
    ctrl_c_at_newton_increment(8 * 2 + 3)
    fit = fit_indentation(study, progress=False, callback=lambda p: costs.append(p.cost))
    assert fit.status == "interrupted" and fit.exit_code == 130
    assert len(costs) == 1  # the first trial step was reported, the second never finished
    assert fit.result.cost == pytest.approx(costs[0])  # the better of the start and trial 1
    assert fit.forward_solves == 3


@pytest.mark.slow
def test_stop_at_r_squared(tmp_path):
    study = make_study(
        tmp_path,
        truth=NEO_HOOKEAN,
        start=NEO_HOOKEAN,
        fit='free = ["C10_Pa"]\ntime_steps = 8\nstop_r_squared = 0.99\n'
        "[fit.start]\nC10_Pa = 400.0\n",
        history=ramp(0.3 * RADIUS_M),
    )
    fit = fit_indentation(study, progress=False)
    assert fit.status == "stopped_at_r_squared" and fit.exit_code == 0
    assert fit.result.r_squared > 0.99
    assert fit.result.iterations == 1


def test_a_record_of_another_probe_radius_is_refused_before_fitting(tmp_path):
    study = make_study(
        tmp_path,
        truth=NEO_HOOKEAN,
        start=NEO_HOOKEAN,
        fit='free = ["C10_Pa"]\n',
        history=ramp(0.3 * RADIUS_M, 5),
    )
    (tmp_path / "record.json").write_text(json.dumps({"probe_radius_m": 0.002}))
    with pytest.raises(InputError) as raised:
        fit_indentation(study, progress=False, device="no-such-device")
    message = str(raised.value)
    assert "record.csv" in message and "probe_radius_m" in message
    assert "0.002" in message and "0.001" in message
    # The same radius passes the check (and then fails on the device, after it).
    (tmp_path / "record.json").write_text(json.dumps({"probe_radius_m": 0.001}))
    with pytest.raises(Exception, match="no-such-device"):
        fit_indentation(study, progress=False, device="no-such-device")


@pytest.mark.parametrize("factor", [100.0, 0.01], ids=["too_stiff", "too_soft"])
@pytest.mark.slow
def test_a_start_100_times_off_converges(tmp_path, factor):
    # The force is nearly linear in C10: LM reaches the truth in a few steps from either side
    # (too soft, K / mu = 1e5: the mixed formulation still converges).
    study = make_study(
        tmp_path,
        truth=NEO_HOOKEAN,
        start=NEO_HOOKEAN,
        fit=f'free = ["C10_Pa"]\ntime_steps = 4\n[fit.start]\nC10_Pa = {287.5 * factor}\n',
        history=ramp(0.3 * RADIUS_M),
    )
    fit = fit_indentation(study, progress=False)
    assert fit.status == "converged", fit.message
    assert_recovered(fit, NEO_HOOKEAN, 0.02)


@pytest.mark.slow
def test_a_drifting_offset_is_reported(tmp_path):
    # An elastic record with a hold whose force rises: a transducer drifting by 2 % of the
    # peak force per second, which an elastic tissue cannot do.
    time = np.concatenate([np.linspace(0.1, 1.0, 10), np.linspace(1.25, 6.0, 20)])
    depth = np.minimum(time, 1.0) * 0.3 * RADIUS_M
    study = make_study(
        tmp_path,
        truth=NEO_HOOKEAN,
        start=NEO_HOOKEAN,
        fit='free = ["C10_Pa"]\ntime_steps = 8\n',
        history=(time, depth),
        noise=0.002,
        drift_per_s=0.02,
    )
    fit = fit_indentation(study, progress=False)
    assert any("rises" in m and "during the hold" in m for m in fit.warnings), fit.warnings
    assert any("Durbin-Watson" in m for m in fit.warnings), fit.warnings


@pytest.mark.slow
def test_two_prony_terms_on_a_one_term_record_are_not_identified(tmp_path):
    two_terms = {**NEO_HOOKEAN, "g1": 0.2, "g2": 0.2, "tau1_s": 0.3, "tau2_s": 3.0}
    study = make_study(
        tmp_path,
        truth=VISCOELASTIC,
        start=two_terms,
        fit='free = ["g1", "g2", "tau1_s", "tau2_s"]\ntime_steps = 12\nmax_iterations = 6\n',
        history=ramp_and_hold(),
    )
    fit = fit_indentation(study, progress=False)
    assert any("not identified" in m for m in fit.warnings), fit.warnings
    assert not fit.result.identified
    assert any("g1 and g2 are correlated" in m for m in fit.warnings), fit.warnings


def test_the_iteration_limit_is_not_a_success(tmp_path):
    study = make_study(
        tmp_path,
        truth=NEO_HOOKEAN,
        start=NEO_HOOKEAN,
        fit='free = ["C10_Pa"]\ntime_steps = 6\nmax_iterations = 1\n[fit.start]\nC10_Pa = 2000.0\n',
        history=ramp(0.3 * RADIUS_M),
    )
    fit = fit_indentation(study, progress=True)  # the bars run too
    assert fit.status == "max_iterations" and not fit.success
    assert fit.exit_code == 4  # ConvergenceError's
    assert fit.result.iterations == 1
    assert any("did not converge (max_iterations)" in m for m in fit.warnings)


@pytest.mark.slow
def test_viscoelastic_c10_g1_tau1_are_recovered_from_a_ramp_and_hold(tmp_path):
    study = make_study(
        tmp_path,
        truth=VISCOELASTIC,
        start={**VISCOELASTIC, "C10_Pa": 250.0, "g1": 0.3, "tau1_s": 2.0},
        fit='free = ["C10_Pa", "g1", "tau1_s"]\ntime_steps = 16\nftol = 1e-6\nxtol = 1e-6\n',
        history=ramp_and_hold(),
    )
    fit = fit_indentation(study, progress=False)
    assert fit.status == "converged", fit.message
    assert_recovered(fit, {"C10_Pa": 287.5, "g1": 0.5, "tau1_s": 1.0}, 0.05)
    assert fit.forward_solves < fit.finite_difference_solves / 2
    assert fit.records[0].fe_time_s.size >= 16
    # The study's protocol is quasi-static: the fitted study replays the record's history
    # instead, so that simulate runs it as it is and gives the fitted force.
    assert not fit.study.protocol.timed
    saved = load_study(save_study(fit.fitted_study, tmp_path / "fitted.toml"))
    assert saved.protocol.kind == "record" and saved.protocol.timed
    outputs = run_study(saved, out_dir=tmp_path / "run", progress=False, announce=False)
    assert outputs.completed
    record = fit.records[0]
    simulated = np.interp(
        record.time_s,
        np.concatenate([[0.0], outputs.result.times_s]),
        np.concatenate([[0.0], outputs.result.reaction_force_N]),
    )
    np.testing.assert_allclose(simulated, record.fitted_force_N, atol=1e-12)


@pytest.mark.slow
def test_ahn_and_kim_two_stage_fits_the_prony_series_first(tmp_path):
    study = make_study(
        tmp_path,
        truth=VISCOELASTIC,
        start={**VISCOELASTIC, "C10_Pa": 250.0, "g1": 0.3, "tau1_s": 2.0},
        fit='free = ["C10_Pa", "g1", "tau1_s"]\nstrategy = "two_stage"\ntime_steps = 16\n',
        history=ramp_and_hold(),
    )
    fit = fit_indentation(study, progress=False)
    assert fit.strategy == "two_stage" and fit.status == "converged"
    # Stage (i): QLV on the record's relaxation, the 0.5 s ramp accounted for.
    (stage,) = fit.stage_one_fits
    assert fit.stage_one is stage
    assert stage.parameters["g1"] == pytest.approx(0.5, rel=0.05)
    assert stage.parameters["tau1_s"] == pytest.approx(1.0, rel=0.05)
    assert fit.stage_one_prony == pytest.approx(
        {"g1": stage.parameters["g1"], "tau1_s": stage.parameters["tau1_s"]}
    )
    # Stage (ii): C10 alone by inverse FE, the Prony terms fixed at stage (i)'s.
    assert fit.result.parameter_names == ("C10_Pa",)
    assert fit.result.x[0] == pytest.approx(287.5, rel=0.02)
    material = fit.fitted_study.material
    assert material.g == (stage.parameters["g1"],)
    assert material.tau_s == (stage.parameters["tau1_s"],)
    summary = json.loads(json.dumps(fit.to_dict()))
    assert summary["stage_one"]["records"][0]["parameters"]["g1"] == pytest.approx(material.g[0])
    assert summary["stage_one"]["mean"]["tau1_s"] == pytest.approx(material.tau_s[0])


def test_two_stage_needs_a_prony_series(neo_hookean_fit):
    with pytest.raises(InputError, match="Prony"):
        fit_indentation(neo_hookean_fit.study, progress=False, strategy="two_stage")
    with pytest.raises(InputError, match="strategy"):
        fit_indentation(neo_hookean_fit.study, progress=False, strategy="three_stage")


def test_the_fit_gives_the_same_parameters_on_every_device(neo_hookean_fit, device):
    """The CUDA fit (cuDSS, Warp kernels on the GPU) equals the CPU fit of the module's
    neo-Hookean record, to the optimizer's tolerance."""
    if device == "cpu":
        pytest.skip("the CPU fit is the reference (neo_hookean_fit)")
    fit = fit_indentation(neo_hookean_fit.study, device=device, progress=False)
    assert fit.status == neo_hookean_fit.status
    np.testing.assert_allclose(fit.result.x, neo_hookean_fit.result.x, rtol=1e-6)
    np.testing.assert_allclose(
        fit.records[0].fitted_force_N, neo_hookean_fit.records[0].fitted_force_N, rtol=1e-6
    )


# Contact point: a record whose recorded depth is offset from the true depth by d0.
OFFSET_M = 0.15e-3
"""The true contact of the offset records: the probe touches at a recorded depth of 0.15 mm."""


def offset_ramp(
    recorded_m: float = 0.45e-3, offset_m: float = OFFSET_M, samples: int = 45
) -> tuple[tuple[np.ndarray, np.ndarray], np.ndarray]:
    """A ramp to the recorded depth ``recorded_m`` (samples 10 um apart by default) that
    touches at ``offset_m``: ((time_s, true depth), recorded depth)."""
    time = 0.1 * np.arange(1, samples + 1)
    recorded = recorded_m * np.arange(1, samples + 1) / samples
    return (time, np.clip(recorded - offset_m, 0.0, None)), recorded


def offset_study(
    folder: Path,
    fit: str,
    truth: dict = NEO_HOOKEAN,
    solver: str = "",
    *,
    ramp=offset_ramp,
    **options,
) -> object:
    """A study of one FE record made by ``ramp(**options)`` (a depth history touching at an
    offset), started at the truth."""
    history, recorded = ramp(**options)
    return make_study(
        folder,
        truth=truth,
        start=truth,
        fit=fit,
        history=history,
        recorded_depth=[recorded],
        solver=solver,
    )


@pytest.fixture(scope="module")
def offset_record(tmp_path_factory):
    """The offset record's study (the contact given, as the lab recorded it)."""
    return offset_study(tmp_path_factory.mktemp("offset"), 'free = ["C10_Pa"]\ntime_steps = 10\n')


def with_fit(study, **changes):
    return dataclasses.replace(study, fit=dataclasses.replace(study.fit, **changes))


@pytest.mark.slow
def test_the_contact_point_and_c10_are_recovered_jointly(offset_record):
    # The offset's start is 50 % off (0.225 mm for 0.15 mm), C10 starts from the record.
    study = with_fit(offset_record, contact_point="fit", start={"depth_offset_m": 0.225e-3})
    fit = fit_indentation(study, progress=False)
    assert fit.status == "converged", fit.message
    assert fit.contact_point == "fit"
    assert fit.result.parameter_names == ("C10_Pa", "depth_offset_m")
    assert fit.result.parameter_units == ("Pa", "m")
    assert fit.start["depth_offset_m"] == pytest.approx(0.225e-3)
    d0, error = fit.parameters["depth_offset_m"], fit.result.standard_errors[1]
    assert abs(d0 - OFFSET_M) < 5e-6, d0  # 5 um, half a sample spacing
    assert abs(d0 - OFFSET_M) <= 3.0 * error
    assert_recovered(fit, {"C10_Pa": 287.5, "depth_offset_m": OFFSET_M}, 0.05)
    assert fit.parameters["C10_Pa"] == pytest.approx(287.5, rel=0.02)
    assert fit.warnings == []
    (record,) = fit.records
    assert record.depth_offset_m == d0 and record.depth_offset_standard_error_m == error
    # The FE depth is the recorded one less the offset; the FE ran in true depth.
    assert record.fe_depth_m[-1] >= 0.45e-3 - d0 > record.fe_depth_m[-2]
    before = record.depth_m < d0
    np.testing.assert_array_equal(record.fitted_force_N[before], 0.0)
    summary = json.loads(json.dumps(fit.to_dict()))
    assert summary["contact_point"] == "fit"
    assert summary["parameters"]["depth_offset_m"]["unit"] == "m"
    assert summary["parameters"]["depth_offset_m"]["standard_error"] == pytest.approx(error)
    assert summary["records"][0]["depth_offset_m"] == pytest.approx(d0)


@pytest.mark.slow
def test_without_the_contact_point_the_same_record_biases_c10(offset_record):
    # The lab's depth counts 0.15 mm of air as indentation: the tissue looks much softer.
    fit = fit_indentation(offset_record, progress=False)
    assert fit.contact_point == "given" and fit.result.parameter_names == ("C10_Pa",)
    assert fit.parameters["C10_Pa"] < 0.8 * 287.5, fit.parameters
    assert any(
        "Durbin-Watson" in m and "fit.contact_point = 'fit' fits it" in m for m in fit.warnings
    ), fit.warnings
    assert "depth_offset_m" not in fit.to_dict()["records"][0]


def test_the_offset_start_comes_from_the_first_force_above_noise(offset_record):
    (record,) = offset_record.data
    start = depth_offset_start_m(record)
    assert abs(start - OFFSET_M) <= 2e-5, start  # within two samples of the touch
    # A record conditioned with a contact point counts its depth from it: start 0.
    conditioned = dataclasses.replace(
        record,
        record=dataclasses.replace(record.record, summary={"contact": {"time_s": 0.0}}),
    )
    assert depth_offset_start_m(conditioned) == 0.0


@pytest.mark.slow
def test_an_offset_pinned_at_its_bound_is_reported(offset_record):
    # The Python option, over the study's "given".
    study = with_fit(
        offset_record,
        start={"depth_offset_m": 0.25e-3},
        bounds={"depth_offset_m": (0.2e-3, 0.3e-3)},
        max_iterations=8,
    )
    fit = fit_indentation(study, progress=False, contact_point="fit")
    assert fit.contact_point == "fit"
    assert fit.parameters["depth_offset_m"] == pytest.approx(0.2e-3)
    assert any(
        "depth_offset_m" in m and "lower bound" in m and "not identified" in m for m in fit.warnings
    ), fit.warnings


@pytest.mark.slow
def test_the_offset_column_of_the_jacobian_equals_central_differences(tmp_path):
    study = offset_study(
        tmp_path,
        'free = ["C10_Pa", "C20_Pa"]\nobjective = "relative"\ntime_steps = 6\n'
        'contact_point = "fit"\n',
        truth=REDUCED_POLYNOMIAL,
        solver="tolerance = 1e-12",
        samples=20,
    )
    free = ("C10_Pa", "C20_Pa")
    model = forward_model(
        study, study.material, free, device="cpu", progress=False, offset_start=np.array([1e-4])
    )
    x = np.array([260.0, 380.0, 1.37e-4])
    jacobian = model.jac(x)
    assert jacobian.shape == (21, 3)
    assert model.forward_solves == 1  # the offset's column costs no FE run
    assert_jacobian_is_central_differences(model, x, jacobian, (1e-6 * x[0], 1e-6 * x[1], 1e-10))
    # The FE lattice is fixed in true depth: a deeper trial adds steps of the same size.
    assert model.depth_step_m == pytest.approx((0.45e-3 - 1e-4) / 6)
    deeper = model.evaluate(np.array([260.0, 380.0, 0.2e-4]))
    assert deeper.fe_curves[0][1][-1] >= 0.45e-3 - 0.2e-4


def test_bad_contact_point_values_are_refused(offset_record, tmp_path):
    with pytest.raises(InputError, match="contact_point") as raised:
        fit_indentation(offset_record, progress=False, contact_point="guess")
    assert "\n" not in str(raised.value)
    # A start beyond the deepest recorded depth leaves nothing in contact.
    study = with_fit(
        offset_record, start={"depth_offset_m": 1e-3}, bounds={"depth_offset_m": (0, 2e-3)}
    )
    with pytest.raises(InputError, match=r"fit\.start\.depth_offset_m") as raised:
        fit_indentation(study, progress=False, contact_point="fit")
    assert "\n" not in str(raised.value)


def offset_ramp_and_hold(
    offset_m: float = 0.1e-3, depth_m: float = 0.3 * RADIUS_M
) -> tuple[tuple[np.ndarray, np.ndarray], np.ndarray]:
    """A 0.5 s ramp to the recorded depth ``offset_m + depth_m`` that touches at ``offset_m``
    (a sample at the touch), then a 5 s hold in log time: ((time_s, true depth), recorded)."""
    recorded_m = offset_m + depth_m
    touch = 0.5 * offset_m / recorded_m
    ramp = np.union1d(np.linspace(0.02, 0.5, 16), [touch])
    time = np.concatenate([ramp, 0.5 + np.geomspace(0.05, 5.0, 24)])
    recorded = np.where(time <= 0.5, recorded_m * time / 0.5, recorded_m)
    return (time, np.clip(recorded - offset_m, 0.0, None)), recorded


def viscous_offset_study(folder: Path, fit: str, **options):
    return offset_study(
        folder, fit, VISCOELASTIC, "tolerance = 1e-12", ramp=offset_ramp_and_hold, **options
    )


@pytest.mark.slow
def test_the_timed_offset_column_equals_central_differences(tmp_path):
    # Viscoelastic: the FE run starts at the touch, which moves with the offset; the column
    # is a one-sided difference (one more run), checked against central differences.
    study = viscous_offset_study(
        tmp_path, 'free = ["C10_Pa", "g1"]\ntime_steps = 6\ncontact_point = "fit"\n'
    )
    free = ("C10_Pa", "g1")
    model = forward_model(
        study, study.material, free, device="cpu", progress=False, offset_start=np.array([1e-4])
    )
    x = np.array([270.0, 0.45, 0.93e-4])
    jacobian = model.jac(x)
    assert model.forward_solves == 2  # the record's run and the offset's difference
    # The column against central differences of whole evaluations (each moves the touch).
    up, down = x.copy(), x.copy()
    up[2] += 1e-9
    down[2] -= 1e-9
    central = (model.fun(up) - model.fun(down)) / 2e-9
    scale = float(np.max(np.abs(central)))
    assert scale > 0.0
    np.testing.assert_allclose(jacobian[:, 2], central, rtol=0, atol=1e-3 * scale)


@pytest.mark.slow
def test_a_viscoelastic_record_gives_its_contact_point_and_c10(tmp_path):
    # A ramp and hold touching at 0.1 mm, the Prony term known; the offset starts 50 % off.
    study = viscous_offset_study(
        tmp_path,
        'free = ["C10_Pa"]\ntime_steps = 12\ncontact_point = "fit"\n'
        "[fit.start]\ndepth_offset_m = 0.15e-3\n",
    )
    fit = fit_indentation(study, progress=False)
    assert fit.status == "converged", fit.message
    assert fit.result.parameter_names == ("C10_Pa", "depth_offset_m")
    assert abs(fit.parameters["depth_offset_m"] - 0.1e-3) < 5e-6
    assert fit.parameters["C10_Pa"] == pytest.approx(287.5, rel=0.02)
    assert fit.forward_solves == 2 * fit.result.nfev  # the record's run and the difference
    assert fit.warnings == []


@pytest.mark.slow
def test_each_record_has_its_own_offset_and_all_share_one_fe_run(tmp_path):
    first, recorded_first = offset_ramp()
    second, recorded_second = offset_ramp(0.3e-3, 0.05e-3, 30)
    study = make_study(
        tmp_path,
        truth=NEO_HOOKEAN,
        start=NEO_HOOKEAN,
        fit='free = ["C10_Pa"]\ntime_steps = 10\ncontact_point = "fit"\n',
        history=[first, second],
        recorded_depth=[recorded_first, recorded_second],
    )
    fit = fit_indentation(study, progress=False)
    assert fit.status == "converged", fit.message
    assert fit.result.parameter_names == ("C10_Pa", "depth_offset1_m", "depth_offset2_m")
    assert fit.forward_solves == fit.result.nfev  # one FE run per evaluation, both records
    assert fit.parameters["C10_Pa"] == pytest.approx(287.5, rel=0.02)
    assert abs(fit.parameters["depth_offset1_m"] - OFFSET_M) < 5e-6
    assert abs(fit.parameters["depth_offset2_m"] - 0.05e-3) < 5e-6
    assert [r.depth_offset_m for r in fit.records] == list(fit.result.x[1:])
    assert fit.warnings == []


@pytest.mark.slow
def test_the_cli_reports_the_fitted_contact_point(offset_record, tmp_path, capsys):
    from warptissue.cli import main

    text = offset_record.path.read_text() + 'contact_point = "fit"\n'
    path = offset_record.path.with_name("contact_fit.toml")
    path.write_text(text)
    status = main(["fit", "indentation", str(path), "-o", str(tmp_path / "out")])
    captured = capsys.readouterr()
    assert status == 0, captured.err
    assert "depth_offset_m" in captured.out
    assert "record.csv: R^2 =" in captured.out and "contact fitted at recorded depth 0.15" in (
        captured.out
    )
    summary = json.loads((tmp_path / "out" / "fit.json").read_text())
    assert summary["contact_point"] == "fit"
    d0 = summary["records"][0]["depth_offset_m"]
    assert abs(d0 - OFFSET_M) < 5e-6
    assert summary["parameters"]["depth_offset_m"]["value"] == d0
    with (tmp_path / "out" / "fit_curves.csv").open() as handle:
        header = handle.readline().strip().split(",")
        rows = [line.strip().split(",") for line in handle]
    below = np.array([float(row[header.index("depth_below_fitted_contact_m")]) for row in rows])
    depth = np.array([float(row[header.index("depth_m")]) for row in rows])
    np.testing.assert_allclose(below, np.clip(depth - d0, 0.0, None), atol=1e-15)
    # The fitted study keeps the records as given (the offset is in fit.json) and still fits
    # the contact point when run again.
    assert "contact_point" in (tmp_path / "out" / "fitted_study.toml").read_text()


def test_the_cli_offers_the_study_keys_contact_points(capsys):
    from warptissue.cli import fit_indentation as command
    from warptissue.cli import main
    from warptissue.study import CONTACT_POINTS

    assert command.CONTACT_POINTS == CONTACT_POINTS
    with pytest.raises(SystemExit):
        main(["fit", "indentation", "--help"])
    assert "--contact-point {given,fit}" in capsys.readouterr().out


def test_the_touch_time_follows_the_offset_through_the_record():
    from types import SimpleNamespace

    from warptissue.acquisition.conditioning import FitRecord
    from warptissue.study import DataRecord

    # As a conditioned record: depth 0 (clipped) until the contact at 1 s, then 0.1 mm/s.
    time = np.arange(0.0, 4.01, 0.1)
    depth = np.clip(time - 1.0, 0.0, None) * 1e-4
    record = DataRecord(
        file="r.csv",
        path=Path("r.csv"),
        record=FitRecord(time, depth, depth * 10.0, True, {}),
    )
    model = SimpleNamespace(records=(record,), steps=8)
    touch, (times, depths) = ForwardModel._touch(model, 0, 0.0)
    assert touch == pytest.approx(1.0)  # the contact, not the first sample
    assert times[-1] == pytest.approx(3.0) and depths[-1] == pytest.approx(3e-4)
    touch, (times, depths) = ForwardModel._touch(model, 0, 0.125e-4)
    assert touch == pytest.approx(1.125)  # between samples
    assert depths[-1] == pytest.approx(3e-4 - 0.125e-4)
    with pytest.raises(RejectStep, match="never reaches"):
        ForwardModel._touch(model, 0, 4e-4)


def test_an_offset_is_judged_against_its_record_not_its_value():
    # A depth offset may be zero: its standard error is judged against a tenth of its
    # record's depth span (standard_error_scales), a modulus against its own value.
    from warptissue.lsq.result import FitResult

    def result(errors, scales):
        x = np.array([287.5, 1e-7])
        return FitResult(
            x=x,
            parameter_names=("C10_Pa", "depth_offset_m"),
            parameter_units=("Pa", "m"),
            cost=1.0,
            residuals=np.ones(10),
            jacobian=np.ones((10, 2)),
            success=True,
            status=1,
            message="",
            iterations=1,
            nfev=1,
            njev=1,
            covariance=np.diag(np.square(errors)),
            standard_errors=np.array(errors),
            correlation=np.eye(2),
            r_squared=None,
            rmse=0.0,
            standard_error_scales=scales,
        )

    scales = np.array([np.nan, 4.5e-5])
    assert result([2.0, 1e-6], scales).identifiability == []
    assert len(result([2.0, 1e-6], None).identifiability) == 1  # 1 um > 0.1 um: by value
    (message,) = result([2.0, 5e-5], scales).identifiability
    assert "depth_offset_m" in message and "larger than 4.5e-05 m" in message
    (message,) = result([300.0, 1e-6], scales).identifiability
    assert "C10_Pa" in message and "larger than its value" in message


@pytest.mark.slow
def test_batched_record_runs_equal_runs_one_after_another(tmp_path):
    """A viscoelastic fit of two records with fitted contact points: its forward model with
    the records' FE runs (and the offset columns' extra runs) batched gives the residuals
    and Jacobian of the runs one after another, to 1e-8."""
    study = viscous_offset_study(
        tmp_path, 'free = ["C10_Pa", "g1"]\ntime_steps = 6\ncontact_point = "fit"\n'
    )
    record = study.data[0]
    samples = record.record
    shorter = dataclasses.replace(
        record,
        record=dataclasses.replace(
            samples,
            time_s=samples.time_s[:-6],
            displacement_m=samples.displacement_m[:-6],
            force_N=samples.force_N[:-6],
        ),
    )
    study = dataclasses.replace(study, data=(record, shorter))
    x = np.array([270.0, 0.45, 0.93e-4, 1.1e-4])
    evaluations = {}
    for batch in (False, True):
        model = forward_model(
            study,
            study.material,
            ("C10_Pa", "g1"),
            device="cpu",
            progress=False,
            offset_start=np.array([1e-4, 1e-4]),
            batch_records=batch,
        )
        assert model.batch_records is batch
        evaluations[batch] = model.evaluate(x)
        assert model.forward_solves == 4  # two records, each with its offset's difference
    single, batched = evaluations[False], evaluations[True]
    scale = np.abs(single.residuals).max()
    np.testing.assert_allclose(batched.residuals, single.residuals, rtol=0, atol=1e-8 * scale)
    np.testing.assert_allclose(
        batched.jacobian, single.jacobian, rtol=1e-7, atol=1e-8 * np.abs(single.jacobian).max()
    )


@pytest.mark.slow
def test_studies_fitted_together_equal_each_fitted_alone(tmp_path):
    """An elastic and a viscoelastic study (different records, depths and models of time;
    both touching at (nearly) depth 0), fitted together (their forward runs batched
    whenever both ask), give each fit alone's parameters to 1e-8 (and the truth to the
    meshes' and steps' accuracy); a bad study in the list is raised after the others have
    ended."""
    (tmp_path / "e").mkdir()
    (tmp_path / "v").mkdir()
    elastic = with_fit(
        offset_study(
            tmp_path / "e",
            'free = ["C10_Pa"]\ntime_steps = 8\n',
            solver="tolerance = 1e-12",
            offset_m=0.0,
        ),
        start={"C10_Pa": 200.0},
    )
    viscous = with_fit(
        viscous_offset_study(tmp_path / "v", 'free = ["C10_Pa"]\ntime_steps = 6\n', offset_m=1e-7),
        start={"C10_Pa": 350.0},
    )
    together = fit_indentation([elastic, viscous], progress=False)
    for fit, study in zip(together, (elastic, viscous), strict=True):
        alone = fit_indentation(study, progress=False)
        assert fit.status == alone.status == "converged", (fit.message, alone.message)
        assert fit.parameters["C10_Pa"] == pytest.approx(alone.parameters["C10_Pa"], rel=1e-8)
        assert fit.parameters["C10_Pa"] == pytest.approx(287.5, rel=0.05)  # coarse steps
    broken = with_fit(elastic, strategy="no_such_strategy")
    with pytest.raises(InputError, match="no_such_strategy"):
        fit_indentation([viscous, broken], progress=False)
    with pytest.raises(InputError, match="sequence of studies"):
        fit_indentation([], progress=False)


def _follows_shear_study(folder: Path):
    """A record of NEO_HOOKEAN (K/mu0 = 1000), and a study that starts at C10 = 200 Pa with
    K/mu0 = 1000 and fits C10 with fit.bulk_modulus = "follows_shear"."""
    start = {**NEO_HOOKEAN, "C10_Pa": 200.0, "bulk_modulus_Pa": 400_000.0}
    return make_study(
        folder,
        truth=NEO_HOOKEAN,
        start=start,
        fit='free = ["C10_Pa"]\ntime_steps = 3\nstart_from = "material"\n'
        'bulk_modulus = "follows_shear"\n',
        history=ramp(0.3 * RADIUS_M, 3),
        noise=0.0,
        solver="tolerance = 1e-12",
    )


@pytest.mark.slow
def test_the_jacobian_with_the_bulk_modulus_following_the_shear_is_exact(tmp_path):
    """Issue 36: with fit.bulk_modulus = "follows_shear" K = (K/mu0 of [material]) mu0 at
    every trial point; the Jacobian (dF/dC10 through K too: the chain rule with the FE's
    dF/dK) equals central differences of the residuals, and differs from the column with K
    held (the chain rule's term is not negligible)."""
    study = _follows_shear_study(tmp_path)
    assert study.fit.bulk_modulus == "follows_shear"
    model = forward_model(study, study.material, ("C10_Pa",), device="cpu", progress=False)
    x = np.array([250.0])
    assert model.material_at(x).bulk_modulus == pytest.approx(1000.0 * 500.0, rel=1e-14)
    jacobian = model.jac(x)
    step = 1e-6 * x[0]
    central = (model.fun(x + step) - model.fun(x - step)) / (2.0 * step)
    scale = float(np.max(np.abs(central)))
    np.testing.assert_allclose(jacobian[:, 0], central, rtol=0, atol=1e-6 * scale)
    held = forward_model(
        dataclasses.replace(study, fit=dataclasses.replace(study.fit, bulk_modulus="fixed")),
        study.material,
        ("C10_Pa",),
        device="cpu",
        progress=False,
    )
    assert not np.allclose(held.jac(x)[:, 0], central, rtol=0, atol=1e-3 * scale)


@pytest.mark.slow
def test_the_fitted_bulk_to_shear_ratio_is_the_start_s(tmp_path):
    """Issue 36: only K itself could be held, so a nearly incompressible material's K/mu0
    drifted as C10 was fitted (1000 at the start, 1000 * 200/287.5 = 696 fitted). With
    fit.bulk_modulus = "follows_shear" the fitted K/mu0 is the start's, and C10 is recovered
    from a record of that ratio."""
    fit = fit_indentation(_follows_shear_study(tmp_path), progress=False)
    assert fit.success, fit.message
    material = fit.fitted_study.material
    assert material.C10_Pa == pytest.approx(287.5, rel=1e-4)
    assert material.bulk_modulus / material.initial_shear_modulus_Pa == pytest.approx(
        1000.0, rel=1e-12
    )


SITES_STUDY = """\
schema_version = 2
name = "sites"

[specimen]
mesh = "block.vtu"

[indenter]
kind = "flat_punch"
radius_m = 0.001
contact = "bonded"
site_m = {site}
{direction}
[protocol]
max_depth_m = 0.0003
steps = 2

[material]
model = "neo_hookean"
C10_Pa = {c10}
bulk_modulus_Pa = 575000.0

[boundary]
support = "bottom"

[solver]
device = "cpu"
"""
SITES = [  # (site, direction, indenter) of each record: a flat punch and two spheres
    ([0.0, 0.0, 0.004], None, None),
    ([0.0015, -0.001, 0.004], None, '{ kind = "sphere", radius_m = 0.0015 }'),
    ([-0.0015, 0.0012, 0.004], [0.2, 0.0, -1.0], '{ kind = "sphere", radius_m = 0.0015 }'),
]


@pytest.mark.slow
def test_records_at_three_sites_are_fitted_jointly_for_one_c10(tmp_path):
    """Records at three sites of one mesh (a flat punch, a sphere, and a sphere 11 degrees
    off the normal), each made by its own single-site study (its site in ``[indenter]``)
    with 0.5 % noise, fitted jointly from a start 30 % low: C10 within 2 %, the sites'
    forward runs one per site per evaluation."""
    full = indentation_block(
        width_m=0.008, thickness_m=0.004, probe_radius_m=RADIUS_M, quarter=False,
        size_near_m=0.001, size_far_m=0.002, growth=1.5,
    )  # fmt: skip
    write_mesh(tmp_path / "block.vtu", full)
    depth = np.linspace(0.0, 0.0003, 13)[1:]
    rng = np.random.default_rng(3)
    records = ""
    for k, (site, direction, indenter) in enumerate(SITES):
        text = SITES_STUDY.format(
            site=site,
            direction="" if direction is None else f"direction = {direction}\n",
            c10=NEO_HOOKEAN["C10_Pa"],
        )
        if indenter is not None:
            text = text.replace(
                'kind = "flat_punch"\nradius_m = 0.001\ncontact = "bonded"',
                'kind = "sphere"\nradius_m = 0.0015',
            )
        single = load_study(_write(tmp_path / f"site{k}.toml", text))
        run = simulate_indentation(build_problem(single, build_mesh(single)), depth, progress=False)
        force = run.reaction_force_N * (1.0 + 0.005 * rng.standard_normal(depth.size))
        write_csv(
            tmp_path / f"site{k}.csv",
            {
                "time_s": 0.1 * np.arange(1, depth.size + 1),
                "displacement_m": depth,
                "force_N": force,
            },
        )
        records += f'\n[[data]]\nfile = "site{k}.csv"\nsite_m = {site}\n'
        if direction is not None:
            records += f"direction = {direction}\n"
        if indenter is not None:
            records += f"indenter = {indenter}\n"
    text = SITES_STUDY.format(site=SITES[0][0], direction="", c10=0.7 * NEO_HOOKEAN["C10_Pa"])
    text += records + '\n[fit]\nfree = ["C10_Pa"]\nstart_from = "material"\ntime_steps = 6\n'
    study = load_study(_write(tmp_path / "sites.toml", text))
    fit = fit_indentation(study, progress=False)
    assert fit.status == "converged", fit.message
    assert_recovered(fit, NEO_HOOKEAN, 0.02)
    assert fit.forward_solves == 3 * fit.result.nfev  # one run per site per evaluation
    for record in fit.records:
        assert record.r_squared > 0.99, record.file


def _write(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


REGIONS_STUDY = """\
schema_version = 2
name = "two_regions"

[specimen]
mesh = "halves.vtu"

[indenter]
kind = "sphere"
radius_m = 0.0015
site_m = [-0.003, 0.0, 0.003]

[protocol]
max_depth_m = 0.0004
steps = 4

[material]
model = "neo_hookean"
C10_Pa = {default}
bulk_modulus_Pa = {bulk}

[material.regions.right]
tet_regions = [1]
C10_Pa = {right}
bulk_modulus_Pa = {right_bulk}

[boundary]
support = "bottom"

[solver]
device = "cpu"
tolerance = 1e-12

[[data]]
file = "left.csv"

[[data]]
file = "right.csv"
site_m = [0.003, 0.0, 0.003]

[fit]
free = ["C10_Pa", "right.C10_Pa"]
bulk_modulus = "follows_shear"
time_steps = 10
start_from = "material"
"""


def _regions_text(c10: tuple[float, float], start_from: str = "material") -> str:
    """The two-region study with C10 of the left and right halves ``c10`` (K = 100 C10)."""
    text = REGIONS_STUDY.format(
        default=c10[0], bulk=100.0 * c10[0], right=c10[1], right_bulk=100.0 * c10[1]
    )
    return text.replace('start_from = "material"', f'start_from = "{start_from}"')


@pytest.fixture(scope="module")
def regions_folder(tmp_path_factory) -> Path:
    """A block 12 x 6 x 3 mm whose half x > 0 is tet region 1 ("right"), indented by a
    sphere at the middle of each half; the records are the FE's at C10 = 200 Pa (left) and
    600 Pa (right) with 1 % noise."""
    from warptissue.mesh import block_mesh, to_tet10

    folder = tmp_path_factory.mktemp("regions")
    mesh = to_tet10(
        block_mesh(
            np.linspace(-0.006, 0.006, 9), np.linspace(-0.003, 0.003, 5), np.linspace(0, 0.003, 3)
        )
    )
    mesh.tet_regions = (mesh.points[mesh.tets[:, :4]].mean(axis=1)[:, 0] > 0).astype(np.int32)
    mesh.node_sets["bottom"] = mesh.node_sets["zmin"]
    write_mesh(folder / "halves.vtu", mesh)
    time, depth = ramp(0.0004, 40)
    for name in ("left.csv", "right.csv"):
        write_csv(folder / name, {"time_s": time, "displacement_m": depth, "force_N": 1e-4 * depth})
    path = folder / "truth.toml"
    path.write_text(_regions_text((200.0, 600.0)))
    problems, _ = record_problems(load_study(path))
    rng = np.random.default_rng(3)
    for name, problem in zip(("left.csv", "right.csv"), problems, strict=True):
        result = simulate_indentation(problem, depth, device="cpu", progress=False)
        assert result.completed, result.message
        force = result.reaction_force_N
        noisy = force + rng.normal(0.0, 0.01 * force.max(), force.size)
        write_csv(folder / name, {"time_s": time, "displacement_m": depth, "force_N": noisy})
    return folder


def _regions_study(folder: Path, start: tuple[float, float], start_from: str = "material"):
    path = folder / f"start_{start[0]:g}_{start[1]:g}_{start_from}.toml"
    path.write_text(_regions_text(start, start_from))
    return load_study(path)


def test_a_record_start_scales_every_region_s_moduli_by_one_factor(regions_folder):
    """start_from = "record": the default's C10 from the first record's stiffness, the
    region's by the same factor (their [material] ratio kept)."""
    start = start_values_from_record(_regions_study(regions_folder, (400.0, 1200.0), "record"))
    assert start["right.C10_Pa"] == pytest.approx(3.0 * start["C10_Pa"])
    # The left half's 200 Pa by the small-depth rule on this coarse mesh (135 Pa), not 400.
    assert 100.0 < start["C10_Pa"] < 300.0


@pytest.mark.slow
def test_a_region_s_columns_of_the_jacobian_equal_central_differences(regions_folder):
    """Two regions, each K following its own mu0: the Jacobian's columns of C10_Pa and
    right.C10_Pa equal central differences of the residuals."""
    study = _regions_study(regions_folder, (200.0, 600.0))
    assert study.material.parameter_names == ("C10_Pa", "right.C10_Pa")
    free = study.fit.free
    model = forward_model(study, study.material, free, device="cpu", progress=False)
    x = np.array([180.0, 700.0])
    jacobian = model.jac(x)
    material = model.material_at(x)
    assert material.materials["right"].bulk_modulus == pytest.approx(100.0 * 700.0)
    assert material.default.bulk_modulus == pytest.approx(100.0 * 180.0)
    assert_jacobian_is_central_differences(model, x, jacobian, 1e-6 * x, free)
    # Each record sees mostly its own half.
    rows = len(study.data[0].force_N)
    assert abs(jacobian[:rows, 0]).sum() > 3.0 * abs(jacobian[:rows, 1]).sum()
    assert abs(jacobian[rows:, 1]).sum() > 3.0 * abs(jacobian[rows:, 0]).sum()


@pytest.mark.slow
def test_each_region_s_c10_is_recovered_by_a_joint_fit_over_two_sites(regions_folder):
    study = _regions_study(regions_folder, (300.0, 300.0))
    fit = fit_indentation(study, device="cpu", progress=False)
    assert fit.success, fit.message
    assert_recovered(fit, {"C10_Pa": 200.0, "right.C10_Pa": 600.0}, 0.02)
    fitted = fit.fitted_study.material
    assert fitted.materials["right"].bulk_modulus == pytest.approx(
        100.0 * fit.parameters["right.C10_Pa"]
    )
    assert fit.to_dict()["fitted_material"]["regions"]["right"]["tet_regions"] == [1]


def test_each_evaluation_starts_from_the_last_one_s_states(tmp_path, monkeypatch):
    """The forward model hands each FE run the states of the last completed evaluation at
    the depths they share (a warm start), and its residuals and Jacobian are those of a
    model that starts cold, to the Newton tolerance."""
    study = make_study(
        tmp_path,
        truth=NEO_HOOKEAN,
        start=NEO_HOOKEAN,
        fit='free = ["C10_Pa"]\ntime_steps = 4\n',
        history=ramp(0.3 * RADIUS_M, samples=8),
    )
    calls = []
    original = warptissue.fem.simulate_indentation

    def recording(problem, depths, **kwargs):
        result = original(problem, depths, **kwargs)
        calls.append((kwargs.get("warm_states_m"), result))
        return result

    monkeypatch.setattr(warptissue.fem, "simulate_indentation", recording)
    model = forward_model(study, study.material, ("C10_Pa",), device="cpu", progress=False)
    model.evaluate(np.array([250.0]))
    warm = model.evaluate(np.array([300.0]))
    (first_start, first), (second_start, second) = calls
    assert first_start is None
    np.testing.assert_array_equal(second_start, first.displacement_m)
    assert second.newton_iterations.sum() < first.newton_iterations.sum()
    monkeypatch.setattr(warptissue.fem, "simulate_indentation", original)
    cold = forward_model(study, study.material, ("C10_Pa",), device="cpu", progress=False)
    reference = cold.evaluate(np.array([300.0]))
    np.testing.assert_allclose(warm.residuals, reference.residuals, rtol=0, atol=1e-8)
    np.testing.assert_allclose(warm.jacobian, reference.jacobian, rtol=1e-6)
