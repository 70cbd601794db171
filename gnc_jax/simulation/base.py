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


def zeros_like_fields(cls, **given):
    """A NamedTuple ``cls`` of loop counters: the ``given`` fields, every other one a float64
    zero scalar (counters that must be integers are passed in ``given``)."""
    z = jnp.zeros(())
    return cls(**{name: given.get(name, z) for name in cls._fields})


__all__ = ["with_status", "flatten_trace", "zeros_like_fields"]
