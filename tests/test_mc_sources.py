"""Every MCmatlab light source, against its analytic distribution.

The launch sampler is tested directly (:func:`mcmatlab_py.light.source.sample_light_source`,
no transport: fast); a few end-to-end runs check what the kernel does with the packets
(focusing, refraction at the surface). Tolerances come from the number of samples: a
fraction p estimated from N samples has standard error sqrt(p (1 - p) / N); a mean, the
standard deviation of the distribution over sqrt(N); binned samples are compared by a
chi-square test at a false-alarm rate of 1e-4.
"""

import math

import numpy as np
import pytest
from scipy.stats import chi2

from mcmatlab_py import Medium, Model
from mcmatlab_py.light.source import LG01_RADIUS_RATIO, beam_axes, sample_light_source

N = 200_000  # samples per sampler test


def se(p: float, n: int = N) -> float:
    """Standard error of a fraction p estimated from n samples."""
    return math.sqrt(p * (1 - p) / n)


def chi2_ok(counts: np.ndarray, expected_fraction: np.ndarray) -> bool:
    """Counts per bin consistent with the expected fractions (chi-square, false alarm 1e-4)."""
    expected = expected_fraction * counts.sum()
    stat = ((counts - expected) ** 2 / expected).sum()
    return stat < chi2.isf(1e-4, counts.size - 1)


def block(n=(20, 20, 10), L=(1.0, 1.0, 0.5), media=None):
    model = Model()
    model.G.nx, model.G.ny, model.G.nz = n
    model.G.Lx, model.G.Ly, model.G.Lz = L
    model.G.media = media or [Medium("clear", mua=1.0, mus=0.0, g=0.0, n=1.0)]
    model.MC.progress = False
    model.MC.seed = 5
    return model


def focal_plane_points(d: dict, source) -> tuple[np.ndarray, np.ndarray]:
    """Where each ray crosses the focal plane, as (X, Y) along the beam's v and w axes (cm)."""
    u, v, w = beam_axes(source.theta, source.phi, source.psi)
    p = np.stack([d["x"] - source.x_focus, d["y"] - source.y_focus, d["z"] - source.z_focus], 1)
    dirs = np.stack([d["ux"], d["uy"], d["uz"]], 1)
    t = -(p @ u) / (dirs @ u)
    q = p + t[:, None] * dirs
    return q @ v, q @ w


# ----------------------------------------------------------------- the sampler


def test_oblique_pencil_starts_on_its_line_through_the_focus():
    model = block()
    src = model.MC.light_source
    src.source_type, src.theta, src.phi = 0, 0.3, 0.7
    src.x_focus, src.y_focus, src.z_focus = 0.05, -0.02, 0.1
    d = sample_light_source(model, 1000)
    u, _, _ = beam_axes(0.3, 0.7, 0.0)
    start = np.array([0.05, -0.02, 0.1]) - 0.1 / u[2] * u
    assert np.allclose(np.stack([d["x"], d["y"], d["z"]], 1), start, atol=1e-12)
    assert np.allclose(np.stack([d["ux"], d["uy"], d["uz"]], 1), u, atol=1e-12)
    assert d["ok"].all() and start[2] == 0.0


def test_isotropic_point_emits_uniformly_over_the_sphere():
    model = block()
    src = model.MC.light_source
    src.source_type, src.z_focus = "isotropic", 0.25
    d = sample_light_source(model, N)
    # uz is uniform on [-1, 1]: mean 0 (sd 1/sqrt 3), E[uz^2] = 1/3 (sd sqrt(4/45))
    assert abs(d["uz"].mean()) < 4 / math.sqrt(3 * N)
    assert abs((d["uz"] ** 2).mean() - 1 / 3) < 4 * math.sqrt(4 / 45 / N)
    assert abs(d["ux"].mean()) < 4 / math.sqrt(3 * N)
    assert np.allclose(d["ux"] ** 2 + d["uy"] ** 2 + d["uz"] ** 2, 1.0)
    assert np.all(d["z"] == 0.25)


def test_line_emitter_is_uniform_along_its_axis():
    model = block()
    src = model.MC.light_source
    src.source_type, src.emitter_length = 1, 0.2
    src.theta, src.phi, src.z_focus = 0.5, 1.0, 0.25
    d = sample_light_source(model, N)
    u, _, _ = beam_axes(0.5, 1.0, 0.0)
    p = np.stack([d["x"], d["y"], d["z"] - 0.25], 1)
    s = p @ u  # position along the line
    assert np.allclose(p - s[:, None] * u, 0.0, atol=1e-12)  # on the line
    assert np.all(np.abs(s) <= 0.1 + 1e-12)
    counts, _ = np.histogram(s, bins=10, range=(-0.1, 0.1))
    assert chi2_ok(counts, np.full(10, 0.1))
    assert abs((d["uz"] ** 2).mean() - 1 / 3) < 4 * math.sqrt(4 / 45 / N)  # still isotropic


def test_plane_wave_covers_the_top_face_uniformly_along_the_axis():
    model = block()
    src = model.MC.light_source
    src.source_type, src.theta, src.phi = "plane_wave", 0.4, -0.5
    d = sample_light_source(model, N)
    counts, _, _ = np.histogram2d(d["x"], d["y"], bins=4, range=[[-0.5, 0.5], [-0.5, 0.5]])
    assert chi2_ok(counts.ravel(), np.full(16, 1 / 16))
    u, _, _ = beam_axes(0.4, -0.5, 0.0)
    assert np.allclose(np.stack([d["ux"], d["uy"], d["uz"]], 1), u)
    assert np.all(d["z"] == 0.0)


@pytest.mark.parametrize("legacy", [False, True])
def test_gaussian_focal_plane_holds_1_minus_e_minus_2_within_the_waist(legacy):
    """Intensity exp(-2 r^2 / W^2): a fraction 1 - exp(-2 k^2) of the power lies within kW."""
    model = block()
    src = model.MC.light_source
    if legacy:
        src.source_type, src.radius = "gaussian", 0.1
    else:
        src.source_type = "radial"
        src.focal_plane_intensity_distribution.radial_distr = "gaussian"
        src.focal_plane_intensity_distribution.radial_width = 0.1
        src.angular_intensity_distribution.radial_distr = 0
        src.angular_intensity_distribution.radial_width = 0.0
    d = sample_light_source(model, N)
    r = np.hypot(d["x"], d["y"])
    for k in (0.5, 1.0, 1.5):
        p = 1 - math.exp(-2 * k * k)
        assert abs((r < 0.1 * k).mean() - p) < 4 * se(p)
    assert np.all(d["uz"] == 1.0)


def test_top_hat_focal_plane_is_a_uniform_disc():
    model = block()
    src = model.MC.light_source
    src.source_type = 4
    src.focal_plane_intensity_distribution.radial_distr = 0
    src.focal_plane_intensity_distribution.radial_width = 0.1
    src.angular_intensity_distribution.radial_distr = 0
    src.angular_intensity_distribution.radial_width = 0.0
    d = sample_light_source(model, N)
    r = np.hypot(d["x"], d["y"])
    assert r.max() <= 0.1
    counts, _ = np.histogram((r / 0.1) ** 2, bins=10, range=(0, 1))  # r^2 is uniform
    assert chi2_ok(counts, np.full(10, 0.1))


def test_lambertian_far_field_follows_the_cosine_law():
    """Intensity per solid angle ~ cos(angle to the axis): cos^2 of the angle is uniform."""
    model = block()
    src = model.MC.light_source
    src.source_type, src.theta, src.phi = "radial", 0.3, 2.0
    src.focal_plane_intensity_distribution.radial_distr = "tophat"
    src.focal_plane_intensity_distribution.radial_width = 0.05
    src.angular_intensity_distribution.radial_distr = "lambertian"
    d = sample_light_source(model, N)
    u, _, _ = beam_axes(0.3, 2.0, 0.0)
    c = np.stack([d["ux"], d["uy"], d["uz"]], 1) @ u
    assert c.min() >= 0.0
    counts, _ = np.histogram(c**2, bins=10, range=(0, 1))
    assert chi2_ok(counts, np.full(10, 0.1))
    # rays tilted more than 90 deg - 0.3 rad from the vertical point up: they cannot enter
    assert abs((~d["ok"]).mean() - (d["uz"] <= 0).mean()) == 0.0


def test_lg01_ring_is_dark_on_its_axis():
    """LG01: I(r) ~ r^2 exp(-2 r^2 / w^2), w the Gaussian parameter: s = 2 r^2 / w^2 has
    cumulative 1 - (1 + s) e^-s; the outer 1/e^2 radius (MCmatlab's width) is 1.50087 w."""
    model = block()
    src = model.MC.light_source
    src.source_type, src.z_focus = "lg01", 0.2
    src.focal_plane_intensity_distribution.radial_width = 0.1
    src.angular_intensity_distribution.radial_width = 0.05
    d = sample_light_source(model, N)
    X, Y = focal_plane_points(d, src)
    w = 0.1 / LG01_RADIUS_RATIO
    s = 2 * (X**2 + Y**2) / w**2
    F = 1 - (1 + s) * np.exp(-s)  # uniform on [0, 1] if the ring is right
    counts, _ = np.histogram(F, bins=10, range=(0, 1))
    assert chi2_ok(counts, np.full(10, 0.1))
    s0 = 2 * (0.05 * 0.1 / w) ** 2  # within 5 % of the width of the axis
    p0 = 1 - (1 + s0) * math.exp(-s0)
    assert (s < s0).mean() < p0 + 4 * se(p0)
    assert abs(LG01_RADIUS_RATIO - 1.50087) < 1e-5
    # the rays are skewed: tilted along the azimuth of their focal point, not radially
    tilt = np.stack([d["ux"], d["uy"]], 1)
    radial = np.stack([X, Y], 1) / np.hypot(X, Y)[:, None]
    assert np.abs((tilt * radial).sum(1)).max() < 1e-12


def test_xy_beam_is_turned_by_psi():
    """X top-hat of half-width a along v, Y Gaussian of 1/e^2 half-width b along w."""
    a, b, psi = 0.1, 0.05, math.pi / 6
    model = block()
    src = model.MC.light_source
    src.source_type, src.psi = "xy", psi
    fp, an = src.focal_plane_intensity_distribution, src.angular_intensity_distribution
    fp.x_distr, fp.x_width, fp.y_distr, fp.y_width = 0, a, 1, b
    an.x_distr, an.x_width, an.y_distr, an.y_width = 0, 0.0, 0, 0.0
    d = sample_light_source(model, N)
    X = d["x"] * math.cos(psi) + d["y"] * math.sin(psi)
    Y = -d["x"] * math.sin(psi) + d["y"] * math.cos(psi)
    assert np.abs(X).max() <= a + 1e-12
    assert abs((X**2).mean() - a * a / 3) < 4 * math.sqrt(4 / 45 / N) * a * a
    p = math.erf(math.sqrt(2))  # |Y| < b: within 2 standard deviations
    assert abs((np.abs(Y) < b).mean() - p) < 4 * se(p)


def test_custom_arrays_are_sampled_as_piecewise_linear_densities():
    model = block()
    src = model.MC.light_source
    src.source_type = "xy"
    fp, an = src.focal_plane_intensity_distribution, src.angular_intensity_distribution
    fp.x_distr, fp.x_width = np.array([0.0, 1.0]), 0.1  # a ramp: density ~ x + 0.1 on [-0.1, 0.1]
    fp.y_distr, fp.y_width = np.ones(7), 0.05  # flat: a top-hat
    an.x_distr, an.x_width, an.y_distr, an.y_width = 0, 0.0, 0, 0.0
    d = sample_light_source(model, N)
    sd = 0.2 / math.sqrt(18)  # of the ramp density on an interval of length 0.2
    assert abs(d["x"].mean() - 0.1 / 3) < 4 * sd / math.sqrt(N)
    assert abs((d["x"] < 0).mean() - 0.25) < 4 * se(0.25)
    assert abs((np.abs(d["y"]) < 0.025).mean() - 0.5) < 4 * se(0.5)
    # radial arrays are intensity per area: a flat array is a uniform disc, in the focal
    # plane and on tan(angle)
    src.source_type = "radial"
    fp.radial_distr, fp.radial_width = np.ones(5), 0.1
    an.radial_distr, an.radial_width = np.ones(5), 0.2
    d = sample_light_source(model, N)
    r = np.hypot(d["x"], d["y"])
    assert abs((r < 0.05).mean() - 0.25) < 4 * se(0.25)
    tan = np.hypot(d["ux"], d["uy"]) / d["uz"]
    assert tan.max() <= math.tan(0.2) + 1e-12
    assert abs((tan < math.tan(0.2) / 2).mean() - 0.25) < 4 * se(0.25)


def test_source_distribution_emits_from_the_weighted_voxels():
    model = block(n=(4, 4, 4), L=(0.4, 0.4, 0.4))
    S = np.zeros((4, 4, 4))
    S[1, 1, 1], S[2, 3, 0], S[0, 0, 3] = 1.0, 2.0, 3.0
    model.MC.source_distribution = S
    d = sample_light_source(model, N)
    i = np.floor((d["x"] + 0.2) / 0.1).astype(int)
    j = np.floor((d["y"] + 0.2) / 0.1).astype(int)
    k = np.floor(d["z"] / 0.1).astype(int)
    for (a, b, c), p in (((1, 1, 1), 1 / 6), ((2, 3, 0), 2 / 6), ((0, 0, 3), 3 / 6)):
        assert abs(((i == a) & (j == b) & (k == c)).mean() - p) < 4 * se(p)
    assert np.all(S[i, j, k] > 0)
    assert abs((d["uz"] ** 2).mean() - 1 / 3) < 4 * math.sqrt(4 / 45 / N)


# ----------------------------------------------------------- through the kernel


def layer_moments(model):
    """Per z layer: absorbed power and the mean x and r^2 of the absorption (voxel centres)."""
    G, NA = model.G, model.MC.NA
    X, Y = np.meshgrid(G.x, G.y, indexing="ij")
    w = NA.sum(axis=(0, 1))
    mx = (NA * X[:, :, None]).sum(axis=(0, 1)) / w
    r2 = (NA * (X**2 + Y**2)[:, :, None]).sum(axis=(0, 1)) / w
    return w, mx, r2


def test_converging_beam_is_narrowest_at_its_focus():
    """A focused beam in a medium that deflects nothing (g = 1): its mean square radius
    at depth z is W^2 / 2 + (z - z_focus)^2 <tan^2>, a parabola with its vertex at the focus."""
    z_focus = 0.2
    model = block(n=(60, 60, 40), L=(0.3, 0.3, 0.4),
                  media=[Medium("no deflection", mua=1.0, mus=20.0, g=1.0, n=1.0)])
    src = model.MC.light_source
    src.source_type, src.z_focus = "radial", z_focus
    src.focal_plane_intensity_distribution.radial_distr = "tophat"
    src.focal_plane_intensity_distribution.radial_width = 0.01
    src.angular_intensity_distribution.radial_distr = "tophat"
    src.angular_intensity_distribution.radial_width = 0.25
    model.MC.n_photons_requested = 20_000
    model.run_monte_carlo()
    assert model.MC.missed_fraction == 0.0
    _, _, r2 = layer_moments(model)
    z = model.G.z
    a, b, c = np.polyfit(z, r2, 2)
    assert abs(-b / (2 * a) - z_focus) < model.G.dz  # vertex within one layer of the focus
    # the curvature is <tan^2> of the angular top-hat, T^2 U with U uniform: mean T^2 / 2,
    # relative standard error (1 / sqrt 12) / (1 / 2) / sqrt(N) over N photons
    t2 = math.tan(0.25) ** 2 / 2
    assert a == pytest.approx(t2, rel=4 * 2 / math.sqrt(12 * model.MC.n_photons_requested))
    assert r2.min() < r2[0] / 4


def fresnel(n1: float, n2: float, ci: float) -> tuple[float, float]:
    """Unpolarised Fresnel reflectance and the cosine of the refraction angle."""
    st = n1 / n2 * math.sqrt(1 - ci * ci)
    ct = math.sqrt(1 - st * st)
    rs = ((n1 * ci - n2 * ct) / (n1 * ci + n2 * ct)) ** 2
    rp = ((n1 * ct - n2 * ci) / (n1 * ct + n2 * ci)) ** 2
    return (rs + rp) / 2, ct


def test_oblique_pencil_refracts_by_snell_with_fresnel_reflectance():
    theta, n = math.pi / 4, 1.5
    model = block(n=(80, 4, 40), L=(0.4, 0.02, 0.2),
                  media=[Medium("glass", mua=8.0, mus=0.0, g=0.0, n=n)])
    model.MC.matched_interfaces = False
    model.MC.n_photons_requested = 20_000
    src = model.MC.light_source
    src.source_type, src.theta, src.x_focus = "pencil", theta, -0.15
    model.run_monte_carlo()
    R, ct = fresnel(1.0, n, math.cos(theta))
    assert model.MC.specular_reflectance == pytest.approx(R, rel=1e-9)  # a deterministic split
    w, mx, _ = layer_moments(model)
    z = model.G.z
    used = w > 0.02 * w.max()
    slope = np.polyfit(z[used], mx[used], 1)[0]
    # the path x = x_focus + z tan(theta_t); voxel centres shift a layer's mean by < dx / 2
    assert abs(slope - math.sqrt(1 - ct * ct) / ct) < model.G.dx / (np.ptp(z[used]) / 2)


def test_beam_hitting_a_perfect_reflector_is_all_specular():
    model = block(media=[Medium("mirror", mua=1.0, mus=0.0, g=0.0, n=np.inf)])
    model.MC.matched_interfaces = False
    model.MC.n_photons_requested = 1000
    model.MC.light_source.source_type = "plane_wave"
    MC = model.run_monte_carlo().MC
    assert MC.specular_reflectance == 1.0 and MC.absorbed_fraction == 0.0


def test_buried_perfect_reflector_sends_the_beam_back():
    """mus = 0 over a mirror (n = inf) at depth d: the beam returns through 2 d of absorber."""
    Nph, mua, d = 40_000, 3.0, 0.1
    model = block(n=(4, 4, 8), L=(0.4, 0.4, 0.2),
                  media=[Medium("absorber", mua=mua, mus=0.0, g=0.0, n=1.0),
                         Medium("mirror", mua=1.0, mus=0.0, g=0.0, n=np.inf)])
    model.G.geom_func = lambda X, Y, Z: (Z > d).astype(int)
    model.MC.matched_interfaces = False
    model.MC.n_photons_requested = Nph
    model.MC.light_source.source_type = "tophat"
    model.MC.light_source.radius = 0.05
    MC = model.run_monte_carlo().MC
    p = math.exp(-2 * mua * d)
    assert abs(MC.escaped["top"] - p) < 4 * se(p, Nph)
    assert MC.escaped["bottom"] == 0.0 and np.all(MC.NA[:, :, 4:] == 0.0)
    assert MC.energy_balance == pytest.approx(1.0, abs=1e-9)


@pytest.mark.parametrize("smoothing", [0.1, None])
def test_tilted_mirror_reflects_about_the_smoothed_normal(smoothing):
    """A mirror below the 45 degree plane z = z0 + x: smoothed normals (MCmatlab) turn a
    vertical beam horizontal, out of a side; the voxel faces of the staircase send it back up."""
    model = block(n=(40, 12, 40), L=(0.4, 0.12, 0.4),
                  media=[Medium("air", mua=0.0, mus=0.0, g=0.0, n=1.0),
                         Medium("mirror", mua=0.0, mus=0.0, g=0.0, n=np.inf)])
    model.G.geom_func = lambda X, Y, Z: (Z > 0.2 + X).astype(int)
    model.MC.matched_interfaces = False
    model.MC.smoothing_length_scale = smoothing
    model.MC.n_photons_requested = 2000
    src = model.MC.light_source
    src.source_type, src.radius = "tophat", 0.05
    MC = model.run_monte_carlo().MC
    if smoothing is None:
        assert MC.escaped["top"] == pytest.approx(1.0)
    else:
        assert MC.escaped["sides"] > 0.98  # rays that meet the stairs by the cuboid's edge
    assert MC.energy_balance == pytest.approx(1.0, abs=1e-9)


def test_interface_normals_of_a_sphere_point_along_the_radius():
    from mcmatlab_py.monte_carlo.optics import interface_normals

    n, R = 32, 10.0
    i = np.arange(n) - (n - 1) / 2
    X, Y, Z = np.meshgrid(i, i, i, indexing="ij")
    M = (X**2 + Y**2 + Z**2 < R * R).astype(np.int32)
    normals = interface_normals(M, np.array([1.0, 1.5]), (1.0, 1.0, 1.0), 2.0).reshape(n, n, n, 3)
    r = np.sqrt(X**2 + Y**2 + Z**2)
    shell = (M == 1) & (r > R - 1.5)  # the sphere's surface voxels: normals point inwards
    cos = -(normals[shell] * np.stack([X, Y, Z], -1)[shell]).sum(-1) / r[shell]
    assert np.degrees(np.arccos(cos.min())) < 10.0
    planar = interface_normals((Z > 0).astype(np.int32), np.array([1.0, np.inf]), (1, 1, 1), 0.1)
    v = planar.reshape(n, n, n, 3)[:, :, 15:17]
    assert np.array_equal(np.abs(v), np.broadcast_to([0.0, 0.0, 1.0], v.shape))


def test_g_equal_one_is_beer_lambert_whatever_mus():
    Nph, mua, nz, Lz = 50_000, 4.0, 10, 0.5
    model = block(n=(1, 1, nz), L=(1.0, 1.0, Lz),
                  media=[Medium("forward", mua=mua, mus=50.0, g=1.0, n=1.0)])
    model.MC.boundary_type = 3
    model.MC.n_photons_requested = Nph
    MC = model.run_monte_carlo().MC
    layer = MC.NA.sum(axis=(0, 1)) * model.G.dx * model.G.dy * model.G.dz
    edges = np.arange(nz + 1) * model.G.dz
    exact = np.exp(-mua * edges[:-1]) - np.exp(-mua * edges[1:])
    # implicit capture spreads a packet over its path: its deposit in a layer lies in
    # [0, 1], so the Bernoulli bound holds
    assert np.all(np.abs(layer - exact) < 4 * np.sqrt(exact * (1 - exact) / Nph))
    assert MC.escaped["top"] == 0.0  # nothing turns back


def hg(g):
    return lambda theta: (1 - g * g) / (1 + g * g - 2 * g * np.cos(theta)) ** 1.5


def test_tabulated_phase_function_is_sampled_with_its_moments():
    """Draw the scattering cosine from tables: HG (g = 0.9) has mean cosine g; Rayleigh
    (MCmatlab example 21, 1 + cos^2) has E[cos^2] = 0.4."""
    import numba

    from mcmatlab_py.light._sources import sample_pwl
    from mcmatlab_py.monte_carlo.optics import phase_function_table

    @numba.njit
    def cosines(tab, n, k):
        out = np.empty(k)
        for i in range(k):
            out[i] = math.cos(math.pi * sample_pwl(tab, 0, n, (i + 0.5) / k))
        return out

    k = 400_000  # stratified uniforms: the errors are well below the random-sampling bound
    for f, moment, exact, sd in ((hg(0.9), 1, 0.9, math.sqrt((1 - 0.81) / 3)),
                                 (lambda t: 1 + np.cos(t) ** 2, 2, 0.4, math.sqrt(9 / 35 - 0.16))):
        tab = phase_function_table(Medium("t", 0, 1, custom_phase_func=f))
        mu = cosines(tab, tab.size // 2, k)
        assert abs((mu**moment).mean() - exact) < 4 * sd / math.sqrt(k)


def test_tabulated_hg_reproduces_the_mcml_slab():
    """MCML manual Table 6.1 (van de Hulst): as tests/test_mc_physics.py with built-in HG."""
    Nph = 100_000
    model = block(n=(1, 1, 4), L=(1.0, 1.0, 0.02),
                  media=[Medium("slab", mua=10.0, mus=90.0, custom_phase_func=hg(0.75))])
    model.MC.boundary_type = 3
    model.MC.n_photons_requested = Nph
    MC = model.run_monte_carlo().MC
    assert abs(MC.escaped["top"] - 0.09739) < 3 * se(0.09739, Nph)
    assert abs(MC.escaped["bottom"] - 0.66096) < 3 * se(0.66096, Nph)


def test_new_features_same_seed_same_result_any_thread_count():
    import numba

    def run(threads):
        model = block(n=(16, 16, 8), L=(0.4, 0.4, 0.2),
                      media=[Medium("a", mua=1.0, mus=50.0, g=0.8, n=1.0),
                             Medium("b", mua=2.0, mus=80.0, n=1.4, custom_phase_func=hg(0.7))])
        model.G.geom_func = lambda X, Y, Z: (X**2 + Y**2 + (Z - 0.2) ** 2 < 0.12**2).astype(int)
        model.MC.matched_interfaces = False
        model.MC.n_photons_requested = 4000
        model.MC.n_threads = threads
        src = model.MC.light_source
        src.source_type, src.theta, src.z_focus = 4, 0.2, 0.1
        src.focal_plane_intensity_distribution.radial_distr = 1
        src.focal_plane_intensity_distribution.radial_width = 0.05
        src.angular_intensity_distribution.radial_distr = 2
        return model.run_monte_carlo().MC

    a, b = run(1), run(min(2, numba.config.NUMBA_NUM_THREADS))
    np.testing.assert_array_equal(a.NA, b.NA)
    assert a.energy_balance == pytest.approx(1.0, abs=1e-9)


def test_source_distribution_runs_end_to_end():
    model = block(n=(8, 8, 8), L=(0.4, 0.4, 0.4),
                  media=[Medium("absorber", mua=100.0, mus=0.0, g=0.0, n=1.0)])
    S = np.zeros((8, 8, 8))
    S[4, 4, 4] = 1.0
    model.MC.source_distribution = S
    model.MC.n_photons_requested = 5000
    MC = model.run_monte_carlo().MC
    assert MC.missed_fraction == 0.0
    assert MC.NA[4, 4, 4] == MC.NA.max()
    assert MC.energy_balance == pytest.approx(1.0, abs=1e-9)


@pytest.mark.parametrize(
    "setup, pattern",
    [
        (lambda s, M: setattr(s, "source_type", 7), r"source_type .*got 7"),
        (lambda s, M: setattr(s, "source_type", "laser"), r"source_type .*'laser'"),
        (lambda s, M: setattr(s, "source_type", 4),
         r"focal_plane_intensity_distribution\.radial_distr must be set"),
        (lambda s, M: (setattr(s, "source_type", "radial"),
                       setattr(s.focal_plane_intensity_distribution, "radial_distr", 2)),
         r"radial_distr must be 0 \(top-hat\), 1 \(Gaussian\) or an array, got 2"),
        (lambda s, M: setattr(s, "theta", math.pi / 2), r"theta must aim the beam"),
        (lambda s, M: setattr(s, "emitter_length", -1), r"emitter_length must be >= 0, got -1"),
        (lambda s, M: (setattr(s, "source_type", "xy"),
                       setattr(s, "focal_plane_intensity_distribution",
                               type(s.focal_plane_intensity_distribution)(0, None, 0, 0.1, 0, 0.1)),
                       setattr(s, "angular_intensity_distribution",
                               type(s.angular_intensity_distribution)(None, None, 2, None, 0, 0.1))),
         r"x_distr and \.y_distr must both be Lambertian"),
        (lambda s, M: setattr(M, "source_distribution", np.ones((2, 2, 2))),
         r"source_distribution must have the shape"),
        (lambda s, M: setattr(M, "smoothing_length_scale", -1.0),
         r"smoothing_length_scale must be >= 0"),
    ],
)
def test_bad_sources_raise_value_errors_naming_the_field(setup, pattern):
    model = block()
    model.MC.n_photons_requested = 10
    setup(model.MC.light_source, model.MC)
    with pytest.raises(ValueError, match=pattern):
        model.run_monte_carlo()


def test_mcmatlab_names_and_codes():
    model = block()
    src = model.MC.light_source
    with pytest.raises(AttributeError, match="focal_plane_intensity_distribution"):
        src.FPID  # noqa: B018
    with pytest.raises(AttributeError, match="emitter_length"):
        src.emitterLength = 0.1
    with pytest.raises(AttributeError, match="radial_distr"):
        src.focal_plane_intensity_distribution.radialDistr = 1
    with pytest.raises(ValueError, match="custom_phase_func"):
        Medium("m", 1, 1, custom_phase_func=[1.0])
