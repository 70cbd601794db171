"""Synthetic navigation-camera frames of the target (seed 002 §3.1 and §4.2).

A frame is a fixed-size region of interest (ROI) of ``roi_px`` x ``roi_px`` (binned) detector
pixels, placed where the on-board software predicts the target, so every frame of every run has
the same shape and the renderer can be ``vmap``ped and scanned.

Scene: a Lambertian triaxial ellipsoid (a sphere when the three semi-axes are equal) lit by the
Sun, seen in perspective. Lambert's law makes the radiance proportional to cos i (i: incidence
angle), independent of the emission angle.

Rendering is *splatting*: the target's angular bounding box is sampled on a fixed
``samples`` x ``samples`` grid of rays defined relative to the target centre (so the image is
exactly translation-covariant: moving the target by a sub-pixel amount moves every sample by the
same amount); each ray is intersected with the ellipsoid, carries the flux cos i x (solid angle
of its cell), and is spread over the pixels by the Gaussian point-spread function (PSF)
integrated over each pixel box (differences of erf, separable in x and y). The sample cell
itself is spread as a box of the same variance added to the PSF. The image is then a small
matrix product (``samples^2`` x ``roi_px`` per axis).

Detector: on-chip binning by ``bin`` (a power of two chosen per frame, see
:func:`choose_binning`), auto-exposure so that a fully lit (cos i = 1) binned pixel collects
``signal_e`` electrons, shot noise (Gaussian with variance = mean, accurate above ~20 e-), read
noise once per binned pixel (the two drawn as one Gaussian of the summed variance),
full-well clipping, gain, bias pedestal and quantisation to
``adc_bits`` grey levels.

Conventions: detector coordinates in native pixels, x along the camera x_c axis (columns), y
along y_c (rows), pixel centres at integers, the principal point at (0, 0); a tangent-plane
angle u = x_c / z_c maps to x = u f / pitch. Binned ROI pixel (row i, col j) covers native
x in [x0 + b j - 1/2, x0 + b (j + 1) - 1/2) with x0 the ROI origin (a multiple of b).
"""

import equinox as eqx
import jax
import jax.numpy as jnp

from .._random import normal
from .._types import Array, Float, Matrix3, PRNGKeyArray, Scalar, Vector3


class CameraModel(eqx.Module):
    """Navigation camera and detector.

    Defaults: Deep Impact MRI class (f = 2.103 m of seed 000 Table 2; 21 um pixels give an
    instantaneous field of view of 10.0 urad, the MRI's); generic scientific-CCD electronics.

    Attributes:
        focal_length_m: f; pixel_pitch_m: native pixel size.
        psf_sigma_px: Gaussian PSF standard deviation, native pixels.
        signal_e: electrons of a fully lit (cos i = 1) binned pixel (auto-exposure).
        full_well_e: clipping level of a binned pixel, electrons.
        read_noise_e: read noise per (binned) pixel read, electrons rms.
        gain_e_per_dn: electrons per grey level; bias_dn: pedestal, grey levels.
        adc_max_dn: largest grey level (2^bits - 1).
        roi_px, window_px: ROI and sub-pixel window sizes, binned pixels (static).
        samples: rays per axis over the target's bounding box (static).
        label_iterations: label-propagation sweeps of the component labelling (static).
        max_bin_log2: largest binning exponent (bin <= 2^max_bin_log2) (static).
        max_exposure_gain: longest exposure over the resolved-disc exposure (see
            :func:`exposure_gain`).
    """

    focal_length_m: Scalar = 2.103
    pixel_pitch_m: Scalar = 21e-6
    psf_sigma_px: Scalar = 0.7
    signal_e: Scalar = 20000.0
    full_well_e: Scalar = 100000.0
    read_noise_e: Scalar = 20.0
    gain_e_per_dn: Scalar = 100000.0 / 16383.0
    bias_dn: Scalar = 100.0
    adc_max_dn: Scalar = 16383.0
    roi_px: int = eqx.field(static=True, default=32)
    window_px: int = eqx.field(static=True, default=17)
    samples: int = eqx.field(static=True, default=32)
    label_iterations: int = eqx.field(static=True, default=24)
    max_bin_log2: int = eqx.field(static=True, default=7)
    max_exposure_gain: Scalar = 1e4

    @property
    def ifov_rad(self):
        """Instantaneous field of view of one native pixel (rad)."""
        return self.pixel_pitch_m / self.focal_length_m


class TargetModel(eqx.Module):
    """Lambertian ellipsoid target (seed 000/002 give no shape: Tempel 1 class, see README).

    Attributes:
        semi_axes_m: ellipsoid semi-axes along the body axes (m); equal = sphere.
        c_bi: rotation body -> inertial (columns: body axes in inertial), fixed in time.
        sun_direction: unit vector from the target to the Sun, inertial.
    """

    semi_axes_m: Float[Array, "3"]
    c_bi: Matrix3
    sun_direction: Vector3

    @property
    def bounding_radius_m(self):
        return jnp.max(self.semi_axes_m)

    @property
    def mean_radius_m(self):
        """Radius of the sphere of equal volume (used by the on-board phase correction)."""
        return jnp.prod(self.semi_axes_m) ** (1.0 / 3.0)


class Frame(eqx.Module):
    """A rendered ROI and where it sits on the detector.

    Attributes:
        dn: grey levels, shape (roi_px, roi_px), rows = y, columns = x.
        origin_px: native detector coordinates (x0, y0) of the ROI corner (multiples of bin).
        bin: binning factor (a power of two).
        exposure: the exposure over the resolved-disc exposure (:func:`exposure_gain`).
    """

    dn: Float[Array, "n n"]
    origin_px: Float[Array, "2"]
    bin: Scalar
    exposure: Scalar = 1.0


def roi_to_tangent(camera: CameraModel, frame_origin_px, bin_, xy_roi) -> Float[Array, "2"]:
    """Tangent-plane angles (x_c/z_c, y_c/z_c) of a point at ROI coordinates (col, row)."""
    native = frame_origin_px + bin_ * xy_roi + 0.5 * (bin_ - 1.0)
    return native * camera.ifov_rad


def tangent_to_roi(camera: CameraModel, frame_origin_px, bin_, uv) -> Float[Array, "2"]:
    """Inverse of :func:`roi_to_tangent`."""
    native = uv / camera.ifov_rad
    return (native - frame_origin_px - 0.5 * (bin_ - 1.0)) / bin_


def choose_binning(camera: CameraModel, disc_radius_rad, pointing_sigma_rad) -> Scalar:
    """Smallest power-of-two binning at which the target fits the window and the ROI.

    The disc plus 3 PSF sigmas must fit inside the sub-pixel window (with a one-pixel margin),
    and the window, centred wherever a 3-sigma prediction error puts the target, inside the ROI.
    """
    ifov = camera.ifov_rad
    half_w = 0.5 * (camera.window_px - 1) - 1.0
    need_disc = (disc_radius_rad / ifov + 3.0 * camera.psf_sigma_px) / half_w
    half_free = 0.5 * (camera.roi_px - camera.window_px) - 1.0
    need_point = 3.0 * pointing_sigma_rad / ifov / half_free
    k = jnp.ceil(jnp.log2(jnp.maximum(jnp.maximum(need_disc, need_point), 1.0)) - 1e-9)
    return 2.0 ** jnp.clip(k, 0.0, camera.max_bin_log2)


def place_roi(camera: CameraModel, uv_predicted, bin_) -> Float[Array, "2"]:
    """ROI origin (native px, multiple of ``bin_``) centring the ROI on the predicted target."""
    native = uv_predicted / camera.ifov_rad
    return bin_ * (jnp.round(native / bin_) - 0.5 * camera.roi_px)


def _ray_ellipsoid(d_body, o_body, semi_axes):
    """Near intersection of the rays o + t d with the ellipsoid |x / semi_axes| = 1.

    Works in the scaled space where the ellipsoid is the unit sphere, with the perpendicular
    offset form (no cancellation at 1e4 ranges). ``d_body``: tuple of three arrays (ray
    direction components, body axes); ``o_body``: (3,) camera position relative to the target.
    Component-wise arithmetic on purpose: tiny 3 x 3 products as matmuls are slow on CPU.

    Returns:
        ``(hit, n)``: whether each ray hits, and the outward unit normal (tuple of 3 arrays).
    """
    o = [o_body[k] / semi_axes[k] for k in range(3)]
    e = [d_body[k] / semi_axes[k] for k in range(3)]
    inv = jax.lax.rsqrt(e[0] ** 2 + e[1] ** 2 + e[2] ** 2)
    e = [ek * inv for ek in e]
    oe = o[0] * e[0] + o[1] * e[1] + o[2] * e[2]
    o_perp = [o[k] - oe * e[k] for k in range(3)]
    disc = 1.0 - (o_perp[0] ** 2 + o_perp[1] ** 2 + o_perp[2] ** 2)
    hit = disc > 0.0
    root = jnp.sqrt(jnp.where(hit, disc, 0.0))
    n = [(o_perp[k] - root * e[k]) / semi_axes[k] for k in range(3)]  # unit-sphere point / a
    inv_n = jax.lax.rsqrt(n[0] ** 2 + n[1] ** 2 + n[2] ** 2)
    return hit, [nk * inv_n for nk in n]


def target_samples(camera: CameraModel, target: TargetModel, c_ci: Matrix3, r_cam_m: Vector3):
    """Rays over the target on a regular tangent-plane grid.

    Returns:
        ``(u, v, flux, step)``: the grid's column and row tangent coordinates (M,) each (rad),
        the flux (M, M) (rows: v) and the grid step (rad). The flux of a ray is
        cos i x (solid angle of its cell) / ifov^2: the electrons it deposits in units of the
        electrons of a fully lit native pixel. ``r_cam_m`` is the target centre relative to
        the camera, inertial.
    """
    m = camera.samples
    c_cam = c_ci @ r_cam_m
    uv0 = c_cam[:2] / c_cam[2]
    dist = jnp.linalg.norm(c_cam)
    half = 1.02 * jnp.arcsin(jnp.minimum(target.bounding_radius_m / dist, 0.999))
    step = 2.0 * half / m
    g = (jnp.arange(m) + 0.5 - 0.5 * m) * step
    u, v = uv0[0] + g, uv0[1] + g
    uu, vv = jnp.meshgrid(u, v, indexing="xy")
    c_cb = c_ci @ target.c_bi  # body -> camera
    d_body = [uu * c_cb[0, k] + vv * c_cb[1, k] + c_cb[2, k] for k in range(3)]  # C_cb^T d
    o_body = -(c_cam @ c_cb)  # camera origin relative to the target, body axes
    hit, n_body = _ray_ellipsoid(d_body, o_body, target.semi_axes_m)
    s_body = target.sun_direction @ target.c_bi
    cos_i = jnp.maximum(n_body[0] * s_body[0] + n_body[1] * s_body[1] + n_body[2] * s_body[2], 0)
    solid = step**2 / (1.0 + uu**2 + vv**2) ** 1.5
    flux = jnp.where(hit, cos_i, 0.0) * solid / camera.ifov_rad**2
    return u, v, flux, step


def _pixel_weights(centre, sigma, n):
    """Fraction of a Gaussian (mean ``centre``, std ``sigma``) in each pixel [j-1/2, j+1/2)."""
    edges = jnp.arange(n + 1) - 0.5
    cdf = 0.5 * jax.lax.erf((edges[None, :] - centre[:, None]) / (jnp.sqrt(2.0) * sigma))
    return cdf[:, 1:] - cdf[:, :-1]


def expected_electrons(
    camera: CameraModel, target: TargetModel, c_ci, r_cam_m, origin_px, bin_
) -> Float[Array, "n n"]:
    """Noise-free electrons of each binned ROI pixel.

    The detector coordinate of a ray is affine in its tangent coordinates, so the grid's
    columns map to ROI columns and rows to rows: image = W_y^T F W_x with W the per-axis
    PSF-and-pixel weights (M x roi_px) and F the flux grid (M x M).
    """
    u, v, flux, step = target_samples(camera, target, c_ci, r_cam_m)
    x = tangent_to_roi(camera, origin_px[0], bin_, u)
    y = tangent_to_roi(camera, origin_px[1], bin_, v)
    cell_b = step / camera.ifov_rad / bin_  # sample spacing, binned px
    sigma = jnp.sqrt((camera.psf_sigma_px / bin_) ** 2 + cell_b**2 / 12.0)
    n = camera.roi_px
    wx = _pixel_weights(x, sigma, n)
    wy = _pixel_weights(y, sigma, n)
    # electrons per native-pixel flux unit: a fully lit binned pixel (b^2 native) -> signal_e
    scale = camera.signal_e / bin_**2
    return scale * wy.T @ flux @ wx


def digitise(camera: CameraModel, electrons, key: PRNGKeyArray | None) -> Float[Array, "n n"]:
    """Shot and read noise, full well, gain, bias and quantisation (``key=None``: noise-free)."""
    e = electrons
    if key is not None:
        # shot (Gaussian, variance = mean) + read noise: one normal draw of the summed variance
        var = jnp.maximum(e, 0.0) + camera.read_noise_e**2
        e = e + jnp.sqrt(var) * normal(key, e.shape)
    e = jnp.minimum(e, camera.full_well_e)
    dn = jnp.round(e / camera.gain_e_per_dn + camera.bias_dn)
    return jnp.clip(dn, 0.0, camera.adc_max_dn)


def exposure_gain(camera: CameraModel, electrons) -> Scalar:
    """Auto-exposure on the brightest pixel: the factor by which the exposure is lengthened
    from the resolved-disc exposure (a fully lit binned pixel collects ``signal_e``) so that
    the brightest expected pixel collects ``signal_e``, within [1, ``max_exposure_gain``].

    A resolved disc has a pixel close to fully lit: the factor is about 1. A point-like target
    (far below one pixel) spreads its light, the disc's solid angle times cos i, over the PSF:
    at the resolved-disc exposure its brightest pixel holds a small fraction of ``signal_e``
    (a 300 m body at 150,000 km in 5 urad pixels binned 8: about 10 e-, below the read noise)
    and the exposure is lengthened, up to the camera's longest (default 1e4: four decades of
    exposure control, e.g. 1 ms to 10 s). The expected (noise-free) image stands for a
    converged auto-exposure loop on the previous frames.
    """
    peak = jnp.max(electrons)
    gain = camera.signal_e / jnp.maximum(peak, camera.signal_e / camera.max_exposure_gain)
    return jnp.clip(gain, 1.0, camera.max_exposure_gain)


def render_frame(
    camera: CameraModel,
    target: TargetModel,
    c_ci: Matrix3,
    r_cam_m: Vector3,
    uv_predicted,
    bin_,
    key: PRNGKeyArray | None,
) -> Frame:
    """Render the ROI centred on ``uv_predicted`` (tangent angles) at binning ``bin_``.

    Args:
        c_ci: true camera attitude (rows x_c, y_c, z_c, inertial).
        r_cam_m: true target centre relative to the camera, inertial (m).
        uv_predicted: where the on-board software expects the target (tangent angles, rad).
        bin_: binning factor (power of two, see :func:`choose_binning`).
        key: noise key, or ``None`` for a noise-free frame (still quantised).

    The exposure is set on the brightest expected pixel (:func:`exposure_gain`).
    """
    origin = place_roi(camera, uv_predicted, bin_)
    e = expected_electrons(camera, target, c_ci, r_cam_m, origin, bin_)
    gain = exposure_gain(camera, e)
    return Frame(digitise(camera, gain * e, key), origin, jnp.asarray(bin_, float), gain)


def lambert_sphere_offset(phase_rad) -> Scalar:
    """Centre-of-brightness offset of a Lambertian sphere, in radii, toward the Sun.

    Orthographic view, Sun at phase angle alpha; integrating the radiance cos i over the lit,
    visible lune (longitude from alpha - pi/2 to pi/2, latitude +-pi/2) gives

        x_cob / R = (3 pi / 16) sin a (1 + cos a) / (sin a + (pi - a) cos a),

    (the denominator is the Lambert phase integral; 3a/8 for small a, 0.589 at 90 deg,
    9 pi / 32 as a -> pi). Derivation in tests/navigation/test_render_centroid.py, checked
    there by numerical integration.
    """
    a = jnp.asarray(phase_rad, float)
    small = a < 1e-6
    a_s = jnp.where(small, 1e-3, a)
    val = (3.0 * jnp.pi / 16.0) * jnp.sin(a_s) * (1.0 + jnp.cos(a_s))
    val = val / (jnp.sin(a_s) + (jnp.pi - a_s) * jnp.cos(a_s))
    return jnp.where(small, 0.375 * a, val)


def phase_offset_tangent(c_ci: Matrix3, r_rel_m: Vector3, sun_direction: Vector3, radius_m):
    """Predicted centre-of-brightness offset (tangent angles, rad) of a Lambertian sphere.

    ``r_rel_m``: camera (impactor) relative to the target. The offset points along the Sun
    direction projected on the image plane, magnitude ``lambert_sphere_offset`` x R / range.
    """
    rho = jnp.linalg.norm(r_rel_m)
    to_cam = r_rel_m / rho
    cos_a = jnp.clip(jnp.dot(sun_direction, to_cam), -1.0, 1.0)
    s_perp = sun_direction - cos_a * to_cam
    s_perp_n = jnp.sqrt(jnp.dot(s_perp, s_perp) + 1e-300)
    mag = lambert_sphere_offset(jnp.arccos(cos_a)) * radius_m / rho
    return mag * (c_ci[:2] @ (s_perp / s_perp_n))
