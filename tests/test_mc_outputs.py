"""The optional Monte Carlo outputs: boundary maps, far field, light collector, time of
flight, MCML radial tallies, deposition criteria, example paths, combining runs.

Exact invariants first (fixed-point tallies: maps integrate to the face totals to
rounding), then analytic references with tolerances from the photon count (a few
binomial standard errors, ``se``).
"""

import math

import numpy as np
import pytest

from mcmatlab_py import Medium, Model
from mcmatlab_py.combine import combine_models
from mcmatlab_py.monte_carlo.layered import absorption_vs_depth, radial_reflectance_transmittance

C = 29979245800.0  # cm/s


def se(p: float, n: int) -> float:
    return math.sqrt(max(p * (1 - p), 1e-300) / n)


def block(n_photons=4000, *, mua=1.0, mus=100.0, g=0.9, n=1.3, shape=(12, 12, 6), L=(0.5, 0.5, 0.25),
          seed=1, matched=True, source="tophat"):
    model = Model()
    model.G.nx, model.G.ny, model.G.nz = shape
    model.G.Lx, model.G.Ly, model.G.Lz = L
    model.G.media = [Medium("tissue", mua=mua, mus=mus, g=g, n=n)]
    model.MC.n_photons_requested = n_photons
    model.MC.seed = seed
    model.MC.progress = False
    model.MC.matched_interfaces = matched
    model.MC.smoothing_length_scale = None
    model.MC.light_source.source_type = source
    model.MC.light_source.radius = 0.1
    return model


def all_outputs(model):
    MC = model.MC
    MC.calc_normalized_irradiance = True
    MC.far_field_res = 8
    MC.n_radial_bins, MC.radial_bin_size, MC.n_angle_bins = 10, 0.05, 6
    MC.n_example_paths = 3
    return model


@pytest.mark.parametrize("boundary_type", [1, 3])
def test_maps_and_far_field_integrate_to_the_face_totals(boundary_type):
    model = all_outputs(block(matched=False))
    model.MC.boundary_type = boundary_type
    MC = model.run_monte_carlo().MC
    G = model.G
    assert MC.energy_balance == pytest.approx(1.0, abs=1e-12)
    face = {f: getattr(MC, f"NI_{f}").sum() for f in ("xpos", "xneg", "ypos", "yneg", "zpos", "zneg")}
    assert face["zneg"] * G.dx * G.dy == pytest.approx(MC.escaped["top"], rel=1e-12)
    assert face["zpos"] * G.dx * G.dy == pytest.approx(MC.escaped["bottom"], rel=1e-12)
    sides = (face["xpos"] + face["xneg"]) * G.dy * G.dz + (face["ypos"] + face["yneg"]) * G.dx * G.dz
    assert sides == pytest.approx(MC.escaped["sides"], rel=1e-12, abs=1e-15)
    assert MC.far_field.sum() == pytest.approx(sum(MC.escaped.values()), rel=1e-12)
    ring = 2 * np.pi * MC.radial_r * MC.radial_bin_size
    assert (MC.Rd_r * ring).sum() == pytest.approx(MC.escaped["top"], rel=1e-12)
    assert (MC.Tt_a * 2 * np.pi * (np.cos(MC.exit_angle - np.pi / 24)
                                   - np.cos(MC.exit_angle + np.pi / 24))).sum() \
        == pytest.approx(MC.escaped["bottom"], rel=1e-12)


def test_outputs_leave_the_plain_run_untouched():
    """Asking for outputs draws no extra random numbers in the general kernel: NA is
    bit-identical. (Cyclic sides keep the plain run of this one-medium block on the general
    kernel; with escaping sides it takes the one-medium kernel, tests/test_mc_uniform.py.)"""
    plain = block(matched=False)
    plain.MC.boundary_type = 3
    plain = plain.run_monte_carlo().MC
    full = all_outputs(block(matched=False))
    full.MC.boundary_type = 3
    full = full.run_monte_carlo().MC
    np.testing.assert_array_equal(plain.NA, full.NA)
    assert plain.escaped == full.escaped


def test_outputs_same_for_any_thread_count():
    import numba

    runs = []
    for threads in (1, min(2, numba.config.NUMBA_NUM_THREADS)):
        model = all_outputs(block(matched=False))
        model.MC.use_light_collector = True
        LC = model.MC.light_collector
        LC.f, LC.diam, LC.field_size, LC.res, LC.z = 1.0, 1.0, 0.5, 5, 0.0
        LC.n_time_bins, LC.t_end = 4, 2e-11
        model.MC.n_threads = threads
        runs.append(model.run_monte_carlo().MC)
    for name in ("NA", "NI_zneg", "NI_xpos", "far_field", "Rd_r", "example_paths"):
        np.testing.assert_array_equal(getattr(runs[0], name), getattr(runs[1], name))
    np.testing.assert_array_equal(runs[0].light_collector.image, runs[1].light_collector.image)


def transparent(n_photons, z_source, *, L=1.0):
    """A clear cube (no absorption, no scattering) with an isotropic point at depth z_source."""
    model = block(n_photons, mua=0.0, mus=0.0, g=0.0, n=1.0, shape=(4, 4, 4), L=(L, L, L),
                  source="isotropic_point")
    model.MC.light_source.z_focus = z_source
    return model


@pytest.mark.parametrize("NA_, diam", [(0.22, 0.2), (1.0, 0.1)])
def test_fiber_collects_the_analytic_acceptance_of_a_point_source(NA_, diam):
    """Point at distance L below the fiber tip: collected = (1 - cos min(atan(a/L), asin NA)) / 2."""
    N, h, zs = 40_000, 0.2, 0.1
    model = transparent(N, zs)
    model.MC.use_light_collector = True
    LC = model.MC.light_collector
    LC.z, LC.theta, LC.NA, LC.diam = -h, 0.0, NA_, diam  # above the top face, looking down (+z)
    MC = model.run_monte_carlo().MC
    half = min(math.atan(diam / 2 / (h + zs)), math.asin(NA_))
    p = (1 - math.cos(half)) / 2
    assert abs(LC.image - p) < 4 * se(p, N)
    assert abs(MC.n_photons_collected - p * N) < 4 * se(p, N) * N


def test_lens_images_a_point_source_where_optics_say():
    """A lens focused on the plane of a point source images it to one pixel at its (x, y)."""
    x0, y0, zs = 0.13, -0.07, 0.3
    model = transparent(20_000, zs)
    model.MC.light_source.x_focus, model.MC.light_source.y_focus = x0, y0
    model.MC.use_light_collector = True
    LC = model.MC.light_collector
    LC.x, LC.y, LC.z = 0.0, 0.0, zs  # focal plane through the source
    LC.f, LC.diam, LC.field_size, LC.res = 1.0, 0.5, 0.6, 12
    model.run_monte_carlo()
    img = LC.image
    i, j = np.unravel_index(np.argmax(img), img.shape)
    assert img.sum() == img[i, j]  # every collected packet in one pixel
    pix = LC.field_size / LC.res
    assert abs(LC.X[i] - x0) <= pix / 2 and abs(LC.Y[j] - y0) <= pix / 2
    # power: the solid angle of the (off-axis) lens aperture seen from the source, / 4 pi
    rho, phi = np.meshgrid((np.arange(400) + 0.5) / 400 * LC.diam / 2,
                           (np.arange(400) + 0.5) / 400 * 2 * np.pi, indexing="ij")
    s2 = (rho * np.cos(phi) - x0) ** 2 + (rho * np.sin(phi) - y0) ** 2 + LC.f**2
    p = float((LC.f / s2**1.5 * rho).sum() * (LC.diam / 2 / 400) * (2 * np.pi / 400)) / (4 * np.pi)
    assert abs(img.sum() * pix**2 - p) < 4 * se(p, 20_000)


def test_ballistic_time_of_flight_through_a_slab():
    """Clear slab (n = 1.5) under a pencil: transmitted passes arrive at (d n (1 + 2k) + h) / c
    with powers (1-R)^2 R^(2k) exp(-mua d (1 + 2k)); a fiber below times them."""
    N, d, n, mua, h = 20_000, 0.1, 1.5, 2.0, 0.05
    model = block(N, mua=mua, mus=0.0, g=0.0, n=n, shape=(1, 1, 4), L=(1.0, 1.0, d),
                  matched=False, source="pencil")
    model.MC.boundary_type = 1
    model.MC.use_light_collector = True
    LC = model.MC.light_collector
    LC.z, LC.theta, LC.NA, LC.diam = d + h, math.pi, 1.0, 0.5  # below, looking up
    t1 = (d * n + h) / C
    dt2 = 2 * d * n / C
    LC.t_start, LC.t_end, LC.n_time_bins = t1 - dt2 / 2, t1 + 3 * dt2 / 2, 2
    model.run_monte_carlo()
    R = ((n - 1) / (n + 1)) ** 2
    for k, b in ((0, 1), (1, 2)):
        p = (1 - R) ** 2 * R ** (2 * k) * math.exp(-mua * d * (1 + 2 * k))
        assert abs(LC.image[b] - p) < 4 * se(p, N) + 1e-9
    assert LC.image[0] == 0.0
    np.testing.assert_allclose(LC.t[1:3], [t1, t1 + dt2], rtol=1e-12)


def test_far_field_of_an_oblique_beam_through_a_clear_slab():
    """No scattering: the transmitted beam leaves parallel to the incident one (Snell twice)."""
    N = 5000
    model = block(N, mua=0.0, mus=0.0, g=0.0, n=1.4, shape=(1, 1, 2), L=(2.0, 2.0, 0.1),
                  matched=False, source="pencil")
    model.MC.boundary_type = 3
    model.MC.light_source.theta, model.MC.light_source.phi = 0.5, 1.0
    model.MC.far_field_res = 36
    MC = model.run_monte_carlo().MC
    ith = int(0.5 / np.pi * 36)
    iph = int((1.0 + np.pi) / (2 * np.pi) * 36)
    assert MC.far_field[ith, iph] == pytest.approx(MC.escaped["bottom"], rel=1e-12)
    assert MC.far_field.sum() == pytest.approx(sum(MC.escaped.values()), rel=1e-12)


def test_deposition_criteria_unscattered_light_is_beer_lambert():
    """max_scatterings = 0 judged along the path: NA holds only the unscattered beam,
    (mua / mut) (exp(-mut z_k) - exp(-mut z_k+1)) per layer; the balance still counts all."""
    N, mua, mus, nz, Lz = 20_000, 2.0, 8.0, 10, 0.3
    model = block(N, mua=mua, mus=mus, g=0.5, n=1.0, shape=(1, 1, nz), L=(1.0, 1.0, Lz),
                  source="pencil")
    model.MC.boundary_type = 3
    DC = model.MC.deposition_criteria
    DC.max_scatterings, DC.evaluate_only_at_end_of_life = 0, False
    MC = model.run_monte_carlo().MC
    G = model.G
    layer = MC.NA.sum(axis=(0, 1)) * G.dx * G.dy * G.dz
    z = np.arange(nz + 1) * G.dz
    mut = mua + mus
    exact = mua / mut * (np.exp(-mut * z[:-1]) - np.exp(-mut * z[1:]))
    # a packet's deposit in layer k is at most the collision's mua/mut share: Bernoulli bound
    assert np.all(np.abs(layer - exact) < 4 * np.sqrt(exact * (1 - exact) / N) + 1e-12)
    assert MC.energy_balance == pytest.approx(1.0, abs=1e-12)


def test_deposition_criteria_only_collected_and_min_scatterings():
    model = all_outputs(block(6000))
    model.MC.use_light_collector = True
    LC = model.MC.light_collector
    LC.z, LC.theta, LC.NA, LC.diam = -0.01, 0.0, 1.0, 10.0  # above, collects the whole top
    model.MC.deposition_criteria.only_collected = True
    model.MC.boundary_type = 2  # only the top escapes: the fiber collects all of it
    MC = model.run_monte_carlo().MC
    G = model.G
    # only collected packets reach the maps
    assert MC.NI_zneg.sum() * G.dx * G.dy == pytest.approx(LC.image, rel=1e-12)
    assert MC.NI_zpos.sum() == 0.0 and MC.far_field.sum() == pytest.approx(LC.image, rel=1e-12)
    assert 0 < MC.NA.sum() * G.dx * G.dy * G.dz < MC.absorbed_fraction
    assert MC.energy_balance == pytest.approx(1.0, abs=1e-12)
    clear = block(2000, mua=2.0, mus=0.0, g=0.0, n=1.0, source="pencil")
    clear.MC.deposition_criteria.min_scatterings = 1
    MC = clear.run_monte_carlo().MC
    assert MC.NA.sum() == 0.0 and MC.absorbed_fraction > 0.3  # nothing ever scatters


def test_request_collected_photons_is_reproducible():
    import numba

    got = []
    for threads in (1, min(2, numba.config.NUMBA_NUM_THREADS)):
        model = block(500)
        model.MC.n_threads = threads
        model.MC.batch_size = 200
        model.MC.use_light_collector = True
        model.MC.request_collected_photons = True
        LC = model.MC.light_collector
        LC.z, LC.NA, LC.diam = -0.1, 0.5, 0.2
        MC = model.run_monte_carlo().MC
        assert MC.n_photons_collected >= 500
        got.append((MC.n_photons, MC.n_photons_collected, LC.image))
    assert got[0] == got[1]


def test_example_paths_start_at_the_source_and_stay_in_or_on_the_cuboid():
    model = block(200, source="pencil")
    model.MC.light_source.x_focus = 0.05
    model.MC.n_example_paths = 4
    MC = model.run_monte_carlo().MC
    P = MC.example_paths
    starts = np.flatnonzero(np.isnan(P[0])) + 1
    assert len(starts) == 4
    np.testing.assert_allclose(P[:3, starts].T, [[0.05, 0.0, 0.0]] * 4, atol=1e-12)
    ok = ~np.isnan(P[0])
    assert np.all(np.abs(P[0, ok]) <= 0.25 + 1e-12) and np.all((P[2, ok] >= 0) & (P[2, ok] <= 0.25))
    assert np.all(P[3, starts] == 1.0)


def test_combine_models_weights_by_photons_and_by_power():
    a = all_outputs(block(2000, seed=1)).run_monte_carlo()
    b = all_outputs(block(6000, seed=2)).run_monte_carlo()
    ab = combine_models([a, b])
    np.testing.assert_allclose(ab.MC.NA, (2000 * a.MC.NA + 6000 * b.MC.NA) / 8000)
    np.testing.assert_allclose(ab.MC.NI_zneg, (2000 * a.MC.NI_zneg + 6000 * b.MC.NI_zneg) / 8000)
    assert ab.MC.n_photons == 8000
    assert ab.MC.energy_balance == pytest.approx(1.0, abs=1e-12)
    c = block(2000, seed=3)
    c.MC.light_source.x_focus = 0.1
    c = all_outputs(c).run_monte_carlo()
    ac = combine_models([a, c], powers=[1.0, 3.0])  # two beams, the second 3 W
    np.testing.assert_allclose(ac.MC.NA, (a.MC.NA + 3 * c.MC.NA) / 4)  # per W of the total
    assert ac.MC.P == 4.0
    with pytest.raises(ValueError, match=r"light sources or powers differ: set every model's "
                                         r"MC.P"):
        combine_models([a, c])
    a.MC.P, c.MC.P = 1.0, 3.0  # MCmatlab's way: the weights are each model's MC.P
    np.testing.assert_array_equal(combine_models([a, c]).MC.NA, ac.MC.NA)
    other = block(2000, shape=(10, 12, 6)).run_monte_carlo()
    with pytest.raises(ValueError, match="G.nx"):
        combine_models([a, other])


def test_layered_helpers_follow_plotAzFz_and_the_radial_plot():
    model = all_outputs(block(3000))
    model.run_monte_carlo()
    z, A, F = absorption_vs_depth(model)
    G = model.G
    assert (A * G.dz).sum() == pytest.approx(model.MC.absorbed_fraction, rel=1e-12)
    np.testing.assert_allclose(F, A / 1.0)  # one medium with mua = 1
    r, R, T = radial_reflectance_transmittance(model)
    assert r[0] > 0 and np.all(np.diff(r) > 0) and R.shape == T.shape == r.shape


def test_bad_output_settings_raise_value_errors_naming_the_field():
    model = block(100)
    model.MC.boundary_type = 0
    model.MC.far_field_res = 10
    with pytest.raises(ValueError, match="far_field_res"):
        model.run_monte_carlo()
    model = block(100)
    model.MC.use_light_collector = True
    model.MC.light_collector.z = 0.1  # a fiber tip inside the cuboid
    with pytest.raises(ValueError, match="inside the cuboid"):
        model.run_monte_carlo()
    model = block(100)
    model.MC.deposition_criteria.only_collected = True
    with pytest.raises(ValueError, match="only_collected"):
        model.run_monte_carlo()


def test_output_figures_draw():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from mcmatlab_py.plotting import outputs as P

    model = all_outputs(block(300))
    model.MC.use_light_collector = True
    LC = model.MC.light_collector
    LC.f, LC.res, LC.field_size, LC.z = 1.0, 6, 0.5, 0.0
    model.run_monte_carlo()
    for draw in (P.plot_example_paths, P.plot_far_field, P.plot_light_collector,
                 P.plot_boundary_irradiance, P.plot_az_fz, P.plot_radial_reflectance_transmittance):
        plt.close(draw(model))
