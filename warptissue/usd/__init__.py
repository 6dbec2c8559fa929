"""USD reading and writing for warptissue, in one place.

Importing this package registers the ``TissueMaterialAPI`` schema plugin with USD. USD builds
its schema registry once, on first use, so import :mod:`warptissue.usd` before opening any
stage in a process that should see the schema.
"""

from warptissue.usd.schema import register_schema_plugin

register_schema_plugin()

from warptissue.usd.over import write_results_over_asset  # noqa: E402
from warptissue.usd.reader import (  # noqa: E402
    read_material_field_usd,
    read_material_usd,
    read_tetmesh_usd,
)
from warptissue.usd.validation import validate_stage  # noqa: E402
from warptissue.usd.writer import (  # noqa: E402
    UsdScenePaths,
    write_material_usd,
    write_simulation_usd,
)

__all__ = [
    "UsdScenePaths",
    "read_material_field_usd",
    "read_material_usd",
    "read_tetmesh_usd",
    "register_schema_plugin",
    "validate_stage",
    "write_material_usd",
    "write_results_over_asset",
    "write_simulation_usd",
]
