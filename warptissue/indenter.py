"""The indenter: one rigid probe type shared by the study, the finite elements and USD.

A study's ``[indenter]`` table reads into an :class:`Indenter`
(:func:`warptissue.study.load_study`), :class:`warptissue.fem.IndentationProblem` pushes it
into the specimen, and :func:`warptissue.usd.write_simulation_usd` draws it. This module
imports neither Warp nor USD, so that reading a study stays light.

Kinds: ``"flat_punch"`` (a flat-ended cylinder along z whose nodes are prescribed),
``"sphere"`` (a rigid sphere of radius ``radius_m``) and ``"plate"`` (a rigid plane
``z = top - depth``), which the finite elements simulate; ``"line"`` (a cylinder along y
pressed sideways, drawn only) and ``"platen"`` (a square plate, drawn only). Contact under the
probe: ``"bonded"`` (no slip; flat punch only) or ``"frictionless"`` (the only contact of a
sphere or a plate: a penalty, :mod:`warptissue.fem.contact`).

Example:
    >>> from warptissue.indenter import Indenter
    >>> probe = Indenter("flat_punch", radius_m=1.0e-3, contact="bonded")
    >>> probe.to_dict()
    {'kind': 'flat_punch', 'radius_m': 0.001, 'contact': 'bonded'}
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Any

from warptissue.errors import InputError

__all__ = ["CONTACTS", "CONTACT_KINDS", "INDENTER_KINDS", "SIMULATED_KINDS", "Indenter"]

INDENTER_KINDS: tuple[str, ...] = ("flat_punch", "sphere", "plate", "line", "platen")
"""Every kind an :class:`Indenter` may be."""
SIMULATED_KINDS: tuple[str, ...] = ("flat_punch", "sphere", "plate")
"""The kinds the finite elements (and so a study) simulate; the others are drawn only."""
CONTACT_KINDS: tuple[str, ...] = ("sphere", "plate")
"""Rigid indenters that touch the specimen through frictionless (penalty) contact."""
CONTACTS: tuple[str, ...] = ("bonded", "frictionless")
"""Contact conditions under the probe."""


def _positive_length(value: Any, key: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InputError("must be a number in metres", key=key, value=value)
    if not (math.isfinite(value) and value > 0):
        raise InputError("must be a positive length in metres", key=key, value=value)
    return float(value)


@dataclass(frozen=True)
class Indenter:
    """A rigid indenter, its contact point at ``(x_m, y_m, z_m)``.

    Args:
        kind: ``"flat_punch"`` (a flat-ended cylinder along z of radius ``radius_m``),
            ``"sphere"`` (a rigid sphere of radius ``radius_m``, its lowest point at the
            contact point), ``"plate"`` (a rigid plane ``z = top - depth``), ``"line"``
            (a cylinder along y of tip radius ``radius_m`` and length ``length_m``)
            or ``"platen"`` (a thin square plate of side ``length_m``).
        radius_m: Punch, sphere or line tip radius, m (0 where the kind has none).
        contact: ``"bonded"`` (the nodes under a flat punch move with it in x, y and z) or
            ``"frictionless"`` (only z is prescribed under the punch; a sphere or a plate
            pushes the surface nodes along its normal). None: ``"bonded"`` for a flat punch,
            ``"frictionless"`` for a sphere or a plate (their only contact).
        length_m: Line length or platen side, m (0 where the kind has none).
        x_m: Contact point x, m. The finite elements need the probe on the axis, 0.
        y_m: Contact point y, m. The finite elements need the probe on the axis, 0.
        z_m: Contact point z (the specimen's top surface), m; None: the top of the mesh.

    Raises:
        InputError: An unknown kind or contact, a bonded sphere or plate, or a missing,
            non-positive or non-finite length (the error's ``column`` names the field).
    """

    kind: str
    radius_m: float = field(default=0.0, kw_only=True)
    contact: str | None = field(default=None, kw_only=True)
    length_m: float = field(default=0.0, kw_only=True)
    x_m: float = field(default=0.0, kw_only=True)
    y_m: float = field(default=0.0, kw_only=True)
    z_m: float | None = field(default=None, kw_only=True)

    def __post_init__(self) -> None:
        if self.kind not in INDENTER_KINDS:
            raise InputError(
                f"must be one of {', '.join(map(repr, INDENTER_KINDS))}",
                key="kind",
                value=self.kind,
            )
        if self.contact is None:
            contact = "frictionless" if self.kind in CONTACT_KINDS else "bonded"
            object.__setattr__(self, "contact", contact)
        if self.contact not in CONTACTS:
            raise InputError(
                f"must be one of {', '.join(map(repr, CONTACTS))}",
                key="contact",
                value=self.contact,
            )
        if self.kind in CONTACT_KINDS and self.contact != "frictionless":
            raise InputError(
                f"a {self.kind} touches through frictionless contact only (a bonded rigid "
                "contact is not simulated)",
                key="contact",
                value=self.contact,
            )
        for key, needed in (
            ("radius_m", self.kind in ("flat_punch", "sphere", "line")),
            ("length_m", self.kind in ("line", "platen")),
        ):
            value = getattr(self, key)
            if needed or value != 0:
                if needed and value == 0:
                    raise InputError(
                        f"a {self.kind} indenter needs {key} > 0", key=key, value=value
                    )
                object.__setattr__(self, key, _positive_length(value, key))
        for key in ("x_m", "y_m", "z_m"):
            value = getattr(self, key)
            if value is None:
                continue
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise InputError("must be a number in metres", key=key, value=value)
            if not math.isfinite(value):
                raise InputError("must be finite", key=key, value=value)
            object.__setattr__(self, key, float(value))

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Indenter:
        """The indenter of a mapping shaped like :meth:`to_dict`'s.

        Raises:
            InputError: A key is unknown, ``kind`` is missing or a value is invalid.
        """
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise InputError(
                f"unknown indenter key (known: {', '.join(sorted(known))})", key=unknown[0]
            )
        if "kind" not in data:
            raise InputError("the indenter needs a kind", key="kind")
        return cls(**dict(data))

    def to_dict(self) -> dict[str, Any]:
        """``kind``, ``radius_m`` (if any), ``contact``, and the other fields not at default.

        For a study's flat punch this is the ``[indenter]`` table:
        ``{"kind", "radius_m", "contact"}``.
        """
        table: dict[str, Any] = {"kind": self.kind}
        if self.radius_m:
            table["radius_m"] = self.radius_m
        table["contact"] = self.contact
        for key in ("length_m", "x_m", "y_m"):
            if getattr(self, key):
                table[key] = getattr(self, key)
        if self.z_m is not None:
            table["z_m"] = self.z_m
        return table
