"""Choosing the Warp device that host wrappers launch on."""

from __future__ import annotations

import warp as wp

from warptissue.errors import DeviceError

__all__ = ["quiet_warp", "resolve_device"]


def resolve_device(device: str | wp.Device | None = None) -> wp.Device:
    """Return a Warp device, initializing Warp on first use.

    Args:
        device: ``"cpu"``, ``"cuda"``, ``"cuda:N"``, a Warp device, or None for Warp's
            default device (a GPU where one is present, else the CPU).

    Returns:
        The Warp device.

    Raises:
        DeviceError: The device does not exist on this machine.
    """
    wp.init()
    if isinstance(device, wp.Device):
        return device
    if device is None:
        return wp.get_device()
    if str(device).startswith("cuda") and not wp.is_cuda_available():
        raise DeviceError(f"device {device!r} was requested but no CUDA device is available")
    try:
        return wp.get_device(device)
    except (RuntimeError, ValueError) as exc:
        available = ", ".join(str(d) for d in wp.get_devices())
        raise DeviceError(f"unknown device {device!r}; available: {available}") from exc


def quiet_warp() -> None:
    """Keep Warp's start-up and module-load notes off stdout (so ``--json`` prints only JSON).

    Warp 1.19 replaced ``wp.config.quiet`` with log levels; both are handled.
    """
    if hasattr(wp, "LOG_WARNING"):
        wp.config.log_level = wp.LOG_WARNING
    else:
        wp.config.quiet = True
