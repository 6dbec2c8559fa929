"""``warptissue fit indentation STUDY.toml``: inverse-FE fit of a study's material to its records."""

from __future__ import annotations

import argparse

__all__ = ["register_fit"]


def register_fit(subparsers: argparse._SubParsersAction) -> None:
    """Add ``warptissue fit indentation`` (being written)."""
