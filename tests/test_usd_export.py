"""Tests of warptissue.usd.export and ``warptissue export``: simulate output folders to USD."""

from __future__ import annotations

import json

import numpy as np
import pytest

from warptissue.cli import main
from warptissue.errors import InputError
from warptissue.mesh import block_mesh
from warptissue.usd import read_material_usd, read_tetmesh_usd, validate_stage
from warptissue.usd.export import export_result_dir, read_fields_vtu
from warptissue.usd.reader import read_probe_curve_usd

MATERIAL = {"model": "neo_hookean", "C10_Pa": 287.5, "bulk_modulus_Pa": 2.9e4}


def _write_vtu(path, mesh, point_data, cell_data):
    import meshio

    nodal = dict(point_data)
    for name, nodes in mesh.node_sets.items():
        mask = np.zeros(mesh.node_count, dtype=np.int32)
        mask[nodes] = 1
        nodal[f"node_set:{name}"] = mask
    cells = {name: [values] for name, values in cell_data.items()}
    cells["tet_region"] = [mesh.tet_regions]
    meshio.write(
        path, meshio.Mesh(mesh.points, [("tetra", mesh.tets)], point_data=nodal, cell_data=cells)
    )


@pytest.fixture
def simulate_folder(tmp_path, rng):
    """A folder laid out like ``warptissue simulate --out`` output (per-step VTUs optional)."""
    grid = np.linspace(0.0, 0.01, 3)
    mesh = block_mesh(grid, grid, np.linspace(0.0, 0.005, 3))
    steps = 3
    displacement = rng.normal(scale=1e-6, size=(steps, mesh.node_count, 3))
    stress = rng.normal(size=(mesh.tet_count, 6))
    von_mises = rng.uniform(size=mesh.tet_count)
    folder = tmp_path / "run"
    folder.mkdir()
    _write_vtu(
        folder / "fields.vtu",
        mesh,
        {"displacement_m": displacement[-1]},
        {"cauchy_stress_Pa": stress, "von_mises_Pa": von_mises},
    )
    summary = {
        "study": {
            "path": "study.toml",
            "name": "demo",
            "material": MATERIAL,
            "indenter": {"kind": "flat_punch", "radius_m": 1e-3, "contact": "bonded"},
        },
        "completed": True,
        "message": "all steps converged",
        "force_curve": {
            "step": [1, 2, 3],
            "depth_m": [1e-4, 2e-4, 3e-4],
            "reaction_force_N": [0.01, 0.03, 0.06],
        },
        "software": {"warptissue": "0.1.0"},
    }
    (folder / "result.json").write_text(json.dumps(summary))
    return folder, mesh, displacement, stress, von_mises


def test_export_last_step_only(simulate_folder, tmp_path):
    from pxr import Usd, UsdGeom

    folder, mesh, displacement, stress, _ = simulate_folder
    paths = export_result_dir(folder, tmp_path / "out" / "scene.usda", density_kg_per_m3=1060.0)
    assert validate_stage(paths.root) == []
    back = read_tetmesh_usd(paths.root)
    np.testing.assert_array_equal(back.tets, mesh.tets)
    np.testing.assert_array_equal(back.node_sets["zmax"], np.sort(mesh.node_sets["zmax"]))
    stage = Usd.Stage.Open(str(paths.root))
    points = UsdGeom.TetMesh(stage.GetPrimAtPath("/World/Specimen/Volume")).GetPointsAttr()
    assert points.GetTimeSamples() == [0.0, 3.0]
    np.testing.assert_array_equal(
        np.asarray(points.Get(3)), (mesh.points + displacement[-1]).astype(np.float32)
    )
    curve = read_probe_curve_usd(paths.root)
    np.testing.assert_array_equal(curve["reaction_force_N"], [0.0, 0.01, 0.03, 0.06])
    assert read_material_usd(paths.root)["material"] == MATERIAL
    info = stage.GetPrimAtPath("/World").GetCustomDataByKey("warptissue")
    assert info["study_name"] == "demo" and info["result"]["completed"]


def test_export_every_step(simulate_folder, tmp_path):
    from pxr import Usd, UsdGeom

    folder, mesh, displacement, _, _ = simulate_folder
    for k in range(3):
        _write_vtu(
            folder / f"fields_{k + 1:03d}.vtu", mesh, {"displacement_m": displacement[k]}, {}
        )
    paths = export_result_dir(folder, tmp_path / "scene.usda")
    stage = Usd.Stage.Open(str(paths.root))
    points = UsdGeom.TetMesh(stage.GetPrimAtPath("/World/Specimen/Volume")).GetPointsAttr()
    assert points.GetTimeSamples() == [0.0, 1.0, 2.0, 3.0]
    np.testing.assert_array_equal(
        np.asarray(points.Get(2)), (mesh.points + displacement[1]).astype(np.float32)
    )


def test_read_fields_vtu(simulate_folder):
    folder, mesh, _, stress, von_mises = simulate_folder
    back, point_data, cell_data = read_fields_vtu(folder / "fields.vtu")
    assert back.node_sets.keys() == mesh.node_sets.keys()
    np.testing.assert_array_equal(cell_data["cauchy_stress_Pa"], stress)
    np.testing.assert_array_equal(cell_data["von_mises_Pa"], von_mises)
    assert "displacement_m" in point_data


def test_cli_export(simulate_folder, tmp_path, capsys):
    folder = simulate_folder[0]
    status = main(["export", str(folder), "--out", str(tmp_path / "cli.usda"), "--json"])
    assert status == 0
    written = json.loads(capsys.readouterr().out)
    assert written["findings"] == [] and written["results"].endswith("cli.results.usdc")


def test_cli_errors(tmp_path, capsys):
    assert main(["export", str(tmp_path / "nothing"), "--out", str(tmp_path / "x.usda")]) == 2
    assert "simulate output folder" in capsys.readouterr().err
    (tmp_path / "empty").mkdir()
    assert main(["export", str(tmp_path / "empty"), "--out", str(tmp_path / "x.usda")]) == 2
    assert "result.json" in capsys.readouterr().err
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "result.json").write_text("{\n  nope\n}")
    with pytest.raises(InputError, match=r"result.json:2"):
        export_result_dir(broken, tmp_path / "x.usda")


def test_export_study(tmp_path):
    """A study's specimen, material and indenter as USD, no results."""
    from pathlib import Path

    from warptissue.usd.export import export_study

    study = Path(__file__).resolve().parents[1] / "scenes" / "liver_slab_flat_punch.toml"
    paths = export_study(study, tmp_path / "study.usda", density_kg_per_m3=1060.0)
    assert paths.results is None
    assert validate_stage(paths.root) == []
    mesh = read_tetmesh_usd(paths.root)
    assert {"top", "bottom"} <= set(mesh.node_sets)
    assert read_material_usd(paths.root)["density_kg_per_m3"] == 1060.0


def _corrupt(folder, change):
    summary = json.loads((folder / "result.json").read_text())
    change(summary)
    (folder / "result.json").write_text(json.dumps(summary))


BAD_SUMMARIES = [
    pytest.param(
        lambda s: s.clear() or s.update(x=1) or None, "no study.material", id="no-material"
    ),
    pytest.param(
        lambda s: s["force_curve"].update(depth_m=["a", "b", "c"]),
        "force_curve.depth_m must be a list of numbers",
        id="depths-not-numbers",
    ),
    pytest.param(
        lambda s: s.update(force_curve=[1, 2]), "'force_curve' must be a JSON object", id="curve"
    ),
    pytest.param(lambda s: s.update(study=[1]), "'study' must be a JSON object", id="study"),
    pytest.param(
        lambda s: s["study"]["indenter"].update(radius_m=-1.0),
        "study.indenter.radius_m: must be a positive length",
        id="indenter",
    ),
]


@pytest.mark.parametrize(("change", "message"), BAD_SUMMARIES)
def test_cli_bad_result_json_is_one_line_exit_2(simulate_folder, tmp_path, capsys, change, message):
    folder = simulate_folder[0]
    _corrupt(folder, change)
    assert main(["export", str(folder), "--out", str(tmp_path / "x.usda")]) == 2
    error = capsys.readouterr().err.strip().splitlines()
    assert len(error) == 1 and "result.json" in error[0] and message in error[0]


def test_cli_result_json_that_is_not_an_object(simulate_folder, tmp_path, capsys):
    folder = simulate_folder[0]
    (folder / "result.json").write_text("[1, 2]")
    assert main(["export", str(folder), "--out", str(tmp_path / "x.usda")]) == 2
    assert "must hold a JSON object" in capsys.readouterr().err


def test_cli_unreadable_vtu_is_one_line_exit_2(simulate_folder, tmp_path, capsys):
    """meshio prints and exits on a file it cannot parse: that must not end the command."""
    folder = simulate_folder[0]
    (folder / "fields.vtu").write_text("not a vtu file")
    assert main(["export", str(folder), "--out", str(tmp_path / "x.usda")]) == 2
    captured = capsys.readouterr()
    error = captured.err.strip().splitlines()
    assert len(error) == 1 and "fields.vtu" in error[0] and "cannot read VTU" in error[0]
    assert captured.out == ""


def test_step_fields_of_another_mesh_are_refused(simulate_folder, tmp_path):
    folder, mesh, displacement, _, _ = simulate_folder
    grid = np.linspace(0.0, 0.01, 4)
    other = block_mesh(grid, grid, grid)
    for k in range(3):
        step_mesh, values = (
            (other, np.zeros((other.node_count, 3)))
            if k == 1
            else (
                mesh,
                displacement[k],
            )
        )
        _write_vtu(folder / f"fields_{k + 1:03d}.vtu", step_mesh, {"displacement_m": values}, {})
    with pytest.raises(InputError, match="another run") as caught:
        export_result_dir(folder, tmp_path / "x.usda")
    assert caught.value.path == folder / "fields_002.vtu"


def test_cli_out_must_be_usda_and_source_must_exist(simulate_folder, tmp_path, capsys):
    folder = simulate_folder[0]
    assert main(["export", str(folder), "--out", str(tmp_path / "x.usdc")]) == 2
    assert ".usda" in capsys.readouterr().err
    assert not list(tmp_path.glob("x.*"))
    assert main(["export", str(tmp_path / "missing.toml"), "--out", str(tmp_path / "y.usda")]) == 2
    assert "no such simulate output folder or study file" in capsys.readouterr().err


def test_a_probe_at_a_site_is_drawn_turned_to_its_direction(simulate_folder, tmp_path):
    """result.json's ``probe`` (a probe at a site, issue 34): the indenter's Xform stands at
    the site, its z turned to the frame's e3 (= -direction, the shape above the contact),
    and step k moves it by depth_k along the direction; the scene validates."""
    from pxr import Gf, Usd, UsdGeom

    from warptissue.fem.probe import probe_frame

    folder, *_ = simulate_folder
    frame = probe_frame(origin_m=[0.005, 0.004, 0.005], direction=[0.3, -0.2, -1.0])
    summary = json.loads((folder / "result.json").read_text())
    summary["probe"] = {
        "site_m": frame.origin_m.tolist(),
        "direction": frame.direction.tolist(),
        "axes": frame.axes.tolist(),
    }
    (folder / "result.json").write_text(json.dumps(summary))
    paths = export_result_dir(folder, tmp_path / "turned.usda")
    assert validate_stage(paths.root) == []
    stage = Usd.Stage.Open(str(paths.root))
    indenter = UsdGeom.Xformable(stage.GetPrimAtPath("/World/Indenter"))
    for time_code, depth in enumerate([0.0, 1e-4, 2e-4, 3e-4]):
        matrix = indenter.ComputeLocalToWorldTransform(time_code)
        position = np.array(matrix.ExtractTranslation())
        np.testing.assert_allclose(position, frame.origin_m + depth * frame.direction, atol=1e-12)
        up = np.array(matrix.TransformDir(Gf.Vec3d(0.0, 0.0, 1.0)))
        np.testing.assert_allclose(up, -frame.direction, atol=1e-12)
        edge = np.array(matrix.TransformDir(Gf.Vec3d(0.0, 1.0, 0.0)))
        np.testing.assert_allclose(edge, frame.axes[1], atol=1e-12)


ORGAN_STUDY = """\
schema_version = 1
name = "layered"
[specimen]
mesh = "{asset}"
element = "TET10"
[indenter]
kind = "sphere"
radius_m = 0.003
site_m = [0.0, 0.0, 0.004]
[protocol]
max_depth_m = 0.0002
steps = 2
[material]
model = "neo_hookean"
C10_Pa = 287.5
bulk_modulus_Pa = 575000.0
[boundary]
support = "zmin"
[solver]
device = "cpu"
"""


@pytest.fixture(scope="module")
def organ_run(tmp_path_factory):
    """An organ's asset (a block written by write_simulation_usd, with a flat punch drawn and
    its own material), a study that indents it with a sphere, and the run's output folder."""
    from warptissue.indenter import Indenter
    from warptissue.materials import NeoHookean
    from warptissue.usd import write_simulation_usd

    folder = tmp_path_factory.mktemp("layered")
    grid = np.linspace(-4e-3, 4e-3, 5)
    organ = block_mesh(grid, grid, np.linspace(0.0, 4e-3, 3))
    write_simulation_usd(
        folder / "organ.usda",
        organ,
        material=NeoHookean(500.0, 1e6),
        indenter=Indenter("flat_punch", radius_m=1e-3),
        density_kg_per_m3=1060.0,
    )
    (folder / "study.toml").write_text(ORGAN_STUDY.format(asset="organ.asset.usda"))
    run = ["simulate", str(folder / "study.toml"), "--out", str(folder / "run")]
    assert main([*run, "--quiet", "--vtu-every-step"]) == 0
    return folder


def test_a_run_is_layered_over_the_organ_s_own_asset(organ_run, tmp_path):
    """`export --over`: the organ's asset is referenced unchanged under an overlay and a
    results layer; the composed TetMesh moves by the run's displacement at every time code,
    the indenter is the run's sphere (the asset's punch blocked), the material the run's."""
    from pxr import Usd, UsdGeom

    asset = organ_run / "organ.asset.usda"
    before = asset.read_bytes()
    root = tmp_path / "scene" / "layered.usda"
    status = main(["export", str(organ_run / "run"), "--over", str(asset), "--out", str(root)])
    assert status == 0
    assert asset.read_bytes() == before
    assert validate_stage(root) == []
    stage = Usd.Stage.Open(str(root))
    layers = [layer.identifier for layer in stage.GetLayerStack(includeSessionLayers=False)]
    assert layers[-1].endswith("organ.asset.usda") and str(tmp_path) not in layers[-1]
    rest = read_tetmesh_usd(asset).points
    volume = UsdGeom.TetMesh(stage.GetPrimAtPath("/World/Specimen/Volume"))
    summary = json.loads((organ_run / "run" / "result.json").read_text())
    steps = len(summary["force_curve"]["depth_m"])
    for k in range(1, steps + 1):
        _, point_data, _ = read_fields_vtu(organ_run / "run" / f"fields_{k:03d}.vtu")
        moved = np.asarray(volume.GetPointsAttr().Get(k), dtype=np.float64)
        expected = rest + point_data["displacement_m"][: len(rest)]
        np.testing.assert_allclose(moved, expected, atol=1e-9)
    np.testing.assert_allclose(volume.GetPointsAttr().Get(0), rest, atol=1e-9)
    shape = stage.GetPrimAtPath("/World/Indenter/Shape")
    assert shape.GetTypeName() == "Sphere" and shape.GetAttribute("radius").Get() == 0.003
    assert shape.GetAttribute("height").Get() is None  # the asset's punch, blocked
    material = read_material_usd(root)
    assert material["material"]["C10_Pa"] == pytest.approx(287.5)
    assert material["density_kg_per_m3"] == pytest.approx(1060.0)  # the asset's, kept
    force = read_probe_curve_usd(root)
    np.testing.assert_allclose(
        force["reaction_force_N"][1:], summary["force_curve"]["reaction_force_N"]
    )


def test_a_run_on_another_mesh_or_units_is_not_layered(organ_run, tmp_path, capsys):
    from warptissue.usd import write_simulation_usd

    grid = np.linspace(-4e-3, 4e-3, 4)
    write_simulation_usd(
        tmp_path / "other.usda",
        block_mesh(grid, grid, np.linspace(0.0, 4e-3, 3)),
        material=MATERIAL,
    )
    millimetres = tmp_path / "mm.asset.usda"
    text = (organ_run / "organ.asset.usda").read_text()
    millimetres.write_text(text.replace("metersPerUnit = 1", "metersPerUnit = 0.001", 1))
    for asset, message in (
        (tmp_path / "other.asset.usda", "is not the asset's"),
        (millimetres, "layering needs an asset in metres"),
        (tmp_path / "missing.usda", "over an existing USD asset"),
    ):
        root = tmp_path / "out" / "scene.usda"
        status = main(["export", str(organ_run / "run"), "--over", str(asset), "--out", str(root)])
        err = capsys.readouterr().err.strip()
        assert status == 2 and "--over" in err and message in err and "\n" not in err, err
        assert not root.parent.exists()


def test_a_run_refined_from_the_asset_is_transferred_onto_it(organ_run, tmp_path):
    """A run on a mesh refined around a site (TetGen's fill of the asset's bisected surface)
    layers over the asset: a quadratic displacement field of the run arrives at the asset's
    nodes exactly (TET10 interpolation), a uniform stress as it is, and /World says the
    fields were transferred."""
    from pxr import Usd, UsdGeom

    from warptissue.indenter import Indenter
    from warptissue.mesh import refine_near_sites, to_tet10
    from warptissue.usd import write_results_over_asset

    asset = organ_run / "organ.asset.usda"
    organ = read_tetmesh_usd(asset)
    organ.tet_regions[:] = 0  # the block's regions are its hexahedra, one material
    refined = to_tet10(
        refine_near_sites(organ, sites_m=[[0.0, 0.0, 4e-3]], zone_radii_m=[2e-3], sizes_m=[1e-3])
    )
    assert refined.node_count > 2 * organ.node_count

    def field(points, scale):
        return scale * np.column_stack(
            [points[:, 0] * points[:, 2], points[:, 1] ** 2, -(points[:, 2] ** 2)]
        )

    steps = (1.0, 2.0)
    stress = np.tile(np.arange(1.0, 7.0), (refined.tet_count, 1))
    result = {
        "depths_m": np.array([1e-4, 2e-4]),
        "reaction_force_N": np.array([1e-3, 2e-3]),
        "displacement_m": np.stack([field(refined.points, s) for s in steps]),
        "cauchy_stress_Pa": stress,
        "von_mises_Pa": np.full(refined.tet_count, 5.0),
    }
    root = tmp_path / "refined.usda"
    write_results_over_asset(
        root, asset, refined, result=result, indenter=Indenter("sphere", radius_m=3e-3)
    )
    assert validate_stage(root) == []
    stage = Usd.Stage.Open(str(root))
    volume = UsdGeom.TetMesh(stage.GetPrimAtPath("/World/Specimen/Volume"))
    for k, scale in enumerate(steps, start=1):
        moved = np.asarray(volume.GetPointsAttr().Get(k), dtype=np.float64)
        np.testing.assert_allclose(moved, organ.points + field(organ.points, scale), atol=1e-12)
    written = np.asarray(volume.GetPrim().GetAttribute("primvars:tissue:cauchyStress").Get(2))
    np.testing.assert_allclose(
        written.reshape(-1, 6), np.tile(np.arange(1.0, 7.0), (organ.tet_count, 1))
    )
    how = stage.GetPrimAtPath("/World").GetCustomDataByKey("warptissue")["transferred_from"]
    assert how["nodes"] == refined.node_count
