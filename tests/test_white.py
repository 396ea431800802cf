"""The perturbation ("white") Monte Carlo against the direct kernel, and the white build.

A packet's contribution to a layer's absorbed power or to the escaped power lies in
[0, 1] (up to the roulette gains of a survivor, at most 0.09 each, so we take [0, 1.1]):
the standard error of such a tally over N packets is at most sqrt(p (c - p) / N) with
c = 1.1 (the two-valued case is the worst). The white run and the direct run are
independent, so their difference has at most sqrt(se_w^2 + se_d^2); tests allow 4.5 of
those (about 7e-6 two-sided per comparison).
"""

import math

import numba
import numpy as np
import pytest

from mcmatlab_py._strict import NotBuiltError
from mcmatlab_py.emulator import (
    AbsorptionEmulator,
    EmulatorSpec,
    cache_key,
    resolve_method,
    symmetrize,
    white_supported,
)
from mcmatlab_py.emulator.white import white_absorbed, white_column
from mcmatlab_py.monte_carlo import _tally as K

C = 1.1


def se_bound(p: float, n: int) -> float:
    return math.sqrt(max(p * (C - p), 1e-300) / n)


def spec_(**kw):
    args = dict(nx=8, ny=8, nz=4, Lx=0.5, Ly=0.5, Lz=0.25, g=0.9, n=1.3, source_type="tophat",
                radius=0.1, n_photons=3000, seed=7)
    args.update(kw)
    return EmulatorSpec(**args)


def assert_same_tallies(white_maps, direct_maps, n_w, n_d, what):
    """Each tally (a sum of NA over a layer, in launched-power units) within 4.5 bounds."""
    for tw, td in zip(white_maps, direct_maps, strict=True):
        p = 0.5 * (tw + td)
        tol = 4.5 * math.hypot(se_bound(p, n_w), se_bound(p, n_d))
        assert abs(tw - td) <= tol, (what, tw, td, tol)


def compare(spec, mua, mus, n_w, n_d):
    res = white_absorbed(spec, mua, mus, n_photons=n_w, seed=11)
    for k, a in enumerate(mua):
        MC = spec.model(a, mus, n_photons=n_d, seed=12).run_monte_carlo().MC
        dV = spec.Lx * spec.Ly * spec.Lz / (spec.nx * spec.ny * spec.nz)
        direct = MC.NA * dV  # absorbed fraction per voxel
        white = res.absorbed[k] / n_w
        what = f"mua={a} mus={mus}"
        assert_same_tallies(white.sum((0, 1)), direct.sum((0, 1)), n_w, n_d, what + " z layers")
        assert_same_tallies(white.sum((1, 2)), direct.sum((1, 2)), n_w, n_d, what + " x slabs")
        assert_same_tallies([res.fraction(K.T_TOP)[k], white.sum()],
                            [MC.escaped["top"], MC.absorbed_fraction], n_w, n_d,
                            what + " escaped top, absorbed")


@pytest.mark.parametrize("mus", [10.0, 2000.0])
def test_white_equals_direct_at_the_table_edges(mus):
    """mua at both ends of the default table range (0.1, 20) and inside, one white run."""
    spec = spec_()
    n_w, n_d = (20000, 20000) if mus < 100 else (3000, 3000)
    compare(spec, np.array([0.1, 1.3, 20.0]), mus, n_w, n_d)


@pytest.mark.parametrize("matched, boundary_type, source",
                         [(False, 1, "tophat"), (False, 2, "gaussian"), (True, 3, "pencil"),
                          (True, 0, "isotropic_point"), (False, 1, "plane_wave")])
def test_white_equals_direct_interfaces_boundaries_sources(matched, boundary_type, source):
    spec = spec_(matched_interfaces=matched, boundary_type=boundary_type, source_type=source,
                 z_focus=0.1 if source == "isotropic_point" else 0.0)
    compare(spec, np.array([0.5, 4.0]), 100.0, 10000, 10000)


@pytest.mark.parametrize("roulette", [True, False])
def test_energy_balance_is_exact_for_every_mua(roulette, monkeypatch):
    spec = spec_(matched_interfaces=False)
    if not roulette:
        model = EmulatorSpec.model

        def no_roulette(self, *a, **kw):
            m = model(self, *a, **kw)
            m.MC.russian_roulette = False
            return m

        monkeypatch.setattr(EmulatorSpec, "model", no_roulette)
    res = white_absorbed(spec, [0.1, 2.0, 20.0], 300.0, n_photons=2000, seed=1)
    out = res.tally[[K.T_SPECULAR, K.T_TOP, K.T_BOTTOM, K.T_SIDES, K.T_OUTSIDE_ABSORBED,
                     K.T_KILLED, K.T_MISSED]].sum(axis=0)
    balance = res.absorbed.reshape(3, -1).sum(axis=1) + out - res.tally[K.T_ROULETTE]
    # fixed-point sums: exact up to the float division of the final totals
    np.testing.assert_allclose(balance, res.tally[K.T_LAUNCHED], rtol=1e-13)
    assert (res.tally[K.T_ROULETTE] != 0).any() == roulette


def test_same_seed_same_result_any_thread_count():
    spec = spec_()
    runs = [white_absorbed(spec, [0.3, 3.0], 200.0, n_photons=3000, seed=5, n_threads=t)
            for t in (1, min(2, numba.config.NUMBA_NUM_THREADS))]
    np.testing.assert_array_equal(runs[0].absorbed, runs[1].absorbed)
    np.testing.assert_array_equal(runs[0].tally, runs[1].tally)
    other = white_absorbed(spec, [0.3, 3.0], 200.0, n_photons=3000, seed=6)
    assert not np.array_equal(runs[0].absorbed, other.absorbed)


def test_symmetrized_tally_equals_symmetrize():
    spec = spec_()
    plain = white_absorbed(spec, [1.0], 100.0, n_photons=3000, seed=2)
    folded = white_absorbed(spec, [1.0], 100.0, n_photons=3000, seed=2, symmetrized=True)
    np.testing.assert_allclose(folded.absorbed[0], symmetrize(plain.absorbed[0], spec),
                               rtol=1e-12, atol=1e-15)


def test_white_build_is_cached_under_its_own_key(tmp_path):
    spec = spec_(mua_range=(0.5, 4.0), mus_range=(50.0, 400.0), n_mua=4, n_mus=4,
                 n_photons=1000)
    assert cache_key(spec, "white") != cache_key(spec, "table") == spec.key()
    emu = AbsorptionEmulator.build(spec, cache_dir=tmp_path, progress=False, method="white")
    assert len(list(tmp_path.glob("emulator-white-*.npz"))) == 1
    rows, fracs = white_column(spec, 2)
    np.testing.assert_array_equal(emu.log_na[:, 2], rows)
    np.testing.assert_array_equal(emu.absorbed[:, 2], fracs)
    again = AbsorptionEmulator.build(spec, cache_dir=tmp_path, progress=False, method="white")
    np.testing.assert_array_equal(again.log_na, emu.log_na)
    with pytest.raises(ValueError, match="method"):
        AbsorptionEmulator.build(spec, cache_dir=tmp_path, progress=False, method="fast")


@pytest.mark.parametrize("layered", [False, True])
def test_a_weight_does_not_depend_on_the_other_weights(layered):
    """Each photon has its own path stream and each weight its own roulette numbers: a
    run of some of the mua values gives their maps and tallies bit for bit as a run of
    all of them (the one-medium kernel, and the general kernel with two media)."""
    spec = layered_spec_() if layered else spec_()
    mua = np.array([0.2, 0.7, 2.0, 6.0, 20.0])
    full = white_absorbed(spec, mua, 100.0, n_photons=1500, seed=5)
    for rows in ([1, 2], [4], [3, 0]):
        part = white_absorbed(spec, mua[rows], 100.0, n_photons=1500, seed=5)
        np.testing.assert_array_equal(part.absorbed, full.absorbed[rows])
        np.testing.assert_array_equal(part.tally, full.tally[:, rows])


def test_white_fill_in_pieces_equals_the_whole_build(tmp_path):
    """On demand the white fill runs only the rows a column still needs; any order of
    pieces gives the table of one build, bit for bit."""
    spec = spec_(mua_range=(0.5, 4.0), mus_range=(50.0, 400.0), n_mua=5, n_mus=4,
                 n_photons=800)
    whole = AbsorptionEmulator.build(spec, cache_dir=tmp_path / "a", progress=False,
                                     method="white")
    emu = AbsorptionEmulator.build(spec, cache_dir=tmp_path / "b", progress=False,
                                   method="white", on_demand=True)
    assert not emu.have.any()
    for a, b in [(slice(1, 3), 2), (slice(0, 5), 2), (slice(3, 5), slice(0, 2))]:
        piece = np.zeros_like(emu.have)
        piece[a, b] = True
        emu.fill(piece)
        assert emu.have[a, b].all()
    emu.fill(np.ones_like(emu.have))
    np.testing.assert_array_equal(emu.log_na, whole.log_na)
    np.testing.assert_array_equal(emu.absorbed, whole.absorbed)


def test_auto_method_is_white_where_it_applies():
    assert white_supported(spec_()) is None
    assert resolve_method(spec_(), "auto") == "white"
    assert resolve_method(spec_(), "table") == "table"
    other_n = layered_spec_(matched_interfaces=False, media=((5.0, 150.0, 0.8, 1.45),
                                                             (None, None, 0.9, 1.3)))
    assert "refractive" in white_supported(other_n)
    assert resolve_method(other_n, "auto") == "table"
    no_decay = layered_spec_(media=((0.0, 150.0, 0.8, 1.3), (None, None, 0.9, 1.3)))
    assert "mua = 0.0" in white_supported(no_decay)
    assert resolve_method(layered_spec_(), "auto") == "white"
    with pytest.raises(ValueError, match="method must be one of"):
        resolve_method(spec_(), "fast")


# ------------------------------------------------ several media (issue #19, part 2)

def layered_spec_(**kw):
    """A 2-voxel (0.05 cm) epidermis (medium 0, known) over the dermis (medium 1, estimated)."""
    M = np.ones((8, 8, 10), dtype=np.int32)
    M[:, :, :2] = 0
    kw.setdefault("media", ((5.0, 150.0, 0.8, 1.3), (None, None, 0.9, 1.3)))
    return spec_(nz=10, estimated=1, medium_map=M, **kw)


@pytest.mark.parametrize("mus", [30.0, 300.0])
def test_white_equals_direct_two_layers(mus):
    """Exact-mode parity: one white run per dermis mus against direct Monte Carlo of the
    layered model, at dermis mua at both edges of the two-layer example's table (0.3, 3)
    and at its prior's centre, dermis mus at its table's edges."""
    spec = layered_spec_()
    n = 10000 if mus < 100 else 4000
    compare(spec, np.array([0.3, 1.0, 3.0]), mus, n, n)


def test_white_equals_direct_two_layers_fresnel():
    """Mismatched outer interfaces (one refractive index inside): Fresnel at the surface."""
    compare(layered_spec_(matched_interfaces=False), np.array([0.5, 2.0]), 100.0, 8000, 8000)


def test_white_two_layers_energy_balance_and_refraction():
    spec = layered_spec_(matched_interfaces=False)
    res = white_absorbed(spec, [0.3, 3.0], 100.0, n_photons=2000, seed=3)
    out = res.tally[[K.T_SPECULAR, K.T_TOP, K.T_BOTTOM, K.T_SIDES, K.T_OUTSIDE_ABSORBED,
                     K.T_KILLED, K.T_MISSED]].sum(axis=0)
    balance = res.absorbed.reshape(2, -1).sum(axis=1) + out - res.tally[K.T_ROULETTE]
    np.testing.assert_allclose(balance, res.tally[K.T_LAUNCHED], rtol=1e-13)
    other_n = layered_spec_(matched_interfaces=False, media=((5.0, 150.0, 0.8, 1.45),
                                                             (None, None, 0.9, 1.3)))
    with pytest.raises(NotBuiltError, match="one refractive index"):
        white_absorbed(other_n, [1.0], 100.0, n_photons=100, seed=3)


@pytest.mark.parametrize("x", [1e-5, 2e-3, 9.9e-3, 1.01e-2, 0.3, 5.0, 40.0])
def test_loss_point_inverts_where_the_weight_is_lost(x):
    """The point of a move where the one-medium white kernel puts a weight's loss: the
    inverse of the share lost before t, (1 - exp(-x t)) / (1 - exp(-x))."""
    from mcmatlab_py.emulator._white_uniform import loss_point

    t = np.linspace(0.0, 1.0, 41)
    lost = -math.expm1(-x)
    u = -np.expm1(-x * t) / lost
    got = np.array([loss_point(ui, x, lost) for ui in u])
    assert np.all((got >= 0.0) & (got <= 1.0))
    # the share lost before the point is u (the inverse is ill-conditioned near t = 1 for
    # large x, so the check is on the share; the series' error is below 1e-6 of the move)
    np.testing.assert_allclose(-np.expm1(-x * got) / lost, u, rtol=0, atol=1e-6)
    if x < 1.0:
        np.testing.assert_allclose(got, t, rtol=0, atol=1e-6)


@pytest.mark.parametrize("mus", [10.0, 300.0])
def test_one_medium_kernel_equals_direct_where_moves_cross_many_voxels(mus):
    """40 x 40 x 20 voxels of 0.0125 cm: at mus = 10 a free path crosses about 8 voxels,
    so almost every loss is put at its sampled point; at 300 most moves stay in one voxel
    and the losses are settled by path length."""
    spec = spec_(nx=40, ny=40, nz=20, matched_interfaces=False)
    compare(spec, np.array([0.1, 3.0, 20.0]), mus, 8000, 8000)
