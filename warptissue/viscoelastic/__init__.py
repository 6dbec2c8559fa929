"""Lumped viscoelastic tissue models and their fits.

Standard linear solid (Kelvin), Prony series and quasi-linear viscoelasticity (seeds 000 and
001), Wiechert bodies, linear and with exponential springs (seed 004), the Blatz exponential
model and the nonlinear parallel-spring model of seed 001. Forces come from sampled
displacement histories in SI units (``time_s``, ``displacement_m`` -> ``force_N``).
"""

from warptissue.viscoelastic.linear import (
    NotARelaxationWarning,
    PronySeries,
    QuasiLinearViscoelastic,
    StandardLinearSolid,
    exponential_elastic_force,
)
from warptissue.viscoelastic.wiechert import (
    LinearWiechert,
    NonlinearWiechert,
    SurfaceProfile,
    line_indenter_force_N,
    quadratic_profile,
)

__all__ = [
    "LinearWiechert",
    "NonlinearWiechert",
    "SurfaceProfile",
    "line_indenter_force_N",
    "quadratic_profile",
    "NotARelaxationWarning",
    "PronySeries",
    "QuasiLinearViscoelastic",
    "StandardLinearSolid",
    "exponential_elastic_force",
]
