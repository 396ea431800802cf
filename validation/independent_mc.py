"""A minimal Monte Carlo of a semi-infinite medium, written apart from ``mcmatlab_py``.

It shares no code with the package: its own random numbers (a numpy Generator
inside numba), its own stepping (no voxels, no fixed-point weights), isotropic scattering
and an index-matched top surface only. It exists to tell the package's Monte Carlo from
the approximations of diffusion theory where the two disagree (Rd(r) at n = 1, see
``mc_outputs.py``). Pencil beam at the origin, straight down; survival weighting
(weight times albedo at each interaction) and Russian roulette below 1e-4 (1 in 10).
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["semi_infinite_rd"]


@numba.njit(cache=True)
def _run(n_photons, mua, mus, nr, dr, rng):
    mut = mua + mus
    albedo = mus / mut
    tally = np.zeros(nr + 1)  # the last bin holds all beyond
    for _ in range(n_photons):
        x = 0.0
        y = 0.0
        z = 0.0
        ux = 0.0
        uy = 0.0
        uz = 1.0
        w = 1.0
        while True:
            s = -math.log(1.0 - rng.random()) / mut
            if uz < 0.0 and z + s * uz <= 0.0:  # leaves through the surface z = 0
                t = -z / uz
                r = math.hypot(x + t * ux, y + t * uy)
                tally[min(int(r / dr), nr)] += w
                break
            x += s * ux
            y += s * uy
            z += s * uz
            w *= albedo
            if w < 1e-4:
                if rng.random() < 0.1:
                    w *= 10.0
                else:
                    break
            uz = 2.0 * rng.random() - 1.0
            phi = 2.0 * math.pi * rng.random()
            st = math.sqrt(max(0.0, 1.0 - uz * uz))
            ux = st * math.cos(phi)
            uy = st * math.sin(phi)
    return tally


def semi_infinite_rd(n_photons: int, mua: float, mus: float, nr: int, dr: float,
                     seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Rd(r) (1/cm^2) of an isotropically scattering half-space, n = 1, and bin centres (cm)."""
    tally = _run(int(n_photons), float(mua), float(mus), int(nr), float(dr),
                  np.random.default_rng(seed))
    r = (np.arange(nr) + 0.5) * dr
    return tally[:nr] / (n_photons * 2 * np.pi * r * dr), r
