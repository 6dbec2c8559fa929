"""Tests of ``warptissue batch`` (warptissue.batch, warptissue.cli.batch).

The studies are tiny versions of scenes/tutorial_punch.toml (a coarse mesh, 2 load steps) and
a one-parameter inverse-FE fit (3 depth steps), written on the fly. The batch's files are
compared with those of the single-study commands (``warptissue simulate``, ``warptissue fit
indentation``) run on the same files; a broken study among good ones is one line and the
others finish; a rerun skips complete studies and ``--force`` redoes them; and a Dask
LocalCluster of 2 worker processes loses no study when one worker is killed in the middle of
a task (the task is run again on a worker that lives).
"""

from __future__ import annotations

import csv
import json
import os
import re
import time
from pathlib import Path

import numpy as np
import pytest
from _scripts import cli_process, ctrl_c

from warptissue import batch
from warptissue.cli import EXIT_STATUSES, main
from warptissue.errors import InputError
from warptissue.io import write_csv
from warptissue.study import collect_studies, folder_names

ROOT = Path(__file__).resolve().parents[1]

FIT_STUDY = """\
schema_version = 2
name = "tiny_fit"

[specimen]
shape = "block"
width_m = 0.008
thickness_m = 0.004
quarter = true
element = "TET10"
size_near_m = 0.001
size_far_m = 0.002
growth = 1.5

[indenter]
kind = "flat_punch"
radius_m = 0.001

[protocol]
max_depth_m = 0.0003
steps = 2

[material]
model = "neo_hookean"
C10_Pa = 287.5
bulk_modulus_Pa = 575000.0

[solver]
device = "cpu"

[[data]]
file = "ramp.csv"

[fit]
free = ["C10_Pa"]
time_steps = 3
"""


def _tiny_simulation(c10_Pa: float = 287.5) -> str:
    """scenes/tutorial_punch.toml with a coarser mesh, 2 load steps and the given C10."""
    text = (ROOT / "scenes" / "tutorial_punch.toml").read_text(encoding="utf-8")
    text = text.replace("steps = 5", "steps = 2").replace(
        "size_near_m = 0.0005", "size_near_m = 0.001"
    )
    assert "steps = 2" in text and "size_near_m = 0.001" in text
    return text.replace("C10_Pa = 287.5", f"C10_Pa = {c10_Pa!r}")


def _write_studies(folder: Path) -> Path:
    """A simulation, a fit (with its record) and a study with a misspelt key."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "punch.toml").write_text(_tiny_simulation(), encoding="utf-8")
    (folder / "fit.toml").write_text(FIT_STUDY, encoding="utf-8")
    depth = np.linspace(0.0, 3e-4, 7)
    # A stiffening force-depth ramp (C10 about 400-600 Pa on this layer), 0.1 mm/s.
    force = 2e-3 * 2400.0 * depth / 0.75 * 1.3 * (1.0 + 0.5 * depth / 3e-4)
    write_csv(
        folder / "ramp.csv", {"time_s": depth / 1e-4, "displacement_m": depth, "force_N": force}
    )
    broken = _tiny_simulation().replace("growth = 1.5", "growht = 1.5")
    (folder / "broken.toml").write_text(broken, encoding="utf-8")
    return folder


def _summary(path: Path) -> dict[str, dict[str, str]]:
    with path.open(newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == list(batch.SUMMARY_COLUMNS)
    return {row["folder"]: row for row in rows}


def _alive(pid: int) -> bool:
    """Whether a process runs (a zombie, dead but not yet reaped by its parent, does not)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return True
    return state not in ("Z", "X")


def _curve(path: Path) -> np.ndarray:
    return np.loadtxt(path, delimiter=",", skiprows=1)


@pytest.fixture(scope="module")
def first_batch(tmp_path_factory):
    """The batch run once in this process (``--workers 0``): (studies, out, status, stderr)."""
    root = tmp_path_factory.mktemp("batch")
    studies = _write_studies(root / "studies")
    out = root / "out"
    import contextlib
    import io

    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        status = main(["batch", str(studies), "-o", str(out), "--workers", "0", "--quiet"])
    return studies, out, status, err.getvalue()


@pytest.mark.slow
def test_batch_files_equal_the_single_study_commands(first_batch, tmp_path, capsys):
    """Each study's folder holds what its own command writes, with the same numbers."""
    studies, out, _, _ = first_batch
    assert (
        main(["simulate", str(studies / "punch.toml"), "--out", str(tmp_path / "s"), "--quiet"])
        == 0
    )
    assert (
        main(
            ["fit", "indentation", str(studies / "fit.toml"), "-o", str(tmp_path / "f"), "--quiet"]
        )
        == 0
    )
    capsys.readouterr()
    # The simulation: the same force curve (the same code in the same process).
    batch_curve, single_curve = (
        _curve(out / "punch" / "force_curve.csv"),
        _curve(tmp_path / "s" / "force_curve.csv"),
    )
    assert batch_curve.shape == single_curve.shape == (3, 5)
    # time, depth, force and step, to the Newton tolerance (the Newton counts may differ
    # where the threaded linear solver's last bits, or its reuse of factors, do).
    np.testing.assert_allclose(batch_curve[:, :4], single_curve[:, :4], rtol=1e-7, atol=0.0)
    assert {p.name for p in (tmp_path / "s").iterdir()} <= {
        p.name for p in (out / "punch").iterdir()
    }
    # The fit: the same fitted parameter and curves, the same files.
    batch_fit = json.loads((out / "fit" / "fit.json").read_text())
    single_fit = json.loads((tmp_path / "f" / "fit.json").read_text())
    assert batch_fit["status"] == single_fit["status"] == "converged"
    c10 = batch_fit["parameters"]["C10_Pa"]["value"]
    # The FE forces agree to the Newton tolerance (which Newton solves use earlier factors
    # follows measured times), the fitted parameter to far within the fit's tolerance.
    assert c10 == pytest.approx(single_fit["parameters"]["C10_Pa"]["value"], rel=1e-6)
    assert c10 != pytest.approx(287.5, rel=0.05)  # it moved from the [material] value
    batch_curves = np.genfromtxt(out / "fit" / "fit_curves.csv", delimiter=",", skip_header=1)
    single_curves = np.genfromtxt(tmp_path / "f" / "fit_curves.csv", delimiter=",", skip_header=1)
    # Columns time, depth, measured, fitted force, residual: the residual (fitted less
    # measured) passes through zero, so its tolerance is that of the force it comes from.
    scale = np.nanmax(np.abs(single_curves[:, 1:]), axis=0)
    scale[4] = scale[3]
    assert np.all(np.abs(batch_curves[:, 1:] - single_curves[:, 1:]) <= 1e-6 * scale)
    # The summary's numbers are those of the files.
    rows = _summary(out / "summary.csv")
    assert rows["punch"]["kind"] == "simulation" and rows["punch"]["status"] == "completed"
    assert float(rows["punch"]["peak_force_N"]) == pytest.approx(
        single_curve[:, 2].max(), rel=1e-12
    )
    assert rows["punch"]["r_squared"] == "" and rows["punch"]["parameters"] == ""
    assert rows["fit"]["kind"] == "fit" and rows["fit"]["exit_status"] == "0"
    assert rows["fit"]["parameters"] == f"C10_Pa={c10!r}"
    assert float(rows["fit"]["r_squared"]) == pytest.approx(batch_fit["r_squared"], rel=1e-12)
    assert int(rows["fit"]["warnings"]) == len(batch_fit["warnings"])
    for name in ("punch", "fit"):
        marker = json.loads((out / name / batch.DONE_MARKER).read_text())
        assert marker["status"] == rows[name]["status"] and marker["exit_status"] == 0


def test_a_broken_study_is_one_line_and_the_others_finish(first_batch):
    studies, out, status, stderr = first_batch
    assert status == batch.FAILED_EXIT_CODE == 6 and 6 in EXIT_STATUSES
    rows = _summary(out / "summary.csv")
    assert [row["study"] for row in rows.values()] == [
        str(studies / name) for name in ("broken.toml", "fit.toml", "punch.toml")
    ]
    broken = rows["broken"]
    assert broken["status"] == "error" and broken["exit_status"] == "2" and broken["kind"] == ""
    assert "broken.toml:" in broken["error"] and "specimen.growht" in broken["error"]
    assert "\n" not in broken["error"]
    assert rows["punch"]["status"] == "completed" and rows["fit"]["status"] == "converged"
    assert not (out / "broken" / batch.DONE_MARKER).exists()
    lines = [line for line in stderr.splitlines() if line.startswith("warptissue:")]
    assert lines[0].startswith("warptissue: error: ") and "growht" in lines[0]
    assert "Traceback" not in stderr
    assert lines[-1] == f"warptissue: error: 1 of 3 studies failed (see {out / 'summary.csv'})"


@pytest.mark.slow
def test_together_solves_a_task_s_simulations_in_one_batched_run(first_batch, tmp_path):
    """``--together 5``: one task holds a broken study, two fits and two simulations; the
    two simulations are solved in one batched FE run (``solved_together`` 2) with the forces
    of the same study alone to the Newton tolerance, the two fits are fitted together (their
    forward runs batched) with the C10 of a fit alone, the broken study is its one-line
    row. A batched run that fails is said, and its studies run alone."""
    studies, alone_out, _, _ = first_batch
    group = _write_studies(tmp_path / "studies")
    (group / "stiff.toml").write_text(_tiny_simulation(400.0), encoding="utf-8")
    (group / "refit.toml").write_text(FIT_STUDY, encoding="utf-8")
    out = tmp_path / "out"
    status = main(["batch", str(group), "-o", str(out), "--workers", "0", "--together", "5"])
    assert status == batch.FAILED_EXIT_CODE
    rows = _summary(out / "summary.csv")
    assert list(rows) == ["broken", "fit", "punch", "refit", "stiff"]
    assert rows["broken"]["status"] == "error" and "growht" in rows["broken"]["error"]
    for name in ("fit", "refit"):
        assert rows[name]["status"] == "converged" and rows[name]["solved_together"] == "2"
    for name in ("punch", "stiff"):
        assert rows[name]["status"] == "completed" and rows[name]["solved_together"] == "2"
        assert json.loads((out / name / "result.json").read_text())["solved_together"] == 2
        marker = json.loads((out / name / batch.DONE_MARKER).read_text())
        assert marker["solved_together"] == 2
    np.testing.assert_allclose(  # time, depth, force, step
        _curve(out / "punch" / "force_curve.csv")[:, :4],
        _curve(alone_out / "punch" / "force_curve.csv")[:, :4],
        rtol=1e-7,
        atol=0.0,
    )
    assert float(rows["stiff"]["peak_force_N"]) > 1.3 * float(rows["punch"]["peak_force_N"])
    single_fit = json.loads((alone_out / "fit" / "fit.json").read_text())
    for name in ("fit", "refit"):
        fit = json.loads((out / name / "fit.json").read_text())
        assert fit["parameters"]["C10_Pa"]["value"] == pytest.approx(
            single_fit["parameters"]["C10_Pa"]["value"], rel=1e-6
        )
    with pytest.raises(InputError, match="--together"):
        batch.run_batch([group], out=out, workers=0, together=0)


def test_a_batched_run_that_fails_leaves_its_studies_to_run_alone(tmp_path, monkeypatch):
    import warptissue.simulate

    def fail(setups):
        raise RuntimeError("the device ran out of memory")

    monkeypatch.setattr(warptissue.simulate, "run_studies_together", fail)
    for name, c10 in (("punch", 287.5), ("stiff", 400.0)):
        (tmp_path / f"{name}.toml").write_text(_tiny_simulation(c10), encoding="utf-8")
    result = batch.run_batch(
        [tmp_path], out=tmp_path / "out", workers=0, together=2, progress=False
    )
    assert result.exit_code == 0
    for outcome in result.outcomes:
        assert outcome.status == "completed" and outcome.solved_together == 1
        assert outcome.warnings == [
            "solved alone: the batched run failed: RuntimeError: the device ran out of memory"
        ]
        assert (tmp_path / "out" / outcome.folder / batch.DONE_MARKER).is_file()


@pytest.mark.slow
def test_resume_skips_complete_studies_and_force_redoes_them(tmp_path):
    studies = tmp_path / "studies"
    studies.mkdir()
    (studies / "punch.toml").write_text(_tiny_simulation(), encoding="utf-8")
    (studies / "stiff.toml").write_text(_tiny_simulation(400.0), encoding="utf-8")
    out = tmp_path / "out"
    first = batch.run_batch([studies], out=out, workers=0, progress=False)
    assert first.exit_code == 0 and not first.skipped
    curve_time = (out / "punch" / "force_curve.csv").stat().st_mtime_ns
    # A rerun runs nothing: both rows come from the markers, their numbers unchanged.
    second = batch.run_batch([studies / "*.toml"], out=out, workers=0, progress=False)
    assert [o.skipped for o in second.outcomes] == [True, True]
    assert [o.peak_force_N for o in second.outcomes] == [o.peak_force_N for o in first.outcomes]
    assert (out / "punch" / "force_curve.csv").stat().st_mtime_ns == curve_time
    assert _summary(out / "summary.csv")["punch"]["skipped"] == "True"
    # A folder without its marker (a run that died before the end), or a study file that
    # changed, runs again; the rest is still skipped.
    (out / "punch" / batch.DONE_MARKER).unlink()
    (studies / "stiff.toml").write_text(_tiny_simulation(500.0), encoding="utf-8")
    third = batch.run_batch([studies], out=out, workers=0, progress=False)
    assert [o.skipped for o in third.outcomes] == [False, False]
    assert third.outcomes[1].peak_force_N > first.outcomes[1].peak_force_N
    # --force runs a complete study again.
    assert (
        main(
            [
                "batch",
                str(studies / "punch.toml"),
                "-o",
                str(out),
                "--workers",
                "0",
                "--force",
                "--quiet",
            ]
        )
        == 0
    )
    assert (out / "punch" / "force_curve.csv").stat().st_mtime_ns > curve_time
    assert _summary(out / "summary.csv")["punch"]["skipped"] == "False"


def test_study_sources_and_folder_names(tmp_path, capsys):
    for folder in ("a", "b"):
        (tmp_path / folder).mkdir()
        (tmp_path / folder / "liver.toml").write_text("", encoding="utf-8")
    (tmp_path / "a" / "kidney.toml").write_text("", encoding="utf-8")
    (tmp_path / "a" / "notes.txt").write_text("", encoding="utf-8")
    found = collect_studies([tmp_path / "a", str(tmp_path / "**" / "liver.toml")])
    assert found == [
        tmp_path / "a" / "kidney.toml",
        tmp_path / "a" / "liver.toml",
        tmp_path / "b" / "liver.toml",
    ]
    names = folder_names(found)
    assert names[0] == "kidney"
    assert re.fullmatch(r"liver-[0-9a-f]{8}", names[1]) and re.fullmatch(
        r"liver-[0-9a-f]{8}", names[2]
    )
    assert names[1] != names[2]
    # The same file gets the same folder whatever the rest of the batch and its order.
    assert folder_names([found[2], found[1]]) == [names[2], names[1]]
    with pytest.raises(InputError, match="not found"):
        collect_studies([tmp_path / "missing.toml"])
    with pytest.raises(InputError, match="no study file matches"):
        collect_studies([str(tmp_path / "*.nothing")])
    assert main(["batch", str(tmp_path / "missing.toml"), "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "study file not found" in err
    assert (
        main(
            [
                "batch",
                str(tmp_path / "a"),
                "-o",
                str(tmp_path / "o"),
                "--workers",
                "1",
                "--scheduler",
                "tcp://127.0.0.1:1",
            ]
        )
        == 2
    )


@pytest.mark.parametrize("together", [1, 2])
@pytest.mark.slow
def test_local_cluster_loses_no_study_when_a_worker_is_killed(tmp_path, monkeypatch, together):
    """Must-show c of issue 23: 2 workers on loopback, one killed in the middle of a task;
    with ``together=2`` the killed task holds two studies solved in one batched run, and
    the task is run again whole."""
    pytest.importorskip("distributed")
    studies = tmp_path / "studies"
    studies.mkdir()
    # With together=2, 4 studies make 2 tasks of 2: whichever is killed holds two.
    stiffnesses = (250.0, 287.5, 325.0) if together == 1 else (250.0, 287.5, 325.0, 362.5)
    for k, c10 in enumerate(stiffnesses):
        (studies / f"punch{k}.toml").write_text(_tiny_simulation(c10), encoding="utf-8")
    flag = tmp_path / "killed.pid"
    # The first task to get there kills its own worker process (SIGKILL) after writing its
    # files and before its marker: the scheduler must run it again elsewhere.
    monkeypatch.setenv(batch._KILL_ONCE_ENV, str(flag))
    result = batch.run_batch(
        [studies], out=tmp_path / "out", workers=2, together=together, progress=False
    )
    assert result.workers == 2
    killed = int(flag.read_text())
    assert not _alive(killed)
    assert result.exit_code == 0 and len(result.outcomes) == len(stiffnesses)
    assert all(o.status == "completed" and not o.skipped for o in result.outcomes)
    assert [o.solved_together for o in result.outcomes] == [together] * len(stiffnesses)
    assert killed not in {o.pid for o in result.outcomes}
    assert all(o.pid != os.getpid() for o in result.outcomes)  # they ran on the workers
    assert len(_summary(result.summary_path)) == len(stiffnesses)
    # The same force curves as this process computes, to the Newton tolerance (another
    # process: the threaded linear solver's last bits, and which Newton solves use earlier
    # factors, which follows measured times, may differ).
    monkeypatch.delenv(batch._KILL_ONCE_ENV)
    here = batch.run_batch([studies], out=tmp_path / "here", workers=0, progress=False)
    assert here.exit_code == 0
    for outcome in result.outcomes:
        assert (tmp_path / "out" / outcome.folder / batch.DONE_MARKER).is_file()
        np.testing.assert_allclose(  # time, depth, force, step (not the Newton counts)
            _curve(tmp_path / "out" / outcome.folder / "force_curve.csv")[:, :4],
            _curve(tmp_path / "here" / outcome.folder / "force_curve.csv")[:, :4],
            rtol=1e-7,
            atol=1e-15,
        )


def test_a_running_scheduler_runs_the_batch(tmp_path):
    """``--scheduler tcp://HOST:PORT``: the studies run on the workers of that cluster, two
    of them in one task with ``--together 2``."""
    distributed = pytest.importorskip("distributed")
    import logging

    (tmp_path / "punch.toml").write_text(_tiny_simulation(), encoding="utf-8")
    (tmp_path / "stiff.toml").write_text(_tiny_simulation(400.0), encoding="utf-8")
    with distributed.LocalCluster(
        n_workers=1,
        threads_per_worker=1,
        host="127.0.0.1",
        dashboard_address=None,
        silence_logs=logging.ERROR,
    ) as cluster:
        worker_pids = set(distributed.Client(cluster).run(os.getpid).values())
        status = main(
            [
                "batch",
                str(tmp_path / "*.toml"),
                "-o",
                str(tmp_path / "out"),
                "--scheduler",
                cluster.scheduler_address,
                "--together",
                "2",
                "--quiet",
            ]
        )
    assert status == 0
    # One task, both studies in one batched FE run on the cluster's worker.
    for name in ("punch", "stiff"):
        marker = json.loads((tmp_path / "out" / name / batch.DONE_MARKER).read_text())
        assert marker["pid"] in worker_pids and marker["status"] == "completed"
        assert marker["solved_together"] == 2
        assert _curve(tmp_path / "out" / name / "force_curve.csv").shape == (3, 5)


def test_run_batch_is_stopped_by_ctrl_c_with_the_summary_of_what_ended(tmp_path, monkeypatch):
    """Ctrl-C in this process ends the batch (KeyboardInterrupt passes the study task)."""
    studies = tmp_path / "studies"
    studies.mkdir()
    for k in range(2):
        (studies / f"p{k}.toml").write_text(_tiny_simulation(), encoding="utf-8")
    calls = []

    def interrupt_second(*args, **kwargs):
        calls.append(args)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    real = batch._simulate
    monkeypatch.setattr(batch, "_simulate", interrupt_second)
    with pytest.raises(KeyboardInterrupt):
        batch.run_batch([studies], out=tmp_path / "out", workers=0, progress=False)
    rows = _summary(tmp_path / "out" / "summary.csv")
    assert list(rows) == ["p0"] and rows["p0"]["status"] == "completed"


def test_outputs_inside_out_are_not_studies_and_workers_take_gpus_in_turn(tmp_path, monkeypatch):
    """A pattern reaching into OUT leaves the batch's own files out; on a LocalCluster of a
    machine with 2 GPUs, worker 3 takes cuda:1 for 'cuda' and 'auto', and an explicit
    device or the CPU stays as it is."""
    (tmp_path / "out" / "fit").mkdir(parents=True)
    (tmp_path / "out" / "fit" / "fitted_study.toml").write_text("", encoding="utf-8")
    with pytest.raises(InputError, match="inside the output folder"):
        batch.run_batch([str(tmp_path / "**" / "*.toml")], out=tmp_path / "out", workers=0)
    distributed = pytest.importorskip("distributed")
    import types

    import warp as wp

    monkeypatch.setattr(distributed, "get_worker", lambda: types.SimpleNamespace(name=3))
    monkeypatch.setattr(wp, "get_cuda_device_count", lambda: 2)
    study = types.SimpleNamespace(solver=types.SimpleNamespace(device="auto"))
    assert batch._worker_device(None, study) == "cuda:1"
    assert batch._worker_device("cuda", study) == "cuda:1"
    assert batch._worker_device("cuda:0", study) == "cuda:0"
    assert batch._worker_device("cpu", study) == "cpu"
    monkeypatch.setattr(wp, "get_cuda_device_count", lambda: 1)
    assert batch._worker_device("cuda", study) == "cuda"
    monkeypatch.setattr(distributed, "get_worker", lambda: types.SimpleNamespace(name="w"))
    monkeypatch.setattr(wp, "get_cuda_device_count", lambda: 2)
    assert batch._worker_device("cuda", study) == "cuda"  # a worker of `dask worker`


@pytest.mark.slow
def test_local_workers_are_pinned_to_the_gpus_in_turn(tmp_path, monkeypatch):
    """One worker per GPU by default, each pinned by CUDA_VISIBLE_DEVICES (two workers on one
    GPU share it): each study's row names the GPU its worker had. Simulated here with the
    GPUs this process may use set to '3,5' (the CPU studies ignore the pin)."""
    pytest.importorskip("distributed")
    import warp as wp

    monkeypatch.setattr(wp, "get_cuda_device_count", lambda: 2)
    monkeypatch.delenv(batch.GPU_PIN_ENV, raising=False)
    assert batch.worker_gpus("cuda") == ["0", "1"]
    assert batch.worker_gpus("cpu") == [] and batch.worker_gpus("cuda:1") == []
    monkeypatch.setenv(batch.GPU_PIN_ENV, "3, 5")
    assert batch.worker_gpus(None) == batch.worker_gpus("auto") == ["3", "5"]
    for k in range(3):
        (tmp_path / f"p{k}.toml").write_text(_tiny_simulation(300.0 + k), encoding="utf-8")
    result = batch.run_batch([tmp_path / "*.toml"], out=tmp_path / "out", progress=False)
    assert result.exit_code == 0 and result.workers == 2
    rows = _summary(tmp_path / "out" / "summary.csv")
    assert {rows[name]["gpu"] for name in rows} <= {"3", "5"} and len(rows) == 3
    client, cluster = batch._dask_client(None, 3, ["7"])
    try:
        pins = client.run(os.getenv, batch.GPU_PIN_ENV)
    finally:
        client.close()
        cluster.close()
    assert sorted(pins.values()) == ["7", "7", "7"]


@pytest.fixture
def silent_port():
    """A loopback port that accepts connections and never answers (a hung scheduler)."""
    import socket
    import threading

    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(8)
    held: list[socket.socket] = []
    stop = threading.Event()

    def accept() -> None:
        server.settimeout(0.2)
        while not stop.is_set():
            try:
                held.append(server.accept()[0])
            except OSError:
                continue

    thread = threading.Thread(target=accept, daemon=True)
    thread.start()
    yield server.getsockname()[1]
    stop.set()
    thread.join()
    for connection in held:
        connection.close()
    server.close()


def test_a_scheduler_that_never_answers_is_unreachable_within_the_timeout(
    tmp_path, capsys, monkeypatch, silent_port
):
    """Issue 36: a port that accepts and never answers is exit 5 within the bounded wait
    (it hung for minutes before); a scheduler address that is not one is exit 5 too."""
    pytest.importorskip("distributed")

    study = tmp_path / "a.toml"
    study.write_text(FIT_STUDY.split("[[data]]")[0], encoding="utf-8")
    monkeypatch.setattr(batch, "SCHEDULER_TIMEOUT_S", 2.0)
    started = time.perf_counter()
    address = f"tcp://127.0.0.1:{silent_port}"
    status = main(
        ["batch", str(study), "-o", str(tmp_path / "o"), "--scheduler", address, "--quiet"]
    )
    assert status == 5
    assert time.perf_counter() - started < 60  # bounded: the wait is 2 s, not forever
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "it did not answer within 2 s" in err
    status = main(
        ["batch", str(study), "-o", str(tmp_path / "o"), "--scheduler", "not a url", "--quiet"]
    )
    assert status == 5
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "cannot reach the Dask scheduler 'not a url'" in err


@pytest.mark.slow
def test_quiet_batch_on_a_local_cluster_prints_nothing(tmp_path):
    """Issue 36: ``--quiet`` printed Warp's start-up notes (stdout) and its CUDA-driver
    warning (stderr, once per process) on a machine without a CUDA driver."""
    pytest.importorskip("distributed")
    study = tmp_path / "punch.toml"
    study.write_text(_tiny_simulation(), encoding="utf-8")
    options = [str(study), "-o", str(tmp_path / "out"), "--workers", "1", "--quiet"]
    with cli_process(tmp_path, "batch", *options) as process:
        out, err = process.communicate(timeout=300)
    assert (process.returncode, out, err) == (0, "", "")


@pytest.mark.slow
def test_ctrl_c_in_a_batch_is_one_line_and_leaves_no_temporary_file(tmp_path):
    """Issue 36: Ctrl-C (SIGINT to the terminal's process group) during a fit on a Dask
    worker printed the workers' tracebacks and a "leaked semaphore" warning; now the batch
    says "interrupted", exits 130, and no atomic write's temporary file is left."""
    pytest.importorskip("distributed")
    out_dir = tmp_path / "out"
    study = str(ROOT / "scenes" / "liver_fit.toml")
    options = [study, "-o", str(out_dir), "--workers", "1", "--quiet"]
    with cli_process(tmp_path, "batch", *options) as process:
        time.sleep(15.0)  # the cluster starts and the fit (about 90 s of CPU) is under way
        assert process.poll() is None, process.communicate()
        out, err = ctrl_c(process, timeout_s=120)
    assert process.returncode == 130, err
    assert err == "warptissue: interrupted\n"
    time.sleep(2.0)  # the workers' cleanup
    assert [p.name for p in out_dir.rglob("*") if ".tmp" in p.name] == []


def test_a_two_stage_fit_whose_stage_one_did_not_converge_is_exit_4_in_the_summary(
    tmp_path, monkeypatch
):
    """Issue 36: stage (i) of Ahn & Kim's two-stage fit stopped at its iteration limit and
    the batch's row said ``converged``, exit status 0, with no warning of it. Now the row's
    status is ``stage_one_not_converged`` (exit status 4, the error naming the record) and
    each stage (i) finding is among the study's warnings (its outcome's and fit.json's)."""
    import functools

    from warptissue.viscoelastic.fitting import fit_qlv

    # Stage (i) as the fit plan runs it, with one iteration.
    monkeypatch.setattr(
        "warptissue.fit._setup.fit_qlv", functools.partial(fit_qlv, max_iterations=1)
    )
    text = FIT_STUDY.replace("C10_Pa = 287.5", "C10_Pa = 287.5\ng1 = 0.3\ntau1_s = 1.0")
    text = text.replace("time_steps = 3", 'time_steps = 3\nstrategy = "two_stage"')
    (tmp_path / "relax.toml").write_text(text, encoding="utf-8")
    ramp_s = np.linspace(0.0, 3.0, 7)
    hold_s = 3.0 + np.arange(1, 13) * 0.25
    depth = np.concatenate([ramp_s * 1e-4, np.full(hold_s.size, 3e-4)])
    peak_N = 2e-3 * 2400.0 * 3e-4 / 0.75 * 1.3
    force = np.concatenate(
        [peak_N * ramp_s / 3.0, peak_N * (0.7 + 0.3 * np.exp(-(hold_s - 3.0) / 1.0))]
    )
    write_csv(
        tmp_path / "ramp.csv",
        {"time_s": np.concatenate([ramp_s, hold_s]), "displacement_m": depth, "force_N": force},
    )
    out = tmp_path / "out"
    result = batch.run_batch([tmp_path / "relax.toml"], out=out, workers=0, progress=False)
    assert result.exit_code == batch.FAILED_EXIT_CODE
    row = _summary(out / "summary.csv")["relax"]
    assert row["status"] == "stage_one_not_converged" and row["exit_status"] == "4"
    assert "stage (i) (Ahn & Kim) did not converge on ramp.csv" in row["error"]
    fit = json.loads((out / "relax" / "fit.json").read_text())
    for warnings in (result.outcomes[0].warnings, fit["warnings"]):
        assert any(
            w.startswith("stage (i) (Ahn & Kim), ramp.csv: the fit did not converge")
            for w in warnings
        ), warnings
    assert int(row["warnings"]) >= 1
