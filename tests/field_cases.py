"""Synthetic marker cases for the field estimation (a test and example fixture).

Two cases, each a block with its base fixed, markers on a grid of its top face, a point force
at one marker, a known heterogeneous (E, nu) per hexahedron solved with the same linear FE,
and Gaussian marker noise:

- the memory pillow of Tong et al. (:func:`synthetic_pillow`): a 50 x 30 x 10 cm block,
  299 markers on a 23-column by 13-row grid, a vertical force at the 150th marker (7th row,
  12th column), the six force levels A-F of their Table 2 (forces corrected by WCFM_SVM),
  and a smooth field around Table 2's linear estimates;
- an independent slab (:func:`synthetic_slab`): 12 x 8 x 3 cm, 9 x 7 markers, an oblique
  force off the centre, a stiff circular inclusion (3x) on a modulus gradient and a Poisson's
  ratio gradient; nothing of it comes from the pillow.

This module lives in tests/ (it is not part of the package); scripts that use it put the
tests/ folder on ``sys.path``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from warptissue.field.fe import LinearTetModel, alpha_from_youngs
from warptissue.field.markers import MarkerGrid, grid_from_markers
from warptissue.io import write_csv

__all__ = [
    "PILLOW_FORCE_N",
    "PILLOW_LINEAR_ESTIMATE",
    "SLAB_SIZE_M",
    "SyntheticCase",
    "pillow_truth",
    "slab_truth",
    "synthetic_pillow",
    "synthetic_slab",
    "write_case_files",
]

PILLOW_FORCE_N: dict[str, float] = {
    "A": 18.5814,
    "B": 19.9533,
    "C": 21.4443,
    "D": 24.0542,
    "E": 27.0678,
    "F": 30.1766,
}
"""Tong et al., Table 2: the WCFM_SVM-corrected forces of deformation sets A-F, N."""

PILLOW_LINEAR_ESTIMATE: dict[str, tuple[float, float]] = {
    "A": (7.4065e3, 0.07),
    "B": (7.9424e3, 0.06),
    "C": (6.2843e3, 0.06),
    "D": (7.2075e3, 0.06),
    "E": (7.3448e3, 0.07),
    "F": (8.4128e3, 0.06),
}
"""Tong et al., Table 2: the linear-FEM (E in Pa, nu) of each deformation set."""


@dataclass(frozen=True)
class SyntheticCase:
    """One synthetic load set.

    Attributes:
        grid: The marker grid and its 5-tet mesh.
        marker_reference_m: Marker positions before loading, shape (k, 3), metres.
        marker_displacement_m: Noisy measured displacements, shape (k, 3), metres.
        exact_displacement_m: Noise-free nodal displacements, shape (node_count, 3).
        force_N: Nodal forces, shape (node_count, 3), newtons.
        loaded_marker: Index of the loaded marker (0-based; the paper's 150th point).
        youngs_modulus_Pa: True E per hexahedron, shape (groups,).
        poissons_ratio: True nu per hexahedron, shape (groups,).
    """

    grid: MarkerGrid
    marker_reference_m: np.ndarray
    marker_displacement_m: np.ndarray
    exact_displacement_m: np.ndarray
    force_N: np.ndarray
    loaded_marker: int
    youngs_modulus_Pa: np.ndarray
    poissons_ratio: np.ndarray


def pillow_truth(
    centroid_m: np.ndarray, *, load_set: str, length_m: float, width_m: float
) -> tuple[np.ndarray, np.ndarray]:
    """Smooth ground-truth (E, nu) at cell centroids around Table 2's values of a load set.

    E = E_T2 (1 + 0.5 sin(2 pi x / L) cos(pi (y - W/2) / W)) and
    nu = nu_T2 + 0.02 cos(2 pi x / L) (1 + y / W): a +-50% modulus pattern that changes
    across the loaded centre, and a Poisson's ratio between about 0.03 and 0.11.
    """
    youngs, nu = PILLOW_LINEAR_ESTIMATE[load_set]
    x, y = centroid_m[:, 0] / length_m, centroid_m[:, 1] / width_m
    youngs_field = youngs * (1.0 + 0.5 * np.sin(2.0 * np.pi * x) * np.cos(np.pi * (y - 0.5)))
    nu_field = nu + 0.02 * np.cos(2.0 * np.pi * x) * (1.0 + y)
    return youngs_field, nu_field


def _synthetic_case(
    *,
    columns: int,
    rows: int,
    length_m: float,
    width_m: float,
    thickness_m: float,
    layers: int,
    truth: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
    loaded_marker: int,
    force_vector_N: np.ndarray,
    noise_m: float,
    seed: int,
    device: str | None,
) -> SyntheticCase:
    """A marker grid on a block, the true field per cell, the exact solve and noisy markers.

    Markers are numbered row by row (``columns`` per row), x along the length, y along the
    width; the force acts at marker ``loaded_marker``.
    """
    xs = np.linspace(0.0, length_m, columns)
    ys = np.linspace(0.0, width_m, rows)
    gx, gy = np.meshgrid(xs, ys)
    reference = np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, thickness_m)])
    grid = grid_from_markers(reference, thickness_m=thickness_m, layers=layers)
    mesh = grid.mesh
    model = LinearTetModel(mesh, device=device)
    centroids = np.zeros((model.group_count, 3))
    np.add.at(centroids, mesh.tet_regions, mesh.points[mesh.tets].mean(axis=1) / 5.0)
    youngs, nu = truth(centroids)
    loaded_node = int(grid.top_nodes.ravel()[loaded_marker])
    force = np.zeros((mesh.node_count, 3))
    force[loaded_node] = force_vector_N
    solution = model.solve(alpha_from_youngs(youngs, nu), nu, force, mesh.node_set("zmin"))
    exact = solution.displacement_m
    noise = np.random.default_rng(seed).normal(0.0, noise_m, size=reference.shape)
    measured = exact[grid.top_nodes.ravel()] + noise
    return SyntheticCase(grid, reference, measured, exact, force, loaded_marker, youngs, nu)


def synthetic_pillow(
    *,
    load_set: str = "F",
    columns: int = 23,
    rows: int = 13,
    length_m: float = 0.50,
    width_m: float = 0.30,
    thickness_m: float = 0.10,
    layers: int = 1,
    noise_m: float = 2e-4,
    seed: int = 2017,
    device: str | None = None,
) -> SyntheticCase:
    """Generate one load set of the synthetic pillow.

    Markers are numbered row by row (23 per row); the load acts in -z at the middle marker,
    index (rows // 2) * columns + columns // 2, which is the paper's 150th point for 13 x 23.

    Args:
        load_set: "A" to "F" (Table 2 force and linear estimate).
        columns, rows: Marker grid (x along the length, y along the width).
        length_m, width_m, thickness_m: Block size, metres.
        layers: Hexahedra through the thickness.
        noise_m: Standard deviation of the Gaussian marker noise per component, metres.
        seed: Random seed of the noise.
        device: Warp device.

    Returns:
        The synthetic load set.
    """
    return _synthetic_case(
        columns=columns,
        rows=rows,
        length_m=length_m,
        width_m=width_m,
        thickness_m=thickness_m,
        layers=layers,
        truth=lambda centroids: pillow_truth(
            centroids, load_set=load_set, length_m=length_m, width_m=width_m
        ),
        loaded_marker=(rows // 2) * columns + columns // 2,
        force_vector_N=np.array([0.0, 0.0, -PILLOW_FORCE_N[load_set]]),
        noise_m=noise_m,
        seed=seed,
        device=device,
    )


SLAB_SIZE_M: tuple[float, float, float] = (0.12, 0.08, 0.03)
"""Length (x), width (y) and thickness (z) of the independent slab, metres."""


def slab_truth(
    centroid_m: np.ndarray, *, inclusion_ratio: float = 3.0
) -> tuple[np.ndarray, np.ndarray]:
    """The slab's true (E, nu) at cell centroids.

    E = 12 kPa (1 + 0.3 x / L), times ``inclusion_ratio`` inside a cylinder of radius 0.2 W
    about (0.35 L, 0.55 W); nu = 0.30 + 0.05 y / W.
    """
    length, width, _ = SLAB_SIZE_M
    x, y = centroid_m[:, 0], centroid_m[:, 1]
    inside = np.hypot(x - 0.35 * length, y - 0.55 * width) < 0.2 * width
    youngs = 12e3 * (1.0 + 0.3 * x / length) * np.where(inside, inclusion_ratio, 1.0)
    return youngs, 0.30 + 0.05 * y / width


def synthetic_slab(
    *,
    noise_m: float = 0.0,
    force_N: tuple[float, float, float] = (0.5, 0.0, -2.0),
    inclusion_ratio: float = 3.0,
    columns: int = 9,
    rows: int = 7,
    seed: int = 3,
    device: str | None = None,
) -> SyntheticCase:
    """Generate the independent slab (:func:`slab_truth`), loaded at the marker left of the
    centre, index (rows // 2) * columns + columns // 2 - 1.

    Args:
        noise_m: Standard deviation of the Gaussian marker noise per component, metres.
        force_N: The force at the loaded marker, N.
        inclusion_ratio: Modulus ratio of the inclusion to its surroundings.
        columns, rows: Marker grid.
        seed: Random seed of the noise.
        device: Warp device.

    Returns:
        The synthetic load set.
    """
    length, width, thickness = SLAB_SIZE_M
    return _synthetic_case(
        columns=columns,
        rows=rows,
        length_m=length,
        width_m=width,
        thickness_m=thickness,
        layers=1,
        truth=lambda centroids: slab_truth(centroids, inclusion_ratio=inclusion_ratio),
        loaded_marker=(rows // 2) * columns + columns // 2 - 1,
        force_vector_N=np.asarray(force_N, dtype=np.float64),
        noise_m=noise_m,
        seed=seed,
        device=device,
    )


def write_case_files(
    out_dir: str | Path,
    cases: dict[str, SyntheticCase],
    *,
    markers_name: str = "markers.csv",
    forces_name: str = "forces.csv",
    decimals: int | None = None,
) -> tuple[Path, Path]:
    """Write synthetic load sets (label to case) as a marker file and a force file (formats
    of :mod:`warptissue.field.markers`), ``markers_name`` and ``forces_name`` in ``out_dir``.
    Marker coordinates are rounded to ``decimals`` decimal places of a metre when given.

    Returns:
        The two paths.
    """
    out = Path(out_dir)
    labels, markers, before, after, force_rows = [], [], [], [], []
    for label, case in cases.items():
        count = len(case.marker_reference_m)
        labels += [label] * count
        markers += [f"M{k + 1:03d}" for k in range(count)]
        before.append(case.marker_reference_m)
        after.append(case.marker_reference_m + case.marker_displacement_m)
        node = case.grid.top_nodes.ravel()[case.loaded_marker]
        force_rows.append((label, f"M{case.loaded_marker + 1:03d}", *case.force_N[node]))
    before, after = np.concatenate(before), np.concatenate(after)
    if decimals is not None:
        before, after = np.round(before, decimals), np.round(after, decimals)
    markers_path = write_csv(
        out / markers_name,
        {
            "load_set": labels,
            "marker": markers,
            "x0_m": before[:, 0],
            "y0_m": before[:, 1],
            "z0_m": before[:, 2],
            "x1_m": after[:, 0],
            "y1_m": after[:, 1],
            "z1_m": after[:, 2],
        },
    )
    columns = list(zip(*force_rows, strict=True))
    forces_path = write_csv(
        out / forces_name,
        {
            "load_set": columns[0],
            "marker": columns[1],
            "fx_N": columns[2],
            "fy_N": columns[3],
            "fz_N": columns[4],
        },
    )
    return markers_path, forces_path
