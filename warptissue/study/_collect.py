"""The study files of a batch: files, folders and glob patterns, and a result folder for
each (used by :func:`warptissue.batch.run_batch`)."""

from __future__ import annotations

import glob
import hashlib
import os
from collections.abc import Sequence
from pathlib import Path

from warptissue.errors import InputError

_GLOB_CHARACTERS = frozenset("*?[")


def collect_studies(sources: Sequence[str | Path]) -> list[Path]:
    """The study files named by files, folders and glob patterns.

    A file is taken as it is; a folder gives its ``*.toml`` files (not those of its
    subfolders), sorted by name; a pattern with ``*``, ``?`` or ``[`` gives the files it
    matches (``**`` reaches into subfolders), sorted. A file named twice is run once.

    Args:
        sources: Study files, folders and patterns.

    Returns:
        The study files, in the order of ``sources``.

    Raises:
        InputError: Nothing given, a path that does not exist, or a folder or pattern that
            holds no study file.
    """
    if not sources:
        raise InputError("no study files given")
    found: list[Path] = []
    for source in sources:
        text = str(source)
        path = Path(text)
        if path.is_dir():
            matches = sorted(p for p in path.glob("*.toml") if p.is_file())
            if not matches:
                raise InputError("this folder holds no study files (*.toml)", path=path)
        elif path.exists():
            matches = [path]
        elif _GLOB_CHARACTERS & set(text):
            matches = sorted(Path(p) for p in glob.glob(text, recursive=True) if Path(p).is_file())
            if not matches:
                raise InputError(f"no study file matches the pattern {text!r}")
        else:
            raise InputError("study file not found", path=path)
        found.extend(matches)
    unique: dict[str, Path] = {}
    for path in found:
        unique.setdefault(os.path.realpath(path), path)
    return list(unique.values())


def folder_names(paths: Sequence[str | Path]) -> list[str]:
    """The result folder of each study: its file's stem, made unique.

    Studies whose stems are unique keep them (``liver.toml`` -> ``liver``). Where several
    files share a stem (``a/liver.toml``, ``b/liver.toml``), each gets the stem and the first
    8 hexadecimal digits of the SHA-1 of its resolved path (``liver-3f2a9c01``): the same
    file gets the same folder whatever the other studies of the batch and their order.

    Args:
        paths: The study files.

    Returns:
        One folder name per path, in order.
    """
    stems = [Path(p).stem for p in paths]
    counts: dict[str, int] = {}
    for stem in stems:
        counts[stem] = counts.get(stem, 0) + 1
    names = []
    for path, stem in zip(paths, stems, strict=True):
        if counts[stem] == 1:
            names.append(stem)
        else:
            digest = hashlib.sha1(os.path.realpath(path).encode("utf-8")).hexdigest()[:8]
            names.append(f"{stem}-{digest}")
    return names
