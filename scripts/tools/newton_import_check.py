"""Load a warptissue USD scene with NVIDIA Newton's importer and check the soft body.

Run inside an environment that has ``newton`` (1.8) and this project installed; see
``scripts/tools/newton_import_check.sh``, which builds one. The script writes a small specimen
scene with :func:`warptissue.usd.write_simulation_usd` (or takes ``--scene``), imports it with
``newton.ModelBuilder.add_usd`` and checks that Newton found one soft body with the tets of
the TetMesh, the Lame parameters of the small-strain E and nu, and the mass of the density.
It prints one JSON line and exits 0 when every check passes, 1 otherwise.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np


def _write_specimen(folder: Path) -> tuple[Path, dict]:
    from warptissue.indenter import Indenter
    from warptissue.mesh import block_mesh
    from warptissue.usd import write_simulation_usd

    mesh = block_mesh(np.linspace(0, 0.02, 4), np.linspace(0, 0.02, 4), np.linspace(0, 0.01, 3))
    material = {"model": "neo_hookean", "C10_Pa": 287.5, "bulk_modulus_Pa": 1.0e5}
    density = 1060.0
    paths = write_simulation_usd(
        folder / "specimen.usda",
        mesh,
        material=material,
        density_kg_per_m3=density,
        indenter=Indenter("flat_punch", radius_m=1.0e-3),
    )
    shear = 2 * 287.5
    bulk = 1.0e5
    expected = {
        "tet_count": mesh.tet_count,
        "node_count": mesh.node_count,
        "youngs_modulus_Pa": 9 * bulk * shear / (3 * bulk + shear),
        "poissons_ratio": (3 * bulk - 2 * shear) / (2 * (3 * bulk + shear)),
        "density_kg_per_m3": density,
        "volume_m3": float(mesh.volumes().sum()),
    }
    return paths.root, expected


def _expected_from_scene(scene: Path) -> dict:
    from warptissue.usd import read_material_usd, read_tetmesh_usd

    mesh = read_tetmesh_usd(scene)
    material = read_material_usd(scene)
    return {
        "tet_count": mesh.tet_count,
        "node_count": mesh.node_count,
        "youngs_modulus_Pa": material["youngs_modulus_Pa"],
        "poissons_ratio": material["poissons_ratio"],
        "density_kg_per_m3": material["density_kg_per_m3"],
        "volume_m3": float(mesh.volumes().sum()),
    }


def check(scene: Path, expected: dict) -> dict:
    import newton
    import warp as wp

    wp.config.quiet = True
    builder = newton.ModelBuilder()
    started = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        builder.add_usd(str(scene))
    seconds = time.perf_counter() - started
    materials = np.asarray(builder.tet_materials, dtype=np.float64).reshape(builder.tet_count, -1)
    mu, lam = materials[:, 0], materials[:, 1]
    youngs = mu * (3 * lam + 2 * mu) / (lam + mu)
    poisson = lam / (2 * (lam + mu))
    mass = float(np.sum(builder.particle_mass))
    report = {
        "newton": newton.__version__,
        "scene": str(scene),
        "import_s": round(seconds, 3),
        "tet_count": builder.tet_count,
        "particle_count": builder.particle_count,
        "youngs_modulus_Pa": float(youngs.mean()) if len(youngs) else None,
        "poissons_ratio": float(poisson.mean()) if len(poisson) else None,
        "mass_kg": mass,
        "density_kg_per_m3": mass / expected["volume_m3"],
        "warnings": sorted({str(w.message)[:200] for w in caught}),
    }
    checks = {
        "tet_count": builder.tet_count == expected["tet_count"],
        "particle_count": builder.particle_count == expected["node_count"],
        "youngs_modulus": bool(len(youngs))
        and np.allclose(youngs, expected["youngs_modulus_Pa"], rtol=1e-5),
        "poissons_ratio": bool(len(poisson))
        and np.allclose(poisson, expected["poissons_ratio"], rtol=1e-5),
        "density": np.isclose(
            report["density_kg_per_m3"], expected["density_kg_per_m3"], rtol=1e-4
        ),
    }
    report["checks"] = {name: bool(passed) for name, passed in checks.items()}
    report["ok"] = all(report["checks"].values())
    return report


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", type=Path, help="a warptissue scene (default: write one)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        if args.scene is None:
            scene, expected = _write_specimen(Path(folder))
        else:
            scene, expected = args.scene, _expected_from_scene(args.scene)
        report = check(scene, expected)
    print(json.dumps(report))
    return 0 if report["ok"] else 1


if __name__ == "__main__":
    sys.exit(main())
