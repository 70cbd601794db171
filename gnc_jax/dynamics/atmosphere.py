"""Atmospheric density: the U.S. Standard Atmosphere 1976 and an exponential model.

US76 (NOAA-S/T 76-1562, NASA-TM-X-74335) is defined by equations, not by a table. This module
evaluates those equations once, at import, with numpy on a fine altitude grid, and keeps the
log-density at about a thousand nodes. `us76_density` then interpolates the log-density with a
monotone piecewise-cubic Hermite (PCHIP) curve: monotone, C1 and cheap inside a vmapped
integrator, with an error far below 0.1 % (the standard's own tables are given to 4 digits).

- 0 to 86 km: seven layers with linear molecular-scale temperature in
  geopotential altitude H; hydrostatic pressure (eqs. 33a, 33b); rho = P M0 / (R* T_M) (eq. 42).
- 86 to 1000 km: kinetic temperature in four segments of geometric altitude Z
  (isothermal, elliptical, linear, exponential, eq. 32); number densities of N2, O, O2, Ar, He
  from the diffusion equation with eddy mixing (f_i of eq. 36) and vertical transport (eq. 37),
  H above 150 km with the escape flux (eqs. 39-40); rho = sum n_i M_i / N_A.

Altitude is geometric, above the standard's sea level. Outside 0-1000 km the log-density is
continued linearly with the end slope (exponential with the local scale height): still positive
and monotone, so an integrator that steps slightly below ground or above 1000 km stays finite.
"""

from typing import Literal

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._types import Array, Float, Scalar
from ..constants import G0_MPS2

# --- constants of the standard (SI; the standard quotes km and g/mol) ---
_G0 = G0_MPS2  # m/s^2, sea-level gravity
_R_GAS = 8.31432  # J/(mol K), the standard's gas constant R*
_AVOGADRO = 6.022169e23  # 1/mol
_R0 = 6.356766e6  # m, effective Earth radius for gravity and geopotential
_M0 = 28.9644e-3  # kg/mol, sea-level mean molar mass
_T0 = 288.15  # K
_P0 = 101325.0  # Pa

# Layers 0-6 below 86 km: base geopotential altitude (m') and molecular-temperature gradient.
_H_BASE = np.array([0.0, 11e3, 20e3, 32e3, 47e3, 51e3, 71e3, 84.852e3])
_LAPSE = np.array([-6.5e-3, 0.0, 1.0e-3, 2.8e-3, 0.0, -2.8e-3, -2.0e-3])  # K/m'

# Above 86 km (geometric altitudes, m).
_Z7, _Z8, _Z9, _Z10, _Z_TOP = 86e3, 91e3, 110e3, 120e3, 1000e3
_T7, _T9, _T10, _T_INF = 186.8673, 240.0, 360.0, 1000.0  # K
_TC, _A_ELL, _a_ELL = 263.1905, -76.3232, -19.9429e3  # K, K, m: elliptical segment 91-110 km
_LAPSE9 = 12.0e-3  # K/m, 110-120 km
_LAMBDA = 0.01875e-3  # 1/m, exponential segment above 120 km

_MOLAR_MASS = {  # kg/mol
    "N2": 28.0134e-3,
    "O": 15.9994e-3,
    "O2": 31.9988e-3,
    "Ar": 39.948e-3,
    "He": 4.0026e-3,
    "H": 1.00797e-3,
}
_N_AT_86KM = {"N2": 1.129794e20, "O": 8.6e16, "O2": 3.030898e19, "Ar": 1.3514e18, "He": 7.5817e14}
_N_H_AT_500KM = 8.0e10  # 1/m^3
_H_FLUX = 7.2e11  # 1/(m^2 s), hydrogen escape flux (eq. 39)
_ALPHA = {"O": 0.0, "O2": 0.0, "Ar": 0.0, "He": -0.40, "H": -0.25}  # thermal diffusion factors
_DIFF_A = {"O": 6.986e20, "O2": 4.863e20, "Ar": 4.487e20, "He": 1.7e21, "H": 3.305e21}  # 1/(m s)
_DIFF_B = {"O": 0.750, "O2": 0.750, "Ar": 0.870, "He": 0.691, "H": 0.500}
_EDDY_K7 = 120.0  # m^2/s, eddy diffusion coefficient below 95 km
# Vertical transport (eq. 37): Q (Z-U)^2 exp(-W (Z-U)^3) [+ q (u-Z)^2 exp(-w (u-Z)^3)], 1/m.
_TRANSPORT = {  # Q (1/m^3), U (m), W (1/m^3)
    "O": (-5.809644e-13, 56.90311e3, 2.706240e-14),
    "O2": (1.366212e-13, 86e3, 8.333333e-14),
    "Ar": (9.434079e-14, 86e3, 8.333333e-14),
    "He": (-2.457369e-13, 86e3, 6.666667e-13),
}
_O_HUMP = (-3.416248e-12, 97e3, 5.008765e-13)  # q (1/m^3), u (m), w (1/m^3); O below 97 km


def _cumtrapz(y: np.ndarray, x: np.ndarray) -> np.ndarray:
    return np.concatenate([[0.0], np.cumsum(0.5 * (y[1:] + y[:-1]) * np.diff(x))])


def _gravity(z: np.ndarray) -> np.ndarray:
    return _G0 * (_R0 / (_R0 + z)) ** 2


def _us76_density_below_86km(z: np.ndarray) -> np.ndarray:
    """Density (kg/m^3) at geometric altitudes 0-86 km: pressure by eqs. 33a/b, then eq. 42."""
    h = _R0 * z / (_R0 + z)  # geopotential altitude
    t_base, p_base = [_T0], [_P0]
    for lapse, h0, h1 in zip(_LAPSE[:-1], _H_BASE[:-2], _H_BASE[1:-1]):
        t_next = t_base[-1] + lapse * (h1 - h0)
        if lapse == 0.0:
            p_next = p_base[-1] * np.exp(-_G0 * _M0 * (h1 - h0) / (_R_GAS * t_base[-1]))
        else:
            p_next = p_base[-1] * (t_base[-1] / t_next) ** (_G0 * _M0 / (_R_GAS * lapse))
        t_base.append(t_next)
        p_base.append(p_next)
    layer = np.clip(np.searchsorted(_H_BASE, h, side="right") - 1, 0, len(_LAPSE) - 1)
    tb, pb, lb, hb = np.array(t_base)[layer], np.array(p_base)[layer], _LAPSE[layer], _H_BASE[layer]
    t_m = tb + lb * (h - hb)
    isothermal = lb == 0.0
    safe_lb = np.where(isothermal, 1.0, lb)
    p = np.where(
        isothermal,
        pb * np.exp(-_G0 * _M0 * (h - hb) / (_R_GAS * tb)),
        pb * (tb / t_m) ** (_G0 * _M0 / (_R_GAS * safe_lb)),
    )
    return p * _M0 / (_R_GAS * t_m)


def _temperature_above_86km(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Kinetic temperature T (K) and dT/dZ (K/m) of the four segments from 86 to 1000 km."""
    x = np.clip((z - _Z8) / _a_ELL, -1.0, 0.0)
    root = np.sqrt(np.maximum(1.0 - x**2, 1e-300))
    xi = (z - _Z10) * (_R0 + _Z10) / (_R0 + z)
    decay = np.exp(-_LAMBDA * xi)
    t = np.select(
        [z <= _Z8, z <= _Z9, z <= _Z10],
        [np.full_like(z, _T7), _TC + _A_ELL * root, _T9 + _LAPSE9 * (z - _Z9)],
        _T_INF - (_T_INF - _T10) * decay,
    )
    dt_dz = np.select(
        [z <= _Z8, z <= _Z9, z <= _Z10],
        [np.zeros_like(z), -_A_ELL / _a_ELL * x / root, np.full_like(z, _LAPSE9)],
        _LAMBDA * (_T_INF - _T10) * ((_R0 + _Z10) / (_R0 + z)) ** 2 * decay,
    )
    return t, dt_dz


def _eddy_diffusion(z: np.ndarray) -> np.ndarray:
    """Eddy diffusion coefficient K (m^2/s): 120 below 95 km, decaying to zero at 115 km."""
    mixed = z < 115e3
    denominator = np.where(mixed, 4e8 - (z - 95e3) ** 2, 1.0)  # m^2
    upper = np.where(mixed, _EDDY_K7 * np.exp(1.0 - 4e8 / denominator), 0.0)
    return np.where(z < 95e3, _EDDY_K7, upper)


def _vertical_transport(species: str, z: np.ndarray) -> np.ndarray:
    """Standard eq. 37: the v_i / (D_i + K) term (1/m), neglected above 150 km."""
    q, u, w = _TRANSPORT[species]
    term = q * (z - u) ** 2 * np.exp(-w * (z - u) ** 3)
    if species == "O":
        q2, u2, w2 = _O_HUMP
        below = u2 - np.minimum(z, u2)  # the hump term vanishes above u2 = 97 km
        term = term + q2 * below**2 * np.exp(-w2 * below**3)
    return np.where(z <= 150e3, term, 0.0)


def _us76_density_above_86km(z: np.ndarray) -> np.ndarray:
    """Density (kg/m^3) on an ascending grid ``z`` from 86 to 1000 km.

    Each number density is n_i = n_i(86 km) (T7/T) exp(-int_86km^Z (f_i + v_i/(D_i+K)) dZ)
    with f_i of eq. 36, integrated with the trapezoid rule on ``z``, which must be fine (tens
    of metres below 150 km) and contain the kinks at 91, 100, 110, 115 and 120 km as nodes.
    """
    g = _gravity(z)
    t, dt_dz = _temperature_above_86km(z)
    eddy = _eddy_diffusion(z)
    mixed = z < 115e3  # eddy mixing only below 115 km
    # Mean molar mass in the mixing term: M0 up to 100 km, then that of N2.
    m_mean = np.where(z <= 100e3, _M0, _MOLAR_MASS["N2"])

    def from_86km(n7: float, integrand: np.ndarray) -> np.ndarray:
        return n7 * (_T7 / t) * np.exp(-_cumtrapz(integrand, z))

    n = {"N2": from_86km(_N_AT_86KM["N2"], g * m_mean / (_R_GAS * t))}  # eq. 33 with D >> K

    def diffusing(species: str, background: np.ndarray) -> np.ndarray:
        mi, alpha = _MOLAR_MASS[species], _ALPHA[species]
        # Molecular diffusion coefficient D_i = a_i / n_b (T / 273.15)^b_i, m^2/s.
        d = _DIFF_A[species] / background * (t / 273.15) ** _DIFF_B[species]
        thermal = alpha * _R_GAS * dt_dz / g
        f_diffusive = g / (_R_GAS * t) * (mi + thermal)  # eq. 36 with K = 0
        f_mixed = g * d / ((d + eddy) * _R_GAS * t) * (mi + m_mean * eddy / d + thermal)
        f = np.where(mixed, f_mixed, f_diffusive)
        return from_86km(_N_AT_86KM[species], f + _vertical_transport(species, z))

    n["O"] = diffusing("O", n["N2"])
    n["O2"] = diffusing("O2", n["N2"])
    heavy = n["N2"] + n["O"] + n["O2"]
    n["Ar"] = diffusing("Ar", heavy)
    n["He"] = diffusing("He", heavy)

    # Hydrogen (eqs. 39-40), zero below 150 km; anchored at 500 km with an upward flux below.
    upper = z >= 150e3
    zu, tu, gu = z[upper], t[upper], g[upper]
    i500 = int(np.argmin(np.abs(zu - 500e3)))
    t500 = tu[i500]
    alpha = _ALPHA["H"]
    tau = _cumtrapz(_MOLAR_MASS["H"] * gu / (_R_GAS * tu), zu)
    tau = tau - tau[i500]  # tau(Z) = int_500km^Z M_H g / (R* T) dZ
    background = sum(n[s][upper] for s in ("N2", "O", "O2", "Ar", "He"))
    d_h = _DIFF_A["H"] / background * (tu / 273.15) ** _DIFF_B["H"]
    flux_integrand = _H_FLUX / d_h * (tu / t500) ** (1.0 + alpha) * np.exp(tau)
    flux_integral = _cumtrapz(flux_integrand, zu)
    flux_integral = np.where(zu < 500e3, flux_integral[i500] - flux_integral, 0.0)
    n_h = np.zeros_like(z)
    n_h[upper] = (_N_H_AT_500KM + flux_integral) * (t500 / tu) ** (1.0 + alpha) * np.exp(-tau)
    n["H"] = n_h

    return sum(n[s] * _MOLAR_MASS[s] for s in n) / _AVOGADRO


def _pchip_slopes(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Fritsch-Carlson node slopes: weighted harmonic mean of the neighbouring secants."""
    h = np.diff(x)
    secant = np.diff(y) / h
    slopes = np.empty_like(y)
    slopes[0], slopes[-1] = secant[0], secant[-1]
    w1 = 2.0 * h[1:] + h[:-1]
    w2 = h[1:] + 2.0 * h[:-1]
    same_sign = secant[:-1] * secant[1:] > 0.0
    safe_l = np.where(same_sign, secant[:-1], 1.0)
    safe_r = np.where(same_sign, secant[1:], 1.0)
    slopes[1:-1] = np.where(same_sign, (w1 + w2) / (w1 / safe_l + w2 / safe_r), 0.0)
    return slopes


def _build_us76_table() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nodes (m), log-density and its slope (1/m) for `us76_density`."""
    # The layer bases below 86 km, as geometric altitudes, are nodes: the slope of
    # log-density jumps there, and a node on the kink keeps the interpolation error local.
    z_layers = _R0 * _H_BASE[1:-1] / (_R0 - _H_BASE[1:-1])
    z_low = np.union1d(np.arange(0.0, _Z7, 250.0), z_layers)
    # Fine integration grid above 86 km: every 10 m to 150 km (contains 91, 100, 110, 115, 120
    # km exactly), every 100 m above; the table keeps every 250 m to 150 km, every 2 km above.
    z_fine = np.concatenate([_Z7 + 10.0 * np.arange(6400), 150e3 + 100.0 * np.arange(8501)])
    rho_fine = _us76_density_above_86km(z_fine)
    keep = np.concatenate([np.arange(0, 6400, 25), 6400 + np.arange(0, 8501, 20)])
    z_nodes = np.concatenate([z_low, z_fine[keep]])
    log_rho = np.log(np.concatenate([_us76_density_below_86km(z_low), rho_fine[keep]]))
    return z_nodes, log_rho, _pchip_slopes(z_nodes, log_rho)


_US76_ALT_M, _US76_LOG_RHO, _US76_DLOG_RHO = _build_us76_table()


def _build_bucket_index(nodes: np.ndarray, width: float, margin: float = 1.0) -> np.ndarray:
    """Uniform buckets over the node range, so that locating an altitude needs no search.

    Bucket b covers [nodes[0] + b width, nodes[0] + (b + 1) width). Row b holds ``first``, the
    index of the last node at or below the bucket's start minus ``margin`` (-1 if none), then
    the nodes that follow it up to the bucket's end plus ``margin`` (padded with +inf): the
    node interval of an altitude in bucket b is ``first`` plus the number of those nodes at or
    below it -- exactly ``searchsorted(nodes, alt, "right") - 1`` (the margin absorbs the
    rounding of the bucket number near a bucket edge)."""
    n_buckets = int(np.ceil((nodes[-1] - nodes[0]) / width)) + 1
    start = nodes[0] + width * np.arange(n_buckets)
    first = np.searchsorted(nodes, start - margin, side="right") - 1
    last = np.searchsorted(nodes, start + width + margin, side="right") - 1
    extra = int(np.max(last - first))
    padded = np.concatenate([nodes, np.full(extra, np.inf)])
    following = padded[np.clip(first[:, None] + np.arange(1, extra + 1), 0, None)]
    following[following > (start + width + margin)[:, None]] = np.inf
    return np.concatenate([first[:, None].astype(float), following], axis=1)


def _build_interval_rows(nodes, log_rho, slope) -> np.ndarray:
    """Row k: (x_k, h_k = x_{k+1} - x_k, ln rho_k, slope_k, ln rho_{k+1}, slope_{k+1})."""
    return np.stack(
        [nodes[:-1], np.diff(nodes), log_rho[:-1], slope[:-1], log_rho[1:], slope[1:]], axis=1
    )


_US76_BUCKET_M = 250.0  # the table's finest regular spacing: at most a layer base is added
_US76_BUCKETS = _build_bucket_index(_US76_ALT_M, _US76_BUCKET_M)
_US76_ROWS = _build_interval_rows(_US76_ALT_M, _US76_LOG_RHO, _US76_DLOG_RHO)


def _us76_interval(alt):
    """Index k of the node interval [nodes[k], nodes[k+1]) holding ``alt``, clipped to the
    table: ``clip(searchsorted(nodes, alt, "right") - 1, 0, n - 2)``, found by one bucket row
    and a few comparisons (a binary search under ``vmap`` costs a loop of ten gathers per
    density, several times the rest of an entry right-hand side)."""
    top = _US76_BUCKETS.shape[0] - 1
    b = jnp.floor((alt - _US76_ALT_M[0]) * (1.0 / _US76_BUCKET_M))
    b = jnp.clip(jnp.where(jnp.isnan(b), top, b), 0, top).astype(jnp.int32)  # NaN: as searchsorted
    row = jnp.asarray(_US76_BUCKETS)[b]
    k = row[..., 0].astype(jnp.int32)
    for j in range(1, _US76_BUCKETS.shape[1]):
        k = k + (row[..., j] <= alt)
    return jnp.clip(k, 0, _US76_ROWS.shape[0] - 1)


def us76_density(alt_m: Float[Array, "*batch"]) -> Float[Array, "*batch"]:
    """U.S. Standard Atmosphere 1976 density, kg/m^3, at geometric altitude ``alt_m`` (m).

    Monotone cubic Hermite interpolation of ln(rho) between table nodes (every 250 m below
    150 km, 2 km above, plus the layer bases); log-linear continuation outside 0-1000 km.
    Differentiable in ``alt_m`` (C1).
    """
    alt = jnp.asarray(alt_m, dtype=float)
    row = jnp.asarray(_US76_ROWS)[_us76_interval(alt)]
    x0, h, lr0, sl0, lr1, sl1 = (row[..., j] for j in range(6))
    s = (alt - x0) / h
    inside = (
        lr0 * (1.0 + 2.0 * s) * (1.0 - s) ** 2
        + sl0 * h * s * (1.0 - s) ** 2
        + lr1 * s**2 * (3.0 - 2.0 * s)
        - sl1 * h * s**2 * (1.0 - s)
    )
    z0, z1 = _US76_ALT_M[0], _US76_ALT_M[-1]
    below = _US76_LOG_RHO[0] + _US76_DLOG_RHO[0] * (alt - z0)
    above = _US76_LOG_RHO[-1] + _US76_DLOG_RHO[-1] * (alt - z1)
    log_density = jnp.where(alt < z0, below, jnp.where(alt > z1, above, inside))
    return jnp.exp(log_density)


def exponential_density(
    alt_m: Float[Array, "*batch"], rho0: float = 1.225, scale_height_m: float = 7200.0
) -> Float[Array, "*batch"]:
    """Isothermal exponential atmosphere rho = rho0 exp(-h / H), kg/m^3.

    Defaults: rho0 = 1.225 kg/m^3 (US76 sea level) and H = 7200 m, the usual single scale
    height for entry analysis (it matches US76 to within a factor of about 1.5 between 40 and
    90 km but not above 100 km).
    """
    return rho0 * jnp.exp(-jnp.asarray(alt_m, dtype=float) / scale_height_m)


AtmosphereModel = Literal["us76", "exponential"]


class Atmosphere(eqx.Module):
    """The atmosphere a scenario flies through: a model choice and its parameters.

    Attributes:
        model: ``"us76"`` or ``"exponential"`` (static: it selects the code, not a value).
        density_scale: multiplicative density dispersion (seed 003 Table 2: 30 % at 3 sigma).
        rho0: sea-level density of the exponential model, kg/m^3 (unused by US76).
        scale_height_m: scale height of the exponential model, m (unused by US76).
    """

    model: AtmosphereModel = eqx.field(static=True, default="us76")
    density_scale: Scalar = eqx.field(default=1.0, converter=jnp.asarray)
    rho0: Scalar = eqx.field(default=1.225, converter=jnp.asarray)
    scale_height_m: Scalar = eqx.field(default=7200.0, converter=jnp.asarray)

    def __check_init__(self):
        if self.model not in ("us76", "exponential"):
            raise ValueError(
                f"unknown atmosphere model {self.model!r}; use 'us76' or 'exponential'"
            )

    def density(self, alt_m: Float[Array, "*batch"]) -> Float[Array, "*batch"]:
        """Density at geometric altitude ``alt_m`` (m), kg/m^3, including ``density_scale``."""
        if self.model == "us76":  # static field: resolved at trace time
            rho = us76_density(alt_m)
        else:
            rho = exponential_density(alt_m, self.rho0, self.scale_height_m)
        return self.density_scale * rho
