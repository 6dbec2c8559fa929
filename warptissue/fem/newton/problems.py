"""What the Newton loop solves: K problems in one mesh, each with its own prescribed dofs.

One problem is a mesh with its :class:`DirichletConditions`. K problems packed into one mesh
(:func:`warptissue.fem.packing.pack_meshes`: each problem's nodes one contiguous range) share
one assembly, one factorization and one line-search evaluation per Newton iteration; every
decision of the loop (step length, damping, convergence, cutbacks) is taken per problem from
sums over its node range (:class:`Problems`). K = 1 is the single run: its sums are the plain
reductions over the mesh, so one problem alone takes exactly the path it always took.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from warptissue.errors import InputError
from warptissue.fem.arrays import DeviceArrays

__all__ = ["DirichletConditions", "Problems"]


@dataclass(frozen=True)
class DirichletConditions:
    """Prescribed displacement components ``u[node, component] = load * value_per_load``.

    Attributes:
        nodes: Node indices, shape (k,), int.
        components: 0, 1 or 2 (x, y, z) for each entry, shape (k,), int.
        values_per_load: Displacement per unit load, shape (k,), m (0 for a fixed dof).
    """

    nodes: np.ndarray
    components: np.ndarray
    values_per_load: np.ndarray

    def __post_init__(self) -> None:
        nodes = np.asarray(self.nodes, dtype=np.int64).ravel()
        comps = np.asarray(self.components, dtype=np.int64).ravel()
        values = np.asarray(self.values_per_load, dtype=np.float64).ravel()
        if not (nodes.shape == comps.shape == values.shape):
            raise InputError("nodes, components and values_per_load must have the same length")
        if comps.size and (comps.min() < 0 or comps.max() > 2):
            raise InputError("components must be 0, 1 or 2", value=comps)
        if not np.all(np.isfinite(values)):
            raise InputError("prescribed values must be finite")
        keys = nodes * 3 + comps
        order = np.argsort(keys, kind="stable")
        keys, values = keys[order], values[order]
        first = np.ones(len(keys), dtype=bool)
        first[1:] = keys[1:] != keys[:-1]
        # duplicates must agree
        group = np.cumsum(first) - 1
        reference = values[first][group]
        if np.any(np.abs(values - reference) > 1e-12 * (1.0 + np.abs(reference))):
            bad = int(keys[np.flatnonzero(np.abs(values - reference) > 0)[0]])
            raise InputError(
                f"conflicting prescribed values for node {bad // 3}, component {bad % 3}"
            )
        object.__setattr__(self, "nodes", (keys[first] // 3).astype(np.int64))
        object.__setattr__(self, "components", (keys[first] % 3).astype(np.int64))
        object.__setattr__(self, "values_per_load", values[first])

    @staticmethod
    def combine(*conditions: DirichletConditions) -> DirichletConditions:
        """Union of several condition sets (shared dofs must prescribe the same value)."""
        return DirichletConditions(
            np.concatenate([c.nodes for c in conditions]),
            np.concatenate([c.components for c in conditions]),
            np.concatenate([c.values_per_load for c in conditions]),
        )

    def mask(self, node_count: int) -> np.ndarray:
        """1.0 where a dof is prescribed, else 0.0, shape (node_count, 3)."""
        out = np.zeros((node_count, 3))
        out[self.nodes, self.components] = 1.0
        return out

    def values(self, load: float, node_count: int) -> np.ndarray:
        """Prescribed displacement field at ``load`` (0 on free dofs), shape (node_count, 3)."""
        out = np.zeros((node_count, 3))
        out[self.nodes, self.components] = load * self.values_per_load
        return out


class Problems:
    """K problems' node ranges in one mesh, and the per-problem reductions of the Newton loop.

    A reduction is made in two parts: :meth:`dot` and :meth:`squared` build it in the loop's
    array library (on a GPU, on the device), and :meth:`read` brings any number of them to
    the host in one copy, as (K,) arrays. For K = 1 they are the whole-mesh reductions of
    :class:`warptissue.fem.arrays.DeviceArrays`; for K > 1 each problem's range is gathered
    into one row of a zero-padded (K, longest range) array and the rows are summed (no
    atomics, so the sums are the same from run to run; a weighted ``bincount`` over the
    node-to-problem map took 64 % of a 16-problem H100 run).

    Args:
        arrays: The Newton loop's array library.
        node_offsets: First node of each problem and the node count at the end, (K + 1,).

    Attributes:
        count: K.
        offsets: ``node_offsets`` as int64.
    """

    def __init__(self, arrays: DeviceArrays, node_offsets: Any) -> None:
        self.arrays = arrays
        self.offsets = np.asarray(node_offsets, dtype=np.int64)
        if self.offsets.ndim != 1 or self.offsets.size < 2 or np.any(np.diff(self.offsets) < 0):
            raise InputError("node_offsets must be increasing, one more than the problems")
        self.count = self.offsets.size - 1
        self._rows: Any = None
        self._node_problem: Any = None
        if self.count > 1:
            sizes = np.diff(self.offsets)
            node_count = int(self.offsets[-1])
            rows = np.full((self.count, int(sizes.max())), node_count, dtype=np.int64)
            for k in range(self.count):
                rows[k, : sizes[k]] = np.arange(self.offsets[k], self.offsets[k + 1])
            self._rows = arrays.xp.asarray(rows)
            self._node_problem = arrays.xp.asarray(np.repeat(np.arange(self.count), sizes))

    def nodes(self, problem: int) -> slice:
        """Problem ``problem``'s node range."""
        return slice(int(self.offsets[problem]), int(self.offsets[problem + 1]))

    def node_count(self, problem: int) -> int:
        """Problem ``problem``'s number of nodes."""
        return int(self.offsets[problem + 1] - self.offsets[problem])

    def dot(self, a: Any, b: Any) -> Any:
        """Per-problem sums of ``a * b`` (both (N, 3) arrays of the library), to :meth:`read`."""
        if self.count == 1:
            return self.arrays.dot(a, b)
        return (a * b).sum(axis=1)

    def squared(self, values: Any) -> Any:
        """Per-problem sums of squares of an (N, 3) array of the library, to :meth:`read`."""
        if self.count == 1:
            return self.arrays.squared_norm(values)
        return (values * values).sum(axis=1)

    def read(self, *reductions: Any, scalars: Any = None) -> list[np.ndarray]:
        """The reductions' values, each as a (K,) NumPy array, in one copy from the device.

        ``scalars``: an array of the library (any shape, e.g. an assembly's energies and
        smallest J per problem) read in the same copy and returned last, flattened (a copy).
        """
        xp = self.arrays.xp
        if self.count == 1 and scalars is None:
            return [np.array([value]) for value in self.arrays.floats(*reductions)]
        if self.count == 1:
            sums = [xp.asarray(each, dtype=xp.float64).reshape(1) for each in reductions]
        elif reductions:
            padded = xp.zeros((len(reductions), int(self.offsets[-1]) + 1))
            padded[:, :-1] = xp.stack(reductions)
            sums = [padded[:, self._rows].sum(axis=2).ravel()]
        else:
            sums = []
        if scalars is not None:
            sums.append(xp.ravel(xp.asarray(scalars, dtype=xp.float64)))
        host = self.arrays.host(xp.concatenate(sums)) if sums else np.zeros(0)
        count = self.count
        values = [host[i * count : (i + 1) * count] for i in range(len(reductions))]
        if scalars is not None:
            values.append(np.array(host[len(reductions) * count :]))
        return values

    def per_node(self, values: np.ndarray) -> Any:
        """A per-problem value (K,) at every node: a float for K = 1, else an (N, 1) array."""
        if self.count == 1:
            return float(values[0])
        xp = self.arrays.xp
        return xp.asarray(values, dtype=xp.float64)[self._node_problem][:, None]

    def where(self, choose: np.ndarray, a: Any, b: Any) -> Any:
        """Problem-wise choice between two nodal arrays: ``a`` where ``choose`` (K,) holds."""
        if choose.all():
            return a
        if not choose.any():
            return b
        mask = self.per_node(choose.astype(np.float64))
        return self.arrays.xp.where(mask > 0.5, a, b)
