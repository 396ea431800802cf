"""The laser's power from irradiance, radiant exposure, pulse energy (mcmatlab_py.power), and
several light sources in one model: against hand calculations and single-source runs."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mcmatlab_py import LightSource, Medium, Model
from mcmatlab_py.heat import heat_source
from mcmatlab_py.power import (
    absolute_absorption,
    apply_power,
    beam_area,
    peak_power,
    run_light_sources,
    source_seeds,
)


def beam(kind, **fields):
    src = LightSource()
    src.source_type = kind
    for name, value in fields.items():
        if name.startswith("fpid_"):
            setattr(src.focal_plane_intensity_distribution, name[5:], value)
        else:
            setattr(src, name, value)
    return src


def test_irradiance_of_a_top_hat_beam_by_hand():
    # 10 W/cm^2 on a top-hat of radius 1 mm: 10 x pi x 0.1^2 = 0.31416 W
    src = beam("radial", fpid_radial_distr=0, fpid_radial_width=0.1)
    m = Model()
    m.MC.light_source = src
    p = peak_power(irradiance=10.0, model=m)
    assert p.area == pytest.approx(math.pi * 0.01, rel=1e-14)
    assert p.P == pytest.approx(0.3141592653589793, rel=1e-14)
    assert "top-hat of radius 0.1 cm" in p.how
    # mW/cm^2 are 1e-3 W/cm^2 (MCmatlab's issue 37): 50 mW/cm^2 on 2 cm^2 is 0.1 W
    assert peak_power(irradiance=50e-3, area=2.0).P == pytest.approx(0.1, rel=1e-14)


def test_pulsed_dye_laser_by_hand():
    # MCmatlab's issue 21: 3 J/cm^2 per 1 ms pulse at 10 Hz, a Gaussian of 1/e^2 radius 2.5 mm:
    # the centre's radiant exposure is 2 Q / (pi w^2), so Q = 3 x pi x 0.25^2 / 2 = 0.29452 J
    # and the peak power Q / 1 ms = 294.52 W; off for 100 ms - 1 ms
    m = Model()
    m.MC.light_source = beam("gaussian", radius=0.25)
    p = peak_power(radiant_exposure=3.0, pulse_duration=1e-3, repetition_rate=10.0, model=m)
    assert p.area == pytest.approx(math.pi * 0.0625 / 2, rel=1e-14)
    assert p.P == pytest.approx(294.5243112740431, rel=1e-12)
    assert (p.duration_on, p.duration_off) == (1e-3, pytest.approx(0.099, rel=1e-12))
    apply_power(m, p, n_pulses=5)
    assert m.MC.P == m.HS.P == pytest.approx(294.5243112740431, rel=1e-12)
    assert (m.HS.duration_on, m.HS.n_pulses) == (1e-3, 5)
    assert m.HS.duration_off == pytest.approx(0.099, rel=1e-12)


def test_pulse_energy_and_average_power_by_hand():
    assert peak_power(pulse_energy=0.5, pulse_duration=2e-3).P == pytest.approx(250.0)
    # 2 W average at 10 Hz in 1 ms pulses: 0.2 J a pulse, 200 W peak
    p = peak_power(average_power=2.0, repetition_rate=10.0, pulse_duration=1e-3)
    assert p.P == pytest.approx(200.0, rel=1e-14)
    assert p.area is None


def test_beam_areas_by_hand():
    m = Model()
    m.G.Lx, m.G.Ly = 0.2, 0.3
    m.MC.light_source = beam("plane_wave")
    assert beam_area(m)[0] == pytest.approx(0.06, rel=1e-14)
    xy = beam("xy", fpid_x_distr=0, fpid_x_width=0.02, fpid_y_distr=1, fpid_y_width=0.01)
    assert beam_area(xy)[0] == pytest.approx(0.04 * math.sqrt(math.pi / 2) * 0.01, rel=1e-14)
    with pytest.raises(ValueError, match="pencil source has no beam area"):
        beam_area(beam("pencil"))


@pytest.mark.parametrize("kwargs, match", [
    ({"irradiance": 1.0, "pulse_energy": 1.0, "pulse_duration": 1.0}, "exactly one"),
    ({"irradiance": -1.0, "area": 1.0}, "irradiance"),
    ({"irradiance": 1.0}, "needs the beam area"),
    ({"radiant_exposure": 1.0, "area": 1.0}, "pulse_duration"),
    ({"pulse_energy": 1.0, "pulse_duration": 0.2, "repetition_rate": 10.0}, "longer than"),
    ({"average_power": 1.0, "pulse_duration": 1e-3}, "repetition_rate"),
])
def test_bad_input_names_the_field(kwargs, match):
    with pytest.raises(ValueError, match=match):
        peak_power(**kwargs)


def small_model(seed=3):
    m = Model()
    m.G.nx = m.G.ny = m.G.nz = 11
    m.G.Lx = m.G.Ly = m.G.Lz = 0.1
    m.G.media = [Medium("tissue", mua=5.0, mus=50.0, g=0.8, VHC=4.0, TC=5e-3)]
    m.MC.n_photons_requested = 2000
    m.MC.seed = seed
    m.MC.progress = False
    return m


def test_several_sources_add_up_to_the_single_source_runs():
    model = small_model()
    sources = [beam("pencil", x_focus=-0.02), beam("tophat", radius=0.02, x_focus=0.03)]
    powers = [1.0, 0.25]
    combined = run_light_sources(model, sources, powers)
    singles = []
    for src, seed in zip(sources, source_seeds(model.MC.seed, 2), strict=True):
        m = small_model()
        m.MC.light_source, m.MC.seed = src, seed
        singles.append(m.run_monte_carlo())
    # per W of the total power, exactly the power-weighted sum of the two runs (same seeds)
    expect = (1.0 * singles[0].MC.NA + 0.25 * singles[1].MC.NA) / 1.25
    np.testing.assert_allclose(combined.MC.NA, expect, rtol=1e-12, atol=0)
    assert combined.MC.P == combined.HS.P == 1.25
    # absolute: W/cm^3 of both sources at their powers, also as the heat simulation's source
    watts = 1.0 * singles[0].MC.NA + 0.25 * singles[1].MC.NA
    np.testing.assert_allclose(absolute_absorption(combined), watts, rtol=1e-12)
    np.testing.assert_allclose(combined.HS.P * heat_source(combined), watts, rtol=1e-12)
    # the absorbed power adds up too (fractions of each source's power)
    assert combined.MC.absorbed_fraction * 1.25 == pytest.approx(
        singles[0].MC.absorbed_fraction + 0.25 * singles[1].MC.absorbed_fraction, rel=1e-12)


def test_several_sources_refuse_bad_input():
    model = small_model()
    with pytest.raises(ValueError, match="2 sources but 1 powers"):
        run_light_sources(model, [beam("pencil"), beam("pencil")], [1.0])
    with pytest.raises(ValueError, match=r"powers\[0\]"):
        run_light_sources(model, [beam("pencil")], [-1.0])
    with pytest.raises(ValueError, match=r"sources\[0\] must be a LightSource"):
        run_light_sources(model, ["pencil"], [1.0])
