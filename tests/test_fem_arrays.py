"""The Newton loop's array library (:class:`warptissue.fem.arrays.DeviceArrays`) on every
Warp device: views share the Warp arrays' memory both ways, and the scalar reductions equal
NumPy's."""

from __future__ import annotations

import importlib.util
import math

import numpy as np
import pytest
import warp as wp

from warptissue.fem.arrays import DeviceArrays


def test_the_library_follows_the_device(device):
    arrays = DeviceArrays(wp.get_device(device))
    has_cupy = importlib.util.find_spec("cupy") is not None
    assert arrays.resident == (device.startswith("cuda") and has_cupy)
    assert (arrays.xp is np) == (not arrays.resident)


def test_views_share_memory_with_warp_both_ways(device, rng):
    """A Warp array seen through :meth:`view` shows later kernel writes, and a module array
    handed to Warp through :meth:`warp` shows Warp's writes (no copy either way, where the
    arrays are resident or on the CPU)."""
    arrays = DeviceArrays(wp.get_device(device))
    values = rng.standard_normal((11, 3))
    with arrays.context():
        source = wp.array(values, dtype=wp.vec3d, device=device)
        view = arrays.view(source)
        np.testing.assert_array_equal(arrays.host(view), values)
        source.fill_(wp.vec3d(1.0, 2.0, 3.0))
        if arrays.resident or device == "cpu":
            np.testing.assert_array_equal(arrays.host(view), np.tile([1.0, 2.0, 3.0], (11, 1)))
            module_array = arrays.asarray(values)
            shared = arrays.warp(module_array)
            shared.zero_()
            np.testing.assert_array_equal(arrays.host(module_array), 0.0)
        else:  # a CUDA device without CuPy: copies
            np.testing.assert_array_equal(view, values)
            np.testing.assert_array_equal(arrays.warp(values).numpy(), values)


def test_scalar_reductions_equal_numpy(device, rng):
    arrays = DeviceArrays(wp.get_device(device))
    a, b = rng.standard_normal((9, 3)), rng.standard_normal((9, 3))
    with arrays.context():
        x, y = arrays.asarray(a), arrays.asarray(b)
        squared, dot = arrays.floats(arrays.squared_norm(x), arrays.dot(x, y))
        assert squared == pytest.approx(np.sum(a * a), rel=1e-14)
        assert dot == pytest.approx(np.sum(a * b), rel=1e-13)
        assert arrays.norm(x) == pytest.approx(np.linalg.norm(a), rel=1e-14)
        np.testing.assert_allclose(
            arrays.host(arrays.row_norms(x)), np.linalg.norm(a, axis=1), rtol=1e-14
        )
        x[4, 1] = math.nan
        assert math.isnan(arrays.floats(arrays.squared_norm(x))[0])
