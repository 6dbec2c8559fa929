"""Tests of warptissue.usd.validation: each rule fires on a scene that breaks it."""

from __future__ import annotations

import numpy as np
import pytest

from warptissue.mesh import block_mesh
from warptissue.usd import validate_stage, write_simulation_usd

MATERIAL = {"model": "neo_hookean", "C10_Pa": 300.0, "bulk_modulus_Pa": 3.0e4}


@pytest.fixture
def mesh():
    grid = np.linspace(0.0, 0.01, 3)
    return block_mesh(grid, grid, grid)


def _result(mesh, displacement):
    return {
        "depths_m": np.array([1e-4]),
        "reaction_force_N": np.array([1e-3]),
        "displacement_m": displacement[None],
    }


def _findings_named(findings, name):
    return [f for f in findings if name in f]


def test_clean_scene_has_no_findings(tmp_path, mesh):
    paths = write_simulation_usd(
        tmp_path / "ok.usda",
        mesh,
        material=MATERIAL,
        result=_result(mesh, np.zeros((mesh.node_count, 3))),
    )
    assert validate_stage(paths.root) == []


def test_inverted_element_in_a_time_sample(tmp_path, mesh):
    displacement = np.zeros((mesh.node_count, 3))
    apex = mesh.tets[0, 3]
    base = mesh.points[mesh.tets[0, :3]]
    normal = np.cross(base[1] - base[0], base[2] - base[0])
    normal /= np.linalg.norm(normal)
    # Push the apex through the opposite face: the tet turns inside out.
    height = np.dot(mesh.points[apex] - base[0], normal)
    displacement[apex] = -2.5 * height * normal
    paths = write_simulation_usd(tmp_path / "inv.usda", mesh, result=_result(mesh, displacement))
    findings = _findings_named(validate_stage(paths.root), "InvertedElements")
    assert len(findings) == 1 and "time 1" in findings[0]


def test_layer_rules(tmp_path, mesh):
    from pxr import Sdf

    paths = write_simulation_usd(
        tmp_path / "l.usda", mesh, result=_result(mesh, np.zeros((mesh.node_count, 3)))
    )
    asset = Sdf.Layer.FindOrOpen(str(paths.asset))
    asset.SetTimeSample(
        Sdf.Path("/World/Specimen/Volume.points"),
        5.0,
        asset.GetAttributeAtPath("/World/Specimen/Volume.points").default,
    )
    asset.Save()
    results = Sdf.Layer.FindOrOpen(str(paths.results))
    results.GetAttributeAtPath("/World/Indenter.tissue:probe:depth").default = 1.0
    results.Save()
    findings = _findings_named(validate_stage(paths.root), "LayerRules")
    assert len(findings) == 2
    assert any("asset layer" in f and "Volume.points" in f for f in findings)
    assert any("results layer" in f and "probe:depth" in f for f in findings)


def test_material_range_and_units(tmp_path, mesh):
    from pxr import Sdf

    paths = write_simulation_usd(tmp_path / "m.usda", mesh, material=MATERIAL)
    asset = Sdf.Layer.FindOrOpen(str(paths.asset))
    asset.GetAttributeAtPath("/World/Materials/Tissue.physics:poissonsRatio").default = 0.7
    asset.Save()
    root = Sdf.Layer.FindOrOpen(str(paths.root))
    root.pseudoRoot.SetInfo("kilogramsPerUnit", 0.001)
    root.pseudoRoot.ClearInfo("upAxis")
    root.Save()
    findings = validate_stage(paths.root)
    assert len(_findings_named(findings, "physics:poissonsRatio")) == 1
    assert len(_findings_named(findings, "kilogramsPerUnit")) == 1
    assert len(_findings_named(findings, "MissingUpAxisMetadata")) == 1


def test_surface_faces_must_match(tmp_path, mesh):
    from pxr import Sdf, Vt

    paths = write_simulation_usd(tmp_path / "f.usda", mesh)
    asset = Sdf.Layer.FindOrOpen(str(paths.asset))
    spec = asset.GetAttributeAtPath("/World/Specimen/Volume.surfaceFaceVertexIndices")
    faces = np.asarray(spec.default)
    spec.default = Vt.Vec3iArray.FromNumpy(np.ascontiguousarray(faces[:-1]))
    asset.Save()
    assert len(_findings_named(validate_stage(paths.root), "SurfaceFaces")) == 1


def test_material_field_values_sizes_and_interpolation(tmp_path, mesh):
    from pxr import Sdf, UsdGeom, Vt

    field = {
        "youngs_modulus_Pa": np.linspace(1e3, 2e3, mesh.tet_count),
        "poissons_ratio": np.linspace(0.1, 0.45, mesh.tet_count),
    }
    paths = write_simulation_usd(
        tmp_path / "mf.usda", mesh, material=MATERIAL, material_field=field
    )
    assert validate_stage(paths.root) == []
    asset = Sdf.Layer.FindOrOpen(str(paths.asset))
    volume = "/World/Specimen/Volume.primvars:tissue:"
    surface = "/World/Specimen/Surface.primvars:tissue:"
    nu = field["poissons_ratio"].copy()
    nu[7] = 0.5
    asset.GetAttributeAtPath(volume + "poissonsRatio").default = Vt.DoubleArray.FromNumpy(nu)
    youngs = asset.GetAttributeAtPath(surface + "youngsModulus")
    faces = np.asarray(youngs.default).copy()
    faces[2] = -1.0
    youngs.default = Vt.DoubleArray.FromNumpy(faces)
    short = field["youngs_modulus_Pa"][:-1].copy()
    asset.GetAttributeAtPath(volume + "youngsModulus").default = Vt.DoubleArray.FromNumpy(short)
    asset.GetAttributeAtPath(surface + "poissonsRatio").SetInfo(
        "interpolation", UsdGeom.Tokens.vertex
    )
    asset.Save()
    findings = _findings_named(validate_stage(paths.root), "MaterialField")
    assert len(findings) == 4
    assert any(
        "Volume.primvars:tissue:poissonsRatio" in f and "index 7: 0.5" in f for f in findings
    )
    assert any(
        "Surface.primvars:tissue:youngsModulus" in f and "index 2: -1.0" in f for f in findings
    )
    assert any(
        "Volume.primvars:tissue:youngsModulus" in f and f"expected ({mesh.tet_count},)" in f
        for f in findings
    )
    assert any(
        "Surface.primvars:tissue:poissonsRatio" in f and "not uniform" in f for f in findings
    )
