"""Every code block of the README and the docs pages runs.

One test per page (README.md and every ``docs/**/*.md``); a failure names the page and the
line of the block's opening fence. The contract, for authors of examples:

- ```` ```python ```` blocks run with ``exec``, all blocks of one page in order in one fresh
  namespace, so a later block can use the names of an earlier one.
- ```` ```bash ```` blocks run with ``bash -e`` (the package's ``python`` and ``warptissue``
  first on ``PATH``).
- Both run in a temporary working directory of their own per page, in which ``scenes/``
  (the studies and the example data in ``scenes/data/``) and ``scripts/`` of the repository
  are available as symbolic links; whatever a block writes (``runs/...``) stays in that
  directory.
- ```` ```toml ```` blocks are parsed with :mod:`tomllib`; one with a ``schema_version`` is
  a study and must pass :func:`warptissue.study.study_from_dict`.
- Blocks in any other language (```` ```text ```` for output and for synopses with
  ``[optional]`` parts, ```` ```console ````, ```` ```json ````, ```` ```c ````, untagged
  frames of the rig protocol) and MyST directives (```` ```{toctree} ````) are not run.
  ``py``, ``sh``, ``shell`` and the like are refused, so that a block meant to run cannot be
  skipped silently.

The README's two set-up commands (``python -m pip install . && warptissue simulate ...`` and
``python -m pip install '.[test]' && pytest -q``) are run by ``.ci/run`` itself, on a fresh
virtual environment. Here a leading ``python -m pip install ... &&`` is stripped from a bash
line (the package is already installed), and a line that runs ``pytest`` is skipped (the
tests would run themselves recursively).

Examples must be quick (seconds); a page whose examples are slower is listed in
``SLOW_PAGES`` and marked ``slow``, but still runs in CI.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
import tomllib
from dataclasses import dataclass
from pathlib import Path

import pytest

from warptissue.study import study_from_dict

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md"] + sorted(
    p for p in (ROOT / "docs").rglob("*.md") if "_build" not in p.relative_to(ROOT).parts
)
LINKED = ("scenes", "scripts")
"""Folders of the repository that the examples see in their working directory."""

SLOW_PAGES = {
    "README.md",
    "docs/tutorial.md",
    "docs/live-fitting.md",
    "docs/trainer-assets.md",
}
"""Pages whose examples run FE simulations (tens of seconds with a cold Warp cache; the live
fitting page also records two tests in real time; the trainer page calibrates an asset)."""

AMBIGUOUS = {"py", "python3", "pycon", "ipython", "sh", "shell", "zsh"}
"""Languages that look runnable but are not run: write ``python`` or ``bash`` (or ``text``)."""
BLOCK_TIMEOUT_S = 600

PIP_PREFIX = re.compile(r"^\s*python3? -m pip install [^&]*&&\s*")
PIP_ONLY = re.compile(r"^\s*python3? -m pip install [^&]*$")
PYTEST = re.compile(r"^\s*(python3? -m )?pytest(\s|$)")


@dataclass(frozen=True)
class Block:
    """A fenced code block: its language, the line of its opening fence and its text."""

    language: str
    line: int
    text: str


def code_blocks(path: Path) -> list[Block]:
    """The fenced blocks of a Markdown page, in order (fences of three or more backticks)."""
    blocks: list[Block] = []
    fence: str | None = None
    language, start, body = "", 0, []
    for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
        stripped = line.strip()
        if fence is None:
            match = re.match(r"^(`{3,}|~{3,})\s*([^`\s]*)", stripped)
            if match:
                fence, language, start, body = match.group(1), match.group(2), number, []
        elif stripped.startswith(fence) and stripped.strip(fence[0]) == "":
            blocks.append(Block(language, start, "\n".join(body) + "\n"))
            fence = None
        else:
            body.append(line)
    assert fence is None, f"{path}:{start}: code fence {fence!r} is never closed"
    return blocks


def shell_script(text: str) -> str:
    """A bash block without the set-up commands that ``.ci/run`` runs itself.

    Continuation lines (ending in a backslash) are joined first, so that a command is one line.
    """
    joined = re.sub(r"\s*\\\n\s*", " ", text)
    lines = []
    for line in joined.splitlines():
        line = PIP_PREFIX.sub("", line)
        if PIP_ONLY.match(line) or PYTEST.match(line):
            continue
        lines.append(line)
    return "\n".join(lines) + "\n"


def _page_id(path: Path) -> str:
    return path.relative_to(ROOT).as_posix()


def _where(page: Path, block: Block) -> str:
    return f"{_page_id(page)}:{block.line} ({block.language} block)"


def _workdir(tmp_path: Path) -> Path:
    for name in LINKED:
        (tmp_path / name).symlink_to(ROOT / name, target_is_directory=True)
    return tmp_path


def _run_bash(page: Path, block: Block, cwd: Path) -> None:
    env = dict(os.environ)
    env["PATH"] = str(Path(sys.executable).parent) + os.pathsep + env.get("PATH", "")
    env["MPLBACKEND"] = "Agg"
    script = shell_script(block.text)
    done = subprocess.run(
        ["bash", "-e", "-c", script],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=BLOCK_TIMEOUT_S,
        check=False,
    )
    if done.returncode != 0:
        pytest.fail(
            f"{_where(page, block)} exited with status {done.returncode}:\n"
            f"$ {shlex.quote(script.strip())}\n--- stdout\n{done.stdout[-4000:]}\n"
            f"--- stderr\n{done.stderr[-4000:]}",
            pytrace=False,
        )


def _run_python(page: Path, block: Block, namespace: dict) -> None:
    try:
        code = compile(block.text, f"{_page_id(page)}:{block.line}", "exec")
        exec(code, namespace)  # noqa: S102 - running the documented example is the test
    except Exception as exc:  # noqa: BLE001 - report any failure with the page and line
        raise AssertionError(f"{_where(page, block)} failed: {exc!r}") from exc


def _check_toml(page: Path, block: Block) -> None:
    try:
        data = tomllib.loads(block.text)
    except tomllib.TOMLDecodeError as exc:
        raise AssertionError(f"{_where(page, block)} is not valid TOML: {exc}") from exc
    if "schema_version" in data:
        study_from_dict(data)


PAGE_PARAMS = [
    pytest.param(
        page,
        id=_page_id(page),
        marks=[pytest.mark.slow] if _page_id(page) in SLOW_PAGES else [],
    )
    for page in PAGES
]


@pytest.mark.parametrize("page", PAGE_PARAMS)
@pytest.mark.slow
def test_page_code_blocks(page: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every runnable block of the page runs, in order, without error."""
    blocks = code_blocks(page)
    ambiguous = [_where(page, b) for b in blocks if b.language in AMBIGUOUS]
    assert not ambiguous, f"write python, bash or text, so that the tests know: {ambiguous}"
    cwd = _workdir(tmp_path)
    monkeypatch.chdir(cwd)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    namespace: dict = {"__name__": "__docs__"}
    for block in blocks:
        if block.language == "python":
            _run_python(page, block, namespace)
        elif block.language == "bash":
            _run_bash(page, block, cwd)
        elif block.language == "toml":
            _check_toml(page, block)


def test_shell_script_strips_the_set_up_commands() -> None:
    """The README's set-up lines lose their pip install; pytest is never run recursively."""
    text = (
        "python -m pip install . && warptissue simulate scenes/a.toml --out runs/a\n"
        "python -m pip install '.[test]' && pytest -q\n"
        "python -m pip install '.[docs]'\n"
        "warptissue mesh block --width-m 0.04 \\\n    --out runs/b.vtu\n"
    )
    assert shell_script(text).splitlines() == [
        "warptissue simulate scenes/a.toml --out runs/a",
        "warptissue mesh block --width-m 0.04 --out runs/b.vtu",
    ]


def test_code_blocks_finds_fences_and_languages(tmp_path: Path) -> None:
    """Blocks come back in order with their language and the line of the opening fence."""
    page = tmp_path / "page.md"
    page.write_text("# T\n\n```python\nx = 1\n```\n\ntext\n\n````bash\necho ```\n````\n")
    assert code_blocks(page) == [Block("python", 3, "x = 1\n"), Block("bash", 9, "echo ```\n")]
    page.write_text("```python\nx = 1\n")
    with pytest.raises(AssertionError, match="never closed"):
        code_blocks(page)


def test_readme_links_point_to_files() -> None:
    """The README's relative links (to the docs pages) name files that exist.

    Sphinx checks the links between the docs pages (``-W`` in ``.ci/run``); the README is
    read on the repository's front page, outside the docs build.
    """
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    targets = re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text)
    relative = [t for t in targets if "://" not in t]
    assert relative, "the README links to the docs pages"
    missing = [t for t in relative if not (ROOT / t).exists()]
    assert not missing, f"README.md links to missing files: {missing}"


def test_readme_command_table_names_every_command() -> None:
    """Each command of ``warptissue --help`` (and each ``fit`` kind) has a row in the README."""
    import argparse

    from warptissue.cli import build_parser

    def subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
        actions = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        return dict(actions[0].choices) if actions else {}

    commands = subcommands(build_parser())
    names = [f"warptissue fit {kind}" for kind in subcommands(commands.pop("fit"))]
    names += [f"warptissue {name}" for name in commands]
    rows = [
        line
        for line in (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
        if line.startswith("| `warptissue ")
    ]
    missing = [n for n in names if not any(row.startswith(f"| `{n}") for row in rows)]
    assert not missing, f"README.md's command table lacks {missing}"


def test_the_fit_exit_status_table_agrees_with_the_commands_and_names_real_tests(capsys) -> None:
    """Issue 36: docs/fitting.md's table of every fit's exit statuses: each status a row
    gives is one its command's ``--help`` states, and each test it names exists."""
    from warptissue.cli import main

    text = (ROOT / "docs" / "fitting.md").read_text(encoding="utf-8")
    section = text.split("## Exit statuses and warnings of every fit", 1)[1]
    rows = [line for line in section.splitlines() if line.startswith("| `fit ")]
    header = next(line for line in section.splitlines() if line.startswith("| fit |"))
    statuses = [cell.strip() for cell in header.strip("|").split("|")][1:-1]
    assert statuses == ["0", "2", "4", "130"]
    commands = set()
    for row in rows:
        cells = [cell.strip() for cell in row.strip("|").split("|")]
        command = re.match(r"`fit ([a-z-]+)`", cells[0]).group(1)
        commands.add(command)
        with pytest.raises(SystemExit):
            main(["fit", command, "--help"])
        stated = " ".join(capsys.readouterr().out.split())
        for status, cell in zip(statuses, cells[1:-1], strict=True):
            if cell:
                assert re.search(rf"(exit status:? |, |; ){status} ", stated, re.IGNORECASE) or (
                    f"exit status {status}" in stated
                ), f"fit {command}: --help does not state exit status {status}"
        for name in re.findall(r"`(test_[a-z_]+\.py)::(test_[a-z0-9_]+)`", cells[-1]):
            module, function = name
            assert f"def {function}(" in (ROOT / "tests" / module).read_text(encoding="utf-8"), (
                f"{module}::{function} named in docs/fitting.md does not exist"
            )
    assert commands == {"uniaxial", "hyperelastic", "relaxation", "punch-modulus", "indentation"}
