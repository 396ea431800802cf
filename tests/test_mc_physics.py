"""Monte Carlo light transport against analytic and published results.

Tolerances come from the photon count. A packet's contribution X to any tally
(a reflectance, the power absorbed in a layer) lies in [0, 1], so its variance is
at most p (1 - p) with p = E[X] (the Bernoulli case is the worst): the standard
error of a tally over N packets is at most sqrt(p (1 - p) / N). Tests allow a
few of these bounds.
"""

import math

import numpy as np
import pytest

from mcmatlab_py import Medium, Model


def se_bound(p: float, n: int) -> float:
    """Upper bound of the standard error of a [0, 1]-valued tally with mean p over n packets."""
    return math.sqrt(max(p * (1 - p), 1e-300) / n)


def slab_model(mua, mus, g, d, n_photons, *, n=1.0, nz=4, seed=3, matched=True):
    """Laterally infinite slab of thickness d (cm): cyclic sides, top and bottom escape."""
    model = Model()
    model.G.nx, model.G.ny, model.G.nz = 1, 1, nz
    model.G.Lx, model.G.Ly, model.G.Lz = 1.0, 1.0, d
    model.G.media = [Medium("slab", mua=mua, mus=mus, g=g, n=n)]
    model.MC.boundary_type = 3
    model.MC.matched_interfaces = matched
    model.MC.n_photons_requested = n_photons
    model.MC.seed = seed
    model.MC.progress = False
    model.MC.light_source.source_type = "pencil"
    return model


@pytest.mark.parametrize("kernel", ["general", "one-medium"])
def test_mcml_table_6_1_van_de_hulst(kernel):
    """MCML manual Table 6.1 (van de Hulst 1980): n = 1, mua = 10, mus = 90, g = 0.75, d = 0.02 cm.

    Cyclic sides run the general kernel; a block 4 cm wide whose faces all escape runs the
    one-medium kernel (what reaches its sides, 2 cm away through mua = 10, is below 1e-8)."""
    N = 200_000
    model = slab_model(10.0, 90.0, 0.75, 0.02, N)
    if kernel == "one-medium":
        model.G.Lx = model.G.Ly = 4.0
        model.MC.boundary_type = 1
    MC = model.run_monte_carlo().MC
    Rd, Tt = MC.escaped["top"], MC.escaped["bottom"]
    assert MC.specular_reflectance == 0.0
    assert abs(Rd - 0.09739) < 3 * se_bound(0.09739, N)
    assert abs(Tt - 0.66096) < 3 * se_bound(0.66096, N)
    assert MC.escaped["sides"] < 1e-6  # cyclic sides never escape


def test_beer_lambert_depth_profile_is_exact():
    """mus = 0: a pencil beam deposits exp(-mua z_k) - exp(-mua z_{k+1}) in layer k."""
    N, mua, nz, Lz = 100_000, 4.0, 25, 0.5
    model = slab_model(mua, 0.0, 0.0, Lz, N, nz=nz)
    model.MC.boundary_type = 1
    MC = model.run_monte_carlo().MC
    G = model.G
    layer = MC.NA.sum(axis=(0, 1)) * G.dx * G.dy * G.dz  # absorbed fraction per layer
    edges = np.arange(nz + 1) * G.dz
    exact = np.exp(-mua * edges[:-1]) - np.exp(-mua * edges[1:])
    tol = 4 * np.sqrt(exact * (1 - exact) / N)
    assert np.all(np.abs(layer - exact) < tol)
    assert abs(MC.escaped["bottom"] - math.exp(-mua * Lz)) < 4 * se_bound(math.exp(-mua * Lz), N)
    # mut dz = 0.08 < THIN: the fluence rate is the track length. A packet's path in layer k
    # over dz is a [0, 1] tally whose mean is the layer's absorbed fraction over mua dz
    path = MC.NFR.sum(axis=(0, 1)) * G.dx * G.dy * G.dz / G.dz
    p = exact / (mua * G.dz)
    assert np.all(np.abs(path - p) < 4 * np.sqrt(p * (1 - p) / N))


def test_nfr_is_na_over_mua_where_packets_interact():
    """Voxels a packet rarely crosses without interacting (mut dz = 0.4): NFR = NA / mua."""
    N, mua, nz, Lz = 20_000, 4.0, 5, 0.5
    model = slab_model(mua, 0.0, 0.0, Lz, N, nz=nz)
    model.MC.boundary_type = 1
    MC = model.run_monte_carlo().MC
    np.testing.assert_allclose(MC.NFR, MC.NA / mua)


def _air_column(absorber_mua=None, n_photons=2000, threads=None):
    """A pencil beam down the middle column of 5 x 5 x 10 voxels of air (mua = mus = 1e-8,
    MCmatlab's air), or of air over an absorber below z = 0.05 cm."""
    model = Model()
    G = model.G
    G.nx = G.ny = 5
    G.nz = 10
    G.Lx = G.Ly = G.Lz = 0.1
    air = Medium("air", mua=1e-8, mus=1e-8, g=1.0)
    if absorber_mua is None:
        G.media = [air]
        G.geom_func = lambda X, Y, Z: np.zeros(X.shape, dtype=int)
    else:
        G.media = [air, Medium("absorber", mua=absorber_mua, mus=0.0, g=0.0)]
        G.geom_func = lambda X, Y, Z: np.where(Z > 0.05, 1, 0)
    model.MC.n_photons_requested = n_photons
    model.MC.seed = 2
    model.MC.progress = False
    model.MC.n_threads = threads
    model.MC.light_source.source_type = "pencil"
    return model.run_monte_carlo()


def test_fluence_rate_in_air_is_the_beam():
    """MCmatlab's air: no packet interacts, yet the fluence rate along the beam is 1 / (dx dy)
    (every packet crosses each voxel of the column, dz in each; NFR = path / (N dV)); zero
    beside it; NA (interactions) stays 0."""
    for absorber in (None, 50.0):  # air alone (one medium), air over an absorber
        model = _air_column(absorber)
        G, MC = model.G, model.MC
        beam = 1.0 / (G.dx * G.dy)
        top = MC.NFR[:, :, :5] if absorber else MC.NFR
        np.testing.assert_allclose(top[2, 2], beam, rtol=1e-6)
        rest = top.copy()
        rest[2, 2] = 0.0
        assert np.all(rest == 0.0)
        assert np.all(MC.NA[:, :, :5] == 0.0)  # no packet interacts in the air
        if absorber:  # mut dz = 0.5: NFR = NA / mua below
            np.testing.assert_allclose(MC.NFR[:, :, 5:], MC.NA[:, :, 5:] / absorber)


@pytest.mark.parametrize("below", [None, "clear"])
def test_fluence_rate_where_packets_interact_but_hardly_absorb(below):
    """Air that scatters straight on (mus = 100 cm^-1, g = 1) and absorbs 1e-10 of the weight
    per interaction (mua = 1e-8): NFR = NA / mua is the beam's 1 / (dx dy) in every voxel of
    the column, the first included, with one medium (the one-medium kernel) or a second of
    the same attenuation and another index below it (the general kernel, delta tracking
    across the interface). The collision estimator's relative standard error is
    1 / sqrt(mut dz N) (Poisson collisions, straight paths); a deposit's fraction of a
    fixed-point unit carried to the next interaction had left the first voxel 0.7% low."""
    n_photons, mut, dz = 100_000, 100.0, 0.1
    model = Model()
    G = model.G
    G.nx = G.ny = 5
    G.nz = 10
    G.Lx = G.Ly = 0.5
    G.Lz = 1.0
    air = Medium("air", mua=1e-8, mus=mut - 1e-8, g=1.0)
    under = None if below is None else Medium("clear", mua=1e-8, mus=mut - 1e-8, g=1.0, n=1.4)
    if under is None:
        G.media = [air]
        G.geom_func = lambda X, Y, Z: np.zeros(X.shape, dtype=int)
    else:
        G.media = [air, under]
        G.geom_func = lambda X, Y, Z: (Z > 0.1).astype(int)
    MC = model.MC
    MC.n_photons_requested = n_photons
    MC.seed = 5
    MC.progress = False
    MC.boundary_type = 1
    MC.matched_interfaces = True
    MC.light_source.source_type = "pencil"
    MC = model.run_monte_carlo().MC
    column = MC.NFR[2, 2] * G.dx * G.dy
    se = 1.0 / math.sqrt(mut * dz * n_photons)
    z = (column - 1.0) / se
    assert np.all(np.abs(z) < 4), z
    assert abs(z[0]) < 4  # the first voxel, where the carried fractions had biased it


def test_calc_normalized_fluence_rate_false_skips_the_track_length():
    """MCmatlab's calcNormalizedFluenceRate = false: no track-length tally, NFR = NA / mua
    (the air empty again), NA the same to the bit."""
    model = _air_column(50.0)
    ref = model.MC.NA.copy()
    model.MC.calc_normalized_fluence_rate = False
    MC = model.run_monte_carlo().MC
    np.testing.assert_array_equal(MC.NA, ref)
    np.testing.assert_allclose(MC.NFR, MC.NA / np.where(model.G.medium_map() == 1, 50.0, 1e-8))
    assert np.all(MC.NFR[:, :, :5] == 0.0)
    model.MC.calc_normalized_fluence_rate = "no"
    with pytest.raises(ValueError, match="calc_normalized_fluence_rate must be True or False"):
        model.run_monte_carlo()


def test_track_length_fluence_same_for_any_thread_count():
    a = _air_column(50.0, threads=1).MC
    b = _air_column(50.0, threads=2).MC
    np.testing.assert_array_equal(a.NFR, b.NFR)
    np.testing.assert_array_equal(a.NA, b.NA)


def test_track_length_and_absorption_estimate_the_same_power():
    """A thin scattering medium (mut dz = 0.06): mua x the track length and the deposits are
    two estimators of one absorbed power (implicit capture deposits w mua / mut where a
    packet interacts, mut times per cm). Their difference over 8 independent runs, within 4
    standard errors of its own scatter."""
    d = []
    for seed in range(8):
        model = slab_model(1.0, 5.0, 0.8, 0.1, 5000, nz=10, seed=seed + 1)
        MC = model.run_monte_carlo().MC
        G = model.G
        dV = G.dx * G.dy * G.dz
        d.append((MC.NFR.sum() * 1.0 - MC.NA.sum()) * dV)
    d = np.array(d)
    assert abs(d.mean()) < 4 * d.std(ddof=1) / math.sqrt(len(d))
    assert d.std() > 0  # the two estimators differ run by run: the test can fail


def test_wide_sums_are_exact_past_int64():
    """The fixed-point totals of a long run: exact integers past 2^63, rounded once."""
    from mcmatlab_py.monte_carlo import WideSums

    rng = np.random.default_rng(5)
    parts = [rng.integers(-2**61, 2**62, size=7, dtype=np.int64) for _ in range(40)]
    exact = [sum(int(p[i]) for p in parts) for i in range(7)]
    assert max(abs(e) for e in exact) > 2**63  # past what int64 holds
    a, b = WideSums(), WideSums()
    for k, p in enumerate(parts):
        (a if k % 2 else b).add("x", p)
    a.merge(b)
    assert a.value("x").tolist() == [float(e) for e in exact]
    small = WideSums()
    small.add("x", parts[0])
    assert small.value("x").tolist() == parts[0].astype(np.float64).tolist()


def test_moving_the_sums_often_changes_no_bit(monkeypatch):
    """Where a run moves its int64 sums into the wide ones does not change any number."""
    import mcmatlab_py.monte_carlo.host as mc

    def run(flush, threads):
        monkeypatch.setattr(mc, "FLUSH_PHOTONS", flush)
        model = slab_model(2.0, 50.0, 0.8, 0.1, 20_000, nz=5)
        model.MC.n_threads = threads
        MC = model.run_monte_carlo().MC
        return MC.NA.copy(), MC.escaped["top"], MC.absorbed_fraction

    ref = run(2**25, 2)
    for flush, threads in ((1000, 1), (3000, 2)):
        other = run(flush, threads)
        np.testing.assert_array_equal(other[0], ref[0])
        assert other[1:] == ref[1:]


@pytest.mark.slow
@pytest.mark.slow
def test_a_run_past_int64_fixed_point_keeps_its_energy():
    """2^27 packets of weight W_ONE = 2^36 fill int64: a longer run (a GPU's second, two
    minutes on two cores of a slow kernel) must still balance. A thin absorbing slab with
    mus = 0 (about 8 s on two cores): a packet is absorbed with chance 1 - exp(-mua d)."""
    N, mua, d = 2**27 + 2**24, 69.3, 0.01
    model = slab_model(mua, 0.0, 0.0, d, N, nz=1)
    model.MC.boundary_type = 1
    MC = model.run_monte_carlo().MC
    f = 1.0 - math.exp(-mua * d)
    assert MC.n_photons == N
    assert MC.energy_balance == pytest.approx(1.0, abs=1e-12)
    assert abs(MC.absorbed_fraction - f) < 4 * se_bound(f, N)
    assert abs(MC.escaped["bottom"] - (1 - f)) < 4 * se_bound(f, N)
    G = model.G
    assert MC.NA.sum() * G.dx * G.dy * G.dz == pytest.approx(MC.absorbed_fraction, rel=1e-12)


def test_fresnel_lossless_slab_total_reflectance():
    """Non-absorbing, non-scattering slab (n = 1.5) in air: R_total = 2 R / (1 + R) at normal incidence."""
    N, n = 100_000, 1.5
    model = slab_model(0.0, 0.0, 0.0, 0.1, N, n=n, matched=False)
    model.MC.boundary_type = 1
    MC = model.run_monte_carlo().MC
    R = ((n - 1) / (n + 1)) ** 2
    assert MC.specular_reflectance == pytest.approx(R, rel=1e-9)
    total_R = MC.specular_reflectance + MC.escaped["top"]
    assert abs(total_R - 2 * R / (1 + R)) < 4 * se_bound(2 * R / (1 + R), N)
    assert MC.energy_balance == pytest.approx(1.0, abs=1e-9)


@pytest.mark.parametrize("matched", [True, False])
@pytest.mark.parametrize("boundary_type", [0, 1, 2, 3])
def test_energy_is_conserved_exactly_without_roulette(matched, boundary_type):
    model = standard_tissue(12, 12, 6, n_photons=3000)
    model.MC.matched_interfaces = matched
    model.MC.boundary_type = boundary_type
    model.MC.russian_roulette = False
    MC = model.run_monte_carlo().MC
    assert MC.roulette_gain_fraction == 0.0
    total = (MC.absorbed_fraction + sum(MC.escaped.values()) + MC.specular_reflectance
             + MC.absorbed_outside_fraction + MC.killed_fraction + MC.missed_fraction)
    assert total == pytest.approx(1.0, abs=1e-9)
    if boundary_type == 1:
        assert MC.absorbed_outside_fraction == 0.0 and MC.killed_fraction == 0.0


def test_roulette_conserves_energy_in_expectation():
    N = 20_000
    model = standard_tissue(10, 10, 5, n_photons=N)
    model.G.Lx = model.G.Ly = model.G.Lz = 3.0  # big block: many packets reach roulette
    MC = model.run_monte_carlo().MC
    assert MC.energy_balance == pytest.approx(1.0, abs=1e-9)
    assert MC.roulette_gain_fraction != 0.0  # roulette did happen
    # a packet's net roulette gain lies in [-0.01, 0.09]: variance at most 0.1^2 / 4
    assert abs(MC.roulette_gain_fraction) < 4 * 0.05 / math.sqrt(N)
    assert MC.absorbed_fraction + sum(MC.escaped.values()) == pytest.approx(1.0, abs=4 * 0.05 / math.sqrt(N))


def standard_tissue(nx=20, ny=20, nz=10, n_photons=20_000, seed=1, source="tophat"):
    model = Model()
    model.G.nx, model.G.ny, model.G.nz = nx, ny, nz
    model.G.Lx, model.G.Ly, model.G.Lz = 0.5, 0.5, 0.25
    model.G.media = [Medium("standard tissue", mua=1.0, mus=100.0, g=0.9, n=1.3)]
    model.MC.n_photons_requested = n_photons
    model.MC.seed = seed
    model.MC.progress = False
    model.MC.light_source.source_type = source
    model.MC.light_source.radius = 0.1
    return model


@pytest.mark.parametrize("axis", [0, 1])
def test_centred_beam_is_symmetric_including_the_face_layers(axis):
    """x -> -x and y -> -y symmetry; the -x/-y face layers hold no excess (the mcxyz bug)."""
    N = 40_000
    # a pencil at x = 0 would sit on a voxel face and enter the +x voxel: use a disc
    model = standard_tissue(16, 16, 8, n_photons=N, source="tophat")
    model.G.Lx = model.G.Ly = 0.2  # narrow: many packets reach the side faces
    model.MC.light_source.radius = 0.05
    G, MC = model.G, model.run_monte_carlo().MC
    other = (1, 2) if axis == 0 else (0, 2)
    frac = MC.NA.sum(axis=other) * G.dx * G.dy * G.dz  # absorbed fraction per slice
    mirrored = frac[::-1]
    tol = 4.5 * np.sqrt((frac + mirrored) / N)
    assert np.all(np.abs(frac - mirrored) <= tol)
    assert frac[0] > 0 and frac[-1] > 0


def test_same_seed_same_result_any_thread_count():
    import numba

    results = []
    for threads in (1, min(2, numba.config.NUMBA_NUM_THREADS)):
        model = standard_tissue(n_photons=5000)
        model.MC.n_threads = threads
        results.append(model.run_monte_carlo().MC.NA)
    np.testing.assert_array_equal(results[0], results[1])
    other = standard_tissue(n_photons=5000, seed=2).run_monte_carlo().MC.NA
    assert not np.array_equal(results[0], other)


def test_atomic_counter_hands_out_each_batch_exactly_once():
    """The work queue of run_batches: every index claimed once, by whichever thread."""
    import numba

    from mcmatlab_py.monte_carlo._atomic import fetch_add

    @numba.njit(parallel=True)
    def claim(n_items, n_workers):
        counter = np.zeros(1, dtype=np.int64)
        owner = np.full(n_items, -1, dtype=np.int64)
        hits = np.zeros(n_items, dtype=np.int64)
        for k in numba.prange(n_workers):
            while True:
                i = fetch_add(counter, 0, 1)
                if i >= n_items:
                    break
                owner[i] = k
                hits[i] += 1
        return owner, hits

    owner, hits = claim(20_000, 4)
    np.testing.assert_array_equal(hits, 1)
    assert set(np.unique(owner)) <= {0, 1, 2, 3}


def test_noise_falls_as_one_over_sqrt_photons():
    """||NA(seed a) - NA(seed b)|| shrinks by 2 when the photon count grows by 4."""
    def spread(n):
        a = standard_tissue(n_photons=n, seed=11).run_monte_carlo().MC.NA
        b = standard_tissue(n_photons=n, seed=12).run_monte_carlo().MC.NA
        return np.linalg.norm(a - b)

    ratio = spread(10_000) / spread(40_000)
    assert 1.7 < ratio < 2.3


@pytest.mark.parametrize("matched, roulette", [(True, True), (False, True), (False, False)])
def test_voxel_walk_agrees_with_the_one_medium_kernel(matched, roulette):
    """Two identical media force the general kernel's voxel-by-voxel walk; a block of one
    medium runs the one-medium kernel (mcmatlab_py.monte_carlo._uniform), which draws its numbers
    differently: layer by layer and face by face the two agree within the photon noise of
    two independent runs."""
    N = 40_000
    fast = standard_tissue(n_photons=N)
    walk = standard_tissue(n_photons=N, seed=2)
    tissue = walk.G.media[0]
    walk.G.media = [tissue, Medium("copy", tissue.mua, tissue.mus, tissue.g, tissue.n)]
    walk.G.geom_func = lambda X, Y, Z: (Z > 0.1).astype(int)
    for model in (fast, walk):
        model.MC.matched_interfaces = matched
        model.MC.russian_roulette = roulette
        model.run_monte_carlo()
    G = fast.G
    a = fast.MC.NA.sum(axis=(0, 1)) * G.dx * G.dy * G.dz  # absorbed fraction per layer
    b = walk.MC.NA.sum(axis=(0, 1)) * G.dx * G.dy * G.dz
    p = 0.5 * (a + b)
    assert np.all(np.abs(a - b) < 4.5 * np.sqrt(2 * p * (1 - p) / N))
    for face in ("top", "bottom", "sides"):
        x, y = fast.MC.escaped[face], walk.MC.escaped[face]
        assert abs(x - y) < 4.5 * math.sqrt(2) * se_bound(0.5 * (x + y), N), face
    assert fast.MC.specular_reflectance == walk.MC.specular_reflectance
    assert fast.MC.energy_balance == pytest.approx(1.0, abs=1e-9)


def test_refractive_step_inside_the_grid_reflects():
    """A buried index step (n 1.0 over 1.5, no absorption or scattering) reflects R of a pencil beam."""
    N = 50_000
    model = slab_model(0.0, 0.0, 0.0, 0.2, N, nz=4, matched=False)
    model.MC.boundary_type = 1
    model.G.media = [Medium("air", 0, 0, 0, 1.0), Medium("glass", 0, 0, 0, 1.5)]
    model.G.geom_func = lambda X, Y, Z: (Z > 0.1).astype(int)
    MC = model.run_monte_carlo().MC
    R = (0.5 / 2.5) ** 2
    # enters through air (no specular), reflects at the step, then bounces in the glass
    expected_top = R + (1 - R) ** 2 * R / (1 - R * R)
    assert MC.specular_reflectance == 0.0
    assert abs(MC.escaped["top"] - expected_top) < 4 * se_bound(expected_top, N)


@pytest.mark.parametrize("source", ["pencil", "tophat", "gaussian", "plane_wave"])
def test_sources_launch_where_they_should(source):
    model = standard_tissue(20, 20, 4, n_photons=4000, source=source)
    model.G.media = [Medium("absorber", mua=1000.0, mus=0.0, g=0.0)]  # absorbed at entry
    MC = model.run_monte_carlo().MC
    top = MC.NA[:, :, 0] * model.G.dx * model.G.dy * model.G.dz
    X, Y = np.meshgrid(model.G.x, model.G.y, indexing="ij")
    r = np.hypot(X, Y)
    if source == "pencil":
        assert top[9:11, 9:11].sum() == pytest.approx(MC.absorbed_fraction)
    elif source == "tophat":
        assert top[r > 0.1 + model.G.dx].sum() == 0.0
    elif source == "gaussian":
        # 1/e^2 radius 0.1: a fraction 1 - e^-2 lies within r < 0.1
        inside = top[r < 0.1].sum() / top.sum()
        assert 0.75 < inside < 0.95
    else:
        assert np.all(top > 0)
    assert MC.missed_fraction == 0.0
