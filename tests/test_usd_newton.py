"""NVIDIA Newton imports warptissue scenes (runs only where Newton is installed).

Set ``WARPTISSUE_NEWTON_PYTHON`` to an interpreter that has ``newton`` (1.8) and warptissue
installed (``scripts/tools/newton_import_check.sh`` builds one in ``.venv-newton``), or install
Newton into the test environment; otherwise the test is skipped.
"""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


def _newton_python() -> str | None:
    configured = os.environ.get("WARPTISSUE_NEWTON_PYTHON")
    if configured:
        return configured
    if importlib.util.find_spec("newton") is not None:
        return sys.executable
    return None


@pytest.mark.skipif(
    _newton_python() is None,
    reason="NVIDIA Newton is not installed here; set WARPTISSUE_NEWTON_PYTHON to a Python with "
    "newton 1.8 (scripts/tools/newton_import_check.sh builds one)",
)
@pytest.mark.parametrize("scene", [None, "scenes/liver_organ.usda"])
def test_newton_imports_soft_body(scene):
    command = [_newton_python(), str(ROOT / "scripts" / "tools" / "newton_import_check.py")]
    if scene is not None:
        command += ["--scene", str(ROOT / scene)]
    completed = subprocess.run(command, capture_output=True, text=True, timeout=300, cwd=ROOT)
    report = json.loads(completed.stdout.strip().splitlines()[-1])
    assert report["checks"] == {
        "tet_count": True,
        "particle_count": True,
        "youngs_modulus": True,
        "poissons_ratio": True,
        "density": True,
    }, report
    assert completed.returncode == 0


@pytest.mark.slow
@pytest.mark.skipif(
    _newton_python() is None,
    reason="NVIDIA Newton is not installed here; set WARPTISSUE_NEWTON_PYTHON to a Python with "
    "newton 1.8 (scripts/tools/newton_import_check.sh builds one)",
)
def test_newton_reproduces_the_trainer_asset_force(tmp_path):
    """A trainer asset (export --trainer --max-tets 2000 of the tutorial's block, the whole
    body on linear tets) pressed in Newton's VBD: the fitted probe within 10 % of the
    locking-free force at every depth, Newton equal to warptissue's linear-tet model of the
    same material to 0.1 %, and every load step settled in at most 2 000 sweeps."""
    from warptissue.cli import main

    scene = tmp_path / "trainer.usda"
    assert (
        main(
            [
                "export",
                str(ROOT / "scenes" / "tutorial_punch.toml"),
                "--trainer",
                "--max-tets",
                "2000",
                "--out",
                str(scene),
            ]
        )
        == 0
    )
    command = [
        _newton_python(),
        str(ROOT / "scripts" / "tools" / "newton_probe_check.py"),
        "--scene",
        str(scene),
        "--probes",
        "fitted",
        "--max-sweeps",
        "2000",
    ]
    completed = subprocess.run(command, capture_output=True, text=True, timeout=600, cwd=ROOT)
    report = json.loads(completed.stdout.strip().splitlines()[-1])
    assert report["ok"], report
    (probe,) = report["probes"]
    assert probe["max_sweeps_per_step"] <= 2000
    assert np.allclose(probe["newton_over_warptissue_tet4"], 1.0, atol=1e-3)
    assert np.all(np.abs(np.asarray(probe["newton_over_reference"]) - 1.0) <= 0.10)
    assert completed.returncode == 0
