"""Warp device code of warptissue, installed as ``warptissue.kernels``.

Only ``@wp.kernel``, ``@wp.func`` and ``@wp.struct`` live here: no launches, no NumPy, no
I/O. Host wrappers in ``warptissue`` validate inputs and launch these kernels.
"""
