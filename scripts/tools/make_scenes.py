"""Generate the USD scenes that ship in ``scenes/`` (run from the repository root).

    python scripts/tools/make_scenes.py [--out scenes]

Every scene is written by :func:`warptissue.usd.write_simulation_usd` (a root ``NAME.usda``
and its ``NAME.asset.usda``), validated with :func:`warptissue.usd.validate_stage`, and kept
coarse so that each file stays well under 1 MB. The scenes are generated, not hand-edited:
change this script and re-run it.

Material values come from the papers the methods follow (docs/references.md) where they give
them; where they do not (bulk
moduli, densities, the pillow's modulus) the value is an assumption and the scene's
provenance says so.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

from warptissue.indenter import Indenter
from warptissue.mesh import TetMesh, block_mesh, graded_coordinates, tetrahedralize_surface
from warptissue.usd import validate_stage, write_simulation_usd

NEARLY_INCOMPRESSIBLE_NU = 0.49
"""Poisson's ratio assumed where a paper gives no bulk modulus."""


def bulk_modulus_for(shear_modulus_Pa: float, poissons_ratio: float) -> float:
    """K = 2 mu (1 + nu) / (3 (1 - 2 nu)) (isotropic linear elasticity)."""
    return 2.0 * shear_modulus_Pa * (1.0 + poissons_ratio) / (3.0 * (1.0 - 2.0 * poissons_ratio))


def centred_coordinates(
    length_m: float, cells_per_half: int, *, ratio: float, core_m: float | None = None
) -> np.ndarray:
    """Grid planes from -length/2 to length/2, finest at 0.

    Args:
        length_m: Total length, metres.
        cells_per_half: Graded cells on each side.
        ratio: Last graded cell over the first.
        core_m: When given, planes at 0, core/2 and core (so a probe of radius ``core_m`` has
            nodes on its rim), graded beyond.
    """
    if core_m is None:
        half = graded_coordinates(length_m / 2, cells_per_half, ratio=ratio)
    else:
        outer = core_m + graded_coordinates(length_m / 2 - core_m, cells_per_half, ratio=ratio)
        half = np.concatenate([[0.0, core_m / 2], outer])
    return np.concatenate([-half[::-1], half[1:]])


def specimen_sets(mesh: TetMesh, *, probe_radius_m: float | None = None) -> TetMesh:
    """Rename block_mesh's sets to the standard names (top, bottom, side) and merge regions."""
    top, bottom = mesh.node_sets["zmax"], mesh.node_sets["zmin"]
    side = np.unique(np.concatenate([mesh.node_sets[k] for k in ("xmin", "xmax", "ymin", "ymax")]))
    node_sets = {"top": top, "bottom": bottom, "side": side}
    face_sets = {"top": mesh.face_sets["zmax"], "bottom": mesh.face_sets["zmin"]}
    if probe_radius_m is not None:
        radius = np.hypot(mesh.points[top, 0], mesh.points[top, 1])
        node_sets["probe"] = top[radius <= probe_radius_m * (1 + 1e-9)]
    return TetMesh(
        points=mesh.points,
        tets=mesh.tets,
        node_sets=node_sets,
        face_sets=face_sets,
        tet_regions=np.zeros(mesh.tet_count, dtype=np.int32),
    )


def liver_material() -> dict:
    """Ahn & Kim: C10 = 287.5 Pa (Table 2), Prony experiment 1 (Table 1)."""
    c10 = 287.5
    return {
        "model": "neo_hookean",
        "C10_Pa": c10,
        "bulk_modulus_Pa": bulk_modulus_for(2 * c10, NEARLY_INCOMPRESSIBLE_NU),
        "prony_g": [0.348, 0.358],
        "prony_tau_s": [1.376, 49.369],
    }


LIVER_PROVENANCE = {
    "source": "Ahn & Kim: C10 Table 2 mean; Prony g, tau Table 1 experiment 1",
    "assumptions": "bulk modulus from nu = 0.49; density 1060 kg/m^3",
}


def beef_liver_material() -> dict:
    """Takacs et al.'s linear Wiechert (Table I) as a continuum on the 20 x 20 x 20 mm cube.

    A spring k [N/m] on a cube of area A and height L acts as Young's modulus k L / A;
    the Wiechert relaxation G(t) / G0 = (k0 + k1 e^(-t/tau1) + k2 e^(-t/tau2)) / (k0 + k1 + k2),
    tau_i = b_i / k_i, is a Prony series with g_i = k_i / (k0 + k1 + k2).
    """
    k0, k1, k2, b1, b2 = 4.86, 57.81, 53.32, 9987.0, 10464.0
    length, area = 0.020, 0.020**2
    total = k0 + k1 + k2
    return {
        "model": "linear_elastic",
        "youngs_modulus_Pa": total * length / area,
        "poissons_ratio": NEARLY_INCOMPRESSIBLE_NU,
        "prony_g": [k1 / total, k2 / total],
        "prony_tau_s": [b1 / k1, b2 / k2],
    }


BEEF_PROVENANCE = {
    "source": "Takacs et al.: Table I linear Wiechert, mapped to E = k L / A",
    "assumptions": "nu = 0.49; density 1060 kg/m^3; small-strain continuum equivalent",
}


def organ_surface(*, theta_count: int = 18, phi_count: int = 36) -> tuple[np.ndarray, np.ndarray]:
    """A closed, liver-like triangle surface from a deformed superellipsoid (procedural).

    The surface is star-shaped about the origin: each direction d on a latitude-longitude
    grid is scaled by a radius r(d) > 0, so the triangulation is watertight and free of
    self-intersections by construction. The right lobe (x > 0) is thick, the left lobe thin,
    with a shallow notch underneath.

    Returns:
        Vertices (V, 3) in metres and outward triangles (F, 3).
    """
    theta = np.linspace(0.0, np.pi, theta_count + 1)[1:-1]
    phi = np.linspace(0.0, 2 * np.pi, phi_count, endpoint=False)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    d = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1).reshape(-1, 3)
    d = np.vstack([d, [[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]]])
    a = 0.090 * (1.0 + 0.12 * d[:, 0])
    b = 0.065
    c = 0.045 * (1.0 + 0.45 * d[:, 0]) * (1.0 - 0.25 * np.clip(-d[:, 2], 0, 1) ** 2)
    p_exp = 2.6
    radius = (
        np.abs(d[:, 0] / a) ** p_exp + np.abs(d[:, 1] / b) ** p_exp + np.abs(d[:, 2] / c) ** p_exp
    ) ** (-1.0 / p_exp)
    notch = 1.0 - 0.18 * np.exp(-((d[:, 0] - 0.25) ** 2 + d[:, 1] ** 2) / 0.04) * np.clip(
        -d[:, 2], 0, 1
    )
    vertices = d * (radius * notch)[:, None]
    ring = lambda i, j: i * phi_count + (j % phi_count)  # noqa: E731
    north, south = len(vertices) - 2, len(vertices) - 1
    triangles = []
    for j in range(phi_count):
        triangles.append([north, ring(0, j), ring(0, j + 1)])
        last = theta_count - 2
        triangles.append([south, ring(last, j + 1), ring(last, j)])
        for i in range(theta_count - 2):
            triangles.append([ring(i, j), ring(i + 1, j), ring(i + 1, j + 1)])
            triangles.append([ring(i, j), ring(i + 1, j + 1), ring(i, j + 1)])
    return vertices, np.asarray(triangles, dtype=np.int32)


def liver_slab(out: Path) -> Path:
    """Ahn & Kim, Kim et al.: a porcine liver slab under a 2 mm diameter flat probe."""
    mesh = block_mesh(
        centred_coordinates(0.040, 4, ratio=4.0, core_m=1.0e-3),
        centred_coordinates(0.040, 4, ratio=4.0, core_m=1.0e-3),
        graded_coordinates(0.015, 5, ratio=0.4),
    )
    return write_simulation_usd(
        out / "liver_slab_flat_punch.usda",
        specimen_sets(mesh, probe_radius_m=1.0e-3),
        material=liver_material(),
        provenance={**LIVER_PROVENANCE, "specimen": "40 x 40 x 15 mm slab, full model"},
        density_kg_per_m3=1060.0,
        indenter=Indenter("flat_punch", radius_m=1.0e-3),
    ).root


def _brain_material() -> dict:
    c10 = 600.553
    return {
        "model": "reduced_polynomial",
        "C10_Pa": c10,
        "C20_Pa": 4097.45,
        "bulk_modulus_Pa": bulk_modulus_for(2 * c10, NEARLY_INCOMPRESSIBLE_NU),
    }


BRAIN_PROVENANCE = {
    "source": "the needle-indentation study: reduced polynomial N = 2, C10 = 600.553 Pa, "
    "C20 = 4097.45 Pa",
    "assumptions": "bulk modulus from nu = 0.49; density 1000 kg/m^3",
    "specimen": "70 x 80 x 80 mm phantom block (box mold), full model",
}


def brain_phantom(out: Path, *, indentation: bool) -> Path:
    """The needle-indentation study's 70 x 80 x 80 mm phantom: plate compression, or 5 mm
    circle indentation."""
    if indentation:
        x = centred_coordinates(0.070, 4, ratio=4.0, core_m=2.5e-3)
        y = centred_coordinates(0.080, 4, ratio=4.0, core_m=2.5e-3)
        z = graded_coordinates(0.080, 6, ratio=0.3)
    else:
        x, y, z = (
            np.linspace(-0.035, 0.035, 6),
            np.linspace(-0.04, 0.04, 6),
            np.linspace(0, 0.08, 6),
        )
    mesh = specimen_sets(block_mesh(x, y, z), probe_radius_m=2.5e-3 if indentation else None)
    name = "brain_phantom_indentation" if indentation else "brain_phantom_compression"
    indenter = (
        Indenter("flat_punch", radius_m=2.5e-3)
        if indentation
        else Indenter("platen", length_m=0.12)
    )
    test = (
        "displacement prescribed on the top nodes inside a 5 mm diameter circle (node set probe)"
        if indentation
        else "rigid plate compression to 12.7 mm at 0.4 mm/s"
    )
    return write_simulation_usd(
        out / f"{name}.usda",
        mesh,
        material=_brain_material(),
        provenance={**BRAIN_PROVENANCE, "test": test},
        density_kg_per_m3=1000.0,
        indenter=indenter,
    ).root


def memory_pillow(out: Path) -> Path:
    """Tong et al.: the 50 x 30 x 10 cm memory pillow, hexahedra split into five tets.

    The 23 x 13 surface grid matches the paper's marker grid; the force acts at marker 150
    (row 7, column 12), the centre of the top face.
    """
    mesh = block_mesh(
        np.linspace(-0.25, 0.25, 23),
        np.linspace(-0.15, 0.15, 13),
        np.linspace(0, 0.10, 3),
        split="five",
    )
    return write_simulation_usd(
        out / "memory_pillow.usda",
        specimen_sets(mesh),
        material={"model": "linear_elastic", "youngs_modulus_Pa": 20.0e3, "poissons_ratio": 0.3},
        provenance={
            "source": "Tong et al.: geometry, 23 x 13 marker grid, five-tet split",
            "assumptions": "E = 20 kPa, nu = 0.3, density 50 kg/m^3 are placeholders "
            "(polyurethane foam), not values from the paper; the probe radius (5 mm) too",
        },
        density_kg_per_m3=50.0,
        indenter=Indenter("flat_punch", radius_m=5.0e-3),
    ).root


def beef_liver_cube(out: Path) -> Path:
    """Takacs et al.: a 20 mm beef liver cube under uniform compression."""
    grid = np.linspace(-0.01, 0.01, 5)
    mesh = specimen_sets(block_mesh(grid, grid, np.linspace(0, 0.02, 5)))
    return write_simulation_usd(
        out / "beef_liver_cube.usda",
        mesh,
        material=beef_liver_material(),
        provenance={**BEEF_PROVENANCE, "test": "uniform compression, 20 and 100 mm/min"},
        density_kg_per_m3=1060.0,
        indenter=Indenter("platen", length_m=0.03),
    ).root


def beef_liver_strip(out: Path) -> Path:
    """Takacs et al.: a 25 x 25 x 200 mm strip under a line indenter across its long axis."""
    mesh = block_mesh(
        centred_coordinates(0.200, 8, ratio=6.0),
        np.linspace(-0.0125, 0.0125, 5),
        np.linspace(0, 0.025, 5),
    )
    return write_simulation_usd(
        out / "beef_liver_strip_line.usda",
        specimen_sets(mesh),
        material=beef_liver_material(),
        provenance={
            **BEEF_PROVENANCE,
            "test": "line indenter (30 mm edge, 30 degree) to 6 mm at 5-40 mm/s",
        },
        density_kg_per_m3=1060.0,
        indenter=Indenter("wedge", radius_m=0.5e-3, angle_deg=30.0, length_m=0.030),
    ).root


def liver_organ(out: Path) -> Path:
    """An organ-shaped liver volume: procedural surface, TetGen volume mesh."""
    vertices, triangles = organ_surface()
    mesh = tetrahedralize_surface(vertices, triangles, max_volume_m3=2.0e-6)
    near_axis = np.hypot(mesh.points[:, 0], mesh.points[:, 1]) < 0.01
    top_z = float(mesh.points[near_axis, 2].max())
    return write_simulation_usd(
        out / "liver_organ.usda",
        mesh,
        material=liver_material(),
        provenance={
            **LIVER_PROVENANCE,
            "geometry": "procedural: deformed superellipsoid (scripts/tools/make_scenes.py "
            "organ_surface), tetrahedralized with TetGen (warptissue.mesh.tetrahedralize_surface)",
        },
        density_kg_per_m3=1060.0,
        indenter=Indenter("flat_punch", radius_m=1.0e-3, z_m=top_z),
    ).root


SCENES: tuple[Callable[[Path], Path], ...] = (
    liver_slab,
    lambda out: brain_phantom(out, indentation=False),
    lambda out: brain_phantom(out, indentation=True),
    memory_pillow,
    beef_liver_cube,
    beef_liver_strip,
    liver_organ,
)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("scenes"))
    args = parser.parse_args()
    status = 0
    for make in SCENES:
        root = make(args.out)
        findings = validate_stage(root)
        size = sum(p.stat().st_size for p in args.out.glob(f"{root.stem}.*"))
        print(f"{root}: {size / 1024:.0f} KiB, {len(findings)} findings")
        for finding in findings:
            print(f"  {finding}")
        status = status or int(bool(findings))
    return status


if __name__ == "__main__":
    sys.exit(main())
