"""identify: run the tissue filter on a series of sensor readings (see :mod:`enkf.tissue`)."""

from __future__ import annotations

import copy
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from fem.threads import blas_threads, keep_freed_memory

from ..adaptive import InflationEstimator
from ..loop import run_filter
from ..problem import FilterDivergence, FilterResult, StepReport
from .coagulation import CoagulationForwardModel
from .drift import identify_bank
from .estimates import TissueEstimates, persistence_summary
from .pieces import assemble
from .restart import restart_ensemble, restart_points, restarted
from .setup import TissueFilterSetup

__all__ = ["RunHead", "identify", "identify_single"]


@dataclass
class RunHead:
    """A filter's run up to its first restart from the smoother, before the restart: the
    forms of a drift bank's drifting filters (the same filter until then) share it
    (:func:`enkf.tissue.drift.identify_bank`), each resuming from it with its own restart."""

    #: the index of the segment whose restart comes next (len(segments): after the last)
    segment: int
    #: readings read before the restart
    readings: int
    #: the results of the segments before it (:class:`~enkf.problem.FilterResult`)
    parts: list
    #: the recorded rows (the tracked temperatures, bands, members), copies
    rows: dict
    #: the adaptive inflation's running estimate (a copy), or None
    inflation: object
    #: the emulator's clamp counts so far
    clamp_counts: dict


def _join(parts: list[FilterResult]) -> FilterResult:
    """One result from the segments of a run with restarts: each segment's first row (the
    restarted ensemble) replaces the last row of the one before."""
    if len(parts) == 1:
        return parts[0]
    rows = ("times", "param_mean", "param_std", "tracked_mean", "tracked_std")
    steps = ("analysed", "step_latency_s", "analysis_latency_s", "inflation",
             "innovation_loglik", "innovation_normalized")
    out = {k: np.concatenate([getattr(r, k)[:-1] for r in parts[:-1]]
                             + [getattr(parts[-1], k)]) for k in rows}
    out.update({k: np.concatenate([getattr(r, k) for r in parts]) for k in steps})
    return FilterResult(**out, state_ensemble=parts[-1].state_ensemble,
                        param_ensemble=parts[-1].param_ensemble)


def identify(setup: TissueFilterSetup, times: np.ndarray, data: np.ndarray, *,
             callback: Callable[[StepReport], None] | None = None,
             param_bounds: np.ndarray | None = None) -> TissueEstimates:
    """Run the filter on sensor data.

    With ``setup.parameters.drift`` (a :class:`~enkf.tissue.drift.DriftBank`) a still and a drifting
    filter run on the readings and the estimates are their mixture under the evidence
    (:func:`enkf.tissue.drift.identify_bank`; ``drift_weight`` says, per reading, how
    probable the drift is).

    With ``setup.restarts.times`` the filter restarts from the smoother after the
    readings :func:`restart_points` names (:func:`restart_ensemble`; ``docs/enkf.md``,
    "Restarts"). After each restart the callback sees the restarted members' re-run again
    from step 0 (``StepReport.replayed``), then the filter's steps go on: a
    :class:`~enkf.tissue.risk.RiskTracker` (step 0 starts it afresh) so integrates each
    member's damage along its own history.

    Parameters
    ----------
    times : (M,) s, strictly increasing, after 0 (the prior is at t = 0)
    data : (M, p) deg C at ``setup.sensors.positions`` (then the image's pixels);
        NaN = missing (no analysis)
    callback : called with a :class:`~enkf.problem.StepReport` after each step (the prior
        is step 0)
    param_bounds : (n_par, 2), physical range of each parameter's ensemble mean;
        leaving it stops the run (default: :meth:`ParameterModel.default_bounds`)

    Returns
    -------
    TissueEstimates; if the filter diverges, the estimates up to that point with
    ``diverged`` set to the message.
    """
    if setup.parameters.drift is not None:
        return identify_bank(setup, times, data, identify_single, callback=callback,
                             param_bounds=param_bounds)
    return identify_single(setup, times, data, callback=callback, param_bounds=param_bounds)


def identify_single(setup: TissueFilterSetup, times: np.ndarray, data: np.ndarray, *,
                     callback: Callable[[StepReport], None] | None = None,
                     param_bounds: np.ndarray | None = None,
                     restart_gate: Callable[[int, np.ndarray], bool] | None = None,
                     head: RunHead | None = None,
                     on_head: Callable[[RunHead], None] | None = None) -> TissueEstimates:
    """:func:`identify` with one filter. ``restart_gate(a, loglik)``, if given, is asked
    before each restart (after reading ``a``, with the filter's log-densities of readings
    1..a): False skips that restart, and the filter goes on with its members.

    ``on_head(head)``, if given, receives the run up to its first restart (a
    :class:`RunHead`, just before the smoother runs); ``head`` resumes a run from there
    (another setup's whose filter is the same up to its restarts: the restart, and every
    step after it, are this setup's; the callback sees the restart's replay and the steps
    after it)."""
    pieces = assemble(setup, param_bounds, float(times[0]) if len(times) else None)
    P_track, n = pieces.P_track, pieces.n
    n_off = setup.sensors.n_offsets
    M = len(times)
    tr_mean = np.full((M + 1, P_track.shape[0]), np.nan)
    tr_std = np.full_like(tr_mean, np.nan)
    q_lo = np.full((M + 1, n), np.nan)
    q_hi = np.full_like(q_lo, np.nan)
    members = np.full((M + 1, setup.n_members, n), np.nan)
    coag = isinstance(pieces.model, CoagulationForwardModel)
    eff_mean = np.full((M + 1, 2), np.nan) if coag else None
    eff_std = np.full((M + 1, 2), np.nan) if coag else None
    frac = np.full(M + 1, np.nan) if coag else None

    rows = dict(tr_mean=tr_mean, tr_std=tr_std, q_lo=q_lo, q_hi=q_hi, members=members,
                eff_mean=eff_mean, eff_std=eff_std, frac=frac)

    def record(rep: StepReport, outside: bool = True):
        tr_mean[rep.step], tr_std[rep.step] = pieces.tracked(rep)
        members[rep.step] = rep.param_ensemble[:, :n]
        with np.errstate(invalid="ignore"):
            q_lo[rep.step], q_hi[rep.step] = np.quantile(
                rep.param_ensemble[:, :n], [0.02275, 0.97725], axis=0)
        if coag:  # the optics the members had at this time: their damage, their values
            F, eff = pieces.model.effective(rep.param_ensemble[:, :n], rep.time)
            eff_mean[rep.step], eff_std[rep.step] = eff.mean(axis=0), eff.std(axis=0, ddof=1)
            frac[rep.step] = F.mean()
        if callback is not None and outside:
            callback(rep)

    def replay(k, t, X, th):  # a restart's re-run, for the callback (StepReport.replayed)
        rep = StepReport(k, t, False, 0.0, th.mean(axis=0), th.std(axis=0, ddof=1),
                         np.zeros(0), np.zeros(0), X, th, replayed=True)
        callback(rep)

    on_step = None if callback is None else replay
    t0 = time.perf_counter()
    diverged = None
    # the restarts from the smoother (setup.restarts.times) cut the readings into
    # segments: the filter runs each from the ensemble the one before left (the first from
    # the prior), replaced after a segment's last reading by the smoother's
    cuts = restart_points(setup, times, data)
    edges = [0, *[c for c in cuts if c < M], M]
    parts, restarts = [], []
    # the inflation estimate runs across the restarts, as in OnlineIdentifier; the
    # model error's time-correlated field starts afresh with each segment's new members
    ai = pieces.config.adaptive_inflation
    inflation = InflationEstimator(ai) if ai is not None else None
    # the filter's dense products are small (50 x 5000): threaded BLAS only spins, and
    # on a busy machine it is 20-30 times slower (measured); numba kernels keep the cores
    keep_freed_memory()  # ensemble-sized temporaries: reuse, not fresh page faults
    start = 0
    if head is not None:  # resume another run's start (the same filter up to here)
        start, parts = head.segment, list(head.parts)
        for key, arr in head.rows.items():
            if arr is not None:
                np.copyto(rows[key], arr)
        inflation = copy.deepcopy(head.inflation)
        pieces.model.clamp_counts = head.clamp_counts

    def keep_head(j, a):
        if on_head is not None and not restarts and (head is None or j > start):
            on_head(RunHead(j, a, list(parts), {k: None if v is None else v.copy()
                                                  for k, v in rows.items()},
                            copy.deepcopy(inflation), pieces.model.clamp_counts))

    for j, (a, b) in enumerate(zip(edges[:-1], edges[1:], strict=True)):
        if j < start:
            continue
        if not j:
            problem = pieces.problem(times[:b], data[:b])
        elif j > start and restart_gate is not None and not restart_gate(a, np.concatenate(
                [p.innovation_loglik for p in parts])):
            # no restart here: the filter goes on with its members
            last = parts[-1]
            problem = pieces.problem(times[a:b], data[a:b], t0=float(times[a - 1]),
                                     prior=lambda rng, N, X=last.state_ensemble,
                                     th=last.param_ensemble: (X.copy(), th.copy()))
        else:
            keep_head(j, a)
            X, theta, w = restart_ensemble(setup, pieces, times[:a], data[:a], on_step)
            restarts.append({"time_s": float(times[a - 1]), "readings": a, "wall_s": w})
            problem = pieces.problem(times[a:b], data[a:b], t0=float(times[a - 1]),
                                     prior=lambda rng, N, X=X, th=theta: (X.copy(), th.copy()))
        config = pieces.config if not j else replace(
            pieces.config, seed=int(np.random.SeedSequence([setup.seed, j]).generate_state(1)[0]))

        def seg_record(rep, a=a):  # this segment's steps in the run's numbering; the
            # restarted ensemble (its step 0) replaces the last step's, unseen outside
            record(replace(rep, step=rep.step + a), outside=rep.step > 0 or a == 0)

        try:
            with blas_threads(1):
                res = run_filter(problem, config, health=pieces.health, callback=seg_record,
                                 inflation_state=inflation)
        except FilterDivergence as err:
            parts.append(err.result)
            if j and err.step == 0:  # the restarted ensemble failed: its row is all its own
                r = err.result
                record(StepReport(a, float(times[a - 1]), False, 0.0, r.param_mean[0],
                                  r.param_std[0], r.tracked_mean[0], r.tracked_std[0],
                                  r.state_ensemble, r.param_ensemble), outside=False)
            # a later segment counts its steps from its restart
            diverged = str(err) + (f" (steps counted from the restart after the reading at "
                                   f"{times[a - 1]:g} s, reading {a})" if j else "")
            break
        parts.append(res)
    if diverged is None and M in cuts and (start == len(edges) - 1 or restart_gate is None
                                           or restart_gate(M, np.concatenate(
                                               [p.innovation_loglik for p in parts]))):
        # a restart after the last reading: the final ensemble
        keep_head(len(edges) - 1, M)
        X, theta, w = restart_ensemble(setup, pieces, times, data, on_step)
        restarts.append({"time_s": float(times[-1]), "readings": M, "wall_s": w})
        parts.append(restarted(parts[-1], X, theta))
        r = parts[-1]
        record(StepReport(M, float(times[-1]), False, 0.0, r.param_mean[0], r.param_std[0],
                          r.tracked_mean[0], r.tracked_std[0], X, theta), outside=False)
    res = _join(parts)
    wall = time.perf_counter() - t0
    clamped = pieces.model.clamp_report()
    if clamped:
        warnings.warn(f"the absorption emulator clamped members' optics to its table on "
                      f"{clamped['member_steps']} member-steps over {clamped['forecast_steps']} "
                      f"forecast steps: {clamped['advice']}", RuntimeWarning, stacklevel=2)
    k = len(res.times)
    est = TissueEstimates(
        times=res.times, names=setup.parameters.names, param_mean=res.param_mean[:, :n],
        param_std=res.param_std[:, :n],
        tracked_positions=setup.sensors.tracked, tracked_mean=tr_mean[:k],
        tracked_std=tr_std[:k], analysed=res.analysed, step_latency_s=res.step_latency_s,
        filter_wall_s=wall, result=res, diverged=diverged, param_q_low=q_lo[:k],
        param_q_high=q_hi[:k], method=setup.method, clamped=clamped,
        effective_mean=None if eff_mean is None else eff_mean[:k],
        effective_std=None if eff_std is None else eff_std[:k],
        coagulated_fraction=None if frac is None else frac[:k],
        innovation_loglik=res.innovation_loglik,
        innovation_normalized=res.innovation_normalized,
        laser_on=np.array([setup.mean_power(float(a), float(b)) > 0
                           for a, b in zip(res.times[:-1], res.times[1:], strict=True)]),
        sensor_offset_mean=res.param_mean[:, -n_off:] if n_off else None,
        sensor_offset_std=res.param_std[:, -n_off:] if n_off else None,
        restarts=tuple(restarts), param_members=members[:k])
    persistence = persistence_summary(est)
    if persistence["flagged"]:
        warnings.warn(persistence["advice"], RuntimeWarning, stacklevel=2)
    return est
