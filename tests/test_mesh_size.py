"""The specimen size estimate: exact counts against generated meshes, and the refusal of a
mesh that cannot fit in memory before any of it is allocated; the near size chosen for a
force accuracy from the measured table."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from warptissue.cli import main
from warptissue.errors import InputError, MeshError
from warptissue.mesh import (
    FORCE_ACCURACY_DEPTH_RATIO,
    estimate_indentation_mesh,
    force_accuracy_depth_warning,
    indentation_block,
    indentation_disc,
    near_size_choice,
    size_near_for_force_accuracy,
)
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


# --------------------------------------------------------------------------- force accuracy

ROOT = Path(__file__).resolve().parents[1]
SIZE_RESULTS = {
    mesher: sorted((ROOT / "scripts/results").glob(f"bench_flat_punch_size_near_{mesher}_*.json"))
    for mesher in ("extruded", "delaunay")
}
REFERENCE_FORCE_N = 2.460e-3  # bench_flat_punch.REFERENCE_FORCE_N


@pytest.mark.parametrize("mesher", ["extruded", "delaunay"])
def test_the_force_error_table_is_the_benchmarks_measurement(mesher):
    """FLAT_PUNCH_FORCE_ERRORS holds, per mesher, each completed run of the size-near
    benchmark files: its near size over the punch radius and its force error."""
    measured = []
    for path in SIZE_RESULTS[mesher]:
        report = json.loads(path.read_text())
        assert report["problem"]["warptissue_mesher"] == mesher
        radius = report["problem"]["probe_radius_m"]
        measured += [
            (
                round(run["size_near_m"] / radius, 6),
                round(abs(run["final_force_N"] / REFERENCE_FORCE_N - 1.0), 4),
            )
            for run in report["runs"]
            if run["completed"] and run["size_far_m"] == pytest.approx(2.5 * radius)
        ]
    assert sorted(mesh_size.FLAT_PUNCH_FORCE_ERRORS[mesher]) == sorted(measured)


@pytest.mark.parametrize("mesher", ["extruded", "delaunay"])
def test_the_near_size_grows_with_the_accuracy(mesher):
    accuracies = np.linspace(mesh_size.FORCE_ACCURACY_FLOOR, 0.5, 200)
    sizes = [
        size_near_for_force_accuracy(a, probe_radius_m=2e-3, mesher=mesher) for a in accuracies
    ]
    assert np.all(np.diff(sizes) >= 0)
    assert min(sizes) > 0 and max(sizes) <= 2e-3  # never coarser than the probe


@pytest.mark.parametrize("mesher", ["extruded", "delaunay"])
def test_the_near_size_reproduces_the_measured_points(mesher):
    """At each measured error that no finer size exceeded, the size is that point's own (or a
    coarser one that also met it), and its measured error meets the accuracy."""
    points = sorted(mesh_size.FLAT_PUNCH_FORCE_ERRORS[mesher])
    for index, (ratio, error) in enumerate(points):
        if error < mesh_size.FORCE_ACCURACY_FLOOR:
            continue
        if any(finer_error > error for _, finer_error in points[:index]):
            continue
        choice = near_size_choice(error, probe_radius_m=1e-3, mesher=mesher)
        assert choice.size_ratio >= ratio
        assert choice.size_near_m == pytest.approx(choice.size_ratio * 1e-3)
        assert choice.measured_error <= error
        # Every measured size at or below the chosen one met the accuracy.
        assert all(e <= error for r, e in points if r <= choice.size_ratio)
        assert "force_accuracy" in choice.reason() and mesher in choice.reason()


@pytest.mark.parametrize(
    "options, key, fragment",
    [
        ({"accuracy": 0.001}, "force_accuracy", "must lie in [0.01, 1)"),
        ({"accuracy": 1.5}, "force_accuracy", "must lie in [0.01, 1)"),
        ({"accuracy": float("nan")}, "force_accuracy", "must lie in"),
        ({"accuracy": True}, "force_accuracy", "must be a number"),
        ({"accuracy": 0.02, "mesher": "octree"}, "mesher", "must be one of"),
        ({"accuracy": 0.02, "element": "TET4"}, "element", "TET10"),
        ({"accuracy": 0.02, "indenter": "sphere"}, "indenter", "flat punch"),
        ({"accuracy": 0.02, "probe_radius_m": 0.0}, "probe_radius_m", "positive"),
    ],
)
def test_an_accuracy_outside_what_was_measured_is_refused(options, key, fragment):
    options = {"probe_radius_m": 1e-3, **options}
    accuracy = options.pop("accuracy")
    with pytest.raises(InputError) as raised:
        size_near_for_force_accuracy(accuracy, **options)
    assert raised.value.column == key
    assert fragment in str(raised.value)
    if key == "force_accuracy" and "lie in" in fragment:
        assert "range from" in str(raised.value)  # the measured range is named


def test_a_generator_takes_the_accuracy_instead_of_the_near_size():
    common = {"width_m": 0.02, "thickness_m": 0.01, "probe_radius_m": 1e-3, "size_far_m": 2.5e-3}
    mesh = indentation_block(force_accuracy=0.02, **common)
    size = size_near_for_force_accuracy(0.02, probe_radius_m=1e-3)
    same = indentation_block(size_near_m=size, **common)
    assert (mesh.tet_count, mesh.node_count) == (same.tet_count, same.node_count)
    with pytest.raises(InputError, match="not both"):
        indentation_block(force_accuracy=0.02, size_near_m=size, **common)
    with pytest.raises(InputError, match="either size_near_m or force_accuracy"):
        indentation_disc(radius_m=0.01, thickness_m=0.01, probe_radius_m=1e-3, size_far_m=2e-3)


def test_the_force_accuracy_s_depth_range_is_half_the_probe_radius():
    """Issue 36: the size rule holds to the benchmark's depth (half the probe radius); a
    deeper depth gets one line naming the key, the depth and the range."""
    assert FORCE_ACCURACY_DEPTH_RATIO == 0.5
    assert force_accuracy_depth_warning(0.01, depth_m=1e-3, probe_radius_m=2e-3) is None
    message = force_accuracy_depth_warning(0.02, depth_m=2.08e-3, probe_radius_m=2e-3)
    assert message is not None and "\n" not in message
    assert "specimen.force_accuracy = 0.02" in message
    assert "up to 0.5 probe radii (0.001 m)" in message and "0.00208 m (1.04 probe" in message
