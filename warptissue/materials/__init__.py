"""Constitutive models: one class per model for the FE, the homogeneous tests and the fits.

Each model is a small frozen dataclass in SI units with Abaqus conventions (C10, C01, Ci0,
mu_i, alpha_i, D1 = 2/K), in the manner of FElupe's ``ConstitutiveMaterial``: the same object

- runs in the FE: ``material.device_params()`` packs it into the
  ``warptissue.kernels.materials.MaterialParams`` struct that the FE kernels read, and
  :func:`evaluate_material` evaluates energy, stress and tangent for a batch of deformation
  gradients on any Warp device;
- gives the incompressible closed forms of the homogeneous tests of a materials lab (the four
  :class:`HyperelasticMaterial` models): nominal stress in uniaxial, equibiaxial and planar
  tension or compression, its gradient with respect to the parameters, the energy, and the
  log-strain Hessian of the Drucker stability check;
- is fitted: ``parameter_names`` (units in the names), ``parameter_units``,
  ``parameter_vector`` / ``with_parameters`` (vector <-> model), ``parameter_bounds`` and, for
  the hyperelastic models, ``start_parameters`` (least-squares start values). The fitting and
  the test records are in :mod:`warptissue.fit.hyperelastic`;
- is serialized: ``to_dict()`` / :func:`material_from_dict` with flat keys (``C10_Pa``,
  ``mu1_Pa``, ``alpha1``, ``bulk_modulus_Pa``, ...), as study files and USD layers store them.

A body of several materials, one per group of its mesh's tet regions (an organ with a tumour),
is a :class:`MaterialRegions`: the FE gives each tet its region's material, and a fit frees
each region's parameters under their qualified names (``tumour.C10_Pa``).

The four Abaqus hyperelastic models (:class:`NeoHookean`, :class:`MooneyRivlin`,
:class:`ReducedPolynomial` with :func:`Yeoh`, :class:`Ogden`) take an optional bulk modulus:
without one (``bulk_modulus_Pa=None``, D1 = 0 as in Abaqus) the model is incompressible, which
is what the homogeneous closed forms and their fits use; the FE needs a bulk modulus
(``with_bulk_modulus``). The volumetric term is not a fit parameter of these models: their
``parameter_names`` are the isochoric parameters only, and ``with_parameters`` keeps the bulk
modulus. A model with a bulk modulus must have a positive initial shear modulus (the FE
tangent at rest is indefinite otherwise); an incompressible one may have any, as the trial
points of a fit do (the Drucker check in :mod:`warptissue.fit.hyperelastic` reports it).

Notes:
    Energies (the needle-indentation study, Eq. 2; Abaqus Theory Manual 4.6.1), with
    isochoric invariants ``I1b = J^(-2/3) tr C``, ``I2b = J^(-4/3) (tr^2 C - tr C^2) / 2`` and
    ``U(J) = (J - 1)^2 / D1``:

    - ``NeoHookean``: ``W = C10 (I1b - 3) + U``, ``mu0 = 2 C10``.
    - ``MooneyRivlin``: ``W = C10 (I1b - 3) + C01 (I2b - 3) + U``, ``mu0 = 2 (C10 + C01)``.
    - ``ReducedPolynomial``: ``W = sum_i Ci0 (I1b - 3)^i + U``, ``mu0 = 2 C10``; Yeoh is N = 3.
      The study prints higher-order volumetric terms ``K_i/2 (J - 1)^(2i)``; only ``D1`` is
      used here, as for nearly incompressible fits in Abaqus.
    - ``Ogden``: ``W = sum_i 2 mu_i / alpha_i^2 (l1b^alpha_i + l2b^alpha_i + l3b^alpha_i - 3)
      + U``, ``mu0 = sum_i mu_i``.
    - ``CompressibleNeoHookean``: ``W = mu/2 (I1 - 3) - mu ln J + lambda/2 (ln J)^2`` with
      ``lambda = K - 2 mu / 3``.
    - ``LinearElastic``: small strain, ``W = mu eps:eps + lambda/2 (tr eps)^2``.
    - ``StableNeoHookean``: ``W = mu/2 (I1 - 3) + (lambda + mu)/2 (J - alpha)^2``,
      ``alpha = 1 + mu / (lambda + mu)``: NVIDIA Newton's VBD tet energy (Smith et al. 2018),
      parametrized by E and nu as a simulator reads them.

    Homogeneous tests (incompressible, principal stretches l1, l2, l3 with l1 l2 l3 = 1):
    uniaxial (l, l^-1/2, l^-1/2), equibiaxial (l, l, l^-2), planar (l, 1, l^-1). Invariant
    models W(I1, I2), with W1 = dW/dI1 and W2 = dW/dI2, give the nominal stress (force per
    reference area) along the loading direction (free lateral faces)::

        uniaxial     S = 2 (l - l^-2) (W1 + W2 / l) = 2 (1 - l^-3) (l W1 + W2)
        equibiaxial  S = 2 (l - l^-5) (W1 + l^2 W2)
        planar       S = 2 (l - l^-3) (W1 + W2)

    The study's Eq. 3 (uniaxial) agrees for neo-Hookean, RP2 and Mooney-Rivlin. Ogden gives::

        S = sum 2 mu_i / alpha_i (l^(a_i - 1) - l^(-k a_i - 1)),  k = 1/2, 2, 1

    for uniaxial, equibiaxial and planar; k = 1/2 is the study's Eq. 3. Each formula is the
    derivative of the energy along the path: S = dW/dl / (number of loaded directions), which
    the tests check by numerical differentiation. Stresses are signed (tension positive).
"""

from warptissue.materials._base import (
    HOMOGENEOUS_MODES,
    HyperelasticMaterial,
    Material,
    principal_log_strains,
    principal_stretches,
)
from warptissue.materials._compressible import (
    CompressibleNeoHookean,
    LinearElastic,
    StableNeoHookean,
)
from warptissue.materials._evaluate import MaterialEvaluation, evaluate_material
from warptissue.materials._from_dict import material_from_dict
from warptissue.materials._ogden import Ogden
from warptissue.materials._polynomial import MooneyRivlin, NeoHookean, ReducedPolynomial, Yeoh
from warptissue.materials._regions import MaterialRegions
from warptissue.materials._rules import positive_bounds, prony_term
from warptissue.materials._viscoelastic import Viscoelastic

__all__ = [
    "HOMOGENEOUS_MODES",
    "CompressibleNeoHookean",
    "HyperelasticMaterial",
    "LinearElastic",
    "StableNeoHookean",
    "Material",
    "MaterialEvaluation",
    "MaterialRegions",
    "MooneyRivlin",
    "NeoHookean",
    "Ogden",
    "ReducedPolynomial",
    "Viscoelastic",
    "Yeoh",
    "evaluate_material",
    "material_from_dict",
    "positive_bounds",
    "principal_log_strains",
    "principal_stretches",
    "prony_term",
]
