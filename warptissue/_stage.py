"""Opening USD stages, for every floor of the package: ``warptissue``'s schema plugin is
registered first.

USD builds its schema registry once per process, on first use: a stage opened before the
``TissueMaterialAPI`` plugin is registered leaves the schema unknown for the rest of the
process. :mod:`warptissue.usd` registers it on import; a reader below it (a study whose
specimen is a USD TetMesh asset, :mod:`warptissue.mesh`) opens its stages here so that the
order of imports does not matter.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from warptissue.errors import InputError

PLUGIN_DIRECTORY = Path(__file__).resolve().parent / "usd" / "plugin"
"""Folder holding the schema plugin's ``plugInfo.json`` and ``generatedSchema.usda``."""

_registered = False


def register_schema_plugin() -> None:
    """Register the ``TissueMaterialAPI`` plugin with USD (once per process).

    Registration has to happen before USD's schema registry is first used, which is why
    :mod:`warptissue.usd` calls this on import and :func:`open_stage` before it opens a
    stage. Later calls do nothing.
    """
    global _registered
    if _registered:
        return
    from pxr import Plug

    Plug.Registry().RegisterPlugins([PLUGIN_DIRECTORY.as_posix()])
    _registered = True


def open_stage(path: str | Path) -> Any:
    """Open a USD stage with an error naming the file when it cannot be read."""
    from pxr import Tf, Usd

    register_schema_plugin()
    path = Path(path)
    if not path.is_file():
        raise InputError("no such USD file", path=path)
    try:
        stage = Usd.Stage.Open(str(path))
    except Tf.ErrorException as exc:
        raise InputError(f"cannot open USD stage: {str(exc).strip()}", path=path) from None
    if stage is None:
        raise InputError("cannot open USD stage", path=path)
    return stage
