"""Closed-loop lunar-return skip entry with the combined guidance of seed 003.

One dispersed trajectory per call. The truth integrates the Cartesian 3-DOF dynamics (RK4,
``dt_s``) with the dispersed vehicle and atmosphere and the bank angle actually flown (finite
roll rate and acceleration); guidance runs every control step (1 s), the predictor-corrector
every ``pc_every`` control steps. Navigation is perfect (the dispersions are in the entry state,
the aerodynamics and the atmosphere); the accelerometers measure the actual drag and lift,
from which the guidance filters the ratios of actual to modelled drag and lift that its
predictor uses. The chute-deploy crossing at 10 km is located inside the step by cubic
Hermite interpolation.

The simulator holds only the truth (dynamics, actuator, loads and heating, chute crossing), the
accelerometer measurement and the outcome. :func:`simulate` is the shared
:func:`~gnc_jax.systems.loop.closed_loop` of its ``start``, ``run`` and ``finish``, whose
carry is a :class:`~gnc_jax.systems.loop.LoopState` of the typed parts of
:mod:`gnc_jax.systems.capsule.state`. The guidance is a member of the
:class:`~gnc_jax.guidance.entry.base.AbstractEntryGuidance` family, called with
``init(nav, ctx)`` and ``step(state, nav, t, ctx)`` (``nav`` an
:class:`~gnc_jax.guidance.entry.base.EntryNav`, ``ctx`` the
:class:`~gnc_jax.guidance.entry.base.EntryGuidanceContext` of :func:`guidance_context`).
"""

import dataclasses

import equinox as eqx
import equinox.internal as eqxi
import jax
import jax.numpy as jnp

from ..._numerics import loop_shape
from ..._random import stream_normal, stream_uniform
from ..._status import Status
from ..._types import PRNGKeyArray, Scalar, Vector3
from ...dynamics.atmosphere import Atmosphere
from ...dynamics.entry import (
    G0,
    BankActuator,
    BankActuatorState,
    EarthModel,
    EntryArgs,
    EntryConditions,
    EntryState,
    EntryStateXYZ,
    EntryVehicle,
    entry_acceleration_xyz,
    entry_state_from_conditions,
    from_xyz,
    sutton_graves_heat_rate,
    to_xyz,
)
from ...geometry.sphere import along_cross_track, destination, to_earth_fixed, unit
from ...guidance.entry.base import (
    AbstractEntryGuidance,
    EntryGuidanceContext,
    EntryModel,
    EntryNav,
    altitude_speed_hdot,
    drag_and_lift,
    flight_variables,
    ground_range_m,
    hermite_crossing,
    hermite_state,
)
from ...integrate import rk4_step
from ...root_finding import RootStatus
from ..loop import LoopState, closed_loop, flatten_trace, with_status
from .dispersions import CapsuleDispersions
from .params import CapsuleParams, capsule_params, loop_counts
from .state import CapsuleDraws, CapsuleOutcome, CapsuleTally, CapsuleTruth, Trace


class CapsuleSimulation(eqx.Module):
    """Everything a capsule run needs except the guidance law and the key."""

    entry: EntryConditions  # nominal entry interface
    vehicle: EntryVehicle  # nominal vehicle (the guidance's model)
    earth: EarthModel
    atmosphere: Atmosphere  # nominal atmosphere (the guidance's model)
    actuator: BankActuator
    dispersions: CapsuleDispersions
    target_fixed: Vector3  # unit vector, Earth-fixed
    ratio_filter_gain: Scalar  # per control step, for the measured drag/lift ratios
    hold_bank_rad: Scalar  # attitude held before guidance starts
    chute_altitude_m: Scalar  # the chute deploys (the flight ends) below it
    miss_limit_m: Scalar  # delivery tolerance: a larger downrange or crossrange miss reads missed
    load_limit_g: Scalar  # a larger sensed peak load reads overload
    dt_s: float = eqx.field(static=True, default=0.5)
    substeps: int = eqx.field(static=True, default=2)  # truth steps per control step
    n_control: int = eqx.field(static=True, default=2400)
    pc_every: int = eqx.field(static=True, default=4)
    # "lax": while_loops (evaluation, forward mode); "checkpointed" (:func:`reverse_mode`):
    # the flight's cycles as equinox's checkpointed while_loop, the corrector's "lax" loops
    # differentiated at its solutions; "fixed": the same loops as scans of their bounds,
    # masked (no loop predicate)
    loop_kind: str = eqx.field(static=True, default="lax")
    # with "checkpointed": whether the corrector's solutions carry a derivative (False: what
    # is differentiated acts only after the corrector's last cycle, see reverse_mode)
    corrector_derivative: bool = eqx.field(static=True, default=True)

    @property
    def control_dt(self) -> float:
        return self.dt_s * self.substeps


# Streams of a capsule run: the nine entry, vehicle and atmosphere normals; the mass draw.
_ENTRY, _MASS = range(2)


def dispersed_entry(sim: CapsuleSimulation, key):
    """Dispersed entry state, truth vehicle and atmosphere, and the standard-normal draws."""
    d = sim.dispersions
    z = stream_normal(key, _ENTRY, (9,))
    u = stream_uniform(key, _MASS, (), minval=-1.0, maxval=1.0)
    e = sim.entry
    r_e = sim.earth.equatorial_radius_m
    start = jnp.array(
        [
            jnp.cos(e.latitude) * jnp.cos(e.longitude),
            jnp.cos(e.latitude) * jnp.sin(e.longitude),
            jnp.sin(e.latitude),
        ]
    )
    p = destination(start, e.azimuth, d.downrange_m * z[3] / r_e)
    p = destination(p, e.azimuth + jnp.pi / 2, d.crossrange_m * z[5] / r_e)
    lat, lon = jnp.arcsin(p[2]), jnp.arctan2(p[1], p[0])
    cond = EntryConditions(
        altitude_m=e.altitude_m + d.altitude_m * z[4],
        speed_mps=e.speed_mps + d.speed_mps * z[0],
        flight_path_angle=e.flight_path_angle + d.fpa_rad * z[1],
        azimuth=e.azimuth + d.heading_rad * z[2],
        longitude=lon,
        latitude=lat,
    )
    v = sim.vehicle
    truth_vehicle = eqx.tree_at(
        lambda x: (x.mass_kg, x.lift_scale, x.drag_scale),
        v,
        (
            v.mass_kg * (1.0 + d.mass_frac_half_width * u),
            v.lift_scale * (1.0 + d.lift_frac * z[6]),
            v.drag_scale * (1.0 + d.drag_frac * z[7]),
        ),
    )
    truth_atm = eqx.tree_at(
        lambda a: a.density_scale,
        sim.atmosphere,
        sim.atmosphere.density_scale * (1.0 + d.density_frac * z[8]),
    )
    draws = jnp.concatenate([z, u[None]])
    return entry_state_from_conditions(cond, sim.earth), truth_vehicle, truth_atm, draws


def guidance_context(sim: CapsuleSimulation) -> EntryGuidanceContext:
    """The on-board mission data of ``sim``: nominal model, target, hold bank, filter, period."""
    return EntryGuidanceContext(
        model=EntryModel(sim.vehicle, sim.earth, sim.atmosphere),
        target_fixed=sim.target_fixed,
        hold_bank_rad=sim.hold_bank_rad,
        ratio_filter_gain=sim.ratio_filter_gain,
        pc_every=sim.pc_every,
        loop_kind=sim.loop_kind if sim.corrector_derivative else "held",
    )


def _truth_substep(
    sim: CapsuleSimulation,
    args: EntryArgs,
    command,
    f: tuple[CapsuleTruth, BankActuatorState, CapsuleTally],
) -> tuple[CapsuleTruth, BankActuatorState, CapsuleTally]:
    """Bank actuator and one RK4 step of the truth (``args`` without the bank), with the
    loads and heating at the end of the step, on ``(truth, actuator, tally)``. A finished
    flight (``done``) keeps its state and time; the step that crosses the chute altitude is
    recorded for :func:`_chute_point`.

    Four density lookups per step: the first stage reuses the density carried from the end
    of the previous step, whose lookup also gives the heat rate and the load."""
    truth, act, tally = f
    dt = sim.dt_s
    earth, vehicle, atmosphere = args.earth, args.vehicle, args.atmosphere
    act = sim.actuator.step(act, command, dt)
    cos_b, sin_b = jnp.cos(act.bank), jnp.sin(act.bank)  # constant over the step

    def field(t, y, density=None):
        accel, _ = entry_acceleration_xyz(
            y, vehicle, earth, atmosphere, cos_b, sin_b, density=density
        )
        return EntryStateXYZ(y.v, accel)

    y1 = rk4_step(field, truth.t, truth.y, dt, k1=field(truth.t, truth.y, truth.density))
    alt1, speed1, _ = altitude_speed_hdot(y1, earth)
    rho1 = atmosphere.density(alt1)
    q_dot = sutton_graves_heat_rate(rho1, speed1, vehicle.nose_radius_m)
    c_r = jnp.sqrt(vehicle.c_l**2 + vehicle.c_d**2)
    ng1 = 0.5 * rho1 * speed1**2 * vehicle.reference_area_m2 * c_r / (vehicle.mass_kg * G0)
    done = truth.done
    cross = ~done & (alt1 < sim.chute_altitude_m)
    keep = ~done

    def unless_done(old, new):
        return jax.tree_util.tree_map(lambda a, b: jnp.where(done, a, b), old, new)

    def if_cross(new, old):
        return jax.tree_util.tree_map(lambda a, b: jnp.where(cross, a, b), new, old)

    truth_1 = CapsuleTruth(
        y=unless_done(truth.y, y1),
        density=jnp.where(done, truth.density, rho1),
        t=truth.t + jnp.where(done, 0.0, dt),
        done=done | cross,
    )
    tally_1 = CapsuleTally(
        cross_y=if_cross(truth.y, tally.cross_y),
        cross_t=jnp.where(cross, truth.t, tally.cross_t),
        cross_bank=jnp.where(cross, act.bank, tally.cross_bank),
        heat_load=tally.heat_load + keep * q_dot * dt,
        heat_peak=jnp.maximum(tally.heat_peak, keep * q_dot),
        load_peak=jnp.maximum(tally.load_peak, keep * ng1),
    )
    return truth_1, act, tally_1


def _chute_point(
    sim: CapsuleSimulation, args: EntryArgs, f: CapsuleTruth, tally: CapsuleTally, y0: EntryState
):
    """State and time at the chute altitude: the crossing inside the step that crossed it, by
    cubic Hermite interpolation (``y0`` and 0 for a flight that never crossed)."""
    dt, earth = sim.dt_s, args.earth
    bank = tally.cross_bank

    def accel(y):
        a, _ = entry_acceleration_xyz(
            y, args.vehicle, earth, args.atmosphere, jnp.cos(bank), jnp.sin(bank)
        )
        return jnp.stack(a)

    alt0, _, hdot0 = altitude_speed_hdot(tally.cross_y, earth)
    alt1, _, hdot1 = altitude_speed_hdot(f.y, earth)
    sfrac = hermite_crossing(alt0, hdot0, alt1, hdot1, dt, sim.chute_altitude_m)
    y_a, y_b = from_xyz(tally.cross_y), from_xyz(f.y)
    now = hermite_state(y_a, accel(tally.cross_y), y_b, accel(f.y), dt, sfrac)
    chute = jax.tree_util.tree_map(lambda a, b: jnp.where(f.done, a, b), now, y0)
    return chute, jnp.where(f.done, tally.cross_t + sfrac * dt, 0.0)


def _trace(y0: EntryState, c: LoopState, nav: EntryNav, command, g, earth) -> Trace:
    """This control step's trace: the state at its start, the command and the new law state."""
    y, t = nav.y, c.truth.t
    fv = flight_variables(y, earth)
    return Trace(
        t_s=t,
        altitude_m=fv.altitude_m,
        speed_mps=fv.speed_mps,
        range_flown_m=ground_range_m(y0.r, 0.0, y.r, t, earth),
        bank_cmd_rad=command,
        bank_rad=c.actuator.bank,
        load_g=jnp.sqrt(nav.drag_mps2**2 + nav.lift_mps2**2) / G0,
        phase=g.phase,
        sigma_0_rad=g.sigma_0,
        predicted_miss_m=g.log.step_miss_m,
        corrector_evals=g.log.step_predictions,
        r_m=y.r,
        v_mps=y.v,
        pulled_up=g.pulled_up,
        drag_ratio=g.drag_ratio,
        lift_ratio=g.lift_ratio,
    )


def _start(sim: CapsuleSimulation, law: AbstractEntryGuidance, key: PRNGKeyArray):
    """The run's draws and its initial :data:`CapsuleLoopState`: the dispersed entry, the
    actuator holding ``hold_bank_rad``, the law's ``init`` from the first measurement."""
    y0, vehicle, atmosphere, dispersion = dispersed_entry(sim, key)
    draws = CapsuleDraws(y0, EntryArgs(vehicle, sim.earth, atmosphere, jnp.zeros(())), dispersion)
    truth, actuator, tally = initial_flight(sim, y0, atmosphere)
    law_state = law.init(_measure(sim, draws, y0), guidance_context(sim))
    return LoopState(truth, (), law_state, actuator, tally), draws


def initial_flight(sim: CapsuleSimulation, y0: EntryState, atmosphere: Atmosphere):
    """``(truth, actuator, tally)`` at the entry interface ``y0`` (atmosphere: the truth's)."""
    z = jnp.zeros(())
    y0_xyz = to_xyz(y0)
    truth = CapsuleTruth(
        y=y0_xyz,
        density=atmosphere.density(flight_variables(y0, sim.earth).altitude_m),
        t=z,
        done=jnp.asarray(False),
    )
    tally = CapsuleTally(
        cross_y=y0_xyz, cross_t=z, cross_bank=z, heat_load=z, heat_peak=z, load_peak=z
    )
    return truth, sim.actuator.init(sim.hold_bank_rad), tally


def _measure(sim: CapsuleSimulation, draws: CapsuleDraws, y: EntryState) -> EntryNav:
    """The navigated (true) state and the accelerometer-measured drag and lift at ``y``."""
    return EntryNav(y, *drag_and_lift(y, draws.truth.vehicle, sim.earth, draws.truth.atmosphere))


def _run(sim: CapsuleSimulation, law: AbstractEntryGuidance, key, draws: CapsuleDraws, c, record):
    """The control steps, in guidance cycles of ``pc_every`` (see :func:`simulate`)."""
    ctx = guidance_context(sim)

    def control_step(c: LoopState, j):
        nav = _measure(sim, draws, from_xyz(c.truth.y))
        step_ctx = eqx.tree_at(lambda x: x.cycle_start, ctx, j == 0, is_leaf=lambda x: x is None)
        command, g = law.step(c.law, nav, c.truth.t, step_ctx)
        (truth, actuator, tally), _ = jax.lax.scan(
            lambda f, _: (_truth_substep(sim, draws.truth, command, f), None),
            (c.truth, c.actuator, c.tally),
            None,
            length=sim.substeps,
            unroll=loop_shape().unroll,
        )
        rec = _trace(draws.y0, c, nav, command, g, sim.earth) if record else None
        return LoopState(truth, c.estimate, g, actuator, tally), rec

    def cycle(c: LoopState, n=sim.pc_every):
        if loop_shape().unroll < n:
            return jax.lax.scan(control_step, c, jnp.arange(n), unroll=loop_shape().unroll)
        # Unrolled whole (a GPU's layout): the step index is a Python int, so which step runs
        # the corrector is decided at trace time; a scan would leave a branch taken on the
        # device, with a trip to the host, and a loop whose carry is copied, at every step.
        recs = []
        for j in range(n):
            c, rec = control_step(c, j)
            recs.append(rec)
        return c, (jax.tree_util.tree_map(lambda *x: jnp.stack(x), *recs) if record else None)

    n_cycles, rest = divmod(sim.n_control, sim.pc_every)
    if record:
        c, rec = jax.lax.scan(lambda c, _: cycle(c), c, None, length=n_cycles)
        rec = flatten_trace(rec)
    else:
        c, _ = _while(
            sim,
            lambda ck: (ck[1] < n_cycles) & ~ck[0].truth.done,
            lambda ck: (cycle(ck[0])[0], ck[1] + 1),
            (c, jnp.asarray(0, jnp.int32)),
            n_cycles,
        )
        rec = None
    if rest:  # the control steps of a last, partial cycle (a finished flight is frozen)
        c, tail = cycle(c, rest)
        if record:
            rec = jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a, b]), rec, tail)
    return c, rec


# Cycle carries reverse mode keeps per flight (loop_kind "checkpointed"): every cycle of the
# paper's 2400 s (600 cycles, 0.2 kB per run each), so that none is recomputed twice (32 kept:
# 25-30 % more reverse-mode time at 64 runs); a longer flight recomputes some
FLIGHT_CHECKPOINTS = 1024


def _while(sim: CapsuleSimulation, cond, body, init, most: int):
    if sim.loop_kind == "fixed":  # every trip runs, a finished run's carry held

        def trip(x, _):
            go = cond(x)
            new = body(x)
            return jax.tree_util.tree_map(lambda a, b: jnp.where(go, a, b), new, x), None

        return jax.lax.scan(trip, init, None, length=most)[0]
    if sim.loop_kind == "checkpointed":
        return eqxi.while_loop(
            cond,
            body,
            init,
            max_steps=most,
            kind="checkpointed",
            checkpoints=min(most, FLIGHT_CHECKPOINTS),
        )
    return jax.lax.while_loop(cond, body, init)


def reverse_mode(sim: CapsuleSimulation, corrector_derivative: bool = True) -> CapsuleSimulation:
    """``sim`` flown with equinox's checkpointed ``while_loop`` for the cycles of the flight,
    its corrector solved by the ``lax`` loops and differentiated at each solution by the
    implicit function theorem (:func:`~gnc_jax.guidance.entry.corrector.implicit_correct`):
    the same trip counts and arithmetic, so the same outcomes, reverse-mode differentiable
    with memory bounded by the checkpoints (forward mode needs ``"lax"``).

    ``corrector_derivative=False``: the solutions pass no derivative (``loop_kind = "held"``
    of the corrector), exact when everything differentiated acts only after the corrector's
    last cycle (the tracking gains: the tracking phase, which no run leaves, follows the
    first entry, the only phase that corrects); the reverse pass then skips the prediction
    it would differentiate at each solution, about 40 % of its time."""
    return dataclasses.replace(
        sim, loop_kind="checkpointed", corrector_derivative=corrector_derivative
    )


def _finish(sim: CapsuleSimulation, law, key, draws: CapsuleDraws, c: LoopState):
    """The chute point (:func:`_chute_point`) and the outcome (:func:`_outcome`)."""
    chute, t_chute = _chute_point(sim, draws.truth, c.truth, c.tally, draws.y0)
    return _outcome(sim, c, chute, t_chute, draws.dispersion)


_closed_loop = closed_loop(_start, _run, _finish)


def simulate(sim: CapsuleSimulation, law: AbstractEntryGuidance, key: PRNGKeyArray, record=False):
    """One closed-loop skip entry. Returns ``(CapsuleOutcome, Trace | None)``.

    Every control step the accelerometers measure the drag and lift of the dispersed vehicle,
    the law commands a bank from them and the navigated (true) state, and the truth flies
    ``substeps`` RK4 steps with the bank the actuator achieves.

    The control steps run in guidance cycles of ``pc_every`` steps whose first runs the
    corrector: the simulator keeps that clock (``ctx.cycle_start``), the same for every run, so
    that under ``vmap`` the corrector is a ``lax.cond`` on it. Without ``record`` the cycles
    are a ``while_loop`` that stops once the flight is down (under ``vmap``: once every run of
    the batch is; a finished flight is frozen either way, so the outcome is the same), with
    ``record`` a ``scan`` over the whole ``max_time_s`` for fixed-length traces."""
    return _closed_loop(sim, law, key, record)


def _outcome(
    sim: CapsuleSimulation, c: LoopState, chute: EntryState, t_chute, draws
) -> CapsuleOutcome:
    """Chute-point errors against the nominal entry -> target track, loads, the law's log.

    Status, by precedence: ``skip_out`` (climbed above the law's skip-out altitude),
    ``time_out`` (no chute crossing within ``max_time_s``), ``overload`` (a sensed peak load
    beyond ``load_limit_g``), ``missed`` (a downrange or
    crossrange miss beyond ``miss_limit_m``, the delivery tolerance, whether its corrector
    converged or not; a dispersed vehicle that cannot reach the target ends here), then
    ``no_convergence`` (the last corrector cycle failed, the chute point within the
    tolerance), else ``ok``."""
    earth, f, g = sim.earth, c.tally, c.law
    log = g.log
    nominal_start = unit(entry_state_from_conditions(sim.entry, earth).r)
    u_chute = unit(to_earth_fixed(chute.r, t_chute, earth.rotation_rate))
    along, cross = along_cross_track(u_chute, nominal_start, sim.target_fixed)
    r_e_km = earth.equatorial_radius_m / 1e3
    outcome = CapsuleOutcome(
        status=jnp.zeros((), jnp.int32),
        downrange_err_km=along * r_e_km,
        crossrange_err_km=cross * r_e_km,
        load_peak_g=f.load_peak,
        heat_rate_peak_kw_m2=f.heat_peak / 1e3,
        heat_load_mj_m2=f.heat_load / 1e6,
        skip_apogee_km=log.skip_apogee_m / 1e3,
        switch_speed_mps=log.switch[0],
        switch_altitude_km=log.switch[1] / 1e3,
        switch_hdot_mps=log.switch[2],
        switch_range_km=log.switch[3] / 1e3,
        bank_offset_deg=jnp.degrees(g.bank_offset),
        predictions=log.predictions,
        cycle_predictions_max=log.cycle_predictions_max,
        pc_cycles=log.pc_cycles,
        corrector_failures=log.corrector_failures,
        reversals=log.reversals,
        predictor_steps=log.predictor_steps,
        t_guidance_s=log.t_guidance_s,
        t_kepler_s=log.t_kepler_s,
        t_switch_s=log.t_switch_s,
        t_chute_s=t_chute,
        dispersion=draws,
    )
    return with_status(
        outcome,
        (
            (log.skipped_out, Status.skip_out),
            (~c.truth.done, Status.time_out),
            (f.load_peak > sim.load_limit_g, Status.overload),
            (
                jnp.maximum(jnp.abs(along), jnp.abs(cross)) * r_e_km * 1e3 > sim.miss_limit_m,
                Status.missed,
            ),
            (g.last_status != RootStatus.ok, Status.no_convergence),
        ),
    )


def nominal_models(p: CapsuleParams):
    """Earth, nominal vehicle and atmosphere, and the nominal entry interface of the
    parameters ``p`` (the envelope's open-loop flights use the same models)."""
    return EarthModel(), p.vehicle.entry_vehicle(), p.atmosphere.atmosphere(), p.entry.conditions()


def target_direction(p: CapsuleParams, earth: EarthModel, entry: EntryConditions) -> Vector3:
    """The target (unit vector, Earth-fixed): ``entry.range_km`` along the entry azimuth."""
    y0 = entry_state_from_conditions(entry, earth)
    return destination(
        unit(y0.r), entry.azimuth, p.entry.range_m / float(earth.equatorial_radius_m)
    )


def build(scenario) -> CapsuleSimulation:
    """Simulation data of a validated capsule scenario (SI units); the law (with the reference
    designed for this vehicle, entry and target: :mod:`gnc_jax.systems.capsule.reference`) is
    built by the system from ``[guidance.<law>]``."""
    return build_from_config(scenario.config)


def build_from_config(cfg: dict) -> CapsuleSimulation:
    """:func:`build` from a validated configuration (no guidance law, no reference design)."""
    p = capsule_params(cfg)
    earth, vehicle, atmosphere, entry = nominal_models(p)
    counts = loop_counts(p.simulation, p.guidance)
    return CapsuleSimulation(
        entry=entry,
        vehicle=vehicle,
        earth=earth,
        atmosphere=atmosphere,
        actuator=p.actuator.bank_actuator(),
        dispersions=p.dispersions,
        target_fixed=target_direction(p, earth, entry),
        ratio_filter_gain=p.guidance.ratio_filter_gain,
        hold_bank_rad=p.guidance.hold_bank_rad,
        chute_altitude_m=p.entry.chute_altitude_m,
        miss_limit_m=p.simulation.miss_limit_m,
        load_limit_g=p.simulation.load_limit_g,
        dt_s=counts.dt_s,
        substeps=counts.substeps,
        n_control=counts.n_control,
        pc_every=counts.pc_every,
    )
