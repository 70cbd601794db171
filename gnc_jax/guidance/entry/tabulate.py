"""Tabulation of the designed second entry as the reference the law tracks.

From the designed nominal (:mod:`gnc_jax.guidance.entry.design`) this module flies the second
entry at 1 s steps and tabulates it against speed (bank, range to go, Ḣ, drag load, range
rate), with the range sensitivities that schedule the tracking gains (eq. 7) and the partials
of the second-entry range with respect to the switch-point speed, flight-path angle, altitude
and a uniform bank offset (seed 003 eqs. 10 and 16): a
:class:`~gnc_jax.guidance.entry.reference.ReferenceTrajectory`.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ...dynamics.entry import EntryState
from ...integrate import rk4_step
from ...schema import ScenarioError
from .base import (
    drag_load_g,
    flight_variables,
    ground_range_m,
    hermite_crossing,
    hermite_state,
    perturb_switch_state,
)
from .design import DesignResult
from .nominal import NominalProblem, fly_nominal_jit, reference_bank
from .reference import ReferenceTrajectory


def second_entry_range(
    problem: NominalProblem,
    switch: EntryState,
    t_switch,
    sigma_a,
    sigma_b,
    v_switch,
    d_bank=0.0,
    dt_s=1.0,
    max_steps=1200,
    d_cos=0.0,
):
    """Ground range (m) flown from a switch state to the chute with cos(sigma_ref(v) + d_bank)
    + d_cos."""
    m, earth = problem.model, problem.model.earth

    def body(c, _):
        y, t, done, chute, t_chute = c
        fv = flight_variables(y, earth)
        cos_b = (
            jnp.cos(
                reference_bank(sigma_a, sigma_b, v_switch, problem.v_end_mps, fv.speed_mps) + d_bank
            )
            + d_cos
        )
        f = lambda t, y, a: m.vertical_plane_field(t, y, a)  # noqa: E731
        y1 = rk4_step(f, t, y, dt_s, cos_b)
        alt1 = flight_variables(y1, earth)
        crossing = ~done & (alt1.altitude_m < problem.chute_altitude_m)
        s = hermite_crossing(
            fv.altitude_m,
            fv.hdot_mps,
            alt1.altitude_m,
            alt1.hdot_mps,
            dt_s,
            problem.chute_altitude_m,
        )
        now = hermite_state(y, f(t, y, cos_b).v, y1, f(t + dt_s, y1, cos_b).v, dt_s, s)
        chute = jax.tree_util.tree_map(lambda a, b: jnp.where(crossing, a, b), now, chute)
        t_chute = jnp.where(crossing, t + s * dt_s, t_chute)
        y = jax.tree_util.tree_map(lambda a, b: jnp.where(done, a, b), y, y1)
        return (y, t + dt_s, done | crossing, chute, t_chute), None

    init = (
        switch,
        jnp.asarray(t_switch, float),
        jnp.asarray(False),
        switch,
        jnp.asarray(t_switch, float),
    )
    (_, _, _, chute, t_chute), _ = jax.lax.scan(body, init, None, length=max_steps)
    return ground_range_m(switch.r, t_switch, chute.r, t_chute, earth)


class _SecondEntryRecord(NamedTuple):
    """The designed second entry flown at 1 s steps, down to the chute altitude (numpy)."""

    r: np.ndarray
    t: np.ndarray
    speed: np.ndarray
    hdot: np.ndarray
    alt: np.ndarray
    bank: np.ndarray
    ngx: np.ndarray
    v: np.ndarray
    range_to_go: np.ndarray  # ground range to the chute point, m (first n points)
    n: int  # points above the chute altitude


@jax.jit
def _second_entry_steps(problem: NominalProblem, switch, t_sw, sigma_a, sigma_b, v_switch):
    """The designed second entry flown from the switch point at 1 s steps (1200 of them)."""
    m, earth = problem.model, problem.model.earth

    def body(c, _):
        y, t = c
        fv = flight_variables(y, earth)
        bank = reference_bank(sigma_a, sigma_b, v_switch, problem.v_end_mps, fv.speed_mps)
        f = lambda t, y, a: m.vertical_plane_field(t, y, a)  # noqa: E731
        y1 = rk4_step(f, t, y, 1.0, jnp.cos(bank))
        return (y1, t + 1.0), (
            y.r,
            t,
            fv.speed_mps,
            fv.hdot_mps,
            fv.altitude_m,
            bank,
            drag_load_g(y, m),
            y.v,
        )

    return jax.lax.scan(body, (switch, t_sw), None, length=1200)[1]


@jax.jit
def _ranges_to(problem: NominalProblem, r, t, chute_r, chute_t):
    """Ground range (m) from each recorded point ``(r[i], t[i])`` to the chute point."""
    earth = problem.model.earth
    return jax.vmap(lambda ri, ti: ground_range_m(ri, ti, chute_r, chute_t, earth))(r, t)


def _record_second_entry(problem: NominalProblem, d: DesignResult, fl) -> _SecondEntryRecord:
    """Fly the designed second entry from the switch point and record it step by step."""
    r, t, speed, hdot, alt, bank, ngx, v = (
        np.asarray(x)
        for x in _second_entry_steps(
            problem, fl.switch, fl.t_switch, d.sigma_a, d.sigma_b, d.v_switch
        )
    )
    above = alt >= float(problem.chute_altitude_m)
    n = int(np.argmin(above)) if not above.all() else len(alt)
    rng = np.asarray(_ranges_to(problem, r[:n], t[:n], fl.chute.r, fl.t_chute))
    return _SecondEntryRecord(r, t, speed, hdot, alt, bank, ngx, v, rng, n)


@jax.jit
def _node_sensitivities(problem: NominalProblem, r, v, t, sigma_a, sigma_b, v_switch):
    """d(second-entry range)/d(altitude, flight-path angle, uniform cos sigma) from each of the
    states ``(r[i], v[i], t[i])``, by forward-mode autodiff (shape: nodes x 3)."""
    earth = problem.model.earth

    def range_from(ri, vi, ti, x):
        y = perturb_switch_state(EntryState(ri, vi), earth, 0.0, x[1], x[0])
        return second_entry_range(problem, y, ti, sigma_a, sigma_b, v_switch, 0.0, d_cos=x[2])

    return jax.vmap(
        lambda ri, vi, ti: jax.jacfwd(lambda x: range_from(ri, vi, ti, x))(jnp.zeros(3))
    )(r, v, t)


@jax.jit
def _switch_partials(problem: NominalProblem, switch, t_sw, sigma_a, sigma_b, v_switch):
    """d(second-entry range)/d(switch speed, flight-path angle, altitude, uniform bank)."""
    earth = problem.model.earth

    def s2(x):
        y = perturb_switch_state(switch, earth, x[0], x[1], x[2])
        return second_entry_range(problem, y, t_sw, sigma_a, sigma_b, v_switch, x[3])

    return jax.jacfwd(s2)(jnp.zeros(4))


def _tracking_sensitivities(problem: NominalProblem, d: DesignResult, rec, node_idx, chute_t):
    """(dR/dN_gx, dR/dḢ, dR/dcos sigma, time to go) at the table nodes ``node_idx``."""
    m = problem.model
    r, v, t, alt, ngx = rec.r, rec.v, rec.t, rec.alt, rec.ngx
    speed, hdot = rec.speed, rec.hdot

    # Range sensitivities along the reference (the gains of the tracking law): at table nodes,
    # d(range)/d(altitude), d(range)/d(flight-path angle) at fixed speed, and d(range)/d(cos
    # sigma) for a uniform change of cos(sigma) from that point on, all by forward-mode autodiff
    # through the remaining second entry.
    sens = np.asarray(
        _node_sensitivities(
            problem, r[node_idx], v[node_idx], t[node_idx], d.sigma_a, d.sigma_b, d.v_switch
        )
    )
    # at fixed speed N_gx is proportional to the density: dN/dh = N dln(rho)/dh
    dlnrho_dh = np.asarray(
        jax.vmap(jax.grad(lambda h: jnp.log(m.atmosphere.density(h))))(jnp.asarray(alt[node_idx]))
    )
    f_drag = sens[:, 0] / (dlnrho_dh * ngx[node_idx])  # m per g of N_gx
    cosg = np.cos(np.arcsin(np.clip(hdot[node_idx] / speed[node_idx], -1, 1)))
    f_hdot = sens[:, 1] / (speed[node_idx] * cosg)  # m per m/s of Ḣ
    f_cos = sens[:, 2]  # m per unit of cos(sigma)
    t_go = chute_t - t[node_idx]

    return f_drag, f_hdot, f_cos, t_go


def tabulate_reference(
    problem: NominalProblem, d: DesignResult, n_grid: int = 256
) -> ReferenceTrajectory:
    """Fly the designed nominal and store the second-entry reference against speed."""
    earth = problem.model.earth
    fl = fly_nominal_jit(problem, d.sigma_1, d.sigma_a, d.sigma_b, d.v_switch)
    switch, t_sw = fl.switch, fl.t_switch
    rec = _record_second_entry(problem, d, fl)
    n, speed, t, rng = rec.n, rec.speed, rec.t, rec.range_to_go
    chute_t = float(fl.t_chute)
    # range rate: central difference of the range to go along the record
    sdot = np.gradient(rng, t[:n])
    # keep the part where speed decreases monotonically (the table's abscissa)
    keep = np.concatenate([[True], np.diff(speed[:n]) < 0])
    last = int(np.argmin(keep)) if not keep.all() else n
    if last < 3:  # a table needs points; require_design makes this unreachable in practice
        raise ScenarioError(
            f"entry: the designed second entry has {last} tabulable points above the chute "
            "altitude; allowed: an entry whose nominal skips and then descends to the chute"
        )
    grid = np.linspace(speed[0], speed[last - 1], n_grid)
    order = np.argsort(speed[:last])

    def table(x):
        return jnp.asarray(np.interp(grid, speed[:last][order], x[:last][order]))

    node_idx = np.linspace(0, last - 1, 48).astype(int)
    f_drag, f_hdot, f_cos, t_go = _tracking_sensitivities(problem, d, rec, node_idx, chute_t)
    bank, hdot, ngx = rec.bank, rec.hdot, rec.ngx

    def node_table(x):
        o = np.argsort(speed[node_idx])
        return jnp.asarray(np.interp(grid, speed[node_idx][o], x[o]))

    partials = _switch_partials(problem, switch, t_sw, d.sigma_a, d.sigma_b, d.v_switch)
    fv = flight_variables(switch, earth)
    return ReferenceTrajectory(
        velocity_mps=jnp.asarray(grid),
        bank_rad=table(bank),
        range_to_go_m=table(rng),
        hdot_mps=table(hdot),
        drag_load_g=table(ngx),
        range_rate_mps=table(sdot),
        switch_velocity_mps=fv.speed_mps,
        switch_fpa_rad=fv.fpa_rad,
        switch_altitude_m=fv.altitude_m,
        switch_time_s=jnp.asarray(t_sw),
        second_entry_range_m=jnp.asarray(rng[0]),
        d_range_d_switch=partials[:3],
        d_range_d_bank=partials[3],
        first_entry_bank_rad=jnp.asarray(d.sigma_1),
        sigma_a_rad=jnp.asarray(d.sigma_a),
        sigma_b_rad=jnp.asarray(d.sigma_b),
        v_end_mps=jnp.asarray(problem.v_end_mps),
        range_per_drag_load_m=node_table(f_drag),
        range_per_hdot_s=node_table(f_hdot),
        range_per_cos_bank_m=node_table(f_cos),
        time_to_go_s=node_table(t_go),
    )
