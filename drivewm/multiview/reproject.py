"""Reprojected refinement: the trajectory put into a sample's pixels, then refined by the model.

The multi-view denoiser uses the ego trajectory (its loss is lower with the right one), but a
sample drawn from pure noise turns by a degree or two of the 36 asked: the trajectory's pull per
step is far smaller than what seed and caption give (docs/quality-vs-compute.md). Reprojection
moves the trajectory out of the network and into the sample's starting point:

1. the first frame of every camera (generated, or a real clip's in Video2World) is warped into
   every later frame's cameras along the trajectory (drivewm.multiview.warp: the road plane and
   the plane at infinity, content fetched from whichever camera saw it, so a left turn pulls the
   front-left camera's pixels into the front camera; with ``walls_m``, ``--reproject-walls``, a
   corridor of vertical planes beside the road too); pixels no camera saw keep the first pass's;
2. the warped clip is encoded by the tokenizer (a pixel warp keeps the latents in the tokenizer's
   distribution, where a bilinear warp of the 20 x 12 latents decoded to stripes);
3. its later latent frames are noised to ``sigma`` and denoised by the model under the same prompt
   and trajectory (SDEdit, Meng et al. 2022), the first latent frame given (Video2World).

This is CamTrol's training-free camera control (Hou et al. 2024: render the first frame along the
camera path, noise, denoise) with GEN3C's flat-world rendering of a 3D cache (Ren et al. 2025).
Low ``sigma`` keeps the warp's motion and its smeared road; high ``sigma`` returns to the model's
own motion (at 2 the turn is gone). Road and distant scenery move exactly; what stands on the road
moves as if it were far away, which the refinement has to correct.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import torch
from einops import rearrange

from drivewm.config import finite_at_least
from drivewm.errors import DrivewmError
from drivewm.geometry import Rig, invert_T
from drivewm.multiview.coding import encode_views
from drivewm.multiview.defaults import DEFAULT_BLEND, DEFAULT_RESHADE, DEFAULT_SIGMA
from drivewm.multiview.model import MultiView
from drivewm.multiview.reshade import reshade as reshade_road
from drivewm.multiview.trajectories import poses_from_waypoints
from drivewm.multiview.warp import warp_first_frame, warp_grid


def reproject_first_frame(
    videos: np.ndarray,
    rig: Rig,
    waypoints: np.ndarray,
    dt_s: float,
    fps: float,
    max_ground_m: float = 100.0,
    walls_m: float = 0.0,
    reshade: bool = False,
) -> tuple[np.ndarray, float]:
    """uint8 (V, T, H, W, 3) views of ``rig`` -> the same shape: frame 0 of every view rendered at
    every frame's ego pose along ``waypoints`` (W, 3) m spaced ``dt_s`` (first at ``dt_s``), frames
    at ``fps``; pixels no view's first frame sees keep the input's own. Also the fraction rendered.
    ``walls_m``: the corridor of :func:`drivewm.multiview.warp.warp_grid` (0: road and infinity only);
    ``reshade``: the road given the first frame's look at its own distance (drivewm.multiview.reshade)."""
    out, valid = reproject_first_frame_mask(videos, rig, waypoints, dt_s, fps, max_ground_m, walls_m, reshade)
    return out, float(valid.mean())


def reproject_first_frame_mask(
    videos: np.ndarray,
    rig: Rig,
    waypoints: np.ndarray,
    dt_s: float,
    fps: float,
    max_ground_m: float = 100.0,
    walls_m: float = 0.0,
    reshade: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`reproject_first_frame` with the pixels it rendered: bool (V, T, H, W)."""
    v, t, h, w, _ = videos.shape
    poses = poses_from_waypoints(np.asarray(waypoints, dtype=np.float64), t, dt_s, fps)  # (T, 4, 4)
    rel = np.einsum("ij,tjk->tik", invert_T(poses[0]), poses)
    grid, valid = warp_grid(rig, (h, w), rel, max_ground_m, walls_m)
    frames = rearrange(torch.from_numpy(videos).float(), "v t h w c -> v c t h w")
    warped = warp_first_frame(frames, grid, valid, v)[:, :3]  # (V, 3, T, H, W), zero where not valid
    keep = valid[:, None].float()
    out = warped * keep + frames * (1 - keep)
    out = rearrange(out, "v c t h w -> v t h w c").round().clamp(0, 255).byte().numpy()
    if reshade:
        out = reshade_road(out, valid.numpy(), rig, rel, walls_m)
    return out, valid.numpy()


@dataclasses.dataclass
class Reprojection:
    """Settings of reprojected refinement (``--reproject SIGMA``)."""

    sigma: float | None = 0.0
    """Noise level the warped clip is refined from (0 = off; None = the commands' default,
    :meth:`resolved`). Chosen on validation prompts (never the benchmark's):
    docs/quality-vs-compute.md, "Reprojected refinement"."""
    steps: int = 10
    """Sampler steps of the refinement (the Karras schedule from ``sigma`` down to 0)."""
    walls_m: float = 0.0
    """Corridor of the warp (``--reproject-walls``; drivewm.multiview.warp.warp_grid ``walls_m``):
    what stands beside the road is placed on vertical planes this far (m) left and right of the
    first ego frame instead of at infinity, so it passes by with parallax. 0 = road and infinity
    only. Measured: docs/quality-vs-compute.md, "The flat-world warp stands still"."""
    reshade: bool | None = DEFAULT_RESHADE
    """``--reproject-reshade``: the warped road of every frame given the first frame's road colour at its
    own distance (drivewm.multiview.reshade), so fog's airlight and a wet road's sheen stay where they
    were instead of being pulled toward the camera (None = :data:`DEFAULT_RESHADE`):
    docs/quality-vs-compute.md, "Fog reads snow at --reproject 0.1"."""
    blend: bool | None = DEFAULT_BLEND
    """``--reproject-blend`` (generate only): the first pass's first frame blended where the rig's cameras
    overlap before it is warped (drivewm.multiview.blend), so the views agree there (None =
    :data:`DEFAULT_BLEND`). Never applied to a real clip's frames (``--condition-clip``, rollouts)."""

    def __post_init__(self) -> None:
        if self.reshade is None:
            self.reshade = DEFAULT_RESHADE
        if self.blend is None:
            self.blend = DEFAULT_BLEND
        if self.sigma is not None:
            finite_at_least("reprojection", 0, **{"--reproject": self.sigma})
        finite_at_least("reprojection", 0, **{"--reproject-walls": self.walls_m})
        if self.steps < 1:
            raise DrivewmError(f"reprojection: --reproject-steps must be >= 1, got {self.steps}")

    def resolved(self, decodes_pixels: bool) -> Reprojection:
        """These settings with the default sigma filled in: :data:`DEFAULT_SIGMA` for a model that decodes
        through its tokenizer, off for a preview model (no pixels to warp)."""
        if self.sigma is not None:
            return self
        return dataclasses.replace(self, sigma=DEFAULT_SIGMA if decodes_pixels else 0.0)

    def record(self) -> dict:
        """What a generated clip's metadata says of it."""
        record = {"reproject_sigma": self.sigma, "reproject_steps": self.steps if self.sigma else 0}
        record |= {"reproject_walls_m": self.walls_m} if self.sigma and self.walls_m else {}
        record |= {"reproject_reshade": True} if self.sigma and self.reshade else {}
        return record | ({"reproject_blend": True} if self.sigma and self.blend else {})


def refine_reprojected(
    model: MultiView,
    tokenizer,
    rig: Rig,
    view_captions: list[str],
    waypoints: np.ndarray,
    seed: int,
    videos: np.ndarray,
    reprojection: Reprojection,
    sampling: dict,
    fps: float | None = None,
) -> torch.Tensor:
    """Raw latents (V, c, t, h, w) of one clip: the first frames of ``videos`` (uint8 (V, T, H, W, 3),
    a first pass or a window's frames) reprojected along ``waypoints``, encoded, noised to
    ``reprojection.sigma`` and denoised (the first latent frame given). ``sampling``: guidance,
    sampler and trajectory_guidance, as the first pass used them; clips at ``fps`` (default the model's)."""
    fps = fps or model.latent.fps
    mv = model.cfg.multiview
    warped, _ = reproject_first_frame(
        videos, rig, waypoints, mv.trajectory_dt_s, fps, mv.warp_ground_m, reprojection.walls_m, reprojection.reshade
    )
    z = encode_views(tokenizer, warped, videos.shape[2:4], model.device)[None]  # (1, V, c, t, h, w)
    return model.sample_latents(
        rig,
        [view_captions],
        np.asarray(waypoints)[None],
        [seed],
        reprojection.steps,
        cond_latents=z,
        fps=fps,
        start_latents=z,
        start_sigma=reprojection.sigma,
        **sampling,
    )[0]
