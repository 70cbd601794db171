"""Closed-loop lunar-return skip entry with the combined guidance of seed 003 (SPEC §8).

One dispersed trajectory per call. The truth integrates the Cartesian 3-DOF dynamics (RK4,
``dt_s``) with the dispersed vehicle and atmosphere and the bank angle actually flown (finite
roll rate and acceleration); guidance runs every control step (1 s), the predictor-corrector
every ``pc_every`` control steps. Navigation is perfect (the dispersions are in the entry state,
the aerodynamics and the atmosphere); the accelerometers measure the actual drag and lift,
from which the guidance filters the ratios of actual to modelled drag and lift that its
predictor uses. The chute-deploy crossing at 10 km is located inside the step by cubic
Hermite interpolation.
"""

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from .._status import Status, all_finite
from .._types import Array, Float, PRNGKeyArray, Scalar, Vector3
from ..dynamics.atmosphere import Atmosphere
from ..dynamics.entry import (
    G0,
    BankActuator,
    BankActuatorState,
    EarthModel,
    EntryArgs,
    EntryConditions,
    EntryState,
    EntryVehicle,
    aerodynamic_acceleration,
    entry_state_from_conditions,
    entry_vector_field,
    sensed_load_g,
    sutton_graves_heat_rate,
)
from ..geometry.sphere import (
    along_cross_track,
    along_track_to_go,
    crossrange_to_target,
    destination,
    range_rate_to_target,
    to_earth_fixed,
    to_inertial,
    unit,
)
from ..guidance.entry_common import (
    EntryModel,
    flight_variables,
    ground_range_m,
    hermite_crossing,
    hermite_state,
)
from ..guidance.skip_entry import SkipEntryGuidance
from ..integrate import rk4_step
from ..root_finding import RegulaFalsiResult, RootStatus


class CapsuleDispersions(eqx.Module):
    """1-sigma dispersions (seed 003 Table 2 gives 3-sigma values; mass is uniform ±)."""

    speed_mps: Scalar = 100.0 / 3
    fpa_rad: Scalar = 0.2 / 3 * jnp.pi / 180
    heading_rad: Scalar = 0.5 / 3 * jnp.pi / 180
    downrange_m: Scalar = 100e3 / 3
    altitude_m: Scalar = 1e3 / 3
    crossrange_m: Scalar = 100e3 / 3
    lift_frac: Scalar = 0.2 / 3
    drag_frac: Scalar = 0.2 / 3
    density_frac: Scalar = 0.3 / 3
    mass_frac_half_width: Scalar = 0.05


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
    dt_s: float = eqx.field(static=True, default=0.5)
    substeps: int = eqx.field(static=True, default=2)  # truth steps per control step
    n_control: int = eqx.field(static=True, default=2400)
    pc_every: int = eqx.field(static=True, default=4)

    @property
    def control_dt(self) -> float:
        return self.dt_s * self.substeps


class CapsuleOutcome(NamedTuple):
    status: Array
    downrange_err_km: Scalar  # > 0 overshoot
    crossrange_err_km: Scalar  # > 0 left of the entry -> target track
    load_peak_g: Scalar
    heat_rate_peak_kw_m2: Scalar
    heat_load_mj_m2: Scalar
    skip_apogee_km: Scalar
    switch_speed_mps: Scalar
    switch_altitude_km: Scalar
    switch_hdot_mps: Scalar
    switch_range_km: Scalar  # ground range flown from the entry point to the switch point
    bank_offset_deg: Scalar  # switch-point compensation (eqs. 16-17)
    predictions: Array  # predictions an early-exit corrector would have made (whole flight)
    cycle_predictions_max: Array
    pc_cycles: Array
    corrector_failures: Array
    reversals: Array
    predictor_steps: Scalar  # RK4 steps of all predictions (4 right-hand sides each)
    t_guidance_s: Scalar
    t_kepler_s: Scalar
    t_switch_s: Scalar
    t_chute_s: Scalar
    dispersion: Float[Array, "10"]  # the draws, in the order of CapsuleDispersions


class Trace(NamedTuple):
    t_s: Scalar
    altitude_m: Scalar
    speed_mps: Scalar
    range_flown_m: Scalar
    bank_cmd_rad: Scalar
    bank_rad: Scalar
    load_g: Scalar
    phase: Array
    sigma_0_rad: Scalar  # corrector solution
    predicted_miss_m: Scalar  # corrector residual at that solution (0 outside a PC cycle)
    corrector_evals: Array  # predictions an early-exit corrector would make this step
    r_m: Vector3  # ECI state
    v_mps: Vector3
    pulled_up: Array
    drag_ratio: Scalar
    lift_ratio: Scalar


class _Guidance(NamedTuple):
    phase: Array  # 0 hold, 1 predictor-corrector, 2 Kepler, 3 tracking, 4 chute
    pulled_up: Array
    sigma_0: Scalar
    sign: Scalar
    bank_mag: Scalar
    bank_offset: Scalar
    drag_ratio: Scalar
    lift_ratio: Scalar
    last_status: Array
    predicted_crossrange: Scalar  # at the switch point, from the last corrector solution


class _Carry(NamedTuple):
    y: EntryState
    t: Scalar
    act: BankActuatorState
    g: _Guidance
    done: Array
    chute: EntryState
    t_chute: Scalar
    load_peak: Scalar
    heat_peak: Scalar
    heat_load: Scalar
    apogee: Scalar
    skipped_out: Array
    switch: Float[Array, "4"]  # speed, altitude, hdot, range flown
    t_guidance: Scalar
    t_kepler: Scalar
    t_switch: Scalar
    predictions: Array
    cycle_max: Array
    pc_cycles: Array
    failures: Array
    reversals: Array
    predictor_steps: Scalar


def dispersed_entry(sim: CapsuleSimulation, key):
    """Dispersed entry state, truth vehicle and atmosphere, and the standard-normal draws."""
    d = sim.dispersions
    z = jax.random.normal(jax.random.fold_in(key, 0), (9,))
    u = jax.random.uniform(jax.random.fold_in(key, 1), (), minval=-1.0, maxval=1.0)
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


def simulate(sim: CapsuleSimulation, law: SkipEntryGuidance, key: PRNGKeyArray, record=False):
    """One closed-loop skip entry. Returns ``(CapsuleOutcome, Trace | None)``."""
    earth = sim.earth
    y0, vehicle, atmosphere, draws = dispersed_entry(sim, key)
    nominal_start = unit(entry_state_from_conditions(sim.entry, earth).r)
    truth_args = lambda bank: EntryArgs(vehicle, earth, atmosphere, bank)  # noqa: E731
    c_l0, c_d0 = sim.vehicle.c_l, sim.vehicle.c_d

    def measure(y, g: _Guidance):
        """Perfect navigation plus accelerometers: flight variables, loads, ratios."""
        fv = flight_variables(y, earth)
        a_true = aerodynamic_acceleration(y.r, y.v, 0.0, vehicle, earth, atmosphere)
        v_rel = y.v - jnp.cross(earth.angular_velocity(), y.r)
        drag = -jnp.dot(a_true, unit(v_rel))
        lift = jnp.linalg.norm(a_true + drag * unit(v_rel))
        model = EntryModel(sim.vehicle, earth, sim.atmosphere)
        a_model = aerodynamic_acceleration(y.r, y.v, 0.0, sim.vehicle, earth, sim.atmosphere)
        drag_model = -jnp.dot(a_model, unit(v_rel))
        lift_model = jnp.linalg.norm(a_model + drag_model * unit(v_rel))
        ng = jnp.sqrt(drag**2 + lift**2) / G0
        sensing = ng > 0.05
        k = sim.ratio_filter_gain
        dr = jnp.where(
            sensing,
            g.drag_ratio + k * (drag / jnp.maximum(drag_model, 1e-12) - g.drag_ratio),
            g.drag_ratio,
        )
        lr = jnp.where(
            sensing,
            g.lift_ratio + k * (lift / jnp.maximum(lift_model, 1e-12) - g.lift_ratio),
            g.lift_ratio,
        )
        return fv, ng, drag / G0, lift / jnp.maximum(drag, 1e-12), dr, lr, model

    def control_step(c: _Carry, step):
        g = c.g
        fv, ng, ngx, ld, dr, lr, model = measure(c.y, g)
        model = EntryModel(model.vehicle, earth, model.atmosphere, dr, lr)
        target = to_inertial(sim.target_fixed, c.t, earth.rotation_rate)
        v_rel = c.y.v - jnp.cross(earth.angular_velocity(), c.y.r)
        to_go = earth.equatorial_radius_m * along_track_to_go(c.y.r, v_rel, target)
        live = ~c.done

        # phase logic (hard)
        phase = g.phase
        start = live & (phase == 0) & (ng > law.ng0_g)
        phase = jnp.where(start, 1, phase)
        pulled = g.pulled_up | ((phase >= 1) & (fv.hdot_mps > 0.0))
        to_kepler = live & (phase == 1) & pulled & (fv.hdot_mps > 0.0) & (ng < law.kepler_load_g)
        phase = jnp.where(to_kepler, 2, phase)
        to_track = (
            live
            & ((phase == 1) | (phase == 2))
            & pulled
            & (fv.hdot_mps < 0.0)
            & (ng >= law.kepler_load_g)
        )
        bank_offset = jnp.where(to_track, law.switch_compensation(fv, to_go), g.bank_offset)
        phase = jnp.where(to_track, 3, phase)

        # predictor-corrector every pc_every steps, only runs in phase 1 do any work
        def pc(_):
            return law.correct(
                c.y, c.t, pulled, g.sigma_0, model, sim.target_fixed, live & (phase == 1)
            )

        def no_pc(_):
            z = jnp.zeros((), int)
            return RegulaFalsiResult(
                g.sigma_0,
                jnp.zeros(()),
                jnp.asarray(True),
                z,
                z,
                z,
                g.predicted_crossrange,
                jnp.zeros(()),
            )

        is_pc_step = (step % sim.pc_every) == 0
        res = jax.lax.cond(is_pc_step, pc, no_pc, None)
        did_pc = is_pc_step & live & (phase == 1)
        sigma_0 = jnp.where(did_pc, res.x, g.sigma_0)
        last_status = jnp.where(did_pc, res.status, g.last_status)
        chi_switch = jnp.where(did_pc, res.aux, g.predicted_crossrange)

        # bank magnitude by phase
        pc_mag = law.profile(sigma_0, fv.speed_mps, fv.speed_mps)
        range_rate = earth.equatorial_radius_m * range_rate_to_target(c.y.r, v_rel, target)
        track_mag = law.track(
            fv.speed_mps, ngx, fv.hdot_mps, to_go, range_rate, ld / (c_l0 / c_d0), bank_offset
        )
        mag = jnp.where(
            phase == 0,
            sim.hold_bank_rad,
            jnp.where(phase == 1, pc_mag, jnp.where(phase == 2, g.bank_mag, track_mag)),
        )
        # lateral: reverse when the crossrange leaves the funnel (phases 1 and 3); the first
        # entry judges the crossrange predicted at the switch point, which includes the drift
        # of the rotating Earth under the Kepler arc
        chi_now = earth.equatorial_radius_m * crossrange_to_target(c.y.r, v_rel, target)
        chi = jnp.where(phase == 1, chi_switch, chi_now)
        want = -jnp.sign(chi)  # negative bank turns left, towards a target on the left
        threshold = jnp.where(phase == 1, law.switch_crossrange_m, law.funnel_m(fv.speed_mps))
        outside = (jnp.abs(chi) > threshold) & ((phase == 1) | (phase == 3))
        reverse = live & outside & (want != g.sign)
        sign = jnp.where(reverse, want, g.sign)
        command = sign * mag

        g_new = _Guidance(
            phase, pulled, sigma_0, sign, mag, bank_offset, dr, lr, last_status, chi_switch
        )

        # truth: actuator + RK4 substeps, chute crossing located by Hermite interpolation
        def sub(s, _):
            y, t, act, done, chute, t_chute, heat_load, heat_peak, load_peak = s
            act = sim.actuator.step(act, command, sim.dt_s)
            args = truth_args(act.bank)
            y1 = rk4_step(entry_vector_field, t, y, sim.dt_s, args)
            f0 = flight_variables(y, earth)
            f1 = flight_variables(y1, earth)
            cross = ~done & (f1.altitude_m < law.chute_altitude_m)
            sfrac = hermite_crossing(
                f0.altitude_m,
                f0.hdot_mps,
                f1.altitude_m,
                f1.hdot_mps,
                sim.dt_s,
                law.chute_altitude_m,
            )
            now = hermite_state(
                y,
                entry_vector_field(t, y, args).v,
                y1,
                entry_vector_field(t + sim.dt_s, y1, args).v,
                sim.dt_s,
                sfrac,
            )
            chute = jax.tree_util.tree_map(lambda a, b: jnp.where(cross, a, b), now, chute)
            t_chute = jnp.where(cross, t + sfrac * sim.dt_s, t_chute)
            rho = atmosphere.density(f1.altitude_m)
            q_dot = sutton_graves_heat_rate(rho, f1.speed_mps, vehicle.nose_radius_m)
            ng1 = sensed_load_g(y1.r, y1.v, vehicle, earth, atmosphere)
            keep = ~done
            y = jax.tree_util.tree_map(lambda a, b: jnp.where(done, a, b), y, y1)
            return (
                y,
                t + jnp.where(done, 0.0, sim.dt_s),
                act,
                done | cross,
                chute,
                t_chute,
                heat_load + keep * q_dot * sim.dt_s,
                jnp.maximum(heat_peak, keep * q_dot),
                jnp.maximum(load_peak, keep * ng1),
            ), None

        s0 = (c.y, c.t, c.act, c.done, c.chute, c.t_chute, c.heat_load, c.heat_peak, c.load_peak)
        (y, t, act, done, chute, t_chute, heat_load, heat_peak, load_peak), _ = jax.lax.scan(
            sub, s0, None, length=sim.substeps
        )

        range_flown = ground_range_m(y0.r, 0.0, c.y.r, c.t, earth)
        new = _Carry(
            y=y,
            t=t,
            act=act,
            g=g_new,
            done=done,
            chute=chute,
            t_chute=t_chute,
            load_peak=load_peak,
            heat_peak=heat_peak,
            heat_load=heat_load,
            apogee=jnp.where((phase == 2) & live, jnp.maximum(c.apogee, fv.altitude_m), c.apogee),
            skipped_out=c.skipped_out | (live & (fv.altitude_m > law.skip_out_altitude_m)),
            switch=jnp.where(
                to_track,
                jnp.stack([fv.speed_mps, fv.altitude_m, fv.hdot_mps, range_flown]),
                c.switch,
            ),
            t_guidance=jnp.where(start, c.t, c.t_guidance),
            t_kepler=jnp.where(to_kepler, c.t, c.t_kepler),
            t_switch=jnp.where(to_track, c.t, c.t_switch),
            predictions=c.predictions + jnp.where(did_pc, res.n_evals_early_exit, 0),
            cycle_max=jnp.maximum(c.cycle_max, jnp.where(did_pc, res.n_evals_early_exit, 0)),
            pc_cycles=c.pc_cycles + did_pc,
            failures=c.failures + (did_pc & (res.status != RootStatus.ok)),
            reversals=c.reversals + reverse,
            predictor_steps=c.predictor_steps + jnp.where(did_pc, res.cost, 0.0),
        )
        rec = None
        if record:
            rec = Trace(
                c.t,
                fv.altitude_m,
                fv.speed_mps,
                range_flown,
                command,
                c.act.bank,
                ng,
                phase,
                sigma_0,
                jnp.where(did_pc, res.f_x, 0.0),
                jnp.where(did_pc, res.n_evals_early_exit, 0),
                c.y.r,
                c.y.v,
                pulled,
                dr,
                lr,
            )
        return new, rec

    z = jnp.zeros(())
    zi = jnp.zeros((), int)
    g0 = _Guidance(
        zi,
        jnp.asarray(False),
        law.reference.first_entry_bank_rad,
        jnp.ones(()),
        sim.hold_bank_rad,
        z,
        jnp.ones(()),
        jnp.ones(()),
        zi,
        z,
    )
    c0 = _Carry(
        y0,
        z,
        sim.actuator.init(sim.hold_bank_rad),
        g0,
        jnp.asarray(False),
        y0,
        z,
        z,
        z,
        z,
        z,
        jnp.asarray(False),
        jnp.zeros(4),
        z,
        z,
        z,
        zi,
        zi,
        zi,
        zi,
        zi,
        z,
    )
    c, rec = jax.lax.scan(control_step, c0, jnp.arange(sim.n_control))

    u_chute = unit(to_earth_fixed(c.chute.r, c.t_chute, earth.rotation_rate))
    along, cross = along_cross_track(u_chute, nominal_start, sim.target_fixed)
    r_e_km = earth.equatorial_radius_m / 1e3
    outcome = CapsuleOutcome(
        status=jnp.zeros((), jnp.int32),
        downrange_err_km=along * r_e_km,
        crossrange_err_km=cross * r_e_km,
        load_peak_g=c.load_peak,
        heat_rate_peak_kw_m2=c.heat_peak / 1e3,
        heat_load_mj_m2=c.heat_load / 1e6,
        skip_apogee_km=c.apogee / 1e3,
        switch_speed_mps=c.switch[0],
        switch_altitude_km=c.switch[1] / 1e3,
        switch_hdot_mps=c.switch[2],
        switch_range_km=c.switch[3] / 1e3,
        bank_offset_deg=jnp.degrees(c.g.bank_offset),
        predictions=c.predictions,
        cycle_predictions_max=c.cycle_max,
        pc_cycles=c.pc_cycles,
        corrector_failures=c.failures,
        reversals=c.reversals,
        predictor_steps=c.predictor_steps,
        t_guidance_s=c.t_guidance,
        t_kepler_s=c.t_kepler,
        t_switch_s=c.t_switch,
        t_chute_s=c.t_chute,
        dispersion=draws,
    )
    finite = all_finite(outcome)
    status = jnp.where(
        ~finite,
        Status.nan,
        jnp.where(
            c.skipped_out,
            Status.skip_out,
            jnp.where(
                ~c.done,
                Status.time_out,
                jnp.where(c.g.last_status != RootStatus.ok, Status.no_convergence, Status.ok),
            ),
        ),
    )
    return outcome._replace(status=status.astype(jnp.int32)), rec


def build(scenario) -> tuple[CapsuleSimulation, SkipEntryGuidance]:
    """Simulation data and guidance law of a validated capsule scenario (SI units).

    The second-entry reference is designed by :mod:`gnc_jax.guidance.reference_design` for the
    scenario's nominal vehicle, entry and target (cached on disk after the first design).
    """
    import math

    from ..guidance.reference_design import NominalProblem, reference_for

    cfg = scenario.config
    e, v, a, act, dsp, g, ref, s = (
        cfg[k]
        for k in (
            "entry",
            "vehicle",
            "atmosphere",
            "actuator",
            "dispersions",
            "guidance",
            "reference",
            "simulation",
        )
    )
    f = lambda x: jnp.asarray(x, dtype=jnp.float64)  # noqa: E731
    rad = math.radians
    earth = EarthModel()
    vehicle = EntryVehicle(
        mass_kg=v["mass_kg"],
        reference_area_m2=v["area_m2"],
        lift_coefficient=v["cl"],
        drag_coefficient=v["cd"],
        nose_radius_m=v["nose_radius_m"],
    )
    atmosphere = Atmosphere(
        model=a["model"], rho0=a["rho0_kgm3"], scale_height_m=a["scale_height_km"] * 1e3
    )
    entry = EntryConditions(
        f(e["altitude_km"] * 1e3),
        f(e["speed_kmps"] * 1e3),
        f(rad(e["fpa_deg"])),
        f(rad(e["azimuth_deg"])),
        f(rad(e["longitude_deg"])),
        f(rad(e["latitude_deg"])),
    )
    y0 = entry_state_from_conditions(entry, earth)
    target = destination(
        unit(y0.r), entry.azimuth, e["range_km"] * 1e3 / float(earth.equatorial_radius_m)
    )
    problem = NominalProblem(
        model=EntryModel(vehicle, earth, atmosphere),
        entry=y0,
        target_fixed=target,
        kepler_load_g=f(g["kepler_load_g"]),
        chute_altitude_m=f(e["chute_altitude_km"] * 1e3),
        v_end_mps=f(ref["v_end_mps"]),
    )
    description = {
        "entry": e,
        "vehicle": v,
        "atmosphere": a,
        "kepler_load_g": g["kepler_load_g"],
        "v_end_mps": ref["v_end_mps"],
    }
    reference, _ = reference_for(
        problem, description, w_margin=ref["w_margin"], steps=ref["design_steps"]
    )
    law = SkipEntryGuidance(
        reference=reference,
        k_drag_load=f(g["k_drag_load"]),
        k_hdot=f(g["k_hdot"]),
        k_range=f(g["k_range"]),
        k_range_rate=f(g["k_range_rate"]),
        ng0_g=f(g["ng0_g"]),
        kepler_load_g=f(g["kepler_load_g"]),
        bracket_step_rad=f(rad(g["bracket_step_deg"])),
        range_tolerance_m=f(g["range_tolerance_km"] * 1e3),
        bank_min_rad=f(rad(g["bank_min_deg"])),
        bank_max_rad=f(rad(g["bank_max_deg"])),
        skip_out_altitude_m=f(g["skip_out_altitude_km"] * 1e3),
        funnel_base_m=f(g["funnel_base_km"] * 1e3),
        funnel_quadratic_s2_m=f(g["funnel_quadratic_km"] * 1e3 / 1e6),
        switch_crossrange_m=f(g["switch_crossrange_km"] * 1e3),
        track_bank_min_rad=f(rad(g["track_bank_min_deg"])),
        chute_altitude_m=f(e["chute_altitude_km"] * 1e3),
        predictor_dt_s=float(g["predictor_dt_s"]),
        predictor_max_steps=int(g["predictor_max_steps"]),
        n_bracket=int(g["n_bracket"]),
        n_iter=int(g["n_iter"]),
    )
    three = 1.0 / 3.0
    sim = CapsuleSimulation(
        entry=entry,
        vehicle=vehicle,
        earth=earth,
        atmosphere=atmosphere,
        actuator=BankActuator(
            max_rate=rad(act["max_rate_dps"]), max_acceleration=rad(act["max_accel_dps2"])
        ),
        dispersions=CapsuleDispersions(
            speed_mps=f(dsp["speed_mps"] * three),
            fpa_rad=f(rad(dsp["fpa_deg"]) * three),
            heading_rad=f(rad(dsp["heading_deg"]) * three),
            downrange_m=f(dsp["downrange_km"] * 1e3 * three),
            altitude_m=f(dsp["altitude_km"] * 1e3 * three),
            crossrange_m=f(dsp["crossrange_km"] * 1e3 * three),
            lift_frac=f(dsp["cl_pct"] / 100 * three),
            drag_frac=f(dsp["cd_pct"] / 100 * three),
            density_frac=f(dsp["density_pct"] / 100 * three),
            mass_frac_half_width=f(dsp["mass_pct"] / 100),
        ),
        target_fixed=target,
        ratio_filter_gain=f(g["ratio_filter_gain"]),
        hold_bank_rad=f(rad(g["hold_bank_deg"])),
        dt_s=float(s["dt_s"]),
        substeps=int(round(s["control_dt_s"] / s["dt_s"])),
        n_control=int(math.ceil(s["max_time_s"] / s["control_dt_s"])),
        pc_every=int(round(g["pc_period_s"] / s["control_dt_s"])),
    )
    return sim, law
