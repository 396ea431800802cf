"""Combine Monte Carlo runs (MCmatlab's ``combineModels``): several seeds, or several beams.

Runs of one light source (and one ``MC.P``) are averaged with weights ``n_photons`` (as if
it were one longer run). Runs of different light sources are superposed with weights given
by their powers, each model's ``MC.P`` as in MCmatlab or ``powers``: the result is per W of
the total power, which becomes its ``MC.P``. With ``simulation="FMC"`` (MCmatlab's
``combineModels(models, 'FMC')``) fluorescence runs of one excitation are averaged with
weights ``FMC.n_photons``.
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


def combine_models(models: list, powers: list[float] | None = None, simulation: str = "MC"):
    """One model holding the weighted combination of the Monte Carlo results of ``models``.

    Parameters
    ----------
    models : list of Model, each run with :meth:`Model.run_monte_carlo` on the same
        geometry and settings (a ``ValueError`` names the first field that differs).
    powers : list of float, optional
        W, relative powers of the runs' light sources, instead of each model's ``MC.P``
        (MCmatlab's weights). One of the two is needed when the light sources or powers
        differ; runs of one source and power are averaged by photon count.
    simulation : {"MC", "FMC"}
        ``"FMC"``: combine the fluorescence runs (``model.FMC``) instead, each run with
        ``model.run_monte_carlo("fluorescence")`` from the same excitation (equal
        ``MC.NA``), weighted by ``FMC.n_photons``; the heat results of the copy are
        forgotten (``HS.reset()``), as MCmatlab resets its ``HS``.

    Returns
    -------
    Model
        A copy of ``models[0]`` whose outputs are per W of the combined power; its
        ``n_photons``, ``simulation_time``, ``n_photons_collected`` are summed and its
        ``example_paths`` concatenated.
    """
    if simulation not in ("MC", "FMC"):
        raise ValueError(f"combine_models: simulation must be 'MC' or 'FMC', got {simulation!r}")
    if not models:
        raise ValueError("combine_models needs at least one model, got []")
    first = models[0]
    o = simulation
    sims = [getattr(m, o) for m in models]
    for m, sim in zip(models, sims, strict=True):
        if sim.NA is None:
            how = "model.run_monte_carlo()" if o == "MC" else \
                "model.run_monte_carlo('fluorescence')"
            raise ValueError(f"combine_models: every model must have run its {o} Monte Carlo "
                             f"({how}) first")
        if o == "FMC" and not (np.array_equal(m.MC.NA, first.MC.NA)
                               and _equal(m.MC.wavelength, first.MC.wavelength)):
            raise ValueError("combine_models(..., simulation='FMC'): the excitations differ "
                             "(MC.NA or MC.wavelength): only fluorescence runs of one excitation "
                             "can be combined")
        for name in _SAME_G:
            if getattr(m.G, name) != getattr(first.G, name):
                raise ValueError(f"combine_models: G.{name} differs ({getattr(first.G, name)!r} "
                                 f"vs {getattr(m.G, name)!r}): the runs cannot be combined")
        if not np.array_equal(sim.M, sims[0].M):
            raise ValueError(f"combine_models: the medium maps ({o}.M) differ")
        for name in _SAME_MC:
            if not _equal(getattr(sim, name), getattr(sims[0], name)):
                raise ValueError(f"combine_models: {o}.{name} differs: the runs cannot be "
                                 "combined")
        if sims[0].use_light_collector:
            for name in _SAME_LC:
                if getattr(sim.light_collector, name) != getattr(sims[0].light_collector, name):
                    raise ValueError(f"combine_models: {o}.light_collector.{name} differs")
        if sim.deposition_criteria != sims[0].deposition_criteria:
            raise ValueError(f"combine_models: {o}.deposition_criteria differ")
    if o == "FMC":
        if powers is not None:
            raise ValueError(f"combine_models: powers = {powers!r} with simulation='FMC': "
                             "fluorescence runs of one excitation are weighted by their photon "
                             "counts (give powers=None)")
        same_beam = True
    else:
        same_beam = all(m.MC.light_source == first.MC.light_source and m.MC.P == first.MC.P
                        for m in models)
    if powers is None and not same_beam:
        if any(m.MC.P is None for m in models):
            raise ValueError("combine_models: the light sources or powers differ: set every "
                             "model's MC.P (W; relative values will do) or give powers=[...]")
        powers = [m.MC.P for m in models]
    if powers is None:
        w = np.array([sim.n_photons for sim in sims], dtype=float)
    else:
        w = np.asarray(powers, dtype=float)
        if w.shape != (len(models),) or not np.all(np.isfinite(w)) or np.any(w < 0) or w.sum() <= 0:
            raise ValueError(f"combine_models: powers must be {len(models)} non-negative "
                             f"numbers, not all zero, got {powers!r}")
    out = copy.deepcopy(first)
    combined = getattr(out, o)  # MC or FMC
    if o == "FMC":
        out.HS.reset()
    if powers is not None:
        combined.P = float(w.sum())  # W: the outputs are per W of all the light sources together
    w = w / w.sum()

    def mix(get):
        values = [get(sim) for sim in sims]
        if any(v is None for v in values):
            return None
        return sum(wi * np.asarray(v, dtype=float) for wi, v in zip(w, values, strict=True))

    for name in _AVERAGED:
        v = mix(lambda sim, name=name: getattr(sim, name))
        setattr(combined, name, v if v is None or np.ndim(v) else float(v))
    combined.escaped = {}
    for k in sims[0].escaped:
        v = mix(lambda sim, k=k: sim.escaped[k])
        combined.escaped[k] = v if np.ndim(v) else float(v)  # (n,) in broadband runs
    if combined.use_light_collector:
        img = mix(lambda sim: sim.light_collector.image)
        combined.light_collector.image = img if np.ndim(img) else float(img)
        combined.n_photons_collected = sum(sim.n_photons_collected or 0 for sim in sims)
    combined.n_photons = sum(sim.n_photons for sim in sims)
    if sims[0].n_photons_per_wavelength is not None:
        combined.n_photons_per_wavelength = sum(sim.n_photons_per_wavelength for sim in sims)
    combined.simulation_time = sum(sim.simulation_time for sim in sims)
    paths = [sim.example_paths for sim in sims if sim.example_paths is not None]
    combined.example_paths = np.hstack(paths) if paths else None
    return out
