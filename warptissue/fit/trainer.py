"""The trainer-calibrated material: effective E and nu for a simulator's linear tets.

Real-time soft-body engines (NVIDIA Newton's VBD and XPBD, PhysX deformables, SOFA) run linear
tetrahedra with a displacement formulation. Near incompressibility (nu = 0.4995, the fitted
tissue's K = 1000 mu) such elements lock: Newton 1.8's VBD on a 1 920-tet block under a bonded
2.5 mm punch gives 25 times the locking-free force. :func:`calibrate_trainer_material` finds
the Young's modulus and Poisson's ratio that make the trainer's own discretization reproduce
the tissue instead:

1. the reference: warptissue's locking-free FE (the study's own mesh and formulation, TET10
   mixed) of each of the study's probes, with the fitted material's elastic part;
2. the trainer's model: the trainer's mesh (the whole body, TET4, no symmetry planes), the
   same probes, :class:`~warptissue.materials.StableNeoHookean` (Newton's VBD tet energy,
   which this FE reproduces to 1e-6) in the displacement formulation;
3. for each Poisson's ratio the trainer's force scales exactly with E (the energy is linear
   in (mu, lambda) at a fixed nu, so the equilibrium does not change), so E follows in closed
   form from a relative least-squares fit of all depths of all probes, and nu is the one of
   ``nu_bounds`` whose fitted curve has the smallest root-mean-square relative error
   (a bounded scalar minimization).

The result keeps what the calibration costs: the force error at every depth of every probe,
probes of other radii checked but not fitted (``check_radius_factors``), and the body's
volume change at the deepest depth as a fraction of the volume its indented surface swept in
(the true tissue keeps its volume; a compressible trainer loses some instead of bulging).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy.optimize import minimize_scalar

from warptissue.errors import ConvergenceError, InputError
from warptissue.fem import IndentationProblem, NewtonOptions, simulate_indentation
from warptissue.fem.probe import surface_triangles
from warptissue.materials import StableNeoHookean
from warptissue.mesh import TetMesh, coarsen_mesh
from warptissue.simulate import build_mesh, build_problem, record_problems
from warptissue.study import Study, organ_mesh, probe_placement, support_nodes

__all__ = [
    "TrainerCalibration",
    "TrainerProbe",
    "calibrate_trainer_material",
    "trainer_mesh",
]

#: Poisson's ratios searched by default: from a compressible solid to the point where
#: Newton's VBD still settles a load step in about 2 000 sweeps (docs/usd.md).
DEFAULT_NU_BOUNDS = (0.30, 0.48)

#: A bonded punch needs at least this many nodes of the trainer's mesh under it (the centre
#: and a ring) for its force to mean something.
MIN_PUNCH_NODES = 7


@dataclasses.dataclass(frozen=True)
class TrainerProbe:
    """One probe's force curves: the tissue's and the calibrated trainer's.

    Attributes:
        label: The probe, e.g. ``"flat_punch r=5 mm"``.
        radius_m: Its radius, m.
        fitted: Whether the calibration fitted this probe (False: checked only).
        depths_m: Depths, (S,), m.
        reference_force_N: The locking-free FE force, (S,), N.
        trainer_force_N: The calibrated trainer model's force, (S,), N.
        punch_nodes: The trainer mesh's nodes the bonded punch moves (none under a rigid
            indenter), (P,).
        direction: The probe's direction into the body, (3,).
    """

    label: str
    radius_m: float
    fitted: bool
    depths_m: np.ndarray
    reference_force_N: np.ndarray
    trainer_force_N: np.ndarray
    punch_nodes: np.ndarray
    direction: np.ndarray

    @property
    def relative_error(self) -> np.ndarray:
        """``trainer / reference - 1`` at each depth, (S,)."""
        return self.trainer_force_N / self.reference_force_N - 1.0

    def to_dict(self) -> dict[str, Any]:
        return {
            "label": self.label,
            "radius_m": self.radius_m,
            "fitted": self.fitted,
            "depths_m": self.depths_m.tolist(),
            "reference_force_N": self.reference_force_N.tolist(),
            "trainer_force_N": self.trainer_force_N.tolist(),
            "relative_error": self.relative_error.tolist(),
            "punch_nodes": [int(n) for n in self.punch_nodes],
            "direction": [float(v) for v in self.direction],
        }


@dataclasses.dataclass(frozen=True)
class TrainerCalibration:
    """The trainer's material and what it costs.

    Attributes:
        youngs_modulus_Pa: The calibrated E, Pa (``physics:youngsModulus``).
        poissons_ratio: The calibrated nu (``physics:poissonsRatio``).
        true_youngs_modulus_Pa: The tissue's small-strain E, Pa.
        true_poissons_ratio: The tissue's small-strain nu.
        probes: Every probe's curves (fitted first, then the checked ones).
        volume_change: Volume change of the trainer's body at the deepest depth of the first
            probe, as a fraction of the volume its indented surface swept inward (negative:
            lost; the tissue's is about 0).
        tet_count: Tets of the trainer's mesh.
        node_count: Nodes of the trainer's mesh.
        scan: ``(nu, E, rms relative error)`` of every Poisson's ratio evaluated.
        nu_bounds: The Poisson's ratios searched.
        unchecked: The probes of other radii whose run did not converge, with why.
    """

    youngs_modulus_Pa: float
    poissons_ratio: float
    true_youngs_modulus_Pa: float
    true_poissons_ratio: float
    probes: tuple[TrainerProbe, ...]
    volume_change: float
    tet_count: int
    node_count: int
    scan: tuple[tuple[float, float, float], ...]
    nu_bounds: tuple[float, float]
    unchecked: tuple[str, ...] = ()

    @property
    def max_relative_error(self) -> float:
        """The largest ``|trainer / reference - 1|`` over the fitted probes' depths."""
        return float(max(np.abs(p.relative_error).max() for p in self.probes if p.fitted))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready, as the asset's ``customData`` and the CLI's report hold it."""
        return {
            "method": "trainer calibration: Newton VBD stable neo-Hookean on linear tets "
            "(displacement formulation) fitted to the locking-free TET10 mixed FE",
            "youngs_modulus_Pa": self.youngs_modulus_Pa,
            "poissons_ratio": self.poissons_ratio,
            "true_youngs_modulus_Pa": self.true_youngs_modulus_Pa,
            "true_poissons_ratio": self.true_poissons_ratio,
            "max_relative_error": self.max_relative_error,
            "volume_change_of_swept": self.volume_change,
            "tet_count": self.tet_count,
            "node_count": self.node_count,
            "nu_bounds": list(self.nu_bounds),
            "unchecked": list(self.unchecked),
            "unresolved": self.unresolved,
            "probes": {f"probe_{i}": p.to_dict() for i, p in enumerate(self.probes)},
            "not_matched": [
                "volume: the trainer's body changes volume where the tissue keeps it "
                "(volume_change_of_swept)",
                "rate: the Prony series stays in tissue:viscoelastic (Newton 1.8 reads no "
                "damping for volume deformables)",
            ],
        }

    @property
    def unresolved(self) -> list[str]:
        """The bonded punches that hold fewer than :data:`MIN_PUNCH_NODES` nodes of the
        trainer's mesh: its surface does not resolve them, and their force means little."""
        return [
            f"{p.label}: {len(p.punch_nodes)} node(s) under the punch"
            for p in self.probes
            if 0 < len(p.punch_nodes) < MIN_PUNCH_NODES
        ]

    def report_lines(self) -> list[str]:
        """The calibration as the CLI prints it."""
        lines = [
            f"trainer material: E = {self.youngs_modulus_Pa:.6g} Pa, nu = "
            f"{self.poissons_ratio:.4f} (tissue: E = {self.true_youngs_modulus_Pa:.6g} Pa, "
            f"nu = {self.true_poissons_ratio:.4f}) on {self.tet_count} linear tets",
        ]
        for probe in self.probes:
            errors = ", ".join(f"{100 * e:+.1f}" for e in probe.relative_error)
            kind = "fitted" if probe.fitted else "checked"
            lines.append(f"  {probe.label} ({kind}): force error % by depth: {errors}")
        lines.extend(f"  not checked: {reason}" for reason in self.unchecked)
        lines.extend(
            f"  warning: the trainer's mesh does not resolve {what}; refine it there"
            for what in self.unresolved
        )
        lines.append(
            f"  cost: the body's volume changes by {100 * self.volume_change:+.1f} % of the "
            "volume the indented surface swept in at the deepest depth (the tissue keeps its "
            "volume); the Prony series is not in the physics material"
        )
        return lines


def trainer_mesh(study: Study, *, max_tets: int | None = None) -> TetMesh:
    """The trainer's mesh of a study's specimen: the whole body (no symmetry planes), TET4,
    at the study's sizes, or coarser until it has at most ``max_tets`` tets.

    A generated block or disc is meshed again at sizes scaled by 1.25 per try; an organ's
    mesh file is refined around the study's sites as its fit refines it (a probe needs
    nodes under it: the liver organ's own surface has one node under a 5 mm punch), or where
    it has more than ``max_tets`` tets, its boundary decimated and filled again
    (:func:`warptissue.mesh.coarsen_mesh`), with the support and the surface found on the new
    boundary as the study finds them on the file's.

    Raises:
        InputError: ``max_tets`` is not a positive integer, or cannot be met.
    """
    if max_tets is not None and (
        isinstance(max_tets, bool) or int(max_tets) != max_tets or max_tets < 1
    ):
        raise InputError("must be a positive integer", key="--max-tets", value=max_tets)
    specimen = study.specimen
    if specimen.shape == "mesh":
        whole = dataclasses.replace(specimen, element="TET4")
        mesh = build_mesh(dataclasses.replace(study, specimen=whole))
        if max_tets is None or mesh.tet_count <= max_tets:
            return mesh
        coarse = coarsen_mesh(mesh, max_tets=int(max_tets))
        site, along = probe_placement(
            coarse, study.site_m, study.direction, radius_m=study.indenter.radius_m
        )
        support = support_nodes(coarse, study.boundary.support, site_m=site, direction=along)
        return organ_mesh(coarse, support)
    scale = 1.0
    for _ in range(20):
        whole = dataclasses.replace(
            specimen,
            quarter=False,
            element="TET4",
            size_near_m=specimen.size_near_m * scale,
            size_far_m=max(specimen.size_far_m * scale, specimen.size_near_m * scale),
            force_accuracy=None,
        )
        mesh = build_mesh(dataclasses.replace(study, specimen=whole))
        if max_tets is None or mesh.tet_count <= max_tets:
            return mesh
        scale *= 1.25
    raise InputError(
        f"no mesh of the specimen has at most {max_tets} tets (the coarsest tried has "
        f"{mesh.tet_count})",
        key="--max-tets",
        value=max_tets,
    )


def _elastic(material: Any) -> Any:
    return getattr(material, "elastic", material)


def _depths(study: Study, count: int) -> np.ndarray:
    deepest = float(study.deepest_depth_m)
    return deepest * np.arange(1, count + 1) / count


def _label(problem: IndentationProblem) -> str:
    return f"{problem.indenter.kind} r={1e3 * problem.indenter.radius_m:.4g} mm"


def _reference_problems(study: Study) -> list[IndentationProblem]:
    """The study's probes on its own mesh: one per distinct probe of its records, or its own."""
    elastic = _elastic(study.material)
    if study.data:
        return record_problems(study, elastic)[0]
    placed = dataclasses.replace(study, material=elastic)
    return [build_problem(placed, build_mesh(placed))]


def _other_radius(study: Study, problem: IndentationProblem, factor: float) -> IndentationProblem:
    """``problem`` with a probe ``factor`` times as wide: a generated specimen meshed again for
    it (its refined zone follows the probe), an organ on the same mesh."""
    indenter = dataclasses.replace(problem.indenter, radius_m=problem.indenter.radius_m * factor)
    if study.specimen.shape == "mesh":
        return dataclasses.replace(problem, indenter=indenter)
    placed = dataclasses.replace(study, indenter=indenter, material=problem.material)
    return dataclasses.replace(problem, mesh=build_mesh(placed), indenter=indenter)


def _simulate(problem: IndentationProblem, depths: np.ndarray, device: str) -> Any:
    result = simulate_indentation(
        problem, depths, device=device, progress=False, options=NewtonOptions(tolerance=1e-8)
    )
    if not result.completed:
        raise ConvergenceError(
            f"the trainer calibration's {_label(problem)} run stopped: {result.message}"
        )
    return result


def _volume_change(mesh: TetMesh, displacement: np.ndarray) -> float:
    """The body's volume change over the volume its loaded surface (``top``) swept inward.

    The deformed minus the rest volume of every tet (TET4), over the sum of
    ``area max(0, -u . n)`` of the ``top`` boundary triangles (u at their centroids, n
    outward): 0 for an incompressible body (what the probe pushes in bulges out elsewhere),
    -1 where all that is pushed in is lost.
    """
    tets = mesh.tets[:, :4]

    def volumes(points: np.ndarray) -> np.ndarray:
        a, b, c, d = (points[tets[:, k]] for k in range(4))
        return np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a) / 6.0

    change = volumes(mesh.points + displacement).sum() - volumes(mesh.points).sum()
    top = surface_triangles(mesh, surface="top")
    a, b, c = (mesh.points[top[:, k]] for k in range(3))
    area_normal = 0.5 * np.cross(b - a, c - a)
    u = displacement[top].mean(axis=1)
    swept = np.maximum(0.0, -np.einsum("ij,ij->i", u, area_normal)).sum()
    return float(change / swept) if swept > 0 else 0.0


def _checked_options(
    nu_bounds: tuple[float, float],
    depth_count: int,
    check_radius_factors: Sequence[float],
    fit_radius_factors: Sequence[float],
) -> tuple[float, float, list[float], list[float]]:
    """:func:`calibrate_trainer_material`'s options checked: (the bounds of nu, the check's
    and the fit's radius factors)."""
    low, high = (float(v) for v in nu_bounds)
    if not 0.0 <= low < high < 0.5:
        raise InputError(
            "nu_bounds must satisfy 0 <= low < high < 0.5", key="nu_bounds", value=nu_bounds
        )
    if isinstance(depth_count, bool) or int(depth_count) != depth_count or depth_count < 1:
        raise InputError("must be a positive integer", key="depth_count", value=depth_count)
    factors = [float(f) for f in check_radius_factors]
    fit_factors = [float(f) for f in fit_radius_factors]
    for key, values in (("check_radius_factors", factors), ("fit_radius_factors", fit_factors)):
        for factor in values:
            if not (math.isfinite(factor) and factor > 0):
                raise InputError("must be positive", key=key, value=factor)
    return low, high, factors, fit_factors


def calibrate_trainer_material(
    study: Study,
    *,
    mesh: TetMesh | None = None,
    max_tets: int | None = None,
    depth_count: int = 6,
    nu_bounds: tuple[float, float] = DEFAULT_NU_BOUNDS,
    fit_radius_factors: Sequence[float] = (),
    check_radius_factors: Sequence[float] = (0.5, 2.0),
    device: str = "cpu",
) -> TrainerCalibration:
    """Calibrate the trainer's E and nu on its own mesh against the locking-free FE.

    Args:
        study: The (fitted) study: specimen, probes, depths and material.
        mesh: The trainer's mesh (TET4, the whole body, node sets ``top`` and ``bottom``);
            None: :func:`trainer_mesh` of the study.
        max_tets: With ``mesh=None``: the most tets of the trainer's mesh.
        depth_count: Depths per probe, evenly spaced to the study's deepest depth.
        nu_bounds: The Poisson's ratios searched, ``0 <= low < high < 0.5``.
        fit_radius_factors: Probes of these multiples of each probe's radius are fitted too
            (a trainer whose tools come in several sizes).
        check_radius_factors: Probes of these multiples of each probe's radius are
            simulated with the calibrated material and reported, not fitted.
        device: Warp device of the FE runs.

    Returns:
        The calibration.

    Raises:
        InputError: Bad options.
        ConvergenceError: A run that does not converge.

    Notes:
        For the trainer's energy ``W(F; mu, lambda)`` linear in ``(mu, lambda)``, scaling E
        at a fixed nu scales every force by the same factor, so with the trainer's force
        ``f_kd`` at ``E_0`` and the reference ``F_kd`` (probe k, depth d) the relative
        least-squares E is ``E = E_0 sum(r) / sum(r^2)`` with ``r = f_kd / F_kd``.
    """
    low, high, factors, fit_factors = _checked_options(
        nu_bounds, depth_count, check_radius_factors, fit_radius_factors
    )
    trainer = trainer_mesh(study, max_tets=max_tets) if mesh is None else mesh
    depths = _depths(study, int(depth_count))
    study_probes = _reference_problems(study)
    references = study_probes + [
        _other_radius(study, base, factor) for factor in fit_factors for base in study_probes
    ]
    true_e, true_nu = _elastic(study.material).small_strain_equivalent()
    reference_forces = [
        np.asarray(_simulate(p, depths, device).reaction_force_N, dtype=np.float64)
        for p in references
    ]
    reference = np.concatenate(reference_forces)

    def trainer_problem(problem: IndentationProblem, nu: float) -> IndentationProblem:
        return dataclasses.replace(
            problem,
            mesh=trainer,
            material=StableNeoHookean(true_e, nu),
            formulation="displacement",
            symmetry_planes=(),
        )

    scan: list[tuple[float, float, float]] = []
    runs: dict[float, list[Any]] = {}  # each nu's runs at E0, which scale to any E

    def misfit(nu: float) -> float:
        runs[float(nu)] = [_simulate(trainer_problem(p, nu), depths, device) for p in references]
        forces = np.concatenate([run.reaction_force_N for run in runs[float(nu)]])
        ratio = forces / reference
        scale = ratio.sum() / (ratio**2).sum()
        rms = float(np.sqrt(np.mean((scale * ratio - 1.0) ** 2)))
        scan.append((float(nu), float(true_e * scale), rms))
        return rms

    minimize_scalar(misfit, bounds=(low, high), method="bounded", options={"xatol": 2e-3})
    nu, youngs, _ = min(scan, key=lambda entry: entry[2])

    def checked(
        problem: IndentationProblem, force: np.ndarray, fitted: bool, run: Any = None
    ) -> tuple:
        """The probe's curves at the calibrated material: from its run at E0 scaled to E (the
        same equilibrium) where the search made one, else from a run of its own."""
        placed = dataclasses.replace(
            trainer_problem(problem, nu), material=StableNeoHookean(youngs, nu)
        )
        scale = 1.0
        if run is None:
            run = _simulate(placed, depths, device)
        else:
            scale = youngs / true_e
        probe = TrainerProbe(
            label=_label(problem),
            radius_m=problem.indenter.radius_m,
            fitted=fitted,
            depths_m=depths,
            reference_force_N=np.asarray(force, dtype=np.float64),
            trainer_force_N=scale * np.asarray(run.reaction_force_N, dtype=np.float64),
            punch_nodes=np.asarray(placed.punch_nodes, dtype=np.int64),
            direction=np.asarray(placed.probe_direction, dtype=np.float64),
        )
        return probe, run

    fitted_runs = [
        checked(p, f, True, run)
        for p, f, run in zip(references, reference_forces, runs[nu], strict=True)
    ]
    probes = [probe for probe, _ in fitted_runs]
    unchecked = []
    for factor in factors:
        for p in (_other_radius(study, base, factor) for base in study_probes):
            try:
                probes.append(checked(p, _simulate(p, depths, device).reaction_force_N, False)[0])
            except ConvergenceError as exc:  # a check that fails says so; the asset stands
                unchecked.append(f"{_label(p)}: {exc}")
    volume = _volume_change(trainer, np.asarray(fitted_runs[0][1].displacement_m)[-1])
    return TrainerCalibration(
        youngs_modulus_Pa=float(youngs),
        poissons_ratio=float(nu),
        true_youngs_modulus_Pa=float(true_e),
        true_poissons_ratio=float(true_nu),
        probes=tuple(probes),
        volume_change=float(volume),
        tet_count=trainer.tet_count,
        node_count=trainer.node_count,
        scan=tuple(sorted(scan)),
        nu_bounds=(low, high),
        unchecked=tuple(unchecked),
    )
