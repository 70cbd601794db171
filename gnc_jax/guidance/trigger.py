"""Schmitt trigger: an on/off switch with hysteresis, and its smooth relaxation.

Several laws fire an engine this way: the LOS law of seed 000 §3.3 (|omega| against the
switching curves omega_open / omega_close) and the pulse-fired PN law of seed 004 §2.2 (|A|
against a_on / a_off; Zarchan's strategic-intercept chapter). The state turns on when the
value reaches the on level, off when it falls to the off level, and in between keeps its
previous state.

The relaxation (temperature T) replaces the switch by
s = p_on + (1 - p_on)(1 - p_off) s_prev, p_on = sigmoid((value/on_level - 1)/T),
p_off = sigmoid((1 - value/off_level)/T), in [0, 1]; it tends to the hard logic as T -> 0 and
lets gradients reach the levels (and every gain behind them).

The event relaxation (:func:`schmitt_trigger_event`) keeps the switch hard, value and
hysteresis state alike, and gives each switching event the derivative of its crossing time:
at a step where the state changes, the value crossed its level at the fraction
phi = (level - value_prev) / (value - value_prev) of the step, and the state carries the
tangent -dphi (switching on) or +dphi (switching off), i.e. the on-time the crossing's shift
adds or removes. Its value is the hard logic's exactly; its tangent is nonzero only at the
firing events, so it does not grow with the number of steps.
"""

import jax
import jax.numpy as jnp

from .._types import Scalar


def schmitt_trigger(value, on_prev, on_level, off_level, temperature=None) -> Scalar:
    """Switch state from ``value`` with hysteresis: hard, or relaxed when ``temperature`` is
    given (see the module docstring).

    Hard: 1 when ``value >= on_level``, 0 when ``value <= off_level``, else ``on_prev``.
    """
    if temperature is None:
        return jnp.where(value >= on_level, 1.0, jnp.where(value <= off_level, 0.0, on_prev))
    p_on = jax.nn.sigmoid((value / on_level - 1.0) / temperature)
    p_off = jax.nn.sigmoid((1.0 - value / off_level) / temperature)
    return p_on + (1.0 - p_on) * (1.0 - p_off) * on_prev


def schmitt_trigger_event(value, value_prev, on_prev, on_level, off_level) -> Scalar:
    """Hard Schmitt trigger with the event relaxation's tangent (see the module docstring).

    ``value_prev``: the value at the previous step (no event is taken when it is on the
    far side of the level, e.g. at the first step). ``on_prev`` is read without its tangent:
    the hysteresis state is hard, only the switching steps carry a tangent.
    """
    prev = jax.lax.stop_gradient(on_prev)
    on = schmitt_trigger(value, prev, on_level, off_level)
    switch_on = (on > 0.5) & (prev < 0.5) & (value_prev < on_level)
    switch_off = (on < 0.5) & (prev > 0.5) & (value_prev > off_level)
    level = jnp.where(switch_on, on_level, off_level)
    event = switch_on | switch_off
    step = jnp.where(event, value - value_prev, 1.0)
    phi = jnp.where(event, (level - value_prev) / step, 0.0)
    tangent = phi - jax.lax.stop_gradient(phi)  # 0 in value, dphi in derivative
    return on + jnp.where(switch_on, -tangent, jnp.where(switch_off, tangent, 0.0))


__all__ = ["schmitt_trigger", "schmitt_trigger_event"]
