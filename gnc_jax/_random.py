"""Random streams of one run: every kind of draw has its own ``jax.random.fold_in`` stream.

A run's key is split by an integer stream identifier per kind of draw (delivery error,
knowledge error, images, control steps, ...), so adding a new kind of draw never changes the
others, and a per-event stream (image ``i``) is folded once more by the event's index.

Every draw of a simulation goes through :func:`normal` or :func:`uniform` of a key derived by
:func:`stream_key` or :func:`fold_in`. Given a plain key they are ``jax.random``'s own
functions. Given a :class:`DrawKey` (the error budget, :mod:`gnc_jax.budget`) they draw from
two keys and route each error source's draws: from the first key or the second, scaled by a
per-source factor (0 turns a source off, and the derivative with respect to the factor at 0 is
the run's linearised response to that source's draws).
"""

import math

import equinox as eqx
import jax
import jax.extend.random as jax_random
import jax.numpy as jnp
import numpy as np

from ._types import Array, Bool, Float, PRNGKeyArray

INDEX = "*"
"""A traced fold-in (an event index) in a :class:`DrawKey` path."""


class DrawKey(eqx.Module):
    """Two run keys and the routing of each error source's draws between them.

    Attributes:
        a, b: the run keys (a: the study's run key; b: the paired run's).
        from_b: per source, take its draws from ``b`` instead of ``a``.
        scale: per source, the factor its standard draws are multiplied by (1: as drawn).
        layout: static ``((path, spec), ...)``: a draw's path (the stream identifiers folded
            in, :data:`INDEX` for a traced index) and its source: an int (the whole draw) or
            ``((lo, hi, source), ...)`` slices of the draw's last axis.
        path: the fold-ins applied so far.
    """

    a: PRNGKeyArray
    b: PRNGKeyArray
    from_b: Bool[Array, " sources"]
    scale: Float[Array, " sources"]
    layout: tuple = eqx.field(static=True)
    path: tuple = eqx.field(static=True, default=())


def run_key(seed: int, index) -> PRNGKeyArray:
    """The key of run ``index`` of a study with root seed ``seed``: ``fold_in(root, index)``,
    so a run's draws never depend on the batch, the chunking, the devices or the workers."""
    return jax.random.fold_in(jax.random.key(jnp.asarray(seed, dtype=jnp.uint32)), index)


class DrawPlan(eqx.Module):
    """The routing of a whole study's draws: run ``i`` gets the :class:`DrawKey` of the
    runs ``i`` of the studies of seeds ``seed_a`` and ``seed_b`` (:func:`plan_key`)."""

    seed_a: Array
    seed_b: Array
    from_b: Bool[Array, " sources"]
    scale: Float[Array, " sources"]
    layout: tuple = eqx.field(static=True)

    def key(self, index) -> DrawKey:
        a, b = run_key(self.seed_a, index), run_key(self.seed_b, index)
        return DrawKey(a, b, self.from_b, self.scale, self.layout)


def plan_key(seed, index):
    """Run ``index``'s key: :func:`run_key` of a root seed, or a :class:`DrawPlan`'s key."""
    return seed.key(index) if isinstance(seed, DrawPlan) else run_key(seed, index)


def fold_in(key, data, indexed: bool = False):
    """``jax.random.fold_in`` of a plain key or of both keys of a :class:`DrawKey` (whose
    path records ``data``, or :data:`INDEX` when it is traced or ``indexed``)."""
    if not isinstance(key, DrawKey):
        return jax.random.fold_in(key, data)
    step = data if isinstance(data, int) and not indexed else INDEX
    return DrawKey(
        jax.random.fold_in(key.a, data),
        jax.random.fold_in(key.b, data),
        key.from_b,
        key.scale,
        key.layout,
        key.path + (step,),
    )


def stream_key(key: PRNGKeyArray, stream: int, index=None) -> PRNGKeyArray:
    """The key of draw kind ``stream`` (and of its ``index``-th event when given)."""
    k = fold_in(key, stream)
    return k if index is None else fold_in(k, index, indexed=True)


def _sources(key: DrawKey, shape) -> np.ndarray:
    """The source index of each element of a draw of ``shape`` at ``key.path`` (static)."""
    for path, spec in key.layout:
        if tuple(path) == key.path:
            if isinstance(spec, int):
                return np.full(shape, spec)
            out = np.full(shape[-1:], -1)
            for lo, hi, source in spec:
                out[lo:hi] = source
            if (out < 0).any():
                raise ValueError(f"draw {key.path}: elements {np.flatnonzero(out < 0)} undeclared")
            return np.broadcast_to(out, shape)
    raise ValueError(f"draw at stream path {key.path}: no declared error source")


def _routed(key: DrawKey, draw, shape):
    xa, xb = draw(key.a), draw(key.b)
    src = _sources(key, xa.shape)
    return jnp.where(key.from_b[src], xb, xa) * key.scale[src].astype(xa.dtype)


def normal(key, shape=(), dtype=None, bits_once=None) -> Float[Array, "..."]:
    """Standard normal draws (``jax.random.normal``; routed for a :class:`DrawKey`).

    ``bits_once``: for float32 draws, how their random bits are computed (``bits_once(fn)``
    returns ``fn()``): a batched caller computes them once into memory
    (:func:`~gnc_jax._numerics.computed_once`) apart from their transformation to normals,
    which XLA otherwise fuses with a :func:`written_out` hash into one slower kernel. The
    same numbers either way.
    """
    kw = {} if dtype is None else {"dtype": dtype}
    if bits_once is None:
        draw = lambda k: jax.random.normal(k, shape, **kw)  # noqa: E731
    elif dtype != jnp.float32:
        raise ValueError(f"normal(bits_once=...) draws float32 only, not {dtype}")
    else:
        draw = lambda k: _normal32(bits_once(lambda: jax.random.bits(k, shape, jnp.uint32)))  # noqa: E731
    if not isinstance(key, DrawKey):
        return draw(key)
    return _routed(key, draw, shape)


def _normal32(bits):
    """``jax.random.normal``'s float32 normals of their 32-bit random ``bits``: the uniform
    draw on (-1, 1) from the top 23 bits, then sqrt(2) erf^-1."""
    one = np.float32(1.0)
    mantissa = jax.lax.shift_right_logical(bits, np.uint32(32 - 23)) | one.view(np.uint32)
    floats = jax.lax.bitcast_convert_type(mantissa, jnp.float32) - one
    lo = np.nextafter(np.float32(-1.0), np.float32(0.0))
    u = jax.lax.max(lo, floats * (one - lo) + lo)
    return np.float32(np.sqrt(2.0)) * jax.lax.erf_inv(u)


def uniform(key, shape=(), minval=0.0, maxval=1.0) -> Float[Array, "..."]:
    """Uniform draws (``jax.random.uniform``); for a :class:`DrawKey`, routed and scaled
    about the interval's centre (0 for the symmetric intervals the simulations draw)."""
    if not isinstance(key, DrawKey):
        return jax.random.uniform(key, shape, minval=minval, maxval=maxval)
    centre = 0.5 * (minval + maxval)
    draw = lambda k: jax.random.uniform(k, shape, minval=minval, maxval=maxval) - centre  # noqa: E731
    return centre + _routed(key, draw, shape)


_THREEFRY = jax_random.threefry_prng_impl
_ROTATIONS = ((13, 15, 26, 6), (17, 29, 16, 24))


def _threefry2x32(k1, k2, x1, x2):
    """The Threefry-2x32 hash (20 rounds; Salmon et al. 2011) of the counts ``(x1, x2)`` under
    the key ``(k1, k2)``, its rounds written out: the arithmetic of ``jax.random``'s own."""
    ks = (k1, k2, k1 ^ k2 ^ np.uint32(0x1BD11BDA))
    x0, x1 = x1 + ks[0], x2 + ks[1]
    for n in range(5):
        for r in _ROTATIONS[n % 2]:
            x0 = x0 + x1
            x1 = ((x1 << np.uint32(r)) | (x1 >> np.uint32(32 - r))) ^ x0
        x0 = x0 + ks[(n + 1) % 3]
        x1 = x1 + ks[(n + 2) % 3] + np.uint32(n + 1)
    return x0, x1


def _written_out_bits(key, bit_width, shape):
    n = math.prod(shape)
    if bit_width != 32 or n >= 2**32 or not jax.config.jax_threefry_partitionable:
        return _THREEFRY.random_bits(key, bit_width, shape)
    counts = jax.lax.iota(np.uint32, n).reshape(shape)
    hi, lo = _threefry2x32(key[0], key[1], jnp.zeros_like(counts), counts)
    return hi ^ lo


def _written_out_fold_in(key, data):
    data = jnp.asarray(data, jnp.uint32)
    return jnp.stack(_threefry2x32(key[0], key[1], jnp.zeros_like(data), data))


_WRITTEN_OUT = jax_random.define_prng_impl(
    key_shape=_THREEFRY.key_shape,
    seed=_THREEFRY.seed,
    split=_THREEFRY.split,
    random_bits=_written_out_bits,
    fold_in=_written_out_fold_in,
    name="threefry2x32_written_out",
    tag="fry_w",
)


def written_out(key):
    """``key`` (a threefry key, jax's default, or both keys of a :class:`DrawKey`) drawing the
    same random numbers from the hash written out as elementwise operations.

    Its fold-ins and 32-bit draws are jax's threefry bit for bit (other draws are jax's own).
    On the CPU jax runs the hash as a loop of five trips, each a few kernels and copies of the
    loop's state, for every draw; written out, XLA fuses a draw's hash into one kernel. Draw
    its float32 normals with :func:`normal`'s ``bits_once`` (the hash and the inverse error
    function fused into one kernel measured slower than jax's loop).
    """
    if isinstance(key, DrawKey):
        a, b = written_out(key.a), written_out(key.b)
        return DrawKey(a, b, key.from_b, key.scale, key.layout, key.path)
    return jax.random.wrap_key_data(jax.random.key_data(key), impl=_WRITTEN_OUT)


def stream_normal(key: PRNGKeyArray, stream: int, shape=(3,)) -> Float[Array, "..."]:
    """Standard normal draws of shape ``shape`` from stream ``stream`` of ``key``."""
    return normal(stream_key(key, stream), shape)


def stream_uniform(key, stream: int, shape=(), minval=0.0, maxval=1.0) -> Float[Array, "..."]:
    """Uniform draws of shape ``shape`` from stream ``stream`` of ``key``."""
    return uniform(stream_key(key, stream), shape, minval, maxval)


__all__ = [
    "DrawKey",
    "DrawPlan",
    "plan_key",
    "fold_in",
    "normal",
    "run_key",
    "stream_key",
    "stream_normal",
    "stream_uniform",
    "uniform",
    "written_out",
]
