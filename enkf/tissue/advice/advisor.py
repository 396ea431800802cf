"""The advisor: each member of the current ensemble forecast to the target under the plan
and with the laser off (:mod:`enkf.tissue.advice` says what and why)."""

from __future__ import annotations

import math
import time
import zlib
from dataclasses import dataclass, field

import numpy as np

import fem

from ..drift import weighted_quantiles
from .drift import member_trends, optics_paths, remember
from .forecast import (
    PointForecast,
    damage,
    first_crossing,
    heat,
    nominal_peak,
    region_points,
)
from .plan import DRIFT_FORECASTS, REGION_POINTS, SURFACE_POINTS, AdviceRow, MemberAdvice, Plan

__all__ = ["Advisor", "online_ensembles"]


@dataclass
class _Track:
    """A filter's members followed so far: damage and hottest temperature at the points."""

    time: float
    T: np.ndarray  #: (N, p) deg C at the points
    omega: np.ndarray  #: (N, p)
    T_max: np.ndarray  #: (N, p) deg C
    reached: np.ndarray  #: (N,) s when the target reached Omega >= 1 (nan: not yet)
    advice: dict = field(default_factory=dict)  #: {step: MemberAdvice}
    heated: float = 0.0  #: s of the plan's heating up to ``time``
    #: [(heated s, (N, n_estimate) the members' log optics), ...] at the readings
    history: list = field(default_factory=list)


class Advisor:
    """Forecasts of the members towards the target (module docstring).

    Parameters
    ----------
    setup : TissueFilterSetup
    E, A : float
        J/mol and 1/s: the Arrhenius law of the tissue (the medium's ``E`` and ``A``).
    target : (n, 3) cm points, or a box ``((x0, x1), (y0, y1), (z0, z1))`` cm
        Every point must reach Omega >= 1 (of a box, its :data:`REGION_POINTS` nodes that
        heat least under the plan at the nominal optics).
    plan : Plan, optional
        Default: the setup's laser (a :meth:`HeatSimulation.laser_power`).
    protected : points or box, optional
        Tissue to spare (of a box, its :data:`REGION_POINTS` hottest nodes), with a damage
        limit ``protected_omega`` and/or a temperature limit ``protected_T`` (deg C).
    surface_T : float, optional
        deg C, the surface's limit (at its :data:`SURFACE_POINTS` hottest nodes).
    step : s, the forecast's heat step (default ``setup.heat.max_dt``, else 0.1 s); tail : s
        forecast after the plan's last pulse; max_horizon : s, the farthest a forecast
        reaches.
    quantiles : (lower, upper) of the reported interval (default 5% and 95%).
    engine : "auto" (adjoint where the heat step is the members' shared one), "adjoint",
        "direct".
    drift : "walk+trend" (default), "walk" or "hold"
        How a drifting filter's optics move in the forecast (module docstring); "hold":
        every member's optics at their present values.
    trend_window : s of heating over which a drifting filter's trend is fitted.
    drift_step : s, the pieces over which the drifting optics are held in the forecast.
    hold_below : log units a step: a filter whose walk is below it holds its optics.
    seed : int, the draws of the walks (one stream per reading and filter).
    """

    def __init__(self, setup, *, E: float, A: float, target, plan: Plan | None = None,
                 protected=None, protected_omega: float | None = None,
                 protected_T: float | None = None, surface_T: float | None = None,
                 step: float | None = None, tail: float = 5.0, max_horizon: float = 30.0,
                 quantiles=(0.05, 0.95), min_weight: float = 0.01, engine: str = "auto",
                 drift: str = "walk+trend", trend_window: float = 1.0,
                 drift_step: float = 0.5, hold_below: float = 0.005, seed: int = 0):
        from ..forward import TissueForwardModel

        if setup.parameters.kind != "random_walk":
            # coagulation: each member's optics follow its own damage, which the point
            # forecast does not carry at the nodes that absorb; trend: the rates ride
            # in the state behind the optics. Neither forecast is built.
            raise ValueError(f"advice needs parameter_model = 'random_walk', got "
                             f"{setup.parameters.kind!r}: the forecast does not move the "
                             f"optics with the damage (coagulation) or with filtered rates "
                             f"(trend); identify without [advice], or with the random walk")
        if drift not in DRIFT_FORECASTS:
            raise ValueError(f"Advisor.drift must be one of {DRIFT_FORECASTS}, got {drift!r}")
        for name, v in (("trend_window", trend_window), ("drift_step", drift_step),
                        ("hold_below", hold_below)):
            if isinstance(v, bool) or not (isinstance(v, int | float | np.number)
                                           and np.isfinite(v) and v > 0):
                raise ValueError(f"Advisor.{name} must be a finite number > 0, got {v!r}")
        if step is None:
            step = setup.heat.max_dt if setup.heat.max_dt is not None else 0.1
        for name, v in (("E", E), ("A", A), ("step", step), ("max_horizon", max_horizon),
                        ("tail", tail)):
            if isinstance(v, bool) or not (isinstance(v, int | float | np.number)
                                           and np.isfinite(v) and (v > 0 or name == "tail" and v == 0)):
                raise ValueError(f"Advisor.{name} must be a finite number "
                                 f"{'>=' if name == 'tail' else '>'} 0, got {v!r}")
        q = tuple(float(v) for v in quantiles)
        if len(q) != 2 or not 0 < q[0] < 0.5 < q[1] < 1:
            raise ValueError(f"Advisor.quantiles must be (lower, upper) with 0 < lower < 0.5 "
                             f"< upper < 1, got {quantiles!r}")
        if protected is not None and protected_omega is None and protected_T is None:
            raise ValueError("Advisor.protected needs a limit: protected_omega and/or "
                             "protected_T")
        for name, v in (("protected_omega", protected_omega), ("protected_T", protected_T),
                        ("surface_T", surface_T)):
            if v is not None and not (np.isfinite(v) and (v > 0 or name != "protected_omega")):
                raise ValueError(f"Advisor.{name} must be a finite number"
                                 f"{' > 0' if name == 'protected_omega' else ''}, got {v!r}")
        if engine not in ("auto", "adjoint", "direct"):
            raise ValueError(f"Advisor.engine must be 'auto', 'adjoint' or 'direct', got "
                             f"{engine!r}")
        self.setup, self.E, self.A, self.quantiles = setup, float(E), float(A), q
        self.protected_omega, self.protected_T, self.surface_T = \
            protected_omega, protected_T, surface_T
        self.min_weight = float(min_weight)
        self.drift, self.trend_window = drift, float(trend_window)
        self.drift_step, self.hold_below, self.seed = float(drift_step), float(hold_below), int(seed)
        # each filter's walk (log units a step) and its factor with the laser off: the
        # bank's filters by name, a lone filter as None
        comps = {None: setup} if setup.parameters.drift is None else \
            setup.parameters.drift.components(setup)
        n_est = len(setup.parameters.estimate)
        self.walks = {k: (np.array(c.parameters.walk_std()[:n_est], float),
                          float(c.parameters.random_walk_when_off)) for k, c in comps.items()}
        if plan is None:
            owner = getattr(setup.power, "__self__", None)
            if owner is None or getattr(setup.power, "__name__", "") != "laser_power":
                raise ValueError("Advisor needs a plan: the setup's power is not a "
                                 "HeatSimulation's laser_power")
            plan = Plan.from_heat_simulation(owner)
        self.plan = plan
        self.model = TissueForwardModel(setup)
        mesh = self.model.mesh
        self.step, self.tail, self.max_horizon = float(step), float(tail), float(max_horizon)
        self.K = max(1, math.ceil(min(max(plan.end, 0.0) + tail, max_horizon) / step - 1e-9))
        peak = nominal_peak(self.model, plan, self.step, self.K)
        groups = {"target": region_points(mesh, target, peak, REGION_POINTS, coldest=True,
                                          what="target")}
        if protected is not None:
            groups["protected"] = region_points(mesh, protected, peak, REGION_POINTS,
                                                coldest=False, what="protected")
        if surface_T is not None:
            top = np.flatnonzero(np.isclose(mesh.p[2], mesh.p[2].min()))
            groups["surface"] = mesh.p[:, top[np.argsort(-peak[top])[:SURFACE_POINTS]]].T
        self.points = {k: np.asarray(v, float) for k, v in groups.items()}
        sizes = np.cumsum([0] + [len(v) for v in self.points.values()])
        self.slices = {k: slice(int(a), int(b)) for k, a, b in
                       zip(self.points, sizes[:-1], sizes[1:], strict=True)}
        P = fem.probe_matrix(mesh, np.vstack(list(self.points.values())).T)
        stepper = self.model.stepper(self.step)
        shared = not ({"VHC", "TC"} & set(setup.parameters.estimate)) and not np.any(
            np.isnan(stepper.fixed_values))
        if engine == "adjoint" and not shared:
            raise ValueError("engine='adjoint' needs a heat step the members share (no VHC, "
                             "TC estimated, no face held at each member's own temperature)")
        self.engine = "adjoint" if engine == "adjoint" or (engine == "auto" and shared) \
            else "direct"
        self.forecast = PointForecast(self.model, P, self.step, self.K, self.engine)
        self.P = self.forecast.P
        self.tracks: dict = {}
        #: the drifting optics' load responses (S pieces x N members of them a reading)
        #: with their product over the nodes in single precision
        #: (:meth:`PointForecast.load_responses`): about 1e-6 of the largest response,
        #: the target and stop times within 1e-6 s of double precision's, where the
        #: walk spreads them over tenths of a second (``tests/test_advice_drift.py``)
        self.drift_dtype = np.float32
        self._warm_kernels()

    def _warm_kernels(self) -> None:
        """Compile (or load from numba's cache) the kernels a reading calls: two members
        at the start temperature and the nominal optics followed over one step and
        forecast as each filter's (held and drifting optics: each layout of the
        responses), then forgotten. The first reading's advice then costs what the next
        ones do (a fresh install compiles here, about 0.4 s, not within a reading)."""
        s = self.setup
        theta = np.tile([s.parameters.nominal[k] for k in s.parameters.estimate], (2, 1))
        X = np.full((2, self.model.mesh.p.shape[1]), float(s.T_initial))
        key = object()  # a track of no filter
        self._track(key, 0.0, X, 0, theta)
        tr = self._track(key, self.step, X, 1, theta)
        for name in self.walks:
            self.member_advice(tr, X, theta, name)
        del self.tracks[key]

    def _track(self, key, t: float, X, step: int | None, theta=None) -> _Track:
        """Follow a filter's members to ``t`` (s) with the ensemble ``X`` (N, n) deg C
        and parameters ``theta`` (N, >= n_estimate) (``step`` 0 starts afresh; None: the
        online filter, whose members started from the prior's uniform ``T_initial`` at
        0 s)."""
        Tp = (self.P @ np.asarray(X, float).T).T
        tr = self.tracks.get(key)
        if step == 0 or (tr is None and t <= 0):
            N, p = Tp.shape
            old = {} if tr is None else tr.advice  # a replay keeps the advice given
            self.tracks[key] = tr = _Track(float(t), Tp, np.zeros((N, p)), Tp.copy(),
                                           np.full(N, np.nan), old)
            tr.heated = self.plan.on_time(0.0, float(t))
            self._remember(tr, theta)
            return tr
        if tr is None:
            tr = self._track(key, 0.0, np.full_like(X, float(self.setup.T_initial)), 0)
        tr.heated += self.plan.on_time(tr.time, t) if t > tr.time else 0.0
        if t > tr.time:
            tg = self.slices["target"]
            before = tr.omega[:, tg].min(axis=1)
            fem.advance_damage(tr.omega, tr.T, Tp, t - tr.time, self.E, self.A,
                               rule="trapezoid")
            after = tr.omega[:, tg].min(axis=1)
            new = np.isnan(tr.reached) & (after >= 1.0)
            frac = (1.0 - before[new]) / np.maximum(after[new] - before[new], 1e-300)
            tr.reached[new] = tr.time + np.clip(frac, 0, 1) * (t - tr.time)
        np.maximum(tr.T_max, Tp, out=tr.T_max)
        tr.time, tr.T = float(t), Tp
        self._remember(tr, theta)
        return tr

    def _remember(self, tr: _Track, theta) -> None:
        """Keep the members' log optics at this reading (their trends)."""
        if theta is not None and self.drift == "walk+trend":
            n = len(self.setup.parameters.estimate)
            remember(tr.history, tr.heated, np.log(np.asarray(theta, float)[:, :n]),
                     self.trend_window)

    def trend(self, key) -> np.ndarray:
        """(N, n_estimate) 1/s of heating: the slope of each member's log optics in the
        filter ``key`` against heated time over its last ``trend_window`` s of heating
        (:func:`~enkf.tissue.advice.drift.member_trends`)."""
        n = len(self.setup.parameters.estimate)
        tr = self.tracks.get(key)
        return np.zeros(n) if tr is None else member_trends(tr.history, self.trend_window, n)

    def optics_paths(self, key, theta, t0: float, K: int):
        """The members of filter ``key`` with optics ``theta`` at ``t0`` over the next
        ``K`` steps: ``(thetas (S, N, n), seg (K,))`` or None where they hold
        (:func:`~enkf.tissue.advice.drift.optics_paths`)."""
        if self.drift == "hold":
            return None
        n = len(self.setup.parameters.estimate)
        walk, when_off = self.walks.get(key, self.walks.get(None, (np.zeros(n), 0.0)))
        h = self.step
        on = np.array([self.plan.on_time(t0 + j * h, t0 + (j + 1) * h) / h for j in range(K)])
        rng = np.random.default_rng([self.seed, zlib.crc32(str(key).encode()),
                                     int(round(t0 * 1e6))])
        trend = self.trend(key) if self.drift == "walk+trend" else np.zeros(n)
        return optics_paths(np.asarray(theta, float)[:, :n], on, h, walk, when_off, trend,
                            self.drift_step, self.hold_below, rng)

    # ------------------------------------------------------------------ forecast
    def member_advice(self, tr: _Track, X, theta, key=None) -> MemberAdvice:
        """The members' advice from their state ``X`` (N, n) deg C, their parameters
        ``theta`` (N, >= n_estimate) and what ``tr`` followed so far (``key``: the bank's
        filter, whose walk moves the optics)."""
        tic = time.perf_counter()
        t0, h = tr.time, self.step
        end = min(max(self.plan.end, t0) + self.tail, t0 + self.max_horizon)
        K = int(min(self.K, max(1, math.ceil((end - t0) / h - 1e-9))))
        seg = None
        P = np.array([self.plan.mean_power(t0 + j * h, t0 + (j + 1) * h) for j in range(K)])
        paths = self.optics_paths(key, theta, t0, K)
        # the responses to the laser only where the plan still heats: after its last
        # pulse they would be multiplied by 0 W
        H, G = self.forecast.responses(X, theta, K, loads=paths is None and P.any())
        if paths is not None:  # the drifting optics' loads, piece by piece
            thetas, seg = paths
            S, N0, n_est = thetas.shape
            G = self.forecast.load_responses(thetas.reshape(S * N0, n_est), K,
                                             self.drift_dtype)
            G = G.reshape(S, N0, K, -1).transpose(1, 0, 2, 3)
        elif G is None:
            G = np.zeros((X.shape[0], K, H.shape[2]))
        N, tg = X.shape[0], self.slices["target"]
        plan = heat(H, G, P, np.full(N, K), seg)
        _, path = damage(self.E, self.A, h, tr.omega[:, tg], plan[..., tg], path=True)
        target = np.where(np.isnan(tr.reached), first_crossing(path, t0, h),
                          tr.reached)
        # switch-offs after c = 0 .. c_max intervals: the latest any member needs
        need = np.ceil((target[np.isfinite(target)] - t0) / h - 1e-9)
        stop = np.full(N, np.inf)
        if need.size:
            C = int(np.clip(need.max(), 0, K)) + 1
            Yc = np.empty((C, N, K + 1, tg.stop - tg.start))
            Yc[0] = H[..., tg]
            Gt = G[..., tg] if seg is not None else G[:, None, :, tg]
            sg = seg if seg is not None else np.zeros(K, int)
            for c in range(1, C):
                Yc[c] = Yc[c - 1]
                Yc[c, :, c:] += P[c - 1] * Gt[:, sg[c - 1], :K - c + 1]
            final = damage(self.E, self.A, h, np.tile(tr.omega[:, tg], (C, 1)),
                           Yc.reshape(C * N, K + 1, -1)).min(axis=1).reshape(C, N)
            for n in np.flatnonzero(np.isfinite(target)):
                c = int(np.argmax(final[:, n] >= 1.0)) if (final[:, n] >= 1.0).any() else C
                if c == 0:
                    stop[n] = t0
                elif c < C:
                    lo, hi = final[c - 1, n], final[c, n]
                    f = -np.log(lo) / np.log(hi / lo) if lo > 0 else (1 - lo) / (hi - lo)
                    stop[n] = t0 + (c - 1 + float(np.clip(f, 0, 1))) * h
                else:  # heated to the crossing it reaches; between samples, the crossing
                    stop[n] = target[n]
        risks, peaks = {}, {}
        own = np.where(np.isfinite(stop), np.ceil((stop - t0) / h - 1e-9), K).astype(int)
        scenarios = (("plan", plan), ("off", H), ("at_target", heat(H, G, P, own, seg)))
        for region, T_lim, om_lim in (("protected", self.protected_T, self.protected_omega),
                                      ("surface", self.surface_T, None)):
            if region not in self.slices:
                continue
            sl = self.slices[region]
            hit = np.zeros((3, N), bool)
            Ys = np.stack([Y[..., sl] for _, Y in scenarios])  # (3, N, K+1, p)
            hottest = np.maximum(Ys.max(axis=2), tr.T_max[:, sl])  # (3, N, p), so far too
            peaks[region] = hottest[0].max(axis=1)
            if T_lim is not None:
                hit |= (hottest >= T_lim).any(axis=2)
            if om_lim is not None:
                om = damage(self.E, self.A, h, np.tile(tr.omega[:, sl], (3, 1)),
                            Ys.reshape(3 * N, K + 1, -1))
                hit |= (om.reshape(3, N, -1) >= om_lim).any(axis=2)
            for i, (scen, _) in enumerate(scenarios):
                risks[f"{region}_{scen}"] = hit[i]
        return MemberAdvice(t0, t0 + K * h, target, stop, risks, time.perf_counter() - tic,
                            peaks)

    # ------------------------------------------------------------------ following a filter
    def __call__(self, rep) -> None:
        """The callback of :func:`~enkf.tissue.identify`: follow each filter's members
        (a restart's replay re-runs their damage) and forecast after each reading."""
        tr = self._track(rep.component, rep.time, rep.state_ensemble, rep.step,
                         rep.param_ensemble)
        if not rep.replayed:
            tr.advice[rep.step] = self.member_advice(tr, rep.state_ensemble, rep.param_ensemble,
                                                     rep.component)

    def filters_at(self, est, s: int) -> list[tuple]:
        """``[(track key, weight), ...]`` of each filter of ``est.component_weights`` after
        step ``s``, named by the track that followed its run there (one filter: its own,
        weight 1)."""
        keys = list(self.tracks)
        weights = getattr(est, "component_weights", None) or {k: None for k in keys}
        comps = getattr(est, "components", None) or {}
        # one that resumed another's run at its first restart: that one's steps before it
        forks = getattr(est, "component_forks", None) or {}
        out = []
        for n, w in weights.items():
            if n in forks and s <= forks[n][1]:
                src = forks[n][0]
            else:  # a bank runs the drifting filters once when none restarts: they share it
                src = next((k for k in keys if k in comps and comps[k] is comps[n]), n)
            out.append((src, 1.0 if w is None else float(w[min(s, len(w) - 1)])))
        return out

    def table(self, est=None) -> list[AdviceRow]:
        """The advice at each step followed: the members of the bank's filters weighed by
        ``est.component_weights`` after each reading (one filter: its own members)."""
        steps = sorted({s for tr in self.tracks.values() for s in tr.advice})
        rows = []
        for s in steps:
            parts = {}
            for src, wk in self.filters_at(est, s):
                tr = self.tracks.get(src)
                adv = None if tr is None else tr.advice.get(s)
                if adv is not None and wk > 0:
                    parts[src] = (parts.get(src, (0.0,))[0] + wk, adv)
            if parts:
                rows.append(self.mix(list(parts.values())))
        return rows

    def online(self, ident) -> AdviceRow:
        """The advice after an :meth:`OnlineIdentifier.update` (each filter of a bank with
        weight >= ``min_weight`` forecast, identical ensembles once)."""
        t = ident.time
        parts, done = [], []
        for name, w, X, theta in ident.filter_ensembles():
            tr = self._track(name, t, X, None, theta)
            if w < self.min_weight:
                continue
            # the drifting filters before their restarts are one filter: forecast once
            same = [a for (X0, th0), a in done
                    if np.array_equal(th0, theta) and np.array_equal(X0, X)]
            adv = same[0] if same else self.member_advice(tr, X, theta, name)
            done.append(((X, theta), adv))
            parts.append((w, adv))
        return self.mix(parts)

    def mix(self, parts) -> AdviceRow:
        """One :class:`AdviceRow` from ``[(weight, MemberAdvice), ...]``: each filter's
        weight shared evenly by its members."""

        w = np.array([p[0] for p in parts], float)
        w = w / w.sum()
        advs = [p[1] for p in parts]
        end = max(a.horizon_end for a in advs)
        big = end + 1e9  # inf (beyond the horizon) as a number the quantiles can order
        vals = [np.column_stack([np.where(np.isfinite(a.target_time), a.target_time, big),
                                 np.where(np.isfinite(a.stop_time), a.stop_time, big)])
                for a in advs]
        qs = weighted_quantiles(vals, w, [0.5, *self.quantiles])
        qs = np.where(qs > end + 1e-6, np.inf, qs)

        def prob(get):
            return float(sum(wj * np.mean(get(a)) for wj, a in zip(w, advs, strict=True)))

        peaks = {}
        for region in advs[0].peak_T:
            pq = weighted_quantiles([a.peak_T[region][:, None] for a in advs], w,
                                    [0.5, *self.quantiles])[:, 0]
            peaks[region] = tuple(float(v) for v in pq)
        return AdviceRow(
            advs[0].time, tuple(float(v) for v in qs[:, 0]),
            prob(lambda a: np.isfinite(a.target_time)), tuple(float(v) for v in qs[:, 1]),
            {k: prob(lambda a, k=k: a.risks[k]) for k in advs[0].risks},
            float(sum(a.wall_s for a in advs)), peaks)


def online_ensembles(ident) -> list[tuple]:
    """``[(name, weight, X (N, n) deg C, theta (N, n_par)), ...]``: the filters of an
    :class:`~enkf.tissue.OnlineIdentifier` after its last update
    (:meth:`~enkf.tissue.OnlineIdentifier.filter_ensembles`)."""
    return ident.filter_ensembles()
