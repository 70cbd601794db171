"""Cross-field checks of a capsule scenario: what one field's range cannot say.

The fields themselves are declared once, with their units and ranges, on the parameter
Modules of :mod:`gnc_jax.systems.capsule.params`; these checks read the validated
configuration in the file's units.
"""

from ...schema import ScenarioError


def _multiple(a, b):
    r = a / b
    return abs(r - round(r)) < 1e-9 and round(r) >= 1


def check(cfg: dict) -> None:
    """Cross-field checks of a validated capsule configuration."""
    g, s = cfg["guidance"], cfg["simulation"]
    if not _multiple(s["control_dt_s"], s["dt_s"]):
        raise ScenarioError(
            f"simulation.control_dt_s: {s['control_dt_s']:g} s; allowed: a whole multiple of "
            f"simulation.dt_s = {s['dt_s']:g} s"
        )
    if not _multiple(g["pc_period_s"], s["control_dt_s"]):
        raise ScenarioError(
            f"guidance.pc_period_s: {g['pc_period_s']:g} s; allowed: a whole multiple of "
            f"simulation.control_dt_s = {s['control_dt_s']:g} s"
        )
