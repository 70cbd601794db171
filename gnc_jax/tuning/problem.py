"""The tuning problem, built once (:class:`TuningProblem`), and the run indices it flies.

**Run indices.** Run ``i`` uses ``fold_in(key(seed), i)`` as in every study. Training step
``s`` flies runs ``(s * batch + j) mod train_runs`` (default ``train_runs = batch * steps``: a
fresh batch each step); held-out runs are ``HELDOUT_OFFSET + j``, and ``train_runs <=
HELDOUT_OFFSET`` and ``j < HELDOUT_MAX_RUNS`` are enforced, so the two sets never share a run.
"""

import dataclasses
import functools
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._numerics import layout_for, using_loop_shape
from ..montecarlo import batch_function, build
from ..params import declared_params
from ..scenario import Scenario
from .objectives import _check_fields, counted
from .parametrisation import Gain, Reparametrisation

HELDOUT_OFFSET = 2**30
"""First run index of the held-out set; training indices stay below it."""
HELDOUT_MAX_RUNS = 2**32 - HELDOUT_OFFSET
"""Held-out runs, at most: a run's key folds its index in modulo 2^32 (``jax.random.fold_in``
takes a uint32), so held-out index ``2^32 + j`` would fly training run ``j``'s draws. Below
it, the int32 indices a batch is flown with wrap to the same uint32 (the same keys)."""


def _si_factors(scenario: Scenario, gains: list[Gain], law) -> list[float]:
    """SI leaf / file value of each gain (all conversions of tunable gains are linear)."""
    out = []
    for g in gains:
        leaf = getattr(law, g.attribute)
        si = float(leaf if g.index is None else leaf[g.index])
        out.append(si / g.start(scenario))
    return out


@functools.lru_cache(maxsize=16)
def _batch_function(system, devices=None):
    return batch_function(system, devices=devices)


class TuningProblem:
    """What one tuning needs, built once: the built scenario (``sim``, ``law``), the gains <->
    law map and the objective. Its jitted functions take ``sim`` and ``law`` as arguments and
    are cached on the problem's static structure (:meth:`jitted`), so a second tuning of the
    same structure (another seed, other weights, other start values) does not recompile."""

    def __init__(self, scenario, gains, objective, seed, backend=None):
        self.scenario, self.system, self.seed = scenario, scenario.system, seed
        placed = backend is not None and not backend.default
        self.platform = backend.platform if placed else None  # None: JAX's default devices
        self.sim, self.law = build(scenario)
        self.gains = tuple(
            dataclasses.replace(g, si_per_file=f)
            for g, f in zip(gains, _si_factors(scenario, gains, self.law), strict=True)
        )
        self.param = Reparametrisation.of(scenario, gains)
        self.objective = objective
        if objective.fn is None:  # traced, not compiled: bad input stops before compilation
            outcome = jax.eval_shape(
                lambda: self.system.simulate(self.sim, self.law, jax.random.key(0))[0]
            )
            _check_fields(objective, outcome._fields, self.system.name)
        self.fn, self.n_dev = _batch_function(self.system, backend.devices if placed else None)
        self.reverse_fn = self.fn
        if self.system.reverse_on_one_device and self.n_dev > 1:
            devices = backend.devices[:1] if placed else None
            self.reverse_fn = batch_function(self.system, n_devices=1, devices=devices)[0]
        # the loops are traced in the layout a study of this system flies on this platform
        self.loop_shape = layout_for(self.platform or jax.default_backend(), self.system)
        self.seed_arr = jnp.asarray(seed, dtype=jnp.uint32)
        self.term_weights = objective.weights
        spec = declared_params(type(self.law)).get("temperature")
        self.law_temperature = (
            float(self.law.temperature) if spec is not None and not spec.static else None
        )

    @property
    def args(self):
        """The dynamic arguments of every jitted function: built scenario, law, seed, weights."""
        return self.sim, self.law, self.seed_arr, self.term_weights

    def args_for(self, gradient: str):
        """:attr:`args`, with the built scenario set up by the system for reverse mode when
        ``gradient == "reverse"`` (:meth:`~gnc_jax.systems.AbstractSystem.reverse_mode`)."""
        if gradient != "reverse":
            return self.args
        names = [g.name for g in self.gains]
        return (self.system.reverse_mode(self.sim, names),) + self.args[1:]

    def jitted(self, kind: str, build_fn):
        """``build_fn()`` jitted, traced in the system's loop layout (:attr:`loop_shape`)."""
        key = (
            kind, self.system, self.objective.structure, self.param, self.gains, self.n_dev,
            self.platform, self.loop_shape,
        )  # fmt: skip
        if key not in _JITTED:
            if len(_JITTED) >= 32:
                _JITTED.pop(next(iter(_JITTED)))
            _JITTED[key] = jax.jit(_traced_in(self.loop_shape, build_fn()))
        return _JITTED[key]

    def compiled(self, kind: str, build_fn, *args):
        """``(executable, compile_s)``: :meth:`jitted` compiled ahead of time for ``args``
        (reused for arguments of the same structure, shapes and dtypes; 0 s then)."""
        leaves, treedef = jax.tree_util.tree_flatten(args)
        shapes = tuple((jnp.shape(x), jnp.result_type(x)) for x in leaves)
        key = (
            kind, self.system, self.objective.structure, self.param, self.gains, treedef, shapes,
            self.platform, self.loop_shape,
        )  # fmt: skip
        if key in _COMPILED:
            return _COMPILED[key], 0.0
        t0 = time.perf_counter()
        executable = self.jitted(kind, build_fn).lower(*args).compile()
        if len(_COMPILED) >= 32:
            _COMPILED.pop(next(iter(_COMPILED)))
        _COMPILED[key] = executable
        return executable, time.perf_counter() - t0

    def law_at(self, law, gains_file):
        """``law`` with the gains ``gains_file`` (file units; a schedule's knots together)."""
        groups: dict[str, list] = {}
        for i, g in enumerate(self.gains):
            groups.setdefault(g.attribute, []).append(
                jnp.asarray(gains_file[i] * g.si_per_file, dtype=jnp.float64)
            )
        values = tuple(jnp.stack(v) if _is_schedule(law, a) else v[0] for a, v in groups.items())
        return eqx.tree_at(lambda l: tuple(getattr(l, a) for a in groups), law, values)

    def padded(self, indices, size: int | None = None):
        """Indices padded to ``size`` (default: a whole number per device) by repeating them,
        and the weights of the real ones (1) and the padding (0)."""
        indices = np.asarray(indices, dtype=np.int64)
        n = -(-max(size or 0, len(indices)) // self.n_dev) * self.n_dev
        valid = np.arange(n) < len(indices)
        return jnp.asarray(np.resize(indices, n), dtype=jnp.int32), jnp.asarray(valid, float)

    @staticmethod
    def weights(outcomes, valid):
        """1 for the real runs (``valid`` 1) that count (:func:`~.objectives.counted`), else 0."""
        return jnp.where(counted(outcomes), valid, 0.0)

    @classmethod
    def failed(cls, outcomes, valid):
        """How many of the real runs (``valid`` 1) did not count (:meth:`weights` 0): the
        failed runs, which the tuners rank before the objective."""
        return jnp.sum(valid) - jnp.sum(cls.weights(outcomes, valid))

    def smooth(self, args, theta, temperature, indices, valid, gradient="forward"):
        """The relaxed objective at ``theta`` on runs ``indices`` (pure in its arguments), to be
        differentiated in ``gradient`` mode (with :meth:`args_for` its ``args``)."""
        sim, law, seed, term_weights = args
        law = law.relax(temperature) if temperature is not None else law.relax()
        fn = self.reverse_fn if gradient == "reverse" else self.fn
        out = fn(sim, self.law_at(law, self.param.gains(theta)), seed, indices)
        weights = self.weights(out, valid)
        return self.objective.value(out, weights, temperature, term_weights, runs=valid)

    def value_and_grad(self, args, theta, temperature, indices, valid, gradient):
        """The relaxed objective at ``theta`` (:meth:`smooth`) and its gradient: ``jax.grad``
        for ``gradient == "reverse"`` (``args`` from :meth:`args_for`), else ``jax.jacfwd``
        (the value its primal)."""
        f = lambda t: self.smooth(args, t, temperature, indices, valid, gradient)  # noqa: E731
        if gradient == "reverse":
            return jax.value_and_grad(f)(theta)

        def twice(t):
            value = f(t)
            return value, value

        jac, value = jax.jacfwd(twice, has_aux=True)(theta)
        return value, jac

    def hard(self, args, gains_file, indices, valid):
        """``(objective, outcomes)`` of the hard logic with gains ``gains_file``."""
        sim, law, seed, term_weights = args
        out = self.fn(sim, self.law_at(law, gains_file), seed, indices)
        value = self.objective.value(out, self.weights(out, valid), None, term_weights, valid)
        return value, out

    def hard_outcomes(self, gains_file, indices):
        fn = self.jitted("hard", lambda: self.hard)
        return fn(self.args, jnp.asarray(gains_file), indices, jnp.ones(len(indices)))[1]


def _traced_in(shape, fn):
    """``fn``, traced in the loop layout ``shape`` (:func:`~gnc_jax._numerics.using_loop_shape`)."""

    @functools.wraps(fn)
    def traced(*args):
        with using_loop_shape(shape):
            return fn(*args)

    return traced


def _is_schedule(law, attribute) -> bool:
    return jnp.ndim(getattr(law, attribute)) == 1


_JITTED: dict = {}
_COMPILED: dict = {}


def train_indices(step: int, batch: int, train_runs: int) -> np.ndarray:
    """Run indices of training step ``step``: ``(step * batch + j) mod train_runs``."""
    return (step * batch + np.arange(batch)) % train_runs


def heldout_indices(runs: int) -> np.ndarray:
    """Run indices of the held-out set: ``HELDOUT_OFFSET + j``."""
    return HELDOUT_OFFSET + np.arange(runs, dtype=np.int64)
