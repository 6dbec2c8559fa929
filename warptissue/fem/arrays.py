"""The array library of the Newton loop: CuPy on a CUDA device, NumPy on the CPU.

The Newton loop (:mod:`warptissue.fem.newton`) keeps its state, residual, directions and
masks as arrays of one library, chosen by the assembler's device:

- On a CUDA device where CuPy imports, CuPy arrays on that device, run on Warp's stream.
  The assembler's Warp arrays are viewed without a copy (``__cuda_array_interface__``) and
  CuPy arrays are handed back to Warp kernels the same way, so nodal arrays never cross to
  the host inside a load increment; the host reads scalars (norms, slopes, energies).
- On the CPU, NumPy arrays; Warp's CPU arrays are NumPy views already.
- On a CUDA device without CuPy (the CG fallback of a bare Warp install), NumPy arrays
  copied from and to the device at each use, as before.

:class:`DeviceArrays` is the one place that knows which.
"""

from __future__ import annotations

import contextlib
import importlib.util
import math
from typing import Any

import numpy as np
import warp as wp

__all__ = ["DeviceArrays"]


class DeviceArrays:
    """Array operations of the Newton loop on one Warp device.

    Args:
        device: The Warp device the assembler and linear solver work on.

    Attributes:
        xp: The array module: ``cupy`` where the arrays stay on a CUDA device, else ``numpy``.
        resident: Whether nodal arrays stay on the device (CuPy on CUDA).
    """

    def __init__(self, device: wp.Device) -> None:
        self.device = device
        self.resident = device.is_cuda and importlib.util.find_spec("cupy") is not None
        if self.resident:
            import cupy

            self.xp: Any = cupy
        else:
            self.xp = np
        self._cupy_stream: Any = None

    @property
    def _stream(self) -> Any:
        """Warp's stream of the device as a CuPy stream (made at first use)."""
        if self._cupy_stream is None:
            self._cupy_stream = self.xp.cuda.Stream.from_external(self.device.stream)
        return self._cupy_stream

    def context(self) -> contextlib.AbstractContextManager:
        """Enter the device and Warp's stream for the array module's work (nothing on NumPy).

        CuPy's operations and Warp's launches then run in order on one stream, so no
        synchronization is needed between them; reading a scalar waits for that stream only.
        """
        if not self.resident:
            return contextlib.nullcontext()
        stack = contextlib.ExitStack()
        stack.enter_context(self.xp.cuda.Device(self.device.ordinal))
        stack.enter_context(self._stream)
        return stack

    def view(self, array: wp.array) -> Any:
        """A vec3d Warp array (N,) as an (N, 3) float64 array of the module (any other Warp
        array as its own shape and type): a view sharing its memory on CUDA (CuPy) and on
        the CPU (NumPy), a host copy otherwise."""
        if self.resident:
            return self.xp.asarray(array)
        return array.numpy()

    def asarray(self, values: Any) -> Any:
        """``values`` (NumPy or the module's) as a float64 array of the module, copied to the
        device where it is on the host."""
        return self.xp.asarray(values, dtype=self.xp.float64)

    def host(self, values: Any) -> np.ndarray:
        """``values`` as a NumPy array (a copy from the device where resident)."""
        if self.resident and not isinstance(values, np.ndarray):
            return self.xp.asnumpy(values, stream=self._stream)
        return np.asarray(values)

    def warp(self, values: Any) -> wp.array:
        """A contiguous float64 (N, 3) array of the module as a vec3d Warp array (N,) on the
        device, sharing its memory (the array must stay alive while Warp uses it)."""
        if self.resident:
            return wp.array(values, dtype=wp.vec3d, device=self.device)
        values = np.ascontiguousarray(values, dtype=np.float64)
        if self.device.is_cpu:
            return wp.array(values, dtype=wp.vec3d, device=self.device, copy=False)
        return wp.array(values, dtype=wp.vec3d, device=self.device)

    def floats(self, *values: Any) -> tuple[float, ...]:
        """0-d arrays (or Python numbers) as Python floats, read from the device at once."""
        if not self.resident:
            return tuple(float(value) for value in values)
        xp = self.xp
        stacked = xp.stack([xp.asarray(value, dtype=xp.float64).reshape(()) for value in values])
        return tuple(float(value) for value in xp.asnumpy(stacked, stream=self._stream))

    def squared_norm(self, values: Any) -> Any:
        """Sum of squares of all entries, a 0-d array (read it with :meth:`floats`)."""
        if self.resident:
            return self.xp.sum(values * values)
        # np.einsum sums in NumPy's own loop; np.linalg.norm goes through the BLAS dot
        # product, whose thread start-up costs about 100x more on the (N, 3) arrays of the
        # Newton loop on a busy 2-core machine.
        return np.einsum("ij,ij->", values, values)

    def norm(self, values: Any) -> float:
        """Euclidean norm of all entries (one scalar read)."""
        return math.sqrt(self.floats(self.squared_norm(values))[0])

    def dot(self, a: Any, b: Any) -> Any:
        """Sum of the entrywise product, a 0-d array."""
        return self.xp.sum(a * b)

    def row_norms(self, values: Any) -> Any:
        """Euclidean norm of each row of an (N, 3) array, shape (N,)."""
        if self.resident:
            return self.xp.sqrt(self.xp.sum(values * values, axis=1))
        return np.sqrt(np.einsum("ij,ij->i", values, values))
