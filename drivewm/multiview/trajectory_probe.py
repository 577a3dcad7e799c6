"""Does a multi-view model use its trajectory conditioning, and which way round?

Sampling and reading the yaw back needs dozens of samples to tell a weak effect from chance. The
probe asks the denoiser instead: the EDM loss of turning clips (Text2World frames, the same noise
each time) under their mirrored waypoints (y -> -y: the other turn, the camera rays moving with it)
minus under their own, with the captions dropped so that only the trajectory can tell the turns
apart. A model that ignores the trajectory scores exactly 0; one that follows it, above 0; one
that learned turns mirrored, below. Post-training logs it (``trajectory_loss_gap`` and its t
statistic over the clips, drivewm.multiview.posttrain); studies/trajectory_loss_gap.py prints it for
a model folder. Measured on the shipped model: docs/quality-vs-compute.md.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import torch

from drivewm.diffusion.denoiser import edm_loss
from drivewm.eval.trajectory_errors import waypoint_heading_deg
from drivewm.geometry import T_from_xyz_yaw
from drivewm.multiview.data import MultiViewDataset, MultiViewSample
from drivewm.multiview.model import MultiView, build_conditioning
from drivewm.views.rays import moving_token_rays

#: Clips whose waypoints turn by more than this (degrees) are probed.
MIN_TURN_DEG = 15.0
MIRROR = np.array([1.0, -1.0, 1.0])


def turning_clips(ds: MultiViewDataset, count: int, min_turn_deg: float = MIN_TURN_DEG, match: str = "") -> list[int]:
    """Indices of the first ``count`` distinct clips (by key) whose key contains ``match`` and whose
    waypoints turn by more than ``min_turn_deg``; fewer, or none, when the data has fewer."""
    seen, out = set(), []
    for i in range(len(ds)):
        if len(out) == count:
            break
        key = ds.cache.rows[i]["key"]  # from the index: reading the clip's file for its key would read it twice
        if key not in seen and match in key and is_turning(ds[i], min_turn_deg):
            out.append(i)
        seen.add(key)
    return out


def is_turning(s: MultiViewSample, min_turn_deg: float) -> bool:
    """Whether a clip's waypoints turn by more than ``min_turn_deg`` (the heading of their last chord,
    as the eval reads a conditioned turn); a clip without ego motion does not."""
    return s.trajectory_known and abs(waypoint_heading_deg(s.trajectory)) > min_turn_deg


@torch.no_grad()
def clip_losses(
    net: torch.nn.Module,
    bundle: MultiView,
    ds: MultiViewDataset,
    index: int,
    sigma: float,
    captions: bool,
    seed: int,
    trajectories: tuple[str, ...] = ("own", "mirrored", "none"),
    cond_frames: int = 0,
) -> list[float]:
    """EDM loss of clip ``index`` under each of ``trajectories`` (its own waypoints, the mirrored
    ones, none, or one of :data:`SPLIT` or :data:`TURNED`), with the same noise. ``net``: the denoiser
    to call (``bundle.net`` or a training wrapper of it); ``bundle``: the
    :class:`~drivewm.multiview.model.MultiView` whose text encoder and camera geometry build the
    conditioning; ``cond_frames``: latent frames given (Video2World), 0 = Text2World."""
    s = ds[index]
    views = s.latents.shape[0]
    device = next(net.parameters()).device
    noise = torch.randn(s.latents.shape, generator=torch.Generator().manual_seed(seed)).to(device)
    edm = dataclasses.replace(bundle.cfg.edm, cond_frames=cond_frames)
    sigmas, keep = torch.full((views,), sigma, device=device), torch.full((views,), captions, device=device)
    waypoints = {"own": s.trajectory, "mirrored": s.trajectory * MIRROR, "none": None}

    def conditioning(name: str):
        traj = waypoints[name]
        return build_conditioning(bundle, s.rig, [s.view_captions], None if traj is None else traj[None], s.fps)

    out = []
    for name in trajectories:
        if name in TURNED:  # the rig standing still, turned by a constant angle the way the clip turns
            cond = conditioning("own")
            angle = np.deg2rad(TURNED[name]) * np.sign(waypoint_heading_deg(s.trajectory))
            cond = dataclasses.replace(cond, rays=turn_rays(cond.static_rays, angle))
        else:
            embedded, rays = SPLIT.get(name, (name, name))
            cond = conditioning(embedded)
            if rays != embedded:  # one pathway fed the other trajectory: which of the two carries the turn
                cond = dataclasses.replace(cond, rays=conditioning(rays).rays)
        out.append(float(edm_loss(net, edm, s.latents.to(device), cond.to(device), sigmas, noise, keep)))
    return out


#: Trajectories whose two pathways disagree: (the waypoints the trajectory encoder embeds, the ones
#: the moving-camera rays follow). With the own and mirrored losses they tell whether the waypoint
#: embedding or the per-frame camera rays carries what the model learned of a turn.
SPLIT = {"own, mirrored rays": ("own", "mirrored"), "mirrored, own rays": ("mirrored", "own")}


#: Rays of the rig standing still, turned at every frame by a constant yaw (deg; + = the way the clip
#: turns, - = against it). A model that reads a ray as a place in the rig, the road's layout there,
#: rather than as the camera's motion, scores the clips lower under one of these than under the rig's
#: own rays; turning left, a road bending left shows its content where a straight one shows it
#: further right (docs/quality-vs-compute.md).
TURNED = {"static rays turned with the turn 20 deg": 20.0, "static rays turned against the turn 20 deg": -20.0}


def turn_rays(rays: torch.Tensor, yaw_rad: float) -> torch.Tensor:
    """(..., 6) Plucker rays (d, m) turned about the ego's up axis through its origin by ``yaw_rad``:
    the rig moved to a pose of pure yaw (:func:`~drivewm.multiview.camera.moving_token_rays`)."""
    pose = torch.from_numpy(T_from_xyz_yaw(0.0, 0.0, 0.0, yaw_rad)[None])
    return moving_token_rays(rays.reshape(1, -1, 6), pose).reshape(rays.shape)


def loss_gap(
    net: torch.nn.Module,
    bundle: MultiView,
    ds: MultiViewDataset,
    clips: list[int],
    sigma: float = 1.0,
    seed: int = 1000,
) -> tuple[float, float]:
    """(mean over ``clips`` of the mirrored minus the own trajectory's loss, its t statistic over the
    clips), captions dropped; clip j uses noise seed ``seed + j``. t is nan without spread (fewer
    than two clips, or a model that ignores the trajectory)."""
    pairs = [clip_losses(net, bundle, ds, i, sigma, False, seed + j, ("own", "mirrored")) for j, i in enumerate(clips)]
    gaps = np.array([mirrored - own for own, mirrored in pairs])
    return float(gaps.mean()), t_statistic(gaps)


def t_statistic(gaps: np.ndarray) -> float:
    """One-sample t of the per-clip gaps against 0; nan without spread (fewer than two, or all equal)."""
    spread = gaps.std(ddof=1) if len(gaps) > 1 else 0.0
    return float(gaps.mean() / (spread / math.sqrt(len(gaps)))) if spread > 0 else math.nan
