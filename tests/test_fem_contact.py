"""Rigid indenters with frictionless penalty contact (issue 21): the sphere and the plate.

Checked against independent truths: the homogeneous analytic stress of plate compression,
Hertz's sphere, the limit of a stiff penalty, and central differences of whole runs.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_fem_solvers import ANALYTIC

from warptissue.errors import InputError
from warptissue.fem import IndentationProblem, NewtonOptions, simulate_indentation
from warptissue.fem.contact import DEFAULT_PENALTY_FACTOR
from warptissue.indenter import CONTACT_KINDS, SIMULATED_KINDS, Indenter
from warptissue.materials import NeoHookean, Viscoelastic, material_from_dict
from warptissue.mesh import TetMesh, block_mesh, graded_coordinates, indentation_block, to_tet10
from warptissue.study import load_study

STUDY = """\
schema_version = 1

[specimen]
shape = "block"
width_m = 0.02
thickness_m = 0.01

[indenter]
{indenter}

[protocol]
max_depth_m = 0.0005
steps = 4

[material]
model = "neo_hookean"
C10_Pa = 287.5
bulk_modulus_Pa = 575000.0
"""


def test_sphere_and_plate_are_simulated_frictionless_kinds():
    assert set(CONTACT_KINDS) <= set(SIMULATED_KINDS)
    sphere = Indenter("sphere", radius_m=2e-3)
    assert sphere.contact == "frictionless"
    assert sphere.to_dict() == {"kind": "sphere", "radius_m": 2e-3, "contact": "frictionless"}
    assert Indenter("plate").to_dict() == {"kind": "plate", "contact": "frictionless"}
    assert Indenter("flat_punch", radius_m=1e-3).contact == "bonded"


@pytest.mark.parametrize("kind", ["sphere", "plate"])
def test_a_bonded_rigid_contact_is_refused_by_key(kind):
    with pytest.raises(InputError) as caught:
        Indenter(kind, radius_m=1e-3, contact="bonded")
    assert caught.value.column == "contact"
    assert "\n" not in str(caught.value)


def test_a_sphere_needs_a_radius():
    with pytest.raises(InputError) as caught:
        Indenter("sphere")
    assert caught.value.column == "radius_m"


def _write(tmp_path: Path, indenter: str) -> Path:
    path = tmp_path / "study.toml"
    path.write_text(STUDY.format(indenter=indenter), encoding="utf-8")
    return path


def test_study_files_accept_a_sphere_and_a_plate(tmp_path):
    study = load_study(_write(tmp_path, 'kind = "sphere"\nradius_m = 0.002'))
    assert study.indenter == Indenter("sphere", radius_m=0.002)
    study = load_study(_write(tmp_path, 'kind = "plate"'))
    assert study.indenter == Indenter("plate")
    assert study.specimen.size_near_m > 0


def test_study_file_refuses_a_bonded_sphere_naming_the_key(tmp_path):
    path = _write(tmp_path, 'kind = "sphere"\nradius_m = 0.002\ncontact = "bonded"')
    with pytest.raises(InputError) as caught:
        load_study(path)
    assert caught.value.column == "contact" or "contact" in str(caught.value)
    assert "\n" not in str(caught.value)


# ---------------------------------------------------------------- plates: homogeneous stress

SIDE_M = 1e-2
PENALTIES = (300.0, 1000.0, 3000.0, 30000.0)


def _plate_cube() -> TetMesh:
    """The 2 x 2 x 2-cell TET10 cube of tests/test_fem_solvers.py with the indentation sets:
    the plate presses "top" (z = side), "bottom" slides on z = 0, symmetry on x = 0, y = 0."""
    grid = np.linspace(0.0, SIDE_M, 3)
    mesh = to_tet10(block_mesh(grid, grid, grid))
    sets = dict(mesh.node_sets)
    sets.update(
        top=sets["zmax"], bottom=sets["zmin"], symmetry_x=sets["xmin"], symmetry_y=sets["ymin"]
    )
    return TetMesh(points=mesh.points, tets=mesh.tets, node_sets=sets, face_sets=mesh.face_sets)


def _plate_run(material, stretches, **problem_options):
    problem = IndentationProblem(
        _plate_cube(), material, Indenter("plate"), base="sliding", **problem_options
    )
    result = simulate_indentation(problem, SIDE_M * (1.0 - stretches), device="cpu", progress=False)
    assert result.completed, result.message
    return problem, result


@pytest.mark.parametrize("name", list(ANALYTIC))
def test_plate_compression_matches_the_homogeneous_analytic_stress(name):
    material, analytic = ANALYTIC[name]
    stretches = np.array([0.9, 0.8, 0.7])
    # The penalty follows the initial shear modulus; this reduced polynomial stiffens to 7.7
    # mu0 of nominal stress at 0.7 and needs a stiffer one there (beta = 1000: 1.0 % low).
    beta = 1e4 if name == "reduced_polynomial_2" else DEFAULT_PENALTY_FACTOR
    problem, result = _plate_run(material, stretches, penalty_factor=beta)
    # The quarter model's force times 4 over the full face (2 side)^2: nominal stress.
    nominal = -result.reaction_force_N / (2.0 * SIDE_M) ** 2
    np.testing.assert_allclose(nominal, analytic(stretches), rtol=5e-3)
    # The base reaction and the contact force sum agree at convergence.
    np.testing.assert_allclose(result.contact_force_N, result.reaction_force_N, rtol=1e-8)
    # The penalty lets the plate into the top by a small fraction of the depth only.
    assert np.all(result.max_penetration_m < 1e-3 * SIDE_M * (1.0 - stretches))
    assert np.all(result.newton_iterations <= 10)
    assert result.to_dict()["contact_force_N"] == result.contact_force_N.tolist()


def test_plate_force_is_insensitive_to_the_penalty_factor():
    """Documented range beta = 300 ... 30 000 (docs/fe.md "Contact"): the force within 1 %
    of the stiffest penalty's, and the penetration falling as 1 / beta."""
    material = ANALYTIC["neo_hookean"][0]
    stretches = np.array([0.8])
    runs = {beta: _plate_run(material, stretches, penalty_factor=beta)[1] for beta in PENALTIES}
    stiffest = runs[max(PENALTIES)]
    for beta, result in runs.items():
        assert abs(result.reaction_force_N[0] / stiffest.reaction_force_N[0] - 1.0) < 1e-2, beta
    penetrations = np.array([runs[beta].max_penetration_m[0] for beta in PENALTIES])
    np.testing.assert_allclose(
        penetrations * np.array(PENALTIES), penetrations[0] * PENALTIES[0], rtol=0.05
    )


# ---------------------------------------------------------------- sphere

RADIUS_M = 1e-3
C10_PA = 500.0


def _hertz_N(depth_m: np.ndarray) -> np.ndarray:
    """Hertz, nu = 0.5, E = 6 C10: F = (16/9) E sqrt(R) d^(3/2)."""
    return 16.0 / 9.0 * 6.0 * C10_PA * np.sqrt(RADIUS_M) * depth_m**1.5


def _dimitriadis_factor(depth_m: np.ndarray, thickness_m: float) -> np.ndarray:
    """Dimitriadis et al. (2002, Biophys. J. 82) correction of Hertz for a layer of thickness
    h bonded to a rigid base, nu = 0.5, chi = sqrt(R d) / h."""
    chi = np.sqrt(RADIUS_M * depth_m) / thickness_m
    return 1 + 1.133 * chi + 1.283 * chi**2 + 0.769 * chi**3 + 0.0975 * chi**4


@pytest.fixture(scope="module")
def sphere_mesh() -> TetMesh:
    """A small quarter block under a sphere: 3 R wide, 1.5 R thick, refined to a/2 within
    the contact radius a = sqrt(R d) of 0.04 R depth (about 3000 TET10 nodes)."""
    contact_radius = 0.2 * RADIUS_M
    return indentation_block(
        width_m=3.0 * RADIUS_M,
        thickness_m=SPHERE_THICKNESS_M,
        probe_radius_m=contact_radius,
        size_near_m=0.5 * contact_radius,
        size_far_m=0.6 * RADIUS_M,
    )


SPHERE_THICKNESS_M = 1.5 * RADIUS_M
SPHERE_DEPTHS_M = RADIUS_M * np.array([0.02, 0.04])


def _sphere_problem(mesh, material=None, **options) -> IndentationProblem:
    material = NeoHookean(C10_PA, 2000.0 * C10_PA) if material is None else material
    return IndentationProblem(mesh, material, Indenter("sphere", radius_m=RADIUS_M), **options)


@pytest.fixture(scope="module")
def sphere_run(sphere_mesh):
    result = simulate_indentation(
        _sphere_problem(sphere_mesh), SPHERE_DEPTHS_M, device="cpu", progress=False
    )
    assert result.completed, result.message
    return result


@pytest.mark.slow
def test_sphere_force_follows_hertz_on_a_coarse_layer(sphere_run):
    """Coarse check (the 3 % case on a large block is scripts/examples/hertz_sphere.py): on
    this thin layer the force lies within 8 % of Hertz corrected for the layer's thickness
    (Dimitriadis), 5-11 % above bare Hertz (measured)."""
    hertz = _hertz_N(SPHERE_DEPTHS_M)
    corrected = hertz * _dimitriadis_factor(SPHERE_DEPTHS_M, SPHERE_THICKNESS_M)
    np.testing.assert_allclose(sphere_run.reaction_force_N, corrected, rtol=0.08)
    np.testing.assert_allclose(sphere_run.contact_force_N, sphere_run.reaction_force_N, rtol=1e-8)
    assert np.all(sphere_run.max_penetration_m < 2e-3 * SPHERE_DEPTHS_M)


@pytest.mark.slow
def test_sphere_force_is_insensitive_to_the_penalty_factor(sphere_mesh, sphere_run):
    soft = simulate_indentation(
        _sphere_problem(sphere_mesh, penalty_factor=min(PENALTIES)),
        SPHERE_DEPTHS_M,
        device="cpu",
        progress=False,
    )
    np.testing.assert_allclose(soft.reaction_force_N, sphere_run.reaction_force_N, rtol=1e-2)
    assert np.all(soft.max_penetration_m > sphere_run.max_penetration_m)


@pytest.mark.slow
@pytest.mark.parametrize("integration", ["nodes", "surface"])
def test_sensitivities_through_contact_match_central_differences(sphere_mesh, integration):
    """Exact dF/dtheta (the penalty's own dependence on mu0 included) against central
    differences of whole runs with a tight Newton tolerance, relative step 1e-6 (measured
    6e-8 for C10, 2e-6 for K), for the nodal and the surface-integrated contact
    (warptissue.fem.surface_contact)."""
    tight = NewtonOptions(tolerance=1e-12)
    material = NeoHookean(C10_PA, 50.0 * C10_PA)
    names = ("C10_Pa", "bulk_modulus_Pa")
    depths = SPHERE_DEPTHS_M[-1:]
    exact = simulate_indentation(
        _sphere_problem(sphere_mesh, material, contact_integration=integration),
        depths,
        device="cpu",
        progress=False,
        options=tight,
        sensitivities=names,
    )
    assert exact.completed, exact.message
    flat = material.to_dict()
    for column, name in enumerate(names):
        step = 1e-6 * flat[name]
        forces = []
        for sign in (1.0, -1.0):
            moved = material_from_dict({**flat, name: flat[name] + sign * step})
            run = simulate_indentation(
                _sphere_problem(sphere_mesh, moved, contact_integration=integration),
                depths,
                device="cpu",
                progress=False,
                options=tight,
            )
            forces.append(run.reaction_force_N[0])
        reference = (forces[0] - forces[1]) / (2.0 * step)
        value = exact.force_sensitivity_N_per_unit[0, column]
        assert abs(value / reference - 1.0) < 1e-4, (name, value, reference)


def test_bad_contact_input_is_refused_by_key(sphere_mesh):
    material = NeoHookean(C10_PA, 2000.0 * C10_PA)
    off_axis = Indenter("sphere", radius_m=RADIUS_M, x_m=1e-4)
    with pytest.raises(InputError) as caught:  # a quarter model needs the probe on its axis
        IndentationProblem(sphere_mesh, material, off_axis)
    assert caught.value.column == "x_m"
    with pytest.raises(InputError) as caught:
        _sphere_problem(sphere_mesh, penalty_factor=0.0)
    assert caught.value.column == "penalty_factor"
    far = Indenter("sphere", radius_m=1e-4, x_m=-5.0 * RADIUS_M)
    with pytest.raises(InputError) as caught:  # off the axis of a full model, beside the block
        IndentationProblem(sphere_mesh, material, far, symmetry_planes=())
    assert caught.value.column == "radius_m"
    for error in (caught.value,):
        assert "\n" not in str(error)


STUDY_COARSE = "thickness_m = 0.01\nsize_near_m = 0.001\nsize_far_m = 0.005\n"


def test_a_sphere_study_builds_and_simulates(tmp_path):
    """The study path (mesh and problem from the study file) runs a sphere end to end."""
    from warptissue.simulate import build_mesh, build_problem

    path = _write(tmp_path, 'kind = "sphere"\nradius_m = 0.002')
    text = path.read_text().replace("thickness_m = 0.01\n", STUDY_COARSE)
    path.write_text(text, encoding="utf-8")
    study = load_study(path)
    mesh = build_mesh(study)
    problem = build_problem(study, mesh)
    assert problem.is_contact and problem.punch_nodes.size == 0
    result = simulate_indentation(problem, [1e-4], device="cpu", progress=False)
    assert result.completed, result.message
    # Hertz with the study's E = 6 C10 (K/mu = 1000): measured +0.4 % on this coarse mesh.
    hertz = 16.0 / 9.0 * 6.0 * 287.5 * np.sqrt(0.002) * 1e-4**1.5
    assert result.reaction_force_N[0] == pytest.approx(hertz, rel=0.1)


def test_a_sphere_on_a_viscoelastic_block_relaxes_at_a_held_depth(sphere_mesh):
    """Timed run: ramp to 0.04 R, hold. The force relaxes toward the long-term share
    (1 - g) of the instantaneous one, and the contact force stays the base reaction."""
    elastic = NeoHookean(C10_PA, 2000.0 * C10_PA)
    material = Viscoelastic(elastic, g=(0.5,), tau_s=(1.0,))
    depth = SPHERE_DEPTHS_M[-1]
    result = simulate_indentation(
        _sphere_problem(sphere_mesh, material),
        [depth, depth, depth],
        times_s=[1e-3, 1.0, 20.0],
        device="cpu",
        progress=False,
    )
    assert result.completed, result.message
    force = result.reaction_force_N
    assert force[0] > force[1] > force[2]
    assert force[2] / force[0] == pytest.approx(0.5, rel=0.05)
    np.testing.assert_allclose(result.contact_force_N, force, rtol=1e-8)


# --- The rigid bodies' geometry: the kernel's signed distance, force and tangent -----------

BODIES = {
    "sphere": Indenter("sphere", radius_m=2e-3),
    "plate": Indenter("plate"),
    "rounded_punch": Indenter("flat_punch", radius_m=2e-3, edge_radius_m=0.5e-3),
    "hemispherical_punch": Indenter("flat_punch", radius_m=1e-3, edge_radius_m=1e-3),
    "wedge": Indenter("wedge", radius_m=0.4e-3, angle_deg=30.0),
    "cylinder": Indenter("wedge", radius_m=0.4e-3, angle_deg=0.0),
}
CONTACT_DEPTH_M = 1.0e-3


def _profile(probe: Indenter) -> np.ndarray:
    """The indenter's outline in its plane of symmetry (r or x, z), densely sampled, at the
    contact depth: the independent description the kernel's distance is checked against."""
    z0 = -CONTACT_DEPTH_M
    if probe.kind == "sphere":
        a = np.linspace(0.0, np.pi, 20001)
        return np.column_stack([probe.radius_m * np.sin(a), z0 + probe.radius_m * (1 - np.cos(a))])
    if probe.kind == "plate":
        return np.column_stack([np.linspace(0.0, 0.02, 20001), np.full(20001, z0)])
    rho = probe.edge_radius_m if probe.kind == "flat_punch" else probe.radius_m
    if probe.kind == "flat_punch":
        core = probe.radius_m - rho
        face = np.column_stack([np.linspace(0.0, core, 5001), np.full(5001, z0)])
        a = np.linspace(0.0, 0.5 * np.pi, 10001)
        rim = np.column_stack([core + rho * np.sin(a), z0 + rho * (1 - np.cos(a))])
        side = np.column_stack(
            [np.full(30001, probe.radius_m), z0 + rho + np.linspace(0, 3e-3, 30001)]
        )
        return np.vstack([face, rim, side])
    half = np.radians(0.5 * probe.angle_deg)
    a = np.linspace(0.0, 0.5 * np.pi - half, 10001)
    tip = np.column_stack([rho * np.sin(a), z0 + rho * (1 - np.cos(a))])
    s = np.linspace(0.0, 0.01, 10001)
    flank = tip[-1] + np.column_stack([s * np.sin(half), s * np.cos(half)])
    return np.vstack([tip, flank])


def _inside(probe: Indenter, planar: np.ndarray) -> np.ndarray:
    """Whether points (r or |x|, z) lie inside the body (the outline of the others is a
    function z(r) up to the side)."""
    if probe.kind == "sphere":
        centre = np.array([0.0, probe.radius_m - CONTACT_DEPTH_M])
        return np.linalg.norm(planar - centre, axis=1) < probe.radius_m
    profile = _profile(probe)
    return planar[:, 1] > np.interp(planar[:, 0], profile[:, 0], profile[:, 1], right=np.inf)


def _launch(probe: Indenter, points: np.ndarray, *, stiffness: float = 1.0, device: str = "cpu"):
    import warp as wp
    from warptissue.kernels import contact as kc

    from warptissue.fem.contact import RigidContact

    contact = RigidContact(probe, np.arange(len(points)), 0.0, stiffness, CONTACT_DEPTH_M)
    count = len(points)
    zeros = wp.zeros(count, dtype=wp.vec3d, device=device)
    force_sum = wp.zeros(1, dtype=wp.vec3d, device=device)
    node_force = wp.zeros(count, dtype=wp.vec3d, device=device)
    gap = wp.zeros(count, dtype=wp.float64, device=device)
    blocks = wp.zeros(count, dtype=wp.mat33d, device=device)
    wp.launch(
        kc.rigid_contact_kernel,
        dim=count,
        inputs=[
            wp.array(points, dtype=wp.vec3d, device=device),
            zeros,
            wp.array(np.arange(count), dtype=wp.int32, device=device),
            wp.array(np.arange(count), dtype=wp.int32, device=device),
            wp.zeros(count, dtype=wp.int32, device=device),  # all of problem 0
            wp.array([contact.device_body()], dtype=kc.RigidBody, device=device),
            wp.array([stiffness], dtype=wp.float64, device=device),
            1,
        ],
        outputs=[
            wp.zeros(count, dtype=wp.vec3d, device=device),
            blocks,
            wp.zeros(1, dtype=wp.float64, device=device),
            force_sum,
            node_force,
            gap,
        ],
        device=device,
    )
    return gap.numpy(), node_force.numpy(), blocks.numpy()


def _sample_points(probe: Indenter, count: int = 400) -> np.ndarray:
    rng = np.random.default_rng(7)
    reach = 3e-3
    return np.column_stack(
        [
            rng.uniform(-reach, reach, count),
            rng.uniform(-reach, reach, count),
            rng.uniform(-CONTACT_DEPTH_M - 0.8e-3, -CONTACT_DEPTH_M + 1.5e-3, count),
        ]
    )


def _planar(probe: Indenter, points: np.ndarray) -> np.ndarray:
    across = np.abs(points[:, 0]) if probe.kind == "wedge" else np.hypot(points[:, 0], points[:, 1])
    return np.column_stack([across, points[:, 2]])


@pytest.mark.parametrize("name", list(BODIES))
def test_rigid_body_gap_matches_the_sampled_outline(name, device):
    """The kernel's signed distance equals the distance to a densely sampled outline of the
    body (its sign from inside/outside), for points on both sides of the surface."""
    probe = BODIES[name]
    points = _sample_points(probe)
    gap, _, _ = _launch(probe, points, device=device)
    planar = _planar(probe, points)
    profile = _profile(probe)
    distance = np.min(np.linalg.norm(planar[:, None, :] - profile[None, :, :], axis=2), axis=1)
    expected = np.where(_inside(probe, planar), -distance, distance)
    assert np.all(np.isfinite(gap))
    assert np.abs(gap - expected).max() < 2e-7  # the outline's sampling step is ~1e-7 m
    assert (gap < 0).sum() > 15 and (gap > 0).sum() > 40


@pytest.mark.parametrize("name", list(BODIES))
def test_rigid_contact_tangent_matches_central_differences(name, device):
    """The kernel's tangent block k (n n^T + g dn/dx) is the derivative of -f_c = k g n with
    respect to the node's position (central differences), at penetrating points."""
    probe = BODIES[name]
    points = _sample_points(probe)
    gap, _, blocks = _launch(probe, points, device=device)
    points, blocks = points[gap < -1e-5], blocks[gap < -1e-5]
    step = 1e-8
    numeric = np.empty_like(blocks)
    for j in range(3):
        shift = np.zeros(3)
        shift[j] = step
        _, plus, _ = _launch(probe, points + shift, device=device)
        _, minus, _ = _launch(probe, points - shift, device=device)
        numeric[:, :, j] = -(plus - minus) / (2 * step)
    # Points within one step of a seam (a tip/flank or face/rim junction) are excluded.
    error = np.abs(blocks - numeric).max(axis=(1, 2))
    assert np.median(error) < 1e-6
    assert np.mean(error < 1e-5) > 0.97


# --- The rounded flat punch (issue 21, must-show b) -----------------------------------------

PUNCH_RADIUS_M = 1e-3
PUNCH_THICKNESS_M = 3.0 * PUNCH_RADIUS_M
PUNCH_DEPTHS_M = PUNCH_RADIUS_M * np.array([0.05, 0.1])


@pytest.fixture(scope="module")
def punch_block() -> TetMesh:
    """A coarse quarter block 6 a x 3 a under a punch of radius a (1 620 TET10, a node ring
    at r = a, near size a / 3)."""
    return indentation_block(
        width_m=6.0 * PUNCH_RADIUS_M,
        thickness_m=PUNCH_THICKNESS_M,
        probe_radius_m=PUNCH_RADIUS_M,
        size_near_m=PUNCH_RADIUS_M / 3.0,
        size_far_m=0.75 * PUNCH_RADIUS_M,
    )


def _punch_run(mesh: TetMesh, edge_radius_m: float):
    if edge_radius_m > 0.0:
        punch = Indenter("flat_punch", radius_m=PUNCH_RADIUS_M, edge_radius_m=edge_radius_m)
    else:
        punch = Indenter("flat_punch", radius_m=PUNCH_RADIUS_M, contact="frictionless")
    result = simulate_indentation(
        IndentationProblem(mesh, NeoHookean(287.5, 5.75e5), punch),
        PUNCH_DEPTHS_M,
        device="cpu",
        progress=False,
    )
    assert result.completed, result.message
    return result


@pytest.fixture(scope="module")
def rounded_punch_runs(punch_block):
    return {rho: _punch_run(punch_block, rho * PUNCH_RADIUS_M) for rho in (0.0, 0.4, 0.1)}


def _sneddon_layer_ratio(edge_radius_over_radius: float) -> np.ndarray:
    """Force of the rounded punch over the sharp one's on the layer: Sneddon's effective
    radius on the half-space (scripts/examples/rounded_punch.py), moved onto the layer of
    thickness h by Hayes et al.'s factor, a_eff kappa(a_eff / h) / (a kappa(a / h))."""
    import importlib.util

    from warptissue.fit.punch import hayes_kappa

    path = Path(__file__).resolve().parents[1] / "scripts" / "examples" / "rounded_punch.py"
    spec = importlib.util.spec_from_file_location("rounded_punch", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    a, h = PUNCH_RADIUS_M, PUNCH_THICKNESS_M
    ratios = []
    for depth in PUNCH_DEPTHS_M:
        radius = module.sneddon_rounded_punch(depth, a, edge_radius_over_radius * a)
        effective = radius["effective_radius_m"]
        ratios.append(effective * hayes_kappa(effective / h, 0.5) / (a * hayes_kappa(a / h, 0.5)))
    return np.array(ratios)


@pytest.mark.slow
def test_rounded_punch_converges_to_the_prescribed_frictionless_punch(rounded_punch_runs):
    """On the same mesh, the rigid punch with a rounded edge in contact approaches the sharp
    frictionless punch with prescribed nodes as its edge radius shrinks, by the contact area
    that the rounding takes away: its force over the sharp punch's follows Sneddon's rounded
    punch moved onto the layer (measured within 6 % at rho = 0.4 a, 2 % at rho = 0.1 a on
    this coarse mesh), and the difference falls about as fast as rho (0.41 -> 0.10)."""
    sharp = rounded_punch_runs[0.0].reaction_force_N
    wide = rounded_punch_runs[0.4].reaction_force_N / sharp
    narrow = rounded_punch_runs[0.1].reaction_force_N / sharp
    assert np.all(1.0 - narrow < 0.4 * (1.0 - wide))
    np.testing.assert_allclose(wide, _sneddon_layer_ratio(0.4), rtol=0.08)
    np.testing.assert_allclose(narrow, _sneddon_layer_ratio(0.1), rtol=0.03)
    for rho in (0.4, 0.1):
        run = rounded_punch_runs[rho]
        np.testing.assert_allclose(run.contact_force_N, run.reaction_force_N, rtol=1e-6)


@pytest.mark.slow
def test_penalty_ramp_keeps_the_force_and_saves_newton_iterations(
    punch_block, rounded_punch_runs, monkeypatch
):
    """The penalty ramp of a contact increment (``newton.increment.CONTACT_PENALTY_RAMP``)
    changes the path, not the converged state: the force of the full penalty at once equals
    it to the Newton tolerance, in more iterations."""
    from warptissue.fem.newton import increment

    monkeypatch.setattr(increment, "CONTACT_PENALTY_RAMP", 1.0)
    plain = _punch_run(punch_block, 0.4 * PUNCH_RADIUS_M)
    ramped = rounded_punch_runs[0.4]
    np.testing.assert_allclose(ramped.reaction_force_N, plain.reaction_force_N, rtol=1e-6)
    assert ramped.newton_iterations.sum() < plain.newton_iterations.sum()


# --- outputs: contact area and pressure (ContactSurface) -----------------------------------


def _tet4_plate_cube() -> TetMesh:
    grid = np.linspace(0.0, SIDE_M, 3)
    mesh = block_mesh(grid, grid, grid)
    sets = dict(mesh.node_sets)
    sets.update(
        top=sets["zmax"], bottom=sets["zmin"], symmetry_x=sets["xmin"], symmetry_y=sets["ymin"]
    )
    return TetMesh(points=mesh.points, tets=mesh.tets, node_sets=sets, face_sets=mesh.face_sets)


@pytest.mark.parametrize("element", ["TET10", "TET4"])
def test_plate_contact_area_is_the_top_face_and_the_pressure_the_stress(element):
    """Homogeneous compression: the contact area is the whole deformed top face (from the
    displaced corner), the pressure at every top node the tets' Cauchy -sigma_zz, and for the
    nearly incompressible TET10 cube the analytic Cauchy stress (nominal times the stretch).
    TET10 corner nodes carry no force (their tributary weight is 0): their pressure must not
    fall out of line (no checkerboard)."""
    stretches = np.array([0.9, 0.8])
    if element == "TET10":
        material, analytic = ANALYTIC["neo_hookean"]
        problem = IndentationProblem(_plate_cube(), material, Indenter("plate"), base="sliding")
    else:  # TET4 locks when nearly incompressible: a compressible one
        material, analytic = NeoHookean(100.0, 4000.0), None
        problem = IndentationProblem(
            _tet4_plate_cube(),
            material,
            Indenter("plate"),
            base="sliding",
            formulation="displacement",
        )
    result = simulate_indentation(problem, SIDE_M * (1.0 - stretches), device="cpu", progress=False)
    assert result.completed, result.message
    mesh = problem.mesh
    top = mesh.node_set("top")
    corner = int(np.flatnonzero((mesh.points == SIDE_M).all(axis=1))[0])
    x = mesh.points[corner] + result.displacement_m[:, corner]
    np.testing.assert_allclose(result.contact_area_m2, 4.0 * x[:, 0] * x[:, 1], rtol=1e-4)
    pressure = result.contact_pressure_Pa[-1]
    assert result.contact_pressure_Pa.shape == (2, mesh.node_count)
    np.testing.assert_allclose(pressure[top], -result.cauchy_stress_Pa[:, 2].mean(), rtol=5e-3)
    assert np.all(np.delete(pressure, top) == 0.0)
    if analytic is not None:
        cauchy = -analytic(stretches) * stretches
        np.testing.assert_allclose(
            result.contact_pressure_Pa[:, top].mean(axis=1), cauchy, rtol=5e-3
        )
    summary = result.to_dict()
    assert summary["contact_area_m2"] == result.contact_area_m2.tolist()
    assert summary["max_contact_pressure_Pa"][-1] == pytest.approx(pressure.max())


HERTZ_BLOCK_R = 6.0  # width in R; thickness half of it


@pytest.fixture(scope="module")
def hertz_run():
    """A sphere R on a 6 R x 3 R quarter block refined to 0.3 of a = 0.25 R (5025 TET10 nodes,
    about 35 s), at d = 0.02 R and 0.04 R: the assembler is kept for the nodal forces."""
    from warptissue.fem import Assembler

    mesh = indentation_block(
        width_m=HERTZ_BLOCK_R * RADIUS_M,
        thickness_m=0.5 * HERTZ_BLOCK_R * RADIUS_M,
        probe_radius_m=0.25 * RADIUS_M,
        size_near_m=0.075 * RADIUS_M,
        size_far_m=1.5 * RADIUS_M,
        growth=1.5,
    )
    problem = _sphere_problem(mesh)
    assembler = Assembler(mesh, problem.material, device="cpu")
    result = simulate_indentation(
        problem, SPHERE_DEPTHS_M, device="cpu", progress=False, assembler=assembler
    )
    assert result.completed, result.message
    return problem, assembler, result


@pytest.mark.slow
def test_sphere_contact_area_and_pressure_follow_hertz(hertz_run):
    """Hertz (independent): a = sqrt(R d), p(r) = p0 sqrt(1 - r^2/a^2) with p0 = 3 F / (2 pi
    a^2), F the FE force. The area agrees within 10 % (measured +7 % and +5 %: the contact
    edge is resolved by whole nodes, half an element wide at 0.3 a), the pressure within 10 %
    of p0 in the RMS over the surface nodes inside 0.8 a (measured 7 %, corners and mid-edge
    nodes alike) and its peak within 5 % of p0 (measured -1 %, -2 %)."""
    problem, _, result = hertz_run
    mesh = problem.mesh
    top = mesh.node_set("top")
    for step, depth in enumerate(result.depths_m):
        a = np.sqrt(RADIUS_M * depth)
        assert result.contact_area_m2[step] == pytest.approx(np.pi * a**2, rel=0.10)
        p0 = 3.0 * result.reaction_force_N[step] / (2.0 * np.pi * a**2)
        x = mesh.points[top] + result.displacement_m[step, top]
        r = np.hypot(x[:, 0], x[:, 1])
        hertz = p0 * np.sqrt(np.clip(1.0 - (r / a) ** 2, 0.0, None))
        pressure = result.contact_pressure_Pa[step, top]
        inner = r < 0.8 * a
        assert inner.sum() > 20
        assert np.sqrt(np.mean((pressure - hertz)[inner] ** 2)) < 0.10 * p0
        assert pressure.max() == pytest.approx(p0, rel=0.05)
        # Beyond the contact only TET10 corner nodes of triangles reaching into it show a
        # (small) pressure: the mean of their mid-edge nodes'.
        assert np.all(pressure[r > 1.5 * a] < 1e-3 * p0) and np.all(pressure >= 0.0)


def _t6_integral(points: np.ndarray, triangles: np.ndarray, values: np.ndarray) -> float:
    """The integral of a nodal field interpolated by 6-node triangles' shape functions over
    the curved (isoparametric) triangles, by Strang and Fix's 6-point rule."""
    a, b = 0.445948490915965, 0.091576213509771
    weights = np.array([0.223381589678011] * 3 + [0.109951743655322] * 3)
    barycentric = np.array(
        [[a, a, 1 - 2 * a], [a, 1 - 2 * a, a], [1 - 2 * a, a, a]]
        + [[b, b, 1 - 2 * b], [b, 1 - 2 * b, b], [1 - 2 * b, b, b]]
    )
    x = points[triangles]  # (F, 6, 3)
    total = 0.0
    for weight, (l0, l1, l2) in zip(weights, barycentric, strict=True):
        shape = np.array(
            [l0 * (2 * l0 - 1), l1 * (2 * l1 - 1), l2 * (2 * l2 - 1)]
            + [4 * l0 * l1, 4 * l1 * l2, 4 * l2 * l0]
        )
        d_xi = np.array([1 - 4 * l0, 4 * l1 - 1, 0, 4 * (l0 - l1), 4 * l2, -4 * l2])
        d_eta = np.array([1 - 4 * l0, 0, 4 * l2 - 1, -4 * l1, 4 * l1, 4 * (l0 - l2)])
        jacobian = np.linalg.norm(
            np.cross(np.einsum("fjk,j->fk", x, d_xi), np.einsum("fjk,j->fk", x, d_eta)), axis=1
        )
        total += weight * 0.5 * float(np.sum(jacobian * (values[triangles] @ shape)))
    return total


def test_sphere_contact_pressure_integrates_to_the_contact_force(hertz_run):
    """The summed normal contact force of the nodes (the assembler's own, not the helper's)
    is the pressure's integral with the tributary areas (exactly: the force of TET10 corner
    nodes is handed to their mid-edge nodes), and within 0.5 % the integral of the
    interpolated pressure over the curved deformed 6-node triangles by an independent
    quadrature (measured 0.2 %: the tributary areas take each triangle's area from its four
    flat sub-triangles and spread it as on a straight-sided triangle)."""
    from warptissue.fem.contact import ContactSurface

    problem, assembler, result = hertz_run
    surface = ContactSurface.for_mesh(problem.mesh)
    assert surface.triangles.shape[1] == 6
    for step, depth in enumerate(result.depths_m):
        assembler.set_load(depth)
        state = assembler.contact_state(result.displacement_m[step])
        normal_force = np.linalg.norm(state.force_N, axis=1).sum()
        current = problem.mesh.points + result.displacement_m[step]
        integral = _t6_integral(current, surface.triangles, result.contact_pressure_Pa[step])
        weights = surface.tributary_areas_m2(current)
        assert np.all(weights >= 0.0)
        lumped = float(np.sum(weights * result.contact_pressure_Pa[step]))
        assert lumped == pytest.approx(normal_force, rel=1e-12)
        assert integral == pytest.approx(normal_force, rel=5e-3)
        # The force along z, times the symmetry factor, is the probe force.
        assert -4.0 * state.total_force_N[2] == pytest.approx(
            result.reaction_force_N[step], rel=1e-8
        )


def test_a_sharp_flat_punch_has_no_contact_outputs():
    mesh = to_tet10(block_mesh(*(np.linspace(0.0, SIDE_M, 3),) * 3))
    sets = dict(mesh.node_sets, top=mesh.node_sets["zmax"], bottom=mesh.node_sets["zmin"])
    mesh = TetMesh(points=mesh.points, tets=mesh.tets, node_sets=sets)
    problem = IndentationProblem(
        mesh, NeoHookean(100.0, 2e5), Indenter("flat_punch", radius_m=4e-3), symmetry_planes=()
    )
    result = simulate_indentation(problem, [1e-4], device="cpu", progress=False)
    assert result.contact_area_m2.size == 0
    assert result.contact_pressure_Pa.shape == (0, mesh.node_count)
    assert "contact_area_m2" not in result.to_dict()


def test_a_contact_surface_without_triangles_is_refused_before_the_run():
    """The contact outputs need the indented surface's triangles: a node set that holds no
    boundary triangle is refused when the problem is made, naming the key."""
    mesh = _plate_cube()
    sets = dict(mesh.node_sets, few=mesh.node_sets["zmax"][:2])
    mesh = TetMesh(points=mesh.points, tets=mesh.tets, node_sets=sets)
    with pytest.raises(InputError) as caught:
        IndentationProblem(
            mesh, NeoHookean(100.0, 2e5), Indenter("plate"), base="sliding", surface="few"
        )
    assert caught.value.column == "surface" and "\n" not in str(caught.value)


# --- wedge: Takacs et al.'s line indenter (a rigid wedge along y) on a small strip ---------

WEDGE_STRIP_M = (10e-3, 2.5e-3, 5e-3)  # half length (x), half width (y), height (z)


def _wedge_strip(*, full: bool) -> TetMesh:
    """A strip x in [0, L] (across the line), y in [0, w] (along it, free side at w), z in
    [0, h], graded toward the line and the top; mirrored to x in [-L, L] when ``full`` (the
    half strip). Sets: top, bottom, symmetry_x (x = 0 or -L) and symmetry_y (y = 0)."""
    half_length, half_width, height = WEDGE_STRIP_M
    x = np.concatenate([np.linspace(0.0, 1e-3, 5), 1e-3 + np.geomspace(1e-3, 9e-3, 4)])
    y = np.array([0.0, half_width])
    z = graded_coordinates(height, 5, ratio=0.1)
    if full:
        x = np.concatenate([-x[:0:-1], x])
    mesh = to_tet10(block_mesh(x, y, z))
    sets = dict(mesh.node_sets)
    sets.update(
        top=sets["zmax"], bottom=sets["zmin"], symmetry_x=sets["xmin"], symmetry_y=sets["ymin"]
    )
    return TetMesh(points=mesh.points, tets=mesh.tets, node_sets=sets, face_sets=mesh.face_sets)


def _wedge_run(mesh, probe, depths, **problem_options):
    problem = IndentationProblem(
        mesh, NeoHookean(C10_PA, 2000.0 * C10_PA), probe, **problem_options
    )
    result = simulate_indentation(problem, depths, device="cpu", progress=False)
    assert result.completed, result.message
    np.testing.assert_allclose(result.contact_force_N, result.reaction_force_N, rtol=1e-7)
    return result


WEDGE = Indenter("wedge", radius_m=2e-3, angle_deg=30.0)
WEDGE_DEPTHS_M = np.array([0.1e-3, 0.4e-3])


@pytest.fixture(scope="module")
def wedge_quarter_run():
    return _wedge_run(_wedge_strip(full=False), WEDGE, WEDGE_DEPTHS_M)


def test_wedge_quarter_strip_matches_the_half_strip(wedge_quarter_run):
    """The quarter model (symmetry planes x = 0 across the line, y = 0 along it) gives the
    force of the half strip on both sides of the line (x in [-L, L], no plane at x = 0; a
    different mesh, as the tets' split is not mirror-symmetric; measured 0.2-0.4 %), whose
    line nodes stay on the line (no sideways slip of the wedge; measured 0.9 % of the depth)."""
    whole = _wedge_run(
        _wedge_strip(full=True), WEDGE, WEDGE_DEPTHS_M, symmetry_planes=("symmetry_y",)
    )
    np.testing.assert_allclose(
        whole.reaction_force_N, wedge_quarter_run.reaction_force_N, rtol=0.02
    )
    mesh = _wedge_strip(full=True)
    top = mesh.node_set("top")
    line = top[np.abs(mesh.points[top, 0]) < 1e-12]
    assert np.abs(whole.displacement_m[-1][line, 0]).max() < 0.03 * WEDGE_DEPTHS_M[-1]


def test_wedge_force_grows_with_depth_and_equals_a_cylinder_on_its_tip(wedge_quarter_run):
    """While the contact stays on the rounded tip (|x| < R cos 15 deg, below R (1 - sin 15
    deg) = 1.48 mm of the tip), the 30 degree wedge and a cylinder of the same radius (a
    wedge of angle 0) are the same body: equal forces, as the kernel's geometry says."""
    force = wedge_quarter_run.reaction_force_N
    assert force[0] > 0 and np.all(np.diff(force) > 0)
    cylinder = _wedge_run(
        _wedge_strip(full=False), Indenter("wedge", radius_m=2e-3, angle_deg=0.0), WEDGE_DEPTHS_M
    )
    np.testing.assert_allclose(cylinder.reaction_force_N, force, rtol=1e-6)
    # The penalty lets the wedge into the strip by a small fraction of the depth only.
    assert np.all(wedge_quarter_run.max_penetration_m < 2e-3 * WEDGE_DEPTHS_M)


@pytest.mark.parametrize(
    "probe",
    [
        Indenter("sphere", radius_m=RADIUS_M),
        Indenter("flat_punch", radius_m=0.2 * RADIUS_M, edge_radius_m=0.05 * RADIUS_M),
    ],
    ids=["sphere", "rounded_punch"],
)
@pytest.mark.slow
def test_rigid_contact_runs_on_every_device_with_the_cpu_force(sphere_mesh, probe, device):
    """The same run through contact on each Warp device (CUDA where present) gives the CPU's
    forces, contact force and penetration (the GPU's atomics only reorder the sums)."""
    depths = [0.01 * RADIUS_M, 0.03 * RADIUS_M]
    material = NeoHookean(C10_PA, 2000.0 * C10_PA)
    runs = [
        simulate_indentation(
            IndentationProblem(sphere_mesh, material, probe), depths, device=d, progress=False
        )
        for d in ("cpu", device)
    ]
    assert all(run.completed for run in runs)
    for field in ("reaction_force_N", "contact_force_N", "max_penetration_m"):
        np.testing.assert_allclose(getattr(runs[1], field), getattr(runs[0], field), rtol=1e-6)


@pytest.mark.slow
def test_the_contact_radius_is_resolved_to_half_a_near_element():
    """Issue 36: the contact radius at d/R = 0.04 was +10-12 % above Hertz's sqrt(R d) on
    study meshes, with nothing said of its accuracy. The area counts whole nodes, so the
    radius sqrt(A / pi) is resolved to the node spacing at the contact edge, half the near
    element size h (TET10 mid-edge nodes). At two near sizes (0.2 R and 0.1 R within 0.3 R,
    a 6 R x 3 R block, d = 0.04 R, a = 0.2 R) the radius lies within h/2 of Hertz's
    (measured 0.03 h and 0.18 h: area / (pi R d) = 1.064 and 1.192; 0.075 R and 0.0375 R
    give 1.131 and 1.092, the radius converging to +4.5 % above Hertz's on this finite layer
    at finite strain), so the area's bound, about h / a, halves with h; the error itself does
    not fall steadily (docs/fe.md "Contact outputs"). About 30 s on the 2-core CPU."""
    depths = RADIUS_M * np.array([0.02, 0.04])
    hertz_radius = np.sqrt(RADIUS_M * depths[-1])
    radii = []
    for near in (0.2 * RADIUS_M, 0.1 * RADIUS_M):
        mesh = indentation_block(
            width_m=6.0 * RADIUS_M,
            thickness_m=3.0 * RADIUS_M,
            probe_radius_m=1.5 * hertz_radius,
            size_near_m=near,
            size_far_m=RADIUS_M,
            growth=1.3,
        )
        result = simulate_indentation(
            _sphere_problem(mesh, NeoHookean(C10_PA, 1e6)), depths, device="cpu", progress=False
        )
        assert result.completed, result.message
        radius = np.sqrt(result.contact_area_m2[-1] / np.pi)
        assert abs(radius - hertz_radius) < 0.5 * near, (near, radius / hertz_radius)
        radii.append(radius)
    assert radii[0] != radii[1]
