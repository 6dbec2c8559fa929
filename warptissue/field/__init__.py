"""Heterogeneous linear elastic field estimation (Tong et al.)."""

from warptissue.field.fe import (
    ElementBasis,
    LinearSolution,
    LinearTetModel,
    alpha_from_youngs,
    youngs_from_alpha,
)

__all__ = [
    "ElementBasis",
    "LinearSolution",
    "LinearTetModel",
    "alpha_from_youngs",
    "youngs_from_alpha",
]
