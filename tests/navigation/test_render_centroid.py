"""Image front end: renderer and seed 002 centroiding against closed forms, scipy and loops.

Centre of brightness of a Lambertian sphere (used by ``lambert_sphere_offset``)
-------------------------------------------------------------------------------
Observer on +z, Sun at phase angle a in the x-z plane, s = (sin a, 0, cos a); unit sphere,
visible-hemisphere normal n = (x, y, z). Lambert radiance is n.s (independent of the emission
angle), and a projected area element is dA = z dS. With n = (cos b sin l, sin b, cos b cos l)
the lit and visible lune is l in (a - pi/2, pi/2), b in (-pi/2, pi/2), dS = cos b db dl:

    D = int (n.s) z dS   = (4/3) int cos l cos(l - a) dl       = (2/3)[sin a + (pi - a) cos a]
    N = int x (n.s) z dS = (3 pi/8) int sin l cos l cos(l - a) dl = (pi/8) sin a (1 + cos a)

so x_cob / R = N / D = (3 pi / 16) sin a (1 + cos a) / (sin a + (pi - a) cos a).
The test below checks it by direct numerical integration over the disc (scipy), independent of
the renderer, and then checks the renderer + centroiding against it.
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import integrate, ndimage
from short_impactor import SHORT

import gnc_jax as gj
from gnc_jax.navigation.centroid import extract_centroid, label_components
from gnc_jax.navigation.render import (
    CameraModel,
    TargetModel,
    choose_binning,
    lambert_sphere_offset,
    render_frame,
    roi_to_tangent,
)

CAM = CameraModel()
R = 3000.0  # m, the default target radius


def sphere(phase_deg=0.0, axes=(R, R, R), c_bi=None):
    """Target on the camera's +z axis, Sun at ``phase_deg`` in the camera x-z plane."""
    a = np.radians(phase_deg)
    sun = jnp.array([np.sin(a), 0.0, -np.cos(a)])  # from the target; -z points at the camera
    return TargetModel(jnp.asarray(axes, float), jnp.eye(3) if c_bi is None else c_bi, sun)


@jax.jit
def measure(target, rho, bin_, offset_px, key=None):
    """Render the target at ``offset_px`` (binned px) from the ROI centre; return (err_px, c).
    One compiled program for every target, range, binning and offset (op by op, the first
    call would compile each of its ~150 operations on its own)."""
    uv_true = jnp.asarray(offset_px) * CAM.ifov_rad * bin_
    r = rho * jnp.array([uv_true[0], uv_true[1], 1.0])
    frame = render_frame(CAM, target, jnp.eye(3), r, jnp.zeros(2), bin_, key)
    c = extract_centroid(frame.dn, CAM.window_px, CAM.label_iterations)
    uv = roi_to_tangent(CAM, frame.origin_px, frame.bin, c.xy)
    return (uv - uv_true) / (CAM.ifov_rad * bin_), c


@pytest.mark.parametrize("phase_deg", [10.0, 30.0, 60.0, 90.0, 150.0])
def test_lambert_offset_closed_form_matches_numerical_integration(phase_deg):
    a = np.radians(phase_deg)
    s = np.array([np.sin(a), 0.0, np.cos(a)])

    def radiance(y, x):
        z = np.sqrt(max(1.0 - x * x - y * y, 0.0))
        return max(x * s[0] + z * s[2], 0.0)

    def inner(x, weight):
        # split at the terminator y = +-sqrt(1 - x^2 / cos^2 a), where the integrand has a kink
        yd = np.sqrt(1 - x * x)
        yt = np.sqrt(max(1 - x * x / np.cos(a) ** 2, 0.0))
        pts = [p for p in (-yt, yt) if -yd < p < yd]
        f = lambda y: weight(x) * radiance(y, x)
        return integrate.quad(f, -yd, yd, points=pts or None, epsabs=1e-12, limit=200)[0]

    def outer(weight):
        return integrate.quad(lambda x: inner(x, weight), -1, 1, points=[0.0], limit=200)[0]

    num = outer(lambda x: x)
    den = outer(lambda x: 1.0)
    assert den == pytest.approx((2 / 3) * (np.sin(a) + (np.pi - a) * np.cos(a)), rel=1e-6)
    assert float(lambert_sphere_offset(a)) == pytest.approx(num / den, rel=1e-5, abs=1e-7)


# (range m, binning): resolved discs of radius 1-7 binned px, as choose_binning picks them
RESOLVED = [(7.344e7, 4), (7.344e7, 2), (7.344e7, 1), (4e7, 2), (2e7, 4), (3e6, 32), (6.12e5, 128)]


@pytest.mark.parametrize("rho,bin_", RESOLVED)
def test_zero_phase_subpixel_position_recovered(rho, bin_):
    """Noise-free (quantised) sphere at zero phase: the centroid is within 0.05 binned px."""
    offsets = jax.random.uniform(jax.random.key(7), (6, 2), minval=-0.5, maxval=0.5)
    err = jax.vmap(lambda o: measure(sphere(), rho, bin_, o)[0])(offsets)
    assert np.abs(np.asarray(err)).max() <= 0.05


def test_zero_phase_point_like_target_is_pixel_locked():
    """A finding, not the 0.05 px goal: at the start of the approach the 3-sigma pointing
    uncertainty forces bin 8, the disc (radius 0.5 binned px) is a few pixels and the threshold
    cuts its PSF wings asymmetrically, so the noise-free centroid is pulled toward pixel
    centres by up to ~0.17 binned px (~13 urad)."""
    offsets = jax.random.uniform(jax.random.key(8), (12, 2), minval=-0.5, maxval=0.5)
    err = np.asarray(jax.vmap(lambda o: measure(sphere(), 7.344e7, 8, o)[0])(offsets))
    assert 0.02 < np.abs(err).max() <= 0.25


@pytest.mark.parametrize("phase_deg", [30.0, 60.0, 90.0])
@pytest.mark.parametrize("rho,bin_", [(5e7, 1), (6.12e5, 64)])
def test_phase_offset_matches_the_lambert_closed_form(phase_deg, rho, bin_):
    expected = float(lambert_sphere_offset(np.radians(phase_deg))) * R / rho
    expected_px = expected / (CAM.ifov_rad * bin_)
    for o in ([0.2, -0.1], [-0.4, 0.35]):
        err, c = measure(sphere(phase_deg), rho, bin_, jnp.array(o))
        assert bool(c.valid)
        # toward the Sun (+x), nothing across; 1.5 % + 0.03 px: sampling of the terminator
        assert float(err[0]) == pytest.approx(expected_px, rel=0.015, abs=0.03)
        assert abs(float(err[1])) < 0.05


def test_ellipsoid_flux_outline_and_sphere_limit():
    """Ellipsoid seen down its c axis, Sun behind the camera: total signal = the integral of
    cos i over the projected ellipse (scipy, with the ellipsoid's own normal); long axis where
    rotated; equal axes reproduce the sphere."""
    rho, bin_ = 4e7, 1
    a, b, c = 3800.0, 2450.0, 2000.0
    rot = jnp.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # a along camera y
    tgt = sphere(0.0, axes=(a, b, c), c_bi=rot)
    uv = jnp.zeros(2)
    frame = render_frame(CAM, tgt, jnp.eye(3), jnp.array([0.0, 0.0, rho]), uv, bin_, None)
    e = (np.asarray(frame.dn) - float(CAM.bias_dn)) * float(CAM.gain_e_per_dn)
    px = rho * float(CAM.ifov_rad)
    total = e.sum() / float(CAM.signal_e) * px**2

    def cos_i(yp, xp):  # unit-sphere coordinates (x', y'); surface point (a x', b y', c z')
        zp = np.sqrt(max(1.0 - xp * xp - yp * yp, 0.0))
        return (zp / c) / np.sqrt((xp / a) ** 2 + (yp / b) ** 2 + (zp / c) ** 2) * a * b

    lim = (lambda x: -np.sqrt(1 - x * x), lambda x: np.sqrt(1 - x * x))
    ref, _ = integrate.dblquad(cos_i, -1, 1, *lim, epsabs=1e-3)
    assert total == pytest.approx(ref, rel=0.01)
    rows, cols = np.nonzero(e > 0.02 * float(CAM.signal_e))
    assert np.ptp(rows) > np.ptp(cols)  # long axis along y, as rotated
    f_sph = render_frame(CAM, sphere(), jnp.eye(3), jnp.array([0.0, 0.0, rho]), uv, 1, None)
    f_ell = render_frame(
        CAM, sphere(axes=(R, R, R), c_bi=rot), jnp.eye(3), jnp.array([0, 0, rho]), uv, 1, None
    )
    np.testing.assert_allclose(f_sph.dn, f_ell.dn, atol=1.0)


@jax.jit
@functools.partial(jax.vmap, in_axes=(0, 0, None, None))
def _noisy_errors(offset_px, key, rho, bin_):
    return measure(sphere(), rho, bin_, offset_px, key)[0]


def noise_sigma_urad(rho, bin_, n=300):
    offsets = jax.random.uniform(jax.random.key(1), (n, 2), minval=-0.5, maxval=0.5)
    keys = jax.random.split(jax.random.key(0), n)
    err = _noisy_errors(offsets, keys, float(rho), float(bin_))  # one program for all three
    return float(np.std(np.asarray(err))) * float(CAM.ifov_rad) * bin_ * 1e6


def test_centroid_noise_against_the_noise_front_end():
    """Centroid error std (random sub-pixel positions, shot + read noise) vs the 10 urad of
    ``ImpactorErrors.image_processing_rad``.

    At the start of the approach (73 440 km: the 3-sigma pointing uncertainty of ~150 urad
    forces bin 8) the image front end's sigma is below 10 urad (within a factor 2 of it at
    the resolved-disc exposure; 4.6 urad with the exposure set on the brightest pixel,
    which lengthens it for the one-pixel disc), in the last frames (612 km, bin 128)
    within a factor 2 of 10 urad. In between, the resolved, bright (20 000 e- per lit pixel) disc is
    centroided to ~0.005 binned px: 0.1-3 urad, far better than 10 urad (a finding: the noise
    model's 10 urad is conservative for a Lambertian sphere and must stand for shape and albedo
    errors the sphere does not have).
    """
    b0 = float(choose_binning(CAM, R / 7.344e7, 150e-6))
    assert b0 == 8.0
    start = noise_sigma_urad(7.344e7, b0)
    end = noise_sigma_urad(6.12e5, 128)
    mid = noise_sigma_urad(4e7, 2)
    print(f"centroid sigma: start {start:.2f}, mid {mid:.2f}, end {end:.2f} urad (model 10)")
    assert start <= 10.0
    assert 5.0 <= end <= 20.0
    assert mid < 1.0


@pytest.mark.parametrize("density", [0.2, 0.45, 0.6])
def test_label_propagation_matches_scipy(density):
    """Same partition as scipy.ndimage.label with 8-connectivity, on random binary images."""
    masks = np.asarray(jax.random.uniform(jax.random.key(3), (10, 24, 24)) < density)
    labels, converged = jax.jit(jax.vmap(lambda m: label_components(m, 600)))(masks)
    labels = np.asarray(labels)
    assert np.all(np.asarray(converged))
    for m, lab in zip(masks, labels):
        ref, n = ndimage.label(m, structure=np.ones((3, 3)))
        assert len(np.unique(lab[m])) == n
        pairs = set(zip(lab[m].tolist(), ref[m].tolist()))
        assert len(pairs) == n  # a bijection between our labels and scipy's
        assert np.all(lab[~m] == -1)


def test_default_label_sweeps_converge_on_target_frames():
    """The default sweep count labels the largest disc the binning allows in one piece."""
    for rho, bin_ in [(7.344e7, 1), (6.12e5, 128), (6.12e5, 64)]:
        uv = jnp.zeros(2)
        frame = render_frame(CAM, sphere(60.0), jnp.eye(3), jnp.array([0, 0, rho]), uv, bin_, None)
        mask = frame.dn > 2.0 * frame.dn[:, 0].mean()
        _, converged = label_components(mask, CAM.label_iterations)
        assert bool(converged) and int(mask.sum()) > 4


def test_two_targets_the_brightest_wins():
    """Two blobs: the component with the larger summed grey level is centroided."""
    rho = 5e7
    frame = jax.jit(lambda t, r: render_frame(CAM, t, jnp.eye(3), r, jnp.zeros(2), 1, None).dn)
    big = frame(sphere(), jnp.array([0.0, 0.0, rho]))
    offset = -10.0 * float(CAM.ifov_rad)
    small = frame(sphere(axes=(1500.0, 1500.0, 1500.0)), jnp.array([offset, offset, 1.0]) * rho)
    both = big + small - float(CAM.bias_dn)
    c = jax.jit(extract_centroid, static_argnums=(1, 2))(both, 9, CAM.label_iterations)
    assert int(c.n_components) == 2
    assert np.abs(np.asarray(c.pixel_xy) - 16.0).max() < 0.5  # the big one, at the centre


def test_image_navigation_vmap_equals_per_run_loop():
    sc = gj.load_scenario("autonav-predictive", overrides=SHORT)
    study = gj.run_study(sc, runs=4, seed=5, progress=False)
    s = study.summary()
    assert s["failed"] == 0
    for i in range(4):
        one, _ = gj.simulate_one(sc, index=i, seed=5, record=False)
        for name in ("miss_m", "dv_mps", "los_error_rms_urad", "nav_position_error_m"):
            np.testing.assert_allclose(
                study.outcomes[name][i], getattr(one, name), rtol=1e-9, atol=1e-9
            )
        assert study.outcomes["images_rejected"][i] == one.images_rejected
    # the image front end is in the loop: its LOS errors are not the noise model's 10 urad
    assert np.all(study.outcomes["los_error_rms_urad"] < 8.0)


def test_phase_correction_removes_the_brightness_offset():
    """Without the correction the 60 deg phase offset (0.4 R / range) biases every LOS."""
    sc = gj.load_scenario("autonav-predictive", overrides=SHORT)
    on = gj.run_study(sc, runs=4, seed=1, progress=False).outcomes
    off = gj.run_study(
        sc.with_overrides({"navigation.phase_correction": False}), runs=4, seed=1, progress=False
    ).outcomes
    assert np.all(off["los_error_rms_urad"] > 3.0 * on["los_error_rms_urad"])


@pytest.mark.slow
def test_autonav_predictive_acceptance(paper_scale):
    """Seed 002: 300-run image-navigation study (CI: 100 runs), max miss <= 300 m (paper: < 200
    m), mean total Δv 4-12 m/s (paper: 7.6 m/s in its one hardware-in-the-loop run)."""
    runs = 300 if paper_scale else 100
    s = gj.run_study(gj.load_scenario("autonav-predictive"), runs=runs, seed=0).summary()
    assert s["failed"] == 0
    assert s["miss_max_m"] <= 300.0
    assert 4.0 <= s["dv_mean_mps"] <= 12.0
    assert s["firings_max"] == 4
    assert s["images_rejected_max"] <= 5


# ---- point-like to resolved targets --------------------------------------------------------

NARROW = CameraModel(pixel_pitch_m=10.515e-6)  # f = 2.103 m: 5 urad per native pixel


@pytest.mark.parametrize(
    "regime,radius_m,rho_m,pointing_rad,limit_px",
    [
        # 300 m body from 150,000 km: 0.2 px disc radius, bin 8 (PSF sigma 0.09 binned px): the
        # image is undersampled and the centroid locks to pixels, within half a binned pixel
        ("point-like", 150.0, 1.5e8, 60e-6, 0.5),
        # 1 km body from 50,000 km: 2 px radius, bin 2: a few pixels
        ("marginal", 500.0, 5e7, 20e-6, 0.1),
        # 3 km body from 20,000 km: 30 px radius, bin 8: a resolved disc
        ("resolved", 1500.0, 2e7, 20e-6, 0.05),
    ],
)
def test_centroid_error_from_point_like_to_resolved(
    regime, radius_m, rho_m, pointing_rad, limit_px
):
    """Every frame of a target inside the ROI and above the noise is centroided (none lost),
    against the known centre (zero phase), at random sub-pixel positions, noise-free and
    with shot and read noise; the error per regime is printed (ENVELOPE_NOTES) and bounded:
    half a binned pixel where the PSF is undersampled (no centroid can locate a point inside
    one pixel better than the pixel), 0.1 and 0.05 px for few-pixel and resolved discs."""
    tgt = sphere(0.0, axes=(radius_m,) * 3)
    b = float(choose_binning(NARROW, radius_m / rho_m, pointing_rad))
    n = 64
    offsets = np.asarray(jax.random.uniform(jax.random.key(4), (n, 2), minval=-3.0, maxval=3.0))

    def measure_one(o, key):
        uv_true = jnp.asarray(o) * NARROW.ifov_rad * b
        r = rho_m * jnp.array([uv_true[0], uv_true[1], 1.0])
        frame = render_frame(NARROW, tgt, jnp.eye(3), r, jnp.zeros(2), b, key)
        c = extract_centroid(frame.dn, NARROW.window_px, NARROW.label_iterations)
        uv = roi_to_tangent(NARROW, frame.origin_px, frame.bin, c.xy)
        return (uv - uv_true) / (NARROW.ifov_rad * b), c.valid, frame.exposure

    keys = jax.random.split(jax.random.key(5), n)
    for noisy in (False, True):
        one = measure_one if noisy else (lambda o, k: measure_one(o, None))
        err, valid, gain = jax.jit(jax.vmap(one))(jnp.asarray(offsets), keys)
        err = np.asarray(err)
        assert np.all(np.asarray(valid)), f"{regime}: a target was lost"
        rms_urad = float(np.sqrt(np.mean(err**2))) * float(NARROW.ifov_rad) * b * 1e6
        print(
            f"{regime} (bin {b:g}, {'noisy' if noisy else 'noise-free'}): max "
            f"{np.abs(err).max():.3f} binned px, RMS {rms_urad:.2f} urad per axis, exposure "
            f"x{float(np.mean(gain)):.3g}"
        )
        assert np.abs(err).max() <= limit_px


def test_a_point_like_target_is_lost_without_exposure_on_its_peak():
    """At the resolved-disc exposure (max_exposure_gain = 1) the
    300 m body at 150,000 km holds about ten electrons, below the read noise: nothing is found."""
    cam = CameraModel(pixel_pitch_m=10.515e-6, max_exposure_gain=1.0)
    tgt = sphere(0.0, axes=(150.0,) * 3)
    frame = render_frame(cam, tgt, jnp.eye(3), jnp.array([0, 0, 1.5e8]), jnp.zeros(2), 8, None)
    assert not bool(extract_centroid(frame.dn, cam.window_px, cam.label_iterations).valid)
