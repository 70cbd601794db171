# ruff: noqa: F722  (jaxtyping shape strings such as "" and "6 3" are not Python expressions)
"""Heliocentric cruise dynamics: Sun + 8 planets + cannonball solar radiation pressure (seed 001).

Seed 001 (Zhang, Wang, Huang 2009) propagates the Phoenix Earth–Mars transfer with the Sun as
central body, the eight planets as point-mass perturbations and solar radiation pressure. Here
the state is heliocentric, EME2000, SI: y = (r, v) in m and m/s, and the time is seconds past
J2000 TDB (`gnc_jax.time`). The acceleration is

    a = -μ_S r/|r|³ + Σ_p μ_p [ (r_p - r)/|r_p - r|³ - r_p/|r_p|³ ] + k_SRP r/|r|³,

the second sum being the direct minus the indirect (Sun-acceleration) term of each planet, with
planet positions r_p(t) from the analytical plan94 ephemeris in JAX (`dynamics.ephemeris`), and
the cannonball pressure k_SRP = P_1AU AU² C_r A/m, P_1AU = 4.5605e-6 N/m² (no shadow: the
cruise never enters one).

Propagation is adaptive (diffrax, Dormand–Prince 8(7) by default; the paper's 4(5) pair is
``solver="dopri5"``) because the 238-day cruise needs steps of days while the Mars periapsis
needs minutes. `propagate_to_encounter` stops at the closest approach to the target planet,
detected by a diffrax event (r_rel·v_rel turning positive inside the event sphere, with an
impact guard at the planet's surface) and located by Kepler's equation on the osculating
planet-relative hyperbola. Derivatives are forward mode (``diffrax.ForwardMode``): the targeter
needs Jacobians with three columns (Δv), so `jax.jvp` / `jax.jacfwd` work through every function
here (reverse mode does not).

Planet velocities relative to which the encounter is measured are the exact time derivatives of
the plan94 positions (`planet_position_rate`), not plan94's two-body velocities (which differ by
up to 3.3 m/s for Mars): the planet-relative state must be consistent with the motion the
dynamics sees, or the hyperbolic B-plane would drift along the flow.
"""

from typing import NamedTuple

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp

from .._status import Status
from .._types import Array, Float, Matrix3, Scalar, Vector3
from ..constants import SECONDS_PER_DAY
from ..geometry.kepler import time_since_periapsis
from ..integrate import ForwardMode
from .ephemeris import AU_M, GM_PLANETS, GM_SUN, planet_index, planet_state, planet_states

SOLAR_PRESSURE_1AU = 4.5605e-6
"""Solar radiation pressure at 1 AU on an absorbing surface, N/m² (seed 001)."""

MARS_RADIUS_M = 3_396_190.0
"""Mars equatorial radius (IAU 2015), m; the impact guard of the encounter event."""

SOLVERS = {"dopri5": diffrax.Dopri5, "tsit5": diffrax.Tsit5, "dopri8": diffrax.Dopri8}
"""Adaptive explicit Runge–Kutta pairs by name (``HeliocentricModel.solver``)."""

MARS = planet_index("mars")

_ACCELERATION_STEP_S = 600.0


@jax.jit
@jax.vmap
def _node_derivatives(t):
    """Planet positions, exact velocities and accelerations at epoch ``t`` (a table node)."""
    pos = lambda tt: planet_states(tt)[0]
    vel = lambda tt: jax.jvp(pos, (tt,), (jnp.ones_like(tt),))[1]
    r, v = jax.jvp(pos, (t,), (jnp.ones_like(t),))
    # The Kepler solve makes only first derivatives exact (one implicit-function Newton
    # step), so the acceleration is the 4th-order central difference of the exact velocities:
    # error ~ d⁴ |r⁽⁵⁾| / 30 + 1e-16 |v| / d, below 1e-12 m/s² with d = 600 s.
    d = _ACCELERATION_STEP_S
    a = (8.0 * (vel(t + d) - vel(t - d)) - (vel(t + 2 * d) - vel(t - 2 * d))) / (12 * d)
    return jnp.stack([r, v, a])


class EphemerisTable(eqx.Module):
    """Quintic Hermite interpolation of the plan94 planet positions on a uniform time grid.

    Evaluating plan94 (a Kepler solve and 18 periodic terms per planet) at every stage of every
    step dominates the vector field, and a batch of runs on different adaptive time grids cannot
    share it; with the table a propagation is ~8x faster alone and ~17x faster vmapped
    (measured). The table stores, at nodes t_k = t0 + k h, the positions, their exact first
    derivatives (forward mode through the JAX plan94) and second derivatives (4th-order central
    differences of those), and interpolates with the quintic Hermite polynomial matching all
    three at both ends of the interval: C² in time, error ~ h⁶ |r⁽⁶⁾| / 46080. At h = 1 day the
    measured error is below 1 cm for Venus to Neptune and 8 m for Mercury (e = 0.21), far below
    plan94's own accuracy (tests/dynamics/test_heliocentric.py). Velocities are the derivative
    of the interpolant, consistent with its positions.

    Build it with `EphemerisTable.spanning`; outside [t0, t0 + (k-1) h] the end polynomials
    extrapolate (inaccurate), so the span must cover every epoch the propagation visits.
    """

    t0_s: Scalar
    step_s: Scalar
    nodes: Float[Array, "k 3 8 3"]  # node, (position, velocity, acceleration), planet, xyz

    @classmethod
    def spanning(cls, t_start_s: float, t_end_s: float, step_s: float = SECONDS_PER_DAY):
        """A table covering [t_start_s, t_end_s] (with one node of margin at each end)."""
        n = int(jnp.ceil((t_end_s - t_start_s) / step_s)) + 3
        ts = t_start_s - step_s + step_s * jnp.arange(n)
        return cls(jnp.asarray(ts[0]), jnp.asarray(step_s, float), _node_derivatives(ts))

    def positions_rates(self, t_s) -> tuple[Float[Array, "8 3"], Float[Array, "8 3"]]:
        """Positions (m) and velocities (m/s) of the 8 planets at ``t_s`` (EME2000)."""
        h = self.step_s
        x = (t_s - self.t0_s) / h
        k = jnp.clip(jnp.floor(x), 0, self.nodes.shape[0] - 2).astype(jnp.int32)
        s = x - k
        (p0, v0, a0), (p1, v1, a1) = self.nodes[k], self.nodes[k + 1]
        s2 = s * s
        s3 = s2 * s
        s4 = s3 * s
        s5 = s4 * s
        # Quintic Hermite basis on [0, 1] and its s-derivative.
        basis = jnp.stack(
            [
                1.0 - 10.0 * s3 + 15.0 * s4 - 6.0 * s5,
                s - 6.0 * s3 + 8.0 * s4 - 3.0 * s5,
                0.5 * s2 - 1.5 * s3 + 1.5 * s4 - 0.5 * s5,
                10.0 * s3 - 15.0 * s4 + 6.0 * s5,
                -4.0 * s3 + 7.0 * s4 - 3.0 * s5,
                0.5 * s3 - s4 + 0.5 * s5,
            ]
        )
        slope = jnp.stack(
            [
                -30.0 * s2 + 60.0 * s3 - 30.0 * s4,
                1.0 - 18.0 * s2 + 32.0 * s3 - 15.0 * s4,
                s - 4.5 * s2 + 6.0 * s3 - 2.5 * s4,
                30.0 * s2 - 60.0 * s3 + 30.0 * s4,
                -12.0 * s2 + 28.0 * s3 - 15.0 * s4,
                1.5 * s2 - 4.0 * s3 + 2.5 * s4,
            ]
        )
        data = jnp.stack([p0, h * v0, h * h * a0, p1, h * v1, h * h * a1])
        return jnp.tensordot(basis, data, axes=1), jnp.tensordot(slope, data, axes=1) / h


class HeliocentricModel(eqx.Module):
    """Force model and integrator settings of the heliocentric cruise.

    Attributes:
        gm_sun: μ of the Sun, m³/s².
        gm_planets: μ of the 8 planets (systems) in `PLANETS` order, m³/s²; 0 switches one off.
        srp_m2_per_kg: C_r A / m of the cannonball, m²/kg (0: no radiation pressure).
        solar_pressure_npm2: radiation pressure at 1 AU, N/m².
        rtol, atol: integrator tolerances (relative; absolute in SI units of the state).
        target_radius_m: impact guard radius of the target planet, m.
        event_radius_m: closest approaches further than this from the target are ignored, m.
        ephemeris: `EphemerisTable` of the planets, or None to evaluate plan94 directly at
            every stage (the reference; 8-17x slower propagation).
        target: index of the encounter planet (static; 3 = Mars).
        solver: name in `SOLVERS` (static). max_steps: integrator step budget (static).
    """

    gm_sun: Scalar = GM_SUN
    gm_planets: Float[Array, "8"] = eqx.field(default_factory=lambda: jnp.asarray(GM_PLANETS))
    srp_m2_per_kg: Scalar = 0.0
    solar_pressure_npm2: Scalar = SOLAR_PRESSURE_1AU
    rtol: Scalar = 1e-13
    atol: Scalar = 1e-7
    target_radius_m: Scalar = MARS_RADIUS_M
    event_radius_m: Scalar = 1.5e9
    ephemeris: EphemerisTable | None = None
    target: int = eqx.field(static=True, default=MARS)
    solver: str = eqx.field(static=True, default="dopri8")
    max_steps: int = eqx.field(static=True, default=4096)

    @property
    def gm_target(self) -> Scalar:
        return self.gm_planets[self.target]

    def planets(self, t_s) -> tuple[Float[Array, "8 3"], Float[Array, "8 3"]]:
        """Planet positions (m) and consistent velocities (m/s) at ``t_s`` (EME2000)."""
        if self.ephemeris is not None:
            return self.ephemeris.positions_rates(t_s)
        t = jnp.asarray(t_s, dtype=float)
        return jax.jvp(lambda tt: planet_states(tt)[0], (t,), (jnp.ones_like(t),))


class Encounter(NamedTuple):
    """End of a propagation to the closest approach of the target planet.

    ``state`` is heliocentric (r, v); ``r_rel``/``v_rel`` are relative to the target planet.
    ``status`` is a :class:`Status`: ``ok``, ``time_out`` (no closest approach before the end of
    the window) or ``nan`` (integrator failure, e.g. the step budget ran out).
    """

    t_s: Scalar
    state: Float[Array, "6"]
    r_rel: Vector3
    v_rel: Vector3
    status: Array


def planet_position_rate(index, t_s) -> tuple[Vector3, Vector3]:
    """Heliocentric position (m) of a planet and its exact time derivative (m/s), EME2000.

    The rate is the forward-mode derivative of the plan94 position, consistent with the positions
    that enter `acceleration` (plan94's own velocity is the osculating two-body one).
    """
    t = jnp.asarray(t_s, dtype=float)
    return jax.jvp(lambda tt: planet_state(index, tt)[0], (t,), (jnp.ones_like(t),))


def _planet_positions(model: HeliocentricModel, t_s) -> Float[Array, "8 3"]:
    if model.ephemeris is not None:
        return model.ephemeris.positions_rates(t_s)[0]
    return planet_states(t_s)[0]


def acceleration(model: HeliocentricModel, t_s, r: Vector3) -> Vector3:
    """Heliocentric acceleration (m/s²) at epoch ``t_s`` and position ``r`` (module equation)."""
    r_planets = _planet_positions(model, t_s)
    r2 = r @ r
    r_norm = jnp.sqrt(r2)
    central = (
        (model.srp_m2_per_kg * model.solar_pressure_npm2 * AU_M**2 - model.gm_sun)
        * r
        / (r2 * r_norm)
    )
    d = r_planets - r  # spacecraft -> planet
    d_norm = jnp.linalg.norm(d, axis=1, keepdims=True)
    p_norm = jnp.linalg.norm(r_planets, axis=1, keepdims=True)
    direct = d / d_norm**3
    indirect = r_planets / p_norm**3
    return central + model.gm_planets @ (direct - indirect)


def gravity_gradient(model: HeliocentricModel, t_s, r: Vector3) -> Matrix3:
    """∂a/∂r (1/s²) of `acceleration`, in closed form (the variational equations' G matrix).

    For a point source of strength μ at distance vector x = r - r_source (a = -μ x/|x|³):
    ∂a/∂r = -μ (I - 3 x̂ x̂ᵀ)/|x|³. Radiation pressure is a source of strength -k_SRP at the Sun;
    the indirect terms do not depend on r.
    """
    r_planets = _planet_positions(model, t_s)
    eye = jnp.eye(3)

    def point(mu, x):
        x_norm = jnp.linalg.norm(x)
        x_hat = x / x_norm
        return -mu * (eye - 3.0 * jnp.outer(x_hat, x_hat)) / x_norm**3

    mu_central = model.gm_sun - model.srp_m2_per_kg * model.solar_pressure_npm2 * AU_M**2
    planets = jax.vmap(point)(model.gm_planets, r - r_planets)
    return point(mu_central, r) + jnp.sum(planets, axis=0)


def vector_field(t, y: Float[Array, "6"], model: HeliocentricModel) -> Float[Array, "6"]:
    """dy/dt of y = (r, v)."""
    return jnp.concatenate([y[3:], acceleration(model, t, y[:3])])


def _variational_field(t, y, model: HeliocentricModel):
    """d/dt of (x, Φ_v) with Φ_v = ∂x/∂v0 (6×3): Φ̇ = [[0, I], [G, 0]] Φ (seed 001 eq. 22)."""
    x, phi = y
    g = gravity_gradient(model, t, x[:3])
    phi_dot = jnp.concatenate([phi[3:], g @ phi[:3]])
    return vector_field(t, x, model), phi_dot


def _solve(model, field, t0, t1, y0, event=None):
    solver = SOLVERS[model.solver]()
    return diffrax.diffeqsolve(
        diffrax.ODETerm(field),
        solver,
        t0=t0,
        t1=t1,
        dt0=None,
        y0=y0,
        args=model,
        stepsize_controller=diffrax.PIDController(rtol=model.rtol, atol=model.atol),
        event=event,
        max_steps=model.max_steps,
        adjoint=ForwardMode(),
        saveat=diffrax.SaveAt(t1=True),
        throw=False,
    )


def propagate(
    model: HeliocentricModel, t0_s, y0: Float[Array, "6"], t1_s
) -> tuple[Float[Array, "6"], Array]:
    """State at ``t1_s`` from ``y0`` at ``t0_s`` (either direction); returns ``(y1, status)``."""
    sol = _solve(model, vector_field, jnp.asarray(t0_s, float), jnp.asarray(t1_s, float), y0)
    ok = sol.result == diffrax.RESULTS.successful
    return sol.ys[-1], jnp.where(ok, Status.ok, Status.nan).astype(jnp.int32)


def propagate_with_stm(
    model: HeliocentricModel, t0_s, y0: Float[Array, "6"], t1_s
) -> tuple[Float[Array, "6"], Float[Array, "6 3"], Array]:
    """`propagate` to the fixed epoch ``t1_s`` together with Φ_v = ∂x(t1)/∂v(t0) from the
    variational equations; returns ``(y1, Φ_v, status)``."""
    phi0 = jnp.concatenate([jnp.zeros((3, 3)), jnp.eye(3)])
    t0, t1 = jnp.asarray(t0_s, float), jnp.asarray(t1_s, float)
    sol = _solve(model, _variational_field, t0, t1, (y0, phi0))
    ok = sol.result == diffrax.RESULTS.successful
    status = jnp.where(ok, Status.ok, Status.nan).astype(jnp.int32)
    return sol.ys[0][-1], sol.ys[1][-1], status


def relative_state(model: HeliocentricModel, t_s, y: Float[Array, "6"]):
    """Position and velocity relative to the target planet (m, m/s)."""
    if model.ephemeris is not None:
        r_all, v_all = model.ephemeris.positions_rates(t_s)
        r_p, v_p = r_all[model.target], v_all[model.target]
    else:
        r_p, v_p = planet_position_rate(model.target, t_s)
    return y[:3] - r_p, y[3:6] - v_p


def _encounter_event(state_of):
    """Closest approach (r_rel·v_rel crosses zero upwards inside the event sphere) or impact,
    of the state ``state_of(y)``; the model is the solve's ``args``.

    No root finder: the solve stops at the end of the step in which a condition changes sign,
    and `_to_periapsis` then finds the periapsis epoch from Kepler's equation. (Locating the
    root inside diffrax gives the same values, but its forward-mode derivatives through the
    root find and the dense output are off by ~1e-5 relative, measured against central
    differences; the step-end state is differentiated exactly.)
    """

    def closest_approach(t, y, model, **kwargs):
        r_rel, v_rel = relative_state(model, t, state_of(y))
        near = r_rel @ r_rel < model.event_radius_m**2
        # Outside the sphere the value is kept negative, so only a periapsis inside it counts.
        return jnp.where(near, r_rel @ v_rel, -1.0)

    def impact(t, y, model, **kwargs):
        r_rel, _ = relative_state(model, t, state_of(y))
        return jnp.linalg.norm(r_rel) - model.target_radius_m

    return diffrax.Event((closest_approach, impact), direction=(True, False))


def _state(y):
    return y


def _state_of_variational(y):
    return y[0]


# One event object per state layout, built once: every solve to an encounter with the same
# layout is then the same function to JAX, traced once per program (a closure built per call
# would make each solve a new trace: a midcourse study's program traced in 8 s instead of 13).
_ENCOUNTER = _encounter_event(_state)
_ENCOUNTER_VARIATIONAL = _encounter_event(_state_of_variational)


def _to_periapsis(model: HeliocentricModel, field, sol, state_of):
    """From the step end after the event, propagate (back) to the periapsis epoch.

    The epoch t_p = t + (time to periapsis on the osculating planet-relative hyperbola, seed 001
    eqs. 27-32) is held out of differentiation: the targets evaluated there (hyperbolic B-plane,
    arrival epoch) are constants of the planet-relative two-body motion, so moving t_p along the
    flow does not change them to first order. After an impact the state stays at the surface.
    """
    t_event, y_event = sol.ts[-1], jax.tree_util.tree_map(lambda x: x[-1], sol.ys)
    r_rel, v_rel = relative_state(model, t_event, state_of(y_event))
    to_periapsis = -time_since_periapsis(r_rel, v_rel, model.gm_target)
    closest = sol.event_mask[0]
    t_p = jax.lax.stop_gradient(jnp.where(closest, t_event + to_periapsis, t_event))
    refine = _solve(model, field, t_event, t_p, y_event)
    y_p = jax.tree_util.tree_map(lambda x: x[-1], refine.ys)
    found = (sol.result == diffrax.RESULTS.event_occurred) & (
        refine.result == diffrax.RESULTS.successful
    )
    failed = (sol.result != diffrax.RESULTS.successful) & ~found
    status = jnp.where(found, Status.ok, jnp.where(failed, Status.nan, Status.time_out))
    r_rel, v_rel = relative_state(model, t_p, state_of(y_p))
    return t_p, y_p, r_rel, v_rel, status.astype(jnp.int32)


def propagate_to_encounter(
    model: HeliocentricModel, t0_s, y0: Float[Array, "6"], t_max_s
) -> Encounter:
    """Propagate to the closest approach of the target planet (or impact, or ``t_max_s``).

    The closest approach is detected by an event on r_rel·v_rel and its epoch found from
    Kepler's equation (`_to_periapsis`); ``Encounter.t_s`` is that epoch.
    """
    t0 = jnp.asarray(t0_s, float)
    sol = _solve(model, vector_field, t0, jnp.asarray(t_max_s, float), y0, _ENCOUNTER)
    t, y, r_rel, v_rel, status = _to_periapsis(model, vector_field, sol, _state)
    return Encounter(t, y, r_rel, v_rel, status)


def propagate_to_encounter_with_stm(
    model: HeliocentricModel, t0_s, y0: Float[Array, "6"], t_max_s
) -> tuple[Encounter, Float[Array, "6 3"]]:
    """`propagate_to_encounter` together with Φ_v = ∂x(t_f)/∂v(t0), the velocity columns of the
    state-transition matrix, from the variational equations (seed 001 eqs. 21-22).

    Φ_v is integrated alongside the state with the same adaptive steps (its error is controlled
    too) to the periapsis epoch t_f of the reference trajectory; the variation of t_f itself is
    left out, as in the paper, which is harmless for flow-invariant targets such as the
    hyperbolic B-plane and the arrival epoch (`geometry.hyperbola`).
    """
    phi0 = jnp.concatenate([jnp.zeros((3, 3)), jnp.eye(3)])
    t0 = jnp.asarray(t0_s, float)
    y0 = (y0, phi0)
    sol = _solve(
        model, _variational_field, t0, jnp.asarray(t_max_s, float), y0, _ENCOUNTER_VARIATIONAL
    )
    t, (x, phi), r_rel, v_rel, status = _to_periapsis(
        model, _variational_field, sol, _state_of_variational
    )
    return Encounter(t, x, r_rel, v_rel, status), phi


def steps_to_encounter(
    model: HeliocentricModel, t0_s, y0: Float[Array, "6"], t_max_s
) -> tuple[Array, Array]:
    """``(steps, exhausted)`` of `propagate_to_encounter`'s solve from ``y0``: the integrator
    steps it takes to the closest approach (accepted and rejected, what ``max_steps`` bounds)
    and whether it stopped at ``model.max_steps`` before the encounter or ``t_max_s``."""
    t0 = jnp.asarray(t0_s, float)
    sol = _solve(model, vector_field, t0, jnp.asarray(t_max_s, float), y0, _ENCOUNTER)
    return sol.stats["num_steps"], sol.result == diffrax.RESULTS.max_steps_reached
