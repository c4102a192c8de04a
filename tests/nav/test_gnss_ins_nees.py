#!/usr/bin/python3
"""Issue 28 acceptance 4: do the device's IMU, GNSS and barometer err together
as the scene says they do?

An independent loosely coupled GNSS/INS filter (an error-state extended Kalman
filter, 15 states: position, velocity, attitude, accelerometer bias, gyro bias,
ECEF mechanisation; Groves, "Principles of GNSS, Inertial and Multisensor
Integrated Navigation Systems", 2nd ed., ch. 5.2 and 14.2) is tuned ONLY from
the noise figures the scene states (the sensor's datasheet keys, the GNSS and
barometer error keys), converted with the project's noise convention
(docs/sensor-models.md: a density N gives sigma = N sqrt(fs) per sample;
1 deg/sqrt(h) = 1/60 deg/s/sqrt(Hz)). It runs on what `imuemu generate
--scene-file` writes for the device: the IMU samples, the HIL_GPS fixes
(--gnss-out) and the barometer readings (--baro-out), and on the smoothed
trajectory (--trajectory-out) as truth.

Criterion: the normalised estimation error squared of position, velocity and
attitude (9 degrees of freedom) after each GNSS update lies inside its two-sided
95 % chi-square band for at least 90 % of the epochs. A filter whose model
matches the data is consistent (Bar-Shalom, Li, Kirubarajan, "Estimation with
Applications to Tracking and Navigation", 5.4.2); errors larger or smaller than
stated, or correlated where the scene says white, push the NEES out of the band.

Usage: test_gnss_ins_nees.py IMUEMU SCENE [--gnss-sigma-scale S]
[--data-scene FILE] [--expect-fail]. --gnss-sigma-scale mis-tunes the
filter's GNSS noise (0.25: a quarter of the stated sigma); --data-scene
generates the data from another scene (errors other than the ones stated);
--expect-fail inverts the verdict (the negative control: the criterion must
reject a mis-tuned filter).
"""
import argparse
import math
import os
import subprocess
import sys
import tempfile
import time
import tomllib

import numpy as np

# WGS84 and Earth rotation (NIMA TR8350.2, Groves 2.3); J2 gravitation
# (Groves eq. 2.142).
A_WGS84 = 6378137.0
F_WGS84 = 1.0 / 298.257223563
E2_WGS84 = F_WGS84 * (2.0 - F_WGS84)
MU = 3.986004418e14
J2 = 1.082627e-3
OMEGA_IE = 7.292115e-5
OMEGA_IE_SKEW = np.array([[0.0, -OMEGA_IE, 0.0], [OMEGA_IE, 0.0, 0.0], [0.0, 0.0, 0.0]])

# US Standard Atmosphere 1976, troposphere (the barometer's inverse, written
# from the standard, not from core/aiding/atmosphere.cpp): T = T0 - L H,
# p = p0 (T / T0)^(g0 M0 / (R* L)), H geopotential; Z = r0 H / (r0 - H) the
# geometric height above mean sea level (US 1976 eq. 18 inverted).
ISA_T0_K = 288.15
ISA_P0_PA = 101325.0
ISA_LAPSE_K_M = 0.0065
ISA_G0 = 9.80665
ISA_R_STAR = 8.31432
ISA_M0 = 0.0289644
ISA_R0_M = 6356766.0
ISA_EXPONENT = ISA_G0 * ISA_M0 / (ISA_R_STAR * ISA_LAPSE_K_M)

# Two-sided 95 % band of a chi-square with k degrees of freedom, by the
# Wilson-Hilferty approximation (Wilson and Hilferty 1931: (X/k)^(1/3) is
# nearly normal with mean 1 - 2/(9k) and variance 2/(9k)):
#   q_p = k (1 - 2/(9k) + z_p sqrt(2/(9k)))^3, z_0.975 = 1.959964.
# k = 9: [2.675, 19.02] (tables: 2.700, 19.02).
Z_975 = 1.959963984540054


def chi2_band(k):
    a = 2.0 / (9.0 * k)
    return tuple(k * (1.0 - a + z * math.sqrt(a)) ** 3 for z in (-Z_975, Z_975))


def skew(v):
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def rodrigues(a):
    """exp([a x]) (Groves eq. 5.73 with the exact coefficients)."""
    n = math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
    s = skew(a)
    if n < 1e-9:
        return np.eye(3) + s + 0.5 * s @ s
    return np.eye(3) + (math.sin(n) / n) * s + ((1.0 - math.cos(n)) / (n * n)) * (s @ s)


def rotation_log(R):
    """The rotation vector of R (inverse of rodrigues)."""
    c = max(-1.0, min(1.0, 0.5 * (np.trace(R) - 1.0)))
    angle = math.acos(c)
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if angle < 1e-9:
        return 0.5 * w
    return w * (angle / (2.0 * math.sin(angle)))


def quat_to_matrix(q):
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def ecef_from_geodetic(lat, lon, h):
    n = A_WGS84 / math.sqrt(1.0 - E2_WGS84 * math.sin(lat) ** 2)
    return np.array([(n + h) * math.cos(lat) * math.cos(lon), (n + h) * math.cos(lat) * math.sin(lon),
                     (n * (1.0 - E2_WGS84) + h) * math.sin(lat)])


def geodetic_from_ecef(r):
    """Latitude, longitude, height by Bowring's iteration (Groves 2.4.2)."""
    x, y, z = r
    lon = math.atan2(y, x)
    p = math.hypot(x, y)
    lat = math.atan2(z, p * (1.0 - E2_WGS84))
    for _ in range(5):
        n = A_WGS84 / math.sqrt(1.0 - E2_WGS84 * math.sin(lat) ** 2)
        h = p / math.cos(lat) - n
        lat = math.atan2(z, p * (1.0 - E2_WGS84 * n / (n + h)))
    n = A_WGS84 / math.sqrt(1.0 - E2_WGS84 * math.sin(lat) ** 2)
    h = p / math.cos(lat) - n
    return lat, lon, h


def ned_to_ecef(lat, lon):
    """C_n^e (Groves eq. 2.150 transposed)."""
    sl, cl, so, co = math.sin(lat), math.cos(lat), math.sin(lon), math.cos(lon)
    return np.array([[-sl * co, -so, -cl * co], [-sl * so, co, -cl * so], [cl, 0.0, -sl]])


def gravity_ecef(r):
    """Gravity g = gravitation (J2, Groves eq. 2.142) + centrifugal (-Omega^2 r)."""
    x, y, z = r
    rn2 = x * x + y * y + z * z
    rn = math.sqrt(rn2)
    zr2 = z * z / rn2
    k = 1.5 * J2 * A_WGS84 * A_WGS84 / rn2
    gam = -MU / (rn2 * rn) * np.array([x * (1.0 + k * (1.0 - 5.0 * zr2)), y * (1.0 + k * (1.0 - 5.0 * zr2)),
                                        z * (1.0 + k * (3.0 - 5.0 * zr2))])
    return gam + OMEGA_IE * OMEGA_IE * np.array([x, y, 0.0])


def gravity_gradient(r):
    """d g / d r: point-mass gravitation gradient plus the centrifugal term."""
    rn = np.linalg.norm(r)
    u = r / rn
    return -MU / rn ** 3 * (np.eye(3) - 3.0 * np.outer(u, u)) - OMEGA_IE_SKEW @ OMEGA_IE_SKEW


def height_from_pressure(p_pa, geoid_m):
    """Ellipsoidal height of a static pressure (ISA troposphere) and dh/dp."""
    ratio = (p_pa / ISA_P0_PA) ** (1.0 / ISA_EXPONENT)
    H = ISA_T0_K / ISA_LAPSE_K_M * (1.0 - ratio)
    Z = ISA_R0_M * H / (ISA_R0_M - H)
    dH_dp = -ISA_T0_K / ISA_LAPSE_K_M * ratio / (ISA_EXPONENT * p_pa)
    dZ_dH = (ISA_R0_M / (ISA_R0_M - H)) ** 2
    return Z + geoid_m, dZ_dH * dH_dp


def read_csv(path):
    with open(path) as f:
        header = f.readline().strip().split(",")
    data = np.genfromtxt(path, delimiter=",", skip_header=1, filling_values=np.nan)
    return {name: data[:, i] for i, name in enumerate(header)}


# ---- the scene's stated figures -> the filter's tuning

def tuning_from_scene(path):
    """Every error term the scene gives the device, converted to SI; a term
    this filter does not model is refused (its tuning would be a guess)."""
    with open(path, "rb") as f:
        scene = tomllib.load(f)
    imu = scene["imu"][0]
    em = imu.get("error_model", {})
    allowed = {"seed", "gyro", "accel"}
    if em.get("preset", "ideal") != "ideal" or set(em) - allowed - {"preset"}:
        sys.exit(f"scene error model has terms this filter does not model: {sorted(set(em) - allowed)}")
    g, a = em.get("gyro", {}), em.get("accel", {})
    deg = math.pi / 180.0
    t = {}
    # White noise density N (IEEE 952): 1 deg/sqrt(h) = (1/60) deg/s/sqrt(Hz).
    if "arw_deg_rt_h" in g:
        t["gyro_n"] = g["arw_deg_rt_h"] * deg / 60.0
    else:
        t["gyro_n"] = g.get("noise_density_dps_rt_hz", 0.0) * deg
    if "vrw_m_s_rt_h" in a:
        t["accel_n"] = a["vrw_m_s_rt_h"] / 60.0
    else:
        t["accel_n"] = a.get("noise_density_ug_rt_hz", 0.0) * 1e-6 * 9.80665
    # First-order Gauss-Markov bias, stationary sigma and tau (1 ug = 1e-6 g0).
    t["gyro_gm"] = g.get("gauss_markov_sigma_deg_h", 0.0) * deg / 3600.0 + g.get("gauss_markov_sigma_dps", 0.0) * deg
    t["gyro_tau"] = g.get("gauss_markov_tau_s", 1e9)
    t["accel_gm"] = (a.get("gauss_markov_sigma_ug", 0.0) * 1e-6 + a.get("gauss_markov_sigma_mg", 0.0) * 1e-3) * 9.80665
    t["accel_tau"] = a.get("gauss_markov_tau_s", 1e9)
    known = {"arw_deg_rt_h", "noise_density_dps_rt_hz", "gauss_markov_sigma_deg_h", "gauss_markov_sigma_dps",
             "gauss_markov_tau_s", "vrw_m_s_rt_h", "noise_density_ug_rt_hz", "gauss_markov_sigma_ug",
             "gauss_markov_sigma_mg"}
    if (set(g) | set(a)) - known:
        sys.exit(f"scene IMU terms this filter does not model: {sorted((set(g) | set(a)) - known)}")
    mav = imu["mavlink"]
    for key in ("gps_horizontal_gm_sigma_m", "gps_vertical_gm_sigma_m", "baro_bias_pa"):
        if mav.get(key, 0.0) != 0.0:
            sys.exit(f"[imu.mavlink] {key}: not modelled by this 15-state filter")
    t["gnss_h"] = mav.get("gps_horizontal_white_m", 0.0)
    t["gnss_v"] = mav.get("gps_vertical_white_m", 0.0)
    t["gnss_vh"] = mav.get("gps_horizontal_velocity_m_s", 0.0)
    t["gnss_vv"] = mav.get("gps_vertical_velocity_m_s", 0.0)
    t["baro_pa"] = mav.get("baro_noise_rms_pa", 0.0)
    t["geoid_m"] = mav.get("geoid_undulation_m", 0.0)
    t["rate_hz"] = imu["rate_hz"]
    return t


# ---- the filter

class Ekf:
    """Error-state EKF, states (all true minus estimate): dr (0:3), dv (3:6),
    phi (6:9, C_true = (I + [phi x]) C_est), dba (9:12), dbg (12:15).
    Continuous error dynamics (derived as Groves eq. 14.48-14.50, ECEF):
      dr' = dv
      dv' = -[(C f) x] phi + G dr - 2 Omega_ie dv - C dba - C n_a
      phi' = -Omega_ie phi - C dbg - C n_g
      db' = -db / tau + w
    """

    def __init__(self, t, r, v, C, P0):
        self.t = t
        self.r, self.v, self.C = r.copy(), v.copy(), C.copy()
        self.ba = np.zeros(3)
        self.bg = np.zeros(3)
        self.P = P0.copy()

    def propagate_covariance(self, tun, dt, f_e):
        F = np.zeros((15, 15))
        F[0:3, 3:6] = np.eye(3)
        F[3:6, 0:3] = gravity_gradient(self.r)
        F[3:6, 3:6] = -2.0 * OMEGA_IE_SKEW
        F[3:6, 6:9] = -skew(f_e)
        F[3:6, 9:12] = -self.C
        F[6:9, 6:9] = -OMEGA_IE_SKEW
        F[6:9, 12:15] = -self.C
        F[9:12, 9:12] = -np.eye(3) / tun["accel_tau"]
        F[12:15, 12:15] = -np.eye(3) / tun["gyro_tau"]
        Fdt = F * dt
        Phi = np.eye(15) + Fdt + 0.5 * Fdt @ Fdt
        # Q: white noise densities N^2 dt (isotropic: the rotation by C
        # leaves it unchanged); Gauss-Markov drive sigma^2 (1 - e^(-2dt/tau)).
        q = np.zeros(15)
        q[3:6] = tun["accel_n"] ** 2 * dt
        q[6:9] = tun["gyro_n"] ** 2 * dt
        q[9:12] = tun["accel_gm"] ** 2 * (1.0 - math.exp(-2.0 * dt / tun["accel_tau"]))
        q[12:15] = tun["gyro_gm"] ** 2 * (1.0 - math.exp(-2.0 * dt / tun["gyro_tau"]))
        Qd = np.diag(q)
        # Trapezoidal Q (Groves eq. 3.46 approximation).
        self.P = Phi @ (self.P + 0.5 * Qd) @ Phi.T + 0.5 * Qd

    def update(self, z_minus_h, H, R):
        S = H @ self.P @ H.T + R
        K = np.linalg.solve(S, H @ self.P).T
        x = K @ z_minus_h
        IKH = np.eye(15) - K @ H
        self.P = IKH @ self.P @ IKH.T + K @ R @ K.T  # Joseph form
        self.r += x[0:3]
        self.v += x[3:6]
        self.C = rodrigues(x[6:9]) @ self.C
        self.ba += x[9:12]
        self.bg += x[12:15]


def run(imuemu, scene_path, gnss_scale, workdir, data_scene=None):
    tun = tuning_from_scene(scene_path)
    paths = {k: os.path.join(workdir, k + ".csv") for k in ("imu", "truth", "gnss", "baro")}
    subprocess.run([imuemu, "generate", "--scene-file", data_scene or scene_path, "--quiet", "--out", paths["imu"],
                    "--trajectory-out", paths["truth"], "--gnss-out", paths["gnss"], "--baro-out", paths["baro"]],
                   check=True)
    imu, truth, gnss, baro = (read_csv(paths[k]) for k in ("imu", "truth", "gnss", "baro"))
    t_imu = imu["time_ns"].astype(np.int64)
    gyro = np.column_stack([imu["gyro_x_rad_s"], imu["gyro_y_rad_s"], imu["gyro_z_rad_s"]])
    accel = np.column_stack([imu["accel_x_m_s2"], imu["accel_y_m_s2"], imu["accel_z_m_s2"]])
    # Truth on the IMU grid (the kinematics file has one row per sample).
    t_truth = np.rint(truth["time_s"] * 1e9).astype(np.int64)
    index_of = {int(t): i for i, t in enumerate(t_truth)}
    tr = lambda i: np.array([truth["x_m"][i], truth["y_m"][i], truth["z_m"][i]])
    tv = lambda i: np.array([truth["vx_m_s"][i], truth["vy_m_s"][i], truth["vz_m_s"][i]])
    tC = lambda i: quat_to_matrix((truth["qw_ecef"][i], truth["qx_ecef"][i], truth["qy_ecef"][i], truth["qz_ecef"][i]))
    gnss_at = {int(t): j for j, t in enumerate(gnss["time_ns"].astype(np.int64))}
    baro_at = {int(t): j for j, t in enumerate(baro["time_ns"].astype(np.int64))}

    # Initial estimate: the truth plus an error drawn from P0 (seeded), so the
    # first epochs are consistent too. P0: the GNSS's stated position and
    # velocity sigmas, 0.5 deg level / 2 deg heading (a coarse alignment),
    # the stationary bias sigmas.
    i0 = index_of[int(t_imu[0])]
    lat, lon, _ = geodetic_from_ecef(tr(i0))
    Cne = ned_to_ecef(lat, lon)
    deg = math.pi / 180.0
    P0 = np.zeros((15, 15))
    P0[0:3, 0:3] = Cne @ np.diag([tun["gnss_h"] ** 2, tun["gnss_h"] ** 2, tun["gnss_v"] ** 2]) @ Cne.T
    P0[3:6, 3:6] = Cne @ np.diag([tun["gnss_vh"] ** 2, tun["gnss_vh"] ** 2, tun["gnss_vv"] ** 2]) @ Cne.T
    P0[6:9, 6:9] = Cne @ np.diag([(0.5 * deg) ** 2, (0.5 * deg) ** 2, (2.0 * deg) ** 2]) @ Cne.T
    P0[9:12, 9:12] = np.eye(3) * tun["accel_gm"] ** 2
    P0[12:15, 12:15] = np.eye(3) * tun["gyro_gm"] ** 2
    rng = np.random.default_rng(28)
    e0 = np.linalg.cholesky(P0 + 1e-30 * np.eye(15)) @ rng.standard_normal(15)
    # Estimate = truth - error (errors are true minus estimate).
    ekf = Ekf(t_imu[0], tr(i0) - e0[0:3], tv(i0) - e0[3:6], rodrigues(-e0[6:9]) @ tC(i0), P0)
    ekf.ba = -e0[9:12]
    ekf.bg = -e0[12:15]

    sh, sv = gnss_scale * tun["gnss_h"], gnss_scale * tun["gnss_v"]
    svh, svv = gnss_scale * tun["gnss_vh"], gnss_scale * tun["gnss_vv"]
    lo, hi = chi2_band(9)
    nees = []
    cov_every = max(1, int(round(tun["rate_hz"] / 10)))  # covariance at 10 Hz
    baro_every = max(1, int(round(tun["rate_hz"] / 5)))  # barometer updates at 5 Hz
    dt_cov = 0.0
    f_e_acc = np.zeros(3)
    n_acc = 0
    for k in range(1, len(t_imu)):
        dt = (t_imu[k] - t_imu[k - 1]) * 1e-9
        # Strapdown over (t_{k-1}, t_k] (Groves 5.2, ECEF), the bias-corrected
        # point samples at both ends averaged.
        w = 0.5 * (gyro[k - 1] + gyro[k]) - ekf.bg
        f = 0.5 * (accel[k - 1] + accel[k]) - ekf.ba
        C_old = ekf.C
        ekf.C = rodrigues(-OMEGA_IE * dt * np.array([0.0, 0.0, 1.0])) @ C_old @ rodrigues(w * dt)
        f_e = 0.5 * (C_old + ekf.C) @ f
        v_old = ekf.v
        ekf.v = v_old + (f_e + gravity_ecef(ekf.r) - 2.0 * OMEGA_IE_SKEW @ v_old) * dt
        ekf.r = ekf.r + 0.5 * (v_old + ekf.v) * dt
        # The biases' estimates decay as their Gauss-Markov model says.
        ekf.ba *= math.exp(-dt / tun["accel_tau"])
        ekf.bg *= math.exp(-dt / tun["gyro_tau"])
        dt_cov += dt
        f_e_acc += f_e
        n_acc += 1
        t = int(t_imu[k])
        gi = gnss_at.get(t)
        bi = baro_at.get(t) if k % baro_every == 0 else None
        if k % cov_every == 0 or gi is not None or bi is not None:
            ekf.propagate_covariance(tun, dt_cov, f_e_acc / n_acc)
            dt_cov, f_e_acc, n_acc = 0.0, np.zeros(3), 0
        if bi is not None and not math.isnan(baro["pressure_pa"][bi]):
            h_meas, dh_dp = height_from_pressure(baro["pressure_pa"][bi], tun["geoid_m"])
            lat, lon, h_est = geodetic_from_ecef(ekf.r)
            up = -ned_to_ecef(lat, lon)[:, 2]
            H = np.zeros((1, 15))
            H[0, 0:3] = up
            ekf.update(np.array([h_meas - h_est]), H, np.array([[(dh_dp * tun["baro_pa"]) ** 2]]))
        if gi is not None:
            lat_m, lon_m, h_m = gnss["latitude_rad"][gi], gnss["longitude_rad"][gi], gnss["height_m"][gi]
            Cn = ned_to_ecef(lat_m, lon_m)
            z_r = ecef_from_geodetic(lat_m, lon_m, h_m)
            z_v = Cn @ np.array([gnss["velocity_north_m_s"][gi], gnss["velocity_east_m_s"][gi],
                                 gnss["velocity_down_m_s"][gi]])
            H = np.zeros((6, 15))
            H[0:3, 0:3] = np.eye(3)
            H[3:6, 3:6] = np.eye(3)
            R = np.zeros((6, 6))
            R[0:3, 0:3] = Cn @ np.diag([sh * sh, sh * sh, sv * sv]) @ Cn.T
            R[3:6, 3:6] = Cn @ np.diag([svh * svh, svh * svh, svv * svv]) @ Cn.T
            ekf.update(np.concatenate([z_r - ekf.r, z_v - ekf.v]), H, R)
            # NEES of position, velocity and attitude against the truth.
            i = index_of[t]
            e = np.concatenate([tr(i) - ekf.r, tv(i) - ekf.v, rotation_log(tC(i) @ ekf.C.T)])
            nees.append(float(e @ np.linalg.solve(ekf.P[0:9, 0:9], e)))
    nees = np.array(nees)
    inside = float(np.mean((nees >= lo) & (nees <= hi)))
    return nees, inside, (lo, hi)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("imuemu")
    ap.add_argument("scene")
    ap.add_argument("--gnss-sigma-scale", type=float, default=1.0)
    ap.add_argument("--expect-fail", action="store_true")
    ap.add_argument("--data-scene", help="generate the data from this scene (the filter stays tuned from SCENE)")
    args = ap.parse_args()
    cpu0 = time.process_time()
    with tempfile.TemporaryDirectory(prefix="imuemu-nees-") as d:
        nees, inside, (lo, hi) = run(args.imuemu, args.scene, args.gnss_sigma_scale, d, args.data_scene)
    print(f"NEES (9 dof) at {len(nees)} GNSS epochs: mean {nees.mean():.2f} (expected 9), median "
          f"{np.median(nees):.2f}; {100 * inside:.1f} % inside the 95 % band [{lo:.3f}, {hi:.3f}] "
          f"(below {100 * np.mean(nees < lo):.1f} %, above {100 * np.mean(nees > hi):.1f} %); "
          f"GNSS sigma scale {args.gnss_sigma_scale}; filter CPU {time.process_time() - cpu0:.1f} s")
    ok = inside >= 0.90
    if args.expect_fail:
        print("negative control:", "rejected as it must be" if not ok else "NOT rejected")
        return 0 if not ok else 1
    print("consistent" if ok else "INCONSISTENT: fewer than 90 % of epochs inside the band")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
