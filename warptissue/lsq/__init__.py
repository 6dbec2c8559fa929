"""The least-squares engine under every fit of warptissue.

``least_squares`` minimizes a residual function with Levenberg-Marquardt (``method="lm"``)
or Tong et al.'s self-adapting LM (``method="salm"``), with bounds, refusals of trial points
(:class:`RejectStep`), finite-difference or caller-supplied Jacobians, and parameter
statistics. ``fit_curve`` fits model predictions to data with an absolute or relative
objective. See :mod:`warptissue.lsq.engine` for the algorithms and the papers' misprints.
Every :class:`FitResult` reports whether its parameters are identified
(:attr:`FitResult.identifiability`).

Submodules: :mod:`~warptissue.lsq.engine` (the two methods), :mod:`~warptissue.lsq.result`
(:class:`FitResult`), :mod:`~warptissue.lsq.metrics` (R², RMSE),
:mod:`~warptissue.lsq.plausibility` (sign, magnitude and unit checks of indentation data and
results). The fits themselves (:mod:`warptissue.fit`, :mod:`warptissue.viscoelastic`,
:mod:`warptissue.field`) sit above this package and import it; it imports none of them.
"""

from warptissue.lsq import metrics
from warptissue.lsq.engine import fit_curve, least_squares
from warptissue.lsq.result import STATUS_MESSAGES, FitResult, IterationRecord, RejectStep

__all__ = [
    "STATUS_MESSAGES",
    "FitResult",
    "IterationRecord",
    "RejectStep",
    "fit_curve",
    "least_squares",
    "metrics",
]
