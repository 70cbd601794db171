"""Reference tracking of the skip-entry law's second entry (seed 003 §2.2, eqs. 6-7, 16-17).

The second entry follows the designed reference
(:class:`~gnc_jax.guidance.entry.reference.ReferenceTrajectory`): cos sigma_c = [(L/D)_0 cos
sigma_0 + K.Delta] / (L/D) (eq. 6 without its repeated K.Delta, a typo), with the feedback of
eq. 7 on the drag load N_gx, Ḣ, the range to go S and its rate, its gains scheduled with speed
from the reference's own range sensitivities. The reference bank is corrected once, at the
switch point, by eqs. 16-17 (switch-point compensation). Each function takes the law
(:class:`~gnc_jax.guidance.entry.skip_entry.SkipEntryGuidance`) for its gains and reference.
"""

import jax.numpy as jnp

from ..._types import Scalar
from ..schedule import scheduled
from .base import FlightVariables


def switch_compensation(law, fv: FlightVariables, range_to_go_m) -> Scalar:
    """Bank offset (rad) at the switch point (eqs. 16-17, signs made consistent): the
    offset that makes the expanded second-entry range equal the actual range to go."""
    s2 = law.reference.second_entry_range(fv)
    return (range_to_go_m - s2) / law.reference.d_range_d_bank


def feedback_gains(law, speed):
    """Gain vector K(v) of eq. 7 on (ΔN_gx, ΔḢ, ΔS, ΔṠ), per g, s/m, 1/m, s/m.

    The gains are scheduled with speed from the reference's own range sensitivities (as
    Apollo's final phase does): the range the current deviations will add,
    ΔR = dR/dN ΔN_gx + dR/dḢ ΔḢ - t_go ΔṠ, is compared with the range to go deviation ΔS,
    and the difference is removed with cos sigma through dR/dcos. The four leaves
    ``k_range`` (overall gain on ΔS - ΔR) and ``k_drag_load``, ``k_hdot``, ``k_range_rate``
    (weights of the predicted-range terms) are dimensionless multipliers (1 = nominal), each
    constant or scheduled with speed (``<gain>_schedule`` at ``schedule_speed_kmps``).
    """
    f_drag, f_hdot, f_cos, t_go = law.reference.sensitivities(speed)
    f_cos = jnp.maximum(f_cos, 1.0e3)  # no authority left near the chute: bounded gains
    b = law.schedule_speed_mps
    k_range = scheduled(law.k_range, law.k_range_schedule, b, speed)
    k_drag_load = scheduled(law.k_drag_load, law.k_drag_load_schedule, b, speed)
    k_hdot = scheduled(law.k_hdot, law.k_hdot_schedule, b, speed)
    k_range_rate = scheduled(law.k_range_rate, law.k_range_rate_schedule, b, speed)
    k = k_range / f_cos
    return jnp.stack(
        [
            -k * k_drag_load * f_drag,
            -k * k_hdot * f_hdot,
            k,
            k * k_range_rate * t_go,
        ]
    )


def track(law, speed, drag_load, hdot, range_to_go, range_rate, ld_ratio, bank_offset):
    """Commanded bank magnitude (rad) of the second entry (eqs. 6-7).

    ``ld_ratio``: measured L/D over the reference (L/D)_0."""
    ref_bank, ref_s, ref_hdot, ref_ngx, ref_sdot = law.reference.lookup(speed)
    delta = jnp.stack(
        [drag_load - ref_ngx, hdot - ref_hdot, range_to_go - ref_s, range_rate - ref_sdot]
    )
    k_delta = jnp.dot(feedback_gains(law, speed), delta)
    cos_cmd = (jnp.cos(ref_bank + bank_offset) + k_delta) / ld_ratio
    # keep a minimum bank so that the lateral channel never loses all its authority
    lim = jnp.cos(law.track_bank_min_rad)
    return jnp.arccos(jnp.clip(cos_cmd, -lim, lim))
