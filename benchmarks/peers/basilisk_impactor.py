"""Basilisk peer of the ``deep-impact-los`` closed loop: the same study built from
Basilisk's own modules, run on both cores through its Monte Carlo controller and a process pool.

    python -m benchmarks.peers.basilisk_impactor [--quick] [--runs N]

How each Basilisk piece maps to gnc_jax (``simulation/impactor.py`` unless named):

- ``spacecraft.Spacecraft`` (hub of 372 kg, ``pointMassTranslationalOnly``: the study is
  three-degree-of-freedom, attitude errors are small angles) with Basilisk's fixed-step RK4
  (``svIntegratorRK4``, the default) at the 1 s task rate <-> the truth ``propagate`` of
  ``dynamics/impactor.py`` (RK4, one step per control step). The dispersed initial position is
  ``hub.r_CN_NInit`` <-> ``initial_conditions`` (delivery error).
- ``gravityEffector`` through ``simIncludeGravBody.gravBodyFactory().createCustomGravObject``: the
  small body as the central point mass, mu = ``[dynamics] mu_target_m3s2`` (0 in this scenario,
  as in the paper: the terms are evaluated all the same) <-> ``RelativeDynamics.gravity``.
  The solar tide has no Basilisk counterpart short of adding the Sun as a body; the peer refuses
  a scenario with ``sun_distance_au`` > 0.
- ``extForceTorque.ExtForceTorque`` fed a ``CmdForceInertialMsg`` <-> the engine: thrust
  ``throttle F (1 + burn magnitude error) direction`` tilted by the pointing error, both drawn at
  each ignition (``systems.impactor.step.control_step``). Basilisk's ``thrusterDynamicEffector``
  + ``thrFiringSchmitt`` cannot express the law's trigger: its Schmitt levels are fixed fractions
  of a requested on-time, while the LOS law compares |omega| with switching curves that move at
  every step, and its thrusters are body-fixed (the law steers an inertial direction). The engine
  is therefore the external-force effector commanded by the guidance module.
- ``ImpactorLOSGNC``, a Basilisk **Python module** (``sysModel.SysModel`` subclass with
  ``Reset``/``UpdateState``; reads ``SCStatesMsg``, writes ``CmdForceInertialMsg``) <-> the rest of
  the closed loop, transcribed in numpy with the same equations:
  at each 1 s ``UpdateState`` (time t): the EKF mean prediction over [t - 1, t] with the
  accelerometer's Δv (bias + white noise while firing) <-> ``propagate_state``; every 15 s the
  covariance propagation <-> ``propagate_covariance`` (straight line + accelerometer Δv error),
  the image (camera pointed at the estimate with attitude-control error, attitude knowledge bias
  and noise, centroid noise, from the truth position read from ``SCStatesMsg``) and its Joseph
  EKF update <-> ``take_image`` / ``navigation/ekf.py``, and the law's ``plan`` (B-plane error
  ellipse) <-> ``guidance/los.py``; then the law's ``step`` (switching curves, Schmitt trigger
  with hysteresis, k1 = 4, k2 = 1, resolution floor, retarget at t_go = 750 s, cut-off at
  t_go = 60 s) <-> ``LOSSwitchingCurveGuidance.step``. Module priorities order the task as
  spacecraft (integrates [t - 1, t] with the force held since t - 1) -> GNC -> effector (reads
  the new command, held over [t, t + 1]), which is gnc_jax's step order.
- Dispersions: ``MonteCarlo.Dispersions.NormalVectorCartDispersion`` on ``hub.r_CN_NInit``
  (delivery) and on the GNC module's per-run draws (knowledge position along S, T, R and
  velocity, attitude bias, accelerometer bias); ``setShouldDisperseSeeds(True)`` gives the module
  its ``RNGSeed``, from which it draws the per-image and per-burn noise (numpy ``Generator``).
  The process-pool path draws the same distributions with numpy.
- The outcome: after the run the truth crosses the B-plane (the simulation stops at the nominal
  time of flight; the remaining sub-second gap is closed along a straight line, as
  ``coast_to_b_plane`` does) and the miss is measured from the final aim point.
- Framework floor: the same simulation without the GNC module (spacecraft, gravity, the
  effector with no command, integrator, scheduler; 1 s step to the same 7200 s), also measured
  with the default six-degree-of-freedom hub.

Not matched: the hub's mass is constant (``extForceTorque`` has no mass flow); gnc_jax burns
about 1 kg of 372 kg (0.3 % of the acceleration at the end of the burns, against the 2 % burn
magnitude error); ``fuel_kg`` is counted by the module. The random streams differ (numpy
``Generator`` per run against gnc_jax's per-run ``fold_in`` keys), so the outcomes agree in
distribution, not run for run. Only the Gaussian LOS front end (``navigation.measurement =
"noise"``) is transcribed.
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

try:
    from Basilisk.architecture import messaging, sysModel
    from Basilisk.simulation import extForceTorque, spacecraft
    from Basilisk.utilities import SimulationBaseClass, macros, simIncludeGravBody

    BASILISK_ERROR = None
except ImportError as err:  # reported by run(), never faked
    BASILISK_ERROR = f"{type(err).__name__}: {err}"

    class sysModel:  # noqa: N801 - stand-in so that the module still imports
        SysModel = object


G0 = 9.80665  # m/s^2, as gnc_jax.dynamics.impactor.G0
SCENARIO = "deep-impact-los"
REPO = Path(__file__).resolve().parents[2]


# ----------------------------------------------------------------------------------------------
# Scenario -> SI parameters (plain Python: the Basilisk worker process never imports JAX)
# ----------------------------------------------------------------------------------------------


def b_plane_frame(v_inf, ref_normal) -> np.ndarray:
    """Rows S, T, R of the B-plane frame (gnc_jax ``geometry.bplane.b_plane_frame``)."""
    s = np.asarray(v_inf, float) / np.linalg.norm(v_inf)
    t = np.cross(s, ref_normal)
    t = t / np.linalg.norm(t)
    return np.stack([s, t, np.cross(s, t)])


def scenario_params(cfg: dict) -> dict:
    """SI parameters of the study from a validated impactor scenario's ``config`` (the same
    derivations and roundings as gnc_jax's ``systems.impactor.build``)."""
    a, sc, dy, cam, nv, er, g = (
        cfg[k]
        for k in (
            "approach",
            "spacecraft",
            "dynamics",
            "camera",
            "navigation",
            "errors",
            "guidance",
        )
    )
    if dy["sun_distance_au"] > 0:
        raise ValueError("the Basilisk peer has no solar tide (sun_distance_au must be 0)")
    if nv["measurement"] != "noise":
        raise ValueError("the Basilisk peer transcribes only the Gaussian LOS front end")
    if g["law"] != "los":
        raise ValueError("the Basilisk peer transcribes only the LOS switching-curve law")
    r0 = [1e3 * x for x in a["position_km"]]
    v0 = [1e3 * x for x in a["velocity_kmps"]]
    c_bi = b_plane_frame(v0, a["reference_normal"])
    vv = sum(x * x for x in a["velocity_kmps"])
    tof = round(-sum(x * y for x, y in zip(a["position_km"], a["velocity_kmps"])) / vv, 6)
    t_cut = round(tof - g["cutoff_tgo_s"], 6)
    dt, image_dt = float(g["dt_s"]), float(cam["image_interval_s"])

    def aim(b_tr_km):
        return (1e3 * (b_tr_km[0] * c_bi[1] + b_tr_km[1] * c_bi[2])).tolist()

    return dict(
        r0_m=r0,
        v0_mps=v0,
        c_bi=c_bi.tolist(),
        aim_initial_m=aim(g["aim_initial_km"]),
        aim_final_m=aim(g["aim_final_km"]),
        aim_final_tr_m=[1e3 * x for x in g["aim_final_km"]],
        retarget_time_s=round(tof - g["retarget_tgo_s"], 6),
        cutoff_time_s=t_cut,
        tof_s=tof,
        dt_s=dt,
        image_interval_s=image_dt,
        n_images=int(math.ceil(t_cut / image_dt - 1e-9)),
        steps_per_image=int(round(image_dt / dt)),
        mass_kg=float(sc["mass_kg"]),
        thrust_n=float(sc["thrust_n"]),
        isp_s=float(sc["isp_s"]),
        mu_m3s2=float(dy["mu_target_m3s2"]),
        k1=float(g["los"]["k1"]),
        k2=float(g["los"]["k2"]),
        process_noise_m2s3=float(nv["process_noise_m2s3"]),
        consider_attitude_bias=bool(nv["consider_attitude_bias"]),
        delivery_position_m=1e3 * er["delivery_position_km"],
        knowledge_position_m=[1e3 * x for x in nv["knowledge_position_km"]],
        knowledge_velocity_mps=float(nv["knowledge_velocity_mps"]),
        image_processing_rad=1e-6 * er["image_processing_urad"],
        attitude_control_rad=1e-6 * er["attitude_control_urad"],
        attitude_bias_rad=1e-6 * er["attitude_bias_urad"],
        attitude_noise_rad=1e-6 * er["attitude_noise_urad"],
        accel_bias_mps2=1e-6 * G0 * er["accel_bias_ug"],
        accel_noise_mps2=1e-6 * G0 * er["accel_noise_ug"],
        burn_magnitude_frac=er["burn_magnitude_pct"] / 100.0,
    )


# ----------------------------------------------------------------------------------------------
# numpy transcription of the geometry, the camera, the EKF and the LOS law
# ----------------------------------------------------------------------------------------------


def b_plane_crossing(r, v, c_bi):
    """Straight-line B-plane crossing (B_T, B_R) in m and the time to it (``b_plane_crossing``)."""
    s = c_bi[0]
    t_tof = -np.dot(r, s) / np.dot(v, s)
    return c_bi[1:] @ (r + v * t_tof), t_tof


def cross_matrix(a) -> np.ndarray:
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def camera_attitude(boresight, up_hint) -> np.ndarray:
    """C_cI with z_c along ``boresight`` and x_c along up_hint x z_c (``camera_attitude``)."""
    z = boresight / np.linalg.norm(boresight)
    x = np.cross(up_hint, z)
    x = x / np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z])


def small_rotation(theta) -> np.ndarray:
    """Rotation matrix of the rotation vector ``theta``, Rodrigues' formula (``small_rotation``)."""
    angle = math.sqrt(float(np.dot(theta, theta)) + 1e-300)
    kx = cross_matrix(theta / angle)
    return np.eye(3) + math.sin(angle) * kx + (1.0 - math.cos(angle)) * kx @ kx


def los_angles(c_ci, los) -> np.ndarray:
    """Tangent-plane angles of a target seen along ``los`` through ``c_ci`` (``los_angles``)."""
    xc = c_ci @ los
    return xc[:2] / xc[2]


def perturb_direction(u, angles) -> np.ndarray:
    """``u`` tilted by two small angles about two axes perpendicular to it
    (``dynamics.impactor.perturb_direction``)."""
    axis = np.eye(3)[np.argmin(np.abs(u))]
    e1 = np.cross(u, axis)
    e1 = e1 / np.linalg.norm(e1)
    e2 = np.cross(u, e1)
    tilted = u + angles[0] * e1 + angles[1] * e2
    return tilted / np.linalg.norm(tilted)


def attitude_bias_covariance(r, v, sigma_bias_rad) -> np.ndarray:
    """Relative-state covariance of a constant attitude bias (``attitude_bias_covariance``)."""
    g = -np.concatenate([cross_matrix(r), cross_matrix(v)])
    return sigma_bias_rad**2 * g @ g.T


def initial_covariance(p) -> np.ndarray:
    """P0 of the filter (``initial_conditions``): knowledge along S, T, R and per velocity
    axis, plus the considered attitude bias."""
    c_bi = np.asarray(p["c_bi"])
    p0 = np.zeros((6, 6))
    p0[:3, :3] = c_bi.T @ np.diag(np.square(p["knowledge_position_m"])) @ c_bi
    p0[3:, 3:] = p["knowledge_velocity_mps"] ** 2 * np.eye(3)
    if p["consider_attitude_bias"]:
        p0 += attitude_bias_covariance(p["r0_m"], p["v0_mps"], p["attitude_bias_rad"])
    return p0


def propagate_covariance(cov, dt, q_accel, q_dv) -> np.ndarray:
    """P <- Phi P Phi^T + Q for straight-line motion (``ekf.propagate_covariance``)."""
    phi = np.eye(6)
    phi[:3, 3:] = dt * np.eye(3)
    q = np.zeros((6, 6))
    q[:3, :3] = q_accel * dt**3 / 3 * np.eye(3)
    q[:3, 3:] = q[3:, :3] = q_accel * dt**2 / 2 * np.eye(3)
    q[3:, 3:] = (q_accel * dt + q_dv) * np.eye(3)
    return phi @ cov @ phi.T + q


def ekf_update_los(x, cov, z, c_est, sigma_rad):
    """Joseph-form EKF update with the tangent-plane angles ``z`` seen through the believed
    attitude ``c_est`` (``ekf.update_los``: ``predict_measurement`` + ``ekf_update``).

    h(x) = (xc_0, xc_1) / xc_2 with xc = C (-r); its Jacobian in r is -(C_i - h_i C_2) / xc_2.
    """
    xc = c_est @ -x[:3]
    h = xc[:2] / xc[2]
    hj = np.zeros((2, 6))
    hj[:, :3] = -(c_est[:2] - np.outer(h, c_est[2])) / xc[2]
    r_cov = sigma_rad**2 * np.eye(2)
    s = hj @ cov @ hj.T + r_cov + 1e-200 * np.eye(2)
    k = np.linalg.solve(s, hj @ cov).T
    x = x + k @ (z - h)
    ikh = np.eye(6) - k @ hj
    cov = ikh @ cov @ ikh.T + k @ r_cov @ k.T
    return x, 0.5 * (cov + cov.T)


def take_image(x, cov, r_true, attitude_bias, w, p, up):
    """One image and its EKF update (``systems.impactor.navigation.take_image`` with the Gaussian
    front end); ``w`` = 8 standard normals: 2 centroid, 3 attitude control, 3 knowledge."""
    c_cmd = camera_attitude(-x[:3], up)
    c_true = small_rotation(p["attitude_control_rad"] * w[2:5]) @ c_cmd
    c_est = small_rotation(attitude_bias + p["attitude_noise_rad"] * w[5:8]) @ c_true
    z = los_angles(c_true, -np.asarray(r_true)) + p["image_processing_rad"] * w[:2]
    sigma = math.hypot(p["image_processing_rad"], p["attitude_noise_rad"])
    return ekf_update_los(x, cov, z, c_est, sigma)


class LOSSwitchingCurveLaw:
    """The seed 000 LOS switching-curve law (``guidance/los.py``), hard Schmitt trigger."""

    def __init__(self, p):
        self.k1, self.k2 = p["k1"], p["k2"]
        self.c_bi = np.asarray(p["c_bi"])
        self.aim_initial = np.asarray(p["aim_initial_m"])
        self.aim_final = np.asarray(p["aim_final_m"])
        self.retarget_time_s = p["retarget_time_s"]
        self.cutoff_time_s = p["cutoff_time_s"]
        # miss_limits: one control step's burn moves the miss by about (F/m) dt t_go
        self.resolution_per_tgo = 0.5 * p["thrust_n"] / p["mass_kg"] * p["dt_s"]

    def aim_point(self, t):
        return self.aim_final if t >= self.retarget_time_s else self.aim_initial

    def plan(self, x, cov, t) -> float:
        """sigma_B = sqrt(E^2 + F^2) of the navigation covariance mapped to impact (eqs. 8-11)."""
        rho = self.aim_point(t) - x[:3]
        t_go = np.linalg.norm(rho) / np.linalg.norm(x[3:])
        prr = cov[:3, :3] + t_go * (cov[:3, 3:] + cov[3:, :3]) + t_go**2 * cov[3:, 3:]
        tr = self.c_bi[1:]
        return math.sqrt(np.trace(tr @ prr @ tr.T))

    @staticmethod
    def switching_curve(rho, rdot, rho_limit) -> float:
        """omega = -rho_limit rho_dot / sqrt(rho^4 - rho_limit^2 rho^2) (seed 000 eq. 20)."""
        arg = rho**4 - rho_limit**2 * rho**2
        return -rho_limit * rdot / math.sqrt(arg) if arg > 0.0 else math.inf

    def step(self, engine_on, sigma_b, x, t):
        """Engine state (0/1) and the quantities of the trigger: (on, omega, w_open, w_close)."""
        ax, ay, az = self.aim_point(t).tolist()
        rx, ry, rz, vx, vy, vz = x.tolist()
        rho = (ax - rx, ay - ry, az - rz)  # impactor -> aim point; rho_dot = -v
        rr = rho[0] ** 2 + rho[1] ** 2 + rho[2] ** 2
        rho_n = math.sqrt(rr)
        rdot = -(rho[0] * vx + rho[1] * vy + rho[2] * vz) / rho_n
        # |rho x rho_dot| / rho^2 with rho_dot = -v
        cx = rho[1] * vz - rho[2] * vy
        cy = rho[2] * vx - rho[0] * vz
        cz = rho[0] * vy - rho[1] * vx
        omega = math.sqrt(cx * cx + cy * cy + cz * cz) / rr
        t_go = rho_n / math.sqrt(vx * vx + vy * vy + vz * vz)
        sigma = max(sigma_b, self.resolution_per_tgo * t_go / self.k2)  # the band kept k1/k2
        rho_close, rho_open = self.k2 * sigma, self.k1 * sigma
        w_open = self.switching_curve(rho_n, rdot, rho_open)
        w_close = self.switching_curve(rho_n, rdot, rho_close)
        on = 1.0 if omega >= w_open else (0.0 if omega <= w_close else engine_on)
        if t >= self.cutoff_time_s:
            on = 0.0
        return on, omega, w_open, w_close

    def direction(self, x, t) -> np.ndarray:
        """Thrust direction: the zero-effort-miss vector's unit (eq. 19 with the sign that
        reduces |omega|), the B-plane T axis when it vanishes."""
        rho = self.aim_point(t) - x[:3]
        u = x[3:] / np.linalg.norm(x[3:])
        zem = rho - np.dot(rho, u) * u
        n2 = np.dot(zem, zem)
        return zem / math.sqrt(n2) if n2 > 1e-30 else self.c_bi[1].copy()


# ----------------------------------------------------------------------------------------------
# The Basilisk Python module: navigation + guidance + sensor/actuator errors
# ----------------------------------------------------------------------------------------------


class ImpactorLOSGNC(sysModel.SysModel):
    """Camera + accelerometer + EKF + LOS law + engine errors as one Basilisk Python module.

    In: ``scStateInMsg`` (``SCStatesMsg``, truth position for the camera). Out:
    ``cmdForceOutMsg`` (``CmdForceInertialMsg``, the engine's force held over the next step).
    Per-run draws (dispersed by the Monte Carlo controller): ``knowledgePosition_STR`` (m, along
    S, T, R), ``knowledgeVelocity`` (m/s), ``attitudeBias`` (rad), ``accelBias`` (m/s^2);
    ``RNGSeed`` seeds the per-image and per-burn noise.
    """

    def __init__(self, params: dict):
        super().__init__()
        self.ModelTag = "losGNC"
        self.scStateInMsg = messaging.SCStatesMsgReader()
        self.cmdForceOutMsg = messaging.CmdForceInertialMsg()
        self.cmdPayload = messaging.CmdForceInertialMsgPayload()
        self.params = params
        self.law = LOSSwitchingCurveLaw(params)
        self.knowledgePosition_STR = [0.0, 0.0, 0.0]
        self.knowledgeVelocity = [0.0, 0.0, 0.0]
        self.attitudeBias = [0.0, 0.0, 0.0]
        self.accelBias = [0.0, 0.0, 0.0]

    def Reset(self, CurrentSimNanos):
        p = self.params
        self.rng = np.random.default_rng(self.RNGSeed)
        self.dt = p["dt_s"]
        self.spi = p["steps_per_image"]
        self.n_steps = p["n_images"] * self.spi
        self.up = np.asarray(p["c_bi"])[2]
        self.attitude_bias = np.asarray(self.attitudeBias, float)
        self.accel_bias = np.asarray(self.accelBias, float)
        self.x = None
        self.cov = None
        self.sigma_b = 0.0
        self.engine_on = 0.0
        self.force = np.zeros(3)
        self.execution_error = np.zeros(3)
        self.dv_mps = 0.0
        self.firings = 0
        self.burn_time_s = 0.0
        self.burn_time_image_s = 0.0
        self.cmdPayload.forceRequestInertial = [0.0, 0.0, 0.0]
        self.cmdForceOutMsg.write(self.cmdPayload, CurrentSimNanos, self.moduleID)

    def _initialise(self):
        """Initial estimate = truth + knowledge error (``initial_conditions``)."""
        p = self.params
        state = self.scStateInMsg()
        c_bi = np.asarray(p["c_bi"])
        self.x = np.concatenate(
            [
                np.asarray(state.r_BN_N) + c_bi.T @ np.asarray(self.knowledgePosition_STR),
                np.asarray(state.v_BN_N) + np.asarray(self.knowledgeVelocity),
            ]
        )
        self.cov = initial_covariance(p)

    def _predict(self):
        """EKF mean over the last step with the accelerometer's Δv (``propagate_state``)."""
        dt, x = self.dt, self.x
        if self.engine_on > 0.0:
            dv_true = self.force * (dt / self.params["mass_kg"])  # what the hub received
            noise = self.params["accel_noise_mps2"] * self.rng.standard_normal(3)
            dv_meas = dv_true + self.engine_on * (self.accel_bias + noise) * dt
            self.dv_mps += float(np.linalg.norm(dv_true))
            x[:3] += x[3:] * dt + 0.5 * dv_meas * dt
            x[3:] += dv_meas
        else:
            x[:3] += x[3:] * dt

    def _propagate_covariance(self):
        p, tb = self.params, self.burn_time_image_s
        q_dv = p["accel_noise_mps2"] ** 2 * self.dt * tb + p["accel_bias_mps2"] ** 2 * tb**2
        self.cov = propagate_covariance(
            self.cov, p["image_interval_s"], p["process_noise_m2s3"], q_dv
        )
        self.burn_time_image_s = 0.0

    def UpdateState(self, CurrentSimNanos):
        k = int(round(CurrentSimNanos * 1e-9 / self.dt))  # control step index
        if k > self.n_steps:
            return  # after the cut-off the command stays zero
        t = k * self.dt
        if k == 0:
            self._initialise()
        else:
            self._predict()
            if k % self.spi == 0:
                self._propagate_covariance()
        if k == self.n_steps:  # guidance cut-off: the truth coasts from here
            self.engine_on = 0.0
            self.force = np.zeros(3)
            self.cmdPayload.forceRequestInertial = [0.0, 0.0, 0.0]
            self.cmdForceOutMsg.write(self.cmdPayload, CurrentSimNanos, self.moduleID)
            return
        if k % self.spi == 0:
            r_true = self.scStateInMsg().r_BN_N
            w = self.rng.standard_normal(8)
            self.x, self.cov = take_image(
                self.x, self.cov, r_true, self.attitude_bias, w, self.params, self.up
            )
            self.sigma_b = self.law.plan(self.x, self.cov, t)

        on = self.law.step(self.engine_on, self.sigma_b, self.x, t)[0]
        if on > 0.0:
            p = self.params
            if self.engine_on <= 0.0:  # ignition: fresh magnitude and pointing errors
                e = self.rng.standard_normal(3)
                self.execution_error = np.array(
                    [
                        p["burn_magnitude_frac"] * e[0],
                        p["attitude_control_rad"] * e[1],
                        p["attitude_control_rad"] * e[2],
                    ]
                )
                self.firings += 1
            d = perturb_direction(self.law.direction(self.x, t), self.execution_error[1:])
            self.force = on * p["thrust_n"] * (1.0 + self.execution_error[0]) * d
            self.burn_time_s += on * self.dt
            self.burn_time_image_s += on * self.dt
        elif self.engine_on > 0.0:
            self.force = np.zeros(3)
        self.engine_on = on
        self.cmdPayload.forceRequestInertial = self.force.tolist()
        self.cmdForceOutMsg.write(self.cmdPayload, CurrentSimNanos, self.moduleID)


# ----------------------------------------------------------------------------------------------
# Simulation: creation, execution, outcome (the Monte Carlo controller's three functions)
# ----------------------------------------------------------------------------------------------


def create_simulation(params: dict, gnc: bool = True, point_mass: bool = True):
    """A Basilisk simulation of one approach (nominal initial state; dispersions are applied
    to ``sim.scObject.hub.r_CN_NInit`` and ``sim.gnc.*`` afterwards)."""
    p = params
    sim = SimulationBaseClass.SimBaseClass()
    process = sim.CreateNewProcess("dynamicsProcess")
    process.addTask(sim.CreateNewTask("impactorTask", macros.sec2nano(p["dt_s"])))

    sc = spacecraft.Spacecraft()
    sc.ModelTag = "impactor"
    sc.hub.mHub = p["mass_kg"]
    sc.hub.IHubPntBc_B = [[200.0, 0.0, 0.0], [0.0, 200.0, 0.0], [0.0, 0.0, 200.0]]
    sc.hub.r_CN_NInit = list(p["r0_m"])
    sc.hub.v_CN_NInit = list(p["v0_mps"])
    sc.pointMassTranslationalOnly = point_mass

    grav = simIncludeGravBody.gravBodyFactory()
    body = grav.createCustomGravObject("smallBody", p["mu_m3s2"])
    body.isCentralBody = True
    grav.addBodiesTo(sc)

    engine = extForceTorque.ExtForceTorque()
    engine.ModelTag = "engine"
    sc.addDynamicEffector(engine)

    # Priorities: spacecraft (integrate to t) -> GNC (command for [t, t + dt]) -> effector.
    sim.AddModelToTask("impactorTask", sc, 300)
    sim.gnc = None
    if gnc:
        sim.gnc = ImpactorLOSGNC(p)
        sim.gnc.scStateInMsg.subscribeTo(sc.scStateOutMsg)
        engine.cmdForceInertialInMsg.subscribeTo(sim.gnc.cmdForceOutMsg)
        sim.AddModelToTask("impactorTask", sim.gnc, 200)
    sim.AddModelToTask("impactorTask", engine, 100)
    sim.scObject, sim.engine, sim.gravFactory, sim.params = sc, engine, grav, p
    return sim


def stop_time_s(params) -> float:
    """The simulation runs to the nominal time of flight (whole control steps)."""
    return math.ceil(params["tof_s"] / params["dt_s"] - 1e-9) * params["dt_s"]


def execute(sim) -> None:
    sim.InitializeSimulation()
    sim.ConfigureStopTime(macros.sec2nano(stop_time_s(sim.params)))
    sim.ExecuteSimulation()


def outcome(sim) -> dict:
    """Miss and burn statistics of a finished run (also the Monte Carlo retention function)."""
    p = sim.params
    state = sim.scObject.scStateOutMsg.read()
    b, _ = b_plane_crossing(
        np.asarray(state.r_BN_N), np.asarray(state.v_BN_N), np.asarray(p["c_bi"])
    )
    miss = b - np.asarray(p["aim_final_tr_m"])
    out = dict(b_t_m=float(b[0]), b_r_m=float(b[1]), miss_m=float(np.linalg.norm(miss)))
    g = sim.gnc
    if g is not None:
        flow = p["thrust_n"] / (p["isp_s"] * G0)
        out.update(
            dv_mps=g.dv_mps,
            firings=g.firings,
            burn_time_s=g.burn_time_s,
            fuel_kg=flow * g.burn_time_s,
        )
    return out


def execute_and_save(sim, filename) -> None:
    """Execution function that writes the run's outcome next to the controller's archive
    (``<archive>/run<i>.outcome.json``), for a controller without a retention policy."""
    execute(sim)
    with open(filename + ".outcome.json", "w") as f:
        json.dump(outcome(sim), f)


def disperse(sim, rng: np.random.Generator) -> None:
    """The per-run draws of the process-pool path (the controller's dispersions, in numpy)."""
    p = sim.params
    r0 = np.asarray(p["r0_m"]) + p["delivery_position_m"] * rng.standard_normal(3)
    sim.scObject.hub.r_CN_NInit = r0.tolist()
    g = sim.gnc
    if g is not None:
        g.knowledgePosition_STR = (
            np.asarray(p["knowledge_position_m"]) * rng.standard_normal(3)
        ).tolist()
        g.knowledgeVelocity = (p["knowledge_velocity_mps"] * rng.standard_normal(3)).tolist()
        g.attitudeBias = (p["attitude_bias_rad"] * rng.standard_normal(3)).tolist()
        g.accelBias = (p["accel_bias_mps2"] * rng.standard_normal(3)).tolist()
        g.RNGSeed = int(rng.integers(2**32))


def run_one(args) -> dict:
    """One dispersed run (process-pool worker): ``(params, seed, index, gnc, point_mass)``."""
    params, seed, index, gnc, point_mass = args
    sim = create_simulation(params, gnc, point_mass)
    disperse(sim, np.random.default_rng([seed, index]))
    execute(sim)
    return outcome(sim)


def _ready(_):
    return os.getpid()


def run_pool(params, runs, seed=0, gnc=True, point_mass=True, workers=2):
    """``runs`` dispersed runs on a warmed ``ProcessPoolExecutor(workers)``: (outcomes, wall_s)."""
    import multiprocessing as mp

    with ProcessPoolExecutor(workers, mp_context=mp.get_context("fork")) as pool:
        list(pool.map(_ready, range(workers)))
        t0 = time.perf_counter()
        out = list(pool.map(run_one, [(params, seed, i, gnc, point_mass) for i in range(runs)]))
        return out, time.perf_counter() - t0


def run_monte_carlo(params, runs, gnc=True, point_mass=True, retention=True, threads=2):
    """``runs`` runs through Basilisk's ``MonteCarlo.Controller`` on ``threads`` processes.

    With ``retention`` the outcome is retained the documented way (``RetentionPolicy`` with a
    retention function; note that the controller then sleeps 1 s in each worker after queueing
    a run's data); without it the execution function writes the outcome itself.
    Returns (outcomes, wall_s, failed).
    """
    from Basilisk.utilities.MonteCarlo.Controller import Controller
    from Basilisk.utilities.MonteCarlo.Dispersions import NormalVectorCartDispersion
    from Basilisk.utilities.MonteCarlo.RetentionPolicy import RetentionPolicy

    p = params
    with tempfile.TemporaryDirectory(prefix="bsk_mc_") as archive:
        mc = Controller()
        mc.setSimulationFunction(functools.partial(create_simulation, p, gnc, point_mass))
        mc.setExecutionFunction(execute if retention else execute_and_save)
        mc.setExecutionCount(runs)
        mc.setThreadCount(threads)
        mc.setArchiveDir(archive)
        mc.setShouldDisperseSeeds(gnc)
        mc.setVerbose(False)
        d = p["delivery_position_m"]
        mc.addDispersion(
            NormalVectorCartDispersion("scObject.hub.r_CN_NInit", list(p["r0_m"]), [d, d, d])
        )
        if gnc:
            zero = [0.0, 0.0, 0.0]
            for name, sigma in (
                ("knowledgePosition_STR", list(p["knowledge_position_m"])),
                ("knowledgeVelocity", [p["knowledge_velocity_mps"]] * 3),
                ("attitudeBias", [p["attitude_bias_rad"]] * 3),
                ("accelBias", [p["accel_bias_mps2"]] * 3),
            ):
                mc.addDispersion(NormalVectorCartDispersion("gnc." + name, zero, sigma))
        if retention:
            policy = RetentionPolicy()
            policy.addRetentionFunction(outcome)
            mc.addRetentionPolicy(policy)
        with open(os.devnull, "w") as devnull, contextlib.redirect_stdout(devnull):
            t0 = time.perf_counter()
            failed = mc.executeSimulations()
            wall = time.perf_counter() - t0
        outs = []
        for i in range(runs):
            if i in failed:
                continue
            if retention:
                outs.append(dict(mc.getRetainedData(i)["custom"]))
            else:
                with open(os.path.join(archive, f"run{i}.outcome.json")) as f:
                    outs.append(json.load(f))
        return outs, wall, list(failed)


# ----------------------------------------------------------------------------------------------
# Measurement
# ----------------------------------------------------------------------------------------------


def statistics(outs) -> dict:
    miss = np.array([o["miss_m"] for o in outs])
    st = dict(miss_rms_m=float(np.sqrt(np.mean(miss**2))), miss_max_m=float(np.max(miss)))
    if outs and "dv_mps" in outs[0]:
        dv = np.array([o["dv_mps"] for o in outs])
        fir = np.array([o["firings"] for o in outs])
        st.update(
            dv_mean_mps=float(np.mean(dv)),
            dv_max_mps=float(np.max(dv)),
            firings_mean=float(np.mean(fir)),
            firings_max=int(np.max(fir)),
        )
    return st


#: (row name, path, with the GNC module, point-mass hub, in quick mode)
CASES = (
    ("bsk GNC, process pool", "pool", True, True, True),
    ("bsk GNC, MC controller (retention policy)", "mc", True, True, False),
    ("bsk GNC, MC controller (execution fn saves)", "mc-exec", True, True, True),
    ("bsk floor, process pool", "pool", False, True, True),
    ("bsk floor, MC controller (execution fn saves)", "mc-exec", False, True, True),
    ("bsk floor 6-DOF hub, process pool", "pool", False, False, False),
)


def measure_basilisk(params, runs, floor_runs, repeats=1, quick=False) -> list[dict]:
    """All Basilisk rows (run in a process without JAX: the controller forks its workers)."""
    rows = []
    for name, how, gnc, point_mass, in_quick in CASES:
        if quick and not in_quick:
            continue
        n = runs if gnc else floor_runs
        best, outs, failed = math.inf, None, []
        for _ in range(repeats):
            if how == "pool":
                outs, wall = run_pool(params, n, gnc=gnc, point_mass=point_mass)
            else:
                outs, wall, failed = run_monte_carlo(
                    params, n, gnc, point_mass, retention=how == "mc"
                )
            best = min(best, wall)
        row = dict(
            name=name,
            kind="closed loop" if gnc else "floor",
            runs=n,
            workers=2,
            wall_s=round(best, 3),
            per_s=round(n / best, 2),
        )
        row.update(failed=len(failed), **statistics(outs))
        row["_samples"] = {k: [o[k] for o in outs] for k in ("miss_m", "dv_mps") if k in outs[0]}
        rows.append(row)
    return rows


def _measure_in_subprocess(params, runs, floor_runs, repeats, quick) -> list[dict]:
    """Run :func:`measure_basilisk` in a fresh interpreter (no JAX threads to fork)."""
    with tempfile.TemporaryDirectory(prefix="bsk_peer_") as tmp:
        src, dst = os.path.join(tmp, "in.json"), os.path.join(tmp, "out.json")
        with open(src, "w") as f:
            job = dict(
                params=params, runs=runs, floor_runs=floor_runs, repeats=repeats, quick=quick
            )
            json.dump(job, f)
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join([str(REPO)] + [x for x in [env.get("PYTHONPATH")] if x])
        cmd = [sys.executable, "-m", "benchmarks.peers.basilisk_impactor", "--worker", src, dst]
        proc = subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True)
        if proc.returncode != 0:
            raise RuntimeError(
                f"Basilisk worker failed ({proc.returncode}):\n{proc.stderr[-3000:]}"
            )
        with open(dst) as f:
            return json.load(f)


def _gnc_jax_rows(scenario, runs, big_runs, repeats) -> list[dict]:
    import gnc_jax as gj

    rows = []
    for n in dict.fromkeys([runs, big_runs]):
        first = gj.run_study(scenario, runs=n, seed=0, progress=False)
        walls = [first.wall_s] + [
            gj.run_study(scenario, runs=n, seed=0, progress=False).wall_s for _ in range(repeats)
        ]
        out = first.outcomes
        ok = out["status"] == gj.Status.ok
        outs = [
            dict(miss_m=m, dv_mps=d, firings=int(f))
            for m, d, f in zip(out["miss_m"][ok], out["dv_mps"][ok], out["firings"][ok])
        ]
        best = min(walls[1:]) if repeats else walls[0]  # the first call may warm caches
        row = dict(
            name=f"gnc_jax run_study ({first.n_devices} XLA devices)",
            kind="gnc_jax",
            runs=n,
            workers=first.n_devices,
            compile_s=round(first.compile_s, 2),
            wall_s=round(best, 4),
            per_s=round(n / best, 1),
            failed=int(np.sum(~ok)),
        )
        row.update(statistics(outs))
        row["_samples"] = dict(miss_m=out["miss_m"][ok].tolist(), dv_mps=out["dv_mps"][ok].tolist())
        rows.append(row)
    return rows


def _same_distribution(rows, ref) -> None:
    """Two-sample Kolmogorov-Smirnov p-values of each closed-loop row's miss and Δv against
    gnc_jax's reference sample (``ks_p_miss``, ``ks_p_dv``); drops the per-run samples."""
    try:
        from scipy.stats import ks_2samp
    except ImportError:  # scipy is a test dependency, not a bench one
        ks_2samp = None
    reference = ref["_samples"]
    for r in rows:
        samples = r.pop("_samples", {})
        if ks_2samp is None or r is ref or "dv_mps" not in samples:
            continue
        for k, col in (("miss_m", "ks_p_miss"), ("dv_mps", "ks_p_dv")):
            r[col] = round(float(ks_2samp(samples[k], reference[k]).pvalue), 3)


def _fmt(x):
    if isinstance(x, float):
        return f"{x:,.3g}" if abs(x) < 1e4 else f"{x:,.0f}"
    return str(x)


def run(
    quick: bool = False,
    runs: int | None = None,
    repeats: int | None = None,
    bsk_repeats: int = 1,
) -> dict:
    """Throughput and miss statistics of the Basilisk peer beside gnc_jax (suite interface).

    ``runs`` closed-loop runs per Basilisk row (8 quick, 100 full; the floor rows 4x as many
    in full), ``repeats`` timed gnc_jax calls per size, ``bsk_repeats`` passes per Basilisk row
    (best kept).
    """
    title = "Basilisk peer: deep-impact-los closed loop and framework floor (2 cores)"
    if BASILISK_ERROR is not None:
        note = f"Basilisk (package bsk) could not be imported: {BASILISK_ERROR}"
        return dict(title=title, rows=[], markdown=note, notes=[note])
    import gnc_jax as gj

    runs = runs or (8 if quick else 100)
    floor_runs = runs if quick else 4 * runs
    big_runs = 256 if quick else 2000
    repeats = repeats if repeats is not None else (2 if quick else 3)
    scenario = gj.load_scenario(SCENARIO)
    params = scenario_params(scenario.config)
    bsk_rows = _measure_in_subprocess(params, runs, floor_runs, bsk_repeats, quick)
    gj_rows = _gnc_jax_rows(scenario, runs, big_runs, repeats)
    ref = max(gj_rows, key=lambda r: r["runs"])
    rows = gj_rows + bsk_rows
    for r in rows:
        r["ratio_gnc_jax"] = round(ref["per_s"] / r["per_s"], 1)
    _same_distribution(rows, ref)
    best = {
        kind: max((r for r in bsk_rows if r["kind"] == kind), key=lambda r: r["per_s"])
        for kind in ("closed loop", "floor")
    }
    cols = [
        ("name", "study"),
        ("runs", "runs"),
        ("compile_s", "compile (s)"),
        ("wall_s", "wall (s)"),
        ("per_s", "traj/s"),
        ("ratio_gnc_jax", f"gnc_jax@{ref['runs']} / this"),
        ("miss_rms_m", "miss RMS (m)"),
        ("miss_max_m", "miss max (m)"),
        ("dv_mean_mps", "mean Δv (m/s)"),
        ("firings_mean", "firings mean"),
        ("firings_max", "firings max"),
        ("ks_p_miss", "KS p miss"),
        ("ks_p_dv", "KS p Δv"),
    ]
    lines = ["| " + " | ".join(c[1] for c in cols) + " |", "|" + "---|" * len(cols)]
    for r in rows:
        lines.append("| " + " | ".join(_fmt(r.get(k, "")) for k, _ in cols) + " |")
    import platform

    notes = [
        f"gnc_jax ({ref['runs']} runs, {ref['per_s']:.0f} traj/s) / Basilisk closed loop with "
        f"the Python GNC module (fastest path, {best['closed loop']['name']}): "
        f"{best['closed loop']['ratio_gnc_jax']:.0f}x (target >= 300x); / Basilisk "
        f"framework floor ({best['floor']['name']}): {best['floor']['ratio_gnc_jax']:.0f}x "
        "(target >= 60x)",
        _per_step_note(best, params),
        f"machine: {platform.machine()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}, bsk {_bsk_version()}; every row uses both cores "
        "(2 worker processes / 2 XLA devices)",
        f"Basilisk rows: best of {bsk_repeats} pass(es), in a separate interpreter without "
        "JAX (the controller forks); wall time includes each run's simulation build, "
        "dispersion and outcome, pool workers warmed first; gnc_jax: best of repeated "
        "run_study calls after compilation",
        "same study and error sources in distribution, not run for run (different random "
        "streams): statistics of a few runs differ by sampling; 'KS p' = two-sample "
        f"Kolmogorov-Smirnov p-value of the row's miss / Δv against gnc_jax's {ref['runs']} runs",
        "the MC controller with a RetentionPolicy sleeps 1 s per run in its workers (Basilisk's "
        "Controller: time.sleep(1) after queueing retained data) and starts a new process pool "
        "for every batch of 2 runs; the 'execution fn saves' rows avoid the sleep",
        "Basilisk hub mass constant (extForceTorque has no mass flow): ~0.3 % of the "
        "acceleration by the end of the burns; mapping in the module docstring",
    ]
    return dict(title=title, rows=rows, markdown="\n".join(lines), notes=notes)


def _per_step_note(best, params) -> str:
    """Where a Basilisk run's time goes: core time per run of the floor and of the closed
    loop (both cores busy), and what the Python module adds per 1 s control step."""
    steps = stop_time_s(params) / params["dt_s"]
    floor_s = 2.0 / best["floor"]["per_s"]
    loop_s = 2.0 / best["closed loop"]["per_s"]
    return (
        f"per run and core: framework floor {floor_s:.3f} s ({1e6 * floor_s / steps:.1f} us per "
        f"1 s step: build, scheduler, spacecraft, gravity, RK4), closed loop {loop_s:.3f} s; the "
        f"Python GNC module adds {1e6 * (loop_s - floor_s) / steps:.0f} us per step"
    )


def _bsk_version() -> str:
    try:
        from importlib.metadata import version

        return version("bsk")
    except Exception:  # noqa: BLE001
        return "?"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small sizes (~1 min)")
    ap.add_argument("--runs", type=int, default=None, help="closed-loop runs per Basilisk row")
    ap.add_argument("--repeats", type=int, default=None, help="timed gnc_jax calls per size")
    ap.add_argument("--bsk-repeats", type=int, default=1, help="passes per Basilisk row")
    ap.add_argument("--worker", nargs=2, metavar=("IN", "OUT"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        with open(args.worker[0]) as f:
            job = json.load(f)
        rows = measure_basilisk(
            job["params"], job["runs"], job["floor_runs"], job["repeats"], job["quick"]
        )
        with open(args.worker[1], "w") as f:
            json.dump(rows, f)
        return
    res = run(args.quick, args.runs, args.repeats, args.bsk_repeats)
    print(f"## {res['title']}\n\n{res['markdown']}\n")
    for n in res["notes"]:
        print(f"- {n}")


if __name__ == "__main__":
    main()
