"""The second-entry reference of a capsule scenario: the nominal problem of its vehicle,
entry and target, designed once (:func:`gnc_jax.guidance.entry.cache.reference_for`: the reach
check, the design and the tabulation, behind a progress bar, then cached on disk) and handed to
the guidance law, with the chute altitude, in its
:class:`~gnc_jax.guidance.entry.reference.EntryMission` by
:meth:`CapsuleSystem.build <gnc_jax.systems.capsule.CapsuleSystem.build>`.
"""

import jax.numpy as jnp

from ...dynamics.entry import entry_state_from_conditions
from ...guidance.entry.base import AbstractEntryGuidance, EntryModel
from ...guidance.entry.cache import reference_for
from ...guidance.entry.direct import (
    design_direct,
    direct_conditions,
    direct_reach,
    direct_reference,
    reach_text,
    scan_direct,
)
from ...guidance.entry.nominal import NominalProblem
from ...guidance.entry.reference import EntryMission, ReferenceTrajectory
from ...params import from_scenario
from ...schema import ScenarioError
from .params import ReferenceDesignParams
from .simulation import CapsuleSimulation


def nominal_problem(config: dict, sim: CapsuleSimulation, switch_load_g: float) -> NominalProblem:
    """The reference design's problem: the nominal vehicle, entry and target of ``sim``, the
    switch load (g) and the ``[reference]`` section's end speed of the second-entry profile."""
    ref = from_scenario(ReferenceDesignParams, config)
    return NominalProblem(
        model=EntryModel(sim.vehicle, sim.earth, sim.atmosphere),
        entry=entry_state_from_conditions(sim.entry, sim.earth),
        target_fixed=sim.target_fixed,
        kepler_load_g=jnp.asarray(switch_load_g, dtype=jnp.float64),
        chute_altitude_m=sim.chute_altitude_m,
        v_end_mps=jnp.asarray(ref.v_end_mps, dtype=jnp.float64),
    )


def scenario_reference(
    config: dict, sim: CapsuleSimulation, switch_load_g: float
) -> ReferenceTrajectory:
    """The designed second-entry reference of a validated configuration ``config`` and its
    simulation data ``sim`` (the nominal vehicle, Earth, atmosphere, entry and target), for a
    law whose reference switches at the load ``switch_load_g`` (g; the law's Kepler-phase
    threshold). The design settings are the ``[reference]`` section's; the cache file is named
    by a hash of the ``entry``, ``vehicle`` and ``atmosphere`` sections, the switch load and
    the design settings."""
    ref = from_scenario(ReferenceDesignParams, config)
    problem = nominal_problem(config, sim, switch_load_g)
    # the problem named in file units (the cache file's name: keep it as it is)
    description = {
        "entry": config["entry"],
        "vehicle": config["vehicle"],
        "atmosphere": config["atmosphere"],
        "kepler_load_g": switch_load_g,
        "v_end_mps": ref.v_end_mps,
    }
    reference, _ = reference_for(
        problem, description, w_margin=ref.w_margin, steps=ref.design_steps
    )
    return reference


def law_mission(
    law: type[AbstractEntryGuidance], config: dict, sim: CapsuleSimulation
) -> EntryMission:
    """What the capsule system hands the law class ``law`` as the ``ctx`` of its
    ``from_config`` (SI units): the chute altitude of ``sim``, the capsule's load limit and,
    for a law that tracks a reference (whose ``reference_switch_load_g`` is not ``None``),
    the reference of :func:`scenario_reference`."""
    section = config["guidance"][law.law_name]
    load = law.reference_switch_load_g(section)
    limit = float(config["simulation"]["load_limit_g"])
    if load is None:
        return EntryMission(chute_altitude_m=sim.chute_altitude_m, load_limit_g=limit)
    reference, mode = mode_reference(
        config, sim, load, law.entry_mode_of(section), direct_load_limit_g(law, config)
    )
    return EntryMission(
        chute_altitude_m=sim.chute_altitude_m,
        reference=reference,
        entry_mode=mode,
        load_limit_g=limit,
    )


def direct_load_limit_g(law: type[AbstractEntryGuidance], config: dict) -> float:
    """The largest load (g) a direct landing of the law class ``law`` may see in a validated
    capsule configuration: the smaller of the capsule's ``simulation.load_limit_g`` (beyond it
    a run reads ``overload``) and the largest load the law's predictions fly."""
    predicted = law.predicted_load_limit_g(config["guidance"][law.law_name])
    limit = float(config["simulation"]["load_limit_g"])
    return limit if predicted is None else min(limit, float(predicted))


def mode_reference(
    config: dict,
    sim: CapsuleSimulation,
    switch_load_g: float,
    mode: str,
    load_limit_g: float | None = None,
):
    """The reference of the entry ``mode`` and the mode resolved: "skip" (the designed
    second-entry reference of :func:`scenario_reference`), "direct" (the constant-bank direct
    design of :mod:`gnc_jax.guidance.entry.direct`), or "auto": "direct" where the target
    lies inside the nominal vehicle's direct reach, else "skip" (a skip that cannot reach
    either is refused with both intervals). ``load_limit_g``: the largest load (g) a direct
    landing may see (``None``: none), which bounds the direct reach: the smaller of the
    capsule's ``simulation.load_limit_g`` and the largest load the law's predictions fly."""
    if mode == "skip":
        return scenario_reference(config, sim, switch_load_g), "skip"
    problem = nominal_problem(config, sim, switch_load_g)
    scan = scan_direct(problem, load_limit_g)
    reach = direct_reach(scan)
    inside = reach is not None and reach[0] <= 0.0 <= reach[1]
    if mode == "direct" or inside:
        try:
            bank = design_direct(problem, config["entry"], config["vehicle"], scan)
            return direct_reference(problem, bank, 1e3 * config["entry"]["range_km"]), "direct"
        except ScenarioError:
            if mode == "direct":
                raise
            # (auto: inside the reach, but no two neighbouring direct landings bracket it)
    try:
        return scenario_reference(config, sim, switch_load_g), "skip"
    except ScenarioError as e:
        raise ScenarioError(
            f"{e}; a direct entry reaches {reach_text(scan, config['entry'])} "
            f"({direct_conditions(scan)})"
        ) from None
