"""Shared fixtures of the test suite.

``tissue``: the tissue application on a small, fast model: a 6 x 6 x 4 voxel grid, the
paper's nominal values, a smooth stand-in for the absorption emulator, a setup factory
and an identical-twin data generator. ``bad_toml``: the tiny example config with one
string replaced, written to a temporary file.
"""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

import fem

EXAMPLES = Path(__file__).parents[1] / "examples"
TINY_TOML = (EXAMPLES / "tiny.toml").read_text()

GRID = fem.BoxGrid(6, 6, 4, 0.5, 0.5, 0.25)
NOMINAL = {"mua": 1.0, "mus": 100.0, "VHC": 3.76, "TC": 0.0037}


def stand_in_absorption(mua, mus):
    """A smooth stand-in for the emulator: NA ~ mua exp(-mu_eff z), W/cm^3/W."""
    z = GRID.z[None, None, None, :]
    mueff = np.sqrt(3 * mua * (mua + 0.1 * mus))[:, None, None, None]
    return np.broadcast_to(40 * mua[:, None, None, None] * np.exp(-mueff * z),
                           (len(mua), *GRID.shape)).copy()


def make_setup(**kw):
    """A :class:`TissueFilterSetup` on ``GRID`` with the stand-in absorption; ``kw`` override."""
    from enkf.tissue import TissueFilterSetup
    from mcmatlab_py.heat import HeatSimulation

    args = dict(grid=GRID, absorption=stand_in_absorption,
                power=HeatSimulation(P=0.5, duration_on=1.0, duration_off=1.0).laser_power,
                nominal=NOMINAL, n_members=20, seed=1, method="etkf",
                tracked_positions=[(0, 0, 0), (0, 0, 0.125)])
    args.update(kw)
    return TissueFilterSetup.build(**args)


def twin_data(s, mua, mus, seed=0, times=None):
    """Synthetic data of one sensor at the origin from the setup's own model (an identical
    twin), noise var 0.01; ``times`` (s) default 0.1 ... 2.0."""
    from enkf.tissue import TissueForwardModel

    model = TissueForwardModel(s)
    P = fem.probe_matrix(model.mesh, np.zeros((3, 1)))
    T = np.zeros((1, model.mesh.p.shape[1]))
    times = 0.1 * np.arange(1, 21) if times is None else times
    out, t0 = [], 0.0
    for t1 in times:
        T = model(T, np.array([[mua, mus]]), t0, t1)
        out.append((P @ T.T)[0, 0])
        t0 = t1
    rng = np.random.default_rng(seed)
    return times, np.array(out)[:, None] + 0.1 * rng.standard_normal((len(times), 1))


@pytest.fixture
def tissue():
    """The small tissue model: ``grid``, ``nominal``, ``absorption``, ``setup(**kw)``,
    ``twin_data(setup, mua, mus, seed=0)``."""
    return SimpleNamespace(grid=GRID, nominal=NOMINAL, absorption=stand_in_absorption,
                           setup=make_setup, twin_data=twin_data)


@pytest.fixture
def bad_toml(tmp_path):
    """``bad_toml(old, new)``: the tiny config with ``old`` replaced by ``new``, as a file."""
    def write(old, new):
        text = TINY_TOML.replace(old, new)
        assert text != TINY_TOML, old
        p = tmp_path / "bad.toml"
        p.write_text(text)
        return p
    return write
