"""The time loop of the heat simulation (:func:`run_heat`, behind ``model.simulate_heat_distribution``).

One run: set up the mesh, the voxel <-> node operators and the thermal sub-media,
start from ``HS.T_initial`` or a ``HS.T`` set before the run (or, chained, from the end
of the previous run), and march
the schedule of :meth:`HeatSimulation.schedule` with :func:`fem.march`. After every
step the damage integral and the media's highest temperatures advance; at every update
the state is reported (slice plots, movie frames) and, every
``HS.media_prop_recalc_period`` updates, FR-, T- and FD-dependent media are
re-evaluated (:mod:`mcmatlab_py.frt`).
"""

from __future__ import annotations

import functools
import math
import warnings

import numpy as np

from .._strict import NotBuiltError
from ..frt import MediaCoupling
from ..monte_carlo.broadband import is_broadband
from ..monte_carlo.host import optical_arrays
from ..monte_carlo.run import simulate, store_results
from ..progress import Progress
from .mesh import Setup, damage_parameters, voxels_to_nodes
from .rkc import RKCSteps, choose_integrator, spectral_radius
from .simulation import auto_dt
from .state import heat_source, sensor_series, start_from_T, store_heat_results
from .steps import ErrorControlledSteps

__all__ = ["BOILING_WARNING_C", "run_heat", "simulate_heat_distribution"]

BOILING_WARNING_C = 100.0  #: deg C: MCmatlab warns when a medium gets hotter (water boils)


def _value(f, t):
    v = float(f(t))
    if not math.isfinite(v) or v < 0:
        raise ValueError(f"a time-varying property returned {v!r} at t = {t} s")
    return v


def run_heat(model) -> None:  # noqa: C901  (one loop with its callbacks)
    """Run ``model.HS`` (see :mod:`mcmatlab_py.heat`); fills the results of ``model.HS``."""
    import fem


    G, MC, HS = model.G, model.MC, model.HS
    M = G.medium_map()
    HS.validate(G)
    media = G.media
    varying_optics = HS.mua_t is not None or HS.mus_t is not None
    if MC.NA is None and not varying_optics and not callable(HS.absorption):
        raise ValueError("MC.NA is empty: run model.run_monte_carlo() before the heat "
                         "simulation (or give time-varying optics)")
    vm = HS.varying_medium
    if not 0 <= vm < len(media):
        raise ValueError(f"HS.varying_medium must index G.media, got {vm!r}")
    if MC.P is not None and not callable(HS.P) and HS.P != MC.P:
        warnings.warn(f"MC.P = {MC.P:g} W and HS.P = {HS.P:g} W differ: the heat simulation "
                      "heats with HS.P, and its Monte Carlo re-runs see FR = HS.P * NFR "
                      "(MCmatlab has one power, MC.P, for both): set HS.P = MC.P", stacklevel=4)

    S = Setup(G, HS, M)
    present_media = np.unique(M)
    mesh, L = S.mesh, S.L
    npts = mesh.p.shape[1]
    chained = HS.max_media_temps is not None
    if chained and (HS.T_nodes is None or HS.T_nodes.size != npts):
        raise ValueError("HS holds a previous run on another mesh: call model.HS.reset() to "
                         "start afresh")
    T_set = start_from_T(HS, G, S, chained)
    if chained:
        T0 = np.array(HS.T_nodes, dtype=float) if T_set is None else T_set
        Omega = np.array(HS.Omega, dtype=float).ravel()
        Omega_vox = np.array(HS.Omega_voxels, dtype=float).ravel()
        t_offset = float(HS.sensor_times[-1])
    else:
        T0 = voxels_to_nodes(L, HS.T_initial) if T_set is None else T_set
        Omega = np.zeros(npts)
        Omega_vox = np.zeros(M.size)
        t_offset = 0.0

    # thermal media: MCmatlab's sub-media of FR/T/FD-dependent media, then HS.*_t overrides
    coupling = MediaCoupling(model, M, S)
    coupling.update_thermal(S.to_voxels(T0) if coupling.thermal_dependent else None,
                            Omega_vox.reshape(M.shape) if coupling.thermal_dependent else None)

    def element_props(t):
        if HS.VHC_t is None and HS.TC_t is None:  # no copies of the element arrays
            return coupling.vhc_e, coupling.tc_e
        vhc, tc = coupling.vhc_e.copy(), coupling.tc_e.copy()
        in_vm = S.elem_medium == vm
        if HS.VHC_t is not None:
            vhc[in_vm] = _value(HS.VHC_t, t)
        if HS.TC_t is not None:
            tc[in_vm] = _value(HS.TC_t, t)
        return vhc, tc

    vhc0, tc0 = element_props(0.0)

    def stability_props(t):
        """VHC and TC for the automatic step: the sub-media on the voxels where no function
        of time overrides them (the elements' values, without 6 per voxel)."""
        if HS.VHC_t is None and HS.TC_t is None:
            th = coupling.thermal
            on = np.isin(th.parent, present_media)
            return th.VHC[on], th.TC[on]
        return element_props(t)

    dt_max = None
    # steps chosen by accuracy (mcmatlab_py.heat.steps); the *_t functions of time keep
    # the schedule's steps, so that their Monte Carlo re-runs stay at its times
    adaptive = (HS.dt is None and HS.step_control == "accuracy" and not varying_optics
                and HS.VHC_t is None and HS.TC_t is None)
    if HS.dt is None:
        dt_max = auto_dt(S.mesh_grid.spacing, *stability_props(0.0), HS.theta,
                         HS.large_time_steps)
    sched = HS.schedule(math.inf if adaptive else dt_max)
    if adaptive:
        dt_max = None  # no sub-steps from the stability bound
    # the bound of the automatic step for the current thermal sub-media: a step of the
    # schedule longer than it (the media became more diffusive) is taken in sub-steps
    bound = {"dt": dt_max}
    dt_taken = set()
    times = sched.times
    boundary = fem.HeatBoundary.from_mcmatlab(
        HS.heat_boundary_type,
        temperature=None if HS.heat_boundary_type != 2 else HS.T_ambient,
        h=HS.heat_transfer_coefficient if HS.heat_boundary_type == 2 else 0.0)
    single_thermal = len(media) == 1 and not coupling.thermal_dependent
    steppers: dict = {}

    # the operator: the stepper's choice (operator="auto"). Media that vary only with depth
    # take the tensor product of 1-D operators, solved directly (fem.LayeredKroneckerSolver);
    # with lumped mass it is the vertex-centred 7-point finite volumes (a maximum principle,
    # as MCmatlab's), which differ from the P1 tetrahedra only on the box's edges and where an
    # interface meets a side face (fem.layered). One medium keeps the P1 operator's exact fast
    # solver with lumped mass, and takes the tensor product with the averaged mass.
    # HS.use_gpu: the solves on the GPU (fem.gpu), CG warm-started on the device.
    options = {"operator": "auto", "mass": HS.mass, "method": "gpu" if HS.use_gpu else "auto",
               "gpu_device": HS.gpu_device}

    # the voxels' power on the nodes: a P1 operator's (L, V_e / 4 to a tetrahedron's vertex),
    # or the tensor-product operator's (each cell's an eighth to each corner), whose lumped
    # mass is the vertex-centred finite volumes' (they differ on the box's edges, where the
    # P1 load with that mass heated a uniformly heated block unevenly)
    # (None where the heat mesh is neither the voxels' nor a refinement of them: the P1 load)
    corner_load = functools.cache(lambda: fem.corner_load_matrix(S.mesh_grid, S.grid))
    load = {"matrix": L}  # the one that goes with the current operator's mass

    def stepper_for(dt, vhc, tc, theta=HS.theta):
        key = (round(dt, 15), coupling.version, theta)
        if key not in steppers or not single_thermal and (HS.VHC_t or HS.TC_t):
            # a stepper of an older coupling version is never used again: keep only the
            # current version's (one per step length), or media re-binned at every update
            # would hold one factorization each (24 GB at 100^3 voxels)
            for old in [k for k in steppers if k[1] != coupling.version]:
                del steppers[old]
            st = steppers[key] = fem.HeatStepper(mesh, vhc, tc, dt, theta=theta,
                                                 boundary=boundary, **options)
            corner = corner_load() if st.operator == "kronecker" else None
            matrix = L if corner is None else corner
            if matrix is not load["matrix"]:  # the media changed the operator
                load["matrix"] = matrix
                if src["NA"] is not None:
                    set_absorption(src["NA"])
        return steppers[key]

    probes = fem.probe_matrix(mesh, np.asarray(HS.temp_sensor_positions, float)
                              .reshape(-1, 3).T) if len(HS.temp_sensor_positions) else None

    # absorbed power: MC.NA, the emulator, or Monte Carlo runs for time-varying optics
    if varying_optics or callable(HS.absorption):
        if is_broadband(MC.wavelength):
            raise NotBuiltError("HS.mua_t, HS.mus_t and HS.absorption with a broadband "
                                "MC.wavelength are not built: give one wavelength")
        mua, mus, g, nref = optical_arrays(media, MC.wavelength)
    current_optics = None
    src = {"NA": MC.NA, "f": None}  # the voxel map and its nodal load per W

    def set_absorption(NA):
        src["NA"], src["f"] = NA, load["matrix"] @ np.asarray(NA, float).ravel()

    if MC.NA is not None:
        set_absorption(heat_source(model))
    HS.mc_runs = 0 if not chained else HS.mc_runs

    def absorption_load(t):
        nonlocal current_optics
        if not varying_optics:
            if callable(HS.absorption) and src["NA"] is None:
                set_absorption(HS.absorption(np.array([mua[vm]]), np.array([mus[vm]]))[0])
            return src["f"]
        a = _value(HS.mua_t, t) if HS.mua_t is not None else mua[vm]
        s = _value(HS.mus_t, t) if HS.mus_t is not None else mus[vm]
        if current_optics == (a, s):
            return src["f"]
        current_optics = (a, s)
        if callable(HS.absorption):
            set_absorption(HS.absorption(np.array([a]), np.array([s]))[0])
        else:
            mua_now, mus_now = mua.copy(), mus.copy()
            mua_now[vm], mus_now[vm] = a, s
            res = simulate(G, MC, M, mua_now, mus_now, g, nref,
                           seed=(MC.seed or 0) + HS.mc_runs, n_photons=MC.n_photons_requested
                           or 10**6)
            HS.mc_runs += 1
            store_results(MC, res, M, mua_now, G.dx * G.dy * G.dz)
            set_absorption(MC.NA)
        return src["f"]

    E_node, A_node = damage_parameters(mesh, S.elem_medium, media)
    if E_node is not None:  # the voxels' own media, as MCmatlab's voxel damage
        E_vox = np.array([m.E if m.E is not None else 0.0 for m in media])[M.ravel()]
        A_vox = np.array([m.A if m.A is not None else 0.0 for m in media])[M.ravel()]
        T_vox_old = S.to_voxels(T0).ravel()
        node_damage = fem.DamageIntegral(E_node, A_node)  # checked once, not every step
        voxel_damage = fem.DamageIntegral(E_vox, A_vox)
    media_maxima = fem.GroupMaxima(S.medium_nodes)
    if not chained:
        HS.max_media_temps = np.array([T0[n].max() if n.size else -np.inf
                                       for n in S.medium_nodes])
    else:  # a run that goes on from an earlier one (or its saved outputs)
        HS.max_media_temps = np.array(HS.max_media_temps, dtype=np.float64)
    snap_every = max(1, (len(times) - 1) // HS.n_snapshots) if HS.n_snapshots else 0
    if not chained or HS.snapshots is None:
        HS.snapshots = [(t_offset, T0.copy())] if snap_every else []
    monitor = _monitor(model, M, S, chained, T0, t_offset)
    updates = set(int(k) for k in sched.updates)
    observed = (HS.steps_at_updates or monitor is not None or snap_every
                or coupling.thermal_dependent or coupling.optical_dependent
                or coupling.fluorescence_dependent or model.FMC.NA is not None
                or callable(HS.P))
    if adaptive and not observed:
        # nothing reads the state at the updates (no plots, movie, snapshots or media that
        # follow it) and the power changes only at the phases' edges: the error-controlled
        # steps run from one edge to the next, not from update to update (Example 4's 450
        # updates held its steps to 0.1 ms)
        ends = np.cumsum([length for _, length, _ in HS.phases()])
        times = np.concatenate([[0.0], ends])
        times[-1] = sched.times[-1]  # the schedule's own end, to the last bit
        updates = set(range(1, times.size))
    bar = Progress(len(times) - 1, "heat", enabled=HS.progress)
    n_update = 0

    def be_solve(T, dt, load):
        # a backward Euler solve of any length on the stepper of the base step: the
        # solvers take the length as a scale on the mass (VHC / dt), no new factorization
        st = stepper_for(dt_base, coupling.vhc_e, coupling.tc_e, theta=1.0)
        return st.step(T[None, :], None if load is None else load[None, :],
                       vhc_scale=np.array([dt_base / dt]))[0]

    def laser_load(t0, t1):
        power = HS.mean_laser_power(t0, t1)
        return power * absorption_load(0.5 * (t0 + t1)) if power != 0 else None

    readings = []  # (t, sensors) after every accepted step of the error-controlled run
    n_substeps = [0]

    def on_substep(t0, t1, T_old, T_new):
        advance_state(t1 - t0, T_old, T_new)
        readings.append((t1, probes @ T_new if probes is not None else None))

    if adaptive:

        # the first step is MCmatlab's (the stability bound); none shorter than 1/64 of it
        dt_base = auto_dt(S.mesh_grid.spacing, *stability_props(0.0), 1.0, False) / 64

        def current():
            return stepper_for(dt_base, coupling.vhc_e, coupling.tc_e, theta=1.0)

        def apply_a(T):
            st = current()
            return st.K @ T + st.R @ T

        def operator():
            st = current()
            if getattr(st, "_mass_rows", None) is None:  # the lumped capacity, once
                st._mass_rows = (st._m_lumped if st._m_lumped is not None
                                 else np.asarray(st.M.sum(axis=1)).ravel())
            if st._m_lumped is not None:
                return st.g, lambda X: st._m_lumped * X, st._mass_rows, st.fixed
            return st.g, lambda X: st.M @ X, st._mass_rows, st.fixed

        st = current()
        A = _k_plus_r(st) if st._m_lumped is not None and HS.integrator != "implicit" else None
        integrator, rho = _integrator(HS, st, A, T0, be_solve, laser_load)
        if integrator == "rkc":
            rkc_version = [coupling.version]
            # the first step as the implicit one's: MCmatlab's stability bound
            controller = RKCSteps(A, st._m_lumped, st.g, st.fixed, laser_load,
                                  HS.rtol, dt_base * 64, spread=float(T0.max() - T0.min()),
                                  on_step=on_substep, h_min=dt_base,
                                  fixed_values=st.fixed_values, rho=rho)
        else:
            controller = ErrorControlledSteps(
                be_solve, apply_a, operator, laser_load, HS.rtol, dt_base, start_level=6,
                spread=float(T0.max() - T0.min()), on_step=on_substep)

    def step(T, t0, t1):
        if adaptive:  # the steps land on the sensor times within [t0, t1]
            marks = [t0]
            if HS.sensor_interval is not None:
                k = np.arange(math.floor(t0 / HS.sensor_interval + 1e-9) + 1,
                              math.ceil(t1 / HS.sensor_interval - 1e-9))
                marks.extend(k * HS.sensor_interval)
            if integrator == "rkc" and rkc_version[0] != coupling.version:  # re-binned media
                st = current()
                controller.set_operator(_k_plus_r(st), st._m_lumped, st.g)
                rkc_version[0] = coupling.version
            for a, b in zip(marks, [*marks[1:], t1], strict=True):
                T = controller.advance(T, a, b)
            return T
        n_sub = 1 if bound["dt"] is None else max(1, math.ceil((t1 - t0) / bound["dt"] - 1e-9))
        for i in range(n_sub):
            T = substep(T, t0 + (t1 - t0) * i / n_sub, t0 + (t1 - t0) * (i + 1) / n_sub)
        return T

    def substep(T, t0, t1):
        dt = t1 - t0
        dt_taken.add(round(dt, 15))
        n_substeps[0] += 1
        t_mid = t0 + 0.5 * dt  # sources and properties at mid-step
        if HS.VHC_t is not None or HS.TC_t is not None:
            vhc, tc = element_props(t_mid)
            if single_thermal:
                st = stepper_for(dt, vhc0, tc0)
                scales = dict(vhc_scale=np.array([vhc[0] / vhc0[0]]),
                              tc_scale=np.array([tc[0] / tc0[0]]))
            else:
                st, scales = stepper_for(dt, vhc, tc), {}
        else:
            st, scales = stepper_for(dt, coupling.vhc_e, coupling.tc_e), {}
        power = HS.mean_laser_power(t0, t1)  # the step's energy, pulse edges inside it too
        load = power * absorption_load(t_mid) if power != 0 else None  # W
        if scales:
            return st.step(T[None, :], None if load is None else load[None, :], **scales)[0]
        return st.step(T, load)

    def advance_state(dt, T_old, T_new):
        nonlocal T_vox_old
        if E_node is not None:
            node_damage.advance(Omega, T_old, T_new, dt)
            T_vox_new = S.to_voxels(T_new).ravel()
            voxel_damage.advance(Omega_vox, T_vox_old, T_vox_new, dt)
            T_vox_old = T_vox_new
        media_maxima.update(T_new, HS.max_media_temps)

    def on_step(k, t1, T_old, T_new):
        nonlocal n_update
        if not adaptive:  # the error-controlled steps did it step by step
            advance_state(t1 - times[k - 1], T_old, T_new)
        if snap_every and k % snap_every == 0:
            HS.snapshots.append((t_offset + t1, T_new.copy()))
        if k in updates:
            n_update += 1
            if monitor is not None:
                monitor.update(S.to_voxels(T_new), t_offset + t1)
            period = HS.media_prop_recalc_period
            if period and n_update % period == 0:
                T_vox, Om_vox = S.to_voxels(T_new), Omega_vox.reshape(M.shape)
                ran = coupling.update_optics(T_vox, Om_vox, HS.peak_power(t1))
                HS.mc_runs += ran
                if coupling.update_fluorescence(T_vox, Om_vox, ran) or ran:
                    set_absorption(heat_source(model))
                if coupling.update_thermal(T_vox, Om_vox) and dt_max is not None:
                    bound["dt"] = auto_dt(S.mesh_grid.spacing, *stability_props(t1),
                                          HS.theta, HS.large_time_steps)
        bar.update(k)

    T, sensor = fem.march(step, T0, times, probes, on_step)
    bar.close()
    if adaptive:
        times, sensor = sensor_series(times[0], T0, readings, probes, HS.sensor_interval)
        HS.steps_taken = (controller.n_accepted, controller.n_rejected)
        HS.integrator_used = integrator
        dt_taken.update(controller.lengths)
    else:
        HS.steps_taken = (n_substeps[0], 0)
        HS.integrator_used = "implicit"
    store_heat_results(HS, S, T, Omega, times + t_offset, sensor, chained, coupling)
    HS.Omega_voxels = Omega_vox.reshape(M.shape)
    HS.dt_used = np.unique(np.fromiter(dt_taken, float))
    if monitor is not None:
        monitor.finish(HS)
    for i, m in enumerate(media):
        if HS.max_media_temps[i] > BOILING_WARNING_C:
            warnings.warn(f"medium {m.name!r} gets hotter than {BOILING_WARNING_C:g} deg C "
                          f"({HS.max_media_temps[i]:.4g} deg C): water in it would boil, "
                          "which this heat model does not include", stacklevel=4)


#: products with A that one solve costs, for the direct solvers (fast diagonalization,
#: sparse LU): rough, they are cheap enough that RKC wins only on phases near its
#: stability bound, where any of these figures gives the same choice
_DIRECT_SOLVE_PRODUCTS = 8.0
#: products with A that one application of PCG's layer-mean preconditioner costs
#: (fem.stepper.JACOBI_BELOW's measurements: 2.5-4 Jacobi iterations)
_LAYERED_PRECONDITIONER_PRODUCTS = 3.0


def _k_plus_r(st):
    """The stepper's ``K + R`` (W/K): ``K`` itself where no face is convective (the same
    matrix, without adding an empty one to a copy of it)."""
    return st.K if st.R.nnz == 0 else st.K + st.R


def _integrator(HS, st, A, T0, be_solve, laser_load) -> tuple[str, float | None]:
    """``"rkc"`` or ``"implicit"`` for the error-controlled steps (``HS.integrator``), and
    the spectral radius of ``m^-1 A`` (``A = K + R`` of the stepper ``st``) where it was
    computed (None elsewhere), so that RKC does not compute it again.

    RKC needs the diagonal (lumped) heat capacity; ``"auto"`` also keeps the implicit path
    with ``HS.use_gpu`` (its solves on the device). The implicit step's cost, for
    :func:`.rkc.choose_integrator`: two solves and two products (K and R); a PCG solve's
    iterations are those of one trial solve at the first phase's scale of steps.
    """
    if HS.integrator == "implicit" or st._m_lumped is None:
        return "implicit", None
    if HS.integrator == "rkc":
        return "rkc", None
    if HS.use_gpu:
        return "implicit", None
    phases = [length for _, length, _ in HS.phases()]
    rho = spectral_radius(A, st._m_lumped, st.free)
    h = phases[0] / 8
    if st.method == "pcg":
        # RKC cheaper than an implicit step could be (each solve a single product): no
        # trial solve needed to know the choice
        if choose_integrator(rho, phases, 2.0 * 1.0 + 2.0) == "rkc":
            return "rkc", rho
        be_solve(T0, h, laser_load(0.0, h))
        pcg = st._solver
        per = 1.0 if pcg.last_jacobi else 1.0 + _LAYERED_PRECONDITIONER_PRODUCTS
        solve = pcg.last_iterations * per + 1.0
    else:
        solve = _DIRECT_SOLVE_PRODUCTS
    return choose_integrator(rho, phases, 2.0 * solve + 2.0), rho


def _monitor(model, M, S, chained, T0, t_offset):
    """The live slice figure / movie recorder, or None when neither is asked for."""
    HS = model.HS
    if not (HS.live_plot or HS.make_movie):
        return None
    from ..plotting.movie import TemperatureMonitor

    mon = TemperatureMonitor(model, M, show=HS.live_plot, record=HS.make_movie)
    if HS.make_movie and not chained:
        mon.geometry_frame()
    mon.update(S.to_voxels(T0), t_offset, record=HS.make_movie and not chained)
    return mon


def simulate_heat_distribution(model) -> None:
    """Run ``model.HS`` on ``model.G`` with the absorption of ``model.MC`` (see
    :mod:`mcmatlab_py.heat`)."""
    run_heat(model)
