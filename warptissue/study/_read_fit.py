"""Reading a study's ``[fit]`` table: free parameters, their bounds and start values, and the
fit's method, objective and strategy."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from warptissue.errors import InputError
from warptissue.materials import prony_term
from warptissue.study._schema import (
    BULK_MODULUS_RULES,
    CONTACT_POINTS,
    DEPTH_OFFSET,
    FIT_METHODS,
    FIT_OBJECTIVES,
    FIT_STRATEGIES,
    MAX_STEPS,
    START_FROM,
    FitSettings,
)
from warptissue.study._toml import Table, closest, plain


def _free_name_problem(name: str, material: Any) -> str:
    """Why ``name`` is not a free parameter of ``material``."""
    names = material.parameter_names
    if name in material.to_dict():
        return (
            f"is held fixed: the volumetric term is not a fit parameter of model "
            f"{material.model_name!r} (its fit parameters: {', '.join(names)})"
        )
    close = closest(name, names)
    hint = f"did you mean {close!r}? " if close else ""
    return f"is not a parameter of model {material.model_name!r} ({hint}its fit parameters: " + (
        f"{', '.join(names)})"
    )


def _parameter_table(
    table: Table, free: Sequence[str], material: Any, *, contact_point: str = "given"
) -> dict[str, Any]:
    """The keys of ``[fit.start]`` or ``[fit.bounds]``: each must be a free parameter (or
    the depth offset, with ``contact_point = "fit"``)."""
    for key in table.data:
        if key in free:
            continue
        if key == DEPTH_OFFSET:
            if contact_point == "fit":
                continue
            raise table.error(
                key,
                "applies only with fit.contact_point = 'fit' (the depth offset fitted with "
                "the material)",
                table.data[key],
            )
        if key in material.parameter_names:
            raise table.error(
                key,
                "is not free: list it in fit.free, or set its value in [material]",
                table.data[key],
            )
        raise table.error(key, _free_name_problem(key, material), None)
    return dict(table.data)


def read_fit(table: Table, material: Any) -> FitSettings:
    free = _free_names(table, material)
    contact_point = table.string("contact_point", default="given", choices=CONTACT_POINTS)
    bounds_table = optional_table(table, "bounds")
    bounds = _bounds(bounds_table, free, material, contact_point)
    start_table = optional_table(table, "start")
    start = {
        key: start_table.number(key, positive=False)
        for key in _parameter_table(start_table, free, material, contact_point=contact_point)
    }
    if DEPTH_OFFSET in start and DEPTH_OFFSET in bounds:
        low, high = bounds[DEPTH_OFFSET]
        if not low <= start[DEPTH_OFFSET] <= high:
            raise start_table.error(
                DEPTH_OFFSET, f"lies outside fit.bounds [{low:g}, {high:g}]", start[DEPTH_OFFSET]
            )
    start_from = table.string("start_from", default="record", choices=START_FROM)
    method = table.string("method", default="lm", choices=FIT_METHODS)
    objective = table.string("objective", default="absolute", choices=FIT_OBJECTIVES)
    relative_floor_N = table.number("relative_floor_N", default=None)
    if relative_floor_N is not None and objective != "relative":
        raise table.error(
            "relative_floor_N", "applies only with objective = 'relative'", relative_floor_N
        )
    max_iterations = table.integer("max_iterations", default=50)
    tolerances = {key: table.number(key, default=1e-8) for key in ("ftol", "xtol", "gtol")}
    stop_r_squared = table.number("stop_r_squared", default=None)
    if stop_r_squared is not None and not stop_r_squared < 1.0:
        raise table.error("stop_r_squared", "must lie between 0 and 1", stop_r_squared)
    strategy = _strategy(table, material, free)
    bulk_modulus = table.string("bulk_modulus", default="fixed", choices=BULK_MODULUS_RULES)
    if bulk_modulus == "follows_shear" and not hasattr(material, "with_bulk_modulus"):
        raise table.error(
            "bulk_modulus",
            "'follows_shear' holds K/mu0 of a hyperelastic model's bulk modulus (not a fit "
            f"parameter); model {material.model_name!r} has its own compressibility "
            "parameters: leave them out of fit.free to hold them",
            bulk_modulus,
        )
    time_steps = table.integer("time_steps", default=24, minimum=2)
    if time_steps > MAX_STEPS:
        raise table.error("time_steps", f"must be at most {MAX_STEPS}", time_steps)
    table.finish()
    settings = FitSettings(
        free=free,
        start=start,
        bounds=bounds,
        start_from=start_from,
        method=method,
        objective=objective,
        relative_floor_N=relative_floor_N,
        max_iterations=max_iterations,
        stop_r_squared=stop_r_squared,
        strategy=strategy,
        time_steps=time_steps,
        contact_point=contact_point,
        bulk_modulus=bulk_modulus,
        **tolerances,
    )
    _check_start(settings, material, table, start_table)
    return settings


def _free_names(table: Table, material: Any) -> tuple[str, ...]:
    """``fit.free``: a non-empty list of the material's parameter names, each once."""
    free_raw = table.raw("free")
    if (
        not isinstance(free_raw, list)
        or not free_raw
        or not all(isinstance(name, str) for name in free_raw)
    ):
        raise table.error("free", "must be a non-empty list of parameter names", free_raw)
    for name in free_raw:
        if name not in material.parameter_names:
            raise table.error("free", f"{name!r} {_free_name_problem(name, material)}", name)
        if free_raw.count(name) > 1:
            raise table.error("free", f"names {name!r} twice", free_raw)
    return tuple(free_raw)


def _bounds(
    bounds_table: Table, free: tuple[str, ...], material: Any, contact_point: str
) -> dict[str, tuple[float, float]]:
    """``[fit.bounds]``: ``[lower, upper]`` of free parameters, lower below upper."""
    bounds: dict[str, tuple[float, float]] = {}
    for key in _parameter_table(bounds_table, free, material, contact_point=contact_point):
        pair = bounds_table.raw(key)
        if not isinstance(pair, list) or len(pair) != 2:
            raise bounds_table.error(key, "must be [lower, upper]", pair)
        low, high = (plain(v) for v in pair)
        if any(isinstance(v, bool) or not isinstance(v, int | float) for v in (low, high)):
            raise bounds_table.error(key, "must be [lower, upper], two numbers", pair)
        if math.isnan(low) or math.isnan(high) or not low < high:
            raise bounds_table.error(key, "the lower bound must be below the upper", pair)
        bounds[key] = (float(low), float(high))
    return bounds


def _strategy(table: Table, material: Any, free: tuple[str, ...]) -> str:
    """``fit.strategy``; ``"two_stage"`` needs Prony terms and a free parameter that is not
    one."""
    strategy = table.string("strategy", default="joint", choices=FIT_STRATEGIES)
    if strategy == "two_stage":
        prony = [name for name in material.parameter_names if prony_term(name) is not None]
        if not prony:
            raise table.error(
                "strategy",
                "'two_stage' (Ahn & Kim) fits Prony terms first, and [material] has none "
                f"(model {material.model_name!r}): add g1, tau1_s, ... to [material], or use "
                "'joint'",
                strategy,
            )
        if all(prony_term(name) is not None for name in free):
            raise table.error(
                "strategy",
                "'two_stage' fits the Prony terms in stage (i) and the other free parameters "
                "by inverse FE in stage (ii), and fit.free names no other: free an elastic "
                "parameter too (C10_Pa, ...), or use 'joint'",
                strategy,
            )
    return strategy


def _check_start(settings: FitSettings, material: Any, table: Table, start_table: Table) -> None:
    """Refuse a start value (given, or the material's with ``start_from = "material"``)
    outside its bounds, and given start values the material refuses."""
    free, start, start_from = settings.free, settings.start, settings.start_from
    lower, upper = settings.parameter_bounds(material)
    current = dict(zip(material.parameter_names, material.parameter_vector.tolist(), strict=True))
    for j, name in enumerate(free):
        if name in start:
            where, value = start_table, start[name]
        elif start_from == "material":
            where, value = table, current[name]
        else:
            continue
        if not lower[j] <= value <= upper[j]:
            key, problem = (
                (name, "lies outside fit.bounds")
                if where is start_table
                else ("start_from", f"the [material] value of {name} lies outside its bounds")
            )
            raise where.error(key, f"{problem} [{lower[j]:g}, {upper[j]:g}]", value)
    given = {name: value for name, value in start.items() if name != DEPTH_OFFSET}
    if given:
        vector = np.array([given.get(name, current[name]) for name in material.parameter_names])
        try:
            material.with_parameters(vector)
        except InputError as exc:
            key = exc.column if exc.column in given else next(iter(given))
            raise start_table.error(key, exc.message, given[key]) from None


def optional_table(root: Table, key: str) -> Table:
    """A table whose keys all have defaults, so that the table itself may be left out."""
    return Table(root.raw(key, {}), root.key_path(key), root.source)
