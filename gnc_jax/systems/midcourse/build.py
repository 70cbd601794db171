"""From a midcourse scenario's parameters to its simulation data: the force model, the
B-plane reference plane, the epochs and aim, and the designed nominal transfer."""

import equinox as eqx
import jax.numpy as jnp

from ..._types import Vector3
from ...dynamics.ephemeris import ECLIPTIC_POLE_EQUATORIAL, GM_PLANETS, planet_index, planet_state
from ...dynamics.heliocentric import SOLAR_PRESSURE_1AU, EphemerisTable, HeliocentricModel
from ...geometry.bplane import BPlaneError
from ...params import schema_of
from ...schema import ScenarioError
from .nominal import StepBudgetError, design_nominal
from .params import Dynamics, MidcourseParameters, parameters
from .simulation import MidcourseSimulation


def reference_normal(plane: str, t_encounter_s: float) -> Vector3:
    """Normal of the B-plane reference plane in EME2000 (the ecliptic pole)."""
    if plane == "ecliptic":
        return jnp.asarray(ECLIPTIC_POLE_EQUATORIAL)
    if plane == "equator":
        return jnp.array([0.0, 0.0, 1.0])
    r, v = planet_state(planet_index("mars"), t_encounter_s)
    h = jnp.cross(r, v)
    return h / jnp.linalg.norm(h)


def _model(p: MidcourseParameters, t_max_s: float) -> HeliocentricModel:
    """The heliocentric force model of a scenario's parameters (SI)."""
    sc, dy = p.spacecraft, p.dynamics
    f = lambda x: jnp.asarray(x, dtype=jnp.float64)  # noqa: E731
    srp = sc.reflectivity * sc.srp_area_m2 / sc.mass_kg if bool(dy.srp) else 0.0
    table = None
    if dy.ephemeris == "table":
        table = EphemerisTable.spanning(p.mission.first_fix_epoch_s, t_max_s)
    return HeliocentricModel(
        ephemeris=table,
        gm_planets=f(GM_PLANETS if bool(dy.planets) else [0.0] * 8),
        srp_m2_per_kg=f(srp),
        solar_pressure_npm2=f(SOLAR_PRESSURE_1AU),
        rtol=dy.rtol,
        atol=dy.atol,
        solver=dy.solver,
        max_steps=dy.max_steps,
    )


def simulation_data(p: MidcourseParameters) -> MidcourseSimulation:
    """The simulation data of a scenario's parameters, before the nominal is designed."""
    mi, dy, nv, g = p.mission, p.dynamics, p.navigation, p.guidance
    f = lambda x: jnp.asarray(x, dtype=jnp.float64)  # noqa: E731
    t_max = mi.encounter_epoch_s + dy.window_s
    aim = jnp.stack([mi.aim_b_m[1], mi.aim_b_m[0]])  # Q order: (B_R, B_T[, t])
    if g.targets == "b_plane_tof":
        aim = jnp.concatenate([aim, jnp.zeros(1)])
    enabled = bool(g.enabled)
    return MidcourseSimulation(
        model=_model(p, t_max),
        r0_m=jnp.zeros(3),
        v0_mps=jnp.zeros(3),
        t_first_fix_s=f(mi.first_fix_epoch_s),
        fix_interval_s=nv.fix_interval_s,
        t_encounter_s=f(mi.encounter_epoch_s),
        t_max_s=f(t_max),
        aim=aim,
        ref_normal=reference_normal(mi.reference_plane, mi.encounter_epoch_s),
        goal=jnp.stack([p.goal.b_m, p.goal.tof_s]),
        errors=p.errors,
        n_fixes=nv.fixes,
        guidance_enabled=enabled,
        reference_dv=enabled and p.errors.has_per_fix_errors(),
    )


def build(scenario) -> MidcourseSimulation:
    """Simulation data of a validated midcourse :class:`Scenario` (SI, from
    :func:`gnc_jax.systems.midcourse.params.parameters`); the law is built by the system from
    ``[guidance.<law>]`` (``systems.midcourse``).

    Designs the nominal transfer (`design_nominal`, cached) before returning; a nominal that
    cannot be targeted raises :class:`ScenarioError`.
    """
    p = parameters(scenario.config)
    sim = simulation_data(p)
    try:
        nominal = design_nominal(sim, p.mission.launch_epoch_s)
    except BPlaneError as error:
        raise ScenarioError(
            f"mission.reference_plane: {p.mission.reference_plane!r}: {error}"
        ) from None
    except StepBudgetError as error:
        allowed = schema_of(Dynamics)["max_steps"].allowed()
        enough = (
            f"more than {error.max_steps}"
            if error.needed is None
            else f"at least {error.needed} (dispersed runs may need more)"
        )
        raise ScenarioError(
            f"dynamics.max_steps: {error}; allowed: {allowed}, {enough}, or a looser dynamics.rtol"
        ) from None
    except ValueError as error:
        raise ScenarioError(
            f"mission: {error}; allowed: epochs and aim point of a feasible transfer"
        ) from None
    return eqx.tree_at(lambda s: (s.r0_m, s.v0_mps), sim, (nominal.r0_m, nominal.v0_mps))


__all__ = ["build", "reference_normal", "simulation_data"]
