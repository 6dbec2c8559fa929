"""The set-up of one inverse-FE fit: its options checked against the study, the records'
probe radius, Ahn & Kim's stage (i) for the two-stage strategy, the start values, and the
engine's parameters (names, units, start, bounds and scale).

The public face is :mod:`warptissue.fit.indentation` (:func:`fit_indentation`); its module
docstring says what the strategies and the contact point are.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from warptissue.errors import InputError
from warptissue.fit._model import depth_offset_names, offset_box, shifted_record
from warptissue.fit.start import start_values_from_record
from warptissue.io import read_sidecar
from warptissue.lsq.result import FitResult
from warptissue.materials import positive_bounds, prony_term
from warptissue.study import CONTACT_POINTS, FIT_STRATEGIES, Study
from warptissue.viscoelastic.fitting import fit_qlv

__all__ = ["FitPlan", "ParameterSpace", "fit_plan", "parameter_space"]


@dataclass
class FitPlan:
    """One fit's set-up: its strategy and contact point, the material the inverse FE starts
    from (with stage (i)'s Prony terms, for the two-stage strategy), its free parameters and
    their bounds, the start values and the depth offsets' start and box."""

    strategy: str
    contact_point: str
    material: Any
    free: tuple[str, ...]
    all_lower: np.ndarray
    all_upper: np.ndarray
    start: dict[str, float]
    offset_start: np.ndarray | None
    offset_lower: np.ndarray
    offset_upper: np.ndarray
    stage_one_fits: tuple[FitResult, ...] = ()
    prony: dict[str, float] = field(default_factory=dict)


@dataclass
class ParameterSpace:
    """The engine's parameters: names, units, start, bounds and scale (the depth offsets, in
    m, after the material's), and each record's depth span (m)."""

    names: tuple[str, ...]
    units: tuple[str, ...]
    x0: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    x_scale: np.ndarray
    spans: np.ndarray
    offset_names: tuple[str, ...]


def fit_plan(study: Study, *, strategy: str | None, contact_point: str | None) -> FitPlan:
    """The checked set-up of one study's fit (stage (i) run for the two-stage strategy)."""
    if study.fit is None or not study.data:
        raise InputError(
            "the study holds no fit: add [[data]] records and a [fit] table (schema_version 2)",
            path=study.path,
        )
    settings = study.fit
    chosen_strategy = strategy if strategy is not None else settings.strategy
    if chosen_strategy not in FIT_STRATEGIES:
        raise InputError(
            f"strategy must be one of {', '.join(FIT_STRATEGIES)}",
            path=study.path,
            key="fit.strategy",
            value=chosen_strategy,
        )
    chosen_contact = contact_point if contact_point is not None else settings.contact_point
    if chosen_contact not in CONTACT_POINTS:
        raise InputError(
            f"contact_point must be one of {', '.join(CONTACT_POINTS)}",
            path=study.path,
            key="fit.contact_point",
            value=chosen_contact,
        )
    fit_offsets = chosen_contact == "fit"
    _check_probe_radius(study)
    offset_start: np.ndarray | None = None
    offset_lower = offset_upper = np.zeros(0)
    if fit_offsets:
        offset_start, offset_lower, offset_upper = offset_box(study)
        start = start_values_from_record(
            study, shifted_record(study.data[0], float(offset_start[0]))
        )
    else:
        start = start_values_from_record(study)
    all_lower, all_upper = settings.parameter_bounds(study.material)
    plan = FitPlan(
        strategy=chosen_strategy,
        contact_point=chosen_contact,
        material=study.material,
        free=tuple(settings.free),
        all_lower=all_lower,
        all_upper=all_upper,
        start=start,
        offset_start=offset_start,
        offset_lower=offset_lower,
        offset_upper=offset_upper,
    )
    if chosen_strategy == "two_stage":
        _apply_stage_one(study, plan)
    return plan


def _apply_stage_one(study: Study, plan: FitPlan) -> None:
    """Ahn & Kim's stage (i) on ``plan``: its Prony terms fixed in the material, the other
    free parameters (and their bounds) left to stage (ii)."""
    material, free = plan.material, plan.free
    stage_one_fits, prony = _stage_one(study, material, plan.strategy)
    vector = material.parameter_vector.copy()
    names = list(material.parameter_names)
    for name, value in prony.items():
        vector[names.index(name)] = value
    try:
        material = material.with_parameters(vector)
    except InputError as exc:
        raise InputError(
            f"stage (i) (Ahn & Kim) gave an invalid Prony series: {exc.message}",
            path=study.path,
            value=prony,
        ) from None
    keep = [j for j, name in enumerate(free) if prony_term(name) is None]
    if not keep:
        raise InputError(
            "strategy two_stage fits the Prony terms in stage (i) and the other free "
            "parameters by inverse FE in stage (ii): free an elastic parameter too",
            path=study.path,
            key="fit.free",
            value=list(free),
        )
    plan.stage_one_fits, plan.prony, plan.material = stage_one_fits, prony, material
    plan.free = tuple(free[j] for j in keep)
    plan.all_lower, plan.all_upper = plan.all_lower[keep], plan.all_upper[keep]


def parameter_space(study: Study, plan: FitPlan) -> ParameterSpace:
    """The engine's parameters of ``plan``: the free material parameters, then the depth
    offsets when fitted."""
    material, free = plan.material, plan.free
    offset_names = depth_offset_names(study.data) if plan.contact_point == "fit" else ()
    names = free + offset_names
    units = tuple(material.parameter_units[material.parameter_names.index(n)] for n in free)
    units += ("m",) * len(offset_names)
    x0 = np.array([plan.start[name] for name in free], dtype=np.float64)
    lower, upper = positive_bounds(free, plan.all_lower, plan.all_upper)
    x0 = np.clip(x0, lower, upper)
    spans = np.array([float(np.ptp(record.displacement_m)) for record in study.data])
    if plan.offset_start is not None:
        x0 = np.concatenate([x0, plan.offset_start])
        lower = np.concatenate([lower, plan.offset_lower])
        upper = np.concatenate([upper, plan.offset_upper])
    x_scale = _x_scale(x0, units)
    if offset_names:
        x_scale[len(free) :] = spans  # an offset may start at 0: its record's depth span
    return ParameterSpace(names, units, x0, lower, upper, x_scale, spans, offset_names)


def _check_probe_radius(study: Study) -> None:
    """Refuse a record whose sidecar names another probe radius than its probe's (the
    record's own ``indenter``, else the study's)."""

    for record in study.data:
        radius = study.probe_of(record)[0].radius_m
        sidecar = read_sidecar(record.path)
        value = sidecar.get("probe_radius_m")
        if value is None:
            continue
        try:
            measured = float(value)
        except (TypeError, ValueError):
            raise InputError(
                f"{record.file}: the sidecar's probe_radius_m is not a number",
                path=record.path,
                key="probe_radius_m",
                value=value,
            ) from None
        if not math.isclose(measured, radius, rel_tol=1e-3):
            raise InputError(
                f"{record.file} was measured with probe_radius_m = {measured:g} m (its "
                f"sidecar), its indenter in the study has radius_m = {radius:g} m: fit it with "
                "that probe",
                path=record.path,
                key="probe_radius_m",
                value=measured,
            )


def _x_scale(start: np.ndarray, units: Sequence[str]) -> np.ndarray:
    """|start|, or for a zero start the mean |start| of the parameters of its unit (else 1)."""
    scale = np.abs(start).astype(np.float64)
    for j in np.flatnonzero(scale == 0.0):
        same = [abs(start[k]) for k in range(start.size) if units[k] == units[j] and start[k]]
        scale[j] = float(np.mean(same)) if same else 1.0
    return scale


def _stage_one(study: Study, material: Any, strategy: str) -> tuple[tuple[FitResult, ...], dict]:
    """Ahn & Kim's stage (i): fit_qlv on every record; the mean Prony terms."""

    kinds = [term[0] for term in map(prony_term, material.parameter_names) if term is not None]
    terms = kinds.count("g")
    if terms == 0:
        raise InputError(
            "strategy two_stage fits a Prony series first: the material has none (add g1, "
            "tau1_s, ... to [material])",
            path=study.path,
            key="fit.strategy",
            value=strategy,
        )
    fits = []
    for record in study.data:
        try:
            fits.append(fit_qlv(record.time_s, record.displacement_m, record.force_N, terms=terms))
        except InputError as exc:
            raise InputError(
                f"{record.file}: stage (i) (Ahn & Kim): {exc.message}",
                path=record.path,
                value=exc.value,
            ) from None
    mean = {}
    for i in range(1, terms + 1):
        for name in (f"g{i}", f"tau{i}_s"):
            mean[name] = float(np.mean([fit.parameters[name] for fit in fits]))
    return tuple(fits), mean
