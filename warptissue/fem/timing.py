"""Where a load path's time goes: the per-phase timer of the Newton solver.

:func:`warptissue.fem.solve_quasistatic` (and :func:`warptissue.fem.simulate_indentation`,
``warptissue simulate --profile``) take ``profile=True`` to time each phase of every Newton
iteration with one :class:`PhaseTimer`; the result carries the totals as a
:class:`NewtonTimings` (``result.timings``). The phases (:data:`PHASES`):

- ``assembly``: the residual and tangent assemblies of the Newton iterations (element
  kernels, the Dirichlet elimination of the tangent);
- ``analysis``: the linear solver's set-up for the mesh's sparsity pattern, once per mesh
  (PARDISO's ordering and symbolic factorization, cuDSS's analysis, the scalar pattern);
- ``factorization``: the numerical factorizations (PARDISO phase 22, cuDSS ``factorize``);
- ``solve``: the triangular solves (PARDISO phase 33, cuDSS ``solve``, with the copy of the
  solution to the host), or the Krylov iterations of CG;
- ``line_search``: the line searches, with their residual-only assemblies;
- ``elimination``: the nonlinear elimination of the residual peaks (its patch solves and
  assemblies);
- ``sensitivity``: the force sensitivities at the converged states, less their linear
  solves, which count as ``solve`` (or ``factorization``);
- ``host``: the rest of the run's wall time (predictor, residual norms, copies between the
  device and NumPy, the gathering of the tangent's values for the direct solver, the
  viscous history, bookkeeping).

Each phase is timed exclusively: a phase that runs inside another (a solve inside the
sensitivities) stops the outer one's clock, so the phases add up to the run's wall time.
On a CUDA device each phase boundary synchronizes the device (only while profiling; an
unprofiled run neither synchronizes nor reads a clock per phase), so that asynchronous work
is charged to the phase that launched it.
"""

from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass, field
from typing import Any

import warp as wp

__all__ = ["LINEAR_SOLVER_PHASES", "PHASES", "NewtonTimings", "PhaseTimer"]

PHASES = (
    "assembly",
    "analysis",
    "factorization",
    "solve",
    "line_search",
    "elimination",
    "sensitivity",
    "host",
)
"""The timed phases, in the order of the profile's table."""
LINEAR_SOLVER_PHASES = ("analysis", "factorization", "solve")
"""The phases inside the linear solver; the others are the Newton loop's own cost."""
_TIMED = PHASES[:-1]  # "host" is the remainder

_NO_PHASE = contextlib.nullcontext()


class _Phase:
    """The context manager of one phase (made once per timer: entering it allocates nothing)."""

    __slots__ = ("name", "timer")

    def __init__(self, timer: PhaseTimer, name: str) -> None:
        self.timer = timer
        self.name = name

    def __enter__(self) -> None:
        self.timer._push(self.name)

    def __exit__(self, *exc_info: object) -> bool:
        self.timer._pop()
        return False


class PhaseTimer:
    """Exclusive wall-clock time per phase of a Newton solve (see :data:`PHASES`).

    ``with timer.phase("assembly"): ...`` charges the block's time to ``assembly``, less the
    time of phases entered inside it. A disabled timer hands out a shared null context: no
    clock is read and nothing is synchronized.

    Args:
        enabled: Time the phases (False: every :meth:`phase` is a no-op).
        device: The Warp device of the solve; on a CUDA device every phase boundary
            synchronizes it (only when enabled).

    Attributes:
        enabled: Whether the phases are timed.
        seconds: Exclusive seconds per timed phase (all of :data:`PHASES` but ``host``).
        calls: Times each phase was entered.
        newton_iterations: Newton iterations counted by the solver (:meth:`count_iterations`).
        increments: Load increments attempted (cutbacks and retries included).
    """

    def __init__(self, *, enabled: bool = True, device: Any = None) -> None:
        self.enabled = bool(enabled)
        self._device = device if device is not None and getattr(device, "is_cuda", False) else None
        self._device_name = "cpu" if device is None else str(device)
        self.seconds = dict.fromkeys(_TIMED, 0.0)
        self.calls = dict.fromkeys(_TIMED, 0)
        self.newton_iterations = 0
        self.increments = 0
        self._stack: list[str] = []
        self._since = 0.0
        self._phases = {name: _Phase(self, name) for name in _TIMED}

    def phase(self, name: str) -> contextlib.AbstractContextManager:
        """The context manager that charges its block to ``name`` (a no-op when disabled)."""
        if not self.enabled:
            return _NO_PHASE
        return self._phases[name]

    def count_iterations(self, iterations: int) -> None:
        """Add one load increment's Newton iterations."""
        self.newton_iterations += int(iterations)
        self.increments += 1

    def _now(self) -> float:
        if self._device is not None:
            wp.synchronize_device(self._device)
        return time.perf_counter()

    def _push(self, name: str) -> None:
        now = self._now()
        if self._stack:
            self.seconds[self._stack[-1]] += now - self._since
        self._stack.append(name)
        self.calls[name] += 1
        self._since = now

    def _pop(self) -> None:
        now = self._now()
        self.seconds[self._stack.pop()] += now - self._since
        self._since = now

    def timings(self, *, total_s: float, factorizations: int) -> NewtonTimings:
        """The profile of a finished solve whose wall time was ``total_s`` (s)."""
        seconds = dict(self.seconds)
        seconds["host"] = max(total_s - sum(seconds.values()), 0.0)
        return NewtonTimings(
            seconds=seconds,
            total_s=float(total_s),
            newton_iterations=self.newton_iterations,
            increments=self.increments,
            factorizations=int(factorizations),
            calls=dict(self.calls),
            device=self._device_name,
        )


@dataclass(frozen=True)
class NewtonTimings:
    """Where a load path's wall time went, per phase (:data:`PHASES`).

    Attributes:
        seconds: Wall seconds per phase, every phase of :data:`PHASES` (they add up to
            ``total_s``; ``host`` is the remainder), s.
        total_s: Wall time of the whole load path, s.
        newton_iterations: Newton iterations of all load increments, the failed ones (before
            a cutback) included.
        increments: Load increments attempted (cutbacks and retries included).
        factorizations: Numerical factorizations of the linear solver (Newton's and the
            sensitivities'); 0 for CG.
        calls: Times each timed phase was entered (``host`` has none).
        device: The device the path ran on.
    """

    seconds: dict[str, float]
    total_s: float
    newton_iterations: int
    increments: int = 0
    factorizations: int = 0
    calls: dict[str, int] = field(default_factory=dict)
    device: str = "cpu"

    @property
    def per_iteration_s(self) -> dict[str, float]:
        """Mean seconds per Newton iteration, per phase (and ``total``)."""
        count = max(self.newton_iterations, 1)
        means = {name: value / count for name, value in self.seconds.items()}
        means["total"] = self.total_s / count
        return means

    @property
    def linear_solver_s(self) -> float:
        """Seconds in the linear solver: analysis, factorizations and solves."""
        return sum(self.seconds[name] for name in LINEAR_SOLVER_PHASES)

    @property
    def own_share(self) -> float:
        """The Newton loop's own cost: the share of the wall time outside the linear solver
        (assembly, line search, elimination, sensitivities less their solves, host)."""
        if self.total_s <= 0.0:
            return 0.0
        return 1.0 - self.linear_solver_s / self.total_s

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: seconds per phase, per iteration, and the counts."""
        return {
            "seconds": {name: self.seconds[name] for name in PHASES},
            "seconds_per_newton_iteration": {
                name: value for name, value in self.per_iteration_s.items()
            },
            "total_s": self.total_s,
            "newton_iterations": self.newton_iterations,
            "increments": self.increments,
            "factorizations": self.factorizations,
            "linear_solver_s": self.linear_solver_s,
            "own_share": self.own_share,
            "calls": dict(self.calls),
            "device": self.device,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> NewtonTimings:
        """The timings of :meth:`to_dict`'s output."""
        return cls(
            seconds={name: float(data["seconds"][name]) for name in PHASES},
            total_s=float(data["total_s"]),
            newton_iterations=int(data["newton_iterations"]),
            increments=int(data.get("increments", 0)),
            factorizations=int(data.get("factorizations", 0)),
            calls={name: int(value) for name, value in data.get("calls", {}).items()},
            device=str(data.get("device", "cpu")),
        )

    def table(self) -> str:
        """A plain-text table: seconds, share and ms per Newton iteration of each phase."""
        per_iteration = self.per_iteration_s
        total = self.total_s if self.total_s > 0.0 else 1.0
        lines = [f"{'phase':<14} {'seconds':>9} {'share':>7} {'ms/iteration':>13}"]
        for name in PHASES:
            lines.append(
                f"{name:<14} {self.seconds[name]:>9.3f} {100 * self.seconds[name] / total:>6.1f}% "
                f"{1e3 * per_iteration[name]:>13.2f}"
            )
        mean_ms = 1e3 * per_iteration["total"]
        lines.append(f"{'total':<14} {self.total_s:>9.3f} {100.0:>6.1f}% {mean_ms:>13.2f}")
        lines.append(
            f"{self.newton_iterations} Newton iterations in {self.increments} load increments, "
            f"{self.factorizations} factorizations on {self.device}; outside the linear solver: "
            f"{100 * self.own_share:.1f} %"
        )
        return "\n".join(lines)
