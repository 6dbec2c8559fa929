"""Tests of scripts/tools/slowest_tests.py: the slowest-tests table of docs/testing.md."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

REPOSITORY = Path(__file__).resolve().parents[1]
TOOL = REPOSITORY / "scripts" / "tools" / "slowest_tests.py"


def _tool():
    spec = importlib.util.spec_from_file_location("slowest_tests", TOOL)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


TOOL_MODULE = _tool()

DURATIONS = """\
tests/test_a.py ..                                                    [100%]
============================= slowest durations ==============================
120.50s call     tests/test_a.py::test_slow[cpu-sphere]
10.00s setup    tests/test_a.py::test_slow[cpu-sphere]
30.25s call     tests/test_b.py::test_middle
0.50s teardown tests/test_b.py::test_middle
2.00s call     tests/test_b.py::TestGroup::test_quick
============================== 3 passed in 163.25s ===============================
"""

JUNIT = """<?xml version="1.0" encoding="utf-8"?>
<testsuites><testsuite name="pytest" tests="3">
<testcase classname="tests.test_a" name="test_slow[cpu-sphere]" time="130.5" />
<testcase classname="tests.test_b" name="test_middle" time="30.75" />
<testcase classname="tests.test_b.TestGroup" name="test_quick" time="2.0" />
</testsuite></testsuites>
"""


def test_durations_add_each_test_s_phases():
    totals = TOOL_MODULE.durations_from_text(DURATIONS)
    assert totals == {
        "tests/test_a.py::test_slow[cpu-sphere]": pytest.approx(130.5),
        "tests/test_b.py::test_middle": pytest.approx(30.75),
        "tests/test_b.py::TestGroup::test_quick": pytest.approx(2.0),
    }


def test_a_junit_report_gives_the_same_test_ids_and_times():
    assert TOOL_MODULE.durations_from_junit(JUNIT) == TOOL_MODULE.durations_from_text(DURATIONS)


def test_the_table_ranks_the_slowest_with_their_share_and_the_total():
    table = TOOL_MODULE.markdown_table(TOOL_MODULE.durations_from_text(DURATIONS), top=2)
    lines = table.splitlines()
    assert lines[0] == "| # | test | time | share of the run |"
    assert lines[2] == "| 1 | `tests/test_a.py::test_slow[cpu-sphere]` | 130 s (2.2 min) | 80% |"
    assert lines[3] == "| 2 | `tests/test_b.py::test_middle` | 31 s | 19% |"
    assert len([line for line in lines if line.startswith("| ")]) == 3  # header and 2 rows
    assert lines[-1] == "3 tests took 163 s (2.7 min) together; these 2 took 161 s (2.7 min)."


def test_main_prints_the_table_of_a_file_and_where_it_ran(tmp_path, capsys):
    report = tmp_path / "report.xml"
    report.write_text(JUNIT, encoding="utf-8")
    assert TOOL_MODULE.main([str(report), "--top", "1", "--machine", "a 2-core CPU"]) == 0
    out = capsys.readouterr().out
    assert "| 1 | `tests/test_a.py::test_slow[cpu-sphere]` |" in out
    assert "test_middle" not in out
    assert out.rstrip().endswith("Measured on: a 2-core CPU.")


@pytest.mark.parametrize(
    ("text", "top", "message"),
    [
        ("no durations here\n", "10", "no test durations"),
        (DURATIONS, "0", "--top must be 1 or more"),
        ("<testsuites><oops", "10", "not a JUnit XML report"),
    ],
)
def test_a_report_without_durations_is_one_line_and_exit_2(tmp_path, capsys, text, top, message):
    report = tmp_path / "report.txt"
    report.write_text(text, encoding="utf-8")
    assert TOOL_MODULE.main([str(report), "--top", top]) == 2
    error = capsys.readouterr().err
    assert message in error and len(error.strip().splitlines()) == 1


def test_a_missing_file_is_one_line_and_exit_2(tmp_path, capsys):
    assert TOOL_MODULE.main([str(tmp_path / "missing.txt")]) == 2
    error = capsys.readouterr().err
    assert "cannot be read" in error and len(error.strip().splitlines()) == 1
