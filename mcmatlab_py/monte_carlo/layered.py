"""MCML-style views of a run on layered media (MCmatlab's ``plotAzFz`` and
``plotRadialReflectanceTransmittance``, example 24).

* :func:`absorption_vs_depth`: A(z), the absorbed power per unit depth (cm^-1), and
  F(z), the fluence rate summed over x and y (-): MCmatlab's ``plotAzFz``.
* :func:`radial_reflectance_transmittance`: R(r) and T(r) (cm^-2) averaged over the face
  pixels at each distance from the z axis, from the ``NI_zneg`` and ``NI_zpos`` maps, as
  MCmatlab's plot. MCML's own binning (``MC.n_radial_bins``: ``Rd_r``, ``Tt_r``,
  ``Rd_a``, ``Tt_a``, exact annuli about the source and unfolded across cyclic sides) is
  computed in the kernel instead.
"""

from __future__ import annotations

import numpy as np

__all__ = ["absorption_vs_depth", "radial_reflectance_transmittance"]


def absorption_vs_depth(model) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(z (nz,) cm, A(z) (nz,) cm^-1, F(z) (nz,) -): sums over x, y of NA and NFR times dx dy."""
    G, MC = model.G, model.MC
    if MC.NA is None:
        raise ValueError("absorption_vs_depth: run the Monte Carlo first (model.MC.NA is None)")
    dA = G.dx * G.dy
    return G.z, MC.NA.sum(axis=(0, 1)) * dA, MC.NFR.sum(axis=(0, 1)) * dA


def radial_reflectance_transmittance(model) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(r (k,) cm, R (k,) cm^-2, T (k,) cm^-2): NI_zneg and NI_zpos averaged over the pixels
    at each distinct distance r of a pixel centre from the z axis (needs
    ``MC.calc_normalized_irradiance``)."""
    G, MC = model.G, model.MC
    if MC.NI_zneg is None:
        raise ValueError("radial_reflectance_transmittance needs MC.calc_normalized_irradiance "
                         "= True in the run")
    X, Y = np.meshgrid(G.x, G.y, indexing="ij")
    r = np.round(np.hypot(X, Y), 12).ravel()  # equal distances compare equal
    radii, inverse = np.unique(r, return_inverse=True)
    count = np.bincount(inverse)
    R = np.bincount(inverse, MC.NI_zneg.ravel()) / count
    T = np.bincount(inverse, MC.NI_zpos.ravel()) / count
    return radii, R, T
