"""The general kernel's free moves through runs of voxels of one kind of medium.

:mod:`mcmatlab_py.monte_carlo.safety` gives each voxel the distance within which a packet meets no
voxel of other optics, and the kernel moves a whole free path there at once
(:mod:`mcmatlab_py.monte_carlo._kernel`). These tests hold the distances against a brute-force
search, and the moves against the walk face by face that a safety map of zeros gives
(the kernel's behaviour before free moves): with matched interfaces the two cross the same
voxels and draw the same random numbers, so the same seed gives the same numbers up to
the rounding of positions; with refraction, where a rounding can tip a decision about a
smoothed normal, the two agree within the photon noise. Media of similar attenuation
form groups crossed by delta tracking (:func:`mcmatlab_py.monte_carlo.safety.delta_groups`):
other random numbers, so these agree with the walk within the photon noise.
"""

import itertools
import math

import numba
import numpy as np
import pytest

from mcmatlab_py import Medium, Model
from mcmatlab_py.monte_carlo import host as mc
from mcmatlab_py.monte_carlo import safety
from mcmatlab_py.monte_carlo.safety import (
    delta_groups,
    medium_kinds,
    navigation_safety,
    safety_distances,
)


def test_safety_is_the_distance_to_the_nearest_voxel_of_another_kind():
    """Against the distance between voxel boxes, by brute force, on a random grid of three
    kinds with unequal voxel sides; a kind alone in the grid has no limit."""
    rng = np.random.default_rng(4)
    M = rng.choice(3, size=(7, 6, 5), p=[0.8, 0.15, 0.05])
    d = (0.01, 0.02, 0.015)
    got = safety_distances(M, np.arange(3), d).reshape(M.shape)
    for v in itertools.product(*map(range, M.shape)):
        others = np.argwhere(M != M[v])
        gap = np.maximum(np.abs(others - np.array(v)) - 1, 0) * np.array(d)
        exact = np.sqrt((gap**2).sum(axis=1)).min()
        assert exact * (1 - 2e-6) <= got[v] <= exact, (v, got[v], exact)
    assert np.all(safety_distances(np.zeros((3, 4, 5), int), np.arange(1), d) == np.inf)


def test_media_of_equal_optics_are_one_kind():
    mua, mus, g, n = (np.array(a, float) for a in ([1, 1, 1, 2], [100, 100, 100, 100],
                                                     [0.9, 0.9, 0.8, 0.9], [1.3, 1.3, 1.3, 1.3]))
    k = medium_kinds(mua, mus, g, n)
    assert k[0] == k[1] and len(set(k)) == 3
    assert len(set(medium_kinds(mua, mus, g, n, np.array([-1, 0, -1, -1])))) == 4  # a table
    assert len(set(medium_kinds(mua, mus, g, n, by_medium=True))) == 4


def test_a_voxel_of_an_identical_medium_leaves_the_block_one_kind():
    """The paper's block with one voxel of a copy of its tissue: no limit anywhere (the
    free moves of one medium); a voxel of other optics limits the moves around it."""
    assert np.all(_safety(_block(Medium("copy", mua=1.0, mus=100.0, g=0.9, n=1.3))) == np.inf)
    safe = _safety(_block(Medium("other", mua=2.0, mus=100.0, g=0.9, n=1.3)))
    assert safe[0, 0, -1] == 0.0 and safe[1, 1, -2] == 0.0
    assert safe[3, 0, -1] == pytest.approx(0.1, rel=1e-5)  # two voxels of 0.05 cm between


def _block(second: Medium) -> Model:
    model = Model()
    G = model.G
    G.nx, G.ny, G.nz = 10, 10, 5
    G.Lx, G.Ly, G.Lz = 0.5, 0.5, 0.25
    G.media = [Medium("tissue", mua=1.0, mus=100.0, g=0.9, n=1.3), second]

    def corner(X, Y, Z):
        M = np.zeros(X.shape, dtype=int)
        M[0, 0, -1] = 1
        return M

    G.geom_func = corner
    model.MC.n_photons_requested = 1000
    model.MC.progress = False
    return model


def _safety(model) -> np.ndarray:
    """(nx, ny, nz) the safety distances of ``model``'s grid, as a run computes them."""
    G = model.G
    kinds = medium_kinds(*mc.optical_arrays(G.media, model.MC.wavelength))
    return safety_distances(G.medium_map(), kinds, (G.dx, G.dy, G.dz)).reshape(G.nx, G.ny,
                                                                              G.nz)


def _tophat_run(model: Model, n_photons: int, seed: int, *, matched: bool = True,
                boundary_type: int = 1, radius: float = 0.05) -> Model:
    """``model`` set to run ``n_photons`` of a top-hat beam of ``radius`` cm."""
    MC = model.MC
    MC.n_photons_requested = n_photons
    MC.seed = seed
    MC.progress = False
    MC.matched_interfaces = matched
    MC.boundary_type = boundary_type
    MC.light_source.source_type = "tophat"
    MC.light_source.radius = radius
    return model


def _general_args(model: Model) -> tuple:
    """The general kernel's arguments of ``model`` (as a run with a thin medium has them)."""
    args = mc.kernel_args(model.G, model.MC, model.G.medium_map(),
                          *mc.optical_arrays(model.G.media, model.MC.wavelength), 1,
                          model.MC.n_photons_requested)
    return (*args[:5], -1, *args[6:])


def _vessel_model(shape: tuple, size: tuple, media: list, tops: tuple, vessel: tuple
                  ) -> Model:
    """Four media on a grid ``shape`` of ``size`` (Lx = Ly, Lz) cm: the first above the
    depth ``tops[0]``, the second down to ``tops[1]``, the third below, and the fourth in
    a vessel along y at depth ``vessel[0]`` of radius ``vessel[1]``."""
    model = Model()
    G = model.G
    G.nx, G.ny, G.nz = shape
    G.Lx = G.Ly = size[0]
    G.Lz = size[1]
    G.media = media

    def geometry(X, Y, Z):
        M = np.zeros(X.shape, dtype=int)
        M[Z > tops[0]] = 1
        M[Z > tops[1]] = 2
        M[X**2 + (Z - vessel[0]) ** 2 < vessel[1] ** 2] = 3
        return M

    G.geom_func = geometry
    return model


def skin(n_photons: int, *, matched: bool = True, boundary_type: int = 1, seed: int = 3) -> Model:
    """Air (thin: its fluence is tallied along the path) over a layer, a dermis and a vessel
    of other optics, a top-hat beam: every kind of move of the kernel."""
    model = _vessel_model((24, 24, 20), (0.24, 0.2),
                          [Medium("air", mua=1e-8, mus=1e-8, g=1.0, n=1.0),
                           Medium("epidermis", mua=15.0, mus=300.0, g=0.8, n=1.45),
                           Medium("dermis", mua=1.0, mus=150.0, g=0.9, n=1.38),
                           Medium("blood", mua=50.0, mus=90.0, g=0.95, n=1.36)],
                          (0.03, 0.05), (0.1, 0.03))
    return _tophat_run(model, n_photons, seed, matched=matched, boundary_type=boundary_type)


def run(model, *, walk: bool = False, monkeypatch=None, threads: int | None = None):
    """``model``'s Monte Carlo; ``walk``: with a safety map of zeros (face by face)."""
    if walk:
        monkeypatch.setattr(mc, "kernel_safety",
                            lambda args, *_: np.zeros(args[0].size, np.float32))
    model.MC.n_threads = threads
    model.run_monte_carlo()
    if walk:
        monkeypatch.undo()
    return model


def slab_fractions(model) -> np.ndarray:
    """(nz,) fraction of the launched power absorbed in each voxel layer."""
    G = model.G
    return model.MC.NA.sum(axis=(0, 1)) * G.dx * G.dy * G.dz


@pytest.mark.parametrize("boundary_type", [1, 2, 3])
def test_free_moves_give_the_numbers_of_the_walk_face_by_face(boundary_type, monkeypatch):
    """Matched interfaces, no delta tracking (``DELTA_RATIO`` above 1), the same seed: the
    same escapes and layer absorptions to within the weight of 3 packets (a rounding that
    tipped a packet's voxel or face would move at most its own weight), and the same
    fluence rate in the air, where both split each path at the same voxel faces (each
    piece rounded to 2^-24 of a voxel's diagonal, so 1e-4 of the rate covers the
    rounding)."""
    monkeypatch.setattr(safety, "DELTA_RATIO", 2.0)
    N = 3000
    free = run(skin(N, boundary_type=boundary_type))
    walk = run(skin(N, boundary_type=boundary_type), walk=True, monkeypatch=monkeypatch)
    monkeypatch.undo()
    a, b = free.MC, walk.MC
    for face in ("top", "bottom", "sides"):
        assert abs(a.escaped[face] - b.escaped[face]) <= 3 / N
    np.testing.assert_allclose(slab_fractions(free), slab_fractions(walk), rtol=0, atol=3 / N)
    air = free.G.medium_map() == 0
    np.testing.assert_allclose(a.NFR[air], b.NFR[air], rtol=1e-4, atol=0)
    assert a.NFR[air].max() > 0.0


def test_free_moves_agree_with_the_walk_at_refracting_interfaces(monkeypatch):
    """Mismatched interfaces with MCmatlab's smoothed normals, only the top face escaping:
    the absorption per medium and the escape agree within 4 standard errors of the
    difference of two runs (bound sqrt(2 p (1 - p) / N) of a [0, 1] tally of mean p)."""
    N = 20_000
    free = run(skin(N, matched=False, boundary_type=2, seed=5))
    walk = run(skin(N, matched=False, boundary_type=2, seed=5), walk=True,
               monkeypatch=monkeypatch)
    assert free.MC.matched_interfaces is False and free.MC.smoothing_length_scale
    M = free.G.medium_map()
    dV = free.G.dx * free.G.dy * free.G.dz
    pairs = [(free.MC.escaped["top"], walk.MC.escaped["top"])]
    pairs += [(free.MC.NA[M == k].sum() * dV, walk.MC.NA[M == k].sum() * dV) for k in (1, 2, 3)]
    for p, q in pairs:
        m = 0.5 * (p + q)
        assert abs(p - q) < 4 * math.sqrt(2 * m * (1 - m) / N) + 1e-12, (p, q)


def test_groups_of_delta_tracking():
    """Kinds of one refractive index join the group of the largest attenuation not yet
    grouped while theirs is at least DELTA_RATIO (0.7) of it; a medium tallied along the
    path, one of infinite n or of no attenuation stays alone; a medium absent from the grid
    joins but sets no majorant."""
    mua = np.array([10.0, 1.0, 50.0, 1.0, 1.0, 0.0, 2.0, 1e-8])
    mus = np.array([390.0, 350.0, 280.0, 100.0, 100.0, 0.0, 390.0, 1e-8])
    n = np.array([1.4, 1.4, 1.4, 1.4, 1.4, 1.0, np.inf, 1.0])
    kinds = medium_kinds(mua, mus, np.full(8, 0.9), n)
    present = np.array([True, True, True, True, False, True, True, True])
    group, maj, merged = delta_groups(kinds, mua, mus, n, present)
    assert group[0] == group[1] == group[2]  # 400, 351, 330: within 0.7 of 400
    assert group[3] == group[4] and group[3] != group[0]  # 101 (an identical medium, absent)
    assert np.all(maj[:3] == 400.0) and maj[3] == 101.0
    assert list(merged) == [True] * 3 + [False] * 5
    assert len({*group[5:], group[0], group[3]}) == 5  # no attenuation, infinite n, alone
    track = np.zeros(8, bool)
    track[1] = True  # tallied along the path: out of the group
    group, maj, merged = delta_groups(kinds, mua, mus, n, present, track)
    assert group[0] == group[2] != group[1] and maj[2] == 400.0 and not merged[1]
    group, _, merged = delta_groups(kinds, mua, mus, n, present, ratio=2.0)
    assert not merged.any() and np.array_equal(group, kinds)
    n2 = n.copy()
    n2[1] = 1.33  # another refractive index: another group
    group, maj, _ = delta_groups(kinds, mua, mus, n2, present)
    assert group[0] == group[2] != group[1] and maj[1] == 351.0


def test_delta_balls_lie_where_the_walk_goes_face_by_face():
    """A layer of another kind of the same group in a block, a medium of another group
    below: the voxels next to the layer (exact safety 0) get minus the distance to the
    other group, every other voxel its exact safety; without groups the exact one."""
    M = np.zeros((6, 6, 12), int)
    M[:, :, 3] = 1  # a thin layer of a similar medium
    M[:, :, 10:] = 2  # another group
    kinds = np.arange(3)
    group = np.array([0, 0, 2])
    merged = np.array([True, True, False])
    d = (0.01, 0.01, 0.01)
    exact = safety_distances(M, kinds, d).reshape(M.shape)
    got = navigation_safety(M, kinds, group, merged, d).reshape(M.shape)
    far = safety_distances(M, group, d).reshape(M.shape)
    delta = got < 0
    assert np.array_equal(delta[0, 0], [False, False, True, True, True, False, False, False,
                                        False, False, False, False])
    np.testing.assert_array_equal(got[delta], -far[delta])
    np.testing.assert_array_equal(got[~delta], exact[~delta])
    assert np.all(far[delta] > 0) and np.all(exact[delta] == 0)
    np.testing.assert_array_equal(navigation_safety(M, kinds, kinds, np.zeros(3, bool), d),
                                  exact.ravel())


def laminate(n_photons: int, seed: int = 7) -> Model:
    """Layers one voxel thick of two similar media (145 and 150.5 cm^-1, of other albedos
    and g) under a thin air layer: every tissue voxel touches the other kind, so the
    packets cross the tissue by delta tracking (but in its top layer, next to the air)."""
    model = Model()
    G = model.G
    G.nx, G.ny, G.nz = 16, 16, 20
    G.Lx = G.Ly = 0.16
    G.Lz = 0.06
    G.media = [Medium("air", mua=1e-8, mus=1e-8, g=1.0, n=1.0),
               Medium("absorbing", mua=5.0, mus=140.0, g=0.8, n=1.4),
               Medium("scattering", mua=0.5, mus=150.0, g=0.9, n=1.4)]

    def geometry(X, Y, Z):
        M = 1 + (np.round(Z / 0.003 - 0.5).astype(int) % 2)
        M[Z < 0.006] = 0
        return M

    G.geom_func = geometry
    return _tophat_run(model, n_photons, seed)


def test_delta_tracking_agrees_with_the_walk_face_by_face(monkeypatch):
    """The absorption per medium and per layer and the escape per face of the laminate,
    crossed by delta tracking, agree with the walk face by face within 4 standard errors
    of the difference of two runs (bound sqrt(2 p (1 - p) / N) of a [0, 1] tally of mean
    p). Measured with this seed: real interactions 10% too many in the delta balls moved
    the bottom escape by 5.1 of these errors, the interaction left with the medium of the
    ball's last look-up the absorbing layers' share by 43."""
    N = 100_000
    model = laminate(N)
    args = _general_args(model)
    safe = mc.kernel_safety(args, None, mc.track_media(args))
    tissue = model.G.medium_map().ravel() > 0
    assert np.all(safe[tissue] <= 0) and (safe[tissue] < 0).mean() > 0.9  # 0: next to air
    assert np.all(safe[~tissue] >= 0)
    free = run(model)
    walk = run(laminate(N), walk=True, monkeypatch=monkeypatch)
    M = free.G.medium_map()
    dV = free.G.dx * free.G.dy * free.G.dz
    pairs = [(free.MC.escaped[f], walk.MC.escaped[f]) for f in ("top", "bottom", "sides")]
    pairs += [(free.MC.NA[M == k].sum() * dV, walk.MC.NA[M == k].sum() * dV) for k in (1, 2)]
    pairs += list(zip(slab_fractions(free), slab_fractions(walk), strict=True))
    for p, q in pairs:
        m = 0.5 * (p + q)
        assert abs(p - q) < 4 * math.sqrt(2 * m * (1 - m) / N) + 1e-12, (p, q)


def gel_over_skin(n_photons: int, seed: int) -> Model:
    """MCmatlab's Example 4 on 20^3 voxels (its optics at 577 nm): a gel over an epidermis
    one voxel thick, a dermis and a vessel, matched. The voxels next to the epidermis and
    the vessel cross by delta tracking, the rest of the dermis by free moves: packets pass
    from one to the other."""
    model = _vessel_model((20, 20, 20), (0.1, 0.1),
                          [Medium("gel", mua=3.6e-4, mus=10.0, g=1.0, n=1.0),
                           Medium("epidermis", mua=16.57, mus=375.9, g=0.9, n=1.0),
                           Medium("dermis", mua=0.4585, mus=356.5, g=0.9, n=1.0),
                           Medium("blood", mua=230.5, mus=94.0, g=0.9, n=1.0)],
                          (0.01, 0.016), (0.05, 0.01))
    return _tophat_run(model, n_photons, seed, radius=0.03)


def test_delta_tracking_and_free_moves_together_agree_with_the_walk(monkeypatch):
    """Example 4's tissue: the absorption of each voxel layer and of each medium and the
    escape per face, 6 runs of 3 x 10^5 packets each way (other seeds), agree with the walk
    face by face within 4 standard errors of the difference of the means (from the runs'
    spread). A kernel whose packets change between a ball of delta tracking and one of
    free moves before using up the ball they are in (their optical depth already known to
    exceed it) puts 0.9% too little in the second dermis layer: 10.3 of these errors."""
    K, N = 6, 300_000

    def tallies(model):
        MC, G = model.MC, model.G
        M = G.medium_map()
        dV = G.dx * G.dy * G.dz
        return np.r_[MC.NA.sum(axis=(0, 1)) * dV, [MC.NA[M == k].sum() * dV for k in range(4)],
                     [MC.escaped[f] for f in ("top", "bottom", "sides")]]

    model = gel_over_skin(N, 0)
    args = _general_args(model)
    safe = mc.kernel_safety(args, None, mc.track_media(args))
    assert (safe < 0).mean() > 0.05 and (safe > 0).mean() > 0.5  # both kinds of ball
    free = np.array([tallies(run(gel_over_skin(N, 100 + k))) for k in range(K)])
    monkeypatch.setattr(mc, "kernel_safety",
                        lambda args, *_: np.zeros(args[0].size, np.float32))
    walk = np.array([tallies(run(gel_over_skin(N, 200 + k))) for k in range(K)])
    se = np.sqrt(free.var(axis=0, ddof=1) / K + walk.var(axis=0, ddof=1) / K)
    z = (free.mean(axis=0) - walk.mean(axis=0)) / np.where(se > 0, se, 1.0)
    assert np.abs(z).max() < 4.0, np.round(z, 2)


def test_the_skin_model_crosses_its_dermis_and_vessel_by_delta_tracking():
    """With matched interfaces the dermis (151 cm^-1) and the vessel (140) form one group:
    the voxels where they meet get balls of delta tracking."""
    model = skin(100)
    args = _general_args(model)
    _, _, maj, merged = mc.kernel_groups(args, None, mc.track_media(args))
    assert list(merged) == [False, False, True, True] and maj[3] == 151.0
    safe = mc.kernel_safety(args, None, mc.track_media(args)).reshape(model.G.medium_map().shape)
    M = model.G.medium_map()
    assert (safe < 0).any() and np.all(np.isin(M[safe < 0], [2, 3]))


def test_heterogeneous_tissue_gives_the_same_numbers_for_any_thread_count():
    runs = [run(skin(3000, matched=False, boundary_type=3), threads=t).MC
            for t in (1, min(2, numba.config.NUMBA_NUM_THREADS))]
    np.testing.assert_array_equal(runs[0].NA, runs[1].NA)
    np.testing.assert_array_equal(runs[0].NFR, runs[1].NFR)
    assert runs[0].escaped == runs[1].escaped
