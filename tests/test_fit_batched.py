"""Inverse-FE fits of several studies with their forward runs batched
(:func:`warptissue.fit.fit_indentation` over a list of studies, :mod:`warptissue.fit._forward`):
the FE runs in the caller's thread, once per round of trial points, and Ctrl-C stops every
fit with its best point. (That each fit equals the same fit alone is
tests/test_fit_indentation.py's.)"""

from __future__ import annotations

import threading
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import tomli_w

import warptissue.fem
from warptissue.errors import InputError
from warptissue.fit import fit_indentation
from warptissue.io import write_csv
from warptissue.study import load_study


def _study(name: str, start_Pa: float) -> dict:
    """A neo-Hookean flat-punch fit study of C10 (2 FE depths, a 4 mm quarter block) whose
    record is ``ramp.csv`` beside it."""
    return {
        "schema_version": 2,
        "name": f"linear_{name}",
        "specimen": {
            "shape": "block",
            "width_m": 0.008,
            "thickness_m": 0.004,
            "quarter": True,
            "element": "TET10",
            "size_near_m": 0.001,
            "size_far_m": 0.002,
        },
        "indenter": {"kind": "flat_punch", "radius_m": 0.001},
        "protocol": {"max_depth_m": 0.0003, "steps": 2},
        "material": {"model": "neo_hookean", "C10_Pa": start_Pa, "bulk_modulus_Pa": 575000.0},
        "solver": {"device": "cpu"},
        "data": [{"file": "ramp.csv"}],
        "fit": {"free": ["C10_Pa"], "time_steps": 4},
    }


def _linear_studies(folder: Path) -> tuple[list, tuple[float, ...]]:
    """Three studies whose records follow force = C10 * depth (N per Pa m), C10 = 300, 450,
    600 Pa, started 20 % low (the stand-in FE below gives exactly that force)."""
    truths = (300.0, 450.0, 600.0)
    studies = []
    for k, truth in enumerate(truths):
        here = folder / f"s{k}"
        here.mkdir(parents=True)
        depth = np.linspace(0.0, 3e-4, 7)
        write_csv(
            here / "ramp.csv",
            {"time_s": depth / 1e-4, "displacement_m": depth, "force_N": truth * depth},
        )
        (here / "study.toml").write_text(tomli_w.dumps(_study(str(k), 0.8 * truth)))
        studies.append(load_study(here / "study.toml"))
    return studies, truths


def _linear_forward(calls: list, interrupt_at: int | None = None):
    """A stand-in for the batched FE: force = C10 * depth, exact sensitivity; it records the
    thread and size of each call and raises Ctrl-C at call ``interrupt_at``."""

    def run(problems, depths, **kwargs):
        calls.append((threading.current_thread(), len(problems)))
        if len(calls) == interrupt_at:
            raise KeyboardInterrupt
        return [
            SimpleNamespace(
                completed=True,
                depths_m=d,
                reaction_force_N=p.material.parameter_vector[0] * d,
                force_sensitivity_N_per_unit=d[:, None],
                displacement_m=np.zeros((d.size, 1, 3)),  # the states a warm start keeps
            )
            for p, d in zip(problems, depths, strict=True)
        ]

    return run


def test_the_batched_fe_runs_in_the_callers_thread(monkeypatch, tmp_path):
    """Each batch is solved in the thread that called the fit (the GPU libraries keep
    per-thread handles), once per round of trial points, with the assembler built once per
    set of running fits, and every fit finds its truth."""
    studies, truths = _linear_studies(tmp_path)
    calls: list = []
    monkeypatch.setattr(warptissue.fem, "simulate_indentation_batch", _linear_forward(calls))
    builds: list = []
    monkeypatch.setattr(
        warptissue.fem, "batch_assembler", lambda problems, **kw: builds.append(1) or builds
    )
    fits = fit_indentation(studies, progress=False)
    assert {thread for thread, _ in calls} == {threading.current_thread()}
    assert calls[0][1] == 3
    # One assembler per set of meshes asked together, not one per batch.
    assert len(builds) == 1 < len(calls)
    for fit, truth in zip(fits, truths, strict=True):
        assert fit.status == "converged", fit.message
        assert fit.parameters["C10_Pa"] == pytest.approx(truth, rel=1e-8)


def test_ctrl_c_in_a_batch_stops_every_fit(monkeypatch, tmp_path):
    """Ctrl-C while a batch is solved reaches every fit: each ends "interrupted" with the
    best point it had evaluated, and no fit thread is left."""
    studies, _ = _linear_studies(tmp_path)
    calls: list = []
    monkeypatch.setattr(warptissue.fem, "simulate_indentation_batch", _linear_forward(calls, 2))
    monkeypatch.setattr(warptissue.fem, "batch_assembler", lambda problems, **kw: None)
    fits = fit_indentation(studies, progress=False)
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline and any(
        t.name.startswith("warptissue-fit-") for t in threading.enumerate()
    ):
        time.sleep(0.01)
    assert not [t.name for t in threading.enumerate() if t.name.startswith("warptissue-fit-")]
    assert len(calls) == 2
    assert [fit.status for fit in fits] == ["interrupted"] * 3


def test_fits_of_several_studies_refuse_bad_input(tmp_path):
    with pytest.raises(InputError, match="sequence of studies"):
        fit_indentation([], progress=False)
    with pytest.raises(InputError, match="sequence of studies"):
        fit_indentation(["not a study"], progress=False)
