"""Tests of warptissue.usd.writer and warptissue.usd.reader: layout and round trips."""

from __future__ import annotations

import numpy as np
import pytest

from warptissue.errors import InputError, MeshError
from warptissue.indenter import Indenter
from warptissue.mesh import TetMesh, block_mesh, graded_coordinates, to_tet10
from warptissue.usd import (
    read_material_field_usd,
    read_material_usd,
    read_tetmesh_usd,
    validate_stage,
    write_material_usd,
    write_simulation_usd,
)
from warptissue.usd.reader import read_probe_curve_usd
from warptissue.usd.schema import applied_schema_names


@pytest.fixture
def specimen(rng: np.random.Generator) -> TetMesh:
    """A graded block with jittered interior nodes, two material regions and all sets."""
    mesh = block_mesh(
        graded_coordinates(0.02, 4, ratio=2.0),
        np.linspace(0.0, 0.015, 3),
        graded_coordinates(0.01, 3, ratio=0.5),
    )
    points = mesh.points.copy()
    interior = np.ones(mesh.node_count, dtype=bool)
    for nodes in mesh.node_sets.values():
        interior[nodes] = False
    points[interior] += rng.uniform(-2e-4, 2e-4, size=(interior.sum(), 3))
    regions = (mesh.points[mesh.tets].mean(axis=1)[:, 0] > 0.01).astype(np.int32)
    return TetMesh(
        points=points,
        tets=mesh.tets,
        node_sets=mesh.node_sets,
        face_sets=mesh.face_sets,
        tet_regions=regions + 3,
    )


def _result(mesh: TetMesh, rng: np.random.Generator, steps: int = 3) -> dict:
    depth = np.linspace(1e-4, 3e-4, steps)
    return {
        "depths_m": depth,
        "reaction_force_N": 0.5 * depth**1.5 / 1e-6,
        "displacement_m": rng.normal(scale=1e-6, size=(steps, mesh.node_count, 3)),
        "cauchy_stress_Pa": rng.normal(size=(mesh.tet_count, 6)),
        "von_mises_Pa": rng.uniform(0, 10, size=mesh.tet_count),
        "completed": True,
        "message": "converged",
    }


def _cyclic_canonical(triangles: np.ndarray) -> set[tuple[int, ...]]:
    """Triangles up to rotation of their vertex order (orientation kept)."""
    out = set()
    for tri in np.asarray(triangles).tolist():
        k = tri.index(min(tri))
        out.add(tuple(tri[k:] + tri[:k]))
    return out


def test_round_trip_tet4(tmp_path, specimen):
    paths = write_simulation_usd(
        tmp_path / "s.usda",
        specimen,
        material={"model": "linear_elastic", "youngs_modulus_Pa": 3e3, "poissons_ratio": 0.45},
    )
    assert paths.results is None and paths.asset.is_file()
    back = read_tetmesh_usd(paths.root)
    np.testing.assert_array_equal(back.tets, specimen.tets)
    np.testing.assert_array_equal(back.tet_regions, specimen.tet_regions)
    np.testing.assert_array_equal(
        back.points, specimen.points.astype(np.float32).astype(np.float64)
    )
    np.testing.assert_allclose(back.points, specimen.points, rtol=0, atol=1e-7 * 0.02)
    assert back.node_sets.keys() == specimen.node_sets.keys()
    for name, nodes in specimen.node_sets.items():
        np.testing.assert_array_equal(back.node_sets[name], np.sort(nodes))
    assert back.face_sets.keys() == specimen.face_sets.keys()
    for name, triangles in specimen.face_sets.items():
        assert _cyclic_canonical(back.face_sets[name]) == _cyclic_canonical(triangles)
    assert validate_stage(paths.root) == []


def test_layers_and_stage_metadata(tmp_path, specimen, rng):
    from pxr import Sdf, Usd, UsdGeom

    paths = write_simulation_usd(tmp_path / "r.usda", specimen, result=_result(specimen, rng))
    root = Sdf.Layer.FindOrOpen(str(paths.root))
    assert list(root.subLayerPaths) == ["./r.results.usdc", "./r.asset.usda"]
    assert not root.rootPrims
    stage = Usd.Stage.Open(str(paths.root))
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert UsdGeom.GetStageUpAxis(stage) == "Z"
    assert stage.GetRootLayer().pseudoRoot.GetInfo("kilogramsPerUnit") == 1.0
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (0.0, 3.0)
    asset = Sdf.Layer.FindOrOpen(str(paths.asset))
    results = Sdf.Layer.FindOrOpen(str(paths.results))
    assert results.GetFileFormat().formatId == "usdc"
    sampled = results.ListAllTimeSamples()
    assert list(sampled) == [0.0, 1.0, 2.0, 3.0]
    assert not asset.ListAllTimeSamples()


def test_result_samples(tmp_path, specimen, rng):
    from pxr import Usd, UsdGeom

    result = _result(specimen, rng)
    result["time_s"] = np.array([0.5, 1.0, 1.5])
    paths = write_simulation_usd(
        tmp_path / "r.usda", specimen, result=result, indenter=Indenter("flat_punch", radius_m=1e-3)
    )
    stage = Usd.Stage.Open(str(paths.root))
    volume = UsdGeom.TetMesh(stage.GetPrimAtPath("/World/Specimen/Volume"))
    rest = np.asarray(volume.GetPointsAttr().Get(), dtype=np.float64)
    np.testing.assert_array_equal(rest, specimen.points.astype(np.float32))
    for k in range(3):
        deformed = np.asarray(volume.GetPointsAttr().Get(k + 1))
        expected = (specimen.points + result["displacement_m"][k]).astype(np.float32)
        np.testing.assert_array_equal(deformed, expected)
    primvars = UsdGeom.PrimvarsAPI(volume)
    stress = primvars.GetPrimvar("tissue:cauchyStress")
    assert stress.GetInterpolation() == "uniform" and stress.GetElementSize() == 6
    np.testing.assert_array_equal(
        np.asarray(stress.Get(3)).reshape(-1, 6), result["cauchy_stress_Pa"]
    )
    assert primvars.GetPrimvar("tissue:displacement").GetInterpolation() == "vertex"
    # The render surface: each face carries the von Mises stress of the tet it bounds.
    surface = stage.GetPrimAtPath("/World/Specimen/Surface")
    mesh = UsdGeom.Mesh(surface)
    local = np.asarray(mesh.GetFaceVertexIndicesAttr().Get()).reshape(-1, 3)
    global_faces = np.asarray(surface.GetAttribute("tissue:volumePointIndices").Get())[local]
    owners = np.asarray(surface.GetAttribute("tissue:volumeTetIndices").Get())
    for face, owner in zip(global_faces, owners, strict=True):
        assert set(face) <= set(specimen.tets[owner])
    face_vm = np.asarray(UsdGeom.PrimvarsAPI(mesh).GetPrimvar("tissue:vonMises").Get(3))
    np.testing.assert_array_equal(face_vm, result["von_mises_Pa"][owners])
    # Surface winding is outward: the divergence theorem gives the enclosed volume.
    points = specimen.points[global_faces]
    enclosed = np.einsum("ij,ij->i", points[:, 0], np.cross(points[:, 1], points[:, 2])).sum() / 6
    assert enclosed == pytest.approx(specimen.volumes().sum(), rel=1e-12)
    curve = read_probe_curve_usd(paths.root)
    np.testing.assert_array_equal(curve["depth_m"], np.concatenate([[0], result["depths_m"]]))
    np.testing.assert_array_equal(
        curve["reaction_force_N"], np.concatenate([[0], result["reaction_force_N"]])
    )
    time_attr = stage.GetPrimAtPath("/World/Indenter").GetAttribute("tissue:probe:time")
    assert [time_attr.Get(k) for k in (1, 2, 3)] == [0.5, 1.0, 1.5]
    translate = UsdGeom.Xformable(stage.GetPrimAtPath("/World/Indenter")).GetOrderedXformOps()[0]
    assert translate.Get(2)[2] == pytest.approx(0.01 - result["depths_m"][1])
    assert validate_stage(paths.root) == []


def test_tet10_exports_corner_tets(tmp_path, specimen, rng):
    quadratic = to_tet10(specimen)
    result = _result(quadratic, rng, steps=2)
    paths = write_simulation_usd(tmp_path / "q.usda", quadratic, result=result)
    back = read_tetmesh_usd(paths.root)
    assert back.element_type == "TET4"
    np.testing.assert_array_equal(back.tets, specimen.tets)
    np.testing.assert_array_equal(back.node_sets["zmax"], np.sort(specimen.node_sets["zmax"]))
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.Open(str(paths.root))
    volume = UsdGeom.TetMesh(stage.GetPrimAtPath("/World/Specimen/Volume"))
    np.testing.assert_array_equal(
        np.asarray(volume.GetPointsAttr().Get(2)),
        (
            quadratic.points[: specimen.node_count]
            + result["displacement_m"][1, : specimen.node_count]
        ).astype(np.float32),
    )
    info = stage.GetPrimAtPath("/World").GetCustomDataByKey("warptissue")
    assert info["element_type_source"] == "TET10"
    assert validate_stage(paths.root) == []


def _material_field(mesh: TetMesh, rng: np.random.Generator) -> dict:
    """A heterogeneous field with values no float32 can hold (exact float64 round trip)."""
    return {
        "youngs_modulus_Pa": rng.uniform(2e3, 9e3, mesh.tet_count) * (1.0 + 1e-13),
        "poissons_ratio": rng.uniform(-0.2, 0.49, mesh.tet_count),
    }


def test_material_field_round_trip(tmp_path, specimen, rng):
    from pxr import Sdf, Usd, UsdGeom

    field = _material_field(specimen, rng)
    paths = write_simulation_usd(
        tmp_path / "h.usda",
        specimen,
        material={"model": "linear_elastic", "youngs_modulus_Pa": 5e3, "poissons_ratio": 0.3},
        result=_result(specimen, rng, steps=1),
        material_field=field,
    )
    back = read_material_field_usd(paths.root)
    assert back.keys() == field.keys()
    for key, values in field.items():
        assert back[key].dtype == np.float64
        np.testing.assert_array_equal(back[key], values)
    # The homogeneous material stays bound for simulators that read one.
    assert read_material_usd(paths.root)["youngs_modulus_Pa"] == pytest.approx(5e3)
    # Static material data: defaults in the asset layer, nothing in the results layer.
    asset = Sdf.Layer.FindOrOpen(str(paths.asset))
    results = Sdf.Layer.FindOrOpen(str(paths.results))
    for name in ("tissue:youngsModulus", "tissue:poissonsRatio"):
        for prim in ("Volume", "Surface"):
            attr_path = f"/World/Specimen/{prim}.primvars:{name}"
            assert asset.GetAttributeAtPath(attr_path).HasDefaultValue()
            assert results.GetAttributeAtPath(attr_path) is None
    stage = Usd.Stage.Open(str(paths.root))
    volume = UsdGeom.PrimvarsAPI(stage.GetPrimAtPath("/World/Specimen/Volume"))
    youngs = volume.GetPrimvar("tissue:youngsModulus")
    assert youngs.GetInterpolation() == "uniform"
    assert youngs.GetTypeName() == Sdf.ValueTypeNames.DoubleArray
    assert youngs.GetAttr().GetCustomDataByKey("unit") == "Pa"
    assert volume.GetPrimvar("tissue:poissonsRatio").GetAttr().GetCustomDataByKey("unit") == "1"
    # Each render face carries the value of the tet it bounds.
    surface_prim = stage.GetPrimAtPath("/World/Specimen/Surface")
    owners = np.asarray(surface_prim.GetAttribute("tissue:volumeTetIndices").Get())
    surface = UsdGeom.PrimvarsAPI(surface_prim)
    for key, name in (
        ("youngs_modulus_Pa", "tissue:youngsModulus"),
        ("poissons_ratio", "tissue:poissonsRatio"),
    ):
        primvar = surface.GetPrimvar(name)
        assert primvar.GetInterpolation() == "uniform"
        np.testing.assert_array_equal(np.asarray(primvar.Get()), field[key][owners])
    # The material regions (fitted groups) come back one to one with the field's tets.
    np.testing.assert_array_equal(read_tetmesh_usd(paths.root).tet_regions, specimen.tet_regions)
    assert validate_stage(paths.root) == []


def test_material_field_of_a_tet10_mesh_is_per_corner_tet(tmp_path, specimen, rng):
    field = _material_field(specimen, rng)
    paths = write_simulation_usd(tmp_path / "q.usda", to_tet10(specimen), material_field=field)
    back = read_material_field_usd(paths.root)
    np.testing.assert_array_equal(back["poissons_ratio"], field["poissons_ratio"])
    assert validate_stage(paths.root) == []


@pytest.mark.parametrize(
    ("key", "index", "value", "message"),
    [
        ("poissons_ratio", 3, 0.5, "poissons_ratio must be in \\(-1, 0.5\\).*index 3"),
        ("poissons_ratio", 0, -1.0, "poissons_ratio must be in"),
        ("youngs_modulus_Pa", 5, 0.0, "youngs_modulus_Pa must be > 0.*index 5"),
        ("youngs_modulus_Pa", 1, np.nan, "non-finite.*index 1"),
        ("youngs_modulus_Pa", None, None, "shape"),
        ("poissons_ratio", "all", "soft", "not an array of numbers"),
        (None, None, None, "must map exactly"),
    ],
)
def test_bad_material_field_writes_nothing(tmp_path, specimen, rng, key, index, value, message):
    field = _material_field(specimen, rng)
    if key is None:
        del field["poissons_ratio"]
    elif index is None:
        field[key] = field[key][:-1]
    elif index == "all":
        field[key] = [value] * specimen.tet_count
    else:
        field[key][index] = value
    with pytest.raises(InputError, match=message):
        write_simulation_usd(tmp_path / "bad.usda", specimen, material_field=field)
    assert list(tmp_path.iterdir()) == []


def test_material_attributes_and_schema(tmp_path, specimen):
    from pxr import Usd

    material = {
        "model": "reduced_polynomial",
        "C10_Pa": 600.553,
        "C20_Pa": 4097.45,
        "C30_Pa": 12.5,
        "bulk_modulus_Pa": 1.0e5,
        "prony_g": [0.348, 0.358],
        "prony_tau_s": [1.376, 49.369],
    }
    paths = write_simulation_usd(
        tmp_path / "m.usda", specimen, material=material, density_kg_per_m3=1060.0
    )
    stage = Usd.Stage.Open(str(paths.root))
    prim = stage.GetPrimAtPath("/World/Materials/Tissue")
    assert prim.HasAPI("TissueMaterialAPI")
    assert "PhysicsVolumeDeformableMaterialAPI" in applied_schema_names(prim)
    assert prim.GetAttribute("tissue:hyperelastic:C20").Get() == 4097.45
    assert prim.GetAttribute("tissue:convention").Get() == "abaqus"
    definition = Usd.SchemaRegistry().FindAppliedAPIPrimDefinition("TissueMaterialAPI")
    assert "tissue:viscoelastic:pronyTau" in definition.GetPropertyNames()
    back = read_material_usd(paths.root)
    assert back["material"] == material
    shear, bulk = 2 * 600.553, 1.0e5
    # Independent check of the small-strain equivalents:
    # mu = E / (2 (1 + nu)), K = E / (3 (1 - 2 nu)).
    youngs, nu = back["youngs_modulus_Pa"], back["poissons_ratio"]
    assert youngs / (2 * (1 + nu)) == pytest.approx(shear, rel=1e-6)
    assert youngs / (3 * (1 - 2 * nu)) == pytest.approx(bulk, rel=1e-4)
    assert back["density_kg_per_m3"] == 1060.0
    binding = stage.GetPrimAtPath("/World/Specimen/Volume").GetRelationship(
        "material:binding:physics"
    )
    assert binding.GetTargets() == [prim.GetPath()]


def test_material_object_duck_typed(tmp_path, specimen):
    class Ogden:
        def to_dict(self):
            return {
                "model": "ogden",
                "mu1_Pa": 400.0,
                "alpha1": 2.0,
                "mu2_Pa": -50.0,
                "alpha2": -2.0,
            }

        def small_strain_equivalent(self):
            return 1050.0, 0.5

    paths = write_simulation_usd(tmp_path / "o.usda", specimen, material=Ogden())
    back = read_material_usd(paths.root)
    assert back["material"] == Ogden().to_dict()
    assert (back["youngs_modulus_Pa"], back["poissons_ratio"]) == (1050.0, 0.5)


def test_material_layer_validates_and_round_trips(tmp_path):
    from pxr import Usd, UsdGeom

    material = {
        "model": "reduced_polynomial",
        "C10_Pa": 600.553,
        "C20_Pa": 4097.45,
        "bulk_modulus_Pa": 1.0e5,
        "prony_g": [0.348, 0.358],
        "prony_tau_s": [1.376, 49.369],
    }
    provenance = {"data_file": "block.csv", "fit": {"r_squared": 0.998}}
    path = write_material_usd(
        tmp_path / "tissue.usda", material, provenance=provenance, density_kg_per_m3=1060.0
    )
    assert validate_stage(path) == []
    stage = Usd.Stage.Open(str(path))
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z
    assert not any(prim.IsA(UsdGeom.TetMesh) for prim in stage.Traverse())
    info = stage.GetPrimAtPath("/World").GetCustomDataByKey("warptissue")
    assert info["data_file"] == "block.csv"
    assert info["fit"]["r_squared"] == 0.998
    assert "software" in info
    back = read_material_usd(path)
    assert back["material"] == material
    assert back["density_kg_per_m3"] == 1060.0
    # The scene writer authors the identical material prim (one shared helper).
    scene = write_simulation_usd(
        tmp_path / "scene.usda", block_mesh([0.0, 0.01], [0.0, 0.01], [0.0, 0.01]),
        material=material, density_kg_per_m3=1060.0,
    )  # fmt: skip
    scene_back = read_material_usd(scene.root)
    assert scene_back == back
    with pytest.raises(InputError, match="usda"):
        write_material_usd(tmp_path / "tissue.usdc", material)
    with pytest.raises(InputError, match="density"):
        write_material_usd(tmp_path / "bad.usda", material, density_kg_per_m3=0.0)
    assert not (tmp_path / "bad.usda").exists()


def test_bad_inputs_write_nothing(tmp_path, specimen, rng):
    result = _result(specimen, rng)
    result["displacement_m"] = result["displacement_m"][:, :-1]
    with pytest.raises(InputError, match="displacement_m"):
        write_simulation_usd(tmp_path / "bad.usda", specimen, result=result)
    with pytest.raises(InputError, match="prony"):
        write_simulation_usd(
            tmp_path / "bad.usda",
            specimen,
            material={
                "model": "NeoHookean",
                "C10_Pa": 1.0,
                "prony_g": [0.5],
                "prony_tau_s": [1, 2],
            },
        )
    with pytest.raises(InputError, match=".usda"):
        write_simulation_usd(tmp_path / "bad.usdc", specimen)
    inverted = TetMesh(points=specimen.points, tets=specimen.tets[:, [0, 2, 1, 3]])
    with pytest.raises(MeshError, match="inverted"):
        write_simulation_usd(tmp_path / "bad.usda", inverted)
    assert list(tmp_path.iterdir()) == []


def test_set_names_that_are_not_identifiers(tmp_path, specimen):
    top = specimen.node_sets["zmax"]
    named = TetMesh(
        points=specimen.points,
        tets=specimen.tets,
        node_sets={"probe-ring": top[:3], "probe_ring": top[3:5], "2 mm": top[5:6]},
    )
    back = read_tetmesh_usd(write_simulation_usd(tmp_path / "n.usda", named).root)
    assert back.node_sets.keys() == named.node_sets.keys()
    for name, nodes in named.node_sets.items():
        np.testing.assert_array_equal(back.node_sets[name], np.sort(nodes))


def test_read_errors(tmp_path):
    with pytest.raises(InputError, match="no such USD file"):
        read_tetmesh_usd(tmp_path / "missing.usda")
    empty = tmp_path / "empty.usda"
    empty.write_text("#usda 1.0\n")
    with pytest.raises(InputError, match="no UsdGeom.TetMesh"):
        read_tetmesh_usd(empty)
    plain = write_simulation_usd(
        tmp_path / "plain.usda", block_mesh(*[np.linspace(0, 0.01, 2)] * 3)
    )
    with pytest.raises(InputError, match="no primvars:tissue:youngsModulus"):
        read_material_field_usd(plain.root)


def test_reads_foreign_left_handed_tetmesh(tmp_path):
    """A TetMesh from another tool (Houdini writes leftHanded) reads back positively oriented."""
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.CreateNew(str(tmp_path / "foreign.usda"))
    tetmesh = UsdGeom.TetMesh.Define(stage, "/Tet")
    tetmesh.CreatePointsAttr([(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)])
    tetmesh.CreateTetVertexIndicesAttr([(0, 2, 1, 3)])
    tetmesh.CreateOrientationAttr("leftHanded")
    stage.Save()
    mesh = read_tetmesh_usd(tmp_path / "foreign.usda")
    assert mesh.volumes()[0] == pytest.approx(1 / 6)


def test_reads_an_indexed_material_field(tmp_path):
    """Another tool may write the field as an indexed primvar: it reads back flattened."""
    from pxr import Sdf, Usd, UsdGeom, Vt

    stage = Usd.Stage.CreateNew(str(tmp_path / "indexed.usda"))
    tetmesh = UsdGeom.TetMesh.Define(stage, "/Tet")
    tetmesh.CreatePointsAttr([(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 1)])
    tetmesh.CreateTetVertexIndicesAttr([(0, 1, 2, 3), (1, 2, 3, 4)])
    primvars = UsdGeom.PrimvarsAPI(tetmesh)
    for name, values in (("youngsModulus", [4e3, 6e3]), ("poissonsRatio", [0.2, 0.4])):
        primvar = primvars.CreatePrimvar(
            f"tissue:{name}", Sdf.ValueTypeNames.DoubleArray, UsdGeom.Tokens.uniform
        )
        primvar.Set(values)
        primvar.SetIndices(Vt.IntArray([1, 0]))
    stage.Save()
    field = read_material_field_usd(tmp_path / "indexed.usda")
    np.testing.assert_array_equal(field["youngs_modulus_Pa"], [6e3, 4e3])
    np.testing.assert_array_equal(field["poissons_ratio"], [0.4, 0.2])


def test_every_material_model_round_trips(tmp_path, specimen):
    """Every warptissue.materials model comes back from USD equal."""
    from warptissue import materials

    models = [
        materials.NeoHookean(287.5, 3e4),
        materials.MooneyRivlin(100.0, 50.0, 3e4),
        materials.ReducedPolynomial((600.553, 4097.45), 3e4),
        materials.Ogden((400.0, -50.0), (2.0, -2.0), 3e4),
        materials.LinearElastic(2e4, 0.3),
    ]
    for i, model in enumerate(models):
        paths = write_simulation_usd(tmp_path / f"m{i}.usda", specimen, material=model)
        back = read_material_usd(paths.root)
        assert materials.material_from_dict(back["material"]) == model
        youngs, nu = model.small_strain_equivalent()
        assert back["youngs_modulus_Pa"] == pytest.approx(youngs, rel=1e-6)
        assert back["poissons_ratio"] == pytest.approx(nu, rel=1e-6)


def test_indenter_validation():
    with pytest.raises(InputError, match="kind"):
        Indenter("line", radius_m=1e-3)
    with pytest.raises(InputError, match="radius_m"):
        Indenter("flat_punch")
    with pytest.raises(InputError, match="length_m"):
        Indenter("platen")
    with pytest.raises(InputError, match="angle_deg"):
        Indenter("wedge", radius_m=1e-3, angle_deg=180.0)
    with pytest.raises(InputError, match="edge_radius_m"):
        Indenter("flat_punch", radius_m=1e-3, edge_radius_m=2e-3)
    with pytest.raises(InputError, match="edge_radius_m"):
        Indenter("sphere", radius_m=1e-3, edge_radius_m=1e-4)
    with pytest.raises(InputError, match="x_m"):
        Indenter("flat_punch", radius_m=1e-3, x_m=float("nan"))
    with pytest.raises(InputError, match="unknown indenter key") as caught:
        Indenter.from_dict({"kind": "flat_punch", "radius_mm": 1.0})
    assert caught.value.column == "radius_mm"


def test_one_indenter_type_from_the_study_to_usd():
    """The study's [indenter] table, the FE problem and the USD writer share one type, and
    to_dict/from_dict round-trip it (the study's table is exactly kind, radius_m, contact)."""
    import typing

    import warptissue.usd.writer
    from warptissue.fem import IndentationProblem
    from warptissue.study import Study

    assert typing.get_type_hints(Study)["indenter"] is Indenter is warptissue.usd.writer.Indenter
    assert "indenter" in IndentationProblem.__dataclass_fields__
    probe = Indenter("flat_punch", radius_m=1e-3, contact="frictionless")
    assert probe.to_dict() == {"kind": "flat_punch", "radius_m": 1e-3, "contact": "frictionless"}
    line = Indenter("wedge", radius_m=5e-4, angle_deg=30.0, length_m=0.03, z_m=0.01)
    assert Indenter.from_dict(line.to_dict()) == line
    rounded = Indenter("flat_punch", radius_m=1e-3, edge_radius_m=1e-4)
    assert rounded.contact == "frictionless" and rounded.is_rigid_contact
    assert Indenter.from_dict(rounded.to_dict()) == rounded


# --- contact outputs (issue 21): pressure primvar, area attribute, the plate's size ---------


def _contact_result(mesh: TetMesh, rng: np.random.Generator, steps: int = 3) -> dict:
    result = _result(mesh, rng, steps)
    result["contact_area_m2"] = np.linspace(1e-6, 3e-6, steps)
    result["contact_pressure_Pa"] = rng.uniform(0.0, 100.0, size=(steps, mesh.node_count))
    return result


def _surface_pressure(stage, time_code):
    from pxr import UsdGeom

    surface = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Specimen/Surface"))
    primvar = UsdGeom.PrimvarsAPI(surface).GetPrimvar("tissue:contactPressure")
    return primvar, (np.asarray(primvar.Get(time_code)) if primvar else None)


def test_contact_pressure_and_area_are_sampled_per_step(tmp_path, specimen, rng):
    """TET10 result: each surface point of the render Mesh carries, at time code k, the
    pressure of the mesh node at its rest position (found by position, not by index), and
    time code 0 none; the indenter carries the contact area per time code."""
    from pxr import Usd, UsdGeom

    quadratic = to_tet10(specimen)
    result = _contact_result(quadratic, rng)
    paths = write_simulation_usd(
        tmp_path / "c.usda", quadratic, result=result, indenter=Indenter("sphere", radius_m=2e-3)
    )
    assert validate_stage(paths.root) == []
    stage = Usd.Stage.Open(str(paths.root))
    surface = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Specimen/Surface"))
    rest = np.asarray(surface.GetPointsAttr().Get(0), dtype=np.float64)
    node = np.argmin(
        np.linalg.norm(quadratic.points[None, :, :] - rest[:, None, :], axis=2), axis=1
    )
    assert np.abs(quadratic.points[node] - rest).max() < 1e-9
    primvar, values = _surface_pressure(stage, 0)
    assert primvar.GetInterpolation() == "vertex"
    assert primvar.GetAttr().GetCustomDataByKey("unit") == "Pa"
    np.testing.assert_array_equal(values, 0.0)
    for k in range(3):
        np.testing.assert_array_equal(
            _surface_pressure(stage, k + 1)[1], result["contact_pressure_Pa"][k, node]
        )
    area = stage.GetPrimAtPath("/World/Indenter").GetAttribute("tissue:probe:contactArea")
    assert area.GetCustomDataByKey("unit") == "m2"
    assert [area.Get(k) for k in range(4)] == [0.0, *result["contact_area_m2"].tolist()]
    # The results layer holds the samples; the asset layer none.
    from pxr import Sdf

    assert Sdf.Layer.FindOrOpen(str(paths.results)).ListAllTimeSamples() == [0, 1, 2, 3]
    assert not Sdf.Layer.FindOrOpen(str(paths.asset)).ListAllTimeSamples()


def test_last_step_contact_pressure_and_empty_contact_results(tmp_path, specimen, rng):
    """A (N,) pressure is the last step's (time codes 0 and S); a sharp flat punch's empty
    contact arrays write no contact attribute; a wrong shape is refused by name."""
    from pxr import Usd

    result = _contact_result(specimen, rng)
    last = result["contact_pressure_Pa"][-1]
    paths = write_simulation_usd(
        tmp_path / "l.usda", specimen, result={**result, "contact_pressure_Pa": last}
    )
    stage = Usd.Stage.Open(str(paths.root))
    primvar, at_end = _surface_pressure(stage, 3)
    assert primvar.GetAttr().GetTimeSamples() == [0.0, 3.0]
    indices = np.asarray(
        stage.GetPrimAtPath("/World/Specimen/Surface")
        .GetAttribute("tissue:volumePointIndices")
        .Get()
    )
    np.testing.assert_array_equal(at_end, last[indices])
    empty = {
        **_result(specimen, rng),
        "contact_area_m2": np.zeros(0),
        "contact_pressure_Pa": np.zeros((0, specimen.node_count)),
    }
    paths = write_simulation_usd(tmp_path / "e.usda", specimen, result=empty)
    stage = Usd.Stage.Open(str(paths.root))
    assert not _surface_pressure(stage, 1)[0]
    assert not stage.GetPrimAtPath("/World/Indenter").GetAttribute("tissue:probe:contactArea")
    bad = {**result, "contact_pressure_Pa": result["contact_pressure_Pa"][:, :5]}
    with pytest.raises(InputError, match="contact_pressure_Pa"):
        write_simulation_usd(tmp_path / "b.usda", specimen, result=bad)


def test_a_plate_is_drawn_over_the_specimen_footprint(tmp_path, specimen):
    """The rigid plate (no length of its own) covers the specimen's footprint, resting on its
    top; a platen keeps its own side."""
    from pxr import Usd, UsdGeom

    for probe, expected in (
        (Indenter("plate"), (specimen.points[:, :2].min(0), specimen.points[:, :2].max(0))),
        (Indenter("platen", length_m=4e-3), (np.full(2, -2e-3), np.full(2, 2e-3))),
    ):
        paths = write_simulation_usd(tmp_path / f"{probe.kind}.usda", specimen, indenter=probe)
        stage = Usd.Stage.Open(str(paths.root))
        cache = UsdGeom.BBoxCache(Usd.TimeCode.Default(), [UsdGeom.Tokens.default_])
        box = cache.ComputeWorldBound(
            stage.GetPrimAtPath("/World/Indenter/Shape")
        ).ComputeAlignedRange()
        low, high = np.array(box.GetMin()), np.array(box.GetMax())
        np.testing.assert_allclose(low[:2], expected[0], atol=1e-9)
        np.testing.assert_allclose(high[:2], expected[1], atol=1e-9)
        top = specimen.points[:, 2].max()
        assert low[2] == pytest.approx(top, abs=1e-9) and high[2] > top
        assert validate_stage(paths.root) == []


def test_each_region_s_material_is_bound_to_its_subsets(tmp_path, specimen):
    """A body of several materials: the default bound to the TetMesh, the named region's to
    the materialRegion subset of its tet region (purpose physics); a region whose tet
    region has no subset is refused with nothing written."""
    from pxr import Usd, UsdShade

    from warptissue.materials import MaterialRegions, NeoHookean

    body = MaterialRegions(
        NeoHookean(200.0, 2.0e4), {"stiff": NeoHookean(900.0, 9.0e4)}, {"stiff": (4,)}
    )
    paths = write_simulation_usd(tmp_path / "r.usda", specimen, material=body)
    stage = Usd.Stage.Open(str(paths.root))
    volume = "/World/Specimen/Volume"
    bound = {}
    for path in (volume, f"{volume}/materialRegion_3", f"{volume}/materialRegion_4"):
        prim = stage.GetPrimAtPath(path)
        material, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial("physics")
        bound[path] = material.GetPrim().GetAttribute("tissue:hyperelastic:C10").Get()
    assert bound == {
        volume: 200.0,
        f"{volume}/materialRegion_3": 200.0,
        f"{volume}/materialRegion_4": 900.0,
    }
    assert validate_stage(paths.root) == []
    elsewhere = MaterialRegions(body.default, {"stiff": body.materials["stiff"]}, {"stiff": (9,)})
    with pytest.raises(InputError, match="no materialRegion subset of tet region 9"):
        write_simulation_usd(tmp_path / "bad.usda", specimen, material=elsewhere)
    assert not list(tmp_path.glob("bad*"))
