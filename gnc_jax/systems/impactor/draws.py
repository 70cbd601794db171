"""The random streams of one impactor run, and the dispersed start they set.

Each kind of draw has its own stream (:mod:`gnc_jax._random`), so adding a kind never changes
the others. A run draws only what it uses, at the rate it is used:

* once per run: delivery, knowledge (position, velocity), attitude bias, accelerometer bias,
  camera misalignment (3 each);
* once per image i (stream ``_IMAGES``, index i), ``IMAGE_DRAWS`` standard normals:
  [0:2] image-processing noise, [2:5] attitude control, [5:8] attitude knowledge;
* once per run (stream ``_BURNS``), a table of what only burns use, ``BURN_DRAWS`` normals per
  row: [0:4] the execution error (magnitude, 3-axis pointing) of the interval's first
  ignition, [4:8] that of its later ignitions, [8:14] the accelerometer's white noise
  integrated over the interval (:func:`~.navigation.accel_noise`). Row j belongs to the j-th
  image interval in which the engine fires (64 rows: 16 min of burning at the paper's 15 s
  image interval).

Nothing is drawn per control step: the engine fires in well under 1 % of the steps and in a
few per cent of the image intervals, yet every vmapped lane computes whatever any lane might
use: drawing the burns' normals with each image (18 normals instead of 8) cost more than the
whole table, and one row fetched per image costs less than fetching separate ones.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..._numerics import matmul, matvec3
from ..._random import fold_in, normal, stream_key, stream_normal, written_out
from ..._types import Array, Float, PRNGKeyArray, Vector3
from ...dynamics.impactor import ImpactorState
from ...navigation.ekf import NavEstimate
from .navigation import attitude_bias_covariance
from .state import ImpactorSimulation

_DELIVERY, _KNOW_POS, _KNOW_VEL, _ATT_BIAS, _ACC_BIAS, _IMAGES, _BURNS, _MISALIGNMENT = range(8)
IMAGE_DRAWS = 8
BURN_DRAWS = 14
# A run with more burning intervals than the table's rows reuses them cyclically. A third or
# later ignition within one interval repeats the second's draw: a law that chatters on and off
# within one interval fires again with the execution error it just had.
N_BURN_INTERVALS = 64


class ImpactorDraws(NamedTuple):
    """A run's fixed draws: the dispersion the outcome reports (delivery, knowledge and bias
    draws, by outcome field), the burn table, the camera misalignment (``None`` when the
    scenario has none) and the images' stream key (:func:`image_stream`)."""

    dispersion: dict
    burns: Float[Array, "N_BURN_INTERVALS 14"]
    misalignment: Vector3 | None
    image_stream: PRNGKeyArray


def image_stream(key: PRNGKeyArray) -> PRNGKeyArray:
    """The key of the images' stream, into which each image folds its index: a run's loop
    derives it once (a fold-in is a hash). Its fold-ins and draws are
    :func:`~gnc_jax._random.written_out`: the same numbers, fused."""
    return written_out(stream_key(key, _IMAGES))


def image_key(key: PRNGKeyArray, i) -> PRNGKeyArray:
    """The key of image ``i``'s stream."""
    return image_key_in(image_stream(key), i)


def image_key_in(stream: PRNGKeyArray, i) -> PRNGKeyArray:
    """The key of image ``i``'s stream from the images' stream key (:func:`image_stream`)."""
    return fold_in(stream, i, indexed=True)


def image_normals(stream: PRNGKeyArray, i, bits_once=None) -> Float[Array, "8"]:
    """The standard normals of image ``i`` (layout above) from the images' stream key
    (:func:`image_stream`); ``bits_once``: see :func:`~gnc_jax._random.normal`.

    Drawn in single precision (24-bit uniforms, so the tails end near 5.3 sigma) and used in
    float64: measured 1.7x cheaper than float64 draws, which were a third of the closed loop's
    time. The per-run draws (delivery, knowledge, biases), which set the dispersion, stay
    float64.
    """
    w = normal(image_key_in(stream, i), (IMAGE_DRAWS,), jnp.float32, bits_once)
    return w.astype(jnp.float64)


def image_draws(key: PRNGKeyArray, i) -> Float[Array, "8"]:
    """The standard normals of image ``i`` of the run with key ``key`` (:func:`image_normals`
    of its :func:`image_stream`)."""
    return image_normals(image_stream(key), i)


def burn_draws(key: PRNGKeyArray) -> Float[Array, "N_BURN_INTERVALS 14"]:
    """The normals of a run's burns: row j for its j-th image interval with a burn (layout
    above)."""
    return stream_normal(key, _BURNS, (N_BURN_INTERVALS, BURN_DRAWS))


def run_draws(sim: ImpactorSimulation, key: PRNGKeyArray) -> dict:
    """Every standard normal one run uses, by kind: what a peer implementation is fed to
    reproduce gnc_jax's outcomes run for run (``benchmarks/peers``)."""
    return dict(
        delivery=stream_normal(key, _DELIVERY),
        knowledge_position=stream_normal(key, _KNOW_POS),
        knowledge_velocity=stream_normal(key, _KNOW_VEL),
        attitude_bias=stream_normal(key, _ATT_BIAS),
        accel_bias=stream_normal(key, _ACC_BIAS),
        burns=burn_draws(key),
        images=jax.vmap(lambda i: image_draws(key, i))(jnp.arange(sim.n_images)),
    )


def initial_conditions(sim: ImpactorSimulation, key: PRNGKeyArray):
    """Dispersed truth, initial estimate and constant error draws of one run."""
    err = sim.errors
    c_bi = sim.context.c_bi
    delivery = err.delivery_position_m * stream_normal(key, _DELIVERY)
    know_pos = err.knowledge_position_m * stream_normal(key, _KNOW_POS)  # S, T, R components
    know_vel = err.knowledge_velocity_mps * stream_normal(key, _KNOW_VEL)
    r_true = sim.r0_m + delivery
    truth = ImpactorState(r_true, sim.v0_mps, jnp.asarray(sim.mass_kg, float))
    x_hat = jnp.concatenate([r_true + matvec3(c_bi.T, know_pos), sim.v0_mps + know_vel])
    p_pos = matmul(c_bi.T * err.knowledge_position_m**2, c_bi)
    p0 = jax.scipy.linalg.block_diag(p_pos, err.knowledge_velocity_mps**2 * jnp.eye(3))
    p0 = p0 + sim.consider_attitude_bias * attitude_bias_covariance(
        sim.r0_m, sim.v0_mps, sim.noise_model.attitude_bias_rad
    )
    draws = dict(
        delivery_error_m=matvec3(c_bi, delivery),
        knowledge_position_error_m=know_pos,
        knowledge_velocity_error_mps=matvec3(c_bi, know_vel),
        attitude_bias_rad=err.attitude_bias_rad * stream_normal(key, _ATT_BIAS),
        accel_bias_mps2=err.accel_bias_mps2 * stream_normal(key, _ACC_BIAS),
    )
    return truth, NavEstimate(x_hat, p0), draws


def camera_misalignment(sim: ImpactorSimulation, key: PRNGKeyArray) -> Vector3:
    """The run's camera misalignment (rad, a rotation vector): fixed for the run, its own
    random stream, so the other draws do not change with it."""
    return sim.errors.camera_misalignment_rad * stream_normal(key, _MISALIGNMENT)


__all__ = [
    "BURN_DRAWS",
    "IMAGE_DRAWS",
    "N_BURN_INTERVALS",
    "ImpactorDraws",
    "burn_draws",
    "camera_misalignment",
    "image_draws",
    "image_key",
    "image_key_in",
    "image_normals",
    "image_stream",
    "initial_conditions",
    "run_draws",
]
