"""A material from its flat table (``{"model": name, parameters...}``), as study files and
USD layers store it: :func:`material_from_dict`."""

from __future__ import annotations

import difflib
from collections.abc import Mapping
from dataclasses import fields
from typing import Any

from warptissue.errors import InputError
from warptissue.materials._base import Material, check_finite, check_positive, check_terms
from warptissue.materials._compressible import (
    CompressibleNeoHookean,
    LinearElastic,
    StableNeoHookean,
)
from warptissue.materials._ogden import Ogden
from warptissue.materials._polynomial import MooneyRivlin, NeoHookean, ReducedPolynomial
from warptissue.materials._regions import MaterialRegions
from warptissue.materials._rules import PRONY_KEY
from warptissue.materials._viscoelastic import Viscoelastic

_MODELS: dict[str, type[Material]] = {
    cls.model_name: cls
    for cls in (
        NeoHookean,
        MooneyRivlin,
        ReducedPolynomial,
        Ogden,
        CompressibleNeoHookean,
        LinearElastic,
        StableNeoHookean,
    )
}


def material_from_dict(data: Mapping[str, Any]) -> Material:
    """Build a material from ``{"model": name, parameters...}`` (the ``to_dict`` layout).

    A ``regions`` table makes a body of several materials (:class:`MaterialRegions`):
    ``{"regions": {name: {"tet_regions": [id, ...], parameters...}}}``; the rest of the table
    is the default material, and a region's table takes the default's keys it does not give
    (all of them, with its own ``model``, where it names another model).

    ``model`` is one of ``neo_hookean``, ``mooney_rivlin``, ``reduced_polynomial``, ``yeoh``,
    ``ogden``, ``compressible_neo_hookean``, ``linear_elastic``, ``stable_neo_hookean``.
    Parameters are the flat keys of ``to_dict`` (``C10_Pa``, ``C20_Pa``, ``mu1_Pa``,
    ``alpha1``, ``bulk_modulus_Pa``, ...); ``D1_per_Pa`` may replace ``bulk_modulus_Pa``;
    polynomial and Ogden coefficients may also be given as lists ``C_Pa``, ``mu_Pa`` and ``alpha``.

    Raises:
        InputError: Unknown model, missing or unknown key, or a bad value (named).
    """
    if not isinstance(data, Mapping):
        raise InputError("material must be a table of parameters", value=data)
    values = dict(data)
    if "regions" in values:
        return _material_regions(values)
    prony = _pop_prony(values)
    name = values.pop("model", None)
    if name == "yeoh":
        name = "reduced_polynomial"
        order = 3
    else:
        order = None
    if name not in _MODELS:
        names = sorted([*_MODELS, "yeoh"])
        close = difflib.get_close_matches(str(name).lower(), names, n=1, cutoff=0.6)
        hint = f"did you mean {close[0]!r}? " if close else ""
        raise InputError(
            f"unknown material model ({hint}choose from {', '.join(names)})",
            key="model",
            value=name,
        )
    cls = _MODELS[name]
    if "D1_per_Pa" in values:
        if "bulk_modulus_Pa" in values:
            raise InputError("give bulk_modulus_Pa or D1_per_Pa, not both", key="D1_per_Pa")
        d1 = check_positive("D1_per_Pa", values.pop("D1_per_Pa"))
        values["bulk_modulus_Pa"] = 2.0 / d1
    for list_key, prefix, suffix in (
        ("C_Pa", "C", "0_Pa"),
        ("mu_Pa", "mu", "_Pa"),
        ("alpha", "alpha", ""),
    ):
        if list_key in values:
            items = check_terms(list_key, values.pop(list_key))
            for i, v in enumerate(items):
                values[f"{prefix}{i + 1}{suffix}"] = v
    if cls is ReducedPolynomial:
        present = sorted(
            int(k[1])
            for k in values
            if k.startswith("C") and k.endswith("0_Pa") and len(k) == 6 and k[1].isdigit()
        )
        count = order if order is not None else (max(present) if present else 0)
        expected = [f"C{i + 1}0_Pa" for i in range(count)] + ["bulk_modulus_Pa"]
    elif cls is Ogden:
        count = sum(1 for k in values if k.startswith("mu") and k.endswith("_Pa"))
        expected = [
            f"{p}{i + 1}{s}" for i in range(count) for p, s in (("mu", "_Pa"), ("alpha", ""))
        ]
        expected.append("bulk_modulus_Pa")
    else:
        expected = [f.name for f in fields(cls)]
    missing = [key for key in expected if key not in values]
    unknown = [key for key in values if key not in expected]
    if missing:
        lowered = {key.lower(): key for key in unknown}
        close = difflib.get_close_matches(missing[0].lower(), list(lowered), n=1, cutoff=0.6)
        hint = f" (the unknown key {lowered[close[0]]!r} looks like a typo of it)" if close else ""
        raise InputError(f"missing parameter for model {name!r}{hint}", key=missing[0])
    if unknown:
        raise InputError(
            f"unknown parameter for model {name!r}; expected {', '.join(expected)}",
            key=unknown[0],
            value=values[unknown[0]],
        )
    for key in expected:
        check_finite(key, values[key])
    material = cls._from_flat({key: float(values[key]) for key in expected})
    if prony is None:
        return material
    return Viscoelastic(material, *prony)


def _material_regions(values: dict[str, Any]) -> MaterialRegions:
    """A :class:`MaterialRegions` from a material table with a ``regions`` table; an error in
    a region's table names ``regions.<name>.<key>``."""
    regions = values.pop("regions")
    if not isinstance(regions, Mapping) or not regions:
        raise InputError(
            "must be a table of named regions, e.g. [material.regions.tumour]",
            key="regions",
            value=regions,
        )
    default = material_from_dict(values)
    materials, tet_regions = {}, {}
    for name, table in regions.items():
        if not isinstance(table, Mapping):
            raise InputError(
                "must be a table with tet_regions and parameters", key=f"regions.{name}"
            )
        own = dict(table)
        if "tet_regions" not in own:
            raise InputError(
                "missing: the mesh's tet region ids this region holds",
                key=f"regions.{name}.tet_regions",
            )
        tet_regions[name] = own.pop("tet_regions")
        merged = own if "model" in own else {**values, **own}
        if "D1_per_Pa" in own and "model" not in own:
            merged.pop("bulk_modulus_Pa", None)
        if "bulk_modulus_Pa" in own and "model" not in own:
            merged.pop("D1_per_Pa", None)
        try:
            materials[name] = material_from_dict(merged)
        except InputError as exc:
            raise InputError(
                exc.message,
                key=f"regions.{name}.{exc.key}" if exc.key else f"regions.{name}",
                value=exc.value,
            ) from None
    return MaterialRegions(default, materials, tet_regions)


def _pop_prony(values: dict[str, Any]) -> tuple[tuple[float, ...], tuple[float, ...]] | None:
    """Take the Prony keys (``g<i>``, ``tau<i>_s``, numbered 1..N) out of a material table."""
    found: dict[str, dict[int, float]] = {"g": {}, "tau": {}}
    for key in [k for k in values if isinstance(k, str) and PRONY_KEY.match(k)]:
        match = PRONY_KEY.match(key)
        kind, index, unit = match.group(1), int(match.group(2)), match.group(3)
        if (kind == "tau") != (unit == "_s"):
            expected = f"tau{index}_s" if kind == "tau" else f"g{index}"
            raise InputError(f"unknown key; did you mean {expected!r}?", key=key)
        found[kind][index] = check_finite(key, values.pop(key))
    if not found["g"] and not found["tau"]:
        return None
    count = max([*found["g"], *found["tau"]])
    for kind, suffix in (("g", ""), ("tau", "_s")):
        for i in range(1, count + 1):
            if i not in found[kind]:
                raise InputError(
                    f"a Prony series numbers its terms 1..{count}: this term is missing",
                    key=f"{kind}{i}{suffix}",
                )
    return (
        tuple(found["g"][i] for i in range(1, count + 1)),
        tuple(found["tau"][i] for i in range(1, count + 1)),
    )
