"""Print the import structure of warptissue: cycles, imports up a floor, private names.

Reads the sources under ``warptissue/`` and ``kernels/`` (the latter as ``warptissue.kernels``,
as pyproject.toml installs it) with the standard library's :mod:`ast` only; nothing is
imported. It prints:

- the import graph's cycles: strongly connected components of more than one module, once for
  the imports at module top level (what runs at import time) and once counting the imports
  inside functions as well;
- imports "up a floor": a module that imports a module of a higher floor (below);
- private names (leading underscore) imported from another module;
- imports inside functions, counted per module;
- the largest modules by code lines (lines that are neither blank nor only a comment) and the
  largest functions by lines;
- the deprecation aliases: public names that moved, still answered at their old path for one
  release by the old module's ``__getattr__`` (``warptissue._deprecated.MOVED``, read here
  as a literal). They are no imports of the old module (nothing is imported until an old path
  is used, and then by ``warptissue._deprecated``), so they count neither as cycles nor as
  imports up a floor; they are listed apart with their floors, and one whose old module has
  no ``__getattr__ = moved_names(__name__)`` or whose new module does not exist is reported.

Floors (from docs and /work/shared/DESIGN.md's layout: data flows acquisition -> data files ->
fit, which calls fem, which launches kernels -> usd and report). A module may import its own
floor and the floors below it, never a higher one. The first matching prefix wins, longest
prefix first.

====  =====================================================================================
0     ``warptissue`` (the package root), ``errors``, ``device``, ``kernels``
1     ``materials``, ``indenter``, ``mesh``, ``io``, ``loading``, ``lsq`` (the least-squares
      engine under every fit)
2     ``viscoelastic`` (lumped models and their fits), ``acquisition`` (rig, recorder,
      conditioning: upstream of the data files)
3     ``fem``
4     ``study`` (the study schema and its TOML reader and writer: it names fem's solver
      options and acquisition's conditioning, so it sits above both)
5     ``simulate``, ``fit``, ``field``
6     ``usd``, ``report``, ``batch``
7     ``cli``
====  =====================================================================================

Usage::

    python scripts/tools/import_graph.py [--root REPO] [--top N]

Exit status 0 always; the test ``tests/test_import_graph.py`` asserts on :func:`analyse`.
"""

from __future__ import annotations

import argparse
import ast
from dataclasses import dataclass, field
from pathlib import Path

PACKAGE = "warptissue"

FLOORS: dict[str, int] = {
    "warptissue": 0,
    "warptissue.errors": 0,
    "warptissue.device": 0,
    "warptissue.kernels": 0,
    "warptissue.materials": 1,
    "warptissue.indenter": 1,
    "warptissue.mesh": 1,
    "warptissue.io": 1,
    "warptissue.loading": 1,
    "warptissue.lsq": 1,
    "warptissue.viscoelastic": 2,
    "warptissue.acquisition": 2,
    "warptissue.fem": 3,
    "warptissue.study": 4,
    "warptissue.simulate": 5,
    "warptissue.fit": 5,
    "warptissue.field": 5,
    "warptissue.usd": 6,
    "warptissue.report": 6,
    "warptissue.batch": 6,
    "warptissue.cli": 7,
}


@dataclass(frozen=True)
class Import:
    """One import statement's target in the project.

    Attributes:
        source: The importing module.
        target: The imported project module.
        names: Names taken from ``target`` (``from target import names``), empty for
            ``import target``.
        in_function: Whether the statement sits inside a function.
        type_only: Whether it sits under ``if TYPE_CHECKING:`` (never runs).
        line: Its line number in the source file.
    """

    source: str
    target: str
    names: tuple[str, ...]
    in_function: bool
    type_only: bool
    line: int


@dataclass
class Report:
    """What :func:`analyse` found.

    Attributes:
        modules: Module name -> source path.
        imports: Every import of a project module.
        cycles_top: Cycles among the imports that run at import time (top level).
        cycles_all: Cycles counting the imports inside functions as well.
        up_a_floor: Imports of a module on a higher floor than the importer's.
        private: Private names imported from another module, as (import, name).
        function_imports: Import statements inside functions (any module, project or not),
            as (module, line, text).
        module_lines: Module -> code lines (neither blank nor only a comment).
        function_lines: (module, qualified function name) -> lines.
        deprecated: Deprecation aliases, (old path, new path), sorted.
        deprecated_broken: The aliases whose old module does not answer them or whose new
            module is not a project module, as (old path, why).
    """

    modules: dict[str, Path] = field(default_factory=dict)
    imports: list[Import] = field(default_factory=list)
    cycles_top: list[list[str]] = field(default_factory=list)
    cycles_all: list[list[str]] = field(default_factory=list)
    up_a_floor: list[Import] = field(default_factory=list)
    private: list[tuple[Import, str]] = field(default_factory=list)
    function_imports: list[tuple[str, int, str]] = field(default_factory=list)
    module_lines: dict[str, int] = field(default_factory=dict)
    function_lines: dict[tuple[str, str], int] = field(default_factory=dict)
    deprecated: list[tuple[str, str]] = field(default_factory=list)
    deprecated_broken: list[tuple[str, str]] = field(default_factory=list)


def floor(module: str) -> int:
    """The floor of ``module``: that of its longest matching prefix in :data:`FLOORS`."""
    parts = module.split(".")
    for n in range(len(parts), 0, -1):
        prefix = ".".join(parts[:n])
        if prefix in FLOORS:
            return FLOORS[prefix]
    raise KeyError(f"no floor for {module}; add it to FLOORS")


def _owner_name(path: str) -> str:
    """The module part of a dotted ``module.name`` path (its floor's key)."""
    return path.rpartition(".")[0]


def find_modules(root: Path) -> dict[str, Path]:
    """Module name -> path for every ``.py`` file under ``warptissue/`` and ``kernels/``."""
    modules: dict[str, Path] = {}
    for top, prefix in ((root / "warptissue", PACKAGE), (root / "kernels", f"{PACKAGE}.kernels")):
        for path in sorted(top.rglob("*.py")):
            parts = list(path.relative_to(top).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            modules[".".join([prefix, *parts])] = path
    return modules


def _is_package(name: str, modules: dict[str, Path]) -> bool:
    return modules[name].name == "__init__.py"


def _resolve(level: int, module: str | None, current: str, modules: dict[str, Path]) -> str:
    if level == 0:
        return module or ""
    base = current.split(".")
    if not _is_package(current, modules):
        base = base[:-1]
    base = base[: len(base) - (level - 1)]
    return ".".join(base + ([module] if module else []))


def _owner(name: str, modules: dict[str, Path]) -> str | None:
    """The longest project module that ``name`` starts with, or None."""
    parts = name.split(".")
    for n in range(len(parts), 0, -1):
        candidate = ".".join(parts[:n])
        if candidate in modules:
            return candidate
    return None


class _Visitor(ast.NodeVisitor):
    def __init__(self, module: str, modules: dict[str, Path], report: Report, lines: list[str]):
        self.module = module
        self.modules = modules
        self.report = report
        self.lines = lines
        self.scope: list[str] = []
        self.functions = 0
        self.type_checking = 0

    def _function(self, node: ast.FunctionDef | ast.AsyncFunctionDef) -> None:
        name = ".".join([*self.scope, node.name])
        self.report.function_lines[(self.module, name)] = node.end_lineno - node.lineno + 1
        self.scope.append(node.name)
        self.functions += 1
        self.generic_visit(node)
        self.functions -= 1
        self.scope.pop()

    visit_FunctionDef = _function
    visit_AsyncFunctionDef = _function

    def visit_ClassDef(self, node: ast.ClassDef) -> None:
        self.scope.append(node.name)
        self.generic_visit(node)
        self.scope.pop()

    def visit_If(self, node: ast.If) -> None:
        test = node.test
        name = test.id if isinstance(test, ast.Name) else getattr(test, "attr", None)
        if name == "TYPE_CHECKING":
            self.type_checking += 1
            for child in node.body:
                self.visit(child)
            self.type_checking -= 1
            for child in node.orelse:
                self.visit(child)
        else:
            self.generic_visit(node)

    def _add(self, target: str, names: tuple[str, ...], node: ast.stmt) -> None:
        item = Import(
            self.module, target, names, self.functions > 0, self.type_checking > 0, node.lineno
        )
        self.report.imports.append(item)

    def _note_function_import(self, node: ast.stmt) -> None:
        if self.functions:
            text = " ".join(self.lines[node.lineno - 1 : node.end_lineno]).strip()
            self.report.function_imports.append((self.module, node.lineno, " ".join(text.split())))

    def visit_Import(self, node: ast.Import) -> None:
        self._note_function_import(node)
        for alias in node.names:
            name = alias.name.replace("kernels", f"{PACKAGE}.kernels", 1)
            if name.startswith("kernels") or name.startswith(PACKAGE):
                target = _owner(alias.name, self.modules)
                if target is not None:
                    self._add(target, (), node)

    def visit_ImportFrom(self, node: ast.ImportFrom) -> None:
        self._note_function_import(node)
        base = _resolve(node.level, node.module, self.module, self.modules)
        if not (base == PACKAGE or base.startswith(PACKAGE + ".")):
            return
        target = _owner(base, self.modules)
        if target is None:
            return
        names: list[str] = []
        for alias in node.names:
            submodule = f"{target}.{alias.name}"
            if submodule in self.modules:
                self._add(submodule, (), node)
            else:
                names.append(alias.name)
        if names:
            self._add(target, tuple(names), node)


def _code_lines(text: str) -> int:
    return sum(1 for line in text.splitlines() if line.strip() and not line.strip().startswith("#"))


def _strongly_connected(graph: dict[str, set[str]]) -> list[list[str]]:
    """Tarjan's strongly connected components of more than one node, each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    counter = 0

    def visit(node: str) -> None:
        nonlocal counter
        index[node] = low[node] = counter
        counter += 1
        stack.append(node)
        on_stack.add(node)
        for nxt in sorted(graph.get(node, ())):
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in on_stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            component = []
            while True:
                top = stack.pop()
                on_stack.discard(top)
                component.append(top)
                if top == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return sorted(found)


DEPRECATIONS = f"{PACKAGE}._deprecated"
"""The module whose ``MOVED`` table lists the deprecation aliases (old path -> new path)."""


def _moved_table(path: Path) -> dict[str, str]:
    """The literal ``MOVED`` dict of ``path`` (empty where it has none)."""
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        target = node.targets[0] if isinstance(node, ast.Assign) else getattr(node, "target", None)
        if isinstance(target, ast.Name) and target.id == "MOVED" and node.value is not None:
            return dict(ast.literal_eval(node.value))
    return {}


def _answers_moved_names(path: Path) -> bool:
    """Whether a module sets ``__getattr__ = moved_names(__name__)`` at top level."""
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        if (
            isinstance(node, ast.Assign)
            and any(isinstance(t, ast.Name) and t.id == "__getattr__" for t in node.targets)
            and isinstance(node.value, ast.Call)
            and getattr(node.value.func, "id", None) == "moved_names"
        ):
            return True
    return False


def _deprecations(report: Report) -> None:
    """Fill ``report.deprecated`` and ``report.deprecated_broken`` from :data:`DEPRECATIONS`."""
    if DEPRECATIONS not in report.modules:
        return
    for old, new in sorted(_moved_table(report.modules[DEPRECATIONS]).items()):
        report.deprecated.append((old, new))
        old_module = old.rpartition(".")[0]
        if old_module not in report.modules:
            report.deprecated_broken.append((old, f"no module {old_module}"))
        elif not _answers_moved_names(report.modules[old_module]):
            report.deprecated_broken.append((old, f"{old_module} sets no __getattr__"))
        if _owner(new.rpartition(".")[0], report.modules) is None:
            report.deprecated_broken.append((old, f"no module for {new}"))


def analyse(root: Path) -> Report:
    """Read the sources under ``root`` and report their import structure.

    Args:
        root: The repository root (the folder that holds ``warptissue/`` and ``kernels/``).

    Returns:
        The :class:`Report`.
    """
    report = Report(modules=find_modules(root))
    for module, path in report.modules.items():
        text = path.read_text(encoding="utf-8")
        report.module_lines[module] = _code_lines(text)
        _Visitor(module, report.modules, report, text.splitlines()).visit(ast.parse(text))

    top: dict[str, set[str]] = {m: set() for m in report.modules}
    every: dict[str, set[str]] = {m: set() for m in report.modules}
    for item in report.imports:
        if item.type_only or item.target == item.source:
            continue
        every[item.source].add(item.target)
        if not item.in_function:
            top[item.source].add(item.target)
        if floor(item.target) > floor(item.source):
            report.up_a_floor.append(item)
        for name in item.names:
            if name.startswith("_") and not name.startswith("__"):
                report.private.append((item, name))
    report.cycles_top = _strongly_connected(top)
    report.cycles_all = _strongly_connected(every)
    _deprecations(report)
    return report


def main(argv: list[str] | None = None) -> int:
    """Print the report for the repository at ``--root``."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", type=Path, default=Path(__file__).resolve().parents[2])
    parser.add_argument("--top", type=int, default=10, help="rows in the size tables")
    parser.add_argument("--list-function-imports", action="store_true")
    args = parser.parse_args(argv)
    report = analyse(args.root)

    def where(item: Import) -> str:
        kind = "function" if item.in_function else "top level"
        return f"{item.source}:{item.line} ({kind})"

    print(f"modules: {len(report.modules)}")
    for title, cycles in (
        ("cycles among top-level imports", report.cycles_top),
        ("cycles counting imports inside functions", report.cycles_all),
    ):
        print(f"\n{title}: {len(cycles)}")
        for cycle in cycles:
            print("  " + " <-> ".join(cycle))
    print(f"\nimports up a floor: {len(report.up_a_floor)}")
    for item in report.up_a_floor:
        print(
            f"  {where(item)} floor {floor(item.source)} imports {item.target} "
            f"floor {floor(item.target)}"
        )
    print(f"\nprivate names imported across modules: {len(report.private)}")
    for item, name in report.private:
        print(f"  {where(item)} imports {item.target}.{name}")
    print(f"\ndeprecation aliases (old path -> new path, {DEPRECATIONS}): {len(report.deprecated)}")
    for old, new in report.deprecated:
        floors = f"floor {floor(old.rpartition('.')[0])} -> {floor(_owner_name(new))}"
        print(f"  {old} -> {new} ({floors})")
    for old, why in report.deprecated_broken:
        print(f"  BROKEN {old}: {why}")
    print(f"\nimport statements inside functions: {len(report.function_imports)}")
    per_module: dict[str, int] = {}
    for module, _, _ in report.function_imports:
        per_module[module] = per_module.get(module, 0) + 1
    for module, count in sorted(per_module.items(), key=lambda kv: (-kv[1], kv[0])):
        print(f"  {count:4d}  {module}")
    if args.list_function_imports:
        for module, line, text in report.function_imports:
            print(f"  {module}:{line}: {text}")
    print(f"\nlargest modules by code lines (of {sum(report.module_lines.values())}):")
    for module, n in sorted(report.module_lines.items(), key=lambda kv: -kv[1])[: args.top]:
        print(f"  {n:5d}  {module}")
    print("\nlargest functions by lines:")
    ranked = sorted(report.function_lines.items(), key=lambda kv: -kv[1])[: args.top]
    for (module, name), n in ranked:
        print(f"  {n:5d}  {module}.{name}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
