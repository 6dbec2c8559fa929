"""Homogeneous hyperelastic tests: records, fits and Drucker stability.

The incompressible, isotropic hyperelastic models of :mod:`warptissue.materials` (Abaqus
conventions; their closed forms are documented there) under the homogeneous tests of a
materials lab: uniaxial tension and compression, equibiaxial tension and planar tension (pure
shear). Measured force and displacement become nominal stress and strain
(:class:`HomogeneousTest`); the models are fitted with :func:`warptissue.lsq.fit_curve` with
an absolute (the needle-indentation study, Eq. 4) or relative (Eq. 5) objective
(:func:`fit_hyperelastic`); and every fitted model gets a Drucker stability check over the six
standard modes (:func:`drucker_stability`), as Abaqus's material evaluation reports it.

Sign convention: a :class:`HomogeneousTest` holds MAGNITUDES, positive in the loading
direction: ``nominal_strain = d / H0`` and ``nominal_stress_Pa = F / A0`` are both positive
for a specimen compressed by d under a compressive force F. The mechanics underneath is
signed (tension positive): the stretch is 1 - strain in compression and 1 + strain otherwise,
and the model's signed nominal stress is compared with the measured magnitude times the
loading's sign.

Notes:
    Drucker stability (Abaqus Theory Manual, hyperelastic stability): an incompressible
    material is stable when d tau : d eps > 0 for every logarithmic strain increment with
    trace zero (tau = Kirchhoff stress = Cauchy stress at J = 1). With the principal log
    strains (e1, e2, -e1 - e2) and W~(e1, e2) = W(exp e1, exp e2, exp(-e1 - e2)), one has
    tau_i - tau_3 = dW~/de_i, so d tau : d eps = de^T H de with H the 2 x 2 Hessian of W~:
    stable iff H is positive definite, checked at each state of the six modes (uniaxial,
    equibiaxial, planar; tension and compression). Along a uniaxial path the criterion
    contains the familiar one, d(true stress)/d(log strain) > 0 (H in the path direction
    (1, -1/2)), but it is stronger: it also checks the lateral directions. Non-finite values
    (overflow of l^alpha) count as unstable.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from warptissue.errors import InputError
from warptissue.fit._drucker import (  # noqa: F401
    STABILITY_MODES,
    StabilityReport,
    StableRange,
    drucker_stability,
)
from warptissue.fit._homogeneous import (  # noqa: F401
    LOADINGS,
    MAX_NOMINAL_STRAIN,
    STRAIN_COLUMNS,
    STRESS_COLUMNS,
    HomogeneousTest,
    read_homogeneous_test,
)
from warptissue.lsq.engine import fit_curve
from warptissue.lsq.metrics import DURBIN_WATSON_LIMIT, durbin_watson, r_squared, rmse
from warptissue.lsq.plausibility import SOFT_TISSUE_MODULUS_RANGE_PA, fit_quality_warnings
from warptissue.lsq.result import FitResult, RejectStep
from warptissue.materials import (
    HyperelasticMaterial,
    MooneyRivlin,
    NeoHookean,
    Ogden,
    ReducedPolynomial,
    Yeoh,
)

__all__ = [
    "LOADINGS",
    "MAX_NOMINAL_STRAIN",
    "MODEL_NAMES",
    "PREDICTION_LIMIT",
    "STABILITY_MODES",
    "STRAIN_COLUMNS",
    "STRESS_COLUMNS",
    "HomogeneousTest",
    "HyperelasticFit",
    "StabilityReport",
    "StableRange",
    "drucker_stability",
    "fit_hyperelastic",
    "model_from_name",
    "model_label",
    "read_homogeneous_test",
]


MODEL_NAMES: tuple[str, ...] = (
    "neo_hookean",
    "mooney_rivlin",
    "reduced_polynomial",
    "yeoh",
    "ogden",
)
"""Names accepted by :func:`model_from_name` (``reduced_polynomial:N``, ``ogden:N``)."""


def model_from_name(spec: str) -> HyperelasticMaterial:
    """An incompressible model with placeholder parameters from a name such as
    ``reduced_polynomial:2``.

    Accepted: ``neo_hookean``, ``mooney_rivlin``, ``reduced_polynomial:N`` (default N = 2),
    ``yeoh``, ``ogden:N`` (default N = 1).

    Raises:
        InputError: An unknown name or a bad order.
    """
    kind, _, order_text = spec.strip().lower().partition(":")
    if kind not in MODEL_NAMES:
        raise InputError(f"unknown model; choose from {', '.join(MODEL_NAMES)}", value=spec)
    if order_text and kind not in ("reduced_polynomial", "ogden"):
        raise InputError(f"model {kind!r} takes no order", value=spec)
    default_order = {"reduced_polynomial": 2, "ogden": 1}.get(kind, 1)
    try:
        order = int(order_text) if order_text else default_order
    except ValueError:
        raise InputError("the model order must be an integer", value=spec) from None
    if not 1 <= order <= 6:
        raise InputError("the model order must be between 1 and 6", value=spec)
    if kind == "neo_hookean":
        return NeoHookean(1.0)
    if kind == "mooney_rivlin":
        return MooneyRivlin(1.0, 1.0)
    if kind == "reduced_polynomial":
        return ReducedPolynomial((1.0,) * order)
    if kind == "yeoh":
        return Yeoh(1.0, 1.0, 1.0)
    return Ogden((1.0,) * order, tuple(2.0 * (i + 1) for i in range(order)))


def model_label(model: HyperelasticMaterial) -> str:
    """Short label: ``neo_hookean``, ``reduced_polynomial:2``, ``ogden:3``, ..."""
    if isinstance(model, ReducedPolynomial | Ogden):
        return f"{model.model_name}:{model.order}"
    return model.model_name


@dataclass
class HyperelasticFit:
    """A fitted homogeneous hyperelastic model.

    Attributes:
        model: The model with the fitted parameters.
        result: The engine's result (parameters, statistics, R² over the fitted window).
        tests: The tests that were fitted, full records (not windowed).
        objective: "absolute" or "relative".
        min_strain: Lower end of the strain window.
        stability: The Drucker check of the fitted model.
    """

    model: HyperelasticMaterial
    result: FitResult
    tests: tuple[HomogeneousTest, ...]
    objective: str
    min_strain: float
    stability: StabilityReport

    @property
    def label(self) -> str:
        """Model label, e.g. ``reduced_polynomial:2``."""
        return model_label(self.model)

    def to_dict(self) -> dict[str, Any]:
        """JSON-compatible: the model, the fit, the window and the stability check."""
        return {
            "model": self.model.to_dict(),
            "initial_shear_modulus_Pa": self.model.initial_shear_modulus_Pa,
            "objective": self.objective,
            "min_strain": self.min_strain,
            "loadings": [t.loading for t in self.tests],
            "fit": self.result.to_dict(),
            "stability": self.stability.to_dict(),
        }

    def test_errors(self) -> list[dict[str, Any]]:
        """Each test's fit over the strain window.

        Returns:
            Per test: ``test`` (its name), ``loading``, ``points``, ``r_squared`` and
            ``rmse_Pa`` of the nominal stress.
        """
        rows = []
        for test in self.tests:
            window = test.window(self.min_strain)
            predicted = window.predicted_stress_Pa(self.model)
            rows.append(
                {
                    "test": window.name,
                    "loading": window.loading,
                    "points": int(window.nominal_strain.size),
                    "r_squared": r_squared(window.nominal_stress_Pa, predicted),
                    "rmse_Pa": rmse(window.nominal_stress_Pa, predicted),
                }
            )
        return rows

    def mode_predictions(self, *, points: int = 6) -> list[dict[str, Any]]:
        """The fitted model's nominal stress in every loading over the fitted stretch range:
        a loading tested up to its tests' largest stretch (smallest in compression), one not
        tested (tension, equibiaxial, planar) up to the largest stretch of all the tests in
        tension (1 / the smallest in compression when none is). Compression is listed only
        where it was tested.

        Args:
            points: Stretches per loading, evenly spaced after 1.

        Returns:
            Per loading: ``loading``, ``tested`` (a test of it was fitted), ``stretch`` and
            ``nominal_stress_Pa`` (lists), and ``unstable_from_strain`` (the Drucker check of
            that mode; None when stable over the checked range).
        """
        tensile = [float(np.max(t.stretch)) for t in self.tests if t.sign > 0]
        compressive = [float(np.min(t.stretch)) for t in self.tests if t.sign < 0]
        highest = max(tensile) if tensile else 1.0 / min(compressive)
        tested = {t.loading for t in self.tests}
        rows = []
        for loading, (mode, sign) in LOADINGS.items():
            if sign < 0 and not compressive:
                continue
            own = [
                float(np.max(np.abs(t.stretch - 1.0))) for t in self.tests if t.loading == loading
            ]
            end = 1.0 + sign * max(own) if own else highest
            stretch = np.linspace(1.0, end, points + 1)[1:]
            with np.errstate(over="ignore", invalid="ignore"):
                stress = sign * self.model.nominal_stress_Pa(stretch, mode)
            check = self.stability[f"{mode}_{'tension' if sign > 0 else 'compression'}"]
            rows.append(
                {
                    "loading": loading,
                    "tested": loading in tested,
                    "stretch": stretch.tolist(),
                    "nominal_stress_Pa": stress.tolist(),
                    "unstable_from_strain": check.unstable_from_strain,
                }
            )
        return rows

    def comparison_row(self) -> dict[str, Any]:
        """One row of a model-comparison table (the needle-indentation study, Table 1, plus the
        stable range)."""
        mode_names = {f"{t.mode}_{'compression' if t.sign < 0 else 'tension'}" for t in self.tests}
        tested = [self.stability[m].unstable_from_strain for m in sorted(mode_names)]
        unstable = [value for value in tested if value is not None]
        return {
            "model": self.label,
            "objective": self.objective,
            "r_squared": self.result.r_squared,
            "rmse_Pa": self.result.rmse,
            "status": self.result.status,
            "unstable_from_strain_tested_modes": min(unstable) if unstable else None,
            "stable_up_to_strain_all_modes": self.stability.stable_up_to_strain,
        }


def fit_hyperelastic(
    model: str | HyperelasticMaterial,
    tests: HomogeneousTest | Sequence[HomogeneousTest],
    *,
    objective: str = "absolute",
    min_strain: float | None = None,
    method: str = "lm",
    bounds: tuple[Any, Any] | None = None,
    progress: bool = False,
) -> HyperelasticFit:
    """Fit an incompressible hyperelastic model to one or several homogeneous tests.

    Starting values: given a model instance, its parameters; given a name, the linear
    least-squares solution for the invariant models (they are linear in their
    parameters), and for Ogden the best of a grid of alphas with mu solved linearly. The
    engine then runs with analytic Jacobians.

    Args:
        model: A name (see :func:`model_from_name`) or a :mod:`warptissue.materials`
            hyperelastic model (its parameters are the starting point; its bulk modulus, if
            any, is dropped: the closed forms are incompressible).
        tests: One test or several (a joint fit; residuals are concatenated).
        objective: "absolute" (the needle-indentation study, Eq. 4) or "relative" (Eq. 5).
        min_strain: Fit only points with nominal strain above this; default 0.05 for the
            relative objective (as the needle-indentation study) and 0 (all points) for the
            absolute one.
        method: "lm" or "salm".
        bounds: (lower, upper) parameter bounds in the order of the model's parameter
            vector, scalars or arrays; default the model's ``parameter_bounds`` (none for
            these models).
        progress: Show the engine's progress bar.

    Returns:
        The :class:`HyperelasticFit` with its Drucker stability check.

    Raises:
        InputError: Bad model name, objective or data (e.g. zero stress in the window of a
            relative fit).

    ``result.warnings`` gets a message when the fitted model is Drucker-unstable inside the
    strain range of a test, when its small-strain Young's modulus 3 mu0 is implausible for soft
    tissue, or when R^2 < 0.
    """
    template = model_from_name(model) if isinstance(model, str) else model
    if not isinstance(template, HyperelasticMaterial):
        raise InputError(
            "model must be a name or a warptissue.materials hyperelastic model", value=model
        )
    template = template.with_bulk_modulus(None)
    if bounds is None:
        bounds = template.parameter_bounds
    test_list = (tests,) if isinstance(tests, HomogeneousTest) else tuple(tests)
    if not test_list:
        raise InputError("at least one test is needed")
    if objective not in ("absolute", "relative"):
        raise InputError("objective must be 'absolute' or 'relative'", value=objective)
    window = (0.05 if objective == "relative" else 0.0) if min_strain is None else min_strain
    if not (math.isfinite(window) and window >= 0.0):
        raise InputError("min_strain must be >= 0", value=float(window))
    fitted_tests = [t.window(window) for t in test_list]
    data = np.concatenate([t.nominal_stress_Pa for t in fitted_tests])
    divisors = data.copy() if objective == "relative" else np.ones_like(data)
    if not np.any(data):
        raise InputError("the stress is zero throughout the strain window: nothing to fit")
    if objective == "relative" and np.any(data == 0.0):
        raise InputError(
            "the relative objective needs non-zero stresses in the strain window (raise "
            "min_strain above the zero-stress points, or use the absolute objective)"
        )

    def model_at(p: np.ndarray) -> HyperelasticMaterial:
        try:
            return template.with_parameters(p)
        except InputError as exc:
            raise RejectStep(str(exc)) from exc

    def predictions(p: np.ndarray) -> np.ndarray:
        candidate = model_at(p)
        with np.errstate(over="ignore", invalid="ignore"):
            return np.concatenate([t.predicted_stress_Pa(candidate) for t in fitted_tests])

    def gradient(candidate: HyperelasticMaterial) -> np.ndarray:
        return np.concatenate(
            [t.sign * candidate.nominal_stress_gradient(t.stretch, t.mode) for t in fitted_tests]
        )

    def jacobian(p: np.ndarray) -> np.ndarray:
        return gradient(model_at(p))

    if isinstance(model, str):
        start = template.start_parameters(
            lambda candidate: gradient(candidate) / divisors[:, None], data / divisors
        )
    else:
        start = template.parameter_vector
    lower = np.broadcast_to(np.asarray(bounds[0], dtype=np.float64), start.shape)
    upper = np.broadcast_to(np.asarray(bounds[1], dtype=np.float64), start.shape)
    start = np.clip(start, lower, upper)
    result = fit_curve(
        predictions,
        start,
        data,
        objective=objective,
        jac=jacobian,
        bounds=bounds,
        method=method,
        parameter_names=template.parameter_names,
        parameter_units=template.parameter_units,
        progress=progress,
        max_iterations=500,
        ftol=1e-12,
        xtol=1e-12,
        gtol=1e-10,
    )
    fitted = template.with_parameters(result.x)
    stability = drucker_stability(fitted)
    fit = HyperelasticFit(
        model=fitted,
        result=result,
        tests=test_list,
        objective=objective,
        min_strain=window,
        stability=stability,
    )
    result.warnings.extend(_fit_warnings(fit))
    return fit


def _fit_warnings(fit: HyperelasticFit) -> list[str]:
    """What :func:`fit_hyperelastic` warns of: the fit's quality, an implausible modulus,
    Drucker instability inside a test's range, systematic residuals, a test the model
    describes worse than a constant, and implausible predictions of the other modes."""
    result, test_list, fitted = fit.result, fit.tests, fit.model
    warnings = [
        *fit_quality_warnings(result),
        *_modulus_warnings(fitted),
        *_instability_warnings(fit.stability, test_list),
    ]
    largest = max(float(np.max(t.nominal_stress_Pa)) for t in test_list)
    warnings.extend(_systematic_residual_warnings(fit))
    if len(test_list) > 1:
        warnings.extend(
            f"in test {row['test']!r} ({row['loading']}) the fitted model is worse than a "
            f"constant (R^2 = {row['r_squared']:.4g}): it does not describe that loading"
            for row in fit.test_errors()
            if row["r_squared"] is not None and row["r_squared"] < 0.0
        )
    warnings.extend(_prediction_warnings(fit.mode_predictions(), largest))
    return warnings


def _systematic_residual_warnings(fit: HyperelasticFit) -> list[str]:
    """A warning per test whose residuals, in the order of its data, have a Durbin-Watson
    statistic below :data:`~warptissue.lsq.metrics.DURBIN_WATSON_LIMIT` (the inverse FE's
    rule): the model misses the curve's shape (an upturn it cannot follow, say)."""
    messages = []
    advice = (
        "try more terms or another model"
        if isinstance(fit.model, Ogden)
        else "try a model that can (Yeoh, Ogden)"
    )
    for test, row in zip(fit.tests, fit.test_errors(), strict=True):
        window = test.window(fit.min_strain)
        statistic = durbin_watson(window.predicted_stress_Pa(fit.model) - window.nominal_stress_Pa)
        if statistic is not None and statistic < DURBIN_WATSON_LIMIT:
            r2 = "n/a" if row["r_squared"] is None else f"{row['r_squared']:.3g}"
            messages.append(
                f"the residuals of test {test.name!r} ({test.loading}) are systematic "
                f"(Durbin-Watson statistic {statistic:.3g}, about 2 for noise; R^2 = {r2}): "
                f"the model misses the curve's shape; {advice}"
            )
    return messages


PREDICTION_LIMIT = 10.0
"""A loading not tested where the fitted model predicts more than this many times the
largest measured stress (or a negative or non-finite stress) within the fitted stretch range
gets a warning: the model is not to be used there."""


def _prediction_warnings(rows: Sequence[dict[str, Any]], largest_Pa: float) -> list[str]:
    """Warnings for the loadings not tested where the prediction of
    :meth:`HyperelasticFit.mode_predictions` is absurd or Drucker-unstable."""
    messages = []
    for row in rows:
        if row["tested"]:
            continue
        stretch = np.asarray(row["stretch"])
        stress = np.asarray(row["nominal_stress_Pa"])
        bad = ~np.isfinite(stress) | (stress < 0.0) | (stress > PREDICTION_LIMIT * largest_Pa)
        if np.any(bad):
            k = int(np.flatnonzero(bad)[0])
            messages.append(
                f"in {row['loading']} (not tested) the fitted model predicts a nominal stress of "
                f"{float(stress[k]):.4g} Pa at stretch {float(stretch[k]):.3g}, against at most "
                f"{largest_Pa:.4g} Pa measured in the tests: do not use it there"
            )
            continue
        limit = row["unstable_from_strain"]
        strain = float(np.max(np.abs(stretch - 1.0)))
        if limit is not None and limit < strain:
            messages.append(
                f"in {row['loading']} (not tested) the fitted model is not Drucker-stable "
                f"beyond nominal strain {limit:.3g}, inside the fitted stretch range (up to "
                f"strain {strain:.3g}): do not use it there"
            )
    return messages


def _modulus_warnings(model: HyperelasticMaterial) -> list[str]:
    """A message when the small-strain Young's modulus 3 mu0 of the fitted model lies outside
    :data:`~warptissue.lsq.plausibility.SOFT_TISSUE_MODULUS_RANGE_PA` (units of the data or
    of the specimen geometry off?)."""
    youngs_Pa = 3.0 * model.initial_shear_modulus_Pa
    low, high = SOFT_TISSUE_MODULUS_RANGE_PA
    if low <= youngs_Pa <= high:
        return []
    negative = [
        f"{name} = {value:.4g} {unit}"
        for name, value, unit in zip(
            model.parameter_names, model.parameter_vector, model.parameter_units, strict=True
        )
        if unit == "Pa" and value < 0.0
    ]
    if negative:
        return [
            f"the fitted small-strain Young's modulus 3 mu0 = {youngs_Pa:.4g} Pa is outside the "
            f"plausible range of soft tissue [{low:.4g}, {high:.4g}] Pa because "
            f"{', '.join(negative)} is negative: the fit traded it against the other "
            "parameters for the curve's shape (not a unit error); choose another model or "
            "bound that parameter at 0"
        ]
    return [
        f"the fitted small-strain Young's modulus 3 mu0 = {youngs_Pa:.4g} Pa is outside the "
        f"plausible range of soft tissue [{low:.4g}, {high:.4g}] Pa: check the units of the "
        "force and displacement and the specimen's area and height"
    ]


def _instability_warnings(
    stability: StabilityReport, tests: Sequence[HomogeneousTest]
) -> list[str]:
    """A message per tested mode where the fitted model is Drucker-unstable inside the range
    of nominal strain that the test covers."""
    messages = []
    for test in tests:
        mode = f"{test.mode}_{'compression' if test.sign < 0 else 'tension'}"
        limit = stability[mode].unstable_from_strain
        largest = float(np.max(test.nominal_strain))
        if limit is not None and limit < largest:
            messages.append(
                f"the fitted model is not Drucker-stable in {mode.replace('_', ' ')} beyond "
                f"nominal strain {limit:.3g}, inside the tested range (up to {largest:.3g}): "
                "do not use it there"
            )
    return list(dict.fromkeys(messages))
