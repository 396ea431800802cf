"""Broadband Monte Carlo (MCmatlab's ``MC.wavelength`` and ``FMC.wavelength`` as arrays).

Light transport is linear and the wavelength changes nothing but the media's
properties, so a broadband run is a set of monochromatic runs, one per wavelength, as
MCmatlab's MEX loop does (its Example 23):

* **Power.** Wavelength k carries the share :math:`s_k` of the power (W per W in all):
  for the excitation :math:`s_k = S(\\lambda_k) / \\sum_j S(\\lambda_j)` with
  :math:`S` = ``MC.spectrum_func`` (default: equal shares), stored as ``MC.spectrum``; with
  an (nx, ny, nz, n) ``source_distribution`` the shares are those of its wavelength
  slices; for the fluorescence the power emitted at each fluorescence wavelength
  (:mod:`mcmatlab_py.fluorescence`).
* **Photons.** ``n_photons_requested`` (or ``simulation_time_requested``) is split equally
  over the wavelengths, the last taking the remainder (MCmatlab's split). A wavelength of
  zero power is not run (MCmatlab runs it and multiplies by 0): it gets no photons, zero
  maps and NaN fractions.
* **Seeds.** Wavelength k runs with seed ``wavelength_seeds(seed, n)[k]`` (numpy's
  ``SeedSequence(seed, spawn_key=(k,))``: independent streams, the same for wavelength k
  whatever the number of wavelengths), so the monochromatic run at wavelength k with
  that seed and photon count gives its slice exactly.
* **Outputs.** Every map gets a last, wavelength axis, per W incident in all (slice k is
  :math:`s_k` times the monochromatic run's map): ``NA``, ``NFR`` (nx, ny, nz, n);
  ``NI_*`` (.., .., n); ``far_field`` (res, res, n); ``light_collector.image`` (n,),
  (nt, n), (res, res, n) or (res, res, nt, n); MCML's ``Rd_r`` ... (nbins, n). Their sums
  over the last axis are the broadband totals. The fractions (``absorbed_fraction``,
  ``escaped`` values, ...) are (n,) arrays, each a fraction of its own wavelength's power
  (the total absorbed is ``spectrum @ absorbed_fraction``); ``energy_balance`` is (n,).
  ``n_photons`` is the total, ``n_photons_per_wavelength`` the split.
* **Not here.** Example paths with several wavelengths (MCmatlab refuses them too), media
  whose optics depend on FR, T or FD, and ``fr_dep_iterations`` (MCmatlab bins such media
  at the first wavelength only) raise; the heat simulation heats with the sum over
  wavelengths, as MCmatlab's.
"""

from __future__ import annotations

import copy

import numpy as np

from .._strict import NotBuiltError
from ..geometry.media_bins import OpticalMediaProperties, optical_media_properties

__all__ = ["WavelengthStack", "check_supported", "check_wavelengths", "is_broadband",
           "monochromatic", "photon_split", "spectrum", "stacked_properties", "total",
           "wavelength_seeds"]

#: fraction outputs: (n,) arrays in a broadband run
FRACTIONS = ("absorbed_fraction", "specular_reflectance", "absorbed_outside_fraction",
             "killed_fraction", "missed_fraction", "roulette_gain_fraction")
#: map outputs of ``MC`` that get a wavelength axis (``light_collector.image`` too)
MAPS = ("NA", "NFR", "NI_xpos", "NI_xneg", "NI_ypos", "NI_yneg", "NI_zpos", "NI_zneg",
        "far_field", "Rd_r", "Tt_r", "Rd_a", "Tt_a")
#: outputs that do not depend on the wavelength (taken from the last run)
AXES = ("far_field_theta", "far_field_phi", "radial_r", "exit_angle")


def is_broadband(wavelength) -> bool:
    """True for an array of wavelengths (even of one), False for one number or None."""
    return wavelength is not None and np.ndim(wavelength) > 0


def total(field):
    """A map summed over its wavelength axis when it has one (``(nx, ny, nz, n)`` -> (nx, ny,
    nz)); a 3-D map or None as given."""
    if field is None or np.ndim(field) != 4:
        return field
    return np.asarray(field).sum(axis=-1)


def check_wavelengths(owner: str, value) -> float | np.ndarray:
    """``value`` as one wavelength (float, nm) or a 1-D float64 array of them; ValueError
    naming ``owner.wavelength`` for an empty or 2-D array, NaN, inf, or values <= 0."""
    from ..geometry.media import check_positive

    if np.ndim(value) == 0:
        return check_positive(owner, "wavelength", value)
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{owner}.wavelength must be a number or a 1-D array of numbers (nm), "
                         f"got {value!r}") from None
    if arr.ndim != 1 or arr.size == 0:
        raise ValueError(f"{owner}.wavelength must be a number or a non-empty 1-D array (nm), "
                         f"got shape {arr.shape}")
    bad = ~np.isfinite(arr) | (arr <= 0)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise ValueError(f"{owner}.wavelength[{k}] must be a finite number > 0 (nm), "
                         f"got {arr[k]!r}")
    return arr


def spectrum(MC) -> np.ndarray:
    """(n,) power shares of the wavelengths of a broadband ``MC``, summing to 1.

    From the (nx, ny, nz, n) ``source_distribution`` when there is one, else from
    ``spectrum_func`` (one number per wavelength, >= 0, not all 0; None: equal shares).
    """
    wl = MC.wavelength
    o = MC._owner_label
    S = MC.source_distribution
    if S is not None and np.ndim(S) == 4:
        p = np.asarray(S).sum(axis=(0, 1, 2))
        return p / p.sum()
    f = getattr(MC, "spectrum_func", None)
    if f is None:
        return np.full(wl.size, 1.0 / wl.size)
    p = np.empty(wl.size)
    for k, w in enumerate(wl):
        v = np.asarray(f(w), dtype=np.float64)
        if v.size != 1:
            raise ValueError(f"{o}.spectrum_func({w:g}) must return one number, got shape "
                             f"{v.shape}")
        p[k] = float(v.reshape(()))
        if not np.isfinite(p[k]) or p[k] < 0:
            raise ValueError(f"{o}.spectrum_func({w:g}) returned {float(p[k])!r}: the spectral power "
                             "must be finite and >= 0")
    if not p.sum() > 0:
        raise ValueError(f"{o}.spectrum_func is 0 at every {o}.wavelength: no light to simulate")
    return p / p.sum()


def wavelength_seeds(seed: int, n: int) -> np.ndarray:
    """(n,) the seed of each wavelength of a broadband run of ``seed`` (below 2^63).

    Seed k comes from ``numpy.random.SeedSequence(seed, spawn_key=(k,))``: independent of
    ``n`` and of the seeds of the other wavelengths.
    """
    return np.array([int(np.random.SeedSequence(int(seed), spawn_key=(k,))
                         .generate_state(1, np.uint64)[0] >> np.uint64(1)) for k in range(n)],
                    dtype=np.int64)


def photon_split(n_photons: int, n: int) -> np.ndarray:
    """(n,) photons per wavelength: ``n_photons // n`` each, the last one the remainder."""
    counts = np.full(n, n_photons // n, dtype=np.int64)
    counts[-1] = n_photons - (n - 1) * (n_photons // n)
    return counts


def check_supported(G, MC) -> None:
    o = MC._owner_label
    if MC.n_example_paths:
        raise ValueError(f"{o}.n_example_paths = {MC.n_example_paths}: example paths are not "
                         f"kept in broadband runs ({o}.wavelength an array), as in MCmatlab")
    dependent = [m.name for m in G.media if m.is_state_dependent]
    if dependent:
        raise NotBuiltError(
            f"broadband {o}.wavelength with media whose optics depend on FR, T or FD "
            f"({dependent[0]!r}) is not built: run one wavelength at a time")
    if getattr(MC, "fr_dep_iterations", 0):
        raise NotBuiltError(f"broadband {o}.wavelength with {o}.fr_dep_iterations is not built")
    S = MC.source_distribution
    if S is not None and np.ndim(S) == 4 and np.shape(S)[3] != np.size(MC.wavelength):
        raise ValueError(f"{o}.source_distribution has {np.shape(S)[3]} wavelength slices but "
                         f"{o}.wavelength has {np.size(MC.wavelength)} wavelengths")


def monochromatic(MC, wavelength: float, n_photons, minutes, seed: int, source):
    """A copy of ``MC`` for one wavelength of the run (its own light collector for the image)."""
    sub = copy.copy(MC)
    sub.wavelength = float(wavelength)
    sub.n_photons_requested = None if n_photons is None else int(n_photons)
    sub.simulation_time_requested = minutes
    sub.seed = int(seed)
    sub.progress = False
    sub.source_distribution = source
    sub.light_collector = copy.copy(MC.light_collector)
    return sub


class WavelengthStack:
    """The runs' outputs gathered along a last, wavelength axis."""

    def __init__(self, n: int):
        self.n = n
        self.maps: dict = {}
        self.fractions = {f: np.full(n, np.nan) for f in FRACTIONS}
        self.escaped: dict = {}
        self.photons = np.zeros(n, dtype=np.int64)
        self.collected = None
        self.seconds = self.cpu_seconds = 0.0
        self.last = None

    def _put(self, name: str, k: int, value) -> None:
        if value is None:
            return
        value = np.asarray(value, dtype=np.float64)
        if name not in self.maps:
            self.maps[name] = np.zeros((*value.shape, self.n))
        self.maps[name][..., k] = value

    def add(self, k: int, sub) -> None:
        for name in MAPS:
            self._put(name, k, getattr(sub, name))
        if sub.use_light_collector:
            self._put("image", k, sub.light_collector.image)
        for f in FRACTIONS:
            self.fractions[f][k] = getattr(sub, f)
        for face, v in sub.escaped.items():
            self.escaped.setdefault(face, np.full(self.n, np.nan))[k] = v
        self.photons[k] = sub.n_photons
        if sub.n_photons_collected is not None:
            self.collected = (self.collected or 0) + int(sub.n_photons_collected)
        self.seconds += sub.simulation_time
        self.cpu_seconds += sub.cores_used * sub.simulation_time
        self.last = sub

    def store(self, MC) -> None:
        last = self.last
        for name in MAPS:
            setattr(MC, name, self.maps.get(name))
        for name in AXES:
            setattr(MC, name, getattr(last, name))
        if MC.use_light_collector:
            LC, LC_last = MC.light_collector, last.light_collector
            LC.image = self.maps["image"]
            LC.X, LC.Y, LC.t = LC_last.X, LC_last.Y, LC_last.t
        for f, v in self.fractions.items():
            setattr(MC, f, v)
        MC.escaped = self.escaped
        MC.n_photons_per_wavelength = self.photons
        MC.n_photons = int(self.photons.sum())
        MC.n_photons_collected = self.collected
        MC.simulation_time = self.seconds
        MC.photons_per_second = MC.n_photons / max(self.seconds, 1e-12)
        MC.cores_used = self.cpu_seconds / max(self.seconds, 1e-12)
        MC.M = last.M
        MC.example_paths = None


def stacked_properties(G, M_raw, wavelengths) -> OpticalMediaProperties:
    """MCmatlab's broadband ``mediaProperties``: (n_media, n) mua, mus, g, n."""
    each = [optical_media_properties(G.media, M_raw, float(w)) for w in wavelengths]
    first = each[0]
    mua, mus, g, n = (np.column_stack([getattr(p, f) for p in each])
                      for f in ("mua", "mus", "g", "n"))
    return OpticalMediaProperties(mua, mus, g, n, first.parent, first.names, first.M)
