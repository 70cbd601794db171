"""Scenario fields of the impactor terminal phase (seed 000 Table 2, seed 002).

File units follow the papers (km, km/s, urad, ug, %) and are converted to SI when the
simulation is built; the field names carry the units.
"""

import math

from ...constants import G0_MPS2, SECONDS_PER_DAY
from ...dynamics.impactor import straight_line_time_to_b_plane
from ...schema import Field, ScenarioError

F = Field

MIN_RANGE_RADII = 2.0  # the approach starts at least this many target radii away
MIN_SPEED_KMPS = 1e-3
MAX_TOF_S = (
    30 * SECONDS_PER_DAY
)  # a terminal phase; longer approaches are cruise (midcourse system)
MIN_SUN_AU = 0.01
MAX_TIDE_RATIO = 0.05  # |r| / Sun distance of the linearised tide
MIN_IMAGES = 2

SCHEMA = {
    "approach": {
        "position_km": F(
            "floats",
            [73440.0, 0.0, 0.0],
            length=3,
            lo=-1e7,
            hi=1e7,
            units="km",
            doc="nominal initial position of the impactor relative to the target; |r| in "
            f"({MIN_RANGE_RADII:g} target radii, 1e7 km]: a terminal approach (the B-plane frame "
            "is fixed by the initial relative velocity, the solar tide is linearised in |r|)",
        ),
        "velocity_kmps": F(
            "floats",
            [-10.2, 0.0, 0.0],
            length=3,
            lo=-100.0,
            hi=100.0,
            units="km/s",
            doc="nominal relative velocity (defines the B-plane S axis); speed in "
            f"[{MIN_SPEED_KMPS * 1e3:g} m/s, 100 km/s]: an impact, not a rendezvous",
        ),
        "reference_normal": F(
            "floats",
            [0.0, 0.0, 1.0],
            length=3,
            lo=-1e6,
            hi=1e6,
            doc="normal h of the B-plane reference plane (T = S x h); a direction: its length "
            "is ignored but must be in [1e-6, 1e6]",
        ),
    },
    "spacecraft": {
        "mass_kg": F("float", 372.0, lo=0.0, lo_open=True, hi=1e5, units="kg", doc="wet mass"),
        "propellant_kg": F(
            "float",
            25.0,
            lo=0.0,
            hi=1e5,
            units="kg",
            doc="usable propellant, less than mass_kg (not in the paper: 25 kg, ~150 m/s at "
            "230 s on 372 kg, well above the paper's 9.1 m/s); a run that needs more is "
            "flagged 'propellant'",
        ),
        "thrust_n": F("float", 88.0, lo=0.0, lo_open=True, hi=1e4, units="N"),
        "isp_s": F(
            "float",
            230.0,
            lo=10.0,
            hi=1e4,
            units="s",
            doc="specific impulse (hydrazine monopropellant class; not in the paper); >= 10 s: "
            "a thruster",
        ),
    },
    "dynamics": {
        "mu_target_m3s2": F(
            "float",
            0.0,
            lo=0.0,
            hi=1e12,
            units="m^3/s^2",
            doc="target GM; 0 = no target gravity (paper: straight line)",
        ),
        "sun_distance_au": F(
            "float",
            0.0,
            lo=0.0,
            hi=100.0,
            units="AU",
            doc="target's heliocentric distance for the solar tide; 0 = off, else at least "
            f"{MIN_SUN_AU:g} AU and {1 / MAX_TIDE_RATIO:g} x the approach range (the tide is "
            "linearised in range / Sun distance)",
        ),
        "sun_direction": F(
            "floats",
            [1.0, 0.0, 0.0],
            length=3,
            lo=-1e6,
            hi=1e6,
            doc="direction from the target to the Sun (solar tide; image front-end lighting); "
            "length in [1e-6, 1e6]",
        ),
        "coast_steps": F(
            "int", 4, lo=1, hi=10000, doc="RK4 steps of the final coast to the B-plane"
        ),
    },
    "camera": {
        "focal_length_m": F("float", 2.103, lo=0.0, lo_open=True, hi=100.0, units="m"),
        "image_interval_s": F("float", 15.0, lo=0.0, lo_open=True, hi=3600.0, units="s"),
        # Image front end (navigation.measurement = "image"); Deep Impact MRI class defaults.
        "pixel_pitch_um": F(
            "float", 21.0, lo=0.0, lo_open=True, hi=1e3, units="um", doc="native pixel size"
        ),
        "psf_sigma_px": F(
            "float", 0.7, lo=0.05, hi=20.0, units="px", doc="Gaussian PSF sigma, native pixels"
        ),
        "signal_e": F(
            "float",
            20000.0,
            lo=1.0,
            hi=1e7,
            units="e-",
            doc="auto-exposure: electrons of a fully lit (cos i = 1) binned pixel",
        ),
        "full_well_e": F("float", 100000.0, lo=1.0, hi=1e8, units="e-", doc="clipping level"),
        "read_noise_e": F("float", 20.0, lo=0.0, hi=1e5, units="e-", doc="per pixel read"),
        "adc_bits": F("int", 14, lo=8, hi=24, doc="quantisation; gain = full_well/(2^bits-1)"),
        "bias_dn": F(
            "float",
            100.0,
            lo=1.0,
            hi=1e6,
            units="DN",
            doc="pedestal (the threshold is 2 x the first column's mean)",
        ),
        "roi_px": F("int", 32, lo=8, hi=512, units="px", doc="ROI side, binned pixels"),
        "window_px": F(
            "int", 17, lo=3, hi=511, units="px", doc="sub-pixel window side (odd), binned pixels"
        ),
        "samples": F("int", 32, lo=4, hi=512, doc="rays per axis over the target"),
        "label_iterations": F(
            "int", 24, lo=1, hi=10000, doc="sweeps of the connected-component labelling"
        ),
        "max_bin_log2": F("int", 7, lo=0, hi=12, doc="largest binning is 2^max_bin_log2"),
        "max_exposure_gain": F(
            "float",
            1e4,
            lo=1.0,
            hi=1e8,
            doc="auto-exposure on the brightest pixel: longest exposure over the resolved-disc "
            "exposure (1 = the resolved-disc exposure always; point-like targets need more)",
        ),
    },
    "target": {
        "semi_axes_km": F(
            "floats",
            [3.0, 3.0, 3.0],
            length=3,
            lo=0.0,
            lo_open=True,
            hi=1e3,
            units="km",
            doc="Lambertian ellipsoid semi-axes (equal: sphere; Tempel 1 class 3 km)",
        ),
        "orientation_deg": F(
            "floats",
            [0.0, 0.0, 0.0],
            length=3,
            lo=-360.0,
            hi=360.0,
            units="deg",
            doc="rotation vector body -> inertial of the ellipsoid axes",
        ),
    },
    "navigation": {
        "process_noise_m2s3": F(
            "float",
            1e-18,
            lo=0.0,
            hi=1.0,
            units="m^2/s^3",
            doc="filter white-acceleration density (unmodelled forces)",
        ),
        "consider_attitude_bias": F(
            "bool", True, doc="add the attitude-bias rotation to the initial covariance"
        ),
        "measurement": F(
            "str",
            "noise",
            choices=("noise", "image"),
            doc="noise: LOS + Gaussian error; image: rendered frame + seed 002 centroiding",
        ),
        "phase_correction": F(
            "bool",
            True,
            doc="image: remove the Lambertian-sphere centre-of-brightness offset (phase angle)",
        ),
    },
    "guidance": {
        "dt_s": F(
            "float",
            1.0,
            lo=0.01,
            hi=60.0,
            units="s",
            doc="control step; must divide the image interval (>= 0.01 s: finer than any "
            "attitude or thruster response the models resolve)",
        ),
        "aim_initial_km": F(
            "floats",
            [0.0, 0.0],
            length=2,
            units="km",
            doc="aim point (B_T, B_R) before the retarget",
        ),
        "aim_final_km": F(
            "floats",
            [1.0, 3.0],
            length=2,
            units="km",
            doc="aim point (B_T, B_R) after the retarget",
        ),
        "retarget_tgo_s": F(
            "float",
            750.0,
            lo=0.0,
            units="s",
            doc="nominal time to go at which the aim point changes",
        ),
        "cutoff_tgo_s": F(
            "float",
            60.0,
            lo=0.0,
            units="s",
            doc="no burn in the last cutoff_tgo_s before the nominal impact",
        ),
    },
}


def time_of_flight_s(cfg: dict) -> float:
    """Nominal time of flight to the B-plane (s) of the straight-line approach."""
    return straight_line_time_to_b_plane(
        cfg["approach"]["position_km"], cfg["approach"]["velocity_kmps"]
    )


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
    """Cross-field and physical-domain checks of a validated impactor configuration."""
    a, g, cam, dy = cfg["approach"], cfg["guidance"], cfg["camera"], cfg["dynamics"]
    sc = cfg["spacecraft"]
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
    r = _norm(a["position_km"])
    radius = max(cfg["target"]["semi_axes_km"])
    if not MIN_RANGE_RADII * radius < r <= 1e7:
        raise ScenarioError(
            f"approach.position_km: range {r:.4g} km; allowed: more than {MIN_RANGE_RADII:g} "
            f"target radii ({MIN_RANGE_RADII * radius:g} km) and at most 1e7 km"
        )
    tof = time_of_flight_s(cfg)
    if tof <= 0.0:
        raise ScenarioError(
            "approach.velocity_kmps: the impactor must approach the target "
            "(position . velocity < 0)"
        )
    if tof > MAX_TOF_S:
        raise ScenarioError(
            f"approach: time of flight {tof / 86400:.3g} days (range / closing speed); allowed: "
            f"at most {MAX_TOF_S / 86400:g} days (a terminal phase: the B-plane frame is fixed "
            "by the initial velocity; longer approaches are a midcourse problem)"
        )
    au_km = 1.495978707e8
    d = dy["sun_distance_au"]
    if d != 0.0 and not (d >= MIN_SUN_AU and r <= MAX_TIDE_RATIO * d * au_km):
        raise ScenarioError(
            f"dynamics.sun_distance_au: {d:g} AU; allowed: 0 (no solar tide) or at least "
            f"{max(MIN_SUN_AU, r / (MAX_TIDE_RATIO * au_km)):.3g} AU ({MIN_SUN_AU:g} AU and "
            f"{1 / MAX_TIDE_RATIO:g} x the approach range: the tide is linearised)"
        )
    if not sc["propellant_kg"] < sc["mass_kg"]:
        raise ScenarioError(
            f"spacecraft.propellant_kg: {sc['propellant_kg']:g} kg is not less than "
            f"spacecraft.mass_kg = {sc['mass_kg']:g} kg; allowed: [0, mass_kg)"
        )
    _check_dv_budget(cfg, tof)
    ratio = cam["image_interval_s"] / g["dt_s"]
    if abs(ratio - round(ratio)) > 1e-9 * ratio:
        raise ScenarioError(
            f"guidance.dt_s: {g['dt_s']:g} s does not divide camera.image_interval_s = "
            f"{cam['image_interval_s']:g} s; allowed: image_interval_s / n for a whole n"
        )
    if not g["cutoff_tgo_s"] < tof:
        raise ScenarioError(
            f"guidance.cutoff_tgo_s: {g['cutoff_tgo_s']:g} s; allowed: [0, {tof:g}) s (less "
            "than the time of flight)"
        )
    if not g["retarget_tgo_s"] < tof:
        raise ScenarioError(
            f"guidance.retarget_tgo_s: {g['retarget_tgo_s']:g} s; allowed: [0, {tof:g}) s "
            "(less than the time of flight)"
        )
    images = (tof - g["cutoff_tgo_s"]) / cam["image_interval_s"]
    if images < MIN_IMAGES:
        raise ScenarioError(
            f"camera.image_interval_s: {cam['image_interval_s']:g} s leaves {images:.3g} images "
            f"before the cut-off; allowed: at most "
            f"{(tof - g['cutoff_tgo_s']) / MIN_IMAGES:.4g} s ({MIN_IMAGES} images)"
        )
    if cam["window_px"] % 2 == 0 or cam["window_px"] > cam["roi_px"] - 4:
        raise ScenarioError(
            f"camera.window_px: {cam['window_px']}; allowed: an odd number <= camera.roi_px - 4 "
            f"= {cam['roi_px'] - 4}"
        )
