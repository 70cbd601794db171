"""Pieces every single-trajectory simulator shares: the outcome's status and the trace shape.

A simulator returns ``(outcome, trace)``: ``outcome`` a NamedTuple whose first field is
``status`` (a :class:`~gnc_jax.Status` code), ``trace`` a NamedTuple of time series or ``None``.
"""

import jax
import jax.numpy as jnp

from .._status import Status, all_finite


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
    """``lax.scan`` of ``step`` over ``n`` events (images), in blocks of ``block`` events:
    ``block_inputs(b, length)`` gives the scan inputs of block ``b`` (``length`` events, the
    last block may be shorter), e.g. the normals of all its events drawn at once. Returns the
    carry and the trace (event-major, ``None`` when ``step`` records nothing).

    Why blocks: jax's threefry hash runs as a five-trip loop on CPU, whose fixed cost per call
    a block shares between its events (the intercept's one normal per 1 s image). For the
    impactor's eight normals per 15 s image, blocks of 64 images measured 1-2 % faster only,
    so it draws per image."""

    def run(carry, b, length=block):
        return jax.lax.scan(step, carry, block_inputs(b, length))

    n_full, rest = divmod(n, block)
    traces = []
    if n_full:
        carry, rec = jax.lax.scan(run, carry, jnp.arange(n_full))
        traces.append(flatten_trace(rec))
    if rest:
        carry, rec = run(carry, jnp.asarray(n_full), rest)
        traces.append(rec)
    if traces[0] is None:
        return carry, None
    return carry, jax.tree_util.tree_map(lambda *x: jnp.concatenate(x), *traces)


def zeros_like_fields(cls, **given):
    """A NamedTuple ``cls`` of loop counters: the ``given`` fields, every other one a float64
    zero scalar (counters that must be integers are passed in ``given``)."""
    z = jnp.zeros(())
    return cls(**{name: given.get(name, z) for name in cls._fields})


__all__ = ["with_status", "flatten_trace", "scan_in_blocks", "zeros_like_fields"]
