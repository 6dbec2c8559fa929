"""The field-estimation workflow of Tong et al. for marker data, and its outputs.

Per load set: build the 5-tet hexahedral mesh on the marker grid, split the markers into
training and test markers (the paper: 249 / 50), estimate the homogeneous (E0, nu0)
(Eq. 13-14), estimate the heterogeneous field, and evaluate both on the test markers
(maximum and mean displacement error, Table 3).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from warptissue.errors import InputError
from warptissue.field.estimation import (
    CONSTRAINED_YOUNGS_ERROR,
    FieldEstimate,
    FieldProblem,
    HomogeneousEstimate,
    displacement_errors,
    estimate_field,
    fill_nodal_displacements,
    homogeneous_estimate,
)
from warptissue.field.fe import LinearTetModel
from warptissue.field.markers import (
    MarkerData,
    MarkerGrid,
    grid_from_markers,
    surface_interpolation,
)
from warptissue.io import atomic_path, write_csv, write_json
from warptissue.mesh import write_mesh

__all__ = ["LoadSetResult", "estimate_load_set", "split_markers", "write_load_set_outputs"]


def split_markers(
    marker_count: int, *, test_count: int, exclude: np.ndarray, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """Random train/test split of marker indices; ``exclude`` (loaded markers) stay in train.

    Returns:
        (train, test) sorted index arrays.
    """
    candidates = np.setdiff1d(np.arange(marker_count), exclude)
    if not 1 <= test_count < len(candidates):
        raise InputError(
            f"{test_count} test markers asked for (--test-markers); the {len(candidates)} "
            f"markers without a force allow 1 to {len(candidates) - 1}"
        )
    test = np.sort(np.random.default_rng(seed).choice(candidates, test_count, replace=False))
    return np.setdiff1d(np.arange(marker_count), test), test


@dataclass(frozen=True)
class LoadSetResult:
    """Everything estimated and measured for one load set.

    Attributes:
        load_set: Its label.
        grid: The marker grid and mesh.
        train, test: Marker indices.
        homogeneous: The linear homogeneous estimate (Eq. 13-14).
        field: The heterogeneous estimate.
        homogeneous_errors, field_errors: Test-marker errors {max_error_m, mean_error_m}.
        homogeneous_displacement_m, field_displacement_m: Nodal displacements of the forward
            solves, shape (node_count, 3).
        test_measured_m: Measured test-marker displacements, shape (t, 3).
        test_homogeneous_m, test_field_m: Predicted test-marker displacements, shape (t, 3).
        warnings: Implausible data or results, and parameters the data do not determine
            (:func:`load_set_warnings`), one sentence each.
    """

    load_set: str
    grid: MarkerGrid
    train: np.ndarray
    test: np.ndarray
    homogeneous: HomogeneousEstimate
    field: FieldEstimate
    homogeneous_errors: dict[str, float]
    field_errors: dict[str, float]
    homogeneous_displacement_m: np.ndarray
    field_displacement_m: np.ndarray
    test_measured_m: np.ndarray
    test_homogeneous_m: np.ndarray
    test_field_m: np.ndarray
    warnings: list[str]


def _check_markers_inside(markers: MarkerData, grid: MarkerGrid) -> None:
    """Refuse a marker outside the rectangle of the grid lines, naming it."""
    slack = 1e-9 + 1e-6 * max(float(np.ptp(grid.x_m)), float(np.ptp(grid.y_m)))
    for axis, lines in ((0, grid.x_m), (1, grid.y_m)):
        values = markers.reference_m[:, axis]
        outside = np.flatnonzero((values < lines[0] - slack) | (values > lines[-1] + slack))
        if outside.size:
            index = int(outside[0])
            name = "xy"[axis]
            raise InputError(
                f"marker {markers.markers[index]!r} at {name}0 = {values[index]:.6g} m lies "
                f"outside the outermost grid lines ({lines[0]:.6g} to {lines[-1]:.6g} m; each "
                f"line is the mean {name}0 of a row or column of markers): the markers must "
                "lie on a rectangular grid"
            )


def estimate_load_set(
    markers: MarkerData,
    forces: dict[str, np.ndarray],
    *,
    load_set: str,
    thickness_m: float,
    layers: int = 1,
    test_count: int = 50,
    seed: int = 0,
    objective: str = "displacement",
    gamma: float = 1e-5,
    method: str = "salm",
    max_iterations: int = 60,
    alpha_deviation: float | None = None,
    nu_deviation: float | None = None,
    device: str | None = None,
    progress: bool = False,
) -> LoadSetResult:
    """Run Tong et al.'s estimation for one load set of marker data.

    Args:
        markers: Marker positions and displacements (all load sets).
        forces: Marker label to applied force (3,) in N, for this load set.
        load_set: Which load set.
        thickness_m: Block thickness, metres; its base is fixed.
        layers: Hexahedra through the thickness.
        test_count: Markers held out for evaluation (the paper: 50 of 299).
        seed: Random seed of the split.
        objective: "displacement" (forward FE, fitted to the training markers) or "force"
            (Eq. 6 on nodal displacements filled in from the training markers).
        gamma: Tikhonov weight of Eq. 6 (normalized parameters).
        method: "salm" or "lm".
        max_iterations: LM iteration limit.
        alpha_deviation, nu_deviation: Assumed largest deviations of the true field from the
            homogeneous estimate, for the error bounds (:func:`estimate_field`).
        device: Warp device of the element kernels.
        progress: Show progress bars.

    Returns:
        The result.

    Raises:
        InputError: Unknown load set, no force, a force on a marker that is not on a mesh
            node, a bad split, or markers that move against the force.
    """
    if load_set not in markers.load_sets:
        raise InputError(
            f"load set {load_set!r} is not in the marker file, which has "
            f"{', '.join(markers.load_sets)}"
        )
    grid = grid_from_markers(markers.reference_m, thickness_m=thickness_m, layers=layers)
    _check_markers_inside(markers, grid)
    mesh = grid.mesh
    interpolation = surface_interpolation(mesh, markers.reference_m)
    force = np.zeros((mesh.node_count, 3))
    loaded = []
    for label, vector in forces.items():
        if label not in markers.markers:
            raise InputError(
                f"load set {load_set!r}: force on marker {label!r}, which is not in the marker file"
            )
        index = markers.markers.index(label)
        row = interpolation.getrow(index)
        if row.data.max() < 1.0 - 1e-6:
            raise InputError(
                f"load set {load_set!r}: loaded marker {label!r} is not on a grid node of "
                "the markers; forces act on nodes"
            )
        force[row.indices[np.argmax(row.data)]] += vector
        loaded.append(index)
    if not np.any(force):
        raise InputError(f"load set {load_set!r} has no applied force (all forces are zero)")
    train, test = split_markers(
        len(markers.markers), test_count=test_count, exclude=np.array(loaded), seed=seed
    )
    measured = markers.displacement_m[markers.load_sets.index(load_set)]
    model = LinearTetModel(mesh, device=device)
    nodal = fill_nodal_displacements(grid, interpolation[train], measured[train])
    base = mesh.node_set("zmin")
    problem = FieldProblem(model, base, force, interpolation[train], measured[train], nodal)
    try:
        homogeneous = homogeneous_estimate(problem)
    except InputError as exc:
        raise InputError(f"load set {load_set!r}: {exc.message}") from None
    field = estimate_field(
        problem,
        objective=objective,
        initial=homogeneous,
        gamma=gamma,
        method=method,
        max_iterations=max_iterations,
        alpha_deviation=alpha_deviation,
        nu_deviation=nu_deviation,
        progress=progress,
    )
    groups = model.group_count
    homogeneous_solution = model.solve(
        np.full(groups, homogeneous.alpha_Pa),
        np.full(groups, homogeneous.poissons_ratio),
        force,
        base,
    ).displacement_m
    field_solution = model.solve(field.alpha_Pa, field.poissons_ratio, force, base).displacement_m
    test_homogeneous = interpolation[test] @ homogeneous_solution
    test_field = interpolation[test] @ field_solution
    return LoadSetResult(
        load_set=load_set,
        grid=grid,
        train=train,
        test=test,
        homogeneous=homogeneous,
        field=field,
        homogeneous_errors=displacement_errors(test_homogeneous, measured[test]),
        field_errors=displacement_errors(test_field, measured[test]),
        homogeneous_displacement_m=homogeneous_solution,
        field_displacement_m=field_solution,
        test_measured_m=measured[test],
        test_homogeneous_m=test_homogeneous,
        test_field_m=test_field,
        warnings=load_set_warnings(grid, measured, homogeneous, field, thickness_m=thickness_m),
    )


PLAUSIBLE_YOUNGS_PA: tuple[float, float] = (10.0, 1e9)
"""Range of Young's modulus, Pa, outside which a homogeneous estimate is reported as
implausible for soft tissue and phantoms (a unit is likely wrong)."""


def load_set_warnings(
    grid: MarkerGrid,
    displacement_m: np.ndarray,
    homogeneous: HomogeneousEstimate,
    field: FieldEstimate,
    *,
    thickness_m: float,
) -> list[str]:
    """Say out loud what is implausible or not determined in a load set's estimate.

    Checks: a marker grid wider than 2 m or an E0 outside :data:`PLAUSIBLE_YOUNGS_PA` (a unit
    off by 1000), marker displacements above 10% of the thickness (beyond the small strains
    of linear elasticity), a fit that did not converge, parameters that the fit does not
    identify (:attr:`FieldEstimate.identifiability`, counted), and no cell whose
    E is constrained (:meth:`FieldEstimate.constrained_youngs`).

    Returns:
        One sentence per finding; empty when there is nothing to say.
    """
    messages = []
    span = max(float(np.ptp(grid.x_m)), float(np.ptp(grid.y_m)))
    if span > 2.0:
        messages.append(f"the markers span {span:.4g} m: are the marker coordinates in metres?")
    low, high = PLAUSIBLE_YOUNGS_PA
    if not low <= homogeneous.youngs_modulus_Pa <= high:
        messages.append(
            f"the homogeneous estimate E0 = {homogeneous.youngs_modulus_Pa:.4g} Pa is outside "
            f"{low:g} Pa to {high:g} Pa: are the coordinates in metres and the forces in "
            "newtons?"
        )
    largest = float(np.linalg.norm(displacement_m, axis=1).max())
    if largest > 0.1 * thickness_m:
        messages.append(
            f"the largest marker displacement, {largest:.4g} m, exceeds 10% of the thickness "
            f"({thickness_m:.4g} m): linear elasticity assumes small strains"
        )
    if not field.fit.success:
        messages.append(f"the field fit did not converge: {field.fit.message}")
    unidentified = field.identifiability
    if unidentified:
        messages.append(
            f"{len(unidentified)} of {field.fit.x.size} cell parameters are not identified "
            f"by the data (first: {unidentified[0]}); see 'identifiability' in the JSON"
        )
    if not field.constrained_youngs().any():
        messages.append(
            f"no cell's E is constrained to {100 * CONSTRAINED_YOUNGS_ERROR:g}% (regularization "
            "bias bound + 2 standard errors; smallest bound "
            f"{100 * float(field.youngs_error_bound.min()):.3g}%): "
            "read the cells CSV's error bounds before using a cell's E"
        )
    return messages


def _cell_centroids(grid: MarkerGrid) -> np.ndarray:
    """Hexahedron centres in cell order i + nx (j + ny k), shape (cells, 3), metres."""
    nx, ny, nz = grid.hex_shape
    i, j, k = (
        index.ravel(order="F")
        for index in np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij")
    )
    centres = [0.5 * (axis[:-1] + axis[1:]) for axis in (grid.x_m, grid.y_m, grid.z_m)]
    return np.column_stack([centres[0][i], centres[1][j], centres[2][k]])


def plot_field_maps(path: str | Path, result: LoadSetResult) -> Path:
    """Maps of E, nu and E's error bound per hexahedron of the top layer (Tong et al.,
    Figure 5, with the bound beside it), PNG.

    Constrained cells (:meth:`FieldEstimate.constrained_youngs`) are marked with a dot.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    grid, field = result.grid, result.field
    nx, ny, nz = grid.hex_shape
    top = slice((nz - 1) * nx * ny, nz * nx * ny)
    centroids = _cell_centroids(grid)[top]
    constrained = field.constrained_youngs()[top]
    figure, axes = plt.subplots(1, 3, figsize=(18, 3.8), constrained_layout=True)
    panels = (
        (field.youngs_modulus_Pa[top] / 1e3, "Young's modulus E (kPa)", None),
        (field.poissons_ratio[top], "Poisson's ratio nu", None),
        (100.0 * field.youngs_error_bound[top], "error bound of E (%, scale to 100)", 100.0),
    )
    for axis, (values, label, largest) in zip(axes, panels, strict=True):
        image = axis.pcolormesh(
            grid.x_m * 100,
            grid.y_m * 100,
            values.reshape(ny, nx),
            cmap="viridis",
            vmin=0.0 if largest else None,
            vmax=largest,
        )
        axis.plot(centroids[constrained, 0] * 100, centroids[constrained, 1] * 100, "w.", ms=4)
        axis.set_aspect("equal")
        axis.set_xlabel("x (cm)")
        axis.set_ylabel("y (cm)")
        axis.set_title(f"{label}, load set {result.load_set}")
        figure.colorbar(image, ax=axis, label=label)
    with atomic_path(path) as temporary:
        figure.savefig(temporary, dpi=120)
    plt.close(figure)
    return Path(path)


def write_load_set_outputs(out_dir: str | Path, result: LoadSetResult) -> dict[str, Path]:
    """Write ``field_<set>.json`` (summary), ``field_<set>_cells.csv`` (per hexahedron),
    ``field_<set>_test_markers.csv``, ``field_<set>.png`` (maps) and ``field_<set>.vtu``
    (mesh with E, nu, alpha and constrained flags as cell data, displacements as point data).
    """

    out = Path(out_dir)
    stem = f"field_{result.load_set}"
    field = result.field
    centroids = _cell_centroids(result.grid)
    summary = {
        "load_set": result.load_set,
        "homogeneous": {
            "youngs_modulus_Pa": result.homogeneous.youngs_modulus_Pa,
            "poissons_ratio": result.homogeneous.poissons_ratio,
            "test_max_error_m": result.homogeneous_errors["max_error_m"],
            "test_mean_error_m": result.homogeneous_errors["mean_error_m"],
        },
        "heterogeneous": {
            "objective": field.objective,
            "gamma": field.gamma,
            "method": field.fit.method,
            "status": field.fit.status,
            "message": field.fit.message,
            "iterations": field.fit.iterations,
            "test_max_error_m": result.field_errors["max_error_m"],
            "test_mean_error_m": result.field_errors["mean_error_m"],
            "constrained_youngs_cells": int(field.constrained_youngs().sum()),
            "constrained_poissons_ratio_cells": int(field.constrained_poissons_ratio().sum()),
            "cells": int(len(field.alpha_Pa)),
            "confidence": field.confidence_assumptions(),
            "identified": not field.identifiability,
            "identifiability": field.identifiability,
        },
        "train_markers": len(result.train),
        "test_markers": len(result.test),
        "warnings": result.warnings,
    }
    paths = {"json": write_json(out / f"{stem}.json", summary)}
    paths["cells_csv"] = write_csv(
        out / f"{stem}_cells.csv",
        {
            "cell": np.arange(len(field.alpha_Pa)),
            "x_m": centroids[:, 0],
            "y_m": centroids[:, 1],
            "z_m": centroids[:, 2],
            "youngs_modulus_Pa": field.youngs_modulus_Pa,
            "poissons_ratio": field.poissons_ratio,
            "alpha_Pa": field.alpha_Pa,
            "resolution_alpha": field.resolution_alpha,
            "resolution_nu": field.resolution_nu,
            "youngs_relative_error": field.youngs_relative_error,
            "youngs_bias_bound": field.youngs_bias_bound,
            "youngs_error_bound": field.youngs_error_bound,
            "constrained_youngs": field.constrained_youngs().astype(int),
            "poissons_ratio_error": field.poissons_ratio_error,
            "poissons_ratio_bias_bound": field.poissons_ratio_bias_bound,
            "poissons_ratio_error_bound": field.poissons_ratio_error_bound,
            "constrained_poissons_ratio": field.constrained_poissons_ratio().astype(int),
        },
    )
    paths["test_csv"] = write_csv(
        out / f"{stem}_test_markers.csv",
        {
            "marker_index": result.test,
            "measured_dz_m": result.test_measured_m[:, 2],
            "homogeneous_error_m": np.linalg.norm(
                result.test_homogeneous_m - result.test_measured_m, axis=1
            ),
            "heterogeneous_error_m": np.linalg.norm(
                result.test_field_m - result.test_measured_m, axis=1
            ),
        },
    )
    paths["png"] = plot_field_maps(out / f"{stem}.png", result)
    group = result.grid.mesh.tet_regions
    paths["vtu"] = write_mesh(
        out / f"{stem}.vtu",
        result.grid.mesh,
        point_data={
            "displacement_m": result.field_displacement_m,
            "homogeneous_displacement_m": result.homogeneous_displacement_m,
        },
        cell_data={
            "youngs_modulus_Pa": field.youngs_modulus_Pa[group],
            "poissons_ratio": field.poissons_ratio[group],
            "alpha_Pa": field.alpha_Pa[group],
            "constrained_youngs": field.constrained_youngs()[group].astype(np.int32),
        },
    )
    return paths
