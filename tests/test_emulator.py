"""The absorption emulator: cache keys, corruption, range handling, accuracy on and off the table."""

import warnings

import numpy as np
import pytest

from mcmatlab_py.emulator import (
    AbsorptionEmulator,
    DirectMonteCarloAbsorption,
    EmulatorSpec,
    symmetrize,
)


def small_spec(**kw):
    args = dict(nx=8, ny=8, nz=4, Lx=0.5, Ly=0.5, Lz=0.25, g=0.9, n=1.3, source_type="tophat",
                radius=0.1, mua_range=(0.5, 4.0), mus_range=(50.0, 400.0), n_mua=4, n_mus=4,
                n_photons=3000, seed=7)
    args.update(kw)
    return EmulatorSpec(**args)


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    cache = tmp_path_factory.mktemp("cache")
    spec = small_spec()
    return AbsorptionEmulator.build(spec, cache_dir=cache, progress=False), cache


def test_table_nodes_reproduce_direct_monte_carlo(built):
    """At a table node the interpolant returns the (symmetrised) Monte Carlo map itself."""
    emu, _ = built
    spec = emu.spec
    mua, mus = spec.mua_grid()[1], spec.mus_grid()[2]
    direct = spec.model(mua, mus, n_photons=spec.photons_at(mus)).run_monte_carlo().MC.NA
    np.testing.assert_allclose(emu(mua, mus)[0], symmetrize(direct, spec), rtol=1e-9, atol=1e-9)


def test_every_input_is_in_the_cache_key():
    base = small_spec()
    for change in [dict(nx=9), dict(Lz=0.3), dict(g=0.8), dict(n=1.4), dict(radius=0.05),
                   dict(source_type="gaussian"), dict(n_photons=3001), dict(seed=8),
                   dict(boundary_type=3), dict(matched_interfaces=False), dict(n_mua=5)]:
        assert small_spec(**change).key() != base.key(), change
    assert small_spec().key() == base.key()


def test_cache_is_reused_and_corruption_is_detected(built):
    emu, cache = built
    again = AbsorptionEmulator.build(emu.spec, cache_dir=cache, progress=False)
    np.testing.assert_array_equal(again.log_na, emu.log_na)
    path = next(cache.glob("emulator-*.npz"))
    raw = bytearray(path.read_bytes())
    raw[len(raw) // 2] ^= 0xFF  # flip a byte in the middle of the table
    path.write_bytes(bytes(raw))
    with pytest.warns(RuntimeWarning, match="corrupted"):
        rebuilt = AbsorptionEmulator.build(emu.spec, cache_dir=cache, progress=False)
    np.testing.assert_array_equal(rebuilt.log_na, emu.log_na)


def test_outside_the_table_errors_or_clamps_with_a_warning(built):
    emu, _ = built
    with pytest.raises(ValueError, match=r"mua = 5\.0 cm\^-1 is outside"):
        emu(5.0, 100.0)
    with pytest.raises(ValueError, match="mus must be finite"):
        emu(1.0, float("nan"))
    clamp = AbsorptionEmulator(spec=emu.spec, log_na=emu.log_na, out_of_range="clamp")
    with pytest.warns(RuntimeWarning, match="clamped"):
        out = clamp(5.0, 100.0)
    np.testing.assert_allclose(out, clamp(4.0, 100.0))


def test_interpolation_is_smooth_and_monotone_in_mua(built):
    emu, _ = built
    mua = np.linspace(0.5, 4.0, 40)
    absorbed = emu(mua, np.full(40, 120.0)).sum(axis=(1, 2, 3))
    assert np.all(np.diff(absorbed) > 0)  # more absorption absorbs more


def test_exact_mode_has_the_same_call(built):
    emu, _ = built
    exact = DirectMonteCarloAbsorption(emu.spec)
    out = exact(np.array([1.0, 2.0]), np.array([100.0, 200.0]))
    assert out.shape == (2, 8, 8, 4)
    assert exact.calls == 1


def test_bad_spec():
    with pytest.raises(ValueError, match="n_mua must be >= 4"):
        small_spec(n_mua=3)
    with pytest.raises(ValueError, match="mua_range"):
        small_spec(mua_range=(2.0, 1.0))


def test_orbits_rebuild_symmetric_fields():
    spec = small_spec()
    reps, inverse = spec.orbits()
    assert reps.size < 8 * 8 * 4 / 4
    f = symmetrize(np.random.default_rng(0).random((8, 8, 4)), spec)
    np.testing.assert_array_equal(f.ravel()[reps][inverse], f.ravel())
    off = small_spec(x_focus=0.05)
    assert off.orbits()[0].size > reps.size
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert off.symmetric_axes() == (False, True, False)


def test_nodal_load_emulator_conserves_power(tmp_path):
    """With mesh_divisions the table holds P1 nodal loads: they sum to the absorbed fraction."""
    spec = small_spec(nx=8, ny=8, nz=4, mesh_divisions=(4, 4, 2))
    emu = AbsorptionEmulator.build(spec, cache_dir=tmp_path, progress=False)
    assert emu.kind == "load" and emu.shape == (5, 5, 3)
    a, b = 1, 2
    mua, mus = spec.mua_grid()[a], spec.mus_grid()[b]
    load = emu(mua, mus)[0]
    assert load.sum() == pytest.approx(emu.absorbed[a, b], rel=1e-9)
    exact = DirectMonteCarloAbsorption(spec)
    assert exact.kind == "load" and exact(mua, mus).shape == (1, 5, 5, 3)


@pytest.mark.parametrize("method", ["table", "white"])
def test_on_demand_points_equal_the_table_built_at_once(tmp_path, method):
    """An on-demand emulator builds only the 4 x 4 stencils its members need (either
    method), keeps them in the cache (a second process starts from them), and once complete
    equals the table built at once bit for bit."""
    spec = small_spec(n_mua=6, n_mus=6)
    full = AbsorptionEmulator.build(spec, cache_dir=tmp_path / "full", progress=False,
                                    method=method)
    lazy = AbsorptionEmulator.build(spec, cache_dir=tmp_path / "lazy", progress=False,
                                    method=method, on_demand=True)
    assert not lazy.have.any() and not list((tmp_path / "lazy").glob("*.npz"))
    mua, mus = np.array([0.5, 0.7]), np.array([60.0, 90.0])
    np.testing.assert_array_equal(lazy.unique(mua, mus), full.unique(mua, mus))
    need = lazy.needed(mua, mus)
    np.testing.assert_array_equal(lazy.have, need)  # white: only the rows each column needs
    assert 0 < lazy.have.sum() < lazy.have.size
    np.testing.assert_array_equal(lazy.log_na[lazy.have], full.log_na[lazy.have])
    assert np.isnan(lazy.log_na[~lazy.have]).all()
    again = AbsorptionEmulator.build(spec, cache_dir=tmp_path / "lazy", progress=False,
                                     method=method, on_demand=True)
    np.testing.assert_array_equal(again.have, lazy.have)
    # a member at the table's top corner needs new points; the rest come with on_demand=False
    np.testing.assert_array_equal(again.unique(4.0, 400.0), full.unique(4.0, 400.0))
    done = AbsorptionEmulator.build(spec, cache_dir=tmp_path / "lazy", progress=False,
                                    method=method)
    assert done.complete
    np.testing.assert_array_equal(done.log_na, full.log_na)
    np.testing.assert_array_equal(done.absorbed, full.absorbed)


def test_on_demand_cache_merges_points_of_another_process(tmp_path):
    spec = small_spec(n_mua=6, n_mus=6)
    one = AbsorptionEmulator.build(spec, cache_dir=tmp_path, progress=False, on_demand=True)
    two = AbsorptionEmulator.build(spec, cache_dir=tmp_path, progress=False, on_demand=True)
    one.unique(0.5, 50.0)
    two.unique(4.0, 400.0)  # writes the file after `one` did: one's points are kept
    both = AbsorptionEmulator.build(spec, cache_dir=tmp_path, progress=False, on_demand=True)
    np.testing.assert_array_equal(both.have, one.have | two.have)
    assert not one.have[-1, -1] and one.have[0, 0] and two.have[-1, -1]


def test_the_points_of_a_box_cover_every_member_in_it(tmp_path):
    spec = small_spec(n_mua=8, n_mus=8)
    emu = AbsorptionEmulator.build(spec, cache_dir=tmp_path, progress=False, on_demand=True)
    box = emu.needed_box((0.7, 2.0), (60.0, 150.0))
    rng = np.random.default_rng(1)
    members = emu.needed(rng.uniform(0.7, 2.0, 500), rng.uniform(60.0, 150.0, 500))
    assert np.array_equal(box | members, box) and box.sum() < box.size
    assert emu.needed_box((0.7, 0.7), (60.0, 60.0)).sum() == 16  # one point: its stencil


def test_the_prior_points_are_filled_before_the_filter(tmp_path, tissue):
    """fill_prior_points: an on-demand emulator gets the points every member of the prior
    reads (here the prior 0.5-2 x (1, 100) inside a wider table), and nothing else."""
    from enkf.tissue.absorption import fill_prior_points

    spec = small_spec(mua_range=(0.1, 20.0), mus_range=(10.0, 2000.0), n_mua=8, n_mus=8)
    emu = AbsorptionEmulator.build(spec, cache_dir=tmp_path, progress=False, on_demand=True)
    setup = tissue.setup(absorption=emu)
    fill_prior_points(setup)
    lo, hi = setup.parameters.prior_bounds()
    rng = np.random.default_rng(0)
    members = emu.needed(rng.uniform(lo[0], hi[0], 300), rng.uniform(lo[1], hi[1], 300))
    assert np.array_equal(emu.have | members, emu.have)
    np.testing.assert_array_equal(emu.have, emu.needed_box((lo[0], hi[0]), (lo[1], hi[1])))
    assert not emu.complete
    fill_prior_points(tissue.setup())  # a plain function as absorption: nothing to do


def test_an_interrupted_cache_write_leaves_no_file(tmp_path, monkeypatch):
    spec = small_spec()
    emu = AbsorptionEmulator.build(spec, cache_dir=tmp_path, progress=False, on_demand=True)

    def interrupted(file, **arrays):
        with open(file, "wb") as fh:
            fh.write(b"PK\x03\x04 half a table")
        raise KeyboardInterrupt

    monkeypatch.setattr(np, "savez", interrupted)
    with pytest.raises(KeyboardInterrupt):
        emu.unique(1.0, 100.0)
    assert list(tmp_path.iterdir()) == []
