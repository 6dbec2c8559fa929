"""Choosing the Warp device that host wrappers launch on, the host memory available, and the
set-up of a worker process (a Dask worker, the live fit's process).

Warp is imported on first use, so that code that only asks for the memory (the mesh
generators) does not load it.
"""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

from warptissue.errors import DeviceError

if TYPE_CHECKING:
    import warp as wp

__all__ = [
    "CUDA_DRIVER_WARNING",
    "available_host_memory_bytes",
    "quiet_warp",
    "resolve_device",
    "terminal_interrupts_ignored",
    "thread_lock_for_progress_bars",
]


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
    """Keep Warp's start-up and module-load notes off stdout (so ``--json`` prints only JSON),
    and initialize Warp without its CUDA-driver warning.

    On a machine without a CUDA driver, Warp's native start-up prints "Could not find or load
    the NVIDIA CUDA driver" on stderr (through C, whatever the log level), whichever device is
    asked for; a run on the CPU there is no fault, and a request for ``cuda`` is refused by
    :func:`resolve_device` with a :class:`~warptissue.errors.DeviceError`. So Warp starts
    here with that one line held back (anything else it prints on stderr passes). Warp 1.19
    replaced ``wp.config.quiet`` with log levels; both are handled.
    """
    import warp as wp

    if hasattr(wp, "LOG_WARNING"):
        wp.config.log_level = wp.LOG_WARNING
    else:
        wp.config.quiet = True
    with _stderr_without(CUDA_DRIVER_WARNING):
        wp.init()


@contextlib.contextmanager
def terminal_interrupts_ignored() -> Iterator[None]:
    """Ignore SIGINT while worker processes start (a Dask local cluster's, the live fit's);
    they inherit that.

    Ctrl-C in a terminal interrupts every process of the foreground group: a worker would
    print a traceback and die under its task (leaving semaphores behind), and a spawned
    interpreter still importing would print one too. A Python started with SIGINT ignored
    never installs its KeyboardInterrupt handler, so only this process is interrupted, and it
    ends its workers itself. Restored on leaving (a Ctrl-C in between is lost). Outside the
    main thread (where signals cannot be set) nothing changes.
    """
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def thread_lock_for_progress_bars() -> None:
    """Give tqdm a thread lock in a worker process (a Dask worker, the live fit's process).

    tqdm's default lock holds a multiprocessing semaphore, made by the first bar (also a
    disabled one: every least-squares fit makes one); a worker ended under its task (Ctrl-C,
    a closed cluster, a terminated live fit) leaves it behind, and the resource tracker then
    prints its "leaked semaphore" warning. A worker shows no bars anyway.
    """
    import threading

    from tqdm import tqdm

    tqdm.set_lock(threading.RLock())


CUDA_DRIVER_WARNING = "Could not find or load the NVIDIA CUDA driver"
"""The part of Warp's start-up warning on a machine without a CUDA driver that
:func:`quiet_warp` holds back."""


@contextlib.contextmanager
def _stderr_without(text: str) -> Iterator[None]:
    """Hold back the lines containing ``text`` that native code writes to file descriptor 2
    inside the block; the other lines are written to stderr after it."""
    sys.stderr.flush()
    with tempfile.TemporaryFile() as held:
        saved = os.dup(2)
        os.dup2(held.fileno(), 2)
        try:
            yield
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            held.seek(0)
            lines = held.read().decode("utf-8", "replace").splitlines(keepends=True)
            kept = "".join(line for line in lines if text not in line)
            if kept:
                sys.stderr.write(kept)
                sys.stderr.flush()


def available_host_memory_bytes(
    *, meminfo: str | Path = "/proc/meminfo", cgroup_root: str | Path = "/sys/fs/cgroup"
) -> int:
    """Host memory available to a new allocation, bytes.

    Linux's ``MemAvailable`` (else the free physical pages), capped by the headroom of the
    process's memory cgroup where one sets a limit (a container's memory limit: v2
    ``memory.max``, v1 ``memory.limit_in_bytes``; its reclaimable page cache counts as free).
    In a container ``/proc/meminfo`` shows the whole machine, not the limit the container is
    killed at.

    Args:
        meminfo: The kernel's memory summary.
        cgroup_root: Where the cgroup file system is mounted.
    """
    available = None
    try:
        with open(meminfo, encoding="ascii") as lines:
            for line in lines:
                if line.startswith("MemAvailable:"):
                    available = 1024 * int(line.split()[1])
                    break
    except OSError:
        pass
    if available is None:
        available = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    headroom = _cgroup_headroom_bytes(Path(cgroup_root))
    return available if headroom is None else min(available, headroom)


_CGROUP_FILES = (
    ("memory.max", "memory.current", "memory.stat", "inactive_file"),
    (
        "memory/memory.limit_in_bytes",
        "memory/memory.usage_in_bytes",
        "memory/memory.stat",
        "total_inactive_file",
    ),
)
"""(limit, usage, statistics, reclaimable cache key) of cgroup v2 and v1."""


def _cgroup_headroom_bytes(root: Path) -> int | None:
    """Limit minus non-reclaimable usage of the memory cgroup, or None without a limit."""
    for limit_name, usage_name, stat_name, cache_key in _CGROUP_FILES:
        try:
            limit_text = (root / limit_name).read_text().strip()
            usage = int((root / usage_name).read_text().strip())
        except (OSError, ValueError):
            continue
        if limit_text == "max" or not limit_text.isdigit() or int(limit_text) >= 2**60:
            return None  # no limit (v1 writes a huge number)
        cache = 0
        with contextlib.suppress(OSError, ValueError):
            for line in (root / stat_name).read_text().splitlines():
                key, _, value = line.partition(" ")
                if key == cache_key:
                    cache = int(value)
        return max(0, int(limit_text) - max(0, usage - cache))
    return None
