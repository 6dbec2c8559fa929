"""The warptissue USD schema and the mapping of material records onto USD attributes.

Two sets of material attributes go on one ``UsdShade.Material`` bound with purpose physics:

- The small-strain equivalents that physics engines read, through the volume-deformable
  material API of the open physics-deformables proposal (``PhysicsVolumeDeformableMaterialAPI``:
  ``physics:density``, ``physics:youngsModulus``, ``physics:poissonsRatio``, all ``float``). That
  schema is not registered in usd-core (26.11) nor in newton-usd-schemas (0.6); NVIDIA Newton
  1.8 reads it from the raw ``apiSchemas`` metadata, so warptissue writes the name and
  attributes without registering a definition of its own (which would clash with the day
  OpenUSD ships it).
- The full fitted model in the ``tissue:`` namespace, through the codeless single-apply API
  schema ``TissueMaterialAPI`` defined in ``plugin/generatedSchema.usda`` and registered with
  ``Plug.Registry().RegisterPlugins`` when :mod:`warptissue.usd` is imported.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from warptissue import materials
from warptissue._stage import register_schema_plugin
from warptissue.errors import InputError

__all__ = [
    "applied_schema_names",
    "DEFORMABLE_BODY_API",
    "TISSUE_MATERIAL_API",
    "VOLUME_DEFORMABLE_MATERIAL_API",
    "VOLUME_DEFORMABLE_SIM_API",
    "MaterialRecord",
    "material_record",
    "record_from_attributes",
    "register_schema_plugin",
    "small_strain_from_record",
]

TISSUE_MATERIAL_API = "TissueMaterialAPI"
"""The codeless applied API schema carrying the full fitted model (``tissue:`` namespace)."""

VOLUME_DEFORMABLE_MATERIAL_API = "PhysicsVolumeDeformableMaterialAPI"
"""Physics-deformables proposal: elasticity and density of a volume deformable's material."""

VOLUME_DEFORMABLE_SIM_API = "PhysicsVolumeDeformableSimAPI"
"""Physics-deformables proposal: marks a TetMesh as a volume deformable's simulation mesh."""

DEFORMABLE_BODY_API = "PhysicsDeformableBodyAPI"
"""Physics-deformables proposal: the deformable body that owns the simulation mesh."""


# ``warptissue.materials.Material.to_dict()`` is flat, with units in the keys: ``C10_Pa``,
# ``C01_Pa``, ``C20_Pa``, ..., ``mu1_Pa``, ``alpha1``, ..., ``bulk_modulus_Pa``. The tuple form
# of the constructors (``C_Pa``, ``mu_Pa``, ``alpha``) is accepted too. USD attribute names drop
# the unit (the schema documents it). Keys not recognised are written verbatim under
# ``tissue:hyperelastic:`` so that nothing the material reports is lost.
_SCALAR_KEYS: dict[str, str] = {
    "shear_modulus_Pa": "shearModulus",
    "bulk_modulus_Pa": "bulkModulus",
    "D1_per_Pa": "D1",
    "youngs_modulus_Pa": "youngsModulus",
    "poissons_ratio": "poissonsRatio",
}
_PRONY_KEYS: dict[str, str] = {"prony_g": "pronyG", "prony_tau_s": "pronyTau"}
_COEFFICIENT_KEY = re.compile(r"^C([0-9])([0-9])_Pa$")
_COEFFICIENT_NAME = re.compile(r"^C([0-9])([0-9])$")
_OGDEN_KEY = re.compile(r"^(mu|alpha)([1-9][0-9]*)(_Pa)?$")
_TUPLE_KEYS: dict[str, str] = {"mu_Pa": "mu", "alpha": "alpha"}


def applied_schema_names(prim: Any) -> list[str]:
    """Every API schema name applied to a prim, registered or not.

    ``Usd.Prim.GetAppliedSchemas`` lists registered schemas only; the physics-deformables
    proposal's schemas are unregistered, so this reads the composed ``apiSchemas`` list op.
    """
    list_op = prim.GetMetadata("apiSchemas")
    return list(list_op.ApplyOperations([])) if list_op else []


@dataclass(frozen=True)
class MaterialRecord:
    """A material's parameters as USD attribute values.

    Attributes:
        model: The model's name, ``to_dict()["model"]``.
        hyperelastic: ``tissue:hyperelastic:<name>`` attribute name (without the namespace) to a
            float or a float array, shape (n,).
        prony_g: Prony relative moduli g_i, shape (n,) (empty without viscoelasticity).
        prony_tau_s: Prony relaxation times, shape (n,), seconds.
        youngs_modulus_Pa: Small-strain Young's modulus, Pa.
        poissons_ratio: Small-strain Poisson's ratio.
        source: The material's ``to_dict()``, for provenance.
    """

    model: str
    hyperelastic: dict[str, float | np.ndarray]
    prony_g: np.ndarray
    prony_tau_s: np.ndarray
    youngs_modulus_Pa: float
    poissons_ratio: float
    source: dict[str, Any] = field(default_factory=dict)


def _finite(name: str, value: Any) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise InputError(f"material parameter {name!r} must be a number", value=value) from None
    if not math.isfinite(number):
        raise InputError(f"material parameter {name!r} must be finite", value=value)
    return number


def _finite_array(name: str, value: Any) -> np.ndarray:
    try:
        array = np.atleast_1d(np.asarray(value, dtype=np.float64))
    except (TypeError, ValueError):
        raise InputError(
            f"material parameter {name!r} must be a sequence of numbers", value=value
        ) from None
    if array.ndim != 1 or not np.all(np.isfinite(array)):
        raise InputError(
            f"material parameter {name!r} must be a 1-D sequence of finite numbers", value=value
        )
    return array


def _model_key(model: str) -> str:
    return re.sub(r"[^a-z]", "", model.lower())


def _hyperelastic_values(record: Mapping[str, Any]) -> dict[str, float | np.ndarray]:
    """``to_dict()`` keys to ``tissue:hyperelastic:`` attribute names (no namespace) and values."""
    values: dict[str, float | np.ndarray] = {}
    ogden: dict[str, dict[int, float]] = {"mu": {}, "alpha": {}}
    for key, value in record.items():
        if key == "model" or key in _PRONY_KEYS or value is None:
            continue
        coefficient, ogden_term = _COEFFICIENT_KEY.match(key), _OGDEN_KEY.match(key)
        if key in _SCALAR_KEYS:
            values[_SCALAR_KEYS[key]] = _finite(key, value)
        elif coefficient:
            values[f"C{coefficient.group(1)}{coefficient.group(2)}"] = _finite(key, value)
        elif ogden_term:
            ogden[ogden_term.group(1)][int(ogden_term.group(2))] = _finite(key, value)
        elif key == "C_Pa":
            for order, term in enumerate(_finite_array(key, value), start=1):
                values[f"C{order}0"] = float(term)
        elif key in _TUPLE_KEYS:
            values[_TUPLE_KEYS[key]] = _finite_array(key, value)
        elif isinstance(value, (int, float, np.number)) and not isinstance(value, bool):
            values[key] = _finite(key, value)
        elif isinstance(value, (Sequence, np.ndarray)) and not isinstance(value, str):
            values[key] = _finite_array(key, value)
    for name, terms in ogden.items():
        if terms:
            if sorted(terms) != list(range(1, len(terms) + 1)):
                raise InputError(f"Ogden terms {name}1..{name}N are not consecutive", value=terms)
            values[name] = np.array([terms[i] for i in sorted(terms)])
    return values


def small_strain_from_record(record: Mapping[str, Any]) -> tuple[float, float]:
    """Small-strain Young's modulus and Poisson's ratio of a material dictionary.

    Used when the material is given as a plain dictionary (``Material.to_dict()`` form) rather
    than an object with ``small_strain_equivalent()``.

    Args:
        record: ``{"model": name, ...}`` with the ``warptissue.materials`` keys (``C10_Pa``,
            ``C01_Pa``, ``C20_Pa``, ``mu1_Pa``, ``alpha1``, ``shear_modulus_Pa``,
            ``bulk_modulus_Pa``, ``youngs_modulus_Pa``, ``poissons_ratio``; or the tuples
            ``C_Pa``, ``mu_Pa``).

    Returns:
        ``(E_Pa, nu)``. Without a bulk modulus the model is incompressible and nu = 0.5.

    Notes:
        The record becomes the :mod:`warptissue.materials` model (incompressible without a
        bulk modulus; a compressible neo-Hookean needs one), whose
        ``small_strain_equivalent()`` linearizes the strain energy at the reference state:
        initial shear modulus mu0 = 2 C10 (neo-Hookean, reduced polynomial, Yeoh),
        2 (C10 + C01) (Mooney-Rivlin), sum mu_i (Ogden); E = 9 K mu0 / (3 K + mu0) and
        nu = (3 K - 2 mu0) / (2 (3 K + mu0)), and E = 3 mu0, nu = 1/2 when incompressible.
    """
    if "model" not in record:
        raise InputError("material dictionary has no 'model' key", value=dict(record))
    model = _model_key(str(record["model"]))
    values = _hyperelastic_values(record)
    if "youngsModulus" in values and "poissonsRatio" in values:
        return float(values["youngsModulus"]), float(values["poissonsRatio"])
    if "bulkModulus" in values:
        bulk = float(values["bulkModulus"])
    elif "D1" in values:
        bulk = 2.0 / float(values["D1"])
    else:
        bulk = None
    material = _small_strain_material(model, values, bulk)
    if material is None:
        raise InputError(
            "cannot derive small-strain E and nu from this material dictionary; give "
            "'youngs_modulus_Pa' and 'poissons_ratio' or pass the material object",
            value=dict(record),
        )
    return material.small_strain_equivalent()


def _small_strain_material(model: str, values: Mapping[str, Any], bulk: float | None) -> Any:
    """The :mod:`warptissue.materials` model of ``tissue:hyperelastic:`` values (see
    :func:`_hyperelastic_values`) with bulk modulus ``bulk`` (None: incompressible), or None
    when the model or a parameter is unknown or missing.

    Raises:
        InputError: The initial shear modulus is not positive, or a value the model refuses.
    """

    coefficients = []
    while f"C{len(coefficients) + 1}0" in values:
        coefficients.append(float(values[f"C{len(coefficients) + 1}0"]))
    if model == "compressibleneohookean":
        if "shearModulus" not in values or bulk is None:
            return None
        return materials.CompressibleNeoHookean(float(values["shearModulus"]), bulk)
    if model in ("neohookean", "reducedpolynomial", "yeoh") and coefficients:
        material = materials.ReducedPolynomial(tuple(coefficients))
    elif model == "mooneyrivlin" and "C10" in values and "C01" in values:
        material = materials.MooneyRivlin(float(values["C10"]), float(values["C01"]))
    elif model == "ogden" and "mu" in values and "alpha" in values:
        material = materials.Ogden(tuple(values["mu"]), tuple(values["alpha"]))
    else:
        return None
    shear = material.initial_shear_modulus_Pa
    if not shear > 0:
        raise InputError("the material's initial shear modulus must be positive", value=shear)
    return material.with_bulk_modulus(bulk)


def material_record(material: Any) -> MaterialRecord:
    """Turn a material object or dictionary into USD attribute values.

    Args:
        material: An object with ``to_dict()`` and ``small_strain_equivalent()``
            (``warptissue.materials``), or a dictionary in ``to_dict()`` form. Optional keys
            ``prony_g`` and ``prony_tau_s`` carry a Prony series.

    Returns:
        The record, with validated finite values.
    """
    if hasattr(material, "to_dict") and hasattr(material, "small_strain_equivalent"):
        source = dict(material.to_dict())
        youngs, poisson = (float(v) for v in material.small_strain_equivalent())
    elif isinstance(material, Mapping):
        source = dict(material)
        youngs, poisson = small_strain_from_record(source)
    else:
        raise InputError(
            "material must have to_dict() and small_strain_equivalent(), or be a dictionary",
            value=type(material).__name__,
        )
    if "model" not in source:
        raise InputError("material record has no 'model' key", value=source)
    if not youngs > 0 or not -1.0 < poisson <= 0.5:
        raise InputError(
            f"small-strain equivalent out of range: E = {youngs} Pa, nu = {poisson}",
            value=(youngs, poisson),
        )
    prony_g = _finite_array("prony_g", source.get("prony_g", []))
    prony_tau = _finite_array("prony_tau_s", source.get("prony_tau_s", []))
    if prony_g.shape != prony_tau.shape:
        raise InputError(
            f"prony_g has {prony_g.size} terms but prony_tau_s has {prony_tau.size}",
            value=(prony_g.tolist(), prony_tau.tolist()),
        )
    if np.any(prony_tau <= 0) or np.any(prony_g < 0) or prony_g.sum() >= 1.0:
        raise InputError(
            "Prony series needs tau_i > 0, g_i >= 0 and sum g_i < 1",
            value=(prony_g.tolist(), prony_tau.tolist()),
        )
    return MaterialRecord(
        model=str(source["model"]),
        hyperelastic=_hyperelastic_values(source),
        prony_g=prony_g,
        prony_tau_s=prony_tau,
        youngs_modulus_Pa=youngs,
        poissons_ratio=poisson,
        source=source,
    )


def record_from_attributes(model: str, values: Mapping[str, Any]) -> dict[str, Any]:
    """Invert :func:`material_record`: ``tissue:`` attribute values to flat ``to_dict()`` form.

    Args:
        model: ``tissue:hyperelastic:model``.
        values: Attribute name without the ``tissue:hyperelastic:`` / ``tissue:viscoelastic:``
            namespace to its value (float or sequence of floats).

    Returns:
        A dictionary with the ``warptissue.materials`` keys (``C10_Pa``, ``mu1_Pa``, ``alpha1``,
        ``bulk_modulus_Pa``, ``prony_g``, ...), as ``warptissue.materials.material_from_dict``
        reads it.
    """
    inverse = {v: k for k, v in {**_SCALAR_KEYS, **_PRONY_KEYS}.items()}
    record: dict[str, Any] = {"model": model}
    for name, value in values.items():
        if name in ("mu", "alpha"):
            unit = "_Pa" if name == "mu" else ""
            for i, term in enumerate(value, start=1):
                record[f"{name}{i}{unit}"] = float(term)
        elif _COEFFICIENT_NAME.match(name):
            record[f"{name}_Pa"] = float(value)
        elif name in _PRONY_KEYS.values():
            record[inverse[name]] = [float(v) for v in value]
        elif isinstance(value, (Sequence, np.ndarray)):
            record[inverse.get(name, name)] = [float(v) for v in value]
        else:
            record[inverse.get(name, name)] = float(value)
    return record
