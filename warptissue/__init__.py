"""warptissue: soft-tissue characterization for surgical simulation.

Fits constitutive models to indentation records (analytically, with lumped viscoelastic
models, and by inverse finite elements whose tetrahedral hyperelastic FE runs as NVIDIA Warp
kernels), drives the indentation rig, and writes USD for simulators.
"""

from warptissue.errors import (
    ConvergenceError,
    DeviceError,
    InputError,
    MeshError,
    WarpTissueError,
)

__version__ = "0.1.0"

__all__ = [
    "ConvergenceError",
    "DeviceError",
    "InputError",
    "MeshError",
    "WarpTissueError",
    "__version__",
]
