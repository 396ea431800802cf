"""A plain voxel Monte Carlo kernel: the yardstick that ``bench_mc.py`` measures ours against.

The textbook loop of MCML (Wang, Jacques & Zheng 1995) as simple voxel codes write it
(mcxyz, many numba tutorials): one thread, floating-point weights, a free path drawn
from the attenuation of the voxel the packet is in, the whole step taken at once (no
stop at voxel faces: exact for one medium), the voxel index recomputed from the position
after each step, the weight ``w mua / mut`` absorbed there, Henyey-Greenstein scattering,
Russian roulette; a packet leaving the cuboid escapes. It tallies only the absorption
(no escape totals, no energy balance, no reproducibility across threads): the least a
useful kernel does. Do not use it for results; it is a speed reference.
"""

# ruff: noqa: NPY002 -- numba's global legacy generator is what plain kernels use
import math

import numba
import numpy as np


@numba.njit(cache=True)
def plain_run(M, mua, mus, g, nx, ny, nz, d, radius, n_photons, seed):
    """Absorbed weight per voxel (nx, ny, nz) of ``n_photons`` from a top-hat beam of
    ``radius`` (cm) at the centre of the top face; cubic voxels of side ``d`` (cm)."""
    np.random.seed(seed)
    A = np.zeros((nx, ny, nz))
    Lx, Ly, Lz = nx * d, ny * d, nz * d
    for _ in range(n_photons):
        r = radius * math.sqrt(np.random.random())
        phi = 2.0 * math.pi * np.random.random()
        x, y, z = 0.5 * Lx + r * math.cos(phi), 0.5 * Ly + r * math.sin(phi), 0.0
        ux, uy, uz = 0.0, 0.0, 1.0
        w = 1.0
        ix, iy, iz = int(x / d), int(y / d), 0
        while True:
            m = M[ix, iy, iz]
            mut = mua[m] + mus[m]
            s = -math.log(1.0 - np.random.random()) / mut
            x += s * ux
            y += s * uy
            z += s * uz
            if not (0.0 <= x < Lx and 0.0 <= y < Ly and 0.0 <= z < Lz):
                break  # escaped
            ix, iy, iz = int(x / d), int(y / d), int(z / d)
            m = M[ix, iy, iz]
            dw = w * mua[m] / (mua[m] + mus[m])
            A[ix, iy, iz] += dw
            w -= dw
            # Henyey-Greenstein deflection and a uniform azimuth (MCML's spin)
            gm = g[m]
            xi = np.random.random()
            if gm == 0.0:
                ct = 2.0 * xi - 1.0
            else:
                t = (1.0 - gm * gm) / (1.0 - gm + 2.0 * gm * xi)
                ct = min(1.0, max(-1.0, (1.0 + gm * gm - t * t) / (2.0 * gm)))
            st = math.sqrt(1.0 - ct * ct)
            psi = 2.0 * math.pi * np.random.random()
            cp, sp = math.cos(psi), math.sin(psi)
            if abs(uz) > 0.99999:
                ux, uy, uz = st * cp, st * sp, ct * (1.0 if uz > 0.0 else -1.0)
            else:
                tmp = math.sqrt(1.0 - uz * uz)
                ux, uy, uz = (st * (ux * uz * cp - uy * sp) / tmp + ux * ct,
                              st * (uy * uz * cp + ux * sp) / tmp + uy * ct,
                              -st * cp * tmp + uz * ct)
            if w < 0.01:  # Russian roulette, survival chance 0.1
                if np.random.random() < 0.1:
                    w /= 0.1
                else:
                    break
    return A
