"""Inverse-FE fits of several flat-punch curves with their forward runs batched
(:mod:`warptissue.fit.batched`): each fit equals the same fit run alone, and finds the
parameters that made its synthetic curve."""

from __future__ import annotations

import dataclasses
import threading
import time
from types import SimpleNamespace

import numpy as np
import pytest

import warptissue.fit.batched as batched
from warptissue.errors import InputError
from warptissue.fem import IndentationProblem, NewtonOptions, simulate_indentation
from warptissue.fit.batched import fit_indentation_batch
from warptissue.indenter import Indenter
from warptissue.lsq import least_squares
from warptissue.materials import MooneyRivlin, NeoHookean
from warptissue.mesh import indentation_block

RADIUS_M = 1e-3
OPTIONS = NewtonOptions(tolerance=1e-11)


def _punch(size_near_m: float, material, width_m: float = 0.008) -> IndentationProblem:
    mesh = indentation_block(
        width_m=width_m,
        thickness_m=0.004,
        probe_radius_m=RADIUS_M,
        size_near_m=size_near_m,
        size_far_m=2.5e-3,
    )
    return IndentationProblem(mesh, material, Indenter("flat_punch", radius_m=RADIUS_M))


def _synthetic():
    """Two specimens: their true materials, depths and the forces those make."""
    truths = [
        _punch(RADIUS_M / 2.0, NeoHookean(287.5, 575e3)),
        _punch(RADIUS_M / 2.0, MooneyRivlin(200.0, 60.0, 2e5), width_m=0.01),
    ]
    depths = [RADIUS_M * np.array([0.05, 0.1]), RADIUS_M * np.array([0.15])]
    forces = [
        simulate_indentation(p, d, device="cpu", progress=False, options=OPTIONS).reaction_force_N
        for p, d in zip(truths, depths, strict=True)
    ]
    return truths, depths, forces


def test_batched_fits_equal_single_fits_and_find_the_truth(device):
    truths, depths, forces = _synthetic()
    starts = []
    for truth in truths:
        vector = truth.material.parameter_vector
        vector[0] *= 0.8  # C10 80 % of the truth
        starts.append(dataclasses.replace(truth, material=truth.material.with_parameters(vector)))
    fits = fit_indentation_batch(
        starts, depths, forces, ("C10_Pa",), device=device, options=OPTIONS
    )
    for start, truth, path, measured, fit in zip(starts, truths, depths, forces, fits, strict=True):
        assert fit.success, fit.message
        assert fit.x[0] == pytest.approx(truth.material.parameter_vector[0], rel=1e-6)

        def forward(x, start=start, path=path, device=device):
            vector = start.material.parameter_vector
            vector[0] = x[0]
            problem = dataclasses.replace(start, material=start.material.with_parameters(vector))
            return simulate_indentation(
                problem,
                path,
                device=device,
                progress=False,
                options=OPTIONS,
                sensitivities=("C10_Pa",),
            )

        scale = np.abs(measured).max()
        alone = least_squares(
            lambda x, f=forward, m=measured, s=scale: (f(x).reaction_force_N - m) / s,
            start.material.parameter_vector[:1],
            jac=lambda x, f=forward, s=scale: f(x).force_sensitivity_N_per_unit / s,
            bounds=(0.0, np.inf),
            x_scale=start.material.parameter_vector[:1],
            ftol=1e-10,
            xtol=1e-10,
            gtol=1e-10,
        )
        assert fit.x[0] == pytest.approx(alone.x[0], rel=1e-7)
        assert fit.iterations == alone.iterations


def test_batched_fits_refuse_bad_input():
    truths = [_punch(RADIUS_M / 2.0, NeoHookean(287.5, 575e3))] * 2
    depths = [RADIUS_M * np.array([0.05, 0.1])] * 2
    forces = [np.array([1e-4, 2e-4])] * 2
    with pytest.raises(InputError, match="one depth and one force"):
        fit_indentation_batch(truths, depths[:1], forces, ("C10_Pa",))
    with pytest.raises(InputError, match="fit parameters must be some of"):
        fit_indentation_batch(truths, depths, forces, ("C42_Pa",))
    with pytest.raises(InputError, match="one finite force per depth"):
        fit_indentation_batch(truths, depths, [f[:1] for f in forces], ("C10_Pa",))


def _linear_forward(calls: list, interrupt_at: int | None = None):
    """A stand-in for the batched FE: force = C10 * depth (N per Pa m), exact sensitivity;
    it records the thread of each call and raises Ctrl-C at call ``interrupt_at``."""

    def run(problems, depths, **kwargs):
        calls.append((threading.current_thread(), len(problems)))
        if len(calls) == interrupt_at:
            raise KeyboardInterrupt
        return [
            SimpleNamespace(
                completed=True,
                reaction_force_N=p.material.parameter_vector[0] * d,
                force_sensitivity_N_per_unit=d[:, None],
            )
            for p, d in zip(problems, depths, strict=True)
        ]

    return run


def _linear_fits():
    problem = _punch(RADIUS_M, NeoHookean(287.5, 575e3))
    truths = (300.0, 450.0, 600.0)
    depths = [RADIUS_M * np.array([0.1, 0.2])] * 3
    return [problem] * 3, depths, [c * d for c, d in zip(truths, depths, strict=True)], truths


def test_the_batched_fe_runs_in_the_callers_thread(monkeypatch):
    """Each batch is solved in the thread that called the fit (the GPU libraries keep
    per-thread handles), once per round of trial points, with the assembler built once per
    set of running fits, and every fit finds its truth."""
    calls: list = []
    monkeypatch.setattr(batched, "simulate_indentation_batch", _linear_forward(calls))
    builds: list = []
    monkeypatch.setattr(batched, "batch_assembler", lambda problems, **kw: builds.append(1))
    problems, depths, forces, truths = _linear_fits()
    fits = fit_indentation_batch(problems, depths, forces, ("C10_Pa",), device="cpu")
    assert {thread for thread, _ in calls} == {threading.current_thread()}
    assert calls[0][1] == 3
    # One assembler per set of running fits (a set only shrinks), not one per batch.
    assert len(builds) == len({size for _, size in calls}) < len(calls)
    for fit, truth in zip(fits, truths, strict=True):
        assert fit.success and fit.x[0] == pytest.approx(truth, rel=1e-8)


def test_ctrl_c_in_a_batch_stops_every_fit(monkeypatch):
    calls: list = []
    monkeypatch.setattr(batched, "simulate_indentation_batch", _linear_forward(calls, 2))
    problems, depths, forces, _ = _linear_fits()
    with pytest.raises(KeyboardInterrupt):
        fit_indentation_batch(problems, depths, forces, ("C10_Pa",), device="cpu")
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline and any(
        t.name.startswith("warptissue-fit-") for t in threading.enumerate()
    ):
        time.sleep(0.01)
    assert not [t.name for t in threading.enumerate() if t.name.startswith("warptissue-fit-")]
    assert len(calls) == 2
