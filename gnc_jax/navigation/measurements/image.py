"""Image front end: render the frame, centroid it, correct the phase (seed 002 §3.1).

The on-board software places the region of interest where its estimate predicts the target
(the filter's predicted angles, through its attitude estimate), with a binning that fits the
predicted disc and the 3-sigma innovation uncertainty
(:func:`~gnc_jax.navigation.render.choose_binning`). The frame is rendered from the TRUE
geometry in the TRUE camera frame; the centroid's tangent angles are the measurement,
corrected by the predicted Lambertian-sphere centre-of-brightness offset
(:func:`~gnc_jax.navigation.render.phase_offset_tangent`) when ``phase_correction`` is 1.
"""

import math
from typing import ClassVar

import jax.numpy as jnp

from ..._types import Array, Float, PRNGKeyArray, Scalar
from ...schema import ScenarioError
from ..camera import los_angles
from ..centroid import extract_centroid
from ..ekf import MeasurementPrediction, NavEstimate
from ..render import (
    CameraModel,
    TargetModel,
    choose_binning,
    phase_offset_tangent,
    render_frame,
    roi_to_tangent,
)
from .base import (
    AbstractMeasurement,
    Exposure,
    Measurement,
    MeasurementSetup,
    register_measurement,
)


@register_measurement("image")
class ImageMeasurement(AbstractMeasurement):
    """Rendered frame + seed 002 centroiding.

    Attributes:
        camera, target: camera/detector and target models.
        phase_correction: 1.0 to remove the predicted centre-of-brightness offset, 0.0 not to.
    """

    camera: CameraModel
    target: TargetModel
    phase_correction: Scalar = 1.0

    not_differentiable: ClassVar[str] = (
        "the rendered frame's derivatives are not sensitivities (ray-cast limb, threshold and "
        "labelling: forward mode gives shares up to 4e9 % of the miss variance)"
    )

    def __call__(
        self,
        exposure: Exposure,
        nav: NavEstimate,
        predicted: MeasurementPrediction,
        noise: Float[Array, "2"],
        key: PRNGKeyArray,
    ) -> Measurement:
        cam, tgt = self.camera, self.target
        pointing_sigma = jnp.sqrt(jnp.max(jnp.diag(predicted.s)))
        rho_hat = jnp.linalg.norm(nav.r)
        disc = jnp.arcsin(jnp.minimum(tgt.bounding_radius_m / rho_hat, 0.999))
        bin_ = choose_binning(cam, disc, pointing_sigma)
        frame = render_frame(cam, tgt, exposure.c_true, exposure.los_m, predicted.z, bin_, key)
        c = extract_centroid(frame.dn, cam.window_px, cam.label_iterations)
        z = roi_to_tangent(cam, frame.origin_px, frame.bin, c.xy)
        offset = phase_offset_tangent(exposure.c_est, nav.r, tgt.sun_direction, tgt.mean_radius_m)
        z_true = los_angles(exposure.c_true, exposure.los_m)
        return Measurement(z - self.phase_correction * offset, c.valid, z_true)

    @classmethod
    def check(cls, config: dict) -> None:
        """The largest binning must fit the target's disc into the sub-pixel window at the
        guidance cut-off (the closest image)."""
        cam, g = config["camera"], config["guidance"]
        v = config["approach"]["velocity_kmps"]
        rho_cut_m = math.hypot(*v) * 1e3 * g["cutoff_tgo_s"]
        ifov = cam["pixel_pitch_um"] * 1e-6 / cam["focal_length_m"]
        radius_px = max(config["target"]["semi_axes_km"]) * 1e3 / max(rho_cut_m, 1e-9) / ifov
        need = (radius_px + 3.0 * cam["psf_sigma_px"]) / 2.0 ** cam["max_bin_log2"]
        if need > 0.5 * (cam["window_px"] - 1) - 1.0:
            raise ScenarioError(
                f"camera.max_bin_log2: {cam['max_bin_log2']}; the target ({radius_px:.0f} px "
                f"radius at the cut-off) does not fit camera.window_px = {cam['window_px']} even "
                "at the largest binning; allowed: a larger max_bin_log2 or window_px, or a "
                "longer guidance.cutoff_tgo_s"
            )

    @classmethod
    def from_setup(cls, setup: MeasurementSetup) -> "ImageMeasurement":
        return cls(setup.camera, setup.target, setup.phase_correction)


__all__ = ["ImageMeasurement"]
