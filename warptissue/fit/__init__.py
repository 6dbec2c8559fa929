"""The fits of warptissue: homogeneous hyperelastic tests, punch moduli, inverse FE.

The least-squares engine they all use lives one floor below, in :mod:`warptissue.lsq`
(``least_squares``, ``fit_curve``, ``FitResult``, ``RejectStep``, the metrics and the
plausibility checks), so that the lumped viscoelastic fits and the field estimator use it
without importing the fits.

Submodules: :mod:`~warptissue.fit.punch` (Sneddon, Hertz and Hayes et al. contact formulas and
the punch-modulus fit), :mod:`~warptissue.fit.hyperelastic` (homogeneous hyperelastic tests),
:mod:`~warptissue.fit.indentation` (inverse FE: :func:`fit_indentation` of a study's material
parameters to its indentation records, with the FE's exact sensitivities; of several
studies together, their forward runs batched on one device).
"""

from warptissue._deprecated import moved_names
from warptissue.fit.indentation import (
    IndentationFit,
    IndentationFitProgress,
    RecordCurve,
    fit_indentation,
)

__all__ = [
    "IndentationFit",
    "IndentationFitProgress",
    "RecordCurve",
    "fit_indentation",
]

# The old paths of names that moved, with a DeprecationWarning naming the new one
# (warptissue._deprecated.MOVED).
__getattr__ = moved_names(__name__)
