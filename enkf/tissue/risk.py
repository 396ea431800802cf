r"""Risk of thermal injury from the ensemble: where is tissue being damaged, and how surely?

Every member of the filter carries its own temperature field :math:`T_n(x, t)` (deg C at
the nodes of the filter's mesh). Along each member's analysed trajectory (the states the
filter reports after the prior and after every step) the Arrhenius damage integral of
MCmatlab (Henriques 1947; MCmatlab's heat simulation),

.. math::

    \Omega_n(x, t) = \int_0^t A \exp\!\Big(-\frac{E}{R\,(T_n(x, s) + 273.15)}\Big)\,ds,
    \qquad R = 8.3144598\ \mathrm{J\,mol^{-1}\,K^{-1}},

is accumulated per member and node with the trapezoidal rule in the rate,

.. math::

    \Omega_n \mathrel{+}= \tfrac{\Delta t}{2}\,\big(k(T_n^{j}) + k(T_n^{j+1})\big),
    \qquad k(T) = A\, e^{-E / (R (T + 273.15))}

(:func:`fem.advance_damage` with ``rule="trapezoid"``, the project's one Arrhenius kernel).

From the ensemble, at every node and at the recorded times:

* ``p_damage``: the fraction of members with :math:`\Omega > 1` (``omega_threshold``),
  MCmatlab's (and Henriques') threshold of irreversible damage (63% of the molecules
  denatured);
* ``p_T``: the fraction of members with :math:`T > T_\mathrm{threshold}` now (60 deg C by
  default), and ``p_T_ever``: the fraction that has been above it at some reported time;
* ``omega_mean``, ``T_mean``, ``T_std``: ensemble mean damage and temperature mean and
  spread.

These are the filter's beliefs, as honest as its ensemble; how honest is measured in
``validation/risk_calibration.py`` (``docs/risk.md``).

Use it as the callback of :func:`enkf.tissue.identify` (or :func:`enkf.driver.run_filter`)::

    tracker = RiskTracker(E=MCMATLAB_E, A=MCMATLAB_A, record_times=[5.0, 15.0])
    est = identify(setup, times, data, callback=tracker)
    tracker.write_vtu("risk.pvd", setup.grid.mesh())        # ParaView / pyvista series
    plot_depth_maps("risk.png", tracker.snapshots, setup.grid)

Memory: three ``(N, n_nodes)`` arrays (damage, last state, exceedance so far), plus
``6 n_nodes`` numbers per recorded snapshot; ``N = 50`` members on 4,851 nodes is 4 MB.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

import fem

__all__ = ["MCMATLAB_A", "MCMATLAB_E", "RiskSnapshot", "RiskTracker", "plot_depth_maps",
           "xz_slice"]

#: J/mol and 1/s: the Arrhenius parameters MCmatlab's media library gives its tissues
#: (blood, vessel and example tissues, marked there "PLACEHOLDER DATA ONLY"). At 60 deg C
#: they give a rate of 3.2 /s, so Omega = 1 is reached in 0.3 s; at 50 deg C in 35 s.
MCMATLAB_E = 422.5e3
MCMATLAB_A = 7.6e66


# ------------------------------------------------------------------------------ data
@dataclass
class RiskSnapshot:
    """The risk fields at one reported time; every field is ``(n_nodes,)``."""

    time: float  #: s
    step: int  #: the filter step (0: the prior)
    p_damage: np.ndarray  #: fraction of members with Omega > omega_threshold, in [0, 1]
    p_T: np.ndarray  #: fraction of members with T > T_threshold at this time
    p_T_ever: np.ndarray  #: fraction of members that have been above T_threshold so far
    omega_mean: np.ndarray  #: ensemble mean of Omega (dimensionless)
    T_mean: np.ndarray  #: deg C, ensemble mean temperature
    T_std: np.ndarray  #: deg C, ensemble standard deviation (ddof = 1; 0 for one member)


def _threshold_tag(T_threshold: float) -> str:
    return f"{T_threshold:g}".replace("-", "m").replace(".", "p") + "C"


@dataclass
class RiskTracker:
    """A callback for :func:`enkf.tissue.identify` that tracks the risk of thermal injury.

    Parameters
    ----------
    E : float or array (n_nodes,)
        J/mol, Arrhenius activation energy per node (the medium's ``E``; >= 0).
    A : float or array (n_nodes,)
        1/s, Arrhenius frequency factor per node (the medium's ``A``; >= 0, 0: no damage).
    T_threshold : float
        deg C, the temperature whose exceedance is reported (default 60).
    omega_threshold : float
        The damage counted as injury (default 1, MCmatlab's and Henriques').
    record_times : sequence of float, optional
        s: keep a :class:`RiskSnapshot` at the first reported state at or after each of
        these times (one snapshot if a step passes several). If not given, one every
        ``record_every`` steps (the prior, step 0, included).
    record_every : int
        Steps between snapshots when ``record_times`` is None (default 10).

    Attributes
    ----------
    snapshots : list of RiskSnapshot
    omega : array (N, n_nodes) or None
        Each member's damage so far (None before the first report).
    time : float or None
        s, the time of the last report.

    Notes
    -----
    A report with ``step == 0`` (the prior) starts a new run: damage and snapshots are
    reset, so one tracker can follow several runs one after the other. The damage is
    integrated between the reported (analysed) states; an analysis that moves a member
    is taken as the member's temperature having gone there linearly in time.
    """

    E: float | np.ndarray
    A: float | np.ndarray
    T_threshold: float = 60.0
    omega_threshold: float = 1.0
    record_times: Sequence[float] | None = None
    record_every: int = 10
    snapshots: list = field(default_factory=list, init=False)
    omega: np.ndarray | None = field(default=None, init=False)
    time: float | None = field(default=None, init=False)
    _ever: np.ndarray | None = field(default=None, init=False, repr=False)
    _X: np.ndarray | None = field(default=None, init=False, repr=False)  #: last ensemble
    _pending: list = field(default_factory=list, init=False, repr=False)
    _step: int = field(default=-1, init=False, repr=False)

    def __post_init__(self):
        for name, unit in (("E", "J/mol"), ("A", "1/s")):
            v = np.asarray(getattr(self, name), dtype=float)
            if v.ndim > 1:
                raise ValueError(f"RiskTracker.{name} must be a scalar or (n_nodes,) ({unit}), "
                                 f"got shape {v.shape}")
            bad = ~np.isfinite(v) | (v < 0)
            if np.any(bad):
                raise ValueError(f"RiskTracker.{name} must be finite and >= 0 ({unit}), got "
                                 f"{float(v[bad].ravel()[0])!r}")
            setattr(self, name, v)
        for name in ("T_threshold", "omega_threshold"):
            v = getattr(self, name)
            if not isinstance(v, int | float | np.floating | np.integer) or not np.isfinite(v):
                raise ValueError(f"RiskTracker.{name} must be a finite number, got {v!r}")
        if self.omega_threshold <= 0:
            raise ValueError(f"RiskTracker.omega_threshold must be > 0, got "
                             f"{self.omega_threshold!r}")
        if isinstance(self.record_every, bool) or not isinstance(
                self.record_every, int | np.integer) or self.record_every < 1:
            raise ValueError(f"RiskTracker.record_every must be an integer >= 1, got "
                             f"{self.record_every!r}")
        if self.record_times is not None:
            rt = np.asarray(self.record_times, dtype=float).ravel()
            if not np.all(np.isfinite(rt)):
                raise ValueError(f"RiskTracker.record_times must be finite (s), got "
                                 f"{self.record_times!r}")
            self.record_times = sorted(rt.tolist())
        self._reset()

    @classmethod
    def from_medium(cls, medium, **kw) -> RiskTracker:
        """A tracker with the ``E`` and ``A`` of a :class:`mcmatlab_py.Medium`."""
        if medium.E is None or medium.A is None:
            raise ValueError(f"medium {medium.name!r} has no Arrhenius parameters "
                             f"(E={medium.E!r}, A={medium.A!r})")
        return cls(E=medium.E, A=medium.A, **kw)

    # -------------------------------------------------------------- following a run
    def _reset(self) -> None:
        self.snapshots = []
        self.omega = self._ever = self._X = None
        self.time = None
        self._step = -1
        self._pending = list(self.record_times) if self.record_times is not None else []

    def __call__(self, rep) -> None:
        """Take a :class:`enkf.driver.StepReport` (uses ``step``, ``time``, ``state_ensemble``)."""
        self.update(rep.time, rep.state_ensemble, step=rep.step)

    def update(self, time: float, state_ensemble, step: int | None = None) -> None:
        """Advance the damage to the ensemble ``state_ensemble`` (N, n_nodes), deg C, at ``time`` (s).

        ``step``: the filter's step number (0 starts a new run); by default one more
        than the last.
        """
        X = np.asarray(state_ensemble, dtype=float)
        if X.ndim != 2 or X.shape[0] < 1 or X.shape[1] < 1:
            raise ValueError(f"state_ensemble must be (N, n_nodes) deg C, got shape {X.shape}")
        time = float(time)
        if not np.isfinite(time):
            raise ValueError(f"time must be finite (s), got {time!r}")
        lo, hi = float(X.min()), float(X.max())
        if not (lo > -fem.KELVIN and np.isfinite(hi)):
            raise ValueError(f"state_ensemble must be finite temperatures above -273.15 deg C, "
                             f"got min {lo!r}, max {hi!r}")
        step = self._step + 1 if step is None else int(step)
        if step == 0 and self.omega is not None:
            self._reset()
        if self.omega is None:
            n = X.shape[1]
            for name in ("E", "A"):
                v = getattr(self, name)
                if v.ndim == 1 and v.shape != (n,):
                    raise ValueError(f"RiskTracker.{name} has shape {v.shape}, the ensemble "
                                     f"has {n} nodes: give a scalar or ({n},)")
            self.omega = np.zeros_like(X)
            self._ever = np.zeros(X.shape, dtype=bool)
        else:
            if X.shape != self.omega.shape:
                raise ValueError(f"state_ensemble has shape {X.shape}, the run so far "
                                 f"{self.omega.shape}")
            if time <= self.time:
                raise ValueError(f"time must increase: got {time!r} s after {self.time!r} s")
            fem.advance_damage(self.omega, self._X, X, time - self.time, self.E, self.A,
                               rule="trapezoid")
        self._ever |= X > self.T_threshold
        self.time, self._step = time, step
        self._X = X.copy()  # the driver's arrays are views of its working ensemble
        if self._due(step, time):
            self.snapshots.append(self.snapshot())

    def _due(self, step: int, time: float) -> bool:
        if self.record_times is None:
            return step % int(self.record_every) == 0
        due = False
        while self._pending and time >= self._pending[0] - 1e-9 * max(1.0, abs(time)):
            self._pending.pop(0)
            due = True
        return due

    def snapshot(self, state_ensemble=None) -> RiskSnapshot:
        """The risk fields at the last report (``state_ensemble``: the ensemble whose T
        statistics to give instead of the last reported one)."""
        if self.omega is None:
            raise ValueError("RiskTracker.snapshot: nothing reported yet")
        X = self._X if state_ensemble is None else np.asarray(state_ensemble, float)
        N = X.shape[0]
        return RiskSnapshot(
            time=float(self.time), step=int(self._step),
            p_damage=np.mean(self.omega > self.omega_threshold, axis=0),
            p_T=np.mean(X > self.T_threshold, axis=0), p_T_ever=np.mean(self._ever, axis=0),
            omega_mean=self.omega.mean(axis=0), T_mean=X.mean(axis=0),
            T_std=X.std(axis=0, ddof=1) if N > 1 else np.zeros(X.shape[1]))

    # -------------------------------------------------------------- output
    def point_data(self, snapshot: RiskSnapshot) -> dict[str, np.ndarray]:
        """The VTU point fields of a snapshot: ``p_damage``, ``p_T_above_60C``,
        ``p_T_ever_above_60C`` (the threshold in the name), ``omega_mean``, ``T_mean``,
        ``T_std``."""
        tag = _threshold_tag(float(self.T_threshold))
        return {"p_damage": snapshot.p_damage, f"p_T_above_{tag}": snapshot.p_T,
                f"p_T_ever_above_{tag}": snapshot.p_T_ever, "omega_mean": snapshot.omega_mean,
                "T_mean": snapshot.T_mean, "T_std": snapshot.T_std}

    def write_vtu(self, path, mesh, which: int = -1) -> Path:
        """Write the snapshots: a ``.pvd`` path gives the whole series (one VTU per
        snapshot, for ParaView or pyvista), a ``.vtu`` path the snapshot ``which``."""
        if not self.snapshots:
            raise ValueError("RiskTracker.write_vtu: no snapshots recorded")
        path = Path(path)
        if path.suffix == ".pvd":
            with fem.TimeSeriesWriter(path, mesh) as w:
                for s in self.snapshots:
                    w.write(s.time, **self.point_data(s))
            return path
        if path.suffix == ".vtu":
            return fem.write_vtu(path, mesh, point_data=self.point_data(self.snapshots[which]))
        raise ValueError(f"path must end in .pvd (series) or .vtu (one snapshot), got "
                         f"{str(path)!r}")


# ------------------------------------------------------------------------------ maps
def xz_slice(values, grid, y: float = 0.0) -> np.ndarray:
    """A nodal field on the plane ``y`` (cm): ``(nx + 1, nz + 1)`` on ``grid.x_nodes`` x
    ``grid.z_nodes``.

    ``values``: (n_nodes,) in the C order of the ``(nx+1, ny+1, nz+1)`` node grid. Between
    two node planes the P1 field is linear along the y edges, so this is exact.
    """
    shape = grid.node_shape
    v = np.asarray(values, dtype=float)
    if v.shape != (int(np.prod(shape)),):
        raise ValueError(f"values must be ({int(np.prod(shape))},) on the grid's nodes, got "
                         f"shape {v.shape}")
    yn = grid.y_nodes
    if not yn[0] - 1e-12 <= y <= yn[-1] + 1e-12:
        raise ValueError(f"y must lie in [{yn[0]:g}, {yn[-1]:g}] cm, got {y!r}")
    F = v.reshape(shape)
    j = int(np.clip(np.searchsorted(yn, y) - 1, 0, len(yn) - 2))
    w = float(np.clip((y - yn[j]) / (yn[j + 1] - yn[j]), 0.0, 1.0))
    return (1 - w) * F[:, j, :] + w * F[:, j + 1, :]


_COLUMNS = {
    "p_damage": ("P($\\Omega$ > 1)", "magma", (0, 1)),
    "p_T": ("P(T > {thr} $^\\circ$C) now", "magma", (0, 1)),
    "p_T_ever": ("P(T > {thr} $^\\circ$C) so far", "magma", (0, 1)),
    "T_mean": ("mean T [$^\\circ$C]", "inferno", None),
}


def plot_depth_maps(path, snapshots, grid, T_threshold: float = 60.0, *,
                    columns: Sequence[str] = ("p_damage", "p_T", "p_T_ever", "T_mean"),
                    truth: dict | None = None, y: float = 0.0, zmax: float | None = None
                    ) -> Path:
    """Depth maps (the xz plane through the beam axis, ``y`` = 0) as a PNG.

    Parameters
    ----------
    snapshots : RiskSnapshot or list of them
        One row per snapshot.
    grid : fem.BoxGrid
        The filter's grid (its nodes carry the fields).
    columns : names of RiskSnapshot fields, one column each.
    truth : dict, optional
        ``{column: [indicator (n_nodes,) per snapshot]}``: where the event happened in
        the truth (1) or not (0), drawn as a dashed cyan contour at 0.5.
    zmax : cm, depth shown (default the whole block).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if isinstance(snapshots, RiskSnapshot):
        snapshots = [snapshots]
    for c in columns:
        if c not in _COLUMNS:
            raise ValueError(f"columns: unknown field {c!r} (one of {sorted(_COLUMNS)})")
    x, z = grid.x_nodes, grid.z_nodes
    nr, nc = len(snapshots), len(columns)
    fig, axes = plt.subplots(nr, nc, figsize=(3.4 * nc, 2.2 * nr + 0.6), squeeze=False,
                             constrained_layout=True)
    for i, s in enumerate(snapshots):
        for k, c in enumerate(columns):
            ax = axes[i, k]
            label, cmap, lim = _COLUMNS[c]
            F = xz_slice(getattr(s, c), grid, y)
            vmin, vmax = lim if lim is not None else (None, None)
            im = ax.pcolormesh(x, z, F.T, cmap=cmap, vmin=vmin, vmax=vmax, shading="gouraud")
            if c == "T_mean":
                ax.contour(x, z, F.T, levels=[T_threshold], colors="w", linewidths=0.8)
            if truth is not None and c in truth:
                ax.contour(x, z, xz_slice(truth[c][i], grid, y).T, levels=[0.5],
                           colors="c", linestyles="--", linewidths=1.0)
            ax.set_ylim(zmax if zmax is not None else z[-1], z[0])
            ax.set_title(f"{label.format(thr=f'{T_threshold:g}')}, t = {s.time:g} s",
                         fontsize=9)
            if i == nr - 1:
                ax.set_xlabel("x [cm]")
            if k == 0:
                ax.set_ylabel("z [cm]")
            fig.colorbar(im, ax=ax, shrink=0.9)
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
