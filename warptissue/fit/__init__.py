"""Least-squares fitting for every model of warptissue.

``least_squares`` minimizes a residual function with Levenberg-Marquardt (``method="lm"``)
or Tong et al.'s self-adapting LM (``method="salm"``), with bounds, refusals of trial points
(:class:`RejectStep`), finite-difference or caller-supplied Jacobians, and parameter
statistics. ``fit_curve`` fits model predictions to data with an absolute or relative
objective. See :mod:`warptissue.fit.engine` for the algorithms and the papers' misprints.
Every :class:`FitResult` reports whether its parameters are identified
(:attr:`FitResult.identifiability`).

Submodules: :mod:`~warptissue.fit.plausibility` (sign, magnitude and unit checks of
indentation data and results), :mod:`~warptissue.fit.punch` (Sneddon, Hertz and Hayes et al.
contact formulas and the punch-modulus fit), :mod:`~warptissue.fit.hyperelastic`
(homogeneous hyperelastic tests), :mod:`~warptissue.fit.metrics` (R², RMSE),
:mod:`~warptissue.fit.indentation` (inverse FE: :func:`fit_indentation` of a study's material
parameters to its indentation records, with the FE's exact sensitivities; of several
studies together, their forward runs batched on one device).
"""

from warptissue.fit import metrics
from warptissue.fit.engine import fit_curve, least_squares
from warptissue.fit.indentation import (
    IndentationFit,
    IndentationFitProgress,
    RecordCurve,
    fit_indentation,
)
from warptissue.fit.result import STATUS_MESSAGES, FitResult, IterationRecord, RejectStep

__all__ = [
    "STATUS_MESSAGES",
    "FitResult",
    "IndentationFit",
    "IndentationFitProgress",
    "IterationRecord",
    "RecordCurve",
    "RejectStep",
    "fit_curve",
    "fit_indentation",
    "least_squares",
    "metrics",
]
