"""Trajectory errors: Umeyama alignment, ATE, RPE (translation, rotation) and trajectory-following error.

Conventions: trajectories are (N, 4, 4) ``T_world_from_ego`` (the estimate in its own world frame
and scale, the reference in metres); errors are in metres and degrees after aligning the estimate
to the reference with a similarity (Umeyama 1991) -- with scale, because a monocular or generated
video fixes the trajectory only up to scale (Sturm et al. 2012 for ATE/RPE).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from drivewm.errors import DrivewmError
from drivewm.geometry import invert_T, rotation_angle_deg


@dataclasses.dataclass
class Sim3:
    """x_ref = scale * R @ x_est + t."""

    scale: float
    R: np.ndarray
    t: np.ndarray

    def apply_points(self, points: np.ndarray) -> np.ndarray:
        return self.scale * points @ self.R.T + self.t

    def apply_poses(self, T: np.ndarray) -> np.ndarray:
        out = T.copy()
        out[:, :3, :3] = np.einsum("ij,njk->nik", self.R, T[:, :3, :3])
        out[:, :3, 3] = self.apply_points(T[:, :3, 3])
        return out


def umeyama(src: np.ndarray, dst: np.ndarray, with_scale: bool = True) -> Sim3:
    """Least-squares similarity mapping points src (N, 3) onto dst (N, 3) (Umeyama 1991, eqs. 40-42)."""
    if len(src) < 3:
        raise DrivewmError(f"umeyama: needs at least 3 point pairs, got {len(src)}")
    mu_s, mu_d = src.mean(0), dst.mean(0)
    xs, xd = src - mu_s, dst - mu_d
    cov = xd.T @ xs / len(src)  # eq. 38
    U, D, Vt = np.linalg.svd(cov)
    S = np.eye(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:  # eq. 39: keep a proper rotation
        S[2, 2] = -1
    R = U @ S @ Vt  # eq. 40
    var_s = np.mean(np.sum(xs**2, axis=1))
    scale = float(np.trace(np.diag(D) @ S) / var_s) if with_scale and var_s > 0 else 1.0  # eq. 42
    return Sim3(scale, R, mu_d - scale * R @ mu_s)  # eq. 41


def ate(est: np.ndarray, ref: np.ndarray, with_scale: bool = True) -> tuple[float, Sim3]:
    """Absolute trajectory error (m): RMSE of positions after the best similarity (Sturm et al. 2012)."""
    sim = umeyama(est[:, :3, 3], ref[:, :3, 3], with_scale)
    residual = sim.apply_points(est[:, :3, 3]) - ref[:, :3, 3]
    return float(np.sqrt(np.mean(np.sum(residual**2, axis=1)))), sim


def rpe(est: np.ndarray, ref: np.ndarray, delta: int = 1, scale: float = 1.0) -> tuple[float, float]:
    """Relative pose error over ``delta`` frames: (RMSE translation in m, mean rotation in deg).

    E_i = (ref_i^-1 ref_{i+d})^-1 (est_i^-1 est_{i+d}) with the estimate's translations scaled by
    ``scale`` (from the ATE alignment) (Sturm et al. 2012, eq. 1)."""
    if len(est) <= delta:
        return float("nan"), float("nan")
    trans, rots = [], []
    for i in range(len(est) - delta):
        rel_est = invert_T(est[i]) @ est[i + delta]
        rel_est[:3, 3] *= scale
        err = invert_T(invert_T(ref[i]) @ ref[i + delta]) @ rel_est
        trans.append(np.sum(err[:3, 3] ** 2))
        rots.append(rotation_angle_deg(err[:3, :3]))
    return float(np.sqrt(np.mean(trans))), float(np.mean(rots))


def tfe(est_T_world_from_ego: np.ndarray, fps: float, waypoints_ego: np.ndarray, dt_s: float) -> float:
    """Trajectory-following error (m): mean distance between the conditioned waypoints and the
    recovered ego positions at the same times, both in the first frame's ego frame.

    ``waypoints_ego`` (N, 3) are spaced ``dt_s`` apart starting one step after the first frame
    (ClipMeta.trajectory_ego). The recovered positions (frames at 1/fps, linearly interpolated)
    are scaled by the least-squares factor onto the waypoints (monocular scale), nothing else:
    a wrong heading or curvature is not aligned away."""
    T0_inv = invert_T(est_T_world_from_ego[0])
    p = np.einsum("ij,nj->ni", T0_inv[:3, :3], est_T_world_from_ego[:, :3, 3]) + T0_inv[:3, 3]
    frame_t = np.arange(len(p)) / fps
    way_t = (np.arange(len(waypoints_ego)) + 1) * dt_s
    keep = way_t <= frame_t[-1] + 1e-9
    if keep.sum() < 1:
        return float("nan")
    q = np.stack([np.interp(way_t[keep], frame_t, p[:, k]) for k in range(3)], 1)
    w = np.asarray(waypoints_ego, dtype=np.float64)[keep]
    denom = float(np.sum(q * q))
    s = float(np.sum(q * w)) / denom if denom > 0 else 1.0
    return float(np.mean(np.linalg.norm(s * q - w, axis=1)))
