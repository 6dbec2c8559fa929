import json
import shlex
import subprocess
import sys
import warnings

import numpy as np
import pytest

from warptissue.cli import main
from warptissue.mesh import read_mesh


def test_generate_check_and_convert(tmp_path, capsys):
    out = tmp_path / "disc.msh"
    status = main(
        [
            "mesh", "disc", "--radius-m", "0.01", "--thickness-m", "0.004",
            "--probe-radius-m", "0.003", "--size-near-m", "0.001", "--size-far-m", "0.002",
            "--element", "TET4", "--out", str(out), "--json", str(tmp_path / "q.json"),
        ]
    )  # fmt: skip
    assert status == 0
    mesh = read_mesh(out)
    quality = json.loads((tmp_path / "q.json").read_text())["quality"]
    assert quality["tet_count"] == mesh.tet_count
    assert quality["total_volume_m3"] == mesh.volumes().sum()
    assert "min_radius_ratio" in capsys.readouterr().out
    assert main(["mesh", "convert", str(out), str(tmp_path / "disc.vtu")]) == 0
    converted = read_mesh(tmp_path / "disc.vtu")
    np.testing.assert_array_equal(converted.tets, mesh.tets)
    assert main(["mesh", "check", str(tmp_path / "disc.vtu")]) == 0


def test_generate_delaunay_block(tmp_path):
    arguments = [
        "mesh", "block", "--width-m", "0.01", "--thickness-m", "0.004",
        "--probe-radius-m", "0.002", "--size-near-m", "0.0008", "--size-far-m", "0.002",
        "--element", "TET4",
    ]  # fmt: skip
    for mesher in ("extruded", "delaunay"):
        out = tmp_path / f"{mesher}.vtu"
        assert main([*arguments, "--mesher", mesher, "--out", str(out)]) == 0
    extruded, delaunay = (read_mesh(tmp_path / f"{m}.vtu") for m in ("extruded", "delaunay"))
    assert np.isclose(delaunay.volumes().sum(), extruded.volumes().sum(), rtol=1e-12)
    assert not np.array_equal(delaunay.points, extruded.points)
    assert set(delaunay.node_sets) == set(extruded.node_sets)


def test_generate_for_a_force_accuracy(tmp_path, capsys):
    """--force-accuracy replaces --size-near-m, says which size it chose, and refuses an
    accuracy below the measured range as an error of that option."""
    arguments = [
        "mesh", "block", "--width-m", "0.02", "--thickness-m", "0.01",
        "--probe-radius-m", "0.001", "--size-far-m", "0.0025", "--out", str(tmp_path / "b.vtu"),
    ]  # fmt: skip
    assert main([*arguments, "--force-accuracy", "0.02"]) == 0
    assert "size_near_m = " in capsys.readouterr().out
    assert main([*arguments, "--force-accuracy", "0.001"]) == 2
    error = capsys.readouterr().err
    assert "--force-accuracy" in error and "0.001" in error and len(error.splitlines()) == 1
    with pytest.raises(SystemExit):  # argparse: not both
        main([*arguments, "--force-accuracy", "0.02", "--size-near-m", "0.0005"])


def test_errors_are_one_line_with_exit_codes(tmp_path, capsys):
    assert main(["mesh", "check", str(tmp_path / "missing.vtu")]) == 2
    assert "missing.vtu" in capsys.readouterr().err
    bad = tmp_path / "inverted.inp"
    bad.write_text(
        "*NODE\n1, 0, 0, 0\n2, 1, 0, 0\n3, 0, 1, 0\n4, 0, 0, 1\n5, 1, 1, 1e-14\n"
        "*ELEMENT, TYPE=C3D4\n1, 1, 2, 3, 4\n2, 1, 2, 3, 5\n"
    )
    assert main(["mesh", "check", str(bad)]) == 3
    assert "element 1: degenerate" in capsys.readouterr().err
    status = main(
        [
            "mesh", "block", "--width-m", "0.01", "--thickness-m", "0.01",
            "--probe-radius-m", "0.02", "--size-near-m", "0.001", "--size-far-m", "0.002",
            "--out", str(tmp_path / "b.vtu"),
        ]
    )  # fmt: skip
    assert status == 2
    assert "probe_radius_m" in capsys.readouterr().err
    assert not (tmp_path / "b.vtu").exists()


BLOCK = [
    "mesh", "block", "--thickness-m", "0.004", "--probe-radius-m", "0.002",
    "--size-near-m", "0.0008", "--size-far-m", "0.002", "--element", "TET4",
]  # fmt: skip


def test_lengths_take_unit_suffixes(tmp_path):
    """``--width-m 10mm`` is 0.01 m, as ``acquire`` reads its quantities; plain numbers stay
    metres."""
    assert main([*BLOCK, "--width-m", "10mm", "--out", str(tmp_path / "mm.vtu")]) == 0
    assert main([*BLOCK, "--width-m", "0.01", "--out", str(tmp_path / "m.vtu")]) == 0
    in_mm, in_m = read_mesh(tmp_path / "mm.vtu"), read_mesh(tmp_path / "m.vtu")
    np.testing.assert_array_equal(in_mm.points, in_m.points)
    np.testing.assert_array_equal(in_mm.tets, in_m.tets)


@pytest.mark.parametrize(
    ("value", "message"),
    [("10xx", "unknown unit"), ("-0.01", "must be positive"), ("=-1mm", "must be positive"),
     ("0", "must be positive"), ("nan", "not a finite number"), ("wide", "not a length")],
)  # fmt: skip
def test_bad_lengths_are_one_line_usage_errors(tmp_path, capsys, value, message):
    with pytest.raises(SystemExit) as exit_info:
        width = ["--width-m" + value] if value.startswith("=") else ["--width-m", value]
        main([*BLOCK, *width, "--out", str(tmp_path / "b.vtu")])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert f"argument --width-m: {message}" in err
    assert "Traceback" not in err
    assert not (tmp_path / "b.vtu").exists()


def test_a_closed_pipe_ends_the_command_quietly(tmp_path):
    """``warptissue mesh check ... | head -1``: the reader closes the pipe before the command
    writes; the command stops with 141 (as SIGPIPE ends Unix tools), no traceback."""
    out = tmp_path / "b.vtu"
    assert main([*BLOCK, "--width-m", "0.01", "--out", str(out)]) == 0
    command = [sys.executable, "-m", "warptissue.cli", "mesh", "check", str(out)]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    process.stdout.close()  # the reader is gone before the first line
    stderr = process.stderr.read().decode()
    assert process.wait(timeout=120) == 141
    assert stderr == ""
    shell = subprocess.run(
        ["bash", "-c", f"set -o pipefail; {shlex.join(command)} | head -1"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert shell.stdout.startswith("  ")  # the first line of the quality table
    assert shell.stdout.count("\n") == 1
    assert shell.returncode in (0, 141) and "Traceback" not in shell.stderr


def test_outputs_the_system_refuses_are_one_line_errors(tmp_path, capsys):
    """``--json`` or ``--out`` into a folder or below a file: exit 2 naming the path, no
    traceback, nothing left behind."""
    mesh = tmp_path / "b.vtu"
    assert main([*BLOCK, "--width-m", "0.01", "--out", str(mesh)]) == 0
    capsys.readouterr()
    folder = tmp_path / "folder.json"
    folder.mkdir()
    cases = [
        ["mesh", "check", str(mesh), "--json", str(folder)],
        ["mesh", "check", str(mesh), "--json", str(mesh / "q.json")],
        ["mesh", "convert", str(mesh), str(tmp_path / "b.vtu" / "c.vtu")],
        [*BLOCK, "--width-m", "0.01", "--out", str(folder.with_suffix(".vtu")), "--json",
         str(folder)],
    ]  # fmt: skip
    (tmp_path / "folder.vtu").mkdir()
    for arguments in cases:
        assert main(arguments) == 2, arguments
        err = capsys.readouterr().err
        assert err.startswith("warptissue: error: cannot use ") and err.count("\n") == 1, err
        assert str(tmp_path) in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b.vtu", "folder.json", "folder.vtu"]


def test_python_warnings_print_as_one_warning_line(tmp_path, capsys, monkeypatch):
    """A warning raised under a command (cuDSS missing, say) reads as the commands' own
    ``warptissue: warning:`` lines, without the source file and line."""
    from warptissue.cli import mesh as mesh_cli

    def check_with_a_warning(args):
        warnings.warn("cuDSS is not available\n(reason)", RuntimeWarning, stacklevel=1)
        return 0

    monkeypatch.setattr(mesh_cli, "_check", check_with_a_warning)
    assert main(["mesh", "check", str(tmp_path / "any.vtu")]) == 0
    assert capsys.readouterr().err == "warptissue: warning: cuDSS is not available (reason)\n"


def test_errors_name_the_option_not_a_column(tmp_path, capsys):
    status = main(
        [*BLOCK, "--width-m", "0.01", "--growth", "0.5", "--out", str(tmp_path / "b.vtu")]
    )
    assert status == 2
    err = capsys.readouterr().err
    assert err.startswith("warptissue: error: option --growth: ") and "column" not in err


MM_TET = (
    "*NODE\n1, 0, 0, 0\n2, 1000, 0, 0\n3, 0, 1000, 0\n4, 0, 0, 1000\n"
    "*ELEMENT, TYPE=C3D4\n1, 1, 2, 3, 4\n"
)
"""One tet 1 m (1000 mm) on a side, in an Abaqus file in millimetres."""


def test_a_file_in_millimetres_is_warned_about_and_read_with_unit(tmp_path, capsys):
    source = tmp_path / "part.inp"
    source.write_text(MM_TET)  # read as metres: 1 km
    assert main(["mesh", "check", str(source), "--json", str(tmp_path / "m.json")]) == 0
    err = capsys.readouterr().err
    assert err.startswith("warptissue: warning: ") and "--unit mm" in err
    assert (
        main(["mesh", "check", str(source), "--unit", "mm", "--json", str(tmp_path / "mm.json")])
        == 0
    )
    assert capsys.readouterr().err == ""
    volumes = [json.loads((tmp_path / f"{u}.json").read_text())["quality"]["total_volume_m3"]
               for u in ("m", "mm")]  # fmt: skip
    assert volumes[0] == pytest.approx(1000.0**3 / 6.0)
    assert volumes[1] == pytest.approx(1.0 / 6.0)
    assert main(["mesh", "convert", str(source), str(tmp_path / "part.vtu"), "--unit", "mm"]) == 0
    assert read_mesh(tmp_path / "part.vtu").points.max() == pytest.approx(1.0)
