import json

import numpy as np
import pytest

from warptissue.errors import InputError
from warptissue.io import (
    atomic_path,
    csv_number,
    read_csv_rows,
    read_experiment_csv,
    write_csv,
    write_json,
)


def test_csv_round_trip_and_sidecar(tmp_path):
    path = tmp_path / "run.csv"
    t = np.linspace(0.0, 1.0, 5)
    write_csv(path, {"time_s": t, "displacement_m": 1e-3 * t, "force_N": 0.1 * t})
    write_json(tmp_path / "run.json", {"specimen": "liver-1", "value": np.float64(2.5)})
    data = read_experiment_csv(path)
    np.testing.assert_array_equal(data["time_s"], t)
    assert data.sample_count == 5
    assert data.metadata == {"specimen": "liver-1", "value": 2.5}


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        ("", "empty"),
        ("time_s,force_N\n0,1\n", "missing required column"),
        ("time_s,displacement_m,force_N\n", "no data rows"),
        (
            "time_s,displacement_m,force_N\n0,0,0\n1,abc,0\n",
            ":3, column 'displacement_m': not a number",
        ),
        (
            "time_s,displacement_m,force_N\n0,0,0\n1,nan,0\n",
            ":3, column 'displacement_m': not a finite",
        ),
        (
            "time_s,displacement_m,force_N\n0,0,0\n0,0,0\n",
            ":3, column 'time_s': time_s must strictly increase",
        ),
        ("time_s,displacement_m,force_N\n0,0\n", ":2: expected 3 fields"),
    ],
)
def test_bad_csv_names_file_line_and_column(tmp_path, text, fragment):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(InputError) as excinfo:
        read_experiment_csv(path)
    assert str(path) in str(excinfo.value)
    assert fragment in str(excinfo.value)


def test_read_csv_rows_keeps_text_and_file_lines(tmp_path):
    path = tmp_path / "labels.csv"
    path.write_text(" name , force_N\nA,1.5\nB,nan\n", encoding="utf-8")
    rows = read_csv_rows(path, required=("name", "force_N"))
    assert [(line, row["name"]) for line, row in rows] == [(2, "A"), (3, "B")]
    assert csv_number(path, *rows[0], "force_N") == 1.5
    with pytest.raises(InputError) as caught:
        csv_number(path, *rows[1], "force_N")
    assert (caught.value.line, caught.value.column, caught.value.value) == (3, "force_N", "nan")
    assert "not a finite number" in str(caught.value)


def test_read_csv_rows_names_missing_columns_and_files(tmp_path):
    path = tmp_path / "labels.csv"
    path.write_text("name\nA\n", encoding="utf-8")
    with pytest.raises(InputError, match=r"missing column\(s\) \['force_N'\]") as caught:
        read_csv_rows(path, required=("name", "force_N"))
    assert (caught.value.path, caught.value.line) == (path, 1)
    with pytest.raises(InputError, match="cannot read file"):
        read_csv_rows(tmp_path / "absent.csv", required=("name",))


def test_atomic_write_leaves_nothing_on_failure(tmp_path):
    target = tmp_path / "out.json"
    write_json(target, {"a": 1})
    with pytest.raises(RuntimeError), atomic_path(target) as temporary:
        temporary.write_text("half")
        raise RuntimeError("boom")
    assert json.loads(target.read_text()) == {"a": 1}
    assert [p.name for p in tmp_path.iterdir()] == ["out.json"]


def test_atomic_write_gives_the_usual_file_mode(tmp_path):
    import os

    umask = os.umask(0o022)
    try:
        path = write_json(tmp_path / "mode.json", {"a": 1})
    finally:
        os.umask(umask)
    assert path.stat().st_mode & 0o777 == 0o644


def test_experiment_csv_from_a_spreadsheet_with_a_byte_order_mark(tmp_path):
    path = tmp_path / "excel.csv"
    path.write_bytes(b"\xef\xbb\xbftime_s,displacement_m,force_N\r\n0,0,0\r\n1,0.001,0.01\r\n")
    record = read_experiment_csv(path)
    assert list(record.columns) == ["time_s", "displacement_m", "force_N"]
    assert record["force_N"].tolist() == [0.0, 0.01]


def test_a_file_that_is_not_utf8_is_a_one_line_input_error(tmp_path):
    path = tmp_path / "latin1.csv"
    path.write_bytes(b"time_s,displacement_m,force_N\n0,0,0\n1,0.001,\xb5\n")
    with pytest.raises(InputError, match="not UTF-8 text") as caught:
        read_experiment_csv(path)
    assert (caught.value.path, caught.value.line) == (path, 3)
    with pytest.raises(InputError, match="not UTF-8 text"):
        read_csv_rows(path, required=("time_s",))


def test_a_semicolon_separated_file_gets_a_hint(tmp_path):
    path = tmp_path / "semicolons.csv"
    path.write_text("time_s;displacement_m;force_N\n0;0;0\n", encoding="utf-8")
    with pytest.raises(InputError, match="fields separated by ';': use commas"):
        read_experiment_csv(path)


def test_an_atomic_write_interrupted_at_any_point_leaves_no_temporary_file(tmp_path, monkeypatch):
    """Issue 36: Ctrl-C arriving just after the temporary file was made (before the write
    began) left ``.name.<random>.tmp.suffix`` beside the target."""
    import warptissue.io as io_module

    real_close = io_module.os.close

    def interrupted(descriptor: int) -> None:
        real_close(descriptor)
        raise KeyboardInterrupt

    monkeypatch.setattr(io_module.os, "close", interrupted)
    with pytest.raises(KeyboardInterrupt):
        write_json(tmp_path / "fit.json", {"a": 1})
    monkeypatch.setattr(io_module.os, "close", real_close)
    assert list(tmp_path.iterdir()) == []


def test_a_huge_line_is_a_one_line_error_naming_file_and_line(tmp_path):
    """Issue 36: a CSV line of 10 MB was a traceback (``_csv.Error: field larger than field
    limit``)."""
    path = tmp_path / "relax.csv"
    path.write_text("time_s,displacement_m,force_N\n0,0,0\n1," + "9" * 10_000_000 + ",0\n")
    with pytest.raises(InputError) as caught:
        read_experiment_csv(path)
    assert (caught.value.path, caught.value.line) == (path, 3)
    assert "field larger than" in str(caught.value) and "\n" not in str(caught.value)
    with pytest.raises(InputError) as caught:
        read_csv_rows(path, required=("time_s",))
    assert (caught.value.path, caught.value.line) == (path, 3)


def test_a_value_beyond_any_measurement_names_file_line_and_column(tmp_path):
    """Issue 36: values of 1e308 passed, overflowed in the fit and ended in "x0 must be a
    non-empty array of finite numbers", naming neither file nor column."""
    path = tmp_path / "relax.csv"
    path.write_text("time_s,displacement_m,force_N\n0,0,0\n1,1e-3,1e308\n")
    with pytest.raises(InputError) as caught:
        read_experiment_csv(path)
    assert (caught.value.path, caught.value.line, caught.value.column) == (path, 3, "force_N")
    assert "too large" in str(caught.value)


def test_a_folder_given_as_an_experiment_file_is_named_as_one(tmp_path):
    """A folder passed where a record belongs was "experiment file not found"."""
    folder = tmp_path / "run.csv"
    folder.mkdir()
    with pytest.raises(InputError, match="this is a folder, not an experiment file"):
        read_experiment_csv(folder)
    with pytest.raises(InputError, match="experiment file not found"):
        read_experiment_csv(tmp_path / "absent.csv")


def test_an_atomic_write_that_cannot_start_names_the_file_asked_for(tmp_path, monkeypatch):
    """A folder where no file can be made: the error named the hidden temporary file."""
    import tempfile

    def refuse(**_: object) -> None:
        raise PermissionError(13, "Permission denied", str(tmp_path / ".out.xyz.tmp.json"))

    monkeypatch.setattr(tempfile, "mkstemp", refuse)
    with pytest.raises(PermissionError) as caught:
        write_json(tmp_path / "out.json", {"a": 1})
    assert caught.value.filename == str(tmp_path / "out.json")
