"""The skeleton every single-trajectory simulator shares, and its pieces.

A simulator returns ``(outcome, trace)``: ``outcome`` a NamedTuple whose first field is
``status`` (a :class:`~gnc_jax.Status` code), ``trace`` a NamedTuple of time series or ``None``.
Every system's ``simulate`` is :func:`closed_loop` of three functions of its own: ``start``
(the run's draws and its initial :class:`LoopState`), ``run`` (its scans) and ``finish`` (the
outcome and its status). The loop's carry is a :class:`LoopState`: what is true, what the
vehicle believes, what the law remembers, what the actuators hold and what the outcome counts,
each a typed part of its own (gymnax's ``EnvState``).
"""

import functools
from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from .._numerics import loop_shape
from .._status import Status, all_finite


class LoopState(NamedTuple):
    """The carry of a closed loop, by kind.

    Attributes:
        truth: the true state (dynamics, mass, the target's ephemeris).
        estimate: what navigation believes (the filter's mean and covariance); ``()`` with
            perfect navigation.
        law: the guidance law's own state (its ``init``/``plan``/``step`` NamedTuple).
        actuator: what the actuators remember between steps (engine on, pointing, the bank
            actually flown); ``()`` when none.
        tally: what the outcome counts along the way (Δv, firings, images used, ...).
    """

    truth: Any
    estimate: Any
    law: Any
    actuator: Any
    tally: Any


def closed_loop(start: Callable, run: Callable, finish: Callable) -> Callable:
    """A system's single-run ``simulate(params, law, key, record=False) -> (outcome, trace)``
    from its three stages, the skeleton written once:

    * ``start(params, law, key) -> (state, draws)``: the initial :class:`LoopState` and the
      run's fixed draws (anything ``run`` and ``finish`` read that does not evolve);
    * ``run(params, law, key, draws, state, record) -> (state, trace)``: the system's scans;
    * ``finish(params, law, key, draws, state) -> outcome``: the outcome, status included
      (:func:`with_status`).

    ``trace`` is returned only when ``record`` (a static flag)."""

    def simulate(params, law, key, record: bool = False):
        state, draws = start(params, law, key)
        state, trace = run(params, law, key, draws, state, record)
        outcome = finish(params, law, key, draws, state)
        return outcome, (trace if record else None)

    return simulate


def with_status(outcome, failures=()):
    """``outcome`` with its ``status`` set: ``nan`` when any field is not finite, else the
    status of the first ``(condition, Status)`` pair in ``failures`` whose condition holds,
    else ``ok``. The order of ``failures`` is the precedence of the statuses."""
    status = jnp.asarray(Status.ok)
    for condition, code in reversed(tuple(failures)):
        status = jnp.where(condition, code, status)
    status = jnp.where(all_finite(outcome), status, Status.nan)
    return outcome._replace(status=status.astype(jnp.int32))


def flatten_trace(trace):
    """Merge the two leading axes of a trace recorded by nested scans (outer x inner steps)
    into one time axis; ``None`` stays ``None``."""
    if trace is None:
        return None
    return jax.tree_util.tree_map(lambda x: x.reshape((-1,) + x.shape[2:]), trace)


def scan_in_blocks(step, carry, n: int, block: int, block_inputs):
    """``lax.scan`` of ``step`` over ``n`` events (images), in blocks of ``block`` events, each
    block checkpointed for reverse mode (``step`` may be too):
    ``block_inputs(b, length)`` gives the scan inputs of block ``b`` (``length`` events, the
    last block may be shorter), e.g. the normals of all its events drawn at once. Returns the
    carry and the trace (event-major, ``None`` when ``step`` records nothing).

    Why blocks: jax's threefry hash runs as a five-trip loop on CPU, whose fixed cost per call
    a block shares between its events (the intercept's one normal per 1 s image). For the
    impactor's eight normals per 15 s image, blocks of 64 images measured 1-2 % faster only,
    so it draws per image."""

    # Each block is checkpointed, and its events by the caller's step: reverse mode keeps one
    # carry per block, and recomputing a block one carry per event, instead of every event's
    # residuals. Without differentiation the checkpoints are inlined: the evaluation is the same.
    def blocks_of(length):
        @functools.partial(jax.checkpoint, prevent_cse=False)
        def run(carry, b):
            return jax.lax.scan(step, carry, block_inputs(b, length), unroll=loop_shape().unroll)

        return run

    n_full, rest = divmod(n, block)
    traces = []
    if n_full:
        carry, rec = jax.lax.scan(blocks_of(block), carry, jnp.arange(n_full))
        traces.append(flatten_trace(rec))
    if rest:
        carry, rec = blocks_of(rest)(carry, jnp.asarray(n_full))
        traces.append(rec)
    if traces[0] is None:
        return carry, None
    return carry, jax.tree_util.tree_map(lambda *x: jnp.concatenate(x), *traces)


__all__ = [
    "LoopState",
    "closed_loop",
    "with_status",
    "flatten_trace",
    "scan_in_blocks",
]
