"""Figures of the optional Monte Carlo outputs (matplotlib; pyvista optional for paths).

* :func:`plot_example_paths`: MCmatlab's example photon paths in 3-D over the cuboid.
* :func:`plot_far_field`: the escaping power over (theta, phi).
* :func:`plot_light_collector`: the lens image (its time-integral) or the fiber's
  time-of-flight histogram.
* :func:`plot_boundary_irradiance`: the six ``NI_*`` maps.
* :func:`plot_az_fz`, :func:`plot_radial_reflectance_transmittance`: MCmatlab's
  ``plotAzFz`` and ``plotRadialReflectanceTransmittance`` (example 24).

Each returns a matplotlib ``Figure``; nothing is shown or saved unless asked. The first
four take ``simulation="MC"`` or ``"FMC"`` (the fluorescence run's outputs).
"""

from __future__ import annotations

import numpy as np

from ..monte_carlo.broadband import is_broadband
from ..monte_carlo.layered import absorption_vs_depth, radial_reflectance_transmittance
from ..monte_carlo.outputs import far_field_solid_angles

__all__ = ["plot_az_fz", "plot_boundary_irradiance", "plot_example_paths", "plot_far_field",
           "plot_light_collector", "plot_radial_reflectance_transmittance"]


def _need(value, what: str):
    if value is None:
        raise ValueError(f"the run has no {what}: request it before model.run_monte_carlo()")
    return value


def _run(model, simulation: str):
    """``model.MC`` or ``model.FMC``, and a title prefix."""
    if simulation not in ("MC", "FMC"):
        raise ValueError(f"simulation must be 'MC' or 'FMC', got {simulation!r}")
    return getattr(model, simulation), ("Fluorescence: " if simulation == "FMC" else "")


def _all_wavelengths(sim, value):
    """An output summed over the last, wavelength axis of a broadband run (as given else)."""
    if value is None or not is_broadband(sim.wavelength):
        return value
    return np.asarray(value).sum(axis=-1)


def _split_paths(P: np.ndarray) -> list[np.ndarray]:
    """(4, k) paths with NaN columns between them -> list of (4, m) polylines."""
    breaks = np.flatnonzero(np.isnan(P[0]))
    pieces = np.split(P, breaks, axis=1)
    return [p[:, ~np.isnan(p[0])] for p in pieces if np.any(~np.isnan(p[0]))]


def plot_example_paths(model, *, use_pyvista: bool = False, simulation: str = "MC",
                       off_screen: bool = False):
    """The example paths (``MC.n_example_paths``) as 3-D polylines, coloured by weight, in the
    cuboid (z down, as MCmatlab).

    With ``use_pyvista`` a ``pyvista.Plotter`` is returned (not shown; ``off_screen`` for
    screenshots without a display), turned as MCmatlab draws the cuboid: z points down
    the screen, the laser's face (z = 0) on top
    (:func:`~mcmatlab_py.plotting.slice_viewer.laser_face_on_top`).
    """
    G, (MC, prefix) = model.G, _run(model, simulation)
    lines = _split_paths(_need(MC.example_paths, "example paths (MC.n_example_paths)"))
    if use_pyvista:
        import pyvista as pv

        from .slice_viewer import laser_face_on_top

        plotter = pv.Plotter(off_screen=off_screen)
        plotter.add_mesh(pv.Box((-G.Lx / 2, G.Lx / 2, -G.Ly / 2, G.Ly / 2, 0, G.Lz)),
                         style="wireframe")
        for p in lines:
            if p.shape[1] > 1:
                poly = pv.lines_from_points(p[:3].T)
                poly["weight"] = p[3]
                plotter.add_mesh(poly, scalars="weight", cmap="viridis", clim=(0, 1))
        plotter.add_axes()
        return laser_face_on_top(plotter)
    import matplotlib.pyplot as plt
    from matplotlib import cm

    fig = plt.figure(figsize=(6, 5))
    ax = fig.add_subplot(projection="3d")
    for p in lines:
        for a, b, w in zip(p[:3, :-1].T, p[:3, 1:].T, p[3, :-1], strict=True):
            ax.plot(*np.column_stack([a, b]), color=cm.viridis(min(1.0, w)), lw=0.8)
    ax.set(xlim=(-G.Lx / 2, G.Lx / 2), ylim=(-G.Ly / 2, G.Ly / 2), zlim=(G.Lz, 0),
           xlabel="x [cm]", ylabel="y [cm]", zlabel="z [cm]", title=f"{prefix}Example photon paths")
    return fig


def plot_far_field(model, simulation: str = "MC"):
    """The radiant intensity of the escaping light, ``MC.far_field`` over each bin's solid
    angle (W/sr/W incident, as MCmatlab draws it), over theta (from +z) and phi."""
    import matplotlib.pyplot as plt

    MC, prefix = _run(model, simulation)
    FF = _all_wavelengths(MC, _need(MC.far_field, "far field (MC.far_field_res)"))
    FF = np.asarray(FF) / far_field_solid_angles(FF.shape[0])
    fig, ax = plt.subplots(figsize=(6, 4), constrained_layout=True)
    im = ax.pcolormesh(np.degrees(MC.far_field_phi), np.degrees(MC.far_field_theta), FF,
                       shading="nearest", cmap="inferno", vmin=0.0)
    ax.set(xlabel="phi [deg]", ylabel="theta [deg] (0: +z, down)",
           title=f"{prefix}Far field of the escaping light")
    fig.colorbar(im, ax=ax, label="radiant intensity [W/sr/W.incident]")
    return fig


def plot_light_collector(model, simulation: str = "MC"):
    """The lens image (summed over time bins) or the fiber's power (over time); summed over
    the wavelengths of a broadband run (as the far field and the ``NI`` maps)."""
    import matplotlib.pyplot as plt

    MC, prefix = _run(model, simulation)
    LC = MC.light_collector
    img = np.asarray(_all_wavelengths(MC, _need(LC.image,
                                                "light collector image (MC.use_light_collector)")))
    fig, ax = plt.subplots(figsize=(5, 4), constrained_layout=True)
    if LC.is_fiber:
        if img.ndim == 0:
            ax.bar([0], [float(img)])
            ax.set(xticks=[], ylabel="power [W/W.incident]", title=f"{prefix}Collected power")
        else:
            ax.step(LC.t * 1e9, img, where="mid")
            ax.set(xlabel="t [ns]", ylabel="power per time bin [W/W.incident]",
                   title="Time-resolved collected power (end bins: before and after)")
        return fig
    if img.ndim == 3:
        img = img.sum(axis=2)
    h = LC.field_size / 2
    im = ax.imshow(img.T, origin="lower", extent=[-h, h, -h, h], cmap="inferno")
    ax.set(xlabel="X [cm]", ylabel="Y [cm]", title=f"{prefix}Image at 1x magnification")
    fig.colorbar(im, ax=ax, label="image irradiance [W/cm$^2$ per W incident]")
    return fig


def plot_boundary_irradiance(model, simulation: str = "MC"):
    """The six ``NI_*`` maps (W/cm^2/W) on the faces of the cuboid."""
    import matplotlib.pyplot as plt

    G, (MC, prefix) = model.G, _run(model, simulation)
    _need(MC.NI_zneg, "boundary irradiance (MC.calc_normalized_irradiance)")
    fig, axes = plt.subplots(2, 3, figsize=(11, 6), constrained_layout=True)
    ext = {"x": [-G.Ly / 2, G.Ly / 2, G.Lz, 0], "y": [-G.Lx / 2, G.Lx / 2, G.Lz, 0],
           "z": [-G.Lx / 2, G.Lx / 2, -G.Ly / 2, G.Ly / 2]}
    labels = {"x": ("y [cm]", "z [cm]"), "y": ("x [cm]", "z [cm]"), "z": ("x [cm]", "y [cm]")}
    for ax, face in zip(axes.T.ravel(), ("xpos", "xneg", "ypos", "yneg", "zpos", "zneg"),
                        strict=True):
        NI = np.asarray(_all_wavelengths(MC, getattr(MC, f"NI_{face}")))
        # irradiance is >= 0: a face no light leaves is drawn black, not mid-scale
        im = ax.imshow(NI.T, extent=ext[face[0]], aspect="auto", cmap="inferno", vmin=0.0,
                       vmax=float(NI.max()) if NI.max() > 0 else 1.0,
                       origin="lower" if face[0] == "z" else "upper")
        ax.set(title=f"{prefix}NI_{face}" + ("" if NI.max() > 0 else " (no light)"),
               xlabel=labels[face[0]][0], ylabel=labels[face[0]][1])
        fig.colorbar(im, ax=ax, label="irradiance [W/cm$^2$ per W incident]")
    return fig


def plot_az_fz(model):
    """MCmatlab's ``plotAzFz``: A(z) (cm^-1) and F(z) (-) over depth."""
    import matplotlib.pyplot as plt

    z, A, F = absorption_vs_depth(model)
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.5), constrained_layout=True)
    axes[0].plot(z, A)
    axes[0].set(xlabel="z [cm]", ylabel="A$_z$ [cm$^{-1}$]")
    axes[1].plot(z, F)
    axes[1].set(xlabel="z [cm]", ylabel="F$_z$ [-]")
    return fig


def plot_radial_reflectance_transmittance(model):
    """MCmatlab's ``plotRadialReflectanceTransmittance``: R(r), T(r) from the NI maps, mirrored
    to negative r; MCML's ``Rd_r``, ``Tt_r`` overlaid when the run has them."""
    import matplotlib.pyplot as plt

    r, R, T = radial_reflectance_transmittance(model)
    MC = model.MC
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.5), constrained_layout=True)
    for ax, y, mcml, label in ((axes[0], R, MC.Rd_r, "Reflectance"),
                               (axes[1], T, MC.Tt_r, "Transmittance")):
        keep = r > 0
        ax.plot(np.concatenate([-r[keep][::-1], r]), np.concatenate([y[keep][::-1], y]),
                label="face pixels (NI maps)")
        if mcml is not None:
            ax.plot(MC.radial_r, mcml, ".", label="MCML bins")
        ax.set(xlabel="r [cm]", ylabel=f"{label} [cm$^{{-2}}$]", yscale="log")
        ax.legend(loc="upper left", fontsize=8)  # the tails are noisiest at large |r|
    return fig
