"""Choosing the Warp device that host wrappers launch on, and the host memory available.

Warp is imported on first use, so that code that only asks for the memory (the mesh
generators) does not load it.
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING

from warptissue.errors import DeviceError

if TYPE_CHECKING:
    import warp as wp

__all__ = ["available_host_memory_bytes", "quiet_warp", "resolve_device"]


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
    import warp as wp

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
    import warp as wp

    if hasattr(wp, "LOG_WARNING"):
        wp.config.log_level = wp.LOG_WARNING
    else:
        wp.config.quiet = True


def available_host_memory_bytes() -> int:
    """Host memory available to a new allocation, bytes (Linux ``MemAvailable``, else the
    free physical pages)."""
    try:
        with open("/proc/meminfo", encoding="ascii") as meminfo:
            for line in meminfo:
                if line.startswith("MemAvailable:"):
                    return 1024 * int(line.split()[1])
    except OSError:
        pass
    return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
