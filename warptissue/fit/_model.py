"""The inverse-FE fit's forward model: the FE force of every record of a study as a function
of the free parameters (material and depth offsets), with its exact Jacobian, and the FE runs
several fits share (:class:`SharedRuns`).

The public face is :mod:`warptissue.fit.indentation` (:func:`fit_indentation`); its module
docstring holds the model's mathematics ("Notes").
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from warptissue import fem
from warptissue.device import resolve_device
from warptissue.errors import ConvergenceError, InputError
from warptissue.fit._forward import FitMeeting
from warptissue.loading import resample_history
from warptissue.lsq.engine import RELATIVE_FLOOR_SHARE
from warptissue.lsq.metrics import r_squared
from warptissue.lsq.result import RejectStep
from warptissue.materials import Viscoelastic
from warptissue.simulate import check_linear_solver, estimate_mesh, record_problems
from warptissue.study import DEPTH_OFFSET, DataRecord, Study

BULK_MODULUS = "bulk_modulus_Pa"
"""The bulk modulus's name among a material's sensitivity names."""
OFFSET_BOUND_SHARES = (0.5, 0.1)
"""Default bounds of a record's depth offset: from its shallowest recorded depth less this
first share of its depth span, to its deepest less the second share (the probe touches
before its deepest point)."""
OFFSET_DIFFERENCE_SHARE = 1e-4
"""The step of the one-sided difference of a viscoelastic record's force by its depth offset,
as a share of the record's depth span."""
OFFSET_NOISE_SIGMA = 6.0
"""The start of a depth offset without a contact point: where the force first exceeds this
many noise standard deviations (and 1 % of the peak force)."""
_CACHE_SIZE = 8


@dataclass
class Evaluation:
    """One forward evaluation: residuals, Jacobian and the curves behind them."""

    x: np.ndarray
    residuals: np.ndarray
    jacobian: np.ndarray
    predicted: list[np.ndarray]
    fe_curves: list[tuple[np.ndarray, np.ndarray, np.ndarray]]

    @property
    def cost(self) -> float:
        return 0.5 * float(self.residuals @ self.residuals)


class ForwardModel:
    """The FE force of every record as a function of the free parameters, with a cache.

    One evaluation runs the FE (once per probe for an elastic material: per site where
    the records were measured at several; once per record for a viscoelastic one) with the
    sensitivities of the free parameters, and gives the residuals and the Jacobian together:
    ``fun`` and ``jac`` at one point share one run.

    With ``offset_start`` (one depth offset per record, m) the parameter
    vector is the free material parameters followed by the records' depth offsets, and the
    FE depths are a lattice of steps fixed by the start (module docstring, "Contact point").
    """

    def __init__(
        self,
        *,
        study: Study,
        problems: Sequence[Any],
        problem_of: Sequence[int],
        assemblers: Sequence[Any],
        material: Any,
        names: tuple[str, ...],
        device: Any,
        progress: bool,
        offset_start: np.ndarray | None = None,
        batch_records: bool = False,
    ) -> None:
        settings = study.fit
        self.batch_records = batch_records
        self._packed_assembler: Any = None
        self.meeting: tuple[FitMeeting, int] | None = None
        self.study = study
        self.problems = list(problems)
        self.problem_of = list(problem_of)
        self.assemblers = list(assemblers)
        self.material = material
        self.names = names
        self.device = device
        self.progress = progress
        self.options = study.solver.options
        self.all_names = tuple(material.parameter_names)
        missing = [name for name in names if name not in self.all_names]
        if missing:
            raise InputError(
                f"fit.free names {missing[0]!r}, not a parameter of the material "
                f"({', '.join(self.all_names)})",
                path=study.path,
                key="fit.free",
                value=missing[0],
            )
        self.index = [self.all_names.index(name) for name in names]
        self._set_sensitivities(material, names, settings.bulk_modulus)
        self.viscoelastic = isinstance(material, Viscoelastic)
        self.records = study.data
        steps = settings.time_steps
        self.measured = [np.asarray(r.force_N, dtype=np.float64) for r in self.records]
        everything = np.concatenate(self.measured)
        largest = float(np.max(np.abs(everything)))
        if settings.objective == "relative":
            floor = settings.relative_floor_N or RELATIVE_FLOOR_SHARE * largest
            self.divisors = [np.maximum(np.abs(f), floor) for f in self.measured]
        else:
            self.divisors = [np.ones_like(f) for f in self.measured]
        self.contact_s = [r.contact_time_s for r in self.records]
        self.offset_count = 0 if offset_start is None else len(self.records)
        self.depth_step_m = 0.0
        self.steps = steps
        self.offset_differences = [
            OFFSET_DIFFERENCE_SHARE * max(float(np.ptp(r.displacement_m)), 1e-12)
            for r in self.records
        ]
        self.grids = self._start_grids(offset_start)
        self.forward_solves = 0
        self.warm: dict[int, tuple[np.ndarray | None, np.ndarray, np.ndarray]] = {}
        self.solves_per_evaluation = len(self.grids)
        self.cache: dict[bytes, Evaluation] = {}
        self.best: Evaluation | None = None
        self.evaluations = 0

    def _set_sensitivities(self, material: Any, names: tuple[str, ...], bulk_modulus: str) -> None:
        """The sensitivities each run asks for and the weights that give the free
        parameters' from them (``bulk_ratios``, ``shear_weights``)."""
        # fit.bulk_modulus = "follows_shear": each material b of the body (one, or one per
        # region) keeps K_b = ratio_b mu0_b(theta) at every point, so dF/dtheta_j =
        # dF/dtheta_j|K + sum_b dF/dK_b ratio_b dmu0_b/dtheta_j (the FE gives dF/dK_b too).
        self.bulk_ratios: np.ndarray | None = None
        self.sensitivity_names = names
        parts = material.parts
        if bulk_modulus == "follows_shear":
            self.bulk_ratios = np.array(
                [part.bulk_modulus / part.initial_shear_modulus_Pa for _, part in parts]
            )
            self.sensitivity_names = (*names, *(prefix + BULK_MODULUS for prefix, _ in parts))
        self.shear_weights = np.zeros((len(parts), len(names)))
        for j, name in enumerate(names):
            b, local = material.part_of(name)
            self.shear_weights[b, j] = parts[b][1].moduli_derivative(local)[0]

    def _start_grids(self, offset_start: Any) -> list:
        """Each FE run's steps at the start: a viscoelastic record's time steps (from its
        touch at the start offset where offsets are fitted), else each probe's depth
        lattice (to the records' reach at the start offsets where they are fitted)."""
        steps, study = self.steps, self.study
        if self.viscoelastic and self.offset_count:
            offsets = np.asarray(offset_start, dtype=np.float64)
            try:
                return [self._touch(k, offsets[k])[1] for k in range(len(self.records))]
            except RejectStep as exc:
                raise InputError(
                    f"the start of the depth offsets {offsets.tolist()} m: {exc}; give "
                    "fit.start.depth_offset_m below the deepest recorded depth",
                    path=study.path,
                    key=f"fit.start.{DEPTH_OFFSET}",
                ) from None
        if self.viscoelastic:
            return [record.load_history(steps=steps) for record in self.records]
        if self.offset_count:
            reach = self._reach(np.asarray(offset_start, dtype=np.float64))
            if not reach > 0.0:
                raise InputError(
                    f"the start of the depth offsets {np.asarray(offset_start).tolist()} m "
                    "leaves no record in contact: give fit.start.depth_offset_m below the "
                    "deepest recorded depth",
                    path=study.path,
                    key=f"fit.start.{DEPTH_OFFSET}",
                )
            self.depth_step_m = reach / steps
            return self._lattices(np.asarray(offset_start, dtype=np.float64))
        grids = []
        for g in range(len(self.problems)):
            deepest = max(
                float(np.max(r.displacement_m))
                for r, p in zip(self.records, self.problem_of, strict=True)
                if p == g
            )
            grids.append((None, deepest * np.arange(1, steps + 1) / steps))
        return grids

    def material_at(self, x: np.ndarray) -> Any:
        vector = self.material.parameter_vector.copy()
        vector[self.index] = np.asarray(x)[: len(self.names)]
        material = self.material.with_parameters(vector)
        if self.bulk_ratios is None:
            return material
        return material.with_parts(
            [
                part.with_bulk_modulus(ratio * part.initial_shear_modulus_Pa)
                for (_, part), ratio in zip(material.parts, self.bulk_ratios, strict=True)
            ]
        )

    def offsets_at(self, x: np.ndarray) -> np.ndarray:
        """The records' depth offsets (m) in ``x``: zeros when the contact is given."""
        if not self.offset_count:
            return np.zeros(len(self.records))
        return np.asarray(x, dtype=np.float64)[len(self.names) :]

    def _touch(self, k: int, offset: float) -> tuple[float, tuple[np.ndarray, np.ndarray]]:
        """Record ``k``'s touch time at a depth offset and its FE time steps from it.

        The touch time t0 is where the record's recorded depth (its running maximum) first
        passes ``offset`` (linear between samples; the first sample's time for a record
        deeper than that from its start); the steps are
        :func:`warptissue.loading.resample_history` of ``(time - t0, depth - offset)``, as
        :meth:`DataRecord.load_history` does from a given contact.

        Returns:
            ``(t0, (times_s, depths_m))``: t0 on the record's clock (s); the FE times from
            t0 (s) and true depths (m).

        Raises:
            RejectStep: The record never reaches the offset, or fewer than two samples
                follow the touch.
        """
        record = self.records[k]
        t = np.asarray(record.time_s, dtype=np.float64)
        recorded = np.asarray(record.displacement_m, dtype=np.float64)
        reached = np.maximum.accumulate(recorded)
        # The first sample beyond the offset; the touch lies after the one before it (the
        # last at or above the offset's level: a conditioned record's clipped zeros end at
        # its contact).
        i = int(np.searchsorted(reached, offset, side="right"))
        if i >= reached.size:
            raise RejectStep(
                f"{record.file} never reaches the depth offset {offset:.6g} m (its deepest "
                f"recorded depth is {reached[-1]:.6g} m)"
            )
        if i == 0:
            touch = float(t[0])
        else:
            share = (offset - reached[i - 1]) / (reached[i] - reached[i - 1])
            touch = float(t[i - 1] + share * (t[i] - t[i - 1]))

        try:
            grid = resample_history(t - touch, recorded - offset, steps=self.steps)
        except InputError as exc:
            raise RejectStep(f"{record.file}: {exc.message}") from exc
        return touch, grid

    def _reach(self, offsets: np.ndarray, problem: int | None = None) -> float:
        """The deepest true depth of the records (of one problem) at these offsets (m)."""
        return max(
            float(np.max(r.displacement_m)) - d0
            for r, d0, p in zip(self.records, offsets, self.problem_of, strict=True)
            if problem is None or p == problem
        )

    def _lattices(self, offsets: np.ndarray) -> list[tuple[None, np.ndarray]]:
        """Each problem's FE depths: the fixed steps of ``depth_step_m`` to the deepest true
        depth of its records."""
        grids = []
        for g in range(len(self.problems)):
            count = max(1, math.ceil(self._reach(offsets, g) / self.depth_step_m - 1e-9))
            grids.append((None, self.depth_step_m * np.arange(1, count + 1)))
        return grids

    def _problem_at(self, g: int, material: Any) -> Any:
        return dataclasses.replace(self.problems[g], material=material)

    def _path_problems(self) -> list[int]:
        """The problem of each load path: one path per problem (an elastic material's), or
        one per record (a viscoelastic material's)."""
        return list(self.problem_of if self.viscoelastic else range(len(self.problems)))

    def _warm_start(
        self, j: int, times: np.ndarray | None, depths: np.ndarray
    ) -> np.ndarray | None:
        """Load path ``j``'s warm start: the states of its last completed run at the
        requested loads its depths (and times) share from the first, or None."""
        kept = self.warm.get(j)
        if kept is None:
            return None
        old_times, old_depths, states = kept
        count = min(old_depths.size, depths.size)
        same = old_depths[:count] == depths[:count]
        if (old_times is None) != (times is None):
            return None
        if times is not None:
            same &= old_times[:count] == times[:count]
        shared = count if same.all() else int(np.argmin(same))
        return states[:shared] if shared else None

    def _keep_warm(self, grids: Sequence[tuple[np.ndarray | None, np.ndarray]], runs: list) -> None:
        """Keep each load path's converged states for the next evaluation's warm start."""
        for j, ((times, depths), run) in enumerate(zip(grids, runs, strict=True)):
            self.warm[j] = (
                None if times is None else np.asarray(times, dtype=np.float64),
                np.asarray(depths, dtype=np.float64),
                run.displacement_m,
            )

    def _run(
        self,
        material: Any,
        g: int,
        times: np.ndarray | None,
        depths: np.ndarray,
        *,
        sensitivities: bool = True,
        warm: np.ndarray | None = None,
    ) -> Any:
        problem = self._problem_at(g, material)
        extra = {} if times is None else {"times_s": times}
        if warm is not None:
            extra["warm_states_m"] = warm
        self.forward_solves += 1
        try:
            result = _simulate()(
                problem,
                depths,
                device=self.device,
                progress=self.progress,
                options=self.options,
                assembler=self.assemblers[g],
                sensitivities=self.sensitivity_names if sensitivities else (),
                **extra,
            )
        except ConvergenceError as exc:
            raise RejectStep(f"the FE failed: {exc}") from exc
        if not result.completed:
            raise RejectStep(f"the FE did not converge: {result.message}")
        return result

    def _runs(
        self,
        material: Any,
        grids: Sequence[tuple[np.ndarray | None, np.ndarray]],
        *,
        sensitivities: bool = True,
    ) -> list[Any]:
        """The FE runs of several load paths (``(times, depths)`` each) of one material: in
        one batched run (:func:`warptissue.fem.simulate_indentation_batch`) where
        ``batch_records`` and there are several, else one after another. A fit of several
        studies hands them to its :class:`~warptissue.fit._forward.FitMeeting`, which
        solves them with the other fits' runs. The paths are one per problem (an elastic
        material) or one per record (a viscoelastic one)."""
        which = self._path_problems()
        problems = [self._problem_at(g, material) for g in which]
        warm = [self._warm_start(j, times, depths) for j, (times, depths) in enumerate(grids)]
        if self.meeting is not None:
            meeting, fit = self.meeting
            self.forward_solves += len(grids)
            results = meeting.request(
                fit,
                RunRequest(
                    problems=problems,
                    grids=list(grids),
                    names=self.sensitivity_names if sensitivities else (),
                    options=self.options,
                    device=self.device,
                    warm=warm,
                ),
            )
            for result in results:
                if not result.completed:
                    raise RejectStep(f"the FE did not converge: {result.message}")
            self._keep_warm(grids, results)
            return results
        if not (self.batch_records and len(grids) > 1):
            runs = [
                self._run(material, g, times, depths, sensitivities=sensitivities, warm=start)
                for g, (times, depths), start in zip(which, grids, warm, strict=True)
            ]
            self._keep_warm(grids, runs)
            return runs

        if self._packed_assembler is None or self._packed_assembler[0] != which:
            self._packed_assembler = (which, fem.batch_assembler(problems, device=self.device))
        self.forward_solves += len(grids)
        results = fem.simulate_indentation_batch(
            problems,
            [depths for _, depths in grids],
            options=self.options,
            sensitivities=self.sensitivity_names if sensitivities else (),
            assembler=self._packed_assembler[1],
            times_s=[times for times, _ in grids],
            warm_states_m=warm,
        )
        for result in results:
            if not result.completed:
                raise RejectStep(f"the FE did not converge: {result.message}")
        self._keep_warm(grids, results)
        return results

    def evaluate(self, x: np.ndarray) -> Evaluation:
        key = np.asarray(x, dtype=np.float64).tobytes()
        if key in self.cache:  # least recently used out: the current point stays
            self.cache[key] = self.cache.pop(key)
            return self.cache[key]
        try:
            material = self.material_at(x)
        except InputError as exc:
            raise RejectStep(str(exc)) from exc
        if min(float(part.initial_shear_modulus_Pa) for _, part in material.parts) <= 0.0:
            raise RejectStep("an initial shear modulus is not positive")
        offsets = self.offsets_at(x)
        touches = list(self.contact_s)
        if self.viscoelastic and self.offset_count:
            timed = [self._touch(k, offsets[k]) for k in range(len(self.records))]
            touches = [touch for touch, _ in timed]
            grids = [grid for _, grid in timed]
        elif self.offset_count:
            grids = self._lattices(offsets)
        else:
            grids = self.grids
        runs = self._runs(material, grids)
        earlier = None
        if self.viscoelastic and self.offset_count:
            earlier = self._earlier_touches(material, offsets)
        predicted, jacobians, curves = [], [], []
        for k, record in enumerate(self.records):
            if self.viscoelastic:
                run = runs[k]
                fe_time = np.asarray(grids[k][0], dtype=np.float64)
                fe_depth = np.asarray(run.depths_m, dtype=np.float64)
                where = np.concatenate([[0.0], fe_time])
                at = record.time_s - touches[k]
            else:
                run = runs[self.problem_of[k]]
                fe_depth = np.asarray(run.depths_m, dtype=np.float64)
                where = np.concatenate([[0.0], fe_depth])
                shifted = record.displacement_m - offsets[k]
                at = np.clip(shifted, 0.0, None)
                fe_time = _first_passage_times(record.time_s, shifted, self.contact_s[k], fe_depth)
            force = np.asarray(run.reaction_force_N, dtype=np.float64)
            sensitivity = np.asarray(run.force_sensitivity_N_per_unit, dtype=np.float64)
            curve = np.concatenate([[0.0], force])
            predicted.append(np.interp(at, where, curve))
            if self.bulk_ratios is not None:  # K follows mu0: the chain rule through each K
                n = len(self.names)
                sensitivity = (
                    sensitivity[:, :n]
                    + (sensitivity[:, n:] * self.bulk_ratios) @ self.shear_weights
                )
            columns = [
                np.interp(at, where, np.concatenate([[0.0], sensitivity[:, j]]))
                for j in range(len(self.names))
            ]
            for i in range(self.offset_count):
                if i != k:
                    columns.append(np.zeros(at.size))
                elif self.viscoelastic:
                    columns.append((predicted[k] - earlier[k]) / self.offset_differences[k])
                else:
                    columns.append(_offset_column(shifted, where, curve))
            jacobians.append(np.column_stack(columns))
            if self.viscoelastic:
                curves.append((fe_time, fe_depth, force))
            else:
                # The FE steps up to the first one at or beyond the record's deepest point.
                covered = int(np.searchsorted(fe_depth, float(np.max(at))))
                keep = slice(0, covered + 1)
                curves.append((fe_time[keep], fe_depth[keep], force[keep]))
        residuals = np.concatenate(
            [(p - f) / w for p, f, w in zip(predicted, self.measured, self.divisors, strict=True)]
        )
        jacobian = np.vstack(
            [j / w[:, None] for j, w in zip(jacobians, self.divisors, strict=True)]
        )
        evaluation = Evaluation(
            np.array(x, dtype=np.float64), residuals, jacobian, predicted, curves
        )
        self.evaluations += 1
        if len(self.cache) >= _CACHE_SIZE:
            self.cache.pop(next(iter(self.cache)))
        self.cache[key] = evaluation
        if self.best is None or evaluation.cost < self.best.cost:
            self.best = evaluation
        return evaluation

    def _earlier_touches(self, material: Any, offsets: np.ndarray) -> list[np.ndarray]:
        """Each record's force at its samples with the probe touching earlier, for dF/dd0 of
        a viscoelastic material by a one-sided difference.

        The touch time, the FE time steps and the depths all move with the offset, and the
        force is a hereditary integral of the depth history, not a function of the depth:
        one more FE run per record (without sensitivities, all records batched where the
        forward runs are) at ``offset - h`` (the probe touching earlier, so the record stays
        in contact), h = :data:`OFFSET_DIFFERENCE_SHARE` of the record's depth span, gives
        (F(d0) - F(d0 - h)) / h at the samples.
        """
        timed = [
            self._touch(k, offsets[k] - self.offset_differences[k])
            for k in range(len(self.records))
        ]
        runs = self._runs(material, [grid for _, grid in timed], sensitivities=False)
        forces = []
        for record, (touch, (times, _)), run in zip(self.records, timed, runs, strict=True):
            where = np.concatenate([[0.0], np.asarray(times, dtype=np.float64)])
            curve = np.concatenate([[0.0], np.asarray(run.reaction_force_N, dtype=np.float64)])
            forces.append(np.interp(record.time_s - touch, where, curve))
        return forces

    def fun(self, x: np.ndarray) -> np.ndarray:
        return self.evaluate(x).residuals

    def jac(self, x: np.ndarray) -> np.ndarray:
        return self.evaluate(x).jacobian

    def r_squared_at(self, evaluation: Evaluation) -> float | None:
        try:
            return r_squared(np.concatenate(self.measured), np.concatenate(evaluation.predicted))
        except InputError:
            return None


def _offset_column(shifted: np.ndarray, where: np.ndarray, curve: np.ndarray) -> np.ndarray:
    """d F_model / d d0 at the samples: minus the slope of the interpolant's segment at the
    true depth ``shifted`` = d - d0 (m, shape (m,)); zero before the touch and beyond the
    last FE depth, where the interpolant is flat. ``where``, ``curve``: the FE depths and
    forces with (0, 0) first."""
    slopes = np.diff(curve) / np.diff(where)
    segment = np.clip(np.searchsorted(where, shifted, side="right") - 1, 0, slopes.size - 1)
    inside = (shifted > 0.0) & (shifted < where[-1])
    return np.where(inside, -slopes[segment], 0.0)


def _first_passage_times(
    time_s: np.ndarray, depth_m: np.ndarray, contact_s: float, depths: np.ndarray
) -> np.ndarray:
    """The times (from the contact) at which a record of depth ``depth_m`` (below the
    contact, m) first reaches each depth (its loading ramp); depths beyond its deepest point
    get its deepest point's time."""
    t = time_s - contact_s
    d = np.maximum.accumulate(np.clip(depth_m, 0.0, None))
    rising = np.concatenate([[True], np.diff(d) > 0.0])
    return np.interp(depths, d[rising], t[rising])


def _simulate() -> Callable[..., Any]:
    return fem.simulate_indentation


def forward_model(
    study: Study,
    material: Any,
    free: tuple[str, ...],
    *,
    device: str | None,
    progress: bool,
    offset_start: np.ndarray | None = None,
    batch_records: bool | None = None,
) -> ForwardModel:
    """The meshes, problems (one per probe of its records) and assemblers of a study (built
    once), as a :class:`ForwardModel`
    of the free parameters (and of the records' depth offsets, with ``offset_start``);
    ``batch_records`` (None: :func:`batches_records`) solves the records' runs together."""

    chosen = device if device is not None else study.solver.device
    warp_device = resolve_device(None if chosen == "auto" else chosen)
    check_linear_solver(study, warp_device)
    estimate_mesh(study).require_fits(solve=warp_device.is_cpu, what="study's mesh")
    problems, problem_of = record_problems(study, material)
    by_mesh: dict[int, Any] = {}
    for problem in problems:
        if id(problem.mesh) not in by_mesh:
            by_mesh[id(problem.mesh)] = fem.Assembler(
                problem.mesh, material, formulation=problem.formulation, device=warp_device
            )
    return ForwardModel(
        study=study,
        problems=problems,
        problem_of=problem_of,
        assemblers=[by_mesh[id(problem.mesh)] for problem in problems],
        material=material,
        names=free,
        device=warp_device,
        progress=progress,
        offset_start=offset_start,
        batch_records=(batches_records(warp_device) if batch_records is None else batch_records),
    )


def batches_records(device: Any) -> bool:
    """Whether a fit solves its records' FE runs (one per record of a viscoelastic material)
    together in one batched run (:func:`warptissue.fem.simulate_indentation_batch`) rather
    than one after another.

    Args:
        device: The Warp device of the fit.

    Returns:
        True where that was measured to pay: see docs/design-notes/batched-fe.md.
    """
    return RECORD_BATCHING[device.is_cuda]


RECORD_BATCHING = {False: False, True: True}
"""Whether a fit batches its records' FE runs, by device (CPU: False, CUDA: True), as
measured (docs/design-notes/batched-fe.md, "A fit's records")."""


def depth_offset_names(records: Sequence[DataRecord]) -> tuple[str, ...]:
    """The parameter names of the records' depth offsets: ``depth_offset_m`` for one record,
    ``depth_offset1_m``, ``depth_offset2_m``, ... (in ``[[data]]`` order) for several."""
    if len(records) == 1:
        return (DEPTH_OFFSET,)
    return tuple(f"depth_offset{k}_m" for k in range(1, len(records) + 1))


def depth_offset_start_m(record: DataRecord) -> float:
    """A start value of a record's depth offset d0 (m), from the record.

    A record conditioned with a contact point (``contact = "auto"``, detected by
    :func:`warptissue.acquisition.conditioning.detect_contact`, or ``contact_position_m``)
    has its depths counted from it: 0. A record used as recorded (``contact = "none"``):
    where the force first exceeds :data:`OFFSET_NOISE_SIGMA` noise standard deviations and
    1 % of the peak force, refined by a straight line through the next samples (to 4 times
    that force) back to zero force, kept between the last sample below it and the first one
    above; a record above it from its first sample: that line's zero, at most that sample.

    Args:
        record: A conditioned ``[[data]]`` record.

    Returns:
        The recorded depth at first touch (m).

    Notes:
        The noise is estimated from second differences of the force (1.4826 times their
        median absolute value over sqrt(6)), which a smooth loading curve leaves to the
        noise. The force is taken as zero before the touch (the model's too).
    """
    if record.conditioning.get("contact", "none") != "none":
        return 0.0
    d = np.asarray(record.displacement_m, dtype=np.float64)
    f = np.asarray(record.force_N, dtype=np.float64)
    peak = float(np.max(f)) if f.size else 0.0
    if f.size < 3 or not peak > 0.0:
        return float(d[0]) if d.size else 0.0
    noise = 1.4826 * float(np.median(np.abs(np.diff(f, 2)))) / math.sqrt(6.0)
    threshold = max(OFFSET_NOISE_SIGMA * noise, 0.01 * peak)
    loading = int(np.argmax(d)) + 1  # up to the deepest point
    above = np.flatnonzero(f[:loading] > threshold)
    if not above.size:
        return float(d[int(np.argmax(f))])
    first = int(above[0])
    upto = np.flatnonzero(f[first:loading] > 4.0 * threshold)
    last = first + (int(upto[0]) if upto.size else loading - 1 - first)
    last = max(last, min(first + 1, loading - 1))
    pick = slice(first, last + 1)
    guess = float(d[first])
    if last > first and np.ptp(d[pick]) > 0.0:
        slope, intercept = np.polyfit(d[pick], f[pick], 1)
        if slope > 0.0:
            guess = float(-intercept / slope)
    if first > 0:
        return float(np.clip(guess, d[first - 1], d[first]))
    return min(guess, float(d[0]))


def offset_box(study: Study) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(start, lower, upper) of each record's depth offset (m), each shape (records,):
    ``[fit.start]``/``[fit.bounds]`` ``depth_offset_m`` where given, else from the record
    (:func:`depth_offset_start_m`, :data:`OFFSET_BOUND_SHARES`); the start clipped into the
    bounds."""
    settings = study.fit
    starts, lowers, uppers = [], [], []
    below, above = OFFSET_BOUND_SHARES
    for record in study.data:
        d = np.asarray(record.displacement_m, dtype=np.float64)
        shallow, deep = float(np.min(d)), float(np.max(d))
        span = deep - shallow
        low, high = settings.bounds.get(DEPTH_OFFSET, (shallow - below * span, deep - above * span))
        start = settings.start.get(DEPTH_OFFSET)
        start = depth_offset_start_m(record) if start is None else float(start)
        start = min(max(start, low), high)
        if not start < deep:
            key = "start" if DEPTH_OFFSET in settings.start else "bounds"
            raise InputError(
                f"{record.file}: a depth offset of {start:g} m leaves the record out of "
                f"contact (its deepest recorded depth is {deep:g} m): give a start below it",
                path=study.path,
                key=f"fit.{key}.{DEPTH_OFFSET}",
                value=start,
            )
        starts.append(start)
        lowers.append(low)
        uppers.append(high)
    return np.array(starts), np.array(lowers), np.array(uppers)


def shifted_record(record: DataRecord, offset_m: float) -> DataRecord:
    """The record with its depths counted from a depth offset (``d - d0``)."""
    if offset_m == 0.0:
        return record
    samples = dataclasses.replace(record.record, displacement_m=record.displacement_m - offset_m)
    return dataclasses.replace(record, record=samples)


@dataclass(frozen=True)
class RunRequest:
    """FE runs one fit asks of a :class:`~warptissue.fit._forward.FitMeeting`: one problem
    per load path ``(times_s or None, depths_m)``, with the sensitivities ``names``."""

    problems: list[Any]
    grids: list[tuple[np.ndarray | None, np.ndarray]]
    names: tuple[str, ...]
    options: Any
    device: Any
    warm: list[np.ndarray | None] | None = None


class SharedRuns:
    """Solves the requests of fits that meet (:class:`~warptissue.fit._forward.FitMeeting`):
    the requests that share their sensitivities, Newton settings, device and formulation
    are solved in one batched FE run; the packed assembler of the last few sets of meshes is
    kept (a fit's trial points change the materials, not the meshes)."""

    KEPT = 4

    def __init__(self) -> None:
        self._assemblers: dict[tuple, Any] = {}

    def __call__(self, batch: dict[int, RunRequest]) -> dict[int, Any]:
        groups: dict[tuple, list[int]] = {}
        for fit, request in sorted(batch.items()):  # in fit order: one assembler per set
            key = (
                request.names,
                request.options,
                str(request.device),
                request.problems[0].formulation,
            )
            groups.setdefault(key, []).append(fit)
        answers: dict[int, Any] = {}
        for key, fits in groups.items():
            problems = [problem for fit in fits for problem in batch[fit].problems]
            grids = [grid for fit in fits for grid in batch[fit].grids]
            warm = [
                start
                for fit in fits
                for start in (batch[fit].warm or [None] * len(batch[fit].grids))
            ]
            meshes = (key, tuple(id(problem.mesh) for problem in problems))
            try:
                if meshes not in self._assemblers:
                    if len(self._assemblers) >= self.KEPT:
                        self._assemblers.pop(next(iter(self._assemblers)))
                    self._assemblers[meshes] = fem.batch_assembler(
                        problems, device=batch[fits[0]].device
                    )
                assembler = self._assemblers[meshes]
                results = fem.simulate_indentation_batch(
                    problems,
                    [depths for _, depths in grids],
                    options=batch[fits[0]].options,
                    sensitivities=key[0],
                    assembler=assembler,
                    times_s=[times for times, _ in grids],
                    warm_states_m=warm,
                )
            except Exception as exc:  # every fit of the group gets it
                answers.update(dict.fromkeys(fits, exc))
                continue
            start = 0
            for fit in fits:
                count = len(batch[fit].grids)
                answers[fit] = results[start : start + count]
                start += count
        return answers
