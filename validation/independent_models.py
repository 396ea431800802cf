"""Forward models of the paper's block that share no code with the filter's model.

The filter's model is MCmatlab's Monte Carlo (numba kernel, implicit capture: the packet
loses ``w mua / mut`` at every interaction, scored on 100 x 100 x 50 voxels), tabulated
by the emulator and integrated onto the P1 basis of a 20 x 20 x 10 tetrahedral mesh,
stepped by the FEM heat solver (``fem``). To see how honest its uncertainty is when the
truth comes from *another* model, this module writes truths of its own, in plain
numpy and scipy, importing nothing from ``mcmatlab_py``, ``fem`` or ``enkf``:

``"A"``
    **Analog Monte Carlo** (each photon is absorbed whole at one interaction, with
    probability ``mua / mut``; no weights), scored on an axisymmetric ``(r, z)`` grid of
    0.0125 x 0.00625 cm, and a **cell-centred finite-difference** heat solver on a
    35 x 35 x 24 Cartesian grid of the box (insulated faces, backward Euler, 0.00625 s:
    converged in time to 0.04% of the peak; at 0.05 s it lags by 0.25-0.35% of the
    peak, 0.05-0.21 deg C at the surface).
``"B"``
    **Attenuation (path-length) Monte Carlo** (packets scatter with ``mus`` only, their
    weight decays as ``exp(-mua s)`` along each flight; the lost weight is deposited at a
    point drawn on the flight with density ``mua exp(-mua s')``, an unbiased track
    estimator; Russian roulette below 1e-3), scored on a 0.01 x 0.005 cm ``(r, z)`` grid,
    and an **axisymmetric finite-volume** heat solver on a cylinder of the box's
    cross-section area (radius 0.282 cm, 40 x 40 cells, Crank-Nicolson, 0.1 s). The
    cylinder for the box is itself a model error, as a real tissue's shape would be.

``"D"``
    **Model A with 10 times the photons** (2 x 10^6 a map, its own seeds) and A's
    finite differences. A's 2 x 10^5 analog photons leave the absorbed power under the
    beam's centre noisy: through C's spectral heat solution, the surface after 5 s of the
    constant case reads 19.83 deg C on A's map and 19.33 on one of another seed; with 2 x
    10^6 photons two seeds read 19.44 and 19.50 (B's 2 x 10^5 attenuation photons, two
    seeds: 19.58 and 19.50; the filter's model at the truth's optics 19.58). A's truth
    thus lies about 1.8% above its own converged model at the sensor, which the filter,
    fitting the surface, reads as mus about 10% high (constant optics: 110 against 100).
    D is that model converged in its photons.

``"C"``
    **Model B's Monte Carlo** (the same absorbed-power maps) with a **spectral heat
    solution on the box**: the insulated box's cosine eigenmodes on a 64 x 64 x 32 cell
    grid (the source cell-averaged from 4 x 4 x 2 points per cell, projected by a DCT),
    each mode integrated exactly in time over steps of 0.025 s with the source held at
    its mid-step value; temperatures evaluated from the series at the probe points. B and
    C differ only in the heat model, so C tells what B's cylinder costs.

All three: top-hat beam of radius 0.1 cm, collimated along +z, matched interfaces (no
reflection), every face of the 0.5 x 0.5 x 0.25 cm block escapes light, Table 1's
tissue (g 0.9, VHC 3.76, TC 0.0037), 0.5 W for 5 s then 10 s off. The drifting case
(the paper's ramps, mua 1 -> 4, mus 100 -> 500 over the pulse) runs the Monte Carlo at
11 instants of the pulse (every 0.5 s) and interpolates the absorbed power linearly in
time between them.

Other cases (:data:`CASES`): a step of the optics at the onset of coagulation, a saturating
drift, a drift of mua alone, and a train of two 2 s pulses with constant and with drifting
optics; every drift runs on heated time (the optics hold still while the laser is off).

    python validation/independent_models.py [CASE ...]  # writes the cache, prints the traces
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

L_XY, L_Z = 0.5, 0.25  # cm
G_ANISO = 0.9
VHC, TC = 3.76, 0.0037  # J cm^-3 K^-1, W cm^-1 K^-1
POWER, T_ON, T_OFF = 0.5, 5.0, 10.0  # W, s, s
BEAM_RADIUS = 0.1  # cm
DEPTHS = (0.0, 0.1, 0.2)  # cm, the tracked points below the beam centre
TIMES = np.round(0.1 * np.arange(151), 10)  # s, the 10 Hz sensor
KNOTS = np.round(0.5 * np.arange(11), 10)  # s, Monte Carlo instants of the drifting case
CACHE = Path.home() / ".cache" / "tissue-enkf" / "independent"
MODELS = ("A", "B")  #: the two truths the studies run by default
#: every model here: C is B's Monte Carlo with a spectral solution on the box
ALL_MODELS = ("A", "B", "C", "D")
DT_A = 0.00625  #: s, model A's backward-Euler step (16 per reading)
#: the cache keys' versions (A's "v1", truths stepped at 0.05 s, is not read)
VERSIONS = {"A": "v2", "B": "v1", "C": "v1", "D": "v1"}
#: whose Monte Carlo maps each model's light is (C's are B's)
LIGHT = {"A": "A", "B": "B", "C": "B", "D": "D"}
#: each light's Monte Carlo: (estimator, dr cm, dz cm, seed, photons per map as a multiple
#: of ``n_photons`` of :func:`independent_truth`); D is A's with 10 times the photons
MONTE_CARLO = {"A": ("analog", 0.0125, 0.00625, 11, 1),
               "B": ("attenuation", 0.01, 0.005, 22, 1),
               "D": ("analog", 0.0125, 0.00625, 33, 10)}


#: the laser of each case: (on, off) windows of 0.5 W (s); the paper's single 5 s pulse
#: unless named here. "pulse-train": two 2 s pulses 3 s apart
PULSES = {"pulse-train": ((0.0, 2.0), (5.0, 7.0)), "pulse-train-drift": ((0.0, 2.0), (5.0, 7.0))}
#: every case: the paper's constant optics and ramps, then drifts of other forms (a step at
#: the onset of coagulation, a saturating curve, mua alone) and a pulse train with constant
#: and with drifting optics
CASES = ("constant", "time-varying", "step", "saturating", "mua-only", "pulse-train",
         "pulse-train-drift")


def pulses(case: str) -> tuple:
    """The laser's on-windows (s) of ``case``."""
    return PULSES.get(case, ((0.0, T_ON),))


def laser_on(case: str, t: float) -> bool:
    return any(a <= t < b for a, b in pulses(case))


def heated(case: str, t: float) -> float:
    """s of laser-on time before ``t`` (the clock of the drifting optics)."""
    return float(sum(max(0.0, min(t, b) - a) for a, b in pulses(case)))


def heated_total(case: str) -> float:
    return heated(case, np.inf)


def optics(case: str, t: float) -> tuple[float, float]:
    """(mua, mus) cm^-1 of the truth at time ``t``: Table 1, the paper's ramps, or the other
    drifts, each a function of the heated time (they stop when the laser does)."""
    h = heated(case, t)
    if case in ("constant", "pulse-train"):
        return 1.0, 100.0
    if case == "time-varying":
        return 1.0 + 0.6 * h, 100.0 + 80.0 * h
    if case == "step":  # coagulation sets in after 2 s of heating, within 0.5 s
        a = min(max((h - 2.0) / 0.5, 0.0), 1.0)
        return 1.0 + 1.5 * a, 100.0 + 200.0 * a
    if case == "saturating":
        a = 1.0 - np.exp(-h / 1.5)
        return float(1.0 + 2.0 * a), float(100.0 + 250.0 * a)
    if case == "mua-only":
        return 1.0 + 0.4 * h, 100.0
    if case == "pulse-train-drift":
        return 1.0 + 0.5 * h, 100.0 + 50.0 * h
    raise ValueError(f"unknown case {case!r}; one of {CASES}")


# ------------------------------------------------------------------------- Monte Carlo


#: where the truth lies in the filter's prior (0.5 to 2 times the nominal optics)
PRIORS = ("centred", "drawn")


def nominal_optics(case: str, prior: str, key) -> tuple[float, float]:
    """The filter's nominal (mua, mus) cm^-1, its prior's centre, for a run of ``case``:
    the truth's start with ``prior = "centred"``; with ``"drawn"``, the truth's start
    divided by factors drawn uniformly from the prior's range 0.5 to 2 (the generator
    seeded by ``key``), so that the truth lies where the prior puts it at random, as when
    a user's guess of the tissue is off."""
    start = optics(case, 0.0)
    if prior == "centred":
        return float(start[0]), float(start[1])
    if prior != "drawn":
        raise ValueError(f"prior must be one of {PRIORS}, got {prior!r}")
    r = np.random.default_rng(key).uniform(0.5, 2.0, 2)
    return float(start[0] / r[0]), float(start[1] / r[1])


def _hg_scatter(ux, uy, uz, g, rng):
    """New directions after Henyey-Greenstein scattering (Wang & Jacques 1995, MCML)."""
    n = ux.size
    xi = rng.random(n)
    tmp = (1 - g * g) / (1 - g + 2 * g * xi)
    cost = np.clip((1 + g * g - tmp * tmp) / (2 * g), -1.0, 1.0)
    sint = np.sqrt(1 - cost * cost)
    psi = 2 * np.pi * rng.random(n)
    cp, sp_ = np.cos(psi), np.sin(psi)
    vert = np.abs(uz) > 0.99999
    den = np.sqrt(np.maximum(1 - uz * uz, 1e-300))
    nx = np.where(vert, sint * cp, sint * (ux * uz * cp - uy * sp_) / den + ux * cost)
    ny = np.where(vert, sint * sp_, sint * (uy * uz * cp + ux * sp_) / den + uy * cost)
    nz = np.where(vert, np.sign(uz) * cost, -sint * cp * den + uz * cost)
    return nx, ny, nz


def _exit_distance(x, y, z, ux, uy, uz):
    """Distance along (ux, uy, uz) to the faces of the block."""
    big = 1e30
    with np.errstate(divide="ignore", invalid="ignore"):
        dx = np.where(ux > 0, (L_XY / 2 - x) / ux, np.where(ux < 0, (-L_XY / 2 - x) / ux, big))
        dy = np.where(uy > 0, (L_XY / 2 - y) / uy, np.where(uy < 0, (-L_XY / 2 - y) / uy, big))
        dz = np.where(uz > 0, (L_Z - z) / uz, np.where(uz < 0, -z / uz, big))
    return np.minimum(np.minimum(dx, dy), dz)


def monte_carlo(mua: float, mus: float, n_photons: int, estimator: str, dr: float, dz: float,
                seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Absorbed power per watt on an (r, z) grid: (density (nr, nz) W/cm^3/W, r edges,
    z edges). ``estimator``: "analog" or "attenuation" (see the module docstring)."""
    rng = np.random.default_rng(seed)
    r_max = np.hypot(L_XY / 2, L_XY / 2)
    nr, nz = int(np.ceil(r_max / dr)), int(round(L_Z / dz))
    acc = np.zeros(nr * nz)
    rho = BEAM_RADIUS * np.sqrt(rng.random(n_photons))
    phi = 2 * np.pi * rng.random(n_photons)
    x, y, z = rho * np.cos(phi), rho * np.sin(phi), np.zeros(n_photons)
    ux, uy, uz = np.zeros(n_photons), np.zeros(n_photons), np.ones(n_photons)
    w = np.ones(n_photons)
    mut = mua + mus

    def score(px, py, pz, wt):
        ir = np.minimum((np.hypot(px, py) / dr).astype(int), nr - 1)
        iz = np.clip((pz / dz).astype(int), 0, nz - 1)
        acc[:] += np.bincount(ir * nz + iz, weights=wt, minlength=nr * nz)

    while x.size:
        d_exit = _exit_distance(x, y, z, ux, uy, uz)
        if estimator == "analog":
            s = -np.log(rng.random(x.size)) / mut
            out = s >= d_exit
            x, y, z = x + s * ux, y + s * uy, z + s * uz
            absorbed = ~out & (rng.random(x.size) < mua / mut)
            score(x[absorbed], y[absorbed], z[absorbed], np.ones(absorbed.sum()))
            keep = ~out & ~absorbed
        else:  # attenuation: flights drawn with mus, absorption along them
            s = -np.log(rng.random(x.size)) / mus
            out = s >= d_exit
            s_in = np.minimum(s, d_exit)
            lost = w * (1 - np.exp(-mua * s_in))
            # a point on the flight with density mua exp(-mua s') on [0, s_in]
            u = rng.random(x.size)
            s_abs = -np.log(1 - u * (1 - np.exp(-mua * s_in))) / mua
            score(x + s_abs * ux, y + s_abs * uy, z + s_abs * uz, lost)
            w = w - lost
            x, y, z = x + s * ux, y + s * uy, z + s * uz
            keep = ~out
            low = keep & (w < 1e-3)
            survive = rng.random(x.size) < 0.1
            # roulette: a low packet dies or carries on with ten times its weight
            w = np.where(low & survive, 10 * w, w)
            dead = low & ~survive
            if dead.any():  # its last weight is absorbed where it stands
                score(x[dead], y[dead], z[dead], w[dead])
            keep &= ~dead
        x, y, z, ux, uy, uz, w = (a[keep] for a in (x, y, z, ux, uy, uz, w))
        ux, uy, uz = _hg_scatter(ux, uy, uz, G_ANISO, rng)
    r_edges, z_edges = dr * np.arange(nr + 1), dz * np.arange(nz + 1)
    vol = np.outer(annulus_area_in_box(r_edges), np.diff(z_edges))
    return acc.reshape(nr, nz) / n_photons / np.maximum(vol, 1e-300), r_edges, z_edges


def annulus_area_in_box(r_edges: np.ndarray, n: int = 2000) -> np.ndarray:
    """Area (cm^2) of each annulus between ``r_edges`` inside the block's square cross-section
    (by midpoint sampling of the square; annuli beyond L/2 are cut by its sides)."""
    c = (np.arange(n) + 0.5) / n * L_XY - L_XY / 2
    r = np.hypot(c[:, None], c[None, :]).ravel()
    counts = np.histogram(r, bins=r_edges)[0]
    return counts * (L_XY / n) ** 2


def absorbed_maps(model: str, case: str, n_photons: int) -> tuple[np.ndarray, list, tuple]:
    """The Monte Carlo maps of ``model`` for ``case``: (times of the maps, [density (nr, nz)],
    (r edges, z edges)); cached."""
    model = LIGHT[model]
    estimator, dr, dz, seed, _ = MONTE_CARLO[model]
    n_photons = _photons(model, n_photons)
    knots = np.array([0.0]) if case in ("constant", "pulse-train") else \
        np.round(np.linspace(0.0, heated_total(case), int(round(heated_total(case) / 0.5)) + 1), 10)
    tag = hashlib.sha256(f"{model}-{case}-{n_photons}-v1".encode()).hexdigest()[:16]
    path = CACHE / f"maps-{tag}.npz"
    if path.exists():
        with np.load(path) as f:
            return f["knots"], list(f["maps"]), (f["r_edges"], f["z_edges"])
    maps = []
    for i, t in enumerate(knots):  # knots in heated time: the optics at that much heating
        mua, mus = optics(case, _at_heated(case, float(t)))
        m, r_edges, z_edges = monte_carlo(mua, mus, n_photons, estimator, dr, dz, seed + 97 * i)
        maps.append(m)
    CACHE.mkdir(parents=True, exist_ok=True)
    np.savez(path, knots=knots, maps=np.array(maps), r_edges=r_edges, z_edges=z_edges)
    return knots, maps, (r_edges, z_edges)


def _at_heated(case: str, h: float) -> float:
    """The first time at which ``case`` has heated for ``h`` s."""
    for a, b in pulses(case):
        if h <= b - a + 1e-12:
            return a + h
        h -= b - a
    return pulses(case)[-1][1]


def _map_at(knots, maps, t):
    """Absorbed power map at time ``t``, linear between the Monte Carlo instants."""
    if len(maps) == 1:
        return maps[0]
    t = min(max(t, knots[0]), knots[-1])
    i = min(int(np.searchsorted(knots, t, side="right")) - 1, len(knots) - 2)
    a = (t - knots[i]) / (knots[i + 1] - knots[i])
    return (1 - a) * maps[i] + a * maps[i + 1]


def _bins(edges, r, z, shape):
    """(ir, iz): the (r, z) bin of ``shape`` that holds each point."""
    r_edges, z_edges = edges
    ir = np.clip(np.searchsorted(r_edges, r, side="right") - 1, 0, shape[0] - 1)
    iz = np.clip(np.searchsorted(z_edges, z, side="right") - 1, 0, shape[1] - 1)
    return ir, iz


def _lookup(density, edges, r, z):
    """Density of the (r, z) bin that holds each point."""
    return density[_bins(edges, r, z, density.shape)]


# ---------------------------------------------------------------------------- heat solvers


def _end_value(first, second):
    """The value at a zero-flux face from the first two cell centres next to it: the
    parabola with zero slope at the face (cells of equal width)."""
    return (9 * first - second) / 8


def _laplacian_1d(n: int, h: float) -> sp.csr_matrix:
    """Cell-centred second difference with zero-flux ends (W/(cm^2) per K once times TC)."""
    main = -2.0 * np.ones(n)
    main[0] = main[-1] = -1.0
    return sp.diags([np.ones(n - 1), main, np.ones(n - 1)], [-1, 0, 1]) / h**2


class CartesianFD:
    """Cell-centred finite differences on the box, insulated faces, backward Euler."""

    def __init__(self, shape=(35, 35, 24), dt: float = DT_A):
        self.shape = nx, ny, nz = shape
        self.h = (L_XY / nx, L_XY / ny, L_Z / nz)
        I = [sp.identity(n) for n in shape]
        Lx, Ly, Lz = (_laplacian_1d(n, h) for n, h in zip(shape, self.h, strict=True))
        Lap = (sp.kron(sp.kron(Lx, I[1]), I[2]) + sp.kron(sp.kron(I[0], Ly), I[2])
               + sp.kron(sp.kron(I[0], I[1]), Lz))
        self.dt = dt
        self.solve = spla.factorized((sp.identity(nx * ny * nz) - dt * TC / VHC * Lap).tocsc())
        self.centres = [(np.arange(n) + 0.5) * h - (L_XY / 2 if k < 2 else 0.0)
                        for k, (n, h) in enumerate(zip(shape, self.h, strict=True))]
        X, Y, Z = np.meshgrid(*self.centres, indexing="ij")
        self.r, self.z = np.hypot(X, Y).ravel(), Z.ravel()
        self.vol = float(np.prod(self.h))

    def source(self, density, edges, total):
        """Power density per W on the cells, rescaled to the Monte Carlo's absorbed total."""
        s = _lookup(density, edges, self.r, self.z)
        return s * (total / max(s.sum() * self.vol, 1e-300))

    def probes(self, T):
        """T at (0, 0, z) for the tracked depths: the centre column (nx, ny odd), the surface
        by the zero-flux parabola through the first two cells, depths by linear interpolation."""
        nx, ny, nz = self.shape
        col = T.reshape(self.shape)[nx // 2, ny // 2]
        zc = self.centres[2]
        out = []
        for d in DEPTHS:
            out.append(_end_value(col[0], col[1]) if d <= zc[0] else np.interp(d, zc, col))
        return np.array(out)

    def surface(self, T, xy):
        """T on the top face at the points ``xy`` (m, 2) cm: the zero-flux parabola through
        the first two cell layers, bilinear between cell centres (nearest centre beyond)."""
        from scipy.interpolate import RegularGridInterpolator

        T = T.reshape(self.shape)
        top = _end_value(T[:, :, 0], T[:, :, 1])
        cx, cy = self.centres[0], self.centres[1]
        pts = np.column_stack([np.clip(xy[:, 0], cx[0], cx[-1]), np.clip(xy[:, 1], cy[0], cy[-1])])
        return RegularGridInterpolator((cx, cy), top)(pts)

    def step(self, T, q, dt):
        assert abs(dt - self.dt) < 1e-12
        return self.solve(T + dt * q / VHC)


class AxisymmetricFV:
    """Finite volumes on a cylinder of the box's cross-section area, Crank-Nicolson."""

    def __init__(self, nr: int = 40, nz: int = 40, dt: float = 0.1):
        R = L_XY / np.sqrt(np.pi)
        self.shape = (nr, nz)
        dr, dz = R / nr, L_Z / nz
        re = dr * np.arange(nr + 1)
        rc = 0.5 * (re[1:] + re[:-1])
        self.centres = (rc, (np.arange(nz) + 0.5) * dz)
        vol_r = 0.5 * (re[1:] ** 2 - re[:-1] ** 2)  # per radian
        # radial flux conductance between rings i and i + 1 (per radian): r_face / dr
        g = re[1:-1] / dr
        Ar = sp.diags(1 / vol_r) @ sp.diags([g, -(np.r_[g, 0] + np.r_[0, g]), g], [-1, 0, 1])
        Az = _laplacian_1d(nz, dz)
        Lap = sp.kron(Ar, sp.identity(nz)) + sp.kron(sp.identity(nr), Az)
        a = dt * TC / VHC
        Id = sp.identity(nr * nz)
        self.rhs = (Id + 0.5 * a * Lap).tocsr()
        self.solve = spla.factorized((Id - 0.5 * a * Lap).tocsc())
        self.dt = dt
        R_, Z_ = np.meshgrid(*self.centres, indexing="ij")
        self.r, self.z = R_.ravel(), Z_.ravel()
        self.vol = (2 * np.pi * np.outer(vol_r, np.full(nz, dz))).ravel()

    def source(self, density, edges, total):
        s = _lookup(density, edges, self.r, self.z)
        return s * (total / max((s * self.vol).sum(), 1e-300))

    def probes(self, T):
        nr, nz = self.shape
        T = T.reshape(nr, nz)
        col = _end_value(T[0], T[1])  # the axis, by symmetry (zero radial slope)
        zc = self.centres[1]
        return np.array([_end_value(col[0], col[1]) if d <= zc[0] else np.interp(d, zc, col)
                         for d in DEPTHS])

    def surface(self, T, xy):
        """T on the top face at the points ``xy`` (m, 2) cm, linear in the radius between
        ring centres (the axis by symmetry)."""
        nr, nz = self.shape
        T = T.reshape(nr, nz)
        top = _end_value(T[:, 0], T[:, 1])
        rc = np.r_[0.0, self.centres[0]]
        return np.interp(np.hypot(xy[:, 0], xy[:, 1]), rc, np.r_[_end_value(top[0], top[1]), top])

    def step(self, T, q, dt):
        assert abs(dt - self.dt) < 1e-12
        return self.solve(self.rhs @ T + dt * q / VHC)


class SpectralBox:
    """The insulated box's heat equation in its cosine eigenmodes (model C).

    A cell-centred grid of ``shape`` cells; the state is the modes' coefficients (the
    orthonormal DCT-II of the cell values). Mode ``k`` decays at ``kappa (pi k / L)^2``
    (kappa = TC / VHC, the continuous box's eigenvalue), and a step of ``dt`` with a
    constant source is exact for it. The source is the Monte Carlo's density averaged
    over ``sub`` points per cell and axis, rescaled to the absorbed total; temperatures
    at points come from the cosine series itself (no interpolation between cells)."""

    def __init__(self, shape=(64, 64, 32), dt: float = 0.025, sub=(4, 4, 2)):
        from scipy.fft import dctn

        self._dctn = dctn
        self.shape, self.dt = shape, dt
        lengths = (L_XY, L_XY, L_Z)
        self.h = tuple(L / n for L, n in zip(lengths, shape, strict=True))
        kappa = TC / VHC
        lam = sum(np.meshgrid(*[(np.pi * np.arange(n) / L) ** 2
                                for n, L in zip(shape, lengths, strict=True)], indexing="ij"))
        self.decay = np.exp(-kappa * lam * dt)
        with np.errstate(divide="ignore", invalid="ignore"):  # the mean mode: no decay
            self.gain = np.where(lam > 0, (1 - self.decay) / (kappa * lam), dt) / VHC
        # the sub-cell points of every cell, (x, y) from the box's centre and z down
        offs = [(np.arange(k) + 0.5) / k for k in sub]
        cx, cy, cz = [(np.arange(n)[:, None] + o[None, :]).ravel() * h - (L_XY / 2 if i < 2 else 0)
                      for i, (n, o, h) in enumerate(zip(shape, offs, self.h, strict=True))]
        X, Y, Z = np.meshgrid(cx, cy, cz, indexing="ij")
        self._sub = sub
        self.r, self.z = np.hypot(X, Y).ravel(), Z.ravel()  # the source's sample points
        self.vol = float(np.prod(self.h))
        self._lengths = lengths

    def _basis(self, axis: int, x: np.ndarray) -> np.ndarray:
        """(m, n) values of the orthonormal DCT-II basis of ``axis`` at ``x`` (m,) cm from
        the box's low face."""
        n, L = self.shape[axis], self._lengths[axis]
        f = np.full(n, np.sqrt(2.0 / n))
        f[0] = np.sqrt(1.0 / n)
        return f[None, :] * np.cos(np.pi * np.outer(x, np.arange(n)) / L)

    def source(self, density, edges, total):
        """The modes' coefficients of the power density per W (rescaled to ``total``)."""
        key = (edges[0].tobytes(), edges[1].tobytes(), density.shape)
        if getattr(self, "_bins", (None,))[0] != key:  # the sample points' bins, once
            ir, iz = _bins(edges, self.r, self.z, density.shape)
            self._bins = (key, ir * density.shape[1] + iz)
        s = density.ravel()[self._bins[1]]
        nx, ny, nz = self.shape
        sx, sy, sz = self._sub
        cells = s.reshape(nx, sx, ny, sy, nz, sz).mean(axis=(1, 3, 5))
        cells *= total / max(cells.sum() * self.vol, 1e-300)
        return self._dctn(cells, type=2, norm="ortho")

    @property
    def size(self) -> int:
        return int(np.prod(self.shape))

    def values(self, T, xyz: np.ndarray) -> np.ndarray:
        """T at points ``xyz`` (m, 3) cm (x, y from the box's centre, z down)."""
        Bx = self._basis(0, xyz[:, 0] + L_XY / 2)
        By = self._basis(1, xyz[:, 1] + L_XY / 2)
        Bz = self._basis(2, xyz[:, 2])
        C = T.reshape(self.shape)
        return np.einsum("pi,pj,pk,ijk->p", Bx, By, Bz, C, optimize=True)

    def probes(self, T):
        return self.values(T, np.array([[0.0, 0.0, d] for d in DEPTHS]))

    def surface(self, T, xy):
        """T on the top face at the points ``xy`` (m, 2) cm."""
        top = T.reshape(self.shape) @ self._basis(2, np.zeros(1))[0]  # the series at z = 0
        Bx = self._basis(0, xy[:, 0] + L_XY / 2)
        By = self._basis(1, xy[:, 1] + L_XY / 2)
        return np.einsum("pi,ij,pj->p", Bx, top, By, optimize=True)

    def step(self, T, q, dt):
        assert abs(dt - self.dt) < 1e-12
        T = T.reshape(self.shape) * self.decay
        if not np.isscalar(q):
            T = T + self.gain * q
        return T.ravel()


def independent_truth(model: str, case: str, n_photons: int = 200_000) -> np.ndarray:
    """Temperatures (151, 3) deg C at z = 0, 0.1, 0.2 cm below the beam centre, every 0.1 s
    from 0 to 15 s (cached)."""
    path = _truth_path(model, case, n_photons)
    if path.exists():
        return np.load(path)
    return _run(model, case, n_photons)[0]


def independent_surface(model: str, case: str, xy: np.ndarray, n_photons: int = 200_000
                        ) -> np.ndarray:
    """Top-face temperatures (151, m) deg C at the points ``xy`` (m, 2) cm, every 0.1 s
    from 0 to 15 s (cached): what a camera of the model's truth sees."""
    xy = np.ascontiguousarray(xy, dtype=float)
    key = hashlib.sha256(xy.tobytes()).hexdigest()[:12]
    tag = hashlib.sha256(f"surface-{model}-{case}-{_photons(model, n_photons)}-{key}-"
                         f"{VERSIONS[model]}"
                         .encode()).hexdigest()[:16]
    path = CACHE / f"surface-{tag}.npy"
    if path.exists():
        return np.load(path)
    surf = _run(model, case, n_photons, xy)[1]
    np.save(path, surf)
    return surf


def _photons(model: str, n_photons: int) -> int:
    """Photons per Monte Carlo map of ``model`` (:data:`LIGHT`)."""
    return n_photons * MONTE_CARLO[LIGHT[model]][4]


def _truth_path(model: str, case: str, n_photons: int) -> Path:
    tag = hashlib.sha256(f"truth-{model}-{case}-{_photons(model, n_photons)}-{VERSIONS[model]}"
                         .encode()).hexdigest()[:16]
    return CACHE / f"truth-{tag}.npy"


def _run(model: str, case: str, n_photons: int, xy: np.ndarray | None = None):
    """The truth of ``model`` for ``case``: temperatures (151, 3) at the tracked depths
    (written to the cache), and (151, m) on the top face at ``xy`` (None without points)."""
    knots, maps, edges = absorbed_maps(model, case, n_photons)
    solver = {"A": CartesianFD, "B": AxisymmetricFV, "C": SpectralBox, "D": CartesianFD}[model]()
    # the heat each map puts into the block: its integral over the annuli inside the box
    totals = [float((m * np.outer(annulus_area_in_box(edges[0]), np.diff(edges[1]))).sum())
              for m in maps]
    T = np.zeros(getattr(solver, "size", solver.r.size))
    out = [solver.probes(T)]
    surf = None if xy is None else [solver.surface(T, xy)]
    dt = solver.dt
    n_sub = int(round(0.1 / dt))
    t = 0.0
    for _ in range(len(TIMES) - 1):
        for _ in range(n_sub):
            tm = t + 0.5 * dt
            if laser_on(case, tm):
                hm = heated(case, tm)  # the maps' clock: heated time
                m = _map_at(knots, maps, hm)
                tot = float(np.interp(hm, knots, totals)) if len(totals) > 1 else totals[0]
                q = POWER * solver.source(m, edges, tot)
            else:
                q = 0.0
            T = solver.step(T, q, dt)
            t += dt
        out.append(solver.probes(T))
        if surf is not None:
            surf.append(solver.surface(T, xy))
    temps = np.array(out)
    # the tracked temperatures come with every run: cached, so a camera's run serves both
    CACHE.mkdir(parents=True, exist_ok=True)
    np.save(_truth_path(model, case, n_photons), temps)
    return temps, None if surf is None else np.array(surf)


if __name__ == "__main__":
    import sys
    import time

    for case in sys.argv[1:] or ("constant", "time-varying"):
        for model in ALL_MODELS:
            t0 = time.perf_counter()
            T = independent_truth(model, case)
            print(case, model, f"{time.perf_counter() - t0:.1f} s", "T(5 s) =",
                  np.round(T[50], 3), "T(15 s) =", np.round(T[150], 3), flush=True)
