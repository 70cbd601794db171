"""Random streams of one run: every kind of draw has its own ``jax.random.fold_in`` stream.

A run's key is split by an integer stream identifier per kind of draw (delivery error,
knowledge error, images, control steps, ...), so adding a new kind of draw never changes the
others, and a per-event stream (image ``i``) is folded once more by the event's index.
"""

import jax
import jax.numpy as jnp

from ._types import Array, Float, PRNGKeyArray


def run_key(seed: int, index) -> PRNGKeyArray:
    """The key of run ``index`` of a study with root seed ``seed``: ``fold_in(root, index)``,
    so a run's draws never depend on the batch, the chunking, the devices or the workers."""
    return jax.random.fold_in(jax.random.key(jnp.asarray(seed, dtype=jnp.uint32)), index)


def stream_key(key: PRNGKeyArray, stream: int, index=None) -> PRNGKeyArray:
    """The key of draw kind ``stream`` (and of its ``index``-th event when given)."""
    k = jax.random.fold_in(key, stream)
    return k if index is None else jax.random.fold_in(k, index)


def stream_normal(key: PRNGKeyArray, stream: int, shape=(3,)) -> Float[Array, "..."]:
    """Standard normal draws of shape ``shape`` from stream ``stream`` of ``key``."""
    return jax.random.normal(stream_key(key, stream), shape)


__all__ = ["run_key", "stream_key", "stream_normal"]
