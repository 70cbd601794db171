"""The bank-angle actuator: roll with finite rate and acceleration."""

import math
from typing import NamedTuple

import equinox as eqx
import jax.numpy as jnp

from ..._types import Scalar


class BankActuatorState(NamedTuple):
    """Bank angle (rad) and bank rate (rad/s) actually flown."""

    bank: Scalar
    bank_rate: Scalar


class BankActuator(eqx.Module):
    """Roll of the bank angle with finite rate and acceleration (reaction-control limits).

    Defaults: 20 deg/s and 10 deg/s^2, typical of the Apollo/Orion reaction control system in
    roll (a 180 deg reversal then takes about 11 s). ``way`` chooses the way round of a
    reversal (the angle flown is kept in (-180, 180] deg but with ``"through_lift_up"``):

    - ``"shortest"`` (the default): to a lift-down command (beyond 90 deg) the shorter way
      round, which never crosses lift-up to reach lift-down; to a lift-up command through
      lift-up (the straight path in sigma), a roll under way keeping its way round when the
      command changes.
    - ``"lift_down_pairs"``: the straight path in sigma (through lift-up), except between two
      lift-down banks, through lift-down; a roll under way keeps its way round (kept for
      comparison).
    - ``"through_lift_up"``: always the straight path.

    Measured: rolling a lift-down reversal through lift-up lofts a capsule entering shallow
    (-5.6 deg) out of the atmosphere (5 of 256 runs); rolling every reversal the shorter way
    round sinks it at the bottom of its first dip when the bank is near 90 deg (6 of 1000
    nominal runs). With ``"lift_down_pairs"``, reversals commanded in quick succession at
    the bottom of a shallow (-5.3 deg) entry's dip, a roll under way keeping its way, turned
    the capsule through lift-up a whole revolution and lofted it out (the first roll from a
    lift-up hold to a lift-down command crossed lift-up too).

    Attributes:
        max_rate: rad/s.
        max_acceleration: rad/s^2.
        way: ``"shortest"``, ``"lift_down_pairs"`` or ``"through_lift_up"`` (static).
    """

    max_rate: Scalar = eqx.field(default=math.radians(20.0), converter=jnp.asarray)
    max_acceleration: Scalar = eqx.field(default=math.radians(10.0), converter=jnp.asarray)
    way: str = eqx.field(default="shortest", static=True)

    def init(self, bank: Scalar) -> BankActuatorState:
        """At rest at ``bank`` (rad)."""
        bank = jnp.asarray(bank, dtype=float)
        return BankActuatorState(bank, jnp.zeros_like(bank))

    def step(self, state: BankActuatorState, command: Scalar, dt: Scalar) -> BankActuatorState:
        """Advance (sigma, sigma_dot) by ``dt`` (s) towards ``command`` (rad).

        The target rate is the largest that can still stop at the command,
        sign(e) min(max_rate, sqrt(2 a_max |e|), |e| / dt) with e = command - sigma (time-optimal
        bang-bang with a braking curve); the rate moves towards it by at most a_max dt, and
        sigma advances with the new rate (semi-implicit Euler). So |sigma_dot| <= max_rate and
        |delta sigma_dot| <= a_max dt hold exactly at every step.
        """
        error = command - state.bank
        if self.way != "through_lift_up":
            # Two ways round differ when |error| > pi: the straight one (through lift-up) and
            # the wrapped one (through lift-down).
            wrapped = jnp.remainder(error + math.pi, 2.0 * math.pi) - math.pi
            command_down = jnp.abs(command) > 0.5 * math.pi
            rolling = jnp.abs(state.bank_rate) > 0.5 * self.max_rate
            keep = state.bank_rate * wrapped > 0.0  # the roll under way goes the wrapped way
            if self.way == "shortest":
                shorter = jnp.abs(wrapped) < jnp.abs(error)  # a tie goes straight
                way = (command_down & shorter) | (~command_down & rolling & keep)
            else:  # lift_down_pairs
                down = command_down & (jnp.abs(state.bank) > 0.5 * math.pi)
                way = jnp.where(rolling, keep, down)
            error = jnp.where(way, wrapped, error)
        # The floor keeps the gradient of sqrt finite when the command is reached (error 0).
        braking = jnp.sqrt(jnp.maximum(2.0 * self.max_acceleration * jnp.abs(error), 1e-30))
        reachable = jnp.minimum(braking, jnp.abs(error) / dt)
        target_rate = jnp.sign(error) * jnp.minimum(self.max_rate, reachable)
        max_change = self.max_acceleration * dt
        rate = state.bank_rate + jnp.clip(target_rate - state.bank_rate, -max_change, max_change)
        bank = state.bank + rate * dt
        if self.way != "through_lift_up":  # the angle flown in (-pi, pi]
            bank = jnp.where(bank > math.pi, bank - 2.0 * math.pi, bank)
            bank = jnp.where(bank <= -math.pi, bank + 2.0 * math.pi, bank)
        return BankActuatorState(bank, rate)
