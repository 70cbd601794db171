"""The second-entry reference trajectory the skip-entry law tracks (seed 003 §2.2): a table
against Earth-relative speed with its switch state and the sensitivities of eq. 7 and eq. 10.
Designed offline by :mod:`gnc_jax.guidance.entry.design` (kept by
:mod:`gnc_jax.guidance.entry.cache`) for each scenario by the capsule system."""

import math
from typing import NamedTuple

import equinox as eqx
import jax.numpy as jnp

from ..._types import Array, Float, Scalar
from .base import FlightVariables


class ReferenceTrajectory(eqx.Module):
    """Second-entry reference stored against Earth-relative speed (decreasing grid).

    Attributes:
        velocity_mps: table abscissa (decreasing from the switch speed).
        bank_rad, range_to_go_m, hdot_mps, drag_load_g, range_rate_mps: reference values.
        switch_*: nominal switch (second-entry) state; second_entry_range_m: S_std2.
        d_range_d_switch: dS2/d(speed, flight-path angle, altitude) (m/(m/s), m/rad, m/m).
        d_range_d_bank: dS2/d(uniform bank offset), m/rad.
        first_entry_bank_rad: nominal first-entry bank (the end value sigma_f of the
            predictor-corrector profile).
        sigma_a_rad, sigma_b_rad, v_end_mps: the designed linear profile.
        range_per_*: sensitivities of the remaining reference range to the drag load (m/g),
            to Ḣ (m per m/s) and to a uniform change of cos(sigma) (m), and the reference
            time to go (s): the velocity-scheduled gain vectors of eq. 7.
    """

    velocity_mps: Float[Array, " n"]
    bank_rad: Float[Array, " n"]
    range_to_go_m: Float[Array, " n"]
    hdot_mps: Float[Array, " n"]
    drag_load_g: Float[Array, " n"]
    range_rate_mps: Float[Array, " n"]
    switch_velocity_mps: Scalar
    switch_fpa_rad: Scalar
    switch_altitude_m: Scalar
    switch_time_s: Scalar
    second_entry_range_m: Scalar
    d_range_d_switch: Float[Array, "3"]
    d_range_d_bank: Scalar
    first_entry_bank_rad: Scalar
    sigma_a_rad: Scalar
    sigma_b_rad: Scalar
    v_end_mps: Scalar
    range_per_drag_load_m: Float[Array, " n"]
    range_per_hdot_s: Float[Array, " n"]
    range_per_cos_bank_m: Float[Array, " n"]
    time_to_go_s: Float[Array, " n"]

    def _interpolator(self, speed):
        """Linear interpolation in the table at ``speed``, clamped to its ends: the function
        ``table -> value``. The speed grid is uniform (:func:`tabulate_reference`), so the
        interval is found by arithmetic, not by a search (a loop of gathers under ``vmap``);
        equal to ``jnp.interp`` up to rounding."""
        v = self.velocity_mps
        n = v.shape[0]
        x = jnp.clip((v[0] - speed) / (v[0] - v[-1]) * (n - 1), 0.0, n - 1.0)
        i = jnp.clip(jnp.floor(x).astype(jnp.int32), 0, n - 2)
        w = x - i
        return lambda table: table[i] + w * (table[i + 1] - table[i])

    def sensitivities(self, speed):
        """(dR/dN_gx, dR/dḢ, dR/dcos sigma, time to go) of the reference at ``speed``."""
        f = self._interpolator(speed)
        return (
            f(self.range_per_drag_load_m),
            f(self.range_per_hdot_s),
            f(self.range_per_cos_bank_m),
            f(self.time_to_go_s),
        )

    def lookup(self, speed):
        """(bank, range to go, Ḣ, N_gx, Ṡ) of the reference at ``speed`` (clamped)."""
        f = self._interpolator(speed)
        return (
            f(self.bank_rad),
            f(self.range_to_go_m),
            f(self.hdot_mps),
            f(self.drag_load_g),
            f(self.range_rate_mps),
        )

    def bank_at(self, speed):
        """The reference bank (rad) at ``speed``: ``lookup(speed)[0]``."""
        return self._interpolator(speed)(self.bank_rad)

    def switch_at_apogee(self, kepler_load_g) -> Array:
        """Whether the reference's second entry starts at the skip's apogee: its load never
        fell below ``kepler_load_g`` after the pull-up (no Kepler phase), so the switch is the
        first descending point, where the drag load is above the threshold (by more than 10 %;
        at the end of a Kepler arc it is the threshold within a design step, 0.19-0.20 g at
        0.2 g, against 0.25-0.68 g at an apogee switch)."""
        return self.drag_load_g[0] > 1.1 * kepler_load_g

    def second_entry_range(self, fv: FlightVariables) -> Scalar:
        """Seed 003 eq. 10: S2 = S_std2 + dF/dv dv + dF/dtheta dtheta + dF/dH dH, m."""
        delta = jnp.stack(
            [
                fv.speed_mps - self.switch_velocity_mps,
                fv.fpa_rad - self.switch_fpa_rad,
                fv.altitude_m - self.switch_altitude_m,
            ]
        )
        return self.second_entry_range_m + jnp.dot(self.d_range_d_switch, delta)


class EntryMission(NamedTuple):
    """What the capsule system hands an entry law's ``from_config`` as its ``ctx``: the
    mission data the law's fields depend on, in SI units.

    Attributes:
        chute_altitude_m: the chute deploys (guidance ends) below it, m.
        reference: the second-entry reference designed for this vehicle, entry and target
            (for a law whose :meth:`AbstractEntryGuidance.reference_switch_load_g` is not
            ``None``), else ``None``.
        entry_mode: the mode the reference was designed for, "skip" or "direct"
            (:mod:`gnc_jax.guidance.entry.direct`).
        load_limit_g: the capsule's load limit (``simulation.load_limit_g``), g: a run whose
            sensed load exceeds it reads ``overload``.
    """

    chute_altitude_m: Scalar
    reference: ReferenceTrajectory | None = None
    entry_mode: str = "skip"
    load_limit_g: float = math.inf
