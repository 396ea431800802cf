"""Python layer of the optional Monte Carlo outputs: pack the requests, unpack the tallies.

:func:`output_spec` turns ``model.MC``'s requests (light collector, far field, boundary
irradiance, MCML bins, deposition criteria, example paths) into the arrays of
:mod:`mcmatlab_py.monte_carlo._outputs`, or ``None`` when nothing is requested: the kernel is then
compiled without them. :func:`store_outputs` normalises the fixed-point tallies as
MCmatlab does (per W launched; per cm^2 for maps and images, W/W per far-field bin).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from . import _outputs as O
from ._tally import W_ONE

FACES = ("xpos", "xneg", "ypos", "yneg", "zpos", "zneg")
PATH_LEN = 2000  #: vertices kept per example path (the rest of a longer path is dropped)


@dataclass
class OutputSpec:
    """The packed requests and where each output lies in the ``ext`` tally row."""

    oi: np.ndarray | None
    of: np.ndarray
    consider: np.ndarray  #: (n_sub_media,) bool, media counted by the deposition criteria
    n_ext: int
    n_paths: int
    slices: dict = field(default_factory=dict)  #: output name -> (offset, shape)

    @property
    def active(self) -> bool:
        return self.oi is not None

    def arrays(self, n_workers: int) -> tuple:
        """The six kernel arguments, with fresh tallies for ``n_workers``."""
        ext = np.zeros((n_workers, self.n_ext), dtype=np.int64)
        paths = np.full((max(self.n_paths, 1), PATH_LEN if self.n_paths else 1, 4), np.nan)
        path_n = np.zeros(max(self.n_paths, 1), dtype=np.int64)
        return self.oi, self.of, self.consider, ext, paths, path_n


def far_field_solid_angles(res: int) -> np.ndarray:
    """(res, res) sr: the solid angle of each (theta, phi) bin of ``MC.far_field`` (theta
    in ``res`` equal steps over [0, pi], phi over [-pi, pi]); ``far_field`` over it is the
    radiant intensity per W incident (W/sr/W), what MCmatlab draws. The bins sum to 4 pi."""
    edges = np.linspace(0.0, np.pi, int(res) + 1)
    band = np.cos(edges[:-1]) - np.cos(edges[1:])
    return np.repeat((2.0 * np.pi / int(res) * band)[:, None], int(res), axis=1)


def output_spec(G, MC, n_sub: int, parent: np.ndarray | None) -> OutputSpec:
    """Pack ``MC``'s output requests for the kernel; ``parent`` maps sub-media to ``G.media``."""
    oi = np.zeros(O.OI_SIZE, dtype=np.int64)
    of = np.zeros(O.OF_SIZE, dtype=np.float64)
    slices = {}
    n = O.EXT_HEAD

    def add(name, shape):
        nonlocal n
        slices[name] = (n, shape)
        n += int(np.prod(shape))
        return slices[name][0]

    any_output = False
    if MC.calc_normalized_irradiance:
        any_output = True
        oi[O.OI_NI] = 1
        shapes = {"x": (G.ny, G.nz), "y": (G.nx, G.nz), "z": (G.nx, G.ny)}
        for k, face in enumerate(FACES):
            oi[O.OI_OFF_NI + k] = add(f"NI_{face}", shapes[face[0]])
    if MC.far_field_res:
        any_output = True
        oi[O.OI_FF_RES] = MC.far_field_res
        oi[O.OI_OFF_FF] = add("far_field", (MC.far_field_res, MC.far_field_res))
    if MC.use_light_collector:
        any_output = True
        LC = MC.light_collector
        oi[O.OI_LC] = 2 if LC.is_fiber else 1
        oi[O.OI_LC_RES] = LC.res
        nt = LC.n_time_bins + 2 if LC.n_time_bins else 1
        oi[O.OI_LC_NT] = nt
        oi[O.OI_OFF_IMG] = add("image", (LC.res, LC.res, nt))
        c = LC.centre()
        of[O.OF_LC_R:O.OF_LC_R + 3] = (c[0] + G.Lx / 2, c[1] + G.Ly / 2, c[2])
        of[O.OF_LC_THETA], of[O.OF_LC_PHI] = LC.theta, LC.phi
        of[O.OF_LC_F] = LC.f
        of[O.OF_LC_DIAM] = LC.diam
        of[O.OF_LC_FS_OR_NA] = LC.NA if LC.is_fiber else LC.field_size
        of[O.OF_T_START], of[O.OF_T_END] = LC.t_start, LC.t_end
    if MC.n_radial_bins:
        any_output = True
        oi[O.OI_NR], oi[O.OI_NA] = MC.n_radial_bins, MC.n_angle_bins
        of[O.OF_DR] = MC.radial_bin_size
        for name, nb in (("Rd_r", MC.n_radial_bins), ("Rd_a", MC.n_angle_bins),
                         ("Tt_r", MC.n_radial_bins), ("Tt_a", MC.n_angle_bins)):
            oi[getattr(O, f"OI_OFF_{name.upper()}")] = add(name, (nb,))
    of[O.OF_X0] = MC.light_source.x_focus + G.Lx / 2
    of[O.OF_Y0] = MC.light_source.y_focus + G.Ly / 2
    DC = MC.deposition_criteria
    consider = np.zeros(n_sub, dtype=np.bool_)
    if not DC.is_default:
        any_output = True
        oi[O.OI_DC] = 1
        oi[O.OI_DC_END] = int(DC.evaluate_only_at_end_of_life)
        oi[O.OI_DC_COLLECTED] = int(DC.only_collected)
        for k, kind in enumerate(DC.KINDS):
            oi[O.OI_DC_MIN + k] = getattr(DC, f"min_{kind}")
            hi = getattr(DC, f"max_{kind}")
            oi[O.OI_DC_MAX + k] = O.DC_UNLIMITED if hi == math.inf else hi
        par = np.arange(n_sub) if parent is None else np.asarray(parent)
        consider = (par >= DC.min_medium_idx_to_consider) & (par <= DC.max_medium_idx_to_consider)
    if MC.n_example_paths:
        any_output = True
        oi[O.OI_N_PATHS] = MC.n_example_paths
        oi[O.OI_PATH_LEN] = PATH_LEN
    if MC.request_collected_photons:
        any_output = True
    return OutputSpec(oi if any_output else None, of, consider, n, MC.n_example_paths, slices)


def store_outputs(G, MC, spec: OutputSpec, ext: np.ndarray, paths: np.ndarray,
                  path_n: np.ndarray, launched: float) -> None:
    """Normalise the summed ``ext`` tallies (fixed point) into ``MC``'s outputs."""
    def get(name):
        off, shape = spec.slices[name]
        return ext[off:off + int(np.prod(shape))].reshape(shape) / (W_ONE * launched)

    if "NI_xpos" in spec.slices:
        area = {"x": G.dy * G.dz, "y": G.dx * G.dz, "z": G.dx * G.dy}
        for face in FACES:
            setattr(MC, f"NI_{face}", get(f"NI_{face}") / area[face[0]])
    if "far_field" in spec.slices:
        res = MC.far_field_res
        MC.far_field = get("far_field")  # W/W per (theta, phi) bin, as MCmatlab
        MC.far_field_theta = (np.arange(res) + 0.5) * np.pi / res
        MC.far_field_phi = -np.pi + (np.arange(res) + 0.5) * 2 * np.pi / res
    if "image" in spec.slices:
        LC = MC.light_collector
        img = get("image")
        if LC.is_fiber:
            img = img[0, 0]  # W/W
            LC.X = LC.Y = None
        else:
            img = img / (LC.field_size / LC.res) ** 2  # W/cm^2/W in the object plane
            LC.X = LC.field_size * ((np.arange(LC.res) + 0.5) / LC.res - 0.5)
            LC.Y = LC.X.copy()
        if LC.n_time_bins:
            dt = (LC.t_end - LC.t_start) / LC.n_time_bins
            LC.t = LC.t_start + (np.arange(LC.n_time_bins + 2) - 0.5) * dt
        else:
            img = img[..., 0]
            LC.t = None
        LC.image = float(img) if np.ndim(img) == 0 else img
        MC.n_photons_collected = int(ext[O.EXT_COLLECTED])
    if "Rd_r" in spec.slices:
        dr, nr, na = MC.radial_bin_size, MC.n_radial_bins, MC.n_angle_bins
        ring = 2 * np.pi * (np.arange(nr) + 0.5) * dr * dr  # exact annulus areas, cm^2
        da = 0.5 * np.pi / na
        a = np.arange(na + 1) * da
        solid = 2 * np.pi * (np.cos(a[:-1]) - np.cos(a[1:]))  # sr
        MC.Rd_r, MC.Tt_r = get("Rd_r") / ring, get("Tt_r") / ring
        MC.Rd_a, MC.Tt_a = get("Rd_a") / solid, get("Tt_a") / solid
        MC.radial_r = (np.arange(nr) + 0.5) * dr
        MC.exit_angle = (np.arange(na) + 0.5) * da
    if spec.n_paths:
        cols = []
        for i in range(spec.n_paths):
            k = int(path_n[i])
            if k == 0:
                continue
            p = paths[i, :k].T.copy()
            p[0] -= G.Lx / 2
            p[1] -= G.Ly / 2
            cols += [np.full((4, 1), np.nan), p]
        MC.example_paths = np.hstack(cols) if cols else np.zeros((4, 0))
