"""Writing a study back as TOML (:func:`save_study`)."""

from __future__ import annotations

import os
from pathlib import Path

import tomli_w

from warptissue.io import atomic_path
from warptissue.study._schema import Study


def save_study(study: Study, path: str | Path) -> Path:
    """Write a study as TOML (atomically), its data files relative to the new file's folder.

    ``load_study(save_study(study, path))`` gives the study back, and ``warptissue simulate``
    runs the file as it is (a fitted study: ``dataclasses.replace(study, material=fitted)``).

    Args:
        study: The study.
        path: The ``.toml`` file to write.

    Returns:
        The path written.
    """

    target = Path(path)
    text = tomli_w.dumps(study.to_dict(relative_to=os.path.abspath(target.parent)))
    with atomic_path(target) as temporary:
        temporary.write_text(text, encoding="utf-8")
    return target
