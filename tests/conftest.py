"""Shared fixtures: the Warp devices to test on, and small meshes."""

from __future__ import annotations

import os

import numpy as np
import pytest
import warp as wp

from warptissue._stage import register_schema_plugin
from warptissue.device import quiet_warp

quiet_warp()
wp.init()
# USD builds its schema registry once per process: a test that builds a stage with pxr itself
# before any warptissue.usd import (e.g. first on an xdist worker) would leave the project's
# TissueMaterialAPI unknown to every later test there. The package's own readers register it
# (warptissue._stage.open_stage); tests/test_mesh_io.py checks that in a fresh process.
register_schema_plugin()

DEVICES: list[str] = ["cpu"] + (["cuda:0"] if wp.is_cuda_available() else [])

THREAD_VARIABLES = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")
_THREADS_AT_START = {name: os.environ.get(name) for name in THREAD_VARIABLES}


@pytest.fixture(autouse=True)
def _thread_limits_as_at_start():
    """Put the thread limits back after each test: a Dask nanny sets OMP, MKL and OpenBLAS
    to 1 thread in this process's environment when it spawns a worker, and every later
    subprocess (the examples' scripts) would inherit that (a slow test that ran the organ
    example in 15 min alone took over 25 min after the batch tests)."""
    yield
    for name, value in _THREADS_AT_START.items():
        if value is None:
            os.environ.pop(name, None)
        else:
            os.environ[name] = value


@pytest.fixture(params=DEVICES)
def device(request: pytest.FixtureRequest) -> str:
    """Every Warp device present: ``cpu`` always, ``cuda:0`` where a GPU exists."""
    return request.param


@pytest.fixture
def rng() -> np.random.Generator:
    """A seeded random generator, so that every test is reproducible."""
    return np.random.default_rng(20261122)


@pytest.fixture
def unit_cube_tet4():
    """A unit cube split into 2 x 2 x 2 hexahedra of six tets each (48 TET4)."""
    from warptissue.mesh import block_mesh

    grid = np.linspace(0.0, 1.0, 3)
    return block_mesh(grid, grid, grid, split="six")


@pytest.fixture
def ctrl_c_at_newton_increment(monkeypatch: pytest.MonkeyPatch):
    """Arm a Ctrl-C: ``arm(n)`` makes the n-th Newton increment from then on raise
    KeyboardInterrupt, as Ctrl-C during a load step would (one increment per load step while
    no step is cut back)."""
    from warptissue.fem.newton import increment

    original = increment.newton_increment

    def arm(number: int) -> None:
        calls: list[int] = []

        def interrupted(*args, **kwargs):
            calls.append(1)
            if len(calls) == number:
                raise KeyboardInterrupt
            return original(*args, **kwargs)

        monkeypatch.setattr(increment, "newton_increment", interrupted)

    return arm
