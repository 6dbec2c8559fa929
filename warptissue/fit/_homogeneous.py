"""A homogeneous test's record: measured force and displacement as nominal stress and strain
(:class:`HomogeneousTest`, :func:`read_homogeneous_test`); sign convention and the models fitted
to it: :mod:`warptissue.fit.hyperelastic`."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from warptissue.errors import InputError
from warptissue.io import read_experiment_csv
from warptissue.materials import (
    HyperelasticMaterial,
)

LOADINGS: dict[str, tuple[str, float]] = {
    "tension": ("uniaxial", 1.0),
    "compression": ("uniaxial", -1.0),
    "equibiaxial": ("equibiaxial", 1.0),
    "planar": ("planar", 1.0),
}
"""Loading name -> (deformation mode, sign of the stretch change)."""


MAX_NOMINAL_STRAIN = 10.0
"""Largest plausible nominal strain of a test in tension (Abaqus checks stability to 10); a
larger one is refused (a displacement in millimetres?)."""


def _check_magnitudes(
    strain: np.ndarray,
    stress: np.ndarray,
    loading: str,
    *,
    path: str | Path | None = None,
    strain_column: str = "nominal_strain",
    stress_column: str = "nominal_stress_Pa",
) -> None:
    """Refuse strains and stresses that are not magnitudes in the loading direction.

    Raises:
        InputError: A compressive strain of 1 or more (the specimen flattened), strains of
            -1 or less or mostly negative, or mostly negative stresses; naming ``path``, the
            column and the 1-based data row.
    """
    if loading == "compression" and np.any(strain >= 1.0):
        row = int(np.flatnonzero(strain >= 1.0)[0])
        raise InputError(
            f"the compressive nominal strain must stay below 1 but reaches "
            f"{float(strain[row]):.4g} at data row {row + 1}: the data look tensile (the "
            "loading is compression by default: give --loading tension, equibiaxial or "
            "planar), else check the specimen height and that the displacement is in metres",
            path=path,
            column=strain_column,
        )
    if loading != "compression" and np.any(strain > MAX_NOMINAL_STRAIN):
        row = int(np.flatnonzero(strain > MAX_NOMINAL_STRAIN)[0])
        raise InputError(
            f"a nominal strain of {float(strain[row]):.4g} at data row {row + 1} is implausible "
            f"(more than {MAX_NOMINAL_STRAIN:g}): check the specimen height and that the "
            "displacement is in metres",
            path=path,
            column=strain_column,
        )
    if np.any(strain <= -1.0) or np.median(strain) < 0.0:
        raise InputError(
            "strains are magnitudes, positive in the loading direction (see the sign "
            "convention of warptissue.fit.hyperelastic); got mostly negative or <= -1 values "
            f"(median nominal strain {float(np.median(strain)):.4g}): flip the sign",
            path=path,
            column=strain_column,
        )
    if np.median(stress) < 0.0:
        raise InputError(
            "stresses are magnitudes, positive in the loading direction (a compressive force "
            "is positive in a compression test); got mostly negative values (median nominal "
            f"stress {float(np.median(stress)):.4g} Pa): flip the sign",
            path=path,
            column=stress_column,
        )


@dataclass(frozen=True)
class HomogeneousTest:
    """A homogeneous test record as nominal strain and nominal stress magnitudes.

    Attributes:
        loading: "tension", "compression", "equibiaxial" (tension) or "planar" (tension).
        nominal_strain: d / H0, positive in the loading direction, shape (m,).
        nominal_stress_Pa: F / A0, positive in the loading direction, shape (m,).
        name: A label for reports.
    """

    loading: str
    nominal_strain: np.ndarray
    nominal_stress_Pa: np.ndarray
    name: str = ""

    def __post_init__(self) -> None:
        if self.loading not in LOADINGS:
            raise InputError(f"loading must be one of {tuple(LOADINGS)}", value=self.loading)
        strain = np.asarray(self.nominal_strain, dtype=np.float64).reshape(-1)
        stress = np.asarray(self.nominal_stress_Pa, dtype=np.float64).reshape(-1)
        if strain.size == 0 or strain.shape != stress.shape:
            raise InputError(
                "nominal strain and stress must be non-empty and of equal length",
                value=(strain.size, stress.size),
            )
        if not (np.all(np.isfinite(strain)) and np.all(np.isfinite(stress))):
            raise InputError("nominal strain and stress must be finite")
        _check_magnitudes(strain, stress, self.loading)
        object.__setattr__(self, "nominal_strain", strain)
        object.__setattr__(self, "nominal_stress_Pa", stress)

    @classmethod
    def from_force_displacement(
        cls,
        displacement_m: np.ndarray,
        force_N: np.ndarray,
        *,
        area_m2: float,
        height_m: float,
        loading: str,
        name: str = "",
        path: str | Path | None = None,
    ) -> HomogeneousTest:
        """Nominal stress F / A0 and nominal strain d / H0 from a force-displacement record.

        Args:
            displacement_m: Platen displacement, positive in the loading direction, (m,).
            force_N: Force, positive in the loading direction (compressive force positive for
                a compression test), shape (m,).
            area_m2: Undeformed loaded area A0 (> 0).
            height_m: Undeformed gauge length H0 (> 0).
            loading: See :data:`LOADINGS`.
            name: A label for reports.
            path: The file the record came from, named in error messages.

        Raises:
            InputError: Non-positive geometry, or invalid data (see the class); data errors
                name ``path`` and the column (``displacement_m`` or ``force_N``).
        """
        for label, value in (("area_m2", area_m2), ("height_m", height_m)):
            if not (math.isfinite(value) and value > 0.0):
                raise InputError(f"{label} must be positive", column=label, value=float(value))
        strain = np.asarray(displacement_m, dtype=np.float64) / height_m
        stress = np.asarray(force_N, dtype=np.float64) / area_m2
        if loading in LOADINGS and strain.shape == stress.shape:
            _check_magnitudes(
                strain,
                stress,
                loading,
                path=path,
                strain_column="displacement_m",
                stress_column="force_N",
            )
        return cls(loading, strain, stress, name)

    @classmethod
    def from_stretch(
        cls,
        stretch: np.ndarray,
        nominal_stress_Pa: np.ndarray,
        *,
        loading: str,
        name: str = "",
        path: str | Path | None = None,
    ) -> HomogeneousTest:
        """A test given as the stretch of the loading direction and the nominal stress.

        Args:
            stretch: Stretch lambda = L / L0 of the loading direction, shape (m,) (below 1 in
                compression).
            nominal_stress_Pa: Force per undeformed area, positive in the loading direction,
                shape (m,).
            loading: See :data:`LOADINGS`.
            name: A label for reports.
            path: The file the record came from, named in error messages.

        Raises:
            InputError: Invalid data (see the class), naming ``path`` and the column.
        """
        if loading not in LOADINGS:
            raise InputError(f"loading must be one of {tuple(LOADINGS)}", value=loading)
        stretches = np.asarray(stretch, dtype=np.float64)
        if np.any(stretches <= 0.0):
            row = int(np.flatnonzero(stretches <= 0.0)[0])
            raise InputError(
                f"a stretch (L / L0) must be positive; data row {row + 1} has "
                f"{float(stretches[row]):.4g}",
                path=path,
                column="stretch",
            )
        sign = LOADINGS[loading][1]
        if stretches.size and np.median(sign * (stretches - 1.0)) < 0.0:
            other = "compression" if sign > 0 else "tension"
            raise InputError(
                f"the stretches are mostly {'below' if sign > 0 else 'above'} 1 (median "
                f"{float(np.median(stretches)):.4g}), which is {other}, not {loading}: give the "
                f"test's loading as {other}",
                path=path,
                column="stretch",
            )
        strain = sign * (stretches - 1.0)
        stress = np.asarray(nominal_stress_Pa, dtype=np.float64)
        if strain.shape == stress.shape:
            _check_magnitudes(
                strain, stress, loading, path=path, strain_column="stretch",
                stress_column="nominal_stress",
            )  # fmt: skip
        return cls(loading, strain, stress, name)

    @property
    def mode(self) -> str:
        """The deformation mode: uniaxial, equibiaxial or planar."""
        return LOADINGS[self.loading][0]

    @property
    def sign(self) -> float:
        """-1 for compression, +1 otherwise."""
        return LOADINGS[self.loading][1]

    @property
    def stretch(self) -> np.ndarray:
        """Stretch of the loading direction, 1 + sign * strain, shape (m,)."""
        return 1.0 + self.sign * self.nominal_strain

    def window(self, min_strain: float) -> HomogeneousTest:
        """The points with nominal strain above ``min_strain`` (all points when it is 0)."""
        keep = (
            self.nominal_strain > min_strain
            if min_strain > 0.0
            else np.ones(self.nominal_strain.size, bool)
        )
        if not np.any(keep):
            raise InputError(
                f"no data above the strain window's lower end min_strain = {float(min_strain):g} "
                f"in test {self.name!r} (largest nominal strain "
                f"{float(np.max(self.nominal_strain)):.4g})",
            )
        return HomogeneousTest(
            self.loading, self.nominal_strain[keep], self.nominal_stress_Pa[keep], self.name
        )

    def predicted_stress_Pa(self, model: HyperelasticMaterial) -> np.ndarray:
        """Model nominal stress magnitude in the loading direction, shape (m,)."""
        return self.sign * model.nominal_stress_Pa(self.stretch, self.mode)


STRAIN_COLUMNS: tuple[str, ...] = ("stretch", "nominal_strain", "displacement_m")
"""The deformation columns a homogeneous test's CSV may have, in the order they are looked
for: the stretch of the loading direction, the nominal strain (displacement over gauge
length, a magnitude), or the displacement (m, with ``force_N``, the gauge length and area)."""


STRESS_COLUMNS: dict[str, float] = {
    "nominal_stress_Pa": 1.0,
    "nominal_stress_kPa": 1e3,
    "nominal_stress_MPa": 1e6,
}
"""The nominal stress (force per undeformed area) columns of a homogeneous test's CSV, with
the factor to Pa."""


def read_homogeneous_test(
    path: str | Path,
    *,
    loading: str,
    area_m2: float | None = None,
    height_m: float | None = None,
) -> HomogeneousTest:
    """Read a homogeneous test as labs record it, from a CSV with a header row.

    The deformation is the first of :data:`STRAIN_COLUMNS` present: ``stretch``,
    ``nominal_strain`` or ``displacement_m``; the stress one of :data:`STRESS_COLUMNS`
    (``nominal_stress_Pa``, ``_kPa`` or ``_MPa``), or ``force_N`` with ``displacement_m``
    (then ``area_m2`` and ``height_m`` are needed). A ``time_s`` column, where present, must
    increase. Values are magnitudes in the loading direction (a compressive stretch is below
    1).

    Args:
        path: The CSV file.
        loading: See :data:`LOADINGS`.
        area_m2: Undeformed loaded area A0 for ``force_N``, m^2.
        height_m: Undeformed gauge length H0 for ``displacement_m``, m.

    Returns:
        The test, named by the file's stem.

    Raises:
        InputError: A missing column or geometry, or invalid data, naming the file and column.
    """
    record = read_experiment_csv(path, required=(), monotonic="time_s")
    columns = record.columns
    name = Path(path).stem
    stress_names = [c for c in STRESS_COLUMNS if c in columns]
    if "stretch" in columns or "nominal_strain" in columns:
        if not stress_names:
            raise InputError(
                f"no nominal stress column: give one of {list(STRESS_COLUMNS)} beside the "
                f"deformation (header has {list(columns)})",
                path=path,
                line=1,
            )
        stress = columns[stress_names[0]] * STRESS_COLUMNS[stress_names[0]]
        if "stretch" in columns:
            return HomogeneousTest.from_stretch(
                columns["stretch"], stress, loading=loading, name=name, path=path
            )
        strain = columns["nominal_strain"]
        _check_magnitudes(strain, stress, loading, path=path, stress_column=stress_names[0])
        return HomogeneousTest(loading, strain, stress, name)
    if "displacement_m" not in columns or ("force_N" not in columns and not stress_names):
        raise InputError(
            f"needs a deformation column ({', '.join(STRAIN_COLUMNS)}) and a stress column "
            f"({', '.join(STRESS_COLUMNS)}, or force_N with displacement_m); header has "
            f"{list(columns)}",
            path=path,
            line=1,
        )
    if height_m is None:
        raise InputError(
            "displacement_m needs the gauge length (--height-m) to give a strain", path=path
        )
    if stress_names:
        force, area = columns[stress_names[0]] * STRESS_COLUMNS[stress_names[0]], 1.0
    elif area_m2 is None:
        raise InputError("force_N needs the loaded area (--area-m2) to give a stress", path=path)
    else:
        force, area = columns["force_N"], area_m2
    return HomogeneousTest.from_force_displacement(
        columns["displacement_m"], force, area_m2=area, height_m=height_m, loading=loading,
        name=name, path=path,
    )  # fmt: skip
