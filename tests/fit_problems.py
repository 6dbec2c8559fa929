"""Standard nonlinear least-squares test problems (More, Garbow & Hillstrom 1981).

J. J. More, B. S. Garbow and K. E. Hillstrom, "Testing unconstrained optimization
software", ACM Trans. Math. Software 7 (1981) 17-41: residuals, standard starting points and
published minima. The engine's tests (tests/test_fit_engine.py) and
``scripts/benchmarks/bench_fit_engine.py`` use them.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

__all__ = [
    "PROBLEMS",
    "TestProblem",
    "box_3d",
    "brown_badly_scaled",
    "freudenstein_roth",
    "helical_valley",
    "meyer",
    "powell_singular",
    "rosenbrock",
    "rosenbrock_jacobian",
]


@dataclass(frozen=True)
class TestProblem:
    """One test problem.

    Attributes:
        residuals: r(x) -> (m,).
        x0: The standard starting point, shape (n,).
        minimum: Published minimum of sum(r**2) reached from x0 (a local one for
            Freudenstein-Roth).
        minimizer: Published minimizer, shape (n,).
    """

    __test__ = False  # not a pytest class

    residuals: Callable[[np.ndarray], np.ndarray]
    x0: tuple[float, ...]
    minimum: float
    minimizer: tuple[float, ...]


_MEYER_Y = np.array(
    [34780, 28610, 23650, 19630, 16370, 13720, 11540, 9744, 8261, 7030, 6005, 5147, 4427, 3820,
     3307, 2872.0]
)  # fmt: skip
_MEYER_T = 45.0 + 5.0 * np.arange(1, 17)
_BOX_T = 0.1 * np.arange(1, 11)


def rosenbrock(x: np.ndarray) -> np.ndarray:
    """Rosenbrock (MGH 1), m = n = 2."""
    return np.array([10.0 * (x[1] - x[0] ** 2), 1.0 - x[0]])


def rosenbrock_jacobian(x: np.ndarray) -> np.ndarray:
    """Analytic Jacobian of :func:`rosenbrock`, shape (2, 2)."""
    return np.array([[-20.0 * x[0], 10.0], [-1.0, 0.0]])


def freudenstein_roth(x: np.ndarray) -> np.ndarray:
    """Freudenstein and Roth (MGH 2), m = n = 2."""
    return np.array(
        [
            -13.0 + x[0] + ((5.0 - x[1]) * x[1] - 2.0) * x[1],
            -29.0 + x[0] + ((x[1] + 1.0) * x[1] - 14.0) * x[1],
        ]
    )


def powell_singular(x: np.ndarray) -> np.ndarray:
    """Powell singular (MGH 13), m = n = 4; singular Jacobian at the minimum."""
    return np.array(
        [
            x[0] + 10.0 * x[1],
            np.sqrt(5.0) * (x[2] - x[3]),
            (x[1] - 2.0 * x[2]) ** 2,
            np.sqrt(10.0) * (x[0] - x[3]) ** 2,
        ]
    )


def brown_badly_scaled(x: np.ndarray) -> np.ndarray:
    """Brown badly scaled (MGH 4), m = 3, n = 2."""
    return np.array([x[0] - 1e6, x[1] - 2e-6, x[0] * x[1] - 2.0])


def meyer(x: np.ndarray) -> np.ndarray:
    """Meyer (MGH 10), m = 16, n = 3."""
    return x[0] * np.exp(x[1] / (_MEYER_T + x[2])) - _MEYER_Y


def box_3d(x: np.ndarray) -> np.ndarray:
    """Box three-dimensional (MGH 12), m = 10, n = 3."""
    return (
        np.exp(-_BOX_T * x[0])
        - np.exp(-_BOX_T * x[1])
        - x[2] * (np.exp(-_BOX_T) - np.exp(-10.0 * _BOX_T))
    )


def helical_valley(x: np.ndarray) -> np.ndarray:
    """Helical valley (MGH 7), m = n = 3."""
    theta = np.arctan2(x[1], x[0]) / (2.0 * np.pi)
    if theta < -0.25:
        theta += 1.0
    return np.array([10.0 * (x[2] - 10.0 * theta), 10.0 * (np.hypot(x[0], x[1]) - 1.0), x[2]])


PROBLEMS: dict[str, TestProblem] = {
    "rosenbrock": TestProblem(rosenbrock, (-1.2, 1.0), 0.0, (1.0, 1.0)),
    "freudenstein_roth_local": TestProblem(
        freudenstein_roth, (0.5, -2.0), 48.9842, (11.4128, -0.896805)
    ),
    "powell_singular": TestProblem(
        powell_singular, (3.0, -1.0, 0.0, 1.0), 0.0, (0.0, 0.0, 0.0, 0.0)
    ),
    "brown_badly_scaled": TestProblem(brown_badly_scaled, (1.0, 1.0), 0.0, (1e6, 2e-6)),
    "meyer": TestProblem(meyer, (0.02, 4000.0, 250.0), 87.9458, (0.0056096, 6181.35, 345.224)),
    "box_3d": TestProblem(box_3d, (0.0, 10.0, 20.0), 0.0, (1.0, 10.0, 1.0)),
    "helical_valley": TestProblem(helical_valley, (-1.0, 0.0, 0.0), 0.0, (1.0, 0.0, 0.0)),
}
"""Problem name -> problem. Freudenstein-Roth from its standard start reaches the local
minimum 48.9842 (the global one is 0 at (5, 4))."""
