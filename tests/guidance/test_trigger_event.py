"""The event relaxation of the Schmitt trigger (``schmitt_trigger_event``): the hard value, and
the derivative of the on-time against finite differences of the hard switch averaged over the
sampling phase (brute force); in the APN closed loop, the hard outcomes unchanged and the
measured failure mode (the hard objective piecewise constant, the gradient off)."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gnc_jax as gj
from gnc_jax import tuning
from gnc_jax.guidance.trigger import schmitt_trigger, schmitt_trigger_event

SLOPE = 0.37  # value change per step on the ramp's flanks


def _ramp(k, phase, peak_step=40.0):
    """A triangular ramp sampled at steps k + phase: up at SLOPE per step, then down."""
    t = k + phase
    return SLOPE * jnp.minimum(t, 2.0 * peak_step - t)


def _on_steps(levels, phase, event):
    """Steps the trigger is on over the ramp (hard value; event tangent when ``event``)."""
    on_level, off_level = levels[0], levels[1]
    values = _ramp(jnp.arange(100.0), phase)

    def body(carry, value):
        on, prev = carry
        if event:
            on = schmitt_trigger_event(value, prev, on, on_level, off_level)
        else:
            on = schmitt_trigger(value, on, on_level, off_level)
        return (on, value), on

    _, on = jax.lax.scan(body, (jnp.zeros(()), jnp.asarray(on_level)), values)
    return on.sum()


def test_event_trigger_is_the_hard_switch():
    levels = jnp.array([9.1, 4.3])
    for phase in np.linspace(0.0, 0.95, 7):
        hard = _on_steps(levels, phase, event=False)
        assert float(_on_steps(levels, phase, event=True)) == float(hard)


def test_event_trigger_gradient_matches_phase_averaged_hard_switch():
    """d(mean on-steps)/d(level) over a uniform sampling phase: the event tangent against
    central differences of the hard count (2,000 phases), and the closed form -1/SLOPE."""
    levels = jnp.array([9.1, 4.3])
    phases = jnp.asarray((np.arange(2000) + 0.5) / 2000)
    hard = jax.jit(jax.vmap(lambda p, lv: _on_steps(lv, p, False), (0, None)))
    grad = jax.vmap(jax.grad(lambda lv, p: _on_steps(lv, p, True)), (None, 0))(levels, phases)
    event = np.asarray(grad.mean(axis=0))
    h = 0.5
    for i in range(2):
        e = np.eye(2)[i] * h
        cd = (float(hard(phases, levels + e).mean()) - float(hard(phases, levels - e).mean())) / (
            2 * h
        )
        assert abs(event[i] - cd) < 0.01 * abs(cd), (i, event[i], cd)
        assert abs(event[i] + 1.0 / SLOPE) < 0.01 / SLOPE
    # the pathwise gradient of the hard switch itself is zero: nothing for a gradient to follow
    zero = jax.grad(lambda lv: _on_steps(lv, 0.3, False))(levels)
    assert np.all(np.asarray(zero) == 0.0)
