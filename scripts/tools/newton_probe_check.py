"""Press a trainer asset's probes in NVIDIA Newton and compare the force with warptissue's.

Run inside an environment with ``newton`` (1.8) and this project (``.venv-newton``, built by
``scripts/tools/newton_import_check.sh`` and by ``.ci/run``). It loads the asset with
``newton.ModelBuilder.add_usd``, sets the particle radii from the asset's ``primvars:widths``,
holds the ``bottom`` subset, moves each bonded punch's nodes (the calibration's
``punch_nodes``) along its direction depth by depth, and runs ``SolverVBD`` quasi-statically
(gravity off, velocities zeroed after every step) until no particle moves by more than
``--rtol`` times the depth in ``--check-every`` sweeps (1e-4: Newton's positions are float32,
whose resolution at centimetre coordinates is about 1e-5 of a 0.1 mm depth, so a tighter
rule waits on rounding; the forces then equal warptissue's linear-tet model to 1e-4). The
force is the reaction of Newton's own tet energy (stable neo-Hookean, its Lame parameters and
rest poses) on the punch nodes, checked against the base's reaction. ``--physics true`` runs
the tissue's true small-strain E and nu instead of the calibrated ones (the asset before
calibration).

Prints one JSON line and exits 0 when every fitted probe is within ``--tolerance`` of the
locking-free force at every depth and every load step settled within ``--max-sweeps``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np


def tet_forces(x, tets, dm_inv, mu, lam):
    """Nodal elastic forces of Newton's VBD tets: P = mu F + lambda_nh (J - alpha) cof F."""
    lam_nh = lam + mu
    alpha = 1.0 + mu / lam_nh
    v0 = x[tets[:, 0]]
    ds = np.stack([x[tets[:, k]] - v0 for k in (1, 2, 3)], axis=2)
    f = ds @ dm_inv
    j = np.linalg.det(f)
    cof = np.stack(
        [
            np.cross(f[:, :, 1], f[:, :, 2]),
            np.cross(f[:, :, 2], f[:, :, 0]),
            np.cross(f[:, :, 0], f[:, :, 1]),
        ],
        axis=2,
    )
    volume = 1.0 / (6.0 * np.linalg.det(dm_inv))
    piola = mu[:, None, None] * f + (lam_nh * (j - alpha))[:, None, None] * cof
    h = -volume[:, None, None] * piola @ np.transpose(dm_inv, (0, 2, 1))
    forces = np.zeros_like(x)
    for a in range(3):
        np.add.at(forces, tets[:, a + 1], h[:, :, a])
    np.add.at(forces, tets[:, 0], -h.sum(axis=2))
    return forces


def press(scene, probe, held, *, physics, check_every, max_sweeps, rtol, radii):
    import newton
    import warp as wp

    builder = newton.ModelBuilder()
    builder.add_usd(str(scene))
    if radii is not None:
        builder.particle_radius[: len(radii)] = radii.tolist()
    if physics is not None:
        e, nu = physics
        mu, lam = e / (2 * (1 + nu)), e * nu / ((1 + nu) * (1 - 2 * nu))
        builder.tet_materials = [(mu, lam, m[2]) for m in builder.tet_materials]
    punch = np.asarray(probe["punch_nodes"], dtype=np.float64).astype(np.int64)
    for i in np.concatenate([punch, held]):
        builder.particle_mass[i] = 0.0
        builder.particle_flags[i] = int(builder.particle_flags[i]) & ~int(
            newton.ParticleFlags.ACTIVE
        )
    builder.color()
    model = builder.finalize()
    model.set_gravity((0.0, 0.0, 0.0))
    solver = newton.solvers.SolverVBD(
        model,
        iterations=check_every,
        particle_enable_self_contact=False,
        particle_enable_tile_solve=False,
    )
    state, other, control = model.state(), model.state(), model.control()
    rest = state.particle_q.numpy().astype(np.float64)
    tets = model.tet_indices.numpy()
    dm_inv = model.tet_poses.numpy().astype(np.float64)
    materials = model.tet_materials.numpy().astype(np.float64)
    direction = np.asarray(probe["direction"], dtype=np.float64)
    steps = []
    for depth in probe["depths_m"]:
        q = state.particle_q.numpy()
        q[punch] = rest[punch] + depth * direction
        state.particle_q.assign(q)
        state.particle_qd.zero_()
        sweeps, settled, started = 0, False, time.perf_counter()
        previous = state.particle_q.numpy().astype(np.float64)
        while sweeps < max_sweeps:
            solver.step(state, other, control, None, 1.0)
            state, other = other, state
            state.particle_qd.zero_()
            sweeps += check_every
            current = state.particle_q.numpy().astype(np.float64)
            moved = float(np.abs(current - previous).max())
            previous = current
            if moved < rtol * depth:
                settled = True
                break
        forces = tet_forces(previous, tets, dm_inv, materials[:, 0], materials[:, 1])
        steps.append(
            {
                "depth_m": float(depth),
                "force_N": -float((forces[punch] @ direction).sum()),
                "base_N": float((forces[held] @ direction).sum()),
                "sweeps": sweeps,
                "settled": settled,
                "seconds": round(time.perf_counter() - started, 3),
            }
        )
    wp.synchronize()
    return steps


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--scene", type=Path, required=True, help="a warptissue export --trainer scene"
    )
    parser.add_argument("--physics", choices=("calibrated", "true"), default="calibrated")
    parser.add_argument("--probes", choices=("fitted", "all"), default="all")
    parser.add_argument("--depths", type=int, default=0, help="only the first N depths (0: all)")
    parser.add_argument("--check-every", type=int, default=25)
    parser.add_argument("--max-sweeps", type=int, default=2000)
    parser.add_argument("--rtol", type=float, default=1e-4)
    parser.add_argument("--tolerance", type=float, default=0.10)
    args = parser.parse_args()

    import warp as wp

    wp.config.quiet = True
    from warptissue.usd import read_material_usd, read_tetmesh_usd
    from warptissue.usd.reader import read_particle_radii_usd

    record = read_material_usd(args.scene)
    calibration = record["trainer"]
    if calibration is None:
        print(json.dumps({"ok": False, "error": "the scene has no trainer calibration"}))
        return 2
    held = np.asarray(read_tetmesh_usd(args.scene).node_sets["bottom"], dtype=np.int64)
    radii = read_particle_radii_usd(args.scene)
    physics = None
    if args.physics == "true":
        physics = (record["small_strain_youngs_modulus_Pa"], record["small_strain_poissons_ratio"])
    report = {"scene": str(args.scene), "physics": args.physics, "probes": []}
    ok = True
    for _, probe in sorted(calibration["probes"].items(), key=lambda kv: int(kv[0][6:])):
        if args.probes == "fitted" and not probe["fitted"]:
            continue
        if isinstance(probe["punch_nodes"], str):  # customData keeps an empty list as "[]"
            probe = {**probe, "punch_nodes": json.loads(probe["punch_nodes"])}
        if len(probe["punch_nodes"]) == 0:
            continue  # a rigid indenter: Newton's contact is not what this checks
        if args.depths:
            probe = {**probe, "depths_m": probe["depths_m"][: args.depths]}
        steps = press(
            args.scene,
            probe,
            held,
            physics=physics,
            check_every=args.check_every,
            max_sweeps=args.max_sweeps,
            rtol=args.rtol,
            radii=radii,
        )
        reference = np.asarray(probe["reference_force_N"][: len(steps)])
        trainer = np.asarray(probe["trainer_force_N"][: len(steps)])
        newton_force = np.array([s["force_N"] for s in steps])
        entry = {
            "label": probe["label"],
            "fitted": probe["fitted"],
            "newton_over_reference": (newton_force / reference).tolist(),
            "newton_over_warptissue_tet4": (newton_force / trainer).tolist(),
            "max_sweeps_per_step": max(s["sweeps"] for s in steps),
            "all_settled": all(s["settled"] for s in steps),
            "steps": steps,
        }
        report["probes"].append(entry)
        if probe["fitted"]:
            ok &= bool(np.all(np.abs(newton_force / reference - 1.0) <= args.tolerance))
            ok &= entry["all_settled"]
    report["ok"] = ok
    print(json.dumps(report))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
