"""The trainer-calibrated material (warptissue.fit.trainer) and its USD asset."""

from __future__ import annotations

import numpy as np
import pytest

from warptissue.cli import main
from warptissue.errors import InputError
from warptissue.fem import IndentationProblem, simulate_indentation
from warptissue.fit.trainer import calibrate_trainer_material, trainer_mesh
from warptissue.indenter import Indenter
from warptissue.materials import StableNeoHookean
from warptissue.mesh import indentation_block
from warptissue.study import load_study
from warptissue.usd import read_material_usd, read_tetmesh_usd
from warptissue.usd.reader import read_particle_radii_usd
from warptissue.usd.trainer import particle_radii

STUDY = """
schema_version = 1
name = "small_punch"

[specimen]
shape = "block"
width_m = 0.020
thickness_m = 0.010
quarter = true
element = "TET10"
size_near_m = 0.0015
size_far_m = 0.005
growth = 1.5

[indenter]
kind = "flat_punch"
radius_m = 0.0025
contact = "bonded"

[protocol]
max_depth_m = 0.0005
steps = 2

[material]
model = "neo_hookean"
C10_Pa = 287.5
bulk_modulus_Pa = 575000.0
"""


@pytest.fixture
def study(tmp_path):
    path = tmp_path / "small_punch.toml"
    path.write_text(STUDY)
    return load_study(path)


def _whole_block():
    """A small whole block on linear tets."""
    return indentation_block(
        width_m=0.01,
        thickness_m=0.005,
        probe_radius_m=0.0015,
        quarter=False,
        element="TET4",
        size_near_m=0.0015,
        size_far_m=0.004,
        growth=1.5,
    )


def test_trainer_force_scales_with_youngs_modulus_at_a_fixed_poissons_ratio():
    """The closed-form E of the calibration rests on this: Newton's energy is linear in
    (mu, lambda), so scaling E at a fixed nu scales every force by the same factor."""
    mesh = _whole_block()
    probe = Indenter("flat_punch", radius_m=0.0015, contact="bonded")
    forces = []
    for youngs in (1000.0, 3700.0):
        problem = IndentationProblem(
            mesh,
            StableNeoHookean(youngs, 0.42),
            probe,
            symmetry_planes=(),
            formulation="displacement",
        )
        forces.append(simulate_indentation(problem, [2e-4, 5e-4], device="cpu", progress=False))
    np.testing.assert_allclose(
        forces[1].reaction_force_N, 3.7 * forces[0].reaction_force_N, rtol=1e-8
    )


def test_trainer_mesh_is_the_whole_body_on_linear_tets_within_max_tets(study):
    mesh = trainer_mesh(study)
    assert mesh.nodes_per_tet == 4
    assert "symmetry_x" not in mesh.node_sets and "symmetry_y" not in mesh.node_sets
    xy = mesh.points[:, :2]
    np.testing.assert_allclose(xy.min(axis=0), [-0.01, -0.01])
    coarse = trainer_mesh(study, max_tets=mesh.tet_count // 2)
    assert coarse.tet_count <= mesh.tet_count // 2
    with pytest.raises(InputError, match="--max-tets"):
        trainer_mesh(study, max_tets=0)
    with pytest.raises(InputError, match="at most 3 tets"):
        trainer_mesh(study, max_tets=3)


def test_particle_radii_are_half_the_mean_edge_at_each_node():
    points = np.array([[0, 0, 0], [1, 0, 0], [0, 2, 0], [0, 0, 3]], dtype=float)
    radii = particle_radii(points, np.array([[0, 1, 2, 3]]))
    edges = {(0, 1): 1, (0, 2): 2, (0, 3): 3, (1, 2): 5**0.5, (1, 3): 10**0.5, (2, 3): 13**0.5}
    for node in range(4):
        at = [length for pair, length in edges.items() if node in pair]
        assert radii[node] == pytest.approx(0.5 * np.mean(at))


@pytest.mark.slow
def test_calibration_undoes_the_locking_and_the_asset_keeps_both_materials(study, tmp_path):
    """On the small block the calibrated trainer reproduces the locking-free force of the
    fitted probe within 2 % at every depth, with a smaller E than the tissue's (its linear
    tets lock) and nu inside the bounds; the asset written by the CLI holds the calibrated
    physics material, the tissue's true values and the particle sizes."""
    calibration = calibrate_trainer_material(study, depth_count=2, check_radius_factors=())
    fitted = [p for p in calibration.probes if p.fitted]
    assert len(fitted) == 1
    assert np.all(np.abs(fitted[0].relative_error) < 0.02)
    assert calibration.youngs_modulus_Pa < calibration.true_youngs_modulus_Pa
    assert 0.30 <= calibration.poissons_ratio <= 0.48
    assert calibration.volume_change < 0  # the compressible trainer loses volume
    # the reported trainer curve is what the calibrated material gives
    mesh = trainer_mesh(study)
    problem = IndentationProblem(
        mesh,
        StableNeoHookean(calibration.youngs_modulus_Pa, calibration.poissons_ratio),
        study.indenter,
        symmetry_planes=(),
        formulation="displacement",
    )
    again = simulate_indentation(problem, fitted[0].depths_m, device="cpu", progress=False)
    np.testing.assert_allclose(again.reaction_force_N, fitted[0].trainer_force_N, rtol=1e-6)

    out = tmp_path / "trainer.usda"
    assert main(["export", str(study.path), "--trainer", "--out", str(out)]) == 0
    record = read_material_usd(out)
    written = record["trainer"]
    assert record["poissons_ratio"] == pytest.approx(written["poissons_ratio"], rel=1e-6)
    assert record["youngs_modulus_Pa"] == pytest.approx(written["youngs_modulus_Pa"], rel=1e-6)
    assert record["youngs_modulus_Pa"] < calibration.true_youngs_modulus_Pa
    assert record["small_strain_youngs_modulus_Pa"] == pytest.approx(
        calibration.true_youngs_modulus_Pa, rel=1e-6
    )
    assert record["material"]["C10_Pa"] == 287.5
    assert written["probes"]["probe_0"]["fitted"] is True
    assert max(abs(e) for e in written["probes"]["probe_0"]["relative_error"]) < 0.02
    back = read_tetmesh_usd(out)
    assert back.tet_count == mesh.tet_count
    np.testing.assert_allclose(
        read_particle_radii_usd(out), particle_radii(back.points, back.tets), rtol=1e-6
    )


def test_max_tets_needs_trainer(study, tmp_path, capsys):
    code = main(["export", str(study.path), "--max-tets", "100", "--out", str(tmp_path / "a.usda")])
    assert code == 2
    assert "--max-tets needs --trainer" in capsys.readouterr().err


def test_a_calibration_without_the_material_is_refused(tmp_path):
    from warptissue.usd import write_simulation_usd

    mesh = _whole_block()
    with pytest.raises(InputError, match="needs the material"):
        write_simulation_usd(tmp_path / "a.usda", mesh, trainer={"youngs_modulus_Pa": 1.0})
    assert not (tmp_path / "a.usda").exists()
