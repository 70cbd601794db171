"""Variable-coefficient augmented proportional navigation with pulse firing (seed 004).

Line of sight from the impactor to the target, rho = -r (``r``: impactor minus target):

* LOS angle (planar, eq. 4): lambda = atan2(rho_y, rho_x); its rate (eq. 5)
  lambda_dot = (rho_x rho_dot_y - rho_y rho_dot_x) / rho^2, in 3-D the LOS-rate vector
  omega = rho x rho_dot / rho^2 (``geometry.los.los_rate``);
* closing speed (eq. 8): V_c = -(rho . rho_dot) / |rho|;
* A_r (eq. 10): the target's acceleration relative to the impactor perpendicular to the LOS
  (the differential solar gravity; the target's own pull on the impactor is along the LOS).

Command (eq. 11), perpendicular to the LOS: A = N (V_c omega x u + A_r_perp / 2), u = rho/|rho|
(in the plane, omega x u = lambda_dot times u turned by +90 deg, the paper's scalar form), with
the variable coefficient N = max(N_min, N0 (R/R0)^k) (eq. 12, N_min = 2; k = 0 is constant N).
No command in the last ``coast`` seconds (paper: 10 min).

Pulse firing (§2.2, Fig. 4; the Schmitt trigger of Zarchan's strategic-intercept chapter): the
engine fires at its fixed level along A/|A| when |A| >= a_on, stops when |A| <= a_off, and in
between keeps its previous state. The paper gives no thresholds; gnc_jax derives them from the
engine (see ``simulation.pn.trigger_scale``). With ``relaxed=True`` the switch is replaced by
its smooth relaxation (``guidance.trigger.schmitt_trigger`` with value |A|, levels a_on and
a_off), which tends to the hard logic as the temperature T -> 0 and lets gradients reach every
gain; evaluation uses the hard logic. With ``relaxation="event"`` the relaxed law keeps the
hard switch and differentiates each firing event's crossing time instead
(``guidance.trigger.schmitt_trigger_event``): the hard value, a tangent only at the switching
steps. It is exact where |A| drifts across a level; in the closed loop |A| crosses on
navigation noise of the order of the hysteresis band, and neither relaxation's gradient
follows the hard objective over the full approach (measured: ``docs/howto/tune.md``).
"""

import math
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from ..._numerics import cross3, dot3, norm3
from ..._types import Scalar, Vector3
from ...dynamics.intercept import InterceptDynamics
from ...geometry.los import los_rate
from ...params import from_config, param
from ...schema import ScenarioError
from ..base import EngineCommand, register_law, safe_unit
from ..trigger import (  # schmitt_trigger re-exported: gnc_jax.guidance.intercept.apn
    schmitt_trigger,
    schmitt_trigger_event,
)
from .base import AbstractInterceptGuidance


class PNNavigation(NamedTuple):
    """What navigation hands the law: relative state estimate and the target's ephemeris."""

    r: Vector3  # impactor minus target, m (estimate)
    v: Vector3  # m/s
    r_target: Vector3  # target heliocentric position, m (ephemeris: known, seed 004 §2.1)


class PNGuidanceContext(eqx.Module):
    """Mission data known on board.

    Attributes:
        range0_m: R0 of eq. 12, the initial relative distance, m.
        cutoff_time_s: no firing from this mission time on (coast the last 10 min).
        pulse_fraction: pulse width / control step: the engine fires at full thrust for this
            fraction of every control step the trigger is on (the commanded throttle).
        dynamics: the on-board gravity model (A_r of eq. 10).
        reference_normal: unit normal of the reference (orbit) plane; used for planar runs.
        dt_s: control step (static).
    """

    range0_m: Scalar
    cutoff_time_s: Scalar
    pulse_fraction: Scalar
    dynamics: InterceptDynamics
    reference_normal: Vector3
    dt_s: float = eqx.field(static=True)


def los_angle(rho: Vector3) -> Scalar:
    """Planar LOS angle lambda = atan2(rho_y, rho_x) (seed 004 eq. 4), rad."""
    return jnp.arctan2(rho[1], rho[0])


def los_angle_rate(rho: Vector3, rho_dot: Vector3) -> Scalar:
    """Planar LOS rate (seed 004 eq. 5), rad/s."""
    return (rho[0] * rho_dot[1] - rho[1] * rho_dot[0]) / (rho[0] ** 2 + rho[1] ** 2)


def closing_speed(rho: Vector3, rho_dot: Vector3) -> Scalar:
    """Closing speed V_c = -d|rho|/dt (seed 004 eq. 8), m/s (positive when closing)."""
    return -dot3(rho, rho_dot) / norm3(rho)


def navigation_coefficient(range_m, range0_m, n0, k, n_min=2.0) -> Scalar:
    """N = max(N_min, N0 (R/R0)^k) (seed 004 eq. 12).

    The power is written exp(k log(R/R0)): XLA's general ``pow`` on CPU costs twice its
    exp and log (measured 14 against 8 ns per element, float64, vectorised). The ratio's floor
    keeps k = 0 at N0 when R = 0 (0^0 = 1) and the gradient finite."""
    ratio = jnp.maximum(range_m / range0_m, 1e-300)
    return jnp.maximum(n_min, n0 * jnp.exp(k * jnp.log(ratio)))


def augmented_pn_command(
    nav: PNNavigation, n, dynamics: InterceptDynamics
) -> tuple[Vector3, Vector3]:
    """Continuous APN acceleration command (seed 004 eq. 11), m/s^2, and the unit LOS.

    A = N (V_c omega x u + A_r_perp / 2): perpendicular to the LOS u = rho/|rho|.
    """
    rho, rho_dot = -nav.r, -nav.v
    u = rho / norm3(rho)
    omega = los_rate(rho, rho_dot)
    # A_r: target relative to impactor = minus the impactor's relative gravity (eq. 10).
    a_rel_target = -dynamics.relative_gravity(nav.r_target, nav.r)
    a_r_perp = a_rel_target - dot3(a_rel_target, u) * u
    return n * (closing_speed(rho, rho_dot) * cross3(omega, u) + 0.5 * a_r_perp), u


class APNState(NamedTuple):
    engine_on: Scalar  # 0/1 (hard) or in [0, 1] (relaxed)
    command_mps2: Vector3  # continuous command A of eq. 11 (diagnostics, Figs. 7-9)
    coefficient: Scalar  # N of eq. 12
    magnitude_prev: Scalar | None = None  # |A| of the previous step (event relaxation only)


TRIGGER_MIN = 0.01
"""Lowest trigger level, in units of a_ref. Below it a level is under the command noise of
seed 004's navigation (Table 4 errors: |A| held by levels 0.1 / 0.05 has a median of 0.03 to
0.04 a_ref) and under the command change one pulse makes over a 1.06-day approach
(N q / t_go >= 0.0066 a_ref), so a train seldom ends and the engine fires at nearly every
step: ``bennu-apn`` with levels 0.001 / 0.0005 fired at 97 % of its steps (1400 m/s),
error-free at 83 %; with 0.01 / 0.005 at 38 % and 67 %, both past the propellant; with the
packaged 1 / 0.5 at 1 %."""


@register_law("apn")
class AugmentedPNGuidance(AbstractInterceptGuidance):
    """Seed 004 law. ``n0``, ``k``, ``a_on_mps2``, ``a_off_mps2`` are differentiable leaves.

    Paper gains: N0 = 8, k = 2 (variable); constant N is k = 0 with N0 = N. The scenario gives
    the trigger thresholds in units of a_ref = n_min q / coast (``trigger_scale``: the command
    change one pulse causes at the start of the coast); the defaults are the SI values for the
    default engine.
    """

    n0: Scalar = param(8.0, lo=0.0, lo_open=True, hi=100.0, doc="N0 of eq. 12", tunable=True)
    k: Scalar = param(
        2.0, lo=0.0, hi=10.0, doc="exponent k of eq. 12; 0 = constant N = n0", tunable=True
    )
    a_on_mps2: Scalar = param(
        1.0,
        toml="trigger_on",
        lo=TRIGGER_MIN,
        hi=1e6,
        si_default=4e-5,
        doc="Schmitt on-threshold a_on in units of a_ref = n_min x (minimum impulse bit) / "
        "coast_s, the command change one pulse causes at the start of the coast; from 0.01: "
        "a lower level is under the navigation's noise on the command and under the change "
        "one pulse makes to it, and the engine fires at nearly every step",
        tunable=True,
    )
    a_off_mps2: Scalar = param(
        0.5,
        toml="trigger_off",
        lo=TRIGGER_MIN,
        hi=1e6,
        si_default=2e-5,
        doc="Schmitt off-threshold a_off in units of a_ref; trigger_off < trigger_on; from "
        "0.01, as trigger_on",
        tunable=True,
    )
    n_min: Scalar = param(
        2.0,
        lo=2.0,
        hi=100.0,
        doc="lower bound of N (eq. 12: 2); at least 2: below it the PN command grows without "
        "bound as the time to go falls, and the trigger thresholds (a_ref = n_min q / coast_s) "
        "fall with it",
    )
    temperature: Scalar = param(
        0.05, lo=0.0, lo_open=True, hi=10.0, doc="relaxed trigger (gradients only)"
    )
    relaxed: bool = eqx.field(static=True, default=False)
    relaxation: str = eqx.field(static=True, default="sigmoid")  # "sigmoid" | "event"

    ordered_gains = (("trigger_on", "trigger_off"),)

    def __check_init__(self):
        if self.relaxation not in ("sigmoid", "event"):
            raise ValueError(f"relaxation: {self.relaxation!r}; allowed: 'sigmoid', 'event'")

    @classmethod
    def check(cls, section, config):
        if section["trigger_off"] >= section["trigger_on"]:
            raise ScenarioError(
                f"guidance.apn.trigger_off: {section['trigger_off']:g} >= trigger_on = "
                f"{section['trigger_on']:g}; allowed: {TRIGGER_MIN:g} <= trigger_off < trigger_on"
            )

    @classmethod
    def from_config(cls, section, config, ctx=None):
        sc = config["spacecraft"]
        scale = trigger_scale(
            sc["thrust_n"],
            sc["mass_kg"],
            sc["pulse_width_s"],
            section["n_min"],
            config["guidance"]["coast_s"],
        )
        f = lambda x: jnp.asarray(x, dtype=jnp.float64)  # noqa: E731
        return from_config(
            cls,
            section,
            a_on_mps2=f(section["trigger_on"] * scale),
            a_off_mps2=f(section["trigger_off"] * scale),
        )

    def describe(self) -> str:
        return f"N0 = {float(self.n0):g}, k = {float(self.k):g}"

    def switching_levels(self) -> dict[str, float]:
        """The Schmitt trigger's levels on |A| (eq. 12), m/s^2."""
        return {"a_on": float(self.a_on_mps2), "a_off": float(self.a_off_mps2)}

    def init(self, nav: PNNavigation, ctx: PNGuidanceContext) -> APNState:
        z = jnp.zeros(())
        event = self.relaxed and self.relaxation == "event"
        # the first step is no crossing: |A| "was" at a_on (neither below it nor at a_off)
        prev = jax.lax.stop_gradient(jnp.asarray(self.a_on_mps2, float)) if event else None
        return APNState(z, jnp.zeros(3), jnp.asarray(self.n0, float), prev)

    def step(self, state: APNState, nav: PNNavigation, t, ctx: PNGuidanceContext):
        """Engine command (throttle = fraction of the step at full thrust, unit direction)."""
        n = navigation_coefficient(norm3(nav.r), ctx.range0_m, self.n0, self.k, self.n_min)
        a_cmd, u = augmented_pn_command(nav, n, ctx.dynamics)
        magnitude = norm3(a_cmd)
        levels = (self.a_on_mps2, self.a_off_mps2)
        if self.relaxed and self.relaxation == "event":
            on = schmitt_trigger_event(magnitude, state.magnitude_prev, state.engine_on, *levels)
        else:
            temperature = self.temperature if self.relaxed else None
            on = schmitt_trigger(magnitude, state.engine_on, *levels, temperature)
        on = jnp.where(t < ctx.cutoff_time_s, on, 0.0)
        fallback = cross3(ctx.reference_normal, u)
        direction = safe_unit(a_cmd, fallback / norm3(fallback))
        prev = None if state.magnitude_prev is None else magnitude
        return EngineCommand(on * ctx.pulse_fraction, direction), APNState(on, a_cmd, n, prev)

    def pulse_trains(
        self, nav: PNNavigation, dynamics, coast_s, engine_accel_mps2, impulse_bit_mps
    ) -> "PulseTrainEstimate":
        """Closed-form error-free Δv and pulse trains of this law from the initial truth
        ``nav`` (:func:`pulse_train_estimate`). Z0 and T come from the law's own view of it:
        Z0 = |A| T^2 / N with the augmented command of eq. 11 (so the solar differential is
        included) and T = R / V_c."""
        a1, _ = augmented_pn_command(nav, 1.0, dynamics)
        big_t = float(jnp.linalg.norm(nav.r) / closing_speed(-nav.r, -nav.v))
        return pulse_train_estimate(
            zem0_m=float(jnp.linalg.norm(a1)) * big_t**2,
            tgo0_s=big_t,
            n0=float(self.n0),
            k=float(self.k),
            n_min=float(self.n_min),
            a_on_mps2=float(self.a_on_mps2),
            a_off_mps2=float(self.a_off_mps2),
            coast_s=coast_s,
            engine_accel_mps2=engine_accel_mps2,
            impulse_bit_mps=impulse_bit_mps,
        )


def trigger_scale(thrust_n, mass_kg, pulse_width_s, n_min, coast_s):
    """a_ref = n_min q / t_coast with q = F tau / m the minimum impulse bit, m/s^2.

    One pulse perpendicular to the LOS at time-to-go t_go changes the PN command by
    N q / t_go; a_ref is that change for the minimum gain at the start of the coast. A command
    below it asks for less than one pulse can deliver cleanly at the last firing opportunity,
    and its zero-effort miss a_ref t_coast^2 / n_min equals the miss one pulse moves there.
    """
    return n_min * thrust_n * pulse_width_s / mass_kg / coast_s


class PulseTrainEstimate(NamedTuple):
    """Closed-form cost of a pulse-fired PN law, error-free (see ``pulse_train_estimate``)."""

    dv_mps: float  # total Δv
    dv_first_mps: float  # the first pulse train (at t = 0)
    trains: int  # pulse trains (trigger ignitions), first one included
    train_tgo_s: tuple[float, ...]  # time to go at each later train's ignition
    residual_zem_m: float  # zero-effort miss left after the last train
    chatter_tgo_s: float  # below this time to go a train may reverse instead of stopping


def pulse_train_estimate(
    zem0_m: float,
    tgo0_s: float,
    n0: float,
    k: float,
    n_min: float,
    a_on_mps2: float,
    a_off_mps2: float,
    coast_s: float,
    engine_accel_mps2: float = math.inf,
    impulse_bit_mps: float = 0.0,
) -> PulseTrainEstimate:
    """Δv and pulse trains of the Schmitt-triggered law of eqs. 11-12, error-free, in closed form.

    Model: straight-line relative motion (t_go = R / V_c falls at 1 s/s, so N(t_go) =
    max(N_min, N0 (t_go/T)^k)); the command is A = N Z / t_go^2 with Z the zero-effort miss;
    while the trigger is on the engine fires at ``engine_accel_mps2`` (time average over
    pulses) perpendicular to the LOS, and Δv spent at time to go t_go removes t_go of miss
    per m/s. Then:

    * the first train runs from t = 0 until A = a_off: it leaves Z1 = a_off t_e^2 / N(t_e)
      (t_e its end) and costs (Z0 - Z1) / (T - tau/2) for a burn of duration tau;
    * with k = 0 or k >= 2 the command does not grow while coasting until N reaches its end
      value N_e (N0 if k = 0, else N_min); from then on A = N_e Z / t_go^2 reaches a_on at
      t_go1 = sqrt(N_e Z1 / a_on), and each train leaves Z / rho (rho = a_on / a_off) one
      factor sqrt(rho) of time to go later: the i-th train (t_go = t_go1 rho^(-i/2)) costs
      Z1 rho^-i (1 - 1/rho) / t_go, a geometric series cut at the coast. Untruncated it sums
      to sqrt(Z1 a_on / N_e) (1 + rho^-1/2).

    Impulsive and uncut (T >> coast): Δv = Z0/T + a_off T [(1 + sqrt(rho)) / sqrt(N0 N_e) - 1/N0].
    Every law pays the impulsive minimum Z0/T plus a term of order a_off T, and which of two
    laws is cheaper depends on rho: variable N (N0 = 8, k = 2) minus constant N = 3 is
    a_off T (1/8 - sqrt(rho)/12), so the variable law is the cheaper one only for rho > 2.25.

    Not modelled: the impulse bit (a train ends up to one pulse below a_off, which delays the
    next train), gravity gradients, and chatter: once N_e q / t_go > 2 a_off (``impulse_bit_mps``
    = q) one pulse can drive the command from above a_off to below -a_off, so trains at a
    time to go below ``chatter_tgo_s`` may alternate direction pulse after pulse (constant
    N = 8 in Table 3); the estimate is a lower bound there.

    Args: zem0_m, tgo0_s: Z0 and T at t = 0 (m, s); n0, k, n_min: eq. 12; a_on_mps2,
    a_off_mps2: trigger thresholds; coast_s: no firing in the last ``coast_s`` seconds;
    engine_accel_mps2: mean acceleration while the trigger is on (inf: impulsive trains);
    impulse_bit_mps: one pulse's Δv q (only for ``chatter_tgo_s``).
    """
    if not (k == 0 or k >= 2):
        raise ValueError(f"k = {k}: the estimate covers k = 0 and k >= 2 only")
    if not 0 < a_off_mps2 <= a_on_mps2:
        raise ValueError("trigger thresholds: need 0 < a_off <= a_on")
    big_t = float(tgo0_s)
    n_of = lambda tgo: max(n_min, n0 * (tgo / big_t) ** k)  # noqa: E731
    n_end = n0 if k == 0 else n_min
    rho = a_on_mps2 / a_off_mps2
    # First train: fixed point of its duration tau (impulsive when the engine is infinite).
    if n0 * zem0_m / big_t**2 < a_on_mps2:
        z1, dv1, t_end = zem0_m, 0.0, big_t
        trains = 0
    else:
        tau = 0.0
        for _ in range(50):
            t_end = big_t - tau
            z1 = min(zem0_m, a_off_mps2 * t_end**2 / n_of(t_end))
            dv1 = (zem0_m - z1) / (big_t - 0.5 * tau)
            tau_new = dv1 / engine_accel_mps2
            if abs(tau_new - tau) < 1e-9 * big_t:
                break
            tau = tau_new
        trains = 1
    dv, z, tgos = dv1, z1, []
    tgo = math.sqrt(n_end * z1 / a_on_mps2)
    tgo = min(tgo, t_end)
    while tgo > coast_s and z > 0.0:
        removed = z * (1.0 - 1.0 / rho)
        dv += removed / tgo
        z -= removed
        tgos.append(tgo)
        tgo /= math.sqrt(rho)
    chatter = n_end * impulse_bit_mps / (2.0 * a_off_mps2)
    return PulseTrainEstimate(dv, dv1, trains + len(tgos), tuple(tgos), z, chatter)
