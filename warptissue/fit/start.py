"""Start values of the inverse FE fit: from a record's small-depth stiffness, or given.

:func:`start_values_from_record` gives the start of every free parameter of a study's fit:
``[fit.start]`` values as given, the others from ``[material]``, or (``start_from =
"record"``, the default) scaled so that the initial shear modulus matches the first record's
small-depth stiffness, :func:`record_youngs_modulus_Pa` (Sneddon's flat punch with Hayes et
al.'s finite-thickness factor, :func:`warptissue.fit.punch.fit_punch_modulus`).
"""

from __future__ import annotations

import math

import numpy as np

from warptissue.errors import InputError
from warptissue.fit.punch import fit_punch_modulus
from warptissue.study import DataRecord, Study

__all__ = ["START_DEPTH_SHARE", "record_youngs_modulus_Pa", "start_values_from_record"]

START_DEPTH_SHARE: float = 0.1
"""Depth, as a share of the smaller of the probe radius and the specimen thickness, to
which :func:`record_youngs_modulus_Pa` takes a record's small-depth stiffness."""


def record_youngs_modulus_Pa(study: Study, record: DataRecord) -> float:
    """Young's modulus of a record's small-depth stiffness, for the study's probe and layer.

    Fits Sneddon's flat punch with the Hayes factor of the study's layer,
    F = 2 a E delta kappa(a/h, nu) / (1 - nu^2) (:func:`warptissue.fit.punch.fit_punch_modulus`),
    to the loading samples (up to the deepest point) at depths up to :data:`START_DEPTH_SHARE`
    of the smaller of the probe radius a and the specimen thickness h (the two shallowest
    loading samples if fewer lie there). nu is the study material's small-strain Poisson's
    ratio. For a nearly incompressible material the bonded and the frictionless punch have
    the same small-depth stiffness, so the study's contact does not enter.

    Args:
        study: The study (its indenter, specimen thickness and material).
        record: A conditioned record of the study.

    Returns:
        E, Pa.

    Raises:
        InputError: The record has fewer than two loading samples with a positive depth.
    """
    depth, force = record.displacement_m, record.force_N
    loading = slice(0, int(np.argmax(depth)) + 1)
    depth, force = depth[loading], force[loading]
    loaded = depth > 0.0
    depth, force = depth[loaded], force[loaded]
    if depth.size < 2:
        raise InputError(
            "has fewer than two loading samples below the contact: no stiffness to start "
            "from (give start values in [fit.start], or set contact)",
            path=record.path,
        )
    probe = study.probe_of(record)[0]
    if probe.kind in ("plate", "wedge"):
        raise InputError(
            f"no start value from an indentation formula for a {probe.kind} (give "
            "start values in [fit.start])",
            path=study.path,
            key="kind",
            value=probe.kind,
        )
    limit = START_DEPTH_SHARE * min(probe.radius_m, study.specimen.thickness_m)
    shallow = depth <= limit
    if np.count_nonzero(shallow) < 2:
        shallow = np.argsort(depth, kind="stable")[:2]
    poissons_ratio = min(study.material.small_strain_equivalent()[1], 0.5)
    try:
        result = fit_punch_modulus(
            depth[shallow],
            force[shallow],
            radius_m=probe.radius_m,
            poissons_ratio=poissons_ratio,
            geometry="sphere" if probe.kind == "sphere" else "flat",
            thickness_m=study.specimen.thickness_m,
        )
    except InputError as exc:  # e.g. a layer beyond the range of the Hayes factor
        raise InputError(
            f"no start value from {record.file}: {exc.message} (give start values in [fit.start])",
            path=study.path,
            value=exc.value,
        ) from None
    return float(result.x[0])


def start_values_from_record(study: Study, record: DataRecord | None = None) -> dict[str, float]:
    """The start of every free parameter of the study's fit.

    A value in ``[fit.start]`` is taken as it is. With ``start_from = "material"`` the others
    start from ``[material]``. With ``start_from = "record"`` (the default), the free
    parameters that set the initial shear modulus mu0 (``C10_Pa``, ``C01_Pa``, the Ogden
    ``mu<i>_Pa``, ``shear_modulus_Pa``, ``youngs_modulus_Pa``) are multiplied by one common
    factor, chosen so that mu0 equals the record's small-depth shear modulus
    mu = E / (2 (1 + nu)), E from :func:`record_youngs_modulus_Pa`; the other free
    parameters (C20, C30, the Ogden alpha<i>, a Poisson's ratio) start from ``[material]``.
    On a body of several material regions mu0 is the default material's; the free moduli of
    the named regions are multiplied by the same factor (they start from ``[material]`` where
    none of the default's is free).
    For neo-Hookean and reduced-polynomial models this is C10 = mu / 2; for Mooney-Rivlin
    with both free it splits mu / 2 in the ratio of the ``[material]`` values of C10 and C01,
    and with one free it gives that one what the fixed one leaves; for Ogden it scales the
    free mu_i so that sum mu_i = mu. A start outside the parameter's bounds is moved onto the
    nearer bound.

    Args:
        study: A study with a ``[fit]`` table.
        record: The record whose stiffness sets the start (default: the first of ``data``).

    Returns:
        Free parameter name -> start value, in ``study.fit.free`` order.

    Raises:
        InputError: The study has no fit; the record has no usable small-depth stiffness;
            or no positive common factor reaches the record's stiffness (give start values).
    """
    if study.fit is None:
        raise InputError("the study has no [fit] table", path=study.path)
    settings, material = study.fit, study.material
    current = dict(zip(material.parameter_names, material.parameter_vector.tolist(), strict=True))
    start = {name: settings.start.get(name, current[name]) for name in settings.free}
    scaled = [
        name
        for name in settings.free
        if name not in settings.start and material.shear_modulus_weight(name) != 0.0
    ]
    if settings.start_from == "record" and scaled:
        record = study.data[0] if record is None else record
        youngs_Pa = record_youngs_modulus_Pa(study, record)
        nu = min(material.small_strain_equivalent()[1], 0.5)
        target = youngs_Pa / (2.0 * (1.0 + nu))
        # The body's mu0 (the default material's where the body has regions): a region's
        # free moduli scale with the same factor, keeping their [material] ratios.
        weight = {
            name: material.shear_modulus_weight(name) if material.part_of(name)[0] == 0 else 0.0
            for name in current
        }
        free_part = sum(weight[name] * current[name] for name in scaled)
        fixed_part = sum(
            weight[name] * start.get(name, value)
            for name, value in current.items()
            if name not in scaled
        )
        factor = (target - fixed_part) / free_part if free_part > 0.0 else math.nan
        if free_part == 0.0 and len(material.parts) > 1:
            factor = 1.0  # only regions' moduli are free: they start from [material]
        if not factor > 0.0:
            raise InputError(
                f"fit.free: scaling {', '.join(scaled)} cannot reach the record's small-depth "
                f"shear modulus {target:.4g} Pa (the fixed parameters give {fixed_part:.4g} "
                "Pa): give start values in [fit.start]",
                path=study.path,
            )
        for name in scaled:
            start[name] = factor * current[name]
    lower, upper = settings.parameter_bounds(material)
    values = np.clip([start[name] for name in settings.free], lower, upper)
    return dict(zip(settings.free, values.tolist(), strict=True))
