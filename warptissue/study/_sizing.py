"""The specimen's extent and the refined zone of its mesh under the probe."""

from __future__ import annotations

from warptissue.indenter import Indenter


def specimen_half_size_m(shape: str, width_m: float | None, radius_m: float | None) -> float:
    """The specimen's extent from the probe axis: half a block's width, or a disc's radius.

    Args:
        shape: ``"block"`` or ``"disc"``.
        width_m: The block's full edge length, m (block only).
        radius_m: The disc's radius, m (disc only).

    Returns:
        The half size, m.
    """
    return width_m / 2.0 if shape == "block" else radius_m


def mesh_probe_radius(indenter: Indenter, half_size_m: float) -> float:
    """The radius of the specimen mesh's refined zone under the probe, m: the probe's radius,
    or half the specimen's half-size for a plate without one or a wedge (whose contact
    widens with depth along its flanks)."""
    if indenter.kind == "wedge" or indenter.radius_m <= 0:
        return 0.5 * half_size_m
    return indenter.radius_m
