"""The factors of a budget (a system's error sources, or groups of them) and the draw plans
that route their draws: the study's own, a pick-freeze pair, one factor on alone."""

import jax.numpy as jnp
import numpy as np

from .._random import DrawPlan
from ..scenario import Scenario, ScenarioError
from ..systems.base import AbstractSystem


def _value(config: dict, name: str):
    section, _, field = name.rpartition(".")
    node = config
    for part in section.split("."):
        node = node[part]
    return node[field]


def _active(config: dict, source) -> bool:
    """Whether any magnitude of ``source`` is non-zero (a non-numeric field counts as on)."""
    for name in source.fields:
        value = _value(config, name)
        if not isinstance(value, (int, float, list, tuple)) or np.any(np.asarray(value) != 0):
            return True
    return False


def factors(system: AbstractSystem, scenario: Scenario, groups=None) -> tuple[dict, list]:
    """``({factor: (source, ...)}, [inactive sources])``: each active source its own factor,
    except those gathered by ``groups`` (``True``: the system's ``source_groups``; a dict
    ``{group: (source, ...)}``; ``None``: none)."""
    sources = system.error_sources
    if not sources:
        raise ScenarioError(
            f"scenario.kind: {system.name} declares no error sources; allowed: a system with "
            "error_sources"
        )
    groups = dict(system.source_groups) if groups is True else dict(groups or {})
    for group, members in groups.items():
        unknown = sorted(set(members) - set(sources))
        if unknown:
            raise ScenarioError(
                f"groups.{group}: unknown source {unknown[0]!r}; allowed: {', '.join(sources)}"
            )
    inactive = [s for s, src in sources.items() if not _active(scenario.config, src)]
    out, grouped = {}, {m for members in groups.values() for m in members}
    for group, members in groups.items():
        on = tuple(m for m in members if m not in inactive)
        if on:
            out[group] = on
    for s in sources:
        if s not in grouped and s not in inactive:
            out[s] = (s,)
    if not out:
        raise ScenarioError(
            f"{scenario.name}: every error source is zero; allowed: a scenario with errors"
        )
    return out, inactive


def layout(system: AbstractSystem, factor_sources: dict) -> tuple:
    """The static :class:`~gnc_jax._random.DrawKey` layout: every draw of every source
    mapped to its factor's index; an inactive source's draws to the last index (never
    routed: its magnitude is zero)."""
    index = {s: i for i, members in enumerate(factor_sources.values()) for s in members}
    off = len(factor_sources)
    paths: dict = {}
    for name, source in system.error_sources.items():
        f = index.get(name, off)
        for draw in source.draws:
            path = tuple(draw[0])
            if len(draw) == 1:
                paths[path] = f
            else:
                paths.setdefault(path, [])
                paths[path].append((int(draw[1]), int(draw[2]), f))
    return tuple((p, v if isinstance(v, int) else tuple(sorted(v))) for p, v in paths.items())


def plan(seed_a: int, seed_b: int, n: int, lay: tuple, from_b=(), on=None) -> DrawPlan:
    """The :class:`DrawPlan` of ``n`` factors (plus the inactive slot): factors ``from_b``
    from the second seed; factors ``on`` (all by default) scaled 1, the others 0."""
    pick = np.zeros(n + 1, bool)
    pick[list(from_b)] = True
    scale = np.ones(n + 1) if on is None else np.zeros(n + 1)
    if on is not None:
        scale[list(on)] = 1.0
    return DrawPlan(
        jnp.asarray(seed_a, jnp.uint32),
        jnp.asarray(seed_b, jnp.uint32),
        jnp.asarray(pick),
        jnp.asarray(scale),
        lay,
    )


__all__ = ["factors", "layout", "plan"]
