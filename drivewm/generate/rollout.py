"""World-model rollouts: continue a real clip autoregressively under a chosen ego trajectory.

Video2World (Cosmos, arXiv 2501.03575 sec. 5.1): each window is generated with its first
``cond_frames`` latent frames given clean. Window 0 is conditioned on the real clip's first
frames; every later window on the last frames generated so far, decoded to pixels and encoded
again (with a causal tokenizer the first latent frame of a window encodes one frame alone, so
re-encoding keeps the conditioning in the distribution the model was trained on). The trajectory
is laid out once for the whole rollout and handed to each window in that window's first ego frame.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import torch
from einops import rearrange
from tqdm import tqdm

from drivewm.clips.format import Clip
from drivewm.clips.shards import iter_clips
from drivewm.errors import DrivewmError
from drivewm.generate.config import GenerateConfig
from drivewm.generate.reproject import refine_reprojected
from drivewm.generate.writer import GeneratedSample
from drivewm.geometry import Rig
from drivewm.multiview.coding import decode_views, encode_views, frames_to_video
from drivewm.multiview.model import MultiView
from drivewm.multiview.trajectories import (
    NAMED,
    load_waypoints,
    named_poses,
    poses_from_waypoints,
    waypoints_from_poses,
)


def load_clip(path: str | Path, key: str | None = None) -> Clip:
    """The clip ``key`` (or the first one) from a shard ``.tar`` or a clip folder."""
    path = Path(path)
    if not path.exists():
        raise DrivewmError(f"{path}: no such clip shard or folder")
    for clip in iter_clips(path):
        if key is None or clip.key == key:
            return clip
    raise DrivewmError(f"{path}: no clip with key {key!r}")


def initial_speed_mps(clip: Clip) -> float:
    """Ego speed between the clip's first two frames (NaN when the poses are missing or unknown)."""
    T = clip.T_world_from_ego
    if len(T) < 2 or not clip.meta.ego_motion_known:
        return float("nan")
    return float(np.linalg.norm(T[1, :3, 3] - T[0, :3, 3]) * clip.meta.fps)


def rollout_poses(spec: str, num: int, dt_s: float, speed_mps: float, horizon_s: float) -> np.ndarray:
    """(num, 4, 4) T_world_from_ego at ``dt_s`` spacing from frame 0: a named manoeuvre (``stop``
    comes to rest at ``horizon_s``) or a file."""
    if spec in NAMED:
        return named_poses(spec, num, dt_s, speed_mps, horizon_s=horizon_s)
    return poses_from_waypoints(load_waypoints(spec), num, dt_s, 1.0 / dt_s)


def clip_rig(model: MultiView, clip: Clip) -> Rig:
    """The model's training cameras when the clip has them all, else every camera of the clip (a
    dashcam's one): the model conditions on each camera's K and pose, so any rig works; always with
    the clip's own calibration."""
    rig, names = clip.meta.get_rig(), model.training_rig.names
    return rig.subset(names) if set(names) <= set(rig.names) else rig


@dataclasses.dataclass
class _Windows:
    """Frame bookkeeping of a rollout: ``k`` latent conditioning frames are ``n_cond`` video frames,
    a window of ``t`` latent frames is ``n_win`` video frames, ``steps_per_frame`` waypoint steps per frame."""

    k: int
    n_cond: int
    n_win: int
    steps_per_frame: float


def rollout(model: MultiView, clip: Clip, cfg: GenerateConfig, tokenizer, prompt: str = "") -> GeneratedSample:
    """Continue ``clip`` for ``cfg.rollout.windows`` windows on ``model.device`` (the tokenizer must be there
    too), every view captioned ``prompt`` ('' = the clip's own per-view captions); returns the whole video
    (real conditioning frames first) with the trajectory it was conditioned on. The ``reproject`` post-step
    (with ``reshade``), when asked for, refines each window from its first frame warped along the trajectory."""
    rig, mv = clip_rig(model, clip), model.cfg.multiview
    c, t, h, w = model.latent.latent_shape
    tc, sc = tokenizer.config.temporal_compression, tokenizer.config.spatial_compression
    k = max(1, model.cfg.edm.cond_frames)
    win = _Windows(k, 1 + (k - 1) * tc, 1 + (t - 1) * tc, 1.0 / (clip.meta.fps * mv.trajectory_dt_s))
    if clip.meta.num_frames < win.n_cond:
        raise DrivewmError(
            f"clip {clip.key}: needs at least {win.n_cond} frames to condition on, has {clip.meta.num_frames}"
        )
    speed = cfg.rollout.speed_mps or initial_speed_mps(clip)
    speed = speed if np.isfinite(speed) else mv.speed_mps
    total = win.n_cond + cfg.rollout.windows * (win.n_win - win.n_cond)
    num_poses = int(np.ceil(total * win.steps_per_frame)) + mv.trajectory_waypoints + 1
    poses = rollout_poses(cfg.trajectory, num_poses, mv.trajectory_dt_s, speed, (total - 1) / clip.meta.fps)
    captions = (
        [prompt] * len(rig.cameras)
        if prompt
        else [clip.meta.view_captions.get(n) or clip.meta.caption for n in rig.names]
    )
    size = (h * sc, w * sc)
    first = frames_to_video(
        np.stack([clip.video(n)[: win.n_cond] for n in rig.names]), size
    )  # (V, 3, n_cond, h*sc, w*sc)
    video = rearrange(first, "v c t h w -> v t h w c").add(1).mul(127.5).round().byte().numpy()
    for window in tqdm(range(cfg.rollout.windows), desc="rollout"):
        new = _next_window(model, tokenizer, rig, captions, video, poses, win, size, cfg, window, clip.meta.fps)
        video = np.concatenate([video, new], axis=1)
    traj = waypoints_from_poses(poses, 0, int(round((video.shape[1] - 1) * win.steps_per_frame)))
    extra = {
        "rollout_of": clip.key,
        "source_log": clip.meta.source_log,
        "trajectory": cfg.trajectory,
        "windows": cfg.rollout.windows,
        "speed_mps": speed,
        "seed": cfg.sampling.seed,
        **cfg.record(),
        "cond_video_frames": win.n_cond,
    }
    return GeneratedSample(video, rig, captions[0], captions, traj, mv.trajectory_dt_s, extra)


def _next_window(
    model: MultiView,
    tokenizer,
    rig: Rig,
    captions: list[str],
    video: np.ndarray,
    poses: np.ndarray,
    win: _Windows,
    size: tuple[int, int],
    cfg: GenerateConfig,
    window: int,
    fps: float,
) -> np.ndarray:
    """The frames a window adds after its conditioning frames (the last ``n_cond`` of ``video``),
    uint8 (V, n_win - n_cond, H, W, 3)."""
    c, t, h, w = model.latent.latent_shape
    start = video.shape[1] - win.n_cond  # the window's first frame in the rollout
    cond = torch.zeros(len(rig.cameras), c, t, h, w)
    cond[:, :, : win.k] = encode_views(tokenizer, video[:, start:], size, model.device)[:, :, : win.k]
    waypoints = waypoints_from_poses(
        poses, int(round(start * win.steps_per_frame)), model.cfg.multiview.trajectory_waypoints
    )
    s = cfg.sampling
    sampling = s.sample_kwargs()
    seed = s.seed + window
    z = model.sample_latents(
        rig, [captions], waypoints[None], [seed], s.steps, cond_latents=cond[None], fps=fps, **sampling
    )[0]
    if cfg.post("reproject"):
        first = decode_views(tokenizer, z, model.device)
        z = refine_reprojected(
            model, tokenizer, rig, captions, waypoints, seed, first, cfg.reproject, cfg.post("reshade"), sampling, fps
        )
    return decode_views(tokenizer, z, model.device)[:, win.n_cond :]
