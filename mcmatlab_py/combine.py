"""Combine Monte Carlo runs (MCmatlab's ``combineModels``): several seeds, or several beams.

Runs of one light source (and one ``MC.P``) are averaged with weights ``n_photons`` (as if
it were one longer run). Runs of different light sources are superposed with weights given
by their powers, each model's ``MC.P`` as in MCmatlab or ``powers``: the result is per W of
the total power, which becomes its ``MC.P``.
"""

from __future__ import annotations

import copy

import numpy as np

__all__ = ["combine_models"]

#: geometry and Monte Carlo settings that must agree for runs to be combined
_SAME_G = ("nx", "ny", "nz", "Lx", "Ly", "Lz")
_SAME_MC = ("far_field_res", "matched_interfaces", "smoothing_length_scale", "boundary_type",
            "wavelength", "use_light_collector", "calc_normalized_irradiance", "n_radial_bins",
            "radial_bin_size", "n_angle_bins")
_SAME_LC = ("x", "y", "z", "theta", "phi", "f", "diam", "field_size", "NA", "res", "t_start",
            "t_end", "n_time_bins")
#: outputs averaged with the weights (per W incident)
_AVERAGED = ("NA", "NFR", "far_field", "NI_xpos", "NI_xneg", "NI_ypos", "NI_yneg", "NI_zpos",
             "NI_zneg", "Rd_r", "Tt_r", "Rd_a", "Tt_a", "absorbed_fraction",
             "specular_reflectance", "absorbed_outside_fraction", "killed_fraction",
             "missed_fraction", "roulette_gain_fraction")


def _equal(a, b) -> bool:
    try:
        return bool(np.array_equal(a, b)) if isinstance(a, np.ndarray) else a == b
    except (TypeError, ValueError):
        return a is b


def combine_models(models: list, powers: list[float] | None = None):
    """One model holding the weighted combination of the Monte Carlo results of ``models``.

    Parameters
    ----------
    models : list of Model, each run with :meth:`Model.run_monte_carlo` on the same
        geometry and settings (a ``ValueError`` names the first field that differs).
    powers : list of float, optional
        W, relative powers of the runs' light sources, instead of each model's ``MC.P``
        (MCmatlab's weights). One of the two is needed when the light sources or powers
        differ; runs of one source and power are averaged by photon count.

    Returns
    -------
    Model
        A copy of ``models[0]`` whose outputs are per W of the combined power; its
        ``n_photons``, ``simulation_time``, ``n_photons_collected`` are summed and its
        ``example_paths`` concatenated.
    """
    if not models:
        raise ValueError("combine_models needs at least one model, got []")
    first = models[0]
    for m in models:
        if m.MC.NA is None:
            raise ValueError("combine_models: every model must have run its Monte Carlo "
                             "(model.run_monte_carlo()) first")
        for name in _SAME_G:
            if getattr(m.G, name) != getattr(first.G, name):
                raise ValueError(f"combine_models: G.{name} differs ({getattr(first.G, name)!r} "
                                 f"vs {getattr(m.G, name)!r}): the runs cannot be combined")
        if not np.array_equal(m.MC.M, first.MC.M):
            raise ValueError("combine_models: the medium maps (MC.M) differ")
        for name in _SAME_MC:
            if not _equal(getattr(m.MC, name), getattr(first.MC, name)):
                raise ValueError(f"combine_models: MC.{name} differs: the runs cannot be combined")
        if first.MC.use_light_collector:
            for name in _SAME_LC:
                if getattr(m.MC.light_collector, name) != getattr(first.MC.light_collector, name):
                    raise ValueError(f"combine_models: MC.light_collector.{name} differs")
        if m.MC.deposition_criteria != first.MC.deposition_criteria:
            raise ValueError("combine_models: MC.deposition_criteria differ")
    same_beam = all(m.MC.light_source == first.MC.light_source and m.MC.P == first.MC.P
                    for m in models)
    if powers is None and not same_beam:
        if any(m.MC.P is None for m in models):
            raise ValueError("combine_models: the light sources or powers differ: set every "
                             "model's MC.P (W; relative values will do) or give powers=[...]")
        powers = [m.MC.P for m in models]
    if powers is None:
        w = np.array([m.MC.n_photons for m in models], dtype=float)
    else:
        w = np.asarray(powers, dtype=float)
        if w.shape != (len(models),) or not np.all(np.isfinite(w)) or np.any(w < 0) or w.sum() <= 0:
            raise ValueError(f"combine_models: powers must be {len(models)} non-negative "
                             f"numbers, not all zero, got {powers!r}")
    out = copy.deepcopy(first)
    MC = out.MC
    if powers is not None:
        MC.P = float(w.sum())  # W: the outputs are per W of all the light sources together
    w = w / w.sum()

    def mix(get):
        values = [get(m) for m in models]
        if any(v is None for v in values):
            return None
        return sum(wi * np.asarray(v, dtype=float) for wi, v in zip(w, values, strict=True))

    for name in _AVERAGED:
        v = mix(lambda m, name=name: getattr(m.MC, name))
        setattr(MC, name, v if v is None or np.ndim(v) else float(v))
    MC.escaped = {}
    for k in first.MC.escaped:
        v = mix(lambda m, k=k: m.MC.escaped[k])
        MC.escaped[k] = v if np.ndim(v) else float(v)  # (n,) in broadband runs
    if MC.use_light_collector:
        img = mix(lambda m: m.MC.light_collector.image)
        MC.light_collector.image = img if np.ndim(img) else float(img)
        MC.n_photons_collected = sum(m.MC.n_photons_collected or 0 for m in models)
    MC.n_photons = sum(m.MC.n_photons for m in models)
    if first.MC.n_photons_per_wavelength is not None:
        MC.n_photons_per_wavelength = sum(m.MC.n_photons_per_wavelength for m in models)
    MC.simulation_time = sum(m.MC.simulation_time for m in models)
    paths = [m.MC.example_paths for m in models if m.MC.example_paths is not None]
    MC.example_paths = np.hstack(paths) if paths else None
    return out
