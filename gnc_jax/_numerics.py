"""Numeric helpers shared across the package: norms and unit vectors that stay finite.

Both are written so that ``jax.grad`` is finite at the zero vector: the square root is taken of
a value that is never zero on the branch that is kept (the usual double-``where`` trick), so no
``0 * inf`` reaches the gradient of the branch that is thrown away.
"""

import contextlib
import contextvars
import math
from typing import NamedTuple

import jax
import jax.extend
import jax.numpy as jnp

from ._types import Array, Float, Matrix3, Scalar, Vector3

# Small fixed-size vector algebra written out by component. Under ``vmap`` a run's 3-vector
# becomes a (batch, 3) array; ``jnp.dot``/``jnp.cross``/``@`` on it lower to batched dot
# products and gathers that XLA on CPU runs as many small kernels, while these component
# expressions fuse with their neighbours into one elementwise loop over the batch.


class V3(NamedTuple):
    """A 3-vector held as three scalars (one per run under ``vmap``): "structure of arrays".

    Under ``vmap`` a run's (3,) array becomes a (batch, 3) array, and XLA on CPU compiles
    arithmetic on such arrays into kernels per vector shape with strided component accesses;
    with each component a (batch,) array the arithmetic is elementwise over the batch
    (measured: the impactor's bare RK4 step 12 ns instead of 37 ns per run; its closed loop
    12 % faster with the truth state carried this way). Supports + and - (with a V3, a (3,)
    array or a scalar), * and / by scalars, negation and indexing; :func:`as_v3` and
    :func:`as_array` convert. XLA on CPU computes every output array of a loop body in a
    kernel of its own, recomputing what it depends on, so carrying *everything* as
    components (many more outputs) measured slower: use it where the arithmetic is heavy
    and the outputs few.
    """

    x: Array
    y: Array
    z: Array

    def __add__(self, o):
        return V3(*(a + b for a, b in zip(self, _components(o))))

    __radd__ = __add__

    def __sub__(self, o):
        return V3(*(a - b for a, b in zip(self, _components(o))))

    def __rsub__(self, o):
        return V3(*(b - a for a, b in zip(self, _components(o))))

    def __mul__(self, s):
        return V3(*(a * s for a in self))

    __rmul__ = __mul__

    def __truediv__(self, s):
        return V3(*(a / s for a in self))

    def __neg__(self):
        return V3(-self.x, -self.y, -self.z)


def _components(o):
    if isinstance(o, V3):
        return o
    if jnp.ndim(o) == 0:
        return (o, o, o)
    return (o[0], o[1], o[2])


def as_v3(a) -> V3:
    """The components of a (3,) array (or a V3) as a :class:`V3`."""
    return a if isinstance(a, V3) else V3(a[0], a[1], a[2])


def as_array(a) -> Vector3:
    """A :class:`V3` (or a (3,) array) as a (3,) array."""
    return jnp.stack(a) if isinstance(a, V3) else a


def vector3(components, *operands):
    """The three ``components`` as a :class:`V3` when an operand is one, else a (3,) array:
    the helpers below keep a caller's layout (a loop carrying its vectors as components stays
    free of the stack, and on a GPU the transpose kernel, that re-forming an array costs)."""
    if any(isinstance(o, V3) for o in operands):
        return V3(*components)
    return jnp.stack(components)


def as_components(tree):
    """Every (3,) array of ``tree`` as a :class:`V3`: a loop's carry by component."""
    is_v3 = lambda x: isinstance(x, V3)  # noqa: E731
    return jax.tree_util.tree_map(
        lambda x: x if is_v3(x) or jnp.shape(x) != (3,) else as_v3(x), tree, is_leaf=is_v3
    )


def as_arrays(tree):
    """Every :class:`V3` of ``tree`` as a (3,) array (the inverse of :func:`as_components`)."""
    is_v3 = lambda x: isinstance(x, V3)  # noqa: E731
    return jax.tree_util.tree_map(lambda x: as_array(x), tree, is_leaf=is_v3)


def sub3(a: Vector3, b: Vector3) -> Vector3:
    """a - b of two 3-vectors, by component.

    Use it (and :func:`axpy3`) where one operand is shared by the batch and the other is
    per run: under ``vmap`` a (3,) vector broadcast against a (batch, 3) array is an indexed
    broadcast that XLA on CPU does not vectorise (measured 4x slower for the whole LOS step),
    while a shared scalar broadcast is free.
    """
    return vector3([a[0] - b[0], a[1] - b[1], a[2] - b[2]], a, b)


def axpy3(s: Scalar, x: Vector3, y: Vector3) -> Vector3:
    """s x + y of 3-vectors, by component (see :func:`sub3`)."""
    return vector3([s * x[0] + y[0], s * x[1] + y[1], s * x[2] + y[2]], x, y)


def dot3(a: Vector3, b: Vector3) -> Scalar:
    """a . b of two 3-vectors."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def cross3(a: Vector3, b: Vector3) -> Vector3:
    """a x b of two 3-vectors."""
    return vector3(
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]], a, b
    )


def norm3(a: Vector3) -> Scalar:
    """|a| of a 3-vector."""
    return jnp.sqrt(dot3(a, a))


def matvec3(m: Matrix3, v: Vector3) -> Vector3:
    """m @ v for a 3x3 matrix, row by row (the same sums as column by column, term for term:
    the same bits; under ``vmap`` a row of a stacked matrix is a slice XLA fuses through,
    a column was read back from a stored, transposed copy)."""
    return vector3([m[i, 0] * v[0] + m[i, 1] * v[1] + m[i, 2] * v[2] for i in range(3)], v)


def matmul(a: Float[Array, "n k"], b: Float[Array, "k m"]) -> Float[Array, "n m"]:
    """a @ b of small fixed-size matrices, unrolled into scalar products at trace time.

    Under ``vmap`` each entry is an elementwise expression over the batch, which XLA fuses with
    its neighbours; a batched GEMM, or a broadcast product reduced over k, runs as separate
    small kernels (measured: 10-20x slower for the 6x6 filter update).
    """
    n, k = a.shape
    m = b.shape[1]
    rows = [
        jnp.stack(
            [sum(a[i, l] * b[l, j] for l in range(1, k)) + a[i, 0] * b[0, j] for j in range(m)]
        )
        for i in range(n)
    ]
    return jnp.stack(rows)


class LoopShape(NamedTuple):
    """How the closed loops are laid out for the compiler; the results are the same up to
    rounding (within each family's ``batch_tolerance``), the speed is not.

    ``fence``: compute a guidance command once into memory (:func:`computed_once`) instead of
    leaving it to XLA's fusion. ``unroll``: control steps per trip of the innermost closed-loop
    ``lax.scan``. ``early_exit``: a loop whose trip count depends on the data (the capsule
    corrector's predictor steps within a round) stops as soon as every run of the batch is
    done; without it the loop runs its fixed bound with the finished runs masked (the same
    values), so that a GPU does not read the loop's predicate back to the host every trip.
    ``components``: a closed loop that supports it carries its per-run 3-vectors by component
    (:class:`V3`: the intercept's whole loop state, the impactor's filter mean through its
    control steps): on a GPU a 3-vector stacked under ``vmap`` is a kernel and a transpose of
    its own; on a CPU the three times as many loop outputs measured slower (``bennu-apn``,
    200 runs: about 1.5x). ``rare``: a closed loop that supports it flies each stretch of
    its loop first on the cheap path that a run takes when nothing happens in it (the
    impactor's image interval coasting), then recomputes on the full path only the runs where
    something did (the engine fired), gathered into ``rare`` of the batch's lanes
    (:func:`rarely`; ``0``: every run on the full path). On a CPU every lane of a vectorised
    batch otherwise computes the work of the few runs that need it, as a branch in a scalar
    loop does not. It compiles the full path twice (two widths), so a study turns it on only
    where its runs repay that (:class:`RareLayout`).

    The defaults are per platform (:func:`for_platform`), measured on each: on a CPU a fence
    saves XLA recomputing the command in every consumer loop and unrolling gains nothing
    (except where a system declares otherwise: the impactor's 15 control steps per image
    unrolled 5 times measured 5 % faster, results equal to the last bit); on
    a GPU a fence is a ``lax.cond`` whose predicate costs a trip to the host every step, and
    each scan trip a launch and a synchronisation, so the GPU's loops run unfenced and
    unrolled (``bennu-apn``, 2,000 runs on an H100: 6.4 s fenced, 4.1 s unfenced, 2.6 s
    unfenced and unrolled 4 times; per-run outcomes equal to the last bit there).
    """

    fence: bool = True
    unroll: int = 1
    early_exit: bool = True
    components: bool = False
    rare: float = 0.0


class RareLayout(NamedTuple):
    """When a system's study on the CPU runs its closed loop in the ``rare`` layout
    (:attr:`LoopShape.rare` = ``fraction``): a study of at least ``min_runs`` runs, in device
    batches of at least ``min_lanes`` runs. Below, the gathered lanes' fixed cost per step
    and the second compilation cost more than the skipped work saves."""

    fraction: float
    min_runs: int
    min_lanes: int


_PLATFORM_SHAPES = {"cpu": LoopShape(fence=True, unroll=1, early_exit=True)}
_ACCELERATOR_SHAPE = LoopShape(fence=False, unroll=4, early_exit=False)
_LOOP_SHAPE: contextvars.ContextVar = contextvars.ContextVar("loop_shape", default=None)


def for_platform(platform: str, system=None) -> LoopShape:
    """The default :class:`LoopShape` of a JAX platform (``"cpu"``, ``"gpu"``, ``"cuda"``, ...):
    ``system.cpu_loop_shape`` on the CPU and ``system.accelerator_loop_shape`` on an
    accelerator, where the system declares one."""
    if platform in _PLATFORM_SHAPES:
        return getattr(system, "cpu_loop_shape", None) or _PLATFORM_SHAPES[platform]
    return getattr(system, "accelerator_loop_shape", None) or _ACCELERATOR_SHAPE


def loop_shape() -> LoopShape:
    """The :class:`LoopShape` that code traced now is laid out with: the one set by
    :func:`using_loop_shape`, else the default of JAX's default backend."""
    shape = _LOOP_SHAPE.get()
    return for_platform(jax.default_backend()) if shape is None else shape


def explicit_loop_shape() -> LoopShape | None:
    """The :class:`LoopShape` set by :func:`using_loop_shape`, or None."""
    return _LOOP_SHAPE.get()


def layout_for(platform: str, system=None) -> LoopShape:
    """The :class:`LoopShape` a study of ``system`` is traced with on ``platform``: the one set
    by :func:`using_loop_shape`, else the platform's default for the system
    (:func:`for_platform`)."""
    return explicit_loop_shape() or for_platform(platform, system)


@contextlib.contextmanager
def using_loop_shape(shape: LoopShape | None):
    """Trace the closed loops with ``shape`` inside the block (None: the platform's default),
    e.g. to run the GPU's layout on a CPU. Compiled programs are cached per shape."""
    if shape is not None and (not isinstance(shape.unroll, int) or shape.unroll < 1):
        raise ValueError(f"LoopShape.unroll = {shape.unroll!r}: allowed an integer >= 1")
    token = _LOOP_SHAPE.set(shape)
    try:
        yield
    finally:
        _LOOP_SHAPE.reset(token)


_LANES: contextvars.ContextVar = contextvars.ContextVar("lanes_per_device", default=None)


@contextlib.contextmanager
def using_lanes(lanes: int | None):
    """Trace inside the block for a batch of ``lanes`` runs per device (``None``: unknown), so
    that a loop may lay itself out for it (:func:`lanes_per_device`)."""
    token = _LANES.set(lanes)
    try:
        yield
    finally:
        _LANES.reset(token)


def lanes_per_device() -> int | None:
    """The runs per device of the batch being traced, where the caller says
    (:func:`using_lanes`: a study's compiled chunk); ``None`` when unknown."""
    return _LANES.get()


def rarely(pred, taken, otherwise, operands, fraction: float):
    """``taken(operands)`` where ``pred`` holds, else ``otherwise(operands)``, for a ``taken``
    that few runs of a batch take.

    Unbatched this is a ``lax.cond``. Under ``vmap`` (where a ``lax.cond`` computes both
    branches for every run) ``otherwise`` runs for the whole batch and ``taken`` only for the
    runs where ``pred`` holds, gathered into ``fraction`` of the batch's lanes (rounded up
    to a multiple of 8) and written back over ``otherwise``'s results; when more runs take
    it, ``taken`` runs for the whole batch and is selected where ``pred`` holds; when none
    does, ``taken`` is skipped. Each run's value is its branch's, whatever the batch and the
    other runs (up to the rounding of a program compiled for another width).

    ``operands``: a pytree of arrays (batched or not); ``taken`` and ``otherwise`` map it to
    pytrees of the same structure, shapes and dtypes, and may close over traced values.
    """
    taken_c, taken_consts = jax.closure_convert(taken, operands)
    other_c, other_consts = jax.closure_convert(otherwise, operands)
    flat, tree = jax.tree_util.tree_flatten((operands, list(taken_consts), list(other_consts)))

    def take(xs):
        ops, consts, _ = tree.unflatten(list(xs))
        return taken_c(ops, *consts)

    def skip(xs):
        ops, _, consts = tree.unflatten(list(xs))
        return other_c(ops, *consts)

    @jax.custom_batching.custom_vmap
    def branch(p, *xs):
        return jax.lax.cond(p, take, skip, xs)

    @branch.def_vmap
    def batched(size, in_batched, p, *xs):
        axes = [0 if b else None for b in in_batched[1:]]
        p = p if in_batched[0] else jnp.broadcast_to(p, (size,))
        over = lambda fn: jax.vmap(lambda *x: fn(x), in_axes=axes)  # noqa: E731
        base = over(skip)(*xs)  # vmap gives every output the batch axis
        # A multiple of 8 lanes: at 63 the gathered program's remainder loop moved last bits.
        slots = min(size, 8 * max(1, math.ceil(fraction * size / 8)))

        def along(m, x):  # a per-run mask against a batched leaf
            return m.reshape(m.shape + (1,) * (x.ndim - 1))

        def everyone():
            done = over(take)(*xs)
            return jax.tree_util.tree_map(lambda u, v: jnp.where(along(p, v), u, v), done, base)

        def gathered():
            flags, idx = jax.lax.top_k(p.astype(jnp.float32), slots)
            some = [x[idx] if b else x for x, b in zip(xs, in_batched[1:])]
            done = over(take)(*some)

            def put(u, v):
                here = v[idx]
                new = jnp.where(along(flags > 0, here), u, here)
                return v.at[idx].set(new, unique_indices=True)

            return jax.tree_util.tree_map(put, done, base)

        count = jnp.sum(p, dtype=jnp.int32)
        which = jnp.where(count == 0, 0, jnp.where(count <= slots, 1, 2))
        out = jax.lax.switch(which, [lambda: base, gathered, everyone])
        return out, jax.tree_util.tree_map(lambda _: True, out)

    return branch(pred, *flat)


def computed_once(fn, live, *args, adjoint=None):
    """``fn(*args)``, computed once into memory before its consumers run.

    XLA on CPU fuses an elementwise producer into every consumer loop, so a guidance law
    whose command feeds the truth integrator, the accelerometer and the estimate is
    recomputed inside each of those loops (and once per vector component): measured 4-10x
    the work of the closed-loop step. A conditional's branch is a fusion boundary, so the value
    is computed in the taken branch of a ``lax.cond`` whose predicate ``live == live`` is
    true but not known to the compiler (which would otherwise remove the conditional):
    ``live`` must be a runtime scalar shared by the batch (e.g. the scan's time input), so
    that under ``vmap`` the predicate stays unbatched.

    ``adjoint``: how reverse mode crosses the fence. ``None``: as it crosses the conditional,
    in forward and reverse mode; reverse mode then keeps the residuals of both branches and
    transposes a conditional, whose pieces XLA cannot fuse with their neighbours.
    ``"recompute"``: the backward pass recomputes ``fn`` and transposes it in one fence of
    its own (the residuals are the arguments). ``"save"``: the forward pass computes ``fn``'s
    residuals in its fence and the backward pass transposes them in another (for a ``fn``
    that draws random numbers, which recomputing would draw again). Both are reverse mode
    only (forward mode refuses them): a system sets them up in its
    :meth:`~gnc_jax.systems.AbstractSystem.reverse_mode`. The value is the same either way.
    Under a :class:`LoopShape` without fences (a GPU's default) this is ``fn(*args)``.
    """
    if not loop_shape().fence:
        return fn(*args)
    # A floating-point comparison: XLA folds ``i == i`` to true for an integer ``i`` (and
    # then inlines the branch, so nothing is fenced), but not for a float, which may be NaN.
    live = jnp.asarray(live, jnp.float64)
    if adjoint is None:
        return _fenced(fn, live, *args)
    if adjoint not in ("recompute", "save"):
        raise ValueError(f"adjoint = {adjoint!r}: allowed None, 'recompute', 'save'")
    return _fenced_with_adjoint(fn, live, args, adjoint == "save")


def _fenced(fn, live, *args):
    out = jax.eval_shape(fn, *args)

    def skipped(*_):
        return jax.tree_util.tree_map(lambda s: jnp.zeros(s.shape, s.dtype), out)

    return jax.lax.cond(live == live, fn, skipped, *args)


def _closure_converted(fn, args):
    """``fn(*args)`` as ``call(*leaves)``: the leaves of ``args``, then the traced values ``fn``
    closes over (a law's gains; a custom derivative sees only its arguments). Also, per leaf,
    whether the value reads it, and the value's shapes."""
    flat, tree = jax.tree_util.tree_flatten(args)
    closed, out = jax.make_jaxpr(lambda *x: fn(*tree.unflatten(x)), return_shape=True)(*flat)
    jaxpr, consts = closed.jaxpr, closed.consts
    traced = [isinstance(c, jax.core.Tracer) for c in consts]
    out_tree = jax.tree_util.tree_structure(out)

    def call(*leaves):
        hoisted = iter(leaves[len(flat) :])
        kept = iter(c for c, t in zip(consts, traced) if not t)
        values = [next(hoisted) if t else next(kept) for t in traced]
        fun = jax.extend.core.jaxpr_as_fun(jax.extend.core.ClosedJaxpr(jaxpr, values))
        return jax.tree_util.tree_unflatten(out_tree, fun(*leaves[: len(flat)]))

    read = {id(v) for e in jaxpr.eqns for v in e.invars} | {id(v) for v in jaxpr.outvars}
    hoisted_vars = [v for v, t in zip(jaxpr.constvars, traced) if t]
    used = [id(v) in read for v in (*jaxpr.invars, *hoisted_vars)]
    return call, [*flat, *(c for c, t in zip(consts, traced) if t)], used, out


def _fenced_with_adjoint(fn, live, args, save):
    """:func:`computed_once` with ``adjoint`` ``"save"`` (``save``) or ``"recompute"``."""
    call, leaves, used, out = _closure_converted(fn, args)
    out_leaves = jax.tree_util.tree_leaves(out)
    inexact = [jnp.issubdtype(o.dtype, jnp.inexact) for o in out_leaves]
    rule = {}  # set where the forward pass is traced, read where the backward pass is

    def outputs(perturbed, x):
        """``call`` of the perturbed leaves (the others as in ``x``), for ``jax.vjp``: the
        floating-point outputs, and the others as its auxiliary output."""

        def g(*d):
            it = iter(d)
            o = jax.tree_util.tree_leaves(
                call(*[next(it) if p else v for v, p in zip(x, perturbed)])
            )
            return [v for v, f in zip(o, inexact) if f], [v for v, f in zip(o, inexact) if not f]

        return g, [v for v, p in zip(x, perturbed) if p]

    @jax.custom_vjp
    def fence(live, *leaves):
        return _fenced(call, live, *leaves)

    def fwd(live, *leaves):
        x = [leaf.value for leaf in leaves]
        rule["perturbed"] = perturbed = [
            leaf.perturbed and u and jnp.issubdtype(jnp.result_type(v), jnp.inexact)
            for leaf, u, v in zip(leaves, used, x)
        ]
        if not save:
            return _fenced(call, live.value, *x), (live.value, x)

        def value_and_residuals(*x):
            g, d = outputs(perturbed, x)
            floats, pullback, others = jax.vjp(g, *d, has_aux=True)
            residuals, rule["pullback"] = jax.tree_util.tree_flatten(pullback)
            f, o = iter(floats), iter(others)
            value = [next(f) if i else next(o) for i in inexact]
            return jax.tree_util.tree_unflatten(jax.tree_util.tree_structure(out), value), residuals

        value, residuals = _fenced(value_and_residuals, live.value, *x)
        return value, (live.value, residuals)

    def bwd(res, ct):
        live, saved = res
        perturbed = rule["perturbed"]
        zero = jax.custom_derivatives.SymbolicZero
        ct = jax.tree_util.tree_leaves(ct, is_leaf=lambda c: isinstance(c, zero))
        ct = [
            jnp.zeros(o.shape, o.dtype) if isinstance(c, zero) else c
            for c, o, i in zip(ct, out_leaves, inexact)
            if i
        ]

        def transposed(ct, *saved):
            if save:
                return list(jax.tree_util.tree_unflatten(rule["pullback"], saved)(ct))
            g, d = outputs(perturbed, saved)
            return list(jax.vjp(lambda *d: g(*d)[0], *d)[1](ct))

        grads = iter(_fenced(transposed, live, ct, *saved) if any(perturbed) else ())
        return (None, *(next(grads) if p else None for p in perturbed))

    fence.defvjp(fwd, bwd, symbolic_zeros=True)
    return fence(live, *leaves)


def _dot(x, y):
    return dot3(x, y) if isinstance(x, V3) or x.shape == (3,) else jnp.sum(x * y, axis=-1)


def safe_norm(x: Float[Array, " n"]) -> Scalar:
    """|x|, and 0 with a zero (not NaN) gradient at x = 0 (e.g. a coasting step's zero Δv)."""
    n2 = _dot(x, x)
    ok = n2 > 0.0
    return jnp.where(ok, jnp.sqrt(jnp.where(ok, n2, 1.0)), 0.0)


def smooth_norm(x: Float[Array, " n"], floor: float = 1e-12) -> Scalar:
    """sqrt(|x|^2 + floor^2): smooth everywhere and never zero, so ``x / smooth_norm(x)`` is
    finite (0 at x = 0); equal to |x| to the last bit once |x| >> floor (a Δv the predictor
    differentiates through, which may start at exactly zero)."""
    return jnp.sqrt(_dot(x, x) + floor**2)


def safe_unit(v: Vector3, fallback: Vector3) -> Vector3:
    """``v/|v|``, or ``fallback`` when ``v`` is (near) zero, with finite gradients either way."""
    n2 = _dot(v, v)
    ok = n2 > 1e-30
    n = jnp.sqrt(jnp.where(ok, n2, 1.0))
    if isinstance(v, V3) or v.shape == (3,):  # by component: see sub3
        return vector3([jnp.where(ok, v[i] / n, fallback[i]) for i in range(3)], v)
    return jnp.where(ok, v / n, fallback)


__all__ = [
    "LoopShape",
    "RareLayout",
    "V3",
    "as_array",
    "as_v3",
    "as_arrays",
    "as_components",
    "axpy3",
    "computed_once",
    "cross3",
    "dot3",
    "explicit_loop_shape",
    "for_platform",
    "lanes_per_device",
    "loop_shape",
    "matmul",
    "matvec3",
    "norm3",
    "rarely",
    "safe_norm",
    "safe_unit",
    "vector3",
    "smooth_norm",
    "sub3",
    "using_lanes",
    "using_loop_shape",
]
