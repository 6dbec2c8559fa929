"""Warp device code of warptissue, installed as ``warptissue.kernels``.

Only ``@wp.kernel``, ``@wp.func`` and ``@wp.struct`` live here: no launches, no NumPy, no
I/O. Host wrappers in ``warptissue`` validate inputs and launch these kernels.

The finite-element kernels of ``assembly.py``, ``viscous.py`` and ``contact.py`` (each file
mirrors the host module that launches it) are registered in one Warp module, that of
``assembly.py``, which compiles the constitutive code of ``materials.py`` once
(docs/design-notes/kernel-modules.md). Importing any file here imports all three first, so
that this Warp module holds the same kernels whatever was imported, and compiles once.
"""

from warptissue.kernels import assembly, contact, viscous

__all__ = ["assembly", "contact", "viscous"]
