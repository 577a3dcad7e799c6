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


ALIGNMENTS = ("none", "se3", "sim3")
DELTA_UNITS = ("frames", "m")


def align(est_xyz: np.ndarray, ref_xyz: np.ndarray, alignment: str = "sim3") -> Sim3:
    """The transform applied to the estimate before scoring, as evo's ``-a`` (``se3``: rotation and
    translation), ``-as`` (``sim3``: with scale) or no flag (``none``: identity)."""
    if alignment == "none":
        return Sim3(1.0, np.eye(3), np.zeros(3))
    if alignment not in ALIGNMENTS:
        raise DrivewmError(f"trajectory alignment {alignment!r} is not one of {ALIGNMENTS}")
    return umeyama(est_xyz, ref_xyz, with_scale=alignment == "sim3")


def ate(est: np.ndarray, ref: np.ndarray, with_scale: bool = True, alignment: str = "") -> tuple[float, Sim3]:
    """Absolute trajectory error (m): RMSE of positions after the best similarity (Sturm et al. 2012),
    or after ``alignment`` ('none', 'se3', 'sim3'; evo_ape's translation part, RMSE)."""
    sim = align(est[:, :3, 3], ref[:, :3, 3], alignment or ("sim3" if with_scale else "se3"))
    residual = sim.apply_points(est[:, :3, 3]) - ref[:, :3, 3]
    return float(np.sqrt(np.mean(np.sum(residual**2, axis=1)))), sim


def rpe_pairs(T: np.ndarray, delta: float, unit: str = "frames", all_pairs: bool = False) -> list[tuple[int, int]]:
    """Index pairs (i, j) of poses (N, 4, 4) ``delta`` apart, as evo's ``id_pairs_from_delta``.

    ``frames``: j = i + delta, for every i (``all_pairs``, overlapping) or every delta-th i
    (consecutive, evo's default). ``m``: consecutive pairs end where the travelled path first
    reaches ``delta`` metres (then the count restarts); all pairs take, for each i, the j whose path
    from i is closest to ``delta`` and keep it when within 10% of ``delta`` (evo's rel_delta_tol)."""
    n = len(T)
    if unit == "frames":
        d = int(delta)
        starts = range(n) if all_pairs else range(0, n, d)
        return [(i, i + d) for i in starts if i + d < n]
    if unit != "m":
        raise DrivewmError(f"RPE delta unit {unit!r} is not one of {DELTA_UNITS}")
    path = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(T[:, :3, 3], axis=0), axis=1))])
    if all_pairs:
        pairs = []
        for i in range(n - 1):
            j = i + 1 + int(np.argmin(np.abs(path[i + 1 :] - path[i] - delta)))
            if abs(path[j] - path[i] - delta) <= 0.1 * delta:
                pairs.append((i, j))
        return pairs
    ids, travelled = [0], 0.0
    for i in range(1, n):
        travelled += float(np.linalg.norm(T[i, :3, 3] - T[i - 1, :3, 3]))  # summed step by step, as evo does
        if travelled >= delta:
            ids.append(i)
            travelled = 0.0
    return list(zip(ids, ids[1:]))


@dataclasses.dataclass
class RelativePoseErrors:
    """Per-pair relative pose errors: translation (m) and rotation (deg), with the pairs (i, j)."""

    pairs: list[tuple[int, int]]
    trans_m: np.ndarray
    rot_deg: np.ndarray

    @staticmethod
    def _stat(x: np.ndarray, rms: bool) -> float:
        if len(x) == 0:
            return float("nan")
        return float(np.sqrt(np.mean(x**2))) if rms else float(np.mean(x))

    @property
    def trans_rmse(self) -> float:
        return self._stat(self.trans_m, True)

    @property
    def trans_mean(self) -> float:
        return self._stat(self.trans_m, False)

    @property
    def rot_rmse(self) -> float:
        return self._stat(self.rot_deg, True)

    @property
    def rot_mean(self) -> float:
        return self._stat(self.rot_deg, False)


def relative_pose_errors(
    est: np.ndarray,
    ref: np.ndarray,
    delta: float = 1,
    unit: str = "frames",
    all_pairs: bool = False,
    scale: float = 1.0,
    pairs_from: str = "reference",
) -> RelativePoseErrors:
    """Relative pose errors E_ij = (ref_i^-1 ref_j)^-1 (est_i^-1 est_j) (Sturm et al. 2012, eq. 1;
    evo's RPE.rpe_base), the estimate's translations scaled by ``scale`` (the alignment's; a Sim(3)
    applied to the estimate changes its relative poses by exactly that). Rotation errors are the
    angle of the nearest rotation (drivewm.geometry.rotation_angle_deg). Pairs come from
    :func:`rpe_pairs` on ``pairs_from`` ('reference', evo's --pairs_from_reference, or the scaled
    'estimate', evo's default)."""
    if pairs_from not in ("reference", "estimate"):
        raise DrivewmError(f"RPE pairs_from {pairs_from!r} is not 'reference' or 'estimate'")
    scaled = est.copy()
    scaled[:, :3, 3] *= scale
    pairs = rpe_pairs(ref if pairs_from == "reference" else scaled, delta, unit, all_pairs)
    errors = [invert_T(invert_T(ref[i]) @ ref[j]) @ (invert_T(scaled[i]) @ scaled[j]) for i, j in pairs]
    trans = np.array([np.linalg.norm(E[:3, 3]) for E in errors])
    rot = np.array([rotation_angle_deg(E[:3, :3]) for E in errors])
    return RelativePoseErrors(pairs, trans, rot)


def rpe(est: np.ndarray, ref: np.ndarray, delta: int = 1, scale: float = 1.0) -> tuple[float, float]:
    """Relative pose error over ``delta`` frames (every frame starts a pair): (RMSE translation in m,
    mean rotation in deg); see :func:`relative_pose_errors` for the other definitions."""
    r = relative_pose_errors(est, ref, delta, "frames", all_pairs=True, scale=scale)
    return r.trans_rmse, r.rot_mean


@dataclasses.dataclass
class ImagePoseErrors:
    """Per-image pose errors of a reconstruction against reference camera poses: ``position_m`` and
    ``rotation_deg`` (R, ) of the R registered images after ``sim``, out of ``images`` in all."""

    position_m: np.ndarray
    rotation_deg: np.ndarray
    images: int
    sim: Sim3

    def auc(self, max_m: float, max_deg: float) -> float:
        """Area under the accuracy curve up to (``max_m``, ``max_deg``): the mean over all images of
        ``max(0, 1 - max(position / max_m, rotation / max_deg))``, an unregistered image counting 0.
        1 only for exact poses; it falls continuously as errors grow, where a success rate at one
        threshold stays flat (the pose AUC of relative-pose benchmarks, Sarlin et al. 2020, with
        absolute errors in place of angular ones)."""
        if self.images == 0:
            return float("nan")
        err = np.maximum(self.position_m / max_m, self.rotation_deg / max_deg)
        return float(np.sum(np.clip(1.0 - err, 0.0, 1.0)) / self.images)


def image_pose_errors(
    est: dict[str, np.ndarray], registered: dict[str, np.ndarray], ref: dict[str, np.ndarray], alignment: str = "sim3"
) -> ImagePoseErrors:
    """Errors of every registered image's ``T_world_from_cam`` in ``est`` (per camera, (T, 4, 4) in
    the reconstruction's frame) against ``ref`` (per camera, (T, 4, 4) in metres), after one
    ``alignment`` fitted to all registered camera centres at once. With fewer than 3 registered
    images nothing can be aligned, and no image has an error (``auc`` 0).

    Fitting to the centres of every camera of a rig, not to the ego path, keeps the alignment
    well posed when the vehicle drives straight or stands still: the positions of a straight path
    are collinear, leave the roll about that line free, and on simulated reference clips left the
    aligned cameras 19-124 degrees off while the path's ATE was 1-5 cm."""
    images = sum(len(registered[c]) for c in est)
    if sum(int(registered[c].sum()) for c in est) < 3:  # too few to align: every image counts as unregistered
        return ImagePoseErrors(np.zeros(0), np.zeros(0), images, Sim3(1.0, np.eye(3), np.zeros(3)))
    e = np.concatenate([est[c][registered[c]] for c in est])
    r = np.concatenate([ref[c][registered[c]] for c in est])
    sim = align(e[:, :3, 3], r[:, :3, 3], alignment)
    aligned = sim.apply_poses(e)
    position = np.linalg.norm(aligned[:, :3, 3] - r[:, :3, 3], axis=1)
    rotation = np.array([rotation_angle_deg(a[:3, :3].T @ b[:3, :3]) for a, b in zip(aligned, r)])
    return ImagePoseErrors(position, rotation, images, sim)


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


def path_length_m(T_world_from_ego: np.ndarray) -> float:
    """Length of the path through the poses' positions, frame to frame (in the poses' own units)."""
    p = np.asarray(T_world_from_ego, dtype=np.float64)[:, :3, 3]
    return float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())


def path_ratio(est: np.ndarray, ref: np.ndarray, floor_m: float = 1.0) -> float:
    """How far the recovered ego path travels against the reference over the same frames, both
    floored at ``floor_m`` metres: ``max(len(est), floor) / max(len(ref), floor)``. No alignment: a
    rig-aware reconstruction is in metres already (the rig's baselines fix its scale). A standing
    ego and a reconstruction that stands read 1; a reconstruction that stands while the ego drove
    34 m reads 0.03, one spread over 450 m for a 37 m drive 12."""
    return max(path_length_m(est), floor_m) / max(path_length_m(ref), floor_m)


def heading_change_deg(T_world_from_ego: np.ndarray) -> float:
    """Yaw of the last ego pose in the first one's ego frame (degrees; ego is x forward, y left, z up,
    so a left turn is positive). Invariant to the world frame's gauge, so it reads a recovered
    (structure-from-motion) trajectory as well as a reference one."""
    R = T_world_from_ego[0, :3, :3].T @ T_world_from_ego[-1, :3, :3]
    return float(np.degrees(np.arctan2(R[1, 0], R[0, 0])))


def waypoint_heading_deg(waypoints_ego: np.ndarray, min_chord_m: float = 1.0) -> float:
    """The turn a trajectory conditions (degrees, left positive), comparable with
    :func:`heading_change_deg`: the heading of the chord from the last waypoint back to the latest
    earlier one (the origin first) at least ``min_chord_m`` away, which is the last segment itself at
    driving speeds. A shorter reach would read a car that stops and creeps back a few centimetres
    (highway-env's intersection ego does) as turning by ~180 degrees. 0.0 when no waypoint is that
    far from the last one: a standing ego conditions no turn."""
    w = np.concatenate([np.zeros((1, 2)), np.asarray(waypoints_ego, dtype=np.float64)[:, :2]])
    far = np.flatnonzero(np.linalg.norm(w[-1] - w[:-1], axis=1) >= min_chord_m)
    if len(far) == 0:
        return 0.0
    d = w[-1] - w[far[-1]]
    return float(np.degrees(np.arctan2(d[1], d[0])))
