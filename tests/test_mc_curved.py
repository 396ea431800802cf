"""Reflection off a curved interface with smoothed normals goes where a ray trace sends it.

A plane wave falls on a hemisphere of water (n 1.3, radius 0.04 cm) sitting on the bottom
of a cuboid of air (MCmatlab's Example 17). The light reflected at the droplet's surface
leaves the cuboid's side faces; near the rim it leaves them low, below z = 0.0217 cm. A
ray trace of the first-surface reflection off the exact hemisphere (numpy, below; it
shares nothing with the kernel) sends 0.0072 of the launched power through the sides
below that depth and 0.0022 above. A kernel that turns every reflected packet whose true
direction still points into the droplet's voxel back up along the voxel face gives
0.00007 below and 0.022 above (measured on 101 x 101 x 51 voxels).

Tolerance: each packet leaves through one face with weight about 1 (air and water absorb
almost nothing), so a fraction f from N packets has a standard error sqrt(f (1 - f) / N);
4 of them, plus 15% of the ray trace for what it leaves out (light that leaves the
droplet after entering it, the voxelised surface and its smoothed normals).
"""

from __future__ import annotations

import numpy as np
import pytest

from mcmatlab_py import Medium, Model

R, N_WATER, L, LZ, Z_SPLIT = 0.04, 1.3, 0.1, 0.05, 0.0217


def ray_trace(z_base: float, n_rays: int = 1_000_000) -> tuple[float, float]:
    """Fractions of a plane wave over the top face reflected once off the hemisphere
    (Fresnel, unpolarised) that leave through the side faces above and below Z_SPLIT."""
    rng = np.random.default_rng(0)
    x, y = rng.uniform(-L / 2, L / 2, (2, n_rays))
    hit = x * x + y * y < R * R
    x, y = x[hit], y[hit]
    zs = z_base - np.sqrt(R * R - x * x - y * y)
    nx, ny, nz = x / R, y / R, (zs - z_base) / R  # outward normal; the ray is (0, 0, 1)
    ci = -nz
    ct = np.sqrt(1 - (1 - ci**2) / N_WATER**2)
    refl = 0.5 * (((ci - N_WATER * ct) / (ci + N_WATER * ct)) ** 2
                  + ((ct - N_WATER * ci) / (ct + N_WATER * ci)) ** 2)
    rx, ry, rz = -2 * nz * nx, -2 * nz * ny, 1 - 2 * nz * nz
    with np.errstate(divide="ignore", invalid="ignore"):
        tx = np.where(rx != 0, (np.sign(rx) * L / 2 - x) / rx, np.inf)
        ty = np.where(ry != 0, (np.sign(ry) * L / 2 - y) / ry, np.inf)
        tz = np.where(rz > 0, (LZ - zs) / rz, np.where(rz < 0, -zs / rz, np.inf))
    t = np.minimum(np.minimum(tx, ty), tz)
    side = t < tz
    z_exit = zs + t * rz
    w = refl / n_rays
    return float(w[side & (z_exit <= Z_SPLIT)].sum()), float(w[side & (z_exit > Z_SPLIT)].sum())


def test_reflection_off_a_curved_interface_leaves_where_a_ray_trace_sends_it():
    model = Model()
    G, MC = model.G, model.MC
    G.nx, G.ny, G.nz = 101, 101, 51
    G.Lx, G.Ly, G.Lz = L, L, LZ
    G.media = [Medium("air", mua=1e-8, mus=1e-8, g=1.0, n=1.0),
               Medium("water", mua=0.00036, mus=10.0, g=1.0, n=N_WATER)]
    z_base = G.z[-1]
    G.geom_func = lambda X, Y, Z: np.where(X**2 + Y**2 + (Z - z_base) ** 2 < R**2, 1, 0)
    MC.n_photons_requested = 300_000
    MC.seed = 5
    MC.progress = False
    MC.matched_interfaces = False
    MC.smoothing_length_scale = G.Lx * 10
    MC.boundary_type = 1
    MC.calc_normalized_irradiance = True
    MC.light_source.source_type = 2  # a plane wave over the top face
    model.run_monte_carlo()
    above = below = 0.0
    for name, h in (("NI_xpos", G.dy), ("NI_xneg", G.dy), ("NI_ypos", G.dx), ("NI_yneg", G.dx)):
        per_z = getattr(MC, name).sum(axis=0) * h * G.dz  # fraction of the launched power
        above += per_z[G.z <= Z_SPLIT].sum()
        below += per_z[G.z > Z_SPLIT].sum()
    ref_above, ref_below = ray_trace(z_base)
    assert ref_below == pytest.approx(0.0072, abs=2e-4)  # the ray trace itself
    n = MC.n_photons
    for got, ref in ((above, ref_above), (below, ref_below)):
        tol = 4 * np.sqrt(ref * (1 - ref) / n) + 0.15 * ref
        assert abs(got - ref) <= tol, (above, below, ref_above, ref_below, tol)
