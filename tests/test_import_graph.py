"""Tests of scripts/tools/import_graph.py on the repository: the core's layout holds."""

from __future__ import annotations

import importlib.util
import sys
import tomllib
from pathlib import Path

REPOSITORY = Path(__file__).resolve().parents[1]
TOOL = REPOSITORY / "scripts" / "tools" / "import_graph.py"


def _tool():
    spec = importlib.util.spec_from_file_location("import_graph", TOOL)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up by name
    spec.loader.exec_module(module)
    return module


GRAPH = _tool()
REPORT = GRAPH.analyse(REPOSITORY)


def test_reads_every_module():
    for kernels in ("assembly", "contact", "viscous", "materials", "sparse"):
        assert f"warptissue.kernels.{kernels}" in REPORT.modules
    assert "warptissue.fem.newton" in REPORT.modules
    assert all(GRAPH.floor(module) >= 0 for module in REPORT.modules)


def test_no_cycles_among_top_level_imports():
    assert REPORT.cycles_top == []


def test_no_cycles_counting_function_imports():
    assert REPORT.cycles_all == []


def test_no_imports_up_a_floor():
    assert [f"{item.source}:{item.line} -> {item.target}" for item in REPORT.up_a_floor] == []


def _small_repository(tmp_path: Path) -> Path:
    package = tmp_path / "warptissue"
    (package / "fit").mkdir(parents=True)
    (tmp_path / "kernels").mkdir()
    (package / "__init__.py").write_text("")
    (package / "fit" / "__init__.py").write_text("from warptissue.study import _rule\n")
    (package / "study.py").write_text(
        "def _rule():\n    pass\n\n\ndef g():\n    from warptissue.fit import x\n"
    )
    return tmp_path


def test_no_private_names_across_modules():
    assert [(item.source, item.target, name) for item, name in REPORT.private] == []


def test_finds_a_cycle_and_a_private_import(tmp_path):
    report = GRAPH.analyse(_small_repository(tmp_path))
    assert report.cycles_top == []
    assert report.cycles_all == [["warptissue.fit", "warptissue.study"]]
    assert [(item.target, name) for item, name in report.private] == [("warptissue.study", "_rule")]
    assert [item.source for item in report.up_a_floor] == ["warptissue.study"]
    assert len(report.function_imports) == 1


def test_prints_the_report(tmp_path, capsys):
    assert GRAPH.main(["--root", str(_small_repository(tmp_path)), "--top", "3"]) == 0
    out = capsys.readouterr().out
    assert "cycles counting imports inside functions: 1" in out
    assert "warptissue.fit <-> warptissue.study" in out
    assert "largest functions by lines:" in out


def test_pyproject_installs_every_package():
    """pyproject.toml lists its packages: one missing there is left out of a wheel."""
    config = tomllib.loads((REPOSITORY / "pyproject.toml").read_text(encoding="utf-8"))
    listed = set(config["tool"]["setuptools"]["packages"])
    packages = {name for name, path in REPORT.modules.items() if path.name == "__init__.py"}
    assert sorted(packages - listed) == []


def test_deprecation_aliases_are_listed_apart_and_each_resolves():
    """The moved names' old paths (warptissue._deprecated.MOVED) are answered by their old
    module's ``__getattr__`` and lead to a project module; they are no imports, so the
    floors and cycles above hold with them."""
    old_paths = [old for old, _ in REPORT.deprecated]
    assert "warptissue.study.start_values_from_record" in old_paths
    assert (
        "warptissue.study.start_values_from_record",
        "warptissue.fit.start.start_values_from_record",
    ) in REPORT.deprecated
    assert REPORT.deprecated_broken == []
    assert not any(item.source == "warptissue._deprecated" for item in REPORT.imports)
