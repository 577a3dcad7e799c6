"""Turned copies of a simulated clip: the same drive with an extra constant yaw rate, for teaching
and testing trajectory following with few clips.

The ego path is rebuilt from the clip's own per-frame motions with an extra yaw ``yaw_rate_rps * dt``
before each step (the car steers more, and keeps driving along its nose), so frame 0 is unchanged
and the turned trajectory is a drivable one. Each frame is re-rendered for the turned camera by
the rotation homography ``H = K R_new^T R_old K^-1`` (Hartley & Zisserman, sec. 8.4.2: exact for a
pure rotation). What it leaves out: the camera also ends up somewhere else (metres after 1.6 s),
whose parallax on near objects the homography does not render. Because frame 0 is shared by all
turned copies of a clip, a model conditioned on it can only tell the copies apart by the trajectory.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import cv2
import numpy as np
import torch
import torch.nn.functional as F
from einops import rearrange
from mv_standin import PoolTokenizer

from drivewm.clips import iter_clips
from drivewm.clips.latents import write_latent_clip, write_latent_index
from drivewm.geometry import Camera, invert_T, rot_z, yaw_of

CAMERA = "CAM_FRONT"


def turned_key(key: str, rate_rps: float) -> str:
    """The clip key of a copy turned by ``rate_rps``: a safe name (drivewm.paths), e.g. KEY_yawm025 for -0.25."""
    return f"{key}_yaw{'p' if rate_rps >= 0 else 'm'}{round(abs(rate_rps) * 100):03d}"


def turned_poses(T_world_from_ego: np.ndarray, yaw_rate_rps: float, dt_s: float) -> np.ndarray:
    """(T, 4, 4) ego poses in the first frame's ego frame after adding ``yaw_rate_rps`` (+ = left)."""
    P = np.einsum("ij,njk->nik", invert_T(T_world_from_ego[0]), T_world_from_ego)
    out = [np.eye(4)]
    turn = np.eye(4)
    turn[:3, :3] = rot_z(yaw_rate_rps * dt_s)
    for i in range(1, len(P)):
        out.append(out[-1] @ turn @ invert_T(P[i - 1]) @ P[i])
    return np.stack(out)


def turned_video(video: np.ndarray, T_world_from_ego: np.ndarray, turned: np.ndarray, camera: Camera) -> np.ndarray:
    """uint8 (T, H, W, 3) frames of ``camera`` re-rendered for the ``turned`` ego poses (frame-0 ego frame)."""
    P = np.einsum("ij,njk->nik", invert_T(T_world_from_ego[0]), T_world_from_ego)
    K, K_inv = camera.K, np.linalg.inv(camera.K)
    h, w = video.shape[1:3]
    out = []
    for frame, T_old, T_new in zip(video, P, turned):
        R_old = (T_old @ camera.T_ego_from_cam)[:3, :3]
        R_new = (T_new @ camera.T_ego_from_cam)[:3, :3]
        H = K @ R_new.T @ R_old @ K_inv  # old pixel -> new pixel of the same (distant) direction
        out.append(cv2.warpPerspective(frame, H, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE))
    return np.stack(out)


def write_turned_cache(clip_dir: Path, out: Path, yaw_rates_rps: tuple[float, ...], pool: int = 8) -> Path:
    """A latent cache (PoolTokenizer(pool)) of the front camera of every clip, turned by each yaw
    rate: keys ``<clip key>@<rate:+.2f>``, trajectory_ego and poses of the turned drive."""
    tok, rows = PoolTokenizer(pool), []
    for clip in iter_clips(clip_dir):
        camera = clip.meta.get_rig().camera(CAMERA)
        dt = 1.0 / clip.meta.fps
        for rate in yaw_rates_rps:
            P = turned_poses(clip.T_world_from_ego, rate, dt)
            video = turned_video(clip.video(CAMERA), clip.T_world_from_ego, P, camera)
            z = tok.encode(rearrange(torch.from_numpy(video).float() / 127.5 - 1, "t h w c -> 1 c t h w"))
            meta = dataclasses.replace(
                clip.meta,
                key=turned_key(clip.key, rate),
                trajectory_ego=P[1:, :3, 3].tolist(),
                trajectory_dt_s=dt,
                rig=clip.meta.get_rig().subset([CAMERA]).to_dict(),
            )
            rows.append(write_latent_clip(out, meta, z, clip.T_world_from_ego[0] @ P))
    write_latent_index(out, {"path": None, "latent_mean": [0.0] * 3, "latent_std": [0.5] * 3}, rows)
    return out


def decode_bilinear(latents: torch.Tensor, pool: int = 8) -> np.ndarray:
    """Raw pooled latents (c, t, h, w) in [-1, 1] -> uint8 (1 + 4 (t - 1), H, W, 3): each latent
    frame upsampled bilinearly (a smooth stand-in decoder), laid out 4x as PoolTokenizer.decode does."""
    frames = F.interpolate(
        rearrange(latents, "c t h w -> t c h w"), scale_factor=pool, mode="bilinear", align_corners=False
    )
    frames = torch.cat([frames[:1], frames[1:].repeat_interleave(4, dim=0)])
    return ((rearrange(frames, "t c h w -> t h w c").clamp(-1, 1) + 1) * 127.5).round().byte().numpy()


def recovered_yaw(frames: np.ndarray, camera: Camera) -> float:
    """Yaw (rad, + = left) from the first to the last frame, by the eval stage's estimator (dense-flow
    method: SfM leaves these low-resolution frames unregistered)."""
    from drivewm.eval.trajectory import estimate_ego_trajectory

    est = estimate_ego_trajectory(frames, camera, method="flow")
    T = est.T_world_from_ego
    return yaw_of(invert_T(T[0]) @ T[-1]) if est.registered[-1] else float("nan")


def trajectory_yaw(waypoints: np.ndarray) -> float:
    """Heading (rad) of the last step of (W, 3) waypoints."""
    d = waypoints[-1] - waypoints[-2]
    return float(np.arctan2(d[1], d[0]))


def paired_agreement(pairs: list[tuple[float, float, float, float]]) -> int:
    """Pairs (yaw_a, yaw_b conditioned; rec_a, rec_b recovered) whose recovered yaws fit their own
    trajectories better than the swapped ones (squared error), i.e. (rec_a - rec_b)(yaw_a - yaw_b) > 0.
    Two identical recoveries (a model ignoring the trajectory) do not count."""
    return int(sum((ra - rb) * (ya - yb) > 0 for ya, yb, ra, rb in pairs))
