"""Ego trajectory: logged poses smoothed by a Kalman filter + RTS smoother (filterpy).

Model: constant velocity on (x, y, z, yaw) with yaw unwrapped, white-acceleration process noise
(Bar-Shalom, "Estimation with Applications to Tracking", sec. 6.3.2, the discretized continuous
white-noise acceleration model). Measurements are the logged positions and yaw; NaN samples are
skipped (predict only), and a measurement whose innovation has a squared Mahalanobis distance
above ``gate_chi2`` is rejected as GNSS jitter. The Rauch-Tung-Striebel pass then smooths.
Roll and pitch are kept from the log (interpolated); the filter smooths the planar motion.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from drivewm.curate.config import TrajectoryConfig
from drivewm.geometry import euler_to_R, invert_T, make_T, transform_points


@dataclasses.dataclass
class SmoothedTrajectory:
    """Smoothed ego state at the log's pose times: ``t_ns`` (N,), ``xyz`` (N, 3) m, ``yaw`` (N,) rad
    (unwrapped), ``roll``/``pitch`` (N,) rad; ``rejected`` jitter samples, ``missing`` NaN samples."""

    t_ns: np.ndarray
    xyz: np.ndarray
    yaw: np.ndarray
    roll: np.ndarray
    pitch: np.ndarray
    rejected: int
    missing: int

    def poses_at(self, t_ns: np.ndarray) -> np.ndarray:
        """T_world_from_ego (len(t), 4, 4) interpolated linearly at ``t_ns`` (clamped at the ends)."""
        t = np.asarray(t_ns, dtype=np.float64)
        tt = self.t_ns.astype(np.float64)
        xyz = np.stack([np.interp(t, tt, self.xyz[:, i]) for i in range(3)], axis=1)
        angles = [np.interp(t, tt, a) for a in (self.roll, self.pitch, self.yaw)]
        return np.stack([make_T(euler_to_R(r, p, y), q) for r, p, y, q in zip(*angles, xyz)])


def rpy_of(T: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Roll, pitch, yaw (rad) of rotations (N, 4, 4) with R = Rz(yaw) Ry(pitch) Rx(roll)."""
    R = T[:, :3, :3]
    pitch = -np.arcsin(np.clip(R[:, 2, 0], -1, 1))
    return np.arctan2(R[:, 2, 1], R[:, 2, 2]), pitch, np.arctan2(R[:, 1, 0], R[:, 0, 0])


@functools.lru_cache(maxsize=64)
def _transition(dt: float, q_pos: float, q_yaw: float) -> tuple[np.ndarray, np.ndarray]:
    """F and Q (8, 8) of the constant-velocity model over ``dt`` s for state (x, y, z, yaw, vx, vy, vz, vyaw).

    Cached and read-only: a log's poses mostly come at one period, and building them anew for the filter's
    and the smoother's every step was ~40 % of the smoothing's CPU (22 -> 13 ms per 150-pose log)."""
    F = np.eye(8)
    F[:4, 4:] = np.eye(4) * dt
    q = np.array([q_pos, q_pos, q_pos, q_yaw]) ** 2
    Q = np.zeros((8, 8))
    Q[:4, :4] = np.diag(q) * dt**3 / 3
    Q[:4, 4:] = Q[4:, :4] = np.diag(q) * dt**2 / 2
    Q[4:, 4:] = np.diag(q) * dt
    F.flags.writeable = Q.flags.writeable = False
    return F, Q


def _measurements(T_world_from_ego: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(z (N, 4) with yaw unwrapped over valid samples, valid (N,), roll (N,), pitch (N,))."""
    valid = np.isfinite(T_world_from_ego).all(axis=(1, 2))
    roll, pitch, yaw = (np.full(len(valid), np.nan) for _ in range(3))
    if valid.any():
        r, p, y = rpy_of(T_world_from_ego[valid])
        roll[valid], pitch[valid], yaw[valid] = r, p, np.unwrap(y)
    z = np.concatenate([T_world_from_ego[:, :3, 3], yaw[:, None]], axis=1)
    return z, valid, roll, pitch


def smooth_poses(t_ns: np.ndarray, T_world_from_ego: np.ndarray, cfg: TrajectoryConfig) -> SmoothedTrajectory | None:
    """Smooth logged poses (N, 4, 4) at times ``t_ns`` (N,); None when no pose is finite (ego motion unknown)."""
    order = np.argsort(t_ns, kind="stable")
    t_ns, T_world_from_ego = np.asarray(t_ns)[order], np.asarray(T_world_from_ego, dtype=np.float64)[order]
    z, valid, roll, pitch = _measurements(T_world_from_ego)
    if not valid.any():
        return None
    # lazy: filterpy's package __init__ imports every submodule, scipy.stats among them (~1 CPU s idle,
    # ~2 under load), and even filterpy.kalman.kalman_filter runs it; a process that only imports the
    # stage (the driver of a pool, `drivewm curate --help`) never pays it (docs/DESIGN.md section 9)
    from filterpy.kalman import KalmanFilter

    kf = KalmanFilter(dim_x=8, dim_z=4)
    kf.H = np.hstack([np.eye(4), np.zeros((4, 4))])
    kf.R = np.diag([cfg.position_sigma_m**2] * 3 + [cfg.yaw_sigma_rad**2])
    first = int(np.flatnonzero(valid)[0])
    kf.x = np.concatenate([z[first], np.zeros(4)])
    kf.P = np.diag([cfg.position_sigma_m**2] * 3 + [cfg.yaw_sigma_rad**2] + [100.0] * 3 + [1.0])
    n, rejected = len(t_ns), 0
    dts = np.concatenate([[0.0], np.diff(t_ns) * 1e-9])
    xs, Ps = np.empty((n, 8)), np.empty((n, 8, 8))  # filtered states, smoothed in place below
    for k in range(n):
        F, Q = _transition(float(dts[k]), cfg.accel_sigma_mps2, cfg.yaw_accel_sigma_radps2)
        kf.predict(F=F, Q=Q)
        if valid[k]:
            y = z[k] - kf.H @ kf.x
            S = kf.H @ kf.P @ kf.H.T + kf.R
            if float(y @ np.linalg.solve(S, y)) <= cfg.gate_chi2:
                kf.update(z[k])
            else:
                rejected += 1
        xs[k], Ps[k] = kf.x, kf.P
    xs_s = rts_smooth(xs, Ps, dts, cfg.accel_sigma_mps2, cfg.yaw_accel_sigma_radps2)
    idx = np.arange(len(t_ns))
    fill = lambda a: np.interp(idx, idx[valid], a[valid])  # noqa: E731 - roll/pitch across NaN samples
    return SmoothedTrajectory(t_ns, xs_s[:, :3], xs_s[:, 3], fill(roll), fill(pitch), rejected, int((~valid).sum()))


def rts_smooth(xs: np.ndarray, Ps: np.ndarray, dts: np.ndarray, q_pos: float, q_yaw: float) -> np.ndarray:
    """Rauch-Tung-Striebel backward pass (Rauch, Tung & Striebel 1965), in place on the filtered
    states ``xs`` (n, 8) and covariances ``Ps`` (n, 8, 8); returns ``xs`` smoothed.

    Step for step filterpy's ``KalmanFilter.rts_smoother`` (same products, same order: the same
    numbers), but F and Q are rebuilt from each step's ``dts`` (s) instead of stored, and no
    per-step gains are kept: 72 floats per pose, so an hour of 100 Hz poses stays ~200 MB.
    """
    for k in range(len(xs) - 2, -1, -1):
        F, Q = _transition(float(dts[k + 1]), q_pos, q_yaw)
        Pp = np.dot(np.dot(F, Ps[k]), F.T) + Q
        K = np.dot(np.dot(Ps[k], F.T), np.linalg.inv(Pp))
        xs[k] += np.dot(K, xs[k + 1] - np.dot(F, xs[k]))
        Ps[k] += np.dot(np.dot(K, Ps[k + 1] - Pp), K.T)
    return xs


def future_waypoints(T_world_from_ego: np.ndarray, t_ns: np.ndarray, n: int) -> tuple[np.ndarray, float]:
    """``n`` waypoints [x, y, z] (m) in the first frame's ego frame, uniform in time from the 2nd frame
    to the last (ClipMeta.trajectory_ego), interpolated from per-frame poses (T, 4, 4); and their spacing in s."""
    t = np.asarray(t_ns, dtype=np.float64)
    ts = np.linspace(t[1], t[-1], n)
    xyz = np.stack([np.interp(ts, t, T_world_from_ego[:, i, 3]) for i in range(3)], axis=1)
    dt_s = float((t[-1] - t[1]) * 1e-9 / (n - 1)) if n > 1 else float((t[-1] - t[1]) * 1e-9)
    return transform_points(invert_T(T_world_from_ego[0]), xyz), dt_s
