# ruff: noqa: F722  (jaxtyping shape strings such as "" and "8 3" are not Python expressions)
"""Analytical heliocentric ephemerides of the eight planets (Simon et al. 1994) and their GMs.

No ephemeris files can be downloaded (the machine is offline), so the planets follow the
mean-element theory
of Simon, Bretagnon, Chapront, Chapront-Touzé, Francou and Laskar (1994), "Numerical
expressions for precession formulae and mean elements for the Moon and the planets",
Astron. Astrophys. 282, 663, as implemented by SOFA/ERFA ``plan94``: for each planet the mean
semi-major axis, mean longitude, eccentricity, longitude of perihelion, inclination and node are
quadratic polynomials in time, the semi-major axis and mean longitude get 9 and 10 periodic
terms, and the position is that of the Keplerian ellipse with these elements. The velocity is
the two-body velocity on that ellipse (as in plan94), not the time derivative of the position;
over 1990-2030 the two differ by up to 1.6 m/s (EMB), 3.3 m/s (Mars) and 31 m/s (Saturn).

Accuracy quoted by SOFA/ERFA for plan94, RMS against DE200 over 1960-2025 (position /
velocity): Mercury 334 km / 0.44 m/s, Venus 1060 km / 0.86 m/s, EMB 2010 km / 0.82 m/s,
Mars 7690 km / 1.98 m/s, Jupiter 71700 km / 7.7 m/s, Saturn 199000 km / 19.4 m/s, Uranus
564000 km / 16.4 m/s, Neptune 158000 km / 14.4 m/s (maxima over 1800-2100 in plan94.c's
notes; outside 1000-3000 CE the theory degrades). This implementation reproduces ERFA's
``plan94`` to ~1e-13 AU (tests/dynamics/test_ephemeris.py).

Conventions:
    * Planet index 0..7 = Mercury, Venus, Earth, Mars, Jupiter, Saturn, Uranus, Neptune
      (`PLANETS`); ERFA numbers them 1..8. "Earth" is the Earth–Moon barycentre (EMB), which
      is also the right point mass for the Earth+Moon system seen from interplanetary space.
    * Frame: heliocentric, mean equator and equinox of J2000.0 (EME2000, the frame of
      ``erfa.plan94``); it differs from the ICRF by the ~20 mas frame bias, negligible here.
      The theory itself is ecliptic; `equatorial_to_ecliptic` / `ecliptic_to_equatorial`
      rotate by the IAU 1976 J2000 obliquity ε0 = 84381.448″ used by plan94.
    * Time: seconds past J2000 TDB (`gnc_jax.time`); output in m and m/s.
"""

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, Int

from ..constants import AU_M, SECONDS_PER_DAY
from ..geometry.kepler import solve_kepler_elliptic, true_anomaly_from_eccentric

PLANETS: tuple[str, ...] = (
    "mercury",
    "venus",
    "earth",
    "mars",
    "jupiter",
    "saturn",
    "uranus",
    "neptune",
)
"""Planet names in index order; "earth" is the Earth–Moon barycentre."""


OBLIQUITY_J2000_RAD = 84381.448 * np.pi / (180.0 * 3600.0)
"""Mean obliquity of the ecliptic at J2000.0, IAU 1976 (Lieske et al. 1977), rad."""

# Gravitational parameters, m³/s², from the JPL DE440 ephemeris (Park, Folkner, Williams,
# Boggs 2021, AJ 161:105, table 8; TDB-compatible). Outer planets are their systems
# (planet + satellites), "earth" is Earth + Moon to match the EMB position.
GM_SUN = 1.32712440041279419e20
"""Sun, m³/s² (DE440)."""

_GM_KM3_S2 = {
    "mercury": 22031.868551,
    "venus": 324858.592000,
    "earth": 398600.435507 + 4902.800118,  # Earth + Moon
    "mars": 42828.375816,  # Mars system
    "jupiter": 126712764.100000,  # Jupiter system
    "saturn": 37940584.841800,  # Saturn system
    "uranus": 5794556.400000,  # Uranus system
    "neptune": 6836527.100580,  # Neptune system
}
GM_PLANETS = np.array([_GM_KM3_S2[name] * 1e9 for name in PLANETS])
"""Planet (system) gravitational parameters in `PLANETS` order, m³/s² (DE440)."""


def planet_index(name: str) -> int:
    """Index of a planet in `PLANETS` (case-insensitive; "emb" is accepted for "earth")."""
    key = name.strip().lower()
    key = "earth" if key in ("emb", "earth-moon barycentre", "earth-moon barycenter") else key
    if key not in PLANETS:
        raise ValueError(f"unknown planet {name!r}; expected one of {', '.join(PLANETS)}")
    return PLANETS.index(key)


# ---------------------------------------------------------------------------------------------
# Simon et al. (1994) mean elements, as tabulated in SOFA/ERFA plan94.c (rows in PLANETS order).
# Angles: constant term in degrees, t and t² coefficients in arcsec per Julian millennium^n.

# Planetary inverse masses (Sun / planet) of the theory; they enter the mean motion.
_INVERSE_MASS = np.array(
    [6023600.0, 408523.5, 328900.5, 3098710.0, 1047.355, 3498.5, 22869.0, 19314.0]
)

# Semi-major axis a (AU): a0, a1, a2.
_A = np.array([
    [0.3870983098, 0.0, 0.0],
    [0.7233298200, 0.0, 0.0],
    [1.0000010178, 0.0, 0.0],
    [1.5236793419, 3e-10, 0.0],
    [5.2026032092, 19132e-10, -39e-10],
    [9.5549091915, -0.0000213896, 444e-10],
    [19.2184460618, -3716e-10, 979e-10],
    [30.1103868694, -16635e-10, 686e-10],
])  # fmt: skip

# Mean longitude λ.
_MEAN_LONGITUDE = np.array([
    [252.25090552, 5381016286.88982, -1.92789],
    [181.97980085, 2106641364.33548, 0.59381],
    [100.46645683, 1295977422.83429, -2.04411],
    [355.43299958, 689050774.93988, 0.94264],
    [34.35151874, 109256603.77991, -30.60378],
    [50.07744430, 43996098.55732, 75.61614],
    [314.05500511, 15424811.93933, -1.75083],
    [304.34866548, 7865503.20744, 0.21103],
])  # fmt: skip

# Eccentricity e.
_ECCENTRICITY = np.array([
    [0.2056317526, 0.0002040653, -28349e-10],
    [0.0067719164, -0.0004776521, 98127e-10],
    [0.0167086342, -0.0004203654, -0.0000126734],
    [0.0934006477, 0.0009048438, -80641e-10],
    [0.0484979255, 0.0016322542, -0.0000471366],
    [0.0555481426, -0.0034664062, -0.0000643639],
    [0.0463812221, -0.0002729293, 0.0000078913],
    [0.0094557470, 0.0000603263, 0.0],
])  # fmt: skip

# Longitude of perihelion ϖ.
_PERIHELION_LONGITUDE = np.array([
    [77.45611904, 5719.11590, -4.83016],
    [131.56370300, 175.48640, -498.48184],
    [102.93734808, 11612.35290, 53.27577],
    [336.06023395, 15980.45908, -62.32800],
    [14.33120687, 7758.75163, 259.95938],
    [93.05723748, 20395.49439, 190.25952],
    [173.00529106, 3215.56238, -34.09288],
    [48.12027554, 1050.71912, 27.39717],
])  # fmt: skip

# Inclination i.
_INCLINATION = np.array([
    [7.00498625, -214.25629, 0.28977],
    [3.39466189, -30.84437, -11.67836],
    [0.0, 469.97289, -3.35053],
    [1.84972648, -293.31722, -8.11830],
    [1.30326698, -71.55890, 11.95297],
    [2.48887878, 91.85195, -17.66225],
    [0.77319689, -60.72723, 1.25759],
    [1.76995259, 8.12333, 0.08135],
])  # fmt: skip

# Longitude of the ascending node Ω.
_NODE_LONGITUDE = np.array([
    [48.33089304, -4515.21727, -31.79892],
    [76.67992019, -10008.48154, -51.32614],
    [174.87317577, -8679.27034, 15.34191],
    [49.55809321, -10620.90088, -230.57416],
    [100.46440702, 6362.03561, 326.52178],
    [113.66550252, -9240.19942, -66.23743],
    [74.00595701, 2669.15033, 145.93964],
    [131.78405702, -221.94322, -0.78728],
])  # fmt: skip

# Periodic terms of a: Σ_k (ca_k cos(kp_k μ) + sa_k sin(kp_k μ)) 1e-7 AU, μ = 0.35953620 t;
# the 9th term (last column) is multiplied by t.
_A_FREQUENCY = np.array([
    [69613, 75645, 88306, 59899, 15746, 71087, 142173, 3086, 0],
    [21863, 32794, 26934, 10931, 26250, 43725, 53867, 28939, 0],
    [16002, 21863, 32004, 10931, 14529, 16368, 15318, 32794, 0],
    [6345, 7818, 15636, 7077, 8184, 14163, 1107, 4872, 0],
    [1760, 1454, 1167, 880, 287, 2640, 19, 2047, 1454],
    [574, 0, 880, 287, 19, 1760, 1167, 306, 574],
    [204, 0, 177, 1265, 4, 385, 200, 208, 204],
    [0, 102, 106, 4, 98, 1367, 487, 204, 0],
], dtype=float)  # fmt: skip
_A_COS = np.array([
    [4, -13, 11, -9, -9, -3, -1, 4, 0],
    [-156, 59, -42, 6, 19, -20, -10, -12, 0],
    [64, -152, 62, -8, 32, -41, 19, -11, 0],
    [124, 621, -145, 208, 54, -57, 30, 15, 0],
    [-23437, -2634, 6601, 6259, -1507, -1821, 2620, -2115, -1489],
    [62911, -119919, 79336, 17814, -24241, 12068, 8306, -4893, 8902],
    [389061, -262125, -44088, 8387, -22976, -2093, -615, -9720, 6633],
    [-412235, -157046, -31430, 37817, -9740, -13, -7449, 9644, 0],
], dtype=float)  # fmt: skip
_A_SIN = np.array([
    [-29, -1, 9, 6, -6, 5, 4, 0, 0],
    [-48, -125, -26, -37, 18, -13, -20, -2, 0],
    [-150, -46, 68, 54, 14, 24, -28, 22, 0],
    [-621, 532, -694, -20, 192, -94, 71, -73, 0],
    [-14614, -19828, -5869, 1881, -4372, -2255, 782, 930, 913],
    [139737, 0, 24667, 51123, -5102, 7429, -4095, -1976, -9566],
    [-138081, 0, 37205, -49039, -41901, -33872, -27037, -12474, 18797],
    [0, 28492, 133236, 69654, 52322, -49577, -26430, -3593, 0],
], dtype=float)  # fmt: skip

# Periodic terms of λ (1e-7 rad); the 9th and 10th terms are multiplied by t.
_L_FREQUENCY = np.array([
    [3086, 15746, 69613, 59899, 75645, 88306, 12661, 2658, 0, 0],
    [21863, 32794, 10931, 73, 4387, 26934, 1473, 2157, 0, 0],
    [10, 16002, 21863, 10931, 1473, 32004, 4387, 73, 0, 0],
    [10, 6345, 7818, 1107, 15636, 7077, 8184, 532, 10, 0],
    [19, 1760, 1454, 287, 1167, 880, 574, 2640, 19, 1454],
    [19, 574, 287, 306, 1760, 12, 31, 38, 19, 574],
    [4, 204, 177, 8, 31, 200, 1265, 102, 4, 204],
    [4, 102, 106, 8, 98, 1367, 487, 204, 4, 102],
], dtype=float)  # fmt: skip
_L_COS = np.array([
    [21, -95, -157, 41, -5, 42, 23, 30, 0, 0],
    [-160, -313, -235, 60, -74, -76, -27, 34, 0, 0],
    [-325, -322, -79, 232, -52, 97, 55, -41, 0, 0],
    [2268, -979, 802, 602, -668, -33, 345, 201, -55, 0],
    [7610, -4997, -7689, -5841, -2617, 1115, -748, -607, 6074, 354],
    [-18549, 30125, 20012, -730, 824, 23, 1289, -352, -14767, -2062],
    [-135245, -14594, 4197, -4030, -5630, -2898, 2540, -306, 2939, 1986],
    [89948, 2103, 8963, 2695, 3682, 1648, 866, -154, -1963, -283],
], dtype=float)  # fmt: skip
_L_SIN = np.array([
    [-342, 136, -23, 62, 66, -52, -33, 17, 0, 0],
    [524, -149, -35, 117, 151, 122, -71, -62, 0, 0],
    [-105, -137, 258, 35, -116, -88, -112, -80, 0, 0],
    [854, -205, -936, -240, 140, -341, -97, -232, 536, 0],
    [-56980, 8016, 1012, 1448, -3024, -3710, 318, 503, 3767, 577],
    [138606, -13478, -4964, 1441, -1319, -1482, 427, 1236, -9167, -1918],
    [71234, -41116, 5334, -4935, -1848, 66, 434, -1748, 3780, -701],
    [-47645, 11647, 2166, 3194, 679, 0, -244, -419, -2531, 48],
], dtype=float)  # fmt: skip

_GAUSS_K = 0.01720209895  # Gaussian gravitational constant, AU^(3/2) / day
_DAYS_PER_MILLENNIUM = 365250.0
_ARCSEC_TO_RAD = np.pi / (180.0 * 3600.0)
_PERIODIC_RATE = 0.35953620  # rad per millennium per unit frequency of the periodic terms
_N_PERIODIC_A = 8  # pure periodic terms of a; the 9th is of the Poisson form t cos(...)
_N_PERIODIC_L = 8  # pure periodic terms of λ; the 9th and 10th are Poisson terms


def _angle_polynomial(table: np.ndarray, index: Array, t: Array) -> Array:
    """(3600 c0 + c1 t + c2 t²) arcsec in radians, c0 in degrees (Simon et al. 1994 table)."""
    c = jnp.asarray(table)[index]
    return (3600.0 * c[0] + (c[1] + c[2] * t) * t) * _ARCSEC_TO_RAD


def _periodic_sum(
    cos_table: np.ndarray,
    sin_table: np.ndarray,
    frequency_table: np.ndarray,
    index: Array,
    t: Array,
    n_pure: int,
) -> Array:
    """Σ_k (C_k cos(k μ) + S_k sin(k μ)) 1e-7 with μ = 0.35953620 t, the terms from
    ``n_pure`` on multiplied by t (Poisson terms)."""
    argument = jnp.asarray(frequency_table)[index] * (_PERIODIC_RATE * t)
    cos_coefficient = jnp.asarray(cos_table)[index]
    sin_coefficient = jnp.asarray(sin_table)[index]
    terms = cos_coefficient * jnp.cos(argument) + sin_coefficient * jnp.sin(argument)
    return (jnp.sum(terms[:n_pure]) + t * jnp.sum(terms[n_pure:])) * 1e-7


def _mean_elements(index: Array, t: Array):
    """Simon et al. (1994) elements at t Julian millennia from J2000 TDB: a [AU], λ, e, ϖ, i, Ω."""
    a_poly = jnp.asarray(_A)[index]
    e_poly = jnp.asarray(_ECCENTRICITY)[index]
    a = a_poly[0] + (a_poly[1] + a_poly[2] * t) * t
    a = a + _periodic_sum(_A_COS, _A_SIN, _A_FREQUENCY, index, t, _N_PERIODIC_A)
    mean_longitude = _angle_polynomial(_MEAN_LONGITUDE, index, t)
    mean_longitude = mean_longitude + _periodic_sum(
        _L_COS, _L_SIN, _L_FREQUENCY, index, t, _N_PERIODIC_L
    )
    e = e_poly[0] + (e_poly[1] + e_poly[2] * t) * t
    perihelion = _angle_polynomial(_PERIHELION_LONGITUDE, index, t)
    inclination = _angle_polynomial(_INCLINATION, index, t)
    node = _angle_polynomial(_NODE_LONGITUDE, index, t)
    return a, mean_longitude, e, perihelion, inclination, node


def _ecliptic_state_au(index: Array, t: Array) -> tuple[Array, Array]:
    """Heliocentric J2000 ecliptic position (AU) and velocity (AU/day), plan94 algorithm."""
    a, mean_longitude, e, perihelion, inclination, node = _mean_elements(index, t)
    # The mean anomaly (~1e3 rad a century) is reduced to [-π, π) inside the Kepler solve.
    ecc_anomaly = solve_kepler_elliptic(mean_longitude - perihelion, e)
    true_anomaly = true_anomaly_from_eccentric(ecc_anomaly, e)
    radius = a * (1.0 - e * jnp.cos(ecc_anomaly))
    # Mean motion (rad/day) from Kepler's third law with the planet's mass added to the Sun's.
    mean_motion = _GAUSS_K * jnp.sqrt((1.0 + 1.0 / jnp.asarray(_INVERSE_MASS)[index]) / a**3)

    # Orbit orientation through the half-angle node vector (sin(i/2) cos Ω, sin(i/2) sin Ω),
    # exactly as plan94 writes the rotation from the orbit plane to the ecliptic.
    sin_half_i = jnp.sin(0.5 * inclination)
    cos_half_i = jnp.cos(0.5 * inclination)
    q = sin_half_i * jnp.cos(node)
    p = sin_half_i * jnp.sin(node)
    true_longitude = true_anomaly + perihelion
    sin_l, cos_l = jnp.sin(true_longitude), jnp.cos(true_longitude)
    out_of_plane = 2.0 * (p * cos_l - q * sin_l)
    position = radius * jnp.stack(
        [cos_l - out_of_plane * p, sin_l + out_of_plane * q, -out_of_plane * cos_half_i]
    )

    scale = a / jnp.sqrt(1.0 - e * e)
    v_sin = (e * jnp.sin(perihelion) + sin_l) * scale
    v_cos = (e * jnp.cos(perihelion) + cos_l) * scale
    velocity = mean_motion * jnp.stack(
        [
            (-1.0 + 2.0 * p * p) * v_sin + 2.0 * p * q * v_cos,
            (1.0 - 2.0 * q * q) * v_cos - 2.0 * p * q * v_sin,
            2.0 * cos_half_i * (p * v_sin + q * v_cos),
        ]
    )
    return position, velocity


def _ecliptic_to_equatorial_matrix() -> np.ndarray:
    c, s = np.cos(OBLIQUITY_J2000_RAD), np.sin(OBLIQUITY_J2000_RAD)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


ECLIPTIC_TO_EQUATORIAL = _ecliptic_to_equatorial_matrix()
"""Rotation R1(-ε0) taking J2000 ecliptic components to J2000 mean-equatorial components."""


def ecliptic_to_equatorial(vector: Float[ArrayLike, "... 3"]) -> Float[Array, "... 3"]:
    """J2000 ecliptic → J2000 mean equator (EME2000): x_eq = R1(-ε0) x_ecl, ε0 = 84381.448″."""
    return jnp.asarray(vector) @ ECLIPTIC_TO_EQUATORIAL.T


def equatorial_to_ecliptic(vector: Float[ArrayLike, "... 3"]) -> Float[Array, "... 3"]:
    """J2000 mean equator (EME2000) → J2000 ecliptic: x_ecl = R1(ε0) x_eq, ε0 = 84381.448″."""
    return jnp.asarray(vector) @ ECLIPTIC_TO_EQUATORIAL


ECLIPTIC_POLE_EQUATORIAL = ECLIPTIC_TO_EQUATORIAL[:, 2]
"""Unit normal of the J2000 ecliptic in EME2000 components, (0, -sin ε0, cos ε0)."""


def planet_state(
    planet_index: Int[ArrayLike, ""], t_tdb_s: Float[ArrayLike, ""]
) -> tuple[Float[Array, "3"], Float[Array, "3"]]:
    """Heliocentric position (m) and velocity (m/s) of a planet, EME2000 frame.

    Simon et al. (1994) mean elements with periodic terms, Keplerian position on the
    osculating-like ellipse (the ERFA/SOFA ``plan94`` algorithm; see the module docstring for
    accuracy and frame). ``planet_index`` is 0..7 in `PLANETS` order (may be traced; it is not
    range-checked inside jit); ``t_tdb_s`` is seconds past J2000 TDB. Vmap over either.
    """
    index = jnp.asarray(planet_index)
    t = jnp.asarray(t_tdb_s, dtype=float) / (SECONDS_PER_DAY * _DAYS_PER_MILLENNIUM)
    position_au, velocity_au_day = _ecliptic_state_au(index, t)
    position = ECLIPTIC_TO_EQUATORIAL @ position_au * AU_M
    velocity = ECLIPTIC_TO_EQUATORIAL @ velocity_au_day * (AU_M / SECONDS_PER_DAY)
    return position, velocity


def planet_states(
    t_tdb_s: Float[ArrayLike, ""],
) -> tuple[Float[Array, "8 3"], Float[Array, "8 3"]]:
    """Heliocentric positions (m) and velocities (m/s) of all eight planets, EME2000 frame.

    Rows in `PLANETS` order; `planet_state` vmapped over the planet index at one epoch
    ``t_tdb_s`` (seconds past J2000 TDB).
    """
    return jax.vmap(planet_state, in_axes=(0, None))(jnp.arange(len(PLANETS)), t_tdb_s)
