"""The indenter: one rigid probe type shared by the study, the finite elements and USD.

A study's ``[indenter]`` table reads into an :class:`Indenter`
(:func:`warptissue.study.load_study`), :class:`warptissue.fem.IndentationProblem` pushes it
into the specimen, and :func:`warptissue.usd.write_simulation_usd` draws it. This module
imports neither Warp nor USD, so that reading a study stays light.

Kinds the finite elements simulate: ``"flat_punch"`` (a flat-ended cylinder along z: sharp,
its nodes prescribed, or with a rounded edge ``edge_radius_m`` > 0, a rigid body in contact),
``"sphere"`` (a rigid sphere of radius ``radius_m``), ``"plate"`` (a rigid plane
``z = top - depth``) and ``"wedge"`` (a line indenter: a rigid wedge along y of opening angle
``angle_deg`` whose tip is rounded with radius ``radius_m``; ``angle_deg = 0`` is a cylinder
pressed sideways). ``"platen"`` (a square plate) is drawn only. Contact under the probe:
``"bonded"`` (no slip; sharp flat punch only) or ``"frictionless"`` (the only contact of a
rigid body: a penalty, :mod:`warptissue.fem.contact`).

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

INDENTER_KINDS: tuple[str, ...] = ("flat_punch", "sphere", "plate", "wedge", "platen")
"""Every kind an :class:`Indenter` may be."""
SIMULATED_KINDS: tuple[str, ...] = ("flat_punch", "sphere", "plate", "wedge")
"""The kinds the finite elements (and so a study) simulate; the others are drawn only."""
CONTACT_KINDS: tuple[str, ...] = ("sphere", "plate", "wedge")
"""Kinds that always touch the specimen through frictionless (penalty) contact (a flat punch
does when its edge is rounded: :attr:`Indenter.is_rigid_contact`)."""
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
            contact point), ``"plate"`` (a rigid plane ``z = top - depth``), ``"wedge"``
            (a wedge along y of opening angle ``angle_deg``, tip radius ``radius_m``, edge
            length ``length_m``) or ``"platen"`` (a thin square plate of side ``length_m``).
        radius_m: Punch, sphere or wedge tip radius, m (0 where the kind has none).
        contact: ``"bonded"`` (the nodes under a sharp flat punch move with it in x, y and
            z) or ``"frictionless"`` (only z is prescribed under a sharp punch; a rigid body
            pushes the surface nodes along its normal). None: ``"bonded"`` for a sharp flat
            punch, ``"frictionless"`` for a rigid body (its only contact).
        length_m: Wedge edge length (0: it spans the specimen) or platen side, m.
        edge_radius_m: A flat punch's edge radius, m, at most ``radius_m``: 0 (the default) is
            a sharp punch whose nodes are prescribed; > 0 a rigid body in frictionless contact.
        angle_deg: A wedge's opening angle, degrees, in [0, 180) (0: a cylinder).
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
    edge_radius_m: float = field(default=0.0, kw_only=True)
    angle_deg: float = field(default=0.0, kw_only=True)
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
        for key, kind in (("edge_radius_m", "flat_punch"), ("angle_deg", "wedge")):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise InputError("must be a number", key=key, value=value)
            if value != 0 and self.kind != kind:
                raise InputError(f"only a {kind} has {key}", key=key, value=value)
            if not (math.isfinite(value) and value >= 0):
                raise InputError("must be finite and >= 0", key=key, value=value)
            object.__setattr__(self, key, float(value))
        if self.angle_deg >= 180.0:
            raise InputError(
                "a wedge's opening angle must be below 180 degrees (a plate is kind 'plate')",
                key="angle_deg",
                value=self.angle_deg,
            )
        if self.contact is None:
            contact = "frictionless" if self.is_rigid_contact else "bonded"
            object.__setattr__(self, "contact", contact)
        if self.contact not in CONTACTS:
            raise InputError(
                f"must be one of {', '.join(map(repr, CONTACTS))}",
                key="contact",
                value=self.contact,
            )
        if self.is_rigid_contact and self.contact != "frictionless":
            what = "flat punch with a rounded edge" if self.kind == "flat_punch" else self.kind
            raise InputError(
                f"a {what} touches through frictionless contact only (a bonded rigid "
                "contact is not simulated)",
                key="contact",
                value=self.contact,
            )
        for key, needed in (
            ("radius_m", self.kind in ("flat_punch", "sphere", "wedge")),
            ("length_m", self.kind == "platen"),
        ):
            value = getattr(self, key)
            if needed or value != 0:
                if needed and value == 0:
                    raise InputError(
                        f"a {self.kind} indenter needs {key} > 0", key=key, value=value
                    )
                object.__setattr__(self, key, _positive_length(value, key))
        if self.edge_radius_m > self.radius_m:
            raise InputError(
                f"a flat punch's edge radius must not exceed its radius {self.radius_m} m",
                key="edge_radius_m",
                value=self.edge_radius_m,
            )
        for key in ("x_m", "y_m", "z_m"):
            value = getattr(self, key)
            if value is None:
                continue
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise InputError("must be a number in metres", key=key, value=value)
            if not math.isfinite(value):
                raise InputError("must be finite", key=key, value=value)
            object.__setattr__(self, key, float(value))

    @property
    def is_rigid_contact(self) -> bool:
        """Whether the finite elements press this indenter as a rigid body through frictionless
        penalty contact (a sphere, a plate, a wedge, or a flat punch with a rounded edge),
        rather than prescribing the nodes under it (a sharp flat punch)."""
        return self.kind in CONTACT_KINDS or (self.kind == "flat_punch" and self.edge_radius_m > 0)

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
        for key in ("length_m", "edge_radius_m", "angle_deg", "x_m", "y_m"):
            if getattr(self, key):
                table[key] = getattr(self, key)
        if self.z_m is not None:
            table["z_m"] = self.z_m
        return table
