import os

import pytest
import warp as wp

from warptissue.device import available_host_memory_bytes, resolve_device
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
