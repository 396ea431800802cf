"""Risk of thermal injury from the ensemble: where is tissue being damaged, and how surely?

Each member of the filter carries its own temperature field; along its trajectory
(the analysed states, step after step) the Arrhenius damage integral of MCmatlab,

    Omega(t) = integral of A exp(-E / (R T(t))) dt     (T in kelvin),

is accumulated per member and node (:func:`fem.arrhenius_increment`, trapezoidal in
the rate). The probability of injury at a node is the fraction of members with
Omega > 1; the probability of overheating the fraction with T above a threshold
(60 deg C by default) now, and ``p_T_ever`` the fraction that has exceeded it so far.
These are the filter's beliefs, as honest as its ensemble (validation/risk_calibration.py).

    tracker = RiskTracker(E=422.5e3, A=7.6e66, record_times=[5.0, 15.0])
    est = identify(setup, times, data, callback=tracker)
    tracker.write_vtu("risk.pvd", setup.grid.mesh())
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["RiskSnapshot", "RiskTracker", "plot_depth_maps"]


@dataclass
class RiskSnapshot:
    """Risk fields at one time: each (n_nodes,), probabilities in [0, 1]."""

    time: float  #: s
    p_damage: np.ndarray  #: fraction of members with Omega > 1
    p_T: np.ndarray  #: fraction of members above the temperature threshold now
    p_T_ever: np.ndarray  #: fraction of members that have been above it so far
    omega_mean: np.ndarray  #: ensemble mean of Omega
    T_mean: np.ndarray  #: deg C, ensemble mean temperature


@dataclass
class RiskTracker:
    """A callback for :func:`enkf.tissue.identify` (or ``run_filter``) that tracks injury risk.

    Parameters
    ----------
    E : float or (n_nodes,) array
        J/mol, Arrhenius activation energy (MCmatlab's ``E`` of the medium).
    A : float or (n_nodes,) array
        1/s, Arrhenius frequency factor (MCmatlab's ``A``); 0 means no damage.
    T_threshold : float
        deg C, the temperature whose exceedance is reported.
    record_times : sequence of float, optional
        s: keep a :class:`RiskSnapshot` at the first step at or after each of these
        times; default every ``record_every`` steps.
    record_every : int
    """

    E: float | np.ndarray
    A: float | np.ndarray
    T_threshold: float = 60.0
    record_times: list | None = None
    record_every: int = 10
    snapshots: list = field(default_factory=list)
    omega: np.ndarray | None = None  #: (N, n_nodes) each member's damage so far
    _last: tuple | None = field(default=None, repr=False)
    _ever: np.ndarray | None = field(default=None, repr=False)
    _pending: list = field(default_factory=list, repr=False)

    def __post_init__(self):
        for name in ("E", "A"):
            v = np.asarray(getattr(self, name), float)
            if not np.all(np.isfinite(v)) or np.any(v < 0):
                bad = v[~np.isfinite(v) | (v < 0)].ravel()[0]
                raise ValueError(f"RiskTracker.{name} must be finite and >= 0, got {bad!r}")
            setattr(self, name, v)
        if not np.isfinite(self.T_threshold):
            raise ValueError(f"RiskTracker.T_threshold must be finite (deg C), got "
                             f"{self.T_threshold!r}")
        if int(self.record_every) < 1:
            raise ValueError(f"RiskTracker.record_every must be >= 1, got {self.record_every!r}")
        if self.record_times is not None:
            self._pending = sorted(float(t) for t in self.record_times)

    def __call__(self, rep) -> None:
        import fem

        X = np.asarray(rep.state_ensemble, float)
        if self.E.ndim and self.E.shape != (X.shape[1],):
            raise ValueError(f"RiskTracker.E must be a scalar or have shape ({X.shape[1]},), "
                             f"got {self.E.shape}")
        if self.omega is None:
            self.omega = np.zeros_like(X)
            self._ever = np.zeros(X.shape, dtype=bool)
        if self._last is not None:
            t0, X0 = self._last
            dt = float(rep.time) - t0
            if dt > 0:
                self.omega += fem.arrhenius_increment(X0, X, dt, self.E, self.A)
        self._ever |= X > self.T_threshold
        self._last = (float(rep.time), X.copy())
        if self._due(rep):
            self.snapshots.append(RiskSnapshot(
                float(rep.time), np.mean(self.omega > 1.0, axis=0),
                np.mean(X > self.T_threshold, axis=0), np.mean(self._ever, axis=0),
                self.omega.mean(axis=0), X.mean(axis=0)))

    def _due(self, rep) -> bool:
        if self.record_times is None:
            return rep.step % int(self.record_every) == 0
        due = False
        while self._pending and rep.time >= self._pending[0] - 1e-9:
            self._pending.pop(0)
            due = True
        return due

    def write_vtu(self, path, mesh) -> Path:
        """A ParaView/pyvista time series (``.pvd`` + one VTU per snapshot)."""
        import fem

        with fem.TimeSeriesWriter(path, mesh) as w:
            for s in self.snapshots:
                w.write(s.time, p_damage=s.p_damage, p_T_above=s.p_T, p_T_ever=s.p_T_ever,
                        omega_mean=s.omega_mean, T_mean=s.T_mean)
        return Path(path)


def plot_depth_maps(path, snapshot: RiskSnapshot, grid, T_threshold: float = 60.0) -> None:
    """xz maps through the beam axis (y = 0) of P(Omega > 1) and P(T > threshold so far)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    shape = grid.node_shape
    j = shape[1] // 2
    x, z = grid.x_nodes, grid.z_nodes
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6), constrained_layout=True)
    for ax, field_, title in ((axes[0], snapshot.p_damage, "P($\\Omega$ > 1)"),
                              (axes[1], snapshot.p_T_ever,
                               f"P(T > {T_threshold:g} $^\\circ$C so far)")):
        F = np.asarray(field_).reshape(shape)[:, j, :]
        im = ax.pcolormesh(x, z, F.T, vmin=0, vmax=1, cmap="magma", shading="gouraud")
        ax.invert_yaxis()
        ax.set(title=f"{title} at t = {snapshot.time:g} s", xlabel="x [cm]", ylabel="z [cm]")
        fig.colorbar(im, ax=ax)
    fig.savefig(path, dpi=110)
    plt.close(fig)
