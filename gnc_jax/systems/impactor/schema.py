"""Cross-field checks of an impactor scenario (seed 000 Table 2, seed 002).

The fields are declared in :mod:`gnc_jax.systems.impactor.params`; the checks here read a
validated configuration in the file's units (km, km/s, urad, ug, %), which the field names
carry, and say what is allowed in those units.
"""

import math

from ...constants import AU_M, G0_MPS2, SECONDS_PER_DAY
from ...dynamics.impactor import straight_line_time_to_b_plane
from ...guidance.impactor.base import mission_time_s, nominal_time_of_flight_s
from ...schema import ScenarioError

MIN_RANGE_RADII = 2.0  # the approach starts at least this many target radii away
MIN_SPEED_KMPS = 1e-3
MAX_TOF_S = (
    30 * SECONDS_PER_DAY
)  # a terminal phase; longer approaches are cruise (midcourse system)
MIN_SUN_AU = 0.01
MAX_TIDE_RATIO = 0.05  # |r| / Sun distance of the linearised tide
MIN_IMAGES = 2


def time_of_flight_s(cfg: dict) -> float:
    """Nominal time of flight to the B-plane (s) of the straight-line approach."""
    return straight_line_time_to_b_plane(
        cfg["approach"]["position_km"], cfg["approach"]["velocity_kmps"]
    )


def guided_loop(cutoff_time_s: float, image_interval_s: float, dt_s: float) -> tuple[int, int, int]:
    """The guided loop's sizes: ``(images, control steps per image interval, control steps
    the last interval leaves out)``.

    One image every ``image_interval_s`` from t = 0 before the cut-off at ``cutoff_time_s``,
    and every control step that starts before the cut-off: an image interval that does not
    divide the time to the cut-off leaves a shorter last interval, so that the loop ends at
    the first control step at or after the cut-off, not up to an image interval later."""
    images = math.ceil(cutoff_time_s / image_interval_s - 1e-9)
    steps = round(image_interval_s / dt_s)
    last = math.ceil((cutoff_time_s - (images - 1) * image_interval_s) / dt_s - 1e-9)
    return images, steps, steps - min(max(last, 1), steps)


def _norm(v) -> float:
    return math.hypot(*v)


def _direction(name: str, v) -> list[float]:
    """Unit vector of a direction field whose length must be in [1e-6, 1e6]."""
    n = _norm(v)
    if not 1e-6 <= n <= 1e6:
        raise ScenarioError(
            f"{name}: {v} has length {n:.3g}; allowed: a direction of length in [1e-6, 1e6]"
        )
    return [x / n for x in v]


def _check_dv_budget(cfg: dict, tof: float) -> None:
    """Refuse an approach whose nominal B-plane offset from the aim point needs more Δv than
    the propellant holds, even as one impulse at the start (a lower bound of any law's need)."""
    a, sc = cfg["approach"], cfg["spacecraft"]
    r, v = a["position_km"], a["velocity_kmps"]
    speed = _norm(v)
    along = sum(x * y for x, y in zip(r, v)) / speed
    b_vec = [x - along * y / speed for x, y in zip(r, v)]  # nominal offset, km, S-normal
    aim = max(_norm(cfg["guidance"]["aim_initial_km"]), _norm(cfg["guidance"]["aim_final_km"]))
    need = max(_norm(b_vec) - aim, 0.0) * 1e3 / tof
    capacity = (
        sc["isp_s"] * G0_MPS2 * math.log(sc["mass_kg"] / (sc["mass_kg"] - sc["propellant_kg"]))
    )
    if need > capacity:
        raise ScenarioError(
            f"approach.position_km: the nominal approach passes {_norm(b_vec):.4g} km from the "
            f"target; reaching the aim point needs at least {need:.3g} m/s, the propellant "
            f"gives {capacity:.3g} m/s (spacecraft.propellant_kg, isp_s, mass_kg); allowed: an "
            "approach aimed within reach"
        )


def check(cfg: dict) -> None:
    """Cross-field and physical-domain checks of a validated impactor configuration, in this
    order (the first that fails is reported): directions, range and time of flight, solar
    tide, propellant, timeline, centroid window."""
    tof, r = _check_approach(cfg)
    _check_tide(cfg, r)
    _check_propellant(cfg, tof)
    _check_timeline(cfg, tof)
    _check_window(cfg["camera"])


def _check_directions(cfg: dict) -> None:
    """The approach speed, the B-plane reference normal (not along the velocity) and the Sun
    direction."""
    a, dy = cfg["approach"], cfg["dynamics"]
    v = a["velocity_kmps"]
    speed = _norm(v)
    if not MIN_SPEED_KMPS <= speed <= 100.0:
        raise ScenarioError(
            f"approach.velocity_kmps: speed {speed:.3g} km/s; allowed: a speed in "
            f"[{MIN_SPEED_KMPS:g}, 100] km/s (an impact, not a rendezvous)"
        )
    v_hat = [x / speed for x in v]
    h = _direction("approach.reference_normal", a["reference_normal"])
    cross = [
        v_hat[1] * h[2] - v_hat[2] * h[1],
        v_hat[2] * h[0] - v_hat[0] * h[2],
        v_hat[0] * h[1] - v_hat[1] * h[0],
    ]
    if _norm(cross) < 1e-6:
        raise ScenarioError(
            "approach.reference_normal: parallel to the approach velocity (B-plane T axis "
            "undefined); allowed: any vector not parallel to approach.velocity_kmps"
        )
    _direction("dynamics.sun_direction", dy["sun_direction"])


def _check_approach(cfg: dict) -> tuple[float, float]:
    """The directions, then the range (outside the target, at most 1e7 km) and the time of
    flight (an approach, a terminal phase). Returns ``(time of flight s, range km)``."""
    _check_directions(cfg)
    r = _norm(cfg["approach"]["position_km"])
    radius = max(cfg["target"]["semi_axes_km"])
    if not MIN_RANGE_RADII * radius < r <= 1e7:
        raise ScenarioError(
            f"approach.position_km: range {r:.4g} km; allowed: more than {MIN_RANGE_RADII:g} "
            f"target radii ({MIN_RANGE_RADII * radius:g} km) and at most 1e7 km"
        )
    tof = time_of_flight_s(cfg)
    if tof <= 0.0:
        raise ScenarioError(
            "approach.velocity_kmps: the impactor must approach the target; allowed: a "
            "velocity with approach.position_km . approach.velocity_kmps < 0"
        )
    if tof > MAX_TOF_S:
        raise ScenarioError(
            f"approach: time of flight {tof / SECONDS_PER_DAY:.3g} days (range / closing "
            f"speed); allowed: at most {MAX_TOF_S / SECONDS_PER_DAY:g} days (a terminal phase: "
            "the B-plane frame is fixed by the initial velocity; longer approaches are a "
            "midcourse problem)"
        )
    return tof, r


def _check_tide(cfg: dict, r: float) -> None:
    """The Sun far enough for the linearised tide over the approach range ``r`` (km)."""
    au_km = AU_M / 1e3
    d = cfg["dynamics"]["sun_distance_au"]
    if d != 0.0 and not (d >= MIN_SUN_AU and r <= MAX_TIDE_RATIO * d * au_km):
        raise ScenarioError(
            f"dynamics.sun_distance_au: {d:g} AU; allowed: 0 (no solar tide) or at least "
            f"{max(MIN_SUN_AU, r / (MAX_TIDE_RATIO * au_km)):.3g} AU ({MIN_SUN_AU:g} AU and "
            f"{1 / MAX_TIDE_RATIO:g} x the approach range: the tide is linearised)"
        )


def _check_propellant(cfg: dict, tof: float) -> None:
    """Less propellant than mass, and enough of it to reach the aim point
    (:func:`_check_dv_budget`)."""
    sc = cfg["spacecraft"]
    if not sc["propellant_kg"] < sc["mass_kg"]:
        raise ScenarioError(
            f"spacecraft.propellant_kg: {sc['propellant_kg']:g} kg is not less than "
            f"spacecraft.mass_kg = {sc['mass_kg']:g} kg; allowed: [0, mass_kg)"
        )
    _check_dv_budget(cfg, tof)


_TOF_FROM = "of approach.position_km at approach.velocity_kmps"


def _check_timeline(cfg: dict, tof: float) -> None:
    """The control step divides the image interval, the cut-off and retarget times fall
    within the time of flight ``tof`` (s), at least ``MIN_IMAGES`` images come before the
    cut-off, and the guided loop ends before the nominal impact (:func:`_check_loop_end`)."""
    g, cam = cfg["guidance"], cfg["camera"]
    ratio = cam["image_interval_s"] / g["dt_s"]
    if abs(ratio - round(ratio)) > 1e-9 * ratio:
        raise ScenarioError(
            f"guidance.dt_s: {g['dt_s']:g} s does not divide camera.image_interval_s = "
            f"{cam['image_interval_s']:g} s; allowed: image_interval_s / n for a whole n"
        )
    if not g["cutoff_tgo_s"] < tof:
        raise ScenarioError(
            f"guidance.cutoff_tgo_s: {g['cutoff_tgo_s']:g} s; allowed: [0, {tof:g}) s (less "
            f"than the time of flight {_TOF_FROM})"
        )
    if not g["retarget_tgo_s"] < tof:
        raise ScenarioError(
            f"guidance.retarget_tgo_s: {g['retarget_tgo_s']:g} s; allowed: [0, {tof:g}) s "
            f"(less than the time of flight {_TOF_FROM})"
        )
    images = (tof - g["cutoff_tgo_s"]) / cam["image_interval_s"]
    if images < MIN_IMAGES:
        raise ScenarioError(
            f"camera.image_interval_s: {cam['image_interval_s']:g} s leaves {images:.3g} images "
            f"before the cut-off; allowed: at most "
            f"{(tof - g['cutoff_tgo_s']) / MIN_IMAGES:.4g} s ({MIN_IMAGES} images)"
        )
    _check_loop_end(cfg)


def _check_loop_end(cfg: dict) -> None:
    """The guided loop's last control step (:func:`guided_loop`) ends at or before the
    nominal impact: a cut-off less than a control step before it may leave a step that starts
    before the cut-off and ends past the B-plane."""
    g, interval = cfg["guidance"], cfg["camera"]["image_interval_s"]
    tof = nominal_time_of_flight_s(cfg["approach"]["position_km"], cfg["approach"]["velocity_kmps"])
    images, steps, left_out = guided_loop(
        mission_time_s(tof, g["cutoff_tgo_s"]), interval, g["dt_s"]
    )
    end = (images - 1) * interval + (steps - left_out) * g["dt_s"]
    if end > tof + 1e-6:
        raise ScenarioError(
            f"guidance.cutoff_tgo_s: {g['cutoff_tgo_s']:g} s leaves a control step that ends at "
            f"{end:.10g} s, after the nominal impact at {tof:.10g} s; allowed: at least "
            f"{tof - (end - g['dt_s']):.6g} s (every control step ends before the B-plane)"
        )


def _check_window(cam: dict) -> None:
    """The centroid window: odd, and inside the region of interest with a margin."""
    if cam["window_px"] % 2 == 0 or cam["window_px"] > cam["roi_px"] - 4:
        raise ScenarioError(
            f"camera.window_px: {cam['window_px']}; allowed: an odd number <= camera.roi_px - 4 "
            f"= {cam['roi_px'] - 4}"
        )
