import os
import signal
import subprocess
import sys
import threading

import pytest
import warp as wp

from warptissue.device import (
    available_host_memory_bytes,
    resolve_device,
    terminal_interrupts_ignored,
)
from warptissue.errors import DeviceError


def test_resolves_cpu_and_passes_devices_through():
    cpu = resolve_device("cpu")
    assert cpu.is_cpu
    assert resolve_device(cpu) is cpu
    assert resolve_device(None) == wp.get_device()


@pytest.mark.skipif(wp.is_cuda_available(), reason="only meaningful without a GPU")
def test_cuda_without_gpu_is_a_device_error():
    with pytest.raises(DeviceError, match="no CUDA device"):
        resolve_device("cuda")


def test_unknown_device_lists_available():
    with pytest.raises(DeviceError, match="available: .*cpu"):
        resolve_device("tpu")


def test_available_host_memory_is_positive_and_below_the_total():
    available = available_host_memory_bytes()
    assert 0 < available <= os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")


def _cgroup(root, files: dict[str, str]):
    for name, text in files.items():
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        (root / name).write_text(text)
    return root


def test_a_container_limit_caps_the_available_memory(tmp_path):
    """In a container /proc/meminfo shows the whole machine: the cgroup's limit, less what
    the container uses (its reclaimable page cache counted as free), is what is available."""
    meminfo = tmp_path / "meminfo"
    meminfo.write_text("MemTotal:       16000000 kB\nMemAvailable:    8388608 kB\n")
    machine = 8 << 30
    assert available_host_memory_bytes(meminfo=meminfo, cgroup_root=tmp_path / "none") == machine
    v2 = _cgroup(
        tmp_path / "v2",
        {"memory.max": "2147483648\n", "memory.current": "1073741824\n",
         "memory.stat": "anon 1\ninactive_file 268435456\n"},
    )  # fmt: skip
    # 2 GiB limit, 1 GiB used of which 0.25 GiB reclaimable cache: 1.25 GiB left.
    assert available_host_memory_bytes(meminfo=meminfo, cgroup_root=v2) == (1280 << 20)
    v1 = _cgroup(
        tmp_path / "v1",
        {"memory/memory.limit_in_bytes": "1073741824", "memory/memory.usage_in_bytes": "0",
         "memory/memory.stat": "total_inactive_file 0\n"},
    )  # fmt: skip
    assert available_host_memory_bytes(meminfo=meminfo, cgroup_root=v1) == 1 << 30
    unlimited = _cgroup(tmp_path / "max", {"memory.max": "max", "memory.current": "5"})
    assert available_host_memory_bytes(meminfo=meminfo, cgroup_root=unlimited) == machine
    v1_unlimited = _cgroup(
        tmp_path / "v1max",
        {"memory/memory.limit_in_bytes": "9223372036854771712",
         "memory/memory.usage_in_bytes": "17741119488"},
    )  # fmt: skip
    assert available_host_memory_bytes(meminfo=meminfo, cgroup_root=v1_unlimited) == machine


def test_quiet_warp_starts_warp_without_a_word():
    """Issue 36: on a machine without a CUDA driver, Warp's start-up warned "Could not find or
    load the NVIDIA CUDA driver" on stderr even for the CPU; after :func:`quiet_warp` a CPU
    run starts silently (on a machine with CUDA there is nothing to say either)."""
    code = (
        "from warptissue.device import quiet_warp, resolve_device\n"
        "quiet_warp()\n"
        "resolve_device('cpu')\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True
    )
    assert (done.stdout, done.stderr) == ("", "")


def test_thread_lock_for_progress_bars_makes_no_semaphore(tmp_path):
    """In a fresh process (tqdm's lock is per process): after the call, a bar makes no
    multiprocessing semaphore (counted by wrapping SemLock's constructor; without the call a
    disabled bar makes one)."""
    script = """
import multiprocessing.synchronize as synchronize
made = []
original = synchronize.SemLock.__init__
def counting(self, *args, **kwargs):
    made.append(1)
    original(self, *args, **kwargs)
synchronize.SemLock.__init__ = counting
from tqdm import tqdm
from warptissue.device import thread_lock_for_progress_bars
thread_lock_for_progress_bars()
with tqdm(total=1, disable=True) as bar:
    bar.update(1)
print(len(made))
"""
    done = subprocess.run(
        [sys.executable, "-c", script], cwd=tmp_path, capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "0"


def test_terminal_interrupts_ignored_inside_restored_after_and_untouched_off_main():
    before = signal.getsignal(signal.SIGINT)
    with terminal_interrupts_ignored():
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    assert signal.getsignal(signal.SIGINT) is before
    seen = []

    def off_main() -> None:
        with terminal_interrupts_ignored():
            seen.append(signal.getsignal(signal.SIGINT))

    thread = threading.Thread(target=off_main)
    thread.start()
    thread.join()
    assert seen == [before]
