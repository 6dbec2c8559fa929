"""Each tet's material: one per problem, or one per region of a body of several materials
(:class:`warptissue.materials.MaterialRegions`).

The element kernels read tet e's parameters from ``material_params[element_material[e]]``.
Entry k of that table is problem k's material (its default one where its body has regions),
so that the kernels that read a problem's material by its index (the viscous history) read
the right one; a problem's named regions take entries after the K problems'.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from warptissue.errors import InputError
from warptissue.materials import Material, MaterialRegions

__all__ = ["MaterialSlots", "material_slots", "zero_derivative"]


@dataclass(frozen=True)
class MaterialSlots:
    """The materials of the element kernels' table and each tet's entry.

    Attributes:
        materials: The table's materials, (S,): problem k's (or its default) at k, then the
            named regions'.
        problems: The problem of each entry, (S,) int.
        prefixes: The parameter-name prefix of each entry (``""`` for a problem's own
            material or default, ``"tumour."`` for a named region's), (S,).
        element_material: Each tet's entry, (tet_count,) int32.
    """

    materials: tuple[Material, ...]
    problems: np.ndarray
    prefixes: tuple[str, ...]
    element_material: np.ndarray

    def owner(self, slot: int, name: str) -> str | None:
        """The name within entry ``slot``'s material of the body's parameter ``name``
        (qualified where the body has regions), or None where that entry does not hold it."""
        prefix = self.prefixes[slot]
        if prefix:
            return name[len(prefix) :] if name.startswith(prefix) else None
        if "." in name:
            head = name.partition(".")[0] + "."
            if head in self.prefixes:
                return None
        return name


def material_slots(
    materials: Sequence[Material], element_problem: np.ndarray, tet_regions: np.ndarray
) -> MaterialSlots:
    """The element kernels' material table of K problems' materials.

    Args:
        materials: One material per problem, (K,); a :class:`MaterialRegions` gives its
            named regions' tets their own materials.
        element_problem: The problem of each tet, (tet_count,).
        tet_regions: The region of each tet (:attr:`warptissue.mesh.TetMesh.tet_regions`),
            (tet_count,).

    Raises:
        InputError: A named region holds a tet region that the problem's mesh does not have
            (the message lists the mesh's regions).
    """
    element_problem = np.asarray(element_problem, dtype=np.int64)
    tet_regions = np.asarray(tet_regions, dtype=np.int64)
    table: list[Material] = []
    problems: list[int] = []
    prefixes: list[str] = []
    for k, material in enumerate(materials):
        table.append(material.default if isinstance(material, MaterialRegions) else material)
        problems.append(k)
        prefixes.append("")
    element_material = element_problem.astype(np.int32).copy()
    for k, material in enumerate(materials):
        if not isinstance(material, MaterialRegions):
            continue
        mine = element_problem == k
        present = np.unique(tet_regions[mine])
        for name, part in material.materials.items():
            ids = np.asarray(material.tet_regions[name], dtype=np.int64)
            missing = np.setdiff1d(ids, present)
            if missing.size:
                raise InputError(
                    f"region {name!r} holds tet region {int(missing[0])}, which the mesh does "
                    f"not have (its tet regions: {present.tolist()[:20]})",
                    key=f"material.regions.{name}.tet_regions",
                    value=list(material.tet_regions[name]),
                )
            element_material[mine & np.isin(tet_regions, ids)] = len(table)
            table.append(part)
            problems.append(k)
            prefixes.append(f"{name}.")
    return MaterialSlots(
        materials=tuple(table),
        problems=np.asarray(problems, dtype=np.int64),
        prefixes=tuple(prefixes),
        element_material=element_material,
    )


def zero_derivative(material: Material) -> Any:
    """A ``MaterialParams`` of ``material``'s model whose moduli are all zero: the derivative
    of an entry of the table by a parameter that is not its material's (its tets add
    nothing to ``dR/d theta``)."""
    params = material.device_params()
    params.c_i0 = type(params.c_i0)()
    params.c01 = 0.0
    params.ogden_mu = type(params.ogden_mu)()
    params.bulk_modulus = 0.0
    params.shear_modulus = 0.0
    params.lame_lambda = 0.0
    return params
