"""Outcome status of a run, shared by every simulator (like diffrax's RESULTS).

A run that is not ``ok`` is counted and flagged in the results and left out of the statistics.
"""

import enum

import jax.numpy as jnp
import numpy as np


class Status(enum.IntEnum):
    ok = 0
    nan = 1  # the state or an outcome became NaN or infinite
    skip_out = 2  # capsule: skipped out of the atmosphere
    no_convergence = 3  # an iteration (corrector, targeter, a predictive burn's Newton solve)
    # did not converge
    time_out = 4  # the run did not reach its terminal condition in the allotted time
    out_of_domain = 5  # the state left the model's domain (intercept: a B-plane miss larger
    # than the initial range, a run that ends farther from the target than it started;
    # midcourse: an error beyond the autonomous correction's upper threshold, for the ground)
    propellant = 6  # the engine needed more propellant than the vehicle carries (impactor and
    # intercept: spacecraft.propellant_kg)
    nav_lost = 7  # navigation lost the target (most images unused, or innovations persistently
    # beyond their covariance: see gnc_jax.navigation.ekf.NAV_LOST_*)
    missed = 8  # the run ended outside its delivery tolerance (capsule: a chute point beyond
    # simulation.miss_limit_km; impactor and intercept: a B-plane miss beyond
    # guidance.miss_limit_km)
    overload = 9  # capsule: the sensed load exceeded simulation.load_limit_g

    @classmethod
    def name_of(cls, code: int) -> str:
        return cls(int(code)).name


def shown_run(status) -> tuple[int, str]:
    """The run a report draws as an example, and its label: the first ``ok`` run of a study's
    ``status`` column (run 0 when none is, labelled with its status)."""
    status = np.asarray(status)
    ok = np.flatnonzero(status == Status.ok)
    i = int(ok[0]) if ok.size else 0
    return i, f"run {i}" + ("" if ok.size else f" ({Status.name_of(status[0])})")


def all_finite(outcome):
    """True when every field of an outcome NamedTuple after ``status`` (its first field) is
    finite: the check behind ``Status.nan``, shared by every simulator."""

    return jnp.all(jnp.array([jnp.all(jnp.isfinite(jnp.asarray(x))) for x in outcome[1:]]))
