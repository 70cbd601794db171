"""Random streams of one run: every kind of draw has its own ``jax.random.fold_in`` stream.

A run's key is split by an integer stream identifier per kind of draw (delivery error,
knowledge error, images, control steps, ...), so adding a new kind of draw never changes the
others, and a per-event stream (image ``i``) is folded once more by the event's index.
"""

import jax

from ._types import Array, Float, PRNGKeyArray


def stream_key(key: PRNGKeyArray, stream: int, index=None) -> PRNGKeyArray:
    """The key of draw kind ``stream`` (and of its ``index``-th event when given)."""
    k = jax.random.fold_in(key, stream)
    return k if index is None else jax.random.fold_in(k, index)


def stream_normal(key: PRNGKeyArray, stream: int, shape=(3,)) -> Float[Array, "..."]:
    """Standard normal draws of shape ``shape`` from stream ``stream`` of ``key``."""
    return jax.random.normal(stream_key(key, stream), shape)


__all__ = ["stream_key", "stream_normal"]
