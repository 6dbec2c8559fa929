"""Sphinx extension: the CLI reference, generated from ``warptissue.cli.build_parser()``.

The directive ``warptissue-cli`` walks the argument parser that the ``warptissue`` command
itself uses and renders, for every command and ``fit`` subcommand, a section with its one-line
summary (the parser's ``help``) and its full ``--help`` text as a literal block. The
``warptissue-exit-statuses`` directive renders the exit statuses from the error classes of
:mod:`warptissue.errors` and ``warptissue.cli.EXIT_STATUSES``. Nothing on the CLI page is
written by hand, so it cannot drift from the code; pages that use the directives are read
again on every build (the parsers are code, not a source file Sphinx could watch).
"""

from __future__ import annotations

import argparse
import os
from collections.abc import Iterator

from docutils import nodes
from docutils.parsers.rst import Directive
from sphinx.application import Sphinx

HELP_WIDTH = 92
"""Terminal width the help texts are formatted for."""


def _subcommands(
    parser: argparse.ArgumentParser,
) -> Iterator[tuple[str, argparse.ArgumentParser, str]]:
    """Yield ``(name, parser, one-line help)`` for each subcommand of ``parser``, in order."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            helps = {choice.dest: choice.help for choice in action._choices_actions}
            for name, sub in action.choices.items():
                yield name, sub, helps.get(name) or ""


def _walk(
    parser: argparse.ArgumentParser, prefix: str
) -> Iterator[tuple[str, argparse.ArgumentParser, str]]:
    """Yield every command path below ``parser`` (depth first, in ``--help`` order)."""
    for name, sub, summary in _subcommands(parser):
        path = f"{prefix} {name}"
        yield path, sub, summary
        yield from _walk(sub, path)


def _help_text(parser: argparse.ArgumentParser) -> str:
    """The parser's ``--help`` output at a fixed width, independent of the terminal."""
    previous = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = str(HELP_WIDTH)
    try:
        return parser.format_help().rstrip()
    finally:
        if previous is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = previous


def _note_generated(directive: Directive) -> None:
    """Remember the page, so that every build reads it again."""
    env = directive.state.document.settings.env
    if not hasattr(env, "warptissue_generated_docs"):
        env.warptissue_generated_docs = set()
    env.warptissue_generated_docs.add(env.docname)


def _always_outdated(app: Sphinx, env, added, changed, removed) -> list[str]:  # noqa: ARG001
    """``env-get-outdated``: the pages with generated content."""
    return sorted(getattr(env, "warptissue_generated_docs", set()) - set(removed))


class CliDirective(Directive):
    """``warptissue-cli``: one section per command, with its summary and ``--help``."""

    has_content = False

    def run(self) -> list[nodes.Node]:
        from warptissue.cli import build_parser

        _note_generated(self)
        parser = build_parser()
        parser.prog = "warptissue"
        document = self.state.document
        result: list[nodes.Node] = []
        top = nodes.literal_block(_help_text(parser), _help_text(parser))
        top["language"] = "text"
        result.append(top)
        for path, sub, summary in _walk(parser, "warptissue"):
            section = nodes.section()
            section["ids"].append(nodes.make_id(path))
            section["names"].append(nodes.fully_normalize_name(path))
            section += nodes.title(path, "", nodes.literal(path, path))
            if summary:
                text = summary[0].upper() + summary[1:]
                section += nodes.paragraph(text, text if text.endswith(".") else text + ".")
            help_text = _help_text(sub)
            block = nodes.literal_block(help_text, help_text)
            block["language"] = "text"
            section += block
            document.note_implicit_target(section, section)
            result.append(section)
        return result


class ExitStatusDirective(Directive):
    """``warptissue-exit-statuses``: a table of the exit statuses of every command."""

    has_content = False

    def run(self) -> list[nodes.Node]:
        from warptissue import errors
        from warptissue.cli import EXIT_STATUSES

        _note_generated(self)
        rows: dict[int, list[str]] = {k: [v] for k, v in EXIT_STATUSES.items()}
        for name in errors.__all__:
            cls = getattr(errors, name)
            if isinstance(cls, type) and issubclass(cls, errors.WarpTissueError):
                summary = (cls.__doc__ or name).strip().splitlines()[0].rstrip(".")
                rows.setdefault(cls.exit_code, []).append(f"{name}: {summary}")
        table = nodes.table()
        group = nodes.tgroup(cols=2)
        table += group
        group += nodes.colspec(colwidth=10)
        group += nodes.colspec(colwidth=90)
        head = nodes.thead()
        group += head
        body = nodes.tbody()
        group += body
        head += self._row("status", "meaning")
        for code in sorted(rows):
            body += self._row(str(code), "; ".join(rows[code]))
        return [table]

    @staticmethod
    def _row(*cells: str) -> nodes.row:
        row = nodes.row()
        for cell in cells:
            entry = nodes.entry()
            entry += nodes.paragraph(cell, cell)
            row += entry
        return row


def setup(app: Sphinx) -> dict[str, object]:
    """Register the directives."""
    app.add_directive("warptissue-cli", CliDirective)
    app.add_directive("warptissue-exit-statuses", ExitStatusDirective)
    app.connect("env-get-outdated", _always_outdated)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
