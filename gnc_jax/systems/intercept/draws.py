"""The random draws of one intercept run, each kind from its own stream of the run's key.

Once per run the knowledge errors and a table of pointing errors, one row per ignition (stream
``_IGNITIONS``: the k-th ignition of the run takes row k, cyclically past
``N_IGNITION_DRAWS``; one angle about the orbit normal when planar, two in 3-D); once per block
of ``DRAW_BLOCK`` images (stream ``_IMAGES``, index = block) the LOS measurement noise of its
images, one row per angle (the in-plane one, and the out-of-plane one in 3-D) and one column
per image. Nothing is drawn per guidance step, and only what a step uses: the paper scenario
ignites about 53 times in 91,200 steps, so drawing a pointing error at every image cost as much
as its measurement noise (8 ns of a 150 ns step). A block, not an image, per draw: jax's
threefry hash runs as a five-trip loop on CPU, whose fixed cost per call is then shared by
``DRAW_BLOCK`` images.
"""

from typing import NamedTuple

import jax.numpy as jnp

from ..._random import normal, stream_key, stream_normal
from ..._types import Array, Float, PRNGKeyArray, Vector3
from .state import PNSimulation

_KNOW_POS, _KNOW_VEL, _IMAGES, _IGNITIONS, _FRONT_END = range(5)
DRAW_BLOCK = 64
N_IGNITION_DRAWS = 128
"""Rows of the per-run pointing table (measured: at most 67 ignitions per run in 2000 runs of
``bennu-apn``, 103 in 500 of ``bennu-apn-3d``); a run that ignites more reuses them in order."""


class InterceptDraws(NamedTuple):
    """The draws of a run that do not evolve: its knowledge errors (the outcome reports them)
    and its table of ignition pointing normals (:func:`pointing_draws`)."""

    knowledge_position_m: Vector3
    knowledge_velocity_mps: Vector3
    pointing: Float[Array, "n 2"]


class ImageDraws(NamedTuple):
    """Standard normals of one image (float32 draws: 24-bit normals are ample for an error
    source; see ``systems.impactor``'s image draws)."""

    measurement: Float[Array, "2"]  # LOS angle noise (out-of-plane angle: 0 when planar)


def knowledge_errors(sim: PNSimulation, key: PRNGKeyArray) -> tuple[Vector3, Vector3]:
    """The initial position (m) and velocity (m/s) knowledge errors, along the initial LOS,
    across it in the orbit plane and out of plane (zero out of plane when planar)."""
    err = sim.errors
    mask = jnp.array([1.0, 1.0, 0.0]) if sim.planar else jnp.ones(3)
    know_pos = mask * err.knowledge_position_m * stream_normal(key, _KNOW_POS)
    know_vel = mask * err.knowledge_velocity_mps * stream_normal(key, _KNOW_VEL)
    return know_pos, know_vel


def draw_rows(planar: bool) -> int:
    """Normals per image: planar runs draw only the in-plane measurement angle."""
    return 1 if planar else 2


def pointing_draws(key: PRNGKeyArray) -> Float[Array, "n 2"]:
    """The run's table of ignition pointing normals, ``N_IGNITION_DRAWS`` rows (the second
    column unused when planar)."""
    return stream_normal(key, _IGNITIONS, (N_IGNITION_DRAWS, 2))


def block_draws(key: PRNGKeyArray, block, planar: bool) -> Float[Array, "rows block"]:
    """The normals of images ``block * DRAW_BLOCK + j``, j < DRAW_BLOCK: column j, rows as
    :func:`image_draws_of` reads them (single precision)."""
    shape = (draw_rows(planar), DRAW_BLOCK)
    return normal(stream_key(key, _IMAGES, block), shape, jnp.float32)


def image_draws_of(column: tuple, planar: bool) -> ImageDraws:
    """The :class:`ImageDraws` of one column of :func:`block_draws` (float64)."""
    w = [c.astype(jnp.float64) for c in column]
    if planar:
        return ImageDraws(jnp.stack([w[0], jnp.zeros_like(w[0])]))
    return ImageDraws(jnp.stack(w))


def front_end_key(key: PRNGKeyArray, image) -> PRNGKeyArray:
    """The key of image ``image``'s LOS front end, for front ends that draw more than the
    image's normals."""
    return stream_key(key, _FRONT_END, image)


__all__ = [
    "DRAW_BLOCK",
    "N_IGNITION_DRAWS",
    "ImageDraws",
    "InterceptDraws",
    "block_draws",
    "draw_rows",
    "front_end_key",
    "image_draws_of",
    "knowledge_errors",
    "pointing_draws",
]
