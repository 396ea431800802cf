"""The figures of ``model.plot("G" | "MC" | "FMC" | "HS")`` (see :mod:`mcmatlab_py.plotting`)."""

from __future__ import annotations

import numpy as np

from ..monte_carlo.broadband import is_broadband, total
from .slices import new_figure, orthogonal_slices, slices_through_maximum

__all__ = ["fluorescence_figures", "geometry_figures", "heat_figures", "heat_slices",
           "light_slices", "media_properties_figure", "monte_carlo_figures",
           "positive_log_norm"]

#: relative slice positions of the G figure: through the middle in x and y, and the
#: irradiated surface (MCmatlab's NdimSliderPlot default, with y through the middle). The
#: light's maps put their xy slice at the depth of their maximum instead
#: (:func:`light_slices`), and the heat's maps cut through their maximum
#: (:func:`heat_slices`): MCmatlab's 3-D view shows the top face under a slice through
#: the middle; a flat layout of the top layer shows only air in most examples.
DEFAULT_SLICES = (0.5, 0.5, 0.0)
#: a log colour scale spans at most this many decades below the maximum
LOG_DECADES = 6


def positive_log_norm(data: np.ndarray):
    """A LogNorm over the positive values of ``data`` (at most LOG_DECADES decades), or None."""
    from matplotlib.colors import LogNorm

    positive = data[data > 0]
    if positive.size == 0:
        return None
    top = float(positive.max())
    return LogNorm(vmin=max(float(positive.min()), top * 10.0 ** -LOG_DECADES), vmax=top)


def _media_names(G) -> list[str]:
    return [m.name for m in G.media]


def geometry_figures(model) -> dict:
    """``geometry`` (the media on three slices) and ``media_properties``."""
    G = model.G
    M = G.medium_map()
    fig = new_figure(name="Geometry illustration")
    orthogonal_slices(fig, M, G, DEFAULT_SLICES, categories=_media_names(G),
                      title="Geometry illustration")
    return {"geometry": fig, "media_properties": media_properties_figure(model, M)}


def _ranges(values, parent, n_media):
    lo = np.full(n_media, np.nan)
    hi = np.full(n_media, np.nan)
    for i in range(n_media):
        v = values[parent == i]
        v = v[np.isfinite(v)]
        if v.size:
            lo[i], hi[i] = v.min(), v.max()
    return lo, hi


def media_properties_figure(model, M=None):
    """MCmatlab's media-properties figure: each property of each medium at ``MC.wavelength``,
    a bar to its largest value over the voxels and a tick at its smallest (they differ for
    FR-, T- or FD-dependent media); over the wavelengths when ``MC`` or ``FMC`` is broadband
    (:func:`mcmatlab_py.plotting.spectral.media_properties_vs_wavelength`)."""
    from ..geometry.media_bins import optical_media_properties, thermal_media_properties

    G, MC, HS = model.G, model.MC, model.HS
    if is_broadband(MC.wavelength) or is_broadband(model.FMC.wavelength):
        from .spectral import media_properties_vs_wavelength

        return media_properties_vs_wavelength(model, M)
    M = G.medium_map() if M is None else M
    opt = MC.media_properties
    if opt is None or opt.M.shape != M.shape:
        opt = optical_media_properties(G.media, M, MC.wavelength, MC.FR, MC.T, MC.FD)
    props = [("mua", r"absorption $\mu_a$ [cm$^{-1}$]"), ("mus", r"scattering $\mu_s$ [cm$^{-1}$]"),
             ("g", "anisotropy g"), ("n", "refractive index n")]
    rows = [(getattr(opt, f), opt.parent, label) for f, label in props]
    if any(m.VHC is not None for m in G.media) and any(m.TC is not None for m in G.media):
        T = HS.T_voxels if HS.T_voxels is not None else HS.T_initial
        FD = 0.0 if HS.Omega_voxels is None else -np.expm1(-HS.Omega_voxels)
        th = thermal_media_properties(G.media, M, T, FD)
        rows += [(th.VHC, th.parent, r"VHC [J cm$^{-3}$ K$^{-1}$]"),
                 (th.TC, th.parent, r"TC [W cm$^{-1}$ K$^{-1}$]")]
    names = _media_names(G)
    fig = new_figure(width=min(16.0, 2.6 * len(rows) + 1), height=3.8, name="Media properties")
    axes = fig.subplots(1, len(rows))
    x = np.arange(len(names))
    colors = [f"C{i % 10}" for i in x]
    for ax, (values, parent, label) in zip(axes, rows, strict=True):
        lo, hi = _ranges(np.asarray(values, float), np.asarray(parent), len(names))
        ax.bar(x, np.nan_to_num(hi), color=colors)
        ax.scatter(x, lo, marker="_", s=300, color="k", zorder=3)
        ax.set_xticks(x, names, rotation=30, ha="right")
        ax.set_title(label, fontsize=10)
        if np.nanmax(np.r_[hi, 0.0]) / max(np.nanmin(np.r_[hi[hi > 0], np.inf]), 1e-300) > 1e3:
            ax.set_yscale("log")
    wl = "" if MC.wavelength is None else f" at {MC.wavelength:g} nm"
    fig.suptitle(f"Media properties{wl} (bar: largest, tick: smallest over the voxels)")
    return fig


def _summed(sim) -> str:
    """How the maps of a run are drawn: summed over the wavelengths of a broadband run."""
    n = np.size(sim.wavelength)
    return f", summed over {n} wavelengths" if is_broadband(sim.wavelength) else ""


def monte_carlo_figures(model) -> dict:
    """``media_properties``, ``NA`` and ``NFR`` (log colour scales) of ``model.MC``; a
    broadband run's maps summed over its wavelengths, and its ``spectrum``."""
    G, MC = model.G, model.MC
    if MC.NA is None:
        raise ValueError("MC.NA is empty: run model.run_monte_carlo() before plot('MC')")
    figs = {"media_properties": media_properties_figure(model)}
    s = _summed(MC)
    # a distributed source (example 26) emits inside the cuboid: per W emitted
    per = "emitted" if getattr(MC, "source_distribution", None) is not None else "incident"
    figs.update(_log_slice_figures(G, (
        ("NA", total(MC.NA), f"normalized absorbed power per volume{s}", "W/cm$^3$/W"),
        ("NFR", total(MC.NFR), f"normalized fluence rate{s}", "W/cm$^2$/W")), per))
    if is_broadband(MC.wavelength):
        from .spectral import spectrum_figure

        figs["spectrum"] = spectrum_figure(model, "MC")
    return figs


def light_slices(data: np.ndarray) -> tuple[float, float, float]:
    """Relative slice positions of a light map (nx, ny, nz): x and y through the middle,
    z at the depth of the map's maximum (the top layer when the map is all zero)."""
    return slices_through_maximum(data, axes=(2,), fallback=DEFAULT_SLICES)


def heat_slices(HS, field: np.ndarray) -> tuple[float, float, float]:
    """Relative slice positions of a heat map: ``HS.slice_positions`` where the user set
    them; where they are None (the default), through the voxel of the largest positive
    value of ``field`` (nx, ny, nz): the temperature rise above ``HS.T_initial``, or the
    damage integral; through the middle when no value is positive (nothing heated)."""
    if HS.slice_positions is not None:
        return tuple(float(p) for p in HS.slice_positions)
    return slices_through_maximum(field)


def _log_slice_figures(G, fields, per: str = "incident") -> dict:
    """One figure of orthogonal log-scale slices per ``(key, data, what, unit)``, per W
    ``per`` (incident, or emitted by a distributed source)."""
    import matplotlib as mpl

    # zero (log10 of it: -inf) drawn as the scale's lowest colour, as MCmatlab does; the
    # default (blank) read as inferno's top, the hottest colour
    base = mpl.colormaps["inferno"]
    cmap = base.with_extremes(bad=base(0.0), under=base(0.0))
    figs = {}
    for key, data, what, unit in fields:
        fig = new_figure(name=key)
        shown = np.where(data > 0, data, np.nan)
        orthogonal_slices(fig, shown, G, light_slices(data), cmap=cmap,
                          norm=positive_log_norm(data), label=f"{key} [{unit}]",
                          title=f"{key}: {what} [{unit} {per}]")
        figs[key] = fig
    return figs


def fluorescence_figures(model) -> dict:
    """MCmatlab's ``plot(model, 'FMC')``: ``emitters`` (the fluorescence emitted), ``NA`` and
    ``NFR`` of the fluorescence (log colour scales, per W of incident excitation), and the
    outputs the run has: ``light_collector``, ``far_field``, ``NI`` (boundary irradiance),
    ``example_paths``; a broadband run's maps summed over its wavelengths, and its
    ``spectrum``."""
    from . import outputs

    G, FMC = model.G, model.FMC
    if FMC.NA is None:
        raise ValueError("FMC.NA is empty: run model.run_monte_carlo('fluorescence') before "
                         "plot('FMC')")
    wl = _summed(FMC) or f" at {FMC.wavelength:g} nm"
    figs = _log_slice_figures(G, (
        ("emitters", total(FMC.source_distribution), f"fluorescence emitted{wl}", "W/cm$^3$/W"),
        ("NA", total(FMC.NA), f"normalized fluorescence absorbed per volume{wl}", "W/cm$^3$/W"),
        ("NFR", total(FMC.NFR), f"normalized fluorescence fluence rate{wl}", "W/cm$^2$/W")))
    if is_broadband(FMC.wavelength):
        from .spectral import spectrum_figure

        figs["spectrum"] = spectrum_figure(model, "FMC")
    if FMC.use_light_collector:
        figs["light_collector"] = outputs.plot_light_collector(model, "FMC")
    if FMC.far_field_res:
        figs["far_field"] = outputs.plot_far_field(model, "FMC")
    if FMC.calc_normalized_irradiance:
        figs["NI"] = outputs.plot_boundary_irradiance(model, "FMC")
    if FMC.n_example_paths:
        figs["example_paths"] = outputs.plot_example_paths(model, simulation="FMC")
    return figs


def heat_figures(model) -> dict:
    """The figures of MCmatlab's ``plot(model, 'HS')`` (see :mod:`mcmatlab_py.plotting`)."""
    G, HS = model.G, model.HS
    if HS.T_voxels is None:
        raise ValueError("HS holds no results: run model.simulate_heat_distribution() before "
                         "plot('HS')")
    M = G.medium_map()
    names = _media_names(G)
    T = HS.T_voxels
    pos = heat_slices(HS, T - HS.T_initial)  # through the hottest voxel
    figs = {}
    sensors = np.asarray(HS.temp_sensor_positions, float).reshape(-1, 3)
    if sensors.size:
        fig = new_figure(name="Temperature sensor illustration")
        axes, _ = orthogonal_slices(fig, M, G, pos, categories=names,
                                    title="Temperature sensor illustration")
        for ax, (a, b) in zip(axes, ((0, 1), (0, 2), (1, 2)), strict=True):
            at = {}  # sensors in line along the panel's normal share one label: "1,2,3"
            for i, p in enumerate(sensors, start=1):
                at.setdefault((p[a], p[b]), []).append(str(i))
            for (u, v), ids in at.items():
                ax.text(u, v, ",".join(ids), ha="center", va="center", fontsize=11,
                        weight="bold")
        figs["sensor_positions"] = fig
        fig = new_figure(width=8.0, height=4.8, name="Temperature sensor data")
        ax = fig.subplots()
        ijk = G.grid.voxel_of_points(sensors.T)  # (3, n_sensors), inside: validated
        for i in range(sensors.shape[0]):
            medium = names[int(M[ijk[0, i], ijk[1, i], ijk[2, i]])]
            ax.plot(HS.sensor_times, HS.sensor_temps[:, i], lw=2, label=f"{i + 1}, {medium}")
        ax.set(xlabel="time [s]", ylabel="temperature [deg C]", title="Temperature sensor data",
               xlim=(HS.sensor_times[0], HS.sensor_times[-1]))
        ax.grid(True, which="both", alpha=0.4)
        ax.legend(loc="best")
        figs["sensor_temperatures"] = fig
    fig = new_figure(name="Temperature")
    lim = np.asarray(HS.plot_temp_limits, float)
    from matplotlib.colors import Normalize

    norm = Normalize(vmin=T.min() if np.isnan(lim[0]) else lim[0],
                     vmax=T.max() if np.isnan(lim[1]) else lim[1])
    orthogonal_slices(fig, T, G, pos, cmap="hot", norm=norm, label="temperature [deg C]",
                      title=f"Temperature at t = {HS.sensor_times[-1]:.3g} s")
    figs["temperature"] = fig
    if any(m.E is not None and m.A is not None and m.A > 0 for m in G.media):
        Om = HS.Omega_voxels
        pos = heat_slices(HS, Om)  # through the most damaged voxel
        fig = new_figure(name="Thermal damage illustration")
        orthogonal_slices(fig, np.where(Om > 1, len(names), M), G, pos,
                          categories=[*names, "damage"],
                          title=r"Thermal damage illustration ($\Omega > 1$)")
        figs["damage"] = fig
        fig = new_figure(name="Fractional damage")
        orthogonal_slices(fig, -np.expm1(-Om), G, pos, cmap="viridis",
                          norm=Normalize(0.0, max(1e-12, float(-np.expm1(-Om.max())))),
                          label=r"$1 - e^{-\Omega}$", title=r"Fractional damage $1 - e^{-\Omega}$")
        figs["fractional_damage"] = fig
    return figs
