"""What a batch task does with one study on its worker: the device it takes, the fit it
runs, and the numbers of a simulation or a fit for its summary row.
"""

from __future__ import annotations

import os
import signal
from pathlib import Path
from typing import Any

import numpy as np
import warp as wp

from warptissue.errors import InputError
from warptissue.fit.indentation import fit_indentation
from warptissue.report import write_indentation_fit_outputs

KILL_ONCE_ENV = "WARPTISSUE_BATCH_TEST_KILL_ONCE"
"""Test hook (tests/test_batch.py): names a file; the first Dask task to create it kills its
own worker process (SIGKILL) after writing its results and before its marker."""


def worker_device(device: str | None, study: Any) -> str | None:
    """The device of a study on a Dask worker: LocalCluster names its workers 0, 1, ...;
    on a machine with several GPUs, worker k takes GPU k mod (number of GPUs) when the device
    is ``cuda`` or ``auto`` (given or the study's). Elsewhere ``device`` as it is."""
    chosen = device if device is not None else study.solver.device
    if chosen not in ("cuda", "auto"):
        return device
    try:
        from distributed import get_worker

        name = get_worker().name
    except (ImportError, ValueError):
        return device
    if not isinstance(name, int):
        return device

    wp.init()
    count = wp.get_cuda_device_count()
    return f"cuda:{name % count}" if count > 1 else device


def kill_once_hook() -> None:
    """Test hook: the first task to create the file named by :data:`KILL_ONCE_ENV` kills
    its worker process."""
    flag = os.environ.get(KILL_ONCE_ENV)
    if not flag:
        return
    try:
        handle = os.open(flag, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
    except FileExistsError:
        return
    os.write(handle, str(os.getpid()).encode())
    os.close(handle)
    os.kill(os.getpid(), getattr(signal, "SIGKILL", signal.SIGTERM))


def simulation_numbers(outputs: Any) -> dict[str, Any]:
    """A simulation's numbers of its outcome, from its :class:`SimulationOutputs`."""
    forces = np.asarray(outputs.summary["force_curve"]["reaction_force_N"], dtype=np.float64)
    return {
        "status": outputs.status,
        "exit_status": outputs.exit_code,
        "solved_together": int(outputs.summary["solved_together"]),
        "peak_force_N": float(forces.max()) if forces.size else None,
        "warnings": list(outputs.summary["warnings"]),
        "error": "" if outputs.completed else f"stopped early: {outputs.message}",
    }


def fit_study(study: Any, out_dir: Path, device: str | None) -> dict[str, Any]:
    check_out_dir(out_dir)
    return fit_numbers(fit_indentation(study, device=device, progress=False), out_dir)


def check_out_dir(out_dir: Path) -> None:
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError("the output folder is a file", path=out_dir)


def fit_numbers(fit: Any, out_dir: Path, solved_together: int = 1) -> dict[str, Any]:
    """Write a fit's outputs into its folder; its outcome's numbers."""

    write_indentation_fit_outputs(out_dir, fit)
    if fit.status == "interrupted":  # Ctrl-C in this process: stop the batch
        raise KeyboardInterrupt
    error = ""
    if fit.status == "stage_one_not_converged":
        error = fit.message
    elif not fit.success:
        what = "failed" if fit.status == "failed" else f"did not converge ({fit.status})"
        error = f"the fit {what}: {fit.message}"
    return {
        "status": fit.status,
        "exit_status": fit.exit_code,
        "r_squared": fit.result.r_squared,
        "parameters": {name: float(value) for name, value in fit.parameters.items()},
        "warnings": list(fit.warnings),
        "error": error,
        "solved_together": solved_together,
    }
