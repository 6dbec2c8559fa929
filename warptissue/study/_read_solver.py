"""Reading a study's ``[material]``, ``[boundary]`` and ``[solver]`` tables."""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from typing import Any

from warptissue.errors import InputError
from warptissue.fem.assembly import FORMULATIONS
from warptissue.fem.contact import DEFAULT_PENALTY_FACTOR
from warptissue.fem.newton import NewtonOptions
from warptissue.fem.support import Foundation
from warptissue.fem.surface_contact import CONTACT_INTEGRATIONS
from warptissue.materials import material_from_dict
from warptissue.study._organ import (
    OPPOSITE,
    support_nodes,
)
from warptissue.study._schema import (
    BASE_KINDS,
    DEVICE_PATTERN,
    Boundary,
    Solver,
)
from warptissue.study._toml import Table


def read_material(table: Table) -> Any:
    values = table.present(list(table.data))
    return table.build(material_from_dict, values)


def _support(table: Table) -> str | dict[str, Any]:
    """``[boundary] support``: a node set's name, ``"opposite"``, ``{ box = [[xmin, ymin,
    zmin], [xmax, ymax, zmax]] }`` (m, each min below its max) or ``{ half_space = [[x, y, z],
    [nx, ny, nz]] }`` (a point of the plane, m, and the normal pointing into the held side)."""
    support = table.raw("support", default=OPPOSITE)
    if isinstance(support, str):
        return support
    shape = next(iter(support)) if isinstance(support, Mapping) and len(support) == 1 else None
    pair = support.get(shape) if shape in ("box", "half_space") else None
    vectors_ok = (
        isinstance(pair, list)
        and len(pair) == 2
        and all(isinstance(corner, list) and len(corner) == 3 for corner in pair)
        and all(
            isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
            for corner in pair
            for v in corner
        )
    )
    if vectors_ok and shape == "box":
        vectors_ok = all(a < b for a, b in zip(*pair, strict=True))
    if vectors_ok and shape == "half_space":
        vectors_ok = any(v != 0 for v in pair[1])
    if not vectors_ok:
        raise table.error(
            "support",
            'must be a node set\'s name, "opposite", { box = [[xmin, ymin, zmin], '
            "[xmax, ymax, zmax]] } (m, each min below its max) or { half_space = [[x, y, z], "
            "[nx, ny, nz]] } (a point of the plane, m, and a nonzero normal into the held side)",
            support,
        )
    return {shape: [[float(v) for v in corner] for corner in pair]}


def read_boundary(table: Table, organ: tuple | None = None) -> Boundary:
    """The ``[boundary]`` table; ``organ``: a mesh specimen's (mesh, site, direction), whose
    ``support`` is checked against it."""
    base = table.string("base", default="fixed", choices=BASE_KINDS)
    foundation = None
    if base == "foundation":
        if not table.has("foundation_Pa_per_m"):
            raise table.error(
                "foundation_Pa_per_m",
                'is needed with base = "foundation": the bed\'s stiffness per unit area, Pa/m',
            )
        normal = table.number("foundation_Pa_per_m")
        tangential = table.number("foundation_tangential_Pa_per_m", default=normal)
        foundation = Foundation(normal, tangential)
    else:
        for key in ("foundation_Pa_per_m", "foundation_tangential_Pa_per_m"):
            if table.has(key):
                raise table.error(
                    key, f'needs base = "foundation" (base is {base!r})', table.raw(key)
                )
    support = None
    if organ is not None:
        support = _support(table)
        mesh, site, along = organ
        try:
            support_nodes(mesh, support, site_m=site, direction=along)
        except InputError as exc:
            raise table.error("support", exc.message, exc.value) from exc
    table.finish()
    return Boundary(base=base, support=support, foundation=foundation)


LOCKING_BULK_TO_SHEAR = 10.0
"""K / mu (Poisson's ratio about 0.45) from which a TET4 study without a formulation is told
that the displacement formulation it gets locks."""


def read_solver(table: Table, element: str, material: Any) -> Solver:
    # The solver's own modules: importing them does not start Warp (test_study checks).

    device = table.string("device", default="auto")
    if not DEVICE_PATTERN.match(device):
        raise table.error("device", "must be 'auto', 'cpu', 'cuda' or 'cuda:N'", device)
    if table.has("formulation") or element == "TET10":
        formulation = table.string("formulation", default="mixed", choices=FORMULATIONS)
    else:
        # A TET4 study that names no formulation (version-1 files ran so): the one TET4
        # takes, said out loud where it locks.
        formulation = "displacement"
        ratio = material.bulk_modulus / material.initial_shear_modulus_Pa
        if ratio >= LOCKING_BULK_TO_SHEAR:
            where = table.source.path if table.source.path is not None else "the study"
            warnings.warn(
                f"{where}: specimen.element = 'TET4' and no solver.formulation: the "
                f"'displacement' formulation is used, which locks at K/mu = {ratio:.4g} "
                "(forces too high); element = \"TET10\" takes the locking-free 'mixed' one",
                UserWarning,
                stacklevel=2,
            )
    penalty_factor = table.number("penalty_factor", default=DEFAULT_PENALTY_FACTOR)
    contact_integration = table.string(
        "contact_integration", default="nodes", choices=CONTACT_INTEGRATIONS
    )
    options = table.build(
        lambda values: NewtonOptions(**values), table.present(NewtonOptions.keys())
    )
    table.finish()
    return Solver(
        device=device,
        formulation=formulation,
        options=options,
        penalty_factor=penalty_factor,
        contact_integration=contact_integration,
    )
