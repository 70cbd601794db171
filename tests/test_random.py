"""The random streams' written-out hash against the Threefry-2x32 reference vectors and jax's
own threefry: the same bits, draw for draw."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from gnc_jax._random import DrawKey, _threefry2x32, fold_in, normal, written_out


@pytest.mark.parametrize(
    "key, count, expected",
    [  # Random123's known-answer vectors for threefry2x32_20 (Salmon et al. 2011)
        ((0, 0), (0, 0), (0x6B200159, 0x99BA4EFE)),
        ((0xFFFFFFFF,) * 2, (0xFFFFFFFF,) * 2, (0x1CB996FC, 0xBB002BE7)),
        ((0x13198A2E, 0x03707344), (0x243F6A88, 0x85A308D3), (0xC4923A9C, 0x483DF7A0)),
    ],
)
def test_hash_matches_the_reference_vectors(key, count, expected):
    k, x = np.uint32(key), np.uint32(count)
    got = _threefry2x32(jnp.uint32(k[0]), jnp.uint32(k[1]), jnp.uint32(x[0]), jnp.uint32(x[1]))
    assert tuple(int(v) for v in got) == expected


def _bits(x):
    x = np.asarray(x)
    return x.view(np.dtype(f"u{x.dtype.itemsize}")) if x.dtype.kind == "f" else x


DRAWS = {
    "normal32": lambda k: jax.random.normal(k, (8,), jnp.float32),
    "normal64": lambda k: jax.random.normal(k, (3, 5)),
    "uniform": lambda k: jax.random.uniform(k, (7,)),
    "bits8": lambda k: jax.random.bits(k, (5,), jnp.uint8),
    "bits64": lambda k: jax.random.bits(k, (2, 2), jnp.uint64),
    "split": lambda k: jax.random.key_data(jax.random.split(k, 3)),
}


@pytest.mark.parametrize("draw", sorted(DRAWS))
def test_written_out_key_draws_what_jax_draws(key, draw):
    """Fold-ins then a draw, eager and batched under jit (where the hash is lowered)."""
    fn = DRAWS[draw]

    def chain(k, i):
        return fn(jax.random.fold_in(jax.random.fold_in(k, 7), i))

    for i in (0, 1, 2**31 + 5):
        assert np.array_equal(_bits(chain(key, i)), _bits(chain(written_out(key), i)))
    batched = jax.jit(jax.vmap(chain, in_axes=(None, 0)))
    index = jnp.arange(64)
    assert np.array_equal(_bits(batched(key, index)), _bits(batched(written_out(key), index)))


def test_written_out_draw_key_keeps_its_routing(key):
    """Both keys of a DrawKey written out, its path and routing kept: the same routed draws."""
    dk = DrawKey(
        key, jax.random.fold_in(key, 1), jnp.array([True]), jnp.array([0.5]), ((("*",), 0),)
    )
    got = normal(fold_in(written_out(dk), 3, indexed=True), (4,))
    want = normal(fold_in(dk, 3, indexed=True), (4,))
    assert np.array_equal(np.asarray(got), np.asarray(want))
    assert fold_in(written_out(dk), 3, indexed=True).path == ("*",)


@pytest.mark.parametrize("written", [False, True])
def test_normals_from_bits_computed_apart_are_jax_normals(key, written):
    """normal(..., bits_once=...): the bits handed back by the caller, then jax's float32
    transformation (the caller's fence is the identity here), plain and routed keys."""
    k = written_out(key) if written else key
    dk = DrawKey(k, jax.random.fold_in(k, 1), jnp.array([True]), jnp.array([2.0]), (((), 0),))
    calls = []

    def once(fn):
        calls.append(fn)
        return fn()

    for kk, shape in ((k, (8,)), (jax.random.fold_in(k, 9), (3, 4)), (dk, (5,))):
        got = normal(kk, shape, jnp.float32, bits_once=once)
        want = normal(kk, shape, jnp.float32)
        assert got.dtype == jnp.float32
        assert np.array_equal(_bits(got), _bits(want))
    assert len(calls) == 4  # the routed key draws from both of its keys
    with pytest.raises(ValueError, match="float32 only"):
        normal(k, (2,), jnp.float64, bits_once=once)
