"""The whole thermal image: a camera's pixels over the top face as observations.

A thermal camera sees the surface temperature averaged over each pixel's footprint. A
:class:`ThermalImage` is an ``ny x nx`` grid of square or rectangular pixels over a
region of the top face (z = 0); its observation operator averages the model's surface
field over each footprint (mean of ``subsamples x subsamples`` point probes per pixel,
exact for the bilinear parts of the P1 field as the sub-grid refines). Frames come
from an NPZ file (``times`` (n,) s and ``frames`` (n, ny, nx) deg C, NaN for dead
pixels) or from arrays.

The analysis with hundreds to thousands of pixels stays fast in the ensemble
transform (ETKF) form: its cost is O(N^2 p) for p pixels and a diagonal D
(``enkf.analysis.etkf``); ``enkf.analysis.enkf_localized`` adds covariance
localization for the perturbed-observation filter.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp

__all__ = ["ThermalImage", "estimate_spot_center"]


@dataclass(frozen=True)
class ThermalImage:
    """A camera's pixel grid over the top face.

    Parameters
    ----------
    x_range, y_range : (lo, hi), cm
        The imaged region of the top face (x, y in [-L/2, L/2] as in MCmatlab).
    shape : (ny, nx)
        Pixels along y (rows) and x (columns); frames are (ny, nx) arrays.
    noise_var : float
        deg C^2, the noise variance of one pixel reading (D = noise_var I).
    subsamples : int
        Probes per pixel side used to average the surface field over a footprint.
    model_error_rel_std : float
        The filter's model error in each pixel, as a fraction of the pixel's predicted
        rise above the initial temperature, at each of the correlation lengths (see
        :meth:`error_covariance`); 0 turns it off.
    model_error_lengths : tuple of float
        cm, the correlation lengths of that error between pixels (squared exponential),
        an error of ``model_error_rel_std`` at each; 0: independent pixels.
    binning : int
        Super-pixels: each reading is the mean of a ``binning x binning`` block of the
        camera's pixels (``shape`` stays the frames' shape and must be a multiple of it);
        1 (default): one reading per pixel. See :meth:`readings`.
    """

    x_range: tuple[float, float]
    y_range: tuple[float, float]
    shape: tuple[int, int]
    noise_var: float = 0.01
    subsamples: int = 4
    #: sized from the coarse model against independent models (2-5% of the rise,
    #: validation/reports/model_error_coverage.md) and the emulator (1-3%)
    model_error_rel_std: float = 0.04
    #: a pixel-scale error (0.02 cm, 0.8 pixel pitch of the paper's 250 um camera: the
    #: interpolation, the Monte Carlo's noise) and a beam-scale one (0.1 cm: a hot spot too
    #: wide or too narrow, as the independent models' images differ from ours);
    #: docs/beyond.md, "The model's error in the image"
    model_error_lengths: tuple = (0.02, 0.1)
    #: deg, counterclockwise: the angle from the tissue's x axis to the image's rows (the
    #: camera turned about the beam's axis, x = y = 0); ``x_range`` and ``y_range`` are
    #: then the image's extent along its own columns and rows, from the beam's axis
    rotation: float = 0.0
    #: the image is mirrored (its columns run along -x before the rotation)
    mirror: bool = False
    #: the camera's pixels per super-pixel side: the filter reads block means (a 64 x 64
    #: camera at 10 Hz as 16 x 16 readings, docs/camera.md); their noise is
    #: ``noise_var / binning**2`` and their model error the block mean of the pixels'
    binning: int = 1

    @classmethod
    def registered(cls, shape, pixel_size, spot_center, rotation: float = 0.0,
                   mirror: bool = False, **kw) -> ThermalImage:
        """The camera of ``shape`` (ny, nx) whose pixels are ``pixel_size`` cm (one number
        or (dx, dy)) and which sees the laser spot's centre at ``spot_center`` = (column,
        row) in pixels (0-based indices of the pixels' centres, fractional), turned by
        ``rotation`` degrees (see :attr:`rotation`, :attr:`mirror`)."""
        ny, nx = (int(v) for v in shape)
        dx, dy = (float(v) for v in np.broadcast_to(np.asarray(pixel_size, float), (2,)))
        col, row = (float(v) for v in spot_center)
        return cls(((-0.5 - col) * dx, (nx - 0.5 - col) * dx),
                   ((-0.5 - row) * dy, (ny - 0.5 - row) * dy), (ny, nx),
                   rotation=rotation, mirror=mirror, **kw)

    def to_tissue(self, uv: np.ndarray) -> np.ndarray:
        """(..., 2) cm on the top face of points (..., 2) in the image's own axes (along
        its columns, along its rows, from the beam's axis)."""
        uv = np.asarray(uv, float)
        u = -uv[..., 0] if self.mirror else uv[..., 0]
        c, s = np.cos(np.radians(self.rotation)), np.sin(np.radians(self.rotation))
        return np.stack([c * u - s * uv[..., 1], s * u + c * uv[..., 1]], axis=-1)

    def footprint_bounds(self) -> tuple[float, float, float, float]:
        """``(x_lo, x_hi, y_lo, y_hi)`` cm: the box on the top face that the image covers."""
        (x0, x1), (y0, y1) = self.x_range, self.y_range
        xy = self.to_tissue(np.array([[x0, y0], [x1, y0], [x0, y1], [x1, y1]]))
        return (float(xy[:, 0].min()), float(xy[:, 0].max()), float(xy[:, 1].min()),
                float(xy[:, 1].max()))

    def __post_init__(self):
        for name in ("x_range", "y_range"):
            lo, hi = (float(v) for v in getattr(self, name))
            if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
                raise ValueError(f"ThermalImage.{name} must be (lo, hi) with lo < hi (cm), "
                                 f"got {getattr(self, name)!r}")
        ny, nx = (int(v) for v in self.shape)
        if ny < 1 or nx < 1:
            raise ValueError(f"ThermalImage.shape must be (ny, nx) >= 1, got {self.shape!r}")
        if not (np.isfinite(self.noise_var) and self.noise_var > 0):
            raise ValueError(f"ThermalImage.noise_var must be > 0 (deg C^2), got {self.noise_var!r}")
        if int(self.subsamples) < 1:
            raise ValueError(f"ThermalImage.subsamples must be >= 1, got {self.subsamples!r}")
        v = self.model_error_rel_std
        if not (np.isfinite(v) and v >= 0):
            raise ValueError(f"ThermalImage.model_error_rel_std must be a finite number >= 0, "
                             f"got {v!r}")
        lengths = np.atleast_1d(np.asarray(self.model_error_lengths, dtype=float))
        if lengths.ndim != 1 or lengths.size == 0 or not np.all(np.isfinite(lengths)
                                                                 & (lengths >= 0)):
            raise ValueError(f"ThermalImage.model_error_lengths must be one or more finite "
                             f"lengths >= 0 (cm), got {self.model_error_lengths!r}")
        object.__setattr__(self, "model_error_lengths", tuple(float(x) for x in lengths))
        b = self.binning
        if isinstance(b, bool) or int(b) != b or b < 1 or ny % int(b) or nx % int(b):
            raise ValueError(f"ThermalImage.binning must be an integer >= 1 that divides the "
                             f"shape {tuple(self.shape)}, got {b!r}")
        object.__setattr__(self, "binning", int(b))
        if not np.isfinite(self.rotation):
            raise ValueError(f"ThermalImage.rotation must be a finite angle (deg), got "
                             f"{self.rotation!r}")

    def error_correlation(self) -> np.ndarray:
        """(n_pixels, n_pixels): the sum over ``model_error_lengths`` of the correlations
        ``exp(-d^2 / (2 length^2))`` between pixel centres (the identity for length 0);
        with :attr:`binning`, those of the block means of the camera's pixels."""
        if self.binning == 1:
            return self.point_correlation(self.pixel_centers()[:, :2])
        # the kernel on the camera's (rotated) pixel grid depends on the distance along its
        # rows times the one along its columns: C = K_rows (x) K_cols for each length, and
        # the block means are the blocks' means of those 1-D kernels (never the p^2 matrix
        # of the camera's pixels)
        ny, nx = (int(v) for v in self.shape)
        b = self.binning
        out = 0.0
        for ell in self.model_error_lengths:
            K = []
            for n, (lo, hi) in ((ny, self.y_range), (nx, self.x_range)):
                c = (np.arange(n) + 0.5) * (hi - lo) / n
                d2 = (c[:, None] - c[None, :]) ** 2
                k = (d2 == 0).astype(float) if ell == 0 else np.exp(-0.5 * d2 / ell ** 2)
                K.append(k.reshape(n // b, b, n // b, b).mean(axis=(1, 3)))
            out = out + np.kron(K[0], K[1])
        return out

    def point_correlation(self, points_xy: np.ndarray) -> np.ndarray:
        """(q, n_pixels): the same sum between points of the top face ``points_xy`` (q, 2)
        cm and the pixel centres (length 0: one where a point is a pixel's centre)."""
        pts = np.asarray(points_xy, float).reshape(-1, 2)
        if self.binning > 1:  # the block means of the camera's pixels'
            (ny, nx), b = self.grid, self.binning
            fine = replace(self, binning=1).point_correlation(pts)
            return fine.reshape(-1, ny, b, nx, b).mean(axis=(2, 4)).reshape(-1, ny * nx)
        d2 = np.sum((pts[:, None, :] - self.pixel_centers()[None, :, :2]) ** 2, axis=-1)
        return sum((d2 == 0).astype(float) if ell == 0 else np.exp(-0.5 * d2 / ell ** 2)
                   for ell in self.model_error_lengths)

    def error_covariance(self, predicted: np.ndarray, T_ref: float,
                         correlation: np.ndarray | None = None) -> np.ndarray:
        r"""(n_pixels, n_pixels) deg C^2: the model error of the pixels, added to their noise.

        .. math::

            R_{ij} = \alpha^2\,|\bar y_i - T_0|\,|\bar y_j - T_0|\,
                     \sum_\ell \exp\!\big(-d_{ij}^2 / 2\ell^2\big),

        with :math:`\alpha` = ``model_error_rel_std``, :math:`\ell` over
        ``model_error_lengths``, :math:`\bar y` the forecast's mean of each pixel
        (``predicted``, deg C) and :math:`T_0` = ``T_ref``. A model that is a few percent
        wrong in the absorbed power or the conduction is wrong by a few percent of the
        rise, in many pixels of the hot spot at once; hundreds of pixels read as
        independent would otherwise weigh that error as information and pull the optics
        and the unseen temperatures beneath the surface away from the truth with a
        collapsed spread. ``correlation``: :meth:`error_correlation`, if already computed.
        """
        rise = np.abs(np.asarray(predicted, float) - float(T_ref))
        if rise.shape != (self.n_pixels,):
            raise ValueError(f"predicted must have shape ({self.n_pixels},), got {rise.shape}")
        C = self.error_correlation() if correlation is None else correlation
        a = self.model_error_rel_std * rise
        return np.outer(a, a) * C

    def point_error(self, points_xy: np.ndarray, point_rise: np.ndarray, predicted: np.ndarray,
                    T_ref: float, correlation: np.ndarray | None = None
                    ) -> tuple[np.ndarray, np.ndarray]:
        r"""The same model error at points of the top face: ``(k_zy (q, n_pixels), k_zz
        (q,))`` deg C^2, the covariance of each point's error with the pixels' and its
        variance, :math:`\alpha^2 |z_i - T_0| |\bar y_j - T_0| \sum_\ell
        \exp(-d_{ij}^2/2\ell^2)` and :math:`\alpha^2 (z_i - T_0)^2 n_\ell`.

        ``points_xy`` (q, 2) cm, ``point_rise`` (q,) deg C: the model's rise at the points
        (its forecast less ``T_ref``); ``predicted`` (n_pixels,) deg C as in
        :meth:`error_covariance`. A model that is a few percent wrong at every pixel is as
        wrong at a point between them: :func:`enkf.discrepancy.discrepancy_posterior`
        turns these into the points' share of the error given the frame. ``correlation``:
        :meth:`point_correlation` of the points, if already computed.
        """
        q = np.asarray(points_xy, float).reshape(-1, 2).shape[0]
        a_z = self.model_error_rel_std * np.abs(np.asarray(point_rise, float).reshape(-1))
        a_y = self.model_error_rel_std * np.abs(np.asarray(predicted, float) - float(T_ref))
        if a_z.shape != (q,) or a_y.shape != (self.n_pixels,):
            raise ValueError(f"point_rise must have shape ({q},) and predicted "
                             f"({self.n_pixels},), got {a_z.shape} and {a_y.shape}")
        C = self.point_correlation(points_xy) if correlation is None else correlation
        return a_z[:, None] * a_y[None, :] * C, a_z ** 2 * len(self.model_error_lengths)

    @property
    def grid(self) -> tuple[int, int]:
        """(ny, nx) of the readings: :attr:`shape` over :attr:`binning`."""
        return int(self.shape[0]) // self.binning, int(self.shape[1]) // self.binning

    @property
    def n_pixels(self) -> int:
        """The readings of a frame (super-pixels with :attr:`binning`)."""
        return self.grid[0] * self.grid[1]

    @property
    def reading_noise_var(self) -> float:
        """deg C^2: the noise of one reading, the mean of ``binning**2`` pixels'."""
        return float(self.noise_var) / self.binning ** 2

    def readings(self, frames: np.ndarray) -> np.ndarray:
        """(..., n_pixels) deg C: the readings of frames (..., ny, nx) of :attr:`shape`,
        each the mean of its ``binning x binning`` block (NaN where any of its pixels is
        dead: the noise of a mean of fewer pixels would be larger than stated)."""
        f = np.asarray(frames, float)
        ny, nx = (int(v) for v in self.shape)
        if f.shape[-2:] != (ny, nx):
            raise ValueError(f"frames must end with the camera's shape ({ny}, {nx}), got "
                             f"{f.shape}")
        if self.binning > 1:
            (gy, gx), b = self.grid, self.binning
            f = f.reshape(*f.shape[:-2], gy, b, gx, b).mean(axis=(-3, -1))
        return f.reshape(*f.shape[:-2], self.n_pixels)

    def pixel_centers(self) -> np.ndarray:
        """(n_pixels, 3) cm, pixel centres on z = 0, rows of the frame in C order."""
        return self._points(1)[:, 0, :]

    def _points(self, s: int) -> np.ndarray:
        """(n_pixels, s*s, 3) sub-pixel sample points (midpoints of an s x s split)."""
        ny, nx = self.grid
        (x0, x1), (y0, y1) = self.x_range, self.y_range
        dx, dy = (x1 - x0) / nx, (y1 - y0) / ny
        u = (np.arange(s) + 0.5) / s
        px = x0 + (np.arange(nx)[:, None] + u[None, :]) * dx  # (nx, s)
        py = y0 + (np.arange(ny)[:, None] + u[None, :]) * dy  # (ny, s)
        X = np.broadcast_to(px[None, :, None, :], (ny, nx, s, s))
        Y = np.broadcast_to(py[:, None, :, None], (ny, nx, s, s))
        if self.rotation or self.mirror:  # the image's axes onto the tissue's
            X, Y = np.moveaxis(self.to_tissue(np.stack([X, Y], axis=-1)), -1, 0)
        pts = np.stack([X, Y, np.zeros_like(X)], axis=-1)
        return pts.reshape(ny * nx, s * s, 3)

    def sample_points(self) -> np.ndarray:
        """(n_pixels * subsamples^2, 3) cm: every probe point, pixel by pixel."""
        return self._points(self._probes()).reshape(-1, 3)

    def _probes(self) -> int:
        # a super-pixel's midpoints are its pixels' (the same footprint average)
        return int(self.subsamples) * self.binning

    def average(self, values: np.ndarray) -> np.ndarray:
        """Pixel values (..., n_pixels) from values at :meth:`sample_points` (..., n_points)."""
        v = np.asarray(values, float)
        s2 = self._probes() ** 2
        return v.reshape(*v.shape[:-1], self.n_pixels, s2).mean(axis=-1)

    def matrix(self, mesh, interpolation: str = "cubic") -> sp.csr_matrix:
        """(n_pixels, n_nodes): the footprint average of the model's surface field.

        ``interpolation="cubic"`` (default, structured box meshes): the surface field
        between nodes is the tensor-product cubic Lagrange interpolant of the nodal
        values (4 x 4 nodes around each probe). ``"p1"``: the finite-element field
        itself, piecewise linear, which flattens a peaked surface field between nodes:
        with pixels the size of an element it averaged the paper's hot spot 0.7% low,
        against 0.1% at the nodes, and over 256 pixels that bias is what the filter
        then fits (validation/reports/image_vs_point.md).
        """
        import fem

        if interpolation not in ("cubic", "p1"):
            raise ValueError(f"interpolation must be 'cubic' or 'p1', got {interpolation!r}")
        pts = self.sample_points()
        lo, hi = mesh.p.min(axis=1), mesh.p.max(axis=1)
        tol = 1e-9 * float(np.max(hi - lo))
        outside = np.any((pts < lo - tol) | (pts > hi + tol), axis=1)
        if outside.any():
            bad = pts[np.flatnonzero(outside)[0]]
            raise ValueError(f"ThermalImage: pixel footprint point {tuple(bad.round(6))} cm is "
                             f"outside the tissue [{lo.round(6)}, {hi.round(6)}]")
        grid = fem.structured_grid(mesh) if interpolation == "cubic" else None
        P = _cubic_surface_probes(grid, pts) if grid is not None else fem.probe_matrix(mesh, pts.T)
        s2 = self._probes() ** 2
        A = sp.csr_matrix((np.full(pts.shape[0], 1.0 / s2),
                           (np.repeat(np.arange(self.n_pixels), s2), np.arange(pts.shape[0]))),
                          shape=(self.n_pixels, pts.shape[0]))
        return (A @ P).tocsr()


def estimate_spot_center(frames: np.ndarray, noise_sd: float, *, min_snr: float = 20.0,
                         n_average: int = 5, complete: bool = True
                         ) -> tuple[float, float] | None:
    """(column, row) in pixels of the laser spot's centre, from a camera's first frames.

    The rise of each frame over the first (the tissue before, or as, the laser starts) is
    taken from the first frame whose largest rise exceeds ``min_snr`` times the noise of a
    difference of two frames (``noise_sd`` deg C, one pixel's); the mean rise of that frame
    and up to ``n_average - 1`` after it is averaged over the pixels above half its
    maximum, each weighted by its rise: the centre of a symmetric spot, whatever the
    camera's rotation, to a fraction of a pixel. None while no frame rises enough, or,
    with ``complete=False`` (a follower, which then waits for more frames), while fewer
    than ``n_average`` frames from the first that does are there.

    ``frames`` (n, ny, nx) deg C, NaN for dead pixels.
    """
    f = np.asarray(frames, float)
    if f.ndim != 3 or f.shape[0] < 2:
        return None
    rise = f[1:] - f[:1]
    peak = np.nanmax(np.where(np.isfinite(rise), rise, -np.inf).reshape(rise.shape[0], -1), axis=1)
    above = np.flatnonzero(peak > min_snr * np.sqrt(2.0) * float(noise_sd))
    if above.size == 0:
        return None
    k = int(above[0])
    if not complete and rise.shape[0] < k + n_average:
        return None
    mean = np.nanmean(rise[k:k + n_average], axis=0)
    w = np.where(np.isfinite(mean) & (mean > 0.5 * np.nanmax(mean)), mean, 0.0)
    rows, cols = np.indices(w.shape)
    return float((w * cols).sum() / w.sum()), float((w * rows).sum() / w.sum())


def _lagrange_stencil(u: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """4-point Lagrange stencil at node coordinates ``u`` (in units of the spacing) on
    nodes 0..n: first node index (m,) and weights (m, 4); shifted inward at the ends."""
    i0 = np.clip(np.floor(u).astype(int) - 1, 0, max(n - 3, 0))
    t = u - i0
    nodes = np.arange(4.0)
    w = np.ones((u.size, 4))
    for a in range(4):
        for b in range(4):
            if a != b:
                w[:, a] *= (t - nodes[b]) / (nodes[a] - nodes[b])
    return i0, w


def _cubic_surface_probes(grid, pts: np.ndarray) -> sp.csr_matrix:
    """(n_points, n_nodes): tensor-product cubic interpolation of the top-face nodes."""
    lo = grid.lower
    ix, wx = _lagrange_stencil((pts[:, 0] - lo[0]) / grid.dx, grid.nx)
    iy, wy = _lagrange_stencil((pts[:, 1] - lo[1]) / grid.dy, grid.ny)
    rows, cols, vals = [], [], []
    r = np.arange(pts.shape[0])
    for a in range(4):
        for b in range(4):
            rows.append(r)
            cols.append(grid.node_index(ix + a, iy + b, 0))
            vals.append(wx[:, a] * wy[:, b])
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(pts.shape[0], grid.npoints))
