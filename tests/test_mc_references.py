"""Our Monte Carlo against references that share no code with it.

* total R and T of slabs against adding-doubling (Prahl's ``iadpython``), matched and
  mismatched boundaries, isotropic and forward scattering;
* Rd(r) of an index-matched half-space against a minimal Monte Carlo written apart from
  the package (``validation/independent_mc.py``): the reference where diffusion theory is
  poor (see ``validation/reports/mc_outputs.md``).

Tolerances come from the photon count (``se_bound`` of test_mc_physics: a packet's
contribution to a tally lies in [0, 1]); adding-doubling's own error is its change from
32 to 48 quadrature points.
"""

import math
import sys
from pathlib import Path

import numpy as np
import pytest
from test_mc_physics import se_bound, slab_model

sys.path.insert(0, str(Path(__file__).parents[1] / "validation"))


def adding_doubling(mua, mus, g, d, n):
    """iadpython's R, T and its own error (``validation/mc_outputs.ad_rt``)."""
    pytest.importorskip("iadpython")
    from mc_outputs import ad_rt

    return ad_rt(mua, mus, g, d, n)


@pytest.mark.parametrize("mua, mus, g, d, n", [(1.0, 10.0, 0.8, 0.1, 1.0),
                                                (0.5, 50.0, 0.9, 0.05, 1.4),
                                                (2.0, 20.0, 0.0, 0.1, 1.33)])
@pytest.mark.parametrize("kernel", ["general", "one-medium"])
def test_slab_total_reflectance_and_transmittance_match_adding_doubling(mua, mus, g, d, n,
                                                                        kernel):
    """Cyclic sides run the general kernel. A block 40 cm wide whose faces all escape runs
    the one-medium kernel (mcmatlab_py.monte_carlo._uniform); what leaves through its sides, after
    at least 20 cm inside, is below exp(-mua 20 cm) <= 5e-5: far below the tolerance."""
    N = 400_000
    model = slab_model(mua, mus, g, d, N, n=n, matched=n == 1.0, seed=11)
    model.MC.smoothing_length_scale = None
    if kernel == "one-medium":
        model.G.Lx = model.G.Ly = 40.0
        model.MC.boundary_type = 1
    MC = model.run_monte_carlo().MC
    R_ad, T_ad, eR, eT = adding_doubling(mua, mus, g, d, n)
    R = MC.escaped["top"] + MC.specular_reflectance
    T = MC.escaped["bottom"]
    assert abs(R - R_ad) < 4 * se_bound(R_ad, N) + eR
    assert abs(T - T_ad) < 4 * se_bound(T_ad, N) + eT
    assert eR < 1e-3 and eT < 1e-3  # AD itself converged
    assert MC.escaped["sides"] < 1e-4


def test_radial_reflectance_matches_an_independent_monte_carlo():
    """Index-matched half-space (mua 0.1, mus 10 /cm, g 0): Rd(r) at 1-10 transport mean free
    paths, where the two Monte Carlos agree and the diffusion dipole does not (8-25% off)."""
    from independent_mc import semi_infinite_rd

    N, mua, mus = 300_000, 0.1, 10.0
    dr, nr = 0.5 / (mua + mus), 24
    model = slab_model(mua, mus, 0.0, 4.0, N, nz=8, seed=5)
    model.MC.n_radial_bins, model.MC.radial_bin_size, model.MC.n_angle_bins = nr, dr, 1
    MC = model.run_monte_carlo().MC
    ref, r = semi_infinite_rd(N, mua, mus, nr, dr, seed=7)
    np.testing.assert_allclose(MC.radial_r, r, rtol=1e-12)
    area = 2 * np.pi * r * dr  # a bin's tally fraction p = Rd * area
    for i in (3, 7, 11):
        p = ref[i] * area[i]
        tol = 4 * math.sqrt(2) * se_bound(p, N)
        assert abs(MC.Rd_r[i] - ref[i]) * area[i] < tol, (i, MC.Rd_r[i], ref[i])
