"""The reference design's problem of a capsule scenario, built the way the capsule system builds
it but without designing: for the tests of the reach checks and of the design's stages."""

import jax.numpy as jnp

import gnc_jax as gj
from gnc_jax.dynamics.entry import entry_state_from_conditions
from gnc_jax.guidance.entry.base import EntryModel
from gnc_jax.guidance.entry.nominal import NominalProblem
from gnc_jax.systems.capsule import simulation as capsule_sim
from gnc_jax.systems.capsule.params import capsule_params


def design_problem(scenario) -> NominalProblem:
    """The design problem of ``scenario``: its nominal vehicle, entry and target, the skip-entry
    law's switch load and the ``[reference]`` section's end speed."""
    cfg = scenario.config
    p = capsule_params(cfg)
    earth, vehicle, atmosphere, entry = capsule_sim.nominal_models(p)
    return NominalProblem(
        model=EntryModel(vehicle, earth, atmosphere),
        entry=entry_state_from_conditions(entry, earth),
        target_fixed=capsule_sim.target_direction(p, earth, entry),
        kepler_load_g=jnp.asarray(cfg["guidance"]["skip_entry"]["kepler_load_g"]),
        chute_altitude_m=p.entry.chute_altitude_m,
        v_end_mps=jnp.asarray(p.reference.v_end_mps),
    )


def skip_entry_problem(overrides) -> tuple[NominalProblem, dict]:
    """The design problem of ``lunar-skip-entry`` with ``overrides``, and its configuration."""
    scenario = gj.load_scenario("lunar-skip-entry", overrides=overrides)
    return design_problem(scenario), scenario.config
