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


__all__ = ["schmitt_trigger"]
