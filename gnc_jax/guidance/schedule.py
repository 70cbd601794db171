"""Gain schedules: a gain as a piecewise-linear function of a scheduling variable.

A law that offers a schedule of its gain ``k`` declares two more fields besides ``k``: the
knot values ``k_schedule`` (a tunable list, one value per breakpoint) and, once for all its
schedules, the breakpoints of the scheduling variable (time to go, speed, ...), increasing.
An empty schedule (the default) is the constant gain ``k``: the law's arithmetic is then
exactly that of the constant gain (no interpolation is traced). Between the breakpoints the
gain is linear, outside them it holds the end values (``numpy.interp``'s convention), so a
schedule whose knots all equal ``k`` flies bit-identically to the constant gain.

The knot values are array leaves of the law: ``jax.grad`` and the tuner reach them like any
gain (:func:`gnc_jax.tune` tunes each knot as a parameter).
"""

import jax.numpy as jnp
import numpy as np

from ..schema import ScenarioError


def piecewise_linear(x, breakpoints, values):
    """``numpy.interp(x, breakpoints, values)`` in JAX, differentiable in ``values``.

    ``v[i] + w (v[i+1] - v[i])`` with ``w = (x - b[i]) / (b[i+1] - b[i])`` clipped to [0, 1]:
    equal knot values give that value exactly, whatever ``x``.
    """
    b = jnp.asarray(breakpoints)
    i = jnp.clip(jnp.searchsorted(b, x, side="right") - 1, 0, b.shape[0] - 2)
    w = jnp.clip((x - b[i]) / (b[i + 1] - b[i]), 0.0, 1.0)
    return values[i] + w * (values[i + 1] - values[i])


def scheduled(gain, values, breakpoints, x):
    """``gain`` when the schedule ``values`` is empty, else the schedule at ``x``.

    The choice is by shape (static), so the constant gain's program is unchanged."""
    if values.shape[0] == 0:
        return gain
    return piecewise_linear(x, breakpoints, values)


def check_schedules(
    section: dict, breakpoints: str, schedules: dict[str, str], where: str, least: int = 2
) -> None:
    """Refuse a bad schedule in one line naming the field (before anything is compiled).

    ``section``: the law's validated table; ``breakpoints``: the file name of its breakpoints;
    ``schedules``: ``{schedule file name: constant gain file name}``. A non-empty schedule
    needs at least ``least`` strictly increasing breakpoints and one value per breakpoint;
    the values' ranges are their fields' own (checked with the table)."""
    b = np.asarray(section[breakpoints], float)
    used = [s for s in schedules if len(section[s])]
    if not used:
        return
    if len(b) < least:
        raise ScenarioError(
            f"{where}.{breakpoints}: {len(b)} breakpoints for {where}.{used[0]}; allowed: at "
            f"least {least}, strictly increasing"
        )
    if np.any(np.diff(b) <= 0.0):
        raise ScenarioError(
            f"{where}.{breakpoints}: {list(section[breakpoints])} is not strictly increasing; "
            "allowed: b[0] < b[1] < ..."
        )
    for s in used:
        if len(section[s]) != len(b):
            raise ScenarioError(
                f"{where}.{s}: {len(section[s])} values for {len(b)} breakpoints "
                f"({where}.{breakpoints}); allowed: one value per breakpoint, or none"
            )


__all__ = ["piecewise_linear", "scheduled", "check_schedules"]
