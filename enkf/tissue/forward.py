"""The filter's forward model: one implicit heat step per interval, and the observation."""

from __future__ import annotations

import copy
import math
import warnings

import numpy as np
import scipy.sparse as sp

import fem

from .absorption import as_absorption
from .parameters import ABSORPTION_INPUTS, PARAMETER_UNITS, SECOND_MEDIUM_NAMES, column
from .setup import TissueFilterSetup

__all__ = ["TissueForwardModel", "observation_operator"]


class TissueForwardModel:
    """The forecast ``F(T, theta)`` of the filter: one implicit heat step per interval."""

    def __init__(self, setup: TissueFilterSetup):
        self.setup = setup
        g = setup.grid
        self.mesh = g.mesh()
        self.absorption = absorption = as_absorption(setup.absorption, g.shape)
        # an emulator of nodal loads on this mesh: gather, no operator at all
        self._nodal = absorption.kind == "load"
        if self._nodal:
            if tuple(absorption.shape) != tuple(n + 1 for n in g.shape):
                raise ValueError(f"the load emulator's mesh has {absorption.shape} nodes, the "
                                 f"filter's grid {tuple(n + 1 for n in g.shape)}")
            self.L = None
        else:
            # fold the expansion of the symmetry orbits into the voxel -> node operator
            inv = absorption.inverse
            expand = sp.csr_matrix((np.ones(inv.size), (np.arange(inv.size), inv)))
            L = fem.voxel_load_matrix(self.mesh, g).tocsr()  # (npoints, nvox)
            self.L = (L @ expand).tocsr()  # (npoints, n_unique)
        self.steppers: dict[float, fem.HeatStepper] = {}
        self.col = {name: column(setup.parameters.estimate, name) for name in setup.parameters.estimate}
        #: the inputs passed to the absorption model after mua, mus: a second estimated
        #: medium's optics, the beam's radius
        self._extra = tuple(n for n in ABSORPTION_INPUTS[2:] if n in self.col)
        takes = tuple(getattr(absorption, "extra_names", ()))
        if self._extra != takes:
            if any(n in SECOND_MEDIUM_NAMES for n in self._extra + takes):
                use = ("mcmatlab_py.emulator.media.TwoMediaEmulator" if "mua2" in self._extra
                       else "a one-medium absorption model")
            else:
                use = ("mcmatlab_py.emulator.media.BeamRadiusEmulator" if self._extra
                       else "an absorption model of a known beam")
            raise ValueError(f"estimate = {setup.parameters.estimate} passes {('mua', 'mus') + self._extra} "
                             f"to the absorption model, but it ({type(absorption).__name__}) "
                             f"takes {('mua', 'mus') + takes}: use {use}")
        self._clamp = {"calls": 0, "member_calls": 0, "lo": {}, "hi": {}}
        #: (optics (N, n), the absorption model's values, clamped?) of the last call
        self._last_optics = None

    def stepper(self, dt: float) -> fem.HeatStepper:
        key = round(dt, 9)
        if key not in self.steppers:
            s = self.setup
            nominal = s.parameters.nominal
            self.steppers[key] = fem.HeatStepper(self.mesh, nominal["VHC"], nominal["TC"], dt,
                                                 theta=s.heat.theta, boundary=s.heat.boundary,
                                                 operator=s.heat.operator,
                                                 mass=s.heat.mass if s.heat.operator == "kronecker"
                                                 else "lumped")
        return self.steppers[key]

    def warm_up(self, dt: float) -> None:
        """Build the solver and load the JIT code before the online loop (not timed there).

        The exact mode runs no Monte Carlo for a warm-up (zero power)."""
        s = self.setup
        N = s.n_members
        theta = np.tile([s.parameters.nominal[n] for n in s.parameters.estimate], (N, 1))
        npts = self.mesh.p.shape[1]
        # the members as the filter holds them: a plain array from the prior, then the state
        # part of the augmented ensemble, a strided view (the heat step's kernels are
        # compiled for each layout)
        for E in (np.zeros((N, npts)), np.zeros((N, npts + theta.shape[1]))[:, :npts]):
            self.step(E, theta, 0.0, dt, 0.0 if self.absorption.exact else 1.0)

    def table_ranges(self) -> dict:
        """``{"mua": (lo, hi), "mus": (lo, hi)}`` cm^-1 of the emulator's table ({} when the
        absorption model has no table)."""
        ranges = getattr(self.absorption, "ranges", None)
        if ranges is not None:  # several estimated media
            return {k: tuple(v) for k, v in ranges.items()}
        spec = getattr(self.absorption, "spec", None)
        if spec is None or not hasattr(spec, "mua_range"):
            return {}
        return {"mua": tuple(spec.mua_range), "mus": tuple(spec.mus_range)}

    def clamp_report(self) -> dict | None:
        """How often the emulator clamped members' optics to its table since the model was
        built: forecast steps, member-steps, the extreme values asked for, the table and
        what to do; None when it never did."""
        c = self._clamp
        if not c["calls"]:
            return None
        rng = self.table_ranges()
        advice = []
        for name in ABSORPTION_INPUTS:
            lo, hi = c["lo"].get(name), c["hi"].get(name)
            if lo is None and hi is None:
                continue
            want = [v for v in (lo, hi) if v is not None]
            key = "radius_range" if name == "beam_radius" else f"{name}_range"
            edges = rng.get(name, (np.nan, np.nan))
            side = " and ".join(
                f"{'below' if v is lo else 'above'} {edges[0 if v is lo else 1]:.4g}"
                for v in (lo, hi) if v is not None)
            advice.append(f"members' {name} {side} {PARAMETER_UNITS[name]} were computed at "
                          f"the table's edge, which biases the {name} estimate towards it "
                          f"while they matter; widen filter.emulator.{key} (now "
                          f"{list(rng.get(name, ()))}) to cover "
                          f"{', '.join(f'{v:.4g}' for v in want)} {PARAMETER_UNITS[name]}, or "
                          f"narrow the prior and filter.bounds of {name}")
        return {"forecast_steps": int(c["calls"]), "member_steps": int(c["member_calls"]),
                "below_table": {k: float(v) for k, v in c["lo"].items()},
                "above_table": {k: float(v) for k, v in c["hi"].items()},
                "table": {k: list(v) for k, v in rng.items()},
                "advice": "; ".join(advice) or "widen filter.emulator's ranges"}

    @property
    def clamp_counts(self) -> dict:
        """The clamps counted so far (:meth:`clamp_report`'s raw numbers), a copy; set it to
        carry another run's counts on (a run resumed from a :class:`~enkf.tissue.identify.RunHead`)."""
        return copy.deepcopy(self._clamp)

    @clamp_counts.setter
    def clamp_counts(self, value: dict) -> None:
        self._clamp = copy.deepcopy(value)

    def _count_clamps(self, optics: dict) -> None:
        self._clamp["calls"] += 1
        out = np.zeros(optics["mua"].shape, bool)
        for name, v in optics.items():
            lo, hi = self.table_ranges().get(name, (-np.inf, np.inf))
            below, above = v < lo, v > hi
            out |= below | above
            if below.any():
                self._clamp["lo"][name] = min(self._clamp["lo"].get(name, np.inf), v[below].min())
            if above.any():
                self._clamp["hi"][name] = max(self._clamp["hi"].get(name, -np.inf), v[above].max())
        self._clamp["member_calls"] += int(out.sum()) if self.table_ranges() else 0

    def loads(self, theta: np.ndarray, power: float) -> np.ndarray:
        """(N, n_nodes) W: nodal heat loads of the members' optics at laser power ``power``.

        Members whose optics lie outside the emulator's table are clamped to its edge;
        they are counted (:meth:`clamp_report`) instead of warned about one by one."""
        vals = self.values(theta)
        if self._nodal:  # np.take keeps C order (vals[:, idx] comes out in Fortran
            # order), which the heat step's kernels read row by row
            return power * np.take(vals, self.absorption.inverse, axis=1)
        return (self.L @ (power * vals).T).T

    @property
    def value_operator(self) -> sp.csr_matrix:
        """(n_nodes, n_unique): the nodal loads per W of the absorption model's values
        (:meth:`values`), ``loads(theta, 1) == (value_operator @ values(theta).T).T``."""
        if not self._nodal:
            return self.L
        inv = self.absorption.inverse
        return sp.csr_matrix((np.ones(inv.size), (np.arange(inv.size), inv)),
                             shape=(inv.size, int(inv.max()) + 1))

    def values(self, theta: np.ndarray) -> np.ndarray:
        """(N, n_unique): the absorption model's values of the members' optics ``theta``
        (N, n_par) at its orbit representatives, clamps counted as in :meth:`loads`."""
        optics = {n: theta[:, self.col[n]] for n in ("mua", "mus") + self._extra}
        key = np.column_stack(list(optics.values()))
        last = self._last_optics
        if last is not None and last[0].shape == key.shape and np.array_equal(last[0], key):
            # the same optics as the last call (constant optics over a window, as the
            # smoother and the twins run): the absorption model's values again
            vals = last[1]
            if last[2]:
                self._count_clamps(optics)
        else:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                vals = self.absorption.unique(*optics.values())
            clamps = [w for w in caught if "clamped" in str(w.message)]
            if clamps:
                self._count_clamps(optics)
            for w in caught:
                if w not in clamps:
                    warnings.warn(str(w.message), w.category, stacklevel=3)
            self._last_optics = (key, vals, bool(clamps))
        return vals

    def step(self, E_state: np.ndarray, theta: np.ndarray, t0: float, t1: float,
             power: float) -> np.ndarray:
        """Members ``E_state`` (N, n_nodes) deg C from ``t0`` to ``t1`` (s) at laser power
        ``power`` (W), each with its parameters ``theta`` (N, n_par) in ``estimate`` order."""
        s = self.setup
        load = self.loads(theta, power) if power != 0.0 else None
        kw = {}
        if "VHC" in self.col:
            kw["vhc_scale"] = theta[:, self.col["VHC"]] / s.parameters.nominal["VHC"]
        if "TC" in self.col:
            kw["tc_scale"] = theta[:, self.col["TC"]] / s.parameters.nominal["TC"]
        return self.stepper(t1 - t0).step(E_state, load, **kw)

    def __call__(self, E_state: np.ndarray, theta: np.ndarray, t0: float, t1: float):
        """The filter's forecast from ``t0`` to ``t1``: :meth:`step` at each sub-step's laser
        power (:meth:`TissueFilterSetup.mean_power`), in equal sub-steps no longer than
        ``setup.heat.max_dt``."""
        for a, b in self.substeps(t0, t1):
            E_state = self.step(E_state, theta, a, b, self.setup.mean_power(a, b))
        return E_state

    def substeps(self, t0: float, t1: float) -> list[tuple[float, float]]:
        """The heat steps ``(a, b)`` s of the interval ``t0 -> t1``: equal, no longer than
        ``setup.heat.max_dt`` (one step when it is None)."""
        max_dt = self.setup.heat.max_dt
        n = 1 if max_dt is None else max(1, math.ceil((t1 - t0) / max_dt - 1e-9))
        if n == 1:
            return [(float(t0), float(t1))]
        edges = np.linspace(t0, t1, n + 1)
        return [(float(a), float(b)) for a, b in zip(edges[:-1], edges[1:], strict=True)]


def observation_operator(setup: TissueFilterSetup, mesh):
    """``(P (p, n_nodes) csr, noise variances (p,), positions (p, 3) cm)`` of the point
    sensors followed by the image's pixels (pixel centres on z = 0)."""
    blocks, var, xyz = [], [], []
    n_pts = setup.sensors.positions.shape[0]
    if n_pts:
        blocks.append(fem.probe_matrix(mesh, setup.sensors.positions.T))  # points are (3, n)
        var.append(np.broadcast_to(np.asarray(setup.sensors.noise_var, float), (n_pts,)))
        xyz.append(setup.sensors.positions)
    if setup.sensors.image is not None:
        blocks.append(setup.sensors.image.matrix(mesh))
        var.append(np.full(setup.sensors.image.n_pixels, setup.sensors.image.reading_noise_var))
        xyz.append(setup.sensors.image.pixel_centers())
    return (sp.vstack(blocks).tocsr(), np.concatenate(var), np.vstack(xyz))
