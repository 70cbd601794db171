"""The capsule's guidance-law family and the pieces its laws and reference design share.

:class:`AbstractEntryGuidance` is the family base of the capsule (entry) laws: ``nav`` is an
:class:`EntryNav` (navigated state and accelerometer-measured drag and lift), ``ctx`` an
:class:`EntryGuidanceContext` (the on-board model and mission data), ``step`` returns the bank
command in rad.

The on-board predictor and the offline reference design fly the longitudinal
("vertical-plane") problem: lift acts in the vertical plane with the magnitude L cos(sigma),
i.e. the lateral component of a banked lift vector is averaged out by the bank reversals. The
bank magnitude follows a profile of Earth-relative speed.
"""

from typing import ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from ..._numerics import loop_shape
from ..._types import Array, Float, Scalar, Vector3
from ...dynamics.atmosphere import Atmosphere
from ...dynamics.entry import (
    G0,
    EarthModel,
    EntryState,
    EntryStateXYZ,
    EntryVehicle,
    aerodynamic_acceleration,
    altitude,
    earth_relative_velocity,
    earth_relative_velocity_xyz,
    entry_acceleration_xyz,
    gravity_acceleration,
    sensed_load_g,
)
from ...geometry.sphere import central_angle, to_earth_fixed, unit
from ..base import AbstractGuidanceLaw


class EntryModel(eqx.Module):
    """On-board model of the capsule: vehicle, Earth, atmosphere, and the measured ratios of
    actual to modelled drag and lift (1 for the nominal model)."""

    vehicle: EntryVehicle
    earth: EarthModel
    atmosphere: Atmosphere
    drag_ratio: Scalar = eqx.field(default=1.0, converter=jnp.asarray)
    lift_ratio: Scalar = eqx.field(default=1.0, converter=jnp.asarray)

    def scaled_vehicle(self, cos_bank) -> EntryVehicle:
        """Vehicle whose 'lift-up' lift equals the vertical component L cos(sigma)."""
        v = self.vehicle
        return eqx.tree_at(
            lambda x: (x.lift_scale, x.drag_scale),
            v,
            (v.lift_scale * self.lift_ratio * cos_bank, v.drag_scale * self.drag_ratio),
        )

    def vertical_plane_field(self, t, y: EntryState, cos_bank) -> EntryState:
        """d/dt (r, v) with lift L cos(sigma) in the vertical plane."""
        vehicle = self.scaled_vehicle(cos_bank)
        a = gravity_acceleration(y.r, self.earth) + aerodynamic_acceleration(
            y.r, y.v, 0.0, vehicle, self.earth, self.atmosphere
        )
        return EntryState(y.v, a)

    def measured_vehicle(self) -> EntryVehicle:
        """The vehicle with the measured drag and lift ratios applied."""
        return eqx.tree_at(
            lambda x: (x.lift_scale, x.drag_scale),
            self.vehicle,
            (self.vehicle.lift_scale * self.lift_ratio, self.vehicle.drag_scale * self.drag_ratio),
        )

    def load_g(self, y: EntryState) -> Scalar:
        """Sensed load N_g (g) under the model's drag and lift ratios."""
        return sensed_load_g(y.r, y.v, self.measured_vehicle(), self.earth, self.atmosphere)

    def vertical_plane_xyz(self, y: EntryStateXYZ, cos_bank, density=None):
        """:meth:`vertical_plane_field` on components, and the density it used (which may be
        given, see :func:`~gnc_jax.dynamics.entry.entry_acceleration_xyz`)."""
        accel, density = entry_acceleration_xyz(
            y, self.measured_vehicle(), self.earth, self.atmosphere, cos_bank, density=density
        )
        return EntryStateXYZ(y.v, accel), density

    def load_g_xyz(self, density, speed_mps) -> Scalar:
        """Sensed load N_g (g) at a density (kg/m^3) and Earth-relative speed (m/s)."""
        v = self.measured_vehicle()
        c_r = jnp.sqrt(v.c_l**2 + v.c_d**2)
        return 0.5 * density * speed_mps**2 * v.reference_area_m2 * c_r / (v.mass_kg * G0)


class EntryNav(NamedTuple):
    """What the sensors give a capsule law: the navigated state (perfect navigation) and the
    drag and lift accelerations the accelerometers measure, m/s^2 (see :func:`drag_and_lift`)."""

    y: EntryState
    drag_mps2: Scalar
    lift_mps2: Scalar


class EntryGuidanceContext(eqx.Module):
    """Mission data known on board a capsule.

    Attributes:
        model: the nominal vehicle, Earth and atmosphere (ratios 1).
        target_fixed: chute-deploy target, unit vector, Earth-fixed.
        hold_bank_rad: bank held before guidance starts.
        ratio_filter_gain: gain per control step of the measured drag/lift ratio filter.
        pc_every: control steps per predictor-corrector cycle.
        cycle_start: whether this control step starts a predictor-corrector cycle, when the
            caller keeps the clock (a simulator looping over cycles of ``pc_every`` steps: a
            flag it knows for every run at once, so that under ``vmap`` the corrector stays a
            ``lax.cond`` instead of running, masked, at every step); ``None``: the law counts
            its own steps (``step % pc_every == 0``), the same schedule. A Python ``bool``
            when the caller's loop is unrolled: the branch is then chosen at trace time.
        loop_kind: ``"lax"``: the corrector's rounds are a ``lax.while_loop`` (evaluation,
            forward mode); ``"checkpointed"``: the same, the solution differentiated in
            reverse mode by the implicit function theorem (one prediction reversed, with
            equinox's checkpointed ``while_loop``); ``"held"``: the same solve, its solution
            passing no derivative (reverse mode when what is differentiated acts only after
            the corrector's last cycle); ``"fixed"``: a masked ``lax.scan`` of the most
            rounds a solve can take (the same arithmetic under ``vmap``, no loop predicate).
    """

    model: EntryModel
    target_fixed: Vector3
    hold_bank_rad: Scalar
    ratio_filter_gain: Scalar
    pc_every: int = eqx.field(static=True, default=4)
    cycle_start: Array | bool | None = None
    loop_kind: str = eqx.field(static=True, default="lax")


class EntryGuidanceLog(NamedTuple):
    """Diagnostics a capsule law keeps in its state's ``log`` for the run's outcome and trace.

    Attributes:
        predictions: predictions an early-exit corrector would have made (whole flight).
        cycle_predictions_max: the most of them in one corrector cycle.
        pc_cycles, corrector_failures: corrector cycles run, and those not ``ok``.
        reversals: bank reversals.
        predictor_steps: RK4 steps of all predictions.
        t_guidance_s, t_kepler_s, t_switch_s: times guidance started, the Kepler phase began,
            the second entry began (0 if never).
        switch: (speed m/s, altitude m, Ḣ m/s, ground range flown from ``entry_r_m`` m) at the
            switch point (zeros if never).
        skip_apogee_m: highest altitude of the Kepler phase.
        skipped_out: the vehicle climbed above the law's skip-out altitude while guided.
        entry_r_m: ECI position at ``init`` (t = 0), where the switch range is measured from.
        step_predictions, step_miss_m: predictions and corrector residual of this step's
            corrector cycle (0 without one).
    """

    predictions: Array
    cycle_predictions_max: Array
    pc_cycles: Array
    corrector_failures: Array
    reversals: Array
    predictor_steps: Scalar
    t_guidance_s: Scalar
    t_kepler_s: Scalar
    t_switch_s: Scalar
    switch: Float[Array, "4"]
    skip_apogee_m: Scalar
    skipped_out: Array
    entry_r_m: Vector3
    step_predictions: Array
    step_miss_m: Scalar


class AbstractEntryGuidance(AbstractGuidanceLaw):
    """Family base of the capsule (skip-entry) guidance laws.

    ``init(nav: EntryNav, ctx: EntryGuidanceContext) -> state`` and
    ``step(state, nav, t, ctx) -> (bank command in rad, state)``. The capsule simulator reads
    from the state ``log`` (an :class:`EntryGuidanceLog`), ``phase``, ``pulled_up``,
    ``sigma_0``, ``bank_offset``, ``drag_ratio``, ``lift_ratio`` and ``last_status`` (a
    :class:`~gnc_jax.root_finding.RootStatus` code) for the outcome and the trace.

    What the capsule system needs from a law it asks through the family's class methods,
    never by the law's field names: whether the law tracks a designed second-entry reference
    (:meth:`reference_switch_load_g`; the system then designs it for the scenario), the
    largest load its predictions fly (:meth:`predicted_load_limit_g`, which bounds the direct
    reach), the law's checks against the entry interface (:meth:`check_entry`) and the
    predictor's cost (:meth:`prediction_steps`). It hands the law's ``from_config`` an
    :class:`~gnc_jax.guidance.entry.reference.EntryMission` (SI units, the reference included)
    as ``ctx``.
    """

    laws: ClassVar[dict[str, type]] = {}

    @classmethod
    def reference_switch_load_g(cls, section: dict) -> float | None:
        """The load (g) that places the switch point of the second-entry reference this law
        tracks, read from the law's scenario ``section``; ``None`` (the default): the law
        tracks no designed reference."""
        return None

    @classmethod
    def entry_mode_of(cls, section: dict) -> str:
        """The entry mode the law's scenario ``section`` asks of the reference design:
        "skip", "direct" or "auto" (the design chooses from the reach). Default: "skip"."""
        return "skip"

    @classmethod
    def predicted_load_limit_g(cls, section: dict) -> float | None:
        """The largest sensed load (g) the law's on-board predictions fly, read from its
        scenario ``section``: a predicted profile beyond it is not one the law commands, so
        the direct reach (:mod:`~gnc_jax.guidance.entry.direct`) leaves out the constant-bank
        landings whose load exceeds it. ``None`` (the default): no such limit."""
        return None

    @classmethod
    def check_entry(cls, section: dict, entry_altitude_m: float) -> None:
        """Cross-field checks of the law's validated ``section`` against the capsule's entry
        interface altitude (m), which the capsule system's checks hand it; raise
        :class:`~gnc_jax.schema.ScenarioError` with one line. Default: none."""

    @classmethod
    def prediction_steps(cls, section: dict, flight_s: float) -> float | None:
        """RK4 steps the law's on-board predictions take in one corrector cycle of a flight
        of about ``flight_s`` seconds, estimated from its validated ``section`` alone (the
        predictor's share of the capsule system's ``steps_per_run``); ``None`` (the default):
        the law predicts nothing."""
        return None


class FlightVariables(NamedTuple):
    """Longitudinal variables of the guidance (seed 003 §2-3), Earth-relative."""

    speed_mps: Scalar
    fpa_rad: Scalar
    altitude_m: Scalar
    hdot_mps: Scalar


def flight_variables(y: EntryState, earth: EarthModel) -> FlightVariables:
    v_rel = earth_relative_velocity(y.r, y.v, earth)
    speed = jnp.linalg.norm(v_rel)
    hdot = jnp.dot(unit(y.r), v_rel)
    return FlightVariables(
        speed, jnp.arcsin(jnp.clip(hdot / speed, -1, 1)), altitude(y.r, earth), hdot
    )


def altitude_speed_hdot(y: EntryStateXYZ, earth: EarthModel) -> tuple[Scalar, Scalar, Scalar]:
    """Altitude (m), Earth-relative speed (m/s) and Ḣ (m/s) of a component state: the
    :func:`flight_variables` an inner loop needs, without trigonometry."""
    r2 = y.r[0] ** 2 + y.r[1] ** 2 + y.r[2] ** 2
    inv_r = jax.lax.rsqrt(r2)
    v_rel = earth_relative_velocity_xyz(y.r, y.v, earth)
    speed = jnp.sqrt(v_rel[0] ** 2 + v_rel[1] ** 2 + v_rel[2] ** 2)
    hdot = (y.r[0] * v_rel[0] + y.r[1] * v_rel[1] + y.r[2] * v_rel[2]) * inv_r
    return r2 * inv_r - earth.equatorial_radius_m, speed, hdot


def drag_and_lift(
    y: EntryState, vehicle: EntryVehicle, earth: EarthModel, atmosphere: Atmosphere
) -> tuple[Scalar, Scalar]:
    """Drag and lift accelerations (m/s^2) of ``vehicle`` at ``y``: the aerodynamic
    acceleration's components against and normal to the Earth-relative velocity, which is what
    body-mounted accelerometers measure."""
    a = aerodynamic_acceleration(y.r, y.v, 0.0, vehicle, earth, atmosphere)
    v_rel = y.v - jnp.cross(earth.angular_velocity(), y.r)
    drag = -jnp.dot(a, unit(v_rel))
    lift = jnp.linalg.norm(a + drag * unit(v_rel))
    return drag, lift


def drag_load_g(y: EntryState, model: EntryModel) -> Scalar:
    """Tangential (drag) load N_gx = D / (m g0), g."""
    v = model.vehicle
    v_rel = earth_relative_velocity(y.r, y.v, model.earth)
    rho = model.atmosphere.density(altitude(y.r, model.earth))
    q = 0.5 * rho * jnp.dot(v_rel, v_rel)
    return q * v.reference_area_m2 * v.c_d * model.drag_ratio / (v.mass_kg * G0)


def perturb_switch_state(
    y: EntryState, earth: EarthModel, d_speed, d_fpa, d_altitude
) -> EntryState:
    """Shift a state's Earth-relative speed (m/s), flight-path angle (rad) and altitude (m),
    keeping its position on the ground and its heading: the variables of seed 003 eq. 10."""
    r_hat = unit(y.r)
    v_rel = earth_relative_velocity(y.r, y.v, earth)
    speed = jnp.linalg.norm(v_rel)
    hdot = jnp.dot(r_hat, v_rel)
    fpa = jnp.arcsin(jnp.clip(hdot / speed, -1.0, 1.0))
    horizontal = unit(v_rel - hdot * r_hat)
    new_speed, new_fpa = speed + d_speed, fpa + d_fpa
    r = y.r + d_altitude * r_hat
    v_rel_new = new_speed * (jnp.cos(new_fpa) * horizontal + jnp.sin(new_fpa) * r_hat)
    return EntryState(r, v_rel_new + jnp.cross(earth.angular_velocity(), r))


def ground_range_m(r1: Vector3, t1, r2: Vector3, t2, earth: EarthModel) -> Scalar:
    """Great-circle distance over the rotating Earth between two ECI points at two times, m."""
    u1 = unit(to_earth_fixed(r1, t1, earth.rotation_rate))
    u2 = unit(to_earth_fixed(r2, t2, earth.rotation_rate))
    return earth.equatorial_radius_m * central_angle(u1, u2)


def hermite_crossing(f0, df0, f1, df1, dt, level):
    """Fraction s in [0, 1] of a step at which a cubic Hermite interpolant of f crosses
    ``level`` (f0 above, f1 below it), found by a few Newton steps from the linear guess."""
    s = jnp.clip((f0 - level) / jnp.where(f0 != f1, f0 - f1, 1.0), 0.0, 1.0)

    def newton(_, s):
        h00 = 2 * s**3 - 3 * s**2 + 1
        h10 = s**3 - 2 * s**2 + s
        h01 = -2 * s**3 + 3 * s**2
        h11 = s**3 - s**2
        f = h00 * f0 + h10 * dt * df0 + h01 * f1 + h11 * dt * df1 - level
        d = (
            (6 * s**2 - 6 * s) * f0
            + (3 * s**2 - 4 * s + 1) * dt * df0
            + (-6 * s**2 + 6 * s) * f1
            + (3 * s**2 - 2 * s) * dt * df1
        )
        return jnp.clip(s - f / jnp.where(d != 0, d, 1.0), 0.0, 1.0)

    # Unrolled in a GPU's layout: one kernel instead of a loop (in the corrector's rounds,
    # a loop whose carry XLA copies every round).
    return jax.lax.fori_loop(0, 4, newton, s, unroll=min(loop_shape().unroll, 4))


def hermite_state(y0: EntryState, a0, y1: EntryState, a1, dt, s) -> EntryState:
    """Cubic Hermite interpolation of (r, v) at fraction s of a step of length dt, using the
    accelerations a0, a1 at both ends for v and the velocities for r."""
    h00 = 2 * s**3 - 3 * s**2 + 1
    h10 = s**3 - 2 * s**2 + s
    h01 = -2 * s**3 + 3 * s**2
    h11 = s**3 - s**2
    r = h00 * y0.r + h10 * dt * y0.v + h01 * y1.r + h11 * dt * y1.v
    v = h00 * y0.v + h10 * dt * a0 + h01 * y1.v + h11 * dt * a1
    return EntryState(r, v)
