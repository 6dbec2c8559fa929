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
