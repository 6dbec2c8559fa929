"""Lumped viscoelastic tissue models and their fits.

Standard linear solid (Kelvin), Prony series and quasi-linear viscoelasticity (Ahn & Kim,
Kim et al.), Wiechert bodies, linear and with exponential springs (Takacs et al.), the Blatz
exponential model and the nonlinear parallel-spring model of Kim et al. Forces come from sampled
displacement histories in SI units (``time_s``, ``displacement_m`` -> ``force_N``).
"""

from warptissue.viscoelastic.fitting import (
    RELAXATION_MODELS,
    RelaxationRecord,
    fit_qlv,
    fit_relaxation,
    fit_relaxation_joint,
    fit_wiechert_joint,
    model_from_result,
)
from warptissue.viscoelastic.linear import (
    NotARelaxationWarning,
    PronySeries,
    QuasiLinearViscoelastic,
    StandardLinearSolid,
    exponential_elastic_force,
    exponential_spring_force,
)
from warptissue.viscoelastic.springs import ParallelNonlinearSprings, blatz_pressure_Pa, fit_blatz
from warptissue.viscoelastic.wiechert import (
    LinearWiechert,
    NonlinearWiechert,
    SurfaceProfile,
    line_indenter_force_N,
    quadratic_profile,
)

__all__ = [
    "ParallelNonlinearSprings",
    "blatz_pressure_Pa",
    "fit_blatz",
    "RELAXATION_MODELS",
    "RelaxationRecord",
    "fit_qlv",
    "fit_relaxation",
    "fit_relaxation_joint",
    "fit_wiechert_joint",
    "model_from_result",
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
    "exponential_spring_force",
]
