"""The figures of broadband runs (``MC.wavelength`` or ``FMC.wavelength`` an array).

* :func:`media_properties_vs_wavelength`: MCmatlab's media-properties figure of a broadband
  model: each property of each medium over the wavelengths of both runs (its smallest and
  largest value over the voxels where they differ), the emission spectra normalised to unit
  integral, the thermal properties as bars.
* :func:`spectrum_figure`: the power per wavelength of a broadband run: incident (or emitted,
  for the fluorescence), absorbed in the cuboid and escaped, W per W incident. MCmatlab shows
  the wavelength with a slider on every figure; a saved figure cannot slide, so the maps are
  drawn summed over the wavelengths and this figure gives the spectrum (this port's).
"""

from __future__ import annotations

import numpy as np

from ..monte_carlo.broadband import is_broadband
from .slices import new_figure

__all__ = ["media_properties_vs_wavelength", "spectrum_figure"]


def _wavelengths(model) -> np.ndarray:
    """nm: the wavelengths of MC and FMC together, sorted (MCmatlab's ``unique``)."""
    both = [np.atleast_1d(w) for w in (model.MC.wavelength, model.FMC.wavelength)
            if w is not None]
    return np.unique(np.concatenate(both).astype(float))


def _range_over_voxels(model, medium, field: str, mask, wavelength: float):
    """(smallest, largest) of ``field`` of ``medium`` over its voxels at ``wavelength``."""
    if field == "ES" and medium.ES is None:
        return 1.0, 1.0  # MCmatlab's default: a flat emission spectrum
    if getattr(medium, field) is None:
        return np.nan, np.nan
    if field == "n" or not medium.depends_on_state(field):
        v = medium.value(field, wavelength)
        return v, v
    MC = model.MC
    state = [np.broadcast_to(np.asarray(s, dtype=float), mask.shape)[mask]
             for s in (MC.FR, MC.T, MC.FD)]
    v = medium.values(field, wavelength, *state)
    return float(v.min()), float(v.max())


def media_properties_vs_wavelength(model, M=None):
    """The media-properties figure of a broadband model (see the module docstring)."""
    G, HS = model.G, model.HS
    M = G.medium_map() if M is None else M
    wl = _wavelengths(model)
    present = [i for i in range(len(G.media)) if (M == i).any()]
    media = [G.media[i] for i in present]
    fields = [("mua", r"absorption $\mu_a$ [cm$^{-1}$]"), ("mus", r"scattering $\mu_s$ [cm$^{-1}$]"),
              ("g", "anisotropy g")]
    if any(m.value("n", w) != 1 for m in media for w in wl):
        fields.append(("n", "refractive index n"))
    if any(m.QY is not None for m in media):
        fields += [("QY", "fluorescence quantum yield [%]"),
                   ("ES", "emission spectrum (unit integral)")]
    thermal = all(m.VHC is not None and m.TC is not None for m in media)
    n_axes = len(fields) + 2 * thermal
    cols = min(3, n_axes)
    rows = -(-n_axes // cols)
    fig = new_figure(width=4.6 * cols, height=3.4 * rows, name="Media properties")
    axes = np.atleast_1d(fig.subplots(rows, cols)).ravel()
    for ax in axes[n_axes:]:
        ax.set_visible(False)
    for ax, (field, label) in zip(axes, fields, strict=False):
        for c, (i, m) in enumerate(zip(present, media, strict=True)):
            if field in ("QY", "ES") and m.QY is None:
                continue  # not fluorescent
            lo, hi = np.array([_range_over_voxels(model, m, field, M == i, w) for w in wl]).T
            if field == "QY":
                lo, hi = 100 * lo, 100 * hi
            if field == "ES":  # shape only: MCmatlab normalises the drawn spectra to unit area
                lo, hi = lo / np.trapezoid(lo, wl), hi / np.trapezoid(hi, wl)
            ax.plot(wl, hi, "o-", ms=3, color=f"C{c % 10}", label=m.name)
            if not np.array_equal(lo, hi):
                ax.plot(wl, lo, "o--", ms=3, color=f"C{c % 10}", label=f"{m.name} (smallest)")
        ax.set(xlabel="wavelength [nm]", title=label)
        ax.grid(True, alpha=0.4)
        if field in ("mua", "mus"):
            ax.set_yscale("log")
    # beside the panels: on the absorption panel it hid the curves (example 23)
    fig.legend(*axes[0].get_legend_handles_labels(), fontsize=7, loc="outside right upper")
    if thermal:
        T = HS.T_voxels if HS.T_voxels is not None else HS.T_initial
        FD = 0.0 if HS.Omega_voxels is None else -np.expm1(-HS.Omega_voxels)
        from ..geometry.media_bins import thermal_media_properties

        th = thermal_media_properties(G.media, M, T, FD)
        x = np.arange(len(present))
        for ax, (name, label) in zip(axes[len(fields):], (("VHC", r"VHC [J cm$^{-3}$ K$^{-1}$]"),
                                                          ("TC", r"TC [W cm$^{-1}$ K$^{-1}$]")),
                                     strict=True):
            values = getattr(th, name)
            ax.bar(x, [np.nanmax(values[th.parent == i]) for i in present],
                   color=[f"C{c % 10}" for c in x])
            ax.set_xticks(x, [m.name for m in media], rotation=30, ha="right")
            ax.set_title(label, fontsize=10)
    fig.suptitle(f"Media properties over {wl.size} wavelengths")
    return fig


def spectrum_figure(model, simulation: str = "MC"):
    """Power per wavelength of a broadband ``model.MC`` or ``model.FMC`` run, W/W incident."""
    sim = getattr(model, simulation)
    if not is_broadband(sim.wavelength) or sim.absorbed_fraction is None:
        raise ValueError(f"{simulation} holds no broadband run: set {simulation}.wavelength to an "
                         "array and run it first")
    wl = np.asarray(sim.wavelength, float)
    per = "incident"
    if simulation == "MC":
        # a distributed source (example 26) emits inside the cuboid: there is no incident beam
        per = "emitted" if sim.source_distribution is not None else "incident"
        launched, what = np.asarray(sim.spectrum), per
    else:
        launched, what = np.asarray(sim.emitted_power), "fluorescence emitted"
    escaped = np.nansum(np.vstack(list(sim.escaped.values())), axis=0)
    fig = new_figure(width=7.5, height=4.0, name=f"{simulation} spectrum")
    ax = fig.subplots()
    lines = {what: launched, "absorbed in the cuboid": launched * np.nan_to_num(
        sim.absorbed_fraction), "escaped": launched * escaped}
    for (label, y), marker in zip(lines.items(), "os^", strict=True):
        ax.plot(wl, y, f"{marker}-", ms=3, label=label)
    values = np.concatenate(list(lines.values()))
    positive = values[values > 0]
    floor = max(positive.min(), positive.max() * 1e-6) if positive.size else 1e-12
    kind = "Fluorescence" if simulation == "FMC" else ("Excitation" if per == "incident"
                                                       else "Emission")
    ax.set(xlabel="wavelength [nm]", ylabel=f"power per wavelength [W/W {per}]", yscale="log",
           ylim=(floor / 2, None), title=f"{kind}: power at each of the {wl.size} wavelengths")
    ax.grid(True, which="both", alpha=0.4)
    ax.legend(loc="best", fontsize=8)
    return fig
