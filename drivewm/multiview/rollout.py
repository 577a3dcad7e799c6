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
from drivewm.config import check_guidance_interval, finite_at_least
from drivewm.errors import DrivewmError
from drivewm.geometry import Rig
from drivewm.multiview.coding import decode_views, encode_views, frames_to_video
from drivewm.multiview.defaults import DEFAULT_SIGMA
from drivewm.multiview.model import MultiView
from drivewm.multiview.reproject import Reprojection, refine_reprojected
from drivewm.multiview.trajectories import (
    NAMED,
    load_waypoints,
    named_poses,
    poses_from_waypoints,
    waypoints_from_poses,
)
from drivewm.multiview.writer import GeneratedSample

#: Fastest named-trajectory speed a rollout takes (m/s): beyond any road vehicle (100 m/s = 360 km/h).
MAX_SPEED_MPS = 100.0


@dataclasses.dataclass
class RolloutOptions:
    """Settings of ``drivewm rollout``."""

    trajectory: str = "straight"
    """straight|left|right|stop or a waypoint file (N, 3) in the clip's first ego frame."""
    windows: int = 2
    """Generated windows; each adds (latent frames - cond_frames) * temporal compression frames."""
    steps: int = 35
    """Sampler steps per window."""
    guidance: float = 7.0
    """Classifier-free guidance scale."""
    trajectory_guidance: float = 1.0
    """Guidance on the trajectory (drivewm.diffusion.sampling.guided; 1 = none)."""
    sampler: str = "heun"
    """``heun`` or ``euler``."""
    seed: int = 0
    """Window w uses seed + w."""
    prompt: str = ""
    """Caption for every view ('' = the clip's own per-view captions)."""
    speed_mps: float = 0.0
    """Speed of a named trajectory (0 = the clip's own initial speed)."""
    reprojection: Reprojection = dataclasses.field(default_factory=lambda: Reprojection(DEFAULT_SIGMA))
    """Each window's first frame reprojected along the trajectory and refined (drivewm.multiview.reproject;
    ``Reprojection()`` is off; never blended, drivewm.multiview.blend: the first frames are the clip's own)."""
    guidance_interval: tuple[float, float] | None = None
    """Guide only at sigma in (lo, hi] (drivewm.diffusion.sampling); None: at every sigma."""

    def __post_init__(self) -> None:
        if self.windows < 1 or self.steps < 1:
            raise DrivewmError("rollout: windows and steps must be >= 1")
        # a rollout decodes pixels: sigma None is the default; its first frames are the clip's own, never blended
        self.reprojection = dataclasses.replace(self.reprojection.resolved(True), blend=False)
        weights = {"guidance": self.guidance, "trajectory guidance": self.trajectory_guidance}
        # a NaN speed had made NaN waypoints, a blank clip
        finite_at_least("rollout", 0, **weights, **{"--speed": self.speed_mps})
        if self.speed_mps > MAX_SPEED_MPS:  # 1e30 m/s had written waypoints of 1e29 m into the clip
            raise DrivewmError(f"rollout: --speed must be at most {MAX_SPEED_MPS:g} m/s, got {self.speed_mps:g}")
        self.guidance_interval = check_guidance_interval("rollout", self.guidance_interval)


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


def rollout(model: MultiView, clip: Clip, options: RolloutOptions, tokenizer) -> GeneratedSample:
    """Continue ``clip`` for ``options.windows`` windows on ``model.device`` (the tokenizer must be there
    too); returns the whole video (real conditioning frames first) with the trajectory it was conditioned on."""
    rig, mv = clip_rig(model, clip), model.cfg.multiview
    c, t, h, w = model.latent.latent_shape
    tc, sc = tokenizer.config.temporal_compression, tokenizer.config.spatial_compression
    k = max(1, model.cfg.edm.cond_frames)
    win = _Windows(k, 1 + (k - 1) * tc, 1 + (t - 1) * tc, 1.0 / (clip.meta.fps * mv.trajectory_dt_s))
    if clip.meta.num_frames < win.n_cond:
        raise DrivewmError(
            f"clip {clip.key}: needs at least {win.n_cond} frames to condition on, has {clip.meta.num_frames}"
        )
    speed = options.speed_mps or initial_speed_mps(clip)
    speed = speed if np.isfinite(speed) else mv.speed_mps
    total = win.n_cond + options.windows * (win.n_win - win.n_cond)
    num_poses = int(np.ceil(total * win.steps_per_frame)) + mv.trajectory_waypoints + 1
    poses = rollout_poses(options.trajectory, num_poses, mv.trajectory_dt_s, speed, (total - 1) / clip.meta.fps)
    captions = (
        [options.prompt] * len(rig.cameras)
        if options.prompt
        else [clip.meta.view_captions.get(n) or clip.meta.caption for n in rig.names]
    )
    size = (h * sc, w * sc)
    first = frames_to_video(
        np.stack([clip.video(n)[: win.n_cond] for n in rig.names]), size
    )  # (V, 3, n_cond, h*sc, w*sc)
    video = rearrange(first, "v c t h w -> v t h w c").add(1).mul(127.5).round().byte().numpy()
    for window in tqdm(range(options.windows), desc="rollout"):
        new = _next_window(model, tokenizer, rig, captions, video, poses, win, size, options, window, clip.meta.fps)
        video = np.concatenate([video, new], axis=1)
    traj = waypoints_from_poses(poses, 0, int(round((video.shape[1] - 1) * win.steps_per_frame)))
    extra = {
        "rollout_of": clip.key,
        "source_log": clip.meta.source_log,
        "trajectory": options.trajectory,
        "windows": options.windows,
        "speed_mps": speed,
        "seed": options.seed,
        "steps": options.steps,
        "guidance": options.guidance,
        "guidance_interval": list(options.guidance_interval) if options.guidance_interval else None,
        "cond_video_frames": win.n_cond,
        **options.reprojection.record(),
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
    options: RolloutOptions,
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
    sampling = {
        "guidance": options.guidance,
        "sampler": options.sampler,
        "trajectory_guidance": options.trajectory_guidance,
        "guidance_interval": options.guidance_interval,
    }
    seed = options.seed + window
    z = model.sample_latents(
        rig, [captions], waypoints[None], [seed], options.steps, cond_latents=cond[None], fps=fps, **sampling
    )[0]
    if options.reprojection.sigma:
        first = decode_views(tokenizer, z, model.device)
        z = refine_reprojected(
            model, tokenizer, rig, captions, waypoints, seed, first, options.reprojection, sampling, fps
        )
    return decode_views(tokenizer, z, model.device)[:, win.n_cond :]
