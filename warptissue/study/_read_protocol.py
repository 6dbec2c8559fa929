"""Reading a study's ``[protocol]`` table: the load steps of each protocol kind."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from warptissue.errors import InputError
from warptissue.loading import DEPTH_SPACINGS, quasi_static_depths, ramp_hold, sine
from warptissue.study._records import condition_record, record_options
from warptissue.study._schema import (
    MAX_STEPS,
    PROTOCOL_KINDS,
    Protocol,
)
from warptissue.study._toml import Table

PROTOCOL_KEYS: dict[str, tuple[str, ...]] = {
    "quasi_static": ("depths_m", "max_depth_m", "steps", "spacing"),
    "timed": ("depths_m", "times_s"),
    "ramp_hold": ("max_depth_m", "speed_m_per_s", "hold_s", "ramp_steps", "hold_steps"),
    "sine": (
        "preload_depth_m",
        "amplitude_m",
        "frequency_Hz",
        "cycles",
        "preload_s",
        "preload_steps",
        "steps_per_cycle",
    ),
    "record": (
        "file",
        "time_column",
        "displacement_column",
        "force_column",
        "contact",
        "contact_position_m",
        "offset",
        "keep_depth_m",
        "window_s",
        "steps",
    ),
}
"""The keys of ``[protocol]`` for each kind (besides ``kind``)."""


RECORD_PROTOCOL_STEPS: int = 40
"""Default ``protocol.steps`` of a ``"record"`` protocol."""


def read_protocol(table: Table, thickness_m: float, *, version: int, base: Path) -> Protocol:
    timed_list = table.has("times_s")
    kind = table.string(
        "kind", default="timed" if timed_list else "quasi_static", choices=PROTOCOL_KINDS
    )
    if version < 2 and (kind != "quasi_static" or timed_list):
        key = "kind" if table.has("kind") else "times_s"
        raise table.error(
            key, "a timed protocol needs schema_version = 2 (this file says 1)", table.data[key]
        )
    for key in table.data:  # a key of another kind (a typo is named by finish())
        owners = [k for k, keys in PROTOCOL_KEYS.items() if key in keys]
        if key != "kind" and owners and key not in PROTOCOL_KEYS[kind]:
            raise table.error(
                key,
                f"is not a key of kind {kind!r} (its keys: {', '.join(PROTOCOL_KEYS[kind])}); "
                f"it belongs to kind {owners[0]!r}",
                None,
            )
    if kind == "quasi_static":
        return _read_quasi_static(table, thickness_m)
    settings: dict[str, Any] = {}
    record = None
    if kind == "timed":
        depths = table.number_list("depths_m")
        times = table.number_list("times_s")
        if len(times) != len(depths):
            raise table.error(
                "times_s",
                f"must hold one time per depth ({len(depths)} depths, {len(times)} times)",
                len(times),
            )
        for previous, time in zip((0.0, *times[:-1]), times, strict=True):
            if time <= previous:
                raise table.error(
                    "times_s", "must be positive and strictly increasing", list(times)
                )
        depth_key = "depths_m"
    elif kind == "ramp_hold":
        settings = {
            "max_depth_m": table.number("max_depth_m"),
            "speed_m_per_s": table.number("speed_m_per_s"),
            "hold_s": table.number("hold_s", positive=False),
            "ramp_steps": table.integer("ramp_steps", default=10),
            "hold_steps": table.integer("hold_steps", default=20),
        }
        times, depths = table.build(lambda values: ramp_hold(**values), settings)
        depth_key = "max_depth_m"
    elif kind == "sine":
        settings = {
            "preload_depth_m": table.number("preload_depth_m"),
            "amplitude_m": table.number("amplitude_m"),
            "frequency_Hz": table.number("frequency_Hz"),
            "cycles": table.integer("cycles"),
            "preload_s": table.number("preload_s"),
            "preload_steps": table.integer("preload_steps", default=5),
            "steps_per_cycle": table.integer("steps_per_cycle", default=16, minimum=4),
        }
        times, depths = table.build(lambda values: sine(**values), settings)
        depth_key = "amplitude_m"
    else:  # record
        options = record_options(table, base)
        steps = table.integer("steps", default=RECORD_PROTOCOL_STEPS, minimum=2)
        if steps > MAX_STEPS:
            raise table.error("steps", f"must be at most {MAX_STEPS}", steps)
        record = condition_record(table, options, force_required=False)
        try:
            times, depths = record.load_history(steps=steps)
        except InputError as exc:
            raise table.error("file", exc.message, options["file"]) from None
        settings = {"steps": steps}
        depth_key = "file"
    times, depths = tuple(map(float, times)), tuple(map(float, depths))
    if len(depths) > MAX_STEPS:
        raise table.error(depth_key, f"gives more than {MAX_STEPS} steps", len(depths))
    if min(depths) < 0.0:
        raise table.error(depth_key, "depths must be >= 0 (into the specimen)", min(depths))
    if max(depths) >= thickness_m:
        raise table.error(
            depth_key,
            f"the deepest depth must be less than the thickness ({thickness_m!r} m)",
            max(depths),
        )
    table.finish(also_known=PROTOCOL_KEYS[kind])
    return Protocol(depths_m=depths, times_s=times, kind=kind, settings=settings, record=record)


def _read_quasi_static(table: Table, thickness_m: float) -> Protocol:
    has_list = table.has("depths_m")
    has_ramp = table.has("max_depth_m") or table.has("steps")
    if has_list == has_ramp:
        raise table.source.error(
            table.prefix,
            "give either depths_m, or max_depth_m and steps (exactly one of the two forms)",
        )
    settings: dict[str, Any] = {}
    if has_list and table.has("spacing"):
        raise table.error(
            "spacing", "spaces the steps of max_depth_m and steps, not a depths_m list", None
        )
    if has_list:
        depths = table.number_list("depths_m")
        if len(depths) > MAX_STEPS:
            raise table.error("depths_m", f"must hold at most {MAX_STEPS} depths", len(depths))
        for previous, depth in zip((0.0, *depths[:-1]), depths, strict=True):
            if depth <= previous:
                raise table.error(
                    "depths_m", "must be positive and strictly increasing", list(depths)
                )
        last_key = "depths_m"
    else:
        max_depth_m = table.number("max_depth_m")
        steps = table.integer("steps")
        if steps > MAX_STEPS:
            raise table.error("steps", f"must be at most {MAX_STEPS}", steps)
        spacing = table.string("spacing", default="even", choices=DEPTH_SPACINGS)
        depths = tuple(
            map(float, quasi_static_depths(max_depth_m=max_depth_m, steps=steps, spacing=spacing))
        )
        if spacing != "even":  # echoed as the keys that made the depths
            settings = {"max_depth_m": max_depth_m, "steps": steps, "spacing": spacing}
        last_key = "max_depth_m"
    if depths[-1] >= thickness_m:
        raise table.error(
            last_key,
            f"the final depth must be less than the thickness ({thickness_m!r} m)",
            depths[-1],
        )
    table.finish(also_known=("kind", *PROTOCOL_KEYS["quasi_static"]))
    return Protocol(depths_m=depths, settings=settings)
