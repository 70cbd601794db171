"""The guidance-law family: one abstract interface, one registry per system's law family.

A law is an ``equinox.Module`` whose tunable gains are array leaves (declared with
:func:`gnc_jax.params.param`, so the scenario's ``[guidance.<law>]`` section is derived from
them); its evolving state is a small NamedTuple. The simulator calls

* ``init(nav, ctx) -> state`` once,
* ``plan(state, nav, t, ctx) -> state`` at the navigation-update rate (e.g. right after the
  filter has taken an image at time ``t``); the default keeps the state;
* ``step(state, nav, t, ctx) -> (command, state)`` at the control rate.

``nav`` is what navigation hands the law, ``ctx`` the mission data known on board; both are
the system's own types. Everything is written for one trajectory.

Every system with guidance has a *family base*: an abstract subclass of
:class:`AbstractGuidanceLaw` that declares ``laws = {}``. A law joins its family by
:func:`register_law`; the system's scenario chooses one by ``guidance.law``::

    @register_law("pn")
    class ProportionalNavigation(AbstractImpactorGuidance): ...
"""

import abc
import dataclasses
from typing import Any, ClassVar, NamedTuple

import equinox as eqx
import jax.numpy as jnp

from .._numerics import safe_unit  # noqa: F401  (re-exported for the laws)
from .._types import Scalar, Vector3
from ..params import from_config


class EngineCommand(NamedTuple):
    throttle: Scalar  # fraction of the control step the engine fires, in [0, 1]
    direction: Vector3  # commanded thrust direction, unit vector, inertial


class AbstractGuidanceLaw(eqx.Module):
    """Base class of every guidance law (see the module docstring for the protocol).

    Class attributes set by :func:`register_law`: ``law_name``, the name a scenario chooses it
    by (``guidance.law``).
    """

    law_name: ClassVar[str] = ""
    # (larger, smaller) file names of gains whose order the law's check requires (k1 >= k2):
    # tuning keeps each pair ordered by its reparametrisation (gnc_jax.tune)
    ordered_gains: ClassVar[tuple[tuple[str, str], ...]] = ()

    @abc.abstractmethod
    def init(self, nav, ctx): ...

    def plan(self, state, nav, t, ctx):
        return state

    @abc.abstractmethod
    def step(self, state, nav, t, ctx): ...

    def converged(self, state):
        """False when an iteration of the law's own (a burn's Newton solve) ended outside its
        tolerance in this run: the run then ends ``no_convergence``. ``state``: the law's state
        at the run's end. Default: true (a law that solves nothing)."""
        return jnp.asarray(True)

    # ---- what the figures and reports draw: the law says it, nobody reads its fields ----
    def describe(self) -> str:
        """One line naming the law and its gains, for figure titles."""
        return getattr(self, "law_name", type(self).__name__)

    def switching_levels(self) -> dict[str, float]:
        """Command levels at which the law switches its engine on or off, ``{label: value}``
        in the command's units, drawn on command figures; ``{}`` when it has none."""
        return {}

    def state_curves(self, state_trace) -> dict[str, Any]:
        """Time series of the law's own state worth drawing against a run's trace,
        ``{label: array}``, from the law state recorded along the run (``state_trace``, its
        fields with time on the first axis); ``{}`` when there are none."""
        return {}

    def relax(self, temperature=None):
        """The law with its discontinuous logic replaced by its smooth relaxation (for
        gradients; a static ``relaxed`` field), at ``temperature`` when given and the law has
        one; the law itself when it has no relaxation."""
        names = {f.name for f in dataclasses.fields(self)}
        law = dataclasses.replace(self, relaxed=True) if "relaxed" in names else self
        if temperature is not None and "temperature" in names:
            law = eqx.tree_at(lambda x: x.temperature, law, jnp.asarray(temperature, float))
        return law

    @classmethod
    def check(cls, section: dict, config: dict) -> None:
        """Cross-field checks of the law's validated ``[guidance.<law>]`` table against the
        whole scenario; raise :class:`~gnc_jax.scenario.ScenarioError` with one line."""

    @classmethod
    def warnings(cls, section: dict, config: dict) -> list[str]:
        """One-line warnings about a valid but doubtful ``[guidance.<law>]`` table (printed by
        the CLI, recorded in ``summary.json``). Default: none."""
        return []

    @classmethod
    def from_config(cls, section: dict, config: dict, ctx=None):
        """The law of a validated scenario: ``section`` is its ``[guidance.<law>]`` table,
        ``config`` the whole scenario (for laws whose SI values depend on other sections),
        ``ctx`` the on-board context built by the system. Default: every declared field from
        ``section`` (:func:`gnc_jax.params.from_config`)."""
        return from_config(cls, section)


def family_of(cls) -> type:
    """The family base of a law class: the nearest base that declares ``laws``."""
    for base in cls.__mro__:
        if "laws" in vars(base):
            return base
    raise TypeError(f"{cls.__name__} is not in a guidance-law family (no base declares `laws`)")


def register_law(name: str):
    """Class decorator: register a law under ``name`` in its family (``guidance.law = name``)."""

    def decorate(cls):
        family = family_of(cls)
        if name in family.laws and family.laws[name] is not cls:
            raise ValueError(f"{family.__name__}: a law named {name!r} is already registered")
        family.laws[name] = cls
        cls.law_name = name
        return cls

    return decorate
