"""An impactor scenario's simulation data: :func:`build` turns the declared parameters
(:class:`~gnc_jax.systems.impactor.params.ImpactorParams`, SI) into the
:class:`~.state.ImpactorSimulation` one run reads."""

import dataclasses

import jax.numpy as jnp

from ...constants import GM_SUN_M3S2
from ...dynamics.impactor import Engine, RelativeDynamics
from ...geometry.bplane import b_plane_frame, check_b_plane_frame
from ...guidance.impactor.base import ImpactorGuidanceContext
from ...navigation.measurements import MeasurementSetup, measurement_class
from .params import ImpactorParams, timeline
from .state import ImpactorSimulation


def measurement_setup(p: ImpactorParams) -> MeasurementSetup:
    """What the measurement front end is built from (SI), from the scenario's parameters."""
    return MeasurementSetup(
        camera=p.camera.model(),
        target=p.target.model(p.dynamics.sun_unit),
        image_processing_rad=p.errors.image_processing_rad,
        phase_correction=p.navigation.phase_correction,
    )


_MODELLED = (
    "image_processing_rad",
    "attitude_noise_rad",
    "attitude_bias_rad",
    "accel_bias_mps2",
    "accel_noise_mps2",
)
"""The error sources the filter also models; ``navigation.model_<name>`` sets its own value."""


def noise_model(p: ImpactorParams):
    """The error sources as the filter models them: the truth's ``errors``, with each
    ``navigation.model_*`` field that is set (non-negative) in place of the truth's value."""
    nav = p.navigation
    values = {}
    for name in _MODELLED:
        model = getattr(nav, f"model_{name}")
        values[name] = getattr(p.errors, name) if float(model) < 0.0 else model
    return dataclasses.replace(p.errors, **values)


def build(scenario) -> ImpactorSimulation:
    """Simulation data of a validated impactor :class:`Scenario` (SI units, from the declared
    parameters :class:`~gnc_jax.systems.impactor.params.ImpactorParams`); the guidance law is
    built by the system from ``[guidance.<law>]`` (``systems.impactor``)."""
    p = ImpactorParams.of(scenario.config)
    a, sc, dy, g = p.approach, p.spacecraft, p.dynamics, p.guidance
    f = lambda x: jnp.asarray(x, dtype=jnp.float64)  # noqa: E731
    check_b_plane_frame(a.velocity_mps, a.reference_normal)
    c_bi = b_plane_frame(a.velocity_mps, a.reference_normal)
    times = timeline(p)
    d = dy.sun_distance_m
    tide = GM_SUN_M3S2 / d**3 if d > 0 else 0.0
    sun = dy.sun_unit
    dynamics = RelativeDynamics.of(dy.mu_target_m3s2, tide, sun)
    engine = Engine(sc.thrust_n, sc.isp_s)
    context = ImpactorGuidanceContext(
        c_bi=c_bi,
        aim_initial_m=g.aim_initial_m,
        aim_final_m=g.aim_final_m,
        retarget_time_s=f(times.retarget_time_s),
        cutoff_time_s=f(times.cutoff_time_s),
        engine=engine,
        mass_kg=sc.mass_kg,
        dynamics=dynamics,
        dt_s=g.dt_s,
        image_interval_s=p.camera.image_interval_s,
    )
    setup = measurement_setup(p)
    return ImpactorSimulation(
        r0_m=a.position_m,
        v0_mps=a.velocity_mps,
        context=context,
        dynamics=dynamics,
        engine=engine,
        mass_kg=sc.mass_kg,
        propellant_kg=sc.propellant_kg,
        miss_limit_m=g.miss_limit_m,
        errors=p.errors,
        noise_model=noise_model(p),
        focal_length_m=p.camera.focal_length_m,
        process_noise_m2s3=p.navigation.process_noise_m2s3,
        consider_attitude_bias=p.navigation.consider_attitude_bias,
        n_images=times.n_images,
        steps_per_image=times.steps_per_image,
        steps_after_cutoff=times.steps_after_cutoff,
        coast_steps=dy.coast_steps,
        camera_misaligned=float(p.errors.camera_misalignment_rad) != 0.0,
        measurement=measurement_class(p.navigation.measurement).from_setup(setup),
        camera=setup.camera,
        target=setup.target,
    )


__all__ = ["build", "measurement_setup", "noise_model"]
