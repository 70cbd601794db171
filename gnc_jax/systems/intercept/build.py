"""From an intercept scenario's parameters to its simulation data: the nominal initial truth,
the loop sizes (shared with the cost model) and :class:`~.state.PNSimulation`."""

import math
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from ...dynamics.impactor import Engine
from ...dynamics.intercept import InterceptDynamics, InterceptState
from ...geometry.bplane import b_plane_frame
from ...geometry.kepler import OrbitalElements, elements_to_state
from ...guidance.intercept.apn import PNGuidanceContext
from ...navigation.measurements import GaussianLOSMeasurement
from .params import InterceptParameters, parameters
from .state import PNSimulation


def initial_state(p: InterceptParameters) -> tuple[InterceptState, bool]:
    """Nominal initial truth (SI) of an intercept scenario's parameters, and whether it is
    planar.

    ``bennu-3d``: the target's state from the Table 1 elements (ecliptic J2000, the paper's
    mu_sun), and the Table 2 relative state (impactor minus target) expressed in the target's
    (radial, transverse, orbit-normal) frame: the planar case rotated onto Bennu's orbit.
    """
    a = p.approach
    r_t, v_t = np.asarray(a.target_position_m), np.asarray(a.target_velocity_mps)
    r_rel = np.asarray(a.impactor_position_m) - r_t
    v_rel = np.asarray(a.impactor_velocity_mps) - v_t
    planar = a.geometry == "planar"
    if not planar:
        # The planar frame of Table 2: x radial, y transverse (the target is at perihelion).
        radial, transverse = r_t / np.linalg.norm(r_t), v_t / np.linalg.norm(v_t)
        rel_rtn = np.array([r_rel @ radial, r_rel @ transverse, r_rel[2]])
        vel_rtn = np.array([v_rel @ radial, v_rel @ transverse, v_rel[2]])
        el = OrbitalElements(
            a.semi_major_axis_m,
            a.eccentricity,
            a.inclination_rad,
            a.raan_rad,
            a.arg_perihelion_rad,
            a.true_anomaly_rad,
        )
        r_t, v_t = (np.asarray(x) for x in elements_to_state(el, p.dynamics.mu_sun_m3s2))
        x = r_t / np.linalg.norm(r_t)
        zn = np.cross(r_t, v_t)
        zn = zn / np.linalg.norm(zn)
        y = np.cross(zn, x)
        rot = np.stack([x, y, zn], axis=1)  # RTN -> ecliptic
        r_rel, v_rel = rot @ rel_rtn, rot @ vel_rtn
    f = lambda x: jnp.asarray(x, dtype=jnp.float64)  # noqa: E731
    y0 = InterceptState(f(r_t), f(v_t), f(r_rel), f(v_rel), p.spacecraft.mass_kg)
    return y0, planar


class LoopSizes(NamedTuple):
    """The loop lengths of one run, shared by :func:`build` and the cost model
    (:meth:`InterceptSystem.steps_per_run`)."""

    cutoff_time_s: float  # guidance stops here: the straight-line time of flight - coast_s
    n_images: float  # LOS images (measurement intervals) before the cutoff
    steps_per_image: float  # guidance steps per image


def loop_sizes(p: InterceptParameters, y0: InterceptState) -> LoopSizes:
    """The loop lengths of a scenario with parameters ``p`` and initial truth ``y0``; whole
    numbers (ints) unless they would not fit in one, so that a runaway scenario still gets a
    (refusable) cost estimate."""
    r0, v0 = np.asarray(y0.r), np.asarray(y0.v)
    tof = float(-(r0 @ v0) / (v0 @ v0))
    t_cut = tof - p.guidance.coast_s
    image_dt = p.navigation.image_interval_s
    images, per_image = t_cut / image_dt, image_dt / p.guidance.dt_s
    if images < 1e15 and per_image < 1e15:
        images, per_image = math.ceil(images - 1e-9), round(per_image)
    return LoopSizes(t_cut, images, per_image)


def build(scenario) -> PNSimulation:
    """Simulation data of a validated intercept :class:`Scenario` (SI units, from
    :func:`gnc_jax.systems.intercept.params.parameters`); the law is built by the system from
    ``[guidance.apn]`` (``systems.intercept``)."""
    p = parameters(scenario.config)
    dy, sc, g, nv = p.dynamics, p.spacecraft, p.guidance, p.navigation
    f = lambda x: jnp.asarray(x, dtype=jnp.float64)  # noqa: E731
    y0, planar = initial_state(p)
    h = jnp.array([0.0, 0.0, 1.0])  # ecliptic / paper-plane normal: the B-plane reference
    c_bi = b_plane_frame(y0.v, h)
    rho = -np.asarray(y0.r)
    u = rho / np.linalg.norm(rho)
    cross = np.cross(np.asarray(h), u)
    cross = cross / np.linalg.norm(cross)
    los_frame0 = f(np.stack([u, cross, np.cross(u, cross)]))
    sizes = loop_sizes(p, y0)
    dynamics = InterceptDynamics(dy.mu_sun_m3s2, dy.mu_target_m3s2, dy.target_radius_m)
    engine = Engine(sc.thrust_n, sc.isp_s)
    context = PNGuidanceContext(
        range0_m=f(np.linalg.norm(np.asarray(y0.r))),
        cutoff_time_s=f(sizes.cutoff_time_s),
        pulse_fraction=sc.pulse_width_s / g.dt_s,
        dynamics=dynamics,
        reference_normal=h,
        dt_s=g.dt_s,
    )
    return PNSimulation(
        y0=y0,
        context=context,
        dynamics=dynamics,
        engine=engine,
        propellant_kg=sc.propellant_kg,
        miss_limit_m=g.miss_limit_m,
        errors=p.errors,
        process_noise_m2s3=nv.process_noise_m2s3,
        model_attitude_rad=(
            p.errors.attitude_rad if float(nv.model_attitude_rad) < 0.0 else nv.model_attitude_rad
        ),
        c_bi=c_bi,
        los_frame0=los_frame0,
        planar=planar,
        nav_model=nv.model,
        n_images=int(sizes.n_images),
        steps_per_image=int(sizes.steps_per_image),
        coast_steps=g.coast_steps,
        measurement=GaussianLOSMeasurement(p.errors.attitude_rad, planar=planar),
    )


__all__ = ["LoopSizes", "build", "initial_state", "loop_sizes"]
