"""Reprojected refinement: the trajectory put into a sample's pixels, then refined by the model.

The ``reproject`` post-step (opt-in, recorded in the output's ``post_processing``) moves the
trajectory out of the network and into the sample's starting point:

1. the first frame of every camera (generated, or a real clip's in Video2World) is warped into
   every later frame's cameras along the trajectory (drivewm.views.reproject: the road plane and
   the plane at infinity, content fetched from whichever camera saw it, so a left turn pulls the
   front-left camera's pixels into the front camera); pixels no camera saw keep the first pass's;
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

import numpy as np
import torch

from drivewm.generate.config import ReprojectConfig
from drivewm.geometry import Rig
from drivewm.multiview.coding import encode_views
from drivewm.multiview.model import MultiView
from drivewm.multiview.trajectories import poses_from_waypoints
from drivewm.views.reproject import reproject_first_frame


def refine_reprojected(
    model: MultiView,
    tokenizer,
    rig: Rig,
    view_captions: list[str],
    waypoints: np.ndarray,
    seed: int,
    videos: np.ndarray,
    reproject: ReprojectConfig,
    reshade: bool,
    sampling: dict,
    fps: float | None = None,
) -> torch.Tensor:
    """Raw latents (V, c, t, h, w) of one clip: the first frames of ``videos`` (uint8 (V, T, H, W, 3),
    a first pass or a window's frames) reprojected along ``waypoints``, encoded, noised to
    ``reproject.sigma`` and denoised (the first latent frame given). ``sampling``: guidance,
    sampler, trajectory_guidance and guidance_interval, as the first pass used them; ``reshade``: the
    warped road reshaded (drivewm.views.reshade); clips at ``fps`` (default the model's)."""
    fps = fps or model.latent.fps
    mv = model.cfg.multiview
    poses = poses_from_waypoints(np.asarray(waypoints, dtype=np.float64), videos.shape[1], mv.trajectory_dt_s, fps)
    warped, _ = reproject_first_frame(videos, rig, poses, mv.warp_ground_m, reshade)
    z = encode_views(tokenizer, warped, videos.shape[2:4], model.device)[None]  # (1, V, c, t, h, w)
    return model.sample_latents(
        rig,
        [view_captions],
        np.asarray(waypoints)[None],
        [seed],
        reproject.steps,
        cond_latents=z,
        fps=fps,
        start_latents=z,
        start_sigma=reproject.sigma,
        **sampling,
    )[0]
