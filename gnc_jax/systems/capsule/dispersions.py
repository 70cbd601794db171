"""The capsule's dispersions: the ``[dispersions]`` section (seed 003 Table 2), declared once.

The file gives 3-sigma values (the mass a uniform half width) in the paper's units; the Module
holds the 1-sigma values in SI that :func:`~gnc_jax.systems.capsule.simulation.dispersed_entry`
scales its standard-normal draws by.
"""

import math

import equinox as eqx

from ..._types import Scalar
from ...params import param

THIRD = 1.0 / 3.0  # the scenario gives 3-sigma values


def _sigma_deg(x):
    return math.radians(x) * THIRD


def _sigma_km(x):
    return x * 1e3 * THIRD


def _sigma_pct(x):
    return x / 100 * THIRD


class CapsuleDispersions(eqx.Module):
    """1-sigma dispersions, SI; the ``[dispersions]`` section gives 3-sigma values (seed 003
    Table 2; the mass is uniform within ± its half width)."""

    speed_mps: Scalar = param(
        100.0,
        toml="speed_mps",
        section="dispersions",
        scale=THIRD,
        lo=0.0,
        hi=2000.0,
        units="m/s",
        doc="3-sigma entry speed",
    )
    fpa_rad: Scalar = param(
        0.2,
        toml="fpa_deg",
        section="dispersions",
        convert=_sigma_deg,
        lo=0.0,
        hi=5.0,
        units="deg",
        doc="3-sigma entry flight-path angle",
    )
    heading_rad: Scalar = param(
        0.5,
        toml="heading_deg",
        section="dispersions",
        convert=_sigma_deg,
        lo=0.0,
        hi=10.0,
        units="deg",
        doc="3-sigma entry heading",
    )
    downrange_m: Scalar = param(
        100.0,
        toml="downrange_km",
        section="dispersions",
        convert=_sigma_km,
        lo=0.0,
        hi=2000.0,
        units="km",
        doc="3-sigma entry point along track",
    )
    altitude_m: Scalar = param(
        1.0,
        toml="altitude_km",
        section="dispersions",
        convert=_sigma_km,
        lo=0.0,
        hi=50.0,
        units="km",
        doc="3-sigma entry altitude",
    )
    crossrange_m: Scalar = param(
        100.0,
        toml="crossrange_km",
        section="dispersions",
        convert=_sigma_km,
        lo=0.0,
        hi=2000.0,
        units="km",
        doc="3-sigma entry point across track",
    )
    lift_frac: Scalar = param(
        20.0,
        toml="cl_pct",
        section="dispersions",
        convert=_sigma_pct,
        lo=0.0,
        hi=90.0,
        units="%",
        doc="3-sigma lift coefficient",
    )
    drag_frac: Scalar = param(
        20.0,
        toml="cd_pct",
        section="dispersions",
        convert=_sigma_pct,
        lo=0.0,
        hi=90.0,
        units="%",
        doc="3-sigma drag coefficient",
    )
    density_frac: Scalar = param(
        30.0,
        toml="density_pct",
        section="dispersions",
        convert=_sigma_pct,
        lo=0.0,
        hi=90.0,
        units="%",
        doc="3-sigma atmospheric density",
    )
    mass_frac_half_width: Scalar = param(
        5.0,
        toml="mass_pct",
        section="dispersions",
        convert=lambda x: x / 100,
        lo=0.0,
        hi=50.0,
        units="%",
        doc="uniform half-width (not 3-sigma)",
    )


__all__ = ["CapsuleDispersions"]
