"""The specimen size estimate: exact counts against generated meshes, and the refusal of a
mesh that cannot fit in memory before any of it is allocated."""

from __future__ import annotations

import pytest

from warptissue.cli import main
from warptissue.errors import MeshError
from warptissue.mesh import estimate_indentation_mesh, indentation_block, indentation_disc
from warptissue.mesh import size as mesh_size

SPECIMEN = {
    "thickness_m": 0.006,
    "probe_radius_m": 0.002,
    "size_near_m": 0.0008,
    "size_far_m": 0.002,
}


@pytest.mark.parametrize("shape", ["block", "disc"])
@pytest.mark.parametrize("element", ["TET4", "TET10"])
@pytest.mark.parametrize("quarter", [True, False])
def test_counts_are_those_of_the_generated_mesh(shape, element, quarter):
    options = {**SPECIMEN, "quarter": quarter, "element": element, "growth": 1.3}
    if shape == "block":
        options["layer_max_m"] = 0.001
        mesh = indentation_block(width_m=0.016, **options)
    else:
        mesh = indentation_disc(radius_m=0.009, **options)
    half_extent_m = 0.008 if shape == "block" else 0.009
    estimate = estimate_indentation_mesh(shape=shape, half_extent_m=half_extent_m, **options)
    assert (estimate.tet_count, estimate.node_count) == (mesh.tet_count, mesh.node_count)
    assert estimate.element == element
    assert estimate.mesh_bytes > 0 and estimate.solve_bytes > 0


def test_the_delaunay_mesh_stays_within_the_extruded_count():
    options = {**SPECIMEN, "element": "TET4"}
    mesh = indentation_block(width_m=0.016, mesher="delaunay", **options)
    estimate = estimate_indentation_mesh(shape="block", half_extent_m=0.008, **options)
    assert 0.3 * estimate.tet_count < mesh.tet_count <= estimate.tet_count


def test_a_mesh_that_does_not_fit_is_refused_with_the_numbers():
    estimate = estimate_indentation_mesh(shape="block", half_extent_m=0.008, **SPECIMEN)
    estimate.require_fits(available_bytes=estimate.mesh_bytes)
    with pytest.raises(MeshError, match=r"about [\d,]+ TET10 tets and [\d,]+ nodes .* GiB"):
        estimate.require_fits(available_bytes=estimate.mesh_bytes - 1)
    # A simulation needs more than the generation, from a few thousand nodes on.
    estimate.require_fits(available_bytes=estimate.solve_bytes)
    with pytest.raises(MeshError, match="generate and solve"):
        estimate.require_fits(solve=True, available_bytes=estimate.solve_bytes - 1)


def test_the_simulation_memory_law_reproduces_its_measurements():
    """The law is fitted to three measured CPU runs (docs/performance.md); it must give each
    within 5 % (12 915, 44 325 and 104 067 DOFs took 89, 437 and 1 225 MiB)."""
    for dofs, mib in ((12_915, 89), (44_325, 437), (104_067, 1225)):
        predicted = mesh_size._sized(1.0, dofs / 3, "TET10").solve_bytes / 2**20
        assert predicted == pytest.approx(mib, rel=0.05)


def test_an_astronomical_mesh_is_counted_from_a_bound_at_once():
    estimate = estimate_indentation_mesh(
        shape="disc",
        half_extent_m=0.02,
        thickness_m=0.01,
        probe_radius_m=0.0025,
        size_near_m=1e-9,
        size_far_m=1e-9,
    )
    assert estimate.tet_count > mesh_size.MAX_INDEX
    with pytest.raises(MeshError, match="32-bit indices"):
        estimate.require_fits()


def test_the_generators_refuse_before_allocating(monkeypatch):
    monkeypatch.setattr(mesh_size, "available_host_memory_bytes", lambda: 10**6)
    with pytest.raises(MeshError, match="GiB is available"):
        indentation_block(width_m=0.016, **SPECIMEN)
    with pytest.raises(MeshError, match="32-bit indices"):
        indentation_disc(
            radius_m=0.02, thickness_m=0.01, probe_radius_m=0.0025, size_near_m=1e-9,
            size_far_m=1e-9,
        )  # fmt: skip


def test_mesh_block_that_cannot_fit_is_a_one_line_error(tmp_path, capsys, monkeypatch):
    """``warptissue mesh block`` with sizes far too small: exit 3, one line, no file."""
    out = tmp_path / "huge.vtu"
    status = main(
        [
            "mesh", "block", "--width-m", "0.04", "--thickness-m", "0.02",
            "--probe-radius-m", "2.5mm", "--size-near-m", "1um", "--size-far-m", "5um",
            "--out", str(out),
        ]
    )  # fmt: skip
    err = capsys.readouterr().err
    assert status == 3
    assert err.startswith("warptissue: error: the mesh would have about ")
    assert err.count("\n") == 1
    assert not out.exists()
    monkeypatch.setattr(mesh_size, "available_host_memory_bytes", lambda: 2**20)
    small = ["--size-near-m", "0.8mm", "--size-far-m", "2mm", "--out", str(out)]
    status = main(
        [
            "mesh", "disc", "--radius-m", "8mm", "--thickness-m", "6mm",
            "--probe-radius-m", "2mm", *small,
        ]
    )  # fmt: skip
    assert status == 3
    assert "GiB is available" in capsys.readouterr().err
    assert not out.exists()
