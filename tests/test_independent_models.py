"""The independent truths' heat solvers (validation/independent_models.py), checked against
analytic results and each other: model C's spectral solution of the insulated box."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parents[1] / "validation"))

import independent_models as im  # noqa: E402


@pytest.fixture(scope="module")
def box():
    return im.SpectralBox(shape=(16, 16, 8), dt=0.025, sub=(2, 2, 2))


def test_a_cosine_mode_decays_at_its_eigenvalue(box):
    """T = cos(pi x / L) cos(pi z / Lz) in the insulated box decays as exp(-kappa lam t)."""
    xyz = np.array([[0.1, -0.05, 0.03], [-0.2, 0.2, 0.2], [0.0, 0.0, 0.0]])
    T = np.zeros(box.shape)
    T[1, 0, 1] = 1.0
    f0 = box.values(T.ravel(), xyz)
    expect = (np.sqrt(2 / 16) * np.sqrt(1 / 16) * np.sqrt(2 / 8)
              * np.cos(np.pi * (xyz[:, 0] + im.L_XY / 2) / im.L_XY)
              * np.cos(np.pi * xyz[:, 2] / im.L_Z))
    np.testing.assert_allclose(f0, expect, rtol=1e-12)
    lam = (np.pi / im.L_XY) ** 2 + (np.pi / im.L_Z) ** 2
    out = T.ravel()
    for _ in range(40):  # 1 s
        out = box.step(out, 0.0, box.dt)
    np.testing.assert_allclose(box.values(out, xyz), f0 * np.exp(-im.TC / im.VHC * lam * 1.0),
                               rtol=1e-12)


def test_the_box_keeps_the_heat_it_is_given(box):
    """A source held for 1 s: the mean temperature is the energy over VHC and the volume,
    to round-off, whatever the source's shape; the surface is hottest under the beam."""
    T = _heated(box)
    volume = im.L_XY * im.L_XY * im.L_Z
    mean = T.reshape(box.shape)[0, 0, 0] / np.sqrt(np.prod(box.shape))  # the DC mode
    assert mean == pytest.approx(0.8 * 1.0 / (im.VHC * volume), rel=1e-12)
    top = box.surface(T, np.array([[0.0, 0.0], [0.1, 0.0], [0.15, 0.0]]))
    assert top[0] > top[1] > top[2] > 0


def test_the_series_rings_little_on_model_cs_grid():
    """On model C's own grid the cosine series of a top-hat's heat, 1 s after it starts,
    dips below zero where the heat has not arrived by less than 1e-4 of the peak (the
    16 x 16 x 8 grid above: 4e-3)."""
    box = im.SpectralBox()
    T = _heated(box)
    g = np.linspace(-0.25, 0.25, 41)
    face = box.surface(T, np.column_stack([np.repeat(g, 41), np.tile(g, 41)]))
    assert face.min() > -1e-4 * face.max()


def _heated(box):
    """The box after 1 s of a top-hat of 0.1 cm absorbed as exp(-5 z), 0.8 W in all."""
    r_edges, z_edges = np.linspace(0, 0.4, 41), np.linspace(0, im.L_Z, 51)
    R, Z = np.meshgrid(0.5 * (r_edges[1:] + r_edges[:-1]), 0.5 * (z_edges[1:] + z_edges[:-1]),
                       indexing="ij")
    density = np.where(R < 0.1, np.exp(-5 * Z), 0.0)
    q = box.source(density, (r_edges, z_edges), total=0.8)  # W per W, times 1 W
    T = np.zeros(box.size)
    for _ in range(40):
        T = box.step(T, q, box.dt)
    return T


def test_model_d_is_model_a_with_ten_times_the_photons():
    """D runs A's analog Monte Carlo with 10 times the photons on its own seeds, cached
    apart; C's maps are B's, and A, B, C keep their caches."""
    assert im._photons("D", 200_000) == 2_000_000
    assert [im._photons(m, 200_000) for m in "ABC"] == [200_000] * 3
    paths = {m: im._truth_path(m, "constant", 200_000) for m in im.ALL_MODELS}
    assert len(set(paths.values())) == len(im.ALL_MODELS)
