"""Public names that moved to another module, kept at their old import path for one release.

:data:`MOVED` maps each old path to the new one. The old module answers the old name through
its module ``__getattr__`` (PEP 562), which calls :func:`moved_attribute`: it imports the new
module on first use, warns with a :class:`DeprecationWarning` that names the new path, and
returns the object. Nothing is imported until an old path is used, so an old path that lies on
a higher floor than the old module (``warptissue.study`` -> ``warptissue.fit.start``) adds no
import to the import graph; ``scripts/tools/import_graph.py`` reads this table and lists the
aliases apart. CHANGELOG.md lists them under "Deprecated"; they go in :data:`REMOVED_IN`.

Example:
    >>> import warnings
    >>> with warnings.catch_warnings(record=True) as caught:
    ...     warnings.simplefilter("always")
    ...     from warptissue.study import start_values_from_record
    >>> "warptissue.fit.start.start_values_from_record" in str(caught[0].message)
    True
"""

from __future__ import annotations

import importlib
import warnings
from collections.abc import Callable
from typing import Any

__all__ = ["MOVED", "REMOVED_IN", "moved_attribute", "moved_names"]

REMOVED_IN = "0.2.0"
"""The release without the old paths."""

MOVED: dict[str, str] = {
    # fit.start took the inverse FE fit's start values from the study reader.
    "warptissue.study.start_values_from_record": "warptissue.fit.start.start_values_from_record",
    "warptissue.study.record_youngs_modulus_Pa": "warptissue.fit.start.record_youngs_modulus_Pa",
    "warptissue.study.START_DEPTH_SHARE": "warptissue.fit.start.START_DEPTH_SHARE",
    # The least-squares engine moved from fit to lsq, below every fit.
    "warptissue.fit.least_squares": "warptissue.lsq.least_squares",
    "warptissue.fit.fit_curve": "warptissue.lsq.fit_curve",
    "warptissue.fit.FitResult": "warptissue.lsq.FitResult",
    "warptissue.fit.IterationRecord": "warptissue.lsq.IterationRecord",
    "warptissue.fit.RejectStep": "warptissue.lsq.RejectStep",
    "warptissue.fit.STATUS_MESSAGES": "warptissue.lsq.STATUS_MESSAGES",
    "warptissue.fit.metrics": "warptissue.lsq.metrics",
    # The device gathers and scatters moved from the assembler to fem.gather.
    "warptissue.fem.assembly.gather_bsr_blocks": "warptissue.fem.gather.gather_bsr_blocks",
    "warptissue.fem.assembly.gather_vectors": "warptissue.fem.gather.gather_vectors",
    "warptissue.fem.assembly.scatter_vectors": "warptissue.fem.gather.scatter_vectors",
    # A run layered over an organ's asset moved from the writer to usd.over.
    "warptissue.usd.writer.write_results_over_asset": (
        "warptissue.usd.over.write_results_over_asset"
    ),
}
"""Old path (``module.name``) -> new path (``module.name``) of every moved public name."""


def moved_attribute(module: str, name: str) -> Any:
    """The object an old path names, with a :class:`DeprecationWarning` naming its new path.

    A module whose names moved sets ``__getattr__ = moved_names(__name__)``.

    Args:
        module: The old module's name (``__name__``).
        name: The attribute asked for.

    Returns:
        The object at the new path.

    Raises:
        AttributeError: ``module.name`` is not a moved name (as for any missing attribute).
    """
    new = MOVED.get(f"{module}.{name}")
    if new is None:
        raise AttributeError(f"module {module!r} has no attribute {name!r}")
    new_module, _, new_name = new.rpartition(".")
    warnings.warn(
        f"{module}.{name} has moved to {new}: import it from {new_module} "
        f"(the old path is removed in {REMOVED_IN})",
        DeprecationWarning,
        stacklevel=3,
    )
    return getattr(importlib.import_module(new_module), new_name)


def moved_names(module: str) -> Callable[[str], Any]:
    """The module ``__getattr__`` (PEP 562) of a module whose names moved: each old name from
    :func:`moved_attribute`, any other an AttributeError.

    Args:
        module: The old module's name (``__name__``).
    """

    def __getattr__(name: str) -> Any:
        return moved_attribute(module, name)

    return __getattr__
