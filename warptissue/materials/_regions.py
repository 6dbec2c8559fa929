"""A body of several elastic materials, one per group of its mesh's tet regions:
:class:`MaterialRegions`."""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from warptissue.errors import InputError
from warptissue.materials._base import Material
from warptissue.materials._viscoelastic import Viscoelastic

REGION_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_-]*$")
"""A region's name: a letter, then letters, digits, ``_`` or ``-`` (no ``.``: it qualifies a
parameter name, ``tumour.C10_Pa``)."""


@dataclass(frozen=True)
class MaterialRegions(Material):
    """A body of several elastic materials, one per named group of its mesh's tet regions.

    Every tet whose region (:attr:`warptissue.mesh.TetMesh.tet_regions`) a named region lists
    has that region's material; every other tet has ``default``. In the FE each tet reads its
    own material (:class:`warptissue.fem.Assembler`); in a fit each region's parameters are
    parameters of their own.

    Args:
        default: The material of every tet that no named region holds (the organ's bulk).
        materials: Each named region's material, ``{name: material}``; a name is a letter
            followed by letters, digits, ``_`` or ``-``.
        tet_regions: The mesh's tet region ids each named region holds, ``{name: (id, ...)}``
            (the ``tet_region`` cell data of a VTU file, Gmsh's physical volume tags, a USD
            TetMesh's ``materialRegion`` subsets). Two regions hold no id in common.

    Notes:
        Parameter names: the default's as they are (``C10_Pa``), a named region's qualified
        by its name (``tumour.C10_Pa``), in that order (:attr:`parameter_names`). The
        body's :attr:`initial_shear_modulus_Pa` and :attr:`bulk_modulus` are the default's:
        a rigid contact's penalty scales with them, so only the default's parameters move it
        (:meth:`moduli_derivative` is 0 for a region's). The materials are elastic: a
        Prony series of one region only is not modelled (a viscoelastic one is refused).

    Raises:
        InputError: A viscoelastic material, a bad name, no named region, a region without
            ids, or an id held by two regions (named by the region).
    """

    default: Material
    materials: Mapping[str, Material]
    tet_regions: Mapping[str, tuple[int, ...]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.default, Material) or isinstance(self.default, MaterialRegions):
            raise InputError("default must be one warptissue.materials material", key="model")
        if not self.materials:
            raise InputError("a body of several materials names at least one region", key="regions")
        if set(self.materials) != set(self.tet_regions):
            raise InputError(
                "every named region needs its material and its tet regions",
                key="regions",
                value=sorted(set(self.materials) ^ set(self.tet_regions)),
            )
        held: dict[int, str] = {}
        regions: dict[str, tuple[int, ...]] = {}
        for name, material in self.materials.items():
            key = f"regions.{name}"
            if not isinstance(name, str) or not REGION_NAME.match(name):
                raise InputError(
                    "a region's name is a letter, then letters, digits, '_' or '-'",
                    key=key,
                    value=name,
                )
            if not isinstance(material, Material) or isinstance(material, MaterialRegions):
                raise InputError("must be one warptissue.materials material", key=key)
            ids = _region_ids(self.tet_regions[name], f"{key}.tet_regions")
            for each in ids:
                if each in held:
                    raise InputError(
                        f"tet region {each} is held by region {held[each]!r} already",
                        key=f"{key}.tet_regions",
                        value=list(ids),
                    )
                held[each] = name
            regions[name] = ids
        for name, material in (("default", self.default), *self.materials.items()):
            if isinstance(material, Viscoelastic):
                raise InputError(
                    "the materials of a body of several regions are elastic: a Prony series "
                    "per region is not modelled",
                    key="model" if name == "default" else f"regions.{name}",
                )
        object.__setattr__(self, "materials", dict(self.materials))
        object.__setattr__(self, "tet_regions", regions)

    @property
    def model_name(self) -> str:  # type: ignore[override]
        """The default material's model."""
        return self.default.model_name

    @property
    def parts(self) -> tuple[tuple[str, Material], ...]:
        """``(prefix, material)`` of the default (prefix ``""``) and of each named region
        (prefix ``"name."``), in :attr:`parameter_names` order."""
        return (("", self.default),) + tuple(
            (f"{name}.", material) for name, material in self.materials.items()
        )

    def part_of(self, name: str) -> tuple[int, str]:
        """Which part a (qualified) parameter name belongs to: ``(index in`` :attr:`parts`
        ``, the name within that part's material)``."""
        prefix, dot, local = name.partition(".")
        if dot and prefix in self.materials:
            return 1 + list(self.materials).index(prefix), local
        return 0, name

    @property
    def initial_shear_modulus_Pa(self) -> float:
        """The default material's initial shear modulus, Pa."""
        return self.default.initial_shear_modulus_Pa

    @property
    def bulk_modulus(self) -> float:
        """The default material's bulk modulus, Pa."""
        return self.default.bulk_modulus

    def small_strain_equivalent(self) -> tuple[float, float]:
        """The default material's Young's modulus (Pa) and Poisson's ratio."""
        return self.default.small_strain_equivalent()

    def _flat_parameters(self) -> dict[str, float]:
        return {
            prefix + key: value
            for prefix, material in self.parts
            for key, value in material._flat_parameters().items()
        }

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """The default's fit parameters, then each named region's, qualified (``tumour.C10_Pa``)."""
        return tuple(
            prefix + name for prefix, material in self.parts for name in material.parameter_names
        )

    @property
    def parameter_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Each part's box, in :attr:`parameter_names` order."""
        boxes = [material.parameter_bounds for _, material in self.parts]
        return np.concatenate([low for low, _ in boxes]), np.concatenate([up for _, up in boxes])

    def with_parameters(self, values: np.ndarray) -> MaterialRegions:
        """A copy with new fit parameters (:attr:`parameter_names` order); validated."""
        values = np.asarray(values, dtype=np.float64).ravel()
        names = self.parameter_names
        if values.shape != (len(names),):
            raise InputError(f"expected {len(names)} parameters {names}", value=values.tolist())
        parts, start = [], 0
        for _, material in self.parts:
            count = len(material.parameter_names)
            parts.append(material.with_parameters(values[start : start + count]))
            start += count
        return self.with_parts(parts)

    def with_parts(self, materials: Sequence[Material]) -> MaterialRegions:
        """A copy with new materials, one per part (:attr:`parts` order)."""
        if len(materials) != len(self.parts):
            raise InputError(f"one material per part: {len(self.parts)} expected")
        return MaterialRegions(
            materials[0], dict(zip(self.materials, materials[1:], strict=True)), self.tet_regions
        )

    def with_bulk_modulus(self, bulk_modulus_Pa: float | None) -> MaterialRegions:
        """A copy whose every part has this bulk modulus, Pa."""
        return self.with_parts(
            [material.with_bulk_modulus(bulk_modulus_Pa) for _, material in self.parts]
        )

    def to_dict(self) -> dict[str, Any]:
        """The default's table with a ``regions`` table: ``{name: {"tet_regions": [...],
        "model": ..., parameters...}}``, as read by ``material_from_dict``."""
        return {
            **self.default.to_dict(),
            "regions": {
                name: {"tet_regions": list(self.tet_regions[name]), **material.to_dict()}
                for name, material in self.materials.items()
            },
        }

    def device_params(self) -> Any:
        """Refused: a body of several materials has one struct per part, which the FE's
        assembler builds (:class:`warptissue.fem.Assembler`)."""
        raise InputError(
            "a body of several material regions has one set of device parameters per region; "
            "give it to warptissue.fem.Assembler with the mesh whose tet regions it names",
            key="regions",
        )

    def device_params_derivative(self, name: str) -> tuple[Any, int]:
        """The derivative struct of the part that ``name`` belongs to (its material's
        :meth:`~warptissue.materials.Material.device_params_derivative` of the name within
        it) and the Ogden exponent's term (-1 for any other parameter)."""
        index, local = self.part_of(name)
        return self.parts[index][1].device_params_derivative(local)

    def moduli_derivative(self, name: str) -> tuple[float, float]:
        """``(d mu0 / d name, d K / d name)`` of the body's (the default's) moduli: a named
        region's parameter gives (0, 0)."""
        index, local = self.part_of(name)
        if index:
            return 0.0, 0.0
        return self.default.moduli_derivative(local)

    def shear_modulus_weight(self, name: str) -> float:
        """d mu0 / d ``name`` of the part ``name`` belongs to (its own shear modulus)."""
        index, local = self.part_of(name)
        return self.parts[index][1].shear_modulus_weight(local)


def _region_ids(values: Any, key: str) -> tuple[int, ...]:
    try:
        ids = tuple(values)
    except TypeError:
        raise InputError("must be a list of tet region ids", key=key, value=values) from None
    if not ids:
        raise InputError("must list at least one tet region id", key=key, value=list(ids))
    for each in ids:
        if isinstance(each, bool) or not isinstance(each, (int, np.integer)) or each < 0:
            raise InputError("tet region ids are integers >= 0", key=key, value=list(ids))
    if len(set(ids)) != len(ids):
        raise InputError("lists a tet region twice", key=key, value=list(ids))
    return tuple(int(each) for each in ids)
